//! Record stage, collection: the observer that keeps what the recordings show while a run goes,
//! and hands it on as [`Recording`]s (a whole run's, or a streamed run's parts) the writers turn
//! into files.
//!
//! Job: watch a cell run ([`crate::cycle::Observer`]) and keep, decimated where a viewer needs
//! no more: every servo tick (joint states are decimated by the writers), every part's state and
//! pose every [`SCENE_FRAME_S`] from the first pile pour on, each capture's region of
//! interest over the pick tray (all the sensor measures): its depth image and a sixteenth of its point
//! cloud on a [`CLOUD_GRID_M`] grid, each
//! recognition result with its best grasp candidates and, for evaluation, the true poses at its
//! trigger and each detection's error, each motion's tool path as planned and as executed, and
//! the event log, and the takt of every placed pick. Nothing is kept unless a run is watched by a
//! recorder.
//!
//! Streaming: a recorder with files ([`Recorder::streaming`]) hands everything older than
//! [`STREAM_LAG_S`] of simulation time to a writer thread every [`STREAM_EVERY_S`], so its memory
//! stays flat however long the run is. The lag lets what is reported late (a motion's ticks after
//! it played, a takt after its release) join its time range first: every part handed on holds
//! one time range, and the files get their messages in time order.
//!
//! Units: s, m, rad, N m; depth images in mm. Frames: world.

use nalgebra::{Isometry3, Vector3};

use std::path::PathBuf;
use std::sync::mpsc;

use crate::cycle::{CycleEvent, Event, EventLog, Observer, Recognised, Takt};
use crate::geometry::{NamedBox, TrayVolume};
use crate::physics::{PartState, World};
use crate::robot::{JointVector, RobotModel};
use crate::sensor::capture::capture_window;
use crate::sensor::{Camera, Capture, PixelWindow, RecognitionReport, TruthAtTrigger};
use crate::servo::Tick;
use crate::trajectory::Motion;

/// Period of the part-pose snapshots (s).
pub const SCENE_FRAME_S: f64 = 0.1;
/// Recorded point clouds keep every this many pixels in each image direction: a sixteenth of the
/// points (1.8 mm apart at the tray), enough to see the pile in 3D; the depth image beside it
/// keeps every pixel, and Rerun's viewer draws that in 3D too. Every fourth rather than every
/// second pixel took the recording's extra CPU from +31 % to about +18 % of the run's.
pub const CLOUD_EVERY_PX: usize = 4;
/// Recorded cloud coordinates are rounded to this grid (m): a quarter of the depth image's 1 mm
/// steps, its rounding error (0.07 mm rms) well below the sensor's noise (0.3 mm at 1 m), and it
/// lets the files' compressors find repeats (1.4 instead of 4.6 MB of points in a 20-pick MCAP).
pub const CLOUD_GRID_M: f64 = 2.5e-4;
/// Most grasp candidates a [`RecognitionRecord`] keeps.
pub const RECORDED_CANDIDATES: usize = 20;
/// A streaming recorder keeps this much simulation time behind the newest step before it hands
/// data on (s). What is reported after its time is at most a motion (its ticks arrive when it has
/// played, about 1 s) or a pick (its takt arrives when the pick ends, a few seconds after the
/// release) late: a wide margin. Data that still comes later is written out of time order and
/// counted ([`Recorder::late`]).
pub const STREAM_LAG_S: f64 = 20.0;
/// A streaming recorder hands data on every this much simulation time (s): about four picks'
/// worth, up to 10 s of captures in memory beside the lag's.
pub const STREAM_EVERY_S: f64 = 10.0;

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
    /// The run's motion number (from 0).
    pub motion: usize,
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
    /// return, row-major, on the [`CLOUD_GRID_M`] grid (none for a confirming exposure).
    pub points_world_m: Vec<[f32; 3]>,
    /// A confirming exposure (the cycle's motion check, not the image recognition read): the
    /// recordings show it apart.
    pub confirming: bool,
}

impl CaptureImage {
    /// The depth image as the files carry it: 16-bit little-endian mm per pixel, row-major.
    pub fn depth_le_bytes(&self) -> Vec<u8> {
        let mut out = vec![0; 2 * self.depth_mm.len()];
        for (b, d) in out.chunks_exact_mut(2).zip(&self.depth_mm) {
            b.copy_from_slice(&d.to_le_bytes());
        }
        out
    }

    /// The point cloud as packed little-endian f32 x, y, z (12 bytes a point).
    pub fn points_le_bytes(&self) -> Vec<u8> {
        let mut out = vec![0; 12 * self.points_world_m.len()];
        for (b, p) in out.chunks_exact_mut(4).zip(self.points_world_m.iter().flatten()) {
            b.copy_from_slice(&p.to_le_bytes());
        }
        out
    }
}

