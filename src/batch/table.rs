//! Report stage, the takt-time table: what a batch keeps of each run, the table over them,
//! written as Markdown and CSV, and the merge of shards.
//!
//! Job: keep per run the values the table needs ([`RunEntry`]), so shards of a batch run on
//! different machines merge into the same table as the whole batch would give; one row per
//! workpiece over all its seeds: the takt as the reference defines it (mean, p95, min, max of
//! every release-to-release interval after a run's first release, failures, re-captures, waits
//! and refills included) beside the reference's Table 5, the takt excluding the intervals that
//! span a tray refill (a labelled side figure), success (placed / attempts, re-captures
//! counted), waits, faults, mean Pick and Place times, compute per stage, and what the servo
//! was asked for: the peak demanded torque, the time saturated, the largest tracking error.
//!
//! Units: s (ms in the Markdown's compute columns), counts. Rows are in workpiece order as given.

use serde::{Deserialize, Serialize};

use super::{BatchError, BatchSpec};
use crate::cycle::{RunResult, TaktStats};
use crate::report::{Fixed, to_csv};
use crate::sensor::{RecognitionSummary, RecognitionTotals};

/// What the table keeps of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunEntry {
    /// Workpiece.
    pub workpiece: String,
    /// Seed.
    pub seed: u64,
    /// Attempts: every pick, re-captures included.
    pub attempts: usize,
    /// Picks placed.
    pub placed: usize,
    /// Picks the arm set out to make (a grasp chosen, motions generated).
    pub set_out: usize,
    /// Every release-to-release interval after the first release [s] (the reference's takt).
    pub takts_s: Vec<f64>,
    /// The intervals that span no pick-tray refill [s].
    pub takts_excl_refills_s: Vec<f64>,
    /// Pick times of the placed picks [s].
    pub pick_s: Vec<f64>,
    /// Place times of the placed picks [s].
    pub place_s: Vec<f64>,
    /// Compute charged per pick set out, summed: grasp, Pick, Place [s].
    pub compute_sum_s: [f64; 3],
    /// Compute between each pick's result and the motion it unblocks (grasp and Pick), per
    /// pick set out [s].
    #[serde(default)]
    pub result_to_motion_s: Vec<f64>,
    /// Waits for the sensor in the takts: count and total [s].
    pub sensor_waits: (usize, f64),
    /// Waits for compute in the takts: count and total [s].
    pub compute_waits: (usize, f64),
    /// Protective stops, collisions, drops, grasp failures, parts lost.
    pub faults: [usize; 5],
    /// Refills of the pick tray.
    pub refills: usize,
    /// Agitations of the pick tray.
    #[serde(default)]
    pub agitations: usize,
    /// Grasps attempted (the cup reached the part) and sealed.
    #[serde(default)]
    pub grasps: (usize, usize),
    /// Grasp failures on a wrong detection.
    #[serde(default)]
    pub misrecognised: usize,
    /// Blind picks: attempted, placed.
    #[serde(default)]
    pub blind_picks: (usize, usize),
    /// Recognition results the picks set out came from.
    #[serde(default)]
    pub results_used: usize,
    /// Recognition of the results the run used, against the truth at each trigger.
    #[serde(default)]
    pub recognition: RecognitionTotals,
    /// Largest |demanded torque| / limit per joint (before saturation).
    pub peak_demand_ratio: [f64; 6],
    /// Time some joint was saturated [s].
    pub saturated_s: f64,
    /// Largest servo tracking error [deg].
    pub max_tracking_error_deg: f64,
    /// Simulated time [s].
    pub sim_time_s: f64,
    /// Wall time of the run [s]: a measurement, not a result, so a deterministic batch's
    /// `takt.json` leaves it out (`None`) and repeats byte for byte.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_s: Option<f64>,
    /// Why the run ended.
    pub ended: String,
}

impl RunEntry {
    /// From a finished run.
    pub fn from_run(r: &RunResult, wall_s: Option<f64>) -> Self {
        let (s, t) = (&r.summary, &r.tally);
        RunEntry {
            workpiece: s.workpiece.clone(),
            seed: s.seed,
            attempts: s.attempts,
            placed: s.placed,
            set_out: t.set_out,
            takts_s: t.takts_s.clone(),
            takts_excl_refills_s: t.takts_excl_refills_s.clone(),
            pick_s: t.pick_s.clone(),
            place_s: t.place_s.clone(),
            compute_sum_s: t.compute_sum_s,
            result_to_motion_s: t.result_to_motion_s.clone(),
            sensor_waits: s.sensor_stalls,
            compute_waits: s.compute_stalls,
            faults: [s.protective_stops, s.collisions, s.drops, t.faults[3], s.parts_lost],
            refills: s.refills,
            agitations: s.agitations,
            grasps: s.grasps,
            misrecognised: s.misrecognised,
            blind_picks: s.blind_picks,
            results_used: s.results_used,
            recognition: t.recognition.clone(),
            peak_demand_ratio: s.peak_demand_ratio,
            saturated_s: s.saturated_s,
            max_tracking_error_deg: s.max_tracking_error_deg,
            sim_time_s: s.sim_time_s,
            wall_s,
            ended: s.ended.text().to_string(),
        }
    }
}

