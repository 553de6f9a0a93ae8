//! The suction gripper: seal check, vacuum build-up, rigid hold, slip, release.
//!
//! Job: when the vacuum is switched on, decide from the world's geometry whether the cup seals on
//! a part: the cup lip must sit on one flat face of one part that is large enough for the cup,
//! touching it, with the tool axis within the allowed tilt of the face normal. A cup that seals
//! on round surfaces (`gripper.round_min_radius_m`, a bellows cup) also seals where the surface
//! under its lip falls away by no more than a sphere of that radius does, on surface turned from
//! the cup's axis by at most the tilt limit and that sphere's turn across the lip (a can's side). The decision is
//! made when the vacuum has built up (`vacuum_build_up_s` later). A sealed part then moves rigidly
//! with the tool until it slips, or until the vacuum is switched off and has vented.
//!
//! Model (simplified, stated in docs/model.md, "Physics"): the seal is probed with rays along the tool axis at
//! the cup centre and 16 points of the lip circle. Holding force = vacuum x cup area. A part slips
//! when the force the cup must exert on it, m (a_tool - g) in the tool frame, as its pull toward
//! the cup plus its shear over the lip's friction plus 4 / d times its moment across the axis
//! about the cup centre ([`crate::geometry::SuctionModel::required_n`]; d: cup diameter), plus
//! what other parts pull on it off the cup, |F| + 4 |M| / d (M its moment about the cup centre;
//! [`ContactLoad`], with `gripper.seal_loaded_by_parts`), exceeds the holding force.
//! Once the valve closes, the holding force falls linearly to zero over `release_s`: the part
//! comes off when the force it needs exceeds what is left (earlier for a heavy part or a cup
//! still decelerating), and at the latest after `release_s`.
//!
//! The gripper itself ([`SuctionGripper`]) is a state machine (idle, building up, holding,
//! releasing) that says what is due at a step ([`SuctionGripper::due`]); the world decides it
//! with its geometry (the seal probe, the tool's acceleration) and moves the bodies.
//!
//! Units: m, s, N, Pa. Frames: `world_from_tool` (z axis out of the cup), `tool_from_part`.

use nalgebra::{Isometry3, Matrix3, Translation3, Vector3};
use rapier3d::prelude::{ActiveCollisionTypes, RigidBodyType};

use super::{PartState, SIM_UNITS_PER_M, Tag, World, dir_from_sim, point_from_sim, sim_point, to_pose};
use crate::config::GripperConfig;
use crate::robot::Payload;

/// Lip points probed around the cup.
const LIP_RAYS: usize = 16;
/// Probe rays start this far behind the lip, inside the cup (m).
const PROBE_BACK_M: f64 = 0.01;
/// A lip point whose surface normal differs from the centre's by more than this is on another face (rad).
const SAME_FACE_RAD: f64 = 0.087;
/// The cup must touch: the face may be at most this far beyond the lip (m).
const TOUCH_GAP_M: f64 = 0.0008;
/// The bellows take up at most this much overlap of the part with the tray at the seal (m).
const BELLOWS_TAKE_UP_M: f64 = 0.001;
/// Time constant of the low pass on the contact load on the held part (s). A rigid solver
/// delivers a touch as one substep's impulse; a seal is broken by a load that lasts long enough to
/// lift the lip and let air in. Chosen (a few substeps, a fraction of the vacuum's build-up), not
/// measured.
pub const CONTACT_LOAD_LAG_S: f64 = 0.01;

/// What other parts push on the held part with, low-passed over [`CONTACT_LOAD_LAG_S`]: the
/// solver's normal contact impulses over the substep that do not push the held part toward the
/// cup, and their moment about the cup centre. A contact that pushes it toward the cup (a part
/// under the held one, level or slanted) is carried by the lip and neither loads nor relieves
/// the seal; one across the cup's axis or away from the cup (a neighbour the held part strikes,
/// drags or carries) pulls, shears the lip and, off the cup's centre, peels it. Friction
/// impulses are left out.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactLoad {
    /// Their force on the held part [N, world].
    pub force_n: Vector3<f64>,
    /// Its moment about the cup centre [N m, world].
    pub moment_nm: Vector3<f64>,
}

