//! Closed-form inverse kinematics for the spherical-wrist arm.
//!
//! Job: a flange (or tool) pose to every joint solution: 2 shoulder (J1 front/back) x 2 elbow x
//! 2 wrist (J5 sign) principal solutions, each expanded over the multi-turn ranges of every joint
//! (J6 spans +-360 deg, J4 +-190 deg), filtered by the joint limits. Targets at a singularity (wrist
//! centre on the J1 axis, or J5 = 0 where only J4 + J6 is determined) and targets out of reach
//! return a typed [`IkError`].
//!
//! Units: m, rad. Frames: targets are `base_from_flange`, `base_from_tool` or `world_from_tool`.
//! The geometry (shoulder height and offset, upper arm, forearm to wrist centre, wrist to flange)
//! is read off the URDF joint origins at load; a chain of another structure is refused there.

use std::f64::consts::{PI, TAU};

use nalgebra::{Isometry3, Matrix3, Vector3};

use super::{DOF, Joint, JointVector, RobotModel};

/// Below this |sin(q5)| the wrist is singular.
pub const WRIST_SINGULAR_EPS: f64 = 1e-9;
/// Below this radial distance (m) of the wrist centre from the J1 axis the shoulder is singular.
pub const SHOULDER_SINGULAR_EPS_M: f64 = 1e-9;
const STRUCTURE_TOL: f64 = 1e-9;
/// [`RobotModel::ik_tool_position_wrist_held`] converges to this tool position error (m) ...
pub const WRIST_HELD_POSITION_M: f64 = 1e-6;
/// ... within this many Newton steps.
const WRIST_HELD_ITERATIONS: usize = 8;

/// Why an inverse kinematics query has no answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IkError {
    /// The target pose has NaN or infinite entries.
    #[error("target pose is not finite")]
    NonFinite,
    /// The wrist centre is farther from (or nearer to) the shoulder than the arm can reach.
    #[error(
        "target out of reach: wrist centre {distance_m:.4} m from the shoulder axis point, arm reaches {min_m:.4} to {max_m:.4} m"
    )]
    Unreachable {
        /// Shoulder to wrist-centre distance of the nearer J1 branch (m).
        distance_m: f64,
        /// Shortest reachable distance (m).
        min_m: f64,
        /// Longest reachable distance (m).
        max_m: f64,
    },
    /// The wrist centre lies on the J1 axis: J1 is not determined.
    #[error("target at the shoulder singularity: the wrist centre lies on the J1 axis, J1 is not determined")]
    ShoulderSingular,
    /// J5 = 0 in every arm solution: only J4 + J6 is determined.
    #[error("target at the wrist singularity: J5 = 0, only J4 + J6 is determined")]
    WristSingular,
    /// Solutions exist but none lies within the joint limits.
    #[error("all {count} kinematic solutions violate the joint limits (first: {first_violation})")]
    OutOfLimits {
        /// How many principal solutions were found.
        count: usize,
        /// Which joint of the first solution is out, and by how much.
        first_violation: String,
    },
}

/// Which principal branch a solution is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Branch {
    /// J1 points the arm at the target (true) or away, reaching over the back (false).
    pub front: bool,
    /// Elbow solution index (0 or 1).
    pub elbow: u8,
    /// J5 positive (true) or negative.
    pub wrist_positive: bool,
}

/// One inverse kinematics solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkSolution {
    /// Joint positions (rad), within limits.
    pub q: JointVector,
    /// The principal branch it came from.
    pub branch: Branch,
}

/// Arm geometry for the closed-form solution, read off the URDF joint origins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkGeometry {
    /// Height of the J2 axis above the base frame origin (m).
    pub shoulder_height_m: f64,
    /// Radial offset of the J2 axis from the J1 axis (m).
    pub shoulder_offset_m: f64,
    /// J2 to J3 in the link-2 frame, (x, z) (m).
    pub upper_arm_m: [f64; 2],
    /// J3 to the wrist centre in the link-3 frame, (x, z) (m).
    pub forearm_m: [f64; 2],
    /// Wrist centre to flange along the flange z axis (m).
    pub wrist_to_flange_m: f64,
}

