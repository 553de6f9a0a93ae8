//! The sweep runner: every (variant, workpiece, seed) run of a sweep or of its shard, in parallel
//! on a pool of worker threads, with a progress callback.
//!
//! Job: run [`crate::cycle::run`] for each job on `threads` workers (rayon) with the variant's
//! resolved cell, its workpiece and the arm model it shares with the other variants (nothing is
//! parsed or built per run that a batch's run does not build), and keep each run's entry in job
//! order: results do not depend on the number of threads in deterministic mode, and a variant's
//! run gives what `binpick batch` gives on the variant's resolved files.
//!
//! Units: s of wall time per run. Frames: none.

use std::sync::atomic::AtomicBool;

use rayon::prelude::*;

use super::{Resolved, SweepError, SweepRun};
use crate::batch::RunEntry;
use crate::cycle::RunOptions;

/// How a sweep's runs go.
#[derive(Clone, Copy)]
pub struct SweepRuns<'a> {
    /// The runs: (variant index, workpiece name, seed).
    pub jobs: &'a [(usize, String, u64)],
    /// Picks per run.
    pub picks: usize,
    /// Fixed compute budgets (byte-identical results).
    pub deterministic: bool,
    /// Worker threads.
    pub threads: usize,
    /// Set (by a Ctrl-C handler) to end each run after its pick under way.
    pub stop: Option<&'static AtomicBool>,
}

/// Runs the sweep's runs and returns them in job order; `progress` is called (from any worker)
/// after each run. A run that fails fails the sweep (the first such in job order is reported).
pub fn run_sweep(
    resolved: &Resolved,
    runs: &SweepRuns<'_>,
    progress: &(dyn Fn(&SweepRun) + Sync),
) -> Result<Vec<SweepRun>, SweepError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(runs.threads.max(1))
        .build()
        .map_err(|e| SweepError::Run(format!("starting the worker threads: {e}")))?;
    let results: Vec<Result<SweepRun, String>> = pool.install(|| {
        runs.jobs
            .par_iter()
            .map(|(v, w, seed)| {
                let variant = resolved
                    .variants
                    .get(*v)
                    .ok_or_else(|| format!("variant {} is not resolved", v + 1))?;
                let wp = variant
                    .workpieces
                    .iter()
                    .find(|x| &x.workpiece.name == w)
                    .ok_or_else(|| format!("workpiece {w} is not loaded"))?;
                let opts = RunOptions {
                    picks: runs.picks,
                    seed: *seed,
                    deterministic: runs.deterministic,
                    stop: runs.stop,
                    keep_records: false,
                };
                let t = std::time::Instant::now();
                let result = crate::cycle::run(&variant.scene, &resolved.robots[variant.robot], wp, &opts, &mut ())
                    .map_err(|e| format!("variant {} workpiece {w} seed {seed}: {e}", v + 1))?;
                let run = SweepRun {
                    variant: *v,
                    run: RunEntry::from_run(&result, Some(t.elapsed().as_secs_f64())),
                };
                progress(&run);
                Ok(run)
            })
            .collect()
    });
    results.into_iter().map(|r| r.map_err(SweepError::Run)).collect()
}
