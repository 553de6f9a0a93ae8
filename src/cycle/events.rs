//! What a cell run tells whoever watches it: typed events, pick outcomes, why a run ended, the
//! stages of the time chart, and the one observer interface through which recordings, the
//! time chart, the event log and progress displays see a run.
//!
//! Job: name every kind of thing that happens in the cycle once, as a value (not a string; a
//! pick's outcome and its cause in [`super::outcome`]), with its log line (`kind()` and the `Display` detail) and its severity; and define [`Observer`],
//! whose methods do nothing by default, so a run nobody watches keeps nothing.
//!
//! Units: s (simulation time), m, rad; detail texts print mm and deg. Frames: world.

use std::fmt;

use serde::{Serialize, Serializer};

use super::outcome::{Fault, MotionFailure, Outcome, PhysicsFault};
use crate::grasp::GraspCandidate;
use crate::physics::World;
use crate::sensor::{Capture, CaptureProblem, Detection, RecognitionReport, TruthAtTrigger, TruthMatch};
use crate::servo::Tick;
use crate::trajectory::Motion;

/// A stage of the cell cycle, as the time chart draws it (one lane each, top to bottom).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub enum Stage {
    /// The 3D sensor exposes a depth image.
    Sensor,
    /// Recognition finds parts in the capture.
    Recognition,
    /// The grasp selector ranks suction grasps.
    Grasp,
    /// Motion generation: planning and acceleration of the next motion.
    Planning,
    /// The arm moves to a part and picks it.
    Pick,
    /// A Pick from a recognition result older than the last pick (the pile has changed since
    /// its capture; several picks per capture).
    BlindPick,
    /// The arm moves to the cell's waiting pose and waits there for a recognition result.
    WaitingPose,
    /// The arm carries the part to the place tray and releases it.
    Place,
    /// The cell waits (for the sensor, for compute, a fault reset, a refill).
    Stall,
    /// The feeder works the pick tray while the cell goes on: it vibrates the tray to loosen the
    /// pile (then the pile settles), or its hopper doses while the arm places
    /// (`feeder.dose_while_placing`; a dose the arm waits out is a [`Stage::Stall`]).
    Feeder,
}

/// Why a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndReason {
    /// The asked-for picks were attempted.
    PicksDone,
    /// The pick tray held nothing to pick and the cell file's policy is to end.
    TrayEmpty,
    /// A refilled tray held nothing graspable either.
    NothingGraspableInFullTray,
    /// The arm found no path out of the sensor's view.
    NoPathOutOfView,
    /// Ctrl-C: the run ended after the pick under way.
    Interrupted,
    /// The physics world failed (a pour's deep penetration, a non-finite state): the tally's
    /// `physics_faults` holds the record.
    PhysicsFault,
}

impl EndReason {
    /// The text summaries and tables show.
    pub fn text(self) -> &'static str {
        match self {
            EndReason::PicksDone => "picks done",
            EndReason::TrayEmpty => "tray empty",
            EndReason::NothingGraspableInFullTray => "nothing graspable in a full tray",
            EndReason::NoPathOutOfView => "the arm found no path out of the sensor's view",
            EndReason::Interrupted => "interrupted",
            EndReason::PhysicsFault => "physics fault",
        }
    }
}

impl fmt::Display for EndReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.text())
    }
}

impl Serialize for EndReason {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.text())
    }
}

/// What a stall waited for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StallCause {
    /// The recognition result.
    Sensor,
    /// Grasp selection or motion generation.
    Compute,
}

/// How a part was lost from the cell.
#[derive(Debug, Clone, PartialEq)]
pub enum PartLoss {
    /// It left the tray it was in.
    LeftTray {
        /// The part, named by the physics world.
        body: String,
        /// Which tray.
        tray: &'static str,
        /// What the cell was doing then.
        during: LeftDuring,
    },
    /// A fault pressed it deeper into the tray or a neighbour than the health monitor allows.
    PressedDeep {
        /// Part index.
        part: usize,
        /// Overlap (m).
        depth_m: f64,
    },
}

