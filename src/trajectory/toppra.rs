//! TOPP-RA: the time-optimal timing of a fixed path under linear constraints, generic.
//!
//! Job: given a path parameter s in [0, end] and, at every s, linear constraints on the path
//! acceleration u = s'' and the squared path speed x = s'^2 (rows a u + b x <= r, from any
//! source: joint speeds, accelerations, torques, a tool's force), find the fastest s(t) from rest
//! to rest that meets them at the grid points. Reachability analysis (Pham and Pham, 2018): on a
//! grid of stages, a backward pass computes each stage's controllable set of x by two
//! 2-variable linear programs, then a forward pass takes greedily the largest u that keeps the
//! next x controllable. Between grid points u is constant (x is linear in s), which gives the
//! times. The algorithm knows nothing of robots or joint counts: [`PathConstraints`] is all it
//! reads (the robot's constraints are one implementation, in the `retime` module).
//!
//! Units: s in the path's own unit (written (p): a fraction, metres, radians), u [p/s^2],
//! x [p^2/s^2], times (s). Frames: none (a scalar path parameter).

/// One linear constraint of a grid stage: `a u + b x <= r` in (u, x) = (s'', s'^2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageRow {
    /// Coefficient of the path acceleration u = s'' [units of r / (p/s^2)].
    pub a: f64,
    /// Coefficient of the squared path speed x = s'^2 [units of r / (p^2/s^2)].
    pub b: f64,
    /// Bound.
    pub r: f64,
}

impl StageRow {
    /// The row `a u + b x <= r`.
    pub const fn new(a: f64, b: f64, r: f64) -> Self {
        StageRow { a, b, r }
    }
}

/// The constraints a path is retimed under: linear in (u, x) = (s'', s'^2) at every path
/// position s in [0, [`PathConstraints::end_s`]].
pub trait PathConstraints {
    /// End of the path parameter's range (p); it starts at 0.
    fn end_s(&self) -> f64;
    /// The constraint rows at path position `s` (p). `x >= 0` is implied (the algorithm adds it);
    /// an upper bound on x (a speed limit) must be given as a row when the other rows do not
    /// bound x.
    fn rows(&self, s: f64) -> Vec<StageRow>;
}

/// The time-optimal timing found by [`time_optimal`]: squared path speeds and times at the grid
/// points, u constant between them.
#[derive(Debug, Clone)]
pub struct PathTiming {
    /// Grid positions s_i (p).
    s: Vec<f64>,
    /// Squared path speeds x_i = (ds/dt)^2 at the grid points [p^2/s^2].
    x: Vec<f64>,
    /// Times at the grid points (s).
    t: Vec<f64>,
}

/// Where the path is at one instant of a [`PathTiming`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathPoint {
    /// Time, clamped to the timing (s).
    pub t_s: f64,
    /// Path position (p).
    pub s: f64,
    /// Path speed s' [p/s].
    pub s_dot: f64,
    /// Path acceleration s'' [p/s^2].
    pub s_ddot: f64,
}

impl PathTiming {
    /// Duration from rest to rest (s).
    pub fn duration_s(&self) -> f64 {
        *self.t.last().unwrap_or(&0.0)
    }

    /// Grid positions (p).
    pub fn grid_s(&self) -> &[f64] {
        &self.s
    }

    /// Squared path speeds at the grid [p^2/s^2].
    pub fn path_speeds(&self) -> &[f64] {
        &self.x
    }

    /// Times at the grid (s).
    pub fn times_s(&self) -> &[f64] {
        &self.t
    }

    /// Path position, speed and acceleration at time `t` (s) (clamped to the timing): constant
    /// acceleration between grid points.
    pub fn at(&self, t: f64) -> PathPoint {
        let t = t.clamp(0.0, self.duration_s());
        let i = match self.t.partition_point(|&ti| ti <= t) {
            0 => 0,
            k => (k - 1).min(self.s.len() - 2),
        };
        let ds = self.s[i + 1] - self.s[i];
        let u = (self.x[i + 1] - self.x[i]) / (2.0 * ds);
        let v0 = self.x[i].max(0.0).sqrt();
        let tau = t - self.t[i];
        let sdot = (v0 + u * tau).max(0.0);
        let s = (self.s[i] + v0 * tau + 0.5 * u * tau * tau).clamp(self.s[i], self.s[i + 1]);
        PathPoint {
            t_s: t,
            s,
            s_dot: sdot,
            s_ddot: u,
        }
    }
}

