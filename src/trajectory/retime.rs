//! TOPP-RA: the time-optimal retiming of a blended trajectory's path under the robot's joint
//! speed, acceleration and torque limits.
//!
//! Job: turn a blended [`Trajectory`] into a geometric path q(s) with s the fraction of its
//! joint-space arc length ([`ArcPath`]), and find the fastest s(t) along it from rest to rest
//! ([`toppra`]), sampled in time as a [`Motion`] ([`Retimed`]).
//!
//! Units: s a fraction of the arc length (0 to 1); rad, rad/s, rad/s^2, N m, s.
//! Frames: joint space.

use super::{Motion, Sample, Trajectory};
use crate::robot::{DOF, DynamicsModel, JointVector, RobotModel};

/// The geometric path of a trajectory parameterised by joint-space arc length: q(s), s in [0, 1],
/// |q'(s)| constant (the path's length), so no stage of the retiming is singular.
#[derive(Debug, Clone)]
pub struct ArcPath {
    path: Trajectory,
    /// Trajectory times of a fine table and the arc-length fraction reached at each.
    table_t: Vec<f64>,
    table_s: Vec<f64>,
    length: f64,
}

impl ArcPath {
    /// Tabulates the arc length of `path` at 4000 instants.
    pub fn new(path: &Trajectory) -> Self {
        let n = 4000;
        let mut table_t = Vec::with_capacity(n + 1);
        let mut table_s = Vec::with_capacity(n + 1);
        let mut acc = 0.0;
        let mut prev = path.sample(0.0).q;
        for k in 0..=n {
            let t = path.duration_s * k as f64 / n as f64;
            let q = path.sample(t).q;
            acc += (q - prev).norm();
            prev = q;
            table_t.push(t);
            table_s.push(acc);
        }
        let length = acc.max(1e-12);
        table_s.iter_mut().for_each(|v| *v /= length);
        ArcPath {
            path: path.clone(),
            table_t,
            table_s,
            length,
        }
    }

    /// q, q' and q'' at arc-length fraction s.
    pub fn at(&self, s: f64) -> (JointVector, JointVector, JointVector) {
        let s = s.clamp(0.0, 1.0);
        let k = self
            .table_s
            .partition_point(|&v| v < s)
            .clamp(1, self.table_s.len() - 1);
        let (s0, s1) = (self.table_s[k - 1], self.table_s[k]);
        let w = if s1 > s0 { (s - s0) / (s1 - s0) } else { 0.0 };
        let t = self.table_t[k - 1] + w * (self.table_t[k] - self.table_t[k - 1]);
        let p = self.path.sample(t);
        let speed = p.qd.norm();
        if speed < 1e-9 {
            // At rest (the ends): the path leaves along the first blend's acceleration, straight.
            let dir = p.qdd.try_normalize(1e-12).unwrap_or_else(JointVector::zeros);
            return (p.q, dir * self.length, JointVector::zeros());
        }
        let sdot = speed / self.length;
        let sddot = p.qd.dot(&p.qdd) / (speed * self.length);
        let qp = p.qd / sdot;
        let qpp = (p.qdd - qp * sddot) / (sdot * sdot);
        (p.q, qp, qpp)
    }
}

/// A path retimed by TOPP-RA: the arc-length path of a trajectory and the time-optimal s(t)
/// under speed, acceleration and torque limits.
#[derive(Debug, Clone)]
pub struct Retimed {
    path: ArcPath,
    /// Grid positions s_i.
    s: Vec<f64>,
    /// Squared path speeds x_i = (ds/dt)^2 at the grid points.
    x: Vec<f64>,
    /// Times at the grid points [s].
    t: Vec<f64>,
}

impl Retimed {
    fn geometry(&self, s: f64) -> (JointVector, JointVector, JointVector) {
        self.path.at(s)
    }

    /// Squared path speeds at the grid (for inspection).
    pub fn path_speeds(&self) -> &[f64] {
        &self.x
    }
}

impl Motion for Retimed {
    fn duration_s(&self) -> f64 {
        *self.t.last().unwrap_or(&0.0)
    }
    fn at(&self, t: f64) -> Sample {
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
        let (q, qp, qpp) = self.geometry(s);
        Sample {
            t,
            q,
            qd: qp * sdot,
            qdd: qp * u + qpp * (sdot * sdot),
        }
    }
}

/// Shares of the limits TOPP-RA plans with. The constraints hold at the grid points only: the
/// bound uses the full limits ([`Shares::BOUND`]); a motion to execute keeps a little back for
/// the stages between grid points ([`Shares::EXECUTE`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shares {
    /// Of each torque limit.
    pub torque: f64,
    /// Of each specification acceleration.
    pub accel: f64,
    /// Of each speed limit.
    pub speed: f64,
}

impl Shares {
    /// The full limits: the time-optimal bound.
    pub const BOUND: Shares = Shares {
        torque: 1.0,
        accel: 1.0,
        speed: 1.0,
    };
    /// Margins that keep every 1 ms sample within the limits.
    pub const EXECUTE: Shares = Shares {
        torque: 0.98,
        accel: 0.95,
        speed: 0.999,
    };
}

