//! Trajectories: via points to a timed joint trajectory, its torques, and the torque-limited
//! acceleration search (the reference system's §4.2).
//!
//! Job: turn a path of joint via points into a trajectory sampled at 1 ms: straight joint-space
//! segments at a common speed per segment (all joints synchronised: the slowest joint sets the
//! segment time), joined by parabolic blends around each via point (velocity-continuous; the
//! path passes near, not through, inner via points), starting and ending at rest. Evaluate joint
//! torques along it with inverse dynamics including the payload; search per-joint accelerations so
//! every joint's peak torque sits just below its limit.
//!
//! Units: rad, rad/s, rad/s^2, s, N m, J. Frames: joint space.

use serde::Serialize;

use crate::robot::{DOF, DynamicsModel, JointVector, RobotModel};

/// Speed and acceleration limits a trajectory is generated with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    /// Per-joint speed [rad/s].
    pub vel_rad_s: JointVector,
    /// Per-joint acceleration [rad/s^2].
    pub accel_rad_s2: JointVector,
}

/// How smooth the blends between segments are (the smoothing seed's polynomial blends).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Continuity {
    /// Velocity-continuous: parabolic blends (constant acceleration).
    Velocity,
    /// Acceleration-continuous: cubic velocity blend, acceleration zero at both ends.
    Acceleration,
    /// Jerk-continuous: quintic velocity blend, acceleration and jerk zero at both ends.
    Jerk,
}

impl Continuity {
    /// Peak of the normalised acceleration profile: the blend is this much longer than a
    /// parabolic one for the same velocity change and peak acceleration.
    pub fn peak_factor(self) -> f64 {
        match self {
            Continuity::Velocity => 1.0,
            Continuity::Acceleration => 1.5,
            Continuity::Jerk => 1.875,
        }
    }

    /// At blend fraction sigma: the velocity shape s(sigma) from 0 to 1, its derivative, and its
    /// integral from 0 (which is 1/2 at sigma = 1 for every order, so all blends end alike).
    pub fn blend(self, sigma: f64) -> (f64, f64, f64) {
        let x = sigma.clamp(0.0, 1.0);
        match self {
            Continuity::Velocity => (x, 1.0, 0.5 * x * x),
            Continuity::Acceleration => (
                x * x * (3.0 - 2.0 * x),
                6.0 * x * (1.0 - x),
                x * x * x * (1.0 - 0.5 * x),
            ),
            Continuity::Jerk => (
                x * x * x * (10.0 + x * (-15.0 + 6.0 * x)),
                30.0 * x * x * (1.0 - x) * (1.0 - x),
                x * x * x * x * (2.5 + x * (-3.0 + x)),
            ),
        }
    }
}

/// A timed trajectory through via points with polynomial blends.
#[derive(Debug, Clone)]
pub struct Trajectory {
    /// Via points, first and last included.
    pub via: Vec<JointVector>,
    /// Velocity of each linear segment [rad/s].
    seg_vel: Vec<JointVector>,
    /// Duration of each linear segment between via points, blends included [s].
    seg_time: Vec<f64>,
    /// Blend duration at each via point [s].
    blend: Vec<f64>,
    /// When each via point is reached on the linear extension of its segments [s].
    via_t: Vec<f64>,
    /// How smooth the blends are.
    pub continuity: Continuity,
    /// Total duration [s].
    pub duration_s: f64,
}

/// One sample of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time [s].
    pub t: f64,
    /// Positions [rad].
    pub q: JointVector,
    /// Velocities [rad/s].
    pub qd: JointVector,
    /// Accelerations [rad/s^2].
    pub qdd: JointVector,
}

impl Trajectory {
    /// Generates the trajectory through `via` under `limits`. Segment times are the slowest
    /// joint's (distance / speed); blends take the largest velocity change over acceleration
    /// among the joints; segments lengthen until the blends fit in them.
    pub fn through(via: &[JointVector], limits: &MotionLimits) -> Self {
        Self::through_with(via, limits, Continuity::Velocity)
    }

