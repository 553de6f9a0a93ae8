//! The stable resting poses of a part on a flat floor, and how likely each is.
//!
//! Job: the classical quasi-static estimate. A rigid part dropped on a plane comes to rest on a
//! face of its convex hull. Each hull face (coplanar hull triangles merged) is *stable* when the
//! centre of mass projects inside it. Each face collects the probability that the part's first
//! contact direction points at it: the solid angle the face subtends at the centre of mass over
//! 4 pi (a part falling in a uniformly random orientation). An unstable face passes its share on:
//! the part topples over the edge of the face that the projected centre of mass lies farthest
//! beyond, onto the hull face across that edge, and on from there until a stable face is
//! reached (the centre of mass sinks at every step, so the walk ends). A face the part would tip off
//! with almost no lift of its centre of mass (under [`MIN_TOPPLE_BARRIER_SHARE`] of its distance
//! from that edge: a tip of under 8 degrees) is treated as unstable too: what is left of the
//! landing's motion tips it.
//!
//! Stated simplification: no bouncing, rolling momentum or pile contacts (a part in a pile rests
//! on other parts too); the drops the physics simulates are the check of this estimate.
//!
//! Units: m, sr. Frame: the part frame. A pose's `normal` is the hull face's outward normal in
//! the part frame: the part rests with it pointing down (-z of the world).

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};

use super::mesh::Mesh;

/// Angle within which hull triangles count as one face (rad).
pub const HULL_FACE_TOL_RAD: f64 = 1e-3;

/// A face on which the centre of mass must rise less than this share of its distance from the
/// nearest edge to tip over it counts as unstable (a tip of under 8.1 degrees): the part tips
/// off it with the little motion left after landing. Without it, a DIP-8 "rests" on one row of
/// lead tips and its body's edge (0.03 mm of rise, 0.8 % of 3.6 mm: 7.1 degrees) in a third of
/// the drops it is predicted to, where simulated drops put it there in 2 %; with it, that share
/// goes to its back. Until 2026-12-07 the share was of the part's reach (its farthest vertex
/// from the centre of mass), which called C's strips unstable on their 5 mm sides (a 26.6
/// degree tip, 0.59 mm of rise against 1 % of 75 mm), where 22 % of its simulated drops rest.
pub const MIN_TOPPLE_BARRIER_SHARE: f64 = 0.01;

/// A stable resting pose.
#[derive(Debug, Clone, PartialEq)]
pub struct RestingPose {
    /// The supporting hull face's outward normal in the part frame (points down at rest).
    pub normal: Vector3<f64>,
    /// Height of the centre of mass above the floor at rest (m).
    pub com_height_m: f64,
    /// The support polygon's area (m^2).
    pub support_area_m2: f64,
    /// How far the centre of mass's projection is inside the support polygon's nearest edge (m):
    /// the margin against toppling.
    pub stability_margin_m: f64,
    /// Likelihood of resting so (shares sum to 1 over the poses).
    pub likelihood: f64,
}

