//! The symmetries of a workpiece's look, for evaluation: pose errors up to the turns that leave
//! the part looking the same [m, rad].

use nalgebra::{Isometry3, Matrix3, Rotation3, UnitQuaternion, Vector3};

use crate::config::{Axis, PartRole, Piece, ShapeKind, Workpiece};

/// How a workpiece looks the same, for evaluation: a finite set of rotations of the part frame,
/// or any turn about the part's z axis.
#[derive(Debug, Clone)]
pub enum Symmetry {
    /// These rotations (the identity included) leave the part's look unchanged.
    Finite(Vec<UnitQuaternion<f64>>),
    /// Any turn about the part z axis (a can standing on its base: its top hides the base).
    AboutZ,
}

impl Symmetry {
    /// A box workpiece: the box's own proper rotations (a half turn about every axis, a quarter
    /// turn about an axis whose two other edges are equal). A compound: turns about z by
    /// `grasp.yaw_symmetry_deg`; any turn if its body has a cylinder along z (its yaw cannot be
    /// seen from above).
    pub fn of(w: &Workpiece) -> Self {
        let pieces = w.pieces();
        if w.shape.kind == ShapeKind::Compound {
            if pieces
                .iter()
                .any(|(role, p)| *role == PartRole::Body && matches!(p, Piece::Cylinder { axis: Axis::Z, .. }))
            {
                return Symmetry::AboutZ;
            }
            let step = w.grasp.yaw_symmetry_deg;
            let k = if step > 0.0 {
                (360.0 / step).round().max(1.0) as usize
            } else {
                1
            };
            return Symmetry::Finite(
                (0..k)
                    .map(|i| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), (i as f64 * step).to_radians()))
                    .collect(),
            );
        }
        let size = Vector3::from(w.size_m);
        let mut out = Vec::new();
        for perm in [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]] {
            for signs in 0..8 {
                let mut m = Matrix3::zeros();
                for (r, &c) in perm.iter().enumerate() {
                    m[(r, c)] = if signs & (1 << r) == 0 { 1.0 } else { -1.0 };
                }
                if m.determinant() < 0.0 || ((m.abs() * size) - size).norm() > 1e-9 {
                    continue;
                }
                out.push(UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
                    m,
                )));
            }
        }
        Symmetry::Finite(out)
    }

    /// Position [m] and rotation [rad] error of `estimate` against `truth`, the least over the
    /// symmetries.
    pub fn pose_error(&self, truth: &Isometry3<f64>, estimate: &Isometry3<f64>) -> (f64, f64) {
        let dp = (truth.translation.vector - estimate.translation.vector).norm();
        let dr = match self {
            Symmetry::Finite(g) => g
                .iter()
                .map(|s| (truth.rotation * s).angle_to(&estimate.rotation))
                .fold(f64::INFINITY, f64::min),
            Symmetry::AboutZ => (truth.rotation * Vector3::z())
                .dot(&(estimate.rotation * Vector3::z()))
                .clamp(-1.0, 1.0)
                .acos(),
        };
        (dp, dr)
    }
}
