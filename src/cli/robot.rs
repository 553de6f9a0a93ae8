//! `binpick robot ...`: interrogate the simulated arm: its model, forward and inverse
//! kinematics, joint torques. Degrees and metres at this boundary.

use std::path::Path;

use anyhow::Result;
use clap::{Args, Subcommand};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde_json::json;

use super::{InputError, deg_list, finite_args, joints_from_deg, pose_json, pose_text, round};
use binpick::config::{AccelCap, LoadedScene};
use binpick::robot::{JointVector, Payload, RobotModel};

/// Runs a robot command on the arm of `scene` (default: the embedded cell).
pub fn run(command: RobotCommand, scene: Option<&Path>, json: bool) -> Result<()> {
    let loaded = LoadedScene::load(scene)?;
    let robot = RobotModel::from_scene(&loaded)?;
    match command {
        RobotCommand::Info => robot_info(&loaded, &robot, json),
        RobotCommand::Fk { deg } => robot_fk(&robot, &deg, json),
        RobotCommand::Ik {
            xyz,
            rpy_deg,
            all,
            seed_deg,
            flange,
        } => {
            let seed = match seed_deg {
                Some(s) => joints_from_deg("--seed-deg", &s)?,
                None => JointVector::from(loaded.scene.robot.home_rad()),
            };
            robot_ik(&robot, &xyz, &rpy_deg, all, &seed, flange, json)
        }
        RobotCommand::Torque(args) => robot_torque(&loaded, &robot, &args, json),
    }
}

/// `binpick robot ...`.
#[derive(Subcommand)]
pub enum RobotCommand {
    /// Links, masses, joint limits and drives.
    Info,
    /// Forward kinematics: every link frame, the flange and the tool in the world frame.
    Fk {
        /// Joint positions q1..q6 (deg).
        #[arg(long, num_args = 6, allow_negative_numbers = true, required = true)]
        deg: Vec<f64>,
    },
    /// Inverse kinematics of a tool (or flange) pose in the world frame.
    Ik {
        /// Position x y z (m).
        #[arg(long, num_args = 3, allow_negative_numbers = true, required = true)]
        xyz: Vec<f64>,
        /// Orientation roll pitch yaw, fixed axes x, y, z (deg).
        #[arg(long, num_args = 3, allow_negative_numbers = true, required = true)]
        rpy_deg: Vec<f64>,
        /// List every in-limit solution instead of the one nearest the seed.
        #[arg(long)]
        all: bool,
        /// Seed configuration q1..q6 (deg) (default: the cell's home).
        #[arg(long, num_args = 6, allow_negative_numbers = true)]
        seed_deg: Option<Vec<f64>>,
        /// The pose is the flange's, not the tool's.
        #[arg(long)]
        flange: bool,
    },
    /// Joint torques by inverse dynamics (gravity, inertia, Coriolis, armature, friction).
    Torque(TorqueArgs),
}

/// Arguments of `binpick robot torque`.
#[derive(Args)]
pub struct TorqueArgs {
    /// Joint positions q1..q6 (deg).
    #[arg(long, num_args = 6, allow_negative_numbers = true, required = true)]
    deg: Vec<f64>,
    /// Joint velocities [deg/s] (default 0).
    #[arg(long, num_args = 6, allow_negative_numbers = true)]
    vel_deg: Option<Vec<f64>>,
    /// Joint accelerations [deg/s^2] (default 0).
    #[arg(long, num_args = 6, allow_negative_numbers = true)]
    acc_deg: Option<Vec<f64>>,
    /// Held part: a point mass at the tool tip (kg) (default 0).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    payload_kg: f64,
    /// Leave the hand off the flange.
    #[arg(long)]
    no_gripper: bool,
}

