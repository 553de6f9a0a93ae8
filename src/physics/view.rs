//! What the world looks like to a camera: the surface of every collider a ray would see (the
//! parts through their view twins, the arm's links, tool and cup, the held part, the trays, the
//! table and obstacles) as triangles in the world frame, for the sensor's rasterizer.
//!
//! Job: hand out the shapes and poses the physics world holds, tessellated, without rapier's
//! millimetres or handles: boxes and convex polyhedra exactly (their faces), cylinders, balls and
//! capsules as polyhedra whose facets lie within a given chord error of the round surface. The
//! same colliders as [`super::RayTargets`] selects for rays, in the collider set's order.
//!
//! Units: m. Frames: world.

use nalgebra::{Isometry3, Point3, Vector3};
use rapier3d::prelude::*;

use super::{RayTargets, Tag, World, point_from_sim, ray_visible, to_isometry};

/// One visible solid's surface: triangles in the world (m), and what it is.
#[derive(Debug, Clone)]
pub struct ViewMesh {
    /// What the solid is (a part, an arm link, the tool, the cup, an environment object).
    pub tag: Tag,
    /// Vertices in the world frame (m).
    pub vertices_m: Vec<Vector3<f64>>,
    /// Triangles, as indices into `vertices_m`.
    pub triangles: Vec<[u32; 3]>,
    /// The surface bounds a convex solid (every shape but a triangle mesh).
    pub convex: bool,
}

/// Facets of a round surface of radius `radius_m` so that no facet lies farther than `chord_m`
/// inside it: n with r (1 - cos(pi / n)) <= chord, at least 8 and at most 256.
fn round_facets(radius_m: f64, chord_m: f64) -> u32 {
    let c = (1.0 - chord_m / radius_m.max(1e-9)).clamp(-1.0, 1.0);
    let n = (std::f64::consts::PI / c.acos().max(1e-9)).ceil();
    n.clamp(8.0, 256.0) as u32
}

/// The surface of `shape` (rapier units, local frame) as triangles at `world_from_shape` (m),
/// appended to `out` (compounds: each piece as a mesh of its own).
fn tessellate(shape: &dyn Shape, world_from_shape: &Isometry3<f64>, tag: Tag, chord_m: f64, out: &mut Vec<ViewMesh>) {
    let m = |r: f32| r as f64 / super::SIM_UNITS_PER_M;
    let (verts, triangles) = if let Some(c) = shape.as_compound() {
        for (pose, piece) in c.shapes() {
            tessellate(&**piece, &(world_from_shape * to_isometry(pose)), tag, chord_m, out);
        }
        return;
    } else if let Some(b) = shape.as_cuboid() {
        b.to_trimesh()
    } else if let Some(p) = shape.as_convex_polyhedron() {
        p.to_trimesh()
    } else if let Some(c) = shape.as_cylinder() {
        c.to_trimesh(round_facets(m(c.radius), chord_m))
    } else if let Some(b) = shape.as_ball() {
        let n = round_facets(m(b.radius), chord_m);
        b.to_trimesh(n, n.div_ceil(2))
    } else if let Some(c) = shape.as_capsule() {
        let n = round_facets(m(c.radius), chord_m);
        c.to_trimesh(n, n.div_ceil(2))
    } else if let Some(t) = shape.as_trimesh() {
        out.push(ViewMesh {
            tag,
            vertices_m: t
                .vertices()
                .iter()
                .map(|v| (world_from_shape * Point3::from(point_from_sim(*v))).coords)
                .collect(),
            triangles: t.indices().to_vec(),
            convex: false,
        });
        return;
    } else {
        // No other shape is built into the world (see `shapes` and `arm`).
        return;
    };
    out.push(ViewMesh {
        tag,
        vertices_m: verts
            .into_iter()
            .map(|v| (world_from_shape * Point3::from(point_from_sim(v))).coords)
            .collect(),
        triangles,
        convex: true,
    });
}

impl World {
    /// The surfaces of the colliders rays see among `targets` ([`RayTargets::All`]: the fixed
    /// ones first, then the moving ones), round surfaces within `chord_m` (m): each collider as
    /// the ray caster sees it (parts through their view twins; disabled colliders and untagged
    /// ones not at all), in the collider set's order.
    pub fn view_meshes(&self, targets: RayTargets, chord_m: f64) -> Vec<ViewMesh> {
        if targets == RayTargets::All {
            let mut out = self.view_meshes(RayTargets::Fixed, chord_m);
            out.extend(self.view_meshes(RayTargets::Moving, chord_m));
            return out;
        }
        let want_fixed = targets == RayTargets::Fixed;
        let mut out = Vec::new();
        for (h, c) in self.colliders.iter() {
            if !c.is_enabled() || !ray_visible(h, c) {
                continue;
            }
            let fixed = c.parent().is_none_or(|b| self.bodies[b].is_fixed());
            if fixed != want_fixed {
                continue;
            }
            let Some(tag) = Tag::decode(c.user_data) else { continue };
            tessellate(c.shape(), &to_isometry(c.position()), tag, chord_m, &mut out);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The facet count keeps the chord error: a 70 mm link within 0.05 mm needs 84 facets; a
    /// 3 mm lead the minimum of 8.
    #[test]
    fn round_surfaces_are_faceted_within_the_chord() {
        for r in [0.0015, 0.003, 0.02, 0.07] {
            let n = round_facets(r, 5e-5) as f64;
            assert!(
                r * (1.0 - (std::f64::consts::PI / n).cos()) <= 5e-5 + 1e-12,
                "r {r}: {n}"
            );
            assert!(
                n == 8.0 || r * (1.0 - (std::f64::consts::PI / (n - 1.0)).cos()) > 5e-5,
                "r {r}: {n} not the least"
            );
        }
    }
}
