//! Benchmarks run by `binpick bench ...`: timings of our code beside a baseline doing the same work.
//!
//! Job: time hot functions per call on one core, repeated over several runs, and report the
//! median, min and max of the runs. Inputs are drawn from seeded streams so every run times the
//! same work. Units: nanoseconds per call.

use std::hint::black_box;
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::robot::{JointVector, Payload, RobotModel};

/// Per-call timing over several runs.
#[derive(Debug, Clone, Serialize)]
pub struct Timing {
    /// What was timed.
    pub name: String,
    /// Median over runs of the mean time per call [ns].
    pub median_ns: f64,
    /// Fastest run [ns per call].
    pub min_ns: f64,
    /// Slowest run [ns per call].
    pub max_ns: f64,
    /// Calls per run.
    pub calls_per_run: usize,
    /// Runs.
    pub runs: usize,
    /// Target per call, if the issue sets one [ns].
    pub target_ns: Option<f64>,
    /// Free-form note (success rate of a baseline, ...).
    pub note: String,
}

/// Times `f(i)` for `i in 0..calls`, `runs` times after one warm-up run.
pub fn time_per_call(
    name: &str,
    runs: usize,
    calls: usize,
    target_ns: Option<f64>,
    mut f: impl FnMut(usize),
) -> Timing {
    for i in 0..calls.min(1000) {
        f(i);
    }
    let per_call: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let t0 = Instant::now();
            for i in 0..calls {
                f(i);
            }
            t0.elapsed().as_nanos() as f64 / calls as f64
        })
        .collect();
    let (median_ns, min_ns, max_ns) = crate::stats::median_min_max(&per_call);
    Timing {
        name: name.to_string(),
        median_ns,
        min_ns,
        max_ns,
        calls_per_run: calls,
        runs: runs.max(1),
        target_ns,
        note: String::new(),
    }
}

/// Damped least-squares numerical IK on the flange pose: the iterative solver a generic
/// controller uses, as the baseline for the closed-form solver. Returns the solution if the
/// pose error fell below 1e-10 within `max_iter` iterations.
pub fn numerical_ik(
    robot: &RobotModel,
    target: &nalgebra::Isometry3<f64>,
    seed: &JointVector,
    max_iter: usize,
) -> Option<JointVector> {
    let mut q = *seed;
    let flange_from_tool = robot.flange_from_tool;
    for _ in 0..max_iter {
        let cur = robot.base_from_flange(&q);
        let dp = target.translation.vector - cur.translation.vector;
        let dr = (target.rotation * cur.rotation.inverse()).scaled_axis();
        if dp.norm() < 1e-10 && dr.norm() < 1e-10 {
            return robot.within_limits(&q, 0.0).then_some(q);
        }
        // Flange Jacobian: the tool Jacobian shifted back by the tool offset.
        let mut jac = robot.jacobian_tool(&q);
        let tool_offset = cur.rotation * flange_from_tool.translation.vector;
        for i in 0..6 {
            let w = jac.fixed_view::<3, 1>(3, i).into_owned();
            let v = jac.fixed_view::<3, 1>(0, i) - w.cross(&tool_offset);
            jac.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
        }
        let err = nalgebra::Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
        let lambda2 = 1e-6;
        let jjt = jac * jac.transpose() + nalgebra::Matrix6::identity() * lambda2;
        let step = jac.transpose() * jjt.cholesky()?.solve(&err);
        q += step;
    }
    None
}

/// The robot-model benchmark: IK, FK, inverse dynamics, mass matrix, forward dynamics.
#[derive(Debug, Clone, Serialize)]
pub struct RobotBench {
    /// Timings, ours and baselines.
    pub timings: Vec<Timing>,
}

