//! What `binpick batch` and `binpick sweep` share, the two front ends of one study: the
//! arguments that say which runs to make and how, the run with a progress bar, the writing of
//! the results folder and its table on stdout, and `binpick merge` of a study's shards (a
//! batch's or a sweep's).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;

use super::{InputError, Interrupted, ModeArgs, RunsFailed, check_picks, stop_on_ctrl_c};
use binpick::cycle::EndReason;
use binpick::report::RunDir;
use binpick::results::expect::{Expectations, junit_xml};
use binpick::study::{Outputs, RecordTo, Resolved, RunSettings, StudyError, StudyFile, StudySpec};

/// Which runs a study makes, and how: the arguments batch and sweep share.
#[derive(Args)]
pub struct StudyArgs {
    /// Workpieces, comma-separated: A ... F (embedded) or paths to workpiece files.
    #[arg(long, default_value = "A,B,C,D,E,F")]
    pub workpieces: String,
    /// Picks per run (the first of each run follows the initial sensing and has no takt).
    #[arg(long, default_value_t = 21)]
    pub picks: usize,
    /// Sustained operation: 180 picks per run (three piles of the largest part A..F), so the
    /// takt and parts per hour span several pile cycles; the first-20 column keeps the
    /// reference's 20-pick figure beside it.
    #[arg(long, conflicts_with = "picks")]
    pub sustained: bool,
    /// Seeds: 1-3, or 1,2,5.
    #[arg(long, default_value = "1")]
    pub seeds: String,
    /// Runs in parallel (default: the machine's cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Run only the K-th of N disjoint slices of the runs (1-based), e.g. 2/4.
    #[arg(long)]
    pub shard: Option<String>,
    #[command(flatten)]
    pub mode: ModeArgs,
}

/// [`StudyArgs`] checked: seeds, shard (k of n), threads and workpiece names.
pub struct Study {
    /// Picks per run (`--picks`, or the sustained count).
    pub picks: usize,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// This shard, k of n (1 of 1: all).
    pub shard: (usize, usize),
    /// Runs in parallel.
    pub threads: usize,
    /// Workpiece names or paths, as given.
    pub workpieces: Vec<String>,
}

/// A study's error as the command line reports it: bad input exits 2.
pub fn study_error(e: StudyError) -> anyhow::Error {
    match e {
        StudyError::Input(m) => InputError(m).into(),
        StudyError::Config(c) => c.into(),
        other => other.into(),
    }
}

impl StudyArgs {
    /// The arguments checked; a bad one is an input error naming the option.
    pub fn checked(&self) -> Result<Study> {
        check_picks(self.picks)?;
        let picks = if self.sustained {
            binpick::results::SUSTAINED_PICKS
        } else {
            self.picks
        };
        let seeds = binpick::study::parse_seeds(&self.seeds).map_err(study_error)?;
        let shard = match &self.shard {
            Some(t) => binpick::study::parse_shard(t).map_err(study_error)?,
            None => (1, 1),
        };
        let threads = match self.jobs {
            Some(0) => return Err(InputError("--jobs must be at least 1, got 0".into()).into()),
            Some(j) => j,
            None => std::thread::available_parallelism().map_or(1, |n| n.get()),
        };
        let mut workpieces = Vec::new();
        for name in self.workpieces.split(',').map(str::trim) {
            if name.is_empty() {
                return Err(InputError(format!("--workpieces: empty name in {:?}", self.workpieces)).into());
            }
            workpieces.push(name.to_string());
        }
        Ok(Study {
            picks,
            seeds,
            shard,
            threads,
            workpieces,
        })
    }
}

/// A study's results folder, named for the spec and the shard.
pub fn results_dir(out: &Path, spec: &StudySpec, (k, n): (usize, usize)) -> Result<RunDir> {
    let name = if n > 1 {
        format!("{}-shard{k}of{n}", spec.name())
    } else {
        spec.name()
    };
    Ok(RunDir::create(out, &name)?)
}

/// Wall times of a study: the whole study's and the sum of its runs' (s) (NaN, `None` when not
/// known, as for a merge of deterministic shards).
pub struct WallTimes {
    /// The study, start to end.
    pub study_s: f64,
    /// Its runs, summed.
    pub runs_s: Option<f64>,
    /// Threads the runs went on.
    pub threads: usize,
}

/// Runs this shard of the study with a progress bar; with `record`, each run's time charts, picks
/// and events go into `dir`, with its recordings in `record`'s formats. Returns the study's file
/// and its wall times.
pub fn run(
    resolved: &Resolved,
    spec: StudySpec,
    study: &Study,
    dir: &RunDir,
    record: Option<binpick::recording::Formats>,
) -> Result<(StudyFile, WallTimes)> {
    let (k, n) = study.shard;
    let mine = binpick::study::shard(&spec.jobs(), k, n);
    let bar = indicatif::ProgressBar::new(mine.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs {msg}")
            .context("the progress bar's template")?
            .progress_chars("=> "),
    );
    let settings = RunSettings {
        threads: study.threads,
        // With both recordings left out, a recorded run still keeps its charts and logs.
        record: record.map(|formats| RecordTo {
            dir: dir.staging_dir(),
            formats,
        }),
        stop: Some(stop_on_ctrl_c()),
    };
    let wall = std::time::Instant::now();
    let runs = binpick::study::run_study(resolved, &spec, &mine, &settings, &|_| bar.inc(1));
    bar.finish_and_clear();
    let runs = runs.map_err(study_error)?;
    let times = WallTimes {
        study_s: wall.elapsed().as_secs_f64(),
        runs_s: Some(runs.iter().filter_map(|r| r.tally.wall_s).sum()),
        threads: study.threads,
    };
    Ok((StudyFile::new(spec, study.shard, runs), times))
}

