//! The `binpick` command line: validate files, interrogate the robot, run benchmarks.
//!
//! Exit codes: 0 success; 2 bad input (invalid file, bad argument, unreachable target), with one
//! clear line per problem on stderr; 1 any other failure. Nothing is written on bad input.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde_json::json;

use binpick::config::{ConfigError, LoadedScene, LoadedWorkpiece, Source};
use binpick::robot::{JointVector, Payload, RobotModel};

/// A digital twin of a robotic bin-picking cell (OMRON Viper s650).
#[derive(Parser)]
#[command(name = "binpick", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Validate scene (.toml with [robot]), workpiece (.toml) and URDF (.urdf) files.
    Check {
        /// Files to check.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Scene that workpieces are checked against (default: the embedded default cell).
        #[arg(long)]
        scene: Option<PathBuf>,
    },
    /// Interrogate the simulated robot.
    Robot {
        #[command(subcommand)]
        command: RobotCommand,
        /// Scene file (default: the embedded default cell).
        #[arg(long, global = true)]
        scene: Option<PathBuf>,
        /// Machine-readable JSON output.
        #[arg(long, global = true)]
        json: bool,
    },
    /// Build and settle a random pile of one workpiece type in the pick tray.
    Pile(PileArgs),
    /// Build a pile, take a depth capture, recognise the parts and select a grasp.
    Sense(PileArgs),
    /// One cell run: picks of one workpiece end to end, timed; results, time charts and the run's
    /// recordings (`run.rrd` for Rerun, `run.mcap` for Foxglove) in the run folder.
    Run {
        /// Workpiece: A ... F (embedded) or a path to a workpiece file.
        #[arg(long)]
        workpiece: String,
        /// Picks to attempt.
        #[arg(long, default_value_t = 20)]
        picks: usize,
        /// Run seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Charge the cell file's fixed compute budgets instead of measured wall time, so the
        /// same seed gives byte-identical results.
        #[arg(long)]
        deterministic: bool,
        /// Scene file (default: the embedded default cell).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Folder the run folder is written into.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        #[command(flatten)]
        skip: SkipFormats,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// The takt-time table: cell runs of several workpieces and seeds in parallel, one row per
    /// workpiece (the reference system's Table 5, from the simulation).
    Batch(BatchArgs),
    /// Joins the results of a batch's shards (`batch --shard K/N`) into the one table.
    Merge {
        /// The shards' folders (each holding a takt.json).
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Folder the merged batch folder is written into.
        #[arg(long, default_value = "runs")]
        out: PathBuf,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Benchmarks: our code beside a baseline doing the same work.
    Bench {
        #[command(subcommand)]
        command: BenchCommand,
    },
}

/// Recording formats a user can skip (`run` records both by default, `batch --record` too).
#[derive(Args, Clone, Copy)]
struct SkipFormats {
    /// Do not write the Rerun recording (`.rrd`).
    #[arg(long)]
    no_rrd: bool,
    /// Do not write the MCAP recording (`.mcap`).
    #[arg(long)]
    no_mcap: bool,
}

impl SkipFormats {
    /// The formats to write when recording.
    fn formats(self, record: bool) -> binpick::record::Formats {
        binpick::record::Formats {
            rrd: record && !self.no_rrd,
            mcap: record && !self.no_mcap,
        }
    }
}

/// Arguments of `binpick batch`.
#[derive(Args)]
struct BatchArgs {
    /// Workpieces, comma-separated: A ... F (embedded) or paths to workpiece files.
    #[arg(long, default_value = "A,B,C,D,E,F")]
    workpieces: String,
    /// Picks per run (the first of each run follows the initial sensing and has no takt).
    #[arg(long, default_value_t = 21)]
    picks: usize,
    /// Seeds: 1-3, or 1,2,5.
    #[arg(long, default_value = "1")]
    seeds: String,
    /// Runs in parallel (default: the machine's cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Run only the K-th of N disjoint slices of the batch (1-based), e.g. 2/4.
    #[arg(long)]
    shard: Option<String>,
    /// Charge the cell file's fixed compute budgets instead of measured wall time.
    #[arg(long)]
    deterministic: bool,
    /// Record every run: `run-<workpiece>-seed<seed>.rrd` and `.mcap` in the batch folder.
    #[arg(long)]
    record: bool,
    #[command(flatten)]
    skip: SkipFormats,
    /// Scene file (default: the embedded default cell).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Folder the batch folder is written into.
    #[arg(long, default_value = "runs")]
    out: PathBuf,
    /// Machine-readable JSON output.
    #[arg(long)]
    json: bool,
}

#[derive(Subcommand)]
enum RobotCommand {
    /// Links, masses, joint limits and drives.
    Info,
    /// Forward kinematics: every link frame, the flange and the tool in the world frame.
    Fk {
        /// Joint positions q1..q6 [deg].
        #[arg(long, num_args = 6, allow_negative_numbers = true, required = true)]
        deg: Vec<f64>,
    },
    /// Inverse kinematics of a tool (or flange) pose in the world frame.
    Ik {
        /// Position x y z [m].
        #[arg(long, num_args = 3, allow_negative_numbers = true, required = true)]
        xyz: Vec<f64>,
        /// Orientation roll pitch yaw, fixed axes x, y, z [deg].
        #[arg(long, num_args = 3, allow_negative_numbers = true, required = true)]
        rpy_deg: Vec<f64>,
        /// List every in-limit solution instead of the one nearest the seed.
        #[arg(long)]
        all: bool,
        /// Seed configuration q1..q6 [deg] (default: the cell's home).
        #[arg(long, num_args = 6, allow_negative_numbers = true)]
        seed_deg: Option<Vec<f64>>,
        /// The pose is the flange's, not the tool's.
        #[arg(long)]
        flange: bool,
    },
    /// Joint torques by inverse dynamics (gravity, inertia, Coriolis, armature, friction).
    Torque(TorqueArgs),
}

/// A pile of one workpiece in a cell, and where its run folder goes.
#[derive(Args)]
struct PileArgs {
    /// Workpiece: A ... F (embedded) or a path to a workpiece file.
    #[arg(long)]
    workpiece: String,
    /// Parts to drop (default: the workpiece's pile_count).
    #[arg(long)]
    count: Option<usize>,
    /// Run seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Scene file (default: the embedded default cell).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Folder the run folder is written into.
    #[arg(long, default_value = "runs")]
    out: PathBuf,
    /// Machine-readable JSON output.
    #[arg(long)]
    json: bool,
}

#[derive(Args)]
struct TorqueArgs {
    /// Joint positions q1..q6 [deg].
    #[arg(long, num_args = 6, allow_negative_numbers = true, required = true)]
    deg: Vec<f64>,
    /// Joint velocities [deg/s] (default 0).
    #[arg(long, num_args = 6, allow_negative_numbers = true)]
    vel_deg: Option<Vec<f64>>,
    /// Joint accelerations [deg/s^2] (default 0).
    #[arg(long, num_args = 6, allow_negative_numbers = true)]
    acc_deg: Option<Vec<f64>>,
    /// Held part: a point mass at the tool tip [kg] (default 0).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    payload_kg: f64,
    /// Leave the hand off the flange.
    #[arg(long)]
    no_gripper: bool,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Motion accelerator: the reference system's five cases (J1 turns 180 deg between two
    /// containers): default parameters, acceleration search, path correction, time-optimal.
    Accel {
        /// Runs per case (compute time is the max over them).
        #[arg(long, default_value_t = 20)]
        runs: usize,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Planner: the reference system's three cases and a bin-picking query set, ours beside
    /// plain RRT and RRT-Connect.
    Planner {
        /// Trials per case for ours.
        #[arg(long, default_value_t = 100)]
        trials: usize,
        /// Trials per case for each baseline (they take up to seconds each).
        #[arg(long, default_value_t = 10)]
        baseline_trials: usize,
        /// First seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Sensing: depth capture (all cores, and one thread as the peer) and grasp selection per
    /// workpiece at its default pile.
    Sensor {
        /// Timed repetitions after one warm-up.
        #[arg(long, default_value_t = 7)]
        runs: usize,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Physics: pile build-and-settle wall time per workpiece, and the step time of 100 resting
    /// parts with the arm moving, beside rapier's default solver settings.
    Physics {
        /// Runs to take the median over.
        #[arg(long, default_value_t = 5)]
        runs: usize,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Robot model: IK, FK, inverse and forward dynamics per call, beside baselines.
    Robot {
        /// Runs to take the median over.
        #[arg(long, default_value_t = 7)]
        runs: usize,
        /// Calls per run.
        #[arg(long, default_value_t = 200_000)]
        calls: usize,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
}

/// Bad input from the user: reported on one line, exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct InputError(String);

/// The run was interrupted by Ctrl-C; its results so far were written (exit 130).
#[derive(Debug, thiserror::Error)]
#[error("interrupted: the results so far are in {0}")]
struct Interrupted(String);

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if let Some(c) = e.downcast_ref::<ConfigError>() {
                eprintln!("{c}");
                ExitCode::from(2)
            } else if let Some(i) = e.downcast_ref::<binpick::physics::ShapeError>() {
                eprintln!("{i}");
                ExitCode::from(2)
            } else if let Some(i) = e.downcast_ref::<InputError>() {
                eprintln!("error: {i}");
                ExitCode::from(2)
            } else if let Some(i) = e.downcast_ref::<Interrupted>() {
                eprintln!("{i}");
                ExitCode::from(130)
            } else {
                eprintln!("error: {e:#}");
                ExitCode::from(1)
            }
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Check { files, scene } => check(&files, scene.as_deref()),
        Command::Robot { command, scene, json } => {
            let loaded = LoadedScene::load(scene.as_deref())?;
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
        Command::Sense(a) => sense(&a),
        Command::Run {
            workpiece,
            picks,
            seed,
            deterministic,
            scene,
            out,
            skip,
            json,
        } => run_cell(
            &workpiece,
            picks,
            seed,
            deterministic,
            scene.as_deref(),
            &out,
            skip.formats(true),
            json,
        ),
        Command::Pile(a) => pile(&a),
        Command::Batch(a) => batch(&a),
        Command::Merge { dirs, out, json } => merge(&dirs, &out, json),
        Command::Bench {
            command: BenchCommand::Physics { runs, json },
        } => bench_physics(runs, json),
        Command::Bench {
            command: BenchCommand::Accel { runs, json },
        } => bench_accel(runs, json),
        Command::Bench {
            command:
                BenchCommand::Planner {
                    trials,
                    baseline_trials,
                    seed,
                    json,
                },
        } => bench_planner(trials, baseline_trials, seed, json),
        Command::Bench {
            command: BenchCommand::Sensor { runs, json },
        } => bench_sensor(runs, json),
        Command::Bench {
            command: BenchCommand::Robot { runs, calls, json },
        } => {
            let loaded = LoadedScene::embedded_default()?;
            let robot = RobotModel::from_scene(&loaded)?;
            bench_robot(&loaded, &robot, runs, calls, json)
        }
    }
}

fn finite_args(name: &str, v: &[f64]) -> Result<()> {
    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
        return Err(InputError(format!("{name} must be finite numbers, got {bad}")).into());
    }
    Ok(())
}

fn joints_from_deg(name: &str, v: &[f64]) -> Result<JointVector> {
    finite_args(name, v)?;
    Ok(JointVector::from_fn(|i, _| v[i].to_radians()))
}

fn deg_list(q: &JointVector) -> Vec<f64> {
    q.iter().map(|v| round(v.to_degrees(), 6)).collect()
}

fn round(v: f64, digits: i32) -> f64 {
    let s = 10f64.powi(digits);
    (v * s).round() / s
}

fn pose_json(p: &Isometry3<f64>) -> serde_json::Value {
    let (r, pi, y) = p.rotation.euler_angles();
    json!({
        "xyz_m": p.translation.vector.iter().map(|v| round(*v, 9)).collect::<Vec<_>>(),
        "rpy_deg": [round(r.to_degrees(), 6), round(pi.to_degrees(), 6), round(y.to_degrees(), 6)],
    })
}

fn pose_text(p: &Isometry3<f64>) -> String {
    let (r, pi, y) = p.rotation.euler_angles();
    let t = p.translation.vector;
    format!(
        "xyz [{:9.5} {:9.5} {:9.5}] m  rpy [{:8.3} {:8.3} {:8.3}] deg",
        t.x,
        t.y,
        t.z,
        r.to_degrees(),
        pi.to_degrees(),
        y.to_degrees()
    )
}

// ---------------------------------------------------------------------------------------------

fn check(files: &[PathBuf], scene_path: Option<&Path>) -> Result<()> {
    let mut problems = Vec::new();
    let reference_scene = match LoadedScene::load(scene_path) {
        Ok(s) => Some(s),
        Err(e) => {
            problems.extend(e.problems);
            None
        }
    };
    for f in files {
        match check_one(f, reference_scene.as_ref()) {
            Ok(what) => println!("ok: {} ({what})", f.display()),
            Err(e) => problems.extend(e.problems),
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(ConfigError { problems }.into())
    }
}

fn check_one(path: &Path, reference: Option<&LoadedScene>) -> Result<String, ConfigError> {
    let label = path.display().to_string();
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    match ext {
        "urdf" => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| ConfigError::one(&label, "", format!("cannot read file: {e}")))?;
            let base = LoadedScene::embedded_default()?;
            let robot = RobotModel::from_urdf(&label, &text, &base.scene.robot, &base.scene.gripper)?;
            Ok(format!(
                "URDF: robot {:?}, {} joints, {:.2} kg moving",
                robot.name,
                robot.joints.len(),
                robot.moving_mass_kg()
            ))
        }
        "toml" => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| ConfigError::one(&label, "", format!("cannot read file: {e}")))?;
            let table: toml::Table = binpick::config::parse_toml(&label, &text)?;
            if table.contains_key("robot") {
                let scene = LoadedScene::from_text(&label, Source::File(path.to_path_buf()), &text)?;
                let robot = RobotModel::from_scene(&scene)?;
                robot.check_scene_reach(&label, &scene.scene)?;
                Ok(format!(
                    "scene {:?}: robot {:?}, trays reachable, sensor sees the pick tray",
                    scene.scene.name, robot.name
                ))
            } else {
                let wp = LoadedWorkpiece::from_text(&label, Source::File(path.to_path_buf()), &text)?;
                if let Some(s) = reference {
                    wp.workpiece.check_fits_scene(&label, &s.scene)?;
                }
                Ok(format!("workpiece {:?}: {}", wp.workpiece.name, wp.workpiece.kind))
            }
        }
        _ => Err(ConfigError::one(
            &label,
            "",
            "is neither a .toml (scene or workpiece) nor a .urdf file",
        )),
    }
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
    println!(
        "robot {:?} from {} (scene {})",
        robot.name, loaded.urdf_label, loaded.label
    );
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
    let frames = robot.world_from_links(&q);
    let tool = robot.world_from_tool(&q);
    let within = robot.within_limits(&q, 0.0);
    let manip = robot.manipulability(&q);
    if json {
        let links: Vec<_> = robot
            .links
            .iter()
            .zip(&frames)
            .map(|(l, f)| json!({"link": l.name, "world_from_link": pose_json(f)}))
            .collect();
        let out = json!({
            "q_deg": deg_list(&q), "within_limits": within, "links": links,
            "world_from_flange": pose_json(&frames[frames.len() - 1]),
            "world_from_tool": pose_json(&tool), "manipulability": manip,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    for (l, f) in robot.links.iter().zip(&frames) {
        println!("{:<10} {}", l.name, pose_text(f));
    }
    println!("{:<10} {}", "flange", pose_text(&frames[frames.len() - 1]));
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

fn bench_robot(loaded: &LoadedScene, robot: &RobotModel, runs: usize, calls: usize, json: bool) -> Result<()> {
    if runs == 0 || calls == 0 {
        return Err(InputError("--runs and --calls must be > 0".into()).into());
    }
    let payload = Payload::from_gripper(&loaded.scene.gripper);
    let result = binpick::bench::robot_bench(robot, &payload, runs, calls);
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&result).context("serialising the benchmark")?
        );
        return Ok(());
    }
    println!("robot model, one core, {runs} runs (median, min..max of the per-run mean per call)");
    println!(
        "{:<55} {:>10} {:>21} {:>9}  note",
        "what", "median_ns", "min..max_ns", "target"
    );
    for t in &result.timings {
        let target = t.target_ns.map_or(String::new(), |v| format!("<= {v:.0}"));
        println!(
            "{:<55} {:>10.1} {:>10.1}..{:<10.1} {:>9}  {}",
            t.name, t.median_ns, t.min_ns, t.max_ns, target, t.note
        );
    }
    Ok(())
}

/// Loads a scene and a workpiece and checks that they go together.
fn load_cell(scene: Option<&Path>, workpiece: &str) -> Result<(LoadedScene, LoadedWorkpiece, RobotModel)> {
    let loaded = LoadedScene::load(scene)?;
    let robot = RobotModel::from_scene(&loaded)?;
    robot.check_scene_reach(&loaded.label, &loaded.scene)?;
    let wp = LoadedWorkpiece::resolve(workpiece)?;
    wp.workpiece.check_fits_scene(&wp.label, &loaded.scene)?;
    Ok((loaded, wp, robot))
}

/// A cell with a settled pile, as `pile` and `sense` start from.
struct PiledCell {
    loaded: LoadedScene,
    wp: LoadedWorkpiece,
    robot: RobotModel,
    world: binpick::physics::World,
    report: binpick::physics::pile::PileReport,
    count: usize,
}

/// Loads and checks the cell and workpiece, builds the world and settles the pile.
fn piled_cell(a: &PileArgs) -> Result<PiledCell> {
    let (loaded, wp, robot) = load_cell(a.scene.as_deref(), &a.workpiece)?;
    let count = a.count.unwrap_or(wp.workpiece.pile_count as usize);
    if count == 0 || count > 1000 {
        return Err(InputError(format!("--count must be within [1, 1000], got {count}")).into());
    }
    let shape = binpick::physics::PartShape::build(&wp.workpiece, &wp.source)?;
    let mut world = binpick::physics::World::new(&loaded.scene, &robot, shape);
    let report = world
        .build_pile(&binpick::physics::pile::PileOptions::new(count, a.seed))
        .context("building the pile")?;
    Ok(PiledCell {
        loaded,
        wp,
        robot,
        world,
        report,
        count,
    })
}

fn pile(a: &PileArgs) -> Result<()> {
    let PiledCell {
        loaded,
        wp,
        report,
        count,
        ..
    } = piled_cell(a)?;
    let (seed, out, json) = (a.seed, &a.out, a.json);
    let name = format!("pile-{}-seed{seed}", wp.workpiece.name);
    let run = binpick::report::RunDir::create(out, &name)?;
    run.write_inputs(&loaded, Some(&wp))?;
    let file = json!({
        "binpick_version": env!("CARGO_PKG_VERSION"), "workpiece": wp.workpiece.name, "seed": seed, "count": count,
        "physics_dt_s": loaded.scene.sim.physics_dt_s, "report": &report,
    });
    run.write_json("pile.json", &file)?;
    let dest = run.finish()?;
    if json {
        let mut v = file;
        v["wall_s"] = json!(report.wall_s);
        v["run_dir"] = json!(dest.display().to_string());
        v["report"].as_object_mut().map(|o| o.remove("poses"));
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "pile of {count} x {} ({}), seed {seed}",
        wp.workpiece.name, wp.workpiece.kind
    );
    println!("  in tray          {} / {}", report.in_tray, report.spawned);
    println!(
        "  pile height      {:.1} mm above the tray floor",
        report.pile_height_m * 1e3
    );
    println!(
        "  settle time      {:.3} s simulated, {:.3} s wall ({} waves){}",
        report.settle_sim_s,
        report.wall_s,
        report.waves,
        if report.settled { "" } else { "  NOT SETTLED" }
    );
    println!(
        "  max penetration  {:.3} mm ({})",
        report.max_penetration_m * 1e3,
        report.max_penetration_between
    );
    println!("  wrote            {}", dest.join("pile.json").display());
    Ok(())
}

/// The embedded default cell, its robot and all six embedded workpieces: what the benchmarks run on.
fn embedded_cell() -> Result<(LoadedScene, RobotModel, Vec<LoadedWorkpiece>)> {
    let loaded = LoadedScene::embedded_default()?;
    let robot = RobotModel::from_scene(&loaded)?;
    Ok((loaded, robot, LoadedWorkpiece::all_embedded()?))
}

fn bench_physics(runs: usize, json: bool) -> Result<()> {
    let (loaded, robot, workpieces) = embedded_cell()?;
    let b = binpick::bench::physics_bench(&loaded, &robot, &workpieces, runs).map_err(|e| anyhow::anyhow!("{e}"))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&b)?);
        return Ok(());
    }
    println!(
        "physics, one core, {runs} runs per pile (seeds 1..{runs}); target: settle <= {:.1} s wall per pile",
        b.targets.0
    );
    println!(
        "workpiece  parts  wall_s median (min..max)  sim_s  max_pen_mm  settled | rapier defaults: wall_s  max_pen_mm"
    );
    for p in &b.piles {
        let peer = match &p.rapier_defaults {
            Ok((wall, pen)) => format!("{wall:.3}  {:.3}", pen * 1e3),
            Err(e) => format!("stopped: {e}"),
        };
        println!(
            "{:<10} {:>5}  {:.3} ({:.3}..{:.3})       {:>5.2}  {:>10.3}  {:<7} | {peer}",
            p.workpiece,
            p.count,
            p.median_wall_s,
            p.min_max_wall_s.0,
            p.min_max_wall_s.1,
            p.settle_sim_s,
            p.max_penetration_m * 1e3,
            p.settled
        );
    }
    println!(
        "step with {} resting parts of {} and the arm moving: {:.4} ms median ({:.4}..{:.4}), target <= {:.1} ms",
        b.step_pile.0, b.step_pile.1, b.step_ms_median, b.step_ms_min_max.0, b.step_ms_min_max.1, b.targets.1
    );
    Ok(())
}

