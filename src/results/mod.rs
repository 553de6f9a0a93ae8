//! Results: the figures of a run or of many runs, and how they are written.
//!
//! Job: from one [`Tally`] (a run's, or the merge of several runs': see
//! [`crate::cycle::records`]) derive its [`Summary`] (rates, means, takt statistics,
//! percentiles), and write it: the takt table's columns ([`table`]: one list gives the
//! Markdown, the CSV and the JSON of a row; and the terminal's short table) and a run's
//! `summary.json` ([`run_summary`]); check a batch's rows against a user's limits ([`expect`]:
//! `binpick batch --expect`, `takt.junit.xml`).
//!
//! Takt, as the reference system defines it (its Table 5: the mean of consecutive Pick-and-Place
//! cycles, only the very first cycle's sensing and motion generation excluded): the intervals
//! between consecutive releases after a run's first release, everything in between included
//! (failed picks, re-captures, waits, tray refills). The takt "excluding tray refills" leaves out
//! the intervals that span a refill: a labelled side figure, not the headline. Success = placed /
//! attempts, where every pick counts as an attempt: a re-capture (nothing detected, nothing
//! graspable), a grasp failure, a drop and a missing motion too.
//!
//! Sustained operation: the takt over every interval of a run is the sustained takt when the run
//! spans several pile cycles (`batch --sustained`: [`SUSTAINED_PICKS`] picks); parts per hour
//! are 3600 s over it (one release per takt). Beside it, the reference's 20-pick figure: the
//! intervals of each run's first 21 picks ([`crate::cycle::FIRST_PICKS`]). Pile loads placed:
//! the parts placed per run over the pile's size, how many pile cycles the runs spanned.
//!
//! Units: s (ms in the Markdown's compute column), mm and deg where a name says so, counts.

pub mod expect;
pub mod run_summary;
pub mod table;

pub use crate::cycle::{Faults, StageCompute, Tally, Waits};
pub use run_summary::RunSummary;

use crate::sensor::RecognitionSummary;
use crate::stats::{Summary as Stats, mean, median_min_max, percentile_sorted, sorted};

/// Picks per run of `batch --sustained` (and `tune`'s default with the sustained objective):
/// three times the largest pile of the parts A..F (60), so at a success of 2/3 or more a run
/// places at least two full piles of every part (A's 30 and B's 16 many more): the figure
/// includes the pile running low, its agitations and refills, not only a full pile's first
/// third.
pub const SUSTAINED_PICKS: usize = 180;

/// What a tally comes to: the tally itself (its counts are read from it) and the figures derived
/// from it.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// The tally summarised.
    pub tally: Tally,
    /// Placed within the place tray's tolerance / attempts: a misplaced part is a failed attempt.
    pub success_rate: f64,
    /// Takt as the reference defines it: every release-to-release interval after a run's first.
    pub takt: Stats,
    /// The same, leaving out the intervals that span a pick-tray refill (a side figure).
    pub takt_excl_refills: Stats,
    /// The reference's 20-pick takt: the intervals of each run's first 21 picks.
    pub takt_first: Stats,
    /// Parts per hour the runs sustained: 3600 s / the takt's mean (NaN without a takt).
    pub parts_per_hour: f64,
    /// Pile loads placed per run: placed / (runs x the pile's size) (NaN when not known).
    pub pile_loads: f64,
    /// 5th percentile of the takt (nearest rank) (s): the lower edge of the charts' band.
    pub takt_p5_s: f64,
    /// The reference system's takt for this workpiece (s), if it is one of A..F.
    pub reference_takt_s: Option<f64>,
    /// Mean Pick time over the placed picks (s).
    pub mean_pick_s: f64,
    /// Mean Place time over the placed picks (s).
    pub mean_place_s: f64,
    /// The physical floor (s): the takt with instantaneous sensing and compute, motion time only
    /// (mean Pick + Place of the placed picks).
    pub motion_floor_s: f64,
    /// Mean compute charged per pick the arm set out to make, per stage (s).
    pub mean_compute: StageCompute,
    /// Median compute between a pick's result and the motion it unblocks (grasp and Pick) (s).
    pub median_result_to_motion_s: f64,
    /// Grasps sealed / attempted.
    pub grasp_success_rate: f64,
    /// Picks the arm set out to make per recognition result they came from.
    pub picks_per_capture: f64,
    /// Recognition over the results used, against the truth at each trigger.
    pub recognition: RecognitionSummary,
    /// How the placed parts lie against their place poses.
    pub placement: PlacementSummary,
}

