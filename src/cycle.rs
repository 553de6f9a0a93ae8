//! The cell cycle: capture, recognise, select a grasp, plan and accelerate, Pick, Place, repeat.
//!
//! Job: run picks of one workpiece end to end in the simulated cell and time them, following the
//! reference system's time chart (its Fig. 3). The arm is driven by the torque-limited servo
//! ([`crate::execution`]) whose joint states move the arm's bodies in the physics world every
//! physics step, so the arm pushes parts and hides them from the sensor.
//!
//! One pick:
//! 1. The capture is triggered at the first physics step of the previous Place at which the arm
//!    has left the camera's view frustum (or, at the start and after a failure, as soon as the arm
//!    is out of view). The recognition result arrives `latency_s` after the trigger. A capture
//!    spoiled by motion in the scene is repeated when the sensor's exposure is over.
//! 2. From the result: grasp selection, then the Pick motion (transfer to the approach pose,
//!    straight descent, straight lift) is planned and accelerated; the Place motion (transfer to
//!    above the slot, straight descent, straight retreat) is planned next, while the Pick runs.
//!    Compute is charged to the simulation clock: fixed budgets from the cell file with
//!    `deterministic`, the measured wall time of our own code otherwise.
//! 3. Pick: transfer, descent, vacuum on and build-up, lift. Place: transfer, descent, release,
//!    retreat. The arm waits only when the next motion is not ready: a stall, split into waiting
//!    for the sensor (the recognition result) and waiting for compute.
//! 4. Faults: a protective stop of the servo, a collision of the arm (or the held part) with the
//!    cell or a part pressed into the tray (the physics world's health monitor), a part slipping
//!    off the cup. Each ends the pick with its outcome; after a stop or a collision the arm waits
//!    the reset time and retraces its path out. Parts pushed out of a tray are taken out of the
//!    cell and counted as lost.
//! 5. Nothing detected or nothing graspable: re-capture; after `empty_after_captures` in a row the
//!    cell file's policy exchanges the pick tray for a full one (`refill_s`) or ends the run. A
//!    full place tray is exchanged for an empty one (`place_tray_exchange_s`).
//!
//! Held parts: the transfer, lift and descent motions with a part on the cup are slowed (a
//! uniform time scaling) where the tool's acceleration would need more than 75 % of the cup's
//! holding force (the gripper's slip model, with the centre-of-mass offset of the grasp as
//! recognised plus three standard deviations of the recognition's position noise).
//!
//! Takt of a pick = time between consecutive successful releases. The first pick of each pile
//! (the start, and after a refill) follows the initial sensing and is left out of the takt
//! statistics, as the reference system leaves out its first cycle. Units: s, m, rad.

use std::time::Instant;

use nalgebra::{Isometry3, Translation3, Vector3};
use serde::Serialize;

use crate::chart::{Lane, Marker, Span};
use crate::config::{LoadedScene, LoadedWorkpiece, OnEmpty, Scene};
use crate::execution::{Servo, Tick, execute_from};
use crate::grasp::{GraspCandidate, GraspSelector};
use crate::physics::pile::PileOptions;
use crate::physics::suction::GripperEvent;
use crate::physics::{HealthError, PartShape, PartState, World};
use crate::planning::{CollisionModel, Environment, PileColumns, PlanOptions, RobotSpheres};
use crate::robot::{DOF, JointVector, Payload, RobotModel};
use crate::sensor::{CaptureJob, Detection, HeightMap, Sensor};
use crate::trajectory::{
    LineLimits, LineMotion, Motion, Trajectory, accelerate_in_corridor, limit_tool_force, straight_line,
};

/// Fraction of the cup's holding force a held-part motion may use.
pub const SUCTION_MARGIN: f64 = 0.75;
/// The part is released this far above its resting height in the slot [m] (the recognised pose
/// is a little off; the part drops the rest).
const RELEASE_ABOVE_M: f64 = 0.003;
/// A grasp within this distance of a spot where one failed in the same pile is not tried [m].
const FAILED_SPOT_RADIUS_M: f64 = 0.004;
/// The Place transfer ends this far above the release pose [m].
const PLACE_APPROACH_M: f64 = 0.03;

/// Why a run stopped early.
#[derive(Debug, thiserror::Error)]
pub enum CycleError {
    /// The workpiece's shape could not be built.
    #[error(transparent)]
    Shape(#[from] crate::physics::ShapeError),
    /// The physics world failed beyond recovery (a non-finite state).
    #[error("physics: {0}")]
    Health(#[from] HealthError),
    /// Something the cycle needs is missing (sensor pose, place slots).
    #[error("{0}")]
    Setup(String),
}

/// What happened to one pick.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Outcome {
    /// The part was released in its slot.
    Placed,
    /// The cup did not seal (reason).
    GraspFailed(String),
    /// The recognition result held no part: re-capture.
    NothingDetected,
    /// Parts were detected but none was graspable (the selector's reasons).
    NothingGraspable(String),
    /// No path or trajectory for a motion (reason).
    NoMotion(String),
    /// The servo tripped a protective stop (reason).
    ProtectiveStop(String),
    /// The arm, the tool or the held part collided, or pressed a part into the tray (what).
    Collision(String),
    /// The part came off the cup on the way (reason).
    Dropped(String),
}

impl Outcome {
    /// Whether the arm set out to pick (the success rate counts these).
    pub fn is_attempt(&self) -> bool {
        !matches!(self, Outcome::NothingDetected | Outcome::NothingGraspable(_))
    }

    /// A short name: `placed`, `grasp_failed`, ...
    pub fn name(&self) -> &'static str {
        match self {
            Outcome::Placed => "placed",
            Outcome::GraspFailed(_) => "grasp_failed",
            Outcome::NothingDetected => "nothing_detected",
            Outcome::NothingGraspable(_) => "nothing_graspable",
            Outcome::NoMotion(_) => "no_motion",
            Outcome::ProtectiveStop(_) => "protective_stop",
            Outcome::Collision(_) => "collision",
            Outcome::Dropped(_) => "dropped",
        }
    }

    /// The reason, if the outcome has one.
    pub fn detail(&self) -> &str {
        match self {
            Outcome::GraspFailed(s)
            | Outcome::NothingGraspable(s)
            | Outcome::NoMotion(s)
            | Outcome::ProtectiveStop(s)
            | Outcome::Collision(s)
            | Outcome::Dropped(s) => s,
            Outcome::Placed | Outcome::NothingDetected => "",
        }
    }
}

/// One pick (or one capture that found nothing to pick).
#[derive(Debug, Clone, Serialize)]
pub struct PickRecord {
    /// Index.
    pub index: usize,
    /// Outcome.
    pub outcome: Outcome,
    /// When the capture this pick used was triggered [s].
    pub capture_s: f64,
    /// When its recognition result arrived [s].
    pub ready_s: f64,
    /// When the part was released [s] (placed picks).
    pub release_s: Option<f64>,
    /// Time since the previous successful release [s].
    pub takt_s: Option<f64>,
    /// The first pick of a pile (start or refill): left out of the takt statistics.
    pub first_of_pile: bool,
    /// Pick: transfer, descent, vacuum build-up and lift [s].
    pub pick_s: f64,
    /// Place: transfer, descent, release and retreat [s].
    pub place_s: f64,
    /// The arm waited for the recognition result [s].
    pub stall_sensor_s: f64,
    /// The arm waited for grasp selection or motion generation [s].
    pub stall_compute_s: f64,
    /// Grasp selection, charged [s].
    pub grasp_compute_s: f64,
    /// Pick motion generation (planning, acceleration, the straight lines), charged [s].
    pub pick_compute_s: f64,
    /// Place motion generation, charged [s].
    pub place_compute_s: f64,
    /// Horizontal placement error [mm] (placed picks).
    pub placement_error_mm: Option<f64>,
    /// Yaw placement error [deg], modulo the part's symmetry (placed picks).
    pub yaw_error_deg: Option<f64>,
    /// Largest servo tracking error over the pick's motions [deg].
    pub max_tracking_error_deg: f64,
    /// Largest |applied torque| / torque limit over the pick's motions.
    pub peak_torque_ratio: f64,
    /// Time scaling of the held-part Place transfer for the cup's holding force (1: none).
    pub suction_speed_factor: f64,
}

