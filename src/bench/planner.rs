//! Benchmark of the planner: the reference's three planning cases (its Fig. 5) and a bin-picking
//! query set built the way the cycle plans, ours beside plain RRT and RRT-Connect with discrete
//! edge checks.
//!
//! Units: ms of wall time per plan; samples and collision checks per plan.

use serde::Serialize;

use crate::reference::{PlannerCase, fig5_cases};
use crate::robot::{JointVector, RobotModel};

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
    /// Mean, p95 and max planning time of the solved queries (ms).
    pub time_ms: (f64, f64, f64),
    /// Mean samples per plan.
    pub samples_mean: f64,
    /// Mean time per clearance (collision) check (us).
    pub us_per_check: f64,
    /// Mean time per sample (ms) (0 where no sample was needed).
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
/// get `baseline_trials`), and the bin-picking query set: 200 cases of one trial each, every
/// planner on every query (the same queries, so the means compare; the baselines on none when
/// `baseline_trials` is 0).
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
    for alg in [Algorithm::Ours, Algorithm::RrtConnect, Algorithm::Rrt] {
        let n = if alg == Algorithm::Ours || baseline_trials > 0 {
            queries.len()
        } else {
            0
        };
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
    use crate::pipeline::{GraspContext, SensedPile, planning_environment, sense_and_grasp};
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
            let sensor = Sensor::new(&scene.scene.sensor, &w, seed, &wp.workpiece).ok_or("degenerate sensor")?;
            let c = crate::sensor::capture(&w, &sensor.camera, seed, 0);
            let det = sensor.recognize_oracle(&crate::sensor::TruthAtTrigger::take(&w, &sensor, &c));
            // The arm where the pile was captured, its cup empty (the self-filter's input).
            let at_rest = crate::sensor::ArmAtTrigger {
                q: w.joints(),
                tool_from_held_part: None,
            };
            let slots = scene.scene.world_from_slots(&wp.workpiece);
            let selector = crate::grasp::GraspSelector::for_workpiece(&scene.scene, robot, wp);
            let ctx = GraspContext {
                scene: &scene.scene,
                robot,
                selector: &selector,
                pick_tray: w.pick_tray(),
                part_half_extents_m: shape.half_extents_m,
            };
            // The cycle's own grasp ranking and planning scenes; the poses of its motions.
            let sensed = SensedPile::new(&ctx, &c, &at_rest);
            let choice = sense_and_grasp(&ctx, &sensed, &det, &slots[0], &w.joints(), &[]);
            let pile = &sensed.pile;
            let empty = RobotSpheres::new(robot, &scene.scene, None);
            for g in choice.plan.ranked.iter().take(per_pile / 2) {
                let tool_from_part = g.world_from_tool.inverse() * det[g.detection].world_from_part;
                let held = RobotSpheres::new(robot, &scene.scene, Some((tool_from_part, shape.half_extents_m)));
                let env = planning_environment(&scene.scene, pile, g);
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
