//! The world's health monitor: what must never happen in the simulated cell, checked after every
//! step, every problem of a step reported (not only the first).
//!
//! Job: after each physics step, find non-finite poses or velocities, parts that left the tray
//! they belong in, the arm (its links, tool, cup and held part) pressing into the table, a tray
//! or an obstacle, and parts pressed into each other or into a tray deeper than the solver
//! allows; measure overlaps independently of the solver ([`super::overlap`]).
//!
//! Units: m inside the API (mm in the event texts, as a person reads them); the rapier world's
//! millimetres stay in this module. Frames: world.

use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;

use super::{PartState, SIM_UNITS_PER_M, Tag, World, overlap, point_from_sim, to_isometry};

/// One problem the health monitor found in a step. Written (in a run's fault record) as an
/// object whose `kind` names the variant.
#[derive(Debug, Clone, PartialEq, thiserror::Error, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum HealthEvent {
    /// A body's pose or velocity became NaN or infinite.
    #[error("t = {time_s:.4} s: {body} has a non-finite {what}")]
    NonFinite {
        /// Simulation time (s).
        time_s: f64,
        /// Which body.
        body: String,
        /// Pose or velocity.
        what: &'static str,
    },
    /// A part left the tray it should be in.
    #[error(
        "t = {time_s:.4} s: {body} left the {volume} volume{}, now at ({x:.4}, {y:.4}, {z:.4}) m",
        if *with_held { " with the part on the cup" } else { "" }
    )]
    LeftVolume {
        /// Simulation time (s).
        time_s: f64,
        /// Which part.
        body: String,
        /// Which tray's volume.
        volume: &'static str,
        /// Position (m).
        x: f64,
        /// Position (m).
        y: f64,
        /// Position (m).
        z: f64,
        /// Whether it touched the part on the cup just before
        /// ([`World::rode_with_held`]): carried out with it, a double pick.
        with_held: bool,
    },
    /// Two bodies overlap far more than the solver allows.
    #[error("t = {time_s:.4} s: deep penetration {depth_mm:.2} mm between {a} and {b}")]
    DeepPenetration {
        /// Simulation time (s).
        time_s: f64,
        /// First body.
        a: String,
        /// Second body.
        b: String,
        /// Overlap (mm).
        depth_mm: f64,
    },
    /// The arm, its tool or the held part ran into the table, a tray or an obstacle.
    #[error("t = {time_s:.4} s: collision: {robot} penetrates {obstacle} by {depth_mm:.2} mm")]
    ArmCollision {
        /// Simulation time (s).
        time_s: f64,
        /// Which link, the tool or the held part.
        robot: String,
        /// What it hit.
        obstacle: String,
        /// Overlap (mm).
        depth_mm: f64,
    },
}

/// A [`HealthEvent`] read back from a written record: its fixed texts checked against the ones
/// the monitor writes.
mod known_text {
    use super::HealthEvent;

    /// As written.
    #[derive(serde::Deserialize)]
    #[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
    pub enum Written {
        NonFinite {
            time_s: f64,
            body: String,
            what: String,
        },
        LeftVolume {
            time_s: f64,
            body: String,
            volume: String,
            x: f64,
            y: f64,
            z: f64,
            #[serde(default)]
            with_held: bool,
        },
        DeepPenetration {
            time_s: f64,
            a: String,
            b: String,
            depth_mm: f64,
        },
        ArmCollision {
            time_s: f64,
            robot: String,
            obstacle: String,
            depth_mm: f64,
        },
    }

