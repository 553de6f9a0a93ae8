//! Event-driven stepping: which steps need the solver, and the quiet step that replaces the
//! others.
//!
//! Job: decide before each step whether anything can move in it. A step is quiet when every
//! part in both trays sleeps, the pick tray rests, the gripper is idle or holds its part (no
//! seal, no release due) and no kinematic collider (the arm's links, tool and cup, the held
//! part) can come within [`QUIET_MARGIN_M`] of a part or of the cell's boxes (table, trays,
//! obstacles) during the step: its pose at the end of the step, its exact distance to every
//! target whose box it may reach, less the farthest any of its points travels in the step (the
//! translation plus the turn times its bounding radius). A quiet step moves the kinematic
//! bodies to where the step ends and keeps scene queries up to date (collider poses, the query
//! tree) but runs no solver: sleeping parts would not have moved and nothing could have woken
//! them. The check runs every step, so the solver resumes on the first step in which a contact
//! becomes possible, wherever the arm's planned motion takes it.
//!
//! A part that wakes (the pile woken by a seal, an agitation, a pour, the arm) has its contacts
//! recomputed in the step after it woke ([`World::set_refresh_woken_contacts`]): rapier would
//! otherwise keep the contacts it recycled while the pile slept, and a woken pile of strips
//! could be pressed into the floor, into each other or into a wall.
//!
//! Continuous collision detection (CCD) runs only in a step that needs it: one in which some
//! awake part's point, or the pick tray, can travel farther than [`CCD_TRAVEL_M`] (a pour, a
//! drop, a part flung). Parts at rest, rocking in a settling pile or shaken with the tray are
//! stepped without it: their contacts are predicted (soft CCD) well beyond a step's travel.
//!
//! What may differ from stepping always: rapier's internal order (its query tree, contact
//! graph, solver caches) after a quiet spell, so a contact resumed later may come out
//! differently in the last bits. Sleeping bodies themselves are never integrated by rapier, so
//! the parts do not move in a quiet step either way.
//!
//! Units: m and s at the API; rapier's millimetres inside. Frames: world.

use nalgebra::Isometry3;
use rapier3d::parry::bounding_volume::{Aabb, BoundingVolume};
use rapier3d::prelude::*;

use super::*;

/// The clearance a kinematic collider must keep from every part and cell box throughout a
/// step for the step to be quiet (m): ten times rapier's prediction distance, so no contact,
/// speculative or not, can start in it.
pub const QUIET_MARGIN_M: f64 = 0.002;

/// Continuous collision detection runs in a step in which some awake part's point, or the
/// pick tray, can travel farther than this (m). Every part predicts its contacts 10 mm along
/// its path (soft CCD), and the trays' floors and walls are 6–8 mm thick, so a step that
/// moves nothing by 1 mm cannot tunnel; rapier's own test, half the thinnest convex piece's
/// half extent (0.08 mm for a 0.3 mm terminal), would sweep every part still rocking in a
/// settling or shaken pile. 1 mm a step is 0.5 m/s at the 2 ms step: a part falls that fast
/// after 13 mm.
pub const CCD_TRAVEL_M: f64 = 0.001;

/// Most exact distance queries one quiet check makes: beyond, the arm is among parts and the
/// step is solved.
const MAX_EXACT_QUERIES: usize = 12;

/// The colliders a kinematic body may not come near in a quiet step, with their boxes (rapier
/// units): gathered once while nothing moves, dropped after every solved step.
pub(super) struct QuietTargets {
    /// The cell's boxes.
    env: Vec<(ColliderHandle, Aabb)>,
    /// The free and placed parts' colliders.
    parts: Vec<(ColliderHandle, Aabb)>,
    /// The box around all parts, if any.
    parts_box: Option<Aabb>,
}

/// One kinematic collider where the step would take it.
struct Mover {
    handle: ColliderHandle,
    /// Pose at the end of the step.
    end: Pose,
    /// Farthest any of its points travels in the step (m).
    travel_m: f64,
}