/// Why a grasp failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GraspFailure {
    /// Nothing but the tray (or nothing at all) under the cup.
    #[error("no part under the cup (the cup points at {0})")]
    NoPart(String),
    /// The cup does not touch the face (its nearest lip point is too far from it).
    #[error("cup does not touch the part: face {gap_mm:.2} mm beyond the lip")]
    NotTouching {
        /// Gap (mm).
        gap_mm: f64,
    },
    /// The tool axis is tilted too far from the face normal.
    #[error("approach tilted {tilt_deg:.1} deg from the face normal, the cup seals up to {max_deg:.1} deg")]
    Tilted {
        /// Tilt (deg).
        tilt_deg: f64,
        /// Allowed (deg).
        max_deg: f64,
    },
    /// The face under the cup is narrower than the cup.
    #[error("face {width_mm:.1} mm wide is smaller than the {cup_mm:.1} mm cup")]
    FaceTooSmall {
        /// Narrowest width of the face through the cup centre (mm).
        width_mm: f64,
        /// Cup diameter (mm).
        cup_mm: f64,
    },
    /// The face is large enough but the cup overhangs its edge.
    #[error("cup on an edge: {outside} of {LIP_RAYS} lip points off the face")]
    OnEdge {
        /// Lip points not on the face.
        outside: usize,
    },
    /// Something else lies on the face's rim under the cup lip.
    #[error("cup lip blocked by {0}")]
    Obstructed(String),
    /// The vacuum was switched off before it built up.
    #[error("vacuum switched off before it built up")]
    Aborted,
}

/// A cup sealed on a part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seal {
    /// The part.
    pub part: usize,
    /// Tilt of the tool axis from the face normal (rad).
    pub tilt_rad: f64,
    /// The part's centre of mass from the lip's centre, tool frame (m): it moves with the tool.
    pub com_from_cup_m: Vector3<f64>,
}

impl Seal {
    /// Distance of the part's centre of mass from the cup axis (m).
    pub fn com_offset_m(&self) -> f64 {
        self.com_from_cup_m.xy().norm()
    }
}

/// What the gripper did, with the simulation time.
#[derive(Debug, Clone, PartialEq)]
pub enum GripperEvent {
    /// The vacuum built up on a sealed part: it now moves with the tool.
    Grasped {
        /// Time (s).
        time_s: f64,
        /// The seal.
        seal: Seal,
    },
    /// The vacuum did not build up.
    GraspFailed {
        /// Time (s).
        time_s: f64,
        /// Why.
        reason: GraspFailure,
    },
    /// A held part tore off the cup.
    Slipped {
        /// Time (s).
        time_s: f64,
        /// The part.
        part: usize,
        /// Force the cup had to exert: pull, shear over the lip's friction, and peel (N).
        required_n: f64,
        /// Force the vacuum holds (N).
        holding_n: f64,
    },
    /// The part came off the cup after the vacuum was switched off.
    Released {
        /// Time (s).
        time_s: f64,
        /// The part.
        part: usize,
    },
}

/// The gripper's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GripperState {
    /// Vacuum off, nothing held.
    Idle,
    /// Vacuum on since `since_s`, not yet built up.
    BuildingUp {
        /// When the valve opened (s).
        since_s: f64,
    },
    /// Holding a part rigidly.
    Holding {
        /// The seal.
        seal: Seal,
        /// Where the part sits on the tool.
        tool_from_part: Isometry3<f64>,
    },
    /// Vacuum off since `since_s`, the part still on the cup.
    Releasing {
        /// When the valve closed (s).
        since_s: f64,
        /// The seal.
        seal: Seal,
        /// Where the part sits on the tool.
        tool_from_part: Isometry3<f64>,
    },
}

