//! `binpick bench ...`: the benchmarks, our code beside a baseline or peer doing the same work
//! in the same run, on the embedded default cell; medians of several runs.

use anyhow::{Context, Result};
use clap::Subcommand;

use super::InputError;
use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::robot::{Payload, RobotModel};

/// Runs a benchmark.
pub fn run(command: BenchCommand) -> Result<()> {
    match command {
        BenchCommand::Physics { runs, json } => bench_physics(runs, json),
        BenchCommand::Accel { runs, accel_cap, json } => bench_accel(runs, accel_cap, json),
        BenchCommand::Planner {
            trials,
            baseline_trials,
            seed,
            json,
        } => bench_planner(trials, baseline_trials, seed, json),
        BenchCommand::Sensor {
            runs,
            seeds,
            scene,
            workpieces,
            json,
        } => bench_sensor(runs, seeds, scene.as_deref(), workpieces.as_deref(), json),
        BenchCommand::Robot { runs, calls, json } => {
            let loaded = LoadedScene::embedded_default()?;
            let robot = RobotModel::from_scene(&loaded)?;
            bench_robot(&loaded, &robot, runs, calls, json)
        }
    }
}

/// `binpick bench ...`.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// Motion accelerator: the reference system's five cases (J1 turns 180 deg between two
    /// containers): default parameters, acceleration search, path correction, time-optimal.
    Accel {
        /// Runs per case (compute time is the max over them).
        #[arg(long, default_value_t = 20)]
        runs: usize,
        /// The accelerator's acceleration cap: `none` (the torque alone binds) or `spec` (the
        /// specification accelerations too); overrides the cell file's `robot.drives.accel_cap`.
        /// Both bounds are reported either way.
        #[arg(long, value_name = "none|spec")]
        accel_cap: Option<binpick::config::AccelCap>,
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
    /// Sensing: depth capture (all cores, and one thread as the peer), recognition from the
    /// point cloud beside the oracle (quality against the truth at the trigger, compute), and
    /// grasp selection, per workpiece at its default pile.
    Sensor {
        /// Timed repetitions after one warm-up.
        #[arg(long, default_value_t = 7)]
        runs: usize,
        /// Recognition over the default pile of seeds 1..=N per workpiece.
        #[arg(long, default_value_t = 8)]
        seeds: u64,
        /// Scene file (default: the embedded default cell), e.g. another sensor resolution.
        #[arg(long)]
        scene: Option<std::path::PathBuf>,
        /// Workpieces, comma-separated: A ... F (embedded) or paths to workpiece files (default:
        /// A to F).
        #[arg(long)]
        workpieces: Option<String>,
        /// Machine-readable JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Physics: pile build-and-settle wall time per workpiece, and the step time of 100 resting
    /// parts with the arm moving, beside rapier's default solver settings; CAD parts (meshes)
    /// beside primitives of their size and count.
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

/// The embedded default cell, its robot and all six embedded workpieces: what the benchmarks run on.
fn embedded_cell() -> Result<(LoadedScene, RobotModel, Vec<LoadedWorkpiece>)> {
    let loaded = LoadedScene::embedded_default()?;
    let robot = RobotModel::from_scene(&loaded)?;
    Ok((loaded, robot, LoadedWorkpiece::all_embedded()?))
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
        "{:<55} {:>10} {:>21} {:>9}",
        "what", "median_ns", "min..max_ns", "target"
    );
    for t in &result.timings {
        let target = t.target_ns.map_or(String::new(), |v| format!("<= {v:.0}"));
        println!(
            "{:<55} {:>10.1} {:>10.1}..{:<10.1} {:>9}",
            t.name, t.median_ns, t.min_ns, t.max_ns, target
        );
        // A note (a baseline's success rate) on a line of its own under its row.
        if !t.note.is_empty() {
            super::say_under("", 4, &t.note);
        }
    }
    Ok(())
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
            Err(_) => "stopped (below)".to_string(),
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
        if let Err(e) = &p.rapier_defaults {
            super::say_under("", 4, &format!("rapier defaults stopped: {e}"));
        }
    }
    println!(
        "step with {} resting parts of {} and the arm moving: {:.4} ms median ({:.4}..{:.4}), target <= {:.1} ms",
        b.step_pile.0, b.step_pile.1, b.step_ms_median, b.step_ms_min_max.0, b.step_ms_min_max.1, b.targets.1
    );
    println!(
        "CAD parts beside primitives (same seeds); target: mesh wall <= {:.0} x primitive wall",
        b.mesh_target_ratio
    );
    // Two tables within the terminal's width: the walls, then the piles' fidelity (mesh / primitive).
    println!(
        "{:<30} {:>6} {:>5} {:>6}  {:<24} {:<24} {:>6}",
        "mesh part", "pieces", "vs", "parts", "mesh wall_s (min..max)", "prim wall_s (min..max)", "ratio",
    );
    for m in &b.meshes {
        println!(
            "{:<30} {:>6} {:>5} {:>6}  {:.3} ({:.3}..{:.3})      {:.3} ({:.3}..{:.3})      {:>6.2}",
            m.mesh,
            m.mesh_pieces,
            m.primitive,
            m.count,
            m.mesh_wall_s.0,
            m.mesh_wall_s.1,
            m.mesh_wall_s.2,
            m.primitive_wall_s.0,
            m.primitive_wall_s.1,
            m.primitive_wall_s.2,
            m.ratio,
        );
        for (what, stops) in [(&m.mesh, &m.stops.0), (&m.primitive, &m.stops.1)] {
            for s in stops {
                super::say_under("", 4, &format!("{what} stopped (left out of the medians): {s}"));
            }
        }
    }
    // The second table: the piles' fidelity, and where a wall ratio comes from: the time a pile
    // takes to settle (simulated) or the cost of each simulated second (colliders, contacts).
    println!(
        "\n{:<28} {:>5}  {:>15}  {:>13}  {:>14}  {:>12}  {:>9}",
        "mesh part", "vs", "max_pen_mm m/p", "height_mm m/p", "shake x_rt m/p", "settle_s m/p", "per sim s"
    );
    for m in &b.meshes {
        println!(
            "{:<28} {:>5}  {:>7.3} {:>7.3}  {:>6.2} {:>6.2}  {:>6.1} {:>7.1}  {:>5.2} {:>6.2}  {:>9.2}",
            m.mesh,
            m.primitive,
            m.max_penetration_m.0 * 1e3,
            m.max_penetration_m.1 * 1e3,
            m.pile_height_m.0 * 1e3,
            m.pile_height_m.1 * 1e3,
            m.agitation_real_time.0,
            m.agitation_real_time.1,
            m.settle_sim_s.0,
            m.settle_sim_s.1,
            m.per_sim_s_ratio
        );
    }
    super::say_under(
        "",
        0,
        "per sim s: the mesh pile's wall time per simulated second over the primitive's (medians): what its \
         colliders and contacts cost; the wall ratio is about that times how much longer (simulated) the \
         mesh pile takes to settle",
    );
    Ok(())
}

