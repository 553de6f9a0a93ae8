//! Scripted arm motions in the physics world: smooth joint moves and straight tool lines.
//!
//! Job: drive the arm's kinematic bodies for scenes, tests and benchmarks without the planner and
//! servo of later stages: a quintic time scaling (zero velocity and acceleration at both ends),
//! joint-space interpolation, or a straight tool line whose joint positions come from the
//! closed-form IK nearest the previous step. Units: m, rad, s. Frames: `world_from_tool`.

use nalgebra::Isometry3;

use super::{HealthError, World};
use crate::robot::{IkError, JointVector};

/// Why a scripted motion stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScriptError {
    /// A pose on the line has no IK solution.
    #[error("tool pose unreachable at {fraction:.3} of the line: {source}")]
    Unreachable {
        /// How far along the line [0, 1].
        fraction: f64,
        /// Why.
        source: IkError,
    },
    /// The world's health monitor stopped the motion.
    #[error(transparent)]
    Health(#[from] HealthError),
}

/// Quintic time scaling s(u) = 10u^3 - 15u^4 + 6u^5 on [0, 1].
pub fn quintic(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
}

impl World {
    /// Moves the joints from where they are to `q_goal` in `duration_s`, quintic in time.
    pub fn move_joints(&mut self, q_goal: &JointVector, duration_s: f64) -> Result<(), ScriptError> {
        let q0 = self.joints();
        let n = (duration_s / self.dt_s()).ceil().max(1.0) as usize;
        for k in 1..=n {
            let s = quintic(k as f64 / n as f64);
            self.set_joint_target(&(q0 + (q_goal - q0) * s));
            self.step()?;
        }
        Ok(())
    }

    /// Moves the tool along a straight line (position) with a slerp (orientation) to
    /// `world_from_tool_goal` in `duration_s`, quintic in time.
    pub fn move_tool_line(
        &mut self,
        world_from_tool_goal: &Isometry3<f64>,
        duration_s: f64,
    ) -> Result<(), ScriptError> {
        let start = self.world_from_tool();
        let n = (duration_s / self.dt_s()).ceil().max(1.0) as usize;
        for k in 1..=n {
            let u = k as f64 / n as f64;
            let s = quintic(u);
            let pose = start.lerp_slerp(world_from_tool_goal, s);
            let q = self
                .robot
                .ik_tool_nearest(&pose, &self.joints())
                .map_err(|source| ScriptError::Unreachable { fraction: u, source })?;
            self.set_joint_target(&q.q);
            self.step()?;
        }
        Ok(())
    }

    /// Puts the tool at `world_from_tool` at once (IK nearest the current joints), for set-ups.
    pub fn place_tool(&mut self, world_from_tool: &Isometry3<f64>) -> Result<(), ScriptError> {
        let q = self
            .robot
            .ik_tool_nearest(world_from_tool, &self.joints())
            .map_err(|source| ScriptError::Unreachable { fraction: 1.0, source })?;
        self.place_arm(&q.q);
        Ok(())
    }
}
