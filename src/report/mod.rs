//! Run folders: where a run's results land, written all-or-nothing.
//!
//! Job: stage every file of a run in a hidden folder beside its destination and move it into
//! place only when the run has finished, so an error never leaves a half-written output; write
//! the fully resolved inputs (scene, URDF, workpiece) next to the results, so a run folder is
//! self-contained and can be re-run as it is; the per-pick table and CSV files (`tables`); a
//! study's page, `report.html` ([`html`]).

pub mod html;
mod tables;

use std::path::{Path, PathBuf};

pub use tables::{Fixed, PICKS_TABLE_WIDTH, picks_csv, picks_table, to_csv, wrap, wrap_under};

use crate::config::{LoadedScene, LoadedWorkpiece, ShapeKind, Source};

/// A JSON document as binpick writes it: pretty, keys as the value orders them, a final line
/// break.
pub fn pretty_json(value: &serde_json::Value) -> String {
    // A JSON value has string keys only, so it always serialises.
    serde_json::to_string_pretty(value).expect("a JSON value serialises") + "\n"
}

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

    /// Writes a value as pretty JSON ([`pretty_json`]'s text).
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
            // The cup it runs with, in full (the scene written is resolved for it).
            let wp = wp.with_set_up_completed(&scene.scene);
            self.write_workpiece(&wp, "workpiece.toml")?;
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
