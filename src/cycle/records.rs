//! What a cell run produces: one record per pick, and the run's [`Tally`]: the one results
//! type every summary, table and shard file is made from.
//!
//! Job: keep, per pick, when each stage happened and how long it took (capture, recognition
//! result, compute, stalls, Pick, Place, release), its outcome and its errors; tally a run
//! (attempts, takts, waits, faults, ...) as each pick ends, so a long run keeps a few numbers
//! per pick and not its records; merge tallies of several runs (a table row, shards). The
//! figures derived from a tally (rates, means, percentiles) and their writing are
//! [`crate::results`]'s.
//!
//! Takt, as the reference system defines it (its Table 5: the mean of consecutive Pick-and-Place
//! cycles, only the very first cycle's sensing and motion generation excluded): the intervals
//! between consecutive releases after the run's first release, everything in between included
//! (failed picks, re-captures, waits, tray refills). The takt "excluding tray refills" leaves out
//! the intervals that span a refill: a labelled side figure, not the headline.
//!
//! Two spans of a run give two takts. The reference's 20-pick figure: the intervals ending at
//! the releases of the run's first [`FIRST_PICKS`] picks (attempts), exactly what a
//! `--picks 21` run measures (20 intervals when every pick succeeds). The sustained figure: every
//! interval of the run, so a run long enough to empty and refill the pile several times
//! (`batch --sustained`) measures what the line keeps up, refills and agitations included;
//! parts per hour are 3600 s over it. Success = placed /
//! attempts, where every pick counts as an attempt: a re-capture (nothing detected, nothing
//! graspable), a grasp failure, a drop and a missing motion too. Units: s, mm and deg where a
//! name says so.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::events::{EndReason, IncidentKind};
use super::outcome::{Outcome, PhysicsFault};
use crate::sensor::{RecognitionReport, RecognitionTotals, TruthMatch};

/// Picks (attempts) at the start of a run whose takt intervals make the reference's 20-pick
/// figure: 21, as the reference's Table 5 (20 consecutive Pick-and-Place cycles after the first
/// pick's sensing and motion generation) and `binpick batch`'s default `--picks`.
pub const FIRST_PICKS: usize = 21;

/// One pick (or one capture that found nothing to pick).
#[derive(Debug, Clone, Serialize)]
pub struct PickRecord {
    /// Index.
    pub index: usize,
    /// Outcome.
    pub outcome: Outcome,
    /// When the capture this pick used was triggered (s).
    pub capture_s: f64,
    /// When its recognition result arrived (s).
    pub ready_s: f64,
    /// When the part was released (s) (placed picks).
    pub release_s: Option<f64>,
    /// Time since the previous release (s) (none for the run's first release).
    pub takt_s: Option<f64>,
    /// A pick-tray refill happened since the previous release.
    pub spans_refill: bool,
    /// What happened in the interval since the previous release (none without a takt).
    pub interval_cause: Option<IntervalCause>,
    /// Pick: transfer, descent, vacuum build-up and lift (s).
    pub pick_s: f64,
    /// Place: transfer, descent, release and retreat (s).
    pub place_s: f64,
    /// The arm waited for the recognition result (s).
    pub stall_sensor_s: f64,
    /// The arm waited for grasp selection or motion generation (s).
    pub stall_compute_s: f64,
    /// Compute charged per stage: grasp selection, Pick motion generation (planning,
    /// acceleration, the straight lines), Place motion generation. A pick not attempted (no
    /// grasp, or no motions) has the grasp selection's, with the motions of the grasps tried.
    pub compute: StageCompute,
    /// Horizontal placement error (mm) (placed picks): from where the part should lie in its
    /// slot.
    pub placement_error_mm: Option<f64>,
    /// Rotation placement error (deg) (placed picks): from how the part should lie in its slot
    /// (its place pose), the least over the turns that leave it looking the same.
    pub rotation_error_deg: Option<f64>,
    /// Largest servo tracking error over the pick's motions (deg).
    pub max_tracking_error_deg: f64,
    /// Largest |demanded torque| / torque limit over the pick's motions and joints (before the
    /// drive's saturation).
    pub peak_demand_ratio: f64,
    /// The joint (1..6) of that peak.
    pub peak_demand_joint: usize,
    /// Time some joint was saturated during the pick's motions (s).
    pub saturated_s: f64,
    /// Time scaling of the held-part Place transfer for the cup's holding force (1: none).
    pub suction_speed_factor: f64,
    /// How long two motions ran at once, as played (0: one after the other).
    pub overlaps: Overlaps,
    /// The vacuum valve closed this long before the Place's descent ended (s).
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
            interval_cause: None,
            pick_s: 0.0,
            place_s: 0.0,
            stall_sensor_s: 0.0,
            stall_compute_s: 0.0,
            compute: StageCompute::default(),
            placement_error_mm: None,
            rotation_error_deg: None,
            max_tracking_error_deg: 0.0,
            peak_demand_ratio: 0.0,
            peak_demand_joint: 0,
            saturated_s: 0.0,
            suction_speed_factor: 1.0,
            overlaps: Overlaps::default(),
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

/// Compute charged per stage of a pick (s): grasp selection, Pick motion generation, Place
/// motion generation. Written as `[grasp, pick, place]` in result files.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageCompute {
    /// Grasp selection (s), with the motions of the grasps passed over because their motions
    /// failed.
    pub grasp_s: f64,
    /// Pick motion generation (s).
    pub pick_s: f64,
    /// Place motion generation (s).
    pub place_s: f64,
}

