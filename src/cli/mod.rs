//! The command line's shared parts: errors and exit codes, argument helpers, output
//! formatting, Ctrl-C handling. One module per command beside it; each parses nothing itself
//! (clap does) and calls the library's pipelines.
//!
//! Exit codes: 0 success; 2 bad input (invalid file, bad argument, unreachable target), with one
//! clear line per problem on stderr and nothing written; 3 a run ended on a physics fault (every
//! run's results, the failed one's up to its fault, and the table written; the fault on stderr);
//! 130 interrupted (results so far written); 1 any other failure. Units: degrees only at this boundary, SI inside.

pub mod batch;
pub mod bench;
pub mod check;
pub mod export;
pub mod part;
pub mod pile;
pub mod robot;
pub mod run;
pub mod study;
pub mod sweep;
pub mod tune;

use std::path::{Path, PathBuf};

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

/// Runs ended on a physics fault; every run's results were written (exit 3).
#[derive(Debug, thiserror::Error)]
#[error("{count} run(s) ended on a physics fault (their results up to it are in {dir}):\n{faults}")]
pub struct RunsFailed {
    /// Runs that ended on a fault.
    pub count: usize,
    /// Where the results are.
    pub dir: String,
    /// Each fault, one line per run.
    pub faults: String,
}

impl RunsFailed {
    /// The failure of `tallies` written to `dir`, if a run ended on a physics fault.
    pub fn of<'a>(tallies: impl IntoIterator<Item = &'a binpick::cycle::Tally>, dir: &str) -> Option<Self> {
        let lines: Vec<String> = tallies
            .into_iter()
            .flat_map(|t| {
                t.physics_faults
                    .iter()
                    .map(move |f| format!("  workpiece {} seed {}: {f}", t.workpiece, t.seed))
            })
            .collect();
        (!lines.is_empty()).then(|| RunsFailed {
            count: lines.len(),
            dir: dir.to_string(),
            faults: lines.join("\n"),
        })
    }
}

/// How the cell charges compute: the mode of `run`, `batch` and `sweep`.
#[derive(Args, Clone, Copy)]
pub struct ModeArgs {
    /// Charge the cell file's fixed compute budgets instead of measured wall time, so the
    /// same seed gives byte-identical results.
    #[arg(long)]
    pub deterministic: bool,
}

/// Where results go and how they are printed: `run`, `batch`, `sweep` and `merge`.
#[derive(Args, Clone)]
pub struct OutArgs {
    /// Folder the results folder is written into.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Machine-readable JSON output.
    #[arg(long)]
    pub json: bool,
}

/// The cell as given: `run` and `batch` (a sweep varies it with `--set`).
#[derive(Args, Clone)]
pub struct CellArgs {
    /// Recognition: `cloud` (from the depth capture, the default) or `oracle` (the what-if of
    /// perfect recognition); overrides the cell file's `sensor.recognition`.
    #[arg(long, value_name = "cloud|oracle")]
    pub recognition: Option<binpick::config::RecognitionMode>,
    /// Scene file (default: the embedded default cell).
    #[arg(long)]
    pub scene: Option<PathBuf>,
}

impl CellArgs {
    /// The scene loaded, `--recognition` applied (so the resolved scene a run writes says which
    /// it used), its arm built and its trays checked within reach.
    pub fn load(&self) -> Result<(LoadedScene, RobotModel)> {
        let mut loaded = LoadedScene::load(self.scene.as_deref())?;
        if let Some(m) = self.recognition {
            loaded.scene.sensor.recognition = m;
        }
        let robot = RobotModel::from_scene(&loaded)?;
        robot.check_scene_reach(&loaded.label, &loaded.scene)?;
        Ok((loaded, robot))
    }
}

/// A workpiece loaded and checked against the cell: it fits, its shape builds, and the cell's
/// waiting pose is reachable and out of the sensor's view.
pub fn load_workpiece(name: &str, loaded: &LoadedScene, robot: &RobotModel) -> Result<LoadedWorkpiece> {
    let wp = LoadedWorkpiece::resolve(name)?;
    wp.workpiece.check_fits_scene(&wp.label, &loaded.scene)?;
    let shape = binpick::physics::PartShape::build(&wp.workpiece, &wp.source)?;
    binpick::cycle::check_waiting_pose(&loaded.label, &loaded.scene, robot, &shape)?;
    Ok(wp)
}

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
    pub fn formats(self, record: bool) -> binpick::recording::Formats {
        binpick::recording::Formats {
            rrd: record && !self.no_rrd,
            mcap: record && !self.no_mcap,
        }
    }
}

