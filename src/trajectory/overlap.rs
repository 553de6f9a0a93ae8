//! Two motions overlapped in time: the second starts before the first has ended, their joint
//! displacements, velocities and accelerations added (a controller's blending by superposition).
//!
//! Job: the straight lift with the part and the Place transfer after it, the transfer started
//! while the part is still rising, as one motion; or a window of it in time, so the lift's head
//! and the overlapped rest can be played as the Pick's end and the Place's start. The second
//! motion must start where the first ends, both at rest there; the sum then runs continuously in
//! position, velocity and acceleration. Whether the overlap is clear, within the torque limits
//! and within the cup's holding force is for the caller to check (`cycle::motions`).
//!
//! Units: s, rad. Frames: joint space.

use super::{LineMotion, Motion, Sample, Trajectory};

/// `second` started `start_s` into `first`, the two added, seen from `from_s` to `until_s`.
#[derive(Debug, Clone)]
pub struct Overlapped {
    first: LineMotion,
    second: Trajectory,
    start_s: f64,
    from_s: f64,
    until_s: f64,
}

impl Overlapped {
    /// The whole overlap: `second` starts `start_s` into `first` (0 ≤ `start_s` ≤ its duration).
    pub fn new(first: LineMotion, second: Trajectory, start_s: f64) -> Self {
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

    /// When the second motion starts, from the first's start [s].
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

    /// The same overlap seen from `from_s` to `until_s` (times from the first motion's start).
    pub fn window(&self, from_s: f64, until_s: f64) -> Self {
        Overlapped {
            from_s,
            until_s,
            ..self.clone()
        }
    }
}

impl Motion for Overlapped {
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
            let b = self.second.at(t_abs - self.start_s);
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
    }
}
