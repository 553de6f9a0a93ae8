//! `binpick sweep`: the takt table over variants of the cell (`--set KEY=V1,V2,...`), and the
//! merge of a sweep's shards (`binpick merge` on folders holding a `sweep.json`).
//!
//! Every variant is resolved and checked before anything runs or is written (exit 2 naming the
//! variant, the key and the value); the runs go in parallel with a progress bar; the folder
//! holds `sweep.md`, `sweep.csv`, `sweep.json`, `sweep.svg` and each variant's resolved files.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;

use super::{InputError, Interrupted, stop_on_ctrl_c};
use binpick::config::{ShapeKind, Source};
use binpick::cycle::EndReason;
use binpick::sweep::{Resolved, SweepError, SweepFile, SweepRuns, SweepSpec};

/// Arguments of `binpick sweep`.
#[derive(Args)]
pub struct SweepArgs {
    /// A key of the cell file (`gripper.cup_diameter_m`) or, prefixed `workpiece.`, of every
    /// workpiece file (`workpiece.grasp.face_margin_m`), and its values in the file's types:
    /// `0.004,0.006`, a range `0.004:0.012:0.002`, arrays `[0.4,-0.2,0.006]`, words `oracle`.
    /// Repeat for more keys: the variants are the product of the lists.
    #[arg(long = "set", value_name = "KEY=V1,V2,...", required = true)]
    pub sets: Vec<String>,
    #[command(flatten)]
    pub runs: super::batch::RunsArgs,
    /// Scene file the variants start from (default: the embedded default cell).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Folder the sweep folder is written into.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Machine-readable JSON output.
    #[arg(long)]
    pub json: bool,
}

fn input_error(e: SweepError) -> anyhow::Error {
    match e {
        SweepError::Input(m) => InputError(m).into(),
        SweepError::Config(c) => c.into(),
        other => other.into(),
    }
}

/// `binpick sweep`.
pub fn sweep(a: &SweepArgs) -> Result<()> {
    let super::batch::Runs {
        seeds,
        shard: (k, n),
        threads,
        workpieces: names,
    } = a.runs.checked()?;
    let sets = binpick::sweep::parse_sets(&a.sets).map_err(input_error)?;
    // Every variant is resolved and checked before anything runs or is written.
    let values = binpick::sweep::variants(&sets);
    let resolved = binpick::sweep::resolve(a.scene.as_deref(), &names, &sets, &values).map_err(input_error)?;
    let spec = SweepSpec {
        scene: resolved.scene_label.clone(),
        keys: sets.iter().map(|s| s.key.clone()).collect(),
        variants: values
            .iter()
            .map(|v| v.iter().map(binpick::sweep::value_text).collect())
            .collect(),
        workpieces: resolved.variants[0]
            .workpieces
            .iter()
            .map(|w| w.workpiece.name.clone())
            .collect(),
        seeds,
        picks: a.runs.picks,
        deterministic: a.runs.deterministic,
    };
    let mine = binpick::sweep::shard(&spec.jobs(), k, n);
    let name = if n > 1 {
        format!("{}-shard{k}of{n}", spec.name())
    } else {
        spec.name()
    };
    let dir = binpick::report::RunDir::create(&a.out, &name)?;
    let bar = indicatif::ProgressBar::new(mine.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs {msg}")
            .context("the progress bar's template")?
            .progress_chars("=> "),
    );
    let wall = std::time::Instant::now();
    let runs = SweepRuns {
        jobs: &mine,
        picks: spec.picks,
        deterministic: spec.deterministic,
        threads,
        stop: Some(stop_on_ctrl_c()),
    };
    let result = binpick::sweep::run_sweep(&resolved, &runs, &|_| bar.inc(1));
    bar.finish_and_clear();
    let mut runs = result?;
    let wall_s = wall.elapsed().as_secs_f64();
    if a.runs.deterministic {
        // Wall times are measurements, not results: a deterministic sweep.json repeats byte for byte.
        runs.iter_mut().for_each(|r| r.run.wall_s = None);
    }
    write_variants(&dir, &resolved)?;
    let file = SweepFile {
        version: env!("CARGO_PKG_VERSION").into(),
        spec,
        shard: (k, n),
        runs,
    };
    write_sweep(dir, &file, wall_s, threads, a.json)
}