/// The points of every `every_px`-th pixel in each direction of `c`'s organised cloud (its tray
/// window `w`) that have a return, row-major, each coordinate rounded to the [`CLOUD_GRID_M`] grid
/// [m, world].
fn cloud_on_grid(c: &Capture, w: &PixelWindow, every_px: usize) -> Vec<[f32; 3]> {
    let per_m = 1.0 / CLOUD_GRID_M;
    let on_grid = |v: f32| ((f64::from(v) * per_m).round() * CLOUD_GRID_M) as f32;
    c.points_world
        .chunks_exact(w.width_px.max(1))
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

/// Everything a recording shows of a run, or of one time range of it (a streamed part).
#[derive(Debug, Clone)]
pub struct Recording {
    /// Whether this opens the recording (a whole run's recording does): the writers add what is
    /// written once (the cell, the arm's geometry, the robot description, the properties).
    pub opening: bool,
    /// The arm's joint positions at time 0 (rad), in the opening part.
    pub start_q: Option<JointVector>,
    /// The run's index of `trace[0]` among all its servo ticks: the writers decimate on the run's
    /// tick grid, not the part's.
    pub trace_start: usize,
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
    /// The takt of every placed pick (that has one), in pick order.
    pub takts: Vec<Takt>,
    /// The depth camera (pose and intrinsics).
    pub camera: Camera,
    /// The parts' bounding box (m).
    pub part_size_m: [f64; 3],
    /// The cell's fixed boxes (table, trays, obstacles), as the world was built.
    pub cell_boxes: Vec<NamedBox>,
}

impl Recording {
    /// An empty recording of parts with bounding box `part_size_m` seen by `camera`.
    fn empty(camera: Camera, part_size_m: [f64; 3]) -> Self {
        Recording {
            opening: true,
            start_q: None,
            trace_start: 0,
            trace: Vec::new(),
            scene_frames: Vec::new(),
            captures: Vec::new(),
            tool_paths: Vec::new(),
            recognitions: Vec::new(),
            truths: Vec::new(),
            events: Vec::new(),
            takts: Vec::new(),
            camera,
            part_size_m,
            cell_boxes: Vec::new(),
        }
    }

    /// Takes out what happened at or before `until_s` (s), as a part that follows the ones taken
    /// before; the rest stays. `events` is the event log the recorder keeps beside.
    fn take_until(&mut self, until_s: f64, events: &mut EventLog) -> Recording {
        fn split<T>(v: &mut Vec<T>, until_s: f64, time_s: impl Fn(&T) -> f64) -> Vec<T> {
            let (taken, kept) = std::mem::take(v).into_iter().partition(|x| time_s(x) <= until_s);
            *v = kept;
            taken
        }
        let trace = split(&mut self.trace, until_s, |t| t.t_s);
        let part = Recording {
            opening: self.opening,
            start_q: self.start_q.take(),
            trace_start: self.trace_start,
            scene_frames: split(&mut self.scene_frames, until_s, |f| f.t_s),
            captures: split(&mut self.captures, until_s, |c| c.t_s),
            tool_paths: split(&mut self.tool_paths, until_s, |p| p.t_s),
            recognitions: split(&mut self.recognitions, until_s, |r| r.t_s),
            truths: split(&mut self.truths, until_s, |t| t.t_s),
            events: events.take_until(until_s),
            takts: split(&mut self.takts, until_s, |t| t.release_s),
            camera: self.camera.clone(),
            part_size_m: self.part_size_m,
            cell_boxes: self.cell_boxes.clone(),
            trace,
        };
        self.opening = false;
        self.trace_start += part.trace.len();
        part
    }
}

/// What the recorder hands to its writer thread.
enum Handover {
    /// The next time range.
    Part(Box<Recording>),
    /// The run is over: finish the files.
    Finish,
}

/// The writer thread of a streaming recorder and the way to it.
struct Stream {
    to_writer: mpsc::SyncSender<Handover>,
    writer: std::thread::JoinHandle<Result<Vec<PathBuf>, (PathBuf, super::RecordError)>>,
}

/// The observer that collects a [`Recording`], whole or (with files) streamed.
pub struct Recorder<'a> {
    robot: &'a RobotModel,
    /// What is not handed on yet.
    buffer: Recording,
    /// The events not handed on yet.
    events: EventLog,
    /// Simulation time of the newest step (s).
    now_s: f64,
    /// Everything at or before this time is handed on (s).
    handed_until_s: Option<f64>,
    /// Items reported for a time already handed on.
    late: usize,
    /// Parts handed on.
    handed_on: usize,
    /// Motions executed.
    motions: usize,
    /// When the last part-pose snapshot was taken (s).
    last_frame_s: Option<f64>,
    /// The part of each capture that is recorded: the sensor's region of interest over the pick
    /// tray ([`Capture::tray_window`]; nothing outside it is measured).
    window: PixelWindow,
    stream: Option<Stream>,
}

