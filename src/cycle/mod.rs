//! The cell cycle: capture, recognise, select a grasp, plan and accelerate, Pick, Place, repeat.
//!
//! Job: run picks of one workpiece end to end in the simulated cell and time them, following the
//! reference system's time chart (its Fig. 3). The arm is driven by the torque-limited servo
//! ([`crate::servo`]) whose joint states move the arm's bodies in the physics world every
//! physics step, so the arm pushes parts and hides them from the sensor.
//!
//! The cycle is a constant [`Cell`] (robot, scene, grasp selector, servo, budgets, place slots)
//! and a mutable [`CellState`] (the world, the sensor's pending capture, the arm's state, the
//! spots where grasps failed, the trays' state). One pick, in the order the files take it:
//!
//! 1. [`sensing`]: the capture is triggered at the first physics step of the previous Place at
//!    which the arm has left the camera's view frustum (or, at the start and after a failure, as
//!    soon as the arm is out of view). The recognition result arrives `latency_s` after the
//!    trigger. A capture spoiled by motion in the scene is repeated when its exposure is over.
//! 2. [`motions`]: from the result, grasp selection ([`crate::pipeline::sense_and_grasp`]), then the
//!    Pick motion (transfer to the approach pose, straight descent, straight lift) is planned
//!    and accelerated; the Place motion (transfer to above the slot, straight descent, straight
//!    retreat) is planned next, while the Pick runs. Compute is charged to the simulation
//!    clock: fixed budgets from the cell file with `deterministic`, the measured wall time of
//!    our own code otherwise.
//! 3. [`pick_place`]: Pick: transfer, descent, vacuum on and build-up, lift. Place: transfer,
//!    descent, release, retreat. The arm waits only when the next motion is not ready: a stall,
//!    split into waiting for the sensor and waiting for compute. At a release the next pick may
//!    be prepared at once, its Pick starting while this Place's retreat ends (`next_pick`).
//! 4. [`play`]: each motion is played through the servo into the world as a segment (its
//!    motion, payload, valve switch, how it ends, whether a capture may run). Faults: a
//!    protective stop, a collision of the arm (or the held part) with the cell or a part
//!    pressed into the tray (the world's health monitor), a part slipping off the cup. Each ends
//!    the pick with its outcome ([`outcome`]: the cause as the type that found it); after a stop or a collision the arm waits the reset time and
//!    retraces its path out. Parts pushed out of a tray are taken out of the cell as lost. A
//!    physics fault (a non-finite state, a pour failing the health monitor) ends the run, not its
//!    caller: [`run`] returns the tally so far with the fault's record ([`PhysicsFault`]).
//! 5. [`trays`]: nothing detected or nothing graspable: re-capture; after
//!    `empty_after_captures` in a row the cell file's policy exchanges the pick tray for a full
//!    one (`refill_s`) or ends the run. A full place tray is exchanged for an empty one.
//! 6. [`records`]: each pick's record and the run's summary.
//!
//! Whoever watches a run (recordings, the time chart, the event log, a progress display) sees it
//! through one [`Observer`] ([`events`]).
//!
//! Held parts: the transfer, lift and descent motions with a part on the cup are slowed (a
//! uniform time scaling; lines by their acceleration) where the tool's turn and acceleration
//! would need more than [`SUCTION_MARGIN`] of the cup's holding force
//! ([`crate::geometry::SealBudget`]: pull, shear and peel, with the centre of mass of the grasp
//! as recognised, off by up to three standard deviations of the recognition's position noise).
//!
//! Units: s, m, rad. Frames: world.

pub mod events;
pub mod motions;
mod next_pick;
pub mod outcome;
pub mod pick_place;
pub mod play;
pub mod records;
pub mod sensing;
pub mod trays;

use nalgebra::{Isometry3, Vector3};

pub use crate::geometry::SUCTION_MARGIN;
pub use events::{
    CycleEvent, EndReason, Event, EventLog, IncidentKind, LeftDuring, Observer, Observers, PartLoss, PlacementError,
    Planned, Recognised, Stage, StallCause, StartMismatch, Takt,
};
pub use motions::{PLACE_APPROACH_M, RELEASE_ABOVE_M, above_place};
pub use outcome::{Fault, FaultDuring, MotionFailure, NoSeal, Outcome, PhysicsFault, Slip, Stop, WrongPose};
pub use records::{
    FIRST_PICKS, Faults, Incident, IntervalCause, Overlaps, PickRecord, RunResult, StageCompute, TaktCauses, Tally,
    Waits, takts,
};
pub use sensing::SensedResult;

