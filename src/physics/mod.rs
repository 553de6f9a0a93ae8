//! Physics world: the cell in rapier, with the piled parts, the arm and the suction gripper.
//!
//! Job: build the table, trays and obstacles from the cell's geometry ([`crate::geometry`]) as
//! fixed colliders; put the arm's links in as kinematic bodies that follow the joint state every
//! step (so a moving arm pushes parts and hides them from the sensor); drop piles of parts
//! ([`pile`]); hold and release parts with the suction gripper ([`suction`]); report every
//! health problem of each step ([`health`]); answer scene queries in metres ([`query`]).
//!
//! The API is in metres and SI units: rapier runs in f32 millimetres inside this module
//! (`SIM_UNITS_PER_M`), and nothing outside it sees a rapier length, handle or collider.
//! Frames: the rapier frame is the world frame of the cell file (z up).
//!
//! Solver tuning for 5-150 mm parts of a few grams (see docs/model.md, "Physics"): rapier runs in
//! millimetres; length unit 1 cm (allowed penetration 0.05 mm, prediction distance 0.2 mm);
//! contact stiffness 200 Hz (400 Hz against fixed bodies); 8 solver iterations; every contact
//! point solved (no clustering); CCD in steps where a part may travel over 1 mm; the
//! cell file's timestep; the contacts of parts that wake recomputed at once. Steps in which
//! nothing can move are not solved ([`quiet`], the cell file's `sim.stepping`).

mod arm;
pub mod drops;
pub mod health;
pub mod overlap;
mod parts;
pub mod pile;
pub mod query;
pub mod quiet;
pub mod script;
pub mod shapes;
pub mod suction;
mod view;

use nalgebra::{Isometry3, Vector3};
use rapier3d::math::{Pose, Vector};
use rapier3d::prelude::*;

use crate::config::{Scene, Stepping};
pub use crate::geometry::TrayVolume;
use crate::robot::{DOF, JointVector, RobotModel};
pub use health::{HealthError, HealthEvent, HealthLimits, HealthMonitor};
pub use query::{RayCaster, RayHit, RayTargets, ViewVolume};
pub use shapes::{PartShape, ShapeError};
pub use suction::{ContactLoad, GraspFailure, GripperEvent, SuctionGripper};
pub use view::ViewMesh;

/// rapier units per metre: the physics runs in millimetres. parry reuses a pair's contact points
/// while they drift less than a hard-coded 1e-3 units (`ContactManifold::try_update_contacts`);
/// in metres that is 1 mm, enough for centimetre parts to sink into each other unseen along an
/// edge. In millimetres it is 1 um.
pub(crate) const SIM_UNITS_PER_M: f64 = 1000.0;

/// A length (m) in rapier units.
#[inline]
pub(crate) fn sim(v: f64) -> f32 {
    (v * SIM_UNITS_PER_M) as f32
}

/// Our f64 isometry (m) as a rapier pose [rapier units].
pub(crate) fn to_pose(iso: &Isometry3<f64>) -> Pose {
    let mut p: Pose = iso.cast::<f32>().into();
    p.translation = sim_point(&iso.translation.vector);
    p
}

/// Sets a kinematic body's pose at the end of the next step, its quaternion on the same side as
/// the body's present one. rapier derives a kinematic body's velocity from the two quaternions
/// without taking the shorter way round, so `q` then `-q` (the same rotation, as a pose computed
/// afresh may come out) reads as most of a full turn within the step: a strip the cup had just
/// sealed on spun through that step and threw the strips under it out of the tray.
pub(crate) fn set_next_kinematic(body: &mut rapier3d::dynamics::RigidBody, mut pose: Pose) {
    if body.position().rotation.dot(pose.rotation) < 0.0 {
        pose.rotation = -pose.rotation;
    }
    body.set_next_kinematic_position(pose);
}

/// A rapier pose [rapier units] as our f64 isometry (m).
pub(crate) fn to_isometry(p: &Pose) -> Isometry3<f64> {
    let i: Isometry3<f32> = (*p).into();
    let mut i = i.cast::<f64>();
    i.translation.vector = point_from_sim(p.translation);
    i
}

/// A position or velocity [m, m/s] in rapier units.
pub(crate) fn sim_point(v: &Vector3<f64>) -> Vector {
    Vector::new(sim(v.x), sim(v.y), sim(v.z))
}

