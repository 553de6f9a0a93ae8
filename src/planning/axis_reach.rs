//! How far the arm reaches from each joint's axis at one configuration: the pose-dependent part
//! of the motion bound that certifies an edge.
//!
//! Job: hold, per link and per joint, the largest distance from the joint's axis to a point of
//! the link's spheres, which the collision model reads off a pose ([`super::model`]) and the edge
//! certification ([`super::certify`]) bounds a point's speed with.
//!
//! Units: m, rad. Frames: none (distances only).

use crate::robot::DOF;

/// How far each link's spheres reach from each joint's axis at one configuration: `reach_m[k][i]`
/// is the largest distance from joint i's axis to a point of link k's spheres (0 for i ≥ k) (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisReach {
    /// Per link (base first), per joint (m).
    pub reach_m: [[f64; DOF]; DOF + 1],
}

impl AxisReach {
    /// Nothing reaches anywhere (a robot without spheres).
    #[inline]
    pub fn zero() -> Self {
        AxisReach {
            reach_m: [[0.0; DOF]; DOF + 1],
        }
    }

    /// A: the fastest any sphere point moves per unit of t when the joints move by `dq_abs` per
    /// unit of t, here (m). Inlined: the edge certification's hot path calls it at every
    /// examined configuration.
    #[inline]
    pub fn speed_m(&self, dq_abs: &[f64; DOF]) -> f64 {
        self.reach_m
            .iter()
            .map(|r| (0..DOF).map(|i| dq_abs[i] * r[i]).sum::<f64>())
            .fold(0.0, f64::max)
    }
}