/// How a study's results are printed and checked: `--json`, `--wide` and a batch's `--expect`.
#[derive(Default)]
pub struct Finish<'a> {
    /// Machine-readable JSON instead of the table.
    pub json: bool,
    /// A batch's full table instead of the terminal's short one.
    pub wide: bool,
    /// A batch's limits, checked after its runs (`takt.junit.xml`; exit 1 when one is missed).
    pub expect: Option<&'a Expectations>,
}

/// Limits of a batch that its results missed (exit 1).
#[derive(Debug, thiserror::Error)]
#[error("{missed} of {total} limits of {file} missed")]
pub struct LimitsMissed {
    /// Limits missed.
    pub missed: usize,
    /// Limits checked.
    pub total: usize,
    /// The limits file.
    pub file: String,
}

pub use binpick::report::wrap;

/// Writes the study's files (a batch's `takt.*`, a sweep's `sweep.*`; with limits, a batch's
/// `takt.junit.xml`), moves the folder into place and prints the table; an interrupted run makes
/// it exit 130, a run ended on a physics fault 3, a missed limit 1.
pub fn finish(dir: RunDir, file: &StudyFile, times: &WallTimes, how: Finish) -> Result<()> {
    let outputs = if file.spec.is_batch() {
        binpick::batch::outputs(file)
    } else {
        binpick::sweep::outputs(file)
    };
    for (name, text) in &outputs.files {
        dir.write(name, text)?;
    }
    let rows = file.spec.is_batch().then(|| binpick::batch::table(file));
    let checks = match (how.expect, &rows) {
        (Some(e), Some(rows)) => {
            let checks = e.check(rows);
            dir.write("takt.junit.xml", junit_xml(&file.spec.name(), &e.file, &checks))?;
            checks
        }
        _ => Vec::new(),
    };
    // The page last: it links the files written before it.
    dir.write(
        "report.html",
        binpick::study::report_html(file, &outputs, dir.staging_dir()),
    )?;
    let Outputs {
        markdown: md, table, ..
    } = outputs;
    let dest = dir.finish()?;
    let done = || -> Result<()> {
        if file.runs.iter().any(|r| r.tally.ended == Some(EndReason::Interrupted)) {
            return Err(Interrupted(dest.display().to_string()).into());
        }
        if let Some(failed) = RunsFailed::of(file.runs.iter().map(|r| &r.tally), &dest.display().to_string()) {
            return Err(failed.into());
        }
        let missed = checks.iter().filter(|c| !c.met).count();
        match how.expect {
            Some(e) if missed > 0 => Err(LimitsMissed {
                missed,
                total: checks.len(),
                file: e.file.clone(),
            }
            .into()),
            _ => Ok(()),
        }
    };
    if how.json {
        let mut out = serde_json::json!({"table": table, "wall_s": times.study_s, "dir": dest.display().to_string()});
        if how.expect.is_some() {
            out["limits"] = checks
                .iter()
                .map(|c| {
                    serde_json::json!({
                        "workpiece": c.limit.workpiece,
                        "key": c.limit.figure.key,
                        "limit": c.limit.limit,
                        "value": c.value,
                        "met": c.met,
                    })
                })
                .collect();
        }
        println!("{}", serde_json::to_string_pretty(&out)?);
        return done();
    }
    let spec = &file.spec;
    let (k, n) = file.shard;
    let mode = if spec.deterministic {
        ", deterministic compute budgets"
    } else {
        ", measured compute"
    };
    let shard = if n > 1 {
        format!(", shard {k} of {n}")
    } else {
        String::new()
    };
    let sim_s: f64 = file.runs.iter().map(|r| r.tally.sim_time_s).sum();
    // A merge of deterministic shards knows no wall time.
    let wall = if times.study_s.is_finite() {
        format!(", {:.1} s wall on {} threads", times.study_s, times.threads)
    } else {
        " (deterministic results keep no run times: each shard's own output printed them)".to_string()
    };
    let width = binpick::results::table::TERMINAL_WIDTH;
    if let Some(rows) = &rows {
        println!(
            "{}",
            wrap(
                &format!(
                    "{} runs of {} picks{mode}{shard}, seeds {:?}",
                    file.runs.len(),
                    spec.picks,
                    spec.seeds
                ),
                width
            )
        );
        println!();
        if how.wide {
            print!("{md}");
        } else {
            print!("{}", binpick::results::table::terminal(rows));
        }
        println!();
        let guide = if how.wide {
            "takt as the reference defines it: every release-to-release interval after a run's first release, failures, re-captures and refills included (\"excl. tray refills\" leaves out the intervals spanning a refill); the sustained takt when the runs span several piles (--sustained), parts/h = 3600 s / takt; first 20 = the reference's 20-pick figure, the intervals of each run's first 21 picks; pile loads placed = placed per run / the pile's size; success = placed within the place tray's tolerance / attempts, re-captures counted; motion floor = mean Pick + Place, the takt with instantaneous sensing and compute; grasps sealed / attempted; recognition against the truth at each trigger (correct = within 2 mm and 5 deg of a part; recall over the top layer); torque demand before saturation;"
        } else {
            "takt as the reference defines it: every release-to-release interval after a run's first release, failures, re-captures and refills included (sustained when the runs span several piles: --sustained); first 20 = the takt over each run's first 21 picks, the reference's 20-pick definition; ref. = the reference system's takt (its Table 5, same definition); success = placed within the place tray's tolerance / attempts, re-captures counted; floor = the motion floor, mean Pick + Place, the takt with instantaneous sensing and compute; waits = the share of the takt spent waiting for the sensor or compute; faults = protective stops + collisions + drops + parts lost; every column is in takt.md, takt.csv and takt.json (--wide prints them all);"
        };
        let runs = times.runs_s.map_or(String::new(), |w| {
            format!(
                " in {w:.1} s of run time ({:.0}x real time per core)",
                sim_s / w.max(1e-9)
            )
        });
        println!(
            "{}",
            wrap(&format!("{guide} {sim_s:.1} s simulated{runs}{wall}"), width)
        );
        if let Some(e) = how.expect {
            println!("\n{}", wrap(&format!("limits of {}:", e.file), width));
            for c in &checks {
                for line in wrap(&c.message(), width - 2).lines() {
                    println!("  {line}");
                }
            }
        }
    } else {
        println!(
            "{} variants x {} workpieces x {} seeds: {} runs of {} picks{mode}{shard}\n",
            spec.variants.len(),
            spec.workpieces.len(),
            spec.seeds.len(),
            file.runs.len(),
            spec.picks,
        );
        print!(
            "{}",
            binpick::sweep::table::terminal(spec, &binpick::sweep::table::table(file))
        );
        println!(
            "\n{}",
            wrap(
                &format!(
                    "takt as the reference defines it (see `binpick batch`); success = placed within the place tray's tolerance / attempts; p95 = the 95th percentile of every interval; floor = the motion floor, mean Pick + Place; faults = protective stops + collisions + drops + parts lost; sweep.md adds the p5, sensor waits and picks per capture, sweep.csv every column of the batch table; {sim_s:.1} s simulated{wall}"
                ),
                width
            )
        );
    }
    println!("wrote {}", dest.display());
    done()
}

