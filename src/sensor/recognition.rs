//! Recognition: which parts a capture shows and where, and the evaluation of that against the
//! ground truth.
//!
//! Model (simplified, stated in the README): a part counts as detected when at least
//! `detect_min_visible_fraction` of the pixels it would cover, unoccluded, show it in the
//! capture; its pose then comes with Gaussian noise. The ground-truth body per pixel is used only
//! for that visibility count, never to reveal a hidden part. Evaluation ([`evaluate`]) compares
//! detections with the world: the pile's top layer, recall, pose errors.
//!
//! Units: m, rad, px. Frames: world. Randomness: the `recognition` stream of the run seed,
//! positioned by the capture number.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::Serialize;

use super::capture::gaussian;
use super::{Capture, Sensor};
use crate::physics::{PartState, RayHit, Tag, World};

impl Sensor {
    /// Recognition on a capture: detected parts with noisy poses (see the module header).
    pub fn recognize(&self, world: &World, c: &Capture) -> Vec<Detection> {
        let mut visible = vec![0usize; world.part_count()];
        for t in c.truth.iter().flatten() {
            if let Tag::Part(i) = t {
                visible[*i as usize] += 1;
            }
        }
        let mut rng = crate::rng::stream(self.seed, "recognition");
        rng.set_word_pos(c.id as u128 * 1_000_000);
        let mut out = Vec::new();
        for (i, &seen) in visible.iter().enumerate() {
            // Parts in view only: free parts in the pick tray column.
            if world.part_state(i) != PartState::Free || seen == 0 {
                continue;
            }
            let full = self.unoccluded_pixels(world, i);
            if full == 0 {
                continue;
            }
            let fraction = seen as f64 / full as f64;
            if fraction < self.detect_min_visible_fraction {
                continue;
            }
            let truth = world.part_pose(i);
            let dp = Vector3::new(gaussian(&mut rng), gaussian(&mut rng), gaussian(&mut rng)) * self.pose_noise_m;
            let dr = Vector3::new(gaussian(&mut rng), gaussian(&mut rng), gaussian(&mut rng)) * self.pose_noise_rad;
            let pose = Isometry3::from_parts(
                (truth.translation.vector + dp).into(),
                UnitQuaternion::from_scaled_axis(dr) * truth.rotation,
            );
            out.push(Detection {
                world_from_part: pose,
                visible_fraction: fraction.min(1.0),
                truth_part: i,
            });
        }
        out
    }

    /// Pixels part `i` would cover with nothing in front of it (rays against it alone).
    fn unoccluded_pixels(&self, world: &World, i: usize) -> usize {
        let cam = &self.camera;
        let (lo, hi) = world.part_view_box_m(i);
        let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for k in 0..8 {
            let pick = |bit: usize, lo: f64, hi: f64| if k & bit == 0 { lo } else { hi };
            let p = Point3::new(pick(1, lo.x, hi.x), pick(2, lo.y, hi.y), pick(4, lo.z, hi.z));
            if let Some((u, v, _)) = cam.project(&p) {
                u0 = u0.min(u);
                v0 = v0.min(v);
                u1 = u1.max(u);
                v1 = v1.max(v);
            }
        }
        if u0 > u1 {
            return 0;
        }
        let clamp = |x: f64, n: usize| (x.floor().max(0.0) as usize).min(n.saturating_sub(1));
        let origin = cam.world_from_camera.translation.vector;
        let mut n = 0;
        for v in clamp(v0, cam.height_px)..=clamp(v1, cam.height_px) {
            for u in clamp(u0, cam.width_px)..=clamp(u1, cam.width_px) {
                if world.part_meets_ray(i, &origin, &cam.pixel_dir(u, v), cam.max_range_m) {
                    n += 1;
                }
            }
        }
        n
    }
}

/// A recognised part.
#[derive(Debug, Clone, Serialize)]
pub struct Detection {
    /// Estimated `world_from_part` (truth plus recognition noise).
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_part: Isometry3<f64>,
    /// Fraction of its unoccluded image the capture showed.
    pub visible_fraction: f64,
    /// Which part this is, for evaluation only: the grasp selector never reads it.
    pub truth_part: usize,
}