impl PickRecord {
    fn new(index: usize, job: &CaptureJob, capture_s: f64) -> Self {
        PickRecord {
            index,
            outcome: Outcome::Placed,
            capture_s,
            ready_s: job.ready_s,
            release_s: None,
            takt_s: None,
            first_of_pile: false,
            pick_s: 0.0,
            place_s: 0.0,
            stall_sensor_s: 0.0,
            stall_compute_s: 0.0,
            grasp_compute_s: 0.0,
            pick_compute_s: 0.0,
            place_compute_s: 0.0,
            placement_error_mm: None,
            yaw_error_deg: None,
            max_tracking_error_deg: 0.0,
            peak_torque_ratio: 0.0,
            suction_speed_factor: 1.0,
        }
    }
}

/// Takt statistics [s] over the placed picks that follow another release in the same pile.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct TaktStats {
    /// How many takts.
    pub count: usize,
    /// Mean.
    pub mean_s: f64,
    /// 95th percentile (nearest rank).
    pub p95_s: f64,
    /// Minimum.
    pub min_s: f64,
    /// Maximum.
    pub max_s: f64,
}

impl TaktStats {
    /// From a list of takts (NaN statistics when empty).
    pub fn of(values: &[f64]) -> Self {
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n == 0 {
            return TaktStats {
                count: 0,
                mean_s: f64::NAN,
                p95_s: f64::NAN,
                min_s: f64::NAN,
                max_s: f64::NAN,
            };
        }
        TaktStats {
            count: n,
            mean_s: v.iter().sum::<f64>() / n as f64,
            p95_s: v[((n as f64 * 0.95).ceil() as usize).saturating_sub(1)],
            min_s: v[0],
            max_s: v[n - 1],
        }
    }
}

/// A run's summary.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// Workpiece.
    pub workpiece: String,
    /// Seed.
    pub seed: u64,
    /// Deterministic mode.
    pub deterministic: bool,
    /// Picks the arm set out to make.
    pub attempts: usize,
    /// Picks placed.
    pub placed: usize,
    /// placed / attempts.
    pub success_rate: f64,
    /// Takt statistics.
    pub takt: TaktStats,
    /// The reference system's takt for this workpiece [s], if it is one of A..F.
    pub reference_takt_s: Option<f64>,
    /// End-to-end takt: time from the first to the last release over the releases in between
    /// [s], refills, re-captures and failed picks included (NaN below two releases).
    pub effective_takt_s: f64,
    /// Mean Pick and Place times over the placed picks [s].
    pub mean_pick_s: f64,
    /// Mean Place time over the placed picks [s].
    pub mean_place_s: f64,
    /// Mean compute charged per attempt: grasp selection, Pick and Place motion generation [s].
    pub mean_compute_s: [f64; 3],
    /// Stalls waiting for the sensor: count and total [s] (placed picks after the first of a pile).
    pub sensor_stalls: (usize, f64),
    /// Stalls waiting for compute: count and total [s].
    pub compute_stalls: (usize, f64),
    /// Protective stops.
    pub protective_stops: usize,
    /// Collisions.
    pub collisions: usize,
    /// Parts dropped from the cup.
    pub drops: usize,
    /// Parts lost out of the trays.
    pub parts_lost: usize,
    /// Captures triggered and spoiled.
    pub captures: (u64, u64),
    /// Pick-tray refills and place-tray exchanges.
    pub refills: usize,
    /// Place-tray exchanges.
    pub place_tray_exchanges: usize,
    /// Largest |applied torque| / limit over the run.
    pub peak_torque_ratio: f64,
    /// Largest servo tracking error over the run [deg].
    pub max_tracking_error_deg: f64,
    /// Why the run ended: `picks done`, `tray empty` (policy `end`), `nothing graspable in a
    /// full tray` (a refill found nothing to pick either), `too many empty captures`,
    /// `interrupted` (Ctrl-C).
    pub ended: String,
    /// Simulated time [s].
    pub sim_time_s: f64,
}

/// Options of a run.
#[derive(Debug, Clone, Copy)]
pub struct RunOptions {
    /// Picks to attempt.
    pub picks: usize,
    /// Run seed.
    pub seed: u64,
    /// Charge fixed compute budgets instead of measured wall time (byte-identical results).
    pub deterministic: bool,
    /// Keep every servo tick in [`RunResult::trace`] (for checks and recordings).
    pub keep_trace: bool,
    /// Keep the parts' poses every [`SCENE_FRAME_S`] and each capture's depth image (recordings).
    pub keep_scene: bool,
    /// Set (by a Ctrl-C handler) to end the run after the pick under way: the results so far are
    /// returned and the summary says `interrupted`.
    pub stop: Option<&'static std::sync::atomic::AtomicBool>,
}

/// Period of the part-pose snapshots kept for recordings [s].
pub const SCENE_FRAME_S: f64 = 0.1;

pub use crate::physics::SceneFrame;

/// One motion's tool-tip path: as planned and as executed, for recordings.
#[derive(Debug, Clone)]
pub struct ToolPath {
    /// Start of the motion [s].
    pub t_s: f64,
    /// Duration as planned [s].
    pub duration_s: f64,
    /// Planned tool-tip positions every 10 ms [m, world].
    pub planned_m: Vec<Vector3<f64>>,
    /// Executed tool-tip positions every 10 ms of servo time [m, world].
    pub executed_m: Vec<Vector3<f64>>,
}

/// A capture's depth image, for recordings.
#[derive(Debug, Clone)]
pub struct CaptureImage {
    /// Trigger time [s].
    pub t_s: f64,
    /// Image width and height [px].
    pub size_px: (usize, usize),
    /// Depth per pixel [mm], 0 where there is no return.
    pub depth_mm: Vec<u16>,
    /// The capture's point cloud for recordings: the world points [m] of every
    /// [`CLOUD_EVERY_PX`]-th pixel in each direction that has a return, row-major. (The depth
    /// image keeps every pixel.)
    pub points_world_m: Vec<[f32; 3]>,
}

/// Recorded point clouds keep every this many pixels in each image direction (a quarter of the
/// points: 0.4 MB instead of 1 MB per capture).
pub const CLOUD_EVERY_PX: usize = 2;

/// A recognition result as the grasp selector saw it, for recordings.
#[derive(Debug, Clone)]
pub struct RecognitionRecord {
    /// When the result arrived [s].
    pub t_s: f64,
    /// Recognised parts: estimated `world_from_part` and the visible fraction.
    pub detections: Vec<(Isometry3<f64>, f64)>,
    /// The best feasible grasps, best first (at most [`RECORDED_CANDIDATES`]): the tool at the
    /// grasp and the score.
    pub candidates: Vec<(Isometry3<f64>, f64)>,
    /// Which candidate was chosen (the best one not at a failed spot with a clear approach).
    pub chosen: Option<usize>,
}

/// Most grasp candidates a [`RecognitionRecord`] keeps.
pub const RECORDED_CANDIDATES: usize = 20;

/// A cycle event, for logs and recordings.
#[derive(Debug, Clone, Serialize)]
pub struct CycleEvent {
    /// Simulation time [s].
    pub t_s: f64,
    /// Pick index, if the event belongs to one.
    pub pick: Option<usize>,
    /// What: `capture`, `capture_spoiled`, `recognition_ready`, `grasp_chosen`, `planned`,
    /// `pick_start`, `grasped`, `place_start`, `released`, `stall`, `fault`, `part_lost`,
    /// `refill`, `place_tray_exchange`, `outcome`.
    pub kind: &'static str,
    /// Details.
    pub detail: String,
}

