//! A part lying on its body cylinder's curved side (D's can on its side): the cylinder's axis
//! fitted to the measured points around a patch (known radius, Gauss-Newton on the points'
//! distances to the axis, the points on the cylinder re-selected as it converges), with the
//! axis direction's standard error; and the poses along that axis to verify (either way round,
//! turns about the axis for a base that is not round, stations along the axis). Which way round
//! it lies is decided by the pixels only one way explains (its base's top), compared at every
//! pixel; the turn about the axis, where the part is not round about it, by the verification
//! evidence of one turn over every other (else the part is not reported).
//!
//! Units: m, rad. Frames: world; the fit's basis (`axis`, and two directions across it).

use nalgebra::{Isometry3, Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3, Vector4};
use rayon::prelude::*;

use super::CloudModel;
use crate::config::Piece;

/// A point this close to the cylinder's surface is on it (m) (the fit starts looser).
const ON_SURFACE_M: f64 = 0.0008;
/// Length left out at each end of the points along the axis (a base that is not round) (m).
const END_TRIM_M: f64 = 0.0015;
/// Points farther along the axis than the part's half length and this from the start are not
/// on it (m).
const ALONG_MARGIN_M: f64 = 0.001;
/// Fewest points for a fit.
const MIN_POINTS: usize = 12;
/// Gauss-Newton iterations of the fit.
const ITERATIONS: usize = 10;
/// Turns about the axis tried (rad), up to the part's symmetry about it (a quarter turn in these
/// steps: D's base is square).
pub(super) const ROLL_STEP_RAD: f64 = 15.0 * std::f64::consts::PI / 180.0;

/// The body cylinder of a model: centre, unit axis, radius (part frame) (m).
pub(super) fn body_cylinder(model: &CloudModel) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    if model.round.is_some() {
        return model.round;
    }
    model.pieces.iter().zip(&model.lead).find_map(|(p, lead)| match *p {
        Piece::Cylinder {
            center_m,
            radius_m,
            axis,
            ..
        } if !lead => Some((center_m, axis.unit(), radius_m)),
        _ => None,
    })
}

/// A cylinder's axis fitted to measured points.
#[derive(Debug, Clone, Copy)]
pub(super) struct AxisFit {
    /// A point on the axis (world) (m).
    pub point: Vector3<f64>,
    /// The axis direction (unit, world).
    pub axis: Vector3<f64>,
    /// Standard error of the axis direction (rad) (both turns across it, root sum of squares).
    pub sigma_rad: f64,
    /// RMS distance of the points on the surface to it (m).
    pub rms_m: f64,
    /// Range along the axis of the points on (or near) the surface, from `point` (m).
    pub along_m: [f64; 2],
    /// Points on the surface used.
    pub count: usize,
    /// The normal of the patch on top (world, toward the camera).
    pub up: Vector3<f64>,
}

/// The fits of different axes (one lying part makes several patches): the fits in order of
/// points used (then given order), less those whose axis is within 3 degrees of and passes
/// within 1.5 mm of a kept one's point, that point within the part's length (m).
pub(super) fn distinct(mut fits: Vec<AxisFit>, length_m: f64) -> Vec<AxisFit> {
    fits.sort_by_key(|f| std::cmp::Reverse(f.count));
    let mut kept: Vec<AxisFit> = Vec::new();
    for f in fits {
        let same = kept.iter().any(|k| {
            let q = f.point - k.point;
            k.axis.dot(&f.axis).abs() > SAME_AXIS_RAD.cos()
                && (q - k.axis * q.dot(&k.axis)).norm() < SAME_AXIS_M
                && q.dot(&k.axis).abs() < length_m
        });
        if !same {
            kept.push(f);
        }
    }
    kept
}

/// Two axes closer than these are one (rad), (m).
const SAME_AXIS_RAD: f64 = 3.0 * std::f64::consts::PI / 180.0;
const SAME_AXIS_M: f64 = 0.0015;