/// Serialises a pose as `{xyz_m, quat_wxyz}`.
pub fn ser_pose<S: serde::Serializer>(p: &Isometry3<f64>, s: S) -> Result<S::Ok, S::Error> {
    let q = p.rotation.quaternion();
    let v = serde_json::json!({"xyz_m": [p.translation.x, p.translation.y, p.translation.z], "quat_wxyz": [q.w, q.i, q.j, q.k]});
    v.serialize(s)
}

/// Evaluation against ground truth: which parts are in the pile's top layer, recall, pose error.
#[derive(Debug, Clone, Serialize)]
pub struct RecognitionReport {
    /// Parts in the pick tray.
    pub parts: usize,
    /// Parts in the top layer (at least two thirds of their footprint uncovered from straight above).
    pub top_layer: usize,
    /// Top-layer parts detected.
    pub top_layer_detected: usize,
    /// Detections in all.
    pub detected: usize,
    /// top_layer_detected / top_layer.
    pub top_layer_recall: f64,
    /// Mean and max position error of detections [m].
    pub position_error_m: (f64, f64),
    /// Mean and max rotation error of detections [rad].
    pub rotation_error_rad: (f64, f64),
}

/// Parts whose footprint is at least two thirds uncovered seen from straight above (arm ignored):
/// vertical rays over a 7 x 7 grid of the part's box, counted where the part alone would be hit.
pub fn top_layer(world: &World) -> Vec<usize> {
    let skip = |t: Tag| t.is_robot();
    let down = Vector3::new(0.0, 0.0, -1.0);
    world
        .parts_in_pick_tray()
        .into_iter()
        .filter(|&i| {
            let (lo, hi) = world.part_view_box_m(i);
            let top = hi.z + 0.5;
            let (mut covered, mut exposed) = (0, 0);
            for a in 0..7 {
                for b in 0..7 {
                    let x = lo.x + (hi.x - lo.x) * (a as f64 + 0.5) / 7.0;
                    let y = lo.y + (hi.y - lo.y) * (b as f64 + 0.5) / 7.0;
                    let origin = Vector3::new(x, y, top);
                    if !world.part_meets_ray(i, &origin, &down, 1.0) {
                        continue;
                    }
                    covered += 1;
                    if let Some(RayHit { tag: Tag::Part(j), .. }) = world.cast_ray(&origin, &-Vector3::z(), 1.0, &skip)
                        && j as usize == i
                    {
                        exposed += 1;
                    }
                }
            }
            covered > 0 && 3 * exposed >= 2 * covered
        })
        .collect()
}

/// Scores detections against the world's ground truth.
pub fn evaluate(world: &World, detections: &[Detection]) -> RecognitionReport {
    let top = top_layer(world);
    let found: std::collections::BTreeSet<usize> = detections.iter().map(|d| d.truth_part).collect();
    let top_found = top.iter().filter(|i| found.contains(i)).count();
    let (mut sp, mut mp, mut sr, mut mr) = (0.0, 0.0f64, 0.0, 0.0f64);
    for d in detections {
        let truth = world.part_pose(d.truth_part);
        let ep = (truth.translation.vector - d.world_from_part.translation.vector).norm();
        let er = truth.rotation.angle_to(&d.world_from_part.rotation);
        sp += ep;
        sr += er;
        mp = mp.max(ep);
        mr = mr.max(er);
    }
    let n = detections.len().max(1) as f64;
    RecognitionReport {
        parts: world.parts_in_pick_tray().len(),
        top_layer: top.len(),
        top_layer_detected: top_found,
        detected: detections.len(),
        top_layer_recall: if top.is_empty() {
            1.0
        } else {
            top_found as f64 / top.len() as f64
        },
        position_error_m: (sp / n, mp),
        rotation_error_rad: (sr / n, mr),
    }
}