/// What the cell was doing when a part left its tray: what explains the loss.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LeftDuring {
    /// A hopper dose or a refill was pouring parts in: it bounced out.
    Pour,
    /// This part was on the cup: knocked over the wall by it or by the arm.
    Holding(usize),
    /// This part was on the cup, and the lost one touched it as it left: carried out with it (a
    /// double pick) or slid off it over the wall.
    CarriedWith(usize),
    /// Nothing was on the cup: an agitation, a pile settling, a descent.
    CupEmpty,
}

/// A generated motion of one pick, as the event log reports it.
#[derive(Debug, Clone, PartialEq)]
pub enum Planned {
    /// The Pick motion: transfer to the approach pose and straight descent (s), compute (s).
    Pick {
        /// Transfer duration (s).
        transfer_s: f64,
        /// Descent duration (s).
        descent_s: f64,
        /// Where the descent passes the wrist's singularity and was made with the wrist joints
        /// interpolated, the farthest the tool strays from the line's orientation (rad).
        wrist_deviation_rad: Option<f64>,
        /// Compute charged (s).
        compute_s: f64,
    },
    /// The Place motion: lift, transfer, descent and retreat (s), compute (s).
    Place {
        /// Lift duration (s).
        lift_s: f64,
        /// The lift's acceleration where it is gentle (m/s^2) (`cycle.gentle_lift_hemmed`).
        gentle_lift_m_s2: Option<f64>,
        /// Transfer duration (s).
        transfer_s: f64,
        /// Descent duration (s).
        descent_s: f64,
        /// Retreat duration (s).
        retreat_s: f64,
        /// Where a line (lift, descent or retreat) passes the wrist's singularity and was made
        /// with the wrist joints interpolated, the farthest the tool strays from its line's
        /// orientation (rad).
        wrist_deviation_rad: Option<f64>,
        /// Compute charged (s).
        compute_s: f64,
    },
    /// A grasp's motion (`Pick` or `Place`) could not be generated, and why: the grasp was
    /// passed over for the next.
    Failed {
        /// Why.
        why: MotionFailure,
    },
}

/// A motion's note that a line of it went through the wrist's singularity with the wrist joints
/// interpolated, the tool up to `deviation_rad` off its line's orientation.
fn write_wrist_deviation(f: &mut std::fmt::Formatter<'_>, deviation_rad: Option<f64>) -> std::fmt::Result {
    match deviation_rad {
        Some(d) => write!(
            f,
            "; a line through the wrist's singularity, the wrist joints interpolated (the tool up to {:.2} deg off \
             the line's orientation)",
            d.to_degrees()
        ),
        None => Ok(()),
    }
}