/// Fits a cylinder of radius `r` to the points `around` (world), starting from the axis `u0`
/// through `p0` (both world). `None` if too few points stay on it.
pub(super) fn fit_axis(
    around: &[Vector3<f64>],
    p0: &Vector3<f64>,
    u0: &Vector3<f64>,
    r: f64,
    half_length_m: f64,
) -> Option<AxisFit> {
    let (mut a, mut u) = (*p0, u0.normalize());
    let basis = |u: &Vector3<f64>| {
        let t = if u.z.abs() < 0.9 { Vector3::z() } else { Vector3::x() };
        let v = u.cross(&t).normalize();
        (v, u.cross(&v))
    };
    let mut last = None;
    for it in 0..ITERATIONS {
        let tol = if it < 3 { 2.0 * ON_SURFACE_M } else { ON_SURFACE_M };
        let (v, w) = basis(&u);
        // The points on the surface, the ends trimmed.
        let on: Vec<(f64, Vector3<f64>)> = around
            .iter()
            .filter_map(|p| {
                let q = p - a;
                let s = q.dot(&u);
                let d = (q - u * s).norm();
                ((d - r).abs() < tol && s.abs() < half_length_m + ALONG_MARGIN_M).then_some((s, q))
            })
            .collect();
        if on.len() < MIN_POINTS {
            return None;
        }
        let (s0, s1) = on
            .iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), (s, _)| (lo.min(*s), hi.max(*s)));
        let (mut jtj, mut jtr, mut sse, mut n) = (Matrix4::zeros(), Vector4::zeros(), 0.0, 0usize);
        for (s, q) in &on {
            if *s < s0 + END_TRIM_M || *s > s1 - END_TRIM_M {
                continue;
            }
            let perp = q - u * *s;
            let d = perp.norm().max(1e-9);
            let e = perp / d;
            let res = d - r;
            // Parameters: axis point moved along v, w; axis turned toward v, w (about `a`).
            let j = Vector4::new(-e.dot(&v), -e.dot(&w), -s * e.dot(&v), -s * e.dot(&w));
            jtj += j * j.transpose();
            jtr += j * res;
            sse += res * res;
            n += 1;
        }
        if n < MIN_POINTS {
            return None;
        }
        let inv = jtj.try_inverse()?;
        let step = -inv * jtr;
        let rms = (sse / n as f64).sqrt();
        // Noise of a point's distance to the axis: at least the sensor's at 1 m (0.3 mm) scaled
        // down, at most what remains.
        let sigma = (sse / (n.saturating_sub(4).max(1)) as f64).sqrt().max(0.0001);
        let sigma_rad = sigma * (inv[(2, 2)] + inv[(3, 3)]).sqrt();
        a += v * step[0] + w * step[1];
        u = (u + v * step[2] + w * step[3]).normalize();
        last = Some(AxisFit {
            point: a,
            axis: u,
            sigma_rad,
            rms_m: rms,
            along_m: [s0, s1],
            count: n,
            up: Vector3::zeros(),
        });
        if step.norm() < 1e-7 && it >= 4 {
            break;
        }
    }
    let mut fit = last?;
    // Keep the axis point where `p0` projects onto it.
    fit.point += fit.axis * (p0 - fit.point).dot(&fit.axis);
    let shift = (p0 - fit.point).dot(&fit.axis);
    fit.along_m = [fit.along_m[0] - shift, fit.along_m[1] - shift];
    Some(fit)
}

/// The part's extent along its body cylinder's axis, from its origin (m).
pub(super) fn extent_along(model: &CloudModel, a_part: &Vector3<f64>) -> [f64; 2] {
    if let Some(m) = &model.mesh {
        return m
            .vertices_m
            .iter()
            .map(|v| v.dot(a_part))
            .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], t| [lo.min(t), hi.max(t)]);
    }
    let lo = -model
        .pieces
        .iter()
        .map(|p| p.support_m(&-a_part))
        .fold(f64::MIN, f64::max);
    let hi = model
        .pieces
        .iter()
        .map(|p| p.support_m(a_part))
        .fold(f64::MIN, f64::max);
    [lo, hi]
}

/// `world_from_part` with the body cylinder (part frame `c_part`, `a_part`) on the world axis
/// through `axis_p` along `axis_w`, the part origin's station at `axis_p`, turned by `roll_rad`
/// about the axis from `up` (world, across the axis).
pub(super) fn pose_on_axis(
    c_part: &Vector3<f64>,
    a_part: &Vector3<f64>,
    axis_p: &Vector3<f64>,
    axis_w: &Vector3<f64>,
    up: &Vector3<f64>,
    roll_rad: f64,
) -> Isometry3<f64> {
    let b_part = if a_part.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let b_part = (b_part - a_part * a_part.dot(&b_part)).normalize();
    let up = (up - axis_w * axis_w.dot(up)).normalize();
    let b_w = up * roll_rad.cos() + axis_w.cross(&up) * roll_rad.sin();
    let world = Matrix3::from_columns(&[*axis_w, b_w, axis_w.cross(&b_w)]);
    let part = Matrix3::from_columns(&[*a_part, b_part, a_part.cross(&b_part)]);
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(world * part.transpose()));
    let t = axis_p - rot * (c_part - a_part * a_part.dot(c_part));
    Isometry3::from_parts(Translation3::from(t), rot)
}

