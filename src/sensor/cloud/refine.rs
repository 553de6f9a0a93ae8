//! A flat-face detection refined after it wins its patch: (1) settled onto the tray floor when
//! it lies there in one of the part's resting poses, as far as the patch's points can tell;
//! (1b) otherwise, where the patch leaves its tilt open, tilted to the rendering the image
//! supports best; (2) turned about its face's normal, within the yaws its silhouette allows, to
//! the yaw whose rendering the image supports best.
//!
//! (1) Settling. A face of 60-90 pixels under 0.3 mm of depth noise fixes its plane to about a
//! degree (a DIP-8's top face: tilt error median 1.4 degrees), while four in five of a settled
//! pile's top layer lie flat on the floor. A detection whose support normal (of the resting pose
//! nearest its estimate) is within [`TILT_MAX_RAD`] of down and whose lowest point is within
//! [`GAP_MAX_M`] of the floor is turned about its measured face centre until that normal points
//! straight down, then put on the floor. It keeps that pose when the patch's interior points
//! (those whose 8 neighbours are in the patch, and within [`BAND_M`] of their least-squares
//! plane) cannot tell the settled face's plane from their own:
//! with `ssr_fit` their squared distances to their own plane (n - 3 degrees of freedom) and
//! `ssr_settled` to the settled face's (which fixes tilt and height: 3 more), the F statistic
//! `((ssr_settled - ssr_fit) / 3) / (ssr_fit / (n - 3))` is at most [`F_MAX`]. A DIP-8 resting
//! 3 degrees tilted against a neighbour passes across its 6.35 mm width, 5 degrees do not; a
//! part on another part's lead (a 1 mm step) does not. The patch's rim is left out: toward the
//! tray's corners it holds the upper rim of the side walls facing the optical axis, up to a
//! millimetre below the face and all on one side, which tilts the points' own plane. Taking
//! them for noise, the test refused 57 of 522 DIP-8s lying flat on the floor (`sense` seeds
//! 1-12; the median F was 1.31, where F(3, n) gives 0.8); on the interior the median is 0.83
//! and 7 are refused. A patch whose interior is too small to stand for it
//! ([`super::interior_suffices`]) is tested on all its points. Where the face's plane fails
//! the test and the face is stepped (the model's `stepped`), the settled pose's rendered
//! surface is tried in its place (each point's distance from it along its pixel's ray, across
//! the plane; a pose that shows nothing at over a tenth of the points fails): a patch over two
//! of the part's faces whose step one plane's band takes in (a coin cell's cap, 0.3 mm proud of
//! its can's rim) fits no single face's plane, and would otherwise settle only the wrong side
//! up, the one whose flat top the plane stands for.
//!
//! (1b) Tilt, for a CAD part's detection that is not settled: a patch a few pixels wide (a
//! DIP-8's 3.3 mm side) leaves its plane's tilt about its long axis open by several degrees
//! ([`tilt_standard_error`]); where that standard error is at least [`TILT_OPEN_RAD`], the
//! hypothesis is rendered at tilts about that axis (through the face centre) and verified at
//! every pixel, and takes the mean of the tilts of greatest evidence unless its own is one.
//!
//! (2) Yaw, for a face fitted by its true outline (`outline`: one with features beside it, such
//! as a DIP's legs). The silhouette fit takes the middle of the yaws its pixel centres allow,
//! a span of up to the cell's `max_yaw_ambiguity_deg` (12 by default) for a 9 mm face on
//! 0.85 mm pixels: the estimate is off by up to half of it. That span is measured turning about
//! the fitted centre; a turn with a shift can stay consistent much farther, so the scan covers
//! at least [`YAW_SCAN_MIN_RAD`]. The hypothesis is rendered at yaws
//! [`YAW_STEP_RAD`] apart across that span (about the face normal, through the face centre) and
//! verified at every pixel; the estimate is the mean of the yaws of greatest evidence, which
//! counts the pixels on the features beside the face (a DIP's upturned legs) that its outline
//! leaves out. A face that is its rectangle keeps the silhouette's yaw: its outline holds all
//! there is to see, and the scan would only add the neighbours at the same height that a turned
//! corner reaches (on F, over `sense` seeds 1-4: 3 wrong detections where there were none).
//!
//! What it uses: the floor plane is the cell's (the tray's calibrated geometry, as background
//! removal uses it), the resting poses are the part model's (its convex hull and centre of mass),
//! and the rest is the capture. Nothing here comes from the simulated world.
//!
//! Units: m, rad. Frames: world (`world_from_part`); the resting poses' support normals in the
//! part frame.

