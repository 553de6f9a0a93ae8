//! Independent overlap check: exact penetration depth between convex polytopes by the separating
//! axis theorem, in f64, from the workpiece and tray definitions rather than from rapier's shapes.
//!
//! Job: verify what the solver claims (how deep parts sink into each other and into the tray)
//! with code that shares nothing with the solver's contact generation. Every workpiece primitive
//! is a convex polytope here: boxes exactly, cylinders as the same 16-sided prisms the physics
//! uses. Units: m. Frames: each polytope in its part frame; poses map part to world.

use nalgebra::{Isometry3, Point3, Vector3};

use crate::config::{Axis, Piece, ShapeKind, TrayConfig, Workpiece};

/// Sides of the prisms that stand in for cylinders (the physics uses the same).
pub const CYLINDER_SIDES: usize = 16;

/// A convex polytope: vertices, face normals and edge directions, in its own frame.
#[derive(Debug, Clone)]
pub struct Polytope {
    /// Vertices (m).
    pub vertices: Vec<Point3<f64>>,
    /// Outward face normals (unit; opposite faces may share one).
    pub normals: Vec<Vector3<f64>>,
    /// Edge directions (unit; parallel edges share one).
    pub edges: Vec<Vector3<f64>>,
}

impl Polytope {
    /// A workpiece piece: a box exactly, a cylinder as the [`CYLINDER_SIDES`]-sided prism.
    pub fn of(p: &Piece) -> Self {
        match *p {
            Piece::Box { center_m, half_m } => Polytope::cuboid(center_m, half_m),
            Piece::Cylinder {
                center_m,
                radius_m,
                half_length_m,
                axis,
            } => Polytope::prism(center_m, radius_m, half_length_m, axis),
        }
    }

    /// A box with half extents `he`, centred at `c`, axis-aligned.
    pub fn cuboid(c: Vector3<f64>, he: Vector3<f64>) -> Self {
        let mut vertices = Vec::with_capacity(8);
        for sx in [-1.0, 1.0] {
            for sy in [-1.0, 1.0] {
                for sz in [-1.0, 1.0] {
                    vertices.push(Point3::from(c + Vector3::new(sx * he.x, sy * he.y, sz * he.z)));
                }
            }
        }
        let axes = vec![Vector3::x(), Vector3::y(), Vector3::z()];
        Polytope {
            vertices,
            normals: axes.clone(),
            edges: axes,
        }
    }

    /// A prism of `CYLINDER_SIDES` sides with vertices on a circle of `radius`, `half_length`
    /// along `axis`, centred at `c`.
    pub fn prism(c: Vector3<f64>, radius: f64, half_length: f64, axis: Axis) -> Self {
        let (a, u, v) = match axis {
            Axis::X => (Vector3::x(), Vector3::y(), Vector3::z()),
            Axis::Y => (Vector3::y(), Vector3::z(), Vector3::x()),
            Axis::Z => (Vector3::z(), Vector3::x(), Vector3::y()),
        };
        let n = CYLINDER_SIDES;
        let ring: Vec<Vector3<f64>> = (0..n)
            .map(|k| {
                let t = k as f64 * std::f64::consts::TAU / n as f64;
                (u * t.cos() + v * t.sin()) * radius
            })
            .collect();
        let mut vertices = Vec::with_capacity(2 * n);
        for s in [-1.0, 1.0] {
            vertices.extend(ring.iter().map(|r| Point3::from(c + r + a * (s * half_length))));
        }
        let mut normals = vec![a];
        let mut edges = vec![a];
        for k in 0..n {
            let e = (ring[(k + 1) % n] - ring[k]).normalize();
            edges.push(e);
            normals.push(e.cross(&a).normalize());
        }
        Polytope {
            vertices,
            normals,
            edges,
        }
    }

    /// Projection interval of the vertices onto an axis given in the polytope's frame.
    fn project(&self, axis_local: &Vector3<f64>) -> (f64, f64) {
        self.vertices
            .iter()
            .map(|p| p.coords.dot(axis_local))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| (lo.min(x), hi.max(x)))
    }
}

