//! Tessellation of a workpiece's primitives into the one mesh type ([`Mesh`]).
//!
//! Job: turn the boxes and cylinders of a box or compound workpiece into one closed,
//! outward-wound triangle mesh, so the built-in parts can be handled (and exported) as meshes.
//! Boxes are exact (8 vertices, 12 triangles). Cylinders are the same [`PRISM_SIDES`]-sided prisms
//! the physics and its overlap check use (vertices on the circle, the first one on the cylinder's
//! first cross axis: y for an x cylinder, z for y, x for z).
//!
//! Simplification: the mesh is the union of one closed shell per primitive; shells that touch
//! (a relay's pins on its body's bottom face) are not merged, so the touching faces stay as inner
//! faces. Every edge is still shared by exactly two triangles of opposite orientation, and the
//! enclosed volume is the sum of the primitives' volumes for primitives that do not overlap
//! (true of the six built-in parts).
//!
//! Units: m. Frame: the part frame of the workpiece file (origin at the centre of `size_m`).

use nalgebra::{Point3, Vector3};

use super::mesh::Mesh;
use super::primitive::{Axis, Piece};

/// Sides of the prisms that stand in for cylinders (the physics uses the same number).
pub const PRISM_SIDES: usize = 16;

/// The primitives of a box or compound workpiece as one mesh: one closed shell per primitive.
pub fn pieces_mesh<'a>(pieces: impl IntoIterator<Item = &'a Piece>) -> Mesh {
    let mut mesh = Mesh::default();
    for piece in pieces {
        append(&mut mesh, &piece_mesh(piece));
    }
    mesh
}

/// One primitive as a closed shell: a box exactly, a cylinder as the [`PRISM_SIDES`]-sided prism.
pub fn piece_mesh(p: &Piece) -> Mesh {
    match *p {
        Piece::Box { center_m, half_m } => box_mesh(center_m, half_m),
        Piece::Cylinder {
            center_m,
            radius_m,
            half_length_m,
            axis,
        } => prism_mesh(center_m, radius_m, half_length_m, axis, PRISM_SIDES),
    }
}

/// An axis-aligned box with half extents `half_m` centred at `center_m`.
pub fn box_mesh(center_m: Vector3<f64>, half_m: Vector3<f64>) -> Mesh {
    // Corner i has x at +half when bit 2 is set, y at bit 1, z at bit 0.
    let vertices_m = (0..8u32)
        .map(|i| {
            let s = |bit: u32| if i & (1 << bit) != 0 { 1.0 } else { -1.0 };
            Point3::from(center_m + Vector3::new(s(2) * half_m.x, s(1) * half_m.y, s(0) * half_m.z))
        })
        .collect();
    // Each face's corners counter-clockwise seen from outside.
    let quads = [
        [0, 1, 3, 2], // -x
        [4, 6, 7, 5], // +x
        [0, 4, 5, 1], // -y
        [2, 3, 7, 6], // +y
        [0, 2, 6, 4], // -z
        [1, 5, 7, 3], // +z
    ];
    let triangles = quads.iter().flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]]).collect();
    Mesh { vertices_m, triangles }
}

/// A right prism of `sides` sides whose vertices lie on a circle of `radius_m` about `axis`,
/// `half_length_m` either side of `center_m`. The first vertex lies on the first cross axis
/// (y for x, z for y, x for z) and the ring runs counter-clockwise about `axis`.
pub fn prism_mesh(center_m: Vector3<f64>, radius_m: f64, half_length_m: f64, axis: Axis, sides: usize) -> Mesh {
    let (a, u, v) = match axis {
        Axis::X => (Vector3::x(), Vector3::y(), Vector3::z()),
        Axis::Y => (Vector3::y(), Vector3::z(), Vector3::x()),
        Axis::Z => (Vector3::z(), Vector3::x(), Vector3::y()),
    };
    let n = sides.max(3);
    let ring: Vec<Vector3<f64>> = (0..n)
        .map(|k| {
            let t = k as f64 * std::f64::consts::TAU / n as f64;
            (u * t.cos() + v * t.sin()) * radius_m
        })
        .collect();
    // Bottom ring (at -axis) 0..n, top ring n..2n.
    let mut vertices_m = Vec::with_capacity(2 * n);
    for s in [-1.0, 1.0] {
        vertices_m.extend(
            ring.iter()
                .map(|r| Point3::from(center_m + r + a * (s * half_length_m))),
        );
    }
    let n32 = n as u32;
    let mut triangles = Vec::with_capacity(4 * n - 4);
    for k in 0..n32 {
        let k1 = (k + 1) % n32;
        // Side quad: bottom k, bottom k+1, top k+1, top k (outward: the ring turns about +axis).
        triangles.push([k, k1, n32 + k1]);
        triangles.push([k, n32 + k1, n32 + k]);
    }
    for k in 1..n32 - 1 {
        triangles.push([n32, n32 + k, n32 + k + 1]); // top cap, seen from +axis
        triangles.push([0, k + 1, k]); // bottom cap, seen from -axis
    }
    Mesh { vertices_m, triangles }
}