fn sense(a: &PileArgs) -> Result<()> {
    use binpick::sensor::{HeightMap, Sensor};
    let PiledCell {
        loaded,
        wp,
        robot,
        mut world,
        count,
        ..
    } = piled_cell(a)?;
    let (seed, out, json) = (a.seed, &a.out, a.json);
    let mut sensor = Sensor::new(&loaded.scene.sensor, &world, seed).context("the sensor's pose is degenerate")?;
    // Trigger; a spoiled exposure is repeated (up to five times) once the scene is still again.
    let mut capture_ms;
    let mut spoiled = Vec::new();
    let (job, detections) = loop {
        let t0 = std::time::Instant::now();
        let mut job = sensor
            .trigger(&world)
            .map_err(|p| anyhow::anyhow!("capture refused: {p:?}"))?;
        capture_ms = t0.elapsed().as_secs_f64() * 1e3;
        while world.time_s + 1e-9 < job.ready_s && job.spoiled.is_none() {
            world.step().context("waiting for the recognition result")?;
            sensor.watch(&mut job, &world);
        }
        match sensor.result(&job, &world) {
            Some(d) => break (job, d),
            None if spoiled.len() < 5 => {
                spoiled.push(job.spoiled.clone());
                world.run_for(0.2).context("waiting for the scene to settle")?;
            }
            None => anyhow::bail!("six captures in a row were spoiled: {spoiled:?}"),
        }
    };
    let report = binpick::sensor::evaluate(&world, &detections);
    let t1 = std::time::Instant::now();
    let hm = HeightMap::from_capture(&job.capture, &world, 0.002);
    let selector = binpick::grasp::GraspSelector::new(&loaded.scene, &robot, &wp.workpiece);
    let slots = loaded.scene.world_from_slots(&wp.workpiece);
    let plan = selector.select(&detections, &hm, &slots[0], &world.joints());
    let grasp_ms = t1.elapsed().as_secs_f64() * 1e3;
    let name = format!("sense-{}-seed{seed}", wp.workpiece.name);
    let run = binpick::report::RunDir::create(out, &name)?;
    run.write_inputs(&loaded, Some(&wp))?;
    job.capture
        .write_depth_png(&run.path("depth.png"))
        .context("writing depth.png")?;
    job.capture
        .write_ply(&run.path("cloud.ply"))
        .context("writing cloud.ply")?;
    let file = json!({
        "binpick_version": env!("CARGO_PKG_VERSION"), "workpiece": wp.workpiece.name, "seed": seed, "count": count,
        "capture": {"trigger_s": job.capture.trigger_s, "ready_s": job.ready_s, "width_px": job.capture.width,
                    "height_px": job.capture.height, "valid_px": job.capture.valid_count(), "spoiled_before": &spoiled},
        "recognition": &report, "detections": &detections,
        "grasp": {"chosen": plan.best(), "ranked": plan.ranked.len(), "rejected": plan.rejected_counts()},
    });
    run.write_json("sense.json", &file)?;
    let dest = run.finish()?;
    if json {
        let mut v = file;
        v["timing_ms"] = json!({"capture": capture_ms, "grasp": grasp_ms});
        v["run_dir"] = json!(dest.display().to_string());
        v.as_object_mut().map(|o| o.remove("detections"));
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "pile of {count} x {} , seed {seed}: capture at t = {:.3} s, result at {:.3} s",
        wp.workpiece.name, job.capture.trigger_s, job.ready_s
    );
    println!(
        "  capture          {} x {} px, {} returns, {:.1} ms wall; {} spoiled exposure(s) repeated",
        job.capture.width,
        job.capture.height,
        job.capture.valid_count(),
        capture_ms,
        spoiled.len()
    );
    println!(
        "  recognition      {} detected of {} in the tray; top layer {} / {} detected (recall {:.1} %)",
        report.detected,
        report.parts,
        report.top_layer_detected,
        report.top_layer,
        report.top_layer_recall * 100.0
    );
    println!(
        "  pose error       position mean {:.2} / max {:.2} mm, rotation mean {:.2} / max {:.2} deg",
        report.position_error_m.0 * 1e3,
        report.position_error_m.1 * 1e3,
        report.rotation_error_rad.0.to_degrees(),
        report.rotation_error_rad.1.to_degrees()
    );
    match plan.best() {
        Some(g) => {
            let p = g.world_from_tool.translation.vector;
            println!(
                "  chosen grasp     detection {} face {}: tool at ({:.4}, {:.4}, {:.4}) m, score {:.3} (exposure {:.2}, clearance {:.1} mm, success {:.2}, place motion {:.3} s)",
                g.detection,
                g.face,
                p.x,
                p.y,
                p.z,
                g.score.total,
                g.score.exposure,
                g.score.clearance_m * 1e3,
                g.score.success,
                g.score.motion_s
            );
        }
        None => println!("  chosen grasp     none: nothing graspable"),
    }
    let counts: Vec<String> = plan.rejected_counts().iter().map(|(k, v)| format!("{k} {v}")).collect();
    println!(
        "  candidates       {} feasible; rejected: {}",
        plan.ranked.len(),
        if counts.is_empty() {
            "none".into()
        } else {
            counts.join(", ")
        }
    );
    println!("  grasp selection  {grasp_ms:.2} ms wall (height map, candidates, IK, ranking)");
    println!("  wrote            {}", dest.display());
    Ok(())
}

