//! `binpick batch` and `binpick merge`: the takt-time table over many runs (or a shard of
//! them) with a progress bar, and the merge of a batch's shards.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;

use super::{InputError, Interrupted, SkipFormats, check_picks, stop_on_ctrl_c};
use binpick::batch::{
    BatchError, BatchFile, BatchInputs, BatchRuns, BatchSpec, RecordTo, parse_seeds, parse_shard, shard,
};
use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::cycle::EndReason;
use binpick::robot::RobotModel;

/// Which runs a batch or a sweep makes, and how: the arguments both commands share.
#[derive(Args)]
pub struct RunsArgs {
    /// Workpieces, comma-separated: A ... F (embedded) or paths to workpiece files.
    #[arg(long, default_value = "A,B,C,D,E,F")]
    pub workpieces: String,
    /// Picks per run (the first of each run follows the initial sensing and has no takt).
    #[arg(long, default_value_t = 21)]
    pub picks: usize,
    /// Seeds: 1-3, or 1,2,5.
    #[arg(long, default_value = "1")]
    pub seeds: String,
    /// Runs in parallel (default: the machine's cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Run only the K-th of N disjoint slices of the runs (1-based), e.g. 2/4.
    #[arg(long)]
    pub shard: Option<String>,
    /// Charge the cell file's fixed compute budgets instead of measured wall time.
    #[arg(long)]
    pub deterministic: bool,
}

/// [`RunsArgs`] checked: seeds, shard (k of n), threads and workpiece names.
pub struct Runs {
    /// Seeds.
    pub seeds: Vec<u64>,
    /// This shard, k of n (1 of 1: all).
    pub shard: (usize, usize),
    /// Runs in parallel.
    pub threads: usize,
    /// Workpiece names or paths, as given.
    pub workpieces: Vec<String>,
}

