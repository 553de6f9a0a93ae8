//! Recognition by point-pair features (Drost et al., 2010), for parts whose visible surface is not
//! one large planar face: a model description built once from the part's mesh, votes of scene
//! point pairs for poses, pose clusters, refinement by ICP and verification by rendering (the
//! face method's own check, `Cloud::check`), so the grasp selector sees the same detections.
//!
//! Model ([`PpfModel::new`]): the mesh surface sampled on a grid of `step_m / 3` per triangle with
//! the triangle's outward normal, thinned to one sample per `step_m / 3` voxel and distinct normal
//! (30 degrees apart: an edge keeps both sides) for ICP (an R-tree), and per `step_m` voxel for
//! the features. `step_m` is tied to the sensor: [`STEP_PX`] pixels at the tray floor's depth
//! (1.7 mm with the default sensor). Every ordered pair of feature points closer than the part's
//! diameter (its bounding box's diagonal) is stored under its feature F = (distance, angle(n1, d),
//! angle(n2, d), angle(n1, n2)), quantised in `step_m` and [`ANGLE_BINS`] bins of pi, with the
//! angle `alpha_m` of the second point about the first's normal once the first sits at the origin
//! with its normal along x.
//!
//! Scene (`detect`): the foreground pixels thinned to one per `step_m` voxel (the first in the
//! image's row order), each with a normal fitted (least squares) to the foreground pixels within
//! [`NORMAL_RADIUS_PX`] whose depth is within [`NORMAL_DEPTH_M`] of its own, turned toward the
//! camera. Every [`REF_EVERY`]-th scene point is a reference: paired with every scene point within
//! the diameter (an R-tree query), each pair's feature looks up the model pairs, which vote for
//! (model reference point, rotation about the normal) in [`ALPHA_BINS`] bins; the reference's
//! best cell, with at least [`MIN_VOTES`], is a pose. Poses are clustered greedily, most votes
//! first (within a tenth of the diameter and [`CLUSTER_RAD`], the part's symmetries allowed), a
//! cluster keeping its first pose and summing its votes.
//!
//! Refinement and verification: the clusters with most votes, [`PER_PART`] per place and
//! [`MAX_HYPOTHESES`] in all, are refined by point-to-plane ICP (every [`ICP_STRIDE_PX`]-th pixel
//! within the part's bounding radius, each paired with its nearest dense model sample facing the
//! camera, within a distance shrinking from 2.5 mm to [`ICP_FINAL_M`]) and checked as the face
//! method checks its hypotheses (not under the tray floor, rendered against the depth image,
//! score at least [`super::MIN_SCORE`]). Among the verified hypotheses, most evidence first, one
//! closer than half the part's smallest size to a kept one is the same part; a different pose
//! (beyond [`super::SAME_POSE_M`] and [`super::SAME_POSE_RAD`], symmetries allowed) within
//! [`TIE_MARGIN`] of its evidence leaves the place unreported. Each kept pose is then settled
//! (`settle`): turned about the part's axes through its surface centroid (quarter and half turns
//! refined by ICP, 15 and 45 degrees as they are), the best supported of them wins, and nothing is
//! reported when a different one comes within [`TIE_MARGIN`] (precision first, as the face
//! method: a pose the image does not decide is not reported). Last, the rendered outline must
//! be an edge in the image (`outline_is_an_edge`): a part shape fitted into a larger surface
//! (a can's top into a block's top) is not a part.
//!
//! Simplifications: one pose per reference point (Drost keeps every peak above a share of the
//! best); no neighbouring-bin spreading of features; the model's hidden sides vote as well as its
//! visible ones (no view-dependent model); scene points are thinned in voxels, not by a
//! normal-aware filter; the cluster pose is its best member's, not an average; ICP pairs each
//! pixel with the nearest model sample (no projective association) and has no outlier weighting
//! beyond its distance gate; the settling turns are about the part's own axes only.
//!
//! Units: m, rad, px. Frames: the part frame for the model, world for the scene; a pair's local
//! frame puts its first point at the origin with its normal along x. Deterministic: fixed orders,
//! parallel stages collected in order, ties broken by index.

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;
use rstar::RTree;
use rstar::primitives::GeomWithData;