/// Runs the robot-model benchmark on one core.
pub fn robot_bench(robot: &RobotModel, payload: &Payload, runs: usize, calls: usize) -> RobotBench {
    let mut rng = ChaCha8Rng::seed_from_u64(0xB1_4B1C);
    let n = 1024usize;
    let qs: Vec<JointVector> = (0..n)
        .map(|_| JointVector::from_fn(|i, _| rng.random_range(robot.joints[i].lower_rad..robot.joints[i].upper_rad)))
        .collect();
    let qds: Vec<JointVector> = (0..n)
        .map(|_| JointVector::from_fn(|_, _| rng.random_range(-3.0..3.0)))
        .collect();
    let qdds: Vec<JointVector> = (0..n)
        .map(|_| JointVector::from_fn(|_, _| rng.random_range(-30.0..30.0)))
        .collect();
    let targets: Vec<_> = qs.iter().map(|q| robot.base_from_flange(q)).collect();
    let seeds: Vec<JointVector> = qs
        .iter()
        .map(|q| q + JointVector::from_fn(|_, _| rng.random_range(-0.3..0.3)))
        .collect();
    let dynamics = robot.dynamics(payload);
    let mut timings = Vec::new();

    timings.push(time_per_call(
        "ik closed-form, nearest to seed (ours)",
        runs,
        calls,
        Some(2000.0),
        |i| {
            let k = i % n;
            let _ = black_box(robot.ik_flange_nearest(black_box(&targets[k]), &seeds[k]));
        },
    ));
    let mut buf = Vec::with_capacity(64);
    timings.push(time_per_call(
        "ik closed-form, all solutions (ours)",
        runs,
        calls,
        None,
        |i| {
            let k = i % n;
            buf.clear();
            if let Ok(s) = robot.ik_flange_all(black_box(&targets[k])) {
                buf.extend(s);
            }
            black_box(&buf);
        },
    ));
    let baseline_calls = (calls / 20).max(200);
    let mut ok = 0usize;
    let mut total = 0usize;
    let mut t = time_per_call(
        "ik numerical DLS from a seed 0.3 rad off (baseline)",
        runs,
        baseline_calls,
        None,
        |i| {
            let k = i % n;
            total += 1;
            if black_box(numerical_ik(robot, &targets[k], &seeds[k], 100)).is_some() {
                ok += 1;
            }
        },
    );
    t.note = format!(
        "converged within limits in {:.1} % of calls",
        100.0 * ok as f64 / total.max(1) as f64
    );
    timings.push(t);
    timings.push(time_per_call("fk all link frames", runs, calls, None, |i| {
        black_box(robot.base_from_links(black_box(&qs[i % n])));
    }));
    timings.push(time_per_call(
        "inverse dynamics RNEA, full model (ours)",
        runs,
        calls,
        Some(1000.0),
        |i| {
            let k = i % n;
            black_box(dynamics.inverse_dynamics(black_box(&qs[k]), &qds[k], &qdds[k]));
        },
    ));
    timings.push(time_per_call(
        "inverse dynamics as M(q) qdd + bias (baseline)",
        runs,
        calls / 4,
        None,
        |i| {
            let k = i % n;
            let m = dynamics.mass_matrix(&qs[k]);
            let bias = dynamics.inverse_dynamics(&qs[k], &qds[k], &JointVector::zeros());
            black_box(m * qdds[k] + bias);
        },
    ));
    timings.push(time_per_call("mass matrix CRBA", runs, calls / 4, None, |i| {
        black_box(dynamics.mass_matrix(black_box(&qs[i % n])));
    }));
    let taus: Vec<JointVector> = (0..n)
        .map(|k| dynamics.inverse_dynamics(&qs[k], &qds[k], &qdds[k]))
        .collect();
    timings.push(time_per_call(
        "forward dynamics (RNEA bias + CRBA + Cholesky)",
        runs,
        calls / 4,
        None,
        |i| {
            let k = i % n;
            black_box(dynamics.forward_dynamics(&qs[k], &qds[k], &taus[k]));
        },
    ));
    RobotBench { timings }
}

/// One workpiece's pile timing, ours beside rapier's default solver settings.
#[derive(Debug, Clone, Serialize)]
pub struct PileTiming {
    /// Workpiece name.
    pub workpiece: String,
    /// Parts in the pile.
    pub count: usize,
    /// Wall time to build and settle, median of runs [s].
    pub median_wall_s: f64,
    /// Fastest and slowest run [s].
    pub min_max_wall_s: (f64, f64),
    /// Simulated settle time [s].
    pub settle_sim_s: f64,
    /// Deepest overlap after settling, independent check [m].
    pub max_penetration_m: f64,
    /// Whether it settled.
    pub settled: bool,
    /// The same pile with rapier's default contact stiffness and solver iterations, no adaptive
    /// substeps: wall time [s], deepest overlap [m], or the health error that stopped it.
    pub rapier_defaults: Result<(f64, f64), String>,
}

