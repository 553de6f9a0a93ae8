//! A mesh part's planar face as the cloud shows it, and the silhouette fit of its true outline:
//! a polygon with holes, not its bounding rectangle (a hexagon's cut corners, a ring's bore), with
//! the features beside it that a patch of the cloud takes in (a DIP's leg shoulders 1.1 mm behind
//! its face, an SMD capacitor's terminals 0.2 mm in front of its base).
//!
//! An [`Outline`] holds two signed distance fields on a 0.1 mm grid in the face's frame: to the
//! face itself (`core`, its holes cut out), and to the face with those features (`reach`: its
//! outer boundary, holes filled, and every part of the mesh facing the same way within
//! [`BAND_M`] of the face's plane, projected onto it). A hole may hold a feature standing out of
//! it (a relay's pin: a pixel beside the pin sees the face), so points in a hole are allowed;
//! a hole seen through keeps outside points out of `core`. A placement of
//! the outline is consistent with a patch when every inside point lies in `reach` and no outside
//! point in `core` (each within [`FIT_VIOLATION_M`]). [`fit_outline`] finds consistent
//! placements from a few starts (Gauss-Newton on the violations), then measures how far each
//! stays consistent along the plane's two axes and in yaw: a placement not pinned down within
//! [`FIT_AMBIGUITY_M`] and the model's yaw span is no fit; the estimate is the middle of those
//! ranges, as the rectangle fit's.
//!
//! Units: m, rad. Frames: the face frame (origin the fitted face's centre, x along its `along`,
//! y along `normal x along`); the patch's plane basis (e1, e2). A placement (c, t) maps a plane
//! point p to the face frame as R(-t) (p - c).

use nalgebra::{Point2, Vector3};

use super::{FIT_AMBIGUITY_M, FIT_VIOLATION_M, NORMAL_TOL_RAD, PLANE_TOL_M};
use crate::part::faces::PlanarFace;
use crate::part::mesh::Mesh;
use crate::part::primitive::Face;

/// Features of the mesh facing the face's way within this of its plane, either side, can be in
/// the face's patch (m): the region growing's plane tolerance and two sigma of the depth noise.
pub const BAND_M: f64 = PLANE_TOL_M + 0.0007;
/// Features beside a face (and holes seen through) smaller than this in all are not fitted (m^2):
/// about half a pixel of the default sensor at the tray.
pub const BAND_MIN_AREA_M2: f64 = 2.5e-7;
/// Cell of the distance fields (m).
const CELL_M: f64 = 0.0001;
/// The fields reach this far beyond the outline (m); farther, the distance is extrapolated.
const MARGIN_M: f64 = 0.002;
/// Gauss-Newton iterations per start.
const ITERATIONS: usize = 16;
/// After this many iterations, a start whose violations' RMS over its points is still above
/// [`STALL_RMS_M`] is given up.
const STALL_ITERATIONS: usize = 6;
const STALL_RMS_M: f64 = 0.0006;
/// Steps of the consistency scans along each plane axis (m) and in yaw (rad).
const SCAN_STEP_M: f64 = 0.0001;
const SCAN_STEP_RAD: f64 = 0.25 * std::f64::consts::PI / 180.0;
/// How much the fields' value can change per metre a point moves: the bilinear distance's slope
/// is at most 1 along each grid axis (neighbouring cells of a distance transform differ by at
/// most a cell), so sqrt(2); beyond the grid the way out adds 1. Rounded up.
const LIPSCHITZ: f64 = 2.5;
/// A point is skipped only while its margin exceeds its possible change by this (m): far above
/// the rounding of the values.
const SKIP_GUARD_M: f64 = 1e-9;
/// Two fits closer than these are one (m), (rad).
const SAME_M: f64 = 0.001;
const SAME_RAD: f64 = 3.0 * std::f64::consts::PI / 180.0;

/// A signed distance field on a grid (m): negative inside.
#[derive(Debug, Clone)]
struct Field {
    d: Vec<f32>,
}

/// A face's outline for the silhouette fit.
#[derive(Debug, Clone)]
pub struct Outline {
    /// Lower corner of the grid (face frame, m): the centre of cell (0, 0).
    origin: [f64; 2],
    /// Cells along x and y.
    n: [usize; 2],
    /// Distance to the face.
    core: Field,
    /// Distance to the face and the features beside it within the band.
    reach: Field,
    /// The extents of `reach`'s minimum-area rectangle, longest first (m): a patch larger than
    /// this (by a pixel) cannot be this face.
    pub reach_extent_m: [f64; 2],
    /// The bounds of `reach` in the face frame (m): lowest, highest.
    reach_box: ([f64; 2], [f64; 2]),
    /// The area of `reach` (m^2).
    pub reach_area_m2: f64,
    /// The area `reach` adds to `core`: the band's features beside the face and its holes
    /// (m^2).
    band_area_m2: f64,
    /// The face has holes the sensor sees through.
    holes: bool,
}

impl Outline {
    /// The outline of `face` (a part model's planar face) in the frame of `fitted` (the face as
    /// [`super::face_of_planar`] fits it), with the features of `mesh` (part frame) within
    /// [`BAND_M`] of its plane that face the same way.
    pub fn new(face: &PlanarFace, fitted: &Face, mesh: &Mesh) -> Self {
        let to_face = face_frame(fitted);
        let ring =
            |pts: &[Point2<f64>]| -> Vec<[f64; 2]> { pts.iter().map(|p| to_face(&face.to_part(p).coords)).collect() };
        let holes: Vec<Vec<[f64; 2]>> = face.holes.iter().map(|h| ring(h)).collect();
        Self::of_rings(ring(&face.outer), holes, fitted, mesh)
    }