/// A convex hull: vertices and outward-wound triangles.
#[derive(Debug, Clone, PartialEq)]
pub struct Hull {
    /// Vertices (m).
    pub vertices_m: Vec<Point3<f64>>,
    /// Triangles, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

/// The convex hull of the mesh's vertices (`None` when they are flat or too few).
pub fn convex_hull(mesh: &Mesh) -> Option<Hull> {
    use parry3d::math::Vector3 as V;
    // parry works in f32: hull in mm about the bounding box's centre for precision, then map each
    // hull vertex back to the f64 vertex it is a copy of.
    let (lo, hi) = mesh.bounds_m()?;
    let c = nalgebra::center(&lo, &hi);
    let pts: Vec<V> = mesh
        .vertices_m
        .iter()
        .map(|p| {
            let d = (p - c) * 1e3;
            V::new(d.x as f32, d.y as f32, d.z as f32)
        })
        .collect();
    let mut back: HashMap<[u32; 3], usize> = HashMap::new();
    for (i, p) in pts.iter().enumerate() {
        back.entry([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]).or_insert(i);
    }
    let (hv, ht) = parry3d::transformation::try_convex_hull(&pts).ok()?;
    if ht.len() < 4 {
        return None;
    }
    let vertices_m = hv
        .iter()
        .map(|p| match back.get(&[p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]) {
            Some(&i) => mesh.vertices_m[i],
            None => c + Vector3::new(p.x as f64, p.y as f64, p.z as f64) * 1e-3,
        })
        .collect();
    Some(Hull {
        vertices_m,
        triangles: ht,
    })
}

/// Solid angle of triangle `a b c` seen from the origin (Van Oosterom and Strackee), signed by
/// the winding (positive when counter-clockwise seen from the origin's outside).
fn solid_angle(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> f64 {
    let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
    let num = a.dot(&b.cross(c));
    let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
    2.0 * num.atan2(den)
}

/// A hull face: its triangles, normal, and boundary edges (directed as the face runs them).
struct HullFace {
    normal: Vector3<f64>,
    offset: f64,
    triangles: Vec<usize>,
    edges: Vec<(u32, u32)>,
    area: f64,
}

/// The stable resting poses of a hull about the centre of mass `com`, most likely first.
/// Poses with a likelihood under 1e-6 are dropped.
pub fn resting_poses(hull: &Hull, com: &Point3<f64>) -> Vec<RestingPose> {
    let edge_tri = triangle_of_edge(hull);
    let (faces, face_of) = hull_faces(hull, &edge_tri);
    let share = solid_angle_shares(hull, &faces, com);
    let (next, margin) = topple_targets(hull, &faces, &face_of, &edge_tri, com);
    let mass = settled_shares(&faces, &next, &share, com);
    let mut poses: Vec<RestingPose> = faces
        .iter()
        .enumerate()
        .filter(|(i, _)| mass[*i] > 1e-6)
        .map(|(i, f)| RestingPose {
            normal: f.normal,
            com_height_m: f.offset - com.coords.dot(&f.normal),
            support_area_m2: f.area,
            stability_margin_m: margin[i],
            likelihood: mass[i],
        })
        .collect();
    let total: f64 = poses.iter().map(|p| p.likelihood).sum();
    poses.iter_mut().for_each(|p| p.likelihood /= total);
    poses.sort_by(|a, b| b.likelihood.total_cmp(&a.likelihood));
    poses
}

/// The resting pose a part lies in: the pose whose support normal is nearest to `down_in_part`
/// (the world's down direction in the part frame, unit), if within `tol_rad` of it; `None` when
/// the part rests in none of the predicted poses (tilted against something, or on a hull face
/// the estimate calls unstable).
pub fn pose_resting_on(poses: &[RestingPose], down_in_part: &Vector3<f64>, tol_rad: f64) -> Option<usize> {
    poses
        .iter()
        .enumerate()
        .map(|(i, p)| (i, p.normal.dot(down_in_part)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .filter(|(_, c)| *c >= tol_rad.cos())
        .map(|(i, _)| i)
}

/// The poses grouped into classes that the part's shape cannot tell apart by their support:
/// poses whose centre-of-mass height, support area and stability margin agree within 1 % (or
/// 1e-6 m) share a class (the six flats of a hex prism). Returns each pose's class index,
/// classes numbered in the order of their first pose.
pub fn pose_classes(poses: &[RestingPose]) -> Vec<usize> {
    let near = |a: f64, b: f64, floor: f64| (a - b).abs() <= (0.01 * a.abs().max(b.abs())).max(floor);
    let mut class: Vec<usize> = Vec::with_capacity(poses.len());
    let mut heads: Vec<usize> = Vec::new();
    for p in poses {
        let found = heads.iter().position(|&h| {
            let q = &poses[h];
            near(p.com_height_m, q.com_height_m, 1e-6)
                && near(p.support_area_m2, q.support_area_m2, 1e-12)
                && near(p.stability_margin_m, q.stability_margin_m, 1e-6)
        });
        class.push(found.unwrap_or_else(|| {
            heads.push(class.len());
            heads.len() - 1
        }));
    }
    class
}

/// The poses in groups alike: of one class ([`pose_classes`]) and, where `tag` is given (one
/// flag per pose), of one tag (whether a cup face looks up). Each group's poses in the poses'
/// order, the groups in the order of their first pose: a hex prism's six flats are one group,
/// a coin standing on any facet of its rim another.
pub fn alike_groups(poses: &[RestingPose], tag: &[bool]) -> Vec<Vec<usize>> {
    let class = pose_classes(poses);
    let tag_of = |i: usize| tag.get(i).copied().unwrap_or(false);
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in 0..poses.len() {
        match groups
            .iter_mut()
            .find(|g| class[g[0]] == class[i] && tag_of(g[0]) == tag_of(i))
        {
            Some(g) => g.push(i),
            None => groups.push(vec![i]),
        }
    }
    groups
}

/// The hull triangle that runs each directed edge.
fn triangle_of_edge(hull: &Hull) -> HashMap<(u32, u32), usize> {
    let mut edge_tri: HashMap<(u32, u32), usize> = HashMap::new();
    for (k, t) in hull.triangles.iter().enumerate() {
        for e in 0..3 {
            edge_tri.insert((t[e], t[(e + 1) % 3]), k);
        }
    }
    edge_tri
}

/// The hull's faces (coplanar hull triangles merged over shared edges) and, for each hull
/// triangle, the index of its face.
fn hull_faces(hull: &Hull, edge_tri: &HashMap<(u32, u32), usize>) -> (Vec<HullFace>, Vec<usize>) {
    let v = &hull.vertices_m;
    let tri_n: Vec<Vector3<f64>> = hull
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| v[i as usize]);
            (b - a).cross(&(c - a))
        })
        .collect();
    let cos_tol = HULL_FACE_TOL_RAD.cos();
    let mut face_of = vec![usize::MAX; hull.triangles.len()];
    let mut faces: Vec<HullFace> = Vec::new();
    for s in 0..hull.triangles.len() {
        if face_of[s] != usize::MAX {
            continue;
        }
        let id = faces.len();
        let n0 = tri_n[s].normalize();
        face_of[s] = id;
        let mut members = vec![s];
        let mut stack = vec![s];
        while let Some(k) = stack.pop() {
            let t = hull.triangles[k];
            for e in 0..3 {
                if let Some(&o) = edge_tri.get(&(t[(e + 1) % 3], t[e]))
                    && face_of[o] == usize::MAX
                    && tri_n[o].normalize().dot(&n0) >= cos_tol
                {
                    face_of[o] = id;
                    members.push(o);
                    stack.push(o);
                }
            }
        }
        faces.push(hull_face(hull, edge_tri, &tri_n, members));
    }
    (faces, face_of)
}

/// The face of the hull triangles `members` (`tri_n`: each hull triangle's area-weighted normal).
fn hull_face(
    hull: &Hull,
    edge_tri: &HashMap<(u32, u32), usize>,
    tri_n: &[Vector3<f64>],
    members: Vec<usize>,
) -> HullFace {
    let v = &hull.vertices_m;
    let nsum: Vector3<f64> = members.iter().map(|&k| tri_n[k]).sum();
    let normal = nsum.normalize();
    let offset = members
        .iter()
        .flat_map(|&k| hull.triangles[k])
        .map(|i| v[i as usize].coords.dot(&normal))
        .fold(f64::NEG_INFINITY, f64::max);
    let mut edges = Vec::new();
    for &k in &members {
        let t = hull.triangles[k];
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            if edge_tri.get(&(b, a)).is_none_or(|&o| !members.contains(&o)) {
                edges.push((a, b));
            }
        }
    }
    let area = 0.5 * nsum.norm();
    HullFace {
        normal,
        offset,
        triangles: members,
        edges,
        area,
    }
}

