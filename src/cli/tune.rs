//! `binpick tune`: the cell's settings for one workpiece chosen by an optimizer over
//! `--vary KEY=LO:HI` keys ([`binpick::tune`]), judged on test seeds it never evaluated.
//!
//! Everything is checked before anything runs or is written (exit 2): the seeds (training and
//! test seeds that overlap are refused), the keys (unknown, non-numeric, a bad range), the
//! constraints. Each round is one study; each finished evaluation goes to the journal
//! `<out>/<name>.journal.jsonl`, and the same command re-run (after Ctrl-C, or with a larger
//! `--budget`) resumes from it. The folder `<out>/<name>/` holds `tune.md`, `tune.json`,
//! `tune.svg`, `report.html` (the page of all of it), the tuned cell and workpiece files in
//! `tuned/` and the untuned ones in `untuned/`. When no candidate meets the constraints, the files are written without a best
//! and the command fails (exit 1).
//!
//! `--shard K/N` splits each round's evaluations (and the two test measurements) across N
//! processes sharing the `--out` folder: each appends to `<name>.shardKofN.journal.jsonl`, reads
//! the other shards' journals for the rest of the round, and writes `<name>-shardKofN/`, whose
//! `tune.json` is the one a single process writes (the same optimizer on the same figures).

use std::path::PathBuf;
use std::sync::atomic::Ordering;

use anyhow::{Context, Result, anyhow};
use clap::Args;

use super::study::study_error;
use super::{InputError, Interrupted, ModeArgs, OutArgs, check_picks, stop_on_ctrl_c};
use binpick::report::RunDir;
use binpick::tune::journal::{Header, Journal};
use binpick::tune::output::Report;
use binpick::tune::{Constraints, Objective, Optimizer, Settings};

/// Arguments of `binpick tune`.
#[derive(Args)]
#[command(
    override_usage = "binpick tune [OPTIONS] --workpiece <WORKPIECE> --vary <KEY=LO:HI>\n       \
                            --train-seeds <TRAIN_SEEDS> --test-seeds <TEST_SEEDS>"
)]
pub struct TuneArgs {
    /// The workpiece: A ... F (embedded) or a path to a workpiece file.
    #[arg(long)]
    pub workpiece: String,
    /// A numeric key of the cell file (`gripper.cup_diameter_m`) or, prefixed `workpiece.`, of
    /// the workpiece file, and its range `LO:HI`; an integer key takes whole numbers. Repeat for
    /// more keys.
    #[arg(long = "vary", value_name = "KEY=LO:HI", required = true)]
    pub varies: Vec<String>,
    /// Candidates the optimizer may ask for, in all.
    #[arg(long, default_value_t = 60)]
    pub budget: usize,
    /// Candidates per round (the swarm's particles), run in parallel as one study.
    #[arg(long, default_value_t = 10)]
    pub population: usize,
    /// Seeds the optimizer evaluates candidates on: 1-5, or 1,2,5.
    #[arg(long)]
    pub train_seeds: String,
    /// Seeds the best and the untuned cell are measured on afterwards (none of the training seeds).
    #[arg(long)]
    pub test_seeds: String,
    /// Picks per run (default: 180, the sustained count, with `--objective sustained`; 21 with
    /// `first20`).
    #[arg(long)]
    pub picks: Option<usize>,
    /// The takt minimised: `sustained` (every interval of the runs: what the line keeps up,
    /// pile running low and refills included) or `first20` (the reference's 20-pick figure,
    /// each run's first 21 picks).
    #[arg(long, default_value = "sustained", value_parser = ["sustained", "first20"])]
    pub objective: String,
    /// Who asks for the candidates: `swarm` (argmin's particle swarm) or `grid` (an even grid
    /// over the keys with as many points as the budget allows: the hand-laid baseline the
    /// swarm is judged against, through the same runs, constraints and test).
    #[arg(long, default_value = "swarm", value_parser = ["swarm", "grid"])]
    pub optimizer: String,
    /// The optimizer's seed (its random numbers come from this seed's `tune-optimizer` stream).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Lowest success rate (placed within the place tray's tolerance / attempts, 0 to 1) a best must reach on the training seeds.
    #[arg(long, default_value_t = 0.95)]
    pub min_success: f64,
    /// Most collisions a best may have over its training runs.
    #[arg(long, default_value_t = 0)]
    pub max_collisions: usize,
    /// Most protective stops.
    #[arg(long, default_value_t = 0)]
    pub max_stops: usize,
    /// Most parts lost.
    #[arg(long, default_value_t = 0)]
    pub max_parts_lost: usize,
    /// Runs in parallel (default: the machine's cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Run the K-th of N shards of each round's evaluations (1-based), e.g. 2/4, on machines
    /// sharing the `--out` folder: each shard appends to its own journal there, reads the
    /// others', and writes `<name>-shardKofN/` with the tune's outputs (the same `tune.json` as
    /// one machine's).
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// With `--shard`: how long to wait for the other shards' evaluations at most (s).
    #[arg(long, default_value_t = 86_400.0)]
    pub shard_wait_s: f64,
    /// Scene file the candidates start from (default: the embedded default cell).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    #[command(flatten)]
    pub mode: ModeArgs,
    #[command(flatten)]
    pub out: OutArgs,
}

