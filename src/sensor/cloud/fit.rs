//! Silhouette fits in a patch's plane: the minimum-area rectangle's yaw, and the placements of a
//! face's rectangle or disc that hold every inside point and no outside point. Coordinates are
//! in the plane's basis [m]; yaws [rad].

use super::{FIT_AMBIGUITY_M, FIT_VIOLATION_M};

/// Yaw of the minimum-area rectangle around the points (rotating calipers on the convex hull)
/// [rad], in (-pi/2, pi/2].
pub(super) fn min_area_theta(pts: &[[f64; 2]]) -> f64 {
    let hull = convex_hull(pts);
    let mut best = (f64::INFINITY, 0.0);
    for k in 0..hull.len() {
        let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
        let t = (b[1] - a[1]).atan2(b[0] - a[0]);
        let (c, s) = (t.cos(), t.sin());
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in &hull {
            let q = [c * p[0] + s * p[1], -s * p[0] + c * p[1]];
            for a in 0..2 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
            }
        }
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        if area < best.0 - 1e-15 {
            best = (area, t);
        }
    }
    best.1
}

/// Convex hull (Andrew's monotone chain), counter-clockwise.
pub(super) fn convex_hull(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = pts.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// Feasible centre intervals of a rectangle of extents `ext` at yaw `theta` holding every inside
/// point and no outside point, per rotated axis: ([lo, hi]; 2).
pub(super) fn rect_intervals(inside: &[[f64; 2]], outside: &[[f64; 2]], ext: [f64; 2], theta: f64) -> [[f64; 2]; 2] {
    let (c, s) = (theta.cos(), theta.sin());
    let rot = |p: &[f64; 2]| [c * p[0] + s * p[1], -s * p[0] + c * p[1]];
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for p in inside {
        let q = rot(p);
        for a in 0..2 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    let mut iv = [
        [hi[0] - ext[0] / 2.0, lo[0] + ext[0] / 2.0],
        [hi[1] - ext[1] / 2.0, lo[1] + ext[1] / 2.0],
    ];
    for p in outside {
        let q = rot(p);
        for a in 0..2 {
            let b = 1 - a;
            if q[b] < lo[b] || q[b] > hi[b] {
                continue;
            }
            if q[a] > hi[a] {
                iv[a][1] = iv[a][1].min(q[a] - ext[a] / 2.0);
            } else if q[a] < lo[a] {
                iv[a][0] = iv[a][0].max(q[a] + ext[a] / 2.0);
            }
        }
    }
    iv
}

/// Silhouette fit of a rectangle of extents `ext`: every pose consistent with the silhouette is
/// equally likely, so the estimate is their mean: yaws within 10 degrees of `theta0` weighted by
/// the area of their feasible centres (softened by [`FIT_VIOLATION_M`] if none is feasible), the
/// centre the middle of the feasible intervals at that yaw. `None` if infeasible or ambiguous.
/// Returns (centre in the plane basis, yaw).
pub(super) fn fit_rect(
    inside: &[[f64; 2]],
    outside: &[[f64; 2]],
    ext: [f64; 2],
    theta0: f64,
) -> Option<([f64; 2], f64)> {
    let step = 0.25f64.to_radians();
    let widths: Vec<[f64; 2]> = (-40..=40)
        .map(|k| {
            let iv = rect_intervals(inside, outside, ext, theta0 + k as f64 * step);
            [iv[0][1] - iv[0][0], iv[1][1] - iv[1][0]]
        })
        .collect();
    // Strictly consistent yaws if there are any, else those within the plane's error.
    let mean_k = [0.02 * FIT_VIOLATION_M, FIT_VIOLATION_M].iter().find_map(|soft| {
        let (mut sw, mut sk) = (0.0, 0.0);
        for (k, w) in (-40..=40).zip(&widths) {
            let wgt = (w[0] + soft).max(0.0) * (w[1] + soft).max(0.0);
            sw += wgt;
            sk += wgt * k as f64;
        }
        (sw > 0.0).then(|| sk / sw)
    })?;
    let t = theta0 + mean_k * step;
    let iv = rect_intervals(inside, outside, ext, t);
    let widths = [iv[0][1] - iv[0][0], iv[1][1] - iv[1][0]];
    if widths.iter().any(|w| *w < -FIT_VIOLATION_M || *w > FIT_AMBIGUITY_M) {
        return None;
    }
    let m = [(iv[0][0] + iv[0][1]) / 2.0, (iv[1][0] + iv[1][1]) / 2.0];
    let (c, s) = (t.cos(), t.sin());
    Some(([c * m[0] - s * m[1], s * m[0] + c * m[1]], t))
}

/// Silhouette fit of a disc of radius `r`: the mean of the centres holding every inside point and
/// no outside point (within half [`FIT_VIOLATION_M`]), on a 0.1 mm grid around the centroid. `None` if infeasible
/// or ambiguous (the feasible centres spread wider than [`FIT_AMBIGUITY_M`]).
pub(super) fn fit_disc(inside: &[[f64; 2]], outside: &[[f64; 2]], r: f64) -> Option<[f64; 2]> {
    let n = inside.len() as f64;
    let c0 = [
        inside.iter().map(|p| p[0]).sum::<f64>() / n,
        inside.iter().map(|p| p[1]).sum::<f64>() / n,
    ];
    let room = |c: [f64; 2]| {
        let d = |p: &[f64; 2]| ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2)).sqrt();
        let a = inside.iter().map(|p| r - d(p)).fold(f64::INFINITY, f64::min);
        let b = outside.iter().map(|p| d(p) - r).fold(f64::INFINITY, f64::min);
        a.min(b)
    };
    let step = 0.0001;
    let (mut sum, mut cnt) = ([0.0; 2], 0.0);
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for i in -20..=20 {
        for j in -20..=20 {
            let c = [c0[0] + i as f64 * step, c0[1] + j as f64 * step];
            if room(c) >= -FIT_VIOLATION_M / 2.0 {
                for a in 0..2 {
                    sum[a] += c[a];
                    lo[a] = lo[a].min(c[a]);
                    hi[a] = hi[a].max(c[a]);
                }
                cnt += 1.0;
            }
        }
    }
    let spread = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    (cnt > 0.0 && spread <= FIT_AMBIGUITY_M).then(|| [sum[0] / cnt, sum[1] / cnt])
}
