//! How a pick ended, and why, as values: the outcome of each pick with its typed cause (the
//! gripper's, the planner's, the servo's, the health monitor's), and the faults that stop a motion.
//!
//! Job: carry every cause as the type that found it, so whoever decides on an outcome matches on
//! it; the text (`name()` and the cause's `Display`) is made only where a log, a table or a file
//! is written, and reads as it always has.
//!
//! Units: s, m, rad, N; texts print mm, deg and N. Frames: none.

use std::fmt;

use serde::{Serialize, Serializer};

use crate::physics::{GraspFailure, HealthEvent};
use crate::pipeline::NoGrasp;
use crate::planning::PlanError;
use crate::robot::IkError;
use crate::servo::Trip;

/// Why a pick went wrong or did not start.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// The part was released in its slot.
    Placed,
    /// The cup did not seal on a detection that was right (or that no evaluation judged).
    GraspFailed(NoSeal),
    /// The cup did not seal on a detection that was wrong: the evaluation against the truth at
    /// the trigger names it so (nothing decides on it). Counted as a grasp failure.
    Misrecognised {
        /// How far the believed pose was from the part nearest to it (`None`: no part there).
        believed: Option<WrongPose>,
        /// What the gripper found.
        failure: NoSeal,
    },
    /// The recognition result held no part: re-capture.
    NothingDetected,
    /// Parts were detected but none was graspable (the selector's reasons).
    NothingGraspable(NoGrasp),
    /// No path or trajectory for a motion.
    NoMotion(MotionFailure),
    /// The servo tripped a protective stop.
    ProtectiveStop(Stop),
    /// The arm, the tool or the held part collided, or pressed a part into the tray.
    Collision(HealthEvent),
    /// The part came off the cup on the way.
    Dropped(Slip),
}

impl Outcome {
    /// Whether the arm set out to pick (a grasp was chosen and motions generated), as opposed to
    /// a re-capture. (The success rate counts every pick as an attempt, re-captures too.)
    pub fn set_out(&self) -> bool {
        !matches!(self, Outcome::NothingDetected | Outcome::NothingGraspable(_))
    }

    /// A grasp failure on a detection that was wrong.
    pub fn misrecognised(&self) -> bool {
        matches!(self, Outcome::Misrecognised { .. })
    }

    /// Whether the pick may have left something in the slot it was bound for, so the next part
    /// goes to the next slot: a collision or a protective stop once the Place had begun
    /// (`in_place`: a part that bounced there, or the held one), or a part the cup let go of
    /// while the tool was over the place tray.
    pub fn leaves_slot_taken(&self, in_place: bool) -> bool {
        match self {
            Outcome::Collision(_) | Outcome::ProtectiveStop(_) => in_place,
            Outcome::Dropped(Slip::Moving { over_place_tray, .. }) => *over_place_tray,
            _ => false,
        }
    }

    /// The cup did not seal (on a right or a wrong detection).
    pub fn grasp_failed(&self) -> bool {
        matches!(self, Outcome::GraspFailed(_) | Outcome::Misrecognised { .. })
    }

    /// A short name: `placed`, `grasp_failed`, ...
    pub fn name(&self) -> &'static str {
        match self {
            Outcome::Placed => "placed",
            Outcome::GraspFailed(_) | Outcome::Misrecognised { .. } => "grasp_failed",
            Outcome::NothingDetected => "nothing_detected",
            Outcome::NothingGraspable(_) => "nothing_graspable",
            Outcome::NoMotion(_) => "no_motion",
            Outcome::ProtectiveStop(_) => "protective_stop",
            Outcome::Collision(_) => "collision",
            Outcome::Dropped(_) => "dropped",
        }
    }

    /// The reason as text (empty if the outcome has none).
    pub fn detail(&self) -> String {
        self.cause().to_string()
    }

    /// The reason, written where text is written.
    pub fn cause(&self) -> Cause<'_> {
        Cause(self)
    }
}