/// A position or velocity in rapier units as metres [m, m/s].
pub(crate) fn point_from_sim(v: Vector) -> Vector3<f64> {
    Vector3::new(v.x as f64, v.y as f64, v.z as f64) / SIM_UNITS_PER_M
}

/// A direction (unscaled) as a rapier vector.
pub(crate) fn sim_dir(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

/// A rapier direction (unscaled) as an f64 vector.
pub(crate) fn dir_from_sim(v: Vector) -> Vector3<f64> {
    Vector3::new(v.x as f64, v.y as f64, v.z as f64)
}

/// Largest travel of any point of an awake part per physics substep (m).
pub const MAX_SUBSTEP_MOTION_M: f64 = 0.0005;
/// Most substeps one physics step is divided into.
pub const MAX_SUBSTEPS: usize = 8;

/// Collision groups.
const ENV: Group = Group::GROUP_1;
const ARM: Group = Group::GROUP_2;
const PARTS: Group = Group::GROUP_3;

/// What a collider belongs to (stored in its `user_data`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tag {
    /// A fixed environment object, index into `World::env_names`.
    Env(u32),
    /// An arm link (0 = base ... 6 = flange).
    Link(u8),
    /// The gripper's body.
    Tool,
    /// The suction cup.
    Cup,
    /// A part, index into `World::parts`.
    Part(u32),
}

/// `user_data` flag of a part's ray-query twin collider (see [`PartBody::view_collider`]).
const VIEW_FLAG: u128 = 1 << 100;

/// Scene-query predicate: rays see a part through its view twin, not its physics collider.
pub(crate) fn ray_visible(_: ColliderHandle, c: &Collider) -> bool {
    !(matches!(Tag::decode(c.user_data), Some(Tag::Part(_))) && c.user_data & VIEW_FLAG == 0)
}

impl Tag {
    fn encode(self) -> u128 {
        let (kind, idx) = match self {
            Tag::Env(i) => (1u128, i as u128),
            Tag::Link(i) => (2, i as u128),
            Tag::Tool => (3, 0),
            Tag::Cup => (4, 0),
            Tag::Part(i) => (5, i as u128),
        };
        (kind << 64) | idx
    }

    /// Decodes a collider's `user_data`.
    pub fn decode(data: u128) -> Option<Tag> {
        let idx = (data & u64::MAX as u128) as u32;
        Some(match (data >> 64) & 0xff {
            1 => Tag::Env(idx),
            2 => Tag::Link(idx as u8),
            3 => Tag::Tool,
            4 => Tag::Cup,
            5 => Tag::Part(idx),
            _ => return None,
        })
    }

    /// Whether this is part of the robot (links, tool, cup).
    pub fn is_robot(self) -> bool {
        matches!(self, Tag::Link(_) | Tag::Tool | Tag::Cup)
    }
}

/// Where a part is in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PartState {
    /// In the pick tray (or falling into it).
    Free,
    /// On the suction cup.
    Held,
    /// Released over the place tray.
    Placed,
    /// Taken out of the cell (lost over a tray wall, or cleared with an exchanged tray): its body
    /// is parked far below the table and disabled, so it neither collides nor is seen.
    Removed,
}

/// One part in the world.
#[derive(Debug, Clone)]
pub struct PartBody {
    /// Its rigid body.
    body: RigidBodyHandle,
    /// Its collider (physics: convex polyhedra).
    collider: ColliderHandle,
    /// Its twin for rays (sensor pixels, suction probes): the same geometry with boxes as
    /// cuboids, a massless sensor that takes part in no contact.
    view_collider: ColliderHandle,
    /// Where it is in its life.
    pub state: PartState,
    /// A placed part's pose at the start of its current rest window: (time (s), pose).
    rest_ref: Option<(f64, Isometry3<f64>)>,
    /// When it last touched the part on the cup, while one was (s): a part that leaves its tray
    /// within [`RODE_HELD_WINDOW_S`] of that went with the held part.
    touched_held_s: f64,
}

/// A part that leaves its tray within this of touching the part on the cup was carried out with
/// it, or flung out by it (s): its last contact as it slid off the held part over the wall.
pub const RODE_HELD_WINDOW_S: f64 = 0.1;

