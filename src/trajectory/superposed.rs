//! Two motions overlapped in time: the second starts before the first has ended, their joint
//! displacements, velocities and accelerations added (a controller's blending by superposition).
//!
//! Job: the straight lift with the part and the Place transfer after it, the transfer started
//! while the part is still rising, as one motion; or a window of it in time, so the lift's head
//! and the overlapped rest can be played as the Pick's end and the Place's start. Likewise a
//! transfer and the straight descent after it, the descent started while the transfer ends. The second
//! motion must start where the first ends, both at rest there; the sum then runs continuously in
//! position, velocity and acceleration. [`overlap_end`] picks how far to overlap: the largest
//! share of the line whose overlap is clear, within the torques and within the cup's holding
//! force where both move (outside that stretch each motion is as checked on its own).
//!
//! Units: s, rad. Frames: joint space.

use super::{CORRIDOR_CHECK_DT_S, LineMotion, Motion, Sample, TORQUE_DT_S, Trajectory};
use super::{check_corridor, seal_overload, torques};
use crate::geometry::SealBudget;
use crate::planning::CollisionModel;
use crate::robot::{DynamicsModel, RobotModel};

/// What an overlap must keep to where both motions move.
pub struct OverlapCheck<'a> {
    /// The robot the tool's force is computed with.
    pub robot: &'a RobotModel,
    /// The accelerator's robot: its torque limits (less the cell's margin) are the limits here.
    pub accel_robot: &'a RobotModel,
    /// The accelerator's dynamics with the payload the motions carry.
    pub dynamics: &'a DynamicsModel,
    /// The corridor must be clear in this model.
    pub model: &'a CollisionModel,
    /// With a part held: what it may ask of the cup.
    pub seal: Option<&'a SealBudget>,
    /// Each joint's torque stays within this share of the accelerator's limits, or within what
    /// either motion alone demands there if that is more.
    pub torque_share: f64,
    /// Start times are rounded to this grid (s) (the physics step).
    pub grid_s: f64,
}

/// `second` started while `first` ends, by the largest of `shares` of `line_s` (the duration of
/// the line among the two: the lift, or the descent) that passes `check` where both move; None
/// when none passes.
pub fn overlap_end<A: Motion + Clone, B: Motion + Clone>(
    first: &A,
    second: &B,
    line_s: f64,
    shares: &[f64],
    check: &OverlapCheck<'_>,
) -> Option<Overlapped<A, B>> {
    let peak = |samples: &[Sample]| torques(check.dynamics, check.accel_robot, samples, TORQUE_DT_S).peak_ratio;
    shares.iter().find_map(|share| {
        let start_s = ((first.duration_s() - share * line_s) / check.grid_s).round() * check.grid_s;
        if start_s <= 0.0 || start_s >= first.duration_s() {
            return None;
        }
        let o = Overlapped::new(first.clone(), second.clone(), start_s);
        let both = o.both();
        let samples = both.sampled(TORQUE_DT_S);
        let alone_first: Vec<Sample> = samples.iter().map(|x| first.at(start_s + x.t_s)).collect();
        let alone_second: Vec<Sample> = samples.iter().map(|x| second.at(x.t_s)).collect();
        let (p1, p2) = (peak(&alone_first), peak(&alone_second));
        let ok = check
            .seal
            .is_none_or(|b| seal_overload(check.robot, &both, TORQUE_DT_S, b) <= 0.0)
            && peak(&samples)
                .iter()
                .enumerate()
                .all(|(i, r)| *r <= check.torque_share.max(p1[i]).max(p2[i]))
            && check_corridor(check.model, &both, CORRIDOR_CHECK_DT_S).is_ok();
        ok.then_some(o)
    })
}

/// `second` started `start_s` into `first`, the two added, seen from `from_s` to `until_s`.
/// By default a lift and the transfer after it; any two motions (an overlap among them).
#[derive(Debug, Clone)]
pub struct Overlapped<A = LineMotion, B = Trajectory> {
    first: A,
    second: B,
    start_s: f64,
    from_s: f64,
    until_s: f64,
}

impl<A: Motion + Clone, B: Motion + Clone> Overlapped<A, B> {
    /// The whole overlap: `second` starts `start_s` into `first` (0 ≤ `start_s` ≤ its duration).
    pub fn new(first: A, second: B, start_s: f64) -> Self {
        let start_s = start_s.clamp(0.0, first.duration_s());
        let until_s = (start_s + second.duration_s()).max(first.duration_s());
        Overlapped {
            first,
            second,
            start_s,
            from_s: 0.0,
            until_s,
        }
    }

