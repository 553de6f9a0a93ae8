//! Rigid-body dynamics of the arm with its payload.
//!
//! Job: inverse dynamics by recursive Newton-Euler (gravity, Coriolis and centrifugal terms,
//! armature, viscous and smoothed Coulomb friction); the joint-space mass matrix by the composite
//! rigid body algorithm (a separate code path, so each checks the other); forward dynamics; energy.
//!
//! Units: N m, kg, m, rad, s. Frames: each link's quantities in its own link frame; gravity in the
//! base frame. The payload (hand plus held part) is rigidly attached to the flange (link 6) and is
//! merged into link 6's mass properties when a [`DynamicsModel`] is built.
//!
//! Model: tau = M(q) qdd + C(q, qd) qd + G(q) + armature * qdd + viscous * qd
//! + coulomb * tanh(qd / smoothing). M returned by [`DynamicsModel::mass_matrix`] includes the armature.

use nalgebra::{Matrix3, Matrix6, Vector3};

use super::kinematics::Frame;
use super::{DOF, Inertial, JointVector, RobotModel};
use crate::config::GripperConfig;

/// A rigid payload on the flange: mass, centre of mass and inertia in the flange frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Payload {
    /// Mass (kg) (0 for none).
    pub mass_kg: f64,
    /// Centre of mass in the flange frame (m).
    pub com_flange_m: Vector3<f64>,
    /// Inertia about the centre of mass, flange axes [kg m^2].
    pub inertia_com_kg_m2: Matrix3<f64>,
}

impl Payload {
    /// No payload.
    pub fn none() -> Self {
        Payload {
            mass_kg: 0.0,
            com_flange_m: Vector3::zeros(),
            inertia_com_kg_m2: Matrix3::zeros(),
        }
    }

    /// A point mass at `com_flange_m`.
    pub fn point(mass_kg: f64, com_flange_m: Vector3<f64>) -> Self {
        Payload {
            mass_kg,
            com_flange_m,
            inertia_com_kg_m2: Matrix3::zeros(),
        }
    }

    /// The hand from the cell file.
    pub fn from_gripper(g: &GripperConfig) -> Self {
        Payload {
            mass_kg: g.mass_kg,
            com_flange_m: Vector3::from(g.com_m),
            inertia_com_kg_m2: Matrix3::from_diagonal(&Vector3::from(g.inertia_kg_m2)),
        }
    }

    /// Inertia about the flange origin (parallel-axis theorem) [kg m^2].
    pub fn inertia_about_flange(&self) -> Matrix3<f64> {
        inertia_about_origin(self.mass_kg, &self.com_flange_m, &self.inertia_com_kg_m2)
    }

    /// The rigid union of two payloads (hand plus held part).
    pub fn combined(&self, other: &Payload) -> Payload {
        let m = self.mass_kg + other.mass_kg;
        if m <= 0.0 {
            return Payload::none();
        }
        let com = (self.com_flange_m * self.mass_kg + other.com_flange_m * other.mass_kg) / m;
        let about_origin = self.inertia_about_flange() + other.inertia_about_flange();
        // Back from the origin to the combined centre of mass.
        let inertia_com = about_origin - inertia_about_origin(m, &com, &Matrix3::zeros());
        Payload {
            mass_kg: m,
            com_flange_m: com,
            inertia_com_kg_m2: inertia_com,
        }
    }
}

/// Inertia about the frame origin of a body with `mass`, centre of mass `c` and inertia `i_c`.
fn inertia_about_origin(mass: f64, c: &Vector3<f64>, i_c: &Matrix3<f64>) -> Matrix3<f64> {
    i_c + mass * (Matrix3::identity() * c.dot(c) - c * c.transpose())
}

