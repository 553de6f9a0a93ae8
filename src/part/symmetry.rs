//! The rotational symmetry of a part's mesh.
//!
//! Job: for each axis of the part frame through the centre of mass, the order of rotational
//! symmetry: the largest `n` (up to [`MAX_ORDER`]) such that the rotation by 360/n degrees maps
//! the mesh onto itself (every vertex and every triangle's centroid lands within the tolerance
//! of a vertex, respectively a triangle centroid, of the mesh); 1 for none. An order of
//! [`MAX_ORDER`] or more reads as continuous (a round part). The workpiece file may override what
//! is detected.
//!
//! Stated simplification: only rotations about the part frame's axes are tried (CAD models of
//! symmetric parts are drawn on their axes); a symmetry about a tilted axis is not found.
//!
//! Units: m. Frame: the part frame.

use std::collections::HashMap;

use nalgebra::{Point3, Rotation3, Vector3};

use super::mesh::Mesh;

/// The highest order tried; a part with this order or more is taken as round.
pub const MAX_ORDER: u32 = 64;

/// Orders of rotational symmetry about the part's x, y and z axes through the centre of mass.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Symmetry {
    /// Orders about x, y, z (1: none; [`MAX_ORDER`]: round).
    pub orders: [u32; 3],
}

/// A set of points for nearest-point queries within a tolerance.
struct PointSet {
    tol: f64,
    cells: HashMap<[i64; 3], Vec<Point3<f64>>>,
}

impl PointSet {
    fn new(points: impl Iterator<Item = Point3<f64>>, tol: f64) -> Self {
        let mut cells: HashMap<[i64; 3], Vec<Point3<f64>>> = HashMap::new();
        for p in points {
            cells.entry(Self::key(&p, tol)).or_default().push(p);
        }
        PointSet { tol, cells }
    }
    fn key(p: &Point3<f64>, tol: f64) -> [i64; 3] {
        [0, 1, 2].map(|a| (p[a] / tol).floor() as i64)
    }
    fn has(&self, p: &Point3<f64>) -> bool {
        let k = Self::key(p, self.tol);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(c) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz])
                        && c.iter().any(|q| (q - p).norm() <= self.tol)
                    {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// The triangles of a mesh on a grid, for "is this point on the surface" queries.
struct SurfaceGrid<'a> {
    mesh: &'a Mesh,
    cell: f64,
    tol: f64,
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl<'a> SurfaceGrid<'a> {
    fn new(mesh: &'a Mesh, tol: f64) -> Self {
        let ext = mesh.extent_m();
        let cell = (ext.iter().cloned().fold(0.0, f64::max) / 32.0).max(tol * 4.0);
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for k in 0..mesh.triangles.len() {
            let c = mesh.corners(k);
            let lo = [0, 1, 2].map(|a| ((c[0][a].min(c[1][a]).min(c[2][a]) - tol) / cell).floor() as i64);
            let hi = [0, 1, 2].map(|a| ((c[0][a].max(c[1][a]).max(c[2][a]) + tol) / cell).floor() as i64);
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        cells.entry([x, y, z]).or_default().push(k as u32);
                    }
                }
            }
        }
        SurfaceGrid { mesh, cell, tol, cells }
    }

    fn on_surface(&self, p: &Point3<f64>) -> bool {
        let key = [0, 1, 2].map(|a| (p[a] / self.cell).floor() as i64);
        self.cells.get(&key).is_some_and(|ts| {
            ts.iter()
                .any(|&k| distance_to_triangle(p, &self.mesh.corners(k as usize)) <= self.tol)
        })
    }
}

/// A turn of the part that does not map its mesh onto itself but that a depth image cannot tell
/// from the part ([`look_alike_turns`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LookAlike {
    /// The axis of the part frame, through the centre of mass (0: x, 1: y, 2: z).
    pub axis: usize,
    /// The turn is 360 degrees over this.
    pub order: u32,
    /// The farthest the turned mesh's surface lies from the mesh's (m).
    pub max_off_m: f64,
    /// The share of the resting poses (by likelihood) in which a depth image cannot tell the
    /// part from its turn.
    pub share: f64,
    /// The log-likelihood ratio a depth image gives between the part and its turn, averaged
    /// over those poses (by likelihood).
    pub evidence: f64,
}

