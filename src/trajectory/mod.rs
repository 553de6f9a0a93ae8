//! Trajectories: from the planner's via points to a timed, torque-limited joint motion.
//!
//! Job, in data-flow order (one file per step):
//!
//! 1. `blend`: the planned via points become a [`Trajectory`]: straight joint-space segments at
//!    a common speed, joined by polynomial blends, from rest to rest ([`MotionLimits`],
//!    [`Continuity`]).
//! 2. `torque`: its joint torques by inverse dynamics (payload included) every millisecond: peaks
//!    against the limits, and an energy measure ([`torques`], [`TorqueProfile`]).
//! 3. `accel`: the reference system's motion accelerator: §4.2 bisects each joint's acceleration
//!    until its peak torque sits just below its limit, §4.3 folds the arm where J1's inertia
//!    holds it back; the blends are re-checked against the certified corridor and stop at the
//!    via points whose blends cut a corner ([`accelerate_in_corridor`], [`correct_path`],
//!    [`check_corridor`]).
//! 4. `line`: straight tool lines for the descents, lifts and retreats near the trays
//!    ([`straight_line`]), and the cap on the force the tool exerts on a held part
//!    ([`limit_tool_force`]).
//!
//! The time-optimal bound the accelerator is measured against is TOPP-RA: `toppra` holds the
//! generic algorithm over any [`PathConstraints`] (linear in (s'', s'^2), nothing of robots),
//! `retime` the robot's speed, acceleration and torque constraints along a trajectory's path
//! and the retimed [`Motion`] ([`toppra`], [`optimal_duration`]).
//!
//! Everything that can be sampled in time implements [`Motion`] and yields [`Sample`]s.
//!
//! Units: rad, rad/s, rad/s^2, s, N m (tool lines in m, m/s, m/s^2). Frames: joint space; tool
//! poses `world_from_tool`.

mod accel;
mod blend;
mod line;
mod retime;
mod superposed;
mod toppra;
mod torque;

pub use accel::{
    Accelerated, CORRIDOR_BEND_BUDGET_M, CORRIDOR_CHECK_DT_S, Corrected, TORQUE_DT_S, TORQUE_THRESHOLD,
    accel_top_rad_s2, accelerate_in_corridor, check_corridor, chord_deviation_rad, correct_path, default_limits,
    optimal_duration, optimise_accelerations,
};
pub use blend::{Continuity, MotionLimits, Trajectory};
pub use line::{LineLimits, LineMotion, limit_tool_force, release_lead_s, seal_overload, straight_line};
pub use retime::{ArcPath, Retimed, RobotPathConstraints, Shares, toppra};
pub use superposed::{OverlapCheck, Overlapped, overlap_end};
pub use toppra::{PathConstraints, PathPoint, PathTiming, StageRow, time_optimal};
pub use torque::{TorqueProfile, torques};

use crate::robot::JointVector;

/// One sample of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time (s).
    pub t_s: f64,
    /// Positions (rad).
    pub q: JointVector,
    /// Velocities [rad/s].
    pub qd: JointVector,
    /// Accelerations [rad/s^2].
    pub qdd: JointVector,
}

/// A stretch of a motion in time, for certifying the corridor it sweeps ([`check_corridor`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stretch {
    /// Start (s).
    pub t0_s: f64,
    /// End (s).
    pub t1_s: f64,
    /// Per joint, a bound on the acceleration that bends the motion off a straight joint-space
    /// line over the stretch [rad/s^2]; all zero: the stretch runs monotonically along the straight
    /// line between its ends (its chord is the set of configurations it passes).
    pub bend_rad_s2: JointVector,
}

/// Anything that can be sampled in time like a trajectory.
pub trait Motion {
    /// The motion cut into [`Stretch`]es, straight ones and bent ones with their acceleration
    /// bounds, when it knows them (`None`: unknown; [`check_corridor`] then assumes the robot's
    /// specification accelerations everywhere).
    fn stretches(&self) -> Option<Vec<Stretch>> {
        None
    }
    /// Duration (s).
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