/// How far the centre of mass rises (m) when the part, resting on face `f`, tips over the edge
/// `margin_m` from the centre of mass's projection: `sqrt(h^2 + margin^2) - h`, `h` the centre
/// of mass's height over the face.
fn barrier(f: &HullFace, com: &Point3<f64>, margin_m: f64) -> f64 {
    let h = f.offset - com.coords.dot(&f.normal);
    (h * h + margin_m * margin_m).sqrt() - h
}

/// The centre of mass's distance (m) from the edge `margin_m` from its projection on face `f`:
/// the radius it turns on as the part tips over that edge.
fn tip_radius(f: &HullFace, com: &Point3<f64>, margin_m: f64) -> f64 {
    (f.offset - com.coords.dot(&f.normal)).hypot(margin_m)
}

/// Solid angle of each face at the centre of mass, as a share of the whole sphere.
fn solid_angle_shares(hull: &Hull, faces: &[HullFace], com: &Point3<f64>) -> Vec<f64> {
    let v = &hull.vertices_m;
    faces
        .iter()
        .map(|f| {
            f.triangles
                .iter()
                .map(|&k| {
                    let [a, b, c] = hull.triangles[k].map(|i| v[i as usize] - com);
                    solid_angle(&a, &b, &c)
                })
                .sum::<f64>()
                / (4.0 * std::f64::consts::PI)
        })
        .collect()
}