/// Each variant's resolved cell (with its URDF) and workpieces, in `variant-N/`, so a variant
/// re-runs on its own (`binpick batch --scene variant-N/scene.toml --workpieces variant-N/workpiece-A.toml`).
fn write_variants(dir: &binpick::report::RunDir, resolved: &Resolved) -> Result<()> {
    for (i, v) in resolved.variants.iter().enumerate() {
        let sub = format!("variant-{}", i + 1);
        std::fs::create_dir_all(dir.path(&sub)).with_context(|| dir.path(&sub).display().to_string())?;
        let urdf_name = Path::new(&v.scene.scene.robot.urdf)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "robot.urdf".into());
        let mut scene = v.scene.scene.clone();
        scene.robot.urdf = urdf_name.clone();
        let header = format!(
            "# binpick {}: resolved scene, from {}\n",
            env!("CARGO_PKG_VERSION"),
            v.scene.label
        );
        dir.write(&format!("{sub}/scene.toml"), header + &toml::to_string(&scene)?)?;
        dir.write(&format!("{sub}/{urdf_name}"), &v.scene.urdf_text)?;
        for wp in &v.workpieces {
            // A mesh goes beside the variant's workpiece file, which names it by its bare name.
            let mut wp = wp.clone();
            if let (ShapeKind::Mesh, Source::File(p), Some(mesh)) = (
                wp.workpiece.shape.kind,
                &wp.source,
                wp.workpiece.shape.mesh_file.clone(),
            ) {
                let from = p.parent().unwrap_or(Path::new(".")).join(&mesh);
                let name = Path::new(&mesh)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or(mesh);
                dir.write(
                    &format!("{sub}/{name}"),
                    std::fs::read(&from).with_context(|| from.display().to_string())?,
                )?;
                wp.workpiece.shape.mesh_file = Some(name);
                wp.source = Source::Embedded;
            }
            dir.write_workpiece(&wp, &format!("{sub}/workpiece-{}.toml", wp.workpiece.name))?;
        }
    }
    Ok(())
}

/// Writes sweep.json, sweep.csv, sweep.md and sweep.svg of a sweep (or a merge) and prints the table.
fn write_sweep(dir: binpick::report::RunDir, file: &SweepFile, wall_s: f64, threads: usize, json: bool) -> Result<()> {
    let rows = binpick::sweep::table(&file.spec, &file.runs);
    let md = binpick::sweep::markdown(&file.spec, &rows);
    dir.write_json("sweep.json", &json!({"sweep": file, "table": rows}))?;
    dir.write("sweep.csv", binpick::sweep::csv(&file.spec, &rows))?;
    dir.write("sweep.md", &md)?;
    dir.write("sweep.svg", binpick::sweep::chart::sweep_svg(&file.spec, &rows))?;
    let dest = dir.finish()?;
    let done = || -> Result<()> {
        if file.runs.iter().any(|r| r.run.ended == EndReason::Interrupted.text()) {
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
    let sim_s: f64 = file.runs.iter().map(|r| r.run.sim_time_s).sum();
    println!(
        "{} variants x {} workpieces x {} seeds: {} runs of {} picks{}{}\n",
        file.spec.variants.len(),
        file.spec.workpieces.len(),
        file.spec.seeds.len(),
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
    );
    print!("{md}");
    println!(
        "\ntakt as the reference defines it (see `binpick batch`); p5 and p95 are the 5th and 95th percentiles of every interval; faults = protective stops + collisions + drops + parts lost; every column of the batch table is in sweep.csv; {sim_s:.1} s simulated, {wall_s:.1} s wall on {threads} threads"
    );
    println!("wrote {}", dest.display());
    done()
}

/// Copies the files and folders of a shard's folder that are not its results (the variants'
/// resolved inputs) into the merge's folder.
fn copy_inputs(from: &Path, dir: &binpick::report::RunDir, sub: &str) -> Result<()> {
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
        } else if !(sub.is_empty() && name.starts_with("sweep.")) {
            dir.write(&rel, std::fs::read(entry.path())?)?;
        }
    }
    Ok(())
}

/// `binpick merge` of a sweep's shards (folders holding a `sweep.json`) into its table.
pub fn merge(dirs: &[PathBuf], out: &Path, json: bool) -> Result<()> {
    let mut files = Vec::new();
    for d in dirs {
        let path = d.join("sweep.json");
        let text =
            std::fs::read_to_string(&path).map_err(|e| InputError(format!("{}: cannot read: {e}", path.display())))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| InputError(format!("{}: not a sweep result: {e}", path.display())))?;
        let f: SweepFile = serde_json::from_value(v["sweep"].clone())
            .map_err(|e| InputError(format!("{}: not a sweep result: {e}", path.display())))?;
        files.push((path.display().to_string(), f));
    }
    let merged = binpick::sweep::merge(&files).map_err(input_error)?;
    let dir = binpick::report::RunDir::create(out, &merged.spec.name())?;
    // The shards' resolved inputs are the same; the first one's go with the merge.
    copy_inputs(&dirs[0], &dir, "")?;
    let wall_s: Option<f64> = merged.runs.iter().map(|r| r.run.wall_s).sum();
    write_sweep(dir, &merged, wall_s.unwrap_or(f64::NAN), 1, json)
}