/// A 2-variable linear program max (or min) c . (u, x) over a u + b x <= r rows: vertex
/// enumeration (every pair of constraint lines), exact for bounded feasible sets.
fn lp2(rows: &[(f64, f64, f64)], cu: f64, cx: f64) -> Option<(f64, f64)> {
    let mut best: Option<(f64, (f64, f64))> = None;
    let feasible = |u: f64, x: f64| rows.iter().all(|(a, b, r)| a * u + b * x <= r + 1e-9 * (1.0 + r.abs()));
    for i in 0..rows.len() {
        for j in (i + 1)..rows.len() {
            let (a1, b1, r1) = rows[i];
            let (a2, b2, r2) = rows[j];
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

/// TOPP-RA: the time-optimal parameterisation of `path`'s geometry under the joint speed limits,
/// the specification accelerations and the torque limits with `dynamics` (payload included), on
/// `grid` stages. Each stage's constraints are linear in (u, x) = (s'', s'^2):
/// tau = a u + b x + c, with a = M q', b = M q'' + C(q, q') q', c = gravity + Coulomb friction;
/// viscous friction (linear in s', not in s'^2) is bounded by its value at the stage's top speed
/// and taken from the torque margin, which keeps the result feasible (slightly conservative).
/// Backward pass: controllable sets by two 2-variable LPs per stage; forward pass: greedy.
/// Returns `None` if the path cannot be followed even slowly (a static overload).
pub fn toppra(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    path: &Trajectory,
    grid: usize,
    shares: Shares,
) -> Option<Retimed> {
    use crate::robot::dynamics::Terms;
    let n = grid.max(2);
    let arc = ArcPath::new(path);
    let s: Vec<f64> = (0..=n).map(|k| k as f64 / n as f64).collect();
    let ds = 1.0 / n as f64;
    let lim_tau = robot.torque_limit_nm();
    let vmax = robot.max_vel_rad_s();
    let amax = robot.max_accel_rad_s2();
    let zero = JointVector::zeros();
    let rigid = Terms {
        gravity: false,
        friction: false,
        armature: true,
    };
    // Stage constraints as rows a u + b x <= r.
    let stage: Vec<Vec<(f64, f64, f64)>> = s
        .iter()
        .map(|&si| {
            let (q, qp, qpp) = arc.at(si);
            let a = dynamics.inverse_dynamics_terms(&q, &zero, &qp, rigid);
            let b = dynamics.inverse_dynamics_terms(&q, &qp, &qpp, rigid);
            let g = dynamics.gravity_torques(&q);
            let mut rows = Vec::with_capacity(4 * DOF + 2);
            let mut xmax = f64::INFINITY;
            for i in 0..DOF {
                if qp[i].abs() > 1e-9 {
                    xmax = xmax.min((shares.speed * vmax[i] / qp[i].abs()).powi(2));
                }
            }
            let sdot_max = xmax.sqrt();
            for i in 0..DOF {
                let j = &robot.joints[i];
                let coulomb = j.coulomb_nm * qp[i].signum() * if qp[i].abs() > 1e-9 { 1.0 } else { 0.0 };
                let viscous = j.viscous_nm_s_per_rad * qp[i].abs() * if sdot_max.is_finite() { sdot_max } else { 0.0 };
                let c = g[i] + coulomb;
                // 2 % of the limit is kept back for what happens between grid points.
                let cap = shares.torque * lim_tau[i] - viscous;
                rows.push((a[i], b[i], cap - c));
                rows.push((-a[i], -b[i], cap + c));
                rows.push((qp[i], qpp[i], shares.accel * amax[i]));
                rows.push((-qp[i], -qpp[i], shares.accel * amax[i]));
            }
            if xmax.is_finite() {
                rows.push((0.0, 1.0, xmax));
            }
            rows.push((0.0, -1.0, 0.0));
            rows
        })
        .collect();
    // Each stage also honours the next grid point's constraints with x_{i+1} = x_i + 2 ds u
    // (first-order interpolation): the path's curvature jumps where blends begin and end, and a
    // stage straddling such a jump must satisfy both sides.
    let stage: Vec<Vec<(f64, f64, f64)>> = (0..=n)
        .map(|i| {
            let mut rows = stage[i].clone();
            if i < n {
                rows.extend(stage[i + 1].iter().map(|&(a, b, r)| (a + 2.0 * ds * b, b, r)));
            }
            rows
        })
        .collect();
    // Backward pass: controllable sets K_i = [lo, hi] of x.
    let mut k = vec![(0.0f64, 0.0f64); n + 1];
    for i in (0..n).rev() {
        let mut rows = stage[i].clone();
        // x + 2 ds u in K_{i+1}.
        rows.push((2.0 * ds, 1.0, k[i + 1].1));
        rows.push((-2.0 * ds, -1.0, -k[i + 1].0));
        rows.push((0.0, 1.0, 1e6)); // keep the LP bounded
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
        for &(a, b, r) in stage[i]
            .iter()
            .chain([(2.0 * ds, 1.0, k[i + 1].1), (-2.0 * ds, -1.0, -k[i + 1].0)].iter())
        {
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
    Some(Retimed { path: arc, s, x, t })
}
