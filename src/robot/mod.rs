//! Robot model: the Viper s650 built from its URDF plus the cell file's drive data.
//!
//! Job: load and check the URDF (a serial chain of six revolute joints from the root link to the
//! flange link), and hold everything the kinematics and dynamics need: joint origins and axes,
//! limits, link inertials, drive data (armature, friction, acceleration and torque limits),
//! collision geometry, the base pose in the world and the tool on the flange.
//!
//! Units: SI (m, rad, s, kg, N m). Frames: `base` is the robot's root link frame; link `i` is the
//! URDF child frame of joint `i` (the joint-zero frame); `flange` is link 6; `tool` is the cup
//! lip, `gripper.tool_length_m` along the flange z axis. `world_from_base` places the robot.
//!
//! Submodules: `urdf` (the model built from the URDF and checked), [`kinematics`] (forward
//! kinematics, Jacobian), [`ik`] (closed-form inverse kinematics), [`dynamics`] (recursive
//! Newton-Euler, mass matrix, forward dynamics, payload).

pub mod dynamics;
pub mod ik;
pub mod kinematics;
pub mod plant;
mod urdf;

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3, Vector6};

pub use crate::config::AccelCap;
use crate::config::{Checker, ConfigError};

pub use dynamics::{DynamicsModel, Payload};
pub use ik::{IkError, IkSolution};

/// Number of joints.
pub const DOF: usize = 6;

/// Joint-space vector (positions (rad), velocities [rad/s], accelerations [rad/s^2] or torques [N m]).
pub type JointVector = Vector6<f64>;

/// Standard gravity [m/s^2].
pub const GRAVITY_M_S2: f64 = 9.80665;

/// One revolute joint with its limits and drive data.
#[derive(Debug, Clone)]
pub struct Joint {
    /// URDF joint name.
    pub name: String,
    /// Child link name.
    pub child_link: String,
    /// `parent_from_joint_zero`: the joint origin in the parent link frame.
    pub parent_from_origin: Isometry3<f64>,
    /// Rotation part of `parent_from_origin` as a matrix (cached for the hot paths).
    pub origin_rot: Matrix3<f64>,
    /// Translation part of `parent_from_origin` (m) (cached for the hot paths).
    pub origin_pos_m: Vector3<f64>,
    /// Rotation axis, unit, in the child link frame.
    pub axis: Vector3<f64>,
    /// Lower position limit (rad).
    pub lower_rad: f64,
    /// Upper position limit (rad).
    pub upper_rad: f64,
    /// Maximum speed [rad/s].
    pub max_vel_rad_s: f64,
    /// Specification acceleration [rad/s^2]: the controller's default parameters stay within
    /// it; it caps planned motions only when the robot's [`AccelCap`] is `Spec`.
    pub max_accel_rad_s2: f64,
    /// Peak torque limit [N m].
    pub torque_limit_nm: f64,
    /// Reflected rotor inertia [kg m^2].
    pub armature_kg_m2: f64,
    /// Coulomb friction [N m].
    pub coulomb_nm: f64,
    /// Viscous friction [N m s/rad].
    pub viscous_nm_s_per_rad: f64,
}

/// Mass properties of a rigid body in its own frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    /// Mass (kg).
    pub mass_kg: f64,
    /// Centre of mass in the body frame (m).
    pub com_m: Vector3<f64>,
    /// Inertia about the centre of mass, axes along the body frame [kg m^2].
    pub inertia_com_kg_m2: Matrix3<f64>,
}

/// A collision/visual primitive in a link frame.
#[derive(Debug, Clone, PartialEq)]
pub enum LinkPrimitive {
    /// Box with half extents (m).
    Box {
        /// Half extents (m).
        half_extents_m: Vector3<f64>,
    },
    /// Cylinder along the local z axis.
    Cylinder {
        /// Radius (m).
        radius_m: f64,
        /// Half length (m).
        half_length_m: f64,
    },
    /// Sphere.
    Sphere {
        /// Radius (m).
        radius_m: f64,
    },
    /// Capsule along the local z axis.
    Capsule {
        /// Radius (m).
        radius_m: f64,
        /// Half length of the segment (m).
        half_length_m: f64,
    },
}