/// Everything a run produced.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Per pick.
    pub records: Vec<PickRecord>,
    /// Summary.
    pub summary: RunSummary,
    /// The time chart's spans.
    pub spans: Vec<Span>,
    /// The time chart's markers (releases, faults).
    pub markers: Vec<Marker>,
    /// Cycle events in time order.
    pub events: Vec<CycleEvent>,
    /// Servo ticks of every motion, in time order, if asked for (`t` is simulation time).
    pub trace: Vec<Tick>,
    /// Part poses over time, if asked for.
    pub scene_frames: Vec<SceneFrame>,
    /// Depth images of the captures, if asked for.
    pub captures: Vec<CaptureImage>,
    /// Every motion's planned and executed tool path, if asked for.
    pub tool_paths: Vec<ToolPath>,
    /// Every recognition result with the grasp candidates, if asked for.
    pub recognitions: Vec<RecognitionRecord>,
    /// The depth camera (pose and intrinsics).
    pub camera: crate::sensor::Camera,
    /// The parts' bounding box [m].
    pub part_size_m: [f64; 3],
}

/// The reference system's takt for workpieces A..F [s] (its Table 5).
pub fn reference_takt(name: &str) -> Option<f64> {
    match name {
        "A" => Some(2.9),
        "B" => Some(2.7),
        "C" | "D" | "E" => Some(2.9),
        "F" => Some(3.0),
        _ => None,
    }
}

/// A recognition result: the capture job, when it was triggered [s], and the detections (`None`
/// if the result was not available).
type Recognised = (CaptureJob, f64, Option<Vec<Detection>>);

/// How a motion ended.
enum Played {
    /// Done.
    Done,
    /// Ended the pick.
    Failed(Outcome),
}

/// The motions of one pick, generated from one recognition result.
struct Prepared {
    grasp: GraspCandidate,
    slot: Isometry3<f64>,
    pick_transfer: Result<Trajectory, String>,
    descent: LineMotion,
    /// Lift and Place motions, generated while the Pick runs.
    lift: LineMotion,
    place: Result<(Trajectory, LineMotion, LineMotion, f64), String>,
    held: Payload,
    /// The part the chosen detection is (for the event log only; nothing decides on it).
    truth_part: usize,
    charged: [f64; 3],
}

struct Cell<'a> {
    world: World,
    robot: &'a RobotModel,
    scene: &'a Scene,
    sensor: Sensor,
    selector: GraspSelector,
    servo: Servo,
    hand: Payload,
    shape: PartShape,
    slots: Vec<Isometry3<f64>>,
    next_slot: usize,
    yaw_symmetry_rad: f64,
    job: Option<CaptureJob>,
    /// When the arm has nothing to do from [s].
    arm_free_s: f64,
    /// Grasp points where a pick failed at the part, in this pile [m, world].
    failed_spots: Vec<Vector3<f64>>,
    /// Gripper events seen while a motion played (a seal decided before the descent settled).
    gripper_events: Vec<GripperEvent>,
    /// The arm's actual joint positions and velocities after its last motion [rad, rad/s].
    arm_state: (JointVector, JointVector),
    seed: u64,
    pick: Option<usize>,
    events: Vec<CycleEvent>,
    spans: Vec<Span>,
    markers: Vec<Marker>,
    trace: Option<Vec<Tick>>,
    captures: Option<Vec<CaptureImage>>,
    recognitions: Option<Vec<RecognitionRecord>>,
    tool_paths: Option<Vec<ToolPath>>,
    parts_lost: usize,
    peak_torque_ratio: f64,
    max_error_rad: f64,
}

