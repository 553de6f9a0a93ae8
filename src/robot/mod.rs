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
//! Submodules: [`kinematics`] (forward kinematics, Jacobian), [`ik`] (closed-form inverse
//! kinematics), [`dynamics`] (recursive Newton-Euler, mass matrix, forward dynamics, payload).

pub mod dynamics;
pub mod ik;
pub mod kinematics;
pub mod model_error;

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3, Vector6};

pub use crate::config::AccelCap;
use crate::config::{Checker, ConfigError, GripperConfig, Problem, RobotConfig};

pub use dynamics::{DynamicsModel, Payload};
pub use ik::{IkError, IkSolution};

/// Number of joints.
pub const DOF: usize = 6;

/// Joint-space vector (positions [rad], velocities [rad/s], accelerations [rad/s^2] or torques [N m]).
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
    /// Translation part of `parent_from_origin` [m] (cached for the hot paths).
    pub origin_pos_m: Vector3<f64>,
    /// Rotation axis, unit, in the child link frame.
    pub axis: Vector3<f64>,
    /// Lower position limit [rad].
    pub lower_rad: f64,
    /// Upper position limit [rad].
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
    /// Mass [kg].
    pub mass_kg: f64,
    /// Centre of mass in the body frame [m].
    pub com_m: Vector3<f64>,
    /// Inertia about the centre of mass, axes along the body frame [kg m^2].
    pub inertia_com_kg_m2: Matrix3<f64>,
}

/// A collision/visual primitive in a link frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Primitive {
    /// Box with half extents [m].
    Box {
        /// Half extents [m].
        half_extents_m: Vector3<f64>,
    },
    /// Cylinder along the local z axis.
    Cylinder {
        /// Radius [m].
        radius_m: f64,
        /// Half length [m].
        half_length_m: f64,
    },
    /// Sphere.
    Sphere {
        /// Radius [m].
        radius_m: f64,
    },
    /// Capsule along the local z axis.
    Capsule {
        /// Radius [m].
        radius_m: f64,
        /// Half length of the segment [m].
        half_length_m: f64,
    },
}

/// A primitive placed in a link frame.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkShape {
    /// `link_from_shape`.
    pub link_from_shape: Isometry3<f64>,
    /// The primitive.
    pub primitive: Primitive,
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

fn vec3(v: &urdf_rs::Vec3) -> Vector3<f64> {
    Vector3::new(v[0], v[1], v[2])
}

fn pose(p: &urdf_rs::Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p.xyz[0], p.xyz[1], p.xyz[2]),
        UnitQuaternion::from_euler_angles(p.rpy[0], p.rpy[1], p.rpy[2]),
    )
}

fn all_finite(vals: &[f64]) -> bool {
    vals.iter().all(|v| v.is_finite())
}

/// The joints from the root link to the flange link, each with its child link.
type Chain<'u> = Vec<(&'u urdf_rs::Joint, &'u urdf_rs::Link)>;

/// How many times each name occurs, for the names that occur more than once.
fn repeated<'u>(names: impl Iterator<Item = &'u str>) -> BTreeMap<&'u str, usize> {
    let mut count: BTreeMap<&str, usize> = BTreeMap::new();
    for n in names {
        *count.entry(n).or_default() += 1;
    }
    count.retain(|_, n| *n > 1);
    count
}

