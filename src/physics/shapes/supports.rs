//! Support slabs: a thin convex piece flush with each large flat face of more than four corners
//! (a cylinder's 16-sided cap, a hex standoff's end), added to a part's collider.
//!
//! Why: parry 0.31 gives a convex polyhedron's face to the contact clipper as at most four of
//! its corners, the first four in order around the face (its own source says "TODO: select four
//! vertices that maximize the area"). A 16-sided cap then touches as a sliver along one edge of
//! its rim: a can standing on its cap rocks on one side, and two cans stacked cap on cap sink
//! into each other by millimetres over seconds (measured: 4.5 mm in the pile of D, seed 13,
//! where the independent overlap check stops the run). The slab under such a face is the convex
//! hull of the four face corners that span the largest quadrilateral and the same four corners
//! moved a fraction of the way to the piece's centroid: every face of it has four corners, so its
//! contacts span the face, and it lies inside the piece (convexity), so the part's solid is
//! unchanged. Mass properties are computed without the slabs.
//!
//! Units: rapier's (see the parent module). Frame: the part frame.

use rapier3d::math::{Pose, Vector};
use rapier3d::parry::shape::ConvexPolyhedron;
use rapier3d::prelude::SharedShape;

/// Share of the way from a face corner to the piece's centroid that gives the slab's inner
/// corners: a quarter of a 10 mm can's half height is about 1 mm.
const SLAB_DEPTH_FRACTION: f32 = 0.25;

/// Faces smaller than this share of the part's largest face (over all its pieces) get no slab:
/// a part does not rest its weight on them (a lead's end, a pin's tip, a chamfer).
const MIN_FACE_SHARE: f32 = 0.2;

/// The corners of `face`, in order around it.
fn face_corners(p: &ConvexPolyhedron, face: usize) -> Vec<Vector> {
    let f = p.faces()[face];
    let (a, n) = (f.first_vertex_or_edge as usize, f.num_vertices_or_edges as usize);
    p.vertices_adj_to_face()[a..a + n]
        .iter()
        .map(|&v| p.points()[v as usize])
        .collect()
}

/// Area of a planar polygon given in order (rapier units squared).
fn polygon_area(corners: &[Vector]) -> f32 {
    let mut s = Vector::ZERO;
    for i in 0..corners.len() {
        s += corners[i].cross(corners[(i + 1) % corners.len()]);
    }
    s.length() / 2.0
}

/// Four of `corners` (in order around a convex polygon) spanning the largest quadrilateral:
/// exhaustive over index quadruples in order (a face has at most a few dozen corners).
fn largest_quad(corners: &[Vector]) -> [Vector; 4] {
    let n = corners.len();
    let mut best = (f32::NEG_INFINITY, [0usize; 4]);
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                for l in k + 1..n {
                    let q = [corners[i], corners[j], corners[k], corners[l]];
                    let area = polygon_area(&q);
                    if area > best.0 {
                        best = (area, [i, j, k, l]);
                    }
                }
            }
        }
    }
    best.1.map(|i| corners[i])
}

/// Area of the largest face of a convex piece (rapier units squared).
fn largest_face_area(p: &ConvexPolyhedron) -> f32 {
    (0..p.faces().len())
        .map(|f| polygon_area(&face_corners(p, f)))
        .fold(0.0, f32::max)
}

/// The support slabs of one convex piece: one under each face of more than four corners whose
/// area is at least [`MIN_FACE_SHARE`] of `largest` (empty when none).
fn slabs_of(p: &ConvexPolyhedron, largest: f32) -> Vec<SharedShape> {
    let centroid = p.points().iter().copied().sum::<Vector>() / p.points().len() as f32;
    let faces: Vec<Vec<Vector>> = (0..p.faces().len()).map(|f| face_corners(p, f)).collect();
    faces
        .iter()
        .filter(|c| c.len() > 4 && polygon_area(c) >= MIN_FACE_SHARE * largest)
        .filter_map(|c| {
            let quad = largest_quad(c);
            let inner = quad.map(|v| v + (centroid - v) * SLAB_DEPTH_FRACTION);
            let pts: Vec<Vector> = quad.iter().chain(inner.iter()).copied().collect();
            SharedShape::convex_hull(&pts)
        })
        .collect()
}