    /// From the face's outer ring and holes in `fitted`'s frame.
    fn of_rings(outer: Vec<[f64; 2]>, holes: Vec<Vec<[f64; 2]>>, fitted: &Face, mesh: &Mesh) -> Self {
        let n = fitted.normal;
        let to_face = face_frame(fitted);
        // The band's triangles, projected.
        let plane_d = fitted.center.dot(&n);
        let band: Vec<[[f64; 2]; 3]> = (0..mesh.triangles.len())
            .filter_map(|k| {
                let c = mesh.corners(k);
                let tn = (c[1] - c[0]).cross(&(c[2] - c[0]));
                let len = tn.norm();
                if len < 1e-15 || tn.dot(&n) / len < NORMAL_TOL_RAD.cos() {
                    return None;
                }
                c.iter()
                    .all(|p| (p.coords.dot(&n) - plane_d).abs() <= BAND_M)
                    .then(|| c.map(|p| to_face(&p.coords)))
            })
            .collect();
        // A hole the part covers in front of the face (a pin standing out of it, a can on its
        // base) shows the part, not what lies behind: it is no hole to the sensor.
        let covers = |q: [f64; 2]| {
            (0..mesh.triangles.len()).any(|k| {
                let c = mesh.corners(k);
                let tn = (c[1] - c[0]).cross(&(c[2] - c[0]));
                tn.dot(&n) > 0.0
                    && c.iter().any(|p| p.coords.dot(&n) - plane_d > BAND_M)
                    && in_triangle(&c.map(|p| to_face(&p.coords)), q)
            })
        };
        let holes: Vec<Vec<[f64; 2]>> = holes
            .into_iter()
            .filter(|h| {
                let m = h.len().max(1) as f64;
                let centre = [
                    h.iter().map(|p| p[0]).sum::<f64>() / m,
                    h.iter().map(|p| p[1]).sum::<f64>() / m,
                ];
                !(in_polygon(h, centre) && covers(centre))
            })
            .collect();
        let with_band: Vec<[f64; 2]> = outer.iter().chain(band.iter().flatten()).copied().collect();
        let (lo, hi) = bounds(&with_band);
        let origin = [lo[0] - MARGIN_M, lo[1] - MARGIN_M];
        let cells = [
            ((hi[0] - lo[0] + 2.0 * MARGIN_M) / CELL_M).ceil() as usize + 1,
            ((hi[1] - lo[1] + 2.0 * MARGIN_M) / CELL_M).ceil() as usize + 1,
        ];
        let mut in_core = vec![false; cells[0] * cells[1]];
        let mut in_reach = vec![false; cells[0] * cells[1]];
        let mut in_band = vec![false; cells[0] * cells[1]];
        for j in 0..cells[1] {
            for i in 0..cells[0] {
                let p = [origin[0] + i as f64 * CELL_M, origin[1] + j as f64 * CELL_M];
                let within = in_polygon(&outer, p);
                let k = j * cells[0] + i;
                in_core[k] = within && !holes.iter().any(|h| in_polygon(h, p));
                in_band[k] = !within && band.iter().any(|t| in_triangle(t, p));
                in_reach[k] = within || in_band[k];
            }
        }
        // A band larger than the face is not features beside it: the face is a strip of a
        // larger surface (a can's base side, flush with the can's wall), whose patches that
        // surface's own face or the lying fit explains. Such a face is fitted on its own.
        let count = |m: &[bool]| m.iter().filter(|&&x| x).count();
        if count(&in_band) > count(&in_core) {
            for (r, b) in in_reach.iter_mut().zip(&in_band) {
                *r &= !*b;
            }
        }
        // What `reach` spans: the face with the band, unless the band was left out.
        let reach_pts = if in_band.iter().zip(&in_reach).any(|(b, r)| *b && *r) {
            &with_band
        } else {
            &outer
        };
        let hull = super::convex_hull(reach_pts);
        let theta = super::min_area_theta(&hull);
        let (blo, bhi) = super::fit::bounds_at(&hull, theta);
        let e = [bhi[0] - blo[0], bhi[1] - blo[1]];
        let core_d = signed_distance(&in_core, cells);
        let reach_d = signed_distance(&in_reach, cells);
        let band_area_m2 = band_area_m2(&core_d, &reach_d);
        Outline {
            origin,
            n: cells,
            core: Field { d: core_d },
            reach: Field { d: reach_d },
            reach_extent_m: [e[0].max(e[1]), e[0].min(e[1])],
            reach_box: bounds(reach_pts),
            reach_area_m2: count(&in_reach) as f64 * CELL_M * CELL_M,
            band_area_m2,
            holes: !holes.is_empty(),
        }
    }

    /// Whether features beside the face (within the band) or holes seen through add at least
    /// [`BAND_MIN_AREA_M2`] to `core` (less is under a pixel's worth: D's can rim, 0.1 mm past
    /// its base).
    pub fn has_band(&self) -> bool {
        self.band_area_m2 >= BAND_MIN_AREA_M2
    }