/// A placed part whose pose changes less than [`PLACED_REST_M`] and [`PLACED_REST_RAD`] over
/// this window has come to rest in its slot (s), and becomes a fixed body there: a real part
/// resting in the place tray is held by static friction, and nothing in the cell may touch it
/// again (the arm or held part touching it is a collision, [`health`]). Two rapier behaviours
/// make a resting dynamic body unsafe there:
/// - D's can resting on its 16-sided cap kept a solver velocity of ~4 cm/s that jittered it
///   across the floor at ~1.3 mm/s, 22 mm over a run, into the next slot;
/// - a body put to sleep by hand (`RigidBody::sleep`) stays in rapier's awake set, so a later
///   step may integrate it under gravity while its contacts, asleep, are not computed: a B block
///   resting in its slot for seconds fell 6 mm through the 6 mm floor in 34 ms while the arm
///   placed another part 90 mm away (the "deep penetration 6.00 mm between place tray floor and
///   part N" collisions of measured-compute soaks; seed 1, pick 128).
///
/// A fixed body is in no island and never integrated; it is also marked asleep, so every
/// check that a part is at rest ([`World::part_sleeping`], the quiet step) counts it.
pub const PLACED_REST_WINDOW_S: f64 = 0.2;
/// See [`PLACED_REST_WINDOW_S`] (m): 2.5 mm/s, faster than the solver's creep, slower than
/// anything a falling, sliding or toppling part does.
pub const PLACED_REST_M: f64 = 0.0005;
/// See [`PLACED_REST_WINDOW_S`] (rad).
pub const PLACED_REST_RAD: f64 = 0.02;

/// The simulated cell.
pub struct World {
    /// rapier's integration parameters (tuned; see the module header).
    params: IntegrationParameters,
    gravity: Vector,
    pipeline: PhysicsPipeline,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
    ccd_solver: CCDSolver,
    /// Simulation time (s).
    time_s: f64,
    /// Steps taken.
    steps: u64,
    /// Substeps taken (more than `steps` while parts move fast).
    substeps: u64,
    /// Steps taken without the solver ([`quiet`]).
    quiet_steps: u64,
    /// Solved steps that ran continuous collision detection.
    ccd_steps: u64,
    /// A step runs CCD when a point may travel farther than this (m; [`quiet::CCD_TRAVEL_M`]).
    ccd_travel_m: f64,
    /// How the world is stepped.
    stepping: Stepping,
    /// What kinematic bodies must keep clear of in a quiet step, gathered while nothing moves.
    quiet_targets: Option<quiet::QuietTargets>,
    /// Most substeps a step may be divided into (1 turns adaptive substepping off).
    max_substeps: usize,
    /// The arm.
    robot: RobotModel,
    /// Joint positions the arm bodies are at after the last step (rad).
    q: JointVector,
    /// Joint positions the arm reaches at the end of the next step (rad).
    q_target: JointVector,
    link_bodies: Vec<RigidBodyHandle>,
    /// The pick tray's floor and walls hang on this body: fixed at the world origin, kinematic
    /// while the tray is agitated ([`World::set_pick_tray_offset`]).
    pick_tray_body: RigidBodyHandle,
    /// The pick tray's offset from its rest pose after the last step, and at the end of the next
    /// one [m, world].
    pick_tray_offset_m: (Vector3<f64>, Vector3<f64>),
    /// The parts, in insertion order.
    parts: Vec<PartBody>,
    /// The shape every part of this world has.
    part_shape: PartShape,
    /// Names of the environment objects, indexed by [`Tag::Env`].
    env_names: Vec<String>,
    /// The pick tray's volume.
    pick_tray: TrayVolume,
    /// The place tray's volume.
    place_tray: TrayVolume,
    /// The suction gripper.
    gripper: SuctionGripper,
    /// The health monitor.
    health: HealthMonitor,
    /// Tool positions after the last steps, newest last, for the tool's acceleration.
    tool_history: [Vector3<f64>; 3],
    /// What other parts push on the held part with, low-passed ([`suction::ContactLoad`]).
    held_load: suction::ContactLoad,
    /// The physics step (s) (`params.dt` holds the substep's while a step runs).
    step_dt_s: f64,
    /// Both trays' floors and walls for the independent overlap check.
    tray_pieces: Vec<(Isometry3<f64>, overlap::Polytope)>,
    /// Whether the contacts of parts that woke in a step are recomputed in the next
    /// ([`World::set_refresh_woken_contacts`]).
    refresh_woken_contacts: bool,
    /// Which parts slept before the step under way (scratch of [`World::pipeline_step`]).
    asleep_before: Vec<bool>,
    /// The cell's fixed boxes as built (table, trays, obstacles), named as in the geometry.
    cell_boxes: Vec<crate::geometry::NamedBox>,
}

