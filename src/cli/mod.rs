//! The command line's shared parts: errors and exit codes, argument helpers, output
//! formatting, Ctrl-C handling. One module per command beside it; each parses nothing itself
//! (clap does) and calls the library's pipelines.
//!
//! Exit codes: 0 success; 2 bad input (invalid file, bad argument, unreachable target), with one
//! clear line per problem on stderr and nothing written; 130 interrupted (results so far
//! written); 1 any other failure. Units: degrees only at this boundary, SI inside.

pub mod batch;
pub mod bench;
pub mod check;
pub mod part;
pub mod pile;
pub mod robot;
pub mod run;
pub mod sweep;

use std::path::Path;

use anyhow::Result;
use clap::Args;
use nalgebra::Isometry3;
use serde_json::json;

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::robot::{JointVector, RobotModel};

/// Bad input from the user: reported on one line, exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InputError(pub String);

/// The run was interrupted by Ctrl-C; its results so far were written (exit 130).
#[derive(Debug, thiserror::Error)]
#[error("interrupted: the results so far are in {0}")]
pub struct Interrupted(pub String);

/// Recording formats a user can skip (`run` records both by default, `batch --record` too).
#[derive(Args, Clone, Copy)]
pub struct SkipFormats {
    /// Do not write the Rerun recording (`.rrd`).
    #[arg(long)]
    no_rrd: bool,
    /// Do not write the MCAP recording (`.mcap`).
    #[arg(long)]
    no_mcap: bool,
}

impl SkipFormats {
    /// The formats to write when recording.
    pub fn formats(self, record: bool) -> binpick::record::Formats {
        binpick::record::Formats {
            rrd: record && !self.no_rrd,
            mcap: record && !self.no_mcap,
        }
    }
}

/// Loads a scene and a workpiece and checks that they go together (and that the workpiece's
/// shape builds), so a bad file is bad input before anything runs.
pub fn load_cell(scene: Option<&Path>, workpiece: &str) -> Result<(LoadedScene, LoadedWorkpiece, RobotModel)> {
    let loaded = LoadedScene::load(scene)?;
    let robot = RobotModel::from_scene(&loaded)?;
    robot.check_scene_reach(&loaded.label, &loaded.scene)?;
    let wp = LoadedWorkpiece::resolve(workpiece)?;
    wp.workpiece.check_fits_scene(&wp.label, &loaded.scene)?;
    binpick::physics::PartShape::build(&wp.workpiece, &wp.source)?;
    Ok((loaded, wp, robot))
}

/// Applies `--recognition` to the cell (so the resolved scene a run writes says which it used).
pub fn override_recognition(loaded: &mut LoadedScene, mode: Option<binpick::config::RecognitionMode>) {
    if let Some(m) = mode {
        loaded.scene.sensor.recognition = m;
    }
}

/// `--picks` of `run` and `batch`: 1 to 10,000.
pub fn check_picks(picks: usize) -> Result<()> {
    if picks == 0 || picks > 10_000 {
        return Err(InputError(format!("--picks must be within [1, 10000], got {picks}")).into());
    }
    Ok(())
}

/// Refuses non-finite numbers in argument `name`.
pub fn finite_args(name: &str, v: &[f64]) -> Result<()> {
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        return Err(InputError(format!("{name} must be finite numbers, got {bad}")).into());
    }
    Ok(())
}

/// Six joint values in degrees from argument `name` as radians.
pub fn joints_from_deg(name: &str, v: &[f64]) -> Result<JointVector> {
    finite_args(name, v)?;
    Ok(JointVector::from_fn(|i, _| v[i].to_radians()))
}

/// Joint values in degrees, rounded to 6 decimals, for JSON.
pub fn deg_list(q: &JointVector) -> Vec<f64> {
    q.iter().map(|v| round(v.to_degrees(), 6)).collect()
}

/// `v` rounded to `digits` decimals.
pub fn round(v: f64, digits: i32) -> f64 {
    let s = 10f64.powi(digits);
    (v * s).round() / s
}

/// A pose as JSON: position [m] and roll-pitch-yaw [deg].
pub fn pose_json(p: &Isometry3<f64>) -> serde_json::Value {
    let (r, pi, y) = p.rotation.euler_angles();
    json!({
        "xyz_m": p.translation.vector.iter().map(|v| round(*v, 9)).collect::<Vec<_>>(),
        "rpy_deg": [round(r.to_degrees(), 6), round(pi.to_degrees(), 6), round(y.to_degrees(), 6)],
    })
}

/// A pose as one line of text: position [m] and roll-pitch-yaw [deg].
pub fn pose_text(p: &Isometry3<f64>) -> String {
    let (r, pi, y) = p.rotation.euler_angles();
    let t = p.translation.vector;
    format!(
        "xyz [{:9.5} {:9.5} {:9.5}] m  rpy [{:8.3} {:8.3} {:8.3}] deg",
        t.x,
        t.y,
        t.z,
        r.to_degrees(),
        pi.to_degrees(),
        y.to_degrees()
    )
}

/// Set when Ctrl-C was pressed: runs end after the pick under way and write what they have.
pub static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Installs the Ctrl-C handler (once) and returns the flag it sets. A second Ctrl-C, while the
/// first is being honoured, exits at once with 130.
pub fn stop_on_ctrl_c() -> &'static std::sync::atomic::AtomicBool {
    static INSTALLED: std::sync::Once = std::sync::Once::new();
    INSTALLED.call_once(|| {
        let installed = ctrlc::set_handler(|| {
            if STOP.swap(true, std::sync::atomic::Ordering::Relaxed) {
                std::process::exit(130);
            }
            eprintln!("interrupted: finishing the pick under way and writing the results");
        });
        if let Err(e) = installed {
            eprintln!("warning: Ctrl-C will stop the process without writing results: {e}");
        }
    });
    &STOP
}