    /// Whether the outline is, to the sensor, just `fitted`'s rectangle: the face (of area
    /// `area_m2`, its covered holes counted) fills its rectangle, it has no hole seen through, and
    /// the band adds under [`BAND_MIN_AREA_M2`] and nothing beyond the rectangle.
    pub fn is_rectangle(&self, fitted: &Face, area_m2: f64, holes_area_m2: f64) -> bool {
        let [a, b] = fitted.extent_m;
        let (lo, hi) = self.reach_box;
        let tol = 0.5 * CELL_M;
        !self.holes
            && !self.has_band()
            && area_m2 + holes_area_m2 >= 0.995 * a * b
            && lo[0] >= -a / 2.0 - tol
            && hi[0] <= a / 2.0 + tol
            && lo[1] >= -b / 2.0 - tol
            && hi[1] <= b / 2.0 + tol
    }

    /// The cell of the field under `p` (face frame): its four corner distances, where `p` lies
    /// in it, and how far `p` lies beyond the grid (m, zero inside).
    #[inline(always)]
    fn cell(&self, f: &Field, p: [f64; 2]) -> Cell {
        let gx = (p[0] - self.origin[0]) / CELL_M;
        let gy = (p[1] - self.origin[1]) / CELL_M;
        let (mx, my) = ((self.n[0] - 1) as f64, (self.n[1] - 1) as f64);
        let (cx, cy) = (gx.clamp(0.0, mx - 1e-9), gy.clamp(0.0, my - 1e-9));
        // Non-negative: truncation is the floor.
        let (i, j) = (cx as usize, cy as usize);
        let k = j * self.n[0] + i;
        let row = self.n[0];
        Cell {
            d: [f.d[k], f.d[k + 1], f.d[k + row], f.d[k + row + 1]].map(f64::from),
            frac: [cx - i as f64, cy - j as f64],
            out: [(gx - cx) * CELL_M, (gy - cy) * CELL_M],
        }
    }

    /// How far the face-frame point `p` lies outside the face (m, negative inside): with the
    /// features beside it within the band (`reach`), or the face alone.
    pub fn distance_m(&self, p: [f64; 2], reach: bool) -> f64 {
        self.value(if reach { &self.reach } else { &self.core }, p)
    }

    /// The field's distance at `p` (face frame), bilinear between cell centres; beyond the
    /// grid, the edge's distance plus the way out to it.
    #[inline(always)]
    fn value(&self, f: &Field, p: [f64; 2]) -> f64 {
        self.cell(f, p).value()
    }
}

/// A field's cell under a point: see [`Outline::cell`].
struct Cell {
    /// Distances at the corners (m): (0, 0), (1, 0), (0, 1), (1, 1).
    d: [f64; 4],
    /// Where the point lies in the cell, 0 to 1 along x and y.
    frac: [f64; 2],
    /// How far the point lies beyond the grid along x and y (m).
    out: [f64; 2],
}

impl Cell {
    /// The bilinear distance in the cell (m).
    #[inline(always)]
    fn distance(&self) -> f64 {
        let ([d00, d10, d01, d11], [fx, fy]) = (self.d, self.frac);
        d00 * (1.0 - fx) * (1.0 - fy) + d10 * fx * (1.0 - fy) + d01 * (1.0 - fx) * fy + d11 * fx * fy
    }

    /// The field's distance at the point: bilinear in the grid; beyond it, the edge's distance
    /// plus the way out to it (m).
    #[inline(always)]
    fn value(&self) -> f64 {
        match self.beyond() {
            Some((out, _)) => self.distance() + out,
            None => self.distance(),
        }
    }

    /// The gradient of [`Cell::value`]: the bilinear one in the grid, the way out beyond it.
    #[inline(always)]
    fn gradient(&self) -> [f64; 2] {
        match self.beyond() {
            Some((_, g)) => g,
            None => {
                let ([d00, d10, d01, d11], [fx, fy]) = (self.d, self.frac);
                let ddx = ((d10 - d00) * (1.0 - fy) + (d11 - d01) * fy) / CELL_M;
                let ddy = ((d01 - d00) * (1.0 - fx) + (d11 - d10) * fx) / CELL_M;
                [ddx, ddy]
            }
        }
    }

    /// Beyond the grid: how far (m), and the way out (unit).
    #[inline(always)]
    fn beyond(&self) -> Option<(f64, [f64; 2])> {
        let [ox, oy] = self.out;
        if ox == 0.0 && oy == 0.0 {
            return None;
        }
        let out = (ox * ox + oy * oy).sqrt();
        (out > 1e-12).then(|| (out, [ox / out, oy / out]))
    }
}

/// A placement of the outline in the patch's plane: centre `c` (plane basis, m), yaw `t` (rad).
#[derive(Debug, Clone, Copy)]
struct Placement {
    c: [f64; 2],
    t: f64,
}

impl Placement {
    /// Plane point `p` in the face frame.
    fn face_point(&self, p: &[f64; 2]) -> [f64; 2] {
        self.to_face()(p)
    }

    /// The map of plane points to the face frame, its sine and cosine taken once.
    fn to_face(self) -> impl Fn(&[f64; 2]) -> [f64; 2] {
        let (s, c) = self.t.sin_cos();
        let o = self.c;
        move |p| {
            let q = [p[0] - o[0], p[1] - o[1]];
            [c * q[0] + s * q[1], -s * q[0] + c * q[1]]
        }
    }
}

