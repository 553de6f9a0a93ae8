//! The study runner: every run of a study or of its shard, in parallel on a pool of worker
//! threads, each optionally recorded, with a progress callback.
//!
//! Job: run [`crate::cycle::run`] for each job on `threads` workers (rayon; a free worker takes
//! the next job in order) with its variant's resolved cell, its workpiece and the arm model it
//! shares with the other variants (nothing is parsed or built per run), and keep each run's
//! [`Tally`] in job order: results do not depend on the number of threads or their timing in
//! deterministic mode, and a variant's run gives what a batch gives on the variant's resolved
//! files. Each run's recordings are written beside the study's results when asked; each
//! finished run is reported to the caller (a progress bar).
//!
//! Units: s of wall time per run. Frames: none.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use rayon::prelude::*;

use super::{Job, StudyError, StudyRun, StudySpec};
use crate::chart::TimeChart;
use crate::config::{LoadedScene, LoadedWorkpiece};
use crate::cycle::{EventLog, Observer, Observers, RunOptions, Tally};
use crate::recording::{Formats, Recorder, RecordingFiles, RunInfo};
use crate::robot::RobotModel;
use crate::sensor::Camera;

/// One variant, resolved: its values, its cell, its workpieces, which arm model it runs.
#[derive(Debug, Clone)]
pub struct Variant {
    /// Its values, in `--set` order (none for a batch).
    pub values: Vec<toml::Value>,
    /// The cell with the values applied, validated.
    pub scene: LoadedScene,
    /// Index into [`Resolved::robots`].
    pub robot: usize,
    /// The workpieces with the values applied, validated, in `--workpieces` order.
    pub workpieces: Vec<LoadedWorkpiece>,
}

/// Every variant of a study, loaded and checked, and the arm models they share.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// The variants, in study order.
    pub variants: Vec<Variant>,
    /// Distinct arm models (one unless a variant changes the robot or the gripper).
    pub robots: Vec<RobotModel>,
    /// The cell file's label.
    pub scene_label: String,
}

impl Resolved {
    /// A batch's one variant: the cell, its arm and the workpieces as loaded.
    pub fn single(scene: LoadedScene, robot: RobotModel, workpieces: Vec<LoadedWorkpiece>) -> Self {
        Resolved {
            scene_label: scene.label.clone(),
            variants: vec![Variant {
                values: Vec::new(),
                scene,
                robot: 0,
                workpieces,
            }],
            robots: vec![robot],
        }
    }
}

/// Where and how to record each run: `<dir>/run-<workpiece>-seed<seed>.rrd` and `.mcap`, its
/// time charts `.timechart.svg` and `.timechart-steady.svg`, and its per-pick table and event
/// log `.picks.csv` and `.events.json`, as `binpick run` writes them ([`run_stem`]).
#[derive(Clone, Copy)]
pub struct RecordTo<'a> {
    /// The folder.
    pub dir: &'a Path,
    /// Which files.
    pub formats: Formats,
}

/// How a study's runs go (what they are is the spec's).
#[derive(Clone, Copy)]
pub struct RunSettings<'a> {
    /// Worker threads.
    pub threads: usize,
    /// Record each run, if asked.
    pub record: Option<RecordTo<'a>>,
    /// Set (by a Ctrl-C handler) to end each run after its pick under way.
    pub stop: Option<&'static AtomicBool>,
}