impl<'a> Recorder<'a> {
    /// A recorder for a run of `robot` seen by `camera` over `pick_tray`, of parts with bounding
    /// box `part_size_m`, that keeps the whole run in memory ([`Recorder::finish`]). It records
    /// the pick tray's window of each capture ([`capture_window`]), as the
    /// camera [`Camera::cropped`] to it.
    pub fn new(robot: &'a RobotModel, camera: &Camera, pick_tray: &TrayVolume, part_size_m: [f64; 3]) -> Self {
        let window = capture_window(camera, pick_tray, &part_size_m);
        Recorder {
            robot,
            window,
            buffer: Recording::empty(camera.cropped(&window), part_size_m),
            events: EventLog::default(),
            now_s: 0.0,
            handed_until_s: None,
            late: 0,
            handed_on: 0,
            motions: 0,
            last_frame_s: None,
            stream: None,
        }
    }

    /// A recorder that streams to `files` as the run goes ([`Recorder::finish_files`]): its
    /// memory holds at most [`STREAM_LAG_S`] + [`STREAM_EVERY_S`] of simulation time.
    pub fn streaming(
        robot: &'a RobotModel,
        camera: &Camera,
        pick_tray: &TrayVolume,
        part_size_m: [f64; 3],
        files: super::RecordingFiles,
    ) -> Self {
        // Two parts in flight at most: a slow disk holds the run back instead of filling memory.
        let (to_writer, from_recorder) = mpsc::sync_channel::<Handover>(1);
        let writer_robot = robot.clone();
        let writer = std::thread::spawn(move || {
            let mut files = files;
            for handover in from_recorder {
                match handover {
                    Handover::Part(part) => files.write(&part, &writer_robot),
                    Handover::Finish => return files.finish(),
                }
            }
            // The recorder went away without finishing (the run failed): dropping `files` removes
            // what it began.
            drop(files);
            Err((PathBuf::from("recording"), super::RecordError::Unfinished))
        });
        let mut recorder = Recorder::new(robot, camera, pick_tray, part_size_m);
        recorder.stream = Some(Stream { to_writer, writer });
        recorder
    }

    /// How many items were reported for a time already handed on (written out of time order).
    pub fn late(&self) -> usize {
        self.late
    }

    /// How many parts were handed on to the files so far.
    pub fn handed_on(&self) -> usize {
        self.handed_on
    }

    /// The recording of the finished run (of a recorder made by [`Recorder::new`]: a streaming
    /// recorder's [`Recorder::finish_files`] returns what it handed on).
    pub fn finish(mut self) -> Recording {
        let mut events = std::mem::take(&mut self.events);
        self.buffer.take_until(f64::INFINITY, &mut events)
    }

    /// Hands the rest on and finishes the files: the paths written, or the first file that
    /// failed and why. A recorder made by [`Recorder::new`] has no files and writes nothing.
    pub fn finish_files(mut self) -> Result<Vec<PathBuf>, (PathBuf, super::RecordError)> {
        self.hand_on(f64::INFINITY);
        let Some(stream) = self.stream.take() else {
            return Ok(Vec::new());
        };
        // A send fails only if the writer is gone: its result says why.
        let _ = stream.to_writer.send(Handover::Finish);
        drop(stream.to_writer);
        stream.writer.join().unwrap_or_else(|_| {
            Err((
                PathBuf::from("recording"),
                super::RecordError::Rerun("the writer thread panicked".into()),
            ))
        })
    }

    /// Hands everything at or before `until_s` to the writer (streaming only).
    fn hand_on(&mut self, until_s: f64) {
        let Some(stream) = &self.stream else { return };
        let part = self.buffer.take_until(until_s, &mut self.events);
        self.handed_until_s = Some(until_s);
        self.handed_on += 1;
        // A failed send means the writer stopped on an error: its join reports it.
        let _ = stream.to_writer.send(Handover::Part(Box::new(part)));
    }

    /// Counts an item reported for time `t_s` if that time is handed on already.
    fn arrived(&mut self, t_s: f64) {
        if self.handed_until_s.is_some_and(|h| t_s <= h) {
            self.late += 1;
        }
    }