/// The physics benchmark: piles of each workpiece and the step time of a resting pile with the arm moving.
#[derive(Debug, Clone, Serialize)]
pub struct PhysicsBench {
    /// Per workpiece.
    pub piles: Vec<PileTiming>,
    /// Step time with 100 resting parts and the arm moving, median of runs [ms].
    pub step_ms_median: f64,
    /// Fastest and slowest run [ms].
    pub step_ms_min_max: (f64, f64),
    /// Parts in the resting pile, and which workpiece.
    pub step_pile: (usize, String),
    /// Targets: settle wall time per pile [s] and step time [ms].
    pub targets: (f64, f64),
}

fn median(v: Vec<f64>) -> (f64, f64, f64) {
    crate::stats::median_min_max(&v)
}

/// Runs the physics benchmark on one core.
pub fn physics_bench(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    workpieces: &[crate::config::LoadedWorkpiece],
    runs: usize,
) -> Result<PhysicsBench, Box<dyn std::error::Error + Send + Sync>> {
    use crate::physics::{PartShape, World, pile::PileOptions};
    let runs = runs.max(1);
    let mut piles = Vec::new();
    for wp in workpieces {
        let shape = PartShape::build(&wp.workpiece, &wp.source)?;
        let count = wp.workpiece.pile_count as usize;
        let mut walls = Vec::new();
        let mut last = None;
        for run in 0..runs {
            let mut w = World::new(&scene.scene, robot, shape.clone());
            let t0 = Instant::now();
            let r = w.build_pile(&PileOptions::new(count, 1 + run as u64))?;
            walls.push(t0.elapsed().as_secs_f64());
            last = Some(r);
        }
        let r = last.expect("at least one run");
        let (med, lo, hi) = median(walls);
        // Peer: rapier's defaults for contact stiffness and iterations, one step per step.
        let mut w = World::new(&scene.scene, robot, shape.clone());
        w.set_solver(crate::physics::Solver::RapierDefaults);
        let t0 = Instant::now();
        let peer = w
            .build_pile(&PileOptions::new(count, 1))
            .map(|p| (t0.elapsed().as_secs_f64(), p.max_penetration_m))
            .map_err(|e| e.to_string());
        piles.push(PileTiming {
            workpiece: wp.workpiece.name.clone(),
            count,
            median_wall_s: med,
            min_max_wall_s: (lo, hi),
            settle_sim_s: r.settle_sim_s,
            max_penetration_m: r.max_penetration_m,
            settled: r.settled,
            rapier_defaults: peer,
        });
    }
    // 100 resting parts of F, the arm sweeping between the trays above them.
    let f = workpieces
        .iter()
        .find(|w| w.workpiece.name == "F")
        .or(workpieces.first())
        .ok_or("no workpiece given")?;
    let shape = PartShape::build(&f.workpiece, &f.source)?;
    let mut w = World::new(&scene.scene, robot, shape);
    w.build_pile(&PileOptions::new(100, 1))?;
    let home = w.joints();
    let over_pick = robot
        .ik_tool_nearest(
            &crate::robot::tool_down_pose(
                w.pick_tray().world_from_tray.translation.vector + nalgebra::Vector3::z() * 0.15,
                0.0,
            ),
            &home,
        )
        .map_err(|e| e.to_string())?
        .q;
    let mut per_run = Vec::new();
    for _ in 0..runs {
        let steps = 2000;
        let t0 = Instant::now();
        for k in 0..steps {
            // Back and forth between home and over the pick tray, 0.8 s each way.
            let u = (k % 800) as f64 / 400.0;
            let s = crate::physics::script::quintic(if u <= 1.0 { u } else { 2.0 - u });
            w.set_joint_target(&(home + (over_pick - home) * s));
            w.step()?;
        }
        per_run.push(t0.elapsed().as_secs_f64() * 1e3 / steps as f64);
    }
    let (med, lo, hi) = median(per_run);
    Ok(PhysicsBench {
        piles,
        step_ms_median: med,
        step_ms_min_max: (lo, hi),
        step_pile: (100, f.workpiece.name.clone()),
        targets: (1.0, 0.3),
    })
}