/// Checks every reference between the URDF's elements and finds the serial chain from the root
/// link to `flange_link`: link and joint names are unique, every joint's parent and child are
/// links the file defines, no link has two parent joints, the flange link exists, the chain up
/// from it reaches a root without a cycle and has [`DOF`] joints. Returns the root link and the
/// chain, base to flange; every problem names the URDF, the element and the bad name.
///
/// `scene` is the label of the cell file that names the flange link, when there is one: a flange
/// link the URDF lacks, or one that is not the end of the URDF's chain, is then that file's problem
/// (key `robot.flange_link`); on its own, the URDF is to blame.
fn kinematic_chain<'u>(
    label: &str,
    urdf: &'u urdf_rs::Robot,
    flange_link: &str,
    scene: Option<&str>,
) -> Result<(&'u urdf_rs::Link, Chain<'u>), ConfigError> {
    let scene_problem = |scene: &str, message: String| ConfigError {
        problems: vec![Problem {
            file: scene.to_string(),
            key: "robot.flange_link".to_string(),
            message,
        }],
    };
    let mut c = Checker::new(label);
    for (name, n) in repeated(urdf.links.iter().map(|l| l.name.as_str())) {
        c.fail(
            &format!("link[{name}]"),
            format!("is defined {n} times; link names must be unique"),
        );
    }
    for (name, n) in repeated(urdf.joints.iter().map(|j| j.name.as_str())) {
        c.fail(
            &format!("joint[{name}]"),
            format!("is defined {n} times; joint names must be unique"),
        );
    }
    let links_by_name: BTreeMap<&str, &urdf_rs::Link> = urdf.links.iter().map(|l| (l.name.as_str(), l)).collect();
    let mut by_child: BTreeMap<&str, &urdf_rs::Joint> = BTreeMap::new();
    for j in &urdf.joints {
        let key = format!("joint[{}]", j.name);
        for (end, link) in [("parent", &j.parent.link), ("child", &j.child.link)] {
            if !links_by_name.contains_key(link.as_str()) {
                c.fail(
                    &format!("{key}.{end}"),
                    format!("names link {link:?}, which the URDF does not define"),
                );
            }
        }
        if j.parent.link == j.child.link {
            c.fail(
                &key,
                format!("has the same parent and child link, got {:?}", j.child.link),
            );
        }
        if let Some(first) = by_child.insert(j.child.link.as_str(), j) {
            c.fail(
                &format!("joint[{}].child", j.name),
                format!(
                    "names link {:?}, which is already the child of joint {:?}; a link has one parent joint",
                    j.child.link, first.name
                ),
            );
        }
    }
    let mut problems = c.problems;
    if !links_by_name.contains_key(flange_link) {
        match scene {
            Some(scene) => {
                problems.extend(scene_problem(scene, format!("names no link of {label}, got {flange_link:?}")).problems)
            }
            None => problems.push(Problem {
                file: label.to_string(),
                key: String::new(),
                message: format!("has no link named {flange_link:?} (the cell's robot.flange_link)"),
            }),
        }
    }
    if !problems.is_empty() {
        return Err(ConfigError { problems });
    }

    // Walk from the flange link up to the root through the joints' child links.
    let mut chain: Chain<'u> = Vec::new();
    let mut link = flange_link;
    let mut visited = std::collections::BTreeSet::new();
    while let Some(&j) = by_child.get(link) {
        if !visited.insert(link) {
            let names: Vec<&str> = chain.iter().map(|(j, _)| j.name.as_str()).collect();
            return Err(ConfigError::one(
                label,
                &format!("joint[{}]", j.name),
                format!(
                    "closes a cycle in the joint tree: walking up from {flange_link:?} through joints {} returns to link {link:?}",
                    names.join(", ")
                ),
            ));
        }
        let child = links_by_name.get(link).copied();
        let Some(child) = child else {
            return Err(ConfigError::one(
                label,
                &format!("joint[{}].child", j.name),
                format!("names link {link:?}, which the URDF does not define"),
            ));
        };
        chain.push((j, child));
        link = j.parent.link.as_str();
    }
    chain.reverse();
    let Some(root) = links_by_name.get(link).copied() else {
        return Err(ConfigError::one(
            label,
            "",
            format!("has no link named {link:?} (the root of the chain to {flange_link:?})"),
        ));
    };
    if chain.len() != DOF {
        let names: Vec<&str> = chain.iter().map(|(j, _)| j.name.as_str()).collect();
        let mid_chain = urdf.joints.iter().any(|j| j.parent.link == flange_link);
        if let (Some(scene), true) = (scene, mid_chain) {
            return Err(scene_problem(
                scene,
                format!(
                    "names link {flange_link:?} of {label}, which is {} joint(s) from its root link ({}) and has more joints beyond it; the flange link must end a chain of {DOF} revolute joints",
                    chain.len(),
                    names.join(", ")
                ),
            ));
        }
        let roots = urdf
            .links
            .iter()
            .filter(|l| !by_child.contains_key(l.name.as_str()))
            .count();
        let hint = if roots > 1 {
            format!("; link {link:?} is the child of no joint, so a joint between it and its parent is missing")
        } else {
            String::new()
        };
        return Err(ConfigError::one(
            label,
            "",
            format!(
                "needs a chain of {DOF} revolute joints from its root link to {flange_link:?}, found {} ({}){hint}",
                chain.len(),
                names.join(", ")
            ),
        ));
    }
    Ok((root, chain))
}

