//! Rendering of the workpiece model: by ray casting, the entry distance of a ray into the model's
//! boxes and cylinders, or into a mesh workpiece's triangle mesh (parry's bounding-volume tree,
//! in millimetres and single precision), in the part frame (m); and a mesh workpiece's depth on
//! a grid of pixels by rasterizing its triangles (camera frame, m), what the ray through each
//! pixel centre meets first.

use nalgebra::{Isometry3, Point3, Vector3};

use super::CloudModel;
use crate::config::{Axis, Piece};

/// A mesh workpiece's surface for rendering: the triangle mesh (mm, part frame) and its vertices
/// (m, for the lowest point of a pose).
#[derive(Debug, Clone)]
pub(crate) struct MeshView {
    surface: parry3d::shape::TriMesh,
    pub(crate) vertices_m: Vec<Vector3<f64>>,
    /// The triangles (indices into `vertices_m`).
    triangles: Vec<[u32; 3]>,
}

/// A pixel centre this close outside a triangle's edge (in barycentric weight) is on it: a
/// centre on an edge two triangles share is covered, as a ray through it meets one of them.
const EDGE_TOL: f64 = 1e-12;

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
            triangles: mesh.triangles.clone(),
        })
    }

    /// The depth along the optical axis (m) of the surface at `camera_from_part`, seen through
    /// the centres of the pixels `cols` x `rows` (first and last, inclusive, every `stride`-th,
    /// both first ones multiples of it), row by row; `f64::INFINITY` where nothing is met. The
    /// nearest triangle facing the camera that covers a pixel centre (edges included) is what
    /// its ray meets first, as the ray cast finds it, at about two thirds of its cost over a
    /// part's few hundred triangles.
    pub(crate) fn depths(
        &self,
        camera: &crate::sensor::camera::Camera,
        camera_from_part: &Isometry3<f64>,
        cols: [usize; 2],
        rows: [usize; 2],
        stride: usize,
    ) -> Vec<f64> {
        let (nu, nv) = ((cols[1] - cols[0]) / stride + 1, (rows[1] - rows[0]) / stride + 1);
        let mut depth = vec![f64::INFINITY; nu * nv];
        // Screen position (px, pixel centres at half-integers) and inverse depth of each vertex.
        let screen: Vec<Option<[f64; 3]>> = self
            .vertices_m
            .iter()
            .map(|p| {
                let c = camera_from_part * Point3::from(*p);
                (c.z > 1e-9).then(|| {
                    [
                        camera.fx_px * c.x / c.z + camera.cx_px,
                        camera.fy_px * c.y / c.z + camera.cy_px,
                        1.0 / c.z,
                    ]
                })
            })
            .collect();
        // The grid index of the first pixel at or after `x` (a pixel coordinate) along an axis.
        let first = |x: f64, lo: usize| {
            let i = (x - 0.5).ceil().max(lo as f64) as usize;
            (i - lo).div_ceil(stride)
        };
        for t in &self.triangles {
            let (Some(a), Some(b), Some(c)) = (screen[t[0] as usize], screen[t[1] as usize], screen[t[2] as usize])
            else {
                continue;
            };
            // A closed, outward-wound solid (as repair leaves every mesh part) is entered
            // through a triangle facing the camera: wound clockwise on the screen (x right, y
            // down), a negative area here. The others, and those seen edge-on, are skipped.
            let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            if area > -1e-12 {
                continue;
            }
            let (xmin, xmax) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
            let (ymin, ymax) = (a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]));
            if xmax - 0.5 < cols[0] as f64 || ymax - 0.5 < rows[0] as f64 {
                continue;
            }
            let (i0, j0) = (first(xmin, cols[0]), first(ymin, rows[0]));
            let i1 = (((xmax - 0.5).floor() as usize).min(cols[1]) - cols[0]) / stride;
            let j1 = (((ymax - 0.5).floor() as usize).min(rows[1]) - rows[0]) / stride;
            // Edge functions over the area: each pixel centre's barycentric weights, as
            // `w = ex * x + ey * y + e0`.
            let edge = |p: [f64; 3], q: [f64; 3]| {
                let (ex, ey) = (-(q[1] - p[1]) / area, (q[0] - p[0]) / area);
                [ex, ey, -(ex * p[0] + ey * p[1])]
            };
            let (ea, eb, ec) = (edge(b, c), edge(c, a), edge(a, b));
            for j in j0..=j1.min(nv - 1) {
                let y = (rows[0] + j * stride) as f64 + 0.5;
                let row = |e: [f64; 3]| e[1] * y + e[2];
                let (ra, rb, rc) = (row(ea), row(eb), row(ec));
                for i in i0..=i1.min(nu - 1) {
                    let x = (cols[0] + i * stride) as f64 + 0.5;
                    let (wa, wb, wc) = (ea[0] * x + ra, eb[0] * x + rb, ec[0] * x + rc);
                    if wa < -EDGE_TOL || wb < -EDGE_TOL || wc < -EDGE_TOL {
                        continue;
                    }
                    // The inverse depth is linear on the screen.
                    let z = 1.0 / (wa * a[2] + wb * b[2] + wc * c[2]);
                    let k = j * nu + i;
                    if z < depth[k] {
                        depth[k] = z;
                    }
                }
            }
        }
        depth
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

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

    use super::MeshView;
    use crate::sensor::cloud::tests::{cad_model, cell};

    /// The rasterized depths of a CAD part (leads, a tab with a hole) are the ray cast's at
    /// every pixel centre, over poses flat, tilted and on edge; control: the mesh wound inside
    /// out, so that the triangles facing away are drawn, shows its far side, deeper.
    #[test]
    fn rasterized_depths_are_the_ray_casts() {
        let c = cell();
        let cam = &c.camera;
        for file in ["to220.toml", "dip8.toml"] {
            let (mesh, _) = cad_model(file, 0.006);
            let view = MeshView::new(&mesh).unwrap();
            let mut inverted = mesh.clone();
            for t in &mut inverted.triangles {
                t.swap(1, 2);
            }
            let inside_out = MeshView::new(&inverted).unwrap();
            let poses = [
                (0.0, 0.0, 0.3),
                (0.4, 0.2, 1.1),
                (1.2, -0.5, 2.0),
                (std::f64::consts::FRAC_PI_2, 0.0, 0.7),
                (3.0, 0.1, -0.4),
            ];
            for (k, (roll, pitch, yaw)) in poses.into_iter().enumerate() {
                let pose = Isometry3::from_parts(
                    Vector3::new(0.1 + 0.01 * k as f64, 0.45, 0.02).into(),
                    UnitQuaternion::from_euler_angles(roll, pitch, yaw),
                );
                let camera_from_part = cam.world_from_camera.inverse() * pose;
                let centre = cam.project(&Point3::from(pose.translation.vector)).unwrap();
                let (u0, v0) = (centre.0 as usize - 16, centre.1 as usize - 16);
                for stride in [1, 2] {
                    let (cols, rows) = ([u0 / stride * stride, u0 + 32], [v0 / stride * stride, v0 + 32]);
                    let depth = view.depths(cam, &camera_from_part, cols, rows, stride);
                    let nu = (cols[1] - cols[0]) / stride + 1;
                    let (mut hits, mut ray_hits) = (0, 0);
                    let inv = pose.inverse();
                    let eye = inv * Point3::from(cam.world_from_camera.translation.vector);
                    let optical = cam.world_from_camera.rotation * Vector3::z();
                    for (j, v) in (rows[0]..=rows[1]).step_by(stride).enumerate() {
                        for (i, u) in (cols[0]..=cols[1]).step_by(stride).enumerate() {
                            let d = cam.pixel_dir(u, v);
                            let ray = view.ray(&eye, &(inv.rotation * d)).map(|t| t * d.dot(&optical));
                            let z = depth[j * nu + i];
                            match ray {
                                Some(r) => {
                                    ray_hits += 1;
                                    // Single precision in millimetres: a few tenths of a micron.
                                    assert!(
                                        (z - r).abs() < 2e-6,
                                        "{file} pose {k} px ({u}, {v}): raster {z} m, ray {r} m"
                                    );
                                }
                                None => assert!(
                                    z.is_infinite(),
                                    "{file} pose {k} px ({u}, {v}): raster {z} m, no ray hit"
                                ),
                            }
                            hits += z.is_finite() as usize;
                        }
                    }
                    assert!(
                        hits > 20 / stride / stride && hits == ray_hits,
                        "{file} pose {k}: {hits} hits"
                    );
                    // The control: culled the wrong way, the far side shows through.
                    let far = inside_out.depths(cam, &camera_from_part, cols, rows, stride);
                    let deeper = far
                        .iter()
                        .zip(&depth)
                        .filter(|(f, z)| f.is_finite() && **f > **z + 1e-4)
                        .count();
                    assert!(
                        deeper > hits / 2,
                        "{file} pose {k}: inside out, {deeper} of {hits} deeper"
                    );
                }
            }
        }
    }
}