fn bench_sensor(
    runs: usize,
    seeds: u64,
    scene: Option<&std::path::Path>,
    names: Option<&str>,
    json: bool,
) -> Result<()> {
    let loaded = LoadedScene::load(scene)?;
    let robot = RobotModel::from_scene(&loaded)?;
    let workpieces = match names {
        Some(list) => list
            .split(',')
            .map(|n| LoadedWorkpiece::resolve(n.trim()))
            .collect::<Result<Vec<_>, _>>()?,
        None => LoadedWorkpiece::all_embedded()?,
    };
    let b =
        binpick::bench::sense_bench(&loaded, &robot, &workpieces, runs, seeds).map_err(|e| anyhow::anyhow!("{e}"))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&b)?);
        return Ok(());
    }
    let s = &loaded.scene.sensor;
    super::say(&format!(
        "sensing, {} x {} px, {} threads, median of {runs} after a warm-up; targets: capture <= {:.0} ms, grasp selection <= {:.0} ms",
        s.resolution_px[0], s.resolution_px[1], b.threads, b.targets_ms.0, b.targets_ms.1
    ));
    println!("workpiece  parts  capture_ms (min..max)   1-thread_ms  grasp_ms (min..max)   feasible");
    for r in &b.rows {
        println!(
            "{:<10} {:>5}  {:>6.2} ({:.2}..{:.2})  {:>11.2}  {:>5.2} ({:.2}..{:.2})  {:>8}",
            r.workpiece,
            r.parts,
            r.capture_ms.0,
            r.capture_ms.1,
            r.capture_ms.2,
            r.capture_one_thread_ms,
            r.grasp_ms.0,
            r.grasp_ms.1,
            r.grasp_ms.2,
            r.feasible
        );
    }
    println!();
    super::say(&format!(
        "recognition over seeds 1..={} of the default pile, one capture each, against the truth at the trigger; \
         correct = within 2 mm and 5 deg of a part (its symmetries allowed); recall over the top layer. \
         targets (cloud): recall >= 90 %, precision >= 99 %, pose median <= 0.7 mm / 1.5 deg, p95 <= 1.5 mm / 4 deg, \
         compute median <= {:.0} ms",
        b.seeds, b.targets_ms.2
    ));
    println!(
        "workpiece  recognition  top  found  recall%  det  correct  prec%  pos_mm med/p95  rot_deg med/p95  ms med/max"
    );
    for r in &b.rows {
        for (name, k) in [("cloud", &r.cloud), ("oracle", &r.oracle)] {
            let q = &k.quality;
            println!(
                "{:<10} {name:<11} {:>4} {:>6} {:>8.1} {:>4} {:>8} {:>6.1}  {:>5.2} / {:>5.2}  {:>6.2} / {:>5.2}  {:>5.1} / {:>5.1}",
                r.workpiece,
                q.top_layer,
                q.top_layer_found,
                q.recall * 100.0,
                q.detected,
                q.correct,
                q.precision * 100.0,
                q.position_error_mm[0],
                q.position_error_mm[1],
                q.rotation_error_deg[0],
                q.rotation_error_deg[1],
                k.compute_ms.0,
                k.compute_ms.1,
            );
        }
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
    let reference: Vec<String> = binpick::reference::TABLE2_PLANNING
        .iter()
        .map(|p| format!("{} {} / {} ms, {} %", p.name, p.mean_ms, p.max_ms, p.success_pct))
        .collect();
    super::say(&format!(
        "planner, one core; reference's Table 2 (its Fig. 5 cases, 100 trials, i5-4310U): {}",
        reference.join("; ")
    ));
    // Each case's name heads its rows (the names run to 52 characters).
    let mut case = "";
    for r in &rows {
        if r.case != case {
            case = &r.case;
            println!("\n{case}");
            println!(
                "  {:<11} {:>6} {:>8} {:>9} {:>9} {:>9} {:>9} {:>8} {:>9}",
                "algorithm", "trials", "success", "mean_ms", "p95_ms", "max_ms", "samples", "us/check", "ms/sample"
            );
        }
        println!(
            "  {:<11} {:>6} {:>7.0}% {:>9.3} {:>9.3} {:>9.3} {:>9.1} {:>8.2} {:>9.4}",
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

fn bench_accel(runs: usize, accel_cap: Option<binpick::config::AccelCap>, json: bool) -> Result<()> {
    let loaded = LoadedScene::embedded_default()?;
    let mut robot = RobotModel::from_scene(&loaded)?;
    if let Some(cap) = accel_cap {
        robot = robot.with_accel_cap(cap);
    }
    let rows = binpick::bench::accel_bench(&loaded, &robot, runs).map_err(|e| anyhow::anyhow!("{e}"))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    super::say(&format!(
        "motion accelerator, one core, hand + 30 g part, acceleration cap `{}` ({}); {runs} runs per case, each planning with its own seed: the median run shown, compute = max over the runs of planning + §4.2 in the corridor + §4.3",
        robot.accel_cap.name(),
        match robot.accel_cap {
            binpick::config::AccelCap::TorqueOnly => "torque and speed alone bind",
            binpick::config::AccelCap::Spec => "the specification accelerations cap every joint",
        }
    ));
    super::say(
        "optimal_s: the time-optimal bound under torque and speed alone; capped_s: with the specification accelerations as caps too; gap: §4.3 / bound - 1",
    );
    // Two tables, each within the terminal's width: the motion times, then the path folds,
    // compute (max / median over the runs), the reference's improvement and compute, the peak
    // torques and the energy (default -> final).
    println!(
        "\ncase   default_s  §4.2_s  §4.3_s  optimal_s  capped_s  toppra_exec_s  improvement  gap_to_opt  gap_to_capped"
    );
    for r in &rows {
        println!(
            "{:<6} {:>9.3} {:>7.3} {:>7.3} {:>10.3} {:>9.3} {:>14.3} {:>11.1}% {:>10.1}% {:>13.1}%",
            r.case,
            r.default_s,
            r.accelerated_s,
            r.corrected_s,
            r.optimal_s,
            r.optimal_capped_s,
            r.toppra_executable_s,
            r.improvement * 100.0,
            r.gap_to_optimal * 100.0,
            r.gap_to_capped * 100.0,
        );
    }
    println!("\ncase   folds  max/med ms  corridor  ref: impr.  ref ms  peak torque/limit J1..J6       energy");
    for r in &rows {
        let peaks: Vec<String> = r.peak_ratio.iter().map(|p| format!("{p:.2}")).collect();
        println!(
            "{:<6} {:>3}/{:<2} {:>6.1}/{:<5.1}  {:<8}  {:>9.1}% {:>7.1}  {:<29}  {:.0} -> {:.0}",
            r.case,
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
    let mean = binpick::stats::mean_of(rows.iter().map(|r| r.improvement));
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