/// How the placed parts lie in their slots, against the pose the place motion aimed each at.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PlacementSummary {
    /// Placed parts measured.
    pub measured: usize,
    /// Position error, median and p95 (nearest rank) (mm; NaN when none was measured).
    pub position_error_mm: [f64; 2],
    /// Rotation error, median and p95 (nearest rank) (deg; NaN when none was measured).
    pub rotation_error_deg: [f64; 2],
    /// Placed parts beyond the place tray's tolerance (`misplaced` incidents): failed attempts in
    /// the success rate.
    pub misplaced: usize,
}

impl PlacementSummary {
    /// The placements of `t`.
    pub fn of(t: &Tally) -> Self {
        let median_p95 = |v: &[f64]| {
            let v = sorted(v);
            [crate::stats::median_sorted(&v), percentile_sorted(&v, 0.95)]
        };
        PlacementSummary {
            measured: t.placement_error_mm.len(),
            position_error_mm: median_p95(&t.placement_error_mm),
            rotation_error_deg: median_p95(&t.placement_rotation_deg),
            misplaced: t.misplaced(),
        }
    }
}

/// `a / b`, NaN when `b` is 0.
fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 { f64::NAN } else { a as f64 / b as f64 }
}

/// Releases per hour at a mean takt of `takt_s` seconds (NaN when not a positive number).
fn per_hour(takt_s: f64) -> f64 {
    if takt_s > 0.0 { 3600.0 / takt_s } else { f64::NAN }
}

impl Summary {
    /// The figures of `tally`.
    pub fn of(tally: &Tally) -> Summary {
        let t = tally;
        let (mean_pick_s, mean_place_s) = (mean(&t.pick_s), mean(&t.place_s));
        let takt = Stats::of(&t.takts_s);
        Summary {
            success_rate: ratio(t.placed_in_tolerance(), t.attempts),
            parts_per_hour: per_hour(takt.mean_s),
            takt,
            takt_excl_refills: Stats::of(&t.takts_excl_refills_s),
            takt_first: Stats::of(&t.takts_first_s),
            pile_loads: ratio(t.placed, t.runs * t.pile_count),
            takt_p5_s: percentile_sorted(&sorted(&t.takts_s), 0.05),
            reference_takt_s: crate::reference::reference_takt(&t.workpiece),
            mean_pick_s,
            mean_place_s,
            motion_floor_s: mean_pick_s + mean_place_s,
            mean_compute: t.compute_sum.per(t.set_out),
            median_result_to_motion_s: median_min_max(&t.result_to_motion_s).0,
            grasp_success_rate: ratio(t.grasps.1, t.grasps.0),
            picks_per_capture: ratio(t.set_out, t.results_used),
            recognition: t.recognition.summary(),
            placement: PlacementSummary::of(t),
            tally: tally.clone(),
        }
    }

    /// The largest |demanded torque| / limit over every joint (before saturation).
    pub fn peak_demand_ratio(&self) -> f64 {
        self.tally.peak_demand_ratio.iter().copied().fold(0.0, f64::max)
    }
}

/// One summary per workpiece of `order` that has runs in `tallies`, over all its runs (in the
/// order given).
pub fn per_workpiece<'a>(order: &[String], tallies: impl Iterator<Item = &'a Tally> + Clone) -> Vec<Summary> {
    order
        .iter()
        .filter_map(|w| Tally::merged(tallies.clone().filter(|t| &t.workpiece == w)))
        .map(|t| Summary::of(&t))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cycle::{Incident, IncidentKind};

    /// A misplaced part is a failed attempt in the success rate (it still ended an interval and
    /// left the pick tray); the control: the same tally without the incident counts it placed.
    #[test]
    fn a_misplaced_part_is_not_a_success() {
        let incident = |kind: IncidentKind| Incident {
            seed: 1,
            pick: Some(1),
            t_s: 3.0,
            kind,
            detail: String::new(),
        };
        let mut t = Tally {
            workpiece: "A".into(),
            runs: 1,
            attempts: 3,
            placed: 2,
            incidents: vec![incident(IncidentKind::Misplaced), incident(IncidentKind::Fault)],
            ..Tally::default()
        };
        assert_eq!((t.misplaced(), t.placed_in_tolerance()), (1, 1));
        let s = Summary::of(&t);
        assert_eq!((s.success_rate, s.placement.misplaced), (1.0 / 3.0, 1));
        t.incidents.remove(0);
        assert_eq!(Summary::of(&t).success_rate, 2.0 / 3.0);
    }
}