fn bench_sensor(runs: usize, json: bool) -> Result<()> {
    let (loaded, robot, workpieces) = embedded_cell()?;
    let b = binpick::bench::sense_bench(&loaded, &robot, &workpieces, runs).map_err(|e| anyhow::anyhow!("{e}"))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&b)?);
        return Ok(());
    }
    let s = &loaded.scene.sensor;
    println!(
        "sensing, {} x {} px, {} threads, median of {runs} after a warm-up; targets: capture <= {:.0} ms, grasp selection <= {:.0} ms",
        s.resolution_px[0], s.resolution_px[1], b.threads, b.targets_ms.0, b.targets_ms.1
    );
    println!("workpiece  parts  capture_ms (min..max)   1-thread_ms  grasp_ms (min..max)   recall  feasible");
    for r in &b.rows {
        println!(
            "{:<10} {:>5}  {:>6.2} ({:.2}..{:.2})  {:>11.2}  {:>5.2} ({:.2}..{:.2})  {:>6.1}%  {:>8}",
            r.workpiece,
            r.parts,
            r.capture_ms.0,
            r.capture_ms.1,
            r.capture_ms.2,
            r.capture_one_thread_ms,
            r.grasp_ms.0,
            r.grasp_ms.1,
            r.grasp_ms.2,
            r.top_layer_recall * 100.0,
            r.feasible
        );
    }
    Ok(())
}