/// Below this acceleration a joint near rest counts as held, not starting
/// ([`DynamicsModel::drive_torque_bound_nm`]) [rad/s^2]: above finite-difference noise on a joint
/// a straight line does not move.
pub const BREAKAWAY_MIN_ACCEL_RAD_S2: f64 = 1e-3;

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Which terms of the model to include.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Terms {
    /// Gravity.
    pub gravity: bool,
    /// Viscous and Coulomb friction.
    pub friction: bool,
    /// Rotor inertia (armature).
    pub armature: bool,
}

impl Terms {
    /// Everything: the torque the drives must deliver.
    pub const ALL: Terms = Terms {
        gravity: true,
        friction: true,
        armature: true,
    };
    /// Everything but friction: what a drive must deliver besides friction (the servo's bias,
    /// the breakaway bound, the implicit friction step).
    pub const NO_FRICTION: Terms = Terms {
        gravity: true,
        friction: false,
        armature: true,
    };
    /// Rigid bodies only (no friction, no armature), gravity on.
    pub const RIGID: Terms = Terms {
        gravity: true,
        friction: false,
        armature: false,
    };
}

/// Per-link mass properties about the link origin, with the payload merged into link 6, and the
/// joint data the recursions need. Build once per payload; evaluate many times.
#[derive(Debug, Clone)]
pub struct DynamicsModel {
    mass: [f64; DOF],
    /// First moment m * c in the link frame.
    first_moment: [Vector3<f64>; DOF],
    /// Inertia about the link origin.
    inertia_origin: [Matrix3<f64>; DOF],
    origin_rot: [Matrix3<f64>; DOF],
    origin_pos: [Vector3<f64>; DOF],
    axis: [Vector3<f64>; DOF],
    armature: [f64; DOF],
    coulomb: [f64; DOF],
    viscous: [f64; DOF],
    coulomb_smoothing_rad_s: f64,
    gravity_base: Vector3<f64>,
    /// The payload merged into link 6.
    pub payload: Payload,
}

impl RobotModel {
    /// The dynamics of this arm carrying `payload` on the flange.
    pub fn dynamics(&self, payload: &Payload) -> DynamicsModel {
        let mut mass = [0.0; DOF];
        let mut first_moment = [Vector3::zeros(); DOF];
        let mut inertia_origin = [Matrix3::zeros(); DOF];
        for i in 0..DOF {
            let Inertial {
                mass_kg,
                com_m,
                inertia_com_kg_m2,
            } = self.links[i + 1].inertial;
            mass[i] = mass_kg;
            first_moment[i] = com_m * mass_kg;
            inertia_origin[i] = inertia_about_origin(mass_kg, &com_m, &inertia_com_kg_m2);
        }
        mass[DOF - 1] += payload.mass_kg;
        first_moment[DOF - 1] += payload.com_flange_m * payload.mass_kg;
        inertia_origin[DOF - 1] += payload.inertia_about_flange();
        DynamicsModel {
            mass,
            first_moment,
            inertia_origin,
            origin_rot: std::array::from_fn(|i| self.joints[i].origin_rot),
            origin_pos: std::array::from_fn(|i| self.joints[i].origin_pos_m),
            axis: std::array::from_fn(|i| self.joints[i].axis),
            armature: std::array::from_fn(|i| self.joints[i].armature_kg_m2),
            coulomb: std::array::from_fn(|i| self.joints[i].coulomb_nm),
            viscous: std::array::from_fn(|i| self.joints[i].viscous_nm_s_per_rad),
            coulomb_smoothing_rad_s: self.coulomb_smoothing_rad_s,
            gravity_base: self.gravity_base_m_s2,
            payload: *payload,
        }
    }
}

impl DynamicsModel {
    #[inline]
    fn joint_rot(&self, i: usize, q: f64) -> Matrix3<f64> {
        self.origin_rot[i] * super::kinematics::axis_rotation(&self.axis[i], q)
    }

    /// Friction torque at joint velocity `qd` [N m].
    #[inline]
    pub fn friction_nm(&self, i: usize, qd: f64) -> f64 {
        self.viscous[i] * qd + self.coulomb[i] * (qd / self.coulomb_smoothing_rad_s).tanh()
    }