/// The solver settings a world steps with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Solver {
    /// binpick's tuning (see the module header) with adaptive substeps.
    Tuned,
    /// rapier's default contact stiffness and solver iterations, one substep per step: the peer
    /// the physics benchmark compares with.
    RapierDefaults,
}

impl World {
    /// Builds the cell: table, trays, obstacles, the arm at its home configuration and the gripper.
    /// Parts are added by [`World::add_part`] or [`World::build_pile`].
    pub fn new(scene: &Scene, robot: &RobotModel, part_shape: PartShape) -> Self {
        let dt = scene.sim.physics_dt_s as f32;
        let params = IntegrationParameters {
            dt,
            min_ccd_dt: dt / 100.0,
            length_unit: sim(0.01),
            ..IntegrationParameters::default()
        };
        let mut w = World {
            params,
            gravity: Vector::new(0.0, 0.0, -sim(crate::robot::GRAVITY_M_S2)),
            pipeline: PhysicsPipeline::new(),
            islands: IslandManager::new(),
            broad_phase: BroadPhaseBvh::new(),
            narrow_phase: NarrowPhase::new(),
            bodies: RigidBodySet::new(),
            colliders: ColliderSet::new(),
            impulse_joints: ImpulseJointSet::new(),
            multibody_joints: MultibodyJointSet::new(),
            soft_bodies: SoftBodySet::new(),
            ccd_solver: CCDSolver::new(),
            time_s: 0.0,
            steps: 0,
            substeps: 0,
            quiet_steps: 0,
            ccd_steps: 0,
            ccd_travel_m: quiet::CCD_TRAVEL_M,
            stepping: scene.sim.stepping,
            quiet_targets: None,
            max_substeps: MAX_SUBSTEPS,
            robot: robot.clone(),
            q: JointVector::from(scene.robot.home_rad()),
            q_target: JointVector::from(scene.robot.home_rad()),
            link_bodies: Vec::new(),
            pick_tray_body: RigidBodyHandle::invalid(),
            pick_tray_offset_m: (Vector3::zeros(), Vector3::zeros()),
            parts: Vec::new(),
            part_shape,
            env_names: Vec::new(),
            pick_tray: TrayVolume::new(&scene.pick_tray),
            place_tray: TrayVolume::new(&scene.place_tray.tray),
            gripper: SuctionGripper::new(&scene.gripper),
            health: HealthMonitor {
                limits: HealthLimits {
                    deep_penetration_m: scene.sim.deep_penetration_limit_m,
                    ..HealthLimits::default()
                },
            },
            tool_history: [Vector3::zeros(); 3],
            held_load: suction::ContactLoad::default(),
            step_dt_s: f64::from(scene.sim.physics_dt_s as f32),
            tray_pieces: overlap::tray_pieces(&scene.pick_tray)
                .into_iter()
                .chain(overlap::tray_pieces(&scene.place_tray.tray))
                .collect(),
            refresh_woken_contacts: true,
            asleep_before: Vec::new(),
            cell_boxes: Vec::new(),
        };
        // The cell's fixed boxes: table, trays, obstacles (one geometry for physics and planning).
        // The pick tray's hang on a body of their own (fixed, at the world origin) that an
        // agitation moves.
        w.pick_tray_body = w.bodies.insert(RigidBodyBuilder::fixed());
        for (role, b) in crate::geometry::cell_boxes(scene) {
            let name = match role {
                crate::geometry::BoxRole::Obstacle => format!("obstacle {:?}", b.name),
                _ => b.name.clone(),
            };
            let parent = (role == crate::geometry::BoxRole::PickTray).then_some(w.pick_tray_body);
            w.add_env_box(&name, b.world_from_box, b.half_m, parent);
            w.cell_boxes.push(b);
        }
        w.set_solver(Solver::Tuned);
        w.add_arm(scene);
        w.tool_history = [w.tool_position(); 3];
        // One zero-length step so that queries see the world as built.
        w.refresh_queries();
        w
    }