impl StageCompute {
    /// Each stage's sum, added stage by stage.
    pub fn plus(self, o: StageCompute) -> StageCompute {
        StageCompute {
            grasp_s: self.grasp_s + o.grasp_s,
            pick_s: self.pick_s + o.pick_s,
            place_s: self.place_s + o.place_s,
        }
    }

    /// Each stage divided by `n` (NaN when `n` is 0).
    pub fn per(self, n: usize) -> StageCompute {
        let d = |s: f64| if n == 0 { f64::NAN } else { s / n as f64 };
        StageCompute {
            grasp_s: d(self.grasp_s),
            pick_s: d(self.pick_s),
            place_s: d(self.place_s),
        }
    }

    /// What the result waits for before its Pick can move: grasp selection and Pick motion (s).
    pub fn result_to_motion_s(self) -> f64 {
        self.grasp_s + self.pick_s
    }
}

impl Serialize for StageCompute {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        [self.grasp_s, self.pick_s, self.place_s].serialize(s)
    }
}

impl<'de> Deserialize<'de> for StageCompute {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let [grasp_s, pick_s, place_s] = <[f64; 3]>::deserialize(d)?;
        Ok(StageCompute {
            grasp_s,
            pick_s,
            place_s,
        })
    }
}

/// How long two motions of a pick ran at once, as played (s) (0: one after the other).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Overlaps {
    /// The lift and the Place transfer.
    pub lift_s: f64,
    /// The Pick transfer and its descent.
    pub pick_descent_s: f64,
    /// The Place transfer and its descent.
    pub place_descent_s: f64,
    /// The last Place's retreat and this Pick's transfer.
    pub retreat_s: f64,
}

/// What happened in a release-to-release interval (a takt), the first that applies: a pick-tray
/// refill; else a failed attempt (nothing detected or graspable and the agitation after it, a
/// grasp failure, a drop, no motion, a collision or a stop); else a hopper dose; else nothing of
/// these: a clean cycle, as fast as the motions, the sensor and compute allow.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum IntervalCause {
    /// No refill, failed attempt or dose since the previous release.
    Clean,
    /// At least one failed attempt since the previous release, and no refill.
    Failed,
    /// A hopper dose since the previous release, and no refill or failed attempt.
    Dose,
    /// A pick-tray refill since the previous release.
    Refill,
}

impl IntervalCause {
    /// Every cause, in the order tables list them.
    pub const ALL: [IntervalCause; 4] = [
        IntervalCause::Clean,
        IntervalCause::Failed,
        IntervalCause::Dose,
        IntervalCause::Refill,
    ];

    /// The cause of an interval in which these happened (see the type).
    pub fn of(refilled: bool, failed: bool, dosed: bool) -> Self {
        if refilled {
            IntervalCause::Refill
        } else if failed {
            IntervalCause::Failed
        } else if dosed {
            IntervalCause::Dose
        } else {
            IntervalCause::Clean
        }
    }