/// A primitive placed in a link frame.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkShape {
    /// `link_from_shape`.
    pub link_from_shape: Isometry3<f64>,
    /// The primitive.
    pub primitive: LinkPrimitive,
}

/// A link: name, mass properties, collision geometry.
#[derive(Debug, Clone)]
pub struct Link {
    /// URDF link name.
    pub name: String,
    /// Mass properties.
    pub inertial: Inertial,
    /// Collision geometry (URDF `<collision>` elements).
    pub shapes: Vec<LinkShape>,
}

/// The robot: six revolute joints in series, links 0 (base) to 6 (flange).
#[derive(Debug, Clone)]
pub struct RobotModel {
    /// URDF robot name.
    pub name: String,
    /// The joints, base to flange.
    pub joints: Vec<Joint>,
    /// The links: index 0 is the base (fixed), index i the child of joint i.
    pub links: Vec<Link>,
    /// Where the base stands in the world.
    pub world_from_base: Isometry3<f64>,
    /// The tool frame on the flange.
    pub flange_from_tool: Isometry3<f64>,
    /// Gravity in the base frame [m/s^2].
    pub gravity_base_m_s2: Vector3<f64>,
    /// Coulomb friction smoothing speed: friction = coulomb * tanh(qd / this) [rad/s].
    pub coulomb_smoothing_rad_s: f64,
    /// Whether the specification accelerations cap planned motions (`robot.drives.accel_cap`).
    pub accel_cap: AccelCap,
    /// Parameters of the closed-form inverse kinematics, derived from the joint origins.
    pub ik_geometry: ik::IkGeometry,
}

impl RobotModel {
    /// Lower position limits (rad).
    pub fn lower_rad(&self) -> JointVector {
        JointVector::from_fn(|i, _| self.joints[i].lower_rad)
    }

    /// Upper position limits (rad).
    pub fn upper_rad(&self) -> JointVector {
        JointVector::from_fn(|i, _| self.joints[i].upper_rad)
    }

    /// Maximum joint speeds [rad/s].
    pub fn max_vel_rad_s(&self) -> JointVector {
        JointVector::from_fn(|i, _| self.joints[i].max_vel_rad_s)
    }

    /// Specification accelerations [rad/s^2] (a cap on planned motions only with
    /// [`AccelCap::Spec`]: see [`Self::accel_cap_rad_s2`]).
    pub fn max_accel_rad_s2(&self) -> JointVector {
        JointVector::from_fn(|i, _| self.joints[i].max_accel_rad_s2)
    }

    /// The acceleration cap planned motions keep to besides the torque limits [rad/s^2]: the
    /// specification accelerations with [`AccelCap::Spec`], none (the torque alone binds) with
    /// [`AccelCap::TorqueOnly`].
    pub fn accel_cap_rad_s2(&self) -> Option<JointVector> {
        match self.accel_cap {
            AccelCap::Spec => Some(self.max_accel_rad_s2()),
            AccelCap::TorqueOnly => None,
        }
    }

    /// The arm with its planned motions capped (or not) by the specification accelerations
    /// (the cell file's `robot.drives.accel_cap` overridden).
    pub fn with_accel_cap(&self, cap: AccelCap) -> RobotModel {
        let mut r = self.clone();
        r.accel_cap = cap;
        r
    }

    /// Torque limits [N m].
    pub fn torque_limit_nm(&self) -> JointVector {
        JointVector::from_fn(|i, _| self.joints[i].torque_limit_nm)
    }

    /// Whether `q` is within the position limits (inclusive, with `tol_rad` slack).
    pub fn within_limits(&self, q: &JointVector, tol_rad: f64) -> bool {
        self.joints
            .iter()
            .zip(q.iter())
            .all(|(j, v)| *v >= j.lower_rad - tol_rad && *v <= j.upper_rad + tol_rad)
    }

    /// Total mass of the moving links (kg).
    pub fn moving_mass_kg(&self) -> f64 {
        self.links[1..].iter().map(|l| l.inertial.mass_kg).sum()
    }
}

/// `world_from_tool` with the tool's z axis pointing straight down at `xyz`, turned by `yaw_rad`.
pub fn tool_down_pose(xyz: Vector3<f64>, yaw_rad: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(xyz),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_rad)
            * UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
    )
}