use super::icp::{DenseSurface, icp, surface_samples, thin};
pub use super::icp::{ICP_FINAL_M, ICP_ITERATIONS, ICP_STRIDE_PX};
use super::{Cloud, CloudDetection, CloudModel, SAME_POSE_M, SAME_POSE_RAD};
use crate::part::mesh::Mesh;

/// Sampling step of model and scene, in pixels of the sensor at the tray floor's depth.
pub const STEP_PX: f64 = 2.0;
/// Bins of pi for the three angles of a feature (12 degrees).
pub const ANGLE_BINS: usize = 15;
/// Bins of a full turn for the rotation about a reference point's normal (12 degrees).
pub const ALPHA_BINS: usize = 30;
/// Every this many scene points one is a reference point.
pub const REF_EVERY: usize = 5;
/// A scene point's normal is fitted to the pixels within this many pixels of it (px).
pub const NORMAL_RADIUS_PX: i64 = 2;
/// ... whose depth is within this of its own (m).
pub const NORMAL_DEPTH_M: f64 = 0.0015;
/// Fewest votes of a reference point's best cell that make a pose.
pub const MIN_VOTES: u16 = 4;
/// Two poses within this rotation (and a tenth of the diameter) join one cluster (rad).
pub const CLUSTER_RAD: f64 = 15.0 * std::f64::consts::PI / 180.0;
/// Clusters refined and verified per capture, most votes first.
pub const MAX_HYPOTHESES: usize = 120;
/// ... and per place (clusters closer than half the part's smallest size).
pub const PER_PART: usize = 3;
/// A different pose of the same part with at most this much less evidence (grid points) leaves
/// the part unreported.
pub const TIE_MARGIN: i64 = 2;

/// A point with its index, for the R-trees.
type Indexed = GeomWithData<[f64; 3], u32>;

/// The model description: sampled surface, the pair feature table, the dense surface for ICP.
pub struct PpfModel {
    /// Sampling step (m): the feature points' spacing and the distance bin.
    step_m: f64,
    /// The part's diameter: its bounding box's diagonal (m).
    diameter_m: f64,
    /// Feature points and their outward normals (part frame).
    points: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    /// Feature key -> range of `entries`.
    table: HashMap<u32, (u32, u32)>,
    /// (model reference point, alpha_m (rad)) sorted by key.
    entries: Vec<(u32, f32)>,
    /// The dense surface samples, for ICP.
    dense: DenseSurface,
    /// The surface's centroid (the dense samples' mean): turned alternatives turn about it.
    centroid_m: Vector3<f64>,
}

impl std::fmt::Debug for PpfModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PpfModel")
            .field("step_m", &self.step_m)
            .field("points", &self.points.len())
            .field("pairs", &self.entries.len())
            .finish()
    }
}

/// The rotation taking unit `n` onto +x.
fn align_x(n: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(n, &Vector3::x())
        .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI))
}

/// Angle of `q` about x, from the y axis toward z (rad), in [0, 2 pi).
fn angle_about_x(q: &Vector3<f64>) -> f64 {
    q.z.atan2(q.y).rem_euclid(std::f64::consts::TAU)
}

/// The continuous feature of a pair (distance in steps, three angles in bins), or `None` for
/// coincident points.
fn feature(
    p1: &Vector3<f64>,
    n1: &Vector3<f64>,
    p2: &Vector3<f64>,
    n2: &Vector3<f64>,
    step_m: f64,
) -> Option<[f64; 4]> {
    let d = p2 - p1;
    let len = d.norm();
    if len < 1e-9 {
        return None;
    }
    let u = d / len;
    let ang = |a: &Vector3<f64>, b: &Vector3<f64>| {
        a.dot(b).clamp(-1.0, 1.0).acos() / std::f64::consts::PI * ANGLE_BINS as f64
    };
    Some([len / step_m, ang(n1, &u), ang(n2, &u), ang(n1, n2)])
}

