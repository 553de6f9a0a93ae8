//! The batch runner: every (workpiece, seed) run of a batch or of its shard, in parallel on a
//! pool of worker threads, each optionally recorded, with a progress callback.
//!
//! Job: run [`crate::cycle::run`] for each job on `threads` workers (rayon), keep each run's
//! [`RunEntry`] in job order (results do not depend on the number of threads or their timing in
//! deterministic mode), write each run's recordings beside the batch's results when asked, and
//! report each finished run to the caller (a progress bar, a log line).
//!
//! Units: s of wall time per run. Frames: none.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use rayon::prelude::*;

use super::{BatchError, RunEntry};
use crate::config::{LoadedScene, LoadedWorkpiece};
use crate::cycle::{Observer, RunOptions};
use crate::recording::{Formats, Recorder, RunInfo};
use crate::robot::RobotModel;
use crate::sensor::Camera;

/// What every run of a batch shares: the loaded and checked cell, arm and workpieces.
#[derive(Clone, Copy)]
pub struct BatchInputs<'a> {
    /// The cell.
    pub scene: &'a LoadedScene,
    /// The arm.
    pub robot: &'a RobotModel,
    /// The workpieces, by name.
    pub workpieces: &'a [LoadedWorkpiece],
}

/// Where and how to record each run: `<dir>/run-<workpiece>-seed<seed>.rrd` and `.mcap`.
#[derive(Clone, Copy)]
pub struct RecordTo<'a> {
    /// The folder.
    pub dir: &'a Path,
    /// Which files.
    pub formats: Formats,
}

/// How a batch's runs go.
#[derive(Clone, Copy)]
pub struct BatchRuns<'a> {
    /// The runs: (workpiece name, seed).
    pub jobs: &'a [(String, u64)],
    /// Picks per run.
    pub picks: usize,
    /// Fixed compute budgets (byte-identical results).
    pub deterministic: bool,
    /// Worker threads.
    pub threads: usize,
    /// Record each run, if asked.
    pub record: Option<RecordTo<'a>>,
    /// Set (by a Ctrl-C handler) to end each run after its pick under way.
    pub stop: Option<&'static AtomicBool>,
}

/// Runs the batch's runs on its worker threads and returns their entries in job order;
/// `progress` is called (from any worker) after each run. A run that fails, or whose recording
/// fails, fails the batch (the first such in job order is reported).
pub fn run_batch(
    inputs: BatchInputs<'_>,
    runs: &BatchRuns<'_>,
    progress: &(dyn Fn(&RunEntry) + Sync),
) -> Result<Vec<RunEntry>, BatchError> {
    let BatchRuns {
        jobs,
        picks,
        deterministic,
        threads,
        record,
        stop,
    } = *runs;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .map_err(|e| BatchError::Run(format!("starting the worker threads: {e}")))?;
    let camera = Camera::from_config(&inputs.scene.scene.sensor)
        .ok_or_else(|| BatchError::Run("the sensor's pose is degenerate".into()))?;
    let results: Vec<Result<RunEntry, String>> = pool.install(|| {
        jobs.par_iter()
            .map(|(w, seed)| {
                let wp = inputs
                    .workpieces
                    .iter()
                    .find(|x| &x.workpiece.name == w)
                    .ok_or_else(|| format!("workpiece {w} is not loaded"))?;
                let opts = RunOptions {
                    picks,
                    seed: *seed,
                    deterministic,
                    stop,
                    // A recording plays the records; the table needs only the tally.
                    keep_records: record.is_some(),
                };
                let formats = record.map_or(
                    Formats {
                        rrd: false,
                        mcap: false,
                    },
                    |r| r.formats,
                );
                let mut recorder = formats
                    .any()
                    .then(|| Recorder::new(inputs.robot, camera.clone(), wp.workpiece.size_m));
                let t = std::time::Instant::now();
                let obs: &mut dyn Observer = match recorder.as_mut() {
                    Some(r) => r,
                    None => &mut (),
                };
                let result = crate::cycle::run(inputs.scene, inputs.robot, wp, &opts, obs)
                    .map_err(|e| format!("workpiece {w} seed {seed}: {e}"))?;
                let entry = RunEntry::from_run(&result, Some(t.elapsed().as_secs_f64()));
                if let (Some(rec), Some(to)) = (recorder, record) {
                    let info = RunInfo {
                        scene: inputs.scene.label.clone(),
                        workpiece: w.clone(),
                        seed: *seed,
                        deterministic,
                        picks,
                    };
                    crate::recording::write_recordings(
                        to.dir,
                        &format!("run-{w}-seed{seed}"),
                        to.formats,
                        &rec.finish(&result),
                        inputs.robot,
                        &inputs.scene.scene,
                        &info,
                    )
                    .map_err(|(path, e)| format!("{}: {e}", path.display()))?;
                }
                progress(&entry);
                Ok(entry)
            })
            .collect()
    });
    results.into_iter().map(|r| r.map_err(BatchError::Run)).collect()
}