/// Loads a scene and a workpiece and checks that they go together (and that the workpiece's
/// shape builds), so a bad file is bad input before anything runs. The scene comes back
/// resolved for the workpiece's own cup, if it brings one ([`LoadedScene::for_workpiece`]).
pub fn load_cell(scene: Option<&Path>, workpiece: &str) -> Result<(LoadedScene, LoadedWorkpiece, RobotModel)> {
    let loaded = LoadedScene::load(scene)?;
    let robot = RobotModel::from_scene(&loaded)?;
    robot.check_scene_reach(&loaded.label, &loaded.scene)?;
    let wp = load_workpiece(workpiece, &loaded, &robot)?;
    Ok((loaded.for_workpiece(&wp), wp, robot))
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

/// A pose as JSON: position (m) and roll-pitch-yaw (deg).
pub fn pose_json(p: &Isometry3<f64>) -> serde_json::Value {
    let (r, pi, y) = p.rotation.euler_angles();
    json!({
        "xyz_m": p.translation.vector.iter().map(|v| round(*v, 9)).collect::<Vec<_>>(),
        "rpy_deg": [round(r.to_degrees(), 6), round(pi.to_degrees(), 6), round(y.to_degrees(), 6)],
    })
}

/// A pose as one line of text: position (m) and roll-pitch-yaw (deg).
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

/// Prints `text` wrapped to the terminal's width ([`binpick::results::table::TERMINAL_WIDTH`]).
pub fn say(text: &str) {
    say_under("", 0, text);
}

/// Prints `text` wrapped within the terminal's width, from column `indent`: its first line after
/// `head` (padded to `indent`), the others under it (a table row's label, a note under a row).
pub fn say_under(head: &str, indent: usize, text: &str) {
    let width = binpick::results::table::TERMINAL_WIDTH;
    print!("{}", binpick::report::wrap_under(head, indent, text, width));
}

/// A share as a percentage with one decimal ("12.5 %"), or "-" where there is none (a precision
/// without detections, a recall without a top layer): never `NaN`.
pub fn percent(share: f64) -> String {
    if share.is_finite() {
        format!("{:.1} %", 100.0 * share)
    } else {
        "-".into()
    }
}

/// The pose errors of a recognition's correct detections as text: "median / p95: 0.11 / 0.29
/// mm, 0.15 / 0.88 deg", or that there is no correct detection to take them from (never `NaN`).
pub fn pose_errors_text(r: &binpick::sensor::RecognitionSummary) -> String {
    let [p50, p95] = r.position_error_mm;
    let [r50, r95] = r.rotation_error_deg;
    if r.correct == 0 || !(p50.is_finite() && p95.is_finite() && r50.is_finite() && r95.is_finite()) {
        return "none: no detection was correct".into();
    }
    format!("median / p95: {p50:.2} / {p95:.2} mm, {r50:.2} / {r95:.2} deg")
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

#[cfg(test)]
mod tests {
    use binpick::sensor::RecognitionTotals;

    /// A recognition without a correct detection (or without any) prints "-" and says that no
    /// detection was correct, never `NaN`. Negative control: one correct detection prints its
    /// errors.
    #[test]
    fn recognition_figures_without_a_correct_detection_print_no_nan() {
        let none = RecognitionTotals {
            captures: 1,
            top_layer: 4,
            detected: 0,
            ..RecognitionTotals::default()
        }
        .summary();
        assert!(none.precision.is_nan() && none.position_error_mm[0].is_nan());
        assert_eq!(super::percent(none.precision), "-");
        assert_eq!(super::percent(none.recall), "0.0 %");
        let text = super::pose_errors_text(&none);
        assert!(
            !text.contains("NaN") && text.contains("no detection was correct"),
            "{text}"
        );
        let one = RecognitionTotals {
            captures: 1,
            top_layer: 4,
            top_layer_found: 1,
            detected: 2,
            correct: 1,
            position_errors_m: vec![0.0002],
            rotation_errors_rad: vec![0.01],
        }
        .summary();
        assert_eq!(super::percent(one.precision), "50.0 %");
        let text = super::pose_errors_text(&one);
        assert!(
            text.starts_with("median / p95: 0.20 / 0.20 mm, 0.57 / 0.57 deg"),
            "{text}"
        );
    }
}