/// The key of quantised feature bins.
fn key(b: [usize; 4]) -> u32 {
    let a = ANGLE_BINS as u32;
    ((b[0] as u32 * a + b[1] as u32) * a + b[2] as u32) * a + b[3] as u32
}

/// The bin of a feature component: its floor, clamped to `max - 1` (an angle of exactly pi).
fn bin(x: f64, max: usize) -> usize {
    (x.max(0.0) as usize).min(max - 1)
}

impl PpfModel {
    /// The description of `mesh` (part frame, m) sampled at `step_m`.
    pub fn new(mesh: &Mesh, step_m: f64) -> Self {
        let (lo, hi) = mesh.bounds_m().unwrap_or((Point3::origin(), Point3::origin()));
        let diameter_m = (hi - lo).norm();
        // Dense samples: a barycentric grid per triangle, spacing at most step / 3.
        let spacing = step_m / 3.0;
        let (dense_pts, dense_normals) = surface_samples(mesh, spacing);
        // Feature points: per voxel of `step_m`, the first sample of each normal 30 deg apart;
        // the dense set likewise per voxel of `spacing`.
        let (points, normals) = thin(&dense_pts, &dense_normals, step_m);
        let dense = DenseSurface::of_samples(&dense_pts, &dense_normals, spacing, diameter_m);
        // The pair table.
        let dist_bins = (diameter_m / step_m).ceil() as usize + 2;
        let mut keyed: Vec<(u32, u32, f32)> = Vec::new();
        for (i, (pi, ni)) in points.iter().zip(&normals).enumerate() {
            let r = align_x(ni);
            for (j, (pj, nj)) in points.iter().zip(&normals).enumerate() {
                if i == j || (pj - pi).norm() > diameter_m {
                    continue;
                }
                let Some(f) = feature(pi, ni, pj, nj, step_m) else {
                    continue;
                };
                let alpha = angle_about_x(&(r * (pj - pi))) as f32;
                let k = key([
                    bin(f[0], dist_bins),
                    bin(f[1], ANGLE_BINS),
                    bin(f[2], ANGLE_BINS),
                    bin(f[3], ANGLE_BINS),
                ]);
                keyed.push((k, i as u32, alpha));
            }
        }
        keyed.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.total_cmp(&b.2)));
        let mut table = HashMap::new();
        let mut start = 0;
        while start < keyed.len() {
            let k = keyed[start].0;
            let end = start + keyed[start..].iter().take_while(|e| e.0 == k).count();
            table.insert(k, (start as u32, end as u32));
            start = end;
        }
        let entries = keyed.into_iter().map(|(_, i, a)| (i, a)).collect();
        let centroid_m = dense.centroid_m;
        PpfModel {
            step_m,
            diameter_m,
            points,
            normals,
            table,
            entries,
            dense,
            centroid_m,
        }
    }

    /// Feature points of the description.
    pub fn point_count(&self) -> usize {
        self.points.len()
    }
}

impl CloudModel {
    /// The model set to recognise by point-pair features of `mesh` (part frame, m) sampled at
    /// `step_m` (see the module header).
    pub fn with_ppf(mut self, mesh: &Mesh, step_m: f64) -> Self {
        self.ppf = Some(std::sync::Arc::new(PpfModel::new(mesh, step_m)));
        self
    }

    /// Whether the model recognises by point-pair features.
    pub fn uses_ppf(&self) -> bool {
        self.ppf.is_some()
    }
}