/// One workpiece's sensing timings.
#[derive(Debug, Clone, Serialize)]
pub struct SenseTiming {
    /// Workpiece name.
    pub workpiece: String,
    /// Parts in the pile.
    pub parts: usize,
    /// Capture wall time on all cores, median [ms] and min..max.
    pub capture_ms: (f64, f64, f64),
    /// The same capture on one thread, median [ms] (the peer).
    pub capture_one_thread_ms: f64,
    /// Grasp selection (height map, candidates, IK, ranking) wall time, median [ms] and min..max.
    pub grasp_ms: (f64, f64, f64),
    /// Top-layer recall of that capture.
    pub top_layer_recall: f64,
    /// Feasible candidates.
    pub feasible: usize,
}

/// The sensing benchmark: capture and grasp selection per workpiece at its default pile.
#[derive(Debug, Clone, Serialize)]
pub struct SenseBench {
    /// Per workpiece.
    pub rows: Vec<SenseTiming>,
    /// Threads the parallel capture used.
    pub threads: usize,
    /// Targets [ms]: capture, grasp selection.
    pub targets_ms: (f64, f64),
}

/// Runs the sensing benchmark: `runs` timed repetitions after one warm-up.
pub fn sense_bench(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    workpieces: &[crate::config::LoadedWorkpiece],
    runs: usize,
) -> Result<SenseBench, Box<dyn std::error::Error + Send + Sync>> {
    use crate::physics::{PartShape, World, pile::PileOptions};
    use crate::sensor::{Sensor, capture};
    let runs = runs.max(1);
    let mut rows = Vec::new();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    for wp in workpieces {
        let shape = PartShape::build(&wp.workpiece, &wp.source)?;
        let mut w = World::new(&scene.scene, robot, shape);
        w.build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, 1))?;
        let sensor = Sensor::new(&scene.scene.sensor, &w, 1).ok_or("degenerate sensor pose")?;
        let time_ms = |f: &mut dyn FnMut()| {
            f();
            median(
                (0..runs)
                    .map(|_| {
                        let t0 = Instant::now();
                        f();
                        t0.elapsed().as_secs_f64() * 1e3
                    })
                    .collect(),
            )
        };
        let mut c = capture(&w, &sensor.camera, 1, 0);
        let cap = time_ms(&mut || c = capture(&w, &sensor.camera, 1, 0));
        let single = one.install(|| time_ms(&mut || c = capture(&w, &sensor.camera, 1, 0)));
        let detections = sensor.recognize(&w, &c);
        let report = crate::sensor::evaluate(&w, &detections);
        let selector = crate::grasp::GraspSelector::new(&scene.scene, robot, &wp.workpiece);
        let slot = scene.scene.world_from_slots(&wp.workpiece)[0];
        let q = w.joints();
        let mut feasible = 0;
        let ctx = crate::pipeline::GraspContext {
            scene: &scene.scene,
            robot,
            selector: &selector,
            pick_tray: w.pick_tray(),
        };
        // The cycle's own sense-and-grasp: height map, candidates, IK, ranking, clear approach.
        let grasp = time_ms(&mut || {
            feasible = crate::pipeline::sense_and_grasp(&ctx, &c, &detections, &slot, &q, &[])
                .plan
                .ranked
                .len();
        });
        rows.push(SenseTiming {
            workpiece: wp.workpiece.name.clone(),
            parts: w.part_count(),
            capture_ms: cap,
            capture_one_thread_ms: single.0,
            grasp_ms: grasp,
            top_layer_recall: report.top_layer_recall,
            feasible,
        });
    }
    Ok(SenseBench {
        rows,
        threads: rayon::current_num_threads(),
        targets_ms: (20.0, 5.0),
    })
}

pub use crate::reference::{PlannerCase, fig5_cases};

/// Statistics of one planner on one set of queries.
#[derive(Debug, Clone, Serialize)]
pub struct PlannerRow {
    /// Case or set name.
    pub case: String,
    /// Algorithm.
    pub algorithm: crate::planning::Algorithm,
    /// Queries run.
    pub trials: usize,
    /// Fraction solved.
    pub success: f64,
    /// Mean, p95 and max planning time of the solved queries [ms].
    pub time_ms: (f64, f64, f64),
    /// Mean samples per plan.
    pub samples_mean: f64,
    /// Mean time per clearance (collision) check [us].
    pub us_per_check: f64,
    /// Mean time per sample [ms] (0 where no sample was needed).
    pub ms_per_sample: f64,
    /// Failures by reason.
    pub failures: Vec<String>,
}