/// Seeds as a folder name writes them: a range when consecutive.
fn seeds_name(s: &[u64]) -> String {
    match (s.first(), s.last()) {
        (Some(a), Some(b)) if s.len() > 1 && s.windows(2).all(|w| w[0].checked_add(1) == Some(w[1])) => {
            format!("{a}-{b}")
        }
        _ => s.iter().map(u64::to_string).collect::<Vec<_>>().join("_"),
    }
}

/// `binpick tune`.
pub fn tune(a: &TuneArgs) -> Result<()> {
    let objective = Objective::parse(&a.objective)
        .ok_or_else(|| InputError(format!("--objective: {:?} is not sustained or first20", a.objective)))?;
    let picks = a.picks.unwrap_or(match objective {
        Objective::Sustained => binpick::results::SUSTAINED_PICKS,
        Objective::First20 => binpick::cycle::FIRST_PICKS,
    });
    check_picks(picks)?;
    let optimizer = Optimizer::parse(&a.optimizer)
        .ok_or_else(|| InputError(format!("--optimizer: {:?} is not swarm or grid", a.optimizer)))?;
    if a.budget == 0 || a.budget > 10_000 {
        return Err(InputError(format!("--budget must be within [1, 10000], got {}", a.budget)).into());
    }
    if a.population == 0 || a.population > 1000 {
        return Err(InputError(format!("--population must be within [1, 1000], got {}", a.population)).into());
    }
    if !(0.0..=1.0).contains(&a.min_success) {
        return Err(InputError(format!("--min-success must be within [0, 1], got {}", a.min_success)).into());
    }
    let threads = match a.jobs {
        Some(0) => return Err(InputError("--jobs must be at least 1, got 0".into()).into()),
        Some(j) => j,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let shard = match &a.shard {
        Some(t) => binpick::study::parse_shard(t).map_err(study_error)?,
        None => (1, 1),
    };
    if !(a.shard_wait_s.is_finite() && a.shard_wait_s >= 0.0) {
        return Err(InputError(format!("--shard-wait-s must be >= 0, got {}", a.shard_wait_s)).into());
    }
    let parse = |t: &str, opt: &str| {
        binpick::study::parse_seeds(t)
            .map_err(|e| InputError(format!("{opt}{}", e.to_string().trim_start_matches("--seeds"))))
    };
    let train = parse(&a.train_seeds, "--train-seeds")?;
    let test = parse(&a.test_seeds, "--test-seeds")?;
    let both: Vec<u64> = train.iter().filter(|s| test.contains(s)).copied().collect();
    if !both.is_empty() {
        return Err(InputError(format!(
            "--train-seeds and --test-seeds overlap ({}): the test figure must come from seeds the optimizer never evaluated",
            seeds_name(&both)
        ))
        .into());
    }
    let mut dims = binpick::tune::parse_varies(&a.varies).map_err(study_error)?;
    let base = binpick::tune::cell::base(a.scene.as_deref(), &a.workpiece).map_err(study_error)?;
    binpick::tune::cell::check_keys(&base, &mut dims).map_err(study_error)?;
    let untuned = &base.variants[0];
    let wp_name = untuned.workpieces[0].workpiece.name.clone();
    let header = Header {
        version: env!("CARGO_PKG_VERSION").into(),
        scene: base.scene_label.clone(),
        workpiece: a.workpiece.clone(),
        keys: dims.clone(),
        train_seeds: train.clone(),
        picks,
        deterministic: a.mode.deterministic,
        seed: a.seed,
        population: a.population,
        objective,
        optimizer,
    };
    let keys: String = dims
        .iter()
        .map(|d| {
            d.key
                .replace(|c: char| !c.is_ascii_alphanumeric() && c != '_' && c != '.', "_")
        })
        .collect::<Vec<_>>()
        .join("+");
    let name = format!(
        "tune-{wp_name}-{keys}-train{}-test{}-picks{}{}-seed{}{}",
        seeds_name(&train),
        seeds_name(&test),
        picks,
        match objective {
            Objective::Sustained => "",
            Objective::First20 => "-first20",
        },
        a.seed,
        if a.mode.deterministic { "-det" } else { "" }
    );
    let name = match optimizer {
        Optimizer::Swarm => name,
        Optimizer::Grid => format!("{name}-grid"),
    };
    let (k, n) = shard;
    let dir_name = if n > 1 {
        format!("{name}-shard{k}of{n}")
    } else {
        name.clone()
    };
    let dir = RunDir::create(&a.out.out, &dir_name)?;
    let journal_path = a.out.out.join(if n > 1 {
        format!("{name}.shard{k}of{n}.journal.jsonl")
    } else {
        format!("{name}.journal.jsonl")
    });
    let journal = Journal::open(&journal_path, &header).map_err(study_error)?;
    let settings = Settings {
        budget: a.budget,
        population: a.population,
        optimizer,
        seed: a.seed,
        constraints: Constraints {
            min_success: a.min_success,
            max_collisions: a.max_collisions,
            max_stops: a.max_stops,
            max_parts_lost: a.max_parts_lost,
        },
    };

    let bar = indicatif::ProgressBar::new((a.budget * train.len() + 2 * test.len()) as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs (at most) {msg}")
            .context("the progress bar's template")?
            .progress_chars("=> "),
    );
    let progress = |_: &binpick::study::StudyRun| bar.inc(1);
    let stop = stop_on_ctrl_c();
    let wall = std::time::Instant::now();
    let mut cell = binpick::tune::cell::Cell::new(
        a.scene.as_deref(),
        a.workpiece.clone(),
        dims.clone(),
        train.clone(),
        picks,
        a.mode.deterministic,
        threads,
        &journal,
        &progress,
    );
    cell.stop = Some(stop);
    cell.objective = objective;
    cell.shard = shard;
    if n > 1 {
        cell.peers = Some(binpick::tune::cell::Peers {
            dir: a.out.out.clone(),
            stem: name.clone(),
            header: header.clone(),
            poll: std::time::Duration::from_millis(500),
            timeout_s: a.shard_wait_s,
        });
    }
    let interrupted = || {
        Interrupted(format!(
            "{}: it keeps every finished evaluation; the same command resumes from it",
            journal.path().display()
        ))
    };
    let evaluations = match binpick::tune::optimize(&dims, &settings, &mut cell) {
        Ok(e) => e,
        Err(_) if stop.load(Ordering::Relaxed) => {
            bar.finish_and_clear();
            return Err(interrupted().into());
        }
        Err(e) => return Err(study_error(e)),
    };
    let best = binpick::tune::best(&evaluations);
    let test_figures = match best {
        Some(b) => match cell.test(&b.values, &test) {
            Ok(f) => Some(f),
            Err(_) if stop.load(Ordering::Relaxed) => {
                bar.finish_and_clear();
                return Err(interrupted().into());
            }
            Err(e) => return Err(study_error(e)),
        },
        None => None,
    };
    bar.finish_and_clear();
    let report = Report {
        header: &header,
        budget: a.budget,
        constraints: settings.constraints,
        test_seeds: &test,
        evaluations: &evaluations,
        best,
        test: test_figures,
    };
    let doc = binpick::tune::output::json(&report);
    dir.write_json("tune.json", &doc)?;
    let md = binpick::tune::output::markdown(&report);
    dir.write("tune.md", &md)?;
    let svg = binpick::tune::output::svg(&report);
    dir.write("tune.svg", &svg)?;
    super::sweep::write_variant(&dir, "untuned", untuned)?;
    if let Some(b) = best {
        let tuned = cell.resolve(&b.values).map_err(study_error)?;
        super::sweep::write_variant(&dir, "tuned", &tuned.variants[0])?;
    }
    // The page last: it links the files written before it.
    let files = binpick::report::html::folder_files(dir.staging_dir(), &[]);
    let about = format!(
        "{} evaluations of {} on training seeds {} ({} picks each, {}); the best measured on test seeds {} beside the untuned cell.",
        evaluations.len(),
        header.workpiece,
        seeds_name(&train),
        picks,
        if a.mode.deterministic {
            "deterministic compute budgets"
        } else {
            "measured compute"
        },
        seeds_name(&test)
    );
    let page = binpick::report::html::Page {
        title: &format!("binpick tune: {name}"),
        about: &about,
        markdown: &md,
        charts: &[("tune.svg", svg.as_str())],
        runs: &[],
        files: &files,
    };
    dir.write("report.html", binpick::report::html::page_html(&page))?;
    let dest = dir.finish()?;
    if a.out.json {
        let out = serde_json::json!({"tune": doc["tune"]["best"], "test": doc["tune"]["test"], "dir": dest.display().to_string()});
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        print!("{}", binpick::tune::output::terminal(&report));
        let done = format!(
            "{} evaluations ({} from the journal {}), {} cell runs, {:.1} s wall on {threads} threads",
            evaluations.len(),
            cell.replayed,
            journal.path().display(),
            cell.runs,
            wall.elapsed().as_secs_f64()
        );
        println!(
            "\n{}",
            binpick::report::wrap(&done, binpick::results::table::TERMINAL_WIDTH)
        );
        println!("wrote {}", dest.display());
    }
    if best.is_none() {
        return Err(anyhow!(
            "no candidate met every constraint on the training seeds; the evaluations are in {}",
            dest.display()
        ));
    }
    Ok(())
}