/// The method `method` resolves to for a part: point-pair features of which mesh, or none (the
/// face method). `part` is the part model of a mesh workpiece (`None` for primitives), `model`
/// the face method's model of it; `primitive_mesh` the tessellated primitives (what `ppf` samples
/// for a primitive workpiece). `auto` keeps the face method for primitives and for a mesh part
/// with a planar face the face method matches (`model.faces` not empty), and chooses point-pair
/// features for a mesh part without one.
pub fn ppf_mesh<'a>(
    method: crate::config::RecognitionMethod,
    model: &CloudModel,
    part: Option<&'a crate::part::PartModel>,
    primitive_mesh: Option<&'a Mesh>,
) -> Option<&'a Mesh> {
    use crate::config::RecognitionMethod;
    match method {
        RecognitionMethod::Faces => None,
        RecognitionMethod::Ppf => part.map(|pm| &pm.mesh).or(primitive_mesh),
        RecognitionMethod::Auto => part.filter(|_| model.faces.is_empty()).map(|pm| &pm.mesh),
    }
}

/// A pose voted for, with its votes.
#[derive(Debug, Clone, Copy)]
struct Vote {
    pose: Isometry3<f64>,
    votes: u32,
}

/// Parts recognised by point-pair features in the prepared capture, best first (before the
/// caller's non-maximum suppression).
pub(super) fn detect(cloud: &Cloud, model: &CloudModel, ppf: &PpfModel) -> Vec<CloudDetection> {
    let kept = candidates(cloud, model, ppf);
    let mut out: Vec<CloudDetection> = kept
        .par_iter()
        .filter_map(|(e, d)| settle(cloud, model, ppf, *e, d))
        .filter(|d| outline_is_an_edge(cloud, model, &d.world_from_part))
        .collect();
    out.sort_by(|a, b| b.score.total_cmp(&a.score));
    // Two settled on one part: the better scored stays.
    let near = 0.5 * model.min_size_m();
    let mut kept: Vec<CloudDetection> = Vec::new();
    for d in out {
        let c = d.world_from_part.translation.vector;
        if kept
            .iter()
            .all(|k| (k.world_from_part.translation.vector - c).norm() > near)
        {
            kept.push(d);
        }
    }
    kept
}

/// The verified hypotheses, one per part, uncontested by the other hypotheses, with their
/// evidence, best first ([`detect`] before the turned poses are tried).
fn candidates(cloud: &Cloud, model: &CloudModel, ppf: &PpfModel) -> Vec<(i64, CloudDetection)> {
    decide(model, hypotheses(cloud, model, ppf))
}

/// Every verified hypothesis with its evidence: the clusters voted for, refined by ICP, checked.
fn hypotheses(cloud: &Cloud, model: &CloudModel, ppf: &PpfModel) -> Vec<(i64, CloudDetection)> {
    let (scene_pts, scene_normals) = scene_points(cloud, ppf.step_m);
    if scene_pts.len() < 3 {
        return Vec::new();
    }
    let tree = RTree::bulk_load(
        scene_pts
            .iter()
            .enumerate()
            .map(|(i, p)| Indexed::new([p.x, p.y, p.z], i as u32))
            .collect(),
    );
    let refs: Vec<usize> = (0..scene_pts.len()).step_by(REF_EVERY).collect();
    let votes: Vec<Vote> = refs
        .par_chunks(16)
        .flat_map_iter(|chunk| {
            let mut acc = vec![0u16; ppf.points.len() * ALPHA_BINS];
            chunk
                .iter()
                .filter_map(|&r| vote(ppf, &tree, &scene_pts, &scene_normals, r, &mut acc))
                .collect::<Vec<_>>()
        })
        .collect();
    let clusters = cluster(model, ppf, votes);
    // At most PER_PART clusters per place (most votes first), MAX_HYPOTHESES in all.
    let near = 0.5 * model.min_size_m();
    let mut places: Vec<(Vector3<f64>, usize)> = Vec::new();
    let mut chosen: Vec<Vote> = Vec::new();
    for v in &clusters {
        let c = v.pose.translation.vector;
        match places.iter_mut().find(|p| (p.0 - c).norm() <= near) {
            Some(p) if p.1 >= PER_PART => continue,
            Some(p) => p.1 += 1,
            None => places.push((c, 1)),
        }
        chosen.push(*v);
        if chosen.len() >= MAX_HYPOTHESES {
            break;
        }
    }
    chosen
        .par_iter()
        .filter_map(|v| {
            let pose = icp(cloud, &ppf.dense, &v.pose);
            let to_camera = cloud.origin - pose.translation.vector;
            cloud.check(model, &pose, Some(model.face_nearest_up(&pose, &to_camera)))
        })
        .collect()
}