/// The suction gripper: configuration, state and the events it produced.
#[derive(Debug, Clone)]
pub struct SuctionGripper {
    /// Cup lip radius (m).
    pub cup_radius_m: f64,
    /// Largest tilt that seals (rad).
    pub max_tilt_rad: f64,
    /// Flatness the lip tolerates (m).
    pub flatness_m: f64,
    /// How far below the plane at the cup's centre a round surface may fall away under the lip
    /// and still seal (m): the sag of a sphere of `gripper.round_min_radius_m` across the cup's
    /// radius; 0 for a cup that seals on flat faces only.
    pub lip_sag_m: f64,
    /// How much farther than the tilt limit the surface under the lip may turn from the cup's
    /// axis (rad): the turn across the cup's radius on that sphere; 0 for a flat-face cup.
    pub lip_turn_rad: f64,
    /// Holding force of a full seal (N).
    pub holding_n: f64,
    /// The cup's force model.
    pub model: crate::geometry::SuctionModel,
    /// Vacuum build-up time (s).
    pub build_up_s: f64,
    /// Release time (s).
    pub release_s: f64,
    /// Parts pressing on the held part load the seal (`gripper.seal_loaded_by_parts`).
    pub loaded_by_parts: bool,
    /// When the valve was last commanded closed, while it stays closed (s) (the controller's
    /// command, whatever the part did).
    closed_since_s: Option<f64>,
    /// Current state.
    state: GripperState,
    /// Events not yet taken by the caller.
    events: Vec<GripperEvent>,
}

/// What the gripper needs the world to decide or do at a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GripperDue {
    /// Nothing.
    Nothing,
    /// The vacuum has built up: probe the seal under the cup and seal or fail.
    DecideSeal,
    /// A part is held: check that the cup still holds it against the tool's motion.
    CheckHold(Seal),
    /// The vacuum is venting: the part comes off if it needs more than the holding force left,
    /// this fraction of the full seal's.
    CheckRelease(Seal, f64),
    /// The vacuum is off long enough: the part comes off the cup.
    Release(Seal),
}

impl SuctionGripper {
    /// A gripper from the cell file.
    pub fn new(g: &GripperConfig) -> Self {
        let model = crate::geometry::SuctionModel::new(g);
        let r = model.cup_radius_m;
        let (lip_sag_m, lip_turn_rad) = match g.round_min_radius_m {
            Some(big_r) if big_r > r => (big_r - (big_r * big_r - r * r).sqrt(), (r / big_r).asin()),
            _ => (0.0, 0.0),
        };
        SuctionGripper {
            cup_radius_m: model.cup_radius_m,
            max_tilt_rad: g.max_tilt_deg.to_radians(),
            flatness_m: g.cup_flatness_tolerance_m,
            lip_sag_m,
            lip_turn_rad,
            holding_n: model.holding_n,
            model,
            build_up_s: g.vacuum_build_up_s,
            release_s: g.release_s,
            loaded_by_parts: g.seal_loaded_by_parts,
            closed_since_s: None,
            state: GripperState::Idle,
            events: Vec::new(),
        }
    }

    /// Takes the events produced so far.
    pub fn take_events(&mut self) -> Vec<GripperEvent> {
        std::mem::take(&mut self.events)
    }

    /// Opens the vacuum valve at `now_s`: the seal is decided when the vacuum has built up.
    pub fn vacuum_on(&mut self, now_s: f64) {
        self.closed_since_s = None;
        if self.state == GripperState::Idle {
            self.state = GripperState::BuildingUp { since_s: now_s };
        }
    }

    /// Closes the vacuum valve at `now_s`: a held part comes off as the vacuum vents, at the
    /// latest after `release_s`; a vacuum still building up fails the grasp.
    pub fn vacuum_off(&mut self, now_s: f64) {
        self.closed_since_s.get_or_insert(now_s);
        match self.state {
            GripperState::BuildingUp { .. } => {
                self.state = GripperState::Idle;
                self.events.push(GripperEvent::GraspFailed {
                    time_s: now_s,
                    reason: GraspFailure::Aborted,
                });
            }
            GripperState::Holding { seal, tool_from_part } => {
                self.state = GripperState::Releasing {
                    since_s: now_s,
                    seal,
                    tool_from_part,
                };
            }
            _ => {}
        }
    }