    /// Its name in files (`clean`, `failed`, `dose`, `refill`).
    pub fn name(self) -> &'static str {
        match self {
            IntervalCause::Clean => "clean",
            IntervalCause::Failed => "failed",
            IntervalCause::Dose => "dose",
            IntervalCause::Refill => "refill",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// The takt's intervals split by [`IntervalCause`]: per cause, how many and their total (s).
/// Written as `[[count, total_s], ...]` in [`IntervalCause::ALL`]'s order.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TaktCauses([(usize, f64); 4]);

impl TaktCauses {
    /// Adds one interval of `takt_s` seconds with its cause.
    pub fn add(&mut self, cause: IntervalCause, takt_s: f64) {
        let c = &mut self.0[cause.index()];
        c.0 += 1;
        c.1 += takt_s;
    }

    /// Intervals with this cause.
    pub fn count(&self, cause: IntervalCause) -> usize {
        self.0[cause.index()].0
    }

    /// Their total (s).
    pub fn total_s(&self, cause: IntervalCause) -> f64 {
        self.0[cause.index()].1
    }

    /// What the cause adds to the mean takt (s): its intervals' total over every interval's
    /// count, so the shares of all causes add up to the mean takt (NaN without an interval).
    pub fn share_s(&self, cause: IntervalCause) -> f64 {
        let n: usize = self.0.iter().map(|c| c.0).sum();
        if n == 0 {
            f64::NAN
        } else {
            self.total_s(cause) / n as f64
        }
    }
}

impl Merge for TaktCauses {
    fn merge(&mut self, o: &Self) {
        for (a, b) in self.0.iter_mut().zip(o.0) {
            a.0 += b.0;
            a.1 += b.1;
        }
    }
}

/// Waits of the arm: how many and their total (s). Written as `[count, total]` in tallies.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Waits {
    /// How many waits.
    pub count: usize,
    /// Their total (s).
    pub total_s: f64,
}

impl Waits {
    /// Adds one wait of `s` seconds, if it is one (longer than 1 ns).
    pub fn add(&mut self, s: f64) {
        if s > 1e-9 {
            self.count += 1;
            self.total_s += s;
        }
    }

    /// The mean wait (s) (0 when there was none).
    pub fn mean_s(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.total_s / self.count as f64
        }
    }
}

impl Serialize for Waits {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        (self.count, self.total_s).serialize(s)
    }
}

impl<'de> Deserialize<'de> for Waits {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let (count, total_s) = <(usize, f64)>::deserialize(d)?;
        Ok(Waits { count, total_s })
    }
}

/// Faults of a run, counted by kind. Written as the array `[protective_stops, collisions,
/// drops, grasp_failures, parts_lost]` in tallies (the format of shard files since the first).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Faults {
    /// Protective stops of the servo.
    pub protective_stops: usize,
    /// Collisions.
    pub collisions: usize,
    /// Parts dropped from the cup.
    pub drops: usize,
    /// Grasp failures.
    pub grasp_failures: usize,
    /// Parts lost out of the trays.
    pub parts_lost: usize,
}

impl Faults {
    /// Counts a pick's outcome, if it is a fault.
    pub fn count(&mut self, outcome: &Outcome) {
        match outcome {
            Outcome::ProtectiveStop(_) => self.protective_stops += 1,
            Outcome::Collision(_) => self.collisions += 1,
            Outcome::Dropped(_) => self.drops += 1,
            Outcome::GraspFailed(_) | Outcome::Misrecognised { .. } => self.grasp_failures += 1,
            _ => {}
        }
    }
}

impl Serialize for Faults {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        [
            self.protective_stops,
            self.collisions,
            self.drops,
            self.grasp_failures,
            self.parts_lost,
        ]
        .serialize(s)
    }
}

impl<'de> Deserialize<'de> for Faults {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let [protective_stops, collisions, drops, grasp_failures, parts_lost] = <[usize; 5]>::deserialize(d)?;
        Ok(Faults {
            protective_stops,
            collisions,
            drops,
            grasp_failures,
            parts_lost,
        })
    }
}

/// Why a run ended, in a tally: written as its text (null while it runs), read back from it.
mod ended_text {
    use super::EndReason;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    const ALL: [EndReason; 6] = [
        EndReason::PicksDone,
        EndReason::TrayEmpty,
        EndReason::NothingGraspableInFullTray,
        EndReason::NoPathOutOfView,
        EndReason::Interrupted,
        EndReason::PhysicsFault,
    ];