/// An outcome's reason as its log text ([`Outcome::cause`]).
pub struct Cause<'a>(&'a Outcome);

impl fmt::Display for Cause<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Outcome::Placed | Outcome::NothingDetected => Ok(()),
            Outcome::GraspFailed(why) => write!(f, "{why}"),
            Outcome::Misrecognised {
                believed: Some(off),
                failure,
            } => write!(f, "misrecognised: {off} ({failure})"),
            Outcome::Misrecognised {
                believed: None,
                failure,
            } => {
                write!(f, "misrecognised: no part there ({failure})")
            }
            Outcome::NothingGraspable(why) => write!(f, "{why}"),
            Outcome::NoMotion(why) => write!(f, "{why}"),
            Outcome::ProtectiveStop(stop) => write!(f, "{stop}"),
            Outcome::Collision(what) => write!(f, "{what}"),
            Outcome::Dropped(slip) => write!(f, "{slip}"),
        }
    }
}

/// As serde writes an enum of one text per variant: `"Placed"`, `{"GraspFailed": "<reason>"}`
/// (a misrecognition is a grasp failure).
impl Serialize for Outcome {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let variant = match self {
            Outcome::Placed => return s.serialize_unit_variant("Outcome", 0, "Placed"),
            Outcome::NothingDetected => return s.serialize_unit_variant("Outcome", 2, "NothingDetected"),
            Outcome::GraspFailed(_) | Outcome::Misrecognised { .. } => (1, "GraspFailed"),
            Outcome::NothingGraspable(_) => (3, "NothingGraspable"),
            Outcome::NoMotion(_) => (4, "NoMotion"),
            Outcome::ProtectiveStop(_) => (5, "ProtectiveStop"),
            Outcome::Collision(_) => (6, "Collision"),
            Outcome::Dropped(_) => (7, "Dropped"),
        };
        s.serialize_newtype_variant("Outcome", variant.0, variant.1, &self.detail())
    }
}

/// Why the cup holds no part after the vacuum built up.
#[derive(Debug, Clone, PartialEq)]
pub enum NoSeal {
    /// The gripper's seal check failed.
    Failed(GraspFailure),
    /// No part on the cup, and the gripper reported no failure.
    Unexplained,
}

impl fmt::Display for NoSeal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NoSeal::Failed(why) => write!(f, "{why}"),
            NoSeal::Unexplained => f.write_str("no seal"),
        }
    }
}

/// How far a wrong detection's believed pose was from the part nearest to it at the trigger
/// (evaluation only).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WrongPose {
    /// The part nearest to the detection.
    pub part: usize,
    /// Distance of the believed origin from the part's (m).
    pub position_error_m: f64,
    /// Rotation from the part to the believed pose (rad).
    pub rotation_error_rad: f64,
}

impl fmt::Display for WrongPose {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "believed pose {:.1} mm / {:.1} deg from part {}",
            self.position_error_m * 1e3,
            self.rotation_error_rad.to_degrees(),
            self.part
        )
    }
}

/// Why a motion of the pick could not be generated.
#[derive(Debug, Clone, PartialEq)]
pub enum MotionFailure {
    /// No path for the Pick transfer.
    PickTransfer(PlanError),
    /// No joint path along the Pick's straight descent to the grasp or its lift.
    PickLine,
    /// No joint solution above the slot.
    PlacePose(IkError),
    /// No path for the Place transfer.
    PlaceTransfer(PlanError),
    /// No joint path along the Place's straight descent.
    PlaceDescent,
    /// No joint path along the Place's straight retreat.
    PlaceRetreat,
}

impl MotionFailure {
    /// Whether it failed at the slot (above it, or on the lines into and out of it), where any
    /// grasp whose part is set down in the same pose fails the same way.
    pub fn at_slot(&self) -> bool {
        matches!(
            self,
            MotionFailure::PlacePose(_) | MotionFailure::PlaceDescent | MotionFailure::PlaceRetreat
        )
    }