impl Cell<'_> {
    fn event(&mut self, kind: &'static str, detail: String) {
        self.events.push(CycleEvent {
            t_s: self.world.time_s,
            pick: self.pick,
            kind,
            detail,
        });
    }

    /// Keeps a recognition result for recordings (if asked for): the detections, the best ranked
    /// candidates and which of them is `chosen` (the tool pose at the chosen grasp).
    fn note_recognition(
        &mut self,
        t_s: f64,
        detections: &[Detection],
        ranked: &[GraspCandidate],
        chosen: Option<&Isometry3<f64>>,
    ) {
        let Some(records) = self.recognitions.as_mut() else {
            return;
        };
        let ranked = &ranked[..ranked.len().min(RECORDED_CANDIDATES)];
        records.push(RecognitionRecord {
            t_s,
            detections: detections
                .iter()
                .map(|d| (d.world_from_part, d.visible_fraction))
                .collect(),
            candidates: ranked.iter().map(|g| (g.world_from_tool, g.score.total)).collect(),
            chosen: chosen.and_then(|c| ranked.iter().position(|g| g.world_from_tool == *c)),
        });
    }

    fn span(&mut self, lane: Lane, start_s: f64, end_s: f64, label: impl Into<String>) {
        if end_s > start_s {
            self.spans.push(Span {
                lane,
                start_s,
                end_s,
                label: label.into(),
            });
        }
    }

    /// One physics step. Parts that left their tray are taken out of the cell (lost); a collision
    /// of the arm or a part pressed into the tray is returned; a non-finite state ends the run.
    fn step(&mut self) -> Result<Option<String>, CycleError> {
        let result = self.world.step();
        if let Some(job) = self.job.as_mut()
            && let Some(problem) = self.sensor.watch(job, &self.world)
        {
            self.event("capture_spoiled", format!("{problem:?}"));
        }
        match result {
            Ok(()) => Ok(None),
            Err(HealthError::LeftVolume { body, volume, .. }) => {
                for i in 0..self.world.parts.len() {
                    let c = self.world.part_pose(i).translation.vector;
                    let lost = match self.world.parts[i].state {
                        PartState::Free => !self.world.pick_tray.contains(&c),
                        PartState::Placed => !self.world.place_tray.contains(&c),
                        PartState::Held | PartState::Removed => false,
                    };
                    if lost {
                        self.world.remove_part(i);
                        self.parts_lost += 1;
                    }
                }
                self.event("part_lost", format!("{body} left the {volume}"));
                Ok(None)
            }
            Err(e @ (HealthError::ArmCollision { .. } | HealthError::DeepPenetration { .. })) => {
                Ok(Some(e.to_string()))
            }
            Err(e @ HealthError::NonFinite { .. }) => Err(e.into()),
        }
    }

    /// Steps the world to `t` with the arm still. Contacts of a resting arm are not new faults.
    fn idle_until(&mut self, t: f64) -> Result<(), CycleError> {
        while self.world.time_s + 1e-9 < t {
            self.step()?;
        }
        Ok(())
    }

    /// Triggers a capture if none is pending (or the pending one was spoiled and the sensor has
    /// finished exposing it) and the arm is out of view.
    fn maybe_trigger(&mut self) {
        if let Some(j) = &self.job
            && (j.spoiled.is_none() || self.world.time_s + 1e-9 < j.exposure_end_s)
        {
            return;
        }
        if let Ok(job) = self.sensor.trigger(&self.world) {
            self.event("capture", format!("capture {}", self.sensor.triggered - 1));
            if let Some(images) = self.captures.as_mut() {
                images.push(CaptureImage {
                    t_s: self.world.time_s,
                    size_px: (job.capture.width, job.capture.height),
                    depth_mm: job
                        .capture
                        .depth_m
                        .iter()
                        .map(|d| (d * 1000.0).round() as u16)
                        .collect(),
                    points_world_m: job
                        .capture
                        .points_world
                        .iter()
                        .enumerate()
                        .filter(|(k, p)| {
                            let (u, v) = (k % job.capture.width, k / job.capture.width);
                            u % CLOUD_EVERY_PX == 0 && v % CLOUD_EVERY_PX == 0 && p[0].is_finite()
                        })
                        .map(|(_, p)| *p)
                        .collect(),
                });
            }
            self.job = Some(job);
        }
    }

    /// Plays a motion through the servo into the world; `trigger` polls for the next capture.
    fn play(&mut self, motion: &impl Motion, payload: &Payload, trigger: bool) -> Result<Played, CycleError> {
        self.play_with(motion, payload, trigger, None, true)
    }

    /// As [`Cell::play`], switching the vacuum on `vacuum_at_s` into the motion; with `settle`
    /// false the next motion takes over at this one's end without waiting to be in position.
    fn play_with(
        &mut self,
        motion: &impl Motion,
        payload: &Payload,
        trigger: bool,
        vacuum_at_s: Option<f64>,
        settle: bool,
    ) -> Result<Played, CycleError> {
        let jump = (motion.at(0.0).q - self.world.joints()).amax();
        if jump > 1e-3 {
            self.event("motion_start_mismatch", format!("{jump:.4} rad"));
        }
        let dynamics = self.robot.dynamics(payload);
        let run = execute_from(
            self.robot,
            &dynamics,
            &dynamics,
            &self.servo,
            motion,
            self.arm_state,
            settle,
        );
        self.arm_state = run.end_state;
        if let Some(paths) = self.tool_paths.as_mut() {
            let tip = |q: &JointVector| self.robot.world_from_tool(q).translation.vector;
            paths.push(ToolPath {
                t_s: self.world.time_s,
                duration_s: motion.duration_s(),
                planned_m: motion.sampled(0.01).iter().map(|s| tip(&s.q)).collect(),
                executed_m: run.ticks.iter().step_by(10).map(|t| tip(&t.q)).collect(),
            });
        }
        let limit = self.robot.torque_limit_nm();
        let t0 = self.world.time_s;
        for t in &run.ticks {
            for i in 0..DOF {
                self.peak_torque_ratio = self.peak_torque_ratio.max(t.tau[i].abs() / limit[i]);
            }
        }
        self.max_error_rad = run.max_error_rad.iter().fold(self.max_error_rad, |a, e| a.max(*e));
        let per_step = (self.world.dt_s() / self.servo.dt_s).round().max(1.0) as usize;
        let mut dropped = None;
        let mut k = per_step;
        let mut done = 0;
        while k < run.ticks.len() + per_step {
            let end = k.min(run.ticks.len() - 1);
            self.world.set_joint_target(&run.ticks[end].q);
            if vacuum_at_s.is_some_and(|t| run.ticks[end].t + 1e-9 >= t) {
                self.world.vacuum_on();
            }
            if let Some(trace) = self.trace.as_mut() {
                trace.extend(run.ticks[done..=end].iter().map(|tk| Tick { t: t0 + tk.t, ..*tk }));
            }
            done = end + 1;
            if let Some(what) = self.step()? {
                let path: Vec<JointVector> = run.ticks[..=end].iter().map(|tk| tk.q).collect();
                self.recover(&path, &format!("collision: {what}"))?;
                return Ok(Played::Failed(Outcome::Collision(what)));
            }
            if trigger {
                self.maybe_trigger();
            }
            for ev in self.world.gripper.take_events() {
                if !matches!(ev, GripperEvent::Slipped { .. }) {
                    self.gripper_events.push(ev.clone());
                }
                if let GripperEvent::Slipped {
                    required_n,
                    holding_n,
                    time_s,
                    ..
                } = ev
                {
                    dropped.get_or_insert(format!(
                        "slipped {:.3} s into the motion: {required_n:.2} N needed, {holding_n:.2} N held",
                        time_s - t0
                    ));
                }
            }
            k += per_step;
        }
        if let Some((t, trip)) = run.trip {
            let what = format!("{trip:?} at {t:.3} s into the motion");
            self.recover(&[], &format!("protective stop: {what}"))?;
            return Ok(Played::Failed(Outcome::ProtectiveStop(what)));
        }
        if let Some(why) = dropped {
            return Ok(Played::Failed(Outcome::Dropped(why)));
        }
        Ok(Played::Done)
    }

    /// After a fault: the vacuum goes off, the controller waits its reset time, then the arm
    /// retraces `path` (the executed positions of the faulted motion) back to where it started.
    fn recover(&mut self, path: &[JointVector], what: &str) -> Result<(), CycleError> {
        let t = self.world.time_s;
        self.event("fault", what.to_string());
        self.markers.push(Marker {
            t_s: t,
            label: "fault".into(),
        });
        self.world.vacuum_off();
        self.idle_until(t + self.scene.sim.protective_stop_reset_s)?;
        self.arm_state = (self.world.joints(), JointVector::zeros());
        self.clear_deep_penetrations();
        let tool = self.world.world_from_tool();
        let tray = &self.world.pick_tray;
        let above_z = tray.world_from_tray.translation.z + self.scene.pick_tray.wall_height_m + 0.1;
        let local = tray.world_from_tray.inverse() * nalgebra::Point3::from(tool.translation.vector);
        let over_pick_tray = local.x.abs() < tray.half_xy_m[0] && local.y.abs() < tray.half_xy_m[1];
        let hand = self.hand;
        if over_pick_tray && tool.translation.z < above_z {
            // In the tray: straight up, slowly, out of whatever it touches.
            let up = Isometry3::from_parts(
                Translation3::new(tool.translation.x, tool.translation.y, above_z),
                tool.rotation,
            );
            let limits = LineLimits {
                speed_m_s: 0.1,
                accel_m_s2: 1.0,
            };
            if let Some(line) = straight_line(
                self.robot,
                &self.robot.dynamics(&hand),
                &self.arm_state.0,
                &tool,
                &up,
                &limits,
                None,
            ) {
                self.retrace(
                    &line.sampled(self.servo.dt_s).iter().map(|s| s.q).collect::<Vec<_>>(),
                    1,
                )?;
            }
        } else {
            // Elsewhere: back along the faulted motion, at a third of its speed.
            let back: Vec<JointVector> = path.iter().rev().copied().collect();
            self.retrace(&back, 3)?;
        }
        self.arm_state = (self.world.joints(), JointVector::zeros());
        self.world.gripper.take_events();
        self.gripper_events.clear();
        self.span(Lane::Stall, t, self.world.time_s, "fault reset and retreat");
        self.arm_free_s = self.world.time_s;
        Ok(())
    }

    /// After a fault: parts the arm pressed into the tray or into each other (deeper than the
    /// health monitor allows) are damaged goods: taken out of the cell and counted as lost.
    fn clear_deep_penetrations(&mut self) {
        for _ in 0..8 {
            let (depth, pair) = self.world.max_penetration_m();
            let Some((a, b)) = pair.filter(|_| depth > self.world.health.deep_penetration_m) else {
                return;
            };
            let mut removed = false;
            for tag in [a, b] {
                if let crate::physics::Tag::Part(i) = tag
                    && self.world.parts[i as usize].state != PartState::Held
                {
                    self.world.remove_part(i as usize);
                    self.parts_lost += 1;
                    self.event("part_lost", format!("part {i} pressed {:.2} mm deep", depth * 1e3));
                    removed = true;
                }
            }
            if !removed {
                return;
            }
        }
    }

    /// Moves the arm's bodies through servo-rate positions `path`, `slow` times slower, without
    /// treating contacts as new faults (the arm is getting out of one).
    fn retrace(&mut self, path: &[JointVector], slow: usize) -> Result<(), CycleError> {
        let per_step = (self.world.dt_s() / self.servo.dt_s).round().max(1.0) as usize;
        for q in path.iter().step_by(per_step) {
            for _ in 0..slow {
                self.world.set_joint_target(q);
                self.step()?;
            }
        }
        Ok(())
    }

    /// A recognition result to pick from: triggers a capture if none is pending (moving the arm
    /// out of view first if needed) and waits for it. `None` if the arm cannot leave the view.
    fn next_result(&mut self) -> Result<Option<Recognised>, CycleError> {
        loop {
            self.maybe_trigger();
            if self.job.is_none() {
                if !self.move_out_of_view()? {
                    return Ok(None);
                }
                self.maybe_trigger();
                if self.job.is_none() {
                    return Ok(None);
                }
            }
            let job = self.job.clone().expect("checked");
            if job.spoiled.is_some() {
                self.idle_until(job.exposure_end_s)?;
                continue;
            }
            let capture_s = job.exposure_end_s - self.sensor.exposure_s;
            // A spoiled exposure is known when it ends: expose again right away.
            self.idle_until(job.exposure_end_s)?;
            if self.job.as_ref().is_some_and(|j| j.spoiled.is_some()) {
                continue;
            }
            self.idle_until(job.ready_s)?;
            let job = self.job.take().expect("pending");
            if job.spoiled.is_some() {
                continue;
            }
            self.span(Lane::Sensor, capture_s, job.exposure_end_s, "exposure");
            self.span(Lane::Recognition, job.exposure_end_s, job.ready_s, "recognition");
            let detections = self.sensor.result(&job, &self.world);
            self.events.push(CycleEvent {
                t_s: job.ready_s,
                pick: self.pick,
                kind: "recognition_ready",
                detail: format!(
                    "{} parts detected, {} blurred by motion during the exposure",
                    detections.as_ref().map_or(0, Vec::len),
                    job.blurred()
                ),
            });
            return Ok(Some((job, capture_s, detections)));
        }
    }

    /// Moves the arm home when it is in the camera's view and nothing is pending.
    fn move_out_of_view(&mut self) -> Result<bool, CycleError> {
        if self.sensor.frustum.arm_inside(&self.world).is_none() {
            return Ok(true);
        }
        let home = JointVector::from(self.scene.robot.home_rad());
        let free = CollisionModel::new(
            self.robot,
            RobotSpheres::new(self.robot, self.scene, None),
            Environment::from_scene(self.scene),
        );
        let mut rng = crate::rng::stream(self.seed.wrapping_add(self.world.steps), "planner-home");
        let t = self.world.time_s;
        let mut plan = free.plan(&self.world.joints(), &home, &PlanOptions::default(), &mut rng);
        if plan.is_err() {
            // Down in the tray (after a fault): straight up above the rim first.
            let tool = self.world.world_from_tool();
            let rim_z = self.world.pick_tray.world_from_tray.translation.z + self.scene.pick_tray.wall_height_m + 0.1;
            let up = Isometry3::from_parts(
                Translation3::new(tool.translation.x, tool.translation.y, tool.translation.z.max(rim_z)),
                tool.rotation,
            );
            let hand = self.hand;
            if let Some(line) = self.line(&self.world.joints(), &tool, &up, &hand, None) {
                self.play(&line, &hand, true)?;
            }
            plan = free.plan(&self.world.joints(), &home, &PlanOptions::default(), &mut rng);
        }
        let Ok(p) = plan else {
            self.event("fault", "no path out of the sensor's view".into());
            return Ok(false);
        };
        let via: Vec<JointVector> = p.waypoints.iter().map(|q| JointVector::from(*q)).collect();
        let hand = self.hand;
        let (_, acc, _) = accelerate_in_corridor(self.robot, &self.robot.dynamics(&hand), &via, &free, 0.01);
        let played = self.play(&acc.trajectory, &hand, true)?;
        self.span(Lane::Place, t, self.world.time_s, "out of view");
        self.arm_free_s = self.world.time_s;
        Ok(matches!(played, Played::Done))
    }

    /// A straight tool line at the cell's line speed and acceleration, torque-limited and, with a
    /// part on the cup, limited to the cup's holding force.
    fn line(
        &self,
        q_from: &JointVector,
        from: &Isometry3<f64>,
        to: &Isometry3<f64>,
        payload: &Payload,
        max_force: Option<f64>,
    ) -> Option<LineMotion> {
        let limits = LineLimits {
            speed_m_s: self.scene.cycle.line_speed_m_s,
            accel_m_s2: self.scene.cycle.line_accel_m_s2,
        };
        straight_line(
            self.robot,
            &self.robot.dynamics(payload),
            q_from,
            from,
            to,
            &limits,
            max_force,
        )
    }

    /// The largest tool specific force [m/s^2] the cup holds the part against with margin, for
    /// a grasp whose cup axis passes `offset_m` from the part's centre of mass.
    fn suction_limit(&self, offset_m: f64) -> f64 {
        let g = &self.world.gripper;
        SUCTION_MARGIN * g.holding_n / (self.shape.mass_kg * (1.0 + 4.0 * offset_m / (2.0 * g.cup_radius_m)))
    }

    /// Grasp selection and motion generation for one recognition result. Returns the motions
    /// and the wall time of each stage, or why nothing can be picked.
    fn prepare(&mut self, detections: &[Detection], job: &CaptureJob) -> Result<(Prepared, [f64; 3]), String> {
        let wall = Instant::now();
        let hm = HeightMap::from_capture(&job.capture, &self.world, 0.002);
        let slot = self.slots[self.next_slot % self.slots.len()];
        let q_now = self.world.joints();
        let plan = self.selector.select(detections, &hm, &slot, &q_now);
        let inner = self.scene.pick_tray.inner_size_m;
        let pile = hm.inner_only([inner[0] / 2.0, inner[1] / 2.0]);
        // The best grasp whose approach pose is clear in the planner's (conservative) model.
        let mut chosen = None;
        // Not where a grasp has just failed: the same spot would fail the same way.
        let tried = |g: &&GraspCandidate| {
            self.failed_spots
                .iter()
                .any(|p| (p - g.world_from_tool.translation.vector).norm() < FAILED_SPOT_RADIUS_M)
        };
        for g in plan.ranked.iter().filter(|g| !tried(g)).take(8) {
            let local = self.world.pick_tray.world_from_tray.inverse()
                * nalgebra::Point3::from(g.world_from_tool.translation.vector);
            let mut env = Environment::from_scene(self.scene);
            env.pile = Some(PileColumns::new(&pile, 5, Some((local.x, local.y, 0.02))));
            let model = CollisionModel::new(self.robot, RobotSpheres::new(self.robot, self.scene, None), env.clone());
            if model.free(
                &JointVector::from(g.q_approach),
                &mut crate::planning::PlanStats::default(),
            ) {
                chosen = Some((g.clone(), env, model));
                break;
            }
        }
        self.note_recognition(
            job.ready_s,
            detections,
            &plan.ranked,
            chosen.as_ref().map(|(g, _, _)| &g.world_from_tool),
        );
        let Some((grasp, env, empty)) = chosen else {
            let reasons = plan
                .rejected_counts()
                .iter()
                .map(|(k, v)| format!("{k} {v}"))
                .collect::<Vec<_>>()
                .join(", ");
            let why = if plan.ranked.is_empty() {
                format!("no feasible grasp ({reasons})")
            } else {
                format!("no grasp with a clear approach among {}", plan.ranked.len().min(8))
            };
            return Err(why);
        };
        let grasp_s = wall.elapsed().as_secs_f64();
        // Pick: transfer to the approach pose, straight descent.
        let wall = Instant::now();
        let mut rng = crate::rng::stream(self.seed.wrapping_add(self.world.steps), "planner");
        let q_approach = JointVector::from(grasp.q_approach);
        let hand = self.hand;
        let dyn_hand = self.robot.dynamics(&hand);
        let pick_transfer = empty
            .plan(&q_now, &q_approach, &PlanOptions::default(), &mut rng)
            .map(|p| {
                let via: Vec<JointVector> = p.waypoints.iter().map(|q| JointVector::from(*q)).collect();
                accelerate_in_corridor(self.robot, &dyn_hand, &via, &empty, 0.01)
                    .1
                    .trajectory
            })
            .map_err(|e| format!("pick transfer: {e}"));
        let descent = self.line(
            &q_approach,
            &grasp.world_from_tool_approach,
            &grasp.world_from_tool,
            &hand,
            None,
        );
        let pick_s = wall.elapsed().as_secs_f64();
        // Place: with the part on the cup, its centre of mass where the recognition put it.
        let wall = Instant::now();
        let world_from_part = detections[grasp.detection].world_from_part;
        let tool_from_part = grasp.world_from_tool.inverse() * world_from_part;
        // The recognised pose is off by up to three standard deviations of its noise.
        let offset = tool_from_part.translation.vector.xy().norm() + 3.0 * self.sensor.pose_noise_m;
        let max_force = self.suction_limit(offset);
        let held = hand.combined(&Payload::point(
            self.shape.mass_kg,
            self.robot.flange_from_tool * tool_from_part.translation.vector,
        ));
        // The lift starts where the descent ends (the same line, IK-chained from the approach).
        let q_grasp = descent
            .as_ref()
            .map_or(JointVector::from(grasp.q_grasp), LineMotion::end_q);
        let lift = self.line(
            &q_grasp,
            &grasp.world_from_tool,
            &grasp.world_from_tool_approach,
            &held,
            Some(max_force),
        );
        let above_place = Isometry3::from_parts(
            Translation3::from(grasp.world_from_tool_place.translation.vector + Vector3::z() * PLACE_APPROACH_M),
            grasp.world_from_tool_place.rotation,
        );
        let release_pose = Isometry3::from_parts(
            Translation3::from(grasp.world_from_tool_place.translation.vector + Vector3::z() * RELEASE_ABOVE_M),
            grasp.world_from_tool_place.rotation,
        );
        let holding = CollisionModel::new(
            self.robot,
            RobotSpheres::new(
                self.robot,
                self.scene,
                Some((tool_from_part, self.shape.half_extents_m)),
            ),
            env,
        );
        let dyn_held = self.robot.dynamics(&held);
        let place = (|| {
            let q_above = self
                .robot
                .ik_tool_nearest(&above_place, &JointVector::from(grasp.q_place))
                .map_err(|e| format!("place pose: {e}"))?
                .q;
            let q_lifted = lift.as_ref().map_or(q_approach, LineMotion::end_q);
            let path = holding
                .plan(&q_lifted, &q_above, &PlanOptions::default(), &mut rng)
                .map_err(|e| format!("place transfer: {e}"))?;
            let via: Vec<JointVector> = path.waypoints.iter().map(|q| JointVector::from(*q)).collect();
            let (via, acc, _) = accelerate_in_corridor(self.robot, &dyn_held, &via, &holding, 0.01);
            let (transfer, k) = limit_tool_force(self.robot, &via, &acc.limits, max_force);
            let down = self
                .line(&q_above, &above_place, &release_pose, &held, Some(max_force))
                .ok_or("place descent: no joint path along the line")?;
            let q_release = down.end_q();
            let up = self
                .line(&q_release, &release_pose, &above_place, &hand, None)
                .ok_or("place retreat: no joint path along the line")?;
            Ok::<_, String>((transfer, down, up, k))
        })();
        let place_s = wall.elapsed().as_secs_f64();
        let (Some(descent), Some(lift)) = (descent, lift) else {
            return Err("no joint path along the straight descent".into());
        };
        let truth_part = detections[grasp.detection].truth_part;
        Ok((
            Prepared {
                grasp,
                slot,
                pick_transfer,
                descent,
                lift,
                place,
                held,
                truth_part,
                charged: [0.0; 3],
            },
            [grasp_s, pick_s, place_s],
        ))
    }

    /// Takes the parts left in the pick tray out and pours a new pile.
    fn refill(&mut self, fill: u64, count: usize) -> Result<(), CycleError> {
        for i in self.world.parts_in_state(PartState::Free) {
            self.world.remove_part(i);
        }
        let t = self.world.time_s;
        self.event("refill", format!("pile {fill}"));
        self.idle_until(t + self.scene.cycle.refill_s)?;
        self.failed_spots.clear();
        let seed = self.seed.wrapping_add(fill.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        self.world.build_pile(&PileOptions::new(count, seed))?;
        self.span(Lane::Stall, t, self.world.time_s, "pick tray refill");
        self.arm_free_s = self.world.time_s;
        Ok(())
    }
}