/// Turns (deg) about each of the part's axes tried against a detection ([`settle`]), refined by
/// ICP (the large ones) or as they are (the small ones, which test a near symmetry about an axis
/// through the surface's centroid).
const BIG_TURNS_DEG: [f64; 3] = [90.0, 180.0, -90.0];
const SMALL_TURNS_DEG: [f64; 4] = [15.0, 45.0, -45.0, -15.0];

/// The detection's pose settled among its turned variants: each of `d`'s pose turned by
/// [`BIG_TURNS_DEG`] (then refined by ICP) and [`SMALL_TURNS_DEG`] about the part's x, y and z
/// axes through the surface's centroid is verified; the best supported wins, and nothing is reported when a
/// different pose (beyond the symmetries) has evidence within [`TIE_MARGIN`] of it: the image
/// does not decide the pose.
fn settle(
    cloud: &Cloud,
    model: &CloudModel,
    ppf: &PpfModel,
    evidence: i64,
    d: &CloudDetection,
) -> Option<CloudDetection> {
    let pose = d.world_from_part;
    let mut all: Vec<(i64, CloudDetection)> = vec![(evidence, d.clone())];
    for axis in [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()] {
        let turns = BIG_TURNS_DEG
            .iter()
            .map(|t| (t, true))
            .chain(SMALL_TURNS_DEG.iter().map(|t| (t, false)));
        for (deg, refine) in turns {
            let c = Translation3::from(ppf.centroid_m);
            let alt = pose * c * UnitQuaternion::from_axis_angle(&axis, deg.to_radians()) * c.inverse();
            if model.same_pose(&pose, &alt) {
                continue;
            }
            let alt = if refine { icp(cloud, &ppf.dense, &alt) } else { alt };
            let to_camera = cloud.origin - alt.translation.vector;
            all.extend(cloud.check(model, &alt, Some(model.face_nearest_up(&alt, &to_camera))));
        }
    }
    let (best_e, best) = all.iter().max_by_key(|a| a.0)?;
    let tied = all
        .iter()
        .any(|(e, o)| *e >= best_e - TIE_MARGIN && !model.same_pose(&best.world_from_part, &o.world_from_part));
    (!tied).then(|| best.clone())
}

/// Whether the image shows the rendered outline of the part at `pose` as an edge: of the pixels
/// just outside the rendered part (4-neighbours of a rendered pixel, not rendered themselves,
/// with a return), more are measured behind the neighbouring rendered depth (beyond
/// [`super::AGREE_TOL_M`]) or in front of it (an occluder) than continue it within the tolerance.
/// A part shape fitted into a larger surface (a can's top into a block's top) continues it.
fn outline_is_an_edge(cloud: &Cloud, model: &CloudModel, pose: &Isometry3<f64>) -> bool {
    let radius = 0.5 * model.half_size_m.norm() * 2.0 + 0.002;
    let centre = pose.translation.vector;
    let Some((u, v, z)) = cloud.camera.project(&Point3::from(centre)) else {
        return false;
    };
    let r_px = (radius / cloud.camera.pixel_size_at_m(z)).ceil() as i64;
    let (cu, cv) = (u as i64 - cloud.u0 as i64, v as i64 - cloud.v0 as i64);
    let (x0, x1) = ((cu - r_px).max(0), (cu + r_px).min(cloud.w as i64 - 1));
    let (y0, y1) = ((cv - r_px).max(0), (cv + r_px).min(cloud.h as i64 - 1));
    if x0 > x1 || y0 > y1 {
        return false;
    }
    let (w, h) = ((x1 - x0 + 1) as usize, (y1 - y0 + 1) as usize);
    let inv = pose.inverse();
    let o = inv * Point3::from(cloud.origin);
    // Rendered depth per window pixel (0: the ray misses the part).
    let mut rendered = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let d = cloud
                .camera
                .pixel_dir(cloud.u0 + x0 as usize + x, cloud.v0 + y0 as usize + y);
            if let Some((t, _)) = super::render::ray_among_graze(model, &o, &(inv.rotation * d), 0..model.pieces.len())
            {
                rendered[y * w + x] = t * d.dot(&cloud.optical);
            }
        }
    }
    let (mut edge, mut continued) = (0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            let inside = rendered[y * w + x];
            if inside <= 0.0 {
                continue;
            }
            for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                    continue;
                }
                let k = ny as usize * w + nx as usize;
                if rendered[k] > 0.0 {
                    continue;
                }
                let i = (y0 as usize + ny as usize) * cloud.w + x0 as usize + nx as usize;
                let measured = cloud.depth[i];
                if measured <= 0.0 {
                    continue;
                }
                if (measured - inside).abs() <= super::AGREE_TOL_M {
                    continued += 1;
                } else {
                    edge += 1;
                }
            }
        }
    }
    edge > continued
}