use crate::config::{LoadedScene, LoadedWorkpiece, Scene};
use crate::grasp::GraspSelector;
use crate::physics::pile::PileOptions;
use crate::physics::suction::GripperEvent;
use crate::physics::{HealthError, PartShape, World};
use crate::robot::{Payload, RobotModel};
use crate::sensor::{CaptureJob, RecognitionReport, Sensor};
use crate::servo::Servo;
use motions::Unprepared;
use next_pick::Prefetched;

pub use crate::reference::reference_takt;

/// Why a run stopped early.
#[derive(Debug, thiserror::Error)]
pub enum CycleError {
    /// The workpiece's shape could not be built.
    #[error(transparent)]
    Shape(#[from] crate::physics::ShapeError),
    /// The physics world failed beyond recovery (a non-finite state).
    #[error("physics: {0}")]
    Health(#[from] HealthError),
    /// Pouring a pile (the first or a refill) failed the world's health check (a deep
    /// penetration between poured parts, a part poured out of the tray).
    #[error("physics while pouring a pile: {0}")]
    Pour(HealthError),
    /// Something the cycle needs is missing or impossible (place slots, sensor pose, waiting
    /// pose).
    #[error(transparent)]
    Setup(#[from] SetupError),
}

/// What the cell file asks for that the cycle cannot set up.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// The place tray holds no slot for the workpiece.
    #[error("no place slot for this workpiece")]
    NoPlaceSlot,
    /// The sensor's pose gives no camera.
    #[error("degenerate sensor pose")]
    DegenerateSensorPose,
    /// The tool cannot point down at the waiting pose.
    #[error("cycle.waiting_tool_m = {at_m:?}: the tool cannot point down there ({why})")]
    WaitingPoseUnreachable {
        /// `cycle.waiting_tool_m` (m).
        at_m: [f64; 3],
        /// The inverse kinematics' answer.
        why: crate::robot::IkError,
    },
    /// The arm at the waiting pose is in the sensor's view.
    #[error("cycle.waiting_tool_m = {at_m:?}: the arm's {what} is in the sensor's view there")]
    WaitingPoseInView {
        /// `cycle.waiting_tool_m` (m).
        at_m: [f64; 3],
        /// The arm's body in the view.
        what: String,
    },
    /// The cell was not resolved for the workpiece's own cup ([`LoadedScene::for_workpiece`]):
    /// its stages would read the cell's cup instead of the one the workpiece runs with.
    #[error("the cell is not resolved for the workpiece's own gripper (LoadedScene::for_workpiece)")]
    ToolNotResolved,
    /// A slot spacing of the place tray's grid below the part's place footprint.
    #[error("{key} = {pitch_m} m is below the part's place footprint, {extent_m} m along it: the parts would overlap")]
    SlotPitchBelowFootprint {
        /// `place_tray.pitch_x_m` or `place_tray.pitch_y_m`.
        key: &'static str,
        /// The spacing (m).
        pitch_m: f64,
        /// The footprint's extent along it (m).
        extent_m: f64,
    },
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
    /// Set (by a Ctrl-C handler) to end the run after the pick under way: the results so far are
    /// returned and the summary says `interrupted`.
    pub stop: Option<&'static std::sync::atomic::AtomicBool>,
    /// Keep every pick's record and every recognition result's report in the result (`binpick
    /// run` writes them, a recording plays them). Without, a run keeps only its [`Tally`], so
    /// its memory does not grow with its picks beyond the tally's samples.
    pub keep_records: bool,
}

impl RunOptions {
    /// `picks` picks with seed `seed`, deterministic, to the end (no stop flag), keeping only
    /// the tally.
    pub fn deterministic(picks: usize, seed: u64) -> Self {
        RunOptions {
            picks,
            seed,
            deterministic: true,
            stop: None,
            keep_records: false,
        }
    }
}

/// The constant parts of the cell: what does not change while it runs.
pub struct Cell<'a> {
    /// The arm as the controller models it (nominal inertials, friction, armature).
    pub robot: &'a RobotModel,
    /// The arm as the plant is: the model with the cell file's model error, drawn once per run.
    pub plant: RobotModel,
    /// The arm as the motion accelerator budgets it: torque limits less `cycle.torque_margin`.
    pub accel_robot: RobotModel,
    /// The cell file.
    pub scene: &'a Scene,
    /// The grasp selector for this workpiece.
    pub selector: GraspSelector,
    /// The joint servo.
    pub servo: Servo,
    /// The hand on the flange (no part).
    pub hand: Payload,
    /// The part as the controller believes it on the cup: the nominal mass at the cup centre.
    pub nominal_part: Payload,
    /// The workpiece's shape and mass.
    pub shape: PartShape,
    /// The place slots in the world, in filling order.
    pub slots: Vec<Isometry3<f64>>,
    /// Compute budgets charged in deterministic mode: grasp selection, Pick and Place motion.
    pub budgets: StageCompute,
    /// Parts per pile.
    pub pile_count: usize,
    /// The workpiece (its model, for the sensor's recognition).
    pub workpiece: crate::config::Workpiece,
    /// Run options.
    pub opts: RunOptions,
    /// The waiting pose's joints (`cycle.waiting_tool_m`), if the cell file sets one.
    pub waiting_q: Option<crate::robot::JointVector>,
}

/// The arm as the cycle knows it between motions.
#[derive(Debug, Clone, Copy)]
pub struct ArmState {
    /// The arm's actual joint state and the servo's integral after the last motion.
    pub servo: crate::servo::ServoState,
    /// The joint velocity the last motion commanded at its end (rad/s); zero at rest.
    pub commanded_qd: crate::robot::JointVector,
    /// When the arm has nothing to do from (s).
    pub free_s: f64,
    /// Largest tracking error since the pick's motions began (rad).
    pub max_error_rad: f64,
    /// Largest |demanded torque| / limit per joint since the pick's motions began.
    pub peak_demand_ratio: [f64; crate::robot::DOF],
    /// Time some joint was saturated since the pick's motions began (s).
    pub saturated_s: f64,
}

impl ArmState {
    /// The arm stopped at `q`: the servo at rest there, no velocity commanded.
    pub fn rest_at(&mut self, q: crate::robot::JointVector) {
        self.servo = crate::servo::ServoState::at_rest(q);
        self.commanded_qd = crate::robot::JointVector::zeros();
    }
}

/// A pick that went into the pile, as the cell knows it: the part as recognised and the tool's
/// way in. A later pick from an image taken before it keeps clear of what it may have moved
/// (see `Run::usable` in the cycle's `next_pick` module).
#[derive(Debug, Clone)]
pub struct PickSpot {
    /// When the descent began (s).
    pub t_s: f64,
    /// The picked part as recognised: `world_from_part` (m).
    pub world_from_part: Isometry3<f64>,
    /// The tool's straight lines in and out, each from its top to the grasp: the tool's origin at
    /// its approach pose and at its grasp pose, and at the end of its lift and at its grasp
    /// pose (the same line where the tool came straight down) [m, world].
    pub tool_lines_m: [[Vector3<f64>; 2]; 2],
}

/// The mutable state of the cell.
pub struct CellState {
    /// The physics world: trays, parts, the arm's bodies, the gripper.
    pub world: World,
    /// The sensor (its capture counters).
    pub sensor: Sensor,
    /// The capture being exposed or processed.
    pub pending: Option<CaptureJob>,
    /// The arm.
    pub arm: ArmState,
    /// Grasp points where a pick failed at the part, in this pile [m, world].
    pub failed_spots: Vec<Vector3<f64>>,
    /// Where the part being lifted or placed sits on the tool, as its grasp recognised it
    /// (`tool_from_part`): with a part on the cup, a capture's self-filter masks it there.
    pub held_tool_from_part: Option<Isometry3<f64>>,
    /// The maps of the capture the last grasp was chosen on.
    pub sensed: Option<crate::pipeline::SensedPile>,
    /// Gripper events seen while a motion played (a seal decided before the descent settled).
    pub gripper_events: Vec<GripperEvent>,
    /// The trays' state.
    pub trays: trays::TrayState,
    /// The pick under way.
    pub pick: Option<usize>,
    /// Parts lost out of the trays.
    pub parts_lost: usize,
    /// The run's incidents so far.
    pub incidents: Vec<Incident>,
    /// Largest |demanded torque| / limit per joint over the run.
    pub run_peak_demand_ratio: [f64; crate::robot::DOF],
    /// The picks so far, and every recognition result evaluated against the truth at its
    /// trigger (evaluation only), tallied.
    pub tally: Tally,
    /// Every recognition result's report, without its per-detection matches, if the run keeps
    /// its records (evaluation only).
    pub recognitions: Vec<RecognitionReport>,
    /// The newest recognition result and how many picks came from it (several picks per
    /// capture).
    pub in_hand: Option<InHand>,
    /// Each pick that went into the pile since the last pour or agitation: a result is only
    /// picked from clear of the picks made after its trigger.
    pub pick_spots: Vec<PickSpot>,
    /// When compute for the next pick may start (s): the start of the last Place that went as
    /// planned (the arm's remaining motion and where it ends are known then), else when the
    /// last pick ended.
    pub compute_from_s: f64,
    /// The joint position the last Place's retreat was planned to end at (the next Pick is
    /// planned from it when its compute starts before the retreat ends).
    pub planned_end_q: Option<crate::robot::JointVector>,
    /// Recognition results taken into hand so far.
    pub results_collected: usize,
    /// No capture is triggered before this (s): a part let go over the pick tray is still
    /// falling into the pile and would blur the image.
    pub capture_hold_until_s: f64,
    /// Captures in a row taken for a pile in motion (at most [`sensing::MOTION_RECAPTURES`] are).
    pub moving_in_a_row: usize,
    /// Parts released over their slots, measured once they rest.
    settling: Vec<next_pick::Settling>,
    /// Their placement errors, measured, not yet written into the tally and the records.
    measured: Vec<PlacementError>,
}

impl CellState {
    /// The part on the cup as the controller knows it: its grasp's `tool_from_part` while the
    /// vacuum holds a part, `None` with the cup empty.
    pub fn held_part_estimate(&self) -> Option<Isometry3<f64>> {
        self.world.held_part().and(self.held_tool_from_part)
    }
}

/// A recognition result in hand.
pub struct InHand {
    /// The result.
    pub result: SensedResult,
    /// Picks that came from it so far.
    pub taken: usize,
}

/// A running cycle: the constant cell, its state, and who watches.
struct Run<'a, 'o> {
    cell: &'a Cell<'a>,
    st: CellState,
    obs: &'o mut dyn Observer,
}

impl Run<'_, '_> {
    /// Reports an event now.
    fn event(&mut self, event: Event) {
        self.event_at(self.st.world.time_s(), event);
    }

