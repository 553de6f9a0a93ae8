//! `binpick batch`: the takt-time table over many runs of the cell as given (or a shard of
//! them), with a progress bar: a study of one variant ([`super::study`]).

use anyhow::Result;
use clap::Args;

use super::study::{StudyArgs, finish, results_dir};
use super::{CellArgs, InputError, OutArgs, SkipFormats, load_workpiece};
use binpick::config::LoadedWorkpiece;
use binpick::study::{Resolved, StudySpec};

/// Arguments of `binpick batch`.
#[derive(Args)]
pub struct BatchArgs {
    #[command(flatten)]
    pub study: StudyArgs,
    /// Record every run: `run-<workpiece>-seed<seed>.rrd` and `.mcap` in the batch folder.
    #[arg(long)]
    pub record: bool,
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
        let wp = load_workpiece(name, &loaded)?;
        if workpieces.iter().any(|w| w.workpiece.name == wp.workpiece.name) {
            return Err(InputError(format!("--workpieces: {} appears twice", wp.workpiece.name)).into());
        }
        workpieces.push(wp);
    }
    let spec = StudySpec::batch(
        workpieces.iter().map(|w| w.workpiece.name.clone()).collect(),
        study.seeds.clone(),
        a.study.picks,
        a.study.mode.deterministic,
    );
    let dir = results_dir(&a.out.out, &spec, study.shard)?;
    let resolved = Resolved::single(loaded, robot, workpieces);
    let record = a.record.then(|| a.skip.formats(true));
    let (file, times) = super::study::run(&resolved, spec, &study, &dir, record)?;
    let variant = &resolved.variants[0];
    dir.write_inputs(&variant.scene, None)?;
    for wp in &variant.workpieces {
        dir.write_workpiece(wp, &format!("workpiece-{}.toml", wp.workpiece.name))?;
    }
    finish(dir, &file, &times, a.out.json)
}