/// Something that happened in the cell.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The sensor was triggered (capture number).
    Capture(u64),
    /// The sensor took a confirming exposure, right after a capture whose image shows new holes
    /// (capture number; [`crate::cycle`]'s sensing step): it only tells still steep faces from a
    /// pile in motion, recognition reads the image before.
    ConfirmingCapture(u64),
    /// The exposure was spoiled.
    CaptureSpoiled(CaptureProblem),
    /// A recognition result arrived: parts detected, parts blurred by motion during the exposure.
    RecognitionReady {
        /// Parts detected.
        detected: usize,
        /// Parts left out because they moved during the exposure.
        blurred: usize,
    },
    /// Grasp selection chose a grasp.
    GraspChosen {
        /// Detection index.
        detection: usize,
        /// Face index.
        face: usize,
        /// Score.
        score: f64,
        /// How hemmed in by its neighbours the part was seen ([`crate::grasp::Score::hemmed`]).
        hemmed: f64,
        /// The tool's lean from vertical, where it comes down along the face's normal (rad).
        lean_rad: Option<f64>,
    },
    /// A motion was generated.
    Planned(Planned),
    /// The arm waited.
    Stall {
        /// For what.
        cause: StallCause,
        /// How long (s).
        duration_s: f64,
    },
    /// The Pick motion started.
    PickStart,
    /// The cup sealed on a part.
    Grasped {
        /// The part the cup holds.
        part: usize,
        /// The part nearest to the chosen detection at the trigger (evaluation only).
        aimed_at: Option<usize>,
        /// Cup axis to the part's centre of mass (m).
        com_offset_m: f64,
        /// Tilt of the tool axis from the face normal (rad).
        tilt_rad: f64,
    },
    /// The Place motion started.
    PlaceStart,
    /// The part came off the cup over its slot.
    Released,
    /// A placed part lies beyond the place tray's tolerances from its place pose.
    Misplaced(PlacementError),
    /// A fault stopped the arm.
    Fault(Fault),
    /// A part was taken out of the cell.
    PartLost(PartLoss),
    /// A pick that failed with the part on the cup let it go over the pick tray.
    PartLetGo,
    /// A slot was skipped (something lies in it).
    SlotSkipped(usize),
    /// The pick tray was exchanged for a full one (pile number).
    Refill(u64),
    /// The physics world failed: the run ends here.
    PhysicsFault(PhysicsFault),
    /// The pick tray was agitated (the how-manieth in a row).
    Agitation(u32),
    /// The hopper began to pour this many parts onto the pile (the arm waits out of the view).
    Dose(usize),
    /// A pick looks for a part in a recognition result: how many picks the result has served
    /// before, and how many picks went into the pile after its capture (the parts near them
    /// are left out).
    ResultUsed {
        /// Picks from this result before.
        taken: usize,
        /// Picks into the pile since its capture.
        since_capture: usize,
    },
    /// The full place tray was exchanged for an empty one.
    PlaceTrayExchange,
    /// A pick ended.
    Outcome(Outcome),
    /// A motion did not start where the arm was, or as fast as it moved.
    MotionStartMismatch(StartMismatch),
}

/// How far a motion's start was from where the arm was and from the velocity the motion before
/// it commanded at its end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartMismatch {
    /// Largest joint position step from the arm's measured position (rad): its tracking error
    /// at least.
    pub q_rad: f64,
    /// Largest step in the commanded joint velocity (rad/s).
    pub qd_rad_s: f64,
}

impl StartMismatch {
    /// Worth a line in the event log (1 mrad, 0.01 rad/s): a hand-over's tracking error shows.
    pub fn is_logged(&self) -> bool {
        self.q_rad > 1e-3 || self.qd_rad_s > 1e-2
    }

    /// A step the servo's feedback answers with a torque spike (0.01 rad, 0.1 rad/s): an
    /// incident, where the tracking errors of well-joined motions (about 1 mrad) are not.
    pub fn is_large(&self) -> bool {
        self.q_rad > 0.01 || self.qd_rad_s > 0.1
    }
}

/// What an incident a tally lists is: one of the events that are incidents, named in files as
/// the event log names the event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IncidentKind {
    /// A collision or a protective stop.
    Fault,
    /// A part that left the pick tray (not by the cup).
    PartLost,
    /// A placed part beyond the place tray's tolerance.
    Misplaced,
    /// A physics fault (deep penetration, NaN), which ends its run.
    PhysicsFault,
    /// A large step between the arm's state and a motion's start.
    MotionStartMismatch,
}