use nalgebra::{Isometry3, Matrix3, Translation3, Unit, UnitQuaternion, Vector3};

use super::{CloudDetection, CloudModel, Patch, Plane, plane_from_sums};

/// A detection whose support normal is within this of the floor's down direction is tried
/// settled (rad).
pub const TILT_MAX_RAD: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// ... and whose lowest point is within this of the floor (m).
pub const GAP_MAX_M: f64 = 0.002;
/// Patch points within this of their least-squares plane are the settling test's (m): 3 sigma
/// of the depth noise.
pub const BAND_M: f64 = 0.001;
/// The settled plane is kept when its extra squared residual per constrained degree of freedom
/// is at most this many times the fit's residual variance: the 99th percentile of F(3, infinity)
/// (3.78), rounded up.
pub const F_MAX: f64 = 3.8;
/// A detection not settled whose patch leaves its plane's tilt open by at least this standard
/// error (rad) is tilted to the rendering the image supports best: on `sense` seeds 1-12 of the
/// DIP-8, its patches on a 3.3 mm side (about 4 pixels wide, 2.5-5.5 degrees) were 5-10 degrees
/// off in 5 of 6 cases, its top faces (6.35 mm, 1-2 degrees) are pinned by their own points and
/// the scan only made them worse (7 new errors at every detection). CAD parts (mesh models)
/// only: on the built-in parts over `batch` seeds 1-3 it changed only E, 2 more wrong
/// detections of 2798.
pub const TILT_OPEN_RAD: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// The depth noise along a plane's normal the tilt's standard error assumes (m): [`super::AGREE_TOL_M`]
/// is 3 sigma of it.
pub const DEPTH_NOISE_M: f64 = super::AGREE_TOL_M / 3.0;
/// The tilt scan's reach either way (rad).
pub const TILT_SCAN_RAD: f64 = 8.0 * std::f64::consts::PI / 180.0;
/// The tilt scan's step (rad).
pub const TILT_STEP_RAD: f64 = std::f64::consts::PI / 180.0;
/// The yaw scan's step (rad).
pub const YAW_STEP_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// An outline-fitted face's yaw scan spans at least this (rad): the silhouette's span is
/// measured turning about a fixed centre, which understates what the silhouette allows (a DIP-8's
/// back face: 1.75 degrees about its centre, 11 with the centre re-solved at each yaw).
pub const YAW_SCAN_MIN_RAD: f64 = 8.0 * std::f64::consts::PI / 180.0;

