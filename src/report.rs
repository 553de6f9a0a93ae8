//! Run folders: where a run's results land, written all-or-nothing.
//!
//! Job: stage every file of a run in a hidden folder beside its destination and move it into
//! place only when the run has finished, so an error never leaves a half-written output; write
//! the fully resolved inputs (scene, URDF, workpiece) next to the results, so a run folder is
//! self-contained and can be re-run as it is.

use std::path::{Path, PathBuf};

use crate::config::{LoadedScene, LoadedWorkpiece, ShapeKind, Source};

/// Why a run folder could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    /// A file system operation failed.
    #[error("{path}: {source}")]
    Io {
        /// The path involved.
        path: String,
        /// The error.
        source: std::io::Error,
    },
    /// Serialising a result failed.
    #[error("{path}: cannot serialise: {reason}")]
    Serialise {
        /// The file.
        path: String,
        /// What went wrong.
        reason: String,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> RunDirError + '_ {
    move |source| RunDirError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// A run folder being written: files go to a staging folder until [`RunDir::finish`].
#[derive(Debug)]
pub struct RunDir {
    staging: PathBuf,
    dest: PathBuf,
    finished: bool,
}

impl RunDir {
    /// Starts the run folder `base/name` (replaced when the run finishes).
    pub fn create(base: &Path, name: &str) -> Result<Self, RunDirError> {
        std::fs::create_dir_all(base).map_err(io(base))?;
        let staging = base.join(format!(".{name}.partial-{}", std::process::id()));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(io(&staging))?;
        }
        std::fs::create_dir_all(&staging).map_err(io(&staging))?;
        Ok(RunDir {
            staging,
            dest: base.join(name),
            finished: false,
        })
    }

    /// Where the run folder will be once finished.
    pub fn dest(&self) -> &Path {
        &self.dest
    }

    /// Path of a file in the (staged) run folder, for writers that open files themselves.
    pub fn path(&self, file: &str) -> PathBuf {
        self.staging.join(file)
    }

    /// The folder files are written into until [`RunDir::finish`] moves it into place.
    pub fn staging_dir(&self) -> &Path {
        &self.staging
    }

    /// Writes a file into the run folder.
    pub fn write(&self, file: &str, bytes: impl AsRef<[u8]>) -> Result<(), RunDirError> {
        let p = self.staging.join(file);
        std::fs::write(&p, bytes).map_err(io(&p))
    }

    /// Writes a value as pretty JSON.
    pub fn write_json(&self, file: &str, value: &impl serde::Serialize) -> Result<(), RunDirError> {
        let text = serde_json::to_string_pretty(value).map_err(|e| RunDirError::Serialise {
            path: file.into(),
            reason: e.to_string(),
        })?;
        self.write(file, text + "\n")
    }

    /// Writes the resolved scene (`scene.toml`, its URDF beside it) and workpiece (`workpiece.toml`,
    /// and its mesh if it has one), so the run folder can be re-run on its own.
    pub fn write_inputs(&self, scene: &LoadedScene, workpiece: Option<&LoadedWorkpiece>) -> Result<(), RunDirError> {
        let urdf_name = Path::new(&scene.scene.robot.urdf)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "robot.urdf".into());
        let mut resolved = scene.scene.clone();
        resolved.robot.urdf = urdf_name.clone();
        let header = format!(
            "# binpick {}: resolved scene, from {}\n",
            env!("CARGO_PKG_VERSION"),
            scene.label
        );
        let text = toml::to_string(&resolved).map_err(|e| RunDirError::Serialise {
            path: "scene.toml".into(),
            reason: e.to_string(),
        })?;
        self.write("scene.toml", header + &text)?;
        self.write(&urdf_name, &scene.urdf_text)?;
        if let Some(wp) = workpiece {
            self.write_workpiece(wp, "workpiece.toml")?;
        }
        Ok(())
    }

    /// Writes one resolved workpiece as `file` (and its mesh, if it has one, beside it).
    pub fn write_workpiece(&self, wp: &LoadedWorkpiece, file: &str) -> Result<(), RunDirError> {
        let mut w = wp.workpiece.clone();
        if let (ShapeKind::Mesh, Source::File(p), Some(mesh)) = (w.shape.kind, &wp.source, w.shape.mesh_file.clone()) {
            let from = p.parent().unwrap_or(Path::new(".")).join(&mesh);
            let name = Path::new(&mesh)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or(mesh);
            std::fs::copy(&from, self.staging.join(&name)).map_err(io(&from))?;
            w.shape.mesh_file = Some(name);
        }
        let header = format!(
            "# binpick {}: resolved workpiece, from {}\n",
            env!("CARGO_PKG_VERSION"),
            wp.label
        );
        let text = toml::to_string(&w).map_err(|e| RunDirError::Serialise {
            path: file.into(),
            reason: e.to_string(),
        })?;
        self.write(file, header + &text)
    }

    /// Moves the staged files into place, replacing an earlier run of the same name.
    pub fn finish(mut self) -> Result<PathBuf, RunDirError> {
        if self.dest.exists() {
            std::fs::remove_dir_all(&self.dest).map_err(io(&self.dest))?;
        }
        std::fs::rename(&self.staging, &self.dest).map_err(io(&self.dest))?;
        self.finished = true;
        Ok(self.dest.clone())
    }
}

