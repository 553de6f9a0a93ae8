//! The `binpick` command line: parses the arguments and dispatches to one module per command
//! (`src/cli/`), which call the library's pipelines.
//!
//! Exit codes: 0 success; 2 bad input (invalid file, bad argument, unreachable target), with one
//! clear line per problem on stderr and nothing written; 3 a run ended on a physics fault (the
//! other runs and the table written); 130 interrupted; 1 any other failure.

mod cli;

/// mimalloc keeps the memory it frees for the next allocation of its size, where glibc's malloc
/// gave a capture's and a recognition's megabyte buffers back to the system and page-faulted them
/// in again at every capture. By default it still purges (gives back) freed pages 1 s after they
/// fall free: see [`keep_freed_pages`].
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc v3's `mi_option_purge_delay` (its `mimalloc.h`, `mi_option_e`; libmimalloc-sys does
/// not name it).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Tells mimalloc never to give freed pages back to the system: a run frees and allocates the
/// same megabyte buffers at every capture, and each purge had the kernel zero those pages again
/// on their next use (3.5 % of the one-core batch's profile in the kernel's page clearing). The
/// cost: the process keeps its high-water mark (the README's batch peaked 164 MiB against 156).
fn keep_freed_pages() {
    // SAFETY: sets one of mimalloc's options, before any thread but this one exists.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
}

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

use binpick::config::ConfigError;
use cli::{InputError, Interrupted, RunsFailed};

/// A digital twin of a robotic bin-picking cell (OMRON Viper s650).
#[derive(Parser)]
#[command(
    name = "binpick",
    version,
    about,
    long_about = None,
    max_term_width = 110,
    after_help = "Exit codes: 0 success; 2 bad input (nothing written); 3 a run of run, batch or sweep ended on a physics fault (the other runs, the failed run up to its fault and the table are written, the failed run marked); 130 interrupted; 1 any other failure."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Validate scene (.toml with [robot]), workpiece (.toml) and URDF (.urdf) files.
    ///
    /// A valid workpiece is warned about where it will not be picked well: no face for the cup,
    /// one up in under 5 % of its resting poses, turns the sensor cannot tell apart, too flat to see.
    Check {
        /// Files to check.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Scene that workpieces are checked against (default: the embedded default cell).
        #[arg(long)]
        scene: Option<PathBuf>,
    },
    /// Interrogate the simulated robot.
    Robot {
        #[command(subcommand)]
        command: cli::robot::RobotCommand,
        /// Scene file (default: the embedded default cell).
        #[arg(long, global = true)]
        scene: Option<PathBuf>,
        /// Machine-readable JSON output.
        #[arg(long, global = true)]
        json: bool,
    },
    /// A part's model before a run: its faces and cup-fit regions, stable poses, an SVG picture.
    Part(cli::part::PartArgs),
    /// Build and settle a random pile of one workpiece type in the pick tray.
    Pile(cli::pile::PileArgs),
    /// Build a pile, take a depth capture, recognise the parts and select a grasp.
    Sense(cli::pile::SenseArgs),
    /// One cell run: picks of one workpiece end to end, timed; results, time charts and the run's
    /// recordings (`run.rrd` for Rerun, `run.mcap` for Foxglove) in the run folder.
    Run(cli::run::RunArgs),
    /// The takt-time table: cell runs of several workpieces and seeds in parallel, one row per
    /// workpiece (the reference system's Table 5, from the simulation).
    Batch(cli::batch::BatchArgs),
    /// What-if sweeps: the takt table over variants of the cell and workpiece files
    /// (`--set KEY=V1,V2,...`), one row per variant and workpiece, with a chart.
    Sweep(cli::sweep::SweepArgs),
    /// The cell's settings for one workpiece chosen by an optimizer (`--vary KEY=LO:HI`), judged
    /// on test seeds it never evaluated, beside the untuned cell.
    Tune(cli::tune::TuneArgs),
    /// Joins the results of a batch's or a sweep's shards (`--shard K/N`) into the one table.
    Merge {
        /// The shards' folders (each holding a takt.json, or a sweep.json).
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        #[command(flatten)]
        out: cli::OutArgs,
    },
    /// A box or compound workpiece's primitives as a mesh part: `<name>.stl` and a workpiece
    /// file `<name>-mesh.toml` of `kind = "mesh"`, to run a built-in part as CAD.
    ExportMesh(cli::export::ExportMeshArgs),
    /// Benchmarks: our code beside a baseline doing the same work.
    Bench {
        #[command(subcommand)]
        command: cli::bench::BenchCommand,
    },
}

fn main() -> ExitCode {
    keep_freed_pages();
    let cli = Cli::parse();
    match dispatch(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if let Some(c) = e.downcast_ref::<ConfigError>() {
                eprintln!("{c}");
                ExitCode::from(2)
            } else if let Some(i) = e.downcast_ref::<binpick::physics::ShapeError>() {
                eprintln!("{i}");
                ExitCode::from(2)
            } else if let Some(i) = e.downcast_ref::<InputError>() {
                eprintln!("error: {i}");
                ExitCode::from(2)
            } else if let Some(f) = e.downcast_ref::<RunsFailed>() {
                eprintln!("error: {f}");
                ExitCode::from(3)
            } else if let Some(i) = e.downcast_ref::<Interrupted>() {
                eprintln!("{i}");
                ExitCode::from(130)
            } else {
                eprintln!("error: {e:#}");
                ExitCode::from(1)
            }
        }
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Check { files, scene } => cli::check::check(&files, scene.as_deref()),
        Command::Robot { command, scene, json } => cli::robot::run(command, scene.as_deref(), json),
        Command::Part(a) => cli::part::part(&a),
        Command::Pile(a) => cli::pile::pile(&a),
        Command::Sense(a) => cli::pile::sense(&a),
        Command::Run(a) => cli::run::run(&a),
        Command::Batch(a) => cli::batch::batch(&a),
        Command::Sweep(a) => cli::sweep::sweep(&a),
        Command::Tune(a) => cli::tune::tune(&a),
        Command::Merge { dirs, out } => cli::study::merge(&dirs, &out.out, out.json),
        Command::ExportMesh(a) => cli::export::export_mesh(&a),
        Command::Bench { command } => cli::bench::run(command),
    }
}
