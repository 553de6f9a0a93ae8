//! What a cell run produces: one record per pick, the run's summary, and the takt statistics
//! over them.
//!
//! Job: keep, per pick, when each stage happened and how long it took (capture, recognition
//! result, compute, stalls, Pick, Place, release), its outcome and its errors; summarise a run
//! (success, takt, waits, faults) from those records alone.
//!
//! Takt of a pick = time between consecutive successful releases. The first pick of each pile
//! (the start, and after a refill) follows the initial sensing and is left out of the takt
//! statistics. Units: s, mm and deg where a name says so.

use serde::Serialize;

use super::events::{EndReason, Outcome};
use crate::stats::{Summary, mean_of};

/// One pick (or one capture that found nothing to pick).
#[derive(Debug, Clone, Serialize)]
pub struct PickRecord {
    /// Index.
    pub index: usize,
    /// Outcome.
    pub outcome: Outcome,
    /// When the capture this pick used was triggered [s].
    pub capture_s: f64,
    /// When its recognition result arrived [s].
    pub ready_s: f64,
    /// When the part was released [s] (placed picks).
    pub release_s: Option<f64>,
    /// Time since the previous successful release [s].
    pub takt_s: Option<f64>,
    /// The first pick of a pile (start or refill): left out of the takt statistics.
    pub first_of_pile: bool,
    /// Pick: transfer, descent, vacuum build-up and lift [s].
    pub pick_s: f64,
    /// Place: transfer, descent, release and retreat [s].
    pub place_s: f64,
    /// The arm waited for the recognition result [s].
    pub stall_sensor_s: f64,
    /// The arm waited for grasp selection or motion generation [s].
    pub stall_compute_s: f64,
    /// Grasp selection, charged [s].
    pub grasp_compute_s: f64,
    /// Pick motion generation (planning, acceleration, the straight lines), charged [s].
    pub pick_compute_s: f64,
    /// Place motion generation, charged [s].
    pub place_compute_s: f64,
    /// Horizontal placement error [mm] (placed picks).
    pub placement_error_mm: Option<f64>,
    /// Yaw placement error [deg], modulo the part's symmetry (placed picks).
    pub yaw_error_deg: Option<f64>,
    /// Largest servo tracking error over the pick's motions [deg].
    pub max_tracking_error_deg: f64,
    /// Largest |applied torque| / torque limit over the pick's motions.
    pub peak_torque_ratio: f64,
    /// Time scaling of the held-part Place transfer for the cup's holding force (1: none).
    pub suction_speed_factor: f64,
}

impl PickRecord {
    /// A pick that used the capture triggered at `capture_s` whose result arrived at `ready_s`.
    pub fn new(index: usize, capture_s: f64, ready_s: f64) -> Self {
        PickRecord {
            index,
            outcome: Outcome::Placed,
            capture_s,
            ready_s,
            release_s: None,
            takt_s: None,
            first_of_pile: false,
            pick_s: 0.0,
            place_s: 0.0,
            stall_sensor_s: 0.0,
            stall_compute_s: 0.0,
            grasp_compute_s: 0.0,
            pick_compute_s: 0.0,
            place_compute_s: 0.0,
            placement_error_mm: None,
            yaw_error_deg: None,
            max_tracking_error_deg: 0.0,
            peak_torque_ratio: 0.0,
            suction_speed_factor: 1.0,
        }
    }
}

/// Takt statistics [s] over the placed picks that follow another release in the same pile.
pub type TaktStats = Summary;

/// A run's summary.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// Workpiece.
    pub workpiece: String,
    /// Seed.
    pub seed: u64,
    /// Deterministic mode.
    pub deterministic: bool,
    /// Picks the arm set out to make.
    pub attempts: usize,
    /// Picks placed.
    pub placed: usize,
    /// placed / attempts.
    pub success_rate: f64,
    /// Takt statistics.
    pub takt: TaktStats,
    /// The reference system's takt for this workpiece [s], if it is one of A..F.
    pub reference_takt_s: Option<f64>,
    /// End-to-end takt: time from the first to the last release over the releases in between
    /// [s], refills, re-captures and failed picks included (NaN below two releases).
    pub effective_takt_s: f64,
    /// Mean Pick time over the placed picks [s].
    pub mean_pick_s: f64,
    /// Mean Place time over the placed picks [s].
    pub mean_place_s: f64,
    /// Mean compute charged per attempt: grasp selection, Pick and Place motion generation [s].
    pub mean_compute_s: [f64; 3],
    /// Stalls waiting for the sensor: count and total [s] (placed picks after the first of a pile).
    pub sensor_stalls: (usize, f64),
    /// Stalls waiting for compute: count and total [s].
    pub compute_stalls: (usize, f64),
    /// Protective stops.
    pub protective_stops: usize,
    /// Collisions.
    pub collisions: usize,
    /// Parts dropped from the cup.
    pub drops: usize,
    /// Parts lost out of the trays.
    pub parts_lost: usize,
    /// Captures triggered and spoiled.
    pub captures: (u64, u64),
    /// Pick-tray refills.
    pub refills: usize,
    /// Place-tray exchanges.
    pub place_tray_exchanges: usize,
    /// Largest |applied torque| / limit over the run.
    pub peak_torque_ratio: f64,
    /// Largest servo tracking error over the run [deg].
    pub max_tracking_error_deg: f64,
    /// Why the run ended.
    pub ended: EndReason,
    /// Simulated time [s].
    pub sim_time_s: f64,
}