impl IkGeometry {
    /// Reads the geometry off the joints; refuses chains that are not of the Viper's structure
    /// (axes z, y, y, z, y, z; no rotated origins; no sideways offsets; intersecting wrist axes).
    pub fn from_joints(joints: &[Joint]) -> Result<Self, String> {
        let want = [
            Vector3::z(),
            Vector3::y(),
            Vector3::y(),
            Vector3::z(),
            Vector3::y(),
            Vector3::z(),
        ];
        let mut problems = Vec::new();
        for (i, j) in joints.iter().enumerate().take(DOF) {
            if (j.axis - want[i]).norm() > STRUCTURE_TOL {
                problems.push(format!(
                    "{} axis must be {:?}, got {:?}",
                    j.name,
                    want[i].as_slice(),
                    j.axis.as_slice()
                ));
            }
            if (j.origin_rot - Matrix3::identity()).norm() > STRUCTURE_TOL {
                problems.push(format!("{} origin must have rpy = 0", j.name));
            }
        }
        let o: Vec<Vector3<f64>> = joints.iter().map(|j| j.origin_pos_m).collect();
        let zero = |v: f64| v.abs() <= STRUCTURE_TOL;
        let checks = [
            (
                zero(o[0].x) && zero(o[0].y),
                "joint 1 origin must lie on the base z axis",
            ),
            (zero(o[1].y), "joint 2 origin must have y = 0"),
            (zero(o[2].y), "joint 3 origin must have y = 0"),
            (zero(o[3].y), "joint 4 origin must have y = 0"),
            (
                zero(o[4].x) && zero(o[4].y),
                "joint 5 origin must lie on the J4 axis (spherical wrist)",
            ),
            (
                zero(o[5].x) && zero(o[5].y),
                "joint 6 origin must lie on the J4 axis (spherical wrist)",
            ),
        ];
        problems.extend(checks.iter().filter(|(ok, _)| !ok).map(|(_, m)| m.to_string()));
        if !problems.is_empty() {
            return Err(format!(
                "kinematic structure not supported by the closed-form inverse kinematics: {}",
                problems.join("; ")
            ));
        }
        Ok(IkGeometry {
            shoulder_height_m: o[0].z + o[1].z,
            shoulder_offset_m: o[1].x,
            upper_arm_m: [o[2].x, o[2].z],
            forearm_m: [o[3].x, o[3].z + o[4].z],
            wrist_to_flange_m: o[5].z,
        })
    }
}

/// Wraps an angle to (-pi, pi].
#[inline]
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}

/// Up to eight principal solutions, angles in (-pi, pi], before limits.
#[derive(Debug, Clone, Copy)]
struct Principal {
    q: [JointVector; 8],
    branch: [Branch; 8],
    n: usize,
}