impl Event {
    /// The event's kind, as the event log names it: `capture`, `capture_spoiled`,
    /// `recognition_ready`, `grasp_chosen`, `planned`, `stall`, `pick_start`, `grasped`,
    /// `place_start`, `released`, `misplaced`, `fault`, `part_lost`, `part_let_go`,
    /// `slot_skipped`, `refill`, `place_tray_exchange`, `outcome`, `motion_start_mismatch`.
    pub fn kind(&self) -> &'static str {
        match self {
            Event::Capture(_) => "capture",
            Event::ConfirmingCapture(_) => "confirming_capture",
            Event::CaptureSpoiled(_) => "capture_spoiled",
            Event::RecognitionReady { .. } => "recognition_ready",
            Event::GraspChosen { .. } => "grasp_chosen",
            Event::Planned(_) => "planned",
            Event::Stall { .. } => "stall",
            Event::PickStart => "pick_start",
            Event::Grasped { .. } => "grasped",
            Event::PlaceStart => "place_start",
            Event::Released => "released",
            Event::Misplaced(_) => "misplaced",
            Event::Fault(_) => "fault",
            Event::PartLost(_) => "part_lost",
            Event::PartLetGo => "part_let_go",
            Event::SlotSkipped(_) => "slot_skipped",
            Event::Refill(_) => "refill",
            Event::PhysicsFault(_) => "physics_fault",
            Event::Agitation(_) => "agitation",
            Event::Dose(_) => "dose",
            Event::ResultUsed { .. } => "result_used",
            Event::PlaceTrayExchange => "place_tray_exchange",
            Event::Outcome(_) => "outcome",
            Event::MotionStartMismatch(_) => "motion_start_mismatch",
        }
    }

    /// A fault, a lost or misplaced part, a physics fault: always an incident and a warning.
    fn is_mishap(&self) -> bool {
        matches!(
            self,
            Event::Fault(_) | Event::PartLost(_) | Event::Misplaced(_) | Event::PhysicsFault(_)
        )
    }

    /// The incident it is, if a tally lists it ([`super::Incident`]): a fault, a lost part, a
    /// misplaced part, a physics fault, a large step at a motion's start.
    pub fn incident_kind(&self) -> Option<IncidentKind> {
        match self {
            Event::Fault(_) => Some(IncidentKind::Fault),
            Event::PartLost(_) => Some(IncidentKind::PartLost),
            Event::Misplaced(_) => Some(IncidentKind::Misplaced),
            Event::PhysicsFault(_) => Some(IncidentKind::PhysicsFault),
            Event::MotionStartMismatch(m) if m.is_large() => Some(IncidentKind::MotionStartMismatch),
            _ => None,
        }
    }

    /// Whether a log shows it as a warning: faults, lost and misplaced parts, picks that were
    /// not placed.
    pub fn is_warning(&self) -> bool {
        match self {
            Event::Outcome(o) => *o != Outcome::Placed,
            _ => self.is_mishap(),
        }
    }
}