    /// The motion that failed: `Pick` or `Place`.
    pub fn motion(&self) -> &'static str {
        match self {
            MotionFailure::PickTransfer(_) | MotionFailure::PickLine => "Pick",
            _ => "Place",
        }
    }
}

impl fmt::Display for MotionFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MotionFailure::PickTransfer(e) => write!(f, "pick transfer: {e}"),
            MotionFailure::PickLine => f.write_str("pick descent or lift: no joint path along the line"),
            MotionFailure::PlacePose(e) => write!(f, "place pose: {e}"),
            MotionFailure::PlaceTransfer(e) => write!(f, "place transfer: {e}"),
            MotionFailure::PlaceDescent => f.write_str("place descent: no joint path along the line"),
            MotionFailure::PlaceRetreat => f.write_str("place retreat: no joint path along the line"),
        }
    }
}

/// A protective stop: what tripped it, and when.
#[derive(Debug, Clone, PartialEq)]
pub struct Stop {
    /// What tripped.
    pub trip: Trip,
    /// From the motion's start (s).
    pub after_s: f64,
}

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} at {:.3} s into the motion", self.trip, self.after_s)
    }
}

/// The part slipped off the cup.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Slip {
    /// While the arm stood still (as the vacuum built up).
    AtRest {
        /// Force the seal had to hold (N).
        required_n: f64,
    },
    /// While a motion played.
    Moving {
        /// From the motion's start (s).
        after_s: f64,
        /// Force the seal had to hold (N).
        required_n: f64,
        /// Force it held (N).
        holding_n: f64,
        /// The tool was over the place tray when the seal let go (the arm's own pose against
        /// the cell's tray): the part may lie in the slot it was bound for.
        over_place_tray: bool,
    },
}

impl fmt::Display for Slip {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Slip::AtRest { required_n } => write!(f, "slipped at rest: {required_n:.2} N"),
            Slip::Moving {
                after_s,
                required_n,
                holding_n,
                over_place_tray,
            } => {
                write!(
                    f,
                    "slipped {after_s:.3} s into the motion: {required_n:.2} N needed, {holding_n:.2} N held"
                )?;
                if *over_place_tray {
                    write!(f, ", over the place tray")?;
                }
                Ok(())
            }
        }
    }
}