fn planner_row(
    case: &str,
    algorithm: crate::planning::Algorithm,
    results: &[Result<crate::planning::Plan, crate::planning::PlanError>],
) -> PlannerRow {
    let ok: Vec<&crate::planning::Plan> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
    let times = crate::stats::Summary::of(&ok.iter().map(|p| p.time_s * 1e3).collect::<Vec<_>>());
    let n = times.count.max(1) as f64;
    // Nothing solved: zeros, as the table has always shown.
    let or0 = |v: f64| if v.is_nan() { 0.0 } else { v };
    let (mean, p95, max) = (or0(times.mean_s), or0(times.p95_s), or0(times.max_s));
    let checks: usize = ok.iter().map(|p| p.stats.clearance_checks).sum();
    let samples: usize = ok.iter().map(|p| p.stats.samples).sum();
    let total_ms: f64 = ok.iter().map(|p| p.time_s * 1e3).sum();
    PlannerRow {
        case: case.into(),
        algorithm,
        trials: results.len(),
        success: ok.len() as f64 / results.len().max(1) as f64,
        time_ms: (mean, p95, max),
        samples_mean: samples as f64 / n,
        us_per_check: if checks > 0 {
            total_ms * 1e3 / checks as f64
        } else {
            0.0
        },
        ms_per_sample: if samples > 0 { total_ms / samples as f64 } else { 0.0 },
        failures: results
            .iter()
            .filter_map(|r| r.as_ref().err().map(|e| e.to_string()))
            .take(3)
            .collect(),
    }
}

/// Runs the three Fig. 5 cases for `trials` seeds each with ours and the baselines (baselines
/// get `baseline_trials`), and the bin-picking query set.
pub fn planner_bench(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    workpieces: &[crate::config::LoadedWorkpiece],
    trials: usize,
    baseline_trials: usize,
    seed: u64,
) -> Result<Vec<PlannerRow>, Box<dyn std::error::Error + Send + Sync>> {
    use crate::planning::{Algorithm, PlanOptions};
    let mut rows = Vec::new();
    for case in fig5_cases(&scene.scene, robot)? {
        for (alg, n) in [
            (Algorithm::Ours, trials),
            (Algorithm::RrtConnect, baseline_trials),
            (Algorithm::Rrt, baseline_trials),
        ] {
            let opts = PlanOptions {
                algorithm: alg,
                ..PlanOptions::default()
            };
            let results: Vec<_> = (0..n)
                .map(|t| {
                    let mut rng = crate::rng::stream(seed.wrapping_add(t as u64), "planner");
                    case.model.plan(&case.start, &case.goal, &opts, &mut rng)
                })
                .collect();
            rows.push(planner_row(&case.name, alg, &results));
        }
    }
    let queries = binpicking_queries(scene, robot, workpieces, 200)?;
    for (alg, n) in [
        (Algorithm::Ours, queries.len()),
        (Algorithm::RrtConnect, baseline_trials.min(queries.len())),
    ] {
        let opts = PlanOptions {
            algorithm: alg,
            ..PlanOptions::default()
        };
        let results: Vec<_> = queries
            .iter()
            .take(n)
            .enumerate()
            .map(|(k, q)| {
                let mut rng = crate::rng::stream(seed.wrapping_add(k as u64), "planner");
                q.model.plan(&q.start, &q.goal, &opts, &mut rng)
            })
            .collect();
        rows.push(planner_row(
            "bin picking: place <-> pre-grasp over piles of A..F",
            alg,
            &results,
        ));
    }
    Ok(rows)
}