fn bench_planner(trials: usize, baseline_trials: usize, seed: u64, json: bool) -> Result<()> {
    let (loaded, robot, workpieces) = embedded_cell()?;
    let rows = binpick::bench::planner_bench(&loaded, &robot, &workpieces, trials, baseline_trials, seed)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "planner, one core; reference (i5-4310U): developed 28.9 ms mean / 90.4 ms max, 100 %; RRT-Connect 761 / 1629 ms, 99 %; RRT 826 / 2086 ms, 97 %"
    );
    println!(
        "{:<52} {:<11} {:>6} {:>8} {:>9} {:>9} {:>9} {:>9} {:>8} {:>9}",
        "case", "algorithm", "trials", "success", "mean_ms", "p95_ms", "max_ms", "samples", "us/check", "ms/sample"
    );
    for r in &rows {
        println!(
            "{:<52} {:<11} {:>6} {:>7.0}% {:>9.3} {:>9.3} {:>9.3} {:>9.1} {:>8.2} {:>9.4}",
            r.case,
            format!("{:?}", r.algorithm),
            r.trials,
            r.success * 100.0,
            r.time_ms.0,
            r.time_ms.1,
            r.time_ms.2,
            r.samples_mean,
            r.us_per_check,
            r.ms_per_sample
        );
        for f in &r.failures {
            println!("    failure: {f}");
        }
    }
    Ok(())
}

