//! The arm in the physics world: its links' collision shapes as kinematic bodies, moved to the
//! servo's joint positions every step, and the tool's pose and acceleration read back.
//!
//! Units: m, rad (rapier's millimetres inside, converted at this boundary). Frames: world; each
//! link's shapes in its link frame.

use nalgebra::{Isometry3, Vector3};
use rapier3d::math::Pose;
use rapier3d::prelude::*;

use super::*;
use crate::robot::{DOF, JointVector, LinkPrimitive};

fn arm_collider(shape: SharedShape, pose: Pose, tag: Tag, with_fixed: bool) -> Collider {
    let types = if with_fixed {
        ActiveCollisionTypes::default() | ActiveCollisionTypes::KINEMATIC_FIXED
    } else {
        ActiveCollisionTypes::default()
    };
    ColliderBuilder::new(shape)
        .position(pose)
        .collision_groups(InteractionGroups::new(ARM, ENV | PARTS, InteractionTestMode::And))
        .active_collision_types(types)
        .friction(0.5)
        .user_data(tag.encode())
        .build()
}

impl World {
    pub(super) fn add_arm(&mut self, scene: &Scene) {
        let world_from_links = self.robot.world_from_links(&self.q);
        for (i, link) in self.robot.links.iter().enumerate() {
            let builder = if i == 0 {
                RigidBodyBuilder::fixed()
            } else {
                RigidBodyBuilder::kinematic_position_based()
            };
            let body = self.bodies.insert(builder.pose(to_pose(&world_from_links[i])));
            for s in &link.shapes {
                let (shape, local) = match s.primitive {
                    LinkPrimitive::Box { half_extents_m: h } => {
                        (SharedShape::cuboid(sim(h.x), sim(h.y), sim(h.z)), Isometry3::identity())
                    }
                    // rapier's cylinders and capsules run along +y; the URDF's along +z.
                    LinkPrimitive::Cylinder {
                        radius_m,
                        half_length_m,
                    } => (
                        SharedShape::cylinder(sim(half_length_m), sim(radius_m)),
                        Isometry3::rotation(Vector3::x() * std::f64::consts::FRAC_PI_2),
                    ),
                    LinkPrimitive::Sphere { radius_m } => (SharedShape::ball(sim(radius_m)), Isometry3::identity()),
                    LinkPrimitive::Capsule {
                        radius_m,
                        half_length_m,
                    } => (
                        SharedShape::capsule_z(sim(half_length_m), sim(radius_m)),
                        Isometry3::identity(),
                    ),
                };
                // The base stands on the table: its contact there is not a collision.
                let c = arm_collider(shape, to_pose(&(s.link_from_shape * local)), Tag::Link(i as u8), i > 0);
                self.colliders.insert_with_parent(c, body, &mut self.bodies);
            }
            self.link_bodies.push(body);
        }
        // The suction tool on the flange: a body cylinder, then the cup ending at the tool frame.
        let hand = crate::geometry::HandGeometry::new(&scene.gripper);
        let flange = self.link_bodies[DOF];
        let along_z = |z: f64| {
            Isometry3::translation(0.0, 0.0, z) * Isometry3::rotation(Vector3::x() * std::f64::consts::FRAC_PI_2)
        };
        let tool = arm_collider(
            SharedShape::cylinder(sim(hand.body_length_m / 2.0), sim(hand.body_radius_m)),
            to_pose(&along_z(hand.body_length_m / 2.0)),
            Tag::Tool,
            true,
        );
        self.colliders.insert_with_parent(tool, flange, &mut self.bodies);
        let cup = arm_collider(
            SharedShape::cylinder(sim(hand.cup_length_m / 2.0), sim(hand.cup_radius_m)),
            to_pose(&along_z(hand.tool_length_m - hand.cup_length_m / 2.0)),
            Tag::Cup,
            true,
        );
        self.colliders.insert_with_parent(cup, flange, &mut self.bodies);
    }

    /// Joint positions of the arm now (rad).
    pub fn joints(&self) -> JointVector {
        self.q
    }

    /// Puts the arm at `q` immediately (a teleport, no sweep); for setting up scenes.
    pub fn place_arm(&mut self, q: &JointVector) {
        self.q = *q;
        self.q_target = *q;
        let world_from_links = self.robot.world_from_links(q);
        for (i, h) in self.link_bodies.iter().enumerate().skip(1) {
            let pose = to_pose(&world_from_links[i]);
            let b = &mut self.bodies[*h];
            b.set_position(pose, true);
            b.set_next_kinematic_position(pose);
        }
        self.tool_history = [self.tool_position(); 3];
        self.refresh_queries();
    }

    /// Sets the joint positions the arm reaches at the end of the next step (rad). The link
    /// bodies sweep there during the step, pushing what they meet.
    pub fn set_joint_target(&mut self, q: &JointVector) {
        self.q_target = *q;
    }

    /// `world_from_tool` at the joint positions after the last step.
    pub fn world_from_tool(&self) -> Isometry3<f64> {
        self.robot.world_from_tool(&self.q)
    }

    pub(super) fn tool_position(&self) -> Vector3<f64> {
        self.world_from_tool().translation.vector
    }

    /// The tool's acceleration over the last two steps, finite differences [m/s^2].
    pub fn tool_acceleration(&self) -> Vector3<f64> {
        let dt = self.dt_s();
        let [a, b, c] = self.tool_history;
        (c - 2.0 * b + a) / (dt * dt)
    }
}