/// Bin-picking queries: from the pose above the place slot to the pre-grasp pose of the best
/// grasps on settled piles of each workpiece (environment: the cell and the pile as seen), and
/// back with the part held; up to `n` in all.
pub fn binpicking_queries(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    workpieces: &[crate::config::LoadedWorkpiece],
    n: usize,
) -> Result<Vec<PlannerCase>, Box<dyn std::error::Error + Send + Sync>> {
    use crate::physics::{PartShape, World, pile::PileOptions};
    use crate::pipeline::{GraspContext, pile_map, planning_environment, sense_and_grasp};
    use crate::planning::{CollisionModel, RobotSpheres};
    use crate::sensor::Sensor;
    let mut out = Vec::new();
    let per_pile = 6;
    let mut seed = 1;
    while out.len() < n && seed < 50 {
        for wp in workpieces {
            let shape = PartShape::build(&wp.workpiece, &wp.source)?;
            let mut w = World::new(&scene.scene, robot, shape.clone());
            w.build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, seed))?;
            let sensor = Sensor::new(&scene.scene.sensor, &w, seed).ok_or("degenerate sensor")?;
            let c = crate::sensor::capture(&w, &sensor.camera, seed, 0);
            let det = sensor.recognize(&w, &c);
            let slots = scene.scene.world_from_slots(&wp.workpiece);
            let selector = crate::grasp::GraspSelector::new(&scene.scene, robot, &wp.workpiece);
            let ctx = GraspContext {
                scene: &scene.scene,
                robot,
                selector: &selector,
                pick_tray: w.pick_tray(),
            };
            // The cycle's own grasp ranking and planning scenes; the poses of its motions.
            let choice = sense_and_grasp(&ctx, &c, &det, &slots[0], &w.joints(), &[]);
            let pile = pile_map(&scene.scene, &choice.height_map);
            let empty = RobotSpheres::new(robot, &scene.scene, None);
            for g in choice.plan.ranked.iter().take(per_pile / 2) {
                let tool_from_part = g.world_from_tool.inverse() * det[g.detection].world_from_part;
                let held = RobotSpheres::new(robot, &scene.scene, Some((tool_from_part, shape.half_extents_m)));
                let env = planning_environment(&scene.scene, &pile, g);
                let q_place = JointVector::from(g.q_place);
                let Ok(pre_place) = robot.ik_tool_nearest(&crate::cycle::above_place(g), &q_place) else {
                    continue;
                };
                let q_approach = JointVector::from(g.q_approach);
                out.push(PlannerCase {
                    name: format!("{} seed {seed}: place -> pre-grasp", wp.workpiece.name),
                    model: CollisionModel::new(robot, empty.clone(), env.clone()),
                    start: pre_place.q,
                    goal: q_approach,
                });
                out.push(PlannerCase {
                    name: format!("{} seed {seed}: pre-grasp -> place, holding", wp.workpiece.name),
                    model: CollisionModel::new(robot, held, env),
                    start: q_approach,
                    goal: pre_place.q,
                });
            }
        }
        seed += 1;
    }
    out.truncate(n);
    Ok(out)
}

/// One acceleration benchmark case: J1 turns 180 deg between two containers.
#[derive(Debug, Clone, Serialize)]
pub struct AccelRow {
    /// Case (A->a ... E->e).
    pub case: String,
    /// Motion time with the controller's default parameters [s].
    pub default_s: f64,
    /// After the acceleration search (§4.2) [s].
    pub accelerated_s: f64,
    /// After path correction alternated with the search (§4.3) [s].
    pub corrected_s: f64,
    /// Time-optimal (TOPP-RA) along the final path [s]: the bound, full limits.
    pub optimal_s: f64,
    /// TOPP-RA selected as the accelerator: the executable retiming with margins [s].
    pub toppra_executable_s: f64,
    /// 1 - corrected / default, for the median run.
    pub improvement: f64,
    /// Lowest and highest improvement over the runs (each plans with its own seed).
    pub improvement_range: (f64, f64),
    /// corrected / optimal - 1: how far the shipped accelerator is from the bound.
    pub gap_to_optimal: f64,
    /// Folds kept / tried by the path correction.
    pub folds: (usize, usize),
    /// Max over runs of planning + acceleration + correction wall time [ms].
    pub compute_max_ms: f64,
    /// Median over runs of the same [ms].
    pub compute_median_ms: f64,
    /// Whether the final trajectory's blends stay clear (every 1 ms edge certified).
    pub corridor_clear: bool,
    /// Peak torque / limit per joint of the final motion.
    pub peak_ratio: [f64; 6],
    /// Energy (integral of squared torques) of the default and the final motion [N^2 m^2 s].
    pub energy: (f64, f64),
    /// The reference's Table 4: improvement and max compute time [ms].
    pub reference: (f64, f64),
}

