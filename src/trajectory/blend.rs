//! Blended trajectories: via points to a timed joint trajectory.
//!
//! Job: straight joint-space segments between via points at a common speed per segment (all
//! joints synchronised: the slowest joint sets the segment time), joined by polynomial blends
//! around each via point (parabolic by default: velocity-continuous; cubic or quintic velocity
//! blends for acceleration or jerk continuity, the smoothing seed's zones). The path passes near,
//! not through, inner via points, and starts and ends at rest.
//!
//! Units: rad, rad/s, rad/s^2, s. Frames: joint space.

use serde::Serialize;

use super::{Motion, Sample, Stretch};
use crate::robot::{DOF, JointVector};

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
    /// Duration of each linear segment between via points, blends included (s).
    seg_time: Vec<f64>,
    /// Blend duration at each via point (s).
    blend: Vec<f64>,
    /// When each via point is reached on the linear extension of its segments (s).
    via_t: Vec<f64>,
    /// How smooth the blends are.
    pub continuity: Continuity,
    /// Total duration (s).
    pub duration_s: f64,
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

    /// The segment velocities before and after via point `j` (zero before the first segment
    /// and after the last: the trajectory starts and ends at rest).
    fn velocities_around(&self, j: usize) -> (JointVector, JointVector) {
        let before = if j == 0 {
            JointVector::zeros()
        } else {
            self.seg_vel[j - 1]
        };
        let after = self.seg_vel.get(j).copied().unwrap_or_else(JointVector::zeros);
        (before, after)
    }

    /// Position, velocity and acceleration at time `t` (clamped to the trajectory).
    pub fn sample(&self, t: f64) -> Sample {
        let t = t.clamp(0.0, self.duration_s);
        let n = self.seg_time.len();
        let via_t = &self.via_t;
        // The blends' edges are matched within a few ulps of the time: `duration_s` and
        // `via_t` are sums taken in different orders, and at the end (t = duration_s) the last
        // blend must hold, however long the trajectory.
        let rounding = 1e-15 + 8.0 * f64::EPSILON * t;
        // Inside a blend around via j?
        for (j, &tv) in via_t.iter().enumerate() {
            let tb = self.blend[j];
            if (t - tv).abs() <= tb / 2.0 + rounding && tb > 0.0 {
                let (before, after) = self.velocities_around(j);
                let dv = after - before;
                let tau = t - (tv - tb / 2.0);
                let sigma = tau / tb;
                let (shape, shape_rate, shape_integral) = self.continuity.blend(sigma);
                // Entering the blend: on the incoming line at via_t - tb/2.
                let p0 = self.via[j] - before * (tb / 2.0);
                return Sample {
                    t_s: t,
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
            t_s: t,
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

impl Motion for Trajectory {
    fn duration_s(&self) -> f64 {
        self.duration_s
    }
    fn at(&self, t: f64) -> Sample {
        self.sample(t)
    }
    /// The linear segments (straight), and the blends: straight where the motion keeps to one
    /// line without turning back (from or to rest, at the start, the end and every stop; between
    /// parallel segments), bent otherwise, by each joint's blend acceleration (its velocity change
    /// over the blend, times the blend's peak factor).
    fn stretches(&self) -> Option<Vec<Stretch>> {
        let n = self.seg_time.len();
        let mut out = Vec::with_capacity(2 * n + 1);
        let mut t = 0.0;
        for (j, &tv) in self.via_t.iter().enumerate() {
            let tb = self.blend[j];
            let (b0, b1) = (
                (tv - tb / 2.0).clamp(0.0, self.duration_s),
                (tv + tb / 2.0).clamp(0.0, self.duration_s),
            );
            if b0 > t {
                out.push(Stretch {
                    t0_s: t,
                    t1_s: b0,
                    bend_rad_s2: JointVector::zeros(),
                });
            }
            if b1 > b0 {
                let (before, after) = self.velocities_around(j);
                let dv = after - before;
                // Along one line without turning back: no speed before, or the change a multiple
                // c >= -1 of the speed before (after = (1 + c) before).
                let b2 = before.norm_squared();
                let straight = b2 == 0.0 || {
                    let c = dv.dot(&before) / b2;
                    c >= -1.0 && (dv - before * c).amax() <= 1e-12 * (1.0 + dv.amax())
                };
                out.push(Stretch {
                    t0_s: b0,
                    t1_s: b1,
                    bend_rad_s2: if straight {
                        JointVector::zeros()
                    } else {
                        dv.abs() * (self.continuity.peak_factor() / tb)
                    },
                });
            }
            t = t.max(b1);
        }
        if self.duration_s > t {
            out.push(Stretch {
                t0_s: t,
                t1_s: self.duration_s,
                bend_rad_s2: JointVector::zeros(),
            });
        }
        Some(out)
    }
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
                let dt = w[1].t_s - w[0].t_s;
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
    fn stretches_cover_the_motion_and_straight_ones_keep_to_their_chord() {
        let via = [
            JointVector::zeros(),
            JointVector::new(1.0, -0.5, 0.3, 0.0, 0.2, 0.0),
            JointVector::new(1.0, -0.5, 0.3, 0.0, 0.2, 0.0),
            JointVector::new(1.5, 0.2, 0.8, 0.5, -0.3, 1.0),
            JointVector::new(0.2, 0.1, 0.2, 0.0, 0.0, 0.0),
        ];
        for c in [Continuity::Velocity, Continuity::Acceleration, Continuity::Jerk] {
            let t = Trajectory::through_with(&via, &limits(), c);
            let st = t.stretches().expect("a trajectory knows its stretches");
            assert_eq!(st[0].t0_s, 0.0);
            assert_eq!(st.last().map(|s| s.t1_s), Some(t.duration_s));
            assert!(st.windows(2).all(|w| w[0].t1_s == w[1].t0_s), "{c:?}: gaps");
            // Bent: only the blend at via 3 (via 1-2 is a stop, 0 and 4 are rest).
            let bent: Vec<&Stretch> = st.iter().filter(|s| s.bend_rad_s2.amax() > 0.0).collect();
            assert_eq!(bent.len(), 1, "{c:?}: {st:?}");
            for s in &st {
                let (a, b) = (t.sample(s.t0_s).q, t.sample(s.t1_s).q);
                for k in 0..=200 {
                    let x = t.sample(s.t0_s + (s.t1_s - s.t0_s) * k as f64 / 200.0);
                    // Within the joint accelerations the stretch claims.
                    for i in 0..DOF {
                        assert!(x.qdd[i].abs() <= s.bend_rad_s2[i] + 1e-9 || s.bend_rad_s2.amax() == 0.0);
                    }
                    if s.bend_rad_s2.amax() == 0.0 {
                        // On the chord between the stretch's ends, between them.
                        let d = b - a;
                        let u = if d.norm_squared() > 0.0 {
                            (x.q - a).dot(&d) / d.norm_squared()
                        } else {
                            0.0
                        };
                        assert!((-1e-9..=1.0 + 1e-9).contains(&u), "{c:?}: off the chord's ends");
                        assert!((x.q - (a + d * u)).amax() < 1e-9, "{c:?}: off the chord");
                    }
                }
            }
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

    /// A carry slowed to the accelerator's floor (time scale 0.05: a few seconds to tens) ends,
    /// sampled at its duration, at its last via point at rest. Its end blend's half-width is
    /// matched within rounding of the time itself: an absolute 1e-15 s, below one ulp of a time
    /// of several seconds, dropped the end onto the last segment's straight extension, a jump
    /// of v tb / 2 (0.32 rad at J1 in the A run that tripped a protective stop 9.09 s into
    /// its Place). Every scale of the same path, from full speed down, is checked.
    #[test]
    fn a_slowed_trajectory_ends_at_its_last_via_point_at_rest() {
        let via = [
            JointVector::new(0.3, -0.2, 0.1, 0.0, 0.5, 0.0),
            JointVector::new(-0.1, 0.3, 0.4, 0.2, 0.1, 0.7),
            JointVector::new(-0.5271, 0.2, 0.9, -0.3, 0.4, 1.3),
            JointVector::new(-0.848, 0.1, 1.0, -0.2, 0.6, 1.1),
        ];
        let mut worst = 0.0f64;
        for i in 0..=200 {
            let k = 0.05 + 0.95 * i as f64 / 200.0;
            let scaled = MotionLimits {
                vel_rad_s: limits().vel_rad_s * k * 0.37,
                accel_rad_s2: limits().accel_rad_s2 * (k * k) * 0.61,
            };
            let t = Trajectory::through(&via, &scaled);
            let end = t.sample(t.duration_s);
            worst = worst.max((end.q - via[3]).amax()).max(end.qd.amax());
        }
        assert!(worst < 1e-9, "an end off its last via point by {worst} rad");
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
            let dt = w[1].t_s - w[0].t_s;
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