    /// Keeps a capture's image at its trigger time, with its point cloud unless it is a
    /// confirming exposure.
    fn keep_capture(&mut self, c: &Capture, confirming: bool) {
        self.arrived(c.trigger_s);
        let w = &self.window;
        debug_assert_eq!(*w, c.tray_window);
        self.buffer.captures.push(CaptureImage {
            t_s: c.trigger_s,
            size_px: (w.width_px, w.height_px),
            // Depths are non-negative: adding a half and truncating rounds as `round` does, without
            // its library call per pixel.
            depth_mm: c.depth_m.iter().map(|d| (d * 1000.0 + 0.5) as u16).collect(),
            points_world_m: if confirming {
                Vec::new()
            } else {
                cloud_on_grid(c, w, CLOUD_EVERY_PX)
            },
            confirming,
        });
    }
}

impl Drop for Recorder<'_> {
    /// A streaming recorder dropped unfinished (the run failed) waits for its writer to remove
    /// the files it began.
    fn drop(&mut self) {
        if let Some(stream) = self.stream.take() {
            drop(stream.to_writer);
            let _ = stream.writer.join();
        }
    }
}

impl Observer for Recorder<'_> {
    fn event(&mut self, t_s: f64, pick: Option<usize>, event: &Event) {
        self.arrived(t_s);
        self.events.event(t_s, pick, event);
    }

    /// Every step at least [`SCENE_FRAME_S`] after the last snapshot records every part; a
    /// streaming recorder hands on what is [`STREAM_LAG_S`] old every [`STREAM_EVERY_S`].
    fn stepped(&mut self, world: &World) {
        if self.buffer.opening && self.buffer.cell_boxes.is_empty() {
            self.buffer.cell_boxes = world.cell_boxes().to_vec();
            self.buffer.start_q = Some(world.joints());
        }
        self.now_s = self.now_s.max(world.time_s());
        let handed_s = self.handed_until_s.unwrap_or(0.0);
        if self.stream.is_some() && self.now_s - STREAM_LAG_S >= handed_s + STREAM_EVERY_S {
            self.hand_on(self.now_s - STREAM_LAG_S);
        }
        if self
            .last_frame_s
            .is_some_and(|t| world.time_s() + 1e-9 < t + SCENE_FRAME_S)
        {
            return;
        }
        self.last_frame_s = Some(world.time_s());
        self.buffer.scene_frames.push(SceneFrame {
            t_s: world.time_s(),
            parts: (0..world.part_count())
                .map(|i| (world.part_state(i), world.part_pose(i)))
                .collect(),
        });
    }

    fn captured(&mut self, c: &Capture) {
        self.keep_capture(c, false);
    }

    fn confirming_captured(&mut self, c: &Capture) {
        self.keep_capture(c, true);
    }

    fn evaluated(&mut self, t_s: f64, truth: &TruthAtTrigger, _report: &RecognitionReport) {
        self.arrived(t_s);
        self.buffer.truths.push(TruthRecord {
            t_s,
            trigger_s: truth.t_s,
            parts: (0..truth.free.len())
                .filter(|&i| truth.free[i] && truth.visible_px[i] > 0)
                .map(|i| (i, truth.world_from_part[i]))
                .collect(),
        });
    }

    fn recognised(&mut self, r: &Recognised<'_>) {
        self.arrived(r.t_s);
        let ranked = &r.ranked[..r.ranked.len().min(RECORDED_CANDIDATES)];
        let matches = r.judged.filter(|m| m.len() == r.detections.len());
        self.buffer.recognitions.push(RecognitionRecord {
            detection_errors: (0..r.detections.len())
                .map(|k| {
                    matches
                        .and_then(|m| m[k])
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
        self.arrived(t0_s);
        let tip = |q: &JointVector| self.robot.world_from_tool(q).translation.vector;
        self.buffer.tool_paths.push(ToolPath {
            motion: self.motions,
            t_s: t0_s,
            duration_s: planned.duration_s(),
            planned_m: planned.sampled(0.01).iter().map(|s| tip(&s.q)).collect(),
            executed_m: ticks.iter().step_by(10).map(|t| tip(&t.q)).collect(),
        });
        self.motions += 1;
        self.buffer
            .trace
            .extend(ticks[..played.min(ticks.len())].iter().map(|tk| Tick {
                t_s: t0_s + tk.t_s,
                ..*tk
            }));
    }

    fn takt(&mut self, takt: &Takt) {
        self.arrived(takt.release_s);
        self.buffer.takts.push(*takt);
    }
}
