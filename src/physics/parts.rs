//! The parts in the physics world: added as dynamic bodies, taken out, read back (poses, rest,
//! the placement error in a slot).
//!
//! Units: m, rad (rapier's millimetres inside, converted at this boundary). Frames: world; each
//! part in its part frame.

use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;

use super::*;

impl World {
    /// Adds a part at `world_from_part`, dynamic and awake. A part taken out of the cell before
    /// ([`World::remove_part`]) is put back in its place (the lowest index first), so a long run
    /// keeps as many bodies as the trays ever held at once, not one per part ever poured: the
    /// world's memory and every per-step walk over the parts stay bounded.
    pub fn add_part(&mut self, world_from_part: &Isometry3<f64>) -> usize {
        if let Some(idx) = self.parts.iter().position(|p| p.state == PartState::Removed) {
            let p = &mut self.parts[idx];
            p.state = PartState::Free;
            p.rest_ref = None;
            p.touched_held_s = f64::NEG_INFINITY;
            let b = &mut self.bodies[p.body];
            b.set_enabled(true);
            b.set_body_type(RigidBodyType::Dynamic, false);
            b.set_position(to_pose(world_from_part), false);
            b.set_linvel(Vector::ZERO, false);
            b.set_angvel(Vector::ZERO, false);
            b.reset_forces(false);
            b.reset_torques(false);
            b.wake_up(true);
            return idx;
        }
        let idx = self.parts.len();
        let body = self.bodies.insert(
            RigidBodyBuilder::dynamic()
                .pose(to_pose(world_from_part))
                .ccd_enabled(true)
                // Soft CCD: contacts are predicted along the body's path up to 10 mm ahead, so
                // a thin part falling at a few m/s meets the floor's constraint before it sinks.
                .soft_ccd_prediction(sim(0.01))
                .user_data(Tag::Part(idx as u32).encode()),
        );
        let s = &self.part_shape;
        let collider = self.colliders.insert_with_parent(
            ColliderBuilder::new(s.shape.clone())
                .mass(s.mass_kg as f32)
                .friction(s.friction as f32)
                .restitution(s.restitution as f32)
                .collision_groups(InteractionGroups::new(PARTS, Group::ALL, InteractionTestMode::And))
                .user_data(Tag::Part(idx as u32).encode()),
            body,
            &mut self.bodies,
        );
        let view_collider = self.colliders.insert_with_parent(
            ColliderBuilder::new(s.view_shape.clone())
                .mass_properties(MassProperties::default())
                .sensor(true)
                .collision_groups(InteractionGroups::new(
                    Group::GROUP_5,
                    Group::NONE,
                    InteractionTestMode::And,
                ))
                .user_data(Tag::Part(idx as u32).encode() | VIEW_FLAG),
            body,
            &mut self.bodies,
        );
        {
            let act = self.bodies[body].activation_mut();
            act.time_until_sleep = 0.2;
        }
        self.parts.push(PartBody {
            body,
            collider,
            view_collider,
            state: PartState::Free,
            rest_ref: None,
            touched_held_s: f64::NEG_INFINITY,
        });
        idx
    }

    /// Takes part `i` out of the cell: parked 10 m below the table (one spot per part, so parked
    /// parts never touch), disabled, state [`PartState::Removed`]. Indices of other parts stay;
    /// the next [`World::add_part`] takes this one's index and body.
    pub fn remove_part(&mut self, i: usize) {
        let Some(p) = self.parts.get_mut(i) else {
            return;
        };
        p.state = PartState::Removed;
        let parked = Isometry3::translation(i as f64 * 0.5, 0.0, -10.0);
        let b = &mut self.bodies[p.body];
        b.set_body_type(RigidBodyType::Fixed, false);
        b.set_position(to_pose(&parked), false);
        b.set_linvel(Vector::ZERO, false);
        b.set_angvel(Vector::ZERO, false);
        b.set_enabled(false);
    }

    /// Takes every part that is out of the tray it belongs in (a free part out of the pick tray,
    /// a placed one out of the place tray) out of the world: the parts the health monitor reports
    /// as having left their tray. Returns how many.
    pub fn remove_parts_out_of_their_trays(&mut self) -> usize {
        let mut removed = 0;
        for i in 0..self.part_count() {
            let c = self.part_pose(i).translation.vector;
            let out = match self.part_state(i) {
                PartState::Free => !self.pick_tray().contains(&c),
                PartState::Placed => !self.place_tray().contains(&c),
                PartState::Held | PartState::Removed => false,
            };
            if out {
                self.remove_part(i);
                removed += 1;
            }
        }
        removed
    }

    /// Indices of the parts in a given state.
    pub fn parts_in_state(&self, state: PartState) -> Vec<usize> {
        (0..self.parts.len())
            .filter(|&i| self.parts[i].state == state)
            .collect()
    }

    /// `world_from_part` of part `i`.
    pub fn part_pose(&self, i: usize) -> Isometry3<f64> {
        to_isometry(self.bodies[self.parts[i].body].position())
    }

    /// Whether part `i` lies in the place tray, at rest: fixed in its slot once it moved less
    /// than [`super::PLACED_REST_M`] and [`super::PLACED_REST_RAD`] over
    /// [`super::PLACED_REST_WINDOW_S`], or asleep by rapier's rule.
    pub fn placed_part_at_rest(&self, i: usize) -> bool {
        let p = &self.parts[i];
        p.state == PartState::Placed && !self.bodies[p.body].is_dynamic()
    }

    /// Whether every free part is asleep or slower than the given speeds.
    pub fn parts_at_rest(&self, lin_m_s: f64, ang_rad_s: f64) -> bool {
        self.parts.iter().all(|p| {
            let b = &self.bodies[p.body];
            matches!(p.state, PartState::Held | PartState::Removed)
                || b.is_sleeping()
                || ((b.linvel().length() as f64) < lin_m_s * SIM_UNITS_PER_M
                    && (b.angvel().length() as f64) < ang_rad_s)
        })
    }

    /// Indices of the free parts whose centre lies inside the pick tray's inner walls.
    pub fn parts_in_pick_tray(&self) -> Vec<usize> {
        (0..self.parts.len())
            .filter(|&i| {
                self.parts[i].state == PartState::Free
                    && self.pick_tray.inside_inner(&self.part_pose(i).translation.vector)
            })
            .collect()
    }

    /// Wakes every part up (for tests that disturb a settled pile).
    pub fn wake_parts(&mut self) {
        for p in &self.parts {
            self.bodies[p.body].wake_up(true);
        }
    }

    /// Moves part `i` to `world_from_part` at once, awake (for set-ups and tests).
    pub fn set_part_pose(&mut self, i: usize, world_from_part: &Isometry3<f64>) {
        let b = &mut self.bodies[self.parts[i].body];
        b.set_position(to_pose(world_from_part), true);
    }

    /// Sets part `i`'s velocity (m/s, world frame), awake, not turning (for set-ups and tests:
    /// a part flung).
    pub fn set_part_velocity(&mut self, i: usize, velocity_m_s: &Vector3<f64>) {
        let b = &mut self.bodies[self.parts[i].body];
        b.set_linvel(sim_point(velocity_m_s), true);
        b.set_angvel(Vector::ZERO, true);
    }
}