    pub fn serialize<S: Serializer>(e: &Option<EndReason>, s: S) -> Result<S::Ok, S::Error> {
        e.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<EndReason>, D::Error> {
        let Some(text) = Option::<String>::deserialize(d)? else {
            return Ok(None);
        };
        ALL.into_iter()
            .find(|e| e.text() == text)
            .map(Some)
            .ok_or_else(|| serde::de::Error::custom(format!("{text:?} is not a reason a run ends")))
    }
}

fn one() -> usize {
    1
}

/// A field of a tally joined with the same field of another run's: counts and sums added,
/// samples appended (in run order), pairs added element by element.
pub trait Merge {
    /// Joins `o` into `self`.
    fn merge(&mut self, o: &Self);
}

impl Merge for usize {
    fn merge(&mut self, o: &Self) {
        *self += o;
    }
}

impl Merge for u64 {
    fn merge(&mut self, o: &Self) {
        *self += o;
    }
}

impl Merge for f64 {
    fn merge(&mut self, o: &Self) {
        *self += o;
    }
}

impl<A: Merge, B: Merge> Merge for (A, B) {
    fn merge(&mut self, o: &Self) {
        self.0.merge(&o.0);
        self.1.merge(&o.1);
    }
}

impl<T: Clone> Merge for Vec<T> {
    fn merge(&mut self, o: &Self) {
        self.extend_from_slice(o);
    }
}

/// A measurement some runs may lack (wall time): the sum, `None` when either is unknown.
impl Merge for Option<f64> {
    fn merge(&mut self, o: &Self) {
        *self = self.zip(*o).map(|(a, b)| a + b);
    }
}

impl Merge for StageCompute {
    fn merge(&mut self, o: &Self) {
        *self = self.plus(*o);
    }
}

impl Merge for Waits {
    fn merge(&mut self, o: &Self) {
        self.count += o.count;
        self.total_s += o.total_s;
    }
}

impl Merge for Faults {
    fn merge(&mut self, o: &Self) {
        self.protective_stops += o.protective_stops;
        self.collisions += o.collisions;
        self.drops += o.drops;
        self.grasp_failures += o.grasp_failures;
        self.parts_lost += o.parts_lost;
    }
}

impl Merge for RecognitionTotals {
    fn merge(&mut self, o: &Self) {
        RecognitionTotals::merge(self, o);
    }
}

/// Declares the tally with each field's rule for joining runs (`sum`: [`Merge`]; `max`: the
/// larger; `max_each`: the larger per element; `keep`: this run's; `ended`: the first run
/// that did not end with its picks done), so a field is declared, documented and merged in
/// one place.
macro_rules! tally {
    ($(#[$sm:meta])* pub struct $name:ident {
        $( $(#[$fm:meta])* pub $f:ident : $t:ty => $rule:ident, )*
    }) => {
        $(#[$sm])*
        pub struct $name {
            $( $(#[$fm])* pub $f: $t, )*
        }

        impl $name {
            /// Adds another run's (or merge's) tally, field by field by its rule: counts and
            /// sums added, samples appended, maxima taken; the label (workpiece, seed) stays
            /// this one's.
            pub fn merge(&mut self, o: &$name) {
                $( tally!(@rule $rule, self.$f, o.$f); )*
            }
        }
    };
    (@rule sum, $a:expr, $b:expr) => { Merge::merge(&mut $a, &$b) };
    (@rule max, $a:expr, $b:expr) => { $a = $a.max($b) };
    (@rule max_each, $a:expr, $b:expr) => {
        for (p, q) in $a.iter_mut().zip($b) {
            *p = p.max(q);
        }
    };
    (@rule keep, $a:expr, $b:expr) => {};
    (@rule ended, $a:expr, $b:expr) => {
        if $a.is_none_or(|e| e == EndReason::PicksDone) {
            $a = $b;
        }
    };
}

tally! {
/// A run's results, tallied as each pick ends, or the merge of several runs' tallies (a table
/// row, a shard merge). What the summaries, tables and shard files of binpick are made from:
/// the samples of exact medians and percentiles (takts, Pick and Place times, compute before
/// motion), counts, sums and maxima. Sums run in pick order, then in the order runs merge.
///
/// Written as one entry of `takt.json` / `sweep.json`'s runs; field names are kept as shard
/// files have always had them, so shards written before still merge. A field's rule after
/// `=>` says how runs join (see the `tally!` macro).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Tally {
    /// Workpiece.
    pub workpiece: String => keep,
    /// Seed (of the first run, when merged).
    pub seed: u64 => keep,
    /// Runs tallied (set when a run ends; not written: an entry of a shard file is one run).
    #[serde(skip_serializing, default = "one")]
    pub runs: usize => sum,
    /// Attempts: every pick, re-captures included.
    pub attempts: usize => sum,
    /// Picks placed.
    pub placed: usize => sum,
    /// Picks the arm set out to make (a grasp chosen, motions generated).
    pub set_out: usize => sum,
    /// Every release-to-release interval after a run's first release (s): the reference's
    /// takt.
    pub takts_s: Vec<f64> => sum,
    /// The intervals that span no pick-tray refill (s).
    pub takts_excl_refills_s: Vec<f64> => sum,
    /// The intervals ending at a release among a run's first [`FIRST_PICKS`] picks (s): the
    /// reference's 20-pick takt (all of `takts_s` in a run of at most 21 picks).
    #[serde(default)]
    pub takts_first_s: Vec<f64> => sum,
    /// The intervals of `takts_s` by what happened in them.
    #[serde(default)]
    pub takt_causes: TaktCauses => sum,
    /// Parts the pick tray's pile holds when poured (the workpiece's `pile_count`; 0 in shard
    /// files written before it was kept).
    #[serde(default)]
    pub pile_count: usize => keep,
    /// Pick times of the placed picks (s).
    pub pick_s: Vec<f64> => sum,
    /// Place times of the placed picks (s).
    pub place_s: Vec<f64> => sum,
    /// Placement position error of the placed picks that measured one (mm).
    #[serde(default)]
    pub placement_error_mm: Vec<f64> => sum,
    /// Placement rotation error of the placed picks that measured one (deg).
    #[serde(default)]
    pub placement_rotation_deg: Vec<f64> => sum,
    /// Compute charged over the picks set out, summed per stage (s).
    #[serde(rename = "compute_sum_s")]
    pub compute_sum: StageCompute => sum,
    /// Compute between each pick's result and the motion it unblocks (grasp and Pick), per
    /// pick set out (s).
    #[serde(default)]
    pub result_to_motion_s: Vec<f64> => sum,
    /// Waits for the sensor in the takts (placed picks with a takt).
    pub sensor_waits: Waits => sum,
    /// Waits for compute in the takts.
    pub compute_waits: Waits => sum,
    /// Faults by kind.
    pub faults: Faults => sum,
    /// Refills of the pick tray.
    pub refills: usize => sum,
    /// Agitations of the pick tray.
    #[serde(default)]
    pub agitations: usize => sum,
    /// Hopper doses into the pick tray.
    #[serde(default)]
    pub doses: usize => sum,
    /// Place-tray exchanges (not written in shard files: no table shows it).
    #[serde(skip)]
    pub place_tray_exchanges: usize => sum,
    /// Captures triggered and spoiled (not written in shard files: no table shows it).
    #[serde(skip)]
    pub captures: (u64, u64) => sum,
    /// Grasps attempted (the cup reached the part) and sealed.
    #[serde(default)]
    pub grasps: (usize, usize) => sum,
    /// Grasp failures on a wrong detection.
    #[serde(default)]
    pub misrecognised: usize => sum,
    /// Blind picks (picks went into the pile after the result's capture): attempted, placed.
    #[serde(default)]
    pub blind_picks: (usize, usize) => sum,
    /// Recognition results the picks set out came from.
    #[serde(default)]
    pub results_used: usize => sum,
    /// Recognition of the results the run used, against the truth at each trigger.
    #[serde(default)]
    pub recognition: RecognitionTotals => sum,
    /// Largest |demanded torque| / limit per joint (before saturation).
    pub peak_demand_ratio: [f64; crate::robot::DOF] => max_each,
    /// Time some joint was saturated (s).
    pub saturated_s: f64 => sum,
    /// Largest servo tracking error (deg).
    pub max_tracking_error_deg: f64 => max,
    /// Simulated time (s).
    pub sim_time_s: f64 => sum,
    /// Wall time of the runs (s): a measurement, not a result, so a deterministic study leaves
    /// it out (`None`) and its files repeat byte for byte; `None` when any run's is unknown.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_s: Option<f64> => sum,
    /// Why the run ended (`None` while it runs; merged: the first run that did not end with
    /// its picks done).
    #[serde(with = "ended_text")]
    pub ended: Option<EndReason> => ended,
    /// The physics faults that ended runs, one per such run, in run order (left out of a file
    /// when none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub physics_faults: Vec<PhysicsFault> => sum,
    /// Every collision, protective stop, lost part and physics fault, in run order (left out of
    /// a file when none): a long run's faults, each with what the event log says of it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub incidents: Vec<Incident> => sum,
}
}

/// A fault the cell met: a collision, a protective stop, a lost part or a physics fault.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Incident {
    /// The run's seed.
    pub seed: u64,
    /// The pick under way, if any.
    pub pick: Option<usize>,
    /// Simulation time (s).
    pub t_s: f64,
    /// What it is (in files as the event log names it: `fault`, `part_lost`, `misplaced`,
    /// `physics_fault`, `motion_start_mismatch`).
    pub kind: IncidentKind,
    /// The event log's line for it.
    pub detail: String,
}

impl Tally {
    /// Adds a finished pick.
    pub fn add(&mut self, r: &PickRecord) {
        self.attempts += 1;
        let placed = r.outcome == Outcome::Placed;
        if let Some(t) = r.takt_s {
            self.takts_s.push(t);
            if r.index < FIRST_PICKS {
                self.takts_first_s.push(t);
            }
            if !r.spans_refill {
                self.takts_excl_refills_s.push(t);
            }
            if let Some(cause) = r.interval_cause {
                self.takt_causes.add(cause, t);
            }
            if placed {
                self.sensor_waits.add(r.stall_sensor_s);
                self.compute_waits.add(r.stall_compute_s);
            }
        }
        if placed {
            self.placed += 1;
            self.pick_s.push(r.pick_s);
            self.place_s.push(r.place_s);
            self.placement_error_mm.extend(r.placement_error_mm);
            self.placement_rotation_deg.extend(r.rotation_error_deg);
        }
        if r.outcome.set_out() {
            self.set_out += 1;
            self.compute_sum = self.compute_sum.plus(r.compute);
            self.result_to_motion_s.push(r.compute.result_to_motion_s());
            if r.from_result == 0 {
                self.results_used += 1;
            }
        }
        self.faults.count(&r.outcome);
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

    /// Placed parts that lay beyond the place tray's tolerance (`misplaced` incidents).
    pub fn misplaced(&self) -> usize {
        self.incidents
            .iter()
            .filter(|i| i.kind == IncidentKind::Misplaced)
            .count()
    }

    /// Placed parts within the place tray's tolerance: what the success rate counts.
    pub fn placed_in_tolerance(&self) -> usize {
        self.placed.saturating_sub(self.misplaced())
    }

    /// The merge of `tallies`, in their order (`None` when there is none).
    pub fn merged<'a>(tallies: impl IntoIterator<Item = &'a Tally>) -> Option<Tally> {
        let mut it = tallies.into_iter();
        let mut all = it.next()?.clone();
        it.for_each(|t| all.merge(t));
        Some(all)
    }
}

/// Everything a run produced (what its watchers kept is theirs).
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Per pick, when the run was asked to keep them ([`crate::cycle::RunOptions::keep_records`];
    /// empty otherwise).
    pub records: Vec<PickRecord>,
    /// The run's tally, taken as each pick ended.
    pub tally: Tally,
    /// Per recognition result (kept when the run keeps its records, else empty).
    pub recognition_per_capture: Vec<RecognitionReport>,
}

/// The takts (s): every release-to-release interval after the run's first release (the
/// reference's definition).
pub fn takts(records: &[PickRecord]) -> Vec<f64> {
    records.iter().filter_map(|r| r.takt_s).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run's tally with a few of every kind of field.
    fn run(seed: u64, takt_s: f64, ended: EndReason) -> Tally {
        Tally {
            workpiece: "A".into(),
            seed,
            runs: 1,
            attempts: 3,
            placed: 2,
            takts_s: vec![takt_s],
            sensor_waits: Waits { count: 1, total_s: 0.5 },
            faults: Faults {
                drops: 1,
                ..Faults::default()
            },
            grasps: (3, 2),
            peak_demand_ratio: [0.5, 0.9, 0.1, 0.1, 0.1, 0.1],
            max_tracking_error_deg: 0.2 * seed as f64,
            wall_s: Some(1.0),
            ended: Some(ended),
            ..Tally::default()
        }
    }

    #[test]
    fn tallies_merge_by_each_fields_rule_and_read_back_as_written() {
        let mut t = run(1, 2.0, EndReason::PicksDone);
        t.merge(&run(2, 3.0, EndReason::Interrupted));
        assert_eq!((t.seed, t.runs, t.attempts, t.placed), (1, 2, 6, 4));
        assert_eq!(t.takts_s, vec![2.0, 3.0]);
        assert_eq!(t.sensor_waits, Waits { count: 2, total_s: 1.0 });
        assert_eq!((t.faults.drops, t.grasps), (2, (6, 4)));
        assert_eq!(t.peak_demand_ratio[1], 0.9);
        assert_eq!(t.max_tracking_error_deg, 0.4);
        assert_eq!(t.wall_s, Some(2.0));
        assert_eq!(t.ended, Some(EndReason::Interrupted));
        // One run's wall time unknown: the sum is unknown.
        t.merge(&Tally {
            wall_s: None,
            ..run(3, 1.0, EndReason::PicksDone)
        });
        assert_eq!((t.wall_s, t.ended), (None, Some(EndReason::Interrupted)));
        // The file layout: faults and waits as arrays, ended as text, runs not written.
        let v = serde_json::to_value(run(1, 2.0, EndReason::TrayEmpty)).unwrap();
        assert_eq!(v["faults"], serde_json::json!([0, 0, 1, 0, 0]));
        assert_eq!(v["sensor_waits"], serde_json::json!([1, 0.5]));
        assert_eq!(v["ended"], "tray empty");
        assert!(v.get("runs").is_none() && v.get("compute_sum_s").is_some());
        let back: Tally = serde_json::from_value(v.clone()).unwrap();
        assert_eq!(back, run(1, 2.0, EndReason::TrayEmpty));
        // Negative control: a reason no run ends with is refused, naming it.
        let mut bad = v;
        bad["ended"] = "bored".into();
        let e = serde_json::from_value::<Tally>(bad).unwrap_err().to_string();
        assert!(e.contains("\"bored\" is not a reason a run ends"), "{e}");
    }

    /// A placed pick ending an interval of `takt_s` with `cause`.
    fn placed(index: usize, takt_s: f64, cause: IntervalCause) -> PickRecord {
        PickRecord {
            takt_s: Some(takt_s),
            interval_cause: Some(cause),
            ..PickRecord::new(index, 0.0, 0.0)
        }
    }

    #[test]
    fn the_takt_splits_by_cause_into_shares_that_add_up_to_its_mean() {
        use IntervalCause::*;
        // The first that applies: refill, failure, dose.
        assert_eq!(IntervalCause::of(true, true, true), Refill);
        assert_eq!(IntervalCause::of(false, true, true), Failed);
        assert_eq!(IntervalCause::of(false, false, true), Dose);
        assert_eq!(IntervalCause::of(false, false, false), Clean);
        let mut t = Tally::default();
        let failed = PickRecord {
            outcome: Outcome::NothingDetected,
            ..PickRecord::new(2, 0.0, 0.0)
        };
        for r in [
            placed(0, 1.0, Clean),
            placed(1, 2.0, Clean),
            failed,
            placed(3, 7.0, Failed),
            placed(4, 5.0, Dose),
        ] {
            t.add(&r);
        }
        let c = t.takt_causes;
        assert_eq!(IntervalCause::ALL.map(|k| c.count(k)), [2, 1, 1, 0]);
        // Mean takt 15 s / 4 = 3.75 s: clean 3/4, failed 7/4, dose 5/4, refill 0.
        assert_eq!(IntervalCause::ALL.map(|k| c.share_s(k)), [0.75, 1.75, 1.25, 0.0]);
        let mean = t.takts_s.iter().sum::<f64>() / t.takts_s.len() as f64;
        let sum: f64 = IntervalCause::ALL.iter().map(|&k| c.share_s(k)).sum();
        assert_eq!(sum, mean);
        // Runs merge by adding; the file holds [count, total] per cause.
        let mut two = t.clone();
        two.merge(&t);
        assert_eq!(two.takt_causes.count(Clean), 4);
        assert_eq!(two.takt_causes.total_s(Failed), 14.0);
        let v = serde_json::to_value(&t).unwrap();
        assert_eq!(
            v["takt_causes"],
            serde_json::json!([[2, 3.0], [1, 7.0], [1, 5.0], [0, 0.0]])
        );
        // Negative control: no interval, no share (not a zero that reads as "no time lost").
        assert!(Tally::default().takt_causes.share_s(Clean).is_nan());
    }
}