fn bench_accel(runs: usize, json: bool) -> Result<()> {
    let loaded = LoadedScene::embedded_default()?;
    let robot = RobotModel::from_scene(&loaded)?;
    let rows = binpick::bench::accel_bench(&loaded, &robot, runs).map_err(|e| anyhow::anyhow!("{e}"))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "motion accelerator, one core, hand + 30 g part; {runs} runs per case, each planning with its own seed: the median run shown, compute = max over the runs of planning + §4.2 in the corridor + §4.3"
    );
    println!(
        "case   default_s  §4.2_s  §4.3_s  optimal_s  toppra_exec_s  improvement  gap_to_opt  folds  compute_max/median_ms  corridor | reference: improvement  compute_ms | peak torque/limit J1..J6       energy default -> final"
    );
    for r in &rows {
        let peaks: Vec<String> = r.peak_ratio.iter().map(|p| format!("{p:.2}")).collect();
        println!(
            "{:<6} {:>9.3} {:>7.3} {:>7.3} {:>10.3} {:>14.3} {:>11.1}% {:>10.1}% {:>3}/{:<2} {:>10.2}/{:<5.2}  {:<8} | {:>21.1}% {:>11.1} | {}  {:.0} -> {:.0}",
            r.case,
            r.default_s,
            r.accelerated_s,
            r.corrected_s,
            r.optimal_s,
            r.toppra_executable_s,
            r.improvement * 100.0,
            r.gap_to_optimal * 100.0,
            r.folds.0,
            r.folds.1,
            r.compute_max_ms,
            r.compute_median_ms,
            if r.corridor_clear { "clear" } else { "BLOCKED" },
            r.reference.0,
            r.reference.1,
            peaks.join(" "),
            r.energy.0,
            r.energy.1
        );
    }
    let mean = rows.iter().map(|r| r.improvement).sum::<f64>() / rows.len().max(1) as f64;
    let lo = rows.iter().map(|r| r.improvement_range.0).fold(f64::INFINITY, f64::min);
    let hi = rows
        .iter()
        .map(|r| r.improvement_range.1)
        .fold(f64::NEG_INFINITY, f64::max);
    println!(
        "mean improvement {:.1} % over the median runs (all runs {:.1}-{:.1} %); target >= 30 %, reference 19.4-28.3 %",
        mean * 100.0,
        lo * 100.0,
        hi * 100.0
    );
    Ok(())
}