    fn add_env_box(
        &mut self,
        name: &str,
        world_from_box: Isometry3<f64>,
        half: Vector3<f64>,
        parent: Option<RigidBodyHandle>,
    ) {
        let idx = self.env_names.len() as u32;
        self.env_names.push(name.to_string());
        let c = ColliderBuilder::cuboid(sim(half.x), sim(half.y), sim(half.z))
            .position(to_pose(&world_from_box))
            .collision_groups(InteractionGroups::new(ENV, Group::ALL, InteractionTestMode::And))
            .friction(0.5)
            .user_data(Tag::Env(idx).encode());
        match parent {
            // Parented at the world origin: the box's pose relative to its body is its world pose.
            Some(body) => {
                self.colliders.insert_with_parent(c, body, &mut self.bodies);
            }
            None => {
                self.colliders.insert(c);
            }
        }
    }

    /// Sets the pick tray's offset from its rest pose at the end of the next step [m, world]:
    /// the tray's body sweeps there during the step, pushing the parts it carries (an
    /// agitation). A zero offset after a zero offset puts the tray back to rest, fixed, exactly
    /// where it was built (what the sensor's cached background shows).
    pub fn set_pick_tray_offset(&mut self, offset_m: Vector3<f64>) {
        self.pick_tray_offset_m.1 = offset_m;
        let moving = self.pick_tray_offset_m.0 != Vector3::zeros() || offset_m != Vector3::zeros();
        let body = &mut self.bodies[self.pick_tray_body];
        if moving && body.is_fixed() {
            body.set_body_type(RigidBodyType::KinematicPositionBased, true);
        }
    }

    /// Whether the pick tray is away from its rest pose or moving (an agitation under way).
    pub fn pick_tray_moving(&self) -> bool {
        !self.bodies[self.pick_tray_body].is_fixed()
    }

    /// Runs collision detection without advancing time, so scene queries see the current state.
    pub fn refresh_queries(&mut self) {
        // A physics step of 1 ns: collision detection runs and the bounding-volume tree is
        // rebuilt; nothing moves measurably, and simulation time is not advanced. (A zero-length
        // step would divide kinematic displacements by dt = 0 and poison the tree with NaNs.)
        let dt = self.params.dt;
        self.params.dt = 1e-9;
        self.pipeline_step();
        self.params.dt = dt;
    }

    fn pipeline_step(&mut self) {
        self.quiet_targets = None;
        if self.refresh_woken_contacts {
            self.asleep_before.clear();
            self.asleep_before
                .extend(self.parts.iter().map(|p| self.bodies[p.body].is_sleeping()));
        }
        self.pipeline_step_only();
        if self.refresh_woken_contacts {
            self.refresh_contacts_of_woken_parts();
        }
    }

    /// One rapier step, nothing around it.
    fn pipeline_step_only(&mut self) {
        self.pipeline.step(
            self.gravity,
            &self.params,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.soft_bodies,
            &mut self.ccd_solver,
            &(),
            &(),
        );
    }

    /// Physics timestep (s): one [`World::step`], also while it runs in substeps (the
    /// gripper's tool acceleration and release velocity are differences over whole steps).
    pub fn dt_s(&self) -> f64 {
        self.step_dt_s
    }

