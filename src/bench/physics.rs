//! Benchmark of the physics: pile build-and-settle wall time per workpiece and the step time of
//! resting parts with the arm moving, beside rapier's default solver settings.
//!
//! Units: s of wall time (ms for steps); medians over runs.

use std::time::Instant;

use serde::Serialize;

use crate::robot::RobotModel;
use crate::stats::median_min_max as median_of;

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
    median_of(&v)
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