/// `--picks` of `run` and `batch`: 1 to 10,000.
fn check_picks(picks: usize) -> Result<()> {
    if picks == 0 || picks > 10_000 {
        return Err(InputError(format!("--picks must be within [1, 10000], got {picks}")).into());
    }
    Ok(())
}

/// `binpick run`: one cell run; prints the per-pick table and the summary, writes the run folder.
#[allow(clippy::too_many_arguments)]
fn run_cell(
    workpiece: &str,
    picks: usize,
    seed: u64,
    deterministic: bool,
    scene: Option<&Path>,
    out: &Path,
    formats: binpick::record::Formats,
    json: bool,
) -> Result<()> {
    use binpick::cycle::RunOptions;
    check_picks(picks)?;
    let (loaded, wp, robot) = load_cell(scene, workpiece)?;
    let wall = std::time::Instant::now();
    let result = binpick::cycle::run(
        &loaded,
        &robot,
        &wp,
        &RunOptions {
            picks,
            seed,
            deterministic,
            keep_trace: formats.any(),
            keep_scene: formats.any(),
            stop: Some(stop_on_ctrl_c()),
        },
    )
    .map_err(|e| anyhow::anyhow!("cell run failed: {e}"))?;
    let wall_s = wall.elapsed().as_secs_f64();
    let name = format!(
        "run-{}-seed{seed}{}",
        wp.workpiece.name,
        if deterministic { "-det" } else { "" }
    );
    let run = binpick::report::RunDir::create(out, &name)?;
    run.write_inputs(&loaded, Some(&wp))?;
    run.write("picks.csv", binpick::report::picks_csv(&result.records))?;
    run.write_json("summary.json", &result.summary)?;
    run.write_json("events.json", &result.events)?;
    let title = format!("binpick run: workpiece {}, seed {seed}", wp.workpiece.name);
    let (whole, steady) = binpick::report::time_charts(&result, &title);
    run.write("timechart.svg", whole)?;
    if let Some(steady) = steady {
        run.write("timechart-steady.svg", steady)?;
    }
    let info = binpick::record::RunInfo {
        scene: loaded.label.clone(),
        workpiece: wp.workpiece.name.clone(),
        seed,
        deterministic,
        picks,
    };
    binpick::record::write_recordings(run.staging_dir(), "run", formats, &result, &robot, &loaded.scene, &info)
        .map_err(|(path, e)| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    let dest = run.finish()?;
    let s = &result.summary;
    let done = || -> Result<()> {
        match s.ended.as_str() {
            "interrupted" => Err(Interrupted(dest.display().to_string()).into()),
            _ => Ok(()),
        }
    };
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &json!({"summary": s, "wall_s": wall_s, "run_dir": dest.display().to_string()})
            )?
        );
        return done();
    }
    print!("{}", binpick::report::picks_table(&result.records));
    println!(
        "{} of {} placed ({:.1} %); takt mean {:.3} s, p95 {:.3}, min {:.3}, max {:.3} over {} picks (reference {}); \
         Pick {:.3} s, Place {:.3} s; waits: sensor {} ({:.2} s), compute {} ({:.2} s); \
         stops {}, collisions {}, drops {}, parts lost {}; captures {} ({} spoiled), refills {}; \
         {:.1} s simulated in {:.2} s wall ({:.0}x real time)",
        s.placed,
        s.attempts,
        100.0 * s.success_rate,
        s.takt.mean_s,
        s.takt.p95_s,
        s.takt.min_s,
        s.takt.max_s,
        s.takt.count,
        s.reference_takt_s.map_or("-".to_string(), |t| format!("{t:.1} s")),
        s.mean_pick_s,
        s.mean_place_s,
        s.sensor_stalls.0,
        s.sensor_stalls.1,
        s.compute_stalls.0,
        s.compute_stalls.1,
        s.protective_stops,
        s.collisions,
        s.drops,
        s.parts_lost,
        s.captures.0,
        s.captures.1,
        s.refills,
        s.sim_time_s,
        wall_s,
        s.sim_time_s / wall_s
    );
    println!("wrote {}", dest.display());
    done()
}

