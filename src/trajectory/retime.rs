//! The robot's side of TOPP-RA: a blended trajectory's path by arc length, the joint speed,
//! acceleration and torque constraints along it, and the retimed motion.
//!
//! Job: turn a blended [`Trajectory`] into a geometric path q(s) with s the fraction of its
//! joint-space arc length, express the robot's limits along it as linear constraints in
//! (u, x) = (s'', s'^2) for the generic [`time_optimal`] ([`RobotPathConstraints`]), and sample
//! the result in time as a [`Motion`] ([`Retimed`]). [`toppra`] composes the three.
//!
//! Units: s a fraction of the arc length (0 to 1); rad, rad/s, rad/s^2, N m, s.
//! Frames: joint space.

use super::toppra::{PathConstraints, PathTiming, StageRow, time_optimal};
use super::{Motion, Sample, Trajectory};
use crate::robot::dynamics::Terms;
use crate::robot::{DOF, DynamicsModel, JointVector, RobotModel};

/// Instants at which [`ArcPath`] tabulates a trajectory's arc length.
const ARC_TABLE_STEPS: usize = 4000;

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
    /// Tabulates the arc length of `path` at 4001 instants (4000 equal steps in time).
    pub fn new(path: &Trajectory) -> Self {
        let n = ARC_TABLE_STEPS;
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
            // At rest (the ends): the path leaves along the first blend's acceleration and arrives
            // against the last one's (a deceleration), straight. The tangent points along the
            // path at both ends: a torque row with it reversed would take gravity's sign wrong.
            let along = if t < 0.5 * self.path.duration_s { p.qdd } else { -p.qdd };
            let dir = along.try_normalize(1e-12).unwrap_or_else(JointVector::zeros);
            return (p.q, dir * self.length, JointVector::zeros());
        }
        let sdot = speed / self.length;
        let sddot = p.qd.dot(&p.qdd) / (speed * self.length);
        let qp = p.qd / sdot;
        let qpp = (p.qdd - qp * sddot) / (sdot * sdot);
        (p.q, qp, qpp)
    }
}

/// Shares of the limits TOPP-RA plans with. The constraints hold at the grid points only: the
/// bound uses the full limits ([`Shares::BOUND`]); a motion to execute keeps a little back for
/// the stages between grid points ([`Shares::EXECUTE`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shares {
    /// Of each torque limit.
    pub torque: f64,
    /// Of each acceleration cap (none without a cap: [`RobotModel::accel_cap_rad_s2`]).
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

/// The robot's limits along an [`ArcPath`] as TOPP-RA constraints: per joint, the speed limit,
/// the acceleration cap if the robot has one ([`RobotModel::accel_cap_rad_s2`]: the
/// specification accelerations with `robot.drives.accel_cap = "spec"`; without it there are no
/// acceleration rows, the torque alone binds) and the torque limit, each times its [`Shares`]
/// share.
///
/// Torques are linear in (u, x): tau = a u + b x + c, with a = M q', b = M q'' + C(q, q') q',
/// c = gravity + Coulomb friction (the joints' friction parameters; at the ends, at rest, full
/// Coulomb friction against whichever way the drive pushes, as in the torque check of the
/// accelerator); viscous friction (linear in
/// s', not in s'^2) is bounded by its value at the stage's top speed and taken from the torque
/// margin, which keeps the result feasible (slightly conservative).
#[derive(Debug, Clone)]
pub struct RobotPathConstraints<'a> {
    robot: &'a RobotModel,
    dynamics: &'a DynamicsModel,
    path: &'a ArcPath,
    shares: Shares,
    torque_limit_nm: JointVector,
    vel_limit_rad_s: JointVector,
    accel_limit_rad_s2: Option<JointVector>,
}

impl<'a> RobotPathConstraints<'a> {
    /// The limits of `robot` with `dynamics` (payload included) along `path`, at `shares` of them.
    pub fn new(robot: &'a RobotModel, dynamics: &'a DynamicsModel, path: &'a ArcPath, shares: Shares) -> Self {
        RobotPathConstraints {
            robot,
            dynamics,
            path,
            shares,
            torque_limit_nm: robot.torque_limit_nm(),
            vel_limit_rad_s: robot.max_vel_rad_s(),
            accel_limit_rad_s2: robot.accel_cap_rad_s2(),
        }
    }
}