    fn one_of(text: &str, known: &[&'static str]) -> Result<&'static str, String> {
        known
            .iter()
            .find(|k| **k == text)
            .copied()
            .ok_or_else(|| format!("{text:?} is not one of {known:?}"))
    }

    impl<'de> serde::Deserialize<'de> for HealthEvent {
        fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            HealthEvent::try_from(Written::deserialize(d)?).map_err(serde::de::Error::custom)
        }
    }

    impl TryFrom<Written> for HealthEvent {
        type Error = String;

        fn try_from(w: Written) -> Result<Self, String> {
            Ok(match w {
                Written::NonFinite { time_s, body, what } => HealthEvent::NonFinite {
                    time_s,
                    body,
                    what: one_of(&what, &["pose", "velocity"])?,
                },
                Written::LeftVolume {
                    time_s,
                    body,
                    volume,
                    x,
                    y,
                    z,
                    with_held,
                } => HealthEvent::LeftVolume {
                    time_s,
                    body,
                    volume: one_of(&volume, &["pick tray", "place tray"])?,
                    x,
                    y,
                    z,
                    with_held,
                },
                Written::DeepPenetration { time_s, a, b, depth_mm } => {
                    HealthEvent::DeepPenetration { time_s, a, b, depth_mm }
                }
                Written::ArmCollision {
                    time_s,
                    robot,
                    obstacle,
                    depth_mm,
                } => HealthEvent::ArmCollision {
                    time_s,
                    robot,
                    obstacle,
                    depth_mm,
                },
            })
        }
    }
}

/// Every problem of one step (at least one), in the monitor's order: parts first (non-finite
/// states, parts out of their tray, in part order), then contacts (in the narrow phase's order).
#[derive(Debug, Clone, PartialEq)]
pub struct HealthError {
    /// The world's step at which they were found (its count of steps taken).
    pub step: u64,
    /// Simulation time after that step (s).
    pub time_s: f64,
    /// The problems.
    pub events: Vec<HealthEvent>,
}

impl std::fmt::Display for HealthError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let lines: Vec<String> = self.events.iter().map(ToString::to_string).collect();
        f.write_str(&lines.join("; "))
    }
}

impl std::error::Error for HealthError {}

impl HealthError {
    /// The first problem.
    pub fn first(&self) -> Option<&HealthEvent> {
        self.events.first()
    }

    /// Whether any problem makes the state unusable (a non-finite pose or velocity).
    pub fn is_fatal(&self) -> bool {
        self.events.iter().any(|e| matches!(e, HealthEvent::NonFinite { .. }))
    }
}

/// Limits of the health monitor.
#[derive(Debug, Clone, Copy)]
pub struct HealthLimits {
    /// Part-part or part-environment overlap that counts as a failure (m).
    pub deep_penetration_m: f64,
    /// Arm-environment overlap that counts as a collision (m).
    pub arm_collision_m: f64,
}

impl Default for HealthLimits {
    fn default() -> Self {
        HealthLimits {
            deep_penetration_m: crate::config::DEFAULT_DEEP_PENETRATION_LIMIT_M,
            arm_collision_m: 0.0002,
        }
    }
}

/// The health monitor: its limits and the check.
#[derive(Debug, Clone, Copy, Default)]
pub struct HealthMonitor {
    /// Limits.
    pub limits: HealthLimits,
}