impl super::Cloud<'_> {
    /// `d` (the winner of `patch`, whose least-squares plane is `plane`) settled and turned to
    /// its best-supported yaw, each step kept only if it verifies; `d` itself for a part on its
    /// curved side or a model without resting poses.
    pub(super) fn refine(&self, model: &CloudModel, patch: &Patch, plane: &Plane, d: CloudDetection) -> CloudDetection {
        if d.curved_side_up || model.resting.is_empty() {
            return d;
        }
        let span = yaw_scan_span_rad(model, d.face_up, d.yaw_span_rad);
        let settled = match self
            .settled(model, patch, plane, &d)
            .and_then(|pose| self.check(model, &pose, Some(d.face_up)))
        {
            Some((_, s)) => s,
            None if model.mesh.is_none() => d,
            None => match self.tilt_open(patch, plane) {
                Some(long) => self
                    .best_tilt(model, &d, &long)
                    .and_then(|pose| self.check(model, &pose, Some(d.face_up)))
                    .map_or(d, |(_, t)| t),
                None => d,
            },
        };
        match self.best_yaw(model, &settled.world_from_part, settled.face_up, span) {
            Some(turned) => self
                .check(model, &turned, Some(settled.face_up))
                .map_or(settled, |(_, t)| t),
            None => settled,
        }
    }

    /// `d`'s pose settled onto the floor, if it is near a resting pose on the floor and the
    /// patch's points allow it.
    pub(super) fn settled(
        &self,
        model: &CloudModel,
        patch: &Patch,
        plane: &Plane,
        d: &CloudDetection,
    ) -> Option<Isometry3<f64>> {
        let pose = d.world_from_part;
        let up = self.floor.normal;
        let down_in_part = pose.rotation.inverse() * -up;
        let rest = model
            .resting
            .iter()
            .max_by(|a, b| a.dot(&down_in_part).total_cmp(&b.dot(&down_in_part)))?;
        let floor_h = self.floor.point.dot(&up);
        if rest.dot(&down_in_part) < TILT_MAX_RAD.cos() || model.lowest_along(&pose, &up) - floor_h > GAP_MAX_M {
            return None;
        }
        // Turned about the measured face's centre until the support normal points down, then
        // lowered (or raised) onto the floor.
        let turn = UnitQuaternion::rotation_between(&(pose.rotation * rest), &-up)?;
        let turned = turn_about(&pose, &plane.point, &turn);
        let lift = floor_h - model.lowest_along(&turned, &up);
        let settled = Isometry3::from_parts(
            Translation3::from(turned.translation.vector + up * lift),
            turned.rotation,
        );
        let face = &model.faces[d.face_up];
        let settled_plane = Plane {
            point: settled.translation.vector + settled.rotation * face.center,
            normal: settled.rotation * face.normal,
        };
        let on_plane = |_: usize, p: &Vector3<f64>| Some(settled_plane.normal.dot(&(p - settled_plane.point)));
        if self.points_agree(patch, plane, on_plane) {
            return Some(settled);
        }
        if !model.is_stepped(d.face_up) {
            return None;
        }
        // A patch over two of the part's faces that its plane's band takes as one (a coin
        // cell's cap and the can's rim 0.3 mm below it): the settled pose's rendered surface,
        // not its face's plane, against the points.
        let mut predicted = std::collections::HashMap::new();
        self.render(model, &settled, 1, |i, depth, _| {
            predicted.insert(i, depth);
        })?;
        let on_surface = |i: usize, p: &Vector3<f64>| {
            let z = (p - self.origin).dot(&self.optical);
            // Along the pixel's ray to the rendered depth, measured across the patch's plane.
            Some(plane.normal.dot(&(p - self.origin)) * (1.0 - predicted.get(&i)? / z))
        };
        self.points_agree(patch, plane, on_surface).then_some(settled)
    }

    /// Whether the patch's points near `fitted` fit a candidate surface as well as their own
    /// plane, up to the noise (the F test of the module header). `off(pixel, point)` is the
    /// point's distance from the candidate across the plane (m), `None` where the candidate
    /// shows nothing at that pixel: a candidate that leaves over a tenth of the points so does
    /// not fit.
    pub(super) fn points_agree(
        &self,
        patch: &Patch,
        fitted: &Plane,
        off: impl Fn(usize, &Vector3<f64>) -> Option<f64>,
    ) -> bool {
        // The patch's interior: the pixels whose 8 neighbours are all in it.
        let mut member = patch.pixels.clone();
        member.sort_unstable();
        let interior = |i: usize| self.is_interior(&member, i);
        let in_band = |keep: &dyn Fn(usize) -> bool| -> Vec<(usize, Vector3<f64>)> {
            patch
                .pixels
                .iter()
                .filter(|&&i| keep(i))
                .map(|&i| (i, self.pts[i]))
                .filter(|(_, p)| fitted.normal.dot(&(p - fitted.point)).abs() <= BAND_M)
                .collect()
        };
        let mut pts = in_band(&interior);
        if !super::interior_suffices(pts.len(), patch) {
            pts = in_band(&|_| true);
        }
        if pts.len() < super::MIN_PATCH_PX {
            return false;
        }
        let origin = pts[0].1;
        let (mut s, mut ss) = (Vector3::zeros(), Matrix3::zeros());
        for (_, p) in &pts {
            let r = p - origin;
            s += r;
            ss += r * r.transpose();
        }
        let n = pts.len() as f64;
        let own = plane_from_sums(n, &s, &ss, &origin, &self.origin);
        let ssr_fit: f64 = pts.iter().map(|(_, p)| own.normal.dot(&(p - own.point)).powi(2)).sum();
        let (shown, ssr_shown) = pts
            .iter()
            .filter_map(|(i, p)| off(*i, p))
            .fold((0usize, 0.0), |(k, ssr), d| (k + 1, ssr + d * d));
        if 10 * shown < 9 * pts.len() {
            return false;
        }
        let ssr_candidate = ssr_shown * n / shown as f64;
        let variance = ssr_fit / (n - 3.0);
        variance > 0.0 && (ssr_candidate - ssr_fit) / 3.0 <= F_MAX * variance
    }

    /// `pose` (face `face_up` up) turned about its face's normal (through the face centre) to
    /// the mean of the yaws, within the silhouette's span `span_rad` centred on it, that verify
    /// with the most evidence at every pixel; `None` (no scan) for a face fitted as its
    /// rectangle or a yaw the silhouette pins to within a step either way.
    pub(super) fn best_yaw(
        &self,
        model: &CloudModel,
        pose: &Isometry3<f64>,
        face_up: usize,
        span_rad: f64,
    ) -> Option<Isometry3<f64>> {
        let face = &model.faces[face_up];
        let pivot = pose.translation.vector + pose.rotation * face.center;
        let axis = Unit::new_normalize(pose.rotation * face.normal);
        let steps = (0.5 * span_rad / YAW_STEP_RAD).floor() as i64;
        if steps == 0 {
            return None;
        }
        let best = self.best_turns(model, pose, &pivot, &axis, YAW_STEP_RAD, steps);
        if best.is_empty() {
            return None;
        }
        let yaw = best.iter().sum::<i64>() as f64 / best.len() as f64 * YAW_STEP_RAD;
        Some(turn_about(pose, &pivot, &UnitQuaternion::from_axis_angle(&axis, yaw)))
    }
}

