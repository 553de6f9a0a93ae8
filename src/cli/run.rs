//! `binpick run`: one cell run end to end; the per-pick table and the summary on stdout; the
//! run folder with `picks.csv`, `summary.json`, `events.json`, the time charts, the recordings
//! and the resolved inputs.

use anyhow::Result;
use clap::Args;
use serde_json::json;

use super::{
    CellArgs, Interrupted, ModeArgs, OutArgs, RunsFailed, SkipFormats, check_picks, load_workpiece, stop_on_ctrl_c,
};
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
    #[command(flatten)]
    pub mode: ModeArgs,
    #[command(flatten)]
    pub cell: CellArgs,
    #[command(flatten)]
    pub out: OutArgs,
    #[command(flatten)]
    pub skip: SkipFormats,
}

/// `binpick run`: one cell run; prints the per-pick table and the summary, writes the run folder.
pub fn run(a: &RunArgs) -> Result<()> {
    check_picks(a.picks)?;
    let (loaded, robot) = a.cell.load()?;
    let wp = load_workpiece(&a.workpiece, &loaded, &robot)?;
    // The cell with the workpiece's own cup, if it brings one: the run, its recordings and the
    // resolved scene written beside it all show the one tool.
    let loaded = loaded.for_workpiece(&wp);
    let (seed, deterministic, out, json) = (a.seed, a.mode.deterministic, a.out.out.as_path(), a.out.json);
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
    let name = format!(
        "run-{}-seed{seed}{}",
        wp.workpiece.name,
        if deterministic { "-det" } else { "" }
    );
    // The run folder first: the recordings stream into it as the run goes.
    let run = binpick::report::RunDir::create(out, &name)?;
    let mut recorder = match formats.any() {
        true => {
            let info = binpick::recording::RunInfo {
                scene: loaded.label.clone(),
                workpiece: wp.workpiece.name.clone(),
                seed,
                deterministic,
                picks: a.picks,
                robot_description: loaded.urdf_text.clone(),
            };
            let files =
                binpick::recording::RecordingFiles::create(run.staging_dir(), "run", formats, &loaded.scene, &info)
                    .map_err(|(path, e)| anyhow::anyhow!("writing {}: {e}", path.display()))?;
            let pick_tray = binpick::geometry::TrayVolume::new(&loaded.scene.pick_tray);
            Some(Recorder::streaming(
                &robot,
                &camera,
                &pick_tray,
                wp.workpiece.size_m,
                files,
            ))
        }
        false => None,
    };
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
    run.write_inputs(&loaded, Some(&wp))?;
    run.write("picks.csv", binpick::report::picks_csv(&result.records))?;
    let summary = binpick::results::Summary::of(&result.tally);
    let run_summary = binpick::results::RunSummary {
        summary: &summary,
        deterministic,
        per_capture: &result.recognition_per_capture,
    };
    run.write_json("summary.json", &run_summary)?;
    run.write_json("events.json", &log.into_sorted())?;
    let title = format!("binpick run: workpiece {}, seed {seed}", wp.workpiece.name);
    let releases: Vec<f64> = result.records.iter().filter_map(|r| r.release_s).collect();
    let (whole, steady) = chart.svgs(&title, result.tally.sim_time_s, &releases);
    run.write("timechart.svg", whole)?;
    if let Some(steady) = steady {
        run.write("timechart-steady.svg", steady)?;
    }
    if let Some(recorder) = recorder {
        recorder
            .finish_files()
            .map_err(|(path, e)| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    }
    let dest = run.finish()?;
    let done = || -> Result<()> {
        match summary.tally.ended {
            Some(EndReason::Interrupted) => Err(Interrupted(dest.display().to_string()).into()),
            _ => RunsFailed::of([&summary.tally], &dest.display().to_string()).map_or(Ok(()), |f| Err(f.into())),
        }
    };
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &json!({"summary": run_summary, "wall_s": wall_s, "run_dir": dest.display().to_string()})
            )?
        );
        return done();
    }
    print!("{}", binpick::report::picks_table(&result.records));
    print_summary(&summary, loaded.scene.sensor.recognition.name(), wall_s);
    println!("wrote {}", dest.display());
    done()
}

/// A duration for the summary line: "-" where there is none (never `NaN`).
fn seconds(v: f64) -> String {
    if v.is_finite() { format!("{v:.3} s") } else { "-".into() }
}

/// The takt's statistics, or what there is instead: with fewer than two parts placed there is no
/// release-to-release interval, and the line says so and which faults the picks ended in.
fn takt_text(s: &binpick::results::Summary) -> String {
    let t = &s.takt;
    if t.count > 0 {
        return format!(
            "mean {:.3} s, p95 {:.3}, min {:.3}, max {:.3} over {} intervals",
            t.mean_s, t.p95_s, t.min_s, t.max_s, t.count
        );
    }
    let why = binpick::results::table::no_takt_why(s).unwrap_or_default();
    format!("none ({why}; each pick's reason is in picks.csv)")
}