/// A consistent placement of an outline: where the face frame's origin lies in the plane basis
/// (m), its yaw (rad), and how far the consistent yaws spread (rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutlineFit {
    /// The face frame's origin (the fitted face's centre) in the plane basis (m).
    pub center: [f64; 2],
    /// The yaw of the face frame's x axis from e1 toward e2 (rad).
    pub yaw_rad: f64,
    /// The spread of the consistent yaws (rad).
    pub yaw_span_rad: f64,
}

/// The points a placement must hold (`inside`, in `reach`) and keep out (`outside`, of `core`).
struct Problem<'a> {
    o: &'a Outline,
    inside: &'a [[f64; 2]],
    outside: &'a [[f64; 2]],
    tol: f64,
    /// The centroid of all the points (plane basis, m) and the farthest point's distance from it
    /// (m): the lever of a yaw step in the descent's skip bound.
    spread: ([f64; 2], f64),
}

impl<'a> Problem<'a> {
    /// The points `inside` and `outside` of `o`, each violation allowed `tol` (m).
    fn new(o: &'a Outline, inside: &'a [[f64; 2]], outside: &'a [[f64; 2]], tol: f64) -> Self {
        let all = || inside.iter().chain(outside);
        let n = (inside.len() + outside.len()).max(1) as f64;
        let sum = all().fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
        let centroid = [sum[0] / n, sum[1] / n];
        let r2 = all()
            .map(|p| (p[0] - centroid[0]).powi(2) + (p[1] - centroid[1]).powi(2))
            .fold(0.0, f64::max);
        Problem {
            o,
            inside,
            outside,
            tol,
            spread: (centroid, r2.sqrt()),
        }
    }

    /// Whether `x` is consistent: no violation beyond the tolerance.
    fn consistent(&self, x: &Placement) -> bool {
        let to_face = x.to_face();
        self.inside
            .iter()
            .all(|p| self.o.value(&self.o.reach, to_face(p)) <= self.tol)
            && self
                .outside
                .iter()
                .all(|q| self.o.value(&self.o.core, to_face(q)) >= -self.tol)
    }

    /// Gauss-Newton on the violations from `x`: the placement it reaches, and whether it is
    /// consistent.
    ///
    /// A point that does not violate is skipped while it provably cannot: the fields change by
    /// at most [`LIPSCHITZ`] per metre a point moves, and a step of the placement moves every
    /// point by at most the centre's step plus the yaw step times the point's lever. So the
    /// violations, their gradients and their sums are exactly those of evaluating every point.
    fn descend(&self, x: Placement) -> Option<Placement> {
        self.descend_skipping(x, LIPSCHITZ)
    }

    /// [`Problem::descend`] with the fields' change per metre a point moves taken as `lipschitz`
    /// (infinite: every point is read at every step).
    fn descend_skipping(&self, mut x: Placement, lipschitz: f64) -> Option<Placement> {
        // Each point's margin before it can violate, plus `lipschitz` x the bound on how far the
        // points had moved when it was read (m); `moved_m` is that bound now.
        let mut margin: Vec<f64> = vec![f64::NEG_INFINITY; self.inside.len() + self.outside.len()];
        let mut moved_m = 0.0;
        let (centroid, radius_m) = self.spread;
        for it in 0..ITERATIONS {
            // Normal equations in (cx, cy, t).
            let mut jtj = nalgebra::Matrix3::<f64>::zeros();
            let mut jtr = Vector3::<f64>::zeros();
            let mut cost = 0.0;
            let (s, c) = x.t.sin_cos();
            let mut add = |r: f64, g: [f64; 2], pf: [f64; 2]| {
                // d(face point)/dc = -R(-t); d/dt = -J p_face.
                let jc = [-(c * g[0] - s * g[1]), -(s * g[0] + c * g[1])];
                let jt = g[0] * pf[1] - g[1] * pf[0];
                let jrow = Vector3::new(jc[0], jc[1], jt);
                jtj += jrow * jrow.transpose();
                jtr += jrow * r;
                cost += r * r;
            };
            let to_face = x.to_face();
            let reach_now = lipschitz * moved_m + SKIP_GUARD_M;
            let (margin_in, margin_out) = margin.split_at_mut(self.inside.len());
            // The gradient only where a point violates (most do not, near the end), from the
            // cell its value was read from.
            for (p, m) in self.inside.iter().zip(margin_in) {
                if *m > reach_now {
                    continue;
                }
                let pf = to_face(p);
                let cell = self.o.cell(&self.o.reach, pf);
                let d = cell.value();
                if d > 0.0 {
                    add(d, cell.gradient(), pf);
                }
                *m = -d + lipschitz * moved_m;
            }
            for (q, m) in self.outside.iter().zip(margin_out) {
                if *m > reach_now {
                    continue;
                }
                let pf = to_face(q);
                let cell = self.o.cell(&self.o.core, pf);
                let d = cell.value();
                if d < 0.0 {
                    let g = cell.gradient();
                    add(-d, [-g[0], -g[1]], pf);
                }
                *m = d + lipschitz * moved_m;
            }
            if cost == 0.0 {
                break;
            }
            // A start still far off after a few steps leads nowhere.
            let rms = (cost / (self.inside.len() + self.outside.len()).max(1) as f64).sqrt();
            if it >= STALL_ITERATIONS && rms > STALL_RMS_M {
                return None;
            }
            // Levenberg damping, the yaw scaled to a 10 mm lever.
            let damp = 1e-3 * jtj.trace().max(1e-12);
            let a = jtj + nalgebra::Matrix3::from_diagonal(&Vector3::new(damp, damp, damp * 1e-4));
            let step = a.lu().solve(&(-jtr))?;
            let step_len = step[0].hypot(step[1]) + 0.01 * step[2].abs();
            let scale = (0.002 / step_len.max(1e-300)).min(1.0);
            let next = Placement {
                c: [x.c[0] + scale * step[0], x.c[1] + scale * step[1]],
                t: x.t + scale * step[2],
            };
            // |R(-t')(p - c') - R(-t)(p - c)| <= |c' - c| + |t' - t| |p - c|, and
            // |p - c| <= |p - centroid| + |centroid - c|.
            let lever_m = radius_m + (x.c[0] - centroid[0]).hypot(x.c[1] - centroid[1]);
            moved_m += (next.c[0] - x.c[0]).hypot(next.c[1] - x.c[1]) + (next.t - x.t).abs() * lever_m;
            x = next;
            if step_len * scale < 1e-7 {
                break;
            }
        }
        self.consistent(&x).then_some(x)
    }