/// One row of the takt-time table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// Workpiece.
    pub workpiece: String,
    /// Runs.
    pub runs: usize,
    /// Attempts: every pick, re-captures included.
    pub attempts: usize,
    /// Picks placed.
    pub placed: usize,
    /// placed / attempts.
    pub success_rate: f64,
    /// Takt as the reference defines it, over all runs' release-to-release intervals.
    pub takt: TaktStats,
    /// The same leaving out the intervals that span a pick-tray refill (a side figure).
    pub takt_excl_refills: TaktStats,
    /// The reference system's takt [s] (its Table 5).
    pub reference_takt_s: Option<f64>,
    /// Mean Pick time [s].
    pub mean_pick_s: f64,
    /// Mean Place time [s].
    pub mean_place_s: f64,
    /// The physical floor [s]: the takt with instantaneous sensing and compute, motion time only
    /// (mean Pick + Place of the placed picks).
    pub motion_floor_s: f64,
    /// Mean compute per pick set out: grasp, Pick, Place [s].
    pub mean_compute_s: [f64; 3],
    /// Median compute between a pick's result and the motion it unblocks (grasp and Pick) [s].
    pub median_result_to_motion_s: f64,
    /// Waits for the sensor: count, mean [s].
    pub sensor_waits: (usize, f64),
    /// Waits for compute: count, mean [s].
    pub compute_waits: (usize, f64),
    /// Protective stops.
    pub protective_stops: usize,
    /// Collisions.
    pub collisions: usize,
    /// Drops.
    pub drops: usize,
    /// Grasp failures.
    pub grasp_failures: usize,
    /// Parts lost.
    pub parts_lost: usize,
    /// Refills.
    pub refills: usize,
    /// Agitations.
    pub agitations: usize,
    /// Grasps attempted (the cup reached the part) and sealed, all runs.
    pub grasps: (usize, usize),
    /// sealed / attempted.
    pub grasp_success_rate: f64,
    /// Grasp failures on a wrong detection.
    pub misrecognised: usize,
    /// Blind picks: attempted, placed.
    pub blind_picks: (usize, usize),
    /// Picks set out per recognition result they came from.
    pub picks_per_capture: f64,
    /// Recognition over every result the runs used, against the truth at each trigger.
    pub recognition: RecognitionSummary,
    /// Largest |demanded torque| / limit over every joint and run (before saturation).
    pub peak_demand_ratio: f64,
    /// Time some joint was saturated, all runs [s].
    pub saturated_s: f64,
    /// Largest servo tracking error [deg].
    pub max_tracking_error_deg: f64,
    /// Simulated time, all runs [s].
    pub sim_time_s: f64,
    /// Wall time, all runs [s] (`None` if a run's is not known).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wall_s: Option<f64>,
}