    /// The torque each joint's drive must be able to deliver for the motion state (q, qd, qdd),
    /// as a magnitude [N m]: the rigid bodies and the armature exactly, friction at its worst.
    /// Where a joint moves faster than three smoothing widths, friction opposes its velocity as
    /// modelled. Near rest the smoothed model says ~0, which under-states every start: a joint
    /// that accelerates from rest (or takes over from a motion that left it creeping) breaks away
    /// against full Coulomb friction in the direction it accelerates; that is taken when it is
    /// the larger (on the wrist, J6's Coulomb friction is 16 % of its limit: with the smoothed
    /// value alone the servo demanded up to 121 % of the limit at motion starts). A joint that
    /// does not accelerate is held by its static friction, which the drive need not overcome.
    pub fn drive_torque_bound_nm(&self, q: &JointVector, qd: &JointVector, qdd: &JointVector) -> JointVector {
        self.drive_torques_and_bound_nm(q, qd, qdd).1
    }

    /// The drive torques [`DynamicsModel::inverse_dynamics`] gives and their bound
    /// [`DynamicsModel::drive_torque_bound_nm`], from one Newton-Euler pass: bit-identical to the
    /// two calls [N m].
    pub fn drive_torques_and_bound_nm(
        &self,
        q: &JointVector,
        qd: &JointVector,
        qdd: &JointVector,
    ) -> (JointVector, JointVector) {
        let rigid = self.inverse_dynamics_terms(q, qd, qdd, Terms::NO_FRICTION);
        let all = JointVector::from_fn(|i, _| rigid[i] + self.friction_nm(i, qd[i]));
        let bound = JointVector::from_fn(|i, _| {
            let modelled = (rigid[i] + self.friction_nm(i, qd[i])).abs();
            if qd[i].abs() > 3.0 * self.coulomb_smoothing_rad_s || qdd[i].abs() < BREAKAWAY_MIN_ACCEL_RAD_S2 {
                modelled
            } else {
                let breakaway = rigid[i] + self.viscous[i] * qd[i] + self.coulomb[i] * qdd[i].signum();
                modelled.max(breakaway.abs())
            }
        });
        (all, bound)
    }

    /// Slope of the friction torque with joint velocity at `qd` [N m s/rad]: the viscous
    /// coefficient plus the smoothed Coulomb term's derivative (steep near rest).
    #[inline]
    pub fn friction_slope(&self, i: usize, qd: f64) -> f64 {
        let t = (qd / self.coulomb_smoothing_rad_s).tanh();
        self.viscous[i] + self.coulomb[i] * (1.0 - t * t) / self.coulomb_smoothing_rad_s
    }