impl Drop for RunDir {
    fn drop(&mut self) {
        if !self.finished {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

/// Formats an optional value with six decimals, empty when absent.
fn opt6(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x:.6}"))
}

/// `picks.csv`: one row per pick (and per capture that found nothing to pick), SI units in
/// the column names; reasons have commas and quotes replaced so the file stays plain CSV.
pub fn picks_csv(records: &[crate::cycle::PickRecord]) -> String {
    let mut csv = String::from(
        "pick,outcome,detail,capture_s,ready_s,release_s,takt_s,first_of_pile,pick_s,place_s,\
         stall_sensor_s,stall_compute_s,grasp_compute_s,pick_compute_s,place_compute_s,\
         placement_error_mm,yaw_error_deg,max_tracking_error_deg,peak_torque_ratio,suction_speed_factor\n",
    );
    for r in records {
        let detail = r.outcome.detail().replace([',', '"', '\n'], " ");
        csv += &format!(
            "{},{},{},{:.6},{:.6},{},{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{},{},{:.6},{:.6},{:.4}\n",
            r.index,
            r.outcome.name(),
            detail,
            r.capture_s,
            r.ready_s,
            opt6(r.release_s),
            opt6(r.takt_s),
            r.first_of_pile,
            r.pick_s,
            r.place_s,
            r.stall_sensor_s,
            r.stall_compute_s,
            r.grasp_compute_s,
            r.pick_compute_s,
            r.place_compute_s,
            opt6(r.placement_error_mm),
            opt6(r.yaw_error_deg),
            r.max_tracking_error_deg,
            r.peak_torque_ratio,
            r.suction_speed_factor,
        );
    }
    csv
}

/// The per-pick table printed by `binpick run`.
pub fn picks_table(records: &[crate::cycle::PickRecord]) -> String {
    let mut out = String::from(
        "pick  outcome            takt_s  pick_s  place_s  wait_sensor_s  wait_compute_s  place_err_mm  detail\n",
    );
    for r in records {
        let takt = r.takt_s.map_or("-".to_string(), |t| {
            if r.first_of_pile {
                format!("({t:.3})")
            } else {
                format!("{t:.3}")
            }
        });
        let err = r.placement_error_mm.map_or("-".to_string(), |e| format!("{e:.2}"));
        out += &format!(
            "{:>4}  {:<17} {:>7}  {:>6.3}  {:>7.3}  {:>13.3}  {:>14.3}  {:>12}  {:.60}\n",
            r.index,
            r.outcome.name(),
            takt,
            r.pick_s,
            r.place_s,
            r.stall_sensor_s,
            r.stall_compute_s,
            err,
            r.outcome.detail()
        );
    }
    out
}

/// The run's time chart over its whole length, and a close-up of three takts in the steady
/// state (from the release before the middle placed pick), as SVG documents.
pub fn time_charts(result: &crate::cycle::RunResult, title: &str) -> (String, Option<String>) {
    let end = result.summary.sim_time_s;
    let whole = crate::chart::time_chart_svg(title, &result.spans, &result.markers, 0.0, end);
    let releases: Vec<f64> = result.records.iter().filter_map(|r| r.release_s).collect();
    let steady = (releases.len() >= 5).then(|| {
        let i = releases.len() / 2 - 1;
        let t0 = releases[i] - 0.2;
        let t1 = releases[(i + 3).min(releases.len() - 1)] + 0.2;
        crate::chart::time_chart_svg(
            &format!("{title}: three takts in the steady state"),
            &result.spans,
            &result.markers,
            t0,
            t1,
        )
    });
    (whole, steady)
}