/// The table: one row per workpiece (in `order`), over every entry of that workpiece.
pub fn table(order: &[String], entries: &[RunEntry]) -> Vec<Row> {
    order
        .iter()
        .filter_map(|w| {
            let es: Vec<&RunEntry> = entries.iter().filter(|e| &e.workpiece == w).collect();
            if es.is_empty() {
                return None;
            }
            let cat = |f: fn(&RunEntry) -> &Vec<f64>| es.iter().flat_map(|e| f(e).iter().copied()).collect::<Vec<_>>();
            let attempts: usize = es.iter().map(|e| e.attempts).sum();
            let placed: usize = es.iter().map(|e| e.placed).sum();
            let set_out: usize = es.iter().map(|e| e.set_out).sum();
            let waits = |f: fn(&RunEntry) -> (usize, f64)| {
                let (n, t) = es.iter().map(|e| f(e)).fold((0, 0.0), |(n, t), (a, b)| (n + a, t + b));
                (n, if n == 0 { 0.0 } else { t / n as f64 })
            };
            let fault = |i: usize| es.iter().map(|e| e.faults[i]).sum();
            let blind_picks = es
                .iter()
                .fold((0, 0), |(a, b), e| (a + e.blind_picks.0, b + e.blind_picks.1));
            let grasps = es.iter().fold((0, 0), |(a, b), e| (a + e.grasps.0, b + e.grasps.1));
            let compute = |i: usize| {
                if set_out == 0 {
                    f64::NAN
                } else {
                    es.iter().map(|e| e.compute_sum_s[i]).sum::<f64>() / set_out as f64
                }
            };
            Some(Row {
                workpiece: w.clone(),
                runs: es.len(),
                attempts,
                placed,
                success_rate: if attempts == 0 {
                    f64::NAN
                } else {
                    placed as f64 / attempts as f64
                },
                takt: TaktStats::of(&cat(|e| &e.takts_s)),
                takt_excl_refills: TaktStats::of(&cat(|e| &e.takts_excl_refills_s)),
                reference_takt_s: crate::reference::reference_takt(w),
                mean_pick_s: crate::stats::mean(&cat(|e| &e.pick_s)),
                mean_place_s: crate::stats::mean(&cat(|e| &e.place_s)),
                motion_floor_s: crate::stats::mean(&cat(|e| &e.pick_s)) + crate::stats::mean(&cat(|e| &e.place_s)),
                mean_compute_s: [compute(0), compute(1), compute(2)],
                median_result_to_motion_s: crate::stats::median_min_max(&cat(|e| &e.result_to_motion_s)).0,
                sensor_waits: waits(|e| e.sensor_waits),
                compute_waits: waits(|e| e.compute_waits),
                protective_stops: fault(0),
                collisions: fault(1),
                drops: fault(2),
                grasp_failures: fault(3),
                parts_lost: fault(4),
                refills: es.iter().map(|e| e.refills).sum(),
                agitations: es.iter().map(|e| e.agitations).sum(),
                grasps,
                grasp_success_rate: if grasps.0 == 0 {
                    f64::NAN
                } else {
                    grasps.1 as f64 / grasps.0 as f64
                },
                misrecognised: es.iter().map(|e| e.misrecognised).sum(),
                blind_picks,
                picks_per_capture: if es.iter().any(|e| e.results_used > 0) {
                    set_out as f64 / es.iter().map(|e| e.results_used).sum::<usize>() as f64
                } else {
                    f64::NAN
                },
                recognition: {
                    let mut t = RecognitionTotals::default();
                    es.iter().for_each(|e| t.merge(&e.recognition));
                    t.summary()
                },
                peak_demand_ratio: es
                    .iter()
                    .flat_map(|e| e.peak_demand_ratio.iter().copied())
                    .fold(0.0, f64::max),
                saturated_s: es.iter().map(|e| e.saturated_s).sum(),
                max_tracking_error_deg: es.iter().map(|e| e.max_tracking_error_deg).fold(0.0, f64::max),
                sim_time_s: es.iter().map(|e| e.sim_time_s).sum(),
                wall_s: es.iter().map(|e| e.wall_s).sum(),
            })
        })
        .collect()
}

fn num(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "-".into()
    }
}

/// The table as Markdown.
pub fn markdown(rows: &[Row]) -> String {
    let mut md = String::from(
        "| part | runs | placed / attempts | success | takt mean [s] | p95 | min | max | reference [s] \
         | takt excl. tray refills [s] | Pick [s] | Place [s] | motion floor [s] | compute grasp/Pick/Place [ms] | result to motion median [ms] | sensor waits (mean s) \
         | compute waits (mean s) | stops | collisions | drops | grasps sealed | grasp fails (misrecognised) | picks / capture | blind picks placed | lost | agitations | refills \
         | recognition recall / precision | pose error med mm / deg | peak torque demand | saturated [s] | max tracking error [deg] |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        md += &format!(
            "| {} | {} | {}/{} | {} % | {} | {} | {} | {} | {} | {} | {} | {} | {} | {}/{}/{} | {} | {} ({}) | {} ({}) | {} | {} | {} | {} % | {} ({}) | {} | {}/{} | {} | {} | {} | {} % / {} % | {} / {} | {} % | {} | {} |\n",
            r.workpiece,
            r.runs,
            r.placed,
            r.attempts,
            num(100.0 * r.success_rate, 1),
            num(r.takt.mean_s, 3),
            num(r.takt.p95_s, 3),
            num(r.takt.min_s, 3),
            num(r.takt.max_s, 3),
            r.reference_takt_s.map_or("-".into(), |t| num(t, 1)),
            num(r.takt_excl_refills.mean_s, 3),
            num(r.mean_pick_s, 3),
            num(r.mean_place_s, 3),
            num(r.motion_floor_s, 3),
            num(r.mean_compute_s[0] * 1e3, 1),
            num(r.mean_compute_s[1] * 1e3, 1),
            num(r.mean_compute_s[2] * 1e3, 1),
            num(r.median_result_to_motion_s * 1e3, 1),
            r.sensor_waits.0,
            num(r.sensor_waits.1, 3),
            r.compute_waits.0,
            num(r.compute_waits.1, 3),
            r.protective_stops,
            r.collisions,
            r.drops,
            num(100.0 * r.grasp_success_rate, 1),
            r.grasp_failures,
            r.misrecognised,
            num(r.picks_per_capture, 2),
            r.blind_picks.1,
            r.blind_picks.0,
            r.parts_lost,
            r.agitations,
            r.refills,
            num(100.0 * r.recognition.recall, 1),
            num(100.0 * r.recognition.precision, 1),
            num(r.recognition.position_error_mm[0], 2),
            num(r.recognition.rotation_error_deg[0], 2),
            num(100.0 * r.peak_demand_ratio, 1),
            num(r.saturated_s, 3),
            num(r.max_tracking_error_deg, 3),
        );
    }
    md
}

