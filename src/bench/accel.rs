//! Benchmark of the motion accelerator: the reference's five acceleration cases (its Fig. 11 /
//! Table 4): default parameters, the acceleration search (§4.2), path correction (§4.3) and the
//! time-optimal bound, with the specification accelerations as caps and without them (torque and
//! speed alone).
//!
//! Units: s of motion time, ms of compute, torque / limit.

use std::time::Instant;

use serde::Serialize;

use crate::robot::{AccelCap, JointVector, Payload, RobotModel};
use crate::stats::median_min_max;

/// One acceleration benchmark case: J1 turns 180 deg between two containers.
#[derive(Debug, Clone, Serialize)]
pub struct AccelRow {
    /// Case (A->a ... E->e).
    pub case: String,
    /// Motion time with the controller's default parameters (s).
    pub default_s: f64,
    /// After the acceleration search (§4.2) (s).
    pub accelerated_s: f64,
    /// After path correction alternated with the search (§4.3) (s).
    pub corrected_s: f64,
    /// Time-optimal (TOPP-RA) along the final path under torque and speed limits alone (s): the
    /// bound, full limits, no acceleration cap.
    pub optimal_s: f64,
    /// The same with the specification accelerations as caps too (s): the bound the accelerator
    /// was measured against while it kept to them (`robot.drives.accel_cap = "spec"`).
    pub optimal_capped_s: f64,
    /// TOPP-RA selected as the accelerator: the executable retiming with margins (s).
    pub toppra_executable_s: f64,
    /// 1 - corrected / default, for the median run.
    pub improvement: f64,
    /// Lowest and highest improvement over the runs (each plans with its own seed).
    pub improvement_range: (f64, f64),
    /// corrected / optimal - 1: how far the shipped accelerator is from the bound without caps.
    pub gap_to_optimal: f64,
    /// corrected / optimal_capped - 1: how far it is from the bound with the caps (negative: it
    /// is faster than any motion that keeps to them).
    pub gap_to_capped: f64,
    /// Whether the accelerator kept to the specification accelerations (the robot's
    /// `accel_cap`), as `spec` or `none`.
    pub accel_cap: String,
    /// Folds kept / tried by the path correction.
    pub folds: (usize, usize),
    /// Max over runs of planning + acceleration + correction wall time (ms).
    pub compute_max_ms: f64,
    /// Median over runs of the same (ms).
    pub compute_median_ms: f64,
    /// Whether the final trajectory's blends stay clear (every 1 ms edge certified).
    pub corridor_clear: bool,
    /// Peak torque / limit per joint of the final motion.
    pub peak_ratio: [f64; 6],
    /// Energy (integral of squared torques) of the default and the final motion [N^2 m^2 s].
    pub energy: (f64, f64),
    /// The reference's Table 4: improvement and max compute time (ms).
    pub reference: (f64, f64),
}

/// The reference system's five acceleration cases (its Fig. 11 / Table 4): the hand leaves one
/// open container and enters another while J1 turns 180 deg, at five reaches and heights, with
/// the default hand holding a 30 g part. The accelerator keeps to `robot`'s acceleration cap
/// ([`RobotModel::accel_cap_rad_s2`]); both bounds are reported whatever it is.
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
        let bound = |cap: AccelCap| {
            crate::trajectory::optimal_duration(
                &robot.with_accel_cap(cap),
                &dynamics,
                &corrected.via,
                &corrected.accelerated.limits,
                600,
            )
            .unwrap_or(f64::NAN)
        };
        let (optimal, optimal_capped) = (bound(AccelCap::TorqueOnly), bound(AccelCap::Spec));
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
            optimal_capped_s: optimal_capped,
            toppra_executable_s: executable,
            improvement: 1.0 - fast / slow.duration_s,
            improvement_range: range,
            gap_to_optimal: fast / optimal - 1.0,
            gap_to_capped: fast / optimal_capped - 1.0,
            accel_cap: robot.accel_cap.name().to_string(),
            folds: (corrected.folds, corrected.tried),
            compute_max_ms: worst_ms,
            compute_median_ms: median_min_max(&all_ms).0,
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