/// Runs `jobs` of `spec` on the worker threads and returns their tallies in job order, each
/// with its wall time ([`super::StudyFile::new`] leaves it out of a deterministic study's
/// file); `progress` is called (from any worker) after each run. A run that fails, or
/// whose recording fails, fails the study (the first such in job order is reported).
///
/// Each worker takes the next job not yet started, in job order, as it becomes free (a queue):
/// rayon's own split of the job list would hand each worker a contiguous half up front (A-C and
/// D-F of a six-part batch), and a worker that finished its half early found nothing left to
/// take while the other ran its last long run.
pub fn run_study(
    resolved: &Resolved,
    spec: &StudySpec,
    jobs: &[Job],
    settings: &RunSettings<'_>,
    progress: &(dyn Fn(&StudyRun) + Sync),
) -> Result<Vec<StudyRun>, StudyError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(settings.threads.max(1))
        .build()
        .map_err(|e| StudyError::Run(format!("starting the worker threads: {e}")))?;
    let results = pool.install(|| {
        in_queue(jobs, settings.threads, |job| {
            let run = run_one(resolved, spec, job, settings)?;
            progress(&run);
            Ok(run)
        })
    });
    results.into_iter().map(|r| r.map_err(StudyError::Run)).collect()
}

/// `f` of every item on up to `workers` workers of the current rayon pool, each taking the next
/// item not yet started, in order, as it becomes free; the results in item order.
fn in_queue<T: Sync, R: Send>(items: &[T], workers: usize, f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::{Mutex, PoisonError};
    let next = AtomicUsize::new(0);
    let done: Vec<Mutex<Option<R>>> = items.iter().map(|_| Mutex::new(None)).collect();
    (0..workers.clamp(1, items.len().max(1))).into_par_iter().for_each(|_| {
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(item) = items.get(i) else { break };
            let r = f(item);
            *done[i].lock().unwrap_or_else(PoisonError::into_inner) = Some(r);
        }
    });
    done.into_iter()
        .map(|slot| {
            slot.into_inner()
                .unwrap_or_else(PoisonError::into_inner)
                .expect("every item is taken by a worker")
        })
        .collect()
}

/// The name a run's files start with: `run-<workpiece>-seed<seed>`, `run-v<variant>-...` when
/// the study has several variants.
pub fn run_stem(several_variants: bool, job: &Job) -> String {
    let (v, w, seed) = (job.variant + 1, &job.workpiece, job.seed);
    if several_variants {
        format!("run-v{v}-{w}-seed{seed}")
    } else {
        format!("run-{w}-seed{seed}")
    }
}