impl RobotModel {
    /// Builds the model from URDF text and the cell's robot and gripper sections.
    /// `label` names the URDF in error messages.
    pub fn from_urdf(
        label: &str,
        urdf_text: &str,
        robot: &RobotConfig,
        gripper: &GripperConfig,
    ) -> Result<Self, ConfigError> {
        Self::build(label, urdf_text, robot, gripper, None)
    }

    /// Builds the model of a loaded scene.
    pub fn from_scene(scene: &crate::config::LoadedScene) -> Result<Self, ConfigError> {
        Self::build(
            &scene.urdf_label,
            &scene.urdf_text,
            &scene.scene.robot,
            &scene.scene.gripper,
            Some(&scene.label),
        )
    }

    /// [`Self::from_urdf`]; `scene` labels the cell file the robot section came from, if any.
    fn build(
        label: &str,
        urdf_text: &str,
        robot: &RobotConfig,
        gripper: &GripperConfig,
        scene: Option<&str>,
    ) -> Result<Self, ConfigError> {
        let urdf = urdf_rs::read_from_string(urdf_text).map_err(|e| {
            let msg = e.to_string().replace('\n', " ");
            ConfigError::one(label, "", format!("is not a valid URDF: {msg}"))
        })?;
        let (root, chain) = kinematic_chain(label, &urdf, &robot.flange_link, scene)?;
        let mut c = Checker::new(label);

        let d = &robot.drives;
        let mut joints = Vec::with_capacity(DOF);
        for (i, &(j, _)) in chain.iter().enumerate() {
            let key = format!("joint[{}]", j.name);
            if j.joint_type != urdf_rs::JointType::Revolute {
                c.fail(&key, format!("must be revolute, got {:?}", j.joint_type));
            }
            if !all_finite(&[
                j.origin.xyz[0],
                j.origin.xyz[1],
                j.origin.xyz[2],
                j.origin.rpy[0],
                j.origin.rpy[1],
                j.origin.rpy[2],
            ]) {
                c.fail(
                    &format!("{key}.origin"),
                    format!("must be finite, got xyz {:?} rpy {:?}", j.origin.xyz.0, j.origin.rpy.0),
                );
            }
            let axis = vec3(&j.axis.xyz);
            let axis = match axis.try_normalize(1e-9) {
                Some(a) if all_finite(axis.as_slice()) => a,
                _ => {
                    c.fail(
                        &format!("{key}.axis"),
                        format!("must be a finite non-zero vector, got {:?}", j.axis.xyz.0),
                    );
                    Vector3::z()
                }
            };
            let l = &j.limit;
            if !all_finite(&[l.lower, l.upper]) {
                c.fail(
                    &format!("{key}.limit"),
                    format!("lower and upper must be finite, got {} and {}", l.lower, l.upper),
                );
            } else if l.lower >= l.upper {
                c.fail(
                    &format!("{key}.limit"),
                    format!("is inverted or empty: lower {} must be < upper {}", l.lower, l.upper),
                );
            }
            if !(l.velocity.is_finite() && l.velocity > 0.0) {
                c.fail(
                    &format!("{key}.limit.velocity"),
                    format!("must be > 0, got {}", l.velocity),
                );
            }
            let torque = d.torque_limit_nm.map_or(l.effort, |t| t[i]);
            if !(torque.is_finite() && torque > 0.0) {
                c.fail(
                    &format!("{key}.limit.effort"),
                    format!("must be > 0 (or set robot.drives.torque_limit_nm), got {torque}"),
                );
            }
            joints.push(Joint {
                name: j.name.clone(),
                child_link: j.child.link.clone(),
                parent_from_origin: pose(&j.origin),
                origin_rot: *pose(&j.origin).rotation.to_rotation_matrix().matrix(),
                origin_pos_m: pose(&j.origin).translation.vector,
                axis,
                lower_rad: l.lower,
                upper_rad: l.upper,
                max_vel_rad_s: l.velocity,
                max_accel_rad_s2: d.max_accel_deg_s2[i].to_radians(),
                torque_limit_nm: torque,
                armature_kg_m2: d.armature_kg_m2[i],
                coulomb_nm: d.coulomb_friction_nm[i],
                viscous_nm_s_per_rad: d.viscous_friction_nm_s_per_rad[i],
            });
        }

        let mut links = Vec::with_capacity(DOF + 1);
        let chain_links = std::iter::once(root).chain(chain.iter().map(|&(_, l)| l));
        for (i, l) in chain_links.enumerate() {
            let name = l.name.as_str();
            let key = format!("link[{name}].inertial");
            let inn = &l.inertial;
            let m = inn.mass.value;
            let it = &inn.inertia;
            let inertia = Matrix3::new(it.ixx, it.ixy, it.ixz, it.ixy, it.iyy, it.iyz, it.ixz, it.iyz, it.izz);
            if i > 0 && !(m.is_finite() && m > 0.0) {
                c.fail(&format!("{key}.mass"), format!("must be > 0, got {m}"));
            } else if i == 0 && !(m.is_finite() && m >= 0.0) {
                c.fail(&format!("{key}.mass"), format!("must be >= 0, got {m}"));
            }
            if !all_finite(inertia.as_slice()) || !all_finite(&inn.origin.xyz.0) || !all_finite(&inn.origin.rpy.0) {
                c.fail(&key, "must be finite");
            } else if i > 0 && inertia.cholesky().is_none() {
                c.fail(
                    &format!("{key}.inertia"),
                    format!("must be positive definite, got {inertia:?}"),
                );
            }
            // Rotate the inertia into the link frame if the inertial origin has an rpy.
            let com_pose = pose(&inn.origin);
            let r = com_pose.rotation.to_rotation_matrix();
            let inertia_link = r.matrix() * inertia * r.matrix().transpose();
            let mut shapes = Vec::new();
            for (k, col) in l.collision.iter().enumerate() {
                let skey = format!("link[{name}].collision[{k}]");
                let prim = match &col.geometry {
                    urdf_rs::Geometry::Box { size } => Some(Primitive::Box {
                        half_extents_m: vec3(size) / 2.0,
                    }),
                    urdf_rs::Geometry::Cylinder { radius, length } => Some(Primitive::Cylinder {
                        radius_m: *radius,
                        half_length_m: length / 2.0,
                    }),
                    urdf_rs::Geometry::Sphere { radius } => Some(Primitive::Sphere { radius_m: *radius }),
                    urdf_rs::Geometry::Capsule { radius, length } => Some(Primitive::Capsule {
                        radius_m: *radius,
                        half_length_m: length / 2.0,
                    }),
                    urdf_rs::Geometry::Mesh { filename, .. } => {
                        c.fail(
                            &skey,
                            format!("mesh geometry is not supported for the arm's collision model, got {filename:?}"),
                        );
                        None
                    }
                };
                if let Some(p) = prim {
                    let dims: Vec<f64> = match &p {
                        Primitive::Box { half_extents_m } => half_extents_m.iter().copied().collect(),
                        Primitive::Cylinder {
                            radius_m,
                            half_length_m,
                        }
                        | Primitive::Capsule {
                            radius_m,
                            half_length_m,
                        } => {
                            vec![*radius_m, *half_length_m]
                        }
                        Primitive::Sphere { radius_m } => vec![*radius_m],
                    };
                    if dims.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                        c.fail(&skey, format!("dimensions must be > 0, got {dims:?}"));
                    }
                    if !all_finite(&col.origin.xyz.0) || !all_finite(&col.origin.rpy.0) {
                        c.fail(
                            &format!("{skey}.origin"),
                            format!(
                                "must be finite, got xyz {:?} rpy {:?}",
                                col.origin.xyz.0, col.origin.rpy.0
                            ),
                        );
                    }
                    shapes.push(LinkShape {
                        link_from_shape: pose(&col.origin),
                        primitive: p,
                    });
                }
            }
            links.push(Link {
                name: name.to_string(),
                inertial: Inertial {
                    mass_kg: m,
                    com_m: com_pose.translation.vector,
                    inertia_com_kg_m2: inertia_link,
                },
                shapes,
            });
        }
        c.finish()?;

        let ik_geometry = ik::IkGeometry::from_joints(&joints).map_err(|m| ConfigError::one(label, "", m))?;
        let world_from_base = robot.world_from_base();
        let gravity_world = Vector3::new(0.0, 0.0, -GRAVITY_M_S2);
        Ok(RobotModel {
            name: urdf.name.clone(),
            joints,
            links,
            world_from_base,
            flange_from_tool: gripper.flange_from_tool(),
            gravity_base_m_s2: world_from_base.rotation.inverse() * gravity_world,
            coulomb_smoothing_rad_s: d.coulomb_smoothing_deg_s.to_radians(),
            accel_cap: d.accel_cap,
            ik_geometry,
        })
    }

    /// Lower position limits [rad].
    pub fn lower_rad(&self) -> JointVector {
        JointVector::from_fn(|i, _| self.joints[i].lower_rad)
    }

    /// Upper position limits [rad].
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

    /// Total mass of the moving links [kg].
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