impl HealthMonitor {
    /// Every problem in `w` now: each part's pose and velocity finite and the part inside its
    /// tray (free parts the pick tray, placed ones the place tray); each contact of the arm, its
    /// tool or the held part with the cell no deeper than [`HealthLimits::arm_collision_m`];
    /// each contact between parts or a part and the cell no deeper than
    /// [`HealthLimits::deep_penetration_m`] (confirmed by the exact depth). A contact whose
    /// bodies all sleep (or are fixed) is skipped: it was checked while they were awake and has
    /// not changed since.
    pub fn check(&self, w: &World) -> Vec<HealthEvent> {
        let t = w.time_s;
        let mut events = Vec::new();
        for (i, p) in w.parts.iter().enumerate() {
            let b = &w.bodies[p.body];
            let pos = b.position();
            let name = || w.describe(Some(Tag::Part(i as u32)));
            if !(pos.translation.is_finite() && pos.rotation.is_finite()) {
                events.push(HealthEvent::NonFinite {
                    time_s: t,
                    body: name(),
                    what: "pose",
                });
            }
            if !(b.linvel().is_finite() && b.angvel().is_finite()) {
                events.push(HealthEvent::NonFinite {
                    time_s: t,
                    body: name(),
                    what: "velocity",
                });
            }
            let c = point_from_sim(pos.translation);
            let (ok, volume) = match p.state {
                PartState::Free => (w.pick_tray.contains(&c), "pick tray"),
                PartState::Placed => (w.place_tray.contains(&c), "place tray"),
                PartState::Held | PartState::Removed => (true, ""),
            };
            if !ok {
                events.push(HealthEvent::LeftVolume {
                    time_s: t,
                    body: name(),
                    volume,
                    x: c.x,
                    y: c.y,
                    z: c.z,
                    with_held: w.rode_with_held(i),
                });
            }
        }
        // A pair whose bodies all sleep (or are fixed) has not moved since it was last checked
        // awake: its contacts are as they were then.
        let still = |c| {
            w.colliders.get(c).and_then(|c| c.parent()).is_none_or(|b| {
                let b = &w.bodies[b];
                b.is_sleeping() || b.is_fixed()
            })
        };
        for pair in w.narrow_phase.contact_pairs() {
            if !pair.has_any_active_contact() || (still(pair.collider1) && still(pair.collider2)) {
                continue;
            }
            let (t1, t2) = (w.tag_of(pair.collider1), w.tag_of(pair.collider2));
            let deepest = pair
                .manifolds()
                .iter()
                .flat_map(|m| m.points.iter())
                .map(|p| -(p.dist as f64) / SIM_UNITS_PER_M)
                .fold(0.0, f64::max);
            let held = |tag: Option<Tag>| matches!(tag, Some(Tag::Part(i)) if w.parts.get(i as usize).is_some_and(|p| p.state == PartState::Held));
            let robotish = |tag: Option<Tag>| tag.is_some_and(Tag::is_robot) || held(tag);
            // A part at rest in its slot is fixed there ([`super::PLACED_REST_WINDOW_S`]): the
            // arm touching it is a collision, as with the tray it stands in.
            let placed_at_rest = |tag: Option<Tag>| {
                matches!(tag, Some(Tag::Part(i)) if w.parts.get(i as usize).is_some_and(|p| {
                    p.state == PartState::Placed && w.bodies[p.body].is_fixed()
                }))
            };
            let env = |tag: Option<Tag>| matches!(tag, Some(Tag::Env(_))) || placed_at_rest(tag);
            if (robotish(t1) && env(t2)) || (robotish(t2) && env(t1)) {
                // The manifold is from the start of the step, and a pair rapier no longer
                // updates keeps its last one: a part just taken as held, against the tray floor,
                // kept a 22.5 mm depth while it stood 5 mm above the floor (SMD electrolytic,
                // sustained seed 2, pick 93). Confirmed with the exact depth now, where parry can
                // query the two shapes; else the manifold's stands.
                let depth_m = if deepest > self.limits.arm_collision_m {
                    w.exact_depth_if_known_m(pair.collider1, pair.collider2)
                        .unwrap_or(deepest)
                } else {
                    deepest
                };
                if depth_m > self.limits.arm_collision_m {
                    let (r, o) = if robotish(t1) { (t1, t2) } else { (t2, t1) };
                    let obstacle = if placed_at_rest(o) {
                        format!("placed {}", w.describe(o))
                    } else {
                        w.describe(o)
                    };
                    events.push(HealthEvent::ArmCollision {
                        time_s: t,
                        robot: w.describe(r),
                        obstacle,
                        depth_mm: depth_m * 1e3,
                    });
                }
            } else if !robotish(t1) && !robotish(t2) && deepest > self.limits.deep_penetration_m {
                // The manifold is from the start of the step: confirm with the exact depth now.
                let exact = w.exact_depth_m(pair.collider1, pair.collider2);
                if exact > self.limits.deep_penetration_m {
                    events.push(HealthEvent::DeepPenetration {
                        time_s: t,
                        a: w.describe(t1),
                        b: w.describe(t2),
                        depth_mm: exact * 1e3,
                    });
                }
            }
        }
        events
    }
}

