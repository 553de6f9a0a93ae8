//! Silhouette fits in a patch's plane: the minimum-area rectangle's yaw, and the placements of a
//! face's rectangle or disc that hold every inside point and no outside point. Coordinates are
//! in the plane's basis (m); yaws (rad).

use super::{FIT_AMBIGUITY_M, FIT_VIOLATION_M};
use crate::geometry::convex_hull_2d as convex_hull;

/// Yaw of the minimum-area rectangle around the points (rotating calipers on the convex hull)
/// (rad), in (-pi/2, pi/2].
pub(super) fn min_area_theta(pts: &[[f64; 2]]) -> f64 {
    let hull = convex_hull(pts);
    let mut best = (f64::INFINITY, 0.0);
    for k in 0..hull.len() {
        let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
        let t = (b[1] - a[1]).atan2(b[0] - a[0]);
        let (lo, hi) = bounds_at(&hull, t);
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        if area < best.0 - 1e-15 {
            best = (area, t);
        }
    }
    best.1
}

/// The bounds of the points in the frame turned by `theta` (rad): lowest and highest coordinate
/// along each of its two axes (m).
pub(super) fn bounds_at(pts: &[[f64; 2]], theta: f64) -> ([f64; 2], [f64; 2]) {
    let (c, s) = (theta.cos(), theta.sin());
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for p in pts {
        let q = [c * p[0] + s * p[1], -s * p[0] + c * p[1]];
        for a in 0..2 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    (lo, hi)
}

/// A rectangle's silhouette fit: the mean of the placements consistent with the silhouette.
#[derive(Debug, Clone, Copy)]
pub(super) struct RectFit {
    /// Centre in the plane basis (m).
    pub center: [f64; 2],
    /// Yaw of the rectangle's first axis in the plane basis (rad).
    pub yaw_rad: f64,
    /// Width of the range of consistent yaws (rad) (the scan's whole width if it reaches an end).
    pub yaw_span_rad: f64,
}

/// Yaw step of the rectangle fit's scan (rad) and its half width in steps.
const YAW_STEP_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
const YAW_STEPS: i32 = 20;
/// Grid of candidate centres of the rectangle fit (m).
const CELL_M: f64 = 0.0001;
/// ... coarser if the centres' box would need more cells than this per axis.
const MAX_CELLS: usize = 40;
// A row of centres is one 64-bit mask (a box's side may round to two cells more).
const _: () = assert!(MAX_CELLS + 2 <= 64);

/// Silhouette fit of a rectangle of extents `ext`: the placements consistent with the silhouette,
/// yaws within 10 degrees of `theta0` in [`YAW_STEP_RAD`] steps; the estimate is the middle of
/// the consistent yaws (off by at most half their span) and the mean of the consistent centres. At each yaw,
/// the centres on a [`CELL_M`] grid that put every inside point in the rectangle and every outside
/// point out of it (exactly, corners included), within a tolerance: strict, else the plane's
/// error [`FIT_VIOLATION_M`]. `inside` may be just its convex hull. `None` if nothing is consistent or the centres are not pinned down
/// (spread wider than [`FIT_AMBIGUITY_M`]).
pub(super) fn fit_rect(inside: &[[f64; 2]], outside: &[[f64; 2]], ext: [f64; 2], theta0: f64) -> Option<RectFit> {
    let half = [ext[0] / 2.0, ext[1] / 2.0];
    for tol in [0.1 * FIT_VIOLATION_M, FIT_VIOLATION_M] {
        // (weight, weighted sum of centres (plane basis), range of consistent yaw steps).
        let (mut wsum, mut csum) = (0.0, [0.0; 2]);
        let (mut k0, mut k1) = (i32::MAX, i32::MIN);
        let mut rows: Vec<u64> = Vec::new();
        for k in -YAW_STEPS..=YAW_STEPS {
            let t = theta0 + k as f64 * YAW_STEP_RAD;
            let (c, s) = (t.cos(), t.sin());
            let rot = |p: &[f64; 2]| [c * p[0] + s * p[1], -s * p[0] + c * p[1]];
            let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
            for p in inside {
                let q = rot(p);
                for a in 0..2 {
                    lo[a] = lo[a].min(q[a]);
                    hi[a] = hi[a].max(q[a]);
                }
            }
            // Centres holding every inside point.
            let blo = [hi[0] - half[0] - tol, hi[1] - half[1] - tol];
            let bhi = [lo[0] + half[0] + tol, lo[1] + half[1] + tol];
            if blo[0] > bhi[0] || blo[1] > bhi[1] {
                continue;
            }
            let cell = [
                ((bhi[0] - blo[0]) / MAX_CELLS as f64).max(CELL_M),
                ((bhi[1] - blo[1]) / MAX_CELLS as f64).max(CELL_M),
            ];
            let n = [
                ((bhi[0] - blo[0]) / cell[0]) as usize + 1,
                ((bhi[1] - blo[1]) / cell[1]) as usize + 1,
            ];
            // Less the centres that would hold an outside point: each excludes a box of
            // centres, marked row by row in a bit mask per row (bit i: column i).
            rows.clear();
            rows.resize(n[1], 0);
            for p in outside {
                let q = rot(p);
                let mut range = [[0usize; 2]; 2];
                let mut hit = true;
                for a in 0..2 {
                    let (l, h) = (q[a] - half[a] + tol, q[a] + half[a] - tol);
                    // Wholly before the first centre or past the last: no cell (as the bounds
                    // below would find, without their divisions).
                    if h < blo[a] || l - blo[a] > n[a] as f64 * cell[a] {
                        hit = false;
                        break;
                    }
                    let il = ((l - blo[a]) / cell[a]).ceil().max(0.0);
                    let ih = ((h - blo[a]) / cell[a]).floor().min((n[a] - 1) as f64);
                    if il > ih {
                        hit = false;
                        break;
                    }
                    range[a] = [il as usize, ih as usize + 1];
                }
                if hit {
                    let ([i0, i1], [j0, j1]) = (range[0], range[1]);
                    let columns = (u64::MAX >> (64 - (i1 - i0))) << i0;
                    for row in &mut rows[j0..j1] {
                        *row |= columns;
                    }
                }
            }
            // The centres no outside point excludes (a clear bit), counted row by row.
            let all = u64::MAX >> (64 - n[0]);
            let (mut cnt, mut m) = (0usize, [0.0; 2]);
            let (mut glo, mut ghi) = ([usize::MAX; 2], [0usize; 2]);
            for (j, row) in rows.iter().enumerate() {
                // The consistent centres only spread as rows are added: once wider than
                // FIT_AMBIGUITY_M they are not pinned down, whatever the rows left.
                if cnt > 0
                    && ((ghi[0] - glo[0]) as f64 * cell[0]).max((ghi[1] - glo[1]) as f64 * cell[1]) > FIT_AMBIGUITY_M
                {
                    return None;
                }
                let free = !row & all;
                if free == 0 {
                    continue;
                }
                // Sums of small integers: exact in any order.
                let count = free.count_ones() as usize;
                cnt += count;
                m[0] += bit_index_sum(free) as f64;
                m[1] += (j * count) as f64;
                let (first, last) = (free.trailing_zeros() as usize, 63 - free.leading_zeros() as usize);
                glo = [glo[0].min(first), glo[1].min(j)];
                ghi = [ghi[0].max(last), ghi[1].max(j)];
            }
            if cnt == 0 {
                continue;
            }
            if ((ghi[0] - glo[0]) as f64 * cell[0]).max((ghi[1] - glo[1]) as f64 * cell[1]) > FIT_AMBIGUITY_M {
                // Consistent but not pinned down: no fit (the looser tolerance only adds more).
                return None;
            }
            let mr = [
                blo[0] + m[0] / cnt as f64 * cell[0],
                blo[1] + m[1] / cnt as f64 * cell[1],
            ];
            let w = cnt as f64 * cell[0] * cell[1];
            wsum += w;
            csum[0] += w * (c * mr[0] - s * mr[1]);
            csum[1] += w * (s * mr[0] + c * mr[1]);
            k0 = k0.min(k);
            k1 = k1.max(k);
        }
        if wsum > 0.0 {
            let span = if k0 == -YAW_STEPS || k1 == YAW_STEPS {
                2 * YAW_STEPS
            } else {
                k1 - k0
            };
            return Some(RectFit {
                center: [csum[0] / wsum, csum[1] / wsum],
                yaw_rad: theta0 + (k0 + k1) as f64 / 2.0 * YAW_STEP_RAD,
                yaw_span_rad: span as f64 * YAW_STEP_RAD,
            });
        }
    }
    None
}

/// The sum of the indices of the set bits of `x`: per bit k of an index, the set bits whose index
/// has it, times 2^k.
pub(super) fn bit_index_sum(x: u64) -> u64 {
    const HAS_BIT: [u64; 6] = [
        0xAAAA_AAAA_AAAA_AAAA,
        0xCCCC_CCCC_CCCC_CCCC,
        0xF0F0_F0F0_F0F0_F0F0,
        0xFF00_FF00_FF00_FF00,
        0xFFFF_0000_FFFF_0000,
        0xFFFF_FFFF_0000_0000,
    ];
    HAS_BIT
        .iter()
        .enumerate()
        .map(|(k, mask)| u64::from((x & mask).count_ones()) << k)
        .sum()
}

/// Silhouette fit of a disc of radius `r` with a concentric hole of radius `hole_r` (0: none;
/// `inside` may be just its convex hull): the mean of the centres holding every inside point
/// and no outside point but in the hole (within half [`FIT_VIOLATION_M`]), on a 0.2 mm grid
/// around the centroid. `None` if infeasible or ambiguous (the feasible centres spread wider
/// than [`FIT_AMBIGUITY_M`]).
pub(super) fn fit_disc(inside: &[[f64; 2]], outside: &[[f64; 2]], r: f64, hole_r: f64) -> Option<[f64; 2]> {
    let n = inside.len() as f64;
    let c0 = [
        inside.iter().map(|p| p[0]).sum::<f64>() / n,
        inside.iter().map(|p| p[1]).sum::<f64>() / n,
    ];
    // Whether every inside point lies in the disc centred at `c` and every outside point out
    // of it or in its hole, each within the tolerance: the first point that violates it decides.
    let tol = -FIT_VIOLATION_M / 2.0;
    let feasible = |c: [f64; 2]| {
        let d = |p: &[f64; 2]| ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2)).sqrt();
        inside.iter().all(|p| r - d(p) >= tol)
            && outside.iter().all(|p| {
                let dp = d(p);
                dp - r >= tol || (hole_r > 0.0 && hole_r - dp >= tol)
            })
    };
    let step = 0.0002;
    let (mut sum, mut cnt) = ([0.0; 2], 0.0);
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for i in -10..=10 {
        for j in -10..=10 {
            let c = [c0[0] + i as f64 * step, c0[1] + j as f64 * step];
            if feasible(c) {
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