impl World {
    /// How the world is stepped.
    pub fn stepping(&self) -> Stepping {
        self.stepping
    }

    /// Steps as `stepping` says from now on.
    pub fn set_stepping(&mut self, stepping: Stepping) {
        self.stepping = stepping;
    }

    /// Steps taken without the solver (quiet steps), of [`World::steps`].
    pub fn quiet_steps(&self) -> u64 {
        self.quiet_steps
    }

    /// Whether part `i` is asleep (a part taken out of the cell counts as asleep).
    pub fn part_sleeping(&self, i: usize) -> bool {
        let p = &self.parts[i];
        p.state == PartState::Removed || self.bodies[p.body].is_sleeping()
    }

    /// After a step: the contacts of every part that slept before it and is awake now are
    /// recomputed in the next step, from the parts' poses. rapier 0.36.1 recycles a contact
    /// whose two bodies moved less than its recycle distance (0.5 mm here) since the contact
    /// was last computed, so a pile that wakes keeps the contacts it had when it went to
    /// sleep, stale by up to 0.15 mm (the unit test below). A collision-group change is the public way to make rapier recompute a
    /// collider's pairs: the solver groups are switched away and back, which leaves them as
    /// they were and marks the collider changed.
    pub(super) fn refresh_contacts_of_woken_parts(&mut self) {
        for (p, &asleep) in self.parts.iter().zip(&self.asleep_before) {
            let body = &self.bodies[p.body];
            if !asleep || body.is_sleeping() {
                continue;
            }
            for &c in body.colliders() {
                let collider = &mut self.colliders[c];
                let groups = collider.solver_groups();
                collider.set_solver_groups(InteractionGroups::none());
                collider.set_solver_groups(groups);
            }
        }
    }

    /// Whether the next step needs continuous collision detection: the farthest point of an
    /// awake part travels `part_travel_m` in it (at the speeds the step starts with; gravity
    /// adds 0.02 mm a step), and it or the pick tray's travel exceeds [`CCD_TRAVEL_M`] (as set).
    pub(super) fn ccd_needed(&self, part_travel_m: f64) -> bool {
        let (tray_from, tray_to) = self.pick_tray_offset_m;
        self.stepping == Stepping::Always
            || part_travel_m > self.ccd_travel_m
            || (tray_to - tray_from).norm() > self.ccd_travel_m
    }

    /// Whether the next step, with the arm's links going to `world_from_links`, is quiet (see
    /// the module header): checked before the gripper runs.
    pub(super) fn step_is_quiet(&mut self, world_from_links: &[Isometry3<f64>]) -> bool {
        if self.stepping != Stepping::EventDriven
            || self.pick_tray_moving()
            || self.pick_tray_offset_m.1 != nalgebra::Vector3::zeros()
        {
            return false;
        }
        if !matches!(
            self.gripper.due(self.time_s),
            suction::GripperDue::Nothing | suction::GripperDue::CheckHold(_)
        ) {
            return false;
        }
        if !self
            .parts
            .iter()
            .all(|p| matches!(p.state, PartState::Removed | PartState::Held) || self.bodies[p.body].is_sleeping())
        {
            return false;
        }
        let movers = self.movers(world_from_links);
        if self.quiet_targets.is_none() {
            self.quiet_targets = Some(self.gather_targets());
        }
        let Some(targets) = self.quiet_targets.as_ref() else {
            return false;
        };
        let mut exact = 0;
        for m in &movers {
            let c = &self.colliders[m.handle];
            let reach_m = m.travel_m + QUIET_MARGIN_M;
            let reach = c.shape().compute_aabb(&m.end).loosened(sim(reach_m));
            let near_parts = targets.parts_box.is_some_and(|b| b.intersects(&reach));
            let candidates = targets
                .env
                .iter()
                .chain(targets.parts.iter().filter(|_| near_parts))
                .filter(|(_, b)| b.intersects(&reach));
            for (h, _) in candidates {
                exact += 1;
                if exact > MAX_EXACT_QUERIES {
                    return false;
                }
                let t = &self.colliders[*h];
                let d = rapier3d::parry::query::distance(&m.end, c.shape(), t.position(), t.shape());
                match d {
                    Ok(d) if (d.distance as f64) / SIM_UNITS_PER_M > reach_m => {}
                    _ => return false,
                }
            }
        }
        true
    }