/// `shape` (a convex polyhedron, or a compound of them) with a support slab under every large
/// face of more than four corners; `shape` itself when no face needs one.
pub fn with_support_slabs(shape: &SharedShape) -> SharedShape {
    let pieces: Vec<(Pose, SharedShape)> = match shape.as_compound() {
        Some(c) => c.shapes().to_vec(),
        None => vec![(Pose::IDENTITY, shape.clone())],
    };
    let largest = pieces
        .iter()
        .filter_map(|(_, s)| s.as_convex_polyhedron())
        .map(largest_face_area)
        .fold(0.0, f32::max);
    let mut out = pieces.clone();
    for (pose, piece) in &pieces {
        if let Some(p) = piece.as_convex_polyhedron() {
            out.extend(slabs_of(p, largest).into_iter().map(|s| (*pose, s)));
        }
    }
    if out.len() == pieces.len() {
        shape.clone()
    } else {
        SharedShape::compound(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prism(sides: usize, radius: f32, half_height: f32) -> SharedShape {
        let mut pts = Vec::new();
        for k in 0..sides {
            let a = std::f32::consts::TAU * k as f32 / sides as f32;
            for z in [-half_height, half_height] {
                pts.push(Vector::new(radius * a.cos(), radius * a.sin(), z));
            }
        }
        SharedShape::convex_hull(&pts).unwrap()
    }

    fn hull_box(hx: f32, hy: f32, hz: f32) -> SharedShape {
        let pts: Vec<Vector> = (0..8)
            .map(|k| {
                Vector::new(
                    if k & 1 == 0 { -hx } else { hx },
                    if k & 2 == 0 { -hy } else { hy },
                    if k & 4 == 0 { -hz } else { hz },
                )
            })
            .collect();
        SharedShape::convex_hull(&pts).unwrap()
    }

    #[test]
    fn a_sixteen_sided_prism_gets_a_square_slab_under_each_cap_inside_it() {
        let s = prism(16, 5.0, 4.0);
        let with = with_support_slabs(&s);
        let c = with.as_compound().expect("slabs make a compound");
        assert_eq!(c.shapes().len(), 3, "the prism and one slab per cap");
        for (_, slab) in &c.shapes()[1..] {
            let p = slab.as_convex_polyhedron().unwrap();
            assert!(p.faces().iter().all(|f| f.num_vertices_or_edges <= 4));
            // Inside the prism: every slab corner is in the prism (within rounding).
            for v in p.points() {
                assert!(s.distance_to_local_point(*v, true) < 1e-4, "{v:?} outside the prism");
            }
            // The slab's outer face is the largest square in the 16-gon: side r * sqrt(2).
            let top = p.points().iter().map(|v| v.z.abs()).fold(0.0f32, f32::max);
            assert!((top - 4.0).abs() < 1e-4, "flush with the cap: {top}");
        }
        // Negative control: a box's faces have four corners, so it gets none.
        let b = hull_box(1.0, 2.0, 3.0);
        assert!(with_support_slabs(&b).as_compound().is_none());
        let hex = prism(6, 5.0, 4.0);
        assert_eq!(
            with_support_slabs(&hex).as_compound().map(|c| c.shapes().len()),
            Some(3)
        );
        // A thin pin's tip on a large body carries no weight: a body and a pin get no slab.
        let body = hull_box(10.0, 10.0, 4.0);
        let relay = SharedShape::compound(vec![(Pose::IDENTITY, body), (Pose::IDENTITY, prism(16, 0.3, 2.0))]);
        assert_eq!(
            with_support_slabs(&relay).as_compound().map(|c| c.shapes().len()),
            Some(2)
        );
    }

    #[test]
    fn the_largest_quadrilateral_of_a_regular_polygon_is_its_inscribed_square() {
        let corners: Vec<Vector> = (0..16)
            .map(|k| {
                let a = std::f32::consts::TAU * k as f32 / 16.0;
                Vector::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let q = largest_quad(&corners);
        assert!((polygon_area(&q) - 2.0).abs() < 1e-5, "{}", polygon_area(&q));
        // Four consecutive corners (what parry picks) span far less.
        assert!(polygon_area(&corners[..4]) < 0.5);
    }
}
