//! Benchmark of sensing: depth capture on all cores and on one thread (the peer); recognition
//! from the point cloud (ours) beside the oracle (perfect recognition with injected noise), both
//! evaluated against the ground truth at the trigger over seeds of the default pile; and the
//! cycle's own sense-and-grasp on the cloud's detections, per workpiece.
//!
//! Units: ms of wall time (medians over runs after a warm-up), mm and deg for pose errors.

use std::time::Instant;

use serde::Serialize;

use crate::robot::RobotModel;
use crate::sensor::RecognitionSummary;
use crate::stats::median_min_max;

/// Recognition of one kind over the bench's captures.
#[derive(Debug, Clone, Serialize)]
pub struct RecognitionBench {
    /// Recall, precision and pose errors against the truth at the trigger.
    pub quality: RecognitionSummary,
    /// Wall time per capture: median and max over the captures (each the median of the runs) (ms).
    pub compute_ms: (f64, f64),
}

/// One workpiece's sensing timings.
#[derive(Debug, Clone, Serialize)]
pub struct SenseTiming {
    /// Workpiece name.
    pub workpiece: String,
    /// Parts in the pile.
    pub parts: usize,
    /// Capture wall time on all cores, median (ms) and min..max.
    pub capture_ms: (f64, f64, f64),
    /// The same capture on one thread, median (ms) (the peer).
    pub capture_one_thread_ms: f64,
    /// Grasp selection (height map, candidates, IK, ranking) wall time, median (ms) and min..max.
    pub grasp_ms: (f64, f64, f64),
    /// Recognition from the point cloud (the cell's default), over the seeds.
    pub cloud: RecognitionBench,
    /// The oracle (the what-if of perfect recognition), over the same captures.
    pub oracle: RecognitionBench,
    /// Feasible candidates on seed 1's cloud detections.
    pub feasible: usize,
}

/// The sensing benchmark: capture and grasp selection per workpiece at its default pile.
#[derive(Debug, Clone, Serialize)]
pub struct SenseBench {
    /// Per workpiece.
    pub rows: Vec<SenseTiming>,
    /// Threads the parallel capture used.
    pub threads: usize,
    /// Seeds of the default pile per workpiece (captures per recognition row).
    pub seeds: u64,
    /// Targets (ms): capture, grasp selection, recognition.
    pub targets_ms: (f64, f64, f64),
}

/// Runs the sensing benchmark: `runs` timed repetitions after one warm-up; recognition over the
/// default pile of seeds `1..=seeds`.
pub fn sense_bench(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    workpieces: &[crate::config::LoadedWorkpiece],
    runs: usize,
    seeds: u64,
) -> Result<SenseBench, Box<dyn std::error::Error + Send + Sync>> {
    use crate::physics::{PartShape, World, pile::PileOptions};
    use crate::sensor::{RecognitionTotals, Sensor, TruthAtTrigger, capture, evaluate};
    let runs = runs.max(1);
    let mut rows = Vec::new();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
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
    for wp in workpieces {
        // The cell as it runs this workpiece (its own cup, if it brings one).
        let scene = &scene.for_workpiece(wp);
        let shape = PartShape::build(&wp.workpiece, &wp.source)?;
        let (mut cloud, mut oracle) = (RecognitionTotals::default(), RecognitionTotals::default());
        let (mut cloud_ms, mut oracle_ms) = (Vec::new(), Vec::new());
        let mut first = None;
        for seed in 1..=seeds.max(1) {
            let mut w = World::new(&scene.scene, robot, shape.clone());
            w.build_pile(&PileOptions::cells_first_pile(wp.workpiece.pile_count as usize, seed))?;
            let sensor = Sensor::new(&scene.scene.sensor, &w, seed, &wp.workpiece).ok_or("degenerate sensor pose")?;
            let c = capture(&w, &sensor.camera, seed, 0);
            // Ground truth at the trigger: evaluation only.
            let truth = TruthAtTrigger::take(&w, &sensor, &c);
            let mut found = Vec::new();
            cloud_ms.push(time_ms(&mut || found = sensor.recognize_cloud(&c)).0);
            cloud.add(&evaluate(&truth, &found, &sensor.symmetry));
            let mut told = Vec::new();
            oracle_ms.push(time_ms(&mut || told = sensor.recognize_oracle(&truth)).0);
            oracle.add(&evaluate(&truth, &told, &sensor.symmetry));
            if first.is_none() {
                first = Some((w, sensor, c, found));
            }
        }
        let Some((w, sensor, mut c, detections)) = first else {
            continue;
        };
        let cap = time_ms(&mut || c = capture(&w, &sensor.camera, 1, 0));
        let single = one.install(|| time_ms(&mut || c = capture(&w, &sensor.camera, 1, 0)));
        // The cycle's selector: a mesh part's faces come from its part model.
        let selector = crate::grasp::GraspSelector::for_workpiece(&scene.scene, robot, wp);
        let slot = scene.scene.world_from_slots(&wp.workpiece)[0];
        let q = w.joints();
        // The arm where the pile was captured, its cup empty (the self-filter's input).
        let at_home = crate::sensor::ArmAtTrigger {
            q,
            tool_from_held_part: None,
        };
        let mut feasible = 0;
        let ctx = crate::pipeline::GraspContext {
            scene: &scene.scene,
            robot,
            selector: &selector,
            pick_tray: w.pick_tray(),
            part_half_extents_m: shape.half_extents_m,
        };
        // The cycle's own sense-and-grasp: height map, candidates, IK, ranking, clear approach.
        let grasp = time_ms(&mut || {
            let sensed = crate::pipeline::SensedPile::new(&ctx, &c, &at_home);
            feasible = crate::pipeline::sense_and_grasp(&ctx, &sensed, &detections, &slot, &q, &[])
                .plan
                .ranked
                .len();
        });
        let per_capture = |ms: &[f64]| {
            let (med, _, max) = median_min_max(ms);
            (med, max)
        };
        rows.push(SenseTiming {
            workpiece: wp.workpiece.name.clone(),
            parts: w.part_count(),
            capture_ms: cap,
            capture_one_thread_ms: single.0,
            grasp_ms: grasp,
            cloud: RecognitionBench {
                quality: cloud.summary(),
                compute_ms: per_capture(&cloud_ms),
            },
            oracle: RecognitionBench {
                quality: oracle.summary(),
                compute_ms: per_capture(&oracle_ms),
            },
            feasible,
        });
    }
    Ok(SenseBench {
        rows,
        threads: rayon::current_num_threads(),
        seeds: seeds.max(1),
        targets_ms: (20.0, 5.0, 30.0),
    })
}
