//! What a cell run produces: one record per pick, the run's summary, and the takt statistics
//! over them.
//!
//! Job: keep, per pick, when each stage happened and how long it took (capture, recognition
//! result, compute, stalls, Pick, Place, release), its outcome and its errors; summarise a run
//! (success, takt, waits, faults) from those records alone.
//!
//! Takt, as the reference system defines it (its Table 5: the mean of consecutive Pick-and-Place
//! cycles, only the very first cycle's sensing and motion generation excluded): the intervals
//! between consecutive releases after the run's first release, everything in between included
//! (failed picks, re-captures, waits, tray refills). The takt "excluding tray refills" leaves out
//! the intervals that span a refill: a labelled side figure, not the headline. Success = placed /
//! attempts, where every pick counts as an attempt: a re-capture (nothing detected, nothing
//! graspable), a grasp failure, a drop and a missing motion too. Units: s, mm and deg where a
//! name says so.

use serde::Serialize;

use super::events::EndReason;
use super::outcome::Outcome;
use crate::sensor::{RecognitionReport, RecognitionSummary, RecognitionTotals, TruthMatch};
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
    /// Time since the previous release [s] (none for the run's first release).
    pub takt_s: Option<f64>,
    /// A pick-tray refill happened since the previous release.
    pub spans_refill: bool,
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
    /// Largest |demanded torque| / torque limit over the pick's motions and joints (before the
    /// drive's saturation).
    pub peak_demand_ratio: f64,
    /// The joint (1..6) of that peak.
    pub peak_demand_joint: usize,
    /// Time some joint was saturated during the pick's motions [s].
    pub saturated_s: f64,
    /// Time scaling of the held-part Place transfer for the cup's holding force (1: none).
    pub suction_speed_factor: f64,
    /// How long two motions ran at once, as played [s]: the lift and the Place transfer, the
    /// Pick transfer and its descent, the Place transfer and its descent, the last Place's
    /// retreat and this Pick's transfer (0: one after the other).
    pub overlap_s: [f64; 4],
    /// The vacuum valve closed this long before the Place's descent ended [s].
    pub release_lead_s: f64,
    /// A blind pick: picks went into the pile after its result's capture (the image no longer
    /// shows the pile as it is; the part was taken clear of them).
    pub blind: bool,
    /// Picks that came from the same result before this one (0: the first from it).
    pub from_result: usize,
    /// Picks that went into the pile after its result's capture, before this one.
    pub picks_since_capture: usize,
    /// Whether the cup sealed on a part, once it reached the grasp (`None`: it never got there).
    pub sealed: Option<bool>,
    /// The recognition result this pick used: detections and correct ones (evaluation only).
    pub recognition: Option<(usize, usize)>,
    /// The chosen detection against the part nearest to it at the trigger (evaluation only):
    /// how far the believed pose was from the true one.
    pub aimed_at: Option<TruthMatch>,
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
            spans_refill: false,
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
            peak_demand_ratio: 0.0,
            peak_demand_joint: 0,
            saturated_s: 0.0,
            suction_speed_factor: 1.0,
            overlap_s: [0.0; 4],
            release_lead_s: 0.0,
            blind: false,
            from_result: 0,
            picks_since_capture: 0,
            sealed: None,
            recognition: None,
            aimed_at: None,
        }
    }
}