    /// What is due at `now_s`.
    pub fn due(&self, now_s: f64) -> GripperDue {
        match self.state {
            GripperState::Idle => GripperDue::Nothing,
            GripperState::BuildingUp { since_s } if now_s + 1e-9 >= since_s + self.build_up_s => GripperDue::DecideSeal,
            GripperState::BuildingUp { .. } => GripperDue::Nothing,
            GripperState::Holding { seal, .. } => GripperDue::CheckHold(seal),
            GripperState::Releasing { since_s, seal, .. } if now_s + 1e-9 >= since_s + self.release_s => {
                GripperDue::Release(seal)
            }
            GripperState::Releasing { since_s, seal, .. } => {
                GripperDue::CheckRelease(seal, 1.0 - (now_s - since_s) / self.release_s)
            }
        }
    }

    /// The vacuum built up on `seal` at `now_s`; the part sits at `tool_from_part` on the tool.
    pub fn sealed(&mut self, now_s: f64, seal: Seal, tool_from_part: Isometry3<f64>) {
        self.state = GripperState::Holding { seal, tool_from_part };
        self.events.push(GripperEvent::Grasped { time_s: now_s, seal });
    }

    /// The vacuum did not build up at `now_s`.
    pub fn failed(&mut self, now_s: f64, reason: GraspFailure) {
        self.state = GripperState::Idle;
        self.events.push(GripperEvent::GraspFailed { time_s: now_s, reason });
    }

    /// The held part tore off at `now_s`: the cup had to exert `required_n`.
    pub fn slipped(&mut self, now_s: f64, part: usize, required_n: f64) {
        self.state = GripperState::Idle;
        self.events.push(GripperEvent::Slipped {
            time_s: now_s,
            part,
            required_n,
            holding_n: self.holding_n,
        });
    }

    /// The part came off the cup at `now_s`.
    pub fn released(&mut self, now_s: f64, part: usize) {
        self.state = GripperState::Idle;
        self.events.push(GripperEvent::Released { time_s: now_s, part });
    }

    /// When the valve was commanded closed (s), while it stays closed (`None` after an open
    /// command, and before the first close).
    pub fn valve_closed_since_s(&self) -> Option<f64> {
        self.closed_since_s
    }

    /// The part on the cup and where it sits on the tool, if any.
    pub fn held(&self) -> Option<(Seal, Isometry3<f64>)> {
        match self.state {
            GripperState::Holding { seal, tool_from_part }
            | GripperState::Releasing {
                seal, tool_from_part, ..
            } => Some((seal, tool_from_part)),
            _ => None,
        }
    }
}

fn orthonormal(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = n.cross(&helper).normalize();
    (u, n.cross(&u))
}