/// Runs `opts.picks` picks of `workpiece` in the cell of `scene`.
pub fn run(
    scene: &LoadedScene,
    robot: &RobotModel,
    workpiece: &LoadedWorkpiece,
    opts: &RunOptions,
) -> Result<RunResult, CycleError> {
    let wp = &workpiece.workpiece;
    let shape = PartShape::build(wp, &workpiece.source)?;
    let mut world = World::new(&scene.scene, robot, shape.clone());
    if opts.keep_scene {
        world.record_parts_every(SCENE_FRAME_S);
    }
    let pile_count = wp.pile_count as usize;
    world.build_pile(&PileOptions::new(pile_count, opts.seed))?;
    let sensor = Sensor::new(&scene.scene.sensor, &world, opts.seed)
        .ok_or_else(|| CycleError::Setup("degenerate sensor pose".into()))?;
    let slots = scene.scene.world_from_slots(wp);
    if slots.is_empty() {
        return Err(CycleError::Setup("no place slot for this workpiece".into()));
    }
    let mut cell = Cell {
        arm_free_s: world.time_s,
        arm_state: (world.joints(), JointVector::zeros()),
        gripper_events: Vec::new(),
        failed_spots: Vec::new(),
        world,
        robot,
        scene: &scene.scene,
        sensor,
        selector: GraspSelector::new(&scene.scene, robot, wp),
        servo: Servo::from_config(&scene.scene.sim),
        hand: Payload::from_gripper(&scene.scene.gripper),
        shape,
        slots,
        next_slot: 0,
        yaw_symmetry_rad: wp.grasp.yaw_symmetry_deg.to_radians(),
        job: None,
        seed: opts.seed,
        pick: None,
        events: Vec::new(),
        spans: Vec::new(),
        markers: Vec::new(),
        trace: opts.keep_trace.then(Vec::new),
        captures: opts.keep_scene.then(Vec::new),
        recognitions: opts.keep_scene.then(Vec::new),
        tool_paths: opts.keep_scene.then(Vec::new),
        parts_lost: 0,
        peak_torque_ratio: 0.0,
        max_error_rad: 0.0,
    };
    let budgets = [
        scene.scene.compute.grasp_estimation_s,
        scene.scene.compute.motion_generation_s,
        scene.scene.compute.motion_generation_s,
    ];
    let policy = &scene.scene.cycle;
    let mut records: Vec<PickRecord> = Vec::new();
    let mut last_release: Option<f64> = None;
    let mut first_of_pile = true;
    let mut attempts = 0usize;
    let mut empty_in_row = 0u32;
    let mut fills = 1u64;
    let mut attempts_since_fill = 0usize;
    let mut refills = 0usize;
    let mut exchanges = 0usize;
    let mut ended = "picks done".to_string();
    while attempts < opts.picks {
        if opts.stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed)) {
            ended = "interrupted".into();
            break;
        }
        let index = records.len();
        cell.pick = Some(index);
        if index > 20 * opts.picks + 20 {
            ended = "too many empty captures".into();
            break;
        }
        let Some((job, capture_s, detections)) = cell.next_result()? else {
            ended = "the arm found no path out of the sensor's view".into();
            break;
        };
        let mut rec = PickRecord::new(index, &job, capture_s);
        let prepared = match detections.as_deref() {
            None | Some([]) => {
                cell.note_recognition(job.ready_s, &[], &[], None);
                Err(None)
            }
            Some(dets) => cell.prepare(dets, &job).map_err(Some),
        };
        let (mut prep, wall) = match prepared {
            Ok(p) => p,
            Err(why) => {
                rec.outcome = why.map_or(Outcome::NothingDetected, Outcome::NothingGraspable);
                cell.event("outcome", format!("{}: {}", rec.outcome.name(), rec.outcome.detail()));
                records.push(rec);
                empty_in_row += 1;
                if empty_in_row >= policy.empty_after_captures {
                    empty_in_row = 0;
                    match policy.on_empty {
                        OnEmpty::End => {
                            ended = "tray empty".into();
                            break;
                        }
                        OnEmpty::Refill if attempts_since_fill == 0 && fills > 1 => {
                            ended = "nothing graspable in a full tray".into();
                            break;
                        }
                        OnEmpty::Refill => {
                            attempts_since_fill = 0;
                            cell.refill(fills, pile_count)?;
                            fills += 1;
                            refills += 1;
                            first_of_pile = true;
                        }
                    }
                }
                continue;
            }
        };
        empty_in_row = 0;
        attempts += 1;
        attempts_since_fill += 1;
        prep.charged = if opts.deterministic { budgets } else { wall };
        [rec.grasp_compute_s, rec.pick_compute_s, rec.place_compute_s] = prep.charged;
        let ready = job.ready_s;
        let grasp_done = ready + prep.charged[0];
        let pick_ready = grasp_done + prep.charged[1];
        let place_ready = pick_ready + prep.charged[2];
        cell.span(Lane::Grasp, ready, grasp_done, "grasp selection");
        cell.span(Lane::Planning, grasp_done, pick_ready, "Pick motion");
        cell.span(Lane::Planning, pick_ready, place_ready, "Place motion");
        cell.events.push(CycleEvent {
            t_s: grasp_done,
            pick: Some(index),
            kind: "grasp_chosen",
            detail: format!(
                "detection {} face {} score {:.3}",
                prep.grasp.detection, prep.grasp.face, prep.grasp.score.total
            ),
        });
        // Stall before the Pick: waiting for the sensor, then for compute.
        let free = cell.arm_free_s;
        rec.stall_sensor_s = (ready.min(pick_ready) - free).max(0.0);
        rec.stall_compute_s = (pick_ready - free.max(ready)).max(0.0);
        let pick_planned = match &prep.pick_transfer {
            Ok(t) => format!(
                "Pick motion: transfer {:.3} s + descent {:.3} s ({:.1} ms compute)",
                t.duration_s(),
                prep.descent.duration_s(),
                1e3 * prep.charged[1]
            ),
            Err(e) => format!("Pick motion: {e}"),
        };
        let place_planned = match &prep.place {
            Ok((t, descent, retreat, _)) => format!(
                "Place motion: lift {:.3} s + transfer {:.3} s + descent {:.3} s + retreat {:.3} s ({:.1} ms compute)",
                prep.lift.duration_s(),
                t.duration_s(),
                descent.duration_s(),
                retreat.duration_s(),
                1e3 * prep.charged[2]
            ),
            Err(e) => format!("Place motion: {e}"),
        };
        let mut stages = vec![
            (pick_ready, "planned", pick_planned),
            (place_ready, "planned", place_planned),
        ];
        if rec.stall_sensor_s > 0.0 {
            cell.span(Lane::Stall, free, ready, "waiting for the sensor");
            let detail = format!("waiting for the sensor {:.3} s", rec.stall_sensor_s);
            stages.push((free, "stall", detail));
        }
        if rec.stall_compute_s > 0.0 {
            cell.span(Lane::Stall, free.max(ready), pick_ready, "waiting for compute");
            let detail = format!("waiting for compute {:.3} s", rec.stall_compute_s);
            stages.push((free.max(ready), "stall", detail));
        }
        for (t_s, kind, detail) in stages {
            cell.events.push(CycleEvent {
                t_s,
                pick: Some(index),
                kind,
                detail,
            });
        }
        cell.idle_until(pick_ready.max(cell.world.time_s))?;
        let outcome = pick_and_place(&mut cell, &prep, &mut rec, place_ready)?;
        if outcome != Outcome::Placed && cell.world.held_part().is_some() {
            // A pick that ended with the part still on the cup (no Place motion): let it go where
            // the arm is, over the pick tray, before anything else moves.
            cell.world.vacuum_off();
            let t = cell.world.time_s + cell.world.gripper.release_s + cell.world.dt_s();
            cell.idle_until(t)?;
            cell.world.gripper.take_events();
            cell.event("part_let_go", "the part stays in the pick tray".into());
            cell.arm_free_s = cell.arm_free_s.max(cell.world.time_s);
        }
        if matches!(
            outcome,
            Outcome::GraspFailed(_) | Outcome::Collision(_) | Outcome::ProtectiveStop(_)
        ) && rec.place_s == 0.0
        {
            cell.failed_spots.push(prep.grasp.world_from_tool.translation.vector);
        }
        if rec.place_s > 0.0 && matches!(outcome, Outcome::Collision(_) | Outcome::ProtectiveStop(_)) {
            // Something is in the slot (a part that bounced there): the next part goes to the next.
            cell.event("slot_skipped", format!("slot {}", cell.next_slot % cell.slots.len()));
            cell.next_slot += 1;
        }
        rec.outcome = outcome;
        cell.event("outcome", format!("{}: {}", rec.outcome.name(), rec.outcome.detail()));
        if rec.outcome == Outcome::Placed {
            let release = rec.release_s.expect("placed picks have a release");
            rec.takt_s = last_release.map(|r| release - r);
            rec.first_of_pile = first_of_pile;
            first_of_pile = false;
            last_release = Some(release);
            cell.next_slot += 1;
        }
        if cell.next_slot >= cell.slots.len() {
            cell.next_slot = 0;
            for i in cell.world.parts_in_state(PartState::Placed) {
                cell.world.remove_part(i);
            }
            exchanges += 1;
            cell.event("place_tray_exchange", String::new());
            let t = cell.world.time_s + policy.place_tray_exchange_s;
            cell.idle_until(t)?;
            cell.arm_free_s = cell.arm_free_s.max(cell.world.time_s);
        }
        rec.max_tracking_error_deg = cell.max_error_rad.to_degrees();
        rec.peak_torque_ratio = cell.peak_torque_ratio;
        records.push(rec);
    }
    // Events were logged as the simulation reached them; a few carry an earlier time (compute
    // that ran while the arm was busy): order them by time, stably.
    cell.events.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    let summary = summarise(&cell, &records, opts, wp.name.clone(), refills, exchanges, ended);
    Ok(RunResult {
        records,
        summary,
        spans: cell.spans,
        markers: cell.markers,
        events: cell.events,
        trace: cell.trace.unwrap_or_default(),
        scene_frames: cell.world.take_part_frames(),
        captures: cell.captures.unwrap_or_default(),
        tool_paths: cell.tool_paths.unwrap_or_default(),
        recognitions: cell.recognitions.unwrap_or_default(),
        camera: cell.sensor.camera.clone(),
        part_size_m: wp.size_m,
    })
}