impl World {
    /// Deepest overlap between two parts, or a part and a tray (m), with the bodies involved.
    /// Computed independently of the solver: exact separating-axis depths between the workpiece's
    /// convex pieces ([`overlap`]); for mesh workpieces, parry's contact query on the colliders.
    pub fn max_penetration_m(&self) -> (f64, Option<(Tag, Tag)>) {
        let Some(pieces) = &self.part_shape.pieces else {
            return self.max_penetration_parry();
        };
        let poses: Vec<Isometry3<f64>> = (0..self.parts.len()).map(|i| self.part_pose(i)).collect();
        let (d, i, j) = overlap::max_depth(&poses, pieces, self.part_shape.bounding_radius_m, &self.tray_pieces);
        if d <= 0.0 {
            return (0.0, None);
        }
        let b = if j == usize::MAX {
            Tag::Env(u32::MAX)
        } else {
            Tag::Part(j as u32)
        };
        (d, Some((Tag::Part(i as u32), b)))
    }

    fn max_penetration_parry(&self) -> (f64, Option<(Tag, Tag)>) {
        let mut worst = (0.0, None);
        for pair in self.narrow_phase.contact_pairs() {
            let (Some(c1), Some(c2)) = (self.colliders.get(pair.collider1), self.colliders.get(pair.collider2)) else {
                continue;
            };
            let (t1, t2) = (Tag::decode(c1.user_data), Tag::decode(c2.user_data));
            if t1.is_some_and(Tag::is_robot) || t2.is_some_and(Tag::is_robot) {
                continue;
            }
            // parry's `contact` can report a depth for shapes that are apart; ask first whether they meet.
            let (p1, s1, p2, s2) = (c1.position(), c1.shape(), c2.position(), c2.shape());
            if !rapier3d::parry::query::intersection_test(p1, s1, p2, s2).is_ok_and(|r| r.intersecting) {
                continue;
            }
            if let Ok(Some(c)) = rapier3d::parry::query::contact(p1, s1, p2, s2, 0.0) {
                let depth = -(c.dist as f64) / SIM_UNITS_PER_M;
                if depth > worst.0 {
                    worst = (depth, t1.zip(t2));
                }
            }
        }
        worst
    }

    /// Exact overlap depth of two colliders now (m): separating axes on the workpiece's convex
    /// pieces against a part or a box, else parry's contact query (0 for a pair it cannot query).
    pub fn exact_depth_m(&self, a: ColliderHandle, b: ColliderHandle) -> f64 {
        self.exact_depth_if_known_m(a, b).unwrap_or(0.0)
    }

    /// [`World::exact_depth_m`], `None` for a pair of shapes parry cannot query.
    fn exact_depth_if_known_m(&self, a: ColliderHandle, b: ColliderHandle) -> Option<f64> {
        let piece_sets = |h: ColliderHandle| -> Option<(Isometry3<f64>, Vec<overlap::Polytope>)> {
            let c = self.colliders.get(h)?;
            match Tag::decode(c.user_data)? {
                Tag::Part(i) => Some((self.part_pose(i as usize), self.part_shape.pieces.clone()?)),
                _ => {
                    let he = c.shape().as_cuboid()?.half_extents;
                    Some((
                        to_isometry(c.position()),
                        vec![overlap::Polytope::cuboid(Vector3::zeros(), point_from_sim(he))],
                    ))
                }
            }
        };
        if let (Some((pa, ka)), Some((pb, kb))) = (piece_sets(a), piece_sets(b)) {
            return Some(
                ka.iter()
                    .flat_map(|x| kb.iter().map(move |y| (x, y)))
                    .map(|(x, y)| overlap::depth(&pa, x, &pb, y))
                    .fold(0.0, f64::max),
            );
        }
        let (Some(c1), Some(c2)) = (self.colliders.get(a), self.colliders.get(b)) else {
            return Some(0.0);
        };
        let (p1, s1, p2, s2) = (c1.position(), c1.shape(), c2.position(), c2.shape());
        match rapier3d::parry::query::intersection_test(p1, s1, p2, s2) {
            Err(_) => return None,
            Ok(r) if !r.intersecting => return Some(0.0),
            Ok(_) => {}
        }
        match rapier3d::parry::query::contact(p1, s1, p2, s2, 0.0) {
            Ok(Some(c)) => Some((-(c.dist as f64) / SIM_UNITS_PER_M).max(0.0)),
            Ok(None) => Some(0.0),
            Err(_) => None,
        }
    }
}