impl RobotModel {
    fn principal_solutions(&self, base_from_flange: &Isometry3<f64>) -> Result<Principal, IkError> {
        let g = &self.ik_geometry;
        let rot = base_from_flange.rotation.to_rotation_matrix();
        let target_rot = rot.matrix();
        let p = base_from_flange.translation.vector;
        if !(p.iter().all(|v| v.is_finite()) && target_rot.iter().all(|v| v.is_finite())) {
            return Err(IkError::NonFinite);
        }
        let wrist = p - target_rot.column(2) * g.wrist_to_flange_m;
        let rho = wrist.x.hypot(wrist.y);
        if rho < SHOULDER_SINGULAR_EPS_M {
            return Err(IkError::ShoulderSingular);
        }
        let [ux, uz] = g.upper_arm_m;
        let [cx, cz] = g.forearm_m;
        let (u2, c2) = (ux * ux + uz * uz, cx * cx + cz * cz);
        // u . Ry(q3) c = A cos q3 + B sin q3 = rr cos(q3 - phi)
        let (a, b) = (ux * cx + uz * cz, ux * cz - uz * cx);
        let rr = a.hypot(b);
        let phi = b.atan2(a);
        let h = wrist.z - g.shoulder_height_m;
        let azimuth = wrist.y.atan2(wrist.x);

        let mut out = Principal {
            q: [JointVector::zeros(); 8],
            branch: [Branch {
                front: true,
                elbow: 0,
                wrist_positive: true,
            }; 8],
            n: 0,
        };
        let mut nearest_distance = f64::INFINITY;
        let mut any_arm = false;
        for front in [true, false] {
            let (q1, radial) = if front {
                (azimuth, rho)
            } else {
                (wrap(azimuth + PI), -rho)
            };
            let r = radial - g.shoulder_offset_m;
            let d2 = r * r + h * h;
            nearest_distance = nearest_distance.min(d2.sqrt());
            let k = (d2 - u2 - c2) / 2.0;
            let ratio = k / rr;
            if ratio.abs() > 1.0 + 1e-12 {
                continue;
            }
            let delta = ratio.clamp(-1.0, 1.0).acos();
            let elbows: &[f64] = if delta == 0.0 { &[0.0] } else { &[delta, -delta] };
            for (e, d) in elbows.iter().enumerate() {
                any_arm = true;
                let q3 = wrap(phi + d);
                let (s3, c3) = q3.sin_cos();
                let (vx, vz) = (ux + cx * c3 + cz * s3, uz - cx * s3 + cz * c3);
                let q2 = wrap(vz.atan2(vx) - h.atan2(r));
                // R_base_link3 = Rz(q1) Ry(q2 + q3); wrist R36 = R03^T R = Rz(q4) Ry(q5) Rz(q6).
                let (s1, c1) = q1.sin_cos();
                let (s23, c23) = (q2 + q3).sin_cos();
                let r03 = Matrix3::new(c1 * c23, -s1, c1 * s23, s1 * c23, c1, s1 * s23, -s23, 0.0, c23);
                let m = r03.transpose() * target_rot;
                let s5 = m[(0, 2)].hypot(m[(1, 2)]);
                if s5 < WRIST_SINGULAR_EPS {
                    continue;
                }
                let q5 = s5.atan2(m[(2, 2)]);
                let q4 = m[(1, 2)].atan2(m[(0, 2)]);
                let q6 = m[(2, 1)].atan2(-m[(2, 0)]);
                for wrist_positive in [true, false] {
                    let q = if wrist_positive {
                        JointVector::new(q1, q2, q3, q4, q5, q6)
                    } else {
                        JointVector::new(q1, q2, q3, wrap(q4 + PI), -q5, wrap(q6 + PI))
                    };
                    out.q[out.n] = q;
                    out.branch[out.n] = Branch {
                        front,
                        elbow: e as u8,
                        wrist_positive,
                    };
                    out.n += 1;
                }
            }
        }
        if out.n == 0 {
            if any_arm {
                return Err(IkError::WristSingular);
            }
            let (ul, cl) = (u2.sqrt(), c2.sqrt());
            return Err(IkError::Unreachable {
                distance_m: nearest_distance,
                min_m: (ul - cl).abs(),
                max_m: ul + cl,
            });
        }
        Ok(out)
    }

    /// Calls `f` for every in-limit solution (multi-turn variants included) of the flange pose.
    /// Returns the number of principal solutions, or the error when there is no solution at all.
    fn for_each_solution(
        &self,
        base_from_flange: &Isometry3<f64>,
        mut f: impl FnMut(IkSolution),
    ) -> Result<usize, IkError> {
        let principal = self.principal_solutions(base_from_flange)?;
        let mut found = 0usize;
        let mut first_violation = String::new();
        for s in 0..principal.n {
            let q = principal.q[s];
            // Candidate values per joint: q + 2 pi k within the limits.
            let mut cand = [[0.0f64; 3]; DOF];
            let mut count = [0usize; DOF];
            for i in 0..DOF {
                let j = &self.joints[i];
                for k in [-1.0, 0.0, 1.0] {
                    let v = q[i] + k * TAU;
                    if v >= j.lower_rad && v <= j.upper_rad {
                        cand[i][count[i]] = v;
                        count[i] += 1;
                    }
                }
                if count[i] == 0 && first_violation.is_empty() {
                    first_violation = format!(
                        "{} = {:.2} deg outside [{:.1}, {:.1}]",
                        j.name,
                        q[i].to_degrees(),
                        j.lower_rad.to_degrees(),
                        j.upper_rad.to_degrees()
                    );
                }
            }
            if count.contains(&0) {
                continue;
            }
            let mut idx = [0usize; DOF];
            loop {
                let q = JointVector::from_fn(|i, _| cand[i][idx[i]]);
                f(IkSolution {
                    q,
                    branch: principal.branch[s],
                });
                found += 1;
                let mut i = 0;
                while i < DOF {
                    idx[i] += 1;
                    if idx[i] < count[i] {
                        break;
                    }
                    idx[i] = 0;
                    i += 1;
                }
                if i == DOF {
                    break;
                }
            }
        }
        if found == 0 {
            return Err(IkError::OutOfLimits {
                count: principal.n,
                first_violation,
            });
        }
        Ok(principal.n)
    }