    /// When the second motion starts, from the first's start (s).
    pub fn start_s(&self) -> f64 {
        self.start_s
    }

    /// The first motion alone, up to where the second starts.
    pub fn head(&self) -> Self {
        self.window(0.0, self.start_s)
    }

    /// From where the second motion starts to the end of both.
    pub fn rest(&self) -> Self {
        let until_s = (self.start_s + self.second.duration_s()).max(self.first.duration_s());
        self.window(self.start_s, until_s)
    }

    /// Where both move: from where the second starts to where the first ends (empty when the
    /// second starts after the first has ended).
    pub fn both(&self) -> Self {
        self.window(self.start_s, self.first.duration_s().max(self.start_s))
    }

    /// The first motion.
    pub fn first(&self) -> &A {
        &self.first
    }

    /// The same overlap seen from `from_s` to `until_s` (times from the first motion's start).
    pub fn window(&self, from_s: f64, until_s: f64) -> Self {
        Overlapped {
            from_s,
            until_s,
            ..self.clone()
        }
    }
}

impl<A: Motion + Clone, B: Motion + Clone> Motion for Overlapped<A, B> {
    fn duration_s(&self) -> f64 {
        (self.until_s - self.from_s).max(0.0)
    }

    fn at(&self, t: f64) -> Sample {
        let t_abs = self.from_s + t.clamp(0.0, self.duration_s());
        let a = if t_abs < self.first.duration_s() {
            self.first.at(t_abs)
        } else {
            let end = self.first.at(self.first.duration_s());
            Sample {
                qd: end.qd * 0.0,
                qdd: end.qdd * 0.0,
                ..end
            }
        };
        let origin = self.second.at(0.0).q;
        let (dq, qd, qdd) = if t_abs > self.start_s {
            let b = self.second.at((t_abs - self.start_s).min(self.second.duration_s()));
            (b.q - origin, b.qd, b.qdd)
        } else {
            (origin * 0.0, origin * 0.0, origin * 0.0)
        };
        Sample {
            t_s: t,
            q: a.q + dq,
            qd: a.qd + qd,
            qdd: a.qdd + qdd,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LoadedScene;
    use crate::robot::{JointVector, Payload, RobotModel, tool_down_pose};
    use crate::trajectory::{LineLimits, MotionLimits, straight_line};
    use nalgebra::Vector3;

    /// A lift 5 cm up and a transfer after it, overlapped by half the lift: the head is the
    /// lift's, the rest ends where the transfer ends, head and rest meet in position and velocity,
    /// the whole is shorter than the two one after the other, and where both move it is their sum.
    #[test]
    fn an_overlap_is_the_sum_of_its_motions_and_joins_its_head_and_rest() {
        let scene = LoadedScene::embedded_default().unwrap();
        let robot = RobotModel::from_scene(&scene).unwrap();
        let from = tool_down_pose(Vector3::new(0.10, 0.45, 0.05), 0.0);
        let to = tool_down_pose(Vector3::new(0.10, 0.45, 0.10), 0.0);
        let q0 = robot
            .ik_tool_nearest(&from, &JointVector::from(scene.scene.robot.home_rad()))
            .unwrap()
            .q;
        let dynamics = robot.dynamics(&Payload::from_gripper(&scene.scene.gripper));
        let limits = LineLimits {
            speed_m_s: 1.0,
            accel_m_s2: 20.0,
            wrist_deviation_max_rad: 0.0,
        };
        let lift = straight_line(&robot, &dynamics, &q0, &from, &to, &limits, None).unwrap();
        let q1 = lift.end_q();
        let q2 = q1 + JointVector::new(-1.2, 0.2, -0.3, 0.0, 0.1, 0.4);
        let transfer = Trajectory::through(
            &[q1, q2],
            &MotionLimits {
                vel_rad_s: JointVector::repeat(3.0),
                accel_rad_s2: JointVector::repeat(30.0),
            },
        );
        let start_s = 0.5 * lift.duration_s();
        let o = Overlapped::new(lift.clone(), transfer.clone(), start_s);
        let (head, rest) = (o.head(), o.rest());
        assert!((head.at(0.0).q - q0).amax() < 1e-12);
        assert!((head.at(0.3 * start_s).q - lift.at(0.3 * start_s).q).amax() < 1e-12);
        let (a, b) = (head.at(head.duration_s()), rest.at(0.0));
        assert!((a.q - b.q).amax() < 1e-12 && (a.qd - b.qd).amax() < 1e-9);
        assert!((rest.at(rest.duration_s()).q - q2).amax() < 1e-9);
        assert!(head.duration_s() + rest.duration_s() < lift.duration_s() + transfer.duration_s() - 0.4 * start_s);
        let t = 0.5 * (start_s + lift.duration_s());
        let sum = lift.at(t).qd + transfer.at(t - start_s).qd;
        assert!((o.at(t).qd - sum).amax() < 1e-9);
        // Where both move: from the transfer's start to the lift's end.
        let both = o.both();
        assert!((both.duration_s() - (lift.duration_s() - start_s)).abs() < 1e-12);
        assert!((both.at(0.0).q - o.at(start_s).q).amax() < 1e-12);
    }

    /// J1 swung out and back, the way back overlapping the way out: where both move their
    /// accelerations add on J1 (both towards the way back). Accepted by a generous torque share;
    /// refused when the share is below what the sum demands (the negative control); and a box
    /// put where the accepted overlap's arm passes makes it take a smaller share or none.
    #[test]
    fn an_overlap_is_taken_only_within_the_torques_and_the_corridor() {
        use crate::geometry::NamedBox;
        use crate::planning::{CollisionModel, Environment, PlanStats, RobotSpheres};
        let scene = LoadedScene::embedded_default().unwrap();
        let robot = RobotModel::from_scene(&scene).unwrap();
        let hand = Payload::from_gripper(&scene.scene.gripper);
        let dynamics = robot.dynamics(&hand);
        let spheres = || RobotSpheres::new(&robot, &scene.scene, None);
        let model = CollisionModel::new(&robot, spheres(), Environment::from_scene(&scene.scene));
        let q0 = JointVector::from(scene.scene.robot.home_rad());
        assert!(model.free(&q0, &mut PlanStats::default()));
        let limits = MotionLimits {
            vel_rad_s: JointVector::repeat(2.0),
            accel_rad_s2: JointVector::repeat(8.0),
        };
        let q1 = q0 + JointVector::new(0.6, 0.0, 0.0, 0.0, 0.0, 0.0);
        let out = Trajectory::through(&[q0, q1], &limits);
        let back = Trajectory::through(&[q1, q0], &limits);
        let shares = [0.6, 0.4, 0.2];
        fn check<'a>(
            robot: &'a RobotModel,
            dynamics: &'a DynamicsModel,
            share: f64,
            model: &'a CollisionModel,
        ) -> OverlapCheck<'a> {
            OverlapCheck {
                robot,
                accel_robot: robot,
                dynamics,
                model,
                seal: None,
                torque_share: share,
                grid_s: 0.002,
            }
        }
        let check = |share: f64, model| check(&robot, &dynamics, share, model);
        let line_s = back.duration_s();
        let taken = overlap_end(&out, &back, line_s, &shares, &check(10.0, &model)).expect("a generous share");
        let expect_s = ((out.duration_s() - 0.6 * line_s) / 0.002).round() * 0.002;
        assert!((taken.start_s() - expect_s).abs() < 1e-12);
        // J1's torque where both move is above each motion's alone: refused at any share below.
        let samples = taken.both().sampled(TORQUE_DT_S);
        let sum_peak = torques(&dynamics, &robot, &samples, TORQUE_DT_S).peak_ratio[0];
        let out_peak = torques(&dynamics, &robot, &out.sampled(TORQUE_DT_S), TORQUE_DT_S).peak_ratio[0];
        assert!(sum_peak > 1.2 * out_peak, "J1 {sum_peak} vs {out_peak} alone");
        assert!(overlap_end(&out, &back, line_s, &shares[..1], &check(0.9 * sum_peak, &model)).is_none());
        assert!(overlap_end(&out, &back, line_s, &shares[..1], &check(1.01 * sum_peak, &model)).is_some());
        // A box around the tool where the taken overlap turns back.
        let turn = taken.both().at(0.5 * taken.both().duration_s()).q;
        let mut env = Environment::from_scene(&scene.scene);
        env.boxes.push(NamedBox {
            world_from_box: robot.world_from_tool(&turn),
            half_m: Vector3::repeat(0.01),
            name: "in the way".into(),
        });
        let blocked = CollisionModel::new(&robot, spheres(), env);
        let other = overlap_end(&out, &back, line_s, &shares, &check(10.0, &blocked));
        assert!(other.is_none_or(|o| o.start_s() > taken.start_s() + 1e-9));
    }
}