/// Upper bound on x that keeps every stage's linear program bounded [p^2/s^2].
const X_CAP: f64 = 1e6;

/// A 2-variable linear program max (or min) c . (u, x) over a u + b x <= r rows: vertex
/// enumeration (every pair of constraint lines), exact for bounded feasible sets.
fn lp2(rows: &[StageRow], cu: f64, cx: f64) -> Option<(f64, f64)> {
    let mut best: Option<(f64, (f64, f64))> = None;
    let feasible = |u: f64, x: f64| {
        rows.iter()
            .all(|&StageRow { a, b, r }| a * u + b * x <= r + 1e-9 * (1.0 + r.abs()))
    };
    for i in 0..rows.len() {
        for j in (i + 1)..rows.len() {
            let StageRow { a: a1, b: b1, r: r1 } = rows[i];
            let StageRow { a: a2, b: b2, r: r2 } = rows[j];
            let det = a1 * b2 - a2 * b1;
            if det.abs() < 1e-12 {
                continue;
            }
            let u = (r1 * b2 - r2 * b1) / det;
            let x = (a1 * r2 - a2 * r1) / det;
            if feasible(u, x) {
                let v = cu * u + cx * x;
                if best.is_none_or(|(bv, _)| v > bv) {
                    best = Some((v, (u, x)));
                }
            }
        }
    }
    best.map(|(_, p)| p)
}