    /// Every in-limit solution for a flange pose in the base frame.
    pub fn ik_flange_all(&self, base_from_flange: &Isometry3<f64>) -> Result<Vec<IkSolution>, IkError> {
        let mut out = Vec::with_capacity(16);
        self.for_each_solution(base_from_flange, |s| out.push(s))?;
        Ok(out)
    }

    /// The in-limit solution nearest `seed`: the one the arm reaches soonest moving every joint at
    /// its top speed (largest |dq_i| / v_max_i), ties broken by the Euclidean joint distance.
    pub fn ik_flange_nearest(
        &self,
        base_from_flange: &Isometry3<f64>,
        seed: &JointVector,
    ) -> Result<IkSolution, IkError> {
        let mut best: Option<(f64, f64, IkSolution)> = None;
        self.for_each_solution(base_from_flange, |s| {
            let mut time = 0.0f64;
            let mut dist2 = 0.0;
            for i in 0..DOF {
                let d = s.q[i] - seed[i];
                time = time.max(d.abs() / self.joints[i].max_vel_rad_s);
                dist2 += d * d;
            }
            if best
                .as_ref()
                .is_none_or(|(t, e, _)| time < *t - 1e-12 || (time <= *t + 1e-12 && dist2 < *e))
            {
                best = Some((time, dist2, s));
            }
        })?;
        Ok(best.expect("for_each_solution found at least one").2)
    }

    /// The flange pose that puts the tool at `world_from_tool`, in the base frame.
    pub fn base_from_flange_for_tool(&self, world_from_tool: &Isometry3<f64>) -> Isometry3<f64> {
        self.world_from_base.inverse() * world_from_tool * self.flange_from_tool.inverse()
    }

    /// Every in-limit solution that puts the tool at `world_from_tool`.
    pub fn ik_tool_all(&self, world_from_tool: &Isometry3<f64>) -> Result<Vec<IkSolution>, IkError> {
        self.ik_flange_all(&self.base_from_flange_for_tool(world_from_tool))
    }

    /// The in-limit solution nearest `seed` that puts the tool at `world_from_tool`.
    pub fn ik_tool_nearest(&self, world_from_tool: &Isometry3<f64>, seed: &JointVector) -> Result<IkSolution, IkError> {
        self.ik_flange_nearest(&self.base_from_flange_for_tool(world_from_tool), seed)
    }