impl super::Cloud<'_> {
    /// The patch's long in-plane axis (world, unit), if the patch leaves its plane's tilt about
    /// that axis open: a standard error ([`tilt_standard_error`]) of at least [`TILT_OPEN_RAD`].
    fn tilt_open(&self, patch: &Patch, plane: &Plane) -> Option<Vector3<f64>> {
        let (e1, e2) = plane.basis();
        let in_plane: Vec<[f64; 2]> = patch
            .pixels
            .iter()
            .map(|&i| {
                let r = self.pts[i] - plane.point;
                [r.dot(&e1), r.dot(&e2)]
            })
            .collect();
        let (sigma_rad, long) = tilt_standard_error(&in_plane, DEPTH_NOISE_M)?;
        (sigma_rad >= TILT_OPEN_RAD).then(|| (e1 * long[0] + e2 * long[1]).normalize())
    }

    /// `d`'s pose tilted about `long` (world, unit; through its face's centre) to the mean of
    /// the tilts, [`TILT_STEP_RAD`] apart within [`TILT_SCAN_RAD`] either way, that verify with
    /// the most evidence at every pixel; `None` (the measured tilt kept) when the measured tilt
    /// is among them.
    fn best_tilt(&self, model: &CloudModel, d: &CloudDetection, long: &Vector3<f64>) -> Option<Isometry3<f64>> {
        let pose = d.world_from_part;
        let face = &model.faces[d.face_up];
        let pivot = pose.translation.vector + pose.rotation * face.center;
        let axis = Unit::new_normalize(*long);
        let steps = (TILT_SCAN_RAD / TILT_STEP_RAD).round() as i64;
        let best = self.best_turns(model, &pose, &pivot, &axis, TILT_STEP_RAD, steps);
        if best.is_empty() || best.contains(&0) {
            return None;
        }
        let tilt_rad = best.iter().sum::<i64>() as f64 / best.len() as f64 * TILT_STEP_RAD;
        Some(turn_about(
            &pose,
            &pivot,
            &UnitQuaternion::from_axis_angle(&axis, tilt_rad),
        ))
    }

    /// The steps k (`-steps..=steps`) whose turn of `pose` by `k * step_rad` about `axis`
    /// through `pivot` verifies with the most evidence at every pixel; empty when none
    /// verifies. The yaw and the tilt scans both read it.
    fn best_turns(
        &self,
        model: &CloudModel,
        pose: &Isometry3<f64>,
        pivot: &Vector3<f64>,
        axis: &Unit<Vector3<f64>>,
        step_rad: f64,
        steps: i64,
    ) -> Vec<i64> {
        let evidence: Vec<(i64, i64)> = (-steps..=steps)
            .filter_map(|k| {
                let turned = turn_about(pose, pivot, &UnitQuaternion::from_axis_angle(axis, k as f64 * step_rad));
                self.verify_every(model, &turned, 1).map(|(_, _, e)| (k, e))
            })
            .collect();
        let Some(top) = evidence.iter().map(|(_, e)| *e).max() else {
            return Vec::new();
        };
        evidence.iter().filter(|(_, e)| *e == top).map(|(k, _)| *k).collect()
    }
}