impl RobotModel {
    /// Whether the tool can point straight down at `xyz` (world) at any yaw (tried every 15 deg).
    pub fn reaches_tool_down(&self, xyz: Vector3<f64>) -> Result<(), IkError> {
        let mut last = None;
        for k in 0..24 {
            match self.ik_tool_all(&tool_down_pose(xyz, (k as f64 * 15.0).to_radians())) {
                Ok(_) => return Ok(()),
                Err(e) => last = Some(e),
            }
        }
        Err(last.expect("tried at least one yaw"))
    }

    /// Checks that the arm reaches, with the tool pointing down, every corner of both trays' inner
    /// floors (1 cm in from the walls), their centres, and the points 5 cm above their rims.
    pub fn check_scene_reach(&self, label: &str, scene: &crate::config::Scene) -> Result<(), ConfigError> {
        let mut c = Checker::new(label);
        for (key, tray) in [
            ("pick_tray", &scene.pick_tray),
            ("place_tray.tray", &scene.place_tray.tray),
        ] {
            let world_from_tray = tray.world_from_tray();
            let (hx, hy) = (tray.inner_size_m[0] / 2.0 - 0.01, tray.inner_size_m[1] / 2.0 - 0.01);
            let mut points = vec![(0.0, 0.0, 0.002), (0.0, 0.0, tray.wall_height_m + 0.05)];
            for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                points.push((sx * hx.max(0.0), sy * hy.max(0.0), 0.002));
            }
            for (x, y, z) in points {
                let p = world_from_tray * nalgebra::Point3::new(x, y, z);
                if let Err(e) = self.reaches_tool_down(p.coords) {
                    c.fail(
                        key,
                        format!(
                            "is out of the arm's reach: the tool cannot point down at ({:.3}, {:.3}, {:.3}) m: {e}",
                            p.x, p.y, p.z
                        ),
                    );
                    break;
                }
            }
        }
        c.finish()
    }
}

#[cfg(test)]
pub(crate) mod test_support {
    use super::*;
    use crate::config::LoadedScene;

    /// The default cell's robot.
    pub fn default_robot() -> RobotModel {
        let scene = LoadedScene::embedded_default().expect("embedded default scene");
        RobotModel::from_scene(&scene).expect("embedded robot")
    }