    /// The kinematic colliders (the arm's moving links with tool and cup, the held part) and
    /// where the step takes them.
    fn movers(&self, world_from_links: &[Isometry3<f64>]) -> Vec<Mover> {
        let mut out = Vec::with_capacity(16);
        let mut push = |handle: ColliderHandle, body_end: &Isometry3<f64>, radius_m: f64| {
            let c = &self.colliders[handle];
            let end = to_pose(body_end) * c.position_wrt_parent().copied().unwrap_or(Pose::IDENTITY);
            let (a, b) = (to_isometry(c.position()), to_isometry(&end));
            let travel_m =
                (b.translation.vector - a.translation.vector).norm() + a.rotation.angle_to(&b.rotation) * radius_m;
            out.push(Mover { handle, end, travel_m });
        };
        for (i, body) in self.link_bodies.iter().enumerate().skip(1) {
            for h in self.bodies[*body].colliders() {
                let c = &self.colliders[*h];
                let sphere = c.shape().compute_local_bounding_sphere();
                let radius_m = (sphere.center().length() + sphere.radius()) as f64 / SIM_UNITS_PER_M;
                push(*h, &world_from_links[i], radius_m);
            }
        }
        if let Some((seal, tool_from_part)) = self.gripper.held() {
            let end = world_from_links[DOF] * self.robot.flange_from_tool * tool_from_part;
            push(self.parts[seal.part].collider, &end, self.part_shape.bounding_radius_m);
        }
        out
    }

    /// The cell's boxes and the free and placed parts, with their boxes now.
    fn gather_targets(&self) -> QuietTargets {
        let mut env = Vec::new();
        for (h, c) in self.colliders.iter() {
            if matches!(Tag::decode(c.user_data), Some(Tag::Env(_))) {
                env.push((h, c.compute_aabb()));
            }
        }
        let parts: Vec<(ColliderHandle, Aabb)> = self
            .parts
            .iter()
            .filter(|p| matches!(p.state, PartState::Free | PartState::Placed))
            .map(|p| (p.collider, self.colliders[p.collider].compute_aabb()))
            .collect();
        let parts_box = parts.iter().map(|(_, b)| *b).reduce(|a, b| a.merged(&b));
        QuietTargets { env, parts, parts_box }
    }

