//! `binpick batch`: the takt-time table over many runs of the cell as given (or a shard of
//! them), with a progress bar: a study of one variant ([`super::study`]); with `--expect`, the
//! table checked against the user's limits ([`binpick::results::expect`]).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use super::study::{Finish, StudyArgs, finish, results_dir};
use super::{CellArgs, InputError, OutArgs, SkipFormats, load_workpiece};
use binpick::config::LoadedWorkpiece;
use binpick::results::expect::Expectations;
use binpick::study::{Resolved, StudySpec};

/// Arguments of `binpick batch`.
#[derive(Args)]
pub struct BatchArgs {
    #[command(flatten)]
    pub study: StudyArgs,
    /// Record every run: `run-<workpiece>-seed<seed>.rrd` and `.mcap`, its time charts
    /// (`.timechart.svg`, `.timechart-steady.svg`), its per-pick table and event log (`.picks.csv`,
    /// `.events.json`), in the batch folder (linked from report.html). With `--no-rrd --no-mcap`,
    /// all but the recordings: a long run's incidents traced at little cost.
    #[arg(long)]
    pub record: bool,
    /// Print the full table (every column of takt.md) instead of the terminal's short one.
    #[arg(long)]
    pub wide: bool,
    /// Per-workpiece limits (TOML: `[E]` with `takt_max_s = 1.8`, `success_min = 0.95`,
    /// `collisions_max = 0`, ...) checked after the runs: writes takt.junit.xml, exits 1 when a
    /// limit is missed.
    #[arg(long, value_name = "EXPECT.toml")]
    pub expect: Option<PathBuf>,
    #[command(flatten)]
    pub skip: SkipFormats,
    #[command(flatten)]
    pub cell: CellArgs,
    #[command(flatten)]
    pub out: OutArgs,
}

/// `binpick batch`: every (workpiece, seed) run of the batch (or of one shard), in parallel.
pub fn batch(a: &BatchArgs) -> Result<()> {
    let study = a.study.checked()?;
    // Every input is loaded and checked before anything runs or is written.
    let (loaded, robot) = a.cell.load()?;
    let mut workpieces: Vec<LoadedWorkpiece> = Vec::new();
    for name in &study.workpieces {
        let wp = load_workpiece(name, &loaded, &robot)?;
        if workpieces.iter().any(|w| w.workpiece.name == wp.workpiece.name) {
            return Err(InputError(format!("--workpieces: {} appears twice", wp.workpiece.name)).into());
        }
        workpieces.push(wp);
    }
    let spec = StudySpec::batch(
        workpieces.iter().map(|w| w.workpiece.name.clone()).collect(),
        study.seeds.clone(),
        study.picks,
        a.study.mode.deterministic,
    );
    // The limits are checked against the batch's workpieces before anything runs.
    let expect = match &a.expect {
        Some(path) => {
            if study.shard.1 > 1 {
                return Err(InputError(
                    "--expect checks the whole batch's table; a shard (--shard) holds part of it".into(),
                )
                .into());
            }
            Some(Expectations::load(path, &spec.workpieces).map_err(|e| InputError(e.to_string()))?)
        }
        None => None,
    };
    let dir = results_dir(&a.out.out, &spec, study.shard)?;
    let resolved = Resolved::single(loaded, robot, workpieces);
    let record = a.record.then(|| a.skip.formats(true));
    let (file, times) = super::study::run(&resolved, spec, &study, &dir, record)?;
    let variant = &resolved.variants[0];
    dir.write_inputs(&variant.scene, None)?;
    for wp in &variant.workpieces {
        // A workpiece's own cup, written in full.
        let wp = wp.with_set_up_completed(&variant.scene.scene);
        dir.write_workpiece(&wp, &format!("workpiece-{}.toml", wp.workpiece.name))?;
    }
    let how = Finish {
        json: a.out.json,
        wide: a.wide,
        expect: expect.as_ref(),
    };
    finish(dir, &file, &times, how)
}
