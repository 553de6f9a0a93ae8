//! Record stage: a run written to files a user opens days later, offline, to see why a pick was
//! slow or failed.
//!
//! Job: from [`Recording`]s (what a [`Recorder`] kept while it watched a run: the whole run, or
//! the parts a streaming recorder hands on as the run goes, so that an all-day run's recording
//! needs no more memory than a minute's), write
//! - `run.rrd` for the Rerun viewer ([`rrd`]), and
//! - `run.mcap` for Foxglove ([`mcap`]),
//!
//! with the same content: the cell (table, trays, obstacles, the sensor's frustum), the arm (its
//! collision primitives once, its link frames over time), all parts as one batched entity (bounding
//! boxes coloured by state: in the pick tray, held, placed) from the first pile pour on, each
//! capture's window over the pick tray (the camera's pose, its intrinsics cropped to the window,
//! the window's depth image, a sixteenth of its point cloud on a 0.25 mm grid) at its trigger
//! time, each
//! recognition result (detections, ranked grasp candidates with the chosen one marked) when it
//! arrived, every motion's tool path as planned and as executed, the joint positions, velocities
//! and torques beside each joint's torque limit, the cycle's events as log entries and the takt of
//! every placed pick.
//!
//! Time: simulation time only (no wall clock): Rerun timelines `sim_time` (s) and `step` (physics
//! steps since the start), MCAP log time in ns of simulation time. Decimation: joint states
//! 100 Hz, link frames 50 Hz, parts 10 Hz (the servo runs at 1 kHz); captures at their own times.
//!
//! Units: s, rad, rad/s, N m, m (depth images in mm). Frames: `world` (the cell's frame, z up);
//! the camera's optical frame (x right, y down, z forward); one frame per link, named after it.

pub mod collect;
pub mod mcap;
pub mod rrd;

use std::path::{Path, PathBuf};

use crate::config::Scene;
use crate::cycle::CycleEvent;
use crate::physics::PartState;
use crate::robot::RobotModel;

pub use self::collect::{
    CLOUD_EVERY_PX, CLOUD_GRID_M, CaptureImage, RECORDED_CANDIDATES, RecognitionRecord, Recorder, Recording,
    SCENE_FRAME_S, STREAM_EVERY_S, STREAM_LAG_S, SceneFrame, ToolPath,
};
pub use self::mcap::McapFile;
pub use self::rrd::RrdFile;

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The MCAP writer failed.
    #[error("mcap: {0}")]
    Mcap(#[from] ::mcap::McapError),
    /// A message could not be serialised as JSON.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    /// A message could not be encoded as protobuf, or its schema is missing.
    #[error("protobuf: {0}")]
    Encode(String),
    /// The Rerun SDK refused a stream, a log call or a flush.
    #[error("rerun: {0}")]
    Rerun(String),
    /// Writing the file failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The run ended before the recording was finished (its files were removed).
    #[error("the run ended before its recording was finished")]
    Unfinished,
}

/// What the recording's metadata (MCAP) and recording properties (Rerun) say about the run.
#[derive(Debug, Clone)]
pub struct RunInfo {
    /// Scene label (file or `embedded default`).
    pub scene: String,
    /// Workpiece name.
    pub workpiece: String,
    /// Seed.
    pub seed: u64,
    /// Deterministic compute budgets.
    pub deterministic: bool,
    /// Picks asked for.
    pub picks: usize,
    /// The URDF text the arm was built from (the MCAP's `/robot_description`).
    pub robot_description: String,
}

impl RunInfo {
    /// The properties as (key, value) text pairs, in a fixed order.
    pub fn properties(&self) -> Vec<(&'static str, String)> {
        vec![
            ("scene", self.scene.clone()),
            ("workpiece", self.workpiece.clone()),
            ("seed", self.seed.to_string()),
            ("deterministic", self.deterministic.to_string()),
            ("picks", self.picks.to_string()),
            ("binpick_version", env!("CARGO_PKG_VERSION").to_string()),
        ]
    }
}