impl PathConstraints for RobotPathConstraints<'_> {
    fn end_s(&self) -> f64 {
        1.0
    }

    fn rows(&self, s: f64) -> Vec<StageRow> {
        let rigid = Terms {
            gravity: false,
            friction: false,
            armature: true,
        };
        let zero = JointVector::zeros();
        let shares = &self.shares;
        let (q, qp, qpp) = self.path.at(s);
        let a = self.dynamics.inverse_dynamics_terms(&q, &zero, &qp, rigid);
        let b = self.dynamics.inverse_dynamics_terms(&q, &qp, &qpp, rigid);
        let g = self.dynamics.gravity_torques(&q);
        let mut rows = Vec::with_capacity(4 * DOF + 2);
        let mut xmax = f64::INFINITY;
        for i in 0..DOF {
            if qp[i].abs() > 1e-9 {
                xmax = xmax.min((shares.speed * self.vel_limit_rad_s[i] / qp[i].abs()).powi(2));
            }
        }
        let sdot_max = xmax.sqrt();
        // The path starts and ends at rest, where friction is at its worst
        // ([`DynamicsModel::drive_torque_bound_nm`]): the drive breaks away against full Coulomb
        // friction in the direction it accelerates (arriving, against the motion), not helped by
        // it. Without an acceleration cap nothing else holds the last stage's deceleration.
        let at_rest = s <= 0.0 || s >= self.end_s();
        for i in 0..DOF {
            let j = &self.robot.joints[i];
            let moving = qp[i].abs() > 1e-9 && !at_rest;
            let coulomb = j.coulomb_nm * qp[i].signum() * if moving { 1.0 } else { 0.0 };
            let breakaway = if at_rest { j.coulomb_nm } else { 0.0 };
            let viscous = j.viscous_nm_s_per_rad * qp[i].abs() * if sdot_max.is_finite() { sdot_max } else { 0.0 };
            let c = g[i] + coulomb;
            // With Shares::EXECUTE, 2 % of the limit is kept back for what happens between grid points.
            let cap = shares.torque * self.torque_limit_nm[i] - viscous - breakaway;
            rows.push(StageRow::new(a[i], b[i], cap - c));
            rows.push(StageRow::new(-a[i], -b[i], cap + c));
            if let Some(cap) = &self.accel_limit_rad_s2 {
                rows.push(StageRow::new(qp[i], qpp[i], shares.accel * cap[i]));
                rows.push(StageRow::new(-qp[i], -qpp[i], shares.accel * cap[i]));
            }
        }
        if xmax.is_finite() {
            rows.push(StageRow::new(0.0, 1.0, xmax));
        }
        rows
    }
}

/// A path retimed by TOPP-RA: the arc-length path of a trajectory and the time-optimal s(t)
/// under speed and torque limits (and the acceleration cap, if any).
#[derive(Debug, Clone)]
pub struct Retimed {
    path: ArcPath,
    timing: PathTiming,
}

impl Retimed {
    /// Squared path speeds at the grid (for inspection).
    pub fn path_speeds(&self) -> &[f64] {
        self.timing.path_speeds()
    }

    /// The timing of the arc-length fraction.
    pub fn timing(&self) -> &PathTiming {
        &self.timing
    }
}

impl Motion for Retimed {
    fn duration_s(&self) -> f64 {
        self.timing.duration_s()
    }
    fn at(&self, t: f64) -> Sample {
        let p = self.timing.at(t);
        let (q, qp, qpp) = self.path.at(p.s);
        Sample {
            t_s: p.t_s,
            q,
            qd: qp * p.s_dot,
            qdd: qp * p.s_ddot + qpp * (p.s_dot * p.s_dot),
        }
    }
}

/// TOPP-RA on `path`'s geometry: the time-optimal retiming under the joint speed limits, the
/// acceleration cap if the robot has one, and the torque limits with `dynamics` (payload included), at
/// `shares` of each, on `grid` stages ([`RobotPathConstraints`] solved by [`time_optimal`]).
/// Returns `None` if the path cannot be followed even slowly (a static overload).
pub fn toppra(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    path: &Trajectory,
    grid: usize,
    shares: Shares,
) -> Option<Retimed> {
    let arc = ArcPath::new(path);
    let timing = time_optimal(&RobotPathConstraints::new(robot, dynamics, &arc, shares), grid)?;
    Some(Retimed { path: arc, timing })
}
