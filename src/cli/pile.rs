//! `binpick pile` and `binpick sense`: a settled pile of one workpiece; a capture of it, the
//! recognition result and the grasp the cell would choose, through the cycle's own sensing and
//! the library's sense-and-grasp pipeline.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;

use super::{InputError, load_cell};
use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::cycle::FirstPick;
use binpick::pipeline::GraspChoice;
use binpick::sensor::RecognitionReport;

/// A pile of one workpiece in a cell, and where its run folder goes.
#[derive(Args)]
pub struct PileArgs {
    /// Workpiece: A ... F (embedded) or a path to a workpiece file.
    #[arg(long)]
    pub workpiece: String,
    /// Parts to drop (default: the workpiece's pile_count).
    #[arg(long)]
    pub count: Option<usize>,
    /// Run seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Scene file (default: the embedded default cell).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Folder the run folder is written into.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Machine-readable JSON output.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `binpick sense`.
#[derive(Args)]
pub struct SenseArgs {
    #[command(flatten)]
    pub pile: PileArgs,
    /// Recognition: `cloud` (from the depth capture, the default) or `oracle` (the what-if of
    /// perfect recognition); overrides the cell file's `sensor.recognition`.
    #[arg(long, value_name = "cloud|oracle")]
    pub recognition: Option<binpick::config::RecognitionMode>,
}

/// `--count`, or the workpiece's pile count: 1 to 1000.
fn pile_count(a: &PileArgs, wp: &LoadedWorkpiece) -> Result<usize> {
    let count = a.count.unwrap_or(wp.workpiece.pile_count as usize);
    if count == 0 || count > 1000 {
        return Err(InputError(format!("--count must be within [1, 1000], got {count}")).into());
    }
    Ok(count)
}

/// A cell with a settled pile.
struct PiledCell {
    loaded: LoadedScene,
    wp: LoadedWorkpiece,
    report: binpick::physics::pile::PileReport,
    count: usize,
}

/// Loads and checks the cell and workpiece, builds the world and settles the pile as the cell
/// pours its first: a part the pour spills out of the tray is lost (`in tray` counts the rest).
fn piled_cell(a: &PileArgs) -> Result<PiledCell> {
    let (loaded, wp, robot) = load_cell(a.scene.as_deref(), &a.workpiece)?;
    let count = pile_count(a, &wp)?;
    let shape = binpick::physics::PartShape::build(&wp.workpiece, &wp.source)?;
    let mut world = binpick::physics::World::new(&loaded.scene, &robot, shape);
    let report = world
        .build_pile(&binpick::physics::pile::PileOptions::cells_first_pile(count, a.seed))
        .context("building the pile")?;
    Ok(PiledCell {
        loaded,
        wp,
        report,
        count,
    })
}

/// `binpick pile`: builds and settles a pile, writes `pile.json`.
pub fn pile(a: &PileArgs) -> Result<()> {
    let PiledCell {
        loaded,
        wp,
        report,
        count,
        ..
    } = piled_cell(a)?;
    let (seed, out, json) = (a.seed, &a.out, a.json);
    let name = format!("pile-{}-seed{seed}", wp.workpiece.name);
    let run = binpick::report::RunDir::create(out, &name)?;
    run.write_inputs(&loaded, Some(&wp))?;
    let file = json!({
        "binpick_version": env!("CARGO_PKG_VERSION"), "workpiece": wp.workpiece.name, "seed": seed, "count": count,
        "physics_dt_s": loaded.scene.sim.physics_dt_s, "report": &report,
    });
    run.write_json("pile.json", &file)?;
    let dest = run.finish()?;
    if json {
        let mut v = file;
        v["wall_s"] = json!(report.wall_s);
        v["run_dir"] = json!(dest.display().to_string());
        v["report"].as_object_mut().map(|o| o.remove("poses"));
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "pile of {count} x {} ({}), seed {seed}",
        wp.workpiece.name, wp.workpiece.kind
    );
    println!("  in tray          {} / {}", report.in_tray, report.spawned);
    println!(
        "  pile height      {:.1} mm above the tray floor",
        report.pile_height_m * 1e3
    );
    println!(
        "  settle time      {:.3} s simulated, {:.3} s wall ({} waves){}",
        report.settle_sim_s,
        report.wall_s,
        report.waves,
        if report.settled { "" } else { "  NOT SETTLED" }
    );
    println!(
        "  max penetration  {:.3} mm ({})",
        report.max_penetration_m * 1e3,
        report.max_penetration_between
    );
    println!("  wrote            {}", dest.join("pile.json").display());
    Ok(())
}

/// `binpick sense`: a pile, the cycle's first capture of it (the arm out of view, a spoiled
/// exposure repeated), the recognition result scored against the world at that moment, the grasp
/// selector's ranking ([`binpick::pipeline::sense_and_grasp`]) and the grasp the cell takes, its
/// Pick and Place motions generated ([`binpick::cycle::first_pick`]: a grasp whose motions fail
/// is passed over, as in a run).
pub fn sense(args: &SenseArgs) -> Result<()> {
    let a = &args.pile;
    use binpick::cycle::{Cell, RunOptions};
    use binpick::pipeline::{GraspContext, SensedPile, sense_and_grasp};
    let (mut loaded, wp, robot) = load_cell(a.scene.as_deref(), &a.workpiece)?;
    super::override_recognition(&mut loaded, args.recognition);
    let count = pile_count(a, &wp)?;
    let (seed, out, json) = (a.seed, &a.out, a.json);
    let opts = RunOptions::deterministic(1, seed);
    let mut cell = Cell::new(&loaded, &robot, &wp, opts).context("setting up the cell")?;
    cell.pile_count = count;
    let (state, sensed) = binpick::cycle::sense_once(&cell, &mut ()).context("sensing")?;
    let sensed = sensed.context("the arm found no path out of the sensor's view")?;
    let (job, detections) = (&sensed.job, sensed.detections.clone().unwrap_or_default());
    let world = &state.world;
    // Evaluation only: the detections against the truth at the trigger.
    let report = sensed.evaluation.clone().context("no recognition result")?;
    let t1 = std::time::Instant::now();
    let ctx = GraspContext {
        scene: &loaded.scene,
        robot: &robot,
        selector: &cell.selector,
        pick_tray: world.pick_tray(),
        part_half_extents_m: cell.shape.half_extents_m,
    };
    let pile = SensedPile::new(&ctx, &job.capture, &job.arm);
    let choice = sense_and_grasp(&ctx, &pile, &detections, &cell.slots[0], &world.joints(), &[]);
    let grasp_ms = t1.elapsed().as_secs_f64() * 1e3;
    let spoiled = state.sensor.spoiled;
    let t2 = std::time::Instant::now();
    let first = binpick::cycle::first_pick(&cell, state, &sensed);
    let motions_ms = t2.elapsed().as_secs_f64() * 1e3;
    let passed_over: Vec<String> = first.passed_over().iter().map(ToString::to_string).collect();
    let name = format!("sense-{}-seed{seed}", wp.workpiece.name);
    let run = binpick::report::RunDir::create(out, &name)?;
    run.write_inputs(&loaded, Some(&wp))?;
    job.capture
        .write_depth_png(&run.path("depth.png"))
        .context("writing depth.png")?;
    job.capture
        .write_depth_view_png(&run.path("depth-view.png"))
        .context("writing depth-view.png")?;
    job.capture
        .write_ply(&run.path("cloud.ply"))
        .context("writing cloud.ply")?;
    let file = json!({
        "binpick_version": env!("CARGO_PKG_VERSION"), "workpiece": wp.workpiece.name, "seed": seed, "count": count,
        "capture": {"trigger_s": job.capture.trigger_s, "ready_s": job.ready_s, "width_px": job.capture.width_px,
                    "height_px": job.capture.height_px, "valid_px": job.capture.valid_count(),
                    "spoiled_before": spoiled},
        "recognition": &report, "recognition_mode": loaded.scene.sensor.recognition.name(),
        "detections": &detections,
        "detections_truth": &report.matches,
        "top_layer_truth": top_layer_truth(&job.truth, &report),
        "grasp": {"chosen": first.taken(), "passed_over": passed_over, "why_none": why_none(&first),
                  "ranked": choice.plan.ranked.len(), "rejected": choice.plan.rejected_counts()},
    });
    run.write_json("sense.json", &file)?;
    let dest = run.finish()?;
    if json {
        let mut v = file;
        v["timing_ms"] =
            json!({"recognition": sensed.recognition_wall_s * 1e3, "grasp": grasp_ms, "motions": motions_ms});
        v["run_dir"] = json!(dest.display().to_string());
        v.as_object_mut().map(|o| o.remove("detections"));
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "pile of {count} x {}, seed {seed}: capture at t = {:.3} s, result at {:.3} s",
        wp.workpiece.name, job.capture.trigger_s, job.ready_s
    );
    println!(
        "  capture          {} x {} px, {} returns; {} spoiled exposure(s) repeated",
        job.capture.width_px,
        job.capture.height_px,
        job.capture.valid_count(),
        spoiled
    );
    print_recognition(&loaded, &report, sensed.recognition_wall_s);
    print_grasp(&choice, &first, grasp_ms, motions_ms);
    println!("  wrote            {}", dest.display());
    Ok(())
}

/// The text lines of the recognition result against the truth (evaluation only).
fn print_recognition(loaded: &LoadedScene, report: &RecognitionReport, recognition_wall_s: f64) {
    row(
        "recognition",
        &format!(
            "{} ({:.1} ms): {} detected, {} correct (precision {}); top layer {} / {} found (recall {}); {} parts in the tray",
            loaded.scene.sensor.recognition.name(),
            recognition_wall_s * 1e3,
            report.figures.detected,
            report.figures.correct,
            super::percent(report.figures.precision),
            report.figures.top_layer_found,
            report.figures.top_layer,
            super::percent(report.figures.recall),
            report.parts,
        ),
    );
    row(
        "pose error",
        &format!("of the correct ones, {}", super::pose_errors_text(&report.figures)),
    );
}

/// Why the cell takes no grasp (none if it takes one).
fn why_none(first: &FirstPick) -> Option<String> {
    match first {
        FirstPick::Taken { .. } => None,
        FirstPick::NothingDetected => Some("nothing detected".into()),
        FirstPick::NoGrasp(why) => Some(why.to_string()),
        FirstPick::NoMotion(_) => Some("no motions for any grasp tried".into()),
    }
}

/// The text lines of the grasp the cell takes (`first`) and those it passed over, the selector's
/// candidates (`choice`) and the time the grasp selection and the motions took.
fn print_grasp(choice: &GraspChoice, first: &FirstPick, grasp_ms: f64, motions_ms: f64) {
    for (i, why) in first.passed_over().iter().enumerate() {
        row("passed over", &format!("grasp {} of those tried: {why}", i + 1));
    }
    match first.taken() {
        Some(g) => {
            let p = g.world_from_tool.translation.vector;
            row(
                "chosen grasp",
                &format!(
                    "detection {} face {}: tool at ({:.4}, {:.4}, {:.4}) m, score {:.3} (exposure {:.2}, clearance {:.1} mm, success {:.2}, place motion {:.3} s)",
                    g.detection,
                    g.face,
                    p.x,
                    p.y,
                    p.z,
                    g.score.total,
                    g.score.exposure,
                    g.score.clearance_m * 1e3,
                    g.score.success,
                    g.score.motion_s
                ),
            );
        }
        None => row(
            "chosen grasp",
            &format!("none: {}", why_none(first).unwrap_or_default()),
        ),
    }
    let counts: Vec<String> = choice
        .plan
        .rejected_counts()
        .iter()
        .map(|(k, v)| format!("{k} {v}"))
        .collect();
    row(
        "candidates",
        &format!(
            "{} feasible; rejected: {}",
            choice.plan.ranked.len(),
            if counts.is_empty() {
                "none".into()
            } else {
                counts.join(", ")
            }
        ),
    );
    row(
        "sense and grasp",
        &format!(
            "{grasp_ms:.2} ms wall (height map, candidates, IK, ranking, clear approach); the motions {motions_ms:.1} ms"
        ),
    );
}

/// The column where a row's text starts, after its two-space indent and its label.
const ROW_TEXT_COLUMN: usize = 19;

/// Prints a row of the text output: `label` in its column, then `text`, wrapped within the
/// terminal's width under its first line.
fn row(label: &str, text: &str) {
    super::say_under(&format!("  {label}"), ROW_TEXT_COLUMN, text);
}

/// Evaluation only: each top-layer part at the trigger (its pose, its visible pixels, and whether
/// a correct detection found it), so a reader of `sense.json` can see which parts were missed.
fn top_layer_truth(
    truth: &binpick::sensor::recognition::TruthAtTrigger,
    report: &binpick::sensor::recognition::RecognitionReport,
) -> serde_json::Value {
    let found: std::collections::BTreeSet<usize> = report
        .matches
        .iter()
        .flatten()
        .filter(|m| m.correct)
        .map(|m| m.part)
        .collect();
    truth
        .top_layer
        .iter()
        .map(|&i| {
            let p = &truth.world_from_part[i];
            let q = p.rotation.quaternion();
            json!({"part": i, "visible_px": truth.visible_px[i], "found": found.contains(&i),
                   "position_m": [p.translation.x, p.translation.y, p.translation.z],
                   "rotation_xyzw": [q.i, q.j, q.k, q.w]})
        })
        .collect()
}
