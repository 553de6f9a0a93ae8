//! Recognition: the two ways a capture becomes detections, and the evaluation of detections
//! against the ground truth.
//!
//! The cell's default recognition works from the capture alone ([`super::cloud`]); the oracle
//! here is the explicit what-if of perfect recognition (`sensor.recognition = "oracle"`). A
//! [`Detection`] carries nothing of the ground truth: which part it is and whether it is right
//! are the evaluation's business ([`evaluate`], [`TruthMatch`]).
//!
//! Ground truth is snapshotted at the trigger ([`TruthAtTrigger`]): which parts the capture
//! showed, how much of each, where every part was at that instant, and the pile's top layer.
//! Nothing is read from the world after the trigger: a part that slides after the exposure is
//! reported where the picture showed it.
//!
//! The oracle model (simplified, stated in docs/model.md, "Recognition"): a part counts as detected when at least
//! `detect_min_visible_fraction` of the pixels it would cover, unoccluded, show it in the
//! capture; its pose at the trigger then comes with Gaussian noise. The ground-truth body per
//! pixel is used only for that visibility count, never to reveal a hidden part. Evaluation
//! ([`evaluate`]) matches each detection with the nearest part in the snapshot (the part's
//! symmetries allowed) and counts it correct within 2 mm and 5 deg; recall is over the top layer,
//! precision over the detections.
//!
//! Units: m, rad, px. Frames: world. Randomness: the `recognition` stream of the run seed,
//! positioned by the capture number.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::Serialize;

use super::capture::gaussian;
use super::cloud::Symmetry;
use super::{Capture, Sensor};
use crate::physics::{PartState, RayHit, Tag, World};
use crate::stats::{median_sorted, percentile_sorted, sorted};

/// Ground truth at a capture's trigger, for evaluation and for the oracle recognition only: the
/// cell's decisions never read it.
#[derive(Debug, Clone)]
pub struct TruthAtTrigger {
    /// The capture's number.
    pub capture_id: u64,
    /// The trigger (s).
    pub t_s: f64,
    /// Every part's `world_from_part` at the trigger.
    pub world_from_part: Vec<Isometry3<f64>>,
    /// Parts free in the pick tray at the trigger.
    pub free: Vec<bool>,
    /// Pixels of the capture showing each part.
    pub visible_px: Vec<usize>,
    /// Pixels each part that shows in the capture would cover with nothing in front of it (0 for
    /// the others). Counted for the oracle recognition only (`None` when the snapshot was taken
    /// for the cloud recognition: a ray per pixel of each part's silhouette, about 7 % of a run
    /// with 60 parts, for nothing).
    pub unoccluded_px: Option<Vec<usize>>,
    /// Parts in the pile's top layer at the trigger ([`top_layer`]).
    pub top_layer: Vec<usize>,
}

impl TruthAtTrigger {
    /// Snapshots `world` as `c` was taken (call it at the trigger), with the unoccluded pixels
    /// the oracle recognition needs.
    pub fn take(world: &World, sensor: &Sensor, c: &Capture) -> Self {
        Self::take_with(world, sensor, c, true)
    }

    /// As [`TruthAtTrigger::take`]; the unoccluded pixels only if `for_oracle`.
    pub fn take_with(world: &World, sensor: &Sensor, c: &Capture, for_oracle: bool) -> Self {
        let n = world.part_count();
        let mut visible_px = vec![0usize; n];
        for t in c.truth.iter().flatten() {
            if let Tag::Part(i) = t {
                visible_px[*i as usize] += 1;
            }
        }
        let free: Vec<bool> = (0..n).map(|i| world.part_state(i) == PartState::Free).collect();
        let unoccluded_px = for_oracle.then(|| {
            (0..n)
                .map(|i| {
                    if free[i] && visible_px[i] > 0 {
                        sensor.unoccluded_pixels(world, i)
                    } else {
                        0
                    }
                })
                .collect()
        });
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
        self.oracle_parts(truth).into_iter().map(|(_, d)| d).collect()
    }