/// Pick (transfer, descent, vacuum, lift) and Place (transfer, descent, release, retreat).
fn pick_and_place(
    cell: &mut Cell<'_>,
    prep: &Prepared,
    rec: &mut PickRecord,
    place_ready: f64,
) -> Result<Outcome, CycleError> {
    let hand = cell.hand;
    let t_pick = cell.world.time_s;
    cell.event("pick_start", String::new());
    let pick_transfer = match &prep.pick_transfer {
        Ok(t) => t,
        Err(e) => return Ok(Outcome::NoMotion(e.clone())),
    };
    cell.max_error_rad = 0.0;
    cell.peak_torque_ratio = 0.0;
    cell.gripper_events.clear();
    let pick_done = |cell: &mut Cell<'_>, rec: &mut PickRecord| {
        rec.pick_s = cell.world.time_s - t_pick;
        cell.span(Lane::Pick, t_pick, cell.world.time_s, "Pick");
        cell.arm_free_s = cell.world.time_s;
    };
    if let Played::Failed(o) = cell.play_with(pick_transfer, &hand, false, None, false)? {
        pick_done(cell, rec);
        return Ok(o);
    }
    // The vacuum valve opens `vacuum_lead_s` before the cup reaches the face.
    let lead = cell.scene.cycle.vacuum_lead_s;
    let descent = &prep.descent;
    let vacuum_at = (descent.duration_s() - lead).max(0.0);
    let t_descent = cell.world.time_s;
    if let Played::Failed(o) = cell.play_with(descent, &hand, false, Some(vacuum_at), true)? {
        pick_done(cell, rec);
        return Ok(o);
    }
    cell.world.vacuum_on();
    let t = (t_descent + vacuum_at).min(cell.world.time_s) + cell.world.gripper.build_up_s + cell.world.dt_s();
    cell.idle_until(t)?;
    let mut failure = None;
    let mut events = std::mem::take(&mut cell.gripper_events);
    events.extend(cell.world.gripper.take_events());
    for ev in events {
        match ev {
            GripperEvent::Grasped { seal, .. } => {
                let truth = prep.truth_part;
                cell.event(
                    "grasped",
                    format!(
                        "part {} (aimed at part {truth}), cup axis {:.1} mm from its centre of mass, tilt {:.1} deg",
                        seal.part,
                        seal.com_offset_m * 1e3,
                        seal.tilt_rad.to_degrees()
                    ),
                );
            }
            GripperEvent::GraspFailed { reason, .. } => failure = Some(Outcome::GraspFailed(reason.to_string())),
            GripperEvent::Slipped { required_n, .. } => {
                failure = Some(Outcome::Dropped(format!("slipped at rest: {required_n:.2} N")))
            }
            GripperEvent::Released { .. } => {}
        }
    }
    if cell.world.held_part().is_none() {
        cell.world.vacuum_off();
        cell.play(&prep.lift, &hand, false)?;
        pick_done(cell, rec);
        return Ok(failure.unwrap_or_else(|| Outcome::GraspFailed("no seal".into())));
    }
    let held = prep.held;
    if let Played::Failed(o) = cell.play_with(&prep.lift, &held, true, None, false)? {
        pick_done(cell, rec);
        return Ok(o);
    }
    pick_done(cell, rec);
    // Place: the motions were generated while the Pick ran; wait if they are not ready yet.
    if place_ready > cell.world.time_s {
        let t = cell.world.time_s;
        rec.stall_compute_s += place_ready - t;
        cell.span(Lane::Stall, t, place_ready, "waiting for compute");
        cell.idle_until(place_ready)?;
        cell.arm_state.1 = JointVector::zeros();
    }
    let (transfer, down, up, k) = match &prep.place {
        Ok(p) => p,
        Err(e) => return Ok(Outcome::NoMotion(e.clone())),
    };
    rec.suction_speed_factor = *k;
    let t_place = cell.world.time_s;
    cell.event("place_start", String::new());
    let place_done = |cell: &mut Cell<'_>, rec: &mut PickRecord| {
        rec.place_s = cell.world.time_s - t_place;
        cell.span(Lane::Place, t_place, cell.world.time_s, "Place");
        cell.arm_free_s = cell.world.time_s;
    };
    if let Played::Failed(o) = cell.play_with(transfer, &held, true, None, false)? {
        place_done(cell, rec);
        return Ok(o);
    }
    if let Played::Failed(o) = cell.play(down, &held, true)? {
        place_done(cell, rec);
        return Ok(o);
    }
    let part = cell.world.held_part();
    cell.world.vacuum_off();
    let t = cell.world.time_s + cell.world.gripper.release_s + cell.world.dt_s();
    cell.idle_until(t)?;
    cell.world.gripper.take_events();
    cell.gripper_events.clear();
    let release = cell.world.time_s;
    cell.event("released", String::new());
    cell.markers.push(Marker {
        t_s: release,
        label: format!("release {}", rec.index),
    });
    if let Played::Failed(o) = cell.play(up, &hand, true)? {
        place_done(cell, rec);
        return Ok(o);
    }
    place_done(cell, rec);
    if let Some(i) = part {
        let (d, yaw) = cell.world.placement_error(i, &prep.slot, cell.yaw_symmetry_rad);
        rec.placement_error_mm = Some(d * 1e3);
        rec.yaw_error_deg = Some(yaw.to_degrees());
    }
    rec.release_s = Some(release);
    Ok(Outcome::Placed)
}

