//! The cell cycle: capture, recognise, select a grasp, plan and accelerate, Pick, Place, repeat.
//!
//! Job: run picks of one workpiece end to end in the simulated cell and time them. The arm is
//! driven by the torque-limited servo ([`crate::execution`]) whose joint states move the arm's
//! bodies in the physics world every physics step, so the arm pushes parts and hides them from the
//! sensor. The next capture is triggered at the first physics step of the Place motion at which
//! the arm has left the camera's view frustum; its recognition result arrives `latency_s` later.
//! Grasp selection and motion generation start when the result is available and are charged to
//! the simulation clock: fixed budgets from the cell file in deterministic mode, measured wall
//! time otherwise. The arm waits only when the next motion is not ready: that wait is a stall.
//!
//! Takt of a pick = time between consecutive successful releases. Units: s, m, rad.
//!
//! Simplifications of this first slice (stated in the README): straight descents and lifts at
//! 30 % of top speed; one grasp attempt per recognition result; a failed grasp re-captures.

use std::time::Instant;

use nalgebra::{Isometry3, Translation3, Vector3};
use serde::Serialize;

use crate::config::{LoadedScene, LoadedWorkpiece};
use crate::execution::{Servo, execute};
use crate::grasp::GraspSelector;
use crate::physics::pile::PileOptions;
use crate::physics::suction::GripperEvent;
use crate::physics::{PartShape, World};
use crate::planning::{CollisionModel, Environment, PileColumns, PlanOptions, RobotSpheres};
use crate::robot::{JointVector, Payload, RobotModel};
use crate::sensor::{CaptureJob, HeightMap, Sensor};
use crate::trajectory::{Motion, MotionLimits, Trajectory, accelerate_in_corridor};