/// Takt statistics [s] over release-to-release intervals.
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
    /// Attempts: every pick, re-captures included.
    pub attempts: usize,
    /// Picks placed.
    pub placed: usize,
    /// placed / attempts.
    pub success_rate: f64,
    /// Takt as the reference defines it: every release-to-release interval after the first.
    pub takt: TaktStats,
    /// The same, leaving out the intervals that span a pick-tray refill (a side figure).
    pub takt_excl_refills: TaktStats,
    /// The reference system's takt for this workpiece [s], if it is one of A..F.
    pub reference_takt_s: Option<f64>,
    /// Mean Pick time over the placed picks [s].
    pub mean_pick_s: f64,
    /// Mean Place time over the placed picks [s].
    pub mean_place_s: f64,
    /// Mean compute charged per pick the arm set out to make: grasp selection, Pick and Place
    /// motion generation [s].
    pub mean_compute_s: [f64; 3],
    /// Stalls waiting for the sensor: count and total [s] (placed picks with a takt).
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
    /// Pick-tray agitations.
    pub agitations: usize,
    /// Place-tray exchanges.
    pub place_tray_exchanges: usize,
    /// Largest |demanded torque| / limit over the run, per joint (before saturation).
    pub peak_demand_ratio: [f64; 6],
    /// Time some joint was saturated, over the run [s].
    pub saturated_s: f64,
    /// Largest servo tracking error over the run [deg].
    pub max_tracking_error_deg: f64,
    /// Grasps attempted (the cup reached the part) and sealed.
    pub grasps: (usize, usize),
    /// Blind picks (picks went into the pile after the result's capture): attempted and placed.
    pub blind_picks: (usize, usize),
    /// Recognition results the picks the arm set out to make came from.
    pub results_used: usize,
    /// Picks the arm set out to make per recognition result they came from.
    pub picks_per_capture: f64,
    /// Grasp failures on a detection that was wrong (more than 2 mm or 5 deg from every part).
    pub misrecognised: usize,
    /// Recognition over the run's results, against the truth at each trigger.
    pub recognition: RecognitionSummary,
    /// Per recognition result (kept when the run keeps its records, else empty).
    pub recognition_per_capture: Vec<RecognitionReport>,
    /// Why the run ended.
    pub ended: EndReason,
    /// Simulated time [s].
    pub sim_time_s: f64,
}

/// Everything a run produced (what its watchers kept is theirs).
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Per pick, when the run was asked to keep them ([`crate::cycle::RunOptions::keep_records`];
    /// empty otherwise).
    pub records: Vec<PickRecord>,
    /// What the summary and a batch's table need of the picks, tallied as each pick ended.
    pub tally: RunTally,
    /// Summary.
    pub summary: RunSummary,
}

/// The takts [s]: every release-to-release interval after the run's first release (the
/// reference's definition).
pub fn takts(records: &[PickRecord]) -> Vec<f64> {
    records.iter().filter_map(|r| r.takt_s).collect()
}

/// What a run's summary needs of its picks and recognition results, taken as each one ends,
/// so that a long run keeps a few numbers per pick (the samples of its exact medians and
/// percentiles: takts, Pick and Place times, pose errors of correct detections), not its records.
/// Sums run in pick order, as over the records.
#[derive(Debug, Clone, Default)]
pub struct RunTally {
    /// Picks, re-captures included (attempts).
    pub attempts: usize,
    /// Picks placed.
    pub placed: usize,
    /// Picks the arm set out to make.
    pub set_out: usize,
    /// The takts [s] ([`takts`]).
    pub takts_s: Vec<f64>,
    /// The takts of intervals that span no pick-tray refill [s].
    pub takts_excl_refills_s: Vec<f64>,
    /// Pick time of each placed pick [s].
    pub pick_s: Vec<f64>,
    /// Place time of each placed pick [s].
    pub place_s: Vec<f64>,
    /// Compute charged over the picks set out: grasp selection, Pick and Place motion [s].
    pub compute_sum_s: [f64; 3],
    /// Compute between each pick's result and the motion it unblocks (grasp selection and
    /// Pick motion), per pick set out [s].
    pub result_to_motion_s: Vec<f64>,
    /// Stalls waiting for the sensor: count and total [s] (placed picks with a takt).
    pub sensor_stalls: (usize, f64),
    /// Stalls waiting for compute: count and total [s].
    pub compute_stalls: (usize, f64),
    /// Protective stops, collisions, drops, grasp failures.
    pub faults: [usize; 4],
    /// Grasp failures on a wrong detection.
    pub misrecognised: usize,
    /// Time some joint was saturated [s].
    pub saturated_s: f64,
    /// Largest servo tracking error [deg].
    pub max_tracking_error_deg: f64,
    /// Grasps attempted and sealed.
    pub grasps: (usize, usize),
    /// Blind picks attempted and placed.
    pub blind_picks: (usize, usize),
    /// Recognition results the picks set out came from.
    pub results_used: usize,
    /// Recognition of the results, against the truth at each trigger.
    pub recognition: RecognitionTotals,
}