    /// Advances the world by one step: arm bodies sweep to the joint target, the gripper's timers
    /// run, the solver steps, and the health monitor checks every body.
    pub fn step(&mut self) -> Result<(), HealthError> {
        let mut gripper_ran = false;
        if self.stepping == Stepping::EventDriven {
            let world_from_links = self.robot.world_from_links(&self.q_target);
            if self.step_is_quiet(&world_from_links) {
                if self.quiet_step(&world_from_links) {
                    self.time_s += self.params.dt as f64;
                    self.q = self.q_target;
                    self.steps += 1;
                    self.quiet_steps += 1;
                    self.tool_history = [self.tool_history[1], self.tool_history[2], self.tool_position()];
                    self.rest_placed_parts();
                    return Ok(());
                }
                // The gripper let its part go: this step is solved (the gripper has run).
                gripper_ran = true;
            }
        }
        let travel_m = self.fastest_point_travel_m();
        self.params.max_ccd_substeps = usize::from(self.ccd_needed(travel_m));
        self.ccd_steps += self.params.max_ccd_substeps as u64;
        let n = self.substeps_needed(travel_m);
        let dt = self.params.dt;
        let dt_s = dt as f64;
        self.params.dt = dt / n as f32;
        let (q_from, q_to) = (self.q, self.q_target);
        for k in 1..=n {
            let q_k = if k == n {
                q_to
            } else {
                q_from + (q_to - q_from) * (k as f64 / n as f64)
            };
            let world_from_links = self.robot.world_from_links(&q_k);
            for (i, h) in self.link_bodies.iter().enumerate().skip(1) {
                set_next_kinematic(&mut self.bodies[*h], to_pose(&world_from_links[i]));
            }
            if !self.bodies[self.pick_tray_body].is_fixed() {
                let (from, to) = self.pick_tray_offset_m;
                let at = from + (to - from) * (k as f64 / n as f64);
                let pose = to_pose(&Isometry3::translation(at.x, at.y, at.z));
                self.bodies[self.pick_tray_body].set_next_kinematic_position(pose);
            }
            let world_from_tool_next = world_from_links[DOF] * self.robot.flange_from_tool;
            if gripper_ran {
                gripper_ran = false;
                // The held part's pose at the step's end, as the gripper would have set it.
                self.move_held_part(&world_from_tool_next);
            } else {
                self.update_gripper(&world_from_tool_next);
            }
            self.pipeline_step();
            self.update_held_contacts(&world_from_tool_next, dt_s / n as f64);
            self.time_s += dt_s / n as f64;
            self.q = q_k;
        }
        self.params.dt = dt;
        self.steps += 1;
        self.substeps += n as u64;
        self.settle_pick_tray();
        self.tool_history = [self.tool_history[1], self.tool_history[2], self.tool_position()];
        self.rest_placed_parts();
        let events = self.health.check(self);
        if events.is_empty() {
            Ok(())
        } else {
            Err(HealthError {
                step: self.steps,
                time_s: self.time_s,
                events,
            })
        }
    }

    /// After a step: the tray's offset is where the step took it; back at rest with no motion
    /// asked for, its body is fixed again, exactly at its built pose.
    fn settle_pick_tray(&mut self) {
        let (_, to) = self.pick_tray_offset_m;
        self.pick_tray_offset_m.0 = to;
        let body = &mut self.bodies[self.pick_tray_body];
        if to == Vector3::zeros() && !body.is_fixed() {
            body.set_body_type(RigidBodyType::Fixed, true);
            body.set_position(Pose::IDENTITY, true);
        }
    }

    /// Fixes placed parts that have come to rest in their slots ([`PLACED_REST_WINDOW_S`]).
    fn rest_placed_parts(&mut self) {
        let now = self.time_s;
        for i in 0..self.parts.len() {
            let body = self.parts[i].body;
            if self.parts[i].state != PartState::Placed || !self.bodies[body].is_dynamic() {
                self.parts[i].rest_ref = None;
                continue;
            }
            let pose = self.part_pose(i);
            // Asleep by rapier's own rule, or still over the window: at rest.
            let at_rest = self.bodies[body].is_sleeping()
                || match self.parts[i].rest_ref {
                    Some((t0, before)) if now - t0 >= PLACED_REST_WINDOW_S - 1e-9 => {
                        let moved = before.inverse() * pose;
                        if moved.translation.vector.norm() < PLACED_REST_M && moved.rotation.angle() < PLACED_REST_RAD {
                            true
                        } else {
                            self.parts[i].rest_ref = Some((now, pose));
                            false
                        }
                    }
                    Some(_) => false,
                    None => {
                        self.parts[i].rest_ref = Some((now, pose));
                        false
                    }
                };
            if at_rest {
                let b = &mut self.bodies[body];
                b.set_body_type(RigidBodyType::Fixed, false);
                b.set_linvel(Vector::ZERO, false);
                b.set_angvel(Vector::ZERO, false);
                b.sleep();
                self.parts[i].rest_ref = None;
            }
        }
    }

    /// The farthest any point of an awake free or placed part travels in the next step at its
    /// present speed (m): its centre's travel plus its rim's turn.
    fn fastest_point_travel_m(&self) -> f64 {
        let r = self.part_shape.bounding_radius_m;
        self.parts
            .iter()
            .filter(|p| matches!(p.state, PartState::Free | PartState::Placed))
            .map(|p| &self.bodies[p.body])
            .filter(|b| !b.is_sleeping())
            .map(|b| (b.linvel().length() as f64 / SIM_UNITS_PER_M + b.angvel().length() as f64 * r) * self.dt_s())
            .fold(0.0, f64::max)
    }