/// The event's detail, as one line of the event log (empty for some kinds).
impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Event::Capture(id) => write!(f, "capture {id}"),
            Event::ConfirmingCapture(id) => write!(f, "capture {id}, confirming the one before"),
            Event::CaptureSpoiled(problem) => write!(f, "{problem:?}"),
            Event::RecognitionReady { detected, blurred } => write!(
                f,
                "{detected} parts detected, {blurred} blurred by motion during the exposure"
            ),
            Event::GraspChosen {
                detection,
                face,
                score,
                hemmed,
                lean_rad,
            } => {
                write!(
                    f,
                    "detection {detection} face {face} score {score:.3} hemmed {hemmed:.2}"
                )?;
                match lean_rad {
                    Some(lean) => write!(f, ", along its normal, leaning {:.0} deg", lean.to_degrees()),
                    None => Ok(()),
                }
            }
            Event::Planned(Planned::Pick {
                transfer_s,
                descent_s,
                wrist_deviation_rad,
                compute_s,
            }) => {
                write!(
                    f,
                    "Pick motion: transfer {transfer_s:.3} s + descent {descent_s:.3} s ({:.1} ms compute)",
                    1e3 * compute_s
                )?;
                write_wrist_deviation(f, *wrist_deviation_rad)
            }
            Event::Planned(Planned::Place {
                lift_s,
                gentle_lift_m_s2,
                transfer_s,
                descent_s,
                retreat_s,
                wrist_deviation_rad,
                compute_s,
            }) => {
                write!(f, "Place motion: lift {lift_s:.3} s")?;
                if let Some(a) = gentle_lift_m_s2 {
                    write!(f, " (gentle, {a:.1} m/s^2)")?;
                }
                write!(
                    f,
                    " + transfer {transfer_s:.3} s + descent {descent_s:.3} s + retreat {retreat_s:.3} s ({:.1} ms compute)",
                    1e3 * compute_s
                )?;
                write_wrist_deviation(f, *wrist_deviation_rad)
            }
            Event::Planned(Planned::Failed { why }) => {
                write!(f, "{} motion: {why}; the grasp passed over", why.motion())
            }
            Event::Stall { cause, duration_s } => match cause {
                StallCause::Sensor => write!(f, "waiting for the sensor {duration_s:.3} s"),
                StallCause::Compute => write!(f, "waiting for compute {duration_s:.3} s"),
            },
            Event::Grasped {
                part,
                aimed_at,
                com_offset_m,
                tilt_rad,
            } => write!(
                f,
                "part {part} (aimed at part {}), cup axis {:.1} mm from its centre of mass, tilt {:.1} deg",
                aimed_at.map_or("-".to_string(), |p| p.to_string()),
                com_offset_m * 1e3,
                tilt_rad.to_degrees()
            ),
            Event::Fault(Fault::Collision(what)) => write!(f, "collision: {what}"),
            Event::Fault(Fault::ProtectiveStop(what)) => write!(f, "protective stop: {what}"),
            Event::Fault(Fault::NoPathOutOfView(why)) => write!(f, "no path out of the sensor's view: {why}"),
            Event::PartLost(PartLoss::LeftTray { body, tray, during }) => {
                write!(f, "{body} left the {tray}")?;
                match during {
                    LeftDuring::Pour => f.write_str(" in a pour"),
                    LeftDuring::Holding(part) => write!(f, " while part {part} was on the cup"),
                    LeftDuring::CarriedWith(part) => write!(f, " with part {part}, which was on the cup"),
                    LeftDuring::CupEmpty => f.write_str(" with the cup empty"),
                }
            }
            Event::PartLost(PartLoss::PressedDeep { part, depth_m }) => {
                write!(f, "part {part} pressed {:.2} mm deep", depth_m * 1e3)
            }
            Event::Misplaced(m) => write!(
                f,
                "part {} lies {:.2} mm and {:.1} deg from its place pose",
                m.part,
                m.error_m * 1e3,
                m.rotation_rad.to_degrees()
            ),
            Event::PartLetGo => f.write_str("the part stays in the pick tray"),
            Event::SlotSkipped(slot) => write!(f, "slot {slot}"),
            Event::Refill(pile) => write!(f, "pile {pile}"),
            Event::PhysicsFault(fault) => write!(f, "{fault}"),
            Event::Agitation(k) => write!(f, "the pick tray shaken (number {k} in a row)"),
            Event::Dose(parts) => write!(f, "{parts} parts poured from the hopper"),
            Event::ResultUsed { taken, since_capture } => write!(
                f,
                "{taken} pick(s) from this result before, {since_capture} into the pile since its capture"
            ),
            Event::Outcome(o) => write!(f, "{}: {}", o.name(), o.cause()),
            Event::MotionStartMismatch(m) => write!(
                f,
                "a motion started {:.4} rad from the arm, its commanded velocity stepped {:.3} rad/s",
                m.q_rad, m.qd_rad_s
            ),
            Event::PickStart | Event::PlaceStart | Event::Released | Event::PlaceTrayExchange => Ok(()),
        }
    }
}

