//! Record stage, collection: the observer that keeps what the recordings show while a run goes,
//! and the finished [`Recording`] the writers turn into files.
//!
//! Job: watch a cell run ([`crate::cycle::Observer`]) and keep, decimated where a viewer needs
//! no more: every servo tick (joint states are decimated by the writers), every part's state and
//! pose every [`SCENE_FRAME_S`] from the first pile pour on, each capture's depth image and a
//! quarter (and, for the .rrd, a sixteenth) of its point cloud on a [`CLOUD_GRID_M`] grid, each
//! recognition result with its best grasp candidates and, for evaluation, the true poses at its
//! trigger and each detection's error, each motion's tool path as planned and as executed, and
//! the event log. Nothing is kept unless a run is watched by a recorder.
//!
//! Units: s, m, rad, N m; depth images in mm. Frames: world.

use nalgebra::{Isometry3, Vector3};

use crate::cycle::{CycleEvent, Event, EventLog, Observer, PickRecord, Recognised, RunResult};
use crate::geometry::NamedBox;
use crate::physics::{PartState, World};
use crate::robot::{JointVector, RobotModel};
use crate::sensor::{Camera, Capture, RecognitionReport, TruthAtTrigger};
use crate::servo::Tick;
use crate::trajectory::Motion;

/// Period of the part-pose snapshots (s).
pub const SCENE_FRAME_S: f64 = 0.1;
/// Recorded point clouds keep every this many pixels in each image direction (a quarter of the
/// points: 0.4 MB instead of 1 MB per capture). The depth image keeps every pixel.
pub const CLOUD_EVERY_PX: usize = 2;
/// The sparse cloud (the Rerun file's: its viewer draws the depth image itself in 3D at every
/// pixel) keeps every this many pixels in each image direction.
pub const SPARSE_CLOUD_EVERY_PX: usize = 4;
/// Recorded cloud coordinates are rounded to this grid (m): a quarter of the depth image's 1 mm
/// steps, its rounding error (0.07 mm rms) well below the sensor's noise (0.3 mm at 1 m), and it
/// lets the files' compressors find repeats (1.4 instead of 4.6 MB of points in a 20-pick MCAP).
pub const CLOUD_GRID_M: f64 = 2.5e-4;
/// Most grasp candidates a [`RecognitionRecord`] keeps.
pub const RECORDED_CANDIDATES: usize = 20;

/// The ground truth at a capture's trigger, shown when its recognition result arrived: the true
/// poses beside the detections (evaluation only).
#[derive(Debug, Clone)]
pub struct TruthRecord {
    /// When the result arrived (s).
    pub t_s: f64,
    /// When the capture was triggered (s).
    pub trigger_s: f64,
    /// The parts the capture showed: index and `world_from_part` at the trigger.
    pub parts: Vec<(usize, Isometry3<f64>)>,
}

/// Every part's state and pose at one time.
#[derive(Debug, Clone)]
pub struct SceneFrame {
    /// Simulation time (s).
    pub t_s: f64,
    /// Per part, in insertion order: state and `world_from_part`.
    pub parts: Vec<(PartState, Isometry3<f64>)>,
}

/// One motion's tool-tip path: as planned and as executed.
#[derive(Debug, Clone)]
pub struct ToolPath {
    /// Start of the motion (s).
    pub t_s: f64,
    /// Duration as planned (s).
    pub duration_s: f64,
    /// Planned tool-tip positions every 10 ms [m, world].
    pub planned_m: Vec<Vector3<f64>>,
    /// Executed tool-tip positions every 10 ms of servo time [m, world].
    pub executed_m: Vec<Vector3<f64>>,
}

/// A capture's depth image and point cloud.
#[derive(Debug, Clone)]
pub struct CaptureImage {
    /// Trigger time (s).
    pub t_s: f64,
    /// Image width and height (px).
    pub size_px: (usize, usize),
    /// Depth per pixel (mm), 0 where there is no return.
    pub depth_mm: Vec<u16>,
    /// The world points (m) of every [`CLOUD_EVERY_PX`]-th pixel in each direction that has a
    /// return, row-major, on the [`CLOUD_GRID_M`] grid.
    pub points_world_m: Vec<[f32; 3]>,
    /// The same of every [`SPARSE_CLOUD_EVERY_PX`]-th pixel.
    pub sparse_points_world_m: Vec<[f32; 3]>,
}

