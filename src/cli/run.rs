//! `binpick run`: one cell run end to end; the per-pick table and the summary on stdout; the
//! run folder with `picks.csv`, `summary.json`, `events.json`, the time charts, the recordings
//! and the resolved inputs.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::json;

use super::{Interrupted, SkipFormats, check_picks, load_cell, stop_on_ctrl_c};
use binpick::chart::TimeChart;
use binpick::cycle::{EndReason, EventLog, Observer, Observers, RunOptions};
use binpick::recording::Recorder;

/// Arguments of `binpick run`.
#[derive(Args)]
pub struct RunArgs {
    /// Workpiece: A ... F (embedded) or a path to a workpiece file.
    #[arg(long)]
    pub workpiece: String,
    /// Picks to attempt.
    #[arg(long, default_value_t = 20)]
    pub picks: usize,
    /// Run seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Charge the cell file's fixed compute budgets instead of measured wall time, so the
    /// same seed gives byte-identical results.
    #[arg(long)]
    pub deterministic: bool,
    /// Recognition: `cloud` (from the depth capture, the default) or `oracle` (the what-if of
    /// perfect recognition); overrides the cell file's `sensor.recognition`.
    #[arg(long, value_name = "cloud|oracle")]
    pub recognition: Option<binpick::config::RecognitionMode>,
    /// Scene file (default: the embedded default cell).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Folder the run folder is written into.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    #[command(flatten)]
    pub skip: SkipFormats,
    /// Machine-readable JSON output.
    #[arg(long)]
    pub json: bool,
}

/// `binpick run`: one cell run; prints the per-pick table and the summary, writes the run folder.
pub fn run(a: &RunArgs) -> Result<()> {
    check_picks(a.picks)?;
    let (mut loaded, wp, robot) = load_cell(a.scene.as_deref(), &a.workpiece)?;
    super::override_recognition(&mut loaded, a.recognition);
    let (seed, deterministic, out, json) = (a.seed, a.deterministic, a.out.as_path(), a.json);
    let formats = a.skip.formats(true);
    let opts = RunOptions {
        picks: a.picks,
        seed,
        deterministic,
        stop: Some(stop_on_ctrl_c()),
        keep_records: true,
    };
    let camera = binpick::sensor::Camera::from_config(&loaded.scene.sensor)
        .ok_or_else(|| anyhow::anyhow!("the sensor's pose is degenerate"))?;
    let mut log = EventLog::default();
    let mut chart = TimeChart::default();
    let mut recorder = formats
        .any()
        .then(|| Recorder::new(&robot, camera, wp.workpiece.size_m));
    let wall = std::time::Instant::now();
    let result = {
        let mut watchers: Vec<&mut dyn Observer> = vec![&mut log, &mut chart];
        if let Some(r) = recorder.as_mut() {
            watchers.push(r);
        }
        binpick::cycle::run(&loaded, &robot, &wp, &opts, &mut Observers(watchers))
            .map_err(|e| anyhow::anyhow!("cell run failed: {e}"))?
    };
    let wall_s = wall.elapsed().as_secs_f64();
    let name = format!(
        "run-{}-seed{seed}{}",
        wp.workpiece.name,
        if deterministic { "-det" } else { "" }
    );
    let run = binpick::report::RunDir::create(out, &name)?;
    run.write_inputs(&loaded, Some(&wp))?;
    run.write("picks.csv", binpick::report::picks_csv(&result.records))?;
    run.write_json("summary.json", &result.summary)?;
    run.write_json("events.json", &log.into_sorted())?;
    let title = format!("binpick run: workpiece {}, seed {seed}", wp.workpiece.name);
    let releases: Vec<f64> = result.records.iter().filter_map(|r| r.release_s).collect();
    let (whole, steady) = chart.svgs(&title, result.summary.sim_time_s, &releases);
    run.write("timechart.svg", whole)?;
    if let Some(steady) = steady {
        run.write("timechart-steady.svg", steady)?;
    }
    if let Some(recorder) = recorder {
        let info = binpick::recording::RunInfo {
            scene: loaded.label.clone(),
            workpiece: wp.workpiece.name.clone(),
            seed,
            deterministic,
            picks: a.picks,
        };
        binpick::recording::write_recordings(
            run.staging_dir(),
            "run",
            formats,
            &recorder.finish(&result),
            &robot,
            &loaded.scene,
            &info,
        )
        .map_err(|(path, e)| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    let dest = run.finish()?;
    let s = &result.summary;
    let done = || -> Result<()> {
        match s.ended {
            EndReason::Interrupted => Err(Interrupted(dest.display().to_string()).into()),
            _ => Ok(()),
        }
    };
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &json!({"summary": s, "wall_s": wall_s, "run_dir": dest.display().to_string()})
            )?
        );
        return done();
    }
    print!("{}", binpick::report::picks_table(&result.records));
    println!(
        "{} of {} attempts placed ({:.1} %); takt (release to release, everything included, as the reference \
         defines it) mean {:.3} s, p95 {:.3}, min {:.3}, max {:.3} over {} intervals (reference {}); excluding \
         tray refills {:.3} s; Pick {:.3} s, Place {:.3} s (motion floor {:.3} s); waits: sensor {} ({:.2} s), compute {} ({:.2} s); \
         stops {}, collisions {}, drops {}, parts lost {}; captures {} ({} spoiled), agitations {}, refills {}; \
         peak torque demand {:.0} % of a limit, saturated {:.3} s, max tracking error {:.3} deg; \
         {:.1} s simulated in {:.2} s wall ({:.0}x real time)",
        s.placed,
        s.attempts,
        100.0 * s.success_rate,
        s.takt.mean_s,
        s.takt.p95_s,
        s.takt.min_s,
        s.takt.max_s,
        s.takt.count,
        s.reference_takt_s.map_or("-".to_string(), |t| format!("{t:.1} s")),
        s.takt_excl_refills.mean_s,
        s.mean_pick_s,
        s.mean_place_s,
        s.mean_pick_s + s.mean_place_s,
        s.sensor_stalls.0,
        s.sensor_stalls.1,
        s.compute_stalls.0,
        s.compute_stalls.1,
        s.protective_stops,
        s.collisions,
        s.drops,
        s.parts_lost,
        s.captures.0,
        s.captures.1,
        s.agitations,
        s.refills,
        100.0 * s.peak_demand_ratio.iter().cloned().fold(0.0, f64::max),
        s.saturated_s,
        s.max_tracking_error_deg,
        s.sim_time_s,
        wall_s,
        s.sim_time_s / wall_s
    );
    let r = &s.recognition;
    println!(
        "recognition ({}), against the truth at each trigger: top layer {} / {} found (recall {:.1} %), \
         {} of {} detections correct (precision {:.1} %; correct = within 2 mm and 5 deg), pose error median \
         {:.2} mm / {:.2} deg, p95 {:.2} mm / {:.2} deg; grasps sealed {} / {}, misrecognised {}",
        loaded.scene.sensor.recognition.name(),
        r.top_layer_found,
        r.top_layer,
        100.0 * r.recall,
        r.correct,
        r.detected,
        100.0 * r.precision,
        r.position_error_mm[0],
        r.rotation_error_deg[0],
        r.position_error_mm[1],
        r.rotation_error_deg[1],
        s.grasps.1,
        s.grasps.0,
        s.misrecognised
    );
    println!("wrote {}", dest.display());
    done()
}
