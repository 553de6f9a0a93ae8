//! Forward kinematics, the geometric Jacobian and manipulability.
//!
//! Job: joint positions (rad) to the pose of every link frame, the flange and the tool, in the
//! base frame (`base_from_link`) or the world frame (`world_from_tool`); the tool-point Jacobian.
//! Units: m, rad. A [`Frame`] is a rotation matrix and a translation, the fast form the hot loops
//! (planning, dynamics) use; the public pose API returns nalgebra isometries.

use nalgebra::{Isometry3, Matrix3, Matrix6, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::{DOF, JointVector, RobotModel};

/// A rigid transform as rotation matrix and translation: `parent_from_child`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Rotation (columns: child axes in the parent frame).
    pub rot: Matrix3<f64>,
    /// Child origin in the parent frame (m).
    pub pos: Vector3<f64>,
}

impl Frame {
    /// The identity transform.
    pub fn identity() -> Self {
        Frame {
            rot: Matrix3::identity(),
            pos: Vector3::zeros(),
        }
    }

    /// `self * other`.
    #[inline]
    pub fn compose(&self, other: &Frame) -> Frame {
        Frame {
            rot: self.rot * other.rot,
            pos: self.rot * other.pos + self.pos,
        }
    }

    /// Transforms a point.
    #[inline]
    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rot * p + self.pos
    }

    /// As an isometry.
    pub fn to_isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.pos),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(self.rot)),
        )
    }
}

/// Rotation by `angle` about the unit `axis` (Rodrigues).
#[inline]
pub fn axis_rotation(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    let (x, y, z) = (axis.x, axis.y, axis.z);
    Matrix3::new(
        t * x * x + c,
        t * x * y - s * z,
        t * x * z + s * y,
        t * x * y + s * z,
        t * y * y + c,
        t * y * z - s * x,
        t * x * z - s * y,
        t * y * z + s * x,
        t * z * z + c,
    )
}

impl RobotModel {
    /// `parent_from_child` of joint `i` at position `q_i`.
    #[inline]
    pub fn joint_frame(&self, i: usize, q_i: f64) -> Frame {
        let j = &self.joints[i];
        Frame {
            rot: j.origin_rot * axis_rotation(&j.axis, q_i),
            pos: j.origin_pos_m,
        }
    }

    /// `base_from_link` for links 0 (base, identity) to 6 (flange).
    pub fn base_from_links(&self, q: &JointVector) -> [Frame; DOF + 1] {
        let mut out = [Frame::identity(); DOF + 1];
        for i in 0..DOF {
            out[i + 1] = out[i].compose(&self.joint_frame(i, q[i]));
        }
        out
    }

    /// `base_from_flange`.
    pub fn base_from_flange(&self, q: &JointVector) -> Isometry3<f64> {
        self.base_from_links(q)[DOF].to_isometry()
    }

    /// `base_from_tool`.
    pub fn base_from_tool(&self, q: &JointVector) -> Isometry3<f64> {
        self.base_from_flange(q) * self.flange_from_tool
    }

    /// `world_from_tool`.
    pub fn world_from_tool(&self, q: &JointVector) -> Isometry3<f64> {
        self.world_from_base * self.base_from_tool(q)
    }

    /// `world_from_link` for every link, base first.
    pub fn world_from_links(&self, q: &JointVector) -> Vec<Isometry3<f64>> {
        self.base_from_links(q)
            .iter()
            .map(|f| self.world_from_base * f.to_isometry())
            .collect()
    }

    /// Geometric Jacobian of the tool point in the base frame: rows 0-2 linear velocity [m/s per
    /// rad/s], rows 3-5 angular velocity.
    pub fn jacobian_tool(&self, q: &JointVector) -> Matrix6<f64> {
        let base_from_links = self.base_from_links(q);
        let tool = base_from_links[DOF].transform_point(&self.flange_from_tool.translation.vector);
        let mut jac = Matrix6::zeros();
        for i in 0..DOF {
            let f = &base_from_links[i + 1];
            let z = f.rot * self.joints[i].axis;
            let v = z.cross(&(tool - f.pos));
            jac.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
            jac.fixed_view_mut::<3, 1>(3, i).copy_from(&z);
        }
        jac
    }

    /// Yoshikawa manipulability sqrt(det(J J^T)) of the tool Jacobian (0 at a singularity).
    pub fn manipulability(&self, q: &JointVector) -> f64 {
        let j = self.jacobian_tool(q);
        (j * j.transpose()).determinant().max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::test_support::{default_robot, random_q};
    use rand::SeedableRng;

    fn deg(v: [f64; 6]) -> JointVector {
        JointVector::from_fn(|i, _| v[i].to_radians())
    }

    #[test]
    fn data_sheet_test_poses_within_0_1_mm() {
        let r = default_robot();
        let f0 = r.base_from_flange(&JointVector::zeros());
        assert!(
            (f0.translation.vector - Vector3::new(0.255, 0.0, 0.710)).norm() < 1e-4,
            "{f0}"
        );
        assert!((f0.rotation * Vector3::z() - Vector3::z()).norm() < 1e-9);
        let ready = r.base_from_flange(&deg([0.0, -90.0, 180.0, 0.0, 0.0, 0.0]));
        assert!(
            (ready.translation.vector - Vector3::new(0.450, 0.0, 0.695)).norm() < 1e-4,
            "{ready}"
        );
        assert!((ready.rotation * Vector3::z() - Vector3::x()).norm() < 1e-9);
    }

    #[test]
    fn positive_j2_pitches_forward_and_down() {
        let r = default_robot();
        let a = r.base_from_flange(&JointVector::zeros()).translation.vector;
        let b = r
            .base_from_flange(&deg([0.0, 10.0, 0.0, 0.0, 0.0, 0.0]))
            .translation
            .vector;
        assert!(b.x > a.x && b.z < a.z);
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let r = default_robot();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..50 {
            let q = random_q(&r, &mut rng);
            let jac = r.jacobian_tool(&q);
            let h = 1e-6;
            for i in 0..DOF {
                let mut qp = q;
                let mut qm = q;
                qp[i] += h;
                qm[i] -= h;
                let (tp, tm) = (r.base_from_tool(&qp), r.base_from_tool(&qm));
                let dv = (tp.translation.vector - tm.translation.vector) / (2.0 * h);
                let dr = (tp.rotation * tm.rotation.inverse()).scaled_axis() / (2.0 * h);
                let col = jac.column(i);
                assert!((dv - col.fixed_rows::<3>(0)).norm() < 1e-6, "linear column {i}");
                assert!((dr - col.fixed_rows::<3>(3)).norm() < 1e-6, "angular column {i}");
            }
        }
    }

    #[test]
    fn manipulability_vanishes_at_wrist_singularity() {
        let r = default_robot();
        let singular = deg([0.0, -45.0, 120.0, 30.0, 0.0, 10.0]);
        let regular = deg([0.0, -45.0, 120.0, 30.0, 45.0, 10.0]);
        assert!(r.manipulability(&singular) < 1e-9);
        assert!(r.manipulability(&regular) > 1e-3);
    }
}