    /// Forward dynamics for a step of `dt_s` with friction taken implicitly: the joint
    /// accelerations qdd with M qdd + h(q, qd) + f(qd + qdd dt) = tau, friction f at the velocity
    /// the step ends at. Friction near rest is steep (Coulomb over a 1 deg/s smoothing):
    /// explicitly, a 1 ms step on a light wrist joint chatters. Solved by Newton's method from
    /// the first-order expansion of f at qd (which alone damps a breakaway as if the wrist were
    /// three times heavier: the drives then fell a step behind at every start), with a
    /// backtracking line search on the residual (f is monotonic and M positive definite: the solution is unique).
    pub fn forward_dynamics_implicit_friction(
        &self,
        q: &JointVector,
        qd: &JointVector,
        tau: &JointVector,
        dt_s: f64,
    ) -> Option<JointVector> {
        let rigid = self.inverse_dynamics_terms(q, qd, &JointVector::zeros(), Terms::NO_FRICTION);
        let m = self.mass_matrix(q);
        let rhs = tau - rigid;
        let solve_at = |qdd: &JointVector| {
            let mut jac = m;
            for i in 0..DOF {
                jac[(i, i)] += dt_s * self.friction_slope(i, qd[i] + dt_s * qdd[i]);
            }
            jac.cholesky()
        };
        let residual =
            |qdd: &JointVector| m * qdd + JointVector::from_fn(|i, _| self.friction_nm(i, qd[i] + dt_s * qdd[i])) - rhs;
        // First-order expansion at qd: (M + F' dt) qdd = rhs - f(qd).
        let first = rhs - JointVector::from_fn(|i, _| self.friction_nm(i, qd[i]));
        let mut qdd = solve_at(&JointVector::zeros())?.solve(&first);
        let mut r = residual(&qdd);
        for _ in 0..20 {
            if r.amax() < 1e-9 {
                break;
            }
            let Some(c) = solve_at(&qdd) else { break };
            let step = c.solve(&r);
            // Backtracking: the full step where it lowers the residual, else half of it, ...
            let mut taken = false;
            let mut alpha = 1.0;
            for _ in 0..12 {
                let next = qdd - step * alpha;
                let r_next = residual(&next);
                if r_next.norm() < r.norm() {
                    qdd = next;
                    r = r_next;
                    taken = true;
                    break;
                }
                alpha *= 0.5;
            }
            if !taken {
                break;
            }
        }
        Some(qdd)
    }

    /// Joint torques for positions, velocities and accelerations: the full model
    /// (gravity, armature, friction).
    #[inline]
    pub fn inverse_dynamics(&self, q: &JointVector, qd: &JointVector, qdd: &JointVector) -> JointVector {
        self.inverse_dynamics_terms(q, qd, qdd, Terms::ALL)
    }

    /// Recursive Newton-Euler with a choice of terms.
    pub fn inverse_dynamics_terms(
        &self,
        q: &JointVector,
        qd: &JointVector,
        qdd: &JointVector,
        terms: Terms,
    ) -> JointVector {
        let mut rot = [Matrix3::zeros(); DOF];
        let mut force = [Vector3::zeros(); DOF];
        let mut moment = [Vector3::zeros(); DOF];
        let mut w = Vector3::zeros();
        let mut dw = Vector3::zeros();
        // Linear acceleration of the frame origin; gravity enters as an upward base acceleration.
        let mut dv = if terms.gravity {
            -self.gravity_base
        } else {
            Vector3::zeros()
        };
        for i in 0..DOF {
            let r = self.joint_rot(i, q[i]);
            let rt = r.transpose();
            let p = &self.origin_pos[i];
            let a = &self.axis[i];
            let dv_origin = rt * (dv + dw.cross(p) + w.cross(&w.cross(p)));
            let w_in = rt * w;
            let w_i = w_in + a * qd[i];
            let dw_i = rt * dw + a * qdd[i] + w_in.cross(&(a * qd[i]));
            let h = &self.first_moment[i];
            let iw = self.inertia_origin[i] * w_i;
            force[i] = dv_origin * self.mass[i] + dw_i.cross(h) + w_i.cross(&w_i.cross(h));
            moment[i] = self.inertia_origin[i] * dw_i + w_i.cross(&iw) + h.cross(&dv_origin);
            rot[i] = r;
            w = w_i;
            dw = dw_i;
            dv = dv_origin;
        }
        let mut tau = JointVector::zeros();
        let mut f_child = Vector3::zeros();
        let mut n_child = Vector3::zeros();
        for i in (0..DOF).rev() {
            let (f, n) = if i + 1 < DOF {
                let rc = &rot[i + 1];
                let fc = rc * f_child;
                (
                    force[i] + fc,
                    moment[i] + rc * n_child + self.origin_pos[i + 1].cross(&fc),
                )
            } else {
                (force[i], moment[i])
            };
            let mut t = self.axis[i].dot(&n);
            if terms.armature {
                t += self.armature[i] * qdd[i];
            }
            if terms.friction {
                t += self.friction_nm(i, qd[i]);
            }
            tau[i] = t;
            f_child = f;
            n_child = n;
        }
        tau
    }