    /// How many substeps a step whose fastest point travels `travel_m` needs so that no awake
    /// part moves more than [`MAX_SUBSTEP_MOTION_M`] per substep, 1 to 8. A 2.5 g part that
    /// lands on a corner spins at 300 rad/s; at the cell's 2 ms step its far corner would dig
    /// millimetres into the floor before the next collision detection.
    fn substeps_needed(&self, travel_m: f64) -> usize {
        ((travel_m / MAX_SUBSTEP_MOTION_M).ceil() as usize).clamp(1, self.max_substeps.max(1))
    }

    /// Steps for `duration_s` of simulation time (rounded up to whole steps).
    pub fn run_for(&mut self, duration_s: f64) -> Result<(), HealthError> {
        let n = (duration_s / self.dt_s() - 1e-9).ceil().max(0.0) as usize;
        for _ in 0..n {
            self.step()?;
        }
        Ok(())
    }

    /// A readable name for what a collider belongs to.
    pub fn describe(&self, tag: Option<Tag>) -> String {
        match tag {
            Some(Tag::Env(i)) => self
                .env_names
                .get(i as usize)
                .cloned()
                .unwrap_or_else(|| "a tray".to_string()),
            Some(Tag::Link(i)) => self
                .robot
                .links
                .get(i as usize)
                .map_or(format!("link {i}"), |l| l.name.clone()),
            Some(Tag::Tool) => "tool".to_string(),
            Some(Tag::Cup) => "suction cup".to_string(),
            Some(Tag::Part(i)) => {
                let held = self.parts.get(i as usize).is_some_and(|p| p.state == PartState::Held);
                format!("part {i}{}", if held { " (held)" } else { "" })
            }
            None => "unknown body".to_string(),
        }
    }

    /// The tag of a collider.
    pub fn tag_of(&self, c: ColliderHandle) -> Option<Tag> {
        self.colliders.get(c).and_then(|c| Tag::decode(c.user_data))
    }

    /// Simulation time (s).
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Physics steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Substeps taken (more than the steps while parts move fast).
    pub fn substeps(&self) -> u64 {
        self.substeps
    }

    /// The arm.
    pub fn robot(&self) -> &RobotModel {
        &self.robot
    }

    /// How many parts were ever added (removed ones keep their index).
    pub fn part_count(&self) -> usize {
        self.parts.len()
    }

    /// Where part `i` is in its life.
    pub fn part_state(&self, i: usize) -> PartState {
        self.parts[i].state
    }

    /// The shape every part of this world has.
    pub fn part_shape(&self) -> &PartShape {
        &self.part_shape
    }

    /// The cell's fixed boxes (table, trays, obstacles) where the world was built with them (an
    /// agitation moves the pick tray's later).
    pub fn cell_boxes(&self) -> &[crate::geometry::NamedBox] {
        &self.cell_boxes
    }

    /// The pick tray's volume.
    pub fn pick_tray(&self) -> &TrayVolume {
        &self.pick_tray
    }

    /// The place tray's volume.
    pub fn place_tray(&self) -> &TrayVolume {
        &self.place_tray
    }

    /// The suction gripper (its settings and state).
    pub fn gripper(&self) -> &SuctionGripper {
        &self.gripper
    }

    /// Takes the gripper's events produced so far.
    pub fn take_gripper_events(&mut self) -> Vec<GripperEvent> {
        self.gripper.take_events()
    }

    /// The health monitor's limits.
    pub fn health_limits(&self) -> HealthLimits {
        self.health.limits
    }

    /// Checks every step against `limits` from now on.
    pub fn set_health_limits(&mut self, limits: HealthLimits) {
        self.health.limits = limits;
    }

    /// Solved steps so far that ran continuous collision detection.
    pub fn ccd_steps(&self) -> u64 {
        self.ccd_steps
    }

    /// Runs continuous collision detection in a step in which a point may travel farther than
    /// `travel_m` (default [`quiet::CCD_TRAVEL_M`]; 0: whenever anything moves, as rapier's own
    /// test nearly did; infinite: never): the physics tests' negative control.
    pub fn set_ccd_travel_m(&mut self, travel_m: f64) {
        self.ccd_travel_m = travel_m;
    }