/// The takts the statistics are over [s]: placed picks after the first of their pile.
pub fn takts_in_stats(records: &[PickRecord]) -> Vec<f64> {
    records
        .iter()
        .filter(|r| r.outcome == Outcome::Placed && !r.first_of_pile)
        .filter_map(|r| r.takt_s)
        .collect()
}

/// Time from the first to the last release [s] and the releases after the first: their ratio is
/// the end-to-end takt. (0, 0) below two releases.
pub fn release_span(records: &[PickRecord]) -> (f64, usize) {
    let r: Vec<f64> = records.iter().filter_map(|p| p.release_s).collect();
    match (r.first(), r.last()) {
        (Some(a), Some(b)) if r.len() > 1 => (b - a, r.len() - 1),
        _ => (0.0, 0),
    }
}

fn summarise(
    cell: &Cell<'_>,
    records: &[PickRecord],
    opts: &RunOptions,
    workpiece: String,
    refills: usize,
    place_tray_exchanges: usize,
    ended: String,
) -> RunSummary {
    let attempts: Vec<&PickRecord> = records.iter().filter(|r| r.outcome.is_attempt()).collect();
    let placed: Vec<&PickRecord> = attempts
        .iter()
        .copied()
        .filter(|r| r.outcome == Outcome::Placed)
        .collect();
    let takts = takts_in_stats(records);
    let mean = |v: &mut dyn Iterator<Item = f64>| {
        let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
        if n == 0 { f64::NAN } else { s / n as f64 }
    };
    let in_takt = || placed.iter().filter(|r| !r.first_of_pile);
    let stalls = |f: fn(&PickRecord) -> f64| {
        let v: Vec<f64> = in_takt().map(|r| f(r)).filter(|s| *s > 1e-9).collect();
        (v.len(), v.iter().sum())
    };
    let count = |name: &str| attempts.iter().filter(|r| r.outcome.name() == name).count();
    RunSummary {
        reference_takt_s: reference_takt(&workpiece),
        workpiece,
        seed: opts.seed,
        deterministic: opts.deterministic,
        attempts: attempts.len(),
        placed: placed.len(),
        success_rate: if attempts.is_empty() {
            f64::NAN
        } else {
            placed.len() as f64 / attempts.len() as f64
        },
        takt: TaktStats::of(&takts),
        effective_takt_s: match release_span(records) {
            (_, 0) => f64::NAN,
            (t, n) => t / n as f64,
        },
        mean_pick_s: mean(&mut placed.iter().map(|r| r.pick_s)),
        mean_place_s: mean(&mut placed.iter().map(|r| r.place_s)),
        mean_compute_s: [
            mean(&mut attempts.iter().map(|r| r.grasp_compute_s)),
            mean(&mut attempts.iter().map(|r| r.pick_compute_s)),
            mean(&mut attempts.iter().map(|r| r.place_compute_s)),
        ],
        sensor_stalls: stalls(|r| r.stall_sensor_s),
        compute_stalls: stalls(|r| r.stall_compute_s),
        protective_stops: count("protective_stop"),
        collisions: count("collision"),
        drops: count("dropped"),
        parts_lost: cell.parts_lost,
        captures: (cell.sensor.triggered, cell.sensor.spoiled),
        refills,
        place_tray_exchanges,
        peak_torque_ratio: records.iter().map(|r| r.peak_torque_ratio).fold(0.0, f64::max),
        max_tracking_error_deg: records.iter().map(|r| r.max_tracking_error_deg).fold(0.0, f64::max),
        ended,
        sim_time_s: cell.world.time_s,
    }
}
