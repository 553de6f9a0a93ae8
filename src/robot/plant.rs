//! The plant is not the controller's model: a copy of the arm whose inertials, friction and
//! armature differ from the nominal ones by the cell file's `[model_error]`, and the arm as the
//! motion accelerator budgets it (its torque limits less the margin it keeps back).
//!
//! Units: kg, kg m^2, N m, N m s/rad. Frames: each link's own (inertials), joint space.

use rand::RngExt;

use super::RobotModel;
use crate::config::ModelErrorConfig;

/// A factor 1 + u, u uniform in [-f, f] (exactly 1 when f is 0, with no draw).
fn factor(rng: &mut impl RngExt, f: f64) -> f64 {
    if f > 0.0 { 1.0 + rng.random_range(-f..=f) } else { 1.0 }
}

impl RobotModel {
    /// The arm as the plant has it: every link's mass and inertia, every joint's Coulomb and
    /// viscous friction and armature scaled by its own factor drawn from the `model-error`
    /// stream of `seed` (in that order: links 1..6 mass then inertia, then joints 1..6 Coulomb,
    /// viscous, armature). The centres of mass stay where the URDF puts them.
    pub fn with_model_error(&self, error: &ModelErrorConfig, seed: u64) -> RobotModel {
        let mut rng = crate::rng::stream(seed, "model-error");
        let mut plant = self.clone();
        for link in plant.links.iter_mut().skip(1) {
            link.inertial.mass_kg *= factor(&mut rng, error.link_inertial_fraction);
            link.inertial.inertia_com_kg_m2 *= factor(&mut rng, error.link_inertial_fraction);
        }
        for joint in plant.joints.iter_mut() {
            joint.coulomb_nm *= factor(&mut rng, error.joint_friction_fraction);
            joint.viscous_nm_s_per_rad *= factor(&mut rng, error.joint_friction_fraction);
            joint.armature_kg_m2 *= factor(&mut rng, error.armature_fraction);
        }
        plant
    }

    /// The arm with each joint's torque limit scaled by `share` (the motion accelerator plans
    /// against these, keeping `1 - share` of every limit back).
    pub fn with_torque_share(&self, share: f64) -> RobotModel {
        let mut r = self.clone();
        for j in r.joints.iter_mut() {
            j.torque_limit_nm *= share;
        }
        r
    }
}

#[cfg(test)]
mod tests {
    use crate::config::ModelErrorConfig;

    #[test]
    fn the_plant_differs_within_the_fractions_and_repeats_per_seed() {
        let r = crate::robot::test_support::default_robot();
        let e = ModelErrorConfig::default();
        let p = r.with_model_error(&e, 7);
        let q = r.with_model_error(&e, 7);
        let mut differs = false;
        for i in 1..r.links.len() {
            let k = p.links[i].inertial.mass_kg / r.links[i].inertial.mass_kg;
            assert!((k - 1.0).abs() <= e.link_inertial_fraction + 1e-12, "link {i}: {k}");
            assert_eq!(p.links[i].inertial.mass_kg, q.links[i].inertial.mass_kg);
            differs |= (k - 1.0).abs() > 1e-6;
            assert_eq!(p.links[i].inertial.com_m, r.links[i].inertial.com_m);
        }
        for (a, b) in p.joints.iter().zip(&r.joints) {
            let k = a.coulomb_nm / b.coulomb_nm;
            assert!((k - 1.0).abs() <= e.joint_friction_fraction + 1e-12);
            assert_eq!(a.torque_limit_nm, b.torque_limit_nm);
        }
        assert!(differs, "no link's mass changed");
        // Switched off, the plant is the model.
        let same = r.with_model_error(&ModelErrorConfig::none(), 7);
        assert_eq!(same.links[3].inertial.mass_kg, r.links[3].inertial.mass_kg);
        assert_eq!(same.joints[2].coulomb_nm, r.joints[2].coulomb_nm);
    }
}