/// TOPP-RA on `grid` stages (at least 2) over `constraints`: the time-optimal timing from rest
/// to rest, or `None` if the path cannot be followed even slowly (some stage has no feasible
/// (u, x) that keeps the rest of the path controllable, e.g. a static overload).
///
/// Each stage also honours the next grid point's constraints with x_{i+1} = x_i + 2 ds u
/// (first-order interpolation): where the constraints jump between grid points, a stage
/// straddling the jump must satisfy both sides.
pub fn time_optimal(constraints: &impl PathConstraints, grid: usize) -> Option<PathTiming> {
    let n = grid.max(2);
    let end = constraints.end_s();
    let s: Vec<f64> = (0..=n).map(|k| k as f64 / n as f64 * end).collect();
    let ds = end / n as f64;
    // Stage constraints, x >= 0 last.
    let stage: Vec<Vec<StageRow>> = s
        .iter()
        .map(|&si| {
            let mut rows = constraints.rows(si);
            rows.push(StageRow::new(0.0, -1.0, 0.0));
            rows
        })
        .collect();
    let stage: Vec<Vec<StageRow>> = (0..=n)
        .map(|i| {
            let mut rows = stage[i].clone();
            if i < n {
                rows.extend(
                    stage[i + 1]
                        .iter()
                        .map(|&StageRow { a, b, r }| StageRow::new(a + 2.0 * ds * b, b, r)),
                );
            }
            rows
        })
        .collect();
    // Backward pass: controllable sets K_i = [lo, hi] of x.
    let mut k = vec![(0.0f64, 0.0f64); n + 1];
    for i in (0..n).rev() {
        let mut rows = stage[i].clone();
        // x + 2 ds u in K_{i+1}.
        rows.push(StageRow::new(2.0 * ds, 1.0, k[i + 1].1));
        rows.push(StageRow::new(-2.0 * ds, -1.0, -k[i + 1].0));
        rows.push(StageRow::new(0.0, 1.0, X_CAP));
        let hi = lp2(&rows, 0.0, 1.0)?.1;
        let lo = lp2(&rows, 0.0, -1.0)?.1;
        k[i] = (lo.max(0.0), hi);
    }
    if k[0].0 > 1e-12 {
        return None;
    }
    // Forward pass: from rest, the largest u that keeps the next x controllable.
    let mut x = vec![0.0; n + 1];
    for i in 0..n {
        let (mut ulo, mut uhi) = (f64::NEG_INFINITY, f64::INFINITY);
        for &StageRow { a, b, r } in stage[i].iter().chain(
            [
                StageRow::new(2.0 * ds, 1.0, k[i + 1].1),
                StageRow::new(-2.0 * ds, -1.0, -k[i + 1].0),
            ]
            .iter(),
        ) {
            let rr = r - b * x[i];
            if a > 1e-15 {
                uhi = uhi.min(rr / a);
            } else if a < -1e-15 {
                ulo = ulo.max(rr / a);
            }
        }
        let u = if uhi >= ulo - 1e-9 { uhi } else { ulo };
        x[i + 1] = (x[i] + 2.0 * ds * u).clamp(k[i + 1].0, k[i + 1].1);
    }
    let mut t = vec![0.0; n + 1];
    for i in 0..n {
        let v = x[i].max(0.0).sqrt() + x[i + 1].max(0.0).sqrt();
        t[i + 1] = t[i] + if v > 0.0 { 2.0 * ds / v } else { f64::INFINITY };
    }
    if !t[n].is_finite() {
        return None;
    }
    Some(PathTiming { s, x, t })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight 1-D path of `length_m` with |s''| <= `accel_m_s2` and s' <= `speed_m_s`.
    struct Straight {
        length_m: f64,
        speed_m_s: f64,
        accel_m_s2: f64,
    }

    impl PathConstraints for Straight {
        fn end_s(&self) -> f64 {
            self.length_m
        }
        fn rows(&self, _s: f64) -> Vec<StageRow> {
            vec![
                StageRow::new(1.0, 0.0, self.accel_m_s2),
                StageRow::new(-1.0, 0.0, self.accel_m_s2),
                StageRow::new(0.0, 1.0, self.speed_m_s * self.speed_m_s),
            ]
        }
    }

    /// The rest-to-rest minimum time: a trapezoid, or a triangle when the top speed is not reached.
    fn closed_form_s(p: &Straight) -> f64 {
        let (l, v, a) = (p.length_m, p.speed_m_s, p.accel_m_s2);
        if l >= v * v / a {
            l / v + v / a
        } else {
            2.0 * (l / a).sqrt()
        }
    }

    /// Checks the timing keeps the limits between grid points and ends where the path does.
    fn check_profile(p: &Straight, timing: &PathTiming) {
        let n = 2000;
        for k in 0..=n {
            let pt = timing.at(timing.duration_s() * k as f64 / n as f64);
            assert!(
                pt.s_dot <= p.speed_m_s * (1.0 + 1e-9),
                "speed {} at {}",
                pt.s_dot,
                pt.t_s
            );
            assert!(
                pt.s_ddot.abs() <= p.accel_m_s2 * (1.0 + 1e-9),
                "accel {} at {}",
                pt.s_ddot,
                pt.t_s
            );
            assert!((0.0..=p.length_m).contains(&pt.s));
        }
        let end = timing.at(timing.duration_s());
        assert!((end.s - p.length_m).abs() < 1e-12 && end.s_dot.abs() < 1e-6, "{end:?}");
        let start = timing.at(0.0);
        assert!(start.s == 0.0 && start.s_dot == 0.0);
    }

    #[test]
    fn straight_path_recovers_the_trapezoid_and_the_triangle_within_grid_error() {
        let cases = [
            // Cruise reached: 2.1 m at 1 m/s with 2 m/s^2: 2.1 s at top speed + 0.5 s of ramps.
            Straight {
                length_m: 2.1,
                speed_m_s: 1.0,
                accel_m_s2: 2.0,
            },
            // Top speed never reached: a triangle of 2 sqrt(L / a).
            Straight {
                length_m: 0.21,
                speed_m_s: 1.0,
                accel_m_s2: 2.0,
            },
            // Exactly at the switch: L = v^2 / a.
            Straight {
                length_m: 0.5,
                speed_m_s: 1.0,
                accel_m_s2: 2.0,
            },
        ];
        for p in &cases {
            let exact = closed_form_s(p);
            let mut previous_error = f64::INFINITY;
            // Odd grids: the profile's corners fall between grid points.
            for grid in [51, 201, 801] {
                let timing = time_optimal(p, grid).expect("feasible");
                let error = (timing.duration_s() - exact).abs() / exact;
                // The grid's error: a corner between two grid points costs a speed deficit of
                // order ds over a path of order ds, so second order in the stage (measured: 9e-5
                // at 51 stages, 1.2e-6 at 801).
                assert!(
                    error <= 4.0 / (grid * grid) as f64,
                    "L = {} m, grid {grid}: {} s vs {exact} s",
                    p.length_m,
                    timing.duration_s()
                );
                // Never faster than the optimum (the limits hold at the grid and in between).
                assert!(timing.duration_s() >= exact * (1.0 - 1e-9));
                assert!(error <= previous_error + 1e-12, "finer grid, larger error");
                previous_error = error;
                check_profile(p, &timing);
            }
        }
    }

    /// A path with a speed-dependent acceleration bound (drag): s'' <= a - c s'^2 while
    /// accelerating, |s''| <= a braking; no speed limit of its own (the drag bounds it).
    struct Dragged {
        length_m: f64,
        accel_m_s2: f64,
        drag_per_m: f64,
    }

    impl PathConstraints for Dragged {
        fn end_s(&self) -> f64 {
            self.length_m
        }
        fn rows(&self, _s: f64) -> Vec<StageRow> {
            vec![
                StageRow::new(1.0, self.drag_per_m, self.accel_m_s2),
                StageRow::new(-1.0, 0.0, self.accel_m_s2),
            ]
        }
    }

    #[test]
    fn a_speed_dependent_bound_is_followed_to_its_closed_form() {
        let p = Dragged {
            length_m: 1.0,
            accel_m_s2: 3.0,
            drag_per_m: 2.0,
        };
        let (a, c, l) = (p.accel_m_s2, p.drag_per_m, p.length_m);
        // Accelerating: x(s) = (a / c) (1 - e^(-2 c s)); braking: x(s) = 2 a (L - s). They meet at
        // s1; the times are arccosh(e^(c s1)) / sqrt(a c) and sqrt(2 (L - s1) / a).
        let gap = |s: f64| (a / c) * (1.0 - (-2.0 * c * s).exp()) - 2.0 * a * (l - s);
        let (mut lo, mut hi) = (0.0, l);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if gap(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let s1 = 0.5 * (lo + hi);
        let exact = (c * s1).exp().acosh() / (a * c).sqrt() + (2.0 * (l - s1) / a).sqrt();
        let timing = time_optimal(&p, 1000).expect("feasible");
        let error = (timing.duration_s() - exact).abs() / exact;
        assert!(error < 2e-3, "{} s vs {exact} s", timing.duration_s());
        // The drag holds at every grid point.
        for (&x, &s) in timing.path_speeds().iter().zip(timing.grid_s()) {
            assert!(x <= a / c * (1.0 + 1e-9), "x = {x} at s = {s}");
        }
    }

    /// [`Straight`] with a "gravity" row 0 u + 0 x <= `headroom` on [from, to]: a load no motion
    /// changes, within the limit when `headroom` >= 0, a static overload when it is negative.
    struct Loaded {
        path: Straight,
        from_m: f64,
        to_m: f64,
        headroom: f64,
    }

    impl PathConstraints for Loaded {
        fn end_s(&self) -> f64 {
            self.path.end_s()
        }
        fn rows(&self, s: f64) -> Vec<StageRow> {
            let mut rows = self.path.rows(s);
            if (self.from_m..=self.to_m).contains(&s) {
                rows.push(StageRow::new(0.0, 0.0, self.headroom));
            }
            rows
        }
    }

    #[test]
    fn a_static_overload_anywhere_on_the_path_is_infeasible() {
        let path = || Straight {
            length_m: 1.0,
            speed_m_s: 1.0,
            accel_m_s2: 2.0,
        };
        for (from_m, to_m) in [(0.0, 1.0), (0.0, 0.0), (0.4, 0.6), (1.0, 1.0)] {
            // Exactly at the limit: feasible, and no slower than without the row.
            let at_limit = Loaded {
                path: path(),
                from_m,
                to_m,
                headroom: 0.0,
            };
            let timing = time_optimal(&at_limit, 100).expect("a load at the limit is feasible");
            let free = time_optimal(&path(), 100).expect("feasible");
            assert_eq!(timing.duration_s(), free.duration_s());
            // 1 % above it: no u satisfies the row, whatever the speed.
            let over = Loaded {
                path: path(),
                from_m,
                to_m,
                headroom: -0.01,
            };
            assert!(
                time_optimal(&over, 100).is_none(),
                "overload on [{from_m}, {to_m}] accepted"
            );
        }
    }

    /// A path that can only be entered braking (s'' <= -1 at the start): from rest it cannot move.
    struct BrakeOnly;

    impl PathConstraints for BrakeOnly {
        fn end_s(&self) -> f64 {
            1.0
        }
        fn rows(&self, s: f64) -> Vec<StageRow> {
            let mut rows = vec![
                StageRow::new(1.0, 0.0, 1.0),
                StageRow::new(-1.0, 0.0, 1.0),
                StageRow::new(0.0, 1.0, 1.0),
            ];
            if s < 0.5 {
                rows.push(StageRow::new(1.0, 0.0, -0.5));
            }
            rows
        }
    }

    #[test]
    fn a_path_that_cannot_start_from_rest_is_infeasible() {
        assert!(time_optimal(&BrakeOnly, 100).is_none());
    }
}