/// The scene's feature points and normals: foreground pixels thinned to one per voxel.
fn scene_points(cloud: &Cloud, step_m: f64) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let mut seen: std::collections::HashSet<[i64; 3]> = std::collections::HashSet::new();
    let picked: Vec<usize> = (0..cloud.w * cloud.h)
        .filter(|&i| {
            cloud.fg[i] && {
                let v = (cloud.pts[i] / step_m).map(|x| x.floor() as i64);
                seen.insert([v.x, v.y, v.z])
            }
        })
        .collect();
    let fitted: Vec<Option<(Vector3<f64>, Vector3<f64>)>> = picked
        .par_iter()
        .map(|&i| pixel_normal(cloud, i).map(|n| (cloud.pts[i], n)))
        .collect();
    fitted.into_iter().flatten().unzip()
}

/// The least-squares normal of the foreground pixels around pixel `i` (within
/// [`NORMAL_RADIUS_PX`] and [`NORMAL_DEPTH_M`] of its depth), toward the camera.
fn pixel_normal(cloud: &Cloud, i: usize) -> Option<Vector3<f64>> {
    let (mut n, mut s, mut ss) = (0.0, Vector3::zeros(), nalgebra::Matrix3::zeros());
    let c = cloud.pts[i];
    for dv in -NORMAL_RADIUS_PX..=NORMAL_RADIUS_PX {
        for du in -NORMAL_RADIUS_PX..=NORMAL_RADIUS_PX {
            let Some(j) = cloud.neighbour_at(i % cloud.w, i / cloud.w, du, dv) else {
                continue;
            };
            if !cloud.fg[j] || (cloud.depth[j] - cloud.depth[i]).abs() > NORMAL_DEPTH_M {
                continue;
            }
            let r = cloud.pts[j] - c;
            n += 1.0;
            s += r;
            ss += r * r.transpose();
        }
    }
    if n < 6.0 {
        return None;
    }
    let plane = super::plane_from_sums(n, &s, &ss, &c, &cloud.origin);
    Some(plane.normal)
}