/// Why a run stopped early.
#[derive(Debug, thiserror::Error)]
pub enum CycleError {
    /// The workpiece's shape could not be built.
    #[error(transparent)]
    Shape(#[from] crate::physics::ShapeError),
    /// The physics world failed its health check.
    #[error("physics: {0}")]
    Health(#[from] crate::physics::HealthError),
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
    /// No graspable part in the recognition result.
    NothingGraspable,
    /// No path or trajectory for the motion (reason).
    NoMotion(String),
    /// The servo tripped a protective stop (reason).
    ProtectiveStop(String),
    /// The part came off the cup on the way (reason).
    Dropped(String),
}

/// One pick.
#[derive(Debug, Clone, Serialize)]
pub struct PickRecord {
    /// Index.
    pub index: usize,
    /// Outcome.
    pub outcome: Outcome,
    /// When the part was released [s] (placed picks).
    pub release_s: Option<f64>,
    /// Time since the previous successful release [s].
    pub takt_s: Option<f64>,
    /// Pick motion time (to the approach pose) [s].
    pub pick_motion_s: f64,
    /// Place motion time (approach pose to above the slot) [s].
    pub place_motion_s: f64,
    /// Time the arm waited for the next motion [s].
    pub stall_s: f64,
    /// Compute charged: grasp selection, planning and acceleration [s].
    pub compute_s: f64,
    /// Horizontal placement error [m] and yaw error [rad] (placed picks).
    pub placement_error: Option<(f64, f64)>,
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
    /// Picks attempted.
    pub picks: usize,
    /// Picks placed.
    pub placed: usize,
    /// Mean, p95, min, max takt over the placed picks after the first [s].
    pub takt_s: (f64, f64, f64, f64),
    /// Captures triggered and spoiled.
    pub captures: (u64, u64),
    /// Total stall time [s].
    pub stall_s: f64,
    /// Simulated time [s].
    pub sim_time_s: f64,
    /// The reference system's takt for this workpiece [s], if it is one of A..F.
    pub reference_takt_s: Option<f64>,
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
}

struct Cell {
    world: World,
    robot: RobotModel,
    sensor: Sensor,
    selector: GraspSelector,
    servo: Servo,
    hand: Payload,
    shape: PartShape,
    slots: Vec<Isometry3<f64>>,
    scene: crate::config::Scene,
    job: Option<CaptureJob>,
    /// When the arm has nothing to do until [s].
    arm_free_s: f64,
}

fn reference_takt(name: &str) -> Option<f64> {
    match name {
        "A" => Some(2.9),
        "B" => Some(2.7),
        "C" | "D" | "E" => Some(2.9),
        "F" => Some(3.0),
        _ => None,
    }
}

impl Cell {
    /// Steps the world to `t` with the arm still, watching the capture.
    fn idle_until(&mut self, t: f64) -> Result<(), CycleError> {
        while self.world.time_s + 1e-9 < t {
            self.world.step()?;
            self.watch();
        }
        Ok(())
    }

    fn watch(&mut self) {
        if let Some(job) = self.job.as_mut() {
            self.sensor.watch(job, &self.world);
        }
    }

    /// Triggers a capture if none is pending and the arm is out of view.
    fn maybe_trigger(&mut self) {
        if self.job.as_ref().is_some_and(|j| j.spoiled.is_none()) {
            return;
        }
        if let Ok(job) = self.sensor.trigger(&self.world) {
            self.job = Some(job);
        }
    }

    /// Plays a motion through the servo into the world; `trigger` polls for the next capture.
    fn play(
        &mut self,
        motion: &impl Motion,
        payload: &Payload,
        trigger: bool,
    ) -> Result<Result<f64, Outcome>, CycleError> {
        let dynamics = self.robot.dynamics(payload);
        let run = execute(&self.robot, &dynamics, &dynamics, &self.servo, motion);
        let per_step = (self.world.dt_s() / self.servo.dt_s).round().max(1.0) as usize;
        let t0 = self.world.time_s;
        let mut k = per_step;
        while k < run.ticks.len() + per_step {
            let tick = &run.ticks[k.min(run.ticks.len() - 1)];
            self.world.set_joint_target(&tick.q);
            self.world.step()?;
            self.watch();
            if trigger {
                self.maybe_trigger();
            }
            for ev in self.world.gripper.take_events() {
                if let GripperEvent::Slipped {
                    required_n, holding_n, ..
                } = ev
                {
                    return Ok(Err(Outcome::Dropped(format!(
                        "slipped: {required_n:.2} N needed, {holding_n:.2} N held"
                    ))));
                }
            }
            k += per_step;
        }
        if let Some((t, trip)) = run.trip {
            return Ok(Err(Outcome::ProtectiveStop(format!(
                "{trip:?} at {t:.3} s into the motion"
            ))));
        }
        Ok(Ok(self.world.time_s - t0))
    }

    /// A straight tool line from the current pose to `goal`, at 30 % of top speed.
    fn line(&self, goal: &Isometry3<f64>) -> Option<Trajectory> {
        let start = self.world.world_from_tool();
        let mut q = self.world.joints();
        let mut via = vec![q];
        for s in 1..=6 {
            let pose = start.lerp_slerp(goal, s as f64 / 6.0);
            q = self.robot.ik_tool_nearest(&pose, &q).ok()?.q;
            via.push(q);
        }
        let limits = MotionLimits {
            vel_rad_s: self.robot.max_vel_rad_s() * 0.3,
            accel_rad_s2: self.robot.max_accel_rad_s2() * 0.3,
        };
        Some(Trajectory::through(&via, &limits))
    }
}

/// Runs `opts.picks` picks of `workpiece` in the cell of `scene`.
pub fn run(
    scene: &LoadedScene,
    robot: &RobotModel,
    workpiece: &LoadedWorkpiece,
    opts: &RunOptions,
) -> Result<(Vec<PickRecord>, RunSummary), CycleError> {
    let shape = PartShape::build(&workpiece.workpiece, &workpiece.source)?;
    let mut world = World::new(&scene.scene, robot, shape.clone());
    world.build_pile(&PileOptions::new(workpiece.workpiece.pile_count as usize, opts.seed))?;
    let sensor = Sensor::new(&scene.scene.sensor, &world, opts.seed)
        .ok_or_else(|| CycleError::Setup("degenerate sensor pose".into()))?;
    let slots = scene.scene.world_from_slots(&workpiece.workpiece);
    if slots.is_empty() {
        return Err(CycleError::Setup("no place slot for this workpiece".into()));
    }
    let mut cell = Cell {
        arm_free_s: world.time_s,
        world,
        robot: robot.clone(),
        sensor,
        selector: GraspSelector::new(&scene.scene, robot, &workpiece.workpiece),
        servo: Servo::from_config(&scene.scene.sim),
        hand: Payload::from_gripper(&scene.scene.gripper),
        shape,
        slots,
        scene: scene.scene.clone(),
        job: None,
    };
    let budgets = (
        scene.scene.compute.grasp_estimation_s,
        scene.scene.compute.motion_generation_s,
    );
    let mut records: Vec<PickRecord> = Vec::new();
    let mut last_release: Option<f64> = None;
    let mut placed = 0usize;
    cell.maybe_trigger();
    for index in 0..opts.picks {
        let mut rec = PickRecord {
            index,
            outcome: Outcome::Placed,
            release_s: None,
            takt_s: None,
            pick_motion_s: 0.0,
            place_motion_s: 0.0,
            stall_s: 0.0,
            compute_s: 0.0,
            placement_error: None,
        };
        // The recognition result: re-trigger if none is pending (moving the arm home first if
        // it is in view, after a failed pick), then wait for it.
        cell.maybe_trigger();
        if cell.job.is_none() {
            let home = JointVector::from(cell.scene.robot.home_rad());
            let free = CollisionModel::new(
                robot,
                RobotSpheres::new(robot, &cell.scene, None),
                Environment::from_scene(&cell.scene),
            );
            let mut rng = crate::rng::stream(opts.seed + index as u64, "planner-home");
            let hand = cell.hand;
            if let Ok(p) = free.plan(&cell.world.joints(), &home, &PlanOptions::default(), &mut rng) {
                let via: Vec<JointVector> = p.waypoints.iter().map(|q| JointVector::from(*q)).collect();
                let (_, acc, _) = accelerate_in_corridor(robot, &robot.dynamics(&hand), &via, &free, 0.01);
                cell.play(&acc.trajectory, &hand, true)?.ok();
            }
            cell.arm_free_s = cell.world.time_s;
            cell.maybe_trigger();
        }
        let Some(job) = cell.job.clone() else {
            return Err(CycleError::Setup("the arm cannot leave the sensor's view".into()));
        };
        let ready = job.ready_s;
        let wall = Instant::now();
        cell.idle_until(ready)?;
        let detections = match cell.sensor.result(&job, &cell.world) {
            Some(d) => d,
            None => {
                cell.job = None;
                rec.outcome = Outcome::NothingGraspable;
                records.push(rec);
                continue;
            }
        };
        cell.job = None;
        // Grasp selection, then the Pick motion: planned and accelerated.
        let hm = HeightMap::from_capture(&job.capture, &cell.world, 0.002);
        let slot = cell.slots[placed % cell.slots.len()];
        let q_now = cell.world.joints();
        let plan = cell.selector.select(&detections, &hm, &slot, &q_now);
        // The best grasp whose approach pose is clear in the planner's (conservative) model.
        let mut chosen = None;
        for g in plan.ranked.iter().take(8) {
            let local = cell.world.pick_tray.world_from_tray.inverse()
                * nalgebra::Point3::from(g.world_from_tool.translation.vector);
            let mut env = Environment::from_scene(&cell.scene);
            env.pile = Some(PileColumns::new(&hm, 5, Some((local.x, local.y, 0.02))));
            let model = CollisionModel::new(robot, RobotSpheres::new(robot, &cell.scene, None), env.clone());
            if model.free(
                &JointVector::from(g.q_approach),
                &mut crate::planning::PlanStats::default(),
            ) {
                chosen = Some((g.clone(), env, model));
                break;
            }
        }
        let Some((grasp, env, empty)) = chosen else {
            rec.outcome = Outcome::NothingGraspable;
            records.push(rec);
            continue;
        };
        let mut rng = crate::rng::stream(opts.seed + index as u64, "planner");
        let q_approach = JointVector::from(grasp.q_approach);
        let pick_path = empty.plan(&q_now, &q_approach, &PlanOptions::default(), &mut rng);
        let compute_wall = wall.elapsed().as_secs_f64();
        let compute = if opts.deterministic {
            budgets.0 + budgets.1
        } else {
            compute_wall
        };
        rec.compute_s = compute;
        let motion_ready = ready + compute;
        rec.stall_s = (motion_ready - cell.arm_free_s).max(0.0);
        cell.idle_until(motion_ready.max(cell.world.time_s))?;
        let pick_path = match pick_path {
            Ok(p) => p,
            Err(e) => {
                rec.outcome = Outcome::NoMotion(format!("pick: {e}"));
                records.push(rec);
                continue;
            }
        };
        let via: Vec<JointVector> = pick_path.waypoints.iter().map(|q| JointVector::from(*q)).collect();
        let dyn_hand = robot.dynamics(&cell.hand);
        let (_, pick, _) = accelerate_in_corridor(robot, &dyn_hand, &via, &empty, 0.01);
        let hand = cell.hand;
        match cell.play(&pick.trajectory, &hand, false)? {
            Ok(t) => rec.pick_motion_s = t,
            Err(o) => {
                rec.outcome = o;
                records.push(rec);
                continue;
            }
        }
        // Descent to the measured surface, vacuum, lift.
        let press = grasp.world_from_tool;
        let Some(down) = cell.line(&press) else {
            rec.outcome = Outcome::NoMotion("descent: no joint path along the line".into());
            records.push(rec);
            continue;
        };
        if let Err(o) = cell.play(&down, &hand, false)? {
            rec.outcome = o;
            records.push(rec);
            continue;
        }
        cell.world.vacuum_on();
        let t = cell.world.time_s + cell.world.gripper.build_up_s + cell.world.dt_s();
        cell.idle_until(t)?;
        let mut sealed = false;
        for ev in cell.world.gripper.take_events() {
            match ev {
                GripperEvent::Grasped { .. } => sealed = true,
                GripperEvent::GraspFailed { reason, .. } => rec.outcome = Outcome::GraspFailed(reason.to_string()),
                GripperEvent::Slipped { required_n, .. } => {
                    rec.outcome = Outcome::Dropped(format!("slipped at rest: {required_n:.2} N"))
                }
                GripperEvent::Released { .. } => {}
            }
        }
        let held = cell.world.held_payload().map(|p| hand.combined(&p));
        let up = cell.line(&grasp.world_from_tool_approach);
        if !sealed || held.is_none() {
            cell.world.vacuum_off();
            if let Some(up) = up {
                cell.play(&up, &hand, false)?.ok();
            }
            cell.arm_free_s = cell.world.time_s;
            if rec.outcome == Outcome::Placed {
                rec.outcome = Outcome::GraspFailed("no seal".into());
            }
            records.push(rec);
            continue;
        }
        let held = held.expect("checked");
        let Some(up) = up else {
            rec.outcome = Outcome::NoMotion("lift: no joint path along the line".into());
            records.push(rec);
            continue;
        };
        if let Err(o) = cell.play(&up, &held, false)? {
            rec.outcome = o;
            records.push(rec);
            continue;
        }
        // The Place motion, planned with the part on the cup; the next capture is triggered the
        // moment the arm has left the view frustum.
        let tool_from_part = grasp.world_from_tool.inverse() * detections[grasp.detection].world_from_part;
        let holding = CollisionModel::new(
            robot,
            RobotSpheres::new(robot, &cell.scene, Some((tool_from_part, cell.shape.half_extents_m))),
            env,
        );
        let above_place = Isometry3::from_parts(
            Translation3::from(grasp.world_from_tool_place.translation.vector + Vector3::z() * 0.03),
            grasp.world_from_tool_place.rotation,
        );
        let q_above = match robot.ik_tool_nearest(&above_place, &JointVector::from(grasp.q_place)) {
            Ok(s) => s.q,
            Err(e) => {
                rec.outcome = Outcome::NoMotion(format!("place pose: {e}"));
                records.push(rec);
                continue;
            }
        };
        let place_path = match holding.plan(&cell.world.joints(), &q_above, &PlanOptions::default(), &mut rng) {
            Ok(p) => p,
            Err(e) => {
                rec.outcome = Outcome::NoMotion(format!("place: {e}"));
                records.push(rec);
                continue;
            }
        };
        let via: Vec<JointVector> = place_path.waypoints.iter().map(|q| JointVector::from(*q)).collect();
        let dyn_held = robot.dynamics(&held);
        let (_, place, _) = accelerate_in_corridor(robot, &dyn_held, &via, &holding, 0.01);
        match cell.play(&place.trajectory, &held, true)? {
            Ok(t) => rec.place_motion_s = t,
            Err(o) => {
                rec.outcome = o;
                records.push(rec);
                continue;
            }
        }
        // Down into the slot, release 3 mm above the floor (the recognised pose is a little off;
        // the part drops the rest), back up.
        let release_pose = Isometry3::from_parts(
            Translation3::from(grasp.world_from_tool_place.translation.vector + Vector3::z() * 0.003),
            grasp.world_from_tool_place.rotation,
        );
        let Some(down) = cell.line(&release_pose) else {
            rec.outcome = Outcome::NoMotion("place descent".into());
            records.push(rec);
            continue;
        };
        if let Err(o) = cell.play(&down, &held, true)? {
            rec.outcome = o;
            records.push(rec);
            continue;
        }
        let part = cell.world.held_part();
        cell.world.vacuum_off();
        let t = cell.world.time_s + cell.world.gripper.release_s + cell.world.dt_s();
        cell.idle_until(t)?;
        cell.world.gripper.take_events();
        let release = cell.world.time_s;
        if let Some(up) = cell.line(&above_place) {
            cell.play(&up, &hand, true)?.ok();
        }
        cell.arm_free_s = cell.world.time_s;
        if let Some(i) = part {
            rec.placement_error = Some(cell.world.placement_error(
                i,
                &slot,
                workpiece.workpiece.grasp.yaw_symmetry_deg.to_radians(),
            ));
        }
        rec.release_s = Some(release);
        rec.takt_s = last_release.map(|r| release - r);
        last_release = Some(release);
        placed += 1;
        records.push(rec);
    }
    let mut takts: Vec<f64> = records.iter().filter_map(|r| r.takt_s).collect();
    takts.sort_by(f64::total_cmp);
    let n = takts.len();
    let takt = if n == 0 {
        (f64::NAN, f64::NAN, f64::NAN, f64::NAN)
    } else {
        (
            takts.iter().sum::<f64>() / n as f64,
            takts[((n as f64 * 0.95).ceil() as usize).saturating_sub(1)],
            takts[0],
            takts[n - 1],
        )
    };
    let summary = RunSummary {
        workpiece: workpiece.workpiece.name.clone(),
        seed: opts.seed,
        deterministic: opts.deterministic,
        picks: records.len(),
        placed,
        takt_s: takt,
        captures: (cell.sensor.triggered, cell.sensor.spoiled),
        stall_s: records.iter().map(|r| r.stall_s).sum(),
        sim_time_s: cell.world.time_s,
        reference_takt_s: reference_takt(&workpiece.workpiece.name),
    };
    Ok((records, summary))
}