/// Which files to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Formats {
    /// `<stem>.rrd` (Rerun).
    pub rrd: bool,
    /// `<stem>.mcap` (Foxglove).
    pub mcap: bool,
}

impl Formats {
    /// Whether anything is recorded (and so the run must keep its trace and scene).
    pub fn any(&self) -> bool {
        self.rrd || self.mcap
    }
}

/// The asked-for recording files of one run, `<dir>/<stem>.rrd` and `<dir>/<stem>.mcap`, being
/// written part by part. After a failed write the files are removed and later parts ignored;
/// [`RecordingFiles::finish`] reports the first failure. Dropped unfinished, nothing stays.
pub struct RecordingFiles {
    rrd: Option<(PathBuf, RrdFile)>,
    mcap: Option<(PathBuf, McapFile)>,
    failed: Option<(PathBuf, RecordError)>,
}

impl RecordingFiles {
    /// Starts the files of a run in `scene` described by `info`; or names the file that could
    /// not be started and why.
    pub fn create(
        dir: &Path,
        stem: &str,
        formats: Formats,
        scene: &Scene,
        info: &RunInfo,
    ) -> Result<Self, (PathBuf, RecordError)> {
        let rrd_path = dir.join(format!("{stem}.rrd"));
        let mcap_path = dir.join(format!("{stem}.mcap"));
        let rrd = match formats.rrd {
            true => Some((
                rrd_path.clone(),
                RrdFile::create(&rrd_path, scene, info).map_err(|e| (rrd_path, e))?,
            )),
            false => None,
        };
        let mcap = match formats.mcap {
            true => Some((
                mcap_path.clone(),
                McapFile::create(&mcap_path, scene, info).map_err(|e| (mcap_path, e))?,
            )),
            false => None,
        };
        Ok(RecordingFiles {
            rrd,
            mcap,
            failed: None,
        })
    }

    /// Writes the next part of the recording to both files, on two threads.
    pub fn write(&mut self, part: &Recording, robot: &RobotModel) {
        if self.failed.is_some() {
            return;
        }
        let (rrd, mcap) = (&mut self.rrd, &mut self.mcap);
        let failed = std::thread::scope(|s| {
            let rrd = rrd
                .as_mut()
                .map(|(path, f)| (path.clone(), s.spawn(|| f.write(part, robot))));
            let mcap = mcap
                .as_mut()
                .and_then(|(path, f)| f.write(part, robot).err().map(|e| (path.clone(), e)));
            let rrd = rrd.and_then(|(path, h)| {
                h.join()
                    .unwrap_or_else(|_| Err(RecordError::Rerun("the writer thread panicked".into())))
                    .err()
                    .map(|e| (path, e))
            });
            rrd.or(mcap)
        });
        if failed.is_some() {
            // Dropping the writers removes their partial files.
            self.failed = failed;
            self.rrd = None;
            self.mcap = None;
        }
    }

    /// Finishes both files: the paths written, or the first file that failed and why.
    pub fn finish(mut self) -> Result<Vec<PathBuf>, (PathBuf, RecordError)> {
        if let Some(failed) = self.failed.take() {
            return Err(failed);
        }
        let mut written = Vec::new();
        if let Some((path, f)) = self.rrd.take() {
            f.finish().map_err(|e| (path.clone(), e))?;
            written.push(path);
        }
        if let Some((path, f)) = self.mcap.take() {
            f.finish().map_err(|e| (path.clone(), e))?;
            written.push(path);
        }
        Ok(written)
    }
}

/// Writes the asked-for recordings of the whole run `result` as `<dir>/<stem>.rrd` and
/// `<dir>/<stem>.mcap`. Returns the paths written, or the first file that failed and why.
pub fn write_recordings(
    dir: &Path,
    stem: &str,
    formats: Formats,
    result: &Recording,
    robot: &RobotModel,
    scene: &Scene,
    info: &RunInfo,
) -> Result<Vec<PathBuf>, (PathBuf, RecordError)> {
    let mut files = RecordingFiles::create(dir, stem, formats, scene, info)?;
    files.write(result, robot);
    files.finish()
}

