//! Joint torques along a sampled motion, and the energy measure.
//!
//! Job: evaluate inverse dynamics (payload included, friction included) at every sample of a
//! motion: the peak |torque| of each joint (friction at its worst near rest, where its sign is
//! unknown), its share of the joint's limit, and an energy measure,
//! the time integral of the sum of squared torques (the smoothing seed's approximation of the
//! energy a motion consumes).
//!
//! Units: N m, N^2 m^2 s, s. Frames: joint space.

use serde::Serialize;

use super::Sample;
use crate::robot::{DOF, DynamicsModel, RobotModel};

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

/// Evaluates torques at every sample with inverse dynamics (payload included), friction at its
/// worst near rest ([`DynamicsModel::drive_torque_bound_nm`]).
pub fn torques(dynamics: &DynamicsModel, robot: &RobotModel, samples: &[Sample], dt_s: f64) -> TorqueProfile {
    let limit = robot.torque_limit_nm();
    let mut peak = [0.0f64; DOF];
    let mut energy = 0.0;
    for s in samples {
        let (tau, bound) = dynamics.drive_torques_and_bound_nm(&s.q, &s.qd, &s.qdd);
        for i in 0..DOF {
            peak[i] = peak[i].max(bound[i]);
        }
        energy += tau.norm_squared() * dt_s;
    }
    TorqueProfile {
        peak_nm: peak,
        peak_ratio: std::array::from_fn(|i| peak[i] / limit[i]),
        energy,
    }
}