    /// How many steps `dir` (a consistent) `x` can be moved and stay consistent, at most
    /// `max_steps` each way: (steps back, steps forward). By bisection: the consistent
    /// placements along a line are taken as one interval.
    fn reach_along(&self, x: &Placement, dir: [f64; 3], max_steps: i32) -> (i32, i32) {
        let moved = |k: i32| Placement {
            c: [x.c[0] + k as f64 * dir[0], x.c[1] + k as f64 * dir[1]],
            t: x.t + k as f64 * dir[2],
        };
        let reach = |sign: i32| {
            if self.consistent(&moved(sign * max_steps)) {
                return max_steps;
            }
            // Consistent at lo, not at hi.
            let (mut lo, mut hi) = (0, max_steps);
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                if self.consistent(&moved(sign * mid)) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        (reach(-1), reach(1))
    }
}

/// The consistent placements of `o` with a patch: `inside` its points in the plane basis (m)
/// (`edge`, the patch's boundary points among them, are what the starts are fitted to),
/// `outside` the points behind it; starts at the yaws `theta0` plus quarter turns (the patch's
/// minimum-area rectangle), each with the patch's box centred on and cornered into the outline's
/// box. Each distinct consistent placement pinned down within [`FIT_AMBIGUITY_M`] along both
/// plane axes and within `yaw_span_max_rad` in yaw, centred in those ranges.
pub fn fit_outline(
    o: &Outline,
    inside: &[[f64; 2]],
    edge: &[[f64; 2]],
    outside: &[[f64; 2]],
    theta0: f64,
    yaw_span_max_rad: f64,
) -> Vec<OutlineFit> {
    // Each placement at the strictest of the two tolerances it meets (the rectangle fit's: strict,
    // else the plane's error).
    let problems = |tol: f64| {
        (
            Problem::new(o, edge, outside, tol),
            Problem::new(o, inside, outside, tol),
        )
    };
    let (loose_edge, loose_full) = problems(FIT_VIOLATION_M);
    let (strict_edge, strict_full) = problems(0.1 * FIT_VIOLATION_M);
    let (rlo, rhi) = o.reach_box;
    // (placement, strict).
    let mut found: Vec<(Placement, bool)> = Vec::new();
    for q in 0..4 {
        let t = theta0 + q as f64 * std::f64::consts::FRAC_PI_2;
        // The patch's box in the frame turned by t.
        let probe = Placement { c: [0.0, 0.0], t };
        let (lo, hi) = bounds(&edge.iter().map(|p| probe.face_point(p)).collect::<Vec<_>>());
        let mid = |a: usize| (lo[a] + hi[a] - rlo[a] - rhi[a]) / 2.0;
        let starts = [
            [mid(0), mid(1)],
            [lo[0] - rlo[0], lo[1] - rlo[1]],
            [hi[0] - rhi[0], lo[1] - rlo[1]],
            [lo[0] - rlo[0], hi[1] - rhi[1]],
            [hi[0] - rhi[0], hi[1] - rhi[1]],
        ];
        // At this yaw the patch's box must fit the outline's, each side within the loose
        // tolerance, or no placement at it is consistent: a long patch is not tried across a
        // long outline's short side.
        if (0..2).any(|a| hi[a] - lo[a] > rhi[a] - rlo[a] + 2.0 * FIT_VIOLATION_M) {
            continue;
        }
        // A patch as large as the outline (within a millimetre) is not occluded: the centred
        // start suffices.
        let whole = (0..2).all(|a| hi[a] - lo[a] >= rhi[a] - rlo[a] - 0.001);
        for d in starts.into_iter().take(if whole { 1 } else { starts.len() }) {
            // Face frame = R(-t) p - d, so c = R(t) d.
            let (s, c) = t.sin_cos();
            let x = Placement {
                c: [c * d[0] - s * d[1], s * d[0] + c * d[1]],
                t,
            };
            let Some(x) = loose_edge.descend(x) else { continue };
            if !loose_full.consistent(&x) {
                continue;
            }
            let found_one = match strict_edge.descend(x).filter(|y| strict_full.consistent(y)) {
                Some(y) => (y, true),
                None => (x, false),
            };
            // One consistent start per quarter turn is enough.
            if !found.iter().any(|f| same(&f.0, &found_one.0)) {
                found.push(found_one);
            }
            break;
        }
    }
    // Strict placements, if any, else the loose ones.
    let any_strict = found.iter().any(|f| f.1);
    let mut out: Vec<OutlineFit> = Vec::new();
    for (x, strict) in found {
        if any_strict && !strict {
            continue;
        }
        let (edge_p, full_p) = if strict {
            (&strict_edge, &strict_full)
        } else {
            (&loose_edge, &loose_full)
        };
        let max_m = (FIT_AMBIGUITY_M / SCAN_STEP_M) as i32 + 1;
        let max_t = (yaw_span_max_rad / SCAN_STEP_RAD) as i32 + 1;
        let (b0, f0) = edge_p.reach_along(&x, [SCAN_STEP_M, 0.0, 0.0], max_m);
        let (b1, f1) = edge_p.reach_along(&x, [0.0, SCAN_STEP_M, 0.0], max_m);
        let (bt, ft) = edge_p.reach_along(&x, [0.0, 0.0, SCAN_STEP_RAD], max_t);
        if (b0 + f0) as f64 * SCAN_STEP_M > FIT_AMBIGUITY_M
            || (b1 + f1) as f64 * SCAN_STEP_M > FIT_AMBIGUITY_M
            || (bt + ft) as f64 * SCAN_STEP_RAD > yaw_span_max_rad
        {
            continue;
        }
        let mid = Placement {
            c: [
                x.c[0] + (f0 - b0) as f64 / 2.0 * SCAN_STEP_M,
                x.c[1] + (f1 - b1) as f64 / 2.0 * SCAN_STEP_M,
            ],
            t: x.t + (ft - bt) as f64 / 2.0 * SCAN_STEP_RAD,
        };
        let best = if full_p.consistent(&mid) { mid } else { x };
        if !out.iter().any(|g| {
            same(
                &Placement {
                    c: g.center,
                    t: g.yaw_rad,
                },
                &best,
            )
        }) {
            out.push(OutlineFit {
                center: best.c,
                yaw_rad: best.t,
                yaw_span_rad: (bt + ft) as f64 * SCAN_STEP_RAD,
            });
        }
    }
    out
}

/// Whether two placements are one (centre within [`SAME_M`], yaw within [`SAME_RAD`]).
fn same(a: &Placement, b: &Placement) -> bool {
    let dt = (a.t - b.t).rem_euclid(std::f64::consts::TAU);
    (a.c[0] - b.c[0]).hypot(a.c[1] - b.c[1]) < SAME_M && dt.min(std::f64::consts::TAU - dt) < SAME_RAD
}

/// The part-frame point `p` in `fitted`'s face frame (m): from its centre, along `along` and
/// `normal x along`.
fn face_frame(fitted: &Face) -> impl Fn(&Vector3<f64>) -> [f64; 2] + '_ {
    let (ex, ey) = (fitted.along, fitted.normal.cross(&fitted.along));
    move |p| {
        let q = p - fitted.center;
        [q.dot(&ex), q.dot(&ey)]
    }
}

