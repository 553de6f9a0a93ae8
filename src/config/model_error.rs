//! The cell file's `[model_error]` section: how far the simulated plant is from the controller's
//! model of the arm and of the part it holds.
//!
//! Job: a real controller computes its feedforward torques from nominal inertials, friction and
//! payload; the arm it drives differs. The twin draws the plant's differences once per run from
//! the run seed's own stream (`model-error`), so the servo's torques and tracking errors are those
//! of a controller that does not know its plant exactly. Each fraction `f` scales a nominal value
//! by a factor 1 + u, u uniform in [-f, f]; 0 switches that error off.
//!
//! Units: fractions (dimensionless). Frames: none.

use serde::{Deserialize, Serialize};

use super::Checker;

/// Default spread of each link's mass and inertia: the URDF's inertials are estimates from CAD and
/// datasheets (`shared/reference/viper-s650.md`), whose errors are of this order.
pub const LINK_INERTIAL_FRACTION: f64 = 0.10;
/// Default spread of each joint's Coulomb and viscous friction: harmonic-drive friction changes by
/// tens of percent with temperature, lubricant and wear between identification and use.
pub const JOINT_FRICTION_FRACTION: f64 = 0.25;
/// Default spread of each joint's reflected rotor inertia (armature): motor and gearbox
/// datasheet tolerances.
pub const ARMATURE_FRACTION: f64 = 0.10;

/// How far the plant is from the controller's model.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ModelErrorConfig {
    /// Each link's mass and its inertia are scaled (separately, per link) by 1 + u, u uniform in
    /// +- this fraction.
    #[serde(default = "link_inertial_fraction")]
    pub link_inertial_fraction: f64,
    /// Each joint's Coulomb and viscous friction are scaled (separately, per joint) by 1 + u.
    #[serde(default = "joint_friction_fraction")]
    pub joint_friction_fraction: f64,
    /// Each joint's armature (reflected rotor inertia) is scaled by 1 + u.
    #[serde(default = "armature_fraction")]
    pub armature_fraction: f64,
    /// The plant carries the held part as the physics has it on the cup (its mass and inertia,
    /// its centre of mass where the cup actually sealed), while the controller believes the
    /// nominal part's mass at the cup centre. `false`: the plant carries what the controller
    /// believes.
    #[serde(default = "held_part_as_sealed")]
    pub held_part_as_sealed: bool,
}

fn link_inertial_fraction() -> f64 {
    LINK_INERTIAL_FRACTION
}
fn joint_friction_fraction() -> f64 {
    JOINT_FRICTION_FRACTION
}
fn armature_fraction() -> f64 {
    ARMATURE_FRACTION
}
fn held_part_as_sealed() -> bool {
    true
}

impl Default for ModelErrorConfig {
    fn default() -> Self {
        ModelErrorConfig {
            link_inertial_fraction: LINK_INERTIAL_FRACTION,
            joint_friction_fraction: JOINT_FRICTION_FRACTION,
            armature_fraction: ARMATURE_FRACTION,
            held_part_as_sealed: true,
        }
    }
}

impl ModelErrorConfig {
    /// No model error at all: the plant is the controller's model.
    pub fn none() -> Self {
        ModelErrorConfig {
            link_inertial_fraction: 0.0,
            joint_friction_fraction: 0.0,
            armature_fraction: 0.0,
            held_part_as_sealed: false,
        }
    }

    /// Whether the plant differs from the model at all.
    pub fn any(&self) -> bool {
        self.link_inertial_fraction > 0.0
            || self.joint_friction_fraction > 0.0
            || self.armature_fraction > 0.0
            || self.held_part_as_sealed
    }

    /// Checks each fraction is in [0, 0.9] (a factor that stays positive).
    pub(super) fn check(&self, c: &mut Checker) {
        for (key, v) in [
            ("model_error.link_inertial_fraction", self.link_inertial_fraction),
            ("model_error.joint_friction_fraction", self.joint_friction_fraction),
            ("model_error.armature_fraction", self.armature_fraction),
        ] {
            c.within(key, v, 0.0, 0.9);
        }
    }
}