/// Copies the files and folders of a shard's folder that are not its results (the resolved
/// inputs, a sweep's variants, recordings) into the merge's folder.
fn copy_inputs(from: &Path, dir: &RunDir, sub: &str) -> Result<()> {
    for entry in std::fs::read_dir(from).with_context(|| from.display().to_string())? {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let rel = if sub.is_empty() {
            name.clone()
        } else {
            format!("{sub}/{name}")
        };
        if entry.file_type()?.is_dir() {
            std::fs::create_dir_all(dir.path(&rel))?;
            copy_inputs(&entry.path(), dir, &rel)?;
        } else if !(sub.is_empty()
            && (name.starts_with("takt.") || name.starts_with("sweep.") || name == "report.html"))
        {
            dir.write(&rel, std::fs::read(entry.path())?)?;
        }
    }
    Ok(())
}

/// `binpick merge`: the shards of one study (folders holding a `takt.json`, or a
/// `sweep.json`) into its table.
pub fn merge(dirs: &[PathBuf], out: &Path, json: bool) -> Result<()> {
    let mut files = Vec::new();
    for d in dirs {
        let path = if d.join("sweep.json").is_file() {
            d.join("sweep.json")
        } else {
            d.join("takt.json")
        };
        let text =
            std::fs::read_to_string(&path).map_err(|e| InputError(format!("{}: cannot read: {e}", path.display())))?;
        let f = serde_json::from_str(&text)
            .map_err(|e| e.to_string())
            .and_then(|v| StudyFile::from_json(&v))
            .map_err(|e| InputError(format!("{}: not a batch or sweep result: {e}", path.display())))?;
        files.push((path.display().to_string(), f));
    }
    let merged = binpick::study::merge(&files).map_err(study_error)?;
    let dir = RunDir::create(out, &merged.spec.name())?;
    // The shards' resolved inputs are the same; the first one's go with the merge.
    copy_inputs(&dirs[0], &dir, "")?;
    let runs_s: Option<f64> = merged.runs.iter().map(|r| r.tally.wall_s).sum();
    let times = WallTimes {
        study_s: runs_s.unwrap_or(f64::NAN),
        runs_s,
        threads: 1,
    };
    finish(
        dir,
        &merged,
        &times,
        Finish {
            json,
            ..Finish::default()
        },
    )
}