impl World {
    fn skip_robot_and_held(&self) -> impl Fn(Tag) -> bool + '_ {
        move |t: Tag| match t {
            Tag::Link(_) | Tag::Tool | Tag::Cup => true,
            Tag::Part(i) => self.parts.get(i as usize).is_some_and(|p| p.state == PartState::Held),
            Tag::Env(_) => false,
        }
    }

    /// Whether the cup at `world_from_tool` would seal, and on what. Uses the world's true
    /// geometry: this is the physical cup, not the grasp planner's estimate.
    pub fn check_seal(&self, world_from_tool: &Isometry3<f64>) -> Result<Seal, GraspFailure> {
        let g = &self.gripper;
        let axis = world_from_tool.rotation * Vector3::z();
        let centre = world_from_tool.translation.vector;
        let skip = self.skip_robot_and_held();
        let reach = PROBE_BACK_M + 0.02;
        let hit = self.cast_ray(&(centre - axis * PROBE_BACK_M), &axis, reach, &skip);
        let (tag, toi, normal) = match hit {
            Some(h) => (h.tag, h.distance_m, h.normal),
            None => return Err(GraspFailure::NoPart("nothing within 2 cm".into())),
        };
        let Tag::Part(part) = tag else {
            return Err(GraspFailure::NoPart(self.describe(Some(tag))));
        };
        let part = part as usize;
        let gap = toi - PROBE_BACK_M;
        // A tilted cup touches with one side of its lip only: report the tilt, the real cause.
        let tilt = normal.dot(&-axis).clamp(-1.0, 1.0).acos();
        if tilt > g.max_tilt_rad {
            return Err(GraspFailure::Tilted {
                tilt_deg: tilt.to_degrees(),
                max_deg: g.max_tilt_rad.to_degrees(),
            });
        }
        // On a tilted face the lip's nearest point is closer than the centre by r tan(tilt).
        let lip_gap = gap - g.cup_radius_m * tilt.tan();
        if lip_gap > TOUCH_GAP_M {
            return Err(GraspFailure::NotTouching { gap_mm: lip_gap * 1e3 });
        }
        let face_point = centre - axis * PROBE_BACK_M + axis * toi;
        let on_face = |p: &Vector3<f64>, dir: &Vector3<f64>| -> Result<(), Option<Tag>> {
            match self.cast_ray(&(p - dir * PROBE_BACK_M), dir, reach, &skip) {
                Some(super::query::RayHit {
                    tag: t,
                    distance_m: d,
                    normal: n,
                }) => {
                    let q = p - dir * PROBE_BACK_M + dir * d;
                    // Above the centre's plane by at most the flatness; below it by that and,
                    // for a cup that seals on round surfaces, the sag it follows. A flat cup's
                    // lip needs the centre's face under it; a round-sealing cup's lip tilts with
                    // the surface, up to the seal's tilt and the turn it follows, against the
                    // cup's axis (on a faceted can the centre's facet is itself turned from the
                    // true radial direction by up to half a facet).
                    let flat = g.flatness_m.max(1e-5);
                    let height = (q - face_point).dot(&normal);
                    let turned_ok = if g.lip_turn_rad > 0.0 {
                        n.dot(&-axis).clamp(-1.0, 1.0).acos() < g.max_tilt_rad + g.lip_turn_rad
                    } else {
                        n.dot(&normal).clamp(-1.0, 1.0).acos() < SAME_FACE_RAD
                    };
                    let same =
                        t == Tag::Part(part as u32) && turned_ok && height <= flat && height >= -(flat + g.lip_sag_m);
                    if same { Ok(()) } else { Err(Some(t)) }
                }
                None => Err(None),
            }
        };
        let (u, v) = orthonormal(&axis);
        let mut outside = 0;
        let mut blocker = None;
        for k in 0..LIP_RAYS {
            let ang = k as f64 * std::f64::consts::TAU / LIP_RAYS as f64;
            let lip = centre + (u * ang.cos() + v * ang.sin()) * g.cup_radius_m;
            if let Err(t) = on_face(&lip, &axis) {
                outside += 1;
                if let Some(t @ (Tag::Part(_) | Tag::Env(_))) = t
                    && t != Tag::Part(part as u32)
                {
                    blocker.get_or_insert(t);
                }
            }
        }
        if outside > 0 {
            // Is the face wide enough for the cup at all? Measure it through the cup centre.
            let (fu, fv) = orthonormal(&normal);
            let step = 0.00025;
            let extent = |dir: Vector3<f64>| -> f64 {
                let mut d = 0.0;
                while d < 4.0 * g.cup_radius_m + 0.01 {
                    if on_face(&(face_point + dir * (d + step)), &-normal).is_err() {
                        break;
                    }
                    d += step;
                }
                d
            };
            let width = (0..4)
                .map(|k| {
                    let a = k as f64 * std::f64::consts::FRAC_PI_4;
                    let dir = fu * a.cos() + fv * a.sin();
                    extent(dir) + extent(-dir)
                })
                .fold(f64::INFINITY, f64::min);
            if width < 2.0 * g.cup_radius_m {
                return Err(GraspFailure::FaceTooSmall {
                    width_mm: width * 1e3,
                    cup_mm: 2e3 * g.cup_radius_m,
                });
            }
            if let Some(b) = blocker
                && b != Tag::Part(part as u32)
                && matches!(b, Tag::Part(_))
            {
                return Err(GraspFailure::Obstructed(self.describe(Some(b))));
            }
            return Err(GraspFailure::OnEdge { outside });
        }
        let com = self.part_pose(part) * nalgebra::Point3::from(self.part_shape.com_m);
        let rel = com.coords - centre;
        Ok(Seal {
            part,
            tilt_rad: tilt,
            com_from_cup_m: world_from_tool.rotation.inverse_transform_vector(&rel),
        })
    }

    /// Opens the vacuum valve: the seal is decided when the vacuum has built up.
    pub fn vacuum_on(&mut self) {
        self.gripper.vacuum_on(self.time_s);
    }

    /// Closes the vacuum valve: a held part comes off as the vacuum vents, at the latest after
    /// `release_s`.
    pub fn vacuum_off(&mut self) {
        self.gripper.vacuum_off(self.time_s);
    }

    /// The part on the cup, if any.
    pub fn held_part(&self) -> Option<usize> {
        self.gripper.held().map(|(seal, _)| seal.part)
    }

    /// The held part as a payload on the flange (for the robot's dynamics).
    pub fn held_payload(&self) -> Option<Payload> {
        let (_, tool_from_part) = self.gripper.held()?;
        let flange_from_part = self.robot.flange_from_tool * tool_from_part;
        let s = &self.part_shape;
        let r = flange_from_part.rotation.to_rotation_matrix();
        let inertia: Matrix3<f64> = r.matrix() * s.inertia_com_kg_m2 * r.matrix().transpose();
        Some(Payload {
            mass_kg: s.mass_kg,
            com_flange_m: (flange_from_part * nalgebra::Point3::from(s.com_m)).coords,
            inertia_com_kg_m2: inertia,
        })
    }

    fn attach(&mut self, seal: Seal) -> Isometry3<f64> {
        let (body, collider) = (self.parts[seal.part].body, self.parts[seal.part].collider);
        // The bellows: the cup seals on the part as it rests. A part the kinematic cup pressed
        // into the tray by the contact solver's tolerance (a few tenths of a millimetre) is held
        // where it rests, out of that overlap, not frozen into the tray (a real bellows takes
        // the overtravel up). Deeper overlaps are left alone: the health monitor reports them.
        if let Some(out_m) = self.env_overlap_exit_m(collider)
            && out_m.norm() <= BELLOWS_TAKE_UP_M
        {
            let pose = self.part_pose(seal.part);
            let lifted = Isometry3::from_parts(Translation3::from(pose.translation.vector + out_m), pose.rotation);
            self.bodies[body].set_position(to_pose(&lifted), true);
        }
        self.held_load = ContactLoad::default();
        let p = &mut self.parts[seal.part];
        p.state = PartState::Held;
        self.bodies[body].set_body_type(RigidBodyType::KinematicPositionBased, true);
        self.colliders[collider]
            .set_active_collision_types(ActiveCollisionTypes::default() | ActiveCollisionTypes::KINEMATIC_FIXED);
        self.world_from_tool().inverse() * self.part_pose(seal.part)
    }

    /// The shortest move [m, world] that takes `collider` out of its deepest overlap with the
    /// cell (trays, table, obstacles), from the last step's contacts; `None` if it overlaps
    /// nothing.
    fn env_overlap_exit_m(&self, collider: rapier3d::geometry::ColliderHandle) -> Option<Vector3<f64>> {
        let mut best: Option<(f64, Vector3<f64>)> = None;
        for pair in self.narrow_phase.contact_pairs_with(collider) {
            let (other, sign) = if pair.collider1 == collider {
                (pair.collider2, -1.0)
            } else {
                (pair.collider1, 1.0)
            };
            if !matches!(self.tag_of(other), Some(Tag::Env(_))) {
                continue;
            }
            for m in pair.solver_manifolds() {
                let depth_m = m
                    .points
                    .iter()
                    .map(|p| -(p.dist as f64) / SIM_UNITS_PER_M)
                    .fold(0.0, f64::max);
                let n = m.data.normal;
                let normal = Vector3::new(n.x as f64, n.y as f64, n.z as f64);
                if depth_m > 0.0 && best.as_ref().is_none_or(|(d, _)| depth_m > *d) {
                    best = Some((depth_m, normal * (sign * depth_m)));
                }
            }
        }
        best.map(|(_, v)| v)
    }

    fn detach(&mut self, part: usize) {
        let dt = self.dt_s();
        let [_, b, c] = self.tool_history;
        let vel = (c - b) / dt;
        let centre = self.part_pose(part).translation.vector;
        let p = &mut self.parts[part];
        let (body, collider) = (p.body, p.collider);
        p.state = if self.place_tray.contains(&centre) {
            PartState::Placed
        } else {
            PartState::Free
        };
        self.colliders[collider].set_active_collision_types(ActiveCollisionTypes::default());
        let b = &mut self.bodies[body];
        b.set_body_type(RigidBodyType::Dynamic, true);
        b.set_linvel(sim_point(&vel), true);
        b.set_angvel(rapier3d::math::Vector::ZERO, true);
    }

    /// The force the cup must exert on the sealed part against gravity and the tool's
    /// acceleration now, in the tool's frame (pull, shear over the lip's friction, peel: the
    /// cup's [`crate::geometry::SuctionModel::required_n`]), and against what other parts push on it (N).
    fn required_holding_n(&self, seal: &Seal) -> f64 {
        let g = Vector3::new(0.0, 0.0, -crate::robot::GRAVITY_M_S2);
        let specific_force = self
            .world_from_tool()
            .rotation
            .inverse_transform_vector(&(self.tool_acceleration() - g));
        let model = &self.gripper.model;
        let inertial = model.required_n(self.part_shape.mass_kg, &specific_force, &seal.com_from_cup_m);
        if !self.gripper.loaded_by_parts {
            return inertial;
        }
        let axis = self.world_from_tool().rotation * Vector3::z();
        let (f, m) = (self.held_load.force_n, self.held_load.moment_nm);
        let along = f.dot(&axis);
        let shear = (f - axis * along).norm();
        let across = (m - axis * m.dot(&axis)).norm();
        inertial + model.contact_required_n(along.max(0.0), shear, across)
    }

    /// The low-passed contact load on the held part ([`ContactLoad`]), if a part is held.
    pub fn held_contact_load(&self) -> Option<ContactLoad> {
        self.gripper.held().map(|_| self.held_load)
    }

    /// After a solved substep of `dt_s` with the tool at `world_from_tool`, one pass over the
    /// held part's contacts with other parts: each part in active contact with it is marked
    /// touching it now ([`World::rode_with_held`]); and, where the cell loads the seal with them
    /// (`gripper.seal_loaded_by_parts`), the normal impulses the solver applied that do not push
    /// it toward the cup ([`ContactLoad`]), and their moment about the cup centre, go into the
    /// low pass.
    /// Only dynamic bodies push: a kinematic held part gets no impulse from the tray or the arm.
    pub(super) fn update_held_contacts(&mut self, world_from_tool: &Isometry3<f64>, dt_s: f64) {
        let Some((seal, _)) = self.gripper.held() else {
            return;
        };
        let loaded = self.gripper.loaded_by_parts;
        let held = self.parts[seal.part].collider;
        let cup = world_from_tool.translation.vector;
        let axis = world_from_tool.rotation * Vector3::z();
        let held_pose = *self.colliders[held].position();
        let now = self.time_s;
        let mut raw = ContactLoad::default();
        for pair in self.narrow_phase.contact_pairs_with(held) {
            let (held_first, other) = if pair.collider1 == held {
                (true, pair.collider2)
            } else {
                (false, pair.collider1)
            };
            let Some(Tag::Part(other_part)) = self.tag_of(other) else {
                continue;
            };
            if pair.has_any_active_contact() {
                self.parts[other_part as usize].touched_held_s = now;
            }
            if !loaded {
                continue;
            }
            // The manifolds the solver saw (its contact clusters where it made them).
            for m in pair.solver_manifolds() {
                // The manifold's normal points from collider 1 to collider 2; the solver's
                // normal impulse pushes them apart.
                let n = dir_from_sim(m.data.normal);
                let toward_held = if held_first { -n } else { n };
                for pt in &m.points {
                    let impulse = pt.data.impulse as f64;
                    if impulse <= 0.0 {
                        continue;
                    }
                    let local = if held_first { pt.local_p1 } else { pt.local_p2 };
                    let at_m = point_from_sim(held_pose.transform_point(local));
                    // rapier units: kg mm / s; a force in N is that over dt, over 1000. A push
                    // toward the cup (a support under the held part; at rest its slant's
                    // sideways part is held by its friction, left out) is the lip's to carry.
                    let f = toward_held * (impulse / SIM_UNITS_PER_M / dt_s);
                    if f.dot(&axis) < 0.0 {
                        continue;
                    }
                    raw.force_n += f;
                    raw.moment_nm += (at_m - cup).cross(&f);
                }
            }
        }
        if !loaded {
            return;
        }
        let k = (dt_s / CONTACT_LOAD_LAG_S).min(1.0);
        self.held_load.force_n += (raw.force_n - self.held_load.force_n) * k;
        self.held_load.moment_nm += (raw.moment_nm - self.held_load.moment_nm) * k;
    }

    /// Whether part `part` touched the part on the cup within [`super::RODE_HELD_WINDOW_S`]
    /// before now: leaving its tray, it went with the held part (a double pick).
    pub fn rode_with_held(&self, part: usize) -> bool {
        self.parts
            .get(part)
            .is_some_and(|p| self.time_s - p.touched_held_s <= super::RODE_HELD_WINDOW_S)
    }

    /// Runs the gripper's timers and moves the held part with the tool; called by `step` before
    /// the solver, with the tool pose at the end of the step.
    pub(super) fn update_gripper(&mut self, world_from_tool_next: &Isometry3<f64>) {
        let now = self.time_s;
        match self.gripper.due(now) {
            GripperDue::Nothing => {}
            GripperDue::DecideSeal => match self.check_seal(&self.world_from_tool()) {
                Ok(seal) => {
                    let tool_from_part = self.attach(seal);
                    self.gripper.sealed(now, seal, tool_from_part);
                }
                Err(reason) => self.gripper.failed(now, reason),
            },
            GripperDue::CheckHold(seal) => {
                let required = self.required_holding_n(&seal);
                if required > self.gripper.holding_n {
                    self.detach(seal.part);
                    self.gripper.slipped(now, seal.part, required);
                }
            }
            GripperDue::CheckRelease(seal, left) => {
                if self.required_holding_n(&seal) > left * self.gripper.holding_n {
                    self.detach(seal.part);
                    self.gripper.released(now, seal.part);
                }
            }
            GripperDue::Release(seal) => {
                self.detach(seal.part);
                self.gripper.released(now, seal.part);
            }
        }
        self.move_held_part(world_from_tool_next);
    }

    /// Sets the held part's pose at the step's end: where the tool, at `world_from_tool_next`,
    /// carries it.
    pub(super) fn move_held_part(&mut self, world_from_tool_next: &Isometry3<f64>) {
        if let Some((seal, tool_from_part)) = self.gripper.held() {
            let body = self.parts[seal.part].body;
            super::set_next_kinematic(
                &mut self.bodies[body],
                to_pose(&(world_from_tool_next * tool_from_part)),
            );
        }
    }
}