/// The turns a symmetry of `orders` lacks (a half turn about x, y or z, a quarter turn about z)
/// whose image of `mesh` (about `com`) a depth sensor above it, of pixel `pixel_m` and depth
/// noise `noise_m`, cannot tell from the mesh in resting poses making up at least half the
/// likelihood (`poses`: each pose's up direction in the part frame and its likelihood): there
/// the evidence, a log-likelihood ratio between the two, is under `min_evidence` (the
/// recogniser's close-call odds). A pose's evidence is estimated from the surface sampled about
/// once per pixel's area (at least once per triangle), as the part lies and turned, each sample
/// weighted by how much of its area faces up in the pose (its projection on the image): its
/// distance to the other (parry's, through its tree; capped at three sigma) squared over twice
/// the variance, summed, the two images' sums averaged (either may be the truth). A pin-1 dimple 0.1 mm deep and 1 mm across: about 0.1; a coin cell's cap 0.3 mm
/// proud over a 17 mm disc: hundreds. Stated simplification: the image is not rendered;
/// occlusion (of the part by itself too) and grazing dropout are left out.
pub fn look_alike_turns(
    mesh: &Mesh,
    com: &Point3<f64>,
    orders: [u32; 3],
    poses: &[(Vector3<f64>, f64)],
    pixel_m: f64,
    noise_m: f64,
    min_evidence: f64,
) -> Vec<LookAlike> {
    use parry3d::query::PointQuery;
    // The surface in millimetres (parry works in f32), its distance queries through its tree.
    let mm = |p: &Point3<f64>| parry3d::math::Vector3::new((p.x * 1e3) as f32, (p.y * 1e3) as f32, (p.z * 1e3) as f32);
    let Ok(surface) = parry3d::shape::TriMesh::new(mesh.vertices_m.iter().map(mm).collect(), mesh.triangles.clone())
    else {
        return Vec::new();
    };
    let cap_m = 3.0 * noise_m;
    let distance_m = |p: &Point3<f64>| (surface.distance_to_local_point(mm(p), false) as f64 * 1e-3).min(cap_m);
    let mut candidates: Vec<(usize, u32)> = (0..3)
        .filter(|&a| orders[a] < MAX_ORDER && !orders[a].is_multiple_of(2))
        .map(|a| (a, 2))
        .collect();
    if orders[2] < MAX_ORDER && !orders[2].is_multiple_of(4) {
        candidates.push((2, 4));
    }
    candidates
        .into_iter()
        .filter_map(|(axis, order)| {
            let r = Rotation3::from_axis_angle(&Vector3::ith_axis(axis), std::f64::consts::TAU / order as f64);
            let turn = |p: &Point3<f64>| com + r * (p - com);
            let turn_back = |p: &Point3<f64>| com + r.inverse() * (p - com);
            let mut evidence = vec![0.0; poses.len()];
            let mut max_off_m = 0.0f64;
            for k in 0..mesh.triangles.len() {
                let t = mesh.corners(k);
                let normal = (t[1] - t[0]).cross(&(t[2] - t[0]));
                let area = 0.5 * normal.norm();
                if area <= 0.0 {
                    continue;
                }
                let normal = normal / (2.0 * area);
                // Each pose's share of the triangle seen from above (its projection), as the part
                // lies and turned.
                let seen: Vec<(f64, f64)> = poses
                    .iter()
                    .map(|(up, _)| (normal.dot(up).max(0.0), (r * normal).dot(up).max(0.0)))
                    .collect();
                // m x m sub-triangles, each about a pixel's area; their centroids.
                let m = ((2.0 * area).sqrt() / pixel_m).ceil().max(1.0) as usize;
                let w = area / (m * m) as f64 / (pixel_m * pixel_m);
                let (e1, e2) = ((t[1] - t[0]) / m as f64, (t[2] - t[0]) / m as f64);
                for i in 0..m {
                    for j in 0..m - i {
                        let mut corners = vec![
                            (i as f64, j as f64),
                            (i as f64 + 1.0, j as f64),
                            (i as f64, j as f64 + 1.0),
                        ];
                        if i + j + 1 < m {
                            corners.push((i as f64 + 1.0, j as f64 + 1.0));
                        }
                        // The sub-triangle (i, j) and, where it fits, the one flipped beside it.
                        for tri in [[0, 1, 2], [1, 3, 2]].iter().take(corners.len() - 2) {
                            let (a, b) = tri
                                .iter()
                                .fold((0.0, 0.0), |(a, b), &c| (a + corners[c].0, b + corners[c].1));
                            let p = t[0] + e1 * (a / 3.0) + e2 * (b / 3.0);
                            // The point off the turned mesh (its preimage off the mesh), and the
                            // turned point off the mesh.
                            let (d_part, d_turned) = (distance_m(&turn_back(&p)), distance_m(&turn(&p)));
                            max_off_m = max_off_m.max(d_part).max(d_turned);
                            let e = |d: f64| w * d * d / (2.0 * noise_m * noise_m);
                            for (sum, (s_part, s_turned)) in evidence.iter_mut().zip(&seen) {
                                // Either pose the truth: the mean of the two images' evidence.
                                *sum += 0.5 * (e(d_part) * s_part + e(d_turned) * s_turned);
                            }
                        }
                    }
                }
            }
            // The poses in which the image cannot tell them apart, and their likelihood.
            let blind: Vec<(f64, f64)> = poses
                .iter()
                .zip(&evidence)
                .filter(|(_, e)| **e < min_evidence)
                .map(|((_, l), e)| (*l, *e))
                .collect();
            let share: f64 = blind.iter().map(|(l, _)| l).sum();
            (share >= 0.5).then(|| LookAlike {
                axis,
                order,
                max_off_m,
                share,
                evidence: blind.iter().map(|(l, e)| l * e).sum::<f64>() / share,
            })
        })
        .collect()
}

