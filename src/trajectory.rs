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

/// A timed trajectory through via points with parabolic blends.
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
        assert!(via.len() >= 2, "a trajectory needs two via points");
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
                *b = (0..DOF)
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
        Trajectory {
            via: via.to_vec(),
            seg_vel,
            seg_time,
            blend,
            duration_s,
        }
    }

    /// Position, velocity and acceleration at time `t` (clamped to the trajectory).
    pub fn sample(&self, t: f64) -> Sample {
        let t = t.clamp(0.0, self.duration_s);
        let n = self.seg_time.len();
        // Time of via point j on the linear extension: blend[0]/2 + sum of segment times.
        let mut via_t = Vec::with_capacity(n + 1);
        let mut acc = self.blend[0] / 2.0;
        for k in 0..=n {
            via_t.push(acc);
            if k < n {
                acc += self.seg_time[k];
            }
        }
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
                let a = (after - before) / tb;
                let tau = t - (tv - tb / 2.0);
                // Entering the blend: on the incoming line at via_t - tb/2.
                let p0 = self.via[j] - before * (tb / 2.0);
                return Sample {
                    t,
                    q: p0 + before * tau + a * (0.5 * tau * tau),
                    qd: before + a * tau,
                    qdd: a,
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
    let mut lo = JointVector::zeros();
    let mut hi = spec;
    let mut scale = spec * 0.5;
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