/// For each face: the face it topples onto (`None`: stable), and the stability margin (m) of a
/// stable face.
fn topple_targets(
    hull: &Hull,
    faces: &[HullFace],
    face_of: &[usize],
    edge_tri: &HashMap<(u32, u32), usize>,
    com: &Point3<f64>,
) -> (Vec<Option<usize>>, Vec<f64>) {
    let v = &hull.vertices_m;
    let beyond = |f: &HullFace| -> Option<((u32, u32), f64)> {
        // The projection of the centre of mass onto the face's plane, against each edge: the
        // signed distance outward (positive: outside that edge).
        f.edges
            .iter()
            .map(|&(a, b)| {
                let (pa, pb) = (v[a as usize], v[b as usize]);
                let out = (pb - pa).cross(&f.normal).normalize();
                ((a, b), (com - pa).dot(&out))
            })
            .max_by(|x, y| x.1.total_cmp(&y.1))
    };
    let mut next = vec![None; faces.len()];
    let mut margin = vec![0.0; faces.len()];
    for (i, f) in faces.iter().enumerate() {
        match beyond(f) {
            Some(((a, b), d)) if d > 0.0 || barrier(f, com, -d) < MIN_TOPPLE_BARRIER_SHARE * tip_radius(f, com, -d) => {
                next[i] = edge_tri.get(&(b, a)).map(|&o| face_of[o]);
                margin[i] = (-d).max(0.0);
            }
            Some((_, d)) => margin[i] = -d,
            None => {}
        }
    }
    (next, margin)
}

