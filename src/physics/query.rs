//! Scene queries for sensing and checking, in metres: rays (the cup's seal probe, the
//! evaluation's ground truth, the independent check of the rasterized depth), the view frustum
//! against the arm, a part's own silhouette, and the arm's exact shapes against the cell.
//!
//! Job: answer geometric questions about the world as it is now without letting rapier's
//! millimetres or its collider handles out of `physics`: a caller passes points and directions in
//! metres and gets distances in metres and [`Tag`]s. Parts are seen by rays through their view
//! twin (boxes as cuboids), not their physics collider; every shape through parry's own ray casts
//! (the sensor rasterizes instead, `physics/view.rs`).
//!
//! Units: m, unit direction vectors. Frames: world.

use nalgebra::{Isometry3, Vector3};
use rapier3d::math::Pose;
use rapier3d::prelude::*;

use super::{
    PartState, SIM_UNITS_PER_M, Tag, World, dir_from_sim, point_from_sim, ray_visible, sim, sim_dir, sim_point, to_pose,
};
use crate::robot::JointVector;

/// The first thing a ray meets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// What it is.
    pub tag: Tag,
    /// Distance along the (unit) ray (m).
    pub distance_m: f64,
    /// Surface normal at the hit (unit, world frame).
    pub normal: Vector3<f64>,
}

/// Which colliders a [`RayCaster`] sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RayTargets {
    /// Everything.
    All,
    /// The fixed cell only: table, trays, obstacles.
    Fixed,
    /// Everything that moves: parts, arm links, tool, cup, held part.
    Moving,
}

/// Casts many rays against one state of the world (built once, shared by threads): an
/// independent check of the rasterized depth (parry's exact shapes), and the single rays of
/// [`World::cast_ray`].
pub struct RayCaster<'w> {
    world: &'w World,
    pipeline: QueryPipeline<'w>,
}

impl RayCaster<'_> {
    /// The first hit of the ray from `origin` along the unit `dir` within `max_m` (m).
    pub fn cast(&self, origin: &Vector3<f64>, dir: &Vector3<f64>, max_m: f64) -> Option<RayHit> {
        let ray = Ray::new(sim_point(origin), sim_dir(dir));
        let (h, hit) = self.pipeline.cast_ray_and_get_normal(&ray, sim(max_m), true)?;
        Some(RayHit {
            tag: self.world.tag_of(h)?,
            distance_m: hit.time_of_impact as f64 / SIM_UNITS_PER_M,
            normal: dir_from_sim(hit.normal),
        })
    }
}

/// A convex volume in the world (e.g. a camera's view frustum over a tray), to test the arm
/// against.
#[derive(Clone)]
pub struct ViewVolume {
    /// The convex hull, in rapier units.
    shape: SharedShape,
}

impl ViewVolume {
    /// The convex hull of `points_m` [m, world]; `None` if they span no volume.
    pub fn hull(points_m: &[Vector3<f64>]) -> Option<Self> {
        let pts: Vec<_> = points_m.iter().map(sim_point).collect();
        SharedShape::convex_hull(&pts).map(|shape| ViewVolume { shape })
    }
}

impl World {
    /// A ray caster over the colliders of `targets` that rays see.
    pub fn ray_caster(&self, targets: RayTargets) -> RayCaster<'_> {
        let filter = match targets {
            RayTargets::All => QueryFilter::default(),
            RayTargets::Fixed => QueryFilter::only_fixed(),
            RayTargets::Moving => QueryFilter::exclude_fixed(),
        };
        RayCaster {
            world: self,
            pipeline: self.broad_phase.as_query_pipeline(
                self.narrow_phase.query_dispatcher(),
                &self.bodies,
                &self.colliders,
                filter.predicate(&ray_visible),
            ),
        }
    }

    /// Casts one ray into the world: the first hit along the unit `dir` within `max_m` (m) that
    /// `skip` does not pass through.
    pub fn cast_ray(
        &self,
        origin: &Vector3<f64>,
        dir: &Vector3<f64>,
        max_m: f64,
        skip: &dyn Fn(Tag) -> bool,
    ) -> Option<RayHit> {
        let pred =
            |h: ColliderHandle, c: &Collider| ray_visible(h, c) && Tag::decode(c.user_data).is_some_and(|t| !skip(t));
        let caster = RayCaster {
            world: self,
            pipeline: self.broad_phase.as_query_pipeline(
                self.narrow_phase.query_dispatcher(),
                &self.bodies,
                &self.colliders,
                QueryFilter::default().predicate(&pred),
            ),
        };
        caster.cast(origin, dir, max_m)
    }

    /// The first part of the robot (a link, the tool, the cup or the held part) inside `volume`,
    /// named.
    pub fn robot_inside(&self, volume: &ViewVolume) -> Option<String> {
        let id = Pose::IDENTITY;
        for (_, c) in self.colliders.iter() {
            let Some(tag) = Tag::decode(c.user_data) else { continue };
            let held =
                matches!(tag, Tag::Part(i) if self.parts.get(i as usize).is_some_and(|p| p.state == PartState::Held));
            if !(tag.is_robot() || held) {
                continue;
            }
            if rapier3d::parry::query::intersection_test(&id, &*volume.shape, c.position(), c.shape())
                .is_ok_and(|r| r.intersecting)
            {
                return Some(self.describe(Some(tag)));
            }
        }
        None
    }

    /// The world-frame bounding box (min, max corners) (m) of part `i` as rays see it.
    pub fn part_view_box_m(&self, i: usize) -> (Vector3<f64>, Vector3<f64>) {
        let a = self.colliders[self.parts[i].view_collider].compute_aabb();
        (point_from_sim(a.mins), point_from_sim(a.maxs))
    }

    /// Whether the ray from `origin` along the unit `dir` meets part `i` within `max_m` (m), with
    /// nothing else in the world (its silhouette, occlusion ignored).
    pub fn part_meets_ray(&self, i: usize, origin: &Vector3<f64>, dir: &Vector3<f64>, max_m: f64) -> bool {
        let c = &self.colliders[self.parts[i].view_collider];
        let ray = Ray::new(sim_point(origin), sim_dir(dir));
        c.shape().intersects_ray(c.position(), &ray, sim(max_m))
    }

    /// The arm's exact collision shapes (links 1..6, the tool and the cup) at joint positions `q`
    /// against every collider of the world but the robot's own, sensors and those `skip` passes:
    /// the first one touched, if any. An independent check of planned motions.
    pub fn arm_touches_at(&self, q: &JointVector, skip: &dyn Fn(Tag) -> bool) -> Option<Tag> {
        let world_from_links = self.robot.world_from_links(q);
        for (link, h) in self.link_bodies.iter().enumerate().skip(1) {
            for ch in self.bodies[*h].colliders() {
                let arm = &self.colliders[*ch];
                let local: Isometry3<f64> = super::to_isometry(arm.position_wrt_parent().unwrap_or(&Pose::IDENTITY));
                let pose = to_pose(&(world_from_links[link] * local));
                for (_, c) in self.colliders.iter() {
                    let Some(tag) = Tag::decode(c.user_data) else { continue };
                    if tag.is_robot() || c.is_sensor() || !c.is_enabled() || skip(tag) {
                        continue;
                    }
                    if rapier3d::parry::query::intersection_test(&pose, arm.shape(), c.position(), c.shape())
                        .is_ok_and(|r| r.intersecting)
                    {
                        return Some(tag);
                    }
                }
            }
        }
        None
    }
}
