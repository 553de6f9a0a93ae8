//! Benchmark of the robot model: IK, FK, inverse and forward dynamics per call on one core,
//! beside baselines (a numerical IK, ...).
//!
//! Units: nanoseconds per call; medians, minima and maxima over runs of many calls each.

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
    /// Median over runs of the mean time per call (ns).
    pub median_ns: f64,
    /// Fastest run [ns per call].
    pub min_ns: f64,
    /// Slowest run [ns per call].
    pub max_ns: f64,
    /// Calls per run.
    pub calls_per_run: usize,
    /// Runs.
    pub runs: usize,
    /// Target per call, if the issue sets one (ns).
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