impl RunTally {
    /// Adds a finished pick.
    pub fn add(&mut self, r: &PickRecord) {
        self.attempts += 1;
        let placed = r.outcome == Outcome::Placed;
        if let Some(t) = r.takt_s {
            self.takts_s.push(t);
            if !r.spans_refill {
                self.takts_excl_refills_s.push(t);
            }
            if placed {
                for (stalls, s) in [
                    (&mut self.sensor_stalls, r.stall_sensor_s),
                    (&mut self.compute_stalls, r.stall_compute_s),
                ] {
                    if s > 1e-9 {
                        stalls.0 += 1;
                        stalls.1 += s;
                    }
                }
            }
        }
        if placed {
            self.placed += 1;
            self.pick_s.push(r.pick_s);
            self.place_s.push(r.place_s);
        }
        if r.outcome.set_out() {
            self.set_out += 1;
            self.compute_sum_s[0] += r.grasp_compute_s;
            self.compute_sum_s[1] += r.pick_compute_s;
            self.compute_sum_s[2] += r.place_compute_s;
            self.result_to_motion_s.push(r.grasp_compute_s + r.pick_compute_s);
            if r.from_result == 0 {
                self.results_used += 1;
            }
        }
        let fault = match r.outcome {
            Outcome::ProtectiveStop(_) => Some(0),
            Outcome::Collision(_) => Some(1),
            Outcome::Dropped(_) => Some(2),
            Outcome::GraspFailed(_) | Outcome::Misrecognised { .. } => Some(3),
            _ => None,
        };
        if let Some(k) = fault {
            self.faults[k] += 1;
        }
        self.misrecognised += usize::from(r.outcome.misrecognised());
        self.saturated_s += r.saturated_s;
        self.max_tracking_error_deg = self.max_tracking_error_deg.max(r.max_tracking_error_deg);
        if let Some(sealed) = r.sealed {
            self.grasps.0 += 1;
            self.grasps.1 += usize::from(sealed);
        }
        if r.blind {
            self.blind_picks.0 += 1;
            self.blind_picks.1 += usize::from(placed);
        }
    }

    /// Mean compute charged per pick set out [s].
    pub fn mean_compute_s(&self) -> [f64; 3] {
        self.compute_sum_s.map(|s| {
            if self.set_out == 0 {
                f64::NAN
            } else {
                s / self.set_out as f64
            }
        })
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
    /// Pick-tray agitations.
    pub agitations: usize,
    /// Place-tray exchanges.
    pub place_tray_exchanges: usize,
    /// Largest |demanded torque| / limit per joint over the run.
    pub peak_demand_ratio: [f64; 6],
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

/// The summary of a run from its tally; `per_capture`: the recognition reports kept, if any.
pub fn summarise(
    label: RunLabel,
    tally: &RunTally,
    counts: RunCounts,
    per_capture: Vec<RecognitionReport>,
    ended: EndReason,
    sim_time_s: f64,
) -> RunSummary {
    let t = tally;
    RunSummary {
        reference_takt_s: crate::reference::reference_takt(&label.workpiece),
        workpiece: label.workpiece,
        seed: label.seed,
        deterministic: label.deterministic,
        attempts: t.attempts,
        placed: t.placed,
        success_rate: if t.attempts == 0 {
            f64::NAN
        } else {
            t.placed as f64 / t.attempts as f64
        },
        takt: TaktStats::of(&t.takts_s),
        takt_excl_refills: TaktStats::of(&t.takts_excl_refills_s),
        mean_pick_s: mean_of(t.pick_s.iter().copied()),
        mean_place_s: mean_of(t.place_s.iter().copied()),
        mean_compute_s: t.mean_compute_s(),
        sensor_stalls: t.sensor_stalls,
        compute_stalls: t.compute_stalls,
        protective_stops: t.faults[0],
        collisions: t.faults[1],
        drops: t.faults[2],
        parts_lost: counts.parts_lost,
        captures: counts.captures,
        refills: counts.refills,
        agitations: counts.agitations,
        place_tray_exchanges: counts.place_tray_exchanges,
        peak_demand_ratio: counts.peak_demand_ratio,
        saturated_s: t.saturated_s,
        max_tracking_error_deg: t.max_tracking_error_deg,
        grasps: t.grasps,
        misrecognised: t.misrecognised,
        blind_picks: t.blind_picks,
        results_used: t.results_used,
        picks_per_capture: if t.results_used > 0 {
            t.set_out as f64 / t.results_used as f64
        } else {
            f64::NAN
        },
        recognition: t.recognition.summary(),
        recognition_per_capture: per_capture,
        ended,
        sim_time_s,
    }
}