    /// Recomputes the contacts of parts that woke in a step in the step after (default on;
    /// see [`quiet`]): the physics tests' negative control turns it off.
    pub fn set_refresh_woken_contacts(&mut self, on: bool) {
        self.refresh_woken_contacts = on;
    }

    /// Turns rapier's contact clustering on or off ([`Solver::Tuned`] turns it off): the
    /// physics tests' negative control, showing what it does to a pile of small supports.
    pub fn set_contact_clustering(&mut self, on: bool) {
        self.params.contact_clustering = on;
    }

    /// Steps with `solver`'s settings from now on.
    pub fn set_solver(&mut self, solver: Solver) {
        match solver {
            Solver::Tuned => {
                // Stiff contacts: a few grams resting on each other sink well under 0.3 mm
                // (measured by the independent overlap check over many piles; rapier's defaults
                // are 30 and 60 Hz).
                self.params.contact_softness = SpringCoefficients::new(200.0, 10.0);
                self.params.static_contact_softness = SpringCoefficients::new(400.0, 10.0);
                self.params.num_solver_iterations = 8;
                // Every contact point solved, none merged: rapier's clustering keeps at most 4
                // points per contact plane of a pair, which drops or swaps, step to step, the
                // small supports a part can rest on (a lying SMD can's terminal tip, base corner
                // and rim). The can then rocked and walked forever, 0.15 mm deep in the floor.
                self.params.contact_clustering = false;
                self.max_substeps = MAX_SUBSTEPS;
            }
            Solver::RapierDefaults => {
                self.params.contact_softness = SpringCoefficients::contact_defaults();
                self.params.static_contact_softness = SpringCoefficients::contact_static_defaults();
                self.params.contact_clustering = IntegrationParameters::default().contact_clustering;
                self.params.num_solver_iterations = 4;
                self.max_substeps = 1;
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod test_cell {
    //! The default cell for the physics' unit tests.
    use super::PartShape;
    use crate::config::{LoadedScene, LoadedWorkpiece};
    use crate::robot::RobotModel;

    /// The embedded default cell, its robot, and the embedded `workpiece`'s shape.
    pub(crate) fn default_cell_with(workpiece: &str) -> (LoadedScene, RobotModel, PartShape) {
        let scene = LoadedScene::embedded_default().unwrap();
        let robot = RobotModel::from_scene(&scene).unwrap();
        let wp = LoadedWorkpiece::resolve(workpiece).unwrap();
        let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
        (scene, robot, shape)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A kinematic body turned by a milliradian, the new rotation given as the other quaternion
    /// (`-q`), turns by that milliradian in the step (0.5 rad/s): [`set_next_kinematic`] keeps the
    /// quaternion on the present one's side. Negative control: rapier given `-q` as it is spins
    /// the body at hundreds of rad/s (exactly `-q` of the same rotation it reads as no turn).
    #[test]
    fn a_kinematic_body_given_its_rotations_other_quaternion_does_not_spin() {
        let (scene, robot, shape) = test_cell::default_cell_with("C");
        let spin_rad_s = |aligned: bool| {
            let mut w = World::new(&scene.scene, &robot, shape.clone());
            let world_from_part = Isometry3::from_parts(
                Translation3::new(0.2, 0.45, 0.3),
                UnitQuaternion::from_euler_angles(0.0, 0.0, 1.57),
            );
            let i = w.add_part(&world_from_part);
            let body = w.parts[i].body;
            let b = &mut w.bodies[body];
            b.set_body_type(RigidBodyType::KinematicPositionBased, true);
            let mut next = *b.position();
            next.rotation = -(next.rotation * rapier3d::math::Rotation::from_rotation_z(1e-3));
            if aligned {
                set_next_kinematic(b, next);
            } else {
                b.set_next_kinematic_position(next);
            }
            w.pipeline_step_only();
            w.bodies[body].angvel().length()
        };
        let aligned = spin_rad_s(true);
        assert!(
            (aligned - 0.5).abs() < 0.05,
            "{aligned} rad/s with the quaternion aligned"
        );
        let raw = spin_rad_s(false);
        assert!(raw > 100.0, "{raw} rad/s given -q as it is (negative control)");
    }
}