/// One run of the study, recorded if asked (its recordings and its time charts).
fn run_one(resolved: &Resolved, spec: &StudySpec, job: &Job, settings: &RunSettings<'_>) -> Result<StudyRun, String> {
    let Job {
        variant: v,
        workpiece: w,
        seed,
    } = job;
    let several = resolved.variants.len() > 1;
    let what = if several {
        format!("variant {} workpiece {w} seed {seed}", v + 1)
    } else {
        format!("workpiece {w} seed {seed}")
    };
    let variant = resolved
        .variants
        .get(*v)
        .ok_or_else(|| format!("variant {} is not resolved", v + 1))?;
    let wp = variant
        .workpieces
        .iter()
        .find(|x| &x.workpiece.name == w)
        .ok_or_else(|| format!("workpiece {w} is not loaded"))?;
    let robot = &resolved.robots[variant.robot];
    // The cell with the workpiece's own cup, if it brings one: the run and its recordings read it.
    let scene = variant.scene.for_workpiece(wp);
    let record = settings.record;
    let stem = run_stem(several, job);
    let opts = RunOptions {
        picks: spec.picks,
        seed: *seed,
        deterministic: spec.deterministic,
        stop: settings.stop,
        // The time chart marks the releases; the table needs only the tally.
        keep_records: record.is_some(),
    };
    let mut recorder = match record {
        Some(r) if r.formats.any() => {
            let camera = Camera::from_config(&scene.scene.sensor).ok_or("the sensor's pose is degenerate")?;
            let info = RunInfo {
                scene: variant.scene.label.clone(),
                workpiece: w.clone(),
                seed: *seed,
                deterministic: spec.deterministic,
                picks: spec.picks,
                robot_description: variant.scene.urdf_text.clone(),
            };
            let files = RecordingFiles::create(r.dir, &stem, r.formats, &scene.scene, &info)
                .map_err(|(path, e)| format!("{}: {e}", path.display()))?;
            let pick_tray = crate::geometry::TrayVolume::new(&scene.scene.pick_tray);
            Some(Recorder::streaming(
                robot,
                &camera,
                &pick_tray,
                wp.workpiece.size_m,
                files,
            ))
        }
        _ => None,
    };
    // A recorded run also keeps its time chart and its event log.
    let mut chart = record.map(|_| TimeChart::default());
    let mut log = record.map(|_| EventLog::default());
    let t = std::time::Instant::now();
    let mut watchers: Vec<&mut dyn Observer> = Vec::new();
    if let Some(r) = recorder.as_mut() {
        watchers.push(r);
    }
    if let Some(c) = chart.as_mut() {
        watchers.push(c);
    }
    if let Some(l) = log.as_mut() {
        watchers.push(l);
    }
    let result =
        crate::cycle::run(&scene, robot, wp, &opts, &mut Observers(watchers)).map_err(|e| format!("{what}: {e}"))?;
    let tally = Tally {
        wall_s: Some(t.elapsed().as_secs_f64()),
        ..result.tally.clone()
    };
    if let (Some(log), Some(to)) = (log, record) {
        let events = serde_json::to_string_pretty(&log.into_sorted()).map_err(|e| format!("{what}: events: {e}"))?;
        for (suffix, text) in [
            ("picks.csv", crate::report::picks_csv(&result.records)),
            ("events.json", events + "\n"),
        ] {
            let path = to.dir.join(format!("{stem}.{suffix}"));
            std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
        }
    }
    if let (Some(chart), Some(to)) = (chart, record) {
        let title = format!("binpick {what}");
        let releases: Vec<f64> = result.records.iter().filter_map(|r| r.release_s).collect();
        let (whole, steady) = chart.svgs(&title, result.tally.sim_time_s, &releases);
        let steady = steady.map(|s| ("timechart-steady.svg", s));
        for (suffix, svg) in std::iter::once(("timechart.svg", whole)).chain(steady) {
            let path = to.dir.join(format!("{stem}.{suffix}"));
            std::fs::write(&path, svg).map_err(|e| format!("{}: {e}", path.display()))?;
        }
    }
    if let Some(rec) = recorder {
        rec.finish_files()
            .map_err(|(path, e)| format!("{}: {e}", path.display()))?;
    }
    Ok(StudyRun { variant: *v, tally })
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicUsize, Ordering};

    use rayon::prelude::*;

    /// Six items on two workers, the first holding its worker until every other item has run:
    /// the other worker runs items 1 to 5, in order. Returns the order the other worker ran
    /// them in, with `run` the way the items are handed out.
    fn others_order(run: impl Fn(&[usize], &(dyn Fn(&usize) + Sync)) + Sync) -> Vec<usize> {
        let items: Vec<usize> = (0..6).collect();
        let finished = AtomicUsize::new(0);
        let order = Mutex::new(Vec::new());
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        pool.install(|| {
            run(&items, &|&i| {
                if i == 0 {
                    let t0 = std::time::Instant::now();
                    while finished.load(Ordering::SeqCst) < 5 && t0.elapsed().as_secs() < 20 {
                        std::thread::yield_now();
                    }
                } else {
                    order.lock().unwrap().push(i);
                    finished.fetch_add(1, Ordering::SeqCst);
                }
            })
        });
        order.into_inner().unwrap()
    }

    #[test]
    fn a_free_worker_takes_the_next_item_in_order() {
        let queued = others_order(|items, f| {
            let out = super::in_queue(items, 2, |i| {
                f(i);
                *i * 10
            });
            assert_eq!(out, [0, 10, 20, 30, 40, 50], "results in item order");
        });
        assert_eq!(queued, [1, 2, 3, 4, 5]);
        // Negative control: rayon's own split hands the second worker the back half first.
        let split = others_order(|items, f| items.par_iter().for_each(f));
        assert_ne!(split, [1, 2, 3, 4, 5]);
    }
}