    /// The joints that put the tool centre point at `world_tool_m` with the wrist joints (J4-J6)
    /// held at `seed`'s, the arm joints (J1-J3) found by Newton's method from `seed`'s (so on its
    /// branch): the tool's orientation is whatever the wrist then gives. `None` if it does not
    /// converge to [`WRIST_HELD_POSITION_M`] or leaves the joint limits. A controller's straight
    /// line with the wrist joints interpolated ([`crate::trajectory::straight_line`]) needs it.
    pub fn ik_tool_position_wrist_held(&self, world_tool_m: &Vector3<f64>, seed: &JointVector) -> Option<JointVector> {
        let mut q = *seed;
        for _ in 0..WRIST_HELD_ITERATIONS {
            let err = world_tool_m - self.world_from_tool(&q).translation.vector;
            if err.norm() < WRIST_HELD_POSITION_M {
                return self.within_limits(&q, 0.0).then_some(q);
            }
            let err_base = self.world_from_base.rotation.inverse() * err;
            let jac = self.jacobian_tool(&q).fixed_view::<3, 3>(0, 0).into_owned();
            let step = jac.lu().solve(&err_base)?;
            if !step.iter().all(|v| v.is_finite()) {
                return None;
            }
            for i in 0..3 {
                q[i] += step[i];
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::test_support::{default_robot, random_q};
    use nalgebra::UnitQuaternion;
    use rand::SeedableRng;

    fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
        (
            (a.translation.vector - b.translation.vector).norm(),
            a.rotation.angle_to(&b.rotation),
        )
    }

    #[test]
    fn round_trip_10000_random_configurations() {
        let r = default_robot();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2024);
        let mut total_solutions = 0usize;
        let mut worst = (0.0f64, 0.0f64);
        let mut skipped_singular = 0;
        for n in 0..10_000 {
            let q = random_q(&r, &mut rng);
            let target = r.base_from_flange(&q);
            let sols = match r.ik_flange_all(&target) {
                Ok(s) => s,
                Err(IkError::WristSingular) if q[4].sin().abs() < 1e-8 => {
                    skipped_singular += 1;
                    continue;
                }
                Err(e) => panic!("sample {n}: q = {q:?}: {e}"),
            };
            assert!(sols.len() <= 8 * 3 * 3 * 2, "too many solutions");
            total_solutions += sols.len();
            for s in &sols {
                assert!(r.within_limits(&s.q, 0.0), "solution out of limits: {:?}", s.q);
                let (dp, dr) = pose_error(&r.base_from_flange(&s.q), &target);
                worst = (worst.0.max(dp), worst.1.max(dr));
                assert!(
                    dp < 1e-9 && dr < 1e-9,
                    "sample {n}: solution {:?} misses by {dp} m, {dr} rad",
                    s.q
                );
            }
            let found = sols.iter().any(|s| (s.q - q).amax() < 1e-6);
            assert!(found, "sample {n}: original {q:?} not among {} solutions", sols.len());
        }
        assert!(skipped_singular < 5);
        assert!(
            total_solutions > 10_000 * 4,
            "suspiciously few solutions: {total_solutions}"
        );
        eprintln!("IK round trip: worst {:.2e} m, {:.2e} rad", worst.0, worst.1);
    }

    #[test]
    fn nearest_returns_the_seed_itself() {
        let r = default_robot();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for _ in 0..500 {
            let q = random_q(&r, &mut rng);
            if q[4].sin().abs() < 1e-3 {
                continue;
            }
            let s = r.ik_flange_nearest(&r.base_from_flange(&q), &q).unwrap();
            assert!((s.q - q).amax() < 1e-6, "{:?} vs {:?}", s.q, q);
        }
    }

    #[test]
    fn j6_multi_turn_variants_are_listed() {
        let r = default_robot();
        let q = JointVector::new(0.3, -0.9, 2.2, 0.2, 0.8, 0.5);
        let sols = r.ik_flange_all(&r.base_from_flange(&q)).unwrap();
        assert!(sols.iter().any(|s| (s.q - q).amax() < 1e-9));
        let mut turned = q;
        turned[5] -= TAU;
        assert!(
            sols.iter().any(|s| (s.q - turned).amax() < 1e-9),
            "J6 - 360 deg variant missing"
        );
    }

    #[test]
    fn unreachable_and_singular_targets_are_typed_errors() {
        let r = default_robot();
        let far = Isometry3::translation(1.5, 0.0, 0.3);
        assert!(matches!(r.ik_flange_all(&far), Err(IkError::Unreachable { .. })));
        // Wrist centre on the J1 axis: flange straight above the base pointing up.
        let above = Isometry3::translation(0.0, 0.0, 0.9);
        assert_eq!(r.ik_flange_all(&above).unwrap_err(), IkError::ShoulderSingular);
        // J5 = 0 with the arm fully stretched: the one arm solution is wrist-singular (the
        // reach-over-the-back branch is out of reach), so the target is singular.
        let g = r.ik_geometry;
        let stretched_q3 = g.forearm_m[1].atan2(g.forearm_m[0]) - g.upper_arm_m[1].atan2(g.upper_arm_m[0]);
        let stretched = JointVector::new(0.2, 0.1, stretched_q3, 0.0, 0.0, 0.0);
        assert_eq!(
            r.ik_flange_all(&r.base_from_flange(&stretched)).unwrap_err(),
            IkError::WristSingular
        );
        // READY has J5 = 0 on its own branch: that branch is skipped, never returned with
        // arbitrary J4/J6; the other elbow branch is regular and is returned.
        let ready = JointVector::new(0.0, -PI / 2.0, PI, 0.0, 0.0, 0.0);
        let sols = r.ik_flange_all(&r.base_from_flange(&ready)).unwrap();
        assert!(sols.iter().all(|s| s.q[4].sin().abs() > 1e-3));
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.3);
        assert_eq!(r.ik_flange_all(&nan).unwrap_err(), IkError::NonFinite);
    }

    #[test]
    fn tool_target_in_world_round_trips() {
        let r = default_robot();
        let world_from_tool = Isometry3::from_parts(
            nalgebra::Translation3::new(0.1, 0.45, 0.05),
            UnitQuaternion::from_euler_angles(PI, 0.0, 0.3),
        );
        let s = r
            .ik_tool_nearest(&world_from_tool, &r.lower_rad().map(|_| 0.0))
            .unwrap();
        let (dp, dr) = pose_error(&r.world_from_tool(&s.q), &world_from_tool);
        assert!(dp < 1e-9 && dr < 1e-9);
    }
}