/// A fault that stopped a motion.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// The arm, the tool or the held part collided, or pressed a part into the tray.
    Collision(HealthEvent),
    /// The servo tripped a protective stop.
    ProtectiveStop(Stop),
    /// The arm could not leave the sensor's view: why the planner found no path.
    NoPathOutOfView(PlanError),
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The texts the result files hold, from each typed cause; the control: a misrecognised
    /// failure does not read as a plain one.
    #[test]
    fn causes_read_as_the_files_always_had() {
        let tilted = GraspFailure::Tilted {
            tilt_deg: 12.34,
            max_deg: 10.0,
        };
        let plain = Outcome::GraspFailed(NoSeal::Failed(tilted.clone()));
        assert_eq!(
            plain.detail(),
            "approach tilted 12.3 deg from the face normal, the cup seals up to 10.0 deg"
        );
        let wrong = Outcome::Misrecognised {
            believed: Some(WrongPose {
                part: 7,
                position_error_m: 0.01234,
                rotation_error_rad: 0.1,
            }),
            failure: NoSeal::Unexplained,
        };
        assert_eq!(
            wrong.detail(),
            "misrecognised: believed pose 12.3 mm / 5.7 deg from part 7 (no seal)"
        );
        let nothing = Outcome::Misrecognised {
            believed: None,
            failure: NoSeal::Failed(tilted),
        };
        assert!(
            nothing
                .detail()
                .starts_with("misrecognised: no part there (approach tilted")
        );
        assert!(wrong.misrecognised() && wrong.grasp_failed() && !plain.misrecognised() && plain.grasp_failed());
        assert_eq!((wrong.name(), plain.name()), ("grasp_failed", "grasp_failed"));
        assert_eq!(
            serde_json::to_string(&wrong).unwrap(),
            format!("{{\"GraspFailed\":\"{}\"}}", wrong.detail())
        );
        assert_eq!(serde_json::to_string(&Outcome::Placed).unwrap(), "\"Placed\"");
        let slip = Slip::Moving {
            after_s: 0.2,
            required_n: 3.0,
            holding_n: 2.5,
            over_place_tray: false,
        };
        assert_eq!(
            slip.to_string(),
            "slipped 0.200 s into the motion: 3.00 N needed, 2.50 N held"
        );
        let over = Slip::Moving {
            after_s: 0.2,
            required_n: 3.0,
            holding_n: 2.5,
            over_place_tray: true,
        };
        assert_eq!(
            over.to_string(),
            "slipped 0.200 s into the motion: 3.00 N needed, 2.50 N held, over the place tray"
        );
        // A drop over the place tray leaves its slot taken; one elsewhere (the control), a slip
        // at rest or a placed part does not, whether the Place had begun or not.
        for in_place in [false, true] {
            assert!(Outcome::Dropped(over).leaves_slot_taken(in_place));
            assert!(!Outcome::Dropped(slip).leaves_slot_taken(in_place));
            assert!(!Outcome::Dropped(Slip::AtRest { required_n: 1.0 }).leaves_slot_taken(in_place));
            assert!(!Outcome::Placed.leaves_slot_taken(in_place));
        }
        assert_eq!(
            Slip::AtRest { required_n: 1.234 }.to_string(),
            "slipped at rest: 1.23 N"
        );
        assert_eq!(
            MotionFailure::PlaceRetreat.to_string(),
            "place retreat: no joint path along the line"
        );
        // A stop reads in the pendant's terms (J1 to J6, degrees), not as a Rust value.
        let stop = Stop {
            trip: crate::servo::Trip::Saturation {
                joint: 1,
                for_s: 0.020000000000000018,
            },
            after_s: 0.04,
        };
        assert_eq!(
            stop.to_string(),
            "J2 at its torque limit for 0.020 s at 0.040 s into the motion"
        );
        let tracking = crate::servo::Trip::TrackingError {
            joint: 0,
            error_rad: 0.02,
        };
        assert_eq!(tracking.to_string(), "J1 tracking error 1.15 deg");
    }
}

/// What the cell was doing when the physics world failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultDuring {
    /// Pouring a pile (the first, or a refill).
    Pour,
    /// The picks: motions, waits, agitation.
    Cycle,
}

/// A physics fault that ended a run: the health monitor's every problem of the step it was
/// found at (the bodies, the depth), a pour's deep penetration or a non-finite state. The run's
/// tally up to it is kept; the run's `ended` is [`super::EndReason::PhysicsFault`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhysicsFault {
    /// The world's step count at the fault.
    pub step: u64,
    /// Simulation time of the fault (s).
    pub time_s: f64,
    /// What the cell was doing.
    pub during: FaultDuring,
    /// Every problem the monitor found in that step (at least one).
    pub problems: Vec<HealthEvent>,
}

impl PhysicsFault {
    /// The fault of `error`, found while the cell did `during`.
    pub fn new(error: &crate::physics::HealthError, during: FaultDuring) -> Self {
        PhysicsFault {
            step: error.step,
            time_s: error.time_s,
            during,
            problems: error.events.clone(),
        }
    }
}

impl fmt::Display for PhysicsFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let during = match self.during {
            FaultDuring::Pour => "pouring a pile",
            FaultDuring::Cycle => "picking",
        };
        let problems: Vec<String> = self.problems.iter().map(ToString::to_string).collect();
        write!(
            f,
            "physics fault at step {} ({during}): {}",
            self.step,
            problems.join("; ")
        )
    }
}
