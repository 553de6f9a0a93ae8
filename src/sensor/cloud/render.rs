//! Rendering of the workpiece model by ray casting: the entry distance of a ray into the model's
//! boxes and cylinders, or into a mesh workpiece's triangle mesh (parry's bounding-volume tree,
//! in millimetres and single precision), in the part frame (m).

use nalgebra::{Point3, Vector3};

use super::CloudModel;
use crate::config::{Axis, Piece};

/// A mesh workpiece's surface for rendering: the triangle mesh (mm, part frame) and its vertices
/// (m, for the lowest point of a pose).
#[derive(Debug, Clone)]
pub(crate) struct MeshView {
    surface: parry3d::shape::TriMesh,
    pub(crate) vertices_m: Vec<Vector3<f64>>,
}

impl MeshView {
    /// The view of a mesh (m, part frame); `None` if parry refuses it (no triangles).
    pub(crate) fn new(mesh: &crate::part::mesh::Mesh) -> Option<Self> {
        let verts = mesh
            .vertices_m
            .iter()
            .map(|p| parry3d::math::Vector3::new((p.x * 1e3) as f32, (p.y * 1e3) as f32, (p.z * 1e3) as f32))
            .collect();
        let surface = parry3d::shape::TriMesh::new(verts, mesh.triangles.clone()).ok()?;
        Some(MeshView {
            surface,
            vertices_m: mesh.vertices_m.iter().map(|p| p.coords).collect(),
        })
    }

    /// Entry distance of a ray (part frame, unit direction) into the surface (m).
    fn ray(&self, o: &Point3<f64>, d: &Vector3<f64>) -> Option<f64> {
        use parry3d::query::RayCast;
        let v = |x: f64, y: f64, z: f64| parry3d::math::Vector3::new(x as f32, y as f32, z as f32);
        let ray = parry3d::query::Ray::new(v(o.x * 1e3, o.y * 1e3, o.z * 1e3), v(d.x, d.y, d.z));
        self.surface
            .cast_local_ray(&ray, f32::MAX, false)
            .map(|t| t as f64 * 1e-3)
            .filter(|t| *t > 0.0)
    }
}

/// Nearest entry distance of a ray (part frame, unit direction) into the model's pieces.
#[cfg(test)]
pub(crate) fn ray_model(model: &CloudModel, o: &Point3<f64>, d: &Vector3<f64>) -> Option<f64> {
    if let Some(m) = &model.mesh {
        return m.ray(o, d);
    }
    model
        .pieces
        .iter()
        .filter_map(|p| ray_piece(p, &o.coords, d))
        .min_by(|a, b| a.total_cmp(b))
}

/// Nearest entry distance of a ray (part frame, unit direction) into the pieces `among` of the
/// model (indices, in increasing order: the caller leaves out pieces the ray cannot meet; a mesh
/// workpiece's surface is met whatever `among` says), and whether the ray only grazes a thin
/// piece (a lead): it passes it farther from its axis than [`THIN_CORE`] of its radius, where a
/// pose a fraction of a millimetre off decides whether it hits.
pub(super) fn ray_among_graze(
    model: &CloudModel,
    o: &Point3<f64>,
    d: &Vector3<f64>,
    among: impl Iterator<Item = usize>,
) -> Option<(f64, bool)> {
    if let Some(m) = &model.mesh {
        return m.ray(o, d).map(|t| (t, false));
    }
    let (t, k) = among
        .filter_map(|k| ray_piece(&model.pieces[k], &o.coords, d).map(|t| (t, k)))
        .min_by(|a, b| a.0.total_cmp(&b.0))?;
    let graze = match model.pieces[k] {
        Piece::Cylinder {
            center_m,
            radius_m,
            axis,
            ..
        } if model.lead[k] => {
            let a = axis.unit();
            let p = o.coords - center_m;
            let (p, q) = (p - a * p.dot(&a), d - a * d.dot(&a));
            let dist = if q.norm() > 1e-9 {
                p.cross(&q).norm() / q.norm()
            } else {
                p.norm()
            };
            dist > THIN_CORE * radius_m
        }
        _ => false,
    };
    Some((t, graze))
}

/// A ray passing a lead within this fraction of its radius from its axis surely meets it.
const THIN_CORE: f64 = 0.5;

/// Entry distance of a ray into a box or cylinder (part frame); `None` if it misses or starts inside.
pub(super) fn ray_piece(piece: &Piece, o: &Vector3<f64>, d: &Vector3<f64>) -> Option<f64> {
    match *piece {
        Piece::Box { center_m, half_m } => {
            let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
            for a in 0..3 {
                let (p, q) = (o[a] - center_m[a], d[a]);
                if q.abs() < 1e-12 {
                    if p.abs() > half_m[a] {
                        return None;
                    }
                    continue;
                }
                let (ta, tb) = ((-half_m[a] - p) / q, (half_m[a] - p) / q);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
            (t0 <= t1 && t0 > 0.0).then_some(t0)
        }
        Piece::Cylinder {
            center_m,
            radius_m,
            half_length_m,
            axis,
        } => {
            let k = match axis {
                Axis::X => 0,
                Axis::Y => 1,
                Axis::Z => 2,
            };
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let p = o - center_m;
            // Slab along the axis.
            let (mut t0, mut t1) = if d[k].abs() < 1e-12 {
                if p[k].abs() > half_length_m {
                    return None;
                }
                (f64::NEG_INFINITY, f64::INFINITY)
            } else {
                let (ta, tb) = ((-half_length_m - p[k]) / d[k], (half_length_m - p[k]) / d[k]);
                (ta.min(tb), ta.max(tb))
            };
            // Infinite cylinder.
            let a = d[i] * d[i] + d[j] * d[j];
            let b = p[i] * d[i] + p[j] * d[j];
            let c = p[i] * p[i] + p[j] * p[j] - radius_m * radius_m;
            if a < 1e-12 {
                if c > 0.0 {
                    return None;
                }
            } else {
                let disc = b * b - a * c;
                if disc < 0.0 {
                    return None;
                }
                let s = disc.sqrt();
                t0 = t0.max((-b - s) / a);
                t1 = t1.min((-b + s) / a);
            }
            (t0 <= t1 && t0 > 0.0).then_some(t0)
        }
    }
}