    /// Reports an event at time `t_s`, of the pick under way (a misplaced part's: the pick that
    /// placed it, measured late); an incident is also listed for the tally.
    fn event_at(&mut self, t_s: f64, event: Event) {
        let pick = match &event {
            Event::Misplaced(m) => Some(m.pick),
            _ => self.st.pick,
        };
        if let Some(kind) = event.incident_kind() {
            self.st.incidents.push(Incident {
                seed: self.cell.opts.seed,
                pick,
                t_s,
                kind,
                detail: event.to_string(),
            });
        }
        self.obs.event(t_s, pick, &event);
    }

    /// Reports a busy interval of a stage (if it has a positive length).
    fn span(&mut self, stage: Stage, start_s: f64, end_s: f64, label: &str) {
        if end_s > start_s {
            self.obs.span(stage, start_s, end_s, label);
        }
    }
}

impl<'a> Cell<'a> {
    /// The cell of `scene` for `workpiece`. `scene` must be resolved for the workpiece's own cup
    /// ([`LoadedScene::for_workpiece`], as [`run`] does): every stage reads its one gripper.
    pub fn new(
        scene: &'a LoadedScene,
        robot: &'a RobotModel,
        workpiece: &LoadedWorkpiece,
        opts: RunOptions,
    ) -> Result<Self, CycleError> {
        let wp = &workpiece.workpiece;
        let s = &scene.scene;
        if !s.is_set_up_for(wp) {
            return Err(SetupError::ToolNotResolved.into());
        }
        let selector = GraspSelector::for_workpiece(s, robot, workpiece);
        if s.place_tray.pattern == crate::config::SlotPattern::Grid
            && let Some((key, pitch_m, extent_m)) = s.place_tray.pitch_below_footprint(selector.place_footprint_m())
        {
            return Err(SetupError::SlotPitchBelowFootprint { key, pitch_m, extent_m }.into());
        }
        let slots = s.world_from_slots_for(wp, selector.place_footprint_m());
        if slots.is_empty() {
            return Err(SetupError::NoPlaceSlot.into());
        }
        let shape = PartShape::build(wp, &workpiece.source)?;
        let waiting_q = waiting_joints(s, robot, &shape)?;
        Ok(Cell {
            robot,
            plant: robot.with_model_error(&s.model_error, opts.seed),
            accel_robot: robot.with_torque_share(1.0 - s.cycle.torque_margin),
            scene: s,
            selector,
            // The controller compensates the share of its friction model it is sure of.
            servo: Servo::from_config(&s.sim).with_friction_compensation(1.0 - s.model_error.joint_friction_fraction),
            hand: Payload::from_gripper(&s.gripper),
            nominal_part: Payload::point(wp.mass_kg, robot.flange_from_tool.translation.vector),
            shape,
            slots,
            budgets: StageCompute {
                grasp_s: s.compute.grasp_estimation_s,
                pick_s: s.compute.motion_generation_s,
                place_s: s.compute.motion_generation_s,
            },
            pile_count: wp.pile_count as usize,
            workpiece: wp.clone(),
            opts,
            waiting_q,
        })
    }