/// The votes of reference point `r`: its best (model point, rotation) cell as a pose.
fn vote(
    ppf: &PpfModel,
    tree: &RTree<Indexed>,
    pts: &[Vector3<f64>],
    normals: &[Vector3<f64>],
    r: usize,
    acc: &mut [u16],
) -> Option<Vote> {
    acc.fill(0);
    let (sr, nr) = (pts[r], normals[r]);
    let rs = align_x(&nr);
    let dist_bins = (ppf.diameter_m / ppf.step_m).ceil() as usize + 2;
    let d2 = ppf.diameter_m * ppf.diameter_m;
    for q in tree.locate_within_distance([sr.x, sr.y, sr.z], d2) {
        let i = q.data as usize;
        if i == r {
            continue;
        }
        let Some(f) = feature(&sr, &nr, &pts[i], &normals[i], ppf.step_m) else {
            continue;
        };
        let k = key([
            bin(f[0], dist_bins),
            bin(f[1], ANGLE_BINS),
            bin(f[2], ANGLE_BINS),
            bin(f[3], ANGLE_BINS),
        ]);
        let Some(&(a, b)) = ppf.table.get(&k) else { continue };
        let alpha_s = angle_about_x(&(rs * (pts[i] - sr)));
        for &(m, alpha_m) in &ppf.entries[a as usize..b as usize] {
            let a = (alpha_s - alpha_m as f64).rem_euclid(std::f64::consts::TAU);
            let bin = ((a / std::f64::consts::TAU * ALPHA_BINS as f64) as usize).min(ALPHA_BINS - 1);
            let cell = &mut acc[m as usize * ALPHA_BINS + bin];
            *cell = cell.saturating_add(1);
        }
    }
    let (best, &votes) = acc.iter().enumerate().max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))?;
    if votes < MIN_VOTES {
        return None;
    }
    let (m, b) = (best / ALPHA_BINS, best % ALPHA_BINS);
    let alpha = (b as f64 + 0.5) / ALPHA_BINS as f64 * std::f64::consts::TAU;
    // world_from_part(x) = s_r + R_s^-1 R_x(alpha) R_m (x - m_r).
    let rm = align_x(&ppf.normals[m]);
    let rot = rs.inverse() * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), alpha) * rm;
    let t = sr - rot * ppf.points[m];
    Some(Vote {
        pose: Isometry3::from_parts(Translation3::from(t), rot),
        votes: votes as u32,
    })
}

/// Greedy pose clusters, most votes first; each keeps its first pose and sums its votes. Sorted
/// by votes, most first.
fn cluster(model: &CloudModel, ppf: &PpfModel, mut votes: Vec<Vote>) -> Vec<Vote> {
    votes.sort_by_key(|v| std::cmp::Reverse(v.votes));
    let near_m = 0.1 * ppf.diameter_m;
    let mut out: Vec<Vote> = Vec::new();
    for v in votes {
        let joined = out.iter_mut().find(|c| {
            let (dp, dr) = model.symmetry.pose_error(&c.pose, &v.pose);
            dp <= near_m && dr <= CLUSTER_RAD
        });
        match joined {
            Some(c) => c.votes += v.votes,
            None => out.push(v),
        }
    }
    out.sort_by_key(|v| std::cmp::Reverse(v.votes));
    out
}

/// The verified hypotheses reduced to one per part (most evidence first), dropping a part whose
/// pose a different, nearly as well supported hypothesis contests.
fn decide(model: &CloudModel, mut hyps: Vec<(i64, CloudDetection)>) -> Vec<(i64, CloudDetection)> {
    hyps.sort_by(|a, b| b.0.cmp(&a.0).then(b.1.score.total_cmp(&a.1.score)));
    let near = 0.5 * model.min_size_m();
    // (evidence, detection, contested).
    let mut kept: Vec<(i64, CloudDetection, bool)> = Vec::new();
    for (e, d) in hyps {
        let c = d.world_from_part.translation.vector;
        match kept
            .iter_mut()
            .find(|k| (k.1.world_from_part.translation.vector - c).norm() <= near)
        {
            Some(k) => {
                let (dp, dr) = model.symmetry.pose_error(&k.1.world_from_part, &d.world_from_part);
                if (dp > SAME_POSE_M || dr > SAME_POSE_RAD) && e >= k.0 - TIE_MARGIN {
                    k.2 = true;
                }
            }
            None => kept.push((e, d, false)),
        }
    }
    let mut out: Vec<(i64, CloudDetection)> = kept.into_iter().filter(|k| !k.2).map(|k| (k.0, k.1)).collect();
    out.sort_by(|a, b| b.1.score.total_cmp(&a.1.score));
    out
}

#[cfg(test)]
#[path = "ppf_tests.rs"]
mod tests;