    /// As [`Trajectory::through`], with blends of the given continuity. A smoother blend reaches
    /// the same velocity change with a higher peak acceleration for its length, so it is made
    /// longer by that factor (1, 1.5, 1.875) to keep every joint within its acceleration.
    pub fn through_with(via: &[JointVector], limits: &MotionLimits, continuity: Continuity) -> Self {
        assert!(via.len() >= 2, "a trajectory needs two via points");
        let peak = continuity.peak_factor();
        let n = via.len() - 1;
        let mut seg_time: Vec<f64> = (0..n)
            .map(|k| {
                let d = via[k + 1] - via[k];
                (0..DOF).map(|i| d[i].abs() / limits.vel_rad_s[i]).fold(1e-6, f64::max)
            })
            .collect();
        let mut seg_vel = vec![JointVector::zeros(); n];
        let mut blend = vec![0.0; n + 1];
        // Lengthen segments until every blend fits (a few passes converge).
        for _ in 0..50 {
            for k in 0..n {
                seg_vel[k] = (via[k + 1] - via[k]) / seg_time[k];
            }
            for (j, b) in blend.iter_mut().enumerate() {
                let before = if j == 0 { JointVector::zeros() } else { seg_vel[j - 1] };
                let after = if j == n { JointVector::zeros() } else { seg_vel[j] };
                *b = peak
                    * (0..DOF)
                        .map(|i| (after[i] - before[i]).abs() / limits.accel_rad_s2[i])
                        .fold(0.0, f64::max);
            }
            let mut changed = false;
            for k in 0..n {
                // The linear part of segment k runs from half a blend after via k to half a blend
                // before via k+1: it must not be negative. Growing the segment lowers its speed and
                // so both blends, so the fix-point is reached from above.
                let need = (blend[k] + blend[k + 1]) / 2.0;
                if seg_time[k] < need - 1e-12 {
                    seg_time[k] = need;
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        // The first via point is reached on the linear extension half a blend after the start,
        // and the last half a blend before the end.
        let duration_s = seg_time.iter().sum::<f64>() + blend[0] / 2.0 + blend[n] / 2.0;
        // When each via point is reached on the linear extension: half a blend, then segments.
        let via_t: Vec<f64> = std::iter::once(0.0)
            .chain(seg_time.iter().copied())
            .scan(blend[0] / 2.0, |acc, dt| {
                *acc += dt;
                Some(*acc)
            })
            .collect();
        Trajectory {
            via: via.to_vec(),
            seg_vel,
            seg_time,
            blend,
            via_t,
            continuity,
            duration_s,
        }
    }

    /// The via point whose blend is nearest time `t` (the one to stop at if its blend cuts a corner).
    pub fn via_near(&self, t: f64) -> usize {
        (0..self.via_t.len())
            .min_by(|&a, &b| (self.via_t[a] - t).abs().total_cmp(&(self.via_t[b] - t).abs()))
            .unwrap_or(0)
    }

    /// Position, velocity and acceleration at time `t` (clamped to the trajectory).
    pub fn sample(&self, t: f64) -> Sample {
        let t = t.clamp(0.0, self.duration_s);
        let n = self.seg_time.len();
        let via_t = &self.via_t;
        // Inside a blend around via j?
        for (j, &tv) in via_t.iter().enumerate() {
            let tb = self.blend[j];
            if (t - tv).abs() <= tb / 2.0 + 1e-15 && tb > 0.0 {
                let before = if j == 0 {
                    JointVector::zeros()
                } else {
                    self.seg_vel[j - 1]
                };
                let after = if j == n { JointVector::zeros() } else { self.seg_vel[j] };
                let dv = after - before;
                let tau = t - (tv - tb / 2.0);
                let sigma = tau / tb;
                let (shape, shape_rate, shape_integral) = self.continuity.blend(sigma);
                // Entering the blend: on the incoming line at via_t - tb/2.
                let p0 = self.via[j] - before * (tb / 2.0);
                return Sample {
                    t,
                    q: p0 + before * tau + dv * (tb * shape_integral),
                    qd: before + dv * shape,
                    qdd: dv * (shape_rate / tb),
                };
            }
        }
        // On a linear segment k.
        let k = (0..n).rev().find(|&k| t >= via_t[k]).unwrap_or(0);
        let v = self.seg_vel[k];
        Sample {
            t,
            q: self.via[k] + v * (t - via_t[k]),
            qd: v,
            qdd: JointVector::zeros(),
        }
    }

    /// Samples every `dt_s` from 0 to the end (the end included).
    pub fn samples(&self, dt_s: f64) -> Vec<Sample> {
        let n = (self.duration_s / dt_s).ceil() as usize;
        (0..=n)
            .map(|k| self.sample((k as f64 * dt_s).min(self.duration_s)))
            .collect()
    }
}

/// Torques along a trajectory.
#[derive(Debug, Clone, Serialize)]
pub struct TorqueProfile {
    /// Peak |torque| per joint [N m].
    pub peak_nm: [f64; DOF],
    /// Peak |torque| / limit per joint.
    pub peak_ratio: [f64; DOF],
    /// Energy measure: integral of the sum of squared torques [N^2 m^2 s].
    pub energy: f64,
}

/// Evaluates torques at every sample with inverse dynamics (payload included).
pub fn torques(dynamics: &DynamicsModel, robot: &RobotModel, samples: &[Sample], dt_s: f64) -> TorqueProfile {
    let limit = robot.torque_limit_nm();
    let mut peak = [0.0f64; DOF];
    let mut energy = 0.0;
    for s in samples {
        let tau = dynamics.inverse_dynamics(&s.q, &s.qd, &s.qdd);
        for i in 0..DOF {
            peak[i] = peak[i].max(tau[i].abs());
        }
        energy += tau.norm_squared() * dt_s;
    }
    TorqueProfile {
        peak_nm: peak,
        peak_ratio: std::array::from_fn(|i| peak[i] / limit[i]),
        energy,
    }
}

/// The controller's default parameters: top speeds from the data sheet, and one acceleration
/// setting safe for the worst posture at maximum payload: per joint, 80 % of the torque limit over
/// the largest diagonal inertia found over `samples` seeded random postures with a `payload_kg`
/// point mass at the tool tip, capped at the specification acceleration.
pub fn default_limits(
    robot: &RobotModel,
    hand: &crate::robot::Payload,
    payload_kg: f64,
    samples: usize,
) -> MotionLimits {
    use rand::RngExt;
    let part = crate::robot::Payload::point(
        (payload_kg - hand.mass_kg).max(0.0),
        robot.flange_from_tool.translation.vector,
    );
    let d = robot.dynamics(&hand.combined(&part));
    let mut rng = crate::rng::stream(0, "default-limits");
    let mut worst = [0.0f64; DOF];
    for _ in 0..samples {
        let q = JointVector::from_fn(|i, _| rng.random_range(robot.joints[i].lower_rad..robot.joints[i].upper_rad));
        let m = d.mass_matrix(&q);
        for (i, w) in worst.iter_mut().enumerate() {
            *w = w.max(m[(i, i)]);
        }
    }
    MotionLimits {
        vel_rad_s: robot.max_vel_rad_s(),
        accel_rad_s2: JointVector::from_fn(|i, _| {
            (0.8 * robot.joints[i].torque_limit_nm / worst[i]).min(robot.joints[i].max_accel_rad_s2)
        }),
    }
}

/// Result of the acceleration search.
#[derive(Debug, Clone)]
pub struct Accelerated {
    /// The limits found.
    pub limits: MotionLimits,
    /// The trajectory under them.
    pub trajectory: Trajectory,
    /// Its torques.
    pub torques: TorqueProfile,
    /// Search iterations.
    pub iterations: usize,
}

/// The reference system's §4.2: speed fixed at the top; accelerations start at 50 % of the
/// specification; torques every `dt_s`; each joint's acceleration is bisected until its peak
/// torque is within `threshold` (a fraction of the limit) below its limit, none above.
pub fn optimise_accelerations(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    dt_s: f64,
    threshold: f64,
) -> Accelerated {
    let spec = robot.max_accel_rad_s2();
    search_accelerations(robot, dynamics, via, dt_s, threshold, spec * 0.5, JointVector::zeros())
}

/// The bisection of [`optimise_accelerations`] from a given start and lower bracket (a warm
/// start after a small change of the path).
fn search_accelerations(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    dt_s: f64,
    threshold: f64,
    start: JointVector,
    lower: JointVector,
) -> Accelerated {
    let spec = robot.max_accel_rad_s2();
    let mut lo = lower;
    let mut hi = spec;
    let mut scale = start;
    let vel = robot.max_vel_rad_s();
    let mut best: Option<Accelerated> = None;
    for it in 1..=30 {
        let limits = MotionLimits {
            vel_rad_s: vel,
            accel_rad_s2: scale,
        };
        let trajectory = Trajectory::through(via, &limits);
        let profile = torques(dynamics, robot, &trajectory.samples(dt_s), dt_s);
        let feasible = profile.peak_ratio.iter().all(|r| *r <= 1.0);
        if feasible
            && best
                .as_ref()
                .is_none_or(|b| trajectory.duration_s < b.trajectory.duration_s)
        {
            best = Some(Accelerated {
                limits,
                trajectory: trajectory.clone(),
                torques: profile.clone(),
                iterations: it,
            });
        }
        let mut settled = true;
        for i in 0..DOF {
            let r = profile.peak_ratio[i];
            if r > 1.0 {
                hi[i] = scale[i];
                settled = false;
            } else if r < 1.0 - threshold && scale[i] < spec[i] * 0.999 {
                lo[i] = scale[i];
                settled = false;
            } else {
                continue;
            }
            scale[i] = 0.5 * (lo[i] + hi[i]);
        }
        if settled {
            break;
        }
    }
    let mut out = best.unwrap_or_else(|| {
        // Even the lowest accelerations exceed a limit (a static overload): report the last try.
        let limits = MotionLimits {
            vel_rad_s: vel,
            accel_rad_s2: scale,
        };
        let trajectory = Trajectory::through(via, &limits);
        let torques = torques(dynamics, robot, &trajectory.samples(dt_s), dt_s);
        Accelerated {
            limits,
            trajectory,
            torques,
            iterations: 30,
        }
    });
    out.iterations = out.iterations.max(1);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> MotionLimits {
        MotionLimits {
            vel_rad_s: JointVector::repeat(2.0),
            accel_rad_s2: JointVector::repeat(10.0),
        }
    }

    #[test]
    fn smoother_blends_keep_limits_and_are_continuous_in_acceleration() {
        let via = [
            JointVector::zeros(),
            JointVector::new(1.0, -0.5, 0.3, 0.0, 0.2, 0.0),
            JointVector::new(1.5, 0.2, 0.8, 0.5, -0.3, 1.0),
        ];
        let lim = limits();
        let mut durations = Vec::new();
        for c in [Continuity::Velocity, Continuity::Acceleration, Continuity::Jerk] {
            let t = Trajectory::through_with(&via, &lim, c);
            durations.push(t.duration_s);
            let s = t.samples(0.0005);
            assert!((s.last().unwrap().q - via[2]).amax() < 1e-9, "{c:?} misses the end");
            assert!(s[0].qd.amax() < 1e-12 && s.last().unwrap().qd.amax() < 1e-9);
            let mut worst_jump = 0.0f64;
            for w in s.windows(2) {
                let dt = w[1].t - w[0].t;
                assert!(
                    (w[1].q - w[0].q - (w[0].qd + w[1].qd) * (dt / 2.0)).amax() < 1e-6,
                    "{c:?} position/velocity"
                );
                worst_jump = worst_jump.max((w[1].qdd - w[0].qdd).amax());
            }
            for x in &s {
                assert!(
                    x.qdd.amax() <= lim.accel_rad_s2.amax() + 1e-9,
                    "{c:?} exceeds the acceleration"
                );
            }
            // Parabolic blends jump to full acceleration; smoother ones ramp over 0.5 ms samples.
            match c {
                Continuity::Velocity => assert!(worst_jump > 5.0),
                _ => assert!(worst_jump < 1.0, "{c:?}: acceleration jumps by {worst_jump}"),
            }
        }
        assert!(durations[0] < durations[1] && durations[1] < durations[2]);
    }

    #[test]
    fn single_segment_is_a_trapezoid_from_rest_to_rest() {
        let a = JointVector::zeros();
        let b = JointVector::new(2.0, 1.0, 0.0, 0.0, 0.0, 0.0);
        let t = Trajectory::through(&[a, b], &limits());
        // Trapezoid: 2 rad at 2 rad/s with 10 rad/s^2: cruise 1 s + one ramp of 0.2 s.
        assert!((t.duration_s - 1.2).abs() < 1e-9, "{}", t.duration_s);
        let s0 = t.sample(0.0);
        let s1 = t.sample(t.duration_s);
        assert!((s0.q - a).amax() < 1e-12 && s0.qd.amax() < 1e-12);
        assert!((s1.q - b).amax() < 1e-9 && s1.qd.amax() < 1e-9);
        // The slower joint is synchronised: it moves in proportion.
        let mid = t.sample(0.6);
        assert!((mid.q[1] - mid.q[0] / 2.0).abs() < 1e-12);
    }

    #[test]
    fn samples_are_continuous_and_within_limits() {
        let via = [
            JointVector::zeros(),
            JointVector::new(1.0, -0.5, 0.3, 0.0, 0.2, 0.0),
            JointVector::new(1.5, 0.2, 0.8, 0.5, -0.3, 1.0),
            JointVector::new(0.2, 0.1, 0.2, 0.0, 0.0, 0.0),
        ];
        let lim = limits();
        let t = Trajectory::through(&via, &lim);
        let s = t.samples(0.001);
        for w in s.windows(2) {
            let dt = w[1].t - w[0].t;
            if dt <= 0.0 {
                continue;
            }
            // Positions integrate the velocities; velocities the accelerations (to first order).
            assert!((w[1].q - w[0].q - (w[0].qd + w[1].qd) * (dt / 2.0)).amax() < 1e-6);
            assert!((w[1].qd - w[0].qd).amax() <= lim.accel_rad_s2.amax() * dt + 1e-9);
        }
        for x in &s {
            for i in 0..DOF {
                assert!(x.qd[i].abs() <= lim.vel_rad_s[i] + 1e-9);
                assert!(x.qdd[i].abs() <= lim.accel_rad_s2[i] + 1e-9);
            }
        }
        assert!((s.last().unwrap().q - via[3]).amax() < 1e-9);
        // Inner via points are passed near (within the blend), not through.
        let closest = s.iter().map(|x| (x.q - via[1]).amax()).fold(f64::INFINITY, f64::min);
        assert!(closest < 0.2, "{closest}");
    }
}

/// Anything that can be sampled in time like a trajectory.
pub trait Motion {
    /// Duration [s].
    fn duration_s(&self) -> f64;
    /// Position, velocity and acceleration at `t`.
    fn at(&self, t: f64) -> Sample;
    /// Samples every `dt_s`, end included.
    fn sampled(&self, dt_s: f64) -> Vec<Sample> {
        let n = (self.duration_s() / dt_s).ceil() as usize;
        (0..=n)
            .map(|k| self.at((k as f64 * dt_s).min(self.duration_s())))
            .collect()
    }
}

impl Motion for Trajectory {
    fn duration_s(&self) -> f64 {
        self.duration_s
    }
    fn at(&self, t: f64) -> Sample {
        self.sample(t)
    }
}

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

/// Outcome of the alternating path correction and acceleration search (the reference's §4.3).
#[derive(Debug, Clone)]
pub struct Corrected {
    /// The via points after correction (the input's if no fold helped).
    pub via: Vec<JointVector>,
    /// The accelerated trajectory along them.
    pub accelerated: Accelerated,
    /// Folds kept.
    pub folds: usize,
    /// Folds tried.
    pub tried: usize,
}

/// The reference system's §4.3, alternated with §4.2 until no gain, starting from `accelerated`
/// (the §4.2 result on `via`): in each segment where J1
/// needs the longest time and travels more than `min_j1_rad`, insert a via point at the middle
/// with J2 and J3 moved down the gradient of J1's inertia M11 (folding the arm toward the body),
/// by no more than they can travel out and back within J1's time for the segment; keep the fold
/// only if the re-accelerated motion is faster and, with a collision model, its new edges certify.
pub fn correct_path(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    accelerated: &Accelerated,
    collision: Option<&crate::planning::CollisionModel>,
    min_j1_rad: f64,
) -> Corrected {
    let mut current: Vec<JointVector> = via.to_vec();
    let mut best = accelerated.clone();
    let (mut folds, mut tried) = (0, 0);
    // Folding lowers J1's inertia, which only pays when J1's acceleration is held down by its
    // torque, not by its specification.
    if best.limits.accel_rad_s2[0] >= 0.999 * robot.joints[0].max_accel_rad_s2 {
        return Corrected {
            via: current,
            accelerated: best,
            folds,
            tried,
        };
    }
    let vmax = robot.max_vel_rad_s();
    let mut stats = crate::planning::PlanStats::default();
    for _round in 0..4 {
        let mut improved = false;
        let mut k = 0;
        while k + 1 < current.len() {
            let (a, b) = (current[k], current[k + 1]);
            let d = b - a;
            let t1 = d[0].abs() / vmax[0];
            let j1_limits = (1..DOF).all(|i| d[i].abs() / vmax[i] <= t1);
            if !j1_limits || d[0].abs() < min_j1_rad {
                k += 1;
                continue;
            }
            tried += 1;
            let mid = (a + b) / 2.0;
            // Gradient of M11 in (q2, q3) by central differences.
            let m11 = |q: &JointVector| dynamics.mass_matrix(q)[(0, 0)];
            let h = 1e-4;
            let grad: Vec<f64> = [1usize, 2]
                .iter()
                .map(|&i| {
                    let (mut p, mut m) = (mid, mid);
                    p[i] += h;
                    m[i] -= h;
                    (m11(&p) - m11(&m)) / (2.0 * h)
                })
                .collect();
            let norm = grad[0].hypot(grad[1]);
            if norm < 1e-9 {
                k += 1;
                continue;
            }
            // Out and back within half of J1's segment time each way, at 80 % of top speed.
            let reach = [0.8 * vmax[1] * t1 / 2.0, 0.8 * vmax[2] * t1 / 2.0];
            let step = (reach[0] / (grad[0].abs() / norm).max(1e-9)).min(reach[1] / (grad[1].abs() / norm).max(1e-9));
            // The full fold, half and a quarter of it: the fastest that is safe and helps.
            let mut kept: Option<(Vec<JointVector>, Accelerated)> = None;
            for share in [1.0, 0.5, 0.25] {
                let mut fold = mid;
                fold[1] -= share * step * grad[0] / norm;
                fold[2] -= share * step * grad[1] / norm;
                if !robot.within_limits(&fold, 0.0) {
                    continue;
                }
                let safe = collision
                    .is_none_or(|m| m.certify_edge(&a, &fold, &mut stats) && m.certify_edge(&fold, &b, &mut stats));
                if !safe {
                    continue;
                }
                let mut candidate = current.clone();
                candidate.insert(k + 1, fold);
                let acc = optimise_accelerations(robot, dynamics, &candidate, 0.001, 0.05);
                let to_beat = kept
                    .as_ref()
                    .map_or(best.trajectory.duration_s, |(_, k)| k.trajectory.duration_s);
                let within_torque = acc.torques.peak_ratio.iter().all(|r| *r <= 1.0);
                if within_torque && acc.trajectory.duration_s < to_beat - 1e-6 {
                    kept = Some((candidate, acc));
                }
            }
            if let Some((candidate, acc)) = kept {
                current = candidate;
                best = acc;
                folds += 1;
                improved = true;
                k += 2;
                continue;
            }
            k += 1;
        }
        if !improved {
            break;
        }
    }
    Corrected {
        via: current,
        accelerated: best,
        folds,
        tried,
    }
}

/// Re-checks a timed motion against the collision model: every edge between consecutive samples
/// `dt_s` apart must certify (the blends leave the planned, certified polyline, so the corridor
/// they sweep is checked again). Returns the first time at which it does not.
pub fn check_corridor(model: &crate::planning::CollisionModel, motion: &impl Motion, dt_s: f64) -> Result<(), f64> {
    let mut stats = crate::planning::PlanStats::default();
    let samples = motion.sampled(dt_s);
    for w in samples.windows(2) {
        if !model.certify_edge(&w[0].q, &w[1].q, &mut stats) {
            return Err(w[0].t);
        }
    }
    Ok(())
}

/// §4.2 with the blends kept inside the certified corridor: the accelerated trajectory's corridor
/// is checked every `check_dt_s` (edges between samples certified; the chord of a blend between
/// samples deviates from it by at most a dt^2 / 8: below 1 mrad at 10 ms, under half a
/// millimetre of robot motion, inside the model's 2 mm margin); where it fails, the via point whose blend cuts the corner becomes a stop
/// (duplicated: the arm passes exactly through it) and the search runs again.
pub fn accelerate_in_corridor(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    model: &crate::planning::CollisionModel,
    check_dt_s: f64,
) -> (Vec<JointVector>, Accelerated, usize) {
    let mut via = via.to_vec();
    let mut stops = 0;
    let mut acc = optimise_accelerations(robot, dynamics, &via, 0.001, 0.05);
    loop {
        if stops > 0 {
            // A stop changes little: restart the bisection from the accelerations just found.
            let prev = acc.limits.accel_rad_s2;
            acc = search_accelerations(robot, dynamics, &via, 0.001, 0.05, prev, prev * 0.8);
        }
        match check_corridor(model, &acc.trajectory, check_dt_s) {
            Ok(()) => return (via, acc, stops),
            Err(t) if stops < via.len() => {
                let j = acc.trajectory.via_near(t);
                let dup = j.clamp(1, via.len() - 2);
                if via[dup] == via[dup + 1] || via[dup] == via[dup - 1] {
                    // Already a stop there: nothing more to take out of the blend.
                    return (via, acc, stops);
                }
                via.insert(dup, via[dup]);
                stops += 1;
            }
            Err(_) => return (via, acc, stops),
        }
    }
}

/// The time-optimal bound along a path that may stop at via points: the path is cut at every
/// stop (a duplicated via point), each stop-free piece is retimed by TOPP-RA on the geometry
/// `limits` blend it with, and the durations add up. `None` if a piece is infeasible.
pub fn optimal_duration(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    via: &[JointVector],
    limits: &MotionLimits,
    grid: usize,
) -> Option<f64> {
    let mut total = 0.0;
    let mut start = 0;
    for k in 1..=via.len() {
        if k == via.len() || via[k] == via[k - 1] {
            let piece = &via[start..k];
            if piece.len() >= 2 {
                let path = Trajectory::through(piece, limits);
                total += toppra(robot, dynamics, &path, grid, Shares::BOUND)?.duration_s();
            }
            start = k;
        }
    }
    Some(total)
}

/// The largest specific force the tool exerts on what it holds along `motion`: max |a - g| of
/// the tool centre point, from the forward kinematics sampled every `dt_s` (second differences)
/// [m/s^2]. At rest it is g.
pub fn peak_tool_specific_force(robot: &RobotModel, motion: &impl Motion, dt_s: f64) -> f64 {
    let g = nalgebra::Vector3::new(0.0, 0.0, -crate::robot::GRAVITY_M_S2);
    let p: Vec<nalgebra::Vector3<f64>> = motion
        .sampled(dt_s)
        .iter()
        .map(|s| robot.world_from_tool(&s.q).translation.vector)
        .collect();
    p.windows(3)
        .map(|w| ((w[2] - 2.0 * w[1] + w[0]) / (dt_s * dt_s) - g).norm())
        .fold(crate::robot::GRAVITY_M_S2, f64::max)
}

/// Slows a trajectory through `via` under `limits` uniformly in time (speeds x k, accelerations
/// x k^2, which scales the profile's time by 1/k exactly) until the tool's peak specific force
/// is at most `max_specific_force_m_s2`: a suction cup holds its part only up to a force. Returns
/// the trajectory and k (1 when no slowing was needed). Bisection on k to 2 %.
pub fn limit_tool_force(
    robot: &RobotModel,
    via: &[JointVector],
    limits: &MotionLimits,
    max_specific_force_m_s2: f64,
) -> (Trajectory, f64) {
    const DT_S: f64 = 0.004;
    let at = |k: f64| {
        Trajectory::through(
            via,
            &MotionLimits {
                vel_rad_s: limits.vel_rad_s * k,
                accel_rad_s2: limits.accel_rad_s2 * (k * k),
            },
        )
    };
    let full = at(1.0);
    if peak_tool_specific_force(robot, &full, DT_S) <= max_specific_force_m_s2 {
        return (full, 1.0);
    }
    let (mut lo, mut hi) = (0.05, 1.0);
    while hi - lo > 0.02 {
        let mid = 0.5 * (lo + hi);
        if peak_tool_specific_force(robot, &at(mid), DT_S) <= max_specific_force_m_s2 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (at(lo), lo)
}

/// Speed and acceleration of the tool along a straight line [m/s, m/s^2].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineLimits {
    /// Top tool speed [m/s].
    pub speed_m_s: f64,
    /// Tool acceleration [m/s^2].
    pub accel_m_s2: f64,
}

/// A straight tool line (descent, lift, retreat) with a trapezoidal speed profile along it,
/// sampled every `dt_s`: joint positions by inverse kinematics (nearest to the previous sample),
/// velocities and accelerations by central differences. Sampled linearly in between.
#[derive(Debug, Clone)]
pub struct LineMotion {
    dt_s: f64,
    samples: Vec<Sample>,
    /// The profile's tool acceleration after the torque check [m/s^2].
    pub accel_m_s2: f64,
}

impl Motion for LineMotion {
    fn duration_s(&self) -> f64 {
        self.samples.last().map_or(0.0, |s| s.t)
    }
    fn at(&self, t: f64) -> Sample {
        let n = self.samples.len() - 1;
        let x = (t / self.dt_s).clamp(0.0, n as f64);
        let k = (x.floor() as usize).min(n.saturating_sub(1));
        let f = x - k as f64;
        let (a, b) = (&self.samples[k], &self.samples[(k + 1).min(n)]);
        Sample {
            t,
            q: a.q + (b.q - a.q) * f,
            qd: a.qd + (b.qd - a.qd) * f,
            qdd: a.qdd + (b.qdd - a.qdd) * f,
        }
    }
}

impl LineMotion {
    /// Joint positions at the end.
    pub fn end_q(&self) -> JointVector {
        self.samples.last().map_or_else(JointVector::zeros, |s| s.q)
    }
}

/// Fraction of the torque limit a straight line may use (the servo's feedback needs the rest).
const LINE_TORQUE_SHARE: f64 = 0.85;

/// The straight tool line from `from` (the arm at `q_from`) to `to` under `limits`, slowed until
/// the torques (inverse dynamics with `dynamics`' payload) stay within 85 % of each joint's limit
/// and, with `max_specific_force_m_s2`, the tool's |a - g| within it (a part on a suction cup).
/// `None` if the inverse kinematics fails along the line (limits, singularity) or a joint would
/// jump (a branch change).
pub fn straight_line(
    robot: &RobotModel,
    dynamics: &DynamicsModel,
    q_from: &JointVector,
    from: &nalgebra::Isometry3<f64>,
    to: &nalgebra::Isometry3<f64>,
    limits: &LineLimits,
    max_specific_force_m_s2: Option<f64>,
) -> Option<LineMotion> {
    const DT_S: f64 = 0.001;
    let g = crate::robot::GRAVITY_M_S2;
    let length = (to.translation.vector - from.translation.vector).norm() + 0.05 * from.rotation.angle_to(&to.rotation);
    let mut accel = limits.accel_m_s2;
    if let Some(f) = max_specific_force_m_s2 {
        // |a u - g| <= |a| + g along any direction u.
        accel = accel.min((f - g).max(0.5));
    }
    let limit = robot.torque_limit_nm();
    for _ in 0..12 {
        let v = limits.speed_m_s.min((accel * length).sqrt());
        let t_acc = v / accel;
        let duration = if length <= 1e-9 {
            DT_S
        } else {
            2.0 * t_acc + (length - v * t_acc).max(0.0) / v
        };
        let s_at = |t: f64| -> f64 {
            if length <= 1e-9 {
                return 1.0;
            }
            let t = t.clamp(0.0, duration);
            let d = if t < t_acc {
                0.5 * accel * t * t
            } else if t > duration - t_acc {
                let r = duration - t;
                length - 0.5 * accel * r * r
            } else {
                0.5 * accel * t_acc * t_acc + v * (t - t_acc)
            };
            (d / length).clamp(0.0, 1.0)
        };
        let n = (duration / DT_S).ceil() as usize;
        let mut qs = Vec::with_capacity(n + 1);
        let mut q = *q_from;
        for k in 0..=n {
            let pose = from.lerp_slerp(to, s_at(k as f64 * DT_S));
            let mut next = robot.ik_tool_nearest(&pose, &q).ok()?.q;
            if k > 0 && next[4].abs() < 0.02 {
                // Near the wrist singularity (J5 ~ 0) only J4 + J6 is well determined and the
                // solver's J4 is noise: keep J4, give J6 the sum, if the pose still matches.
                let mut kept = next;
                kept[5] += next[3] - q[3];
                kept[3] = q[3];
                let err = robot.world_from_tool(&kept).inverse() * pose;
                if err.translation.vector.norm() < 2e-5 && err.rotation.angle() < 2e-4 {
                    next = kept;
                }
            }
            if k > 0 && (next - q).amax() > 0.05 {
                return None;
            }
            q = next;
            qs.push(q);
        }
        let samples: Vec<Sample> = (0..=n)
            .map(|k| {
                let (a, b) = (qs[k.saturating_sub(1)], qs[(k + 1).min(n)]);
                let qd = if k == 0 || k == n {
                    JointVector::zeros()
                } else {
                    (b - a) / (2.0 * DT_S)
                };
                let qdd = if k == 0 || k == n {
                    JointVector::zeros()
                } else {
                    (b - qs[k] * 2.0 + a) / (DT_S * DT_S)
                };
                Sample {
                    t: k as f64 * DT_S,
                    q: qs[k],
                    qd,
                    qdd,
                }
            })
            .collect();
        let within = samples.iter().all(|s| {
            let tau = dynamics.inverse_dynamics(&s.q, &s.qd, &s.qdd);
            (0..DOF).all(|i| tau[i].abs() <= LINE_TORQUE_SHARE * limit[i])
        });
        if within {
            return Some(LineMotion {
                dt_s: DT_S,
                samples,
                accel_m_s2: accel,
            });
        }
        accel *= 0.75;
    }
    None
}