impl RunsArgs {
    /// The arguments checked; a bad one is an input error naming the option.
    pub fn checked(&self) -> Result<Runs> {
        check_picks(self.picks)?;
        let seeds = parse_seeds(&self.seeds).map_err(|e| InputError(e.to_string()))?;
        let shard = match &self.shard {
            Some(t) => parse_shard(t).map_err(|e| InputError(e.to_string()))?,
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
        Ok(Runs {
            seeds,
            shard,
            threads,
            workpieces,
        })
    }
}

/// Arguments of `binpick batch`.
#[derive(Args)]
pub struct BatchArgs {
    #[command(flatten)]
    pub runs: RunsArgs,
    /// Record every run: `run-<workpiece>-seed<seed>.rrd` and `.mcap` in the batch folder.
    #[arg(long)]
    pub record: bool,
    #[command(flatten)]
    pub skip: SkipFormats,
    /// Recognition: `cloud` (from the depth capture, the default) or `oracle` (the what-if of
    /// perfect recognition); overrides the cell file's `sensor.recognition`.
    #[arg(long, value_name = "cloud|oracle")]
    pub recognition: Option<binpick::config::RecognitionMode>,
    /// Scene file (default: the embedded default cell).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Folder the batch folder is written into.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Machine-readable JSON output.
    #[arg(long)]
    pub json: bool,
}

/// `binpick batch`: every (workpiece, seed) run of the batch (or of one shard), in parallel.
pub fn batch(a: &BatchArgs) -> Result<()> {
    let Runs {
        seeds,
        shard: (k, n),
        threads: jobs,
        workpieces: names,
    } = a.runs.checked()?;
    let formats = a.skip.formats(a.record);
    // Every input is loaded and checked before anything runs or is written.
    let mut loaded = LoadedScene::load(a.scene.as_deref())?;
    super::override_recognition(&mut loaded, a.recognition);
    let robot = RobotModel::from_scene(&loaded)?;
    robot.check_scene_reach(&loaded.label, &loaded.scene)?;
    let mut workpieces: Vec<LoadedWorkpiece> = Vec::new();
    for name in &names {
        let wp = LoadedWorkpiece::resolve(name)?;
        wp.workpiece.check_fits_scene(&wp.label, &loaded.scene)?;
        binpick::physics::PartShape::build(&wp.workpiece, &wp.source)?;
        if workpieces.iter().any(|w| w.workpiece.name == wp.workpiece.name) {
            return Err(InputError(format!("--workpieces: {} appears twice", wp.workpiece.name)).into());
        }
        workpieces.push(wp);
    }
    let spec = BatchSpec {
        workpieces: workpieces.iter().map(|w| w.workpiece.name.clone()).collect(),
        seeds,
        picks: a.runs.picks,
        deterministic: a.runs.deterministic,
    };
    let mine = shard(&spec.jobs(), k, n);
    let bar = indicatif::ProgressBar::new(mine.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs {msg}")
            .context("the progress bar's template")?
            .progress_chars("=> "),
    );
    let name = if n > 1 {
        format!("{}-shard{k}of{n}", spec.name())
    } else {
        spec.name()
    };
    let dir = binpick::report::RunDir::create(&a.out, &name)?;
    let wall = std::time::Instant::now();
    let inputs = BatchInputs {
        scene: &loaded,
        robot: &robot,
        workpieces: &workpieces,
    };
    let record = formats.any().then(|| RecordTo {
        dir: dir.staging_dir(),
        formats,
    });
    let batch_runs = BatchRuns {
        jobs: &mine,
        picks: spec.picks,
        deterministic: spec.deterministic,
        threads: jobs,
        record,
        stop: Some(stop_on_ctrl_c()),
    };
    let runs = binpick::batch::run_batch(inputs, &batch_runs, &|_| bar.inc(1));
    bar.finish_and_clear();
    let runs = runs.map_err(|e| match e {
        BatchError::Input(m) => anyhow::Error::from(InputError(m)),
        other => other.into(),
    })?;
    let wall_s = wall.elapsed().as_secs_f64();
    let run_wall_s: f64 = runs.iter().filter_map(|r| r.wall_s).sum();
    let mut runs = runs;
    if a.runs.deterministic {
        // Wall times are measurements, not results: a deterministic takt.json repeats byte for byte.
        runs.iter_mut().for_each(|r| r.wall_s = None);
    }
    let file = BatchFile {
        version: env!("CARGO_PKG_VERSION").into(),
        spec,
        shard: (k, n),
        runs,
    };
    dir.write_inputs(&loaded, None)?;
    for wp in &workpieces {
        dir.write_workpiece(wp, &format!("workpiece-{}.toml", wp.workpiece.name))?;
    }
    write_batch(dir, &file, (wall_s, Some(run_wall_s)), jobs, a.json)
}

/// Writes takt.json, takt.csv and takt.md of a batch (or a merge) and prints the table.
fn write_batch(
    dir: binpick::report::RunDir,
    file: &binpick::batch::BatchFile,
    (wall_s, run_wall_s): (f64, Option<f64>),
    jobs: usize,
    json: bool,
) -> Result<()> {
    let rows = binpick::batch::table(&file.spec.workpieces, &file.runs);
    let md = binpick::batch::markdown(&rows);
    let sim_s: f64 = file.runs.iter().map(|r| r.sim_time_s).sum();
    dir.write_json("takt.json", &json!({"batch": file, "table": rows}))?;
    dir.write("takt.csv", binpick::batch::csv(&rows))?;
    dir.write("takt.md", &md)?;
    dir.write(
        "takt.svg",
        binpick::batch::chart::takt_svg(
            &format!("takt per workpiece: {}", file.spec.name()),
            &binpick::batch::chart::takt_bars(&rows, &file.runs),
        ),
    )?;
    let dest = dir.finish()?;
    let done = || -> Result<()> {
        if file.runs.iter().any(|r| r.ended == EndReason::Interrupted.text()) {
            Err(Interrupted(dest.display().to_string()).into())
        } else {
            Ok(())
        }
    };
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json!({"table": rows, "wall_s": wall_s, "dir": dest.display().to_string()}))?
        );
        return done();
    }
    let (k, n) = file.shard;
    println!(
        "{} runs of {} picks{}{}, seeds {:?}\n",
        file.runs.len(),
        file.spec.picks,
        if file.spec.deterministic {
            ", deterministic compute budgets"
        } else {
            ", measured compute"
        },
        if n > 1 {
            format!(", shard {k} of {n}")
        } else {
            String::new()
        },
        file.spec.seeds
    );
    print!("{md}");
    println!(
        "\ntakt as the reference defines it: every release-to-release interval after a run's first release, failures, re-captures and refills included (\"excl. tray refills\" leaves out the intervals spanning a refill); success = placed / attempts, re-captures counted; motion floor = mean Pick + Place, the takt with instantaneous sensing and compute; grasps sealed / attempted; recognition against the truth at each trigger (correct = within 2 mm and 5 deg of a part; recall over the top layer); torque demand before saturation; {sim_s:.1} s simulated{}{}",
        run_wall_s.map_or(String::new(), |w| format!(
            " in {w:.1} s of run time ({:.0}x real time per core)",
            sim_s / w.max(1e-9)
        )),
        // A merge of deterministic shards knows no wall time.
        if wall_s.is_finite() {
            format!(", {wall_s:.1} s wall on {jobs} threads")
        } else {
            String::new()
        }
    );
    println!("wrote {}", dest.display());
    done()
}

/// `binpick merge`: the shards of one batch into its table.
pub fn merge(dirs: &[PathBuf], out: &Path, json: bool) -> Result<()> {
    if dirs.first().is_some_and(|d| d.join("sweep.json").is_file()) {
        return super::sweep::merge(dirs, out, json);
    }
    let mut files = Vec::new();
    for d in dirs {
        let path = d.join("takt.json");
        let text =
            std::fs::read_to_string(&path).map_err(|e| InputError(format!("{}: cannot read: {e}", path.display())))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| InputError(format!("{}: not a batch result: {e}", path.display())))?;
        let f: binpick::batch::BatchFile = serde_json::from_value(v["batch"].clone())
            .map_err(|e| InputError(format!("{}: not a batch result: {e}", path.display())))?;
        files.push((path.display().to_string(), f));
    }
    let merged = binpick::batch::merge(&files).map_err(|e| InputError(e.to_string()))?;
    let dir = binpick::report::RunDir::create(out, &merged.spec.name())?;
    // The shards' resolved inputs are the same; the first one's go with the merge.
    for entry in std::fs::read_dir(&dirs[0]).with_context(|| dirs[0].display().to_string())? {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if !name.starts_with("takt.") && entry.file_type()?.is_file() {
            dir.write(&name, std::fs::read(entry.path())?)?;
        }
    }
    let run_wall_s: Option<f64> = merged.runs.iter().map(|r| r.wall_s).sum();
    write_batch(dir, &merged, (run_wall_s.unwrap_or(f64::NAN), run_wall_s), 1, json)
}