/// One entry of the event log (`events.json`, the recordings' log).
#[derive(Debug, Clone, Serialize)]
pub struct CycleEvent {
    /// Simulation time (s).
    pub t_s: f64,
    /// Pick index, if the event belongs to one.
    pub pick: Option<usize>,
    /// What ([`Event::kind`]).
    pub kind: &'static str,
    /// Details ([`Event`]'s `Display`).
    pub detail: String,
    /// Shown as a warning ([`Event::is_warning`]).
    #[serde(skip)]
    pub warning: bool,
}

/// A capture, a recognition result and the grasps ranked on it, as the cycle used them.
#[derive(Debug, Clone, Copy)]
pub struct Recognised<'a> {
    /// When the result arrived (s).
    pub t_s: f64,
    /// The recognised parts.
    pub detections: &'a [Detection],
    /// Each detection against the truth at its capture's trigger, in step with `detections`
    /// (evaluation only: for the recordings, never read by a decision); `None` when the result
    /// was not evaluated.
    pub judged: Option<&'a [Option<TruthMatch>]>,
    /// Feasible grasps, best first.
    pub ranked: &'a [GraspCandidate],
    /// Index into `ranked` of the grasp chosen, if any.
    pub chosen: Option<usize>,
}

/// A placed pick's takt by the reference's definition: the interval from the release before.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Takt {
    /// The pick.
    pub pick: usize,
    /// Its release (s).
    pub release_s: f64,
    /// Release to release (s).
    pub takt_s: f64,
    /// Whether a refill of the pick tray fell into the interval.
    pub spans_refill: bool,
}

/// How far a placed part lies from its place pose, measured once the cup has left it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacementError {
    /// The pick that placed it (its record's index).
    pub pick: usize,
    /// The part.
    pub part: usize,
    /// Horizontal distance from its place pose (m).
    pub error_m: f64,
    /// Rotation from its place pose (rad).
    pub rotation_rad: f64,
}

impl PlacementError {
    /// Whether the part lies beyond `tolerance_m` (m) or `tolerance_rad` (rad): the place
    /// tray's `tolerance_m` and `tolerance_deg`.
    pub fn misplaced(&self, tolerance_m: f64, tolerance_rad: f64) -> bool {
        self.error_m > tolerance_m || self.rotation_rad > tolerance_rad
    }
}

/// Watches a cell run. Every method does nothing by default: a run keeps nothing for a watcher
/// that does not ask for it.
pub trait Observer {
    /// An event at simulation time `t_s`, of pick `pick` if it belongs to one.
    fn event(&mut self, _t_s: f64, _pick: Option<usize>, _event: &Event) {}
    /// A stage was busy from `start_s` to `end_s` (only called for positive lengths).
    fn span(&mut self, _stage: Stage, _start_s: f64, _end_s: f64, _label: &str) {}
    /// A moment to mark on the time chart (a release, a fault).
    fn marker(&mut self, _t_s: f64, _label: &str) {}
    /// The world after each physics step (pile pours and refills included).
    fn stepped(&mut self, _world: &World) {}
    /// The sensor took a capture (at its `trigger_s`).
    fn captured(&mut self, _capture: &Capture) {}
    /// The sensor took a confirming exposure (at its `trigger_s`; see
    /// [`Event::ConfirmingCapture`]).
    fn confirming_captured(&mut self, _capture: &Capture) {}
    /// A recognition result was used.
    fn recognised(&mut self, _result: &Recognised<'_>) {}
    /// The recognition result ready at `t_s` was evaluated against the ground truth at its
    /// trigger (evaluation only: the true poses beside the detections).
    fn evaluated(&mut self, _t_s: f64, _truth: &TruthAtTrigger, _report: &RecognitionReport) {}
    /// A motion ran from simulation time `t0_s`: the motion as planned, every servo tick of its
    /// execution (times from the motion's start) and how many of them the world played before
    /// a fault stopped it (all of them otherwise).
    fn executed(&mut self, _t0_s: f64, _planned: &dyn Motion, _ticks: &[Tick], _played: usize) {}
    /// A placed pick's takt, when its pick ended (after its release).
    fn takt(&mut self, _takt: &Takt) {}
}

/// The observer that keeps nothing.
impl Observer for () {}

/// Several observers watching one run, called in order.
pub struct Observers<'a>(pub Vec<&'a mut dyn Observer>);