    /// The cell's state at the start: the world with its first pile poured and the sensor over it.
    /// A part the pour spills out of the tray is lost, as in a refill or a dose.
    pub fn start(&self, obs: &mut dyn Observer) -> Result<CellState, CycleError> {
        let mut world = World::new(self.scene, self.robot, self.shape.clone());
        let pile = PileOptions::cells_first_pile(self.pile_count, self.opts.seed);
        let spilled = world
            .build_pile_observed(&pile, &mut |w| obs.stepped(w))
            .map_err(CycleError::Pour)?
            .spilled;
        let sensor = Sensor::new(&self.scene.sensor, &world, self.opts.seed, &self.workpiece)
            .ok_or(SetupError::DegenerateSensorPose)?;
        let st = CellState {
            arm: ArmState {
                servo: crate::servo::ServoState::at_rest(world.joints()),
                commanded_qd: crate::robot::JointVector::zeros(),
                free_s: world.time_s(),
                max_error_rad: 0.0,
                peak_demand_ratio: [0.0; crate::robot::DOF],
                saturated_s: 0.0,
            },
            world,
            sensor,
            pending: None,
            failed_spots: Vec::new(),
            held_tool_from_part: None,
            sensed: None,
            gripper_events: Vec::new(),
            trays: trays::TrayState::default(),
            pick: None,
            parts_lost: 0,
            incidents: Vec::new(),
            run_peak_demand_ratio: [0.0; crate::robot::DOF],
            tally: Tally::default(),
            recognitions: Vec::new(),
            in_hand: None,
            pick_spots: Vec::new(),
            compute_from_s: 0.0,
            planned_end_q: None,
            results_collected: 0,
            capture_hold_until_s: f64::NEG_INFINITY,
            moving_in_a_row: 0,
            settling: Vec::new(),
            measured: Vec::new(),
        };
        let mut run = Run { cell: self, st, obs };
        run.lose_spilled(spilled);
        Ok(run.st)
    }
}

/// The joints of the cell's waiting pose (`cycle.waiting_tool_m`; `None` when the cell sets
/// none), checked: the tool can point straight down there (nearest to home), and the arm there
/// leaves the sensor's view over the pick tray free (on a scratch world of `shape`'s parts).
pub fn waiting_joints(
    scene: &Scene,
    robot: &RobotModel,
    shape: &PartShape,
) -> Result<Option<crate::robot::JointVector>, SetupError> {
    let Some(w) = scene.cycle.waiting_tool_m else {
        return Ok(None);
    };
    let home = crate::robot::JointVector::from(scene.robot.home_rad());
    let pose = crate::robot::tool_down_pose(Vector3::from(w), 0.0);
    let q = robot
        .ik_tool_nearest(&pose, &home)
        .map_err(|why| SetupError::WaitingPoseUnreachable { at_m: w, why })?
        .q;
    let mut scratch = World::new(scene, robot, shape.clone());
    scratch.place_arm(&q);
    let camera = crate::sensor::Camera::from_config(&scene.sensor).ok_or(SetupError::DegenerateSensorPose)?;
    let frustum =
        crate::sensor::ViewFrustum::over_tray(scratch.pick_tray(), &camera).ok_or(SetupError::DegenerateSensorPose)?;
    if let Some(what) = frustum.arm_inside(&scratch) {
        return Err(SetupError::WaitingPoseInView { at_m: w, what });
    }
    Ok(Some(q))
}

/// [`waiting_joints`] as a check of the cell file `label` before anything runs: a waiting pose
/// the tool cannot reach pointing down, or one that puts the arm in the sensor's view, is
/// refused naming the file, `cycle.waiting_tool_m` and its value.
pub fn check_waiting_pose(
    label: &str,
    scene: &Scene,
    robot: &RobotModel,
    shape: &PartShape,
) -> Result<(), crate::config::ConfigError> {
    match waiting_joints(scene, robot, shape) {
        Ok(_) => Ok(()),
        Err(e @ (SetupError::WaitingPoseUnreachable { .. } | SetupError::WaitingPoseInView { .. })) => {
            let text = e.to_string();
            let msg = text.strip_prefix("cycle.waiting_tool_m ").unwrap_or(&text);
            Err(crate::config::ConfigError::one(label, "cycle.waiting_tool_m", msg))
        }
        Err(e) => Err(crate::config::ConfigError::one(label, "", e.to_string())),
    }
}

/// Runs `opts.picks` picks of `workpiece` in the cell of `scene` (resolved for the cup the
/// workpiece brings, if any: [`LoadedScene::for_workpiece`]), watched by `obs`. A physics
/// fault (a pour's deep penetration, a non-finite state) ends the run, not the caller: its
/// tally so far is returned, `ended` [`EndReason::PhysicsFault`] and the fault in
/// `physics_faults`.
pub fn run(
    scene: &LoadedScene,
    robot: &RobotModel,
    workpiece: &LoadedWorkpiece,
    opts: &RunOptions,
    obs: &mut dyn Observer,
) -> Result<RunResult, CycleError> {
    let scene = scene.for_workpiece(workpiece);
    let cell = Cell::new(&scene, robot, workpiece, *opts)?;
    match cell.start(obs) {
        Ok(st) => run_from(&cell, st, obs),
        Err(CycleError::Pour(e)) => {
            let mut tally = Tally {
                workpiece: workpiece.workpiece.name.clone(),
                seed: opts.seed,
                pile_count: cell.pile_count,
                sim_time_s: e.time_s,
                runs: 1,
                ended: Some(EndReason::PhysicsFault),
                ..Tally::default()
            };
            let fault = PhysicsFault::new(&e, FaultDuring::Pour);
            tally.incidents.push(Incident {
                seed: opts.seed,
                pick: None,
                t_s: e.time_s,
                kind: IncidentKind::PhysicsFault,
                detail: Event::PhysicsFault(fault.clone()).to_string(),
            });
            tally.physics_faults.push(fault);
            Ok(RunResult {
                records: Vec::new(),
                tally,
                recognition_per_capture: Vec::new(),
            })
        }
        Err(e) => Err(e),
    }
}

/// Runs `cell.opts.picks` picks from the state `st` (as [`Cell::start`] leaves it, or changed by
/// the caller), watched by `obs`; a physics fault ends the run as in [`run`].
pub fn run_from(cell: &Cell<'_>, st: CellState, obs: &mut dyn Observer) -> Result<RunResult, CycleError> {
    let opts = &cell.opts;
    let mut run = Run { cell, st, obs };
    let mut records = Vec::new();
    // The parts placed last are measured once they rest (the world runs on until they do), or as
    // they lie after an interruption or a fault.
    let ended = run.picks(&mut records).and_then(|ended| match ended {
        EndReason::Interrupted => Ok(ended),
        _ => run.settle_placed().map(|()| ended),
    });
    run.measure_settled(true);
    run.apply_placements(&mut records);
    let (ended, fault) = match ended {
        Ok(ended) => (ended, None),
        Err(CycleError::Health(e)) => (EndReason::PhysicsFault, Some(PhysicsFault::new(&e, FaultDuring::Cycle))),
        Err(CycleError::Pour(e)) => (EndReason::PhysicsFault, Some(PhysicsFault::new(&e, FaultDuring::Pour))),
        Err(e) => return Err(e),
    };
    if let Some(f) = &fault {
        run.event(Event::PhysicsFault(f.clone()));
    }
    let st = &mut run.st;
    let mut tally = std::mem::take(&mut st.tally);
    tally.workpiece = cell.workpiece.name.clone();
    tally.seed = opts.seed;
    tally.pile_count = cell.pile_count;
    tally.faults.parts_lost = st.parts_lost;
    tally.captures = (st.sensor.triggered, st.sensor.spoiled);
    tally.refills = st.trays.refills;
    tally.doses = st.trays.doses;
    tally.agitations = st.trays.agitations;
    tally.place_tray_exchanges = st.trays.exchanges;
    tally.peak_demand_ratio = st.run_peak_demand_ratio;
    tally.sim_time_s = st.world.time_s();
    tally.runs = 1;
    tally.ended = Some(ended);
    tally.physics_faults.extend(fault);
    tally.incidents = std::mem::take(&mut st.incidents);
    Ok(RunResult {
        records,
        tally,
        recognition_per_capture: std::mem::take(&mut st.recognitions),
    })
}

/// The first recognition result of a fresh cell: the world with its pile, the arm moved out of
/// the view if needed, the capture triggered, spoiled exposures repeated, the result awaited, as
/// the cycle does before its first pick. `None` if the arm found no path out of the view.
pub fn sense_once(cell: &Cell<'_>, obs: &mut dyn Observer) -> Result<(CellState, Option<SensedResult>), CycleError> {
    let st = cell.start(obs)?;
    let mut run = Run { cell, st, obs };
    let sensed = run.next_result()?;
    Ok((run.st, sensed))
}

/// What the cell makes of a recognition result before its pick: the grasp it takes, its Pick
/// and Place motions generated (a grasp whose motions fail passed over for the next, as in a
/// run), or why it takes none.
#[derive(Debug, Clone)]
pub enum FirstPick {
    /// The grasp taken, after the failures of the grasps passed over (best-ranked first).
    Taken {
        grasp: Box<crate::grasp::GraspCandidate>,
        passed_over: Vec<MotionFailure>,
    },
    /// The recognition reported no part (the run re-captures).
    NothingDetected,
    /// No grasp to try: the grasp selector's reason.
    NoGrasp(crate::pipeline::NoGrasp),
    /// Grasps were chosen, but none of those tried has its motions: each one's failure.
    NoMotion(Vec<MotionFailure>),
}

impl FirstPick {
    /// The grasp taken, if any.
    pub fn taken(&self) -> Option<&crate::grasp::GraspCandidate> {
        match self {
            FirstPick::Taken { grasp, .. } => Some(grasp),
            _ => None,
        }
    }