/// `binpick batch`: every (workpiece, seed) run of the batch (or of one shard), in parallel.
fn batch(a: &BatchArgs) -> Result<()> {
    use binpick::batch::{BatchFile, BatchSpec, RunEntry, parse_seeds, parse_shard, shard};
    use binpick::cycle::RunOptions;
    check_picks(a.picks)?;
    let formats = a.skip.formats(a.record);
    let seeds = parse_seeds(&a.seeds).map_err(|e| InputError(e.to_string()))?;
    let (k, n) = match &a.shard {
        Some(t) => parse_shard(t).map_err(|e| InputError(e.to_string()))?,
        None => (1, 1),
    };
    let jobs = match a.jobs {
        Some(0) => return Err(InputError("--jobs must be at least 1, got 0".into()).into()),
        Some(j) => j,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    // Every input is loaded and checked before anything runs or is written.
    let loaded = LoadedScene::load(a.scene.as_deref())?;
    let robot = RobotModel::from_scene(&loaded)?;
    robot.check_scene_reach(&loaded.label, &loaded.scene)?;
    let mut workpieces: Vec<LoadedWorkpiece> = Vec::new();
    for name in a.workpieces.split(',').map(str::trim) {
        if name.is_empty() {
            return Err(InputError(format!("--workpieces: empty name in {:?}", a.workpieces)).into());
        }
        let wp = LoadedWorkpiece::resolve(name)?;
        wp.workpiece.check_fits_scene(&wp.label, &loaded.scene)?;
        if workpieces.iter().any(|w| w.workpiece.name == wp.workpiece.name) {
            return Err(InputError(format!("--workpieces: {} appears twice", wp.workpiece.name)).into());
        }
        workpieces.push(wp);
    }
    let spec = BatchSpec {
        workpieces: workpieces.iter().map(|w| w.workpiece.name.clone()).collect(),
        seeds,
        picks: a.picks,
        deterministic: a.deterministic,
    };
    let mine = shard(&spec.jobs(), k, n);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .build()
        .context("starting the worker threads")?;
    let bar = indicatif::ProgressBar::new(mine.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs {msg}")
            .expect("static template")
            .progress_chars("=> "),
    );
    let name = if n > 1 {
        format!("{}-shard{k}of{n}", spec.name())
    } else {
        spec.name()
    };
    let dir = binpick::report::RunDir::create(&a.out, &name)?;
    let wall = std::time::Instant::now();
    let results: Vec<Result<RunEntry, String>> = pool.install(|| {
        use rayon::prelude::*;
        mine.par_iter()
            .map(|(w, seed)| {
                let wp = workpieces
                    .iter()
                    .find(|x| &x.workpiece.name == w)
                    .expect("from the spec");
                let t = std::time::Instant::now();
                let r = binpick::cycle::run(
                    &loaded,
                    &robot,
                    wp,
                    &RunOptions {
                        picks: spec.picks,
                        seed: *seed,
                        deterministic: spec.deterministic,
                        keep_trace: formats.any(),
                        keep_scene: formats.any(),
                        stop: Some(stop_on_ctrl_c()),
                    },
                )
                .map_err(|e| format!("workpiece {w} seed {seed}: {e}"))
                .and_then(|r| {
                    let entry = RunEntry::from_run(&r, t.elapsed().as_secs_f64());
                    let info = binpick::record::RunInfo {
                        scene: loaded.label.clone(),
                        workpiece: w.clone(),
                        seed: *seed,
                        deterministic: spec.deterministic,
                        picks: spec.picks,
                    };
                    binpick::record::write_recordings(
                        dir.staging_dir(),
                        &format!("run-{w}-seed{seed}"),
                        formats,
                        &r,
                        &robot,
                        &loaded.scene,
                        &info,
                    )
                    .map_err(|(path, e)| format!("{}: {e}", path.display()))?;
                    Ok(entry)
                });
                bar.inc(1);
                r
            })
            .collect()
    });
    bar.finish_and_clear();
    let wall_s = wall.elapsed().as_secs_f64();
    let mut runs = Vec::new();
    for r in results {
        runs.push(r.map_err(|e| anyhow::anyhow!("cell run failed: {e}"))?);
    }
    let file = BatchFile {
        version: env!("CARGO_PKG_VERSION").into(),
        spec,
        shard: (k, n),
        runs,
    };
    dir.write_inputs(&loaded, None)?;
    for wp in &workpieces {
        dir.write_workpiece(wp, &format!("workpiece-{}.toml", wp.workpiece.name))?;
    }
    write_batch(dir, &file, wall_s, jobs, a.json)
}

/// Writes takt.json, takt.csv and takt.md of a batch (or a merge) and prints the table.
fn write_batch(
    dir: binpick::report::RunDir,
    file: &binpick::batch::BatchFile,
    wall_s: f64,
    jobs: usize,
    json: bool,
) -> Result<()> {
    let rows = binpick::batch::table(&file.spec.workpieces, &file.runs);
    let md = binpick::batch::markdown(&rows);
    let sim_s: f64 = file.runs.iter().map(|r| r.sim_time_s).sum();
    let run_wall_s: f64 = file.runs.iter().map(|r| r.wall_s).sum();
    dir.write_json("takt.json", &json!({"batch": file, "table": rows}))?;
    dir.write("takt.csv", binpick::batch::csv(&rows))?;
    dir.write("takt.md", &md)?;
    let dest = dir.finish()?;
    let done = || -> Result<()> {
        if file.runs.iter().any(|r| r.ended == "interrupted") {
            Err(Interrupted(dest.display().to_string()).into())
        } else {
            Ok(())
        }
    };
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json!({"table": rows, "wall_s": wall_s, "dir": dest.display().to_string()}))?
        );
        return done();
    }
    let (k, n) = file.shard;
    println!(
        "{} runs of {} picks{}{}, seeds {:?}\n",
        file.runs.len(),
        file.spec.picks,
        if file.spec.deterministic {
            ", deterministic compute budgets"
        } else {
            ", measured compute"
        },
        if n > 1 {
            format!(", shard {k} of {n}")
        } else {
            String::new()
        },
        file.spec.seeds
    );
    print!("{md}");
    println!(
        "\ntakt over the placed picks after the first of each pile; {sim_s:.1} s simulated in {run_wall_s:.1} s of run time \
         ({:.0}x real time per core), {wall_s:.1} s wall on {jobs} threads",
        sim_s / run_wall_s.max(1e-9)
    );
    println!("wrote {}", dest.display());
    done()
}