fn robot_info(loaded: &LoadedScene, robot: &RobotModel, json: bool) -> Result<()> {
    let g = &loaded.scene.gripper;
    let hand = Payload::from_gripper(g);
    if json {
        let joints: Vec<_> = robot
            .joints
            .iter()
            .map(|j| {
                json!({
                    "name": j.name, "child_link": j.child_link,
                    "lower_deg": round(j.lower_rad.to_degrees(), 4), "upper_deg": round(j.upper_rad.to_degrees(), 4),
                    "max_vel_deg_s": round(j.max_vel_rad_s.to_degrees(), 4),
                    "max_accel_deg_s2": round(j.max_accel_rad_s2.to_degrees(), 4),
                    "torque_limit_nm": j.torque_limit_nm, "armature_kg_m2": j.armature_kg_m2,
                    "coulomb_nm": j.coulomb_nm, "viscous_nm_s_per_rad": j.viscous_nm_s_per_rad,
                })
            })
            .collect();
        let links: Vec<_> = robot
            .links
            .iter()
            .map(|l| json!({"name": l.name, "mass_kg": l.inertial.mass_kg, "com_m": l.inertial.com_m.as_slice(), "collision_shapes": l.shapes.len()}))
            .collect();
        let out = json!({
            "scene": loaded.label, "urdf": loaded.urdf_label, "robot": robot.name,
            "world_from_base": pose_json(&robot.world_from_base),
            "flange_from_tool": pose_json(&robot.flange_from_tool),
            "moving_mass_kg": robot.moving_mass_kg(),
            "accel_cap": loaded.scene.robot.drives.accel_cap.name(),
            "joints": joints, "links": links,
            "gripper": {"kind": format!("{:?}", g.kind).to_lowercase(), "mass_kg": hand.mass_kg, "com_flange_m": hand.com_flange_m.as_slice(),
                         "tool_length_m": g.tool_length_m, "cup_diameter_m": g.cup_diameter_m},
            "ik": {"shoulder_height_m": robot.ik_geometry.shoulder_height_m, "shoulder_offset_m": robot.ik_geometry.shoulder_offset_m,
                   "upper_arm_m": robot.ik_geometry.upper_arm_m, "forearm_m": robot.ik_geometry.forearm_m,
                   "wrist_to_flange_m": robot.ik_geometry.wrist_to_flange_m},
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    super::say(&format!(
        "robot {:?} from {} (scene {})",
        robot.name, loaded.urdf_label, loaded.label
    ));
    println!("base in world: {}", pose_text(&robot.world_from_base));
    println!(
        "tool: {:?} hand, {:.3} kg, tool frame {:.3} m beyond the flange, cup {:.1} mm",
        g.kind,
        g.mass_kg,
        g.tool_length_m,
        g.cup_diameter_m * 1000.0
    );
    println!("moving mass {:.3} kg (links 1-6, without hand)", robot.moving_mass_kg());
    println!();
    println!("links    mass_kg  com_m (link frame)             shapes");
    for l in &robot.links {
        let c = l.inertial.com_m;
        println!(
            "{:<8} {:7.3}  [{:7.4} {:7.4} {:7.4}]        {}",
            l.name,
            l.inertial.mass_kg,
            c.x,
            c.y,
            c.z,
            l.shapes.len()
        );
    }
    println!();
    let caps = format!(
        "planned motions' accelerations: {} (robot.drives.accel_cap = \"{}\"); amax is the specification",
        match loaded.scene.robot.drives.accel_cap {
            AccelCap::TorqueOnly => "bound by the torque limits alone",
            AccelCap::Spec => "capped at amax as well as bound by the torque limits",
        },
        loaded.scene.robot.drives.accel_cap.name()
    );
    super::say(&caps);
    println!("joint     lower_deg upper_deg  vmax_deg_s  amax_deg_s2  torque_nm  armature  coulomb_nm  viscous_nm_s");
    for j in &robot.joints {
        println!(
            "{:<9} {:9.1} {:9.1} {:11.1} {:12.0} {:10.1} {:9.3} {:11.2} {:13.2}",
            j.name,
            j.lower_rad.to_degrees(),
            j.upper_rad.to_degrees(),
            j.max_vel_rad_s.to_degrees(),
            j.max_accel_rad_s2.to_degrees(),
            j.torque_limit_nm,
            j.armature_kg_m2,
            j.coulomb_nm,
            j.viscous_nm_s_per_rad
        );
    }
    Ok(())
}

fn robot_fk(robot: &RobotModel, deg: &[f64], json: bool) -> Result<()> {
    let q = joints_from_deg("--deg", deg)?;
    let world_from_links = robot.world_from_links(&q);
    let tool = robot.world_from_tool(&q);
    let within = robot.within_limits(&q, 0.0);
    let manip = robot.manipulability(&q);
    if json {
        let links: Vec<_> = robot
            .links
            .iter()
            .zip(&world_from_links)
            .map(|(l, f)| json!({"link": l.name, "world_from_link": pose_json(f)}))
            .collect();
        let out = json!({
            "q_deg": deg_list(&q), "within_limits": within, "links": links,
            "world_from_flange": pose_json(&world_from_links[world_from_links.len() - 1]),
            "world_from_tool": pose_json(&tool), "manipulability": manip,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    for (l, f) in robot.links.iter().zip(&world_from_links) {
        println!("{:<10} {}", l.name, pose_text(f));
    }
    println!(
        "{:<10} {}",
        "flange",
        pose_text(&world_from_links[world_from_links.len() - 1])
    );
    println!("{:<10} {}", "tool", pose_text(&tool));
    println!("manipulability {manip:.5}; within joint limits: {within}");
    Ok(())
}

fn robot_ik(
    robot: &RobotModel,
    xyz: &[f64],
    rpy_deg: &[f64],
    all: bool,
    seed: &JointVector,
    flange: bool,
    json: bool,
) -> Result<()> {
    finite_args("--xyz", xyz)?;
    finite_args("--rpy-deg", rpy_deg)?;
    let target = Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(
            rpy_deg[0].to_radians(),
            rpy_deg[1].to_radians(),
            rpy_deg[2].to_radians(),
        ),
    );
    let base_from_flange = if flange {
        robot.world_from_base.inverse() * target
    } else {
        robot.base_from_flange_for_tool(&target)
    };
    let frame = if flange { "flange" } else { "tool" };
    let sols = if all {
        robot.ik_flange_all(&base_from_flange)
    } else {
        robot.ik_flange_nearest(&base_from_flange, seed).map(|s| vec![s])
    }
    .map_err(|e| {
        InputError(format!(
            "no {frame} pose solution for xyz {xyz:?} m, rpy {rpy_deg:?} deg: {e}"
        ))
    })?;
    if json {
        let list: Vec<_> = sols
            .iter()
            .map(|s| {
                json!({"q_deg": deg_list(&s.q), "front": s.branch.front, "elbow": s.branch.elbow, "wrist_positive": s.branch.wrist_positive})
            })
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(&json!({"frame": frame, "solutions": list}))?
        );
        return Ok(());
    }
    println!("{} solution(s) for the {frame} at {}:", sols.len(), pose_text(&target));
    for s in &sols {
        let q: Vec<String> = s.q.iter().map(|v| format!("{:9.3}", v.to_degrees())).collect();
        println!(
            "  q_deg [{}]  ({}, elbow {}, J5 {})",
            q.join(" "),
            if s.branch.front { "front" } else { "back" },
            s.branch.elbow,
            if s.branch.wrist_positive { "+" } else { "-" }
        );
    }
    Ok(())
}

fn robot_torque(loaded: &LoadedScene, robot: &RobotModel, a: &TorqueArgs, json: bool) -> Result<()> {
    let q = joints_from_deg("--deg", &a.deg)?;
    let qd = a
        .vel_deg
        .as_deref()
        .map(|v| joints_from_deg("--vel-deg", v))
        .transpose()?
        .unwrap_or_default();
    let qdd = a
        .acc_deg
        .as_deref()
        .map(|v| joints_from_deg("--acc-deg", v))
        .transpose()?
        .unwrap_or_default();
    if !(a.payload_kg.is_finite() && a.payload_kg >= 0.0) {
        return Err(InputError(format!(
            "--payload-kg must be a finite number >= 0, got {}",
            a.payload_kg
        ))
        .into());
    }
    let hand = if a.no_gripper {
        Payload::none()
    } else {
        Payload::from_gripper(&loaded.scene.gripper)
    };
    let part = Payload::point(a.payload_kg, robot.flange_from_tool.translation.vector);
    let payload = hand.combined(&part);
    let dynamics = robot.dynamics(&payload);
    let tau = dynamics.inverse_dynamics(&q, &qd, &qdd);
    let gravity = dynamics.gravity_torques(&q);
    let limit = robot.torque_limit_nm();
    if json {
        let rows: Vec<_> = (0..6)
            .map(|i| {
                json!({"joint": robot.joints[i].name, "torque_nm": round(tau[i], 6), "gravity_nm": round(gravity[i], 6),
                       "limit_nm": limit[i], "ratio": round(tau[i].abs() / limit[i], 6)})
            })
            .collect();
        let out = json!({"q_deg": deg_list(&q), "payload_kg": payload.mass_kg, "joints": rows,
                         "within_limits": (0..6).all(|i| tau[i].abs() <= limit[i])});
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "payload on the flange: {:.3} kg (hand {:.3} kg + part {:.3} kg at the tool tip)",
        payload.mass_kg, hand.mass_kg, a.payload_kg
    );
    println!("joint     torque_nm  gravity_nm  limit_nm  |tau|/limit");
    for i in 0..6 {
        let flag = if tau[i].abs() > limit[i] { "  OVER LIMIT" } else { "" };
        println!(
            "{:<9} {:9.3} {:11.3} {:9.1} {:11.3}{flag}",
            robot.joints[i].name,
            tau[i],
            gravity[i],
            limit[i],
            tau[i].abs() / limit[i]
        );
    }
    Ok(())
}