    /// The failures of the grasps tried and passed over, best-ranked first.
    pub fn passed_over(&self) -> &[MotionFailure] {
        match self {
            FirstPick::Taken { passed_over, .. } | FirstPick::NoMotion(passed_over) => passed_over,
            FirstPick::NothingDetected | FirstPick::NoGrasp(_) => &[],
        }
    }
}

/// The cell's choice on `sensed` (from [`sense_once`], in `st`): grasp selection and motion
/// generation as the cycle runs them for a pick into the next place slot.
pub fn first_pick(cell: &Cell<'_>, st: CellState, sensed: &SensedResult) -> FirstPick {
    if sensed.detections.as_deref().is_none_or(<[_]>::is_empty) {
        return FirstPick::NothingDetected;
    }
    let mut run = Run { cell, st, obs: &mut () };
    let (t_s, slot) = (sensed.job.ready_s.max(run.st.compute_from_s), run.st.trays.next_slot);
    match run.prepare(sensed, t_s, slot, None) {
        Ok((prep, _)) => FirstPick::Taken {
            grasp: Box::new(prep.grasp),
            passed_over: prep.passed_over,
        },
        Err(Unprepared::NoGrasp { why, .. }) => FirstPick::NoGrasp(why),
        Err(Unprepared::NoMotion { failures, .. }) => FirstPick::NoMotion(failures),
    }
}

/// After the cell lets a part go over the pick tray (a pick that cannot be placed), no capture
/// is triggered for this long (s): the part drops a few centimetres, bounces and comes to rest in
/// about 0.2 s; an exposure meanwhile sees the pile moving (a C strip let go 90 ms before a
/// trigger blurred four detections, and the grasp on one of them pressed a part 2.6 mm into
/// another).
pub const LET_GO_SETTLE_S: f64 = 0.3;

impl Run<'_, '_> {
    /// Tallies a finished pick, and keeps its record if the run keeps them.
    fn keep(&mut self, records: &mut Vec<PickRecord>, rec: PickRecord) {
        self.st.tally.add(&rec);
        if rec.outcome != Outcome::Placed {
            self.st.trays.failed_since_release = true;
        }
        if let (Some(release_s), Some(takt_s)) = (rec.release_s, rec.takt_s) {
            self.obs.takt(&Takt {
                pick: rec.index,
                release_s,
                takt_s,
                spans_refill: rec.spans_refill,
            });
        }
        if self.cell.opts.keep_records {
            records.push(rec);
        }
    }