/// The points of every `every_px`-th pixel of `c` in each direction that has a return, row-major,
/// each coordinate rounded to the [`CLOUD_GRID_M`] grid [m, world].
fn cloud_on_grid(c: &Capture, every_px: usize) -> Vec<[f32; 3]> {
    let per_m = 1.0 / CLOUD_GRID_M;
    let on_grid = |v: f32| ((f64::from(v) * per_m).round() * CLOUD_GRID_M) as f32;
    c.points_world
        .chunks_exact(c.width_px.max(1))
        .step_by(every_px)
        .flat_map(|row| row.iter().step_by(every_px))
        .filter(|p| p[0].is_finite())
        .map(|p| p.map(on_grid))
        .collect()
}

/// A recognition result as the grasp selector saw it.
#[derive(Debug, Clone)]
pub struct RecognitionRecord {
    /// When the result arrived (s).
    pub t_s: f64,
    /// Recognised parts: estimated `world_from_part` and the visible fraction.
    pub detections: Vec<(Isometry3<f64>, f64)>,
    /// Per detection, against the truth at the trigger (evaluation only): its position (m) and
    /// rotation (rad) error from the nearest part, and whether that is within 2 mm and 5 deg.
    pub detection_errors: Vec<Option<(f64, f64, bool)>>,
    /// The best feasible grasps, best first (at most [`RECORDED_CANDIDATES`]): the tool at the
    /// grasp and the score.
    pub candidates: Vec<(Isometry3<f64>, f64)>,
    /// Which candidate was chosen (if among those kept).
    pub chosen: Option<usize>,
}

/// Everything a recording shows of a finished run.
#[derive(Debug, Clone)]
pub struct Recording {
    /// Servo ticks of every motion, in time order (`t` is simulation time).
    pub trace: Vec<Tick>,
    /// Part poses over time.
    pub scene_frames: Vec<SceneFrame>,
    /// The captures.
    pub captures: Vec<CaptureImage>,
    /// Every motion's planned and executed tool path.
    pub tool_paths: Vec<ToolPath>,
    /// Every recognition result with the grasp candidates.
    pub recognitions: Vec<RecognitionRecord>,
    /// The truth at each recognition result's trigger.
    pub truths: Vec<TruthRecord>,
    /// The cycle's events in time order.
    pub events: Vec<CycleEvent>,
    /// The run's picks.
    pub records: Vec<PickRecord>,
    /// The depth camera (pose and intrinsics).
    pub camera: Camera,
    /// The parts' bounding box (m).
    pub part_size_m: [f64; 3],
    /// The cell's fixed boxes (table, trays, obstacles), as the world was built.
    pub cell_boxes: Vec<NamedBox>,
}

/// The observer that collects a [`Recording`].
pub struct Recorder<'a> {
    robot: &'a RobotModel,
    camera: Camera,
    part_size_m: [f64; 3],
    cell_boxes: Vec<NamedBox>,
    trace: Vec<Tick>,
    scene_frames: Vec<SceneFrame>,
    captures: Vec<CaptureImage>,
    tool_paths: Vec<ToolPath>,
    recognitions: Vec<RecognitionRecord>,
    truths: Vec<TruthRecord>,
    /// The last evaluation (its result time and the per-detection matches), for the detections
    /// that follow it.
    last_matches: Option<(f64, Vec<Option<crate::sensor::TruthMatch>>)>,
    events: EventLog,
}

impl<'a> Recorder<'a> {
    /// A recorder for a run of `robot` seen by `camera`, of parts with bounding box `part_size_m`.
    pub fn new(robot: &'a RobotModel, camera: Camera, part_size_m: [f64; 3]) -> Self {
        Recorder {
            robot,
            camera,
            part_size_m,
            cell_boxes: Vec::new(),
            trace: Vec::new(),
            scene_frames: Vec::new(),
            captures: Vec::new(),
            tool_paths: Vec::new(),
            recognitions: Vec::new(),
            truths: Vec::new(),
            last_matches: None,
            events: EventLog::default(),
        }
    }