impl Observer for Observers<'_> {
    fn event(&mut self, t_s: f64, pick: Option<usize>, event: &Event) {
        self.0.iter_mut().for_each(|o| o.event(t_s, pick, event));
    }
    fn span(&mut self, stage: Stage, start_s: f64, end_s: f64, label: &str) {
        self.0.iter_mut().for_each(|o| o.span(stage, start_s, end_s, label));
    }
    fn marker(&mut self, t_s: f64, label: &str) {
        self.0.iter_mut().for_each(|o| o.marker(t_s, label));
    }
    fn stepped(&mut self, world: &World) {
        self.0.iter_mut().for_each(|o| o.stepped(world));
    }
    fn captured(&mut self, capture: &Capture) {
        self.0.iter_mut().for_each(|o| o.captured(capture));
    }
    fn confirming_captured(&mut self, capture: &Capture) {
        self.0.iter_mut().for_each(|o| o.confirming_captured(capture));
    }
    fn recognised(&mut self, result: &Recognised<'_>) {
        self.0.iter_mut().for_each(|o| o.recognised(result));
    }
    fn evaluated(&mut self, t_s: f64, truth: &TruthAtTrigger, report: &RecognitionReport) {
        self.0.iter_mut().for_each(|o| o.evaluated(t_s, truth, report));
    }
    fn executed(&mut self, t0_s: f64, planned: &dyn Motion, ticks: &[Tick], played: usize) {
        self.0.iter_mut().for_each(|o| o.executed(t0_s, planned, ticks, played));
    }
    fn takt(&mut self, takt: &Takt) {
        self.0.iter_mut().for_each(|o| o.takt(takt));
    }
}

/// The event log: every event as a [`CycleEvent`], in time order (stable) when taken.
#[derive(Debug, Clone, Default)]
pub struct EventLog {
    events: Vec<CycleEvent>,
}

impl EventLog {
    /// The events in time order. A few are logged after later ones (compute that ran while the
    /// arm was busy carries the time it finished): a stable sort by time puts them in place.
    pub fn into_sorted(mut self) -> Vec<CycleEvent> {
        self.events.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        self.events
    }

    /// Takes the events at or before `until_s`, in time order (stable); later ones stay.
    pub fn take_until(&mut self, until_s: f64) -> Vec<CycleEvent> {
        let (mut taken, kept) = std::mem::take(&mut self.events)
            .into_iter()
            .partition(|e: &CycleEvent| e.t_s <= until_s);
        self.events = kept;
        taken.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
        taken
    }
}