    /// A quiet step: the arm's bodies (and the held part) go to where the step ends, the
    /// gripper's timers run, scene queries see the new poses, the clock advances; no solver.
    /// Returns `false` (having done nothing but run the gripper) if the gripper let its part
    /// go, so the step must be solved.
    pub(super) fn quiet_step(&mut self, world_from_links: &[Isometry3<f64>]) -> bool {
        let world_from_tool_next = world_from_links[DOF] * self.robot.flange_from_tool;
        self.update_gripper(&world_from_tool_next);
        if !matches!(
            self.gripper.due(self.time_s),
            suction::GripperDue::Nothing | suction::GripperDue::CheckHold(_)
        ) || self
            .parts
            .iter()
            .any(|p| p.state != PartState::Removed && p.state != PartState::Held && !self.bodies[p.body].is_sleeping())
        {
            return false;
        }
        let mut moved = Vec::with_capacity(16);
        for (i, h) in self.link_bodies.iter().enumerate().skip(1) {
            self.bodies[*h].set_position(to_pose(&world_from_links[i]), false);
            moved.extend_from_slice(self.bodies[*h].colliders());
        }
        if let Some((seal, tool_from_part)) = self.gripper.held() {
            let body = self.parts[seal.part].body;
            self.bodies[body].set_position(to_pose(&(world_from_tool_next * tool_from_part)), false);
            moved.extend_from_slice(self.bodies[body].colliders());
        }
        self.bodies
            .propagate_modified_body_positions_to_colliders(&mut self.colliders);
        let prediction = self.params.prediction_distance();
        for h in moved {
            let aabb = self.colliders[h].compute_aabb().loosened(prediction);
            self.broad_phase.set_aabb(&self.params, h, aabb);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{LoadedScene, LoadedWorkpiece};
    use crate::physics::pile::PileOptions;
    use crate::robot::RobotModel;

    /// Over the contact pairs of the parts `woken`: the largest gap between the nearest point
    /// rapier holds for a pair and the pair's signed distance computed afresh by parry from the
    /// colliders' poses (m).
    fn contact_staleness_m(w: &World, woken: &[usize]) -> f64 {
        let mut worst = 0.0f32;
        for &i in woken {
            for &c in w.bodies[w.parts[i].body].colliders() {
                for pair in w.narrow_phase.contact_pairs_with(c) {
                    let nearest = pair
                        .manifolds()
                        .iter()
                        .flat_map(|m| m.points.iter())
                        .map(|pt| pt.dist)
                        .reduce(f32::min);
                    let (c1, c2) = (&w.colliders[pair.collider1], &w.colliders[pair.collider2]);
                    let fresh =
                        rapier3d::parry::query::contact(c1.position(), c1.shape(), c2.position(), c2.shape(), 1.0);
                    if let (Some(nearest), Ok(Some(fresh))) = (nearest, fresh) {
                        worst = worst.max((fresh.dist - nearest).abs());
                    }
                }
            }
        }
        f64::from(worst) / SIM_UNITS_PER_M
    }

    /// A sleeping pile woken (here by the tray turned kinematic for a step, moved 1 um) has its
    /// woken parts' contacts recomputed in the next step: within 20 um of the geometry (1-10 um
    /// measured, what the parts move in a step). Negative control: without the refresh rapier
    /// keeps the contacts it recycled while the pile slept, 44-154 um off for these piles.
    #[test]
    fn a_woken_pile_has_its_contacts_recomputed() {
        let scene = LoadedScene::embedded_default().unwrap();
        let robot = RobotModel::from_scene(&scene).unwrap();
        for (part, seed) in [("A", 1), ("A", 3), ("C", 1), ("C", 4)] {
            let mut gaps_m = [0.0; 2];
            for (k, refresh) in [true, false].into_iter().enumerate() {
                let wp = LoadedWorkpiece::resolve(part).unwrap();
                let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
                let mut w = World::new(&scene.scene, &robot, shape);
                w.set_refresh_woken_contacts(refresh);
                w.build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, seed))
                    .unwrap();
                for _ in 0..100 {
                    if (0..w.part_count()).all(|i| w.part_sleeping(i)) {
                        break;
                    }
                    w.run_for(0.1).unwrap();
                }
                assert!(
                    (0..w.part_count()).all(|i| w.part_sleeping(i)),
                    "{part} seed {seed}: the pile sleeps"
                );
                w.set_pick_tray_offset(nalgebra::Vector3::new(1e-6, 0.0, 0.0));
                w.step().unwrap();
                let woken: Vec<usize> = (0..w.part_count()).filter(|&i| !w.part_sleeping(i)).collect();
                assert!(woken.len() > 10, "{part} seed {seed}: {} parts woke", woken.len());
                w.set_pick_tray_offset(nalgebra::Vector3::zeros());
                w.step().unwrap();
                gaps_m[k] = contact_staleness_m(&w, &woken);
            }
            assert!(
                gaps_m[0] < 2e-5,
                "{part} seed {seed}: {:.4} mm stale with the refresh",
                gaps_m[0] * 1e3
            );
            assert!(
                gaps_m[1] > 3e-5,
                "{part} seed {seed}: {:.4} mm without the refresh",
                gaps_m[1] * 1e3
            );
        }
    }
}