/// Penetration depth of two posed polytopes: 0 when they are apart, else the smallest overlap
/// over every separating-axis candidate (face normals of both, cross products of edges) (m).
pub fn depth(pa: &Isometry3<f64>, a: &Polytope, pb: &Isometry3<f64>, b: &Polytope) -> f64 {
    let ra = pa.rotation;
    let rb = pb.rotation;
    let mut axes: Vec<Vector3<f64>> =
        Vec::with_capacity(a.normals.len() + b.normals.len() + a.edges.len() * b.edges.len());
    axes.extend(a.normals.iter().map(|n| ra * n));
    axes.extend(b.normals.iter().map(|n| rb * n));
    for ea in &a.edges {
        for eb in &b.edges {
            let c = (ra * ea).cross(&(rb * eb));
            let l = c.norm();
            if l > 1e-9 {
                axes.push(c / l);
            }
        }
    }
    let mut best = f64::INFINITY;
    for axis in axes {
        let (alo, ahi) = a.project(&(pa.rotation.inverse() * axis));
        let (blo, bhi) = b.project(&(pb.rotation.inverse() * axis));
        let (oa, ob) = (pa.translation.vector.dot(&axis), pb.translation.vector.dot(&axis));
        let overlap = (ahi + oa).min(bhi + ob) - (alo + oa).max(blo + ob);
        if overlap <= 0.0 {
            return 0.0;
        }
        best = best.min(overlap);
    }
    best
}

/// The convex pieces of a workpiece, in its part frame (box or compound; `None` for meshes,
/// whose convex pieces exist only in the physics).
pub fn workpiece_pieces(w: &Workpiece) -> Option<Vec<Polytope>> {
    if w.shape.kind == ShapeKind::Mesh {
        return None;
    }
    Some(w.pieces().iter().map(|(_, p)| Polytope::of(p)).collect())
}

/// The tray's floor and walls ([`crate::geometry::tray_pieces_m`]) as `(world_from_tray, box in the
/// tray frame)`.
pub fn tray_pieces(t: &TrayConfig) -> Vec<(Isometry3<f64>, Polytope)> {
    let world_from_tray = t.world_from_tray();
    crate::geometry::tray_pieces_m(t)
        .into_iter()
        .map(|(center_m, half_m)| (world_from_tray, Polytope::cuboid(center_m, half_m)))
        .collect()
}

/// Deepest overlap among parts at `poses` and between parts and the tray pieces (m), with the
/// indices involved (`usize::MAX` for a tray piece).
pub fn max_depth(
    poses: &[Isometry3<f64>],
    pieces: &[Polytope],
    radius_m: f64,
    tray: &[(Isometry3<f64>, Polytope)],
) -> (f64, usize, usize) {
    let mut worst = (0.0, usize::MAX, usize::MAX);
    for i in 0..poses.len() {
        for j in (i + 1)..poses.len() {
            if (poses[i].translation.vector - poses[j].translation.vector).norm() > 2.0 * radius_m {
                continue;
            }
            for a in pieces {
                for b in pieces {
                    let d = depth(&poses[i], a, &poses[j], b);
                    if d > worst.0 {
                        worst = (d, i, j);
                    }
                }
            }
        }
        for (tp, tb) in tray {
            for a in pieces {
                let d = depth(&poses[i], a, tp, tb);
                if d > worst.0 {
                    worst = (d, i, usize::MAX);
                }
            }
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_overlap_by_the_expected_depth() {
        let a = Polytope::cuboid(Vector3::zeros(), Vector3::new(0.01, 0.01, 0.01));
        let pa = Isometry3::identity();
        let pb = Isometry3::translation(0.0195, 0.0, 0.0);
        assert!((depth(&pa, &a, &pb, &a) - 0.0005).abs() < 1e-12);
        let apart = Isometry3::translation(0.0205, 0.0, 0.0);
        assert_eq!(depth(&pa, &a, &apart, &a), 0.0);
        // Rotated 45 deg about z: the corner reaches 0.01 * sqrt(2).
        let rot = Isometry3::new(
            Vector3::new(0.024, 0.0, 0.0),
            Vector3::z() * std::f64::consts::FRAC_PI_4,
        );
        let expected = 0.01 + 0.01 * 2f64.sqrt() - 0.024;
        assert!((depth(&pa, &a, &rot, &a) - expected).abs() < 1e-12);
    }

    #[test]
    fn prism_stands_on_a_box() {
        let floor = Polytope::cuboid(Vector3::new(0.0, 0.0, -0.005), Vector3::new(0.1, 0.1, 0.005));
        let can = Polytope::prism(Vector3::zeros(), 0.005, 0.0035, Axis::Z);
        let sunk = Isometry3::translation(0.0, 0.0, 0.0035 - 0.0002);
        assert!((depth(&Isometry3::identity(), &floor, &sunk, &can) - 0.0002).abs() < 1e-12);
        // Lying on its side: the prism's lowest edge or face is at radius * cos(pi/16) or radius.
        let side = Isometry3::new(
            Vector3::new(0.0, 0.0, 0.006),
            Vector3::x() * std::f64::consts::FRAC_PI_2,
        );
        assert_eq!(depth(&Isometry3::identity(), &floor, &side, &can), 0.0);
    }
}