/// Where the takt goes: each cause's share of the mean takt (they add up to it) and its
/// intervals.
fn takt_by_cause_text(s: &binpick::results::Summary) -> String {
    use binpick::cycle::IntervalCause;
    let c = &s.tally.takt_causes;
    let what = |cause: IntervalCause| match cause {
        IntervalCause::Clean => "clean cycles",
        IntervalCause::Failed => "after failed attempts",
        IntervalCause::Dose => "hopper doses",
        IntervalCause::Refill => "tray refills",
    };
    let parts: Vec<String> = IntervalCause::ALL
        .iter()
        .map(|&cause| {
            format!(
                "{} {:.3} s ({} intervals)",
                what(cause),
                c.share_s(cause),
                c.count(cause)
            )
        })
        .collect();
    format!("takt by cause (shares of the mean): {}", parts.join(", "))
}

/// Prints a run's summary: takt, success, waits, faults, the servo's figures, recognition.
fn print_summary(s: &binpick::results::Summary, recognition: &str, wall_s: f64) {
    use binpick::report::wrap;
    use binpick::results::table::TERMINAL_WIDTH;
    let t = &s.tally;
    let summary = format!(
        "{} of {} attempts placed, {} of them misplaced: success {:.1} %; takt (release to release, everything included, as the reference \
         defines it) {} (reference {}); excluding \
         tray refills {}; Pick {}, Place {} (motion floor {}); waits: sensor {} ({:.2} s), compute {} ({:.2} s); \
         stops {}, collisions {}, drops {}, parts lost {}; captures {} ({} spoiled), agitations {}, refills {}; \
         peak torque demand {:.0} % of a limit, saturated {:.3} s, max tracking error {:.3} deg; \
         {:.1} s simulated in {:.2} s wall ({:.0}x real time)",
        t.placed,
        t.attempts,
        s.placement.misplaced,
        100.0 * s.success_rate,
        takt_text(s),
        s.reference_takt_s.map_or("-".to_string(), |t| format!("{t:.1} s")),
        seconds(s.takt_excl_refills.mean_s),
        seconds(s.mean_pick_s),
        seconds(s.mean_place_s),
        seconds(s.mean_pick_s + s.mean_place_s),
        t.sensor_waits.count,
        t.sensor_waits.total_s,
        t.compute_waits.count,
        t.compute_waits.total_s,
        t.faults.protective_stops,
        t.faults.collisions,
        t.faults.drops,
        t.faults.parts_lost,
        t.captures.0,
        t.captures.1,
        t.agitations,
        t.refills,
        100.0 * s.peak_demand_ratio(),
        t.saturated_s,
        t.max_tracking_error_deg,
        t.sim_time_s,
        wall_s,
        t.sim_time_s / wall_s
    );
    println!("{}", wrap(&summary, TERMINAL_WIDTH));
    if s.takt.count > 0 {
        println!("{}", wrap(&takt_by_cause_text(s), TERMINAL_WIDTH));
    }
    let r = &s.recognition;
    let recognised = format!(
        "recognition ({}), against the truth at each trigger: top layer {} / {} found (recall {}), \
         {} of {} detections correct (precision {}; correct = within 2 mm and 5 deg), pose error {}; \
         grasps sealed {} / {}, misrecognised {}",
        recognition,
        r.top_layer_found,
        r.top_layer,
        super::percent(r.recall),
        r.correct,
        r.detected,
        super::percent(r.precision),
        super::pose_errors_text(r),
        t.grasps.1,
        t.grasps.0,
        t.misrecognised
    );
    println!("{}", wrap(&recognised, TERMINAL_WIDTH));
    let p = &s.placement;
    if p.measured > 0 {
        let placed = format!(
            "placement, against each part's place pose: {} measured, error median {:.2} mm / {:.2} deg, \
             p95 {:.2} mm / {:.2} deg; misplaced (beyond the place tray's tolerance, failed attempts) {}",
            p.measured,
            p.position_error_mm[0],
            p.rotation_error_deg[0],
            p.position_error_mm[1],
            p.rotation_error_deg[1],
            p.misplaced
        );
        println!("{}", wrap(&placed, TERMINAL_WIDTH));
    }
    print!("{}", binpick::results::table::incident_note(&t.workpiece, s));
}

#[cfg(test)]
mod tests {
    use binpick::results::{Faults, Summary, Tally};

    /// A run that placed nothing says so, and which faults its picks ended in; never `NaN`.
    /// Negative control: a run with intervals prints their statistics.
    #[test]
    fn a_run_with_nothing_placed_says_so_without_nan() {
        let none = Summary::of(&Tally {
            workpiece: "C".into(),
            runs: 1,
            attempts: 3,
            faults: Faults {
                drops: 3,
                ..Faults::default()
            },
            ..Tally::default()
        });
        let text = super::takt_text(&none);
        assert!(text.contains("nothing placed") && text.contains("3 drops"), "{text}");
        assert!(!text.contains("NaN") && super::seconds(none.mean_pick_s) == "-");
        let some = Summary::of(&Tally {
            workpiece: "E".into(),
            runs: 1,
            attempts: 3,
            placed: 3,
            takts_s: vec![1.5, 1.25],
            ..Tally::default()
        });
        let text = super::takt_text(&some);
        assert!(
            text.contains("mean 1.375 s") && text.contains("over 2 intervals"),
            "{text}"
        );
    }
}
