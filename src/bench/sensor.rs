//! Benchmark of sensing: depth capture on all cores and on one thread (the peer), and the cycle's
//! own sense-and-grasp, per workpiece at its default pile.
//!
//! Units: ms of wall time; medians over runs after a warm-up.

use std::time::Instant;

use serde::Serialize;

use crate::robot::RobotModel;
use crate::stats::median_min_max;

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
            median_min_max(
                &(0..runs)
                    .map(|_| {
                        let t0 = Instant::now();
                        f();
                        t0.elapsed().as_secs_f64() * 1e3
                    })
                    .collect::<Vec<f64>>(),
            )
        };
        let mut c = capture(&w, &sensor.camera, 1, 0);
        let cap = time_ms(&mut || c = capture(&w, &sensor.camera, 1, 0));
        let single = one.install(|| time_ms(&mut || c = capture(&w, &sensor.camera, 1, 0)));
        let truth = crate::sensor::TruthAtTrigger::take(&w, &sensor, &c);
        let detections = sensor.recognize_oracle(&truth);
        let report = crate::sensor::evaluate(&truth, &detections);
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
