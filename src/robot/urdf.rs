//! The robot model from its URDF: the file parsed, every reference between its elements checked,
//! the serial chain from the root link to the flange link found, and the joints, links and
//! collision shapes built with the cell file's drive data.
//!
//! Job: [`RobotModel::from_urdf`] and [`RobotModel::from_scene`]; every problem names the URDF
//! (or the cell file, for its `robot.flange_link`), the element and the bad value.
//!
//! Units: SI (m, rad, s, kg, N m); URDF values are SI already. Frames: as in [`super`] (link `i`
//! is the child frame of joint `i`; inertials and collision origins in their link's frame).

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};

use super::{DOF, GRAVITY_M_S2, Inertial, Joint, Link, LinkPrimitive, LinkShape, RobotModel, ik};
use crate::config::{Checker, ConfigError, DrivesConfig, GripperConfig, Problem, RobotConfig};

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

/// Links by name and joints by child link, with every broken reference between the URDF's
/// elements as a problem: names repeated, a joint's parent or child link undefined or the same,
/// a link the child of two joints.
#[allow(clippy::type_complexity)]
fn check_references<'u>(
    label: &str,
    urdf: &'u urdf_rs::Robot,
) -> (
    Checker,
    BTreeMap<&'u str, &'u urdf_rs::Link>,
    BTreeMap<&'u str, &'u urdf_rs::Joint>,
) {
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
    (c, links_by_name, by_child)
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
    let (c, links_by_name, by_child) = check_references(label, urdf);
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
        let joints: Vec<Joint> = chain
            .iter()
            .enumerate()
            .map(|(i, &(j, _))| joint_from_urdf(&mut c, i, j, d))
            .collect();
        let chain_links = std::iter::once(root).chain(chain.iter().map(|&(_, l)| l));
        let links: Vec<Link> = chain_links
            .enumerate()
            .map(|(i, l)| link_from_urdf(&mut c, i, l))
            .collect();
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
}

/// Joint `i` of the chain from the URDF's joint `j` and the cell file's drives `d`, its problems
/// collected in `c`.
fn joint_from_urdf(c: &mut Checker, i: usize, j: &urdf_rs::Joint, d: &DrivesConfig) -> Joint {
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
    Joint {
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
    }
}

/// Link `i` of the chain (0: the root) from the URDF's link `l`, its problems collected in `c`.
fn link_from_urdf(c: &mut Checker, i: usize, l: &urdf_rs::Link) -> Link {
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
    let shapes = l
        .collision
        .iter()
        .enumerate()
        .filter_map(|(k, col)| shape_from_urdf(c, &format!("link[{name}].collision[{k}]"), col))
        .collect();
    Link {
        name: name.to_string(),
        inertial: Inertial {
            mass_kg: m,
            com_m: com_pose.translation.vector,
            inertia_com_kg_m2: inertia_link,
        },
        shapes,
    }
}

/// A collision shape from the URDF's `col` (`skey` names it), or `None` if it is not one the
/// arm's collision model takes; its problems collected in `c`.
fn shape_from_urdf(c: &mut Checker, skey: &str, col: &urdf_rs::Collision) -> Option<LinkShape> {
    let prim = match &col.geometry {
        urdf_rs::Geometry::Box { size } => Some(LinkPrimitive::Box {
            half_extents_m: vec3(size) / 2.0,
        }),
        urdf_rs::Geometry::Cylinder { radius, length } => Some(LinkPrimitive::Cylinder {
            radius_m: *radius,
            half_length_m: length / 2.0,
        }),
        urdf_rs::Geometry::Sphere { radius } => Some(LinkPrimitive::Sphere { radius_m: *radius }),
        urdf_rs::Geometry::Capsule { radius, length } => Some(LinkPrimitive::Capsule {
            radius_m: *radius,
            half_length_m: length / 2.0,
        }),
        urdf_rs::Geometry::Mesh { filename, .. } => {
            c.fail(
                skey,
                format!("mesh geometry is not supported for the arm's collision model, got {filename:?}"),
            );
            None
        }
    };
    let p = prim?;
    let dims: Vec<f64> = match &p {
        LinkPrimitive::Box { half_extents_m } => half_extents_m.iter().copied().collect(),
        LinkPrimitive::Cylinder {
            radius_m,
            half_length_m,
        }
        | LinkPrimitive::Capsule {
            radius_m,
            half_length_m,
        } => {
            vec![*radius_m, *half_length_m]
        }
        LinkPrimitive::Sphere { radius_m } => vec![*radius_m],
    };
    if dims.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        c.fail(skey, format!("dimensions must be > 0, got {dims:?}"));
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
    Some(LinkShape {
        link_from_shape: pose(&col.origin),
        primitive: p,
    })
}