/// Each face's share after the unstable faces passed theirs on down the topple walk.
fn settled_shares(faces: &[HullFace], next: &[Option<usize>], share: &[f64], com: &Point3<f64>) -> Vec<f64> {
    let mut mass = vec![0.0; faces.len()];
    for (i, s) in share.iter().enumerate() {
        let mut at = i;
        let mut steps = 0;
        while let Some(n) = next[at] {
            // The centre of mass must sink (the next face's plane is nearer to it); otherwise
            // stop where it is lowest.
            let h = |k: usize| faces[k].offset - com.coords.dot(&faces[k].normal);
            if h(n) >= h(at) || steps > faces.len() {
                break;
            }
            at = n;
            steps += 1;
        }
        mass[at] += s;
    }
    mass
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::mass::tests::box_mesh;

    fn poses_of(m: &Mesh, com: Point3<f64>) -> Vec<RestingPose> {
        resting_poses(&convex_hull(m).unwrap(), &com)
    }

    #[test]
    fn a_cube_rests_on_each_face_at_one_sixth() {
        let m = box_mesh([-0.005; 3], [0.005; 3]);
        let p = poses_of(&m, Point3::origin());
        assert_eq!(p.len(), 6);
        for q in &p {
            assert!((q.likelihood - 1.0 / 6.0).abs() < 1e-9, "{}", q.likelihood);
            assert!((q.com_height_m - 0.005).abs() < 1e-12);
            assert!((q.stability_margin_m - 0.005).abs() < 1e-12);
        }
    }

    #[test]
    fn a_1x2x3_box_rests_most_on_its_largest_faces() {
        let m = box_mesh([0.0; 3], [0.01, 0.02, 0.03]);
        let p = poses_of(&m, Point3::new(0.005, 0.01, 0.015));
        assert_eq!(p.len(), 6);
        // Most likely first: the two 2 x 3 faces (normal along x), then 1 x 3, then 1 x 2.
        assert!(p[0].normal.x.abs() > 0.999 && p[1].normal.x.abs() > 0.999);
        assert!(p[2].normal.y.abs() > 0.999 && p[3].normal.y.abs() > 0.999);
        assert!(p[4].normal.z.abs() > 0.999);
        assert!(p[0].likelihood > p[2].likelihood && p[2].likelihood > p[4].likelihood);
        // Independent check: the solid angle of a rectangle a x b at distance d on its axis is
        // 4 asin(a b / sqrt((a^2 + 4 d^2)(b^2 + 4 d^2))).
        let omega =
            |a: f64, b: f64, d: f64| 4.0 * (a * b / ((a * a + 4.0 * d * d) * (b * b + 4.0 * d * d)).sqrt()).asin();
        let want = omega(0.02, 0.03, 0.005) / (4.0 * std::f64::consts::PI);
        assert!((p[0].likelihood - want).abs() < 1e-9, "{} vs {want}", p[0].likelihood);
    }

    /// A prism whose cross-section (x, z) is the obtuse triangle (0, 0), (30, 0), (40, 10) mm,
    /// 10 mm deep in y. Only its vertices matter to the hull.
    fn obtuse_prism() -> Mesh {
        let mut v = Vec::new();
        for y in [0.0, 0.01] {
            for (x, z) in [(0.0, 0.0), (0.03, 0.0), (0.04, 0.01)] {
                v.push(Point3::new(x, y, z));
            }
        }
        Mesh {
            vertices_m: v,
            triangles: Vec::new(),
        }
    }

    #[test]
    fn an_unstable_face_topples_onto_its_neighbour() {
        // The true centre of mass: the triangle's centroid (23.3, 3.3) mm, mid-depth. The short
        // side (30, 0)-(40, 10) does not hold it (the projection falls beyond (30, 0)): the part
        // topples onto the floor face z = 0, which gets both shares.
        let com = Point3::new(0.07 / 3.0, 0.005, 0.01 / 3.0);
        let p = poses_of(&obtuse_prism(), com);
        assert_eq!(p.len(), 4, "{p:?}");
        let short = Vector3::new(1.0, 0.0, -1.0).normalize();
        assert!(p.iter().all(|q| q.normal.dot(&short) < 0.99));
        let sum: f64 = p.iter().map(|q| q.likelihood).sum();
        assert!((sum - 1.0).abs() < 1e-9);
        let floor = p.iter().find(|q| q.normal.z < -0.999).unwrap();
        // Independent: the floor face's own solid angle, summed with the short side's.
        let tri = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
            let (a, b, c) = (
                Vector3::from(a) - com.coords,
                Vector3::from(b) - com.coords,
                Vector3::from(c) - com.coords,
            );
            solid_angle(&a, &b, &c).abs()
        };
        let rect = |a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]| tri(a, b, c) + tri(a, c, d);
        let floor_own = rect([0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.03, 0.01, 0.0], [0.0, 0.01, 0.0]);
        let short_own = rect(
            [0.03, 0.0, 0.0],
            [0.04, 0.0, 0.01],
            [0.04, 0.01, 0.01],
            [0.03, 0.01, 0.0],
        );
        let want = (floor_own + short_own) / (4.0 * std::f64::consts::PI);
        assert!((floor.likelihood - want).abs() < 1e-9, "{} vs {want}", floor.likelihood);
    }

    #[test]
    fn a_face_tipped_off_with_almost_no_lift_is_not_a_pose() {
        // A 20 x 10 x 10 mm block with the centre of mass 0.05 mm inside the edge of an end face
        // (x = 0 end): on that end, the centre of mass rises 0.000125 mm to tip over, under 1 %
        // of its 10 mm from that edge: not a pose; its share goes to the face across that edge.
        // Negative control: 2 mm inside, the rise is 0.2 mm, 2 % of 10.2 mm: the end is a pose.
        let m = box_mesh([0.0, 0.0, 0.0], [0.02, 0.01, 0.01]);
        let end = |p: &[RestingPose]| p.iter().any(|q| q.normal.x < -0.999);
        let near = poses_of(&m, Point3::new(0.01, 0.005, 0.00005));
        assert!(!end(&near), "{near:?}");
        let sum: f64 = near.iter().map(|q| q.likelihood).sum();
        assert!((sum - 1.0).abs() < 1e-9);
        let inside = poses_of(&m, Point3::new(0.01, 0.005, 0.002));
        assert!(end(&inside), "{inside:?}");
    }

    #[test]
    fn a_long_strip_rests_on_its_narrow_sides_too() {
        // C's strip, 150 x 10 x 5 mm: on a 150 x 5 mm side its centre of mass stands 5 mm high
        // and 2.5 mm inside the edges, a tip of 26.6 deg (0.59 mm of rise, 10.6 % of its 5.59 mm
        // from the edge): a pose, where 22 % of simulated drops rest (`binpick part C`). The
        // control: against 1 % of the strip's reach (75.2 mm), the measure before, the same rise
        // is under the bound, and the sides were no pose.
        let m = box_mesh([-0.075, -0.005, -0.0025], [0.075, 0.005, 0.0025]);
        let poses = poses_of(&m, Point3::origin());
        let side: f64 = poses
            .iter()
            .filter(|q| q.normal.y.abs() > 0.999)
            .map(|q| q.likelihood)
            .sum();
        assert!(side > 0.1, "{poses:?}");
        let rise = 0.005f64.hypot(0.0025) - 0.005;
        let reach = (0.075f64 * 0.075 + 0.005 * 0.005 + 0.0025 * 0.0025).sqrt();
        assert!(rise < MIN_TOPPLE_BARRIER_SHARE * reach && rise > MIN_TOPPLE_BARRIER_SHARE * 0.005f64.hypot(0.0025));
    }

    #[test]
    fn a_wrong_centre_of_mass_changes_the_poses() {
        let right = poses_of(&obtuse_prism(), Point3::new(0.07 / 3.0, 0.005, 0.01 / 3.0));
        // Negative control: the centre of mass put 7 mm off along x (a wrong model, right over
        // the floor face's edge) stands the part on its short side, and the test sees it.
        let wrong = poses_of(&obtuse_prism(), Point3::new(0.03, 0.005, 0.01 / 3.0));
        let short = Vector3::new(1.0, 0.0, -1.0).normalize();
        let on_short = |p: &[RestingPose]| p.iter().any(|q| q.normal.dot(&short) > 0.999);
        assert_eq!(right.len(), 4);
        assert!(!on_short(&right) && on_short(&wrong), "{wrong:?}");
        // And in a tall block, a centre of mass 1 mm under one end makes that end the most
        // likely pose, where the true one rests most likely on a side.
        let m = box_mesh([-0.005, -0.005, -0.02], [0.005, 0.005, 0.02]);
        assert!(poses_of(&m, Point3::origin())[0].normal.z.abs() < 0.5);
        assert!(poses_of(&m, Point3::new(0.0, 0.0, 0.019))[0].normal.z > 0.99);
    }
}