/// The lowest and highest coordinates of `pts` (m).
fn bounds(pts: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    pts.iter().fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), p| {
        ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
    })
}

/// The area `reach` adds to `core` (m^2): cells inside `reach` and more than a cell outside
/// `core` (the two rasterize a shared edge a cell apart).
fn band_area_m2(core_d: &[f32], reach_d: &[f32]) -> f64 {
    core_d
        .iter()
        .zip(reach_d)
        .filter(|(c, r)| **r < 0.0 && **c as f64 > CELL_M)
        .count() as f64
        * CELL_M
        * CELL_M
}

/// Even-odd point in polygon.
fn in_polygon(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut inside = false;
    let n = poly.len();
    for k in 0..n {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// Point in triangle (either winding), edges included.
fn in_triangle(t: &[[f64; 2]; 3], p: [f64; 2]) -> bool {
    let s = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
    let (d0, d1, d2) = (s(t[0], t[1]), s(t[1], t[2]), s(t[2], t[0]));
    (d0 >= 0.0 && d1 >= 0.0 && d2 >= 0.0) || (d0 <= 0.0 && d1 <= 0.0 && d2 <= 0.0)
}

/// Signed distance (m) of each cell centre to the boundary of the cells marked in `mask`
/// (negative inside), from the exact Euclidean distance transforms of the mask and its
/// complement (Felzenszwalb and Huttenlocher), less half a cell: the boundary lies between cells.
fn signed_distance(mask: &[bool], n: [usize; 2]) -> Vec<f32> {
    let to_in = edt(mask, n, true);
    let to_out = edt(mask, n, false);
    mask.iter()
        .enumerate()
        .map(|(k, &m)| {
            let d = if m {
                -(to_out[k].sqrt() - 0.5)
            } else {
                to_in[k].sqrt() - 0.5
            };
            (d * CELL_M) as f32
        })
        .collect()
}

/// Squared distance (cells) of each cell to the nearest cell whose mask equals `target`.
fn edt(mask: &[bool], n: [usize; 2], target: bool) -> Vec<f64> {
    const FAR: f64 = 1e12;
    let [nx, ny] = n;
    let mut g: Vec<f64> = mask.iter().map(|&m| if m == target { 0.0 } else { FAR }).collect();
    let mut f = vec![0.0; nx.max(ny)];
    let mut d = vec![0.0; nx.max(ny)];
    // Columns, then rows.
    for i in 0..nx {
        for j in 0..ny {
            f[j] = g[j * nx + i];
        }
        edt_1d(&f[..ny], &mut d[..ny]);
        for j in 0..ny {
            g[j * nx + i] = d[j];
        }
    }
    for j in 0..ny {
        f[..nx].copy_from_slice(&g[j * nx..(j + 1) * nx]);
        edt_1d(&f[..nx], &mut d[..nx]);
        g[j * nx..(j + 1) * nx].copy_from_slice(&d[..nx]);
    }
    g
}

/// One dimension of the squared distance transform: `d[q] = min_p (q - p)^2 + f[p]` (the lower
/// envelope of parabolas).
fn edt_1d(f: &[f64], d: &mut [f64]) {
    let n = f.len();
    let mut v = vec![0usize; n];
    let mut z = vec![0.0f64; n + 1];
    let mut k = 0usize;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    let meet = |q: usize, p: usize| ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64));
    for q in 1..n {
        let mut s = meet(q, v[k]);
        while s <= z[k] {
            k -= 1;
            s = meet(q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, out) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let p = v[k];
        *out = (q as f64 - p as f64).powi(2) + f[p];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A regular hexagon 14 mm across flats with a 6.8 mm bore (the standoff's end), in the
    /// frame of its minimum-area rectangle (corners along x).
    fn hexagon_ring() -> Outline {
        let r = 0.014 / 3f64.sqrt();
        let outer: Vec<[f64; 2]> = (0..6)
            .map(|k| {
                let a = std::f64::consts::FRAC_PI_3 * k as f64;
                [r * a.cos(), r * a.sin()]
            })
            .collect();
        let bore: Vec<[f64; 2]> = (0..36)
            .rev()
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 36.0;
                [0.0034 * a.cos(), 0.0034 * a.sin()]
            })
            .collect();
        let face = Face {
            center: Vector3::zeros(),
            normal: Vector3::z(),
            along: Vector3::x(),
            extent_m: [2.0 * r, 0.014],
            disc: false,
            hole_radius_m: 0.0,
        };
        let empty = Mesh {
            vertices_m: Vec::new(),
            triangles: Vec::new(),
        };
        Outline::of_rings(outer, vec![bore], &face, &empty)
    }

    /// The points a patch of `inside_face` (face frame) would give on a 0.5 mm pixel grid with the
    /// outline placed at (c, t): the inside points, the boundary ones among them, and the
    /// outside points (grid points within 1 mm of the inside ones, not in it).
    fn patch(inside_face: impl Fn([f64; 2]) -> bool, c: [f64; 2], t: f64) -> [Vec<[f64; 2]>; 3] {
        let x = Placement { c, t };
        let step = 0.0005;
        let (mut inside, mut edge, mut outside) = (Vec::new(), Vec::new(), Vec::new());
        let is_in = |p: [f64; 2]| inside_face(x.face_point(&p));
        for i in -24..=24 {
            for j in -24..=24 {
                let p = [i as f64 * step + 0.0001, j as f64 * step - 0.0002];
                let near = |d: i32| {
                    (-d..=d).any(|a| (-d..=d).any(|b| is_in([p[0] + a as f64 * step, p[1] + b as f64 * step])))
                };
                if is_in(p) {
                    inside.push(p);
                    let ring = [[step, 0.0], [-step, 0.0], [0.0, step], [0.0, -step]];
                    if ring.iter().any(|o| !is_in([p[0] + o[0], p[1] + o[1]])) {
                        edge.push(p);
                    }
                } else if near(2) {
                    outside.push(p);
                }
            }
        }
        [inside, edge, outside]
    }

    /// The patch of `o` (the hexagon ring) placed at a centre and yaw off the origin: the
    /// centre, the yaw, and [`patch`]'s point sets.
    fn hexagon_patch(o: &Outline) -> ([f64; 2], f64, [Vec<[f64; 2]>; 3]) {
        let (c, t) = ([0.0004, -0.0003], 17f64.to_radians());
        let hex = |p: [f64; 2]| o.value(&o.core, p) < 0.0;
        (c, t, patch(hex, c, t))
    }

    /// The hexagon ring's outline is placed within 0.15 mm and 1 degree of where its patch lies
    /// (up to its sixfold turns), from the patch alone. Negative control: a patch filling the
    /// hexagon's bounding rectangle (what the rectangle fit assumed) is consistent with no
    /// placement: its corners lie outside the hexagon.
    #[test]
    fn a_hexagon_ring_is_placed_by_its_true_outline_and_a_rectangle_patch_is_not() {
        let o = hexagon_ring();
        let (c, t, [inside, edge, outside]) = hexagon_patch(&o);
        let theta0 = super::super::min_area_theta(&super::super::convex_hull(&inside));
        let fits = fit_outline(&o, &inside, &edge, &outside, theta0, 12f64.to_radians());
        assert!(!fits.is_empty(), "no fit");
        for f in &fits {
            let dp = (f.center[0] - c[0]).hypot(f.center[1] - c[1]);
            let dt = (f.yaw_rad - t).rem_euclid(std::f64::consts::FRAC_PI_3);
            let dt = dt.min(std::f64::consts::FRAC_PI_3 - dt);
            assert!(dp < 0.00015 && dt < 1f64.to_radians(), "fit {f:?}: {dp} m, {dt} rad");
        }
        let r = 0.014 / 3f64.sqrt();
        let rect = |p: [f64; 2]| p[0].abs() < r && p[1].abs() < 0.007 && p[0].hypot(p[1]) > 0.0034;
        let [inside, edge, outside] = patch(rect, c, t);
        let theta0 = super::super::min_area_theta(&super::super::convex_hull(&inside));
        assert!(fit_outline(&o, &inside, &edge, &outside, theta0, 12f64.to_radians()).is_empty());
    }

    /// The descent that skips points which provably do not violate reaches bit for bit the
    /// placement of the one that reads every point at every step, from starts near and far off
    /// the truth. Negative control: with the fields taken as flat (no change as points move), a
    /// point once clear is never read again, and the descents differ.
    #[test]
    fn skipping_clear_points_leaves_the_descent_unchanged() {
        let o = hexagon_ring();
        let (c, t, [_, edge, outside]) = hexagon_patch(&o);
        let problem = Problem::new(&o, &edge, &outside, FIT_VIOLATION_M);
        let bits = |x: Option<Placement>| x.map(|x| [x.c[0].to_bits(), x.c[1].to_bits(), x.t.to_bits()]);
        let (mut reached, mut flat_differs) = (0, 0);
        for k in 0..40 {
            let a = k as f64 * 0.7;
            let start = Placement {
                c: [c[0] + 0.003 * a.cos() * (k % 5) as f64 / 4.0, c[1] + 0.002 * a.sin()],
                t: t + (k as f64 - 20.0).to_radians() * 1.5,
            };
            let every = problem.descend_skipping(start, f64::INFINITY);
            assert_eq!(bits(problem.descend(start)), bits(every), "start {k}");
            reached += usize::from(every.is_some());
            flat_differs += usize::from(bits(problem.descend_skipping(start, 0.0)) != bits(every));
        }
        assert!(reached >= 10, "only {reached} of 40 starts reached a placement");
        assert!(
            flat_differs >= 10,
            "the flat fields changed only {flat_differs} of 40 descents"
        );
    }

    /// The gradient the descent reads is the slope of the value it reads: inside a cell (where
    /// the bilinear distance is smooth) central differences agree with it; beyond the grid, a
    /// step along it adds the step's length. Negative control: the gradient with its components
    /// swapped disagrees with the differences.
    #[test]
    fn the_gradient_is_the_slope_of_the_value() {
        let o = hexagon_ring();
        let h = 1e-7;
        let (mut inside, mut beyond, mut swapped_off) = (0, 0, 0);
        // A 0.37 mm lattice across the grid and 5 mm beyond it (the extrapolated distance).
        for a in -40..=40 {
            for b in -40..=40 {
                let p = [a as f64 * 0.00037, b as f64 * 0.00037];
                for f in [&o.core, &o.reach] {
                    let cell = o.cell(f, p);
                    let g = cell.gradient();
                    if cell.beyond().is_some() {
                        let step = o.value(f, [p[0] + h * g[0], p[1] + h * g[1]]) - cell.value();
                        assert!(
                            (step - h).abs() < 1e-4 * h,
                            "beyond, at {p:?}: {step} for a step of {h}"
                        );
                        beyond += 1;
                        continue;
                    }
                    if cell.frac.iter().any(|&t| !(1e-3..=1.0 - 1e-3).contains(&t)) {
                        continue;
                    }
                    let slope = [
                        (o.value(f, [p[0] + h, p[1]]) - o.value(f, [p[0] - h, p[1]])) / (2.0 * h),
                        (o.value(f, [p[0], p[1] + h]) - o.value(f, [p[0], p[1] - h])) / (2.0 * h),
                    ];
                    assert!(
                        (slope[0] - g[0]).abs() < 1e-6 && (slope[1] - g[1]).abs() < 1e-6,
                        "at {p:?}: slope {slope:?}, gradient {g:?}"
                    );
                    inside += 1;
                    swapped_off += usize::from((slope[0] - g[1]).abs() > 0.1 || (slope[1] - g[0]).abs() > 0.1);
                }
            }
        }
        assert!(inside > 1000 && beyond > 0, "{inside} points inside, {beyond} beyond");
        assert!(
            swapped_off > 100,
            "the swapped gradient agreed at all but {swapped_off} points"
        );
    }

    #[test]
    fn the_distance_transform_matches_brute_force() {
        let n = [23, 17];
        let mask: Vec<bool> = (0..n[0] * n[1])
            .map(|k| {
                let (i, j) = ((k % n[0]) as f64, (k / n[0]) as f64);
                (i - 8.0).hypot(j - 7.0) < 5.5 || (i > 15.0 && j > 10.0)
            })
            .collect();
        let got = edt(&mask, n, true);
        for (k, got_k) in got.iter().enumerate() {
            let (i, j) = ((k % n[0]) as f64, (k / n[0]) as f64);
            let want = (0..mask.len())
                .filter(|&m| mask[m])
                .map(|m| (i - (m % n[0]) as f64).powi(2) + (j - (m / n[0]) as f64).powi(2))
                .fold(f64::INFINITY, f64::min);
            assert_eq!(*got_k, want, "cell {k}");
        }
    }
}