/// Joint states and series are recorded every this many servo ticks (1 kHz servo: 100 Hz).
pub(crate) const JOINT_STATE_EVERY: usize = 10;
/// Link frames are recorded every this many servo ticks (50 Hz).
pub(crate) const TRANSFORMS_EVERY: usize = 20;

/// The ticks of `result`'s trace on the run's grid of every `every`-th servo tick.
fn every_nth_tick(result: &Recording, every: usize) -> impl Iterator<Item = &crate::servo::Tick> {
    let skip = (every - result.trace_start % every) % every;
    result.trace.iter().skip(skip).step_by(every)
}

/// The servo ticks whose joint states are recorded: every [`JOINT_STATE_EVERY`]-th of the run.
pub(crate) fn joint_state_ticks(result: &Recording) -> impl Iterator<Item = &crate::servo::Tick> {
    every_nth_tick(result, JOINT_STATE_EVERY)
}

/// The arm's joint positions at which its link frames are recorded: from time 0 (the arm at its
/// start pose while the first pile is poured: the trace begins with the first motion), then
/// every [`TRANSFORMS_EVERY`] servo ticks of the run. Between motions the arm stands still, so
/// the last frames hold. (simulation time (s), joint positions (rad))
pub(crate) fn arm_samples(result: &Recording) -> Vec<(f64, crate::robot::JointVector)> {
    let start = result
        .start_q
        .filter(|_| result.trace.first().is_none_or(|t| t.t_s > 0.0))
        .map(|q| (0.0, q));
    start
        .into_iter()
        .chain(every_nth_tick(result, TRANSFORMS_EVERY).map(|t| (t.t_s, t.q)))
        .collect()
}

/// The name of the arm's link `i` (its frame in both files; `link_<i>` if the model has none).
pub(crate) fn link_name(robot: &RobotModel, i: usize) -> String {
    robot
        .links
        .get(i)
        .map_or_else(|| format!("link_{i}"), |l| l.name.clone())
}

/// Colour of a part in a state (RGB, 0..1): blue in the pick tray, orange on the cup, green placed.
pub(crate) fn part_rgb(state: PartState) -> [f32; 3] {
    match state {
        PartState::Held => [1.0, 0.6, 0.0],
        PartState::Placed => [0.2, 0.7, 0.3],
        _ => [0.3, 0.5, 0.9],
    }
}

/// Severity of a cycle event: 2 info, 3 warning (faults, lost parts, picks that were not placed).
pub(crate) fn event_level(e: &CycleEvent) -> u8 {
    if e.warning { 3 } else { 2 }
}

/// A cycle event as one log line.
pub(crate) fn event_text(e: &CycleEvent) -> String {
    let pick = e.pick.map_or("cell".to_string(), |p| format!("pick {p}"));
    if e.detail.is_empty() {
        format!("[{pick}] {}", e.kind)
    } else {
        format!("[{pick}] {}: {}", e.kind, e.detail)
    }
}

/// The tip of a grasp-candidate arrow: this far above the grasp point, pointing down to it (m).
pub(crate) const CANDIDATE_ARROW_M: f64 = 0.03;

/// The camera frustum's corner rays out to `range_m`, in the world frame: apex, then the four
/// far corners (top-left, top-right, bottom-right, bottom-left in the image) (m).
pub(crate) fn frustum_corners(c: &crate::sensor::Camera, range_m: f64) -> [nalgebra::Vector3<f64>; 5] {
    let apex = c.world_from_camera.translation.vector;
    let corner = |u: f64, v: f64| {
        let d = nalgebra::Vector3::new((u - c.cx_px) / c.fx_px, (v - c.cy_px) / c.fy_px, 1.0);
        apex + c.world_from_camera.rotation * (d * range_m)
    };
    let (w, h) = (c.width_px as f64, c.height_px as f64);
    [apex, corner(0.0, 0.0), corner(w, 0.0), corner(w, h), corner(0.0, h)]
}