    /// The recording of the finished run `result`.
    pub fn finish(self, result: &RunResult) -> Recording {
        Recording {
            trace: self.trace,
            scene_frames: self.scene_frames,
            captures: self.captures,
            tool_paths: self.tool_paths,
            recognitions: self.recognitions,
            truths: self.truths,
            events: self.events.into_sorted(),
            records: result.records.clone(),
            camera: self.camera,
            part_size_m: self.part_size_m,
            cell_boxes: self.cell_boxes,
        }
    }
}

impl Observer for Recorder<'_> {
    fn event(&mut self, t_s: f64, pick: Option<usize>, event: &Event) {
        self.events.event(t_s, pick, event);
    }

    /// Every step at least [`SCENE_FRAME_S`] after the last snapshot records every part.
    fn stepped(&mut self, world: &World) {
        if self.cell_boxes.is_empty() {
            self.cell_boxes = world.cell_boxes().to_vec();
        }
        if self
            .scene_frames
            .last()
            .is_some_and(|f| world.time_s() + 1e-9 < f.t_s + SCENE_FRAME_S)
        {
            return;
        }
        self.scene_frames.push(SceneFrame {
            t_s: world.time_s(),
            parts: (0..world.part_count())
                .map(|i| (world.part_state(i), world.part_pose(i)))
                .collect(),
        });
    }

    fn captured(&mut self, c: &Capture) {
        self.captures.push(CaptureImage {
            t_s: c.trigger_s,
            size_px: (c.width_px, c.height_px),
            depth_mm: c.depth_m.iter().map(|d| (d * 1000.0).round() as u16).collect(),
            points_world_m: cloud_on_grid(c, CLOUD_EVERY_PX),
            sparse_points_world_m: cloud_on_grid(c, SPARSE_CLOUD_EVERY_PX),
        });
    }

    fn evaluated(&mut self, t_s: f64, truth: &TruthAtTrigger, report: &RecognitionReport) {
        self.truths.push(TruthRecord {
            t_s,
            trigger_s: truth.t_s,
            parts: (0..truth.free.len())
                .filter(|&i| truth.free[i] && truth.visible_px[i] > 0)
                .map(|i| (i, truth.world_from_part[i]))
                .collect(),
        });
        self.last_matches = Some((t_s, report.matches.clone()));
    }

    fn recognised(&mut self, r: &Recognised<'_>) {
        let ranked = &r.ranked[..r.ranked.len().min(RECORDED_CANDIDATES)];
        let matches = self
            .last_matches
            .as_ref()
            .filter(|(t, m)| *t == r.t_s && m.len() == r.detections.len());
        self.recognitions.push(RecognitionRecord {
            detection_errors: (0..r.detections.len())
                .map(|k| {
                    matches
                        .and_then(|(_, m)| m[k])
                        .map(|m| (m.position_error_m, m.rotation_error_rad, m.correct))
                })
                .collect(),
            t_s: r.t_s,
            detections: r
                .detections
                .iter()
                .map(|d| (d.world_from_part, d.visible_fraction))
                .collect(),
            candidates: ranked.iter().map(|g| (g.world_from_tool, g.score.total)).collect(),
            chosen: r.chosen.filter(|&k| k < ranked.len()),
        });
    }

    fn executed(&mut self, t0_s: f64, planned: &dyn Motion, ticks: &[Tick], played: usize) {
        let tip = |q: &JointVector| self.robot.world_from_tool(q).translation.vector;
        self.tool_paths.push(ToolPath {
            t_s: t0_s,
            duration_s: planned.duration_s(),
            planned_m: planned.sampled(0.01).iter().map(|s| tip(&s.q)).collect(),
            executed_m: ticks.iter().step_by(10).map(|t| tip(&t.q)).collect(),
        });
        self.trace
            .extend(ticks[..played.min(ticks.len())].iter().map(|tk| Tick {
                t_s: t0_s + tk.t_s,
                ..*tk
            }));
    }
}