/// Largest standard error of a lying part's fitted axis reported (rad) (precision first: the
/// error bar is 5 degrees).
pub const AXIS_SIGMA_MAX_RAD: f64 = 4.0 * std::f64::consts::PI / 180.0;
/// Largest RMS distance of the points to the fitted cylinder (m).
const FIT_RMS_MAX_M: f64 = 0.0003;
/// The station along the axis must be pinned: moved by this either way (m) ...
const STATION_PROBE_M: f64 = 0.0015;
/// ... the evidence must drop by at least this (px).
pub const PIN_MARGIN_PX: i64 = 3;
/// Step of the station scan along the axis (m) and its half width in steps.
const STATION_STEP_M: f64 = 0.0005;
const STATION_STEPS: i32 = 3;
/// Which way round a lying part is: each way is placed along the axis by the evidence of every
/// pixel (the verification grid can miss a base a pixel or two long), and one way wins by this
/// much more evidence (px; a wrong way round that renders leads or a base over the floor) ...
const END_EVIDENCE_MARGIN_PX: i64 = 20;
/// ... or by the pixels only it explains ([`end_votes`]; a base's top, which the other way
/// renders as the can's rounded side, an occlusion that no evidence counts against): at least
/// this many ...
const END_VOTES_MIN: usize = 6;
/// ... and this many times the other's; else the part is not reported. The three were chosen on
/// `sense` seeds 1-12 of D and the SMD electrolytic (every lying axis fitted: 561 and 347 ends
/// right, none wrong; 11 and 57 left undecided); the figures on seeds 13-28, which they did not
/// see, are in `docs/benchmarks.md`.
const END_VOTE_RATIO: usize = 3;

/// Of two poses' agreeing pixels (sorted): how many only the first explains, and only the
/// second. Where both agree, or neither (an occluder, noise), a pixel cannot tell them apart.
pub(super) fn end_votes(a: &[usize], b: &[usize]) -> (usize, usize) {
    let only = |x: &[usize], y: &[usize]| x.iter().filter(|i| y.binary_search(i).is_err()).count();
    (only(a, b), only(b, a))
}