/// Everything a run produced (what its watchers kept is theirs).
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Per pick.
    pub records: Vec<PickRecord>,
    /// Summary.
    pub summary: RunSummary,
}

/// The takts the statistics are over [s]: placed picks after the first of their pile.
pub fn takts_in_stats(records: &[PickRecord]) -> Vec<f64> {
    records
        .iter()
        .filter(|r| r.outcome == Outcome::Placed && !r.first_of_pile)
        .filter_map(|r| r.takt_s)
        .collect()
}

/// Time from the first to the last release [s] and the releases after the first: their ratio is
/// the end-to-end takt. (0, 0) below two releases.
pub fn release_span(records: &[PickRecord]) -> (f64, usize) {
    let r: Vec<f64> = records.iter().filter_map(|p| p.release_s).collect();
    match (r.first(), r.last()) {
        (Some(a), Some(b)) if r.len() > 1 => (b - a, r.len() - 1),
        _ => (0.0, 0),
    }
}

/// Counts of a run that the records do not hold.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunCounts {
    /// Parts lost out of the trays.
    pub parts_lost: usize,
    /// Captures triggered and spoiled.
    pub captures: (u64, u64),
    /// Pick-tray refills.
    pub refills: usize,
    /// Place-tray exchanges.
    pub place_tray_exchanges: usize,
}

/// What a run was.
#[derive(Debug, Clone)]
pub struct RunLabel {
    /// Workpiece name.
    pub workpiece: String,
    /// Run seed.
    pub seed: u64,
    /// Fixed compute budgets.
    pub deterministic: bool,
}

/// The summary of a run from its records.
pub fn summarise(
    label: RunLabel,
    records: &[PickRecord],
    counts: RunCounts,
    ended: EndReason,
    sim_time_s: f64,
) -> RunSummary {
    let attempts: Vec<&PickRecord> = records.iter().filter(|r| r.outcome.is_attempt()).collect();
    let placed: Vec<&PickRecord> = attempts
        .iter()
        .copied()
        .filter(|r| r.outcome == Outcome::Placed)
        .collect();
    let takts = takts_in_stats(records);
    let in_takt = || placed.iter().filter(|r| !r.first_of_pile);
    let stalls = |f: fn(&PickRecord) -> f64| {
        let v: Vec<f64> = in_takt().map(|r| f(r)).filter(|s| *s > 1e-9).collect();
        (v.len(), v.iter().sum())
    };
    let count = |f: fn(&Outcome) -> bool| attempts.iter().filter(|r| f(&r.outcome)).count();
    RunSummary {
        reference_takt_s: crate::reference::reference_takt(&label.workpiece),
        workpiece: label.workpiece,
        seed: label.seed,
        deterministic: label.deterministic,
        attempts: attempts.len(),
        placed: placed.len(),
        success_rate: if attempts.is_empty() {
            f64::NAN
        } else {
            placed.len() as f64 / attempts.len() as f64
        },
        takt: TaktStats::of(&takts),
        effective_takt_s: match release_span(records) {
            (_, 0) => f64::NAN,
            (t, n) => t / n as f64,
        },
        mean_pick_s: mean_of(placed.iter().map(|r| r.pick_s)),
        mean_place_s: mean_of(placed.iter().map(|r| r.place_s)),
        mean_compute_s: [
            mean_of(attempts.iter().map(|r| r.grasp_compute_s)),
            mean_of(attempts.iter().map(|r| r.pick_compute_s)),
            mean_of(attempts.iter().map(|r| r.place_compute_s)),
        ],
        sensor_stalls: stalls(|r| r.stall_sensor_s),
        compute_stalls: stalls(|r| r.stall_compute_s),
        protective_stops: count(|o| matches!(o, Outcome::ProtectiveStop(_))),
        collisions: count(|o| matches!(o, Outcome::Collision(_))),
        drops: count(|o| matches!(o, Outcome::Dropped(_))),
        parts_lost: counts.parts_lost,
        captures: counts.captures,
        refills: counts.refills,
        place_tray_exchanges: counts.place_tray_exchanges,
        peak_torque_ratio: records.iter().map(|r| r.peak_torque_ratio).fold(0.0, f64::max),
        max_tracking_error_deg: records.iter().map(|r| r.max_tracking_error_deg).fold(0.0, f64::max),
        ended,
        sim_time_s,
    }
}