/// The yaws the refinement scans a detection of face `face_up` over (rad): an outline-fitted
/// face's at least [`YAW_SCAN_MIN_RAD`] (its silhouette's `span_rad` understates what the
/// silhouette allows), a face fitted as its rectangle its own (0: no scan).
pub(super) fn yaw_scan_span_rad(model: &CloudModel, face_up: usize, span_rad: f64) -> f64 {
    if model.outline(face_up).is_some() {
        span_rad.max(YAW_SCAN_MIN_RAD)
    } else {
        span_rad
    }
}

/// The standard error (rad) of the tilt of a least-squares plane through points with
/// `noise_m` of independent noise along its normal, about the axis the points pin down least
/// (their scatter's longest axis, about which the plane turns most freely), and that axis (unit,
/// in the points' plane basis): `noise_m / sqrt(smallest eigenvalue of the scatter matrix)`.
/// `None` for fewer than 3 points.
pub(super) fn tilt_standard_error(points: &[[f64; 2]], noise_m: f64) -> Option<(f64, [f64; 2])> {
    if points.len() < 3 {
        return None;
    }
    let m = points.len() as f64;
    let mean = [
        points.iter().map(|p| p[0]).sum::<f64>() / m,
        points.iter().map(|p| p[1]).sum::<f64>() / m,
    ];
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for p in points {
        let (x, y) = (p[0] - mean[0], p[1] - mean[1]);
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
    }
    let half = 0.5 * (sxx + syy);
    let r = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
    let (smallest, largest) = (half - r, half + r);
    let long = if sxy.abs() > 1e-18 {
        [largest - syy, sxy]
    } else if sxx >= syy {
        [1.0, 0.0]
    } else {
        [0.0, 1.0]
    };
    let norm = long[0].hypot(long[1]);
    Some((noise_m / smallest.max(1e-24).sqrt(), [long[0] / norm, long[1] / norm]))
}

/// `pose` turned by `turn` (world) about the world point `pivot`.
fn turn_about(pose: &Isometry3<f64>, pivot: &Vector3<f64>, turn: &UnitQuaternion<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(pivot + turn * (pose.translation.vector - pivot)),
        turn * pose.rotation,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pixel centres 0.85 mm apart over a `w` x `h` (m) rectangle turned by `turn_rad`.
    fn grid(w: f64, h: f64, turn_rad: f64) -> Vec<[f64; 2]> {
        let step = 0.00085;
        let (c, s) = (turn_rad.cos(), turn_rad.sin());
        let mut out = Vec::new();
        let (nx, ny) = ((w / step) as i64, (h / step) as i64);
        for i in 0..=nx {
            for j in 0..=ny {
                let (x, y) = (i as f64 * step - w / 2.0, j as f64 * step - h / 2.0);
                out.push([c * x - s * y, s * x + c * y]);
            }
        }
        out
    }

    #[test]
    fn a_narrow_strip_leaves_its_tilt_open_about_its_long_axis() {
        // A DIP-8's 9.3 x 3.3 mm side, about 12 x 4 pixels: its plane's tilt about its long
        // axis has a standard error over the threshold; the axis is the strip's, whatever it is
        // turned by. Negative control: its 9.3 x 6.35 mm top face pins its tilt (under 2 deg).
        for turn_deg in [0.0f64, 30.0, 90.0, 135.0] {
            let t = turn_deg.to_radians();
            let (sigma, long) = tilt_standard_error(&grid(0.0093, 0.0033, t), DEPTH_NOISE_M).unwrap();
            assert!(sigma >= TILT_OPEN_RAD, "turn {turn_deg}: {:.2} deg", sigma.to_degrees());
            assert!(
                (long[0] * t.cos() + long[1] * t.sin()).abs() > 0.999,
                "turn {turn_deg}: axis {long:?}"
            );
            let (sigma, _) = tilt_standard_error(&grid(0.0093, 0.00635, t), DEPTH_NOISE_M).unwrap();
            assert!(
                sigma < TILT_OPEN_RAD,
                "turn {turn_deg}: top face {:.2} deg",
                sigma.to_degrees()
            );
        }
        assert!(tilt_standard_error(&[[0.0, 0.0], [0.001, 0.0]], DEPTH_NOISE_M).is_none());
    }
}