/// The columns of `takt.csv`.
pub const TAKT_CSV_HEADER: [&str; 46] = [
    "workpiece",
    "runs",
    "attempts",
    "placed",
    "success_rate",
    "takt_mean_s",
    "takt_p95_s",
    "takt_min_s",
    "takt_max_s",
    "takt_count",
    "reference_takt_s",
    "takt_excl_refills_mean_s",
    "mean_pick_s",
    "mean_place_s",
    "motion_floor_s",
    "mean_grasp_compute_s",
    "mean_pick_compute_s",
    "mean_place_compute_s",
    "median_result_to_motion_compute_s",
    "sensor_waits",
    "sensor_wait_mean_s",
    "compute_waits",
    "compute_wait_mean_s",
    "protective_stops",
    "collisions",
    "drops",
    "grasp_failures",
    "parts_lost",
    "agitations",
    "refills",
    "grasps_attempted",
    "grasps_sealed",
    "misrecognised",
    "picks_per_capture",
    "blind_picks",
    "blind_picks_placed",
    "recognition_recall",
    "recognition_precision",
    "pose_error_median_mm",
    "pose_error_p95_mm",
    "pose_error_median_deg",
    "pose_error_p95_deg",
    "peak_demand_ratio",
    "saturated_s",
    "max_tracking_error_deg",
    "sim_time_s",
];

/// One row of `takt.csv`.
#[derive(Serialize)]
struct CsvRow<'a> {
    workpiece: &'a str,
    runs: usize,
    attempts: usize,
    placed: usize,
    success_rate: Fixed<6>,
    takt_mean_s: Fixed<6>,
    takt_p95_s: Fixed<6>,
    takt_min_s: Fixed<6>,
    takt_max_s: Fixed<6>,
    takt_count: usize,
    reference_takt_s: Fixed<6>,
    takt_excl_refills_mean_s: Fixed<6>,
    mean_pick_s: Fixed<6>,
    mean_place_s: Fixed<6>,
    motion_floor_s: Fixed<6>,
    mean_grasp_compute_s: Fixed<6>,
    mean_pick_compute_s: Fixed<6>,
    mean_place_compute_s: Fixed<6>,
    median_result_to_motion_compute_s: Fixed<6>,
    sensor_waits: usize,
    sensor_wait_mean_s: Fixed<6>,
    compute_waits: usize,
    compute_wait_mean_s: Fixed<6>,
    protective_stops: usize,
    collisions: usize,
    drops: usize,
    grasp_failures: usize,
    parts_lost: usize,
    agitations: usize,
    refills: usize,
    grasps_attempted: usize,
    grasps_sealed: usize,
    misrecognised: usize,
    picks_per_capture: Fixed<6>,
    blind_picks: usize,
    blind_picks_placed: usize,
    recognition_recall: Fixed<6>,
    recognition_precision: Fixed<6>,
    pose_error_median_mm: Fixed<6>,
    pose_error_p95_mm: Fixed<6>,
    pose_error_median_deg: Fixed<6>,
    pose_error_p95_deg: Fixed<6>,
    peak_demand_ratio: Fixed<6>,
    saturated_s: Fixed<6>,
    max_tracking_error_deg: Fixed<6>,
    sim_time_s: Fixed<6>,
}