/// Distance from `p` to the triangle `t` (its plane inside it, else its nearest edge).
fn distance_to_triangle(p: &Point3<f64>, t: &[Point3<f64>; 3]) -> f64 {
    let n = (t[1] - t[0]).cross(&(t[2] - t[0]));
    let nn = n.norm_squared();
    if nn > 0.0 {
        let d = (p - t[0]).dot(&n) / nn;
        let q = p - n * d;
        let inside = (0..3).all(|e| (t[(e + 1) % 3] - t[e]).cross(&(q - t[e])).dot(&n) >= 0.0);
        if inside {
            return (p - q).norm();
        }
    }
    (0..3)
        .map(|e| {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            let ab = b - a;
            let s = ((p - a).dot(&ab) / ab.norm_squared().max(1e-300)).clamp(0.0, 1.0);
            (p - (a + ab * s)).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Detects the symmetry of `mesh` about axes through `com`, matching within `tol_m`: a rotation
/// is a symmetry when every vertex lands on a vertex and every triangle's centroid lands on the
/// surface (the second test does not depend on how the faces are triangulated).
pub fn detect(mesh: &Mesh, com: &Point3<f64>, tol_m: f64) -> Symmetry {
    let verts = PointSet::new(mesh.vertices_m.iter().copied(), tol_m);
    let surface = SurfaceGrid::new(mesh, tol_m);
    let cents: Vec<Point3<f64>> = (0..mesh.triangles.len())
        .map(|k| {
            let [a, b, c] = mesh.corners(k);
            Point3::from((a.coords + b.coords + c.coords) / 3.0)
        })
        .collect();
    let maps = |axis: Vector3<f64>, angle: f64| {
        let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
        let turn = |p: &Point3<f64>| com + r * (p - com);
        mesh.vertices_m.iter().all(|p| verts.has(&turn(p))) && cents.iter().all(|p| surface.on_surface(&turn(p)))
    };
    // A round part first: turns by angles of no regular polygon map every vertex and every
    // triangle's centroid onto the surface within a looser tolerance (1e-3 of the part's
    // diagonal), as they do for a finely tessellated round surface (not onto vertices: those of
    // the turned mesh fall between the original's).
    let diag = mesh.extent_m().iter().map(|e| e * e).sum::<f64>().sqrt();
    let round_surface = SurfaceGrid::new(mesh, (1e-3 * diag).max(tol_m));
    let round = |axis: Vector3<f64>, angle: f64| {
        let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
        let turn = |p: &Point3<f64>| com + r * (p - com);
        mesh.vertices_m
            .iter()
            .chain(cents.iter())
            .all(|p| round_surface.on_surface(&turn(p)))
    };
    let orders = [Vector3::x(), Vector3::y(), Vector3::z()].map(|axis| {
        if [1.0, 0.37, 2.3].iter().all(|&a| round(axis, a)) {
            return MAX_ORDER;
        }
        (2..=MAX_ORDER)
            .rev()
            .find(|&n| maps(axis, 2.0 * std::f64::consts::PI / n as f64))
            .unwrap_or(1)
    });
    Symmetry { orders }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::mass::tests::box_mesh;

    #[test]
    fn boxes_have_the_orders_of_their_faces() {
        let cube = box_mesh([-0.005; 3], [0.005; 3]);
        assert_eq!(detect(&cube, &Point3::origin(), 1e-7).orders, [4, 4, 4]);
        let plate = box_mesh([-0.01, -0.005, -0.001], [0.01, 0.005, 0.001]);
        assert_eq!(detect(&plate, &Point3::origin(), 1e-7).orders, [2, 2, 2]);
        // Negative control: about a point off the centre, nothing maps onto itself.
        assert_eq!(detect(&plate, &Point3::new(0.001, 0.0, 0.0), 1e-7).orders, [2, 1, 1]);
        // A fine 720-gon prism reads as round about its axis; an octagonal one has order 8.
        let prism = |n: u32| {
            let mut m = Mesh::default();
            for z in [-0.002, 0.002] {
                for k in 0..n {
                    let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
                    m.vertices_m.push(Point3::new(0.005 * a.cos(), 0.005 * a.sin(), z));
                }
            }
            for k in 0..n {
                let j = (k + 1) % n;
                m.triangles.push([k, j, n + j]);
                m.triangles.push([k, n + j, n + k]);
                if k > 0 && j > 0 {
                    m.triangles.push([0, j, k]);
                    m.triangles.push([n, n + k, n + j]);
                }
            }
            m
        };
        assert_eq!(detect(&prism(720), &Point3::origin(), 1e-7).orders[2], MAX_ORDER);
        assert_eq!(detect(&prism(8), &Point3::origin(), 1e-7).orders[2], 8);
    }

    /// A 9 x 6 x 3 mm block with a nub off-centre on its top (a pin-1 mark): the mesh has no
    /// half turn, but a 1 mm nub 0.1 mm high is one no depth image tells apart (0.85 mm pixels,
    /// 0.33 mm noise): the half turns about x, y and z are look-alikes. Negative controls: a
    /// 3 x 3 mm nub 1 mm high is told apart, and so is the small nub by a finer sensor (0.2 mm
    /// pixels, 0.03 mm noise) wherever the nub is up (60 % of the poses here; nub down, no
    /// sensor above tells the turns apart).
    #[test]
    fn a_mark_below_the_depth_noise_makes_turns_look_alike() {
        let with_nub = |side: f64, height: f64| {
            let mut m = box_mesh([-0.0045, -0.003, -0.0015], [0.0045, 0.003, 0.0015]);
            let nub = box_mesh(
                [-0.0035, 0.001, 0.0015],
                [-0.0035 + side, 0.001 + side, 0.0015 + height],
            );
            let off = m.vertices_m.len() as u32;
            m.vertices_m.extend(nub.vertices_m);
            m.triangles.extend(nub.triangles.iter().map(|t| t.map(|i| i + off)));
            m
        };
        let com = Point3::origin();
        let small = with_nub(0.001, 0.0001);
        let orders = detect(&small, &com, 1e-7).orders;
        assert_eq!(orders, [1, 1, 1]);
        let odds = 2.0 * std::f64::consts::LN_10;
        // Lying on either large face, the nub up a little more often.
        let flat = [(Vector3::z(), 0.6), (-Vector3::z(), 0.4)];
        let turns = look_alike_turns(&small, &com, orders, &flat, 0.00085, 0.00033, odds);
        let found: Vec<(usize, u32)> = turns.iter().map(|t| (t.axis, t.order)).collect();
        assert_eq!(found, [(0, 2), (1, 2), (2, 2)], "{turns:?}");
        assert!(
            turns.iter().all(|t| t.max_off_m < 0.00011 && t.evidence < 0.5),
            "{turns:?}"
        );
        let large = with_nub(0.003, 0.001);
        let orders = detect(&large, &com, 1e-7).orders;
        assert!(look_alike_turns(&large, &com, orders, &flat, 0.00085, 0.00033, odds).is_empty());
        assert!(look_alike_turns(&small, &com, [1, 1, 1], &flat, 0.0002, 0.00003, odds).is_empty());
    }
}