    /// Uniformly random in-limit configuration from a simple deterministic generator.
    pub fn random_q(robot: &RobotModel, rng: &mut impl rand::RngExt) -> JointVector {
        JointVector::from_fn(|i, _| rng.random_range(robot.joints[i].lower_rad..robot.joints[i].upper_rad))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{LoadedScene, embedded::VIPER_S650_URDF};

    /// Loads `urdf` with the default cell's robot section: on its own (`check x.urdf`), and as the
    /// URDF of a cell file labelled `cell.toml` whose flange link is `flange`.
    fn load(urdf: &str, flange: &str) -> (Result<RobotModel, ConfigError>, Result<RobotModel, ConfigError>) {
        let mut scene = LoadedScene::embedded_default().expect("embedded default scene");
        let alone = RobotModel::from_urdf("x.urdf", urdf, &scene.scene.robot, &scene.scene.gripper);
        scene.scene.robot.flange_link = flange.to_string();
        scene.label = "cell.toml".into();
        scene.urdf_label = "x.urdf".into();
        scene.urdf_text = urdf.to_string();
        (alone, RobotModel::from_scene(&scene))
    }

    fn lines(r: Result<RobotModel, ConfigError>) -> String {
        r.map(|_| String::new()).unwrap_or_else(|e| e.to_string())
    }

    #[test]
    fn every_reference_between_urdf_elements_is_checked() {
        let link3 = VIPER_S650_URDF.find("<link name=\"link_3\">").unwrap();
        let link3_end = link3 + VIPER_S650_URDF[link3..].find("</link>").unwrap() + "</link>".len();
        let joint4 = VIPER_S650_URDF.find("<joint name=\"joint_4\"").unwrap();
        let joint4_end = joint4 + VIPER_S650_URDF[joint4..].find("</joint>").unwrap() + "</joint>".len();
        let cases: [(String, &[&str]); 7] = [
            (
                format!("{}{}", &VIPER_S650_URDF[..link3], &VIPER_S650_URDF[link3_end..]),
                &[
                    "x.urdf: joint[joint_3].child names link \"link_3\", which the URDF does not define",
                    "x.urdf: joint[joint_4].parent names link \"link_3\", which the URDF does not define",
                ],
            ),
            (
                VIPER_S650_URDF.replacen("<link name=\"link_2\">", "<link name=\"link_two\">", 1),
                &["x.urdf: joint[joint_2].child names link \"link_2\", which the URDF does not define"],
            ),
            (
                VIPER_S650_URDF.replacen("<link name=\"link_2\">", "<link name=\"link_1\">", 1),
                &["x.urdf: link[link_1] is defined 2 times; link names must be unique"],
            ),
            (
                VIPER_S650_URDF.replacen("<joint name=\"joint_5\"", "<joint name=\"joint_4\"", 1),
                &["x.urdf: joint[joint_4] is defined 2 times; joint names must be unique"],
            ),
            (
                VIPER_S650_URDF.replacen("<child link=\"link_5\"/>", "<child link=\"link_4\"/>", 1),
                &[
                    "x.urdf: joint[joint_5] has the same parent and child link, got \"link_4\"",
                    "x.urdf: joint[joint_5].child names link \"link_4\", which is already the child of joint \"joint_4\"",
                ],
            ),
            (
                VIPER_S650_URDF.replacen("<parent link=\"base_link\"/>", "<parent link=\"link_3\"/>", 1),
                &["x.urdf: joint[joint_3] closes a cycle in the joint tree: walking up from \"link_6\""],
            ),
            (
                format!("{}{}", &VIPER_S650_URDF[..joint4], &VIPER_S650_URDF[joint4_end..]),
                &["x.urdf: needs a chain of 6 revolute joints from its root link to \"link_6\", found 2"],
            ),
        ];
        for (urdf, expected) in cases {
            let (alone, in_cell) = load(&urdf, "link_6");
            let (alone, in_cell) = (lines(alone), lines(in_cell));
            for e in expected {
                assert!(alone.contains(e), "lacks {e:?}:\n{alone}");
            }
            assert_eq!(alone, in_cell, "the URDF is to blame in a cell too");
        }
    }

    #[test]
    fn a_flange_link_the_urdf_lacks_or_that_is_mid_chain_is_the_cell_files_problem() {
        let (alone, in_cell) = load(VIPER_S650_URDF, "link_9");
        assert!(lines(in_cell).starts_with("cell.toml: robot.flange_link names no link of x.urdf, got \"link_9\""));
        assert!(
            alone.is_ok(),
            "alone, the URDF is checked against the default cell's flange link_6"
        );
        let (_, in_cell) = load(VIPER_S650_URDF, "link_3");
        let e = lines(in_cell);
        assert!(
            e.starts_with("cell.toml: robot.flange_link names link \"link_3\" of x.urdf, which is 3 joint(s) from its root link (joint_1, joint_2, joint_3) and has more joints beyond it"),
            "{e}"
        );
        // A URDF that names the default flange link nowhere: the URDF's problem when checked alone.
        let renamed = VIPER_S650_URDF.replace("\"link_6\"", "\"tool0\"");
        let (alone, _) = load(&renamed, "link_6");
        assert_eq!(
            lines(alone),
            "x.urdf: has no link named \"link_6\" (the cell's robot.flange_link)"
        );
    }

    #[test]
    fn collision_origins_must_be_finite() {
        let at = VIPER_S650_URDF.find("<collision>").unwrap();
        let origin = at + VIPER_S650_URDF[at..].find("<origin xyz=\"").unwrap() + "<origin xyz=\"".len();
        assert_eq!(&VIPER_S650_URDF[origin..origin + 2], "0 ");
        let urdf = format!("{}nan{}", &VIPER_S650_URDF[..origin], &VIPER_S650_URDF[origin + 1..]);
        let e = lines(load(&urdf, "link_6").0);
        assert!(
            e.contains("x.urdf: link[base_link].collision[0].origin must be finite, got xyz [NaN,"),
            "{e}"
        );
    }
}