impl Observer for EventLog {
    fn event(&mut self, t_s: f64, pick: Option<usize>, event: &Event) {
        self.events.push(CycleEvent {
            t_s,
            pick,
            kind: event.kind(),
            detail: event.to_string(),
            warning: event.is_warning(),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_read_as_the_log_always_has() {
        let e = Event::Stall {
            cause: StallCause::Sensor,
            duration_s: 0.4159,
        };
        assert_eq!(
            (e.kind(), e.to_string().as_str()),
            ("stall", "waiting for the sensor 0.416 s")
        );
        let o = Event::Outcome(Outcome::NothingGraspable(crate::pipeline::NoGrasp::NoneFeasible(
            [("crowded", 3)].into_iter().collect(),
        )));
        assert_eq!(o.to_string(), "nothing_graspable: no feasible grasp (crowded 3)");
        // No reason counted (nothing to rank): no empty parentheses.
        let none = crate::pipeline::NoGrasp::NoneFeasible(Default::default());
        assert_eq!(none.to_string(), "no feasible grasp");
        assert!(o.is_warning());
        assert!(!Event::Outcome(Outcome::Placed).is_warning());
        assert_eq!(Event::Outcome(Outcome::Placed).to_string(), "placed: ");
        assert_eq!(EndReason::Interrupted.to_string(), "interrupted");
        assert_eq!(serde_json::to_string(&EndReason::PicksDone).unwrap(), "\"picks done\"");
    }

    /// A placed part beyond the tolerances (2 mm and 5 deg here) of its place pose is
    /// misplaced, and that is an incident; the control: one within both is not.
    #[test]
    fn a_part_placed_off_its_place_pose_is_an_incident() {
        let at = |error_m: f64, deg: f64| PlacementError {
            pick: 165,
            part: 15,
            error_m,
            rotation_rad: deg.to_radians(),
        };
        let misplaced = |e: PlacementError| e.misplaced(0.002, 5f64.to_radians());
        assert!(!misplaced(at(0.0019, 4.9)));
        assert!(misplaced(at(0.0021, 0.0)) && misplaced(at(0.0, 5.1)));
        let flipped = Event::Misplaced(at(0.00303, 179.0));
        assert!(flipped.incident_kind() == Some(IncidentKind::Misplaced) && flipped.is_warning());
        assert_eq!(flipped.kind(), "misplaced");
        // Files name an incident as the event log names its event.
        assert_eq!(serde_json::to_value(IncidentKind::Misplaced).unwrap(), flipped.kind());
        assert_eq!(
            flipped.to_string(),
            "part 15 lies 3.03 mm and 179.0 deg from its place pose"
        );
    }

    /// A step at a motion's start is an incident when the servo's feedback would answer it with
    /// a torque spike; the control: the tracking error a well-joined motion starts with is not.
    /// A lost part says what the cell was doing; no path out of the view says why.
    #[test]
    fn incidents_say_what_happened_and_a_tracking_error_is_not_one() {
        let step = |q_rad, qd_rad_s| Event::MotionStartMismatch(StartMismatch { q_rad, qd_rad_s });
        assert_eq!(step(0.0013, 0.0).incident_kind(), None);
        assert_eq!(step(0.0, 0.05).incident_kind(), None);
        let large = step(0.02, 0.0);
        assert_eq!(large.incident_kind(), Some(IncidentKind::MotionStartMismatch));
        assert_eq!(
            serde_json::to_value(IncidentKind::MotionStartMismatch).unwrap(),
            large.kind()
        );
        assert!(step(0.0, 0.5).incident_kind().is_some());
        assert_eq!(
            step(0.02, 0.5).to_string(),
            "a motion started 0.0200 rad from the arm, its commanded velocity stepped 0.500 rad/s"
        );
        let left = |during| {
            Event::PartLost(PartLoss::LeftTray {
                body: "part 5".into(),
                tray: "pick tray",
                during,
            })
            .to_string()
        };
        assert_eq!(left(LeftDuring::Pour), "part 5 left the pick tray in a pour");
        assert_eq!(
            left(LeftDuring::Holding(7)),
            "part 5 left the pick tray while part 7 was on the cup"
        );
        assert_eq!(
            left(LeftDuring::CupEmpty),
            "part 5 left the pick tray with the cup empty"
        );
        assert_eq!(
            left(LeftDuring::CarriedWith(7)),
            "part 5 left the pick tray with part 7, which was on the cup"
        );
        let no_path = Event::Fault(Fault::NoPathOutOfView(crate::planning::PlanError::StartInCollision(
            "clearance 1.0 mm between link_6 and the pick tray".into(),
        )));
        assert_eq!(
            no_path.to_string(),
            "no path out of the sensor's view: start in collision: clearance 1.0 mm between link_6 and the pick tray"
        );
    }
}