/// The reference system's five acceleration cases (its Fig. 11 / Table 4): the hand leaves one
/// open container and enters another while J1 turns 180 deg, at five reaches and heights, with
/// the default hand holding a 30 g part.
pub fn accel_bench(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    runs: usize,
) -> Result<Vec<AccelRow>, Box<dyn std::error::Error + Send + Sync>> {
    use crate::planning::PlanOptions;
    use crate::trajectory::{Trajectory, correct_path, default_limits, torques};
    let hand = Payload::from_gripper(&scene.scene.gripper);
    let part = Payload::point(
        crate::reference::ACCEL_PART_KG,
        robot.flange_from_tool.translation.vector,
    );
    let dynamics = robot.dynamics(&hand.combined(&part));
    let defaults = default_limits(robot, &hand, 5.0, 20_000);
    let mut rows = Vec::new();
    for case in crate::reference::accel_cases(&scene.scene, robot)? {
        let (name, model, start, goal) = (case.name, &case.model, case.start, case.goal);
        let mut worst_ms = 0.0f64;
        let mut all_ms = Vec::new();
        let mut outcomes = Vec::new();
        for r in 0..runs.max(1) {
            let t0 = Instant::now();
            let mut rng = crate::rng::stream(r as u64, "planner");
            let plan = model
                .plan(&start, &goal, &PlanOptions::default(), &mut rng)
                .map_err(|e| format!("{name}: {e}"))?;
            let via: Vec<JointVector> = plan.waypoints.iter().map(|q| JointVector::from(*q)).collect();
            let (via, accelerated, _stops) = crate::trajectory::accelerate_in_corridor(
                robot,
                &dynamics,
                &via,
                model,
                crate::trajectory::CORRIDOR_CHECK_DT_S,
            );
            let corrected = correct_path(robot, &dynamics, &via, &accelerated, Some(model), 60f64.to_radians());
            worst_ms = worst_ms.max(t0.elapsed().as_secs_f64() * 1e3);
            all_ms.push(t0.elapsed().as_secs_f64() * 1e3);
            let default_s = Trajectory::through(&via, &defaults).duration_s;
            outcomes.push((
                1.0 - corrected.accelerated.trajectory.duration_s / default_s,
                via,
                accelerated,
                corrected,
            ));
        }
        // Each run plans with another seed, so paths differ: report the median run.
        outcomes.sort_by(|a, b| a.0.total_cmp(&b.0));
        let range = (outcomes[0].0, outcomes[outcomes.len() - 1].0);
        let (_, via, accelerated, corrected) = outcomes.swap_remove(outcomes.len() / 2);
        let slow = Trajectory::through(&via, &defaults);
        let slow_torque = torques(&dynamics, robot, &slow.samples(0.001), 0.001);
        let optimal =
            crate::trajectory::optimal_duration(robot, &dynamics, &corrected.via, &corrected.accelerated.limits, 600)
                .unwrap_or(f64::NAN);
        let fast = corrected.accelerated.trajectory.duration_s;
        // Stop-free paths only: a stop would need the pieces retimed one by one.
        let executable = if corrected.via.windows(2).any(|w| w[0] == w[1]) {
            f64::NAN
        } else {
            crate::trajectory::toppra(
                robot,
                &dynamics,
                &corrected.accelerated.trajectory,
                600,
                crate::trajectory::Shares::EXECUTE,
            )
            .map(|r| crate::trajectory::Motion::duration_s(&r))
            .unwrap_or(f64::NAN)
        };
        rows.push(AccelRow {
            case: name.to_string(),
            default_s: slow.duration_s,
            accelerated_s: accelerated.trajectory.duration_s,
            corrected_s: fast,
            optimal_s: optimal,
            toppra_executable_s: executable,
            improvement: 1.0 - fast / slow.duration_s,
            improvement_range: range,
            gap_to_optimal: fast / optimal - 1.0,
            folds: (corrected.folds, corrected.tried),
            compute_max_ms: worst_ms,
            compute_median_ms: median(all_ms).0,
            corridor_clear: crate::trajectory::check_corridor(
                model,
                &corrected.accelerated.trajectory,
                crate::trajectory::CORRIDOR_CHECK_DT_S,
            )
            .is_ok(),
            peak_ratio: corrected.accelerated.torques.peak_ratio,
            energy: (slow_torque.energy, corrected.accelerated.torques.energy),
            reference: (case.table4_improvement_pct, case.table4_compute_ms),
        });
    }
    Ok(rows)
}