/// The table as CSV (`takt.csv`): workpiece names quoted where they need it.
pub fn csv(rows: &[Row]) -> String {
    to_csv(
        &TAKT_CSV_HEADER,
        rows.iter().map(|r| CsvRow {
            workpiece: &r.workpiece,
            runs: r.runs,
            attempts: r.attempts,
            placed: r.placed,
            success_rate: Fixed::of(r.success_rate),
            takt_mean_s: Fixed::of(r.takt.mean_s),
            takt_p95_s: Fixed::of(r.takt.p95_s),
            takt_min_s: Fixed::of(r.takt.min_s),
            takt_max_s: Fixed::of(r.takt.max_s),
            takt_count: r.takt.count,
            reference_takt_s: Fixed(r.reference_takt_s),
            takt_excl_refills_mean_s: Fixed::of(r.takt_excl_refills.mean_s),
            mean_pick_s: Fixed::of(r.mean_pick_s),
            mean_place_s: Fixed::of(r.mean_place_s),
            motion_floor_s: Fixed::of(r.motion_floor_s),
            mean_grasp_compute_s: Fixed::of(r.mean_compute_s[0]),
            mean_pick_compute_s: Fixed::of(r.mean_compute_s[1]),
            mean_place_compute_s: Fixed::of(r.mean_compute_s[2]),
            median_result_to_motion_compute_s: Fixed::of(r.median_result_to_motion_s),
            sensor_waits: r.sensor_waits.0,
            sensor_wait_mean_s: Fixed::of(r.sensor_waits.1),
            compute_waits: r.compute_waits.0,
            compute_wait_mean_s: Fixed::of(r.compute_waits.1),
            protective_stops: r.protective_stops,
            collisions: r.collisions,
            drops: r.drops,
            grasp_failures: r.grasp_failures,
            parts_lost: r.parts_lost,
            agitations: r.agitations,
            refills: r.refills,
            grasps_attempted: r.grasps.0,
            grasps_sealed: r.grasps.1,
            misrecognised: r.misrecognised,
            picks_per_capture: Fixed::of(r.picks_per_capture),
            blind_picks: r.blind_picks.0,
            blind_picks_placed: r.blind_picks.1,
            recognition_recall: Fixed::of(r.recognition.recall),
            recognition_precision: Fixed::of(r.recognition.precision),
            pose_error_median_mm: Fixed::of(r.recognition.position_error_mm[0]),
            pose_error_p95_mm: Fixed::of(r.recognition.position_error_mm[1]),
            pose_error_median_deg: Fixed::of(r.recognition.rotation_error_deg[0]),
            pose_error_p95_deg: Fixed::of(r.recognition.rotation_error_deg[1]),
            peak_demand_ratio: Fixed::of(r.peak_demand_ratio),
            saturated_s: Fixed::of(r.saturated_s),
            max_tracking_error_deg: Fixed::of(r.max_tracking_error_deg),
            sim_time_s: Fixed::of(r.sim_time_s),
        }),
    )
}

/// What `takt.json` holds: the batch, which shard, every run's entry, and the table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BatchFile {
    /// binpick version.
    pub version: String,
    /// The whole batch.
    pub spec: BatchSpec,
    /// This file's shard (K, N); (1, 1) for a whole batch or a merge.
    pub shard: (usize, usize),
    /// Runs.
    pub runs: Vec<RunEntry>,
}

/// Joins the `takt.json` of every shard of one batch: the specs must agree, and together the
/// shards must cover each run of the batch exactly once.
pub fn merge(files: &[(String, BatchFile)]) -> Result<BatchFile, BatchError> {
    let Some((first_path, first)) = files.first() else {
        return Err(BatchError::Input("merge: no shard results given".into()));
    };
    let mut runs: Vec<RunEntry> = Vec::new();
    for (path, f) in files {
        if f.spec != first.spec {
            return Err(BatchError::Input(format!(
                "merge: {path} is from another batch than {first_path} ({} vs {})",
                f.spec.name(),
                first.spec.name()
            )));
        }
        runs.extend(f.runs.iter().cloned());
    }
    let jobs = first.spec.jobs();
    let mut ordered = Vec::with_capacity(jobs.len());
    for (w, s) in &jobs {
        let found: Vec<&RunEntry> = runs.iter().filter(|e| &e.workpiece == w && e.seed == *s).collect();
        match found.len() {
            1 => ordered.push(found[0].clone()),
            0 => {
                return Err(BatchError::Input(format!(
                    "merge: run {w} seed {s} of {} is in none of the shards given",
                    first.spec.name()
                )));
            }
            _ => {
                return Err(BatchError::Input(format!(
                    "merge: run {w} seed {s} is in {} of the shards given",
                    found.len()
                )));
            }
        }
    }
    Ok(BatchFile {
        version: first.version.clone(),
        spec: first.spec.clone(),
        shard: (1, 1),
        runs: ordered,
    })
}
