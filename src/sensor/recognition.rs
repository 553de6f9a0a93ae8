//! Recognition: which parts a capture shows and where, and the evaluation of that against the
//! ground truth.
//!
//! Ground truth is snapshotted at the trigger ([`TruthAtTrigger`]): which parts the capture
//! showed, how much of each, where every part was at that instant, and the pile's top layer.
//! Nothing is read from the world after the trigger: a part that slides after the exposure is
//! reported where the picture showed it.
//!
//! The oracle model (simplified, stated in the README): a part counts as detected when at least
//! `detect_min_visible_fraction` of the pixels it would cover, unoccluded, show it in the
//! capture; its pose at the trigger then comes with Gaussian noise. The ground-truth body per
//! pixel is used only for that visibility count, never to reveal a hidden part. Evaluation
//! ([`evaluate`]) compares detections with the snapshot: the top layer, recall, pose errors.
//!
//! Units: m, rad, px. Frames: world. Randomness: the `recognition` stream of the run seed,
//! positioned by the capture number.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::Serialize;

use super::capture::gaussian;
use super::{Capture, Sensor};
use crate::physics::{PartState, RayHit, Tag, World};

/// Ground truth at a capture's trigger, for evaluation and for the oracle recognition only: the
/// cell's decisions never read it.
#[derive(Debug, Clone)]
pub struct TruthAtTrigger {
    /// The capture's number.
    pub capture_id: u64,
    /// The trigger [s].
    pub t_s: f64,
    /// Every part's `world_from_part` at the trigger.
    pub world_from_part: Vec<Isometry3<f64>>,
    /// Parts free in the pick tray at the trigger.
    pub free: Vec<bool>,
    /// Pixels of the capture showing each part.
    pub visible_px: Vec<usize>,
    /// Pixels each part that shows in the capture would cover with nothing in front of it (0 for
    /// the others).
    pub unoccluded_px: Vec<usize>,
    /// Parts in the pile's top layer at the trigger ([`top_layer`]).
    pub top_layer: Vec<usize>,
}

impl TruthAtTrigger {
    /// Snapshots `world` as `c` was taken (call it at the trigger).
    pub fn take(world: &World, sensor: &Sensor, c: &Capture) -> Self {
        let n = world.part_count();
        let mut visible_px = vec![0usize; n];
        for t in c.truth.iter().flatten() {
            if let Tag::Part(i) = t {
                visible_px[*i as usize] += 1;
            }
        }
        let free: Vec<bool> = (0..n).map(|i| world.part_state(i) == PartState::Free).collect();
        let unoccluded_px = (0..n)
            .map(|i| {
                if free[i] && visible_px[i] > 0 {
                    sensor.unoccluded_pixels(world, i)
                } else {
                    0
                }
            })
            .collect();
        TruthAtTrigger {
            capture_id: c.id,
            t_s: c.trigger_s,
            world_from_part: (0..n).map(|i| world.part_pose(i)).collect(),
            free,
            visible_px,
            unoccluded_px,
            top_layer: top_layer(world),
        }
    }
}

impl Sensor {
    /// The oracle recognition: the parts the capture showed enough of, at their poses at the
    /// trigger with Gaussian noise (see the module header). Reads the snapshot, not the world.
    pub fn recognize_oracle(&self, truth: &TruthAtTrigger) -> Vec<Detection> {
        let mut rng = crate::rng::stream(self.seed, "recognition");
        rng.set_word_pos(truth.capture_id as u128 * 1_000_000);
        let mut out = Vec::new();
        for (i, &seen) in truth.visible_px.iter().enumerate() {
            // Parts in view only: free parts in the pick tray column.
            if !truth.free[i] || seen == 0 {
                continue;
            }
            let full = truth.unoccluded_px[i];
            if full == 0 {
                continue;
            }
            let fraction = seen as f64 / full as f64;
            if fraction < self.detect_min_visible_fraction {
                continue;
            }
            let truth = truth.world_from_part[i];
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
    pub(super) fn unoccluded_pixels(&self, world: &World, i: usize) -> usize {
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

/// Scores detections against the ground truth at their capture's trigger.
pub fn evaluate(truth: &TruthAtTrigger, detections: &[Detection]) -> RecognitionReport {
    let top = &truth.top_layer;
    let found: std::collections::BTreeSet<usize> = detections.iter().map(|d| d.truth_part).collect();
    let top_found = top.iter().filter(|i| found.contains(i)).count();
    let (mut sp, mut mp, mut sr, mut mr) = (0.0, 0.0f64, 0.0, 0.0f64);
    for d in detections {
        let truth = truth.world_from_part[d.truth_part];
        let ep = (truth.translation.vector - d.world_from_part.translation.vector).norm();
        let er = truth.rotation.angle_to(&d.world_from_part.rotation);
        sp += ep;
        sr += er;
        mp = mp.max(ep);
        mr = mr.max(er);
    }
    let n = detections.len().max(1) as f64;
    RecognitionReport {
        parts: truth.free.iter().filter(|f| **f).count(),
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