impl super::Cloud<'_> {
    /// The pixels within `k` pixels (chessboard distance) of `pixels` that `keep` keeps, sorted.
    pub(super) fn dilate(&self, pixels: &[usize], k: usize, keep: impl Fn(usize) -> bool) -> Vec<usize> {
        let Some(u_lo) = pixels.iter().map(|&i| i % self.w).min() else {
            return Vec::new();
        };
        let u_hi = pixels.iter().map(|&i| i % self.w).max().unwrap_or(u_lo);
        let v_lo = pixels.iter().map(|&i| i / self.w).min().unwrap_or(0);
        let v_hi = pixels.iter().map(|&i| i / self.w).max().unwrap_or(v_lo);
        // A mask over the pixels' box grown by k (within the window), marked around each pixel,
        // read row by row: in increasing index, each pixel once.
        let (u0, v0) = (u_lo.saturating_sub(k), v_lo.saturating_sub(k));
        let (u1, v1) = ((u_hi + k).min(self.w - 1), (v_hi + k).min(self.h - 1));
        let bw = u1 - u0 + 1;
        let mut near = vec![false; bw * (v1 - v0 + 1)];
        for &i in pixels {
            let (u, v) = (i % self.w, i / self.w);
            for nv in v.saturating_sub(k).max(v0)..=(v + k).min(v1) {
                let row = (nv - v0) * bw;
                near[row + u.saturating_sub(k).max(u0) - u0..=row + (u + k).min(u1) - u0].fill(true);
            }
        }
        (v0..=v1)
            .flat_map(|v| (u0..=u1).map(move |u| v * self.w + u))
            .zip(near)
            .filter(|&(j, marked)| marked && keep(j))
            .map(|(j, _)| j)
            .collect()
    }

    /// The axes of the part lying on its body cylinder's side that fit the points around `patch`
    /// (its plane `plane`, `axes` the in-plane directions to start from), their standard error
    /// within [`AXIS_SIGMA_MAX_RAD`] and the patch on top of them.
    pub(super) fn lying_fits(
        &self,
        patch: &super::Patch,
        model: &CloudModel,
        plane: &super::Plane,
        axes: [Vector3<f64>; 2],
    ) -> Vec<AxisFit> {
        let Some((_, a_part, r)) = body_cylinder(model) else {
            return Vec::new();
        };
        let n = plane.normal;
        let m = patch.pixels.len() as f64;
        let p0 = patch.pixels.iter().map(|&i| self.pts[i]).sum::<Vector3<f64>>() / m;
        let around: Vec<Vector3<f64>> = self
            .dilate(&patch.pixels, 4, |j| self.fg[j])
            .into_iter()
            .map(|i| self.pts[i])
            .collect();
        let ext = extent_along(model, &a_part);
        let mut out: Vec<AxisFit> = Vec::new();
        for u0 in axes {
            let Some(mut fit) = fit_axis(&around, &(p0 - n * r), &u0, r, (ext[1] - ext[0]) / 2.0) else {
                continue;
            };
            // The patch must be the cylinder's top: its centroid above the axis by about r.
            let q = p0 - fit.point;
            let lift = (q - fit.axis * q.dot(&fit.axis)).dot(&n);
            if fit.sigma_rad > AXIS_SIGMA_MAX_RAD || fit.rms_m > FIT_RMS_MAX_M || lift < 0.5 * r {
                continue;
            }
            // Both starts may lead to the same axis.
            if out.iter().any(|t| t.axis.dot(&fit.axis).abs() > 0.9998) {
                continue;
            }
            fit.up = n;
            out.push(fit);
        }
        out
    }

    /// The best verified pose on each distinct axis (see [`distinct`]), if pinned down.
    pub(super) fn lying_detections(&self, model: &CloudModel, fits: &[AxisFit]) -> Vec<super::CloudDetection> {
        let Some((c_part, a_part, _)) = body_cylinder(model) else {
            return Vec::new();
        };
        let ext = extent_along(model, &a_part);
        fits.par_iter()
            .filter_map(|f| self.lying_along(model, f, &f.up, &c_part, &a_part, ext).map(|d| d.1))
            .collect()
    }

    /// The model rendered at `pose` on every pixel: (evidence, as [`super::Cloud`]'s
    /// verification counts it, and the pixels whose measured depth agrees, sorted).
    pub(super) fn agreeing(&self, model: &CloudModel, pose: &Isometry3<f64>) -> (i64, Vec<usize>) {
        let (mut px, mut contradict) = (Vec::new(), 0i64);
        self.render(model, pose, 1, |i, predicted, graze| {
            match self.judge(i, predicted, graze) {
                Some(true) => px.push(i),
                Some(false) => contradict += 1,
                None => {}
            }
        });
        (px.len() as i64 - 3 * contradict, px)
    }

    /// The station along the axis (`at(station)` the pose there) with the most evidence on
    /// every pixel, climbing in [`STATION_STEP_M`] steps from `s0` up to [`STATION_STEPS`] either
    /// way (the middle of a run of equal evidence): its evidence, the pose and its agreeing
    /// pixels; `None` if fewer than [`super::MIN_PATCH_PX`] pixels agree.
    fn place_finely(
        &self,
        model: &CloudModel,
        at: impl Fn(f64) -> Isometry3<f64>,
        s0: f64,
    ) -> Option<(i64, Isometry3<f64>, Vec<usize>)> {
        let eval = |k: i32| {
            let p = at(s0 + k as f64 * STATION_STEP_M);
            let (e, px) = self.agreeing(model, &p);
            (e, k, p, px)
        };
        let mut best = vec![eval(0)];
        for dir in [-1, 1] {
            for k in 1..=STATION_STEPS {
                let c = eval(dir * k);
                if c.0 < best[0].0 {
                    break;
                }
                if c.0 > best[0].0 {
                    best.clear();
                }
                best.push(c);
            }
        }
        best.sort_by_key(|c| c.1);
        let mid = best.swap_remove(best.len() / 2);
        (mid.3.len() >= super::MIN_PATCH_PX).then_some((mid.0, mid.2, mid.3))
    }

    /// The pose along a fitted axis: which way round, turn and station by verification, kept
    /// only if pinned down.
    fn lying_along(
        &self,
        model: &CloudModel,
        fit: &AxisFit,
        n: &Vector3<f64>,
        c_part: &Vector3<f64>,
        a_part: &Vector3<f64>,
        ext: [f64; 2],
    ) -> Option<(i64, super::CloudDetection)> {
        let [s0, s1] = fit.along_m;
        let pose = |sign: f64, roll: f64, s: f64| {
            pose_on_axis(c_part, a_part, &(fit.point + fit.axis * s), &(fit.axis * sign), n, roll)
        };
        let evidence = |p: &Isometry3<f64>| self.check(model, p, None);
        // Per way round: the turn about the axis at the middle station (it shows at the base),
        // then the best station of the three (one end at the points' ends, or the middle), on
        // the verification grid; then placed along the axis by the evidence of every pixel (the
        // grid can miss a base a pixel or two long).
        let mid = |sign: f64| {
            let (e0, e1) = if sign > 0.0 {
                (ext[0], ext[1])
            } else {
                (-ext[1], -ext[0])
            };
            ((s0 + s1 - e0 - e1) / 2.0, s0 - e0, s1 - e1)
        };
        // The turns about the axis tried: steps of [`ROLL_STEP_RAD`] over a quarter turn (D's square
        // base shows at each), and on up to the first turn that the part's symmetry maps onto
        // none (a bolt's hex head with its shank: a half turn), at most a full turn.
        let full = (std::f64::consts::TAU / ROLL_STEP_RAD).round() as usize;
        let quarter = full / 4;
        let steps = (quarter..full)
            .find(|&k| model.same_pose(&pose(1.0, k as f64 * ROLL_STEP_RAD, s0), &pose(1.0, 0.0, s0)))
            .unwrap_or(full);
        let mut per_sign = Vec::new();
        for sign in [1.0, -1.0] {
            let (m, a, b) = mid(sign);
            let turns: Vec<(i64, usize)> = (0..steps)
                .filter_map(|k| evidence(&pose(sign, k as f64 * ROLL_STEP_RAD, m)).map(|(e, _)| (e, k)))
                .collect();
            let Some(&(best_e, best_k)) = turns.iter().rev().max_by_key(|t| t.0) else {
                continue;
            };
            let roll = best_k as f64 * ROLL_STEP_RAD;
            // Decided where no other turn tried that is a different pose (up to the part's
            // symmetry) comes within [`super::CLOSE_CALL_PX`] of it: one step off is already past
            // the 5 degrees a pose may be off. A bolt's hex head, a few pixels at the end of its
            // round shank, does not decide its turn; D's square base on its round can need not.
            let decided = !turns.iter().any(|&(e, k)| {
                k != best_k
                    && e >= best_e - super::CLOSE_CALL_PX
                    && !model.same_pose(&pose(sign, roll, m), &pose(sign, k as f64 * ROLL_STEP_RAD, m))
            });
            let mut top: Option<(i64, f64)> = None;
            for s in [m, a, b] {
                if let Some((e, _)) = evidence(&pose(sign, roll, s))
                    && top.is_none_or(|t| e > t.0)
                {
                    top = Some((e, s));
                }
            }
            if let Some((_, s)) = top {
                per_sign.extend(
                    self.place_finely(model, |s| pose(sign, roll, s), s)
                        .map(|(e, p, px)| (e, p, px, decided)),
                );
            }
        }
        // Which way round: one way has [`END_EVIDENCE_MARGIN_PX`] more evidence on every pixel,
        // or the pixels only it explains decide ([`end_votes`]); else the part is not reported.
        let chosen = match per_sign.as_slice() {
            [] => return None,
            [one] => one,
            [a, b, ..] => {
                let (va, vb) = end_votes(&a.2, &b.2);
                if a.0 >= b.0 + END_EVIDENCE_MARGIN_PX || (va >= END_VOTES_MIN && vb * END_VOTE_RATIO <= va) {
                    a
                } else if b.0 >= a.0 + END_EVIDENCE_MARGIN_PX || (vb >= END_VOTES_MIN && va * END_VOTE_RATIO <= vb) {
                    b
                } else {
                    return None;
                }
            }
        };
        // A turn about the axis the image does not decide is not reported.
        if !chosen.3 {
            return None;
        }
        let at = chosen.1;
        let best = evidence(&at)?;
        let axis_w = at.rotation * a_part;
        for probe in [-STATION_PROBE_M, STATION_PROBE_M] {
            let moved = Isometry3::from_parts(Translation3::from(at.translation.vector + axis_w * probe), at.rotation);
            if evidence(&moved).is_some_and(|d| d.0 > best.0 - PIN_MARGIN_PX) {
                return None;
            }
        }
        Some(best)
    }
}