    /// Gravity torques G(q): the torque that holds the arm still [N m].
    pub fn gravity_torques(&self, q: &JointVector) -> JointVector {
        let z = JointVector::zeros();
        self.inverse_dynamics_terms(q, &z, &z, Terms::RIGID)
    }

    /// Joint-space mass matrix by the composite rigid body algorithm (spatial 6x6 inertias,
    /// Featherstone's formulation). `with_armature` adds the rotor inertias to the diagonal.
    pub fn mass_matrix_terms(&self, q: &JointVector, with_armature: bool) -> Matrix6<f64> {
        // Spatial quantities ordered [angular; linear], about each link's origin, in link coordinates.
        let mut composite: [Matrix6<f64>; DOF] = std::array::from_fn(|i| {
            let mut s = Matrix6::zeros();
            let hx = skew(&self.first_moment[i]);
            s.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.inertia_origin[i]);
            s.fixed_view_mut::<3, 3>(0, 3).copy_from(&hx);
            s.fixed_view_mut::<3, 3>(3, 0).copy_from(&hx.transpose());
            s.fixed_view_mut::<3, 3>(3, 3)
                .copy_from(&(Matrix3::identity() * self.mass[i]));
            s
        });
        // Motion transform parent -> child for each joint: X = [[R^T, 0], [-R^T p^, R^T]].
        let xforms: [Matrix6<f64>; DOF] = std::array::from_fn(|i| {
            let rt = self.joint_rot(i, q[i]).transpose();
            let mut x = Matrix6::zeros();
            x.fixed_view_mut::<3, 3>(0, 0).copy_from(&rt);
            x.fixed_view_mut::<3, 3>(3, 3).copy_from(&rt);
            x.fixed_view_mut::<3, 3>(3, 0)
                .copy_from(&(-rt * skew(&self.origin_pos[i])));
            x
        });
        for i in (1..DOF).rev() {
            let add = xforms[i].transpose() * composite[i] * xforms[i];
            composite[i - 1] += add;
        }
        let motion = |i: usize| {
            let mut s = nalgebra::Vector6::zeros();
            s.fixed_rows_mut::<3>(0).copy_from(&self.axis[i]);
            s
        };
        let mut m = Matrix6::zeros();
        for i in 0..DOF {
            let mut f = composite[i] * motion(i);
            m[(i, i)] = motion(i).dot(&f);
            let mut j = i;
            while j > 0 {
                f = xforms[j].transpose() * f;
                j -= 1;
                let v = motion(j).dot(&f);
                m[(i, j)] = v;
                m[(j, i)] = v;
            }
            if with_armature {
                m[(i, i)] += self.armature[i];
            }
        }
        m
    }

    /// Joint-space mass matrix including the armature [kg m^2].
    pub fn mass_matrix(&self, q: &JointVector) -> Matrix6<f64> {
        self.mass_matrix_terms(q, true)
    }

    /// Joint accelerations under motor torques `tau` (full model): M qdd = tau - bias.
    /// `None` if the mass matrix is not positive definite (never for a valid model).
    pub fn forward_dynamics(&self, q: &JointVector, qd: &JointVector, tau: &JointVector) -> Option<JointVector> {
        let bias = self.inverse_dynamics(q, qd, &JointVector::zeros());
        let m = self.mass_matrix(q);
        m.cholesky().map(|c| c.solve(&(tau - bias)))
    }

    /// Kinetic energy of links, payload and rotors, by propagating link velocities (J).
    pub fn kinetic_energy(&self, q: &JointVector, qd: &JointVector) -> f64 {
        let mut w = Vector3::zeros();
        let mut v = Vector3::zeros();
        let mut e = 0.0;
        for i in 0..DOF {
            let r = self.joint_rot(i, q[i]);
            let rt = r.transpose();
            let v_i = rt * (v + w.cross(&self.origin_pos[i]));
            let w_i = rt * w + self.axis[i] * qd[i];
            // 1/2 m v.v + v.(w x h) + 1/2 w.I_o w, about the link origin.
            e += 0.5 * self.mass[i] * v_i.dot(&v_i)
                + v_i.dot(&w_i.cross(&self.first_moment[i]))
                + 0.5 * w_i.dot(&(self.inertia_origin[i] * w_i))
                + 0.5 * self.armature[i] * qd[i] * qd[i];
            w = w_i;
            v = v_i;
        }
        e
    }

    /// Potential energy of links and payload in gravity, relative to the base origin (J).
    pub fn potential_energy(&self, q: &JointVector) -> f64 {
        let mut frame = Frame::identity();
        let mut e = 0.0;
        for i in 0..DOF {
            frame = frame.compose(&Frame {
                rot: self.joint_rot(i, q[i]),
                pos: self.origin_pos[i],
            });
            if self.mass[i] > 0.0 {
                let com_base = frame.transform_point(&(self.first_moment[i] / self.mass[i]));
                e -= self.mass[i] * self.gravity_base.dot(&com_base);
            }
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::test_support::{default_robot, random_q};
    use rand::{RngExt, SeedableRng};

    fn deg(v: [f64; 6]) -> JointVector {
        JointVector::from_fn(|i, _| v[i].to_radians())
    }

    fn within(actual: f64, expected: f64, rel: f64) -> bool {
        (actual - expected).abs() <= rel * expected.abs()
    }

    #[test]
    fn gravity_torques_match_data_sheet_within_2_percent() {
        let r = default_robot();
        let bare = r.dynamics(&Payload::none());
        let out = bare.gravity_torques(&deg([0.0, 0.0, 90.0, 0.0, 0.0, 0.0]));
        assert!(within(out[1], -32.4, 0.02), "outstretched J2 {}", out[1]);
        assert!(within(out[2], -6.0, 0.02), "outstretched J3 {}", out[2]);
        let ready = bare.gravity_torques(&deg([0.0, -90.0, 180.0, 0.0, 0.0, 0.0]));
        assert!(within(ready[1], -6.3, 0.02), "READY J2 {}", ready[1]);
        assert!(within(ready[2], -6.0, 0.02), "READY J3 {}", ready[2]);
        // 5 kg point payload 5 cm beyond the flange, outstretched.
        let loaded = r.dynamics(&Payload::point(5.0, Vector3::new(0.0, 0.0, 0.05)));
        let g = loaded.gravity_torques(&deg([0.0, 0.0, 90.0, 0.0, 0.0, 0.0]));
        assert!(within(g[1], -66.5, 0.02), "payload J2 {}", g[1]);
        assert!(within(g[2], -26.8, 0.02), "payload J3 {}", g[2]);
        assert!(within(g[4], -6.5, 0.02), "payload J5 {}", g[4]);
    }

    #[test]
    fn one_pass_torques_and_bound_equal_the_two_calls_bit_for_bit() {
        let r = default_robot();
        let d = r.dynamics(&Payload::none());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut friction_seen = false;
        for _ in 0..500 {
            let q = random_q(&r, &mut rng);
            let qd = JointVector::from_fn(|_, _| rng.random_range(-3.0..3.0));
            let qdd = JointVector::from_fn(|_, _| rng.random_range(-30.0..30.0));
            let (tau, bound) = d.drive_torques_and_bound_nm(&q, &qd, &qdd);
            let (tau_ref, bound_ref) = (
                d.inverse_dynamics(&q, &qd, &qdd),
                d.drive_torque_bound_nm(&q, &qd, &qdd),
            );
            for i in 0..DOF {
                assert_eq!(tau[i].to_bits(), tau_ref[i].to_bits(), "joint {i}");
                assert_eq!(bound[i].to_bits(), bound_ref[i].to_bits(), "joint {i}");
            }
            // Negative control: the torques without friction are told apart.
            let rigid = d.inverse_dynamics_terms(&q, &qd, &qdd, Terms::NO_FRICTION);
            friction_seen |= (0..DOF).any(|i| rigid[i].to_bits() != tau[i].to_bits());
        }
        assert!(friction_seen);
    }

    #[test]
    fn mass_matrix_diagonal_matches_data_sheet() {
        let r = default_robot();
        let m = r
            .dynamics(&Payload::none())
            .mass_matrix_terms(&deg([0.0, 0.0, 90.0, 0.0, 0.0, 0.0]), false);
        assert!(within(m[(0, 0)], 1.89, 0.03), "M11 {}", m[(0, 0)]);
        assert!(within(m[(1, 1)], 1.24, 0.03), "M22 {}", m[(1, 1)]);
        assert!(within(m[(2, 2)], 0.20, 0.03), "M33 {}", m[(2, 2)]);
    }

    #[test]
    fn mass_matrix_is_symmetric_positive_definite_and_matches_rnea() {
        let r = default_robot();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let payload = Payload::from_gripper(&crate::config::LoadedScene::embedded_default().unwrap().scene.gripper);
        for dynamics in [r.dynamics(&Payload::none()), r.dynamics(&payload)] {
            for _ in 0..200 {
                let q = random_q(&r, &mut rng);
                let m = dynamics.mass_matrix(&q);
                assert!((m - m.transpose()).amax() < 1e-12);
                let eig = m.symmetric_eigenvalues();
                assert!(eig.min() > 0.0, "not positive definite: {eig:?}");
                let qdd = JointVector::from_fn(|_, _| rng.random_range(-20.0..20.0));
                let z = JointVector::zeros();
                let lhs = dynamics.inverse_dynamics(&q, &z, &qdd) - dynamics.inverse_dynamics(&q, &z, &z);
                assert!((lhs - m * qdd).amax() < 1e-9, "RNEA vs CRBA: {lhs:?} vs {:?}", m * qdd);
            }
        }
    }

    #[test]
    fn energy_rate_equals_joint_power_friction_off() {
        let r = default_robot();
        let dynamics = r.dynamics(&Payload::point(1.5, Vector3::new(0.01, -0.02, 0.07)));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let q0 = random_q(&r, &mut rng);
        let amp = JointVector::from_fn(|_, _| rng.random_range(0.2..1.0));
        let freq = JointVector::from_fn(|_, _| rng.random_range(0.5..3.0));
        let phase = JointVector::from_fn(|_, _| rng.random_range(0.0..6.0));
        let state = |t: f64| {
            let q = JointVector::from_fn(|i, _| q0[i] + amp[i] * (freq[i] * t + phase[i]).sin());
            let qd = JointVector::from_fn(|i, _| amp[i] * freq[i] * (freq[i] * t + phase[i]).cos());
            let qdd = JointVector::from_fn(|i, _| -amp[i] * freq[i] * freq[i] * (freq[i] * t + phase[i]).sin());
            (q, qd, qdd)
        };
        let energy = |t: f64| {
            let (q, qd, _) = state(t);
            dynamics.kinetic_energy(&q, &qd) + dynamics.potential_energy(&q)
        };
        let terms = Terms::NO_FRICTION;
        let h = 1e-5;
        for k in 0..200 {
            let t = k as f64 * 0.01;
            let (q, qd, qdd) = state(t);
            let power = qd.dot(&dynamics.inverse_dynamics_terms(&q, &qd, &qdd, terms));
            let rate = (energy(t + h) - energy(t - h)) / (2.0 * h);
            assert!(
                (power - rate).abs() < 1e-5 * (1.0 + power.abs()),
                "t={t}: power {power} vs dE/dt {rate}"
            );
            // Kinetic energy also agrees with the mass matrix.
            let ke = 0.5 * qd.dot(&(dynamics.mass_matrix(&q) * qd));
            assert!((ke - dynamics.kinetic_energy(&q, &qd)).abs() < 1e-9 * (1.0 + ke));
        }
    }

    #[test]
    fn forward_dynamics_inverts_inverse_dynamics() {
        let r = default_robot();
        let d = r.dynamics(&Payload::point(0.8, Vector3::new(0.0, 0.0, 0.06)));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        for _ in 0..100 {
            let q = random_q(&r, &mut rng);
            let qd = JointVector::from_fn(|_, _| rng.random_range(-3.0..3.0));
            let qdd = JointVector::from_fn(|_, _| rng.random_range(-30.0..30.0));
            let tau = d.inverse_dynamics(&q, &qd, &qdd);
            let back = d.forward_dynamics(&q, &qd, &tau).unwrap();
            assert!((back - qdd).amax() < 1e-8);
        }
    }

    #[test]
    fn an_implicit_step_takes_friction_at_the_velocity_it_ends_at() {
        // From rest and moving, with torques that break away and torques that stick: the step's
        // accelerations satisfy M qdd + h + f(qd + qdd dt) = tau (the first-order expansion alone
        // left a breakaway at a third of its acceleration on the wrist).
        let r = default_robot();
        let d = r.dynamics(&Payload::point(0.6, Vector3::new(0.0, 0.0, 0.06)));
        let dt = 0.001;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut first_order_misses = 0;
        for k in 0..200 {
            let q = random_q(&r, &mut rng);
            let qd = if k % 2 == 0 {
                JointVector::zeros()
            } else {
                JointVector::from_fn(|_, _| rng.random_range(-2.0..2.0))
            };
            let want = JointVector::from_fn(|_, _| rng.random_range(-300.0..300.0));
            let rigid = Terms::NO_FRICTION;
            let tau = d.inverse_dynamics_terms(&q, &qd, &want, rigid)
                + JointVector::from_fn(|i, _| d.friction_nm(i, qd[i] + want[i] * dt));
            let qdd = d.forward_dynamics_implicit_friction(&q, &qd, &tau, dt).unwrap();
            let end = qd + qdd * dt;
            let needs =
                d.inverse_dynamics_terms(&q, &qd, &qdd, rigid) + JointVector::from_fn(|i, _| d.friction_nm(i, end[i]));
            assert!((needs - tau).amax() < 1e-4, "{k}: {:?}", needs - tau);
            assert!((qdd - want).amax() < 1e-3 * want.amax(), "{k}: {qdd:?} vs {want:?}");
            // Negative control: one linearised step misses the breakaway.
            let mut m = d.mass_matrix(&q);
            for i in 0..DOF {
                m[(i, i)] += dt * d.friction_slope(i, qd[i]);
            }
            let lin = m
                .cholesky()
                .unwrap()
                .solve(&(tau - d.inverse_dynamics(&q, &qd, &JointVector::zeros())));
            if (lin - want).amax() > 0.1 * want.amax() {
                first_order_misses += 1;
            }
        }
        assert!(first_order_misses > 50, "{first_order_misses}");
    }

    #[test]
    fn payload_combination_preserves_mass_and_moment() {
        let a = Payload::point(0.6, Vector3::new(0.0, 0.0, 0.05));
        let b = Payload::point(0.02, Vector3::new(0.0, 0.0, 0.125));
        let c = a.combined(&b);
        assert!((c.mass_kg - 0.62).abs() < 1e-12);
        assert!((c.inertia_about_flange() - (a.inertia_about_flange() + b.inertia_about_flange())).amax() < 1e-12);
        assert!(
            c.combined(&Payload::none()) == c
                || (c.combined(&Payload::none()).com_flange_m - c.com_flange_m).norm() < 1e-15
        );
    }
}