    /// The oracle's detections with the part each is (the oracle alone knows it).
    pub(super) fn oracle_parts(&self, truth: &TruthAtTrigger) -> Vec<(usize, Detection)> {
        let mut rng = crate::rng::stream(self.seed, "recognition");
        rng.set_word_pos(truth.capture_id as u128 * 1_000_000);
        let unoccluded_px = truth
            .unoccluded_px
            .as_ref()
            .expect("a snapshot for the oracle counts the unoccluded pixels");
        let mut out = Vec::new();
        for (i, &seen) in truth.visible_px.iter().enumerate() {
            // Parts in view only: free parts in the pick tray column.
            if !truth.free[i] || seen == 0 {
                continue;
            }
            let full = unoccluded_px[i];
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
            out.push((
                i,
                Detection {
                    world_from_part: pose,
                    visible_fraction: fraction.min(1.0),
                    score: 1.0,
                    face_up: None,
                },
            ));
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

/// A recognised part, as the grasp selector sees it: what the recognition computed, nothing of
/// the ground truth (which part it is, whether it is right: see [`evaluate`]).
#[derive(Debug, Clone, Serialize)]
pub struct Detection {
    /// Estimated `world_from_part`.
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_part: Isometry3<f64>,
    /// Estimated fraction of its unoccluded image the capture showed.
    pub visible_fraction: f64,
    /// Verification score in [0, 1] (the oracle's detections: 1).
    pub score: f64,
    /// The model face recognised on top (cloud recognition; index into [`super::CloudModel::faces`]).
    pub face_up: Option<usize>,
}

/// A detection counts as correct within this position error of a part (m) (the recognition
/// target's definition; the cell's one pose tolerance, [`crate::config::POSE_WITHIN_M`]).
pub const CORRECT_WITHIN_M: f64 = crate::config::POSE_WITHIN_M;
/// ... and within this rotation error, the part's symmetries allowed (rad) (5 deg).
pub const CORRECT_WITHIN_RAD: f64 = crate::config::POSE_WITHIN_RAD;

/// A detection matched with the part it is nearest to at its capture's trigger (evaluation only).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct TruthMatch {
    /// The part.
    pub part: usize,
    /// Distance of the detection's origin from the part's at the trigger (m).
    pub position_error_m: f64,
    /// Rotation from the part to the detection, the least over the part's symmetries (rad).
    pub rotation_error_rad: f64,
    /// Within [`CORRECT_WITHIN_M`] and [`CORRECT_WITHIN_RAD`].
    pub correct: bool,
}

/// Serialises a pose as `{xyz_m, quat_wxyz}`.
pub fn ser_pose<S: serde::Serializer>(p: &Isometry3<f64>, s: S) -> Result<S::Ok, S::Error> {
    let q = p.rotation.quaternion();
    let v = serde_json::json!({"xyz_m": [p.translation.x, p.translation.y, p.translation.z], "quat_wxyz": [q.w, q.i, q.j, q.k]});
    v.serialize(s)
}

/// One capture's recognition against the ground truth at its trigger.
#[derive(Debug, Clone, Serialize)]
pub struct RecognitionReport {
    /// The capture.
    pub capture_id: u64,
    /// Parts free in the pick tray at the trigger.
    pub parts: usize,
    /// Recall, precision and pose errors of this capture's detections.
    #[serde(flatten)]
    pub figures: RecognitionSummary,
    /// Per detection, in order: its nearest part (none if no part is free).
    #[serde(skip)]
    pub matches: Vec<Option<TruthMatch>>,
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

/// Scores detections against the ground truth at their capture's trigger: a detection within 2
/// mm and 5 deg of a free part (the part's symmetries allowed) is correct, matched with the
/// nearest such part (position, then 1 mm per 6 deg of rotation); any other is matched with the
/// free part nearest to it by position, the part it was taken for (a coin found upside down in
/// place is 180 deg off it, not 20 mm off its neighbour).
pub fn evaluate(truth: &TruthAtTrigger, detections: &[Detection], symmetry: &Symmetry) -> RecognitionReport {
    let matches: Vec<Option<TruthMatch>> = detections
        .iter()
        .map(|d| {
            let candidates: Vec<TruthMatch> = (0..truth.free.len())
                .filter(|&i| truth.free[i])
                .map(|i| {
                    let (dp, dr) = symmetry.pose_error(&truth.world_from_part[i], &d.world_from_part);
                    TruthMatch {
                        part: i,
                        position_error_m: dp,
                        rotation_error_rad: dr,
                        correct: dp <= CORRECT_WITHIN_M && dr <= CORRECT_WITHIN_RAD,
                    }
                })
                .collect();
            let cost = |m: &TruthMatch| m.position_error_m + m.rotation_error_rad * 0.01;
            candidates
                .iter()
                .filter(|m| m.correct)
                .min_by(|a, b| cost(a).total_cmp(&cost(b)))
                .or_else(|| {
                    candidates
                        .iter()
                        .min_by(|a, b| a.position_error_m.total_cmp(&b.position_error_m))
                })
                .copied()
        })
        .collect();
    let right: Vec<&TruthMatch> = matches.iter().flatten().filter(|m| m.correct).collect();
    let found: std::collections::BTreeSet<usize> = right.iter().map(|m| m.part).collect();
    let totals = RecognitionTotals {
        captures: 1,
        top_layer: truth.top_layer.len(),
        top_layer_found: truth.top_layer.iter().filter(|i| found.contains(i)).count(),
        detected: detections.len(),
        correct: right.len(),
        position_errors_m: right.iter().map(|m| m.position_error_m).collect(),
        rotation_errors_rad: right.iter().map(|m| m.rotation_error_rad).collect(),
    };
    RecognitionReport {
        capture_id: truth.capture_id,
        parts: truth.free.iter().filter(|f| **f).count(),
        figures: totals.summary(),
        matches,
    }
}

/// Recognition over many captures: recall and precision pooled over the captures, pose errors of
/// every correct detection.
#[derive(Debug, Clone, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct RecognitionTotals {
    /// Captures evaluated.
    pub captures: usize,
    /// Top-layer parts, summed over the captures.
    pub top_layer: usize,
    /// Of those, found by a correct detection.
    pub top_layer_found: usize,
    /// Detections.
    pub detected: usize,
    /// Correct detections.
    pub correct: usize,
    /// Position errors of the correct detections (m).
    pub position_errors_m: Vec<f64>,
    /// Rotation errors of the correct detections (rad).
    pub rotation_errors_rad: Vec<f64>,
}

impl RecognitionTotals {
    /// Adds a capture's report.
    pub fn add(&mut self, r: &RecognitionReport) {
        let f = &r.figures;
        self.captures += 1;
        self.top_layer += f.top_layer;
        self.top_layer_found += f.top_layer_found;
        self.detected += f.detected;
        self.correct += f.correct;
        for m in r.matches.iter().flatten().filter(|m| m.correct) {
            self.position_errors_m.push(m.position_error_m);
            self.rotation_errors_rad.push(m.rotation_error_rad);
        }
    }

    /// Adds another total (captures of another run).
    pub fn merge(&mut self, o: &RecognitionTotals) {
        self.captures += o.captures;
        self.top_layer += o.top_layer;
        self.top_layer_found += o.top_layer_found;
        self.detected += o.detected;
        self.correct += o.correct;
        self.position_errors_m.extend_from_slice(&o.position_errors_m);
        self.rotation_errors_rad.extend_from_slice(&o.rotation_errors_rad);
    }

    /// The summary figures.
    pub fn summary(&self) -> RecognitionSummary {
        let ratio = |a: usize, b: usize| if b == 0 { f64::NAN } else { a as f64 / b as f64 };
        let pos = sorted(&self.position_errors_m);
        let rot = sorted(&self.rotation_errors_rad);
        RecognitionSummary {
            captures: self.captures,
            top_layer: self.top_layer,
            top_layer_found: self.top_layer_found,
            detected: self.detected,
            correct: self.correct,
            recall: ratio(self.top_layer_found, self.top_layer),
            precision: ratio(self.correct, self.detected),
            position_error_mm: [median_sorted(&pos) * 1e3, percentile_sorted(&pos, 0.95) * 1e3],
            rotation_error_deg: [
                median_sorted(&rot).to_degrees(),
                percentile_sorted(&rot, 0.95).to_degrees(),
            ],
        }
    }
}

/// Recognition figures over many captures (what `summary.json` and the batch table report).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RecognitionSummary {
    /// Captures evaluated.
    pub captures: usize,
    /// Top-layer parts, summed over the captures.
    pub top_layer: usize,
    /// Of those, found by a correct detection.
    pub top_layer_found: usize,
    /// Detections.
    pub detected: usize,
    /// Correct detections.
    pub correct: usize,
    /// top_layer_found / top_layer (NaN for an empty top layer).
    pub recall: f64,
    /// correct / detected (NaN without detections).
    pub precision: f64,
    /// Position error of the correct detections, median and p95 (mm).
    pub position_error_mm: [f64; 2],
    /// Rotation error of the correct detections, median and p95 (deg).
    pub rotation_error_deg: [f64; 2],
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    /// A coin-like part found upside down where it lies, its neighbour 20 mm away lying the
    /// detection's way up: the wrong detection is matched with the part it lies on (0 mm, 180
    /// deg), not with the neighbour; a detection within 2 mm and 5 deg of the neighbour is
    /// matched with it and correct. Control: the cost the matching takes among correct parts
    /// (1 mm per 6 deg) puts the neighbour nearer than the part under the wrong detection.
    #[test]
    fn a_wrong_detection_is_matched_with_the_part_it_was_taken_for() {
        let up = UnitQuaternion::identity();
        let flipped = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let at = |x: f64, r: UnitQuaternion<f64>| Isometry3::from_parts(Translation3::new(x, 0.0, 0.01), r);
        let truth = TruthAtTrigger {
            capture_id: 1,
            t_s: 0.0,
            world_from_part: vec![at(0.0, flipped), at(0.02, up)],
            free: vec![true, true],
            visible_px: vec![400, 400],
            unoccluded_px: None,
            top_layer: vec![0, 1],
        };
        let detection = |pose| Detection {
            world_from_part: pose,
            visible_fraction: 1.0,
            score: 1.0,
            face_up: Some(0),
        };
        let symmetry = Symmetry::of_orders([1, 1, 1]);
        let report = evaluate(
            &truth,
            &[detection(at(0.0002, up)), detection(at(0.0205, up))],
            &symmetry,
        );
        let wrong = report.matches[0].expect("a match");
        assert_eq!(wrong.part, 0);
        assert!(!wrong.correct && wrong.position_error_m < 0.001);
        assert!((wrong.rotation_error_rad - std::f64::consts::PI).abs() < 1e-9);
        let right = report.matches[1].expect("a match");
        assert_eq!(right.part, 1);
        assert!(right.correct);
        assert_eq!(report.figures.precision, 0.5);
        // The control: by the correct parts' cost, the neighbour is the nearer of the two.
        let cost = |part: usize| {
            let (dp, dr) = symmetry.pose_error(&truth.world_from_part[part], &at(0.0002, up));
            dp + dr * 0.01
        };
        assert!(cost(1) < cost(0), "{} against {}", cost(1), cost(0));
    }
}