/// Appends `other`'s vertices and triangles to `mesh` (a second shell of the same mesh).
pub fn append(mesh: &mut Mesh, other: &Mesh) {
    let base = mesh.vertices_m.len() as u32;
    mesh.vertices_m.extend_from_slice(&other.vertices_m);
    mesh.triangles
        .extend(other.triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;
    use crate::config::{LoadedWorkpiece, Workpiece};

    /// Every directed edge appears once and its reverse once: closed and consistently wound.
    fn closed_and_consistent(m: &Mesh) -> Result<(), String> {
        let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &count) in &directed {
            if count != 1 {
                return Err(format!("edge {a}->{b} used {count} times in one direction"));
            }
            if directed.get(&(b, a)) != Some(&1) {
                return Err(format!("edge {a}->{b} has no opposite"));
            }
        }
        Ok(())
    }

    /// Volume by the divergence theorem: the sum of signed tetrahedra from the origin.
    fn signed_volume(m: &Mesh) -> f64 {
        m.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.vertices_m[i as usize].coords);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// The primitives' volume from their dimensions alone (cylinders as regular n-gon prisms).
    fn analytic_volume(w: &Workpiece) -> f64 {
        w.pieces()
            .iter()
            .map(|(_, p)| match *p {
                Piece::Box { half_m, .. } => 8.0 * half_m.x * half_m.y * half_m.z,
                Piece::Cylinder {
                    radius_m,
                    half_length_m,
                    ..
                } => {
                    let n = PRISM_SIDES as f64;
                    0.5 * n * radius_m * radius_m * (std::f64::consts::TAU / n).sin() * 2.0 * half_length_m
                }
            })
            .sum()
    }

    #[test]
    fn every_builtin_part_is_closed_outward_with_its_volume_and_size() {
        let mut all = LoadedWorkpiece::all_embedded().unwrap();
        all.push(LoadedWorkpiece::resolve("workpieces/capacitor-radial.toml").unwrap());
        for wp in all {
            let w = &wp.workpiece;
            let m = w.primitive_mesh().unwrap();
            closed_and_consistent(&m).unwrap_or_else(|e| panic!("{}: {e}", w.name));
            let (v, want) = (signed_volume(&m), analytic_volume(w));
            assert!(v > 0.0, "{}: inward-wound (volume {v})", w.name);
            assert!(
                (v - want).abs() < 1e-9 * want.max(1e-9) + 1e-15,
                "{}: {v} vs {want}",
                w.name
            );
            let (lo, hi) = m.bounds_m().unwrap();
            for a in 0..3 {
                assert!(
                    (hi[a] - lo[a] - w.size_m[a]).abs() < 1e-12 && (hi[a] + lo[a]).abs() < 1e-12,
                    "{}: axis {a} spans [{}, {}], size_m {:?}",
                    w.name,
                    lo[a],
                    hi[a],
                    w.size_m
                );
            }
        }
    }

    #[test]
    fn prisms_match_the_physics_prisms_vertex_for_vertex() {
        use crate::physics::overlap::{CYLINDER_SIDES, Polytope};
        assert_eq!(PRISM_SIDES, CYLINDER_SIDES);
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            let c = Vector3::new(0.001, -0.002, 0.003);
            let piece = Piece::Cylinder {
                center_m: c,
                radius_m: 0.004,
                half_length_m: 0.002,
                axis,
            };
            let (m, p) = (piece_mesh(&piece), Polytope::of(&piece));
            assert_eq!(m.vertices_m.len(), p.vertices.len());
            for v in &p.vertices {
                assert!(m.vertices_m.iter().any(|w| (w - v).norm() < 1e-15), "{axis:?}: {v}");
            }
            closed_and_consistent(&m).unwrap();
            assert!(signed_volume(&m) > 0.0, "{axis:?}");
        }
    }

    #[test]
    fn the_checks_catch_a_flipped_triangle_an_open_shell_and_a_wrong_size() {
        let good = box_mesh(Vector3::zeros(), Vector3::new(0.01, 0.02, 0.03));
        closed_and_consistent(&good).unwrap();
        assert!((signed_volume(&good) - 0.02 * 0.04 * 0.06).abs() < 1e-15);
        let mut flipped = good.clone();
        flipped.triangles[3].swap(0, 1);
        assert!(closed_and_consistent(&flipped).is_err());
        let mut open = good.clone();
        open.triangles.pop();
        assert!(closed_and_consistent(&open).is_err());
        let mut inside_out = good.clone();
        inside_out.triangles.iter_mut().for_each(|t| t.swap(0, 1));
        closed_and_consistent(&inside_out).unwrap();
        assert!(signed_volume(&inside_out) < 0.0);
        // A workpiece whose primitives do not reach its size_m: the bounds check would see it.
        let mut w = LoadedWorkpiece::resolve("A").unwrap().workpiece;
        w.size_m[2] += 0.001;
        let (lo, hi) = w.primitive_mesh().unwrap().bounds_m().unwrap();
        assert!((hi.z - lo.z - w.size_m[2]).abs() > 1e-4);
    }
}