/// `binpick merge`: the shards of one batch into its table.
fn merge(dirs: &[PathBuf], out: &Path, json: bool) -> Result<()> {
    let mut files = Vec::new();
    for d in dirs {
        let path = d.join("takt.json");
        let text =
            std::fs::read_to_string(&path).map_err(|e| InputError(format!("{}: cannot read: {e}", path.display())))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| InputError(format!("{}: not a batch result: {e}", path.display())))?;
        let f: binpick::batch::BatchFile = serde_json::from_value(v["batch"].clone())
            .map_err(|e| InputError(format!("{}: not a batch result: {e}", path.display())))?;
        files.push((path.display().to_string(), f));
    }
    let merged = binpick::batch::merge(&files).map_err(|e| InputError(e.to_string()))?;
    let dir = binpick::report::RunDir::create(out, &merged.spec.name())?;
    // The shards' resolved inputs are the same; the first one's go with the merge.
    for entry in std::fs::read_dir(&dirs[0]).with_context(|| dirs[0].display().to_string())? {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if !name.starts_with("takt.") && entry.file_type()?.is_file() {
            dir.write(&name, std::fs::read(entry.path())?)?;
        }
    }
    let wall_s = merged.runs.iter().map(|r| r.wall_s).sum();
    write_batch(dir, &merged, wall_s, 1, json)
}

/// Set when Ctrl-C was pressed: runs end after the pick under way and write what they have.
static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Installs the Ctrl-C handler (once) and returns the flag it sets. A second Ctrl-C, while the
/// first is being honoured, exits at once with 130.
fn stop_on_ctrl_c() -> &'static std::sync::atomic::AtomicBool {
    static INSTALLED: std::sync::Once = std::sync::Once::new();
    INSTALLED.call_once(|| {
        let installed = ctrlc::set_handler(|| {
            if STOP.swap(true, std::sync::atomic::Ordering::Relaxed) {
                std::process::exit(130);
            }
            eprintln!("interrupted: finishing the pick under way and writing the results");
        });
        if let Err(e) = installed {
            eprintln!("warning: Ctrl-C will stop the process without writing results: {e}");
        }
    });
    &STOP
}