    /// The pick loop: until the asked-for attempts are made (every pick is one, a re-capture
    /// too) or the run ends otherwise.
    /// The picks' records go to `records` as each pick ends (kept there if a fault ends the
    /// run).
    fn picks(&mut self, records: &mut Vec<PickRecord>) -> Result<EndReason, CycleError> {
        let opts = self.cell.opts;
        // The next pick, prepared at the last release.
        let mut next: Option<Prefetched> = None;
        while self.st.tally.attempts < opts.picks {
            self.measure_settled(false);
            self.apply_placements(records);
            if opts.stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed)) {
                self.play_held_retreat(next.take())?;
                return Ok(EndReason::Interrupted);
            }
            let index = self.st.tally.attempts;
            self.st.pick = Some(index);
            // A dose called for on a pick that never reached its Place: the next fresh result
            // decides again.
            self.st.trays.dose_due = None;
            let (result, taken, since, compute_from_s, prepared) = match next.take() {
                // Prepared at the last release, its Pick overlapping that Place's retreat.
                Some(p) => (p.result, p.taken, p.since, p.compute_from_s, Ok((p.prep, p.wall))),
                None => {
                    let Some((result, taken, since)) = self.result_for_pick()? else {
                        return Ok(EndReason::NoPathOutOfView);
                    };
                    // A fresh result whose image shows few parts (the sensor's count, before
                    // the detections near picks made since are set aside): the hopper doses (if
                    // the cell has one), and the cell looks again; a dose that may run while the
                    // arm places waits for this pick's Place, if it has a grasp.
                    let seen = self.st.in_hand.as_ref().and_then(|h| h.result.detections.as_ref());
                    let low = match seen.map(Vec::len) {
                        Some(seen) if taken == 0 => self.dose_wanted(seen),
                        _ => None,
                    };
                    if let Some(parts) = low
                        && !self.dose_may_overlap(parts)
                    {
                        self.dose(parts)?;
                        continue;
                    }
                    self.event(Event::ResultUsed {
                        taken,
                        since_capture: since,
                    });
                    // Compute starts when both the result and the arm's motion up to the next
                    // pick are known: the result's arrival, or the start of the last Place if it
                    // went as planned.
                    let compute_from_s = result.job.ready_s.max(self.st.compute_from_s);
                    let prepared = match result.detections.as_deref() {
                        None | Some([]) => {
                            self.obs.recognised(&Recognised {
                                t_s: result.job.ready_s,
                                detections: &[],
                                judged: None,
                                ranked: &[],
                                chosen: None,
                            });
                            Err(None)
                        }
                        Some(_) => self
                            .prepare(&result, compute_from_s, self.st.trays.next_slot, None)
                            .map_err(Some),
                    };
                    if let Some(parts) = low {
                        if prepared.is_err() {
                            // Nothing to take from the few parts seen: dose now.
                            self.dose(parts)?;
                            continue;
                        }
                        self.st.trays.dose_due = Some(parts);
                    }
                    (result, taken, since, compute_from_s, prepared)
                }
            };
            let blind = since > 0;
            let mut rec = PickRecord::new(index, result.capture_s, result.job.ready_s);
            rec.blind = blind;
            rec.from_result = taken;
            rec.picks_since_capture = since;
            rec.recognition = result
                .evaluation
                .as_ref()
                .map(|e| (e.figures.detected, e.figures.correct));
            let (prep, wall) = match prepared {
                Ok(p) => p,
                Err(why) if blind || taken > 0 => {
                    // Nothing graspable among the parts clear of the picks since the capture: the
                    // cell decides so (charged at the grasp selection's budget, and the motions'
                    // of the grasps it tried) and takes the next result; no pick was attempted.
                    self.st.in_hand = None;
                    self.wait_out_unprepared(why.as_ref(), compute_from_s)?;
                    self.st.compute_from_s = self.st.world.time_s();
                    continue;
                }
                Err(why) => {
                    self.st.in_hand = None;
                    if why.is_some() {
                        // The compute spent on the grasp selection (and on the motions of the
                        // grasps tried) runs out before the cell decides that none is taken.
                        rec.compute.grasp_s = self.wait_out_unprepared(why.as_ref(), compute_from_s)?;
                    }
                    rec.outcome = match why {
                        None => Outcome::NothingDetected,
                        Some(Unprepared::NoGrasp { why, .. }) => Outcome::NothingGraspable(why),
                        Some(Unprepared::NoMotion { failures, .. }) => {
                            for failure in &failures {
                                self.event(Event::Planned(Planned::Failed { why: failure.clone() }));
                            }
                            Outcome::NoMotion(failures[0].clone())
                        }
                    };
                    self.event(Event::Outcome(rec.outcome.clone()));
                    self.keep(records, rec);
                    if let Some(end) = self.nothing_to_pick()? {
                        return Ok(end);
                    }
                    self.st.compute_from_s = self.st.world.time_s();
                    continue;
                }
            };
            // Evaluation only: how far the chosen detection was from the part it is nearest to.
            rec.aimed_at = result
                .evaluation
                .as_ref()
                .and_then(|e| e.matches.get(prep.grasp.detection).copied().flatten());
            self.st.trays.attempted();
            let charged = self.cell.charged(wall, prep.passed_over.len());
            if let Some(h) = self.st.in_hand.as_mut() {
                h.taken += 1;
            }
            let chosen = result
                .detections
                .as_deref()
                .map(|d| d[prep.grasp.detection].world_from_part);
            next = self.pick_and_place(&prep, charged, compute_from_s, chosen, &mut rec)?;
            if !(rec.outcome == Outcome::Placed || rec.outcome.grasp_failed()) {
                // The pile may have been disturbed anywhere: no result from before counts.
                self.st.in_hand = None;
                self.st.pending = None;
            }
            self.keep(records, rec);
        }
        self.play_held_retreat(next)?;
        Ok(EndReason::PicksDone)
    }

    /// Writes the placement errors measured since the last call into the tally and the records.
    fn apply_placements(&mut self, records: &mut [PickRecord]) {
        for fix in std::mem::take(&mut self.st.measured) {
            apply_placement_fix(records, &mut self.st.tally, fix);
        }
    }
}

/// Writes a placement error (measured once the part rested, after its pick's record was
/// tallied) into the tally and into the kept record it belongs to.
fn apply_placement_fix(records: &mut [PickRecord], tally: &mut Tally, fix: PlacementError) {
    let (error_mm, rotation_deg) = (fix.error_m * 1e3, fix.rotation_rad.to_degrees());
    tally.placement_error_mm.push(error_mm);
    tally.placement_rotation_deg.push(rotation_deg);
    if let Some(r) = records.get_mut(fix.pick) {
        r.placement_error_mm = Some(error_mm);
        r.rotation_error_deg = Some(rotation_deg);
    }
}
