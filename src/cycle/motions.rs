//! Cycle step 2, motion generation: from a recognition result to the Pick and Place motions of
//! one pick.
//!
//! Job: choose the grasp ([`crate::pipeline::choose_grasp`]); plan the Pick transfer from
//! where the arm is to the approach pose above the grasp in the planning scene of that grasp,
//! accelerate it under the torque limits less the cell's torque margin inside the certified
//! corridor, and add the straight descent; then, with the part on the cup (as the controller
//! believes it: the nominal part at the cup centre), the straight lift, the Place transfer to above the slot (planned with the part's box on the
//! hand, slowed where the cup's holding force would not hold), the straight descent to the
//! release pose and the straight retreat. A grasp whose motions cannot be generated is passed
//! over for the next: a pick starts only with its Place in hand. The wall time of each stage is
//! measured.
//!
//! Units: m, rad, s. Frames: world (`world_from_tool`), the tool frame for the held part
//! (`tool_from_part`), the flange frame for payloads.

use std::time::Instant;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand_chacha::ChaCha8Rng;

use super::Cell;
use super::Run;
use super::events::Recognised;
use super::outcome::MotionFailure;
use super::play::{Capture, Segment, SegmentMotion, Settle, Valve};
use super::records::StageCompute;
use super::sensing::SensedResult;
use crate::geometry::{NamedBox, SealBudget};
use crate::grasp::GraspCandidate;
use crate::pipeline::{ChosenGrasp, GraspContext, NoGrasp, SensedPile, choose_grasp};
use crate::planning::{CollisionModel, PlanOptions, RobotSpheres};
use crate::robot::{JointVector, Payload};
use crate::sensor::Detection;
use crate::trajectory::{
    CORRIDOR_CHECK_DT_S, LineLimits, LineMotion, Motion, OverlapCheck, Overlapped, Trajectory, accelerate_in_corridor,
    limit_tool_force, overlap_end, release_lead_s, straight_line,
};

/// The part is released at least this far above its resting height in the slot (m) (the
/// recognised pose is a little off; the part drops the rest). See `Cell::release_above_m`.
pub const RELEASE_ABOVE_M: f64 = 0.003;
/// The tilt a part may hang at on the cup, in standard deviations of the recognition's angular
/// noise per axis (the tilt of two axes' Gaussian errors is Rayleigh: 3.5 sigma covers 99.8 %).
pub const RELEASE_TILT_SIGMAS: f64 = 3.5;
/// Time step of the release-lead check along the end of the Place's descent (s).
const LEAD_CHECK_DT_S: f64 = 0.001;

/// The Place transfer ends this far above the release pose (m).
pub const PLACE_APPROACH_M: f64 = 0.03;

/// The Place transfer's goal for a grasp: the tool [`PLACE_APPROACH_M`] above where the part
/// touches down in its slot.
pub fn above_place(grasp: &GraspCandidate) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(grasp.world_from_tool_place.translation.vector + Vector3::z() * PLACE_APPROACH_M),
        grasp.world_from_tool_place.rotation,
    )
}

/// The least acceleration of a gentle lift, as a share of the cell's line acceleration
/// (`cycle.gentle_lift_hemmed`): where even that leaves no room for a neighbour's push, the lift
/// runs at it and the seal decides.
pub const GENTLE_LIFT_FLOOR: f64 = 0.1;

/// The lift's limits for a grasp with the tool turned `world_from_tool`, the part held within
/// `seal`: the cell's `line` limits, or, where the selector saw the part hemmed in by its
/// neighbours (`hemmed`, [`crate::grasp::Score::hemmed`]) beyond `gentle_above`
/// (`cycle.gentle_lift_hemmed`) and the lift at the cell's acceleration leaves the budget no
/// room for a neighbour's push (one part's weight across the cup's axis at the depth of the
/// part's centre of mass below the lip: [`SealBudget::lift_accel_with_room`]), the largest
/// acceleration down to [`GENTLE_LIFT_FLOOR`] of the cell's that leaves it. The controller's reading: the
/// pose and the centre of mass are the recognised ones; the neighbour is assumed, not measured.
fn lift_limits(
    line: LineLimits,
    gentle_above: Option<f64>,
    hemmed: f64,
    world_from_tool: &UnitQuaternion<f64>,
    seal: &SealBudget,
) -> LineLimits {
    if gentle_above.is_none_or(|above| hemmed <= above) {
        return line;
    }
    let floor_m_s2 = GENTLE_LIFT_FLOOR * line.accel_m_s2;
    LineLimits {
        accel_m_s2: seal
            .lift_accel_with_room(world_from_tool, floor_m_s2, line.accel_m_s2)
            .unwrap_or(floor_m_s2),
        ..line
    }
}

/// The Place motion after the lift.
pub(super) struct PlaceMotion {
    /// Transfer to above the slot, with the part.
    pub transfer: Trajectory,
    /// Straight descent to the release pose.
    pub descent: LineMotion,
    /// Straight retreat without the part.
    pub retreat: LineMotion,
    /// The transfer's time scaling for the cup's holding force (1: none).
    pub suction_speed_factor: f64,
    /// The lift and the transfer overlapped, when that is clear, within the torques and within
    /// the holding force.
    pub lift_blend: Option<Overlapped>,
    /// The transfer and the descent overlapped, likewise.
    pub descent_blend: Option<Overlapped<Trajectory, LineMotion>>,
    /// The vacuum valve closes this long before the descent ends (s): at most the cell file's
    /// `release_lead_s`, and no longer than keeps the part on the venting cup, by the
    /// controller's model, until the cup stops ([`release_lead_s`]).
    pub release_lead_s: f64,
}

impl PlaceMotion {
    /// From the transfer's start to the end of the descent (s) (with the descent's overlap).
    pub fn carry_s(&self) -> f64 {
        match &self.descent_blend {
            Some(d) => d.duration_s(),
            None => self.transfer.duration_s() + self.descent.duration_s(),
        }
    }

    /// The carry to the slot with `held`: the transfer (its start overlapping the lift's end
    /// when the lift was played as `lift_blend`'s head) and the descent (its start overlapping
    /// the transfer's end, if so), one segment where they overlap; the valve closes
    /// `release_lead_s` before the descent ends. A capture may run as `capture` says.
    pub(super) fn carry<'m>(
        &'m self,
        lift_blend: Option<&'m Overlapped>,
        held: Payload,
        capture: Capture,
    ) -> Vec<Segment<'m>> {
        let descent = |motion: SegmentMotion<'m>| {
            let close_s = (motion.as_motion().duration_s() - self.release_lead_s).max(0.0);
            Segment {
                motion,
                payload: held,
                valve: Some(Valve::CloseAt(close_s)),
                settle: Settle::InPosition,
                capture,
            }
        };
        let transfer = |motion: SegmentMotion<'m>| Segment {
            motion,
            payload: held,
            valve: None,
            settle: Settle::AtEnd,
            capture,
        };
        match (lift_blend, &self.descent_blend) {
            (Some(b), Some(d)) => vec![descent(
                Overlapped::new(b.first().clone(), d.clone(), b.start_s()).rest().into(),
            )],
            (None, Some(d)) => vec![descent(d.into())],
            (Some(b), None) => vec![transfer(b.rest().into()), descent((&self.descent).into())],
            (None, None) => vec![transfer((&self.transfer).into()), descent((&self.descent).into())],
        }
    }
}

/// The shares of a straight line (the lift, a descent) that may run while the transfer next to
/// it moves, tried largest first (`cycle.overlap_lines`). The rest of the line runs alone: the
/// lift's start straight up off the pile, a descent's end straight onto the face or into the
/// slot.
pub const LINE_OVERLAP_SHARES: [f64; 3] = [0.6, 0.4, 0.2];
/// Where two motions run at once, each joint's torque stays within this share of the
/// accelerator's limits, or within what the two motions alone demand there if that is more
/// (the accelerator takes the transfers up to about 95-100 % of its limits on their own). At
/// 100 % regardless of the motions alone, the servo's feedback on top once demanded 101 % of
/// J1's limit on F.
pub const OVERLAP_TORQUE_SHARE: f64 = 0.9;

/// The last Place's retreat and this pick's Pick (its transfer, then its descent, overlapped or
/// not) overlapped: the transfer starts while the cup still rises out of the place tray.
pub(super) struct RetreatBlend {
    /// The retreat, and the Pick started `motion.start_s()` into it.
    pub motion: Overlapped<LineMotion, Overlapped<Trajectory, LineMotion>>,
    /// When the Pick's descent starts, from the Pick's start (s).
    pub descent_from_s: f64,
}

/// A placed part's box in the planning model grows by this on every side (m) (its placement
/// error is a few tenths of a millimetre).
pub const PLACED_PART_MARGIN_M: f64 = 0.002;

/// The planning scene and the payload with the part on the cup.
pub(super) struct Holding<'a> {
    /// The cell and the pile with the part's box on the hand.
    pub model: &'a CollisionModel,
    /// Hand and part as the controller believes them.
    pub payload: Payload,
    /// What the part may ask of the cup: [`crate::geometry::SUCTION_MARGIN`] of its holding force.
    pub seal: SealBudget,
}

/// The motions of one pick, generated from one recognition result.
pub(super) struct Prepared {
    /// The grasp (with where the part goes: `world_from_part_place`).
    pub grasp: GraspCandidate,
    /// Transfer to the approach pose.
    pub pick_transfer: Trajectory,
    /// Straight descent to the grasp.
    pub descent: LineMotion,
    /// The transfer and the descent overlapped, when that is clear and within the torques
    /// (`cycle.overlap_lines`).
    pub pick_blend: Option<Overlapped<Trajectory, LineMotion>>,
    /// The last Place's retreat overlapped with this Pick, when the Pick was generated before
    /// the retreat started and the overlap is clear and within the torques.
    pub retreat_blend: Option<RetreatBlend>,
    /// Straight lift with the part, generated while the Pick runs.
    pub lift: LineMotion,
    /// The lift's acceleration where it is gentle, below the cell's (m/s^2)
    /// (`cycle.gentle_lift_hemmed`).
    pub gentle_lift_m_s2: Option<f64>,
    /// The Place motion, generated while the Pick runs.
    pub place: PlaceMotion,
    /// Hand and part as the controller believes them (the nominal part at the cup centre).
    pub held: Payload,
    /// Where the part will sit on the tool, as recognised (`tool_from_part`): the planner's held
    /// part, and what the sensor's self-filter masks with the part on the cup.
    pub tool_from_part: nalgebra::Isometry3<f64>,
    /// Why the motions of each better-ranked grasp tried before it could not be generated
    /// ([`Run::prepare`]): each was passed over, its compute spent.
    pub passed_over: Vec<MotionFailure>,
}

impl Prepared {
    /// The Pick's transfer from `transfer` and its descent with the `hand`, as generated: after
    /// the last Place's retreat (overlapped with it), overlapped with each other, or one after
    /// the other. The valve opens `vacuum_lead_s` before the descent ends; no capture runs.
    pub(super) fn pick<'m>(&'m self, transfer: &'m Trajectory, hand: Payload, vacuum_lead_s: f64) -> [Segment<'m>; 2] {
        let (to, down): (SegmentMotion<'m>, SegmentMotion<'m>) = match (&self.retreat_blend, &self.pick_blend) {
            (Some(rb), _) => {
                let (m, s) = (&rb.motion, rb.motion.start_s());
                (
                    m.window(s, s + rb.descent_from_s).into(),
                    m.window(s + rb.descent_from_s, m.duration_s()).into(),
                )
            }
            (None, Some(b)) => (b.head().into(), b.rest().into()),
            (None, None) => (transfer.into(), (&self.descent).into()),
        };
        let open_s = (down.as_motion().duration_s() - vacuum_lead_s).max(0.0);
        [
            Segment::new(to, hand).flowing_on(),
            Segment::new(down, hand).switching(Valve::OpenAt(open_s)),
        ]
    }
}

impl Cell<'_> {
    /// How far above its resting height the part is released (m): [`RELEASE_ABOVE_M`] plus how
    /// far a tilt of the part on the cup ([`RELEASE_TILT_SIGMAS`] of the recognition's angular
    /// noise) lowers its farthest corner. The cup is aligned with the recognised face, so a
    /// part hangs as tilted as the recognition was wrong: a 150 mm strip 2.7 deg off dips 3.5 mm
    /// at its ends, and with 3 mm alone C's strip once touched the place-tray floor while still
    /// on the cup (a collision).
    pub(super) fn release_above_m(&self) -> f64 {
        let h = self.shape.half_extents_m;
        let tilt_rad = (RELEASE_TILT_SIGMAS * self.scene.sensor.pose_noise_deg).to_radians();
        RELEASE_ABOVE_M + h.x.hypot(h.y) * tilt_rad.sin()
    }

    /// The cell's straight-line speed and acceleration (`cycle.line_speed_m_s`,
    /// `cycle.line_accel_m_s2`).
    pub(super) fn line_limits(&self) -> LineLimits {
        LineLimits {
            speed_m_s: self.scene.cycle.line_speed_m_s,
            accel_m_s2: self.scene.cycle.line_accel_m_s2,
            wrist_deviation_max_rad: self.scene.cycle.wrist_deviation_max_deg.to_radians(),
        }
    }

    /// A straight tool line within `limits` (most lines: [`Cell::line_limits`]), torque-limited
    /// and, with a part on the cup, limited to the cup's holding force.
    pub(super) fn line(
        &self,
        q_from: &JointVector,
        from: &Isometry3<f64>,
        to: &Isometry3<f64>,
        payload: &Payload,
        seal: Option<&SealBudget>,
        limits: &LineLimits,
    ) -> Option<LineMotion> {
        // Within the accelerator's torque share, like every other motion: the margin covers
        // the plant's model error and the servo's feedback.
        straight_line(
            &self.accel_robot,
            &self.accel_robot.dynamics(payload),
            q_from,
            from,
            to,
            limits,
            seal,
        )
    }

    /// `second` started while `first` ends ([`overlap_end`]): by the largest of
    /// [`LINE_OVERLAP_SHARES`] of `line_s` (the lift's or the descent's duration) whose overlap
    /// is clear in `model`, within [`OVERLAP_TORQUE_SHARE`] of the accelerator's torques (or
    /// what the motions alone demand there) with `payload`, and within `seal` with a part
    /// held. None when the cell does not overlap lines (`cycle.overlap_lines`).
    pub(super) fn overlap_end<A: Motion + Clone, B: Motion + Clone>(
        &self,
        first: &A,
        second: &B,
        line_s: f64,
        payload: &Payload,
        model: &CollisionModel,
        seal: Option<&SealBudget>,
    ) -> Option<Overlapped<A, B>> {
        if !self.scene.cycle.overlap_lines {
            return None;
        }
        let check = OverlapCheck {
            robot: self.robot,
            accel_robot: &self.accel_robot,
            dynamics: &self.accel_robot.dynamics(payload),
            model,
            seal,
            torque_share: OVERLAP_TORQUE_SHARE,
            // On the physics step's grid: the head ends moving, and a last step shorter than
            // the others would show the cup a jump in acceleration.
            grid_s: self.scene.sim.physics_dt_s,
        };
        overlap_end(first, second, line_s, &LINE_OVERLAP_SHARES, &check)
    }

    /// The Pick's motions from `q_now` to `grasp` in the scene `empty` (the pile as seen, the part
    /// cut out): the transfer to the approach pose (or why not), the straight descent (if the
    /// line has a joint path) and, where clear and within the torques, the two overlapped.
    #[allow(clippy::type_complexity)]
    fn pick_motion(
        &self,
        q_now: &JointVector,
        grasp: &GraspCandidate,
        empty: &CollisionModel,
        rng: &mut ChaCha8Rng,
    ) -> (
        Result<Trajectory, MotionFailure>,
        Option<LineMotion>,
        Option<Overlapped<Trajectory, LineMotion>>,
    ) {
        let (robot, hand) = (self.robot, self.hand);
        let q_approach = JointVector::from(grasp.q_approach);
        let dyn_hand = robot.dynamics(&hand);
        let pick_transfer = empty
            .plan(q_now, &q_approach, &PlanOptions::default(), rng)
            .map(|p| {
                let via: Vec<JointVector> = p.waypoints.iter().map(|q| JointVector::from(*q)).collect();
                accelerate_in_corridor(&self.accel_robot, &dyn_hand, &via, empty, CORRIDOR_CHECK_DT_S)
                    .1
                    .trajectory
            })
            .map_err(MotionFailure::PickTransfer);
        let descent = self.line(
            &q_approach,
            &grasp.world_from_tool_approach,
            &grasp.world_from_tool,
            &hand,
            None,
            &self.line_limits(),
        );
        // The descent starts while the transfer ends, where the pile as seen allows.
        let pick_blend = match (&pick_transfer, &descent) {
            (Ok(t), Some(d)) => self.overlap_end(t, d, d.duration_s(), &hand, empty, None),
            _ => None,
        };
        (pick_transfer, descent, pick_blend)
    }

    /// The last Place's retreat `r` overlapped with the Pick (transfer `t`, descent `d`, and
    /// their overlap `pick_blend`): the transfer starts while the retreat ends, where the cell,
    /// the pile as seen in `empty` and the parts placed in this place tray before slot
    /// `slot_index` allow (each where the cell put it: its slot, its box grown by
    /// [`PLACED_PART_MARGIN_M`]); the retreat ends before the descent starts.
    fn retreat_blend(
        &self,
        r: &LineMotion,
        t: &Trajectory,
        d: &LineMotion,
        pick_blend: Option<&Overlapped<Trajectory, LineMotion>>,
        slot_index: usize,
        empty: &CollisionModel,
    ) -> Option<RetreatBlend> {
        let robot = self.robot;
        let (pick, descent_from_s) = match pick_blend {
            Some(b) => (b.clone(), b.start_s()),
            None => (Overlapped::new(t.clone(), d.clone(), t.duration_s()), t.duration_s()),
        };
        let mut placed = empty.env.clone();
        let filled = (slot_index % self.slots.len()).min(self.slots.len());
        placed.boxes.extend(self.slots[..filled].iter().map(|s| NamedBox {
            name: "placed part".into(),
            world_from_box: *s,
            half_m: self.shape.half_extents_m.add_scalar(PLACED_PART_MARGIN_M),
        }));
        let placed = CollisionModel::new(robot, RobotSpheres::new(robot, self.scene, None), placed);
        self.overlap_end(r, &pick, r.duration_s(), &self.hand, &placed, None)
            .filter(|o| r.duration_s() - o.start_s() <= descent_from_s + 1e-9)
            .map(|motion| RetreatBlend { motion, descent_from_s })
    }

    /// The Place motion of `grasp` after the `lift` (from the lifted pose `q_lifted` when there
    /// is none): the transfer to above the slot in the `holding` scene, slowed where the
    /// cup's holding force would not hold, the straight descent to the release pose, the
    /// straight retreat, their overlaps and the release lead; or why not.
    fn place_motion(
        &self,
        grasp: &GraspCandidate,
        q_lifted: JointVector,
        lift: Option<&LineMotion>,
        holding: &Holding<'_>,
        rng: &mut ChaCha8Rng,
    ) -> Result<PlaceMotion, MotionFailure> {
        let (robot, hand, held, seal) = (self.robot, self.hand, holding.payload, &holding.seal);
        let above_place = above_place(grasp);
        let release_pose = Isometry3::from_parts(
            Translation3::from(grasp.world_from_tool_place.translation.vector + Vector3::z() * self.release_above_m()),
            grasp.world_from_tool_place.rotation,
        );
        let dyn_held = robot.dynamics(&held);
        let q_above = robot
            .ik_tool_nearest(&above_place, &JointVector::from(grasp.q_place))
            .map_err(MotionFailure::PlacePose)?
            .q;
        let q_lifted = lift.map_or(q_lifted, LineMotion::end_q);
        let path = holding
            .model
            .plan(&q_lifted, &q_above, &PlanOptions::default(), rng)
            .map_err(MotionFailure::PlaceTransfer)?;
        let via: Vec<JointVector> = path.waypoints.iter().map(|q| JointVector::from(*q)).collect();
        let (via, acc, _) =
            accelerate_in_corridor(&self.accel_robot, &dyn_held, &via, holding.model, CORRIDOR_CHECK_DT_S);
        let (transfer, k) = limit_tool_force(robot, &via, &acc.limits, seal);
        let down = self
            .line(
                &q_above,
                &above_place,
                &release_pose,
                &held,
                Some(seal),
                &self.line_limits(),
            )
            .ok_or(MotionFailure::PlaceDescent)?;
        let q_release = down.end_q();
        let up = self
            .line(
                &q_release,
                &release_pose,
                &above_place,
                &hand,
                None,
                &self.line_limits(),
            )
            .ok_or(MotionFailure::PlaceRetreat)?;
        // The transfer starts while the part still rises, and the descent into the slot
        // while the transfer ends, once the lift is over.
        let blend = lift.and_then(|l| self.overlap_end(l, &transfer, l.duration_s(), &held, holding.model, Some(seal)));
        let lift_end_s = lift.map_or(0.0, LineMotion::duration_s);
        let descent_blend = self
            .overlap_end(&transfer, &down, down.duration_s(), &held, holding.model, Some(seal))
            .filter(|d| blend.as_ref().is_none_or(|b| b.start_s() + d.start_s() >= lift_end_s));
        // The valve closes before the cup stops, as long before as the venting cup, with
        // the planning margin on what is left of its force, keeps the part until then.
        let (max_lead_s, venting_s) = (self.scene.cycle.release_lead_s, self.scene.gripper.release_s);
        let lead_s = match &descent_blend {
            Some(d) => release_lead_s(robot, d, LEAD_CHECK_DT_S, max_lead_s, venting_s, seal),
            None => release_lead_s(robot, &down, LEAD_CHECK_DT_S, max_lead_s, venting_s, seal),
        };
        Ok(PlaceMotion {
            transfer,
            descent: down,
            retreat: up,
            suction_speed_factor: k,
            lift_blend: blend,
            descent_blend,
            release_lead_s: lead_s,
        })
    }
}

/// Grasps whose motions the cycle tries to generate for one result before it gives up on the
/// result: the best-ranked clear grasp and the next ones, as a controller tries its candidates.
pub const MOTION_CANDIDATES: usize = 3;

/// A grasp whose Place pose lies within this of one whose Place could not be generated is passed
/// over without trying (m, rad): every part goes to the same slot at the same yaw, so another
/// part held by the same face meets the same joint limits and wrist singularity there.
const SAME_PLACE_M: f64 = 1e-3;
const SAME_PLACE_RAD: f64 = 0.02;

/// Why no pick was prepared from a recognition result.
#[derive(Debug, Clone)]
pub(super) enum Unprepared {
    /// No grasp to try: the grasp selector's reason, and the wall time it took (s, in
    /// `grasp_s`).
    NoGrasp { why: NoGrasp, wall: StageCompute },
    /// Grasps were chosen, but the Pick and Place motions of none of those tried could be
    /// generated: each one's failure, best-ranked first, and the wall time spent (s; the
    /// motions' in `grasp_s`, as [`Cell::charged`] counts them).
    NoMotion {
        failures: Vec<MotionFailure>,
        wall: StageCompute,
    },
}

impl Cell<'_> {
    /// The compute charged on the simulation clock for a pick prepared in `wall` (s) after
    /// `passed_over` grasps whose motions failed: the measured wall time, or in deterministic
    /// mode the cell's budgets. The motions of a grasp passed over count as grasp selection
    /// (a grasp is chosen once its Pick and Place motions exist): the Pick starts after them.
    pub(super) fn charged(&self, wall: StageCompute, passed_over: usize) -> StageCompute {
        if !self.opts.deterministic {
            return wall;
        }
        let b = self.budgets;
        StageCompute {
            grasp_s: b.grasp_s + passed_over as f64 * (b.pick_s + b.place_s),
            ..b
        }
    }
}

impl Run<'_, '_> {
    /// The compute charged on the simulation clock for a result from which no pick was
    /// prepared (s): the grasp selection, and the motions of the grasps tried (as
    /// [`Cell::charged`] counts them); with nothing detected, the grasp selection's budget.
    pub(super) fn unprepared_compute_s(&self, why: Option<&Unprepared>) -> f64 {
        match why {
            Some(Unprepared::NoMotion { failures, wall }) => self.cell.charged(*wall, failures.len()).grasp_s,
            Some(Unprepared::NoGrasp { wall, .. }) => self.cell.charged(*wall, 0).grasp_s,
            None => self.cell.budgets.grasp_s,
        }
    }

    /// Waits out the compute charged for a result from which no pick was prepared
    /// ([`Run::unprepared_compute_s`]), started at `compute_from_s` or now, whichever is later;
    /// returns it (s).
    pub(super) fn wait_out_unprepared(
        &mut self,
        why: Option<&Unprepared>,
        compute_from_s: f64,
    ) -> Result<f64, super::CycleError> {
        let spent_s = self.unprepared_compute_s(why);
        self.idle_until(self.st.world.time_s().max(compute_from_s) + spent_s)?;
        Ok(spent_s)
    }

    /// Grasp selection and motion generation for one recognition result (its detections), from
    /// `t_s`, the part to go to place slot `slot_index`; with `retreat` (the last Place's retreat,
    /// not started yet, from the part released in the slot before `slot_index`), the Pick
    /// overlapped with it where it can be. A grasp whose Pick or Place motions cannot be generated
    /// is passed over for the next one (up to [`MOTION_CANDIDATES`]): a pick starts only with its
    /// Place in hand. Returns the motions and the wall time of each stage (s), or why nothing can
    /// be picked.
    pub(super) fn prepare(
        &mut self,
        result: &SensedResult,
        t_s: f64,
        slot_index: usize,
        retreat: Option<&LineMotion>,
    ) -> Result<(Prepared, StageCompute), Unprepared> {
        let cell = self.cell;
        let wall = Instant::now();
        let (job, detections) = (&result.job, result.detections.as_deref().unwrap_or(&[]));
        let slot = cell.slots[slot_index % cell.slots.len()];
        // Compute that starts before the last motion ends plans from where it was planned to end.
        let q_now = match self.st.planned_end_q {
            Some(q) if t_s < self.st.arm.free_s - 1e-9 => q,
            _ => self.st.world.joints(),
        };
        let ctx = GraspContext {
            scene: cell.scene,
            robot: cell.robot,
            selector: &cell.selector,
            pick_tray: self.st.world.pick_tray(),
            part_half_extents_m: cell.shape.half_extents_m,
        };
        // The capture's maps, binned once for every pick chosen on it.
        let sensed = match self.st.sensed.take() {
            Some(s) if s.is_of(&job.capture, ctx.pick_tray) => s,
            _ => SensedPile::new(&ctx, &job.capture, &job.arm),
        };
        let plan = ctx.selector.select(detections, &sensed.height_map, &slot, &q_now);
        let mut spent = StageCompute {
            grasp_s: wall.elapsed().as_secs_f64(),
            ..StageCompute::default()
        };
        // The grasps tried whose motions failed (by rank), and the place poses that failed.
        let (mut passed_over, mut failed_places) = (Vec::<usize>::new(), Vec::<Isometry3<f64>>::new());
        let mut failures = Vec::new();
        let mut outcome = None;
        while passed_over.len() < MOTION_CANDIDATES {
            let wall = Instant::now();
            let chosen = choose_grasp(&ctx, &sensed, detections, &plan, &self.st.failed_spots, |rank| {
                let place = &plan.ranked[rank].world_from_tool_place;
                passed_over.contains(&rank)
                    || failed_places.iter().any(|p| {
                        (p.translation.vector - place.translation.vector).norm() < SAME_PLACE_M
                            && p.rotation.angle_to(&place.rotation) < SAME_PLACE_RAD
                    })
            });
            spent.grasp_s += wall.elapsed().as_secs_f64();
            let Some(chosen) = chosen else { break };
            let (rank, place) = (chosen.rank, chosen.grasp.world_from_tool_place);
            let mut this = StageCompute::default();
            match self.grasp_motions(chosen, detections, &q_now, slot_index, retreat, &mut this) {
                Ok(prep) => {
                    (spent.pick_s, spent.place_s) = (this.pick_s, this.place_s);
                    outcome = Some((rank, prep));
                    break;
                }
                Err(failure) => {
                    spent.grasp_s += this.pick_s + this.place_s;
                    // A failure at the slot passes over its place pose; one at the grasp only
                    // the grasp.
                    if failure.at_slot() {
                        failed_places.push(place);
                    }
                    passed_over.push(rank);
                    failures.push(failure);
                }
            }
        }
        self.obs.recognised(&Recognised {
            t_s,
            detections,
            judged: result.evaluation.as_ref().map(|e| &e.matches[..]),
            ranked: &plan.ranked,
            chosen: outcome.as_ref().map(|(rank, _)| *rank),
        });
        self.st.sensed = Some(sensed);
        match (outcome, failures.first()) {
            (Some((_, mut prep)), _) => {
                prep.passed_over = failures;
                Ok((prep, spent))
            }
            (None, None) => Err(Unprepared::NoGrasp {
                why: crate::pipeline::why_none(&plan),
                wall: spent,
            }),
            (None, Some(_)) => Err(Unprepared::NoMotion { failures, wall: spent }),
        }
    }

    /// The Pick and Place motions of the `chosen` grasp (see [`Run::prepare`]), their wall time
    /// added to `spent`; or why not.
    fn grasp_motions(
        &self,
        chosen: ChosenGrasp,
        detections: &[Detection],
        q_now: &JointVector,
        slot_index: usize,
        retreat: Option<&LineMotion>,
        spent: &mut StageCompute,
    ) -> Result<Prepared, MotionFailure> {
        let cell = self.cell;
        let robot = cell.robot;
        let (grasp, env, empty) = (chosen.grasp, chosen.env, chosen.model);
        // Pick: transfer to the approach pose, straight descent.
        let wall = Instant::now();
        let mut rng = crate::rng::stream(cell.opts.seed.wrapping_add(self.st.world.steps()), "planner");
        let hand = cell.hand;
        let (pick_transfer, descent, pick_blend) = cell.pick_motion(q_now, &grasp, &empty, &mut rng);
        // The transfer starts while the last retreat ends, where the cell, the pile as seen and
        // the parts placed in this place tray allow (each where the cell put it: its slot, its
        // box grown by [`PLACED_PART_MARGIN_M`]); the retreat ends before the descent starts.
        let retreat_blend = match (retreat, &pick_transfer, &descent) {
            (Some(r), Ok(t), Some(d)) => cell.retreat_blend(r, t, d, pick_blend.as_ref(), slot_index, &empty),
            _ => None,
        };
        spent.pick_s += wall.elapsed().as_secs_f64();
        let pick_transfer = pick_transfer?;
        // Place: with the part on the cup, its centre of mass where the recognition put it.
        let wall = Instant::now();
        let world_from_part = detections[grasp.detection].world_from_part;
        let tool_from_part = grasp.world_from_tool.inverse() * world_from_part;
        // What the part may ask of the cup: the budget the selector ranked this grasp's carry by
        // (the centre of mass its peel model reads, where the recognition put it).
        let seal = cell.selector.seal_budget(&grasp.world_from_tool, &world_from_part);
        // The controller's payload: the nominal part at the cup centre (the plant carries the
        // part where the cup actually sealed: see `execute`).
        let held = hand.combined(&cell.nominal_part);
        // The lift starts where the descent ends (the same line, IK-chained from the approach).
        let q_grasp = descent
            .as_ref()
            .map_or(JointVector::from(grasp.q_grasp), LineMotion::end_q);
        let lift_limits = lift_limits(
            cell.line_limits(),
            cell.scene.cycle.gentle_lift_hemmed,
            grasp.score.hemmed,
            &grasp.world_from_tool.rotation,
            &seal,
        );
        let lift = cell.line(
            &q_grasp,
            &grasp.world_from_tool,
            &grasp.world_from_tool_lifted,
            &held,
            Some(&seal),
            &lift_limits,
        );
        let holding = CollisionModel::new(
            robot,
            RobotSpheres::new(robot, cell.scene, Some((tool_from_part, cell.shape.half_extents_m))),
            env,
        );
        let holding = Holding {
            model: &holding,
            payload: held,
            seal,
        };
        let place = cell.place_motion(
            &grasp,
            JointVector::from(grasp.q_lifted),
            lift.as_ref(),
            &holding,
            &mut rng,
        );
        spent.place_s += wall.elapsed().as_secs_f64();
        let (Some(descent), Some(lift)) = (descent, lift) else {
            return Err(MotionFailure::PickLine);
        };
        let place = place?;
        Ok(Prepared {
            grasp,
            pick_transfer,
            descent,
            pick_blend,
            retreat_blend,
            lift,
            gentle_lift_m_s2: (lift_limits.accel_m_s2 < cell.scene.cycle.line_accel_m_s2)
                .then_some(lift_limits.accel_m_s2),
            place,
            held,
            tool_from_part,
            passed_over: Vec::new(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::GRAVITY_M_S2;
    use crate::robot::test_support::default_robot;
    use crate::trajectory::{LineLimits, MotionLimits};

    /// A hemmed part is lifted at the largest acceleration that leaves its cup room for a
    /// neighbour's push, checked against the seal's load worked out here by hand: a 16 g part on
    /// A's 5.5 mm cup at 70 kPa, its centre of mass 5 mm below the lip on the axis,
    /// lifted straight up. Controls: not hemmed, or the key off, the cell's limits; a light part
    /// whose cup has room at the cell's acceleration, the cell's limits; one with no room even
    /// at rest, the floor.
    #[test]
    fn a_hemmed_part_is_lifted_as_gently_as_its_seal_needs_to_take_a_neighbours_push() {
        let mut gripper = crate::config::LoadedScene::embedded_default().unwrap().scene.gripper;
        gripper.cup_diameter_m = 0.0055;
        let model = crate::geometry::SuctionModel::new(&gripper);
        let seal = |mass_kg: f64| SealBudget::planned(model, mass_kg, Vector3::new(0.0, 0.0, 0.005), 0.0);
        let line = LineLimits {
            speed_m_s: 1.0,
            accel_m_s2: 20.0,
            wrist_deviation_max_rad: 0.0,
        };
        let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let a = |gentle_above: Option<f64>, hemmed: f64, mass_kg: f64| {
            lift_limits(line, gentle_above, hemmed, &down, &seal(mass_kg)).accel_m_s2
        };
        // By hand: lifting at a, the cup pulls m (g + a); the push m g shears the lip (over
        // its friction) and peels it with the moment m g x 5 mm (4 |M| / d); the budget is
        // SUCTION_MARGIN of 70 kPa over the lip's area.
        let budget_n = crate::geometry::SUCTION_MARGIN * 70e3 * std::f64::consts::PI * 0.00275f64.powi(2);
        let g = GRAVITY_M_S2;
        let asked_n = |mass_kg: f64, accel: f64| {
            mass_kg * (g + accel) + mass_kg * g / gripper.lip_friction + 4.0 * mass_kg * g * 0.005 / 0.0055
        };
        let gentle = a(Some(0.3), 0.5, 0.016);
        assert!(gentle > 2.0 && gentle < 20.0, "{gentle}");
        assert!(asked_n(0.016, gentle) <= budget_n * (1.0 + 1e-6), "{gentle}");
        assert!(asked_n(0.016, gentle + 0.01) > budget_n, "{gentle}: not the largest");
        assert_eq!(a(Some(0.3), 0.2, 0.016), 20.0, "not hemmed");
        assert_eq!(a(None, 5.0, 0.016), 20.0, "the key off");
        assert!(asked_n(0.004, 20.0) < budget_n);
        assert_eq!(a(Some(0.3), 0.5, 0.004), 20.0, "room at the cell's acceleration");
        assert!(asked_n(0.03, 0.0) > budget_n);
        assert_eq!(a(Some(0.3), 0.5, 0.03), 2.0, "no room even at rest: the floor");
    }

    /// A transfer to the home pose, a 3 cm descent from there and the retreat back up.
    fn place_motion(release_lead_s: f64, blended: bool) -> PlaceMotion {
        let robot = default_robot();
        let home = JointVector::from(
            crate::config::LoadedScene::embedded_default()
                .unwrap()
                .scene
                .robot
                .home_rad(),
        );
        let start = home + JointVector::from_element(0.2);
        let limits = MotionLimits {
            vel_rad_s: JointVector::from_element(1.0),
            accel_rad_s2: JointVector::from_element(4.0),
        };
        let transfer = Trajectory::through(&[start, home], &limits);
        let above = robot.world_from_tool(&home);
        let below = Isometry3::from_parts(
            Translation3::from(above.translation.vector - Vector3::z() * 0.03),
            above.rotation,
        );
        let line = LineLimits {
            speed_m_s: 0.5,
            accel_m_s2: 5.0,
            wrist_deviation_max_rad: 0.0,
        };
        let dynamics = robot.dynamics(&Payload::point(0.5, Vector3::zeros()));
        let descent = straight_line(&robot, &dynamics, &home, &above, &below, &line, None).unwrap();
        let retreat = straight_line(&robot, &dynamics, &descent.end_q(), &below, &above, &line, None).unwrap();
        let descent_blend =
            blended.then(|| Overlapped::new(transfer.clone(), descent.clone(), 0.9 * transfer.duration_s()));
        PlaceMotion {
            transfer,
            descent,
            retreat,
            suction_speed_factor: 1.0,
            lift_blend: None,
            descent_blend,
            release_lead_s,
        }
    }

    /// The carry plays the transfer flowing on into the descent, or the two as one overlapped
    /// segment; the valve closes once, `release_lead_s` before the last segment's end, and every
    /// segment may trigger a capture as asked. The control: a lead longer than the descent
    /// closes the valve at its start, not before.
    #[test]
    fn the_carry_closes_the_valve_once_before_the_descents_end() {
        let payload = Payload::point(0.1, Vector3::zeros());
        let capture = Capture::EndingBy(12.5);
        for blended in [false, true] {
            let p = place_motion(0.02, blended);
            let carry = p.carry(None, payload, capture);
            assert_eq!(carry.len(), if blended { 1 } else { 2 }, "blended {blended}");
            let last = carry.last().unwrap();
            assert_eq!(last.settle, Settle::InPosition);
            let closes: Vec<f64> = carry.iter().filter_map(|s| s.valve.map(Valve::at_s)).collect();
            let end_s = last.motion.as_motion().duration_s();
            assert_eq!(closes, vec![end_s - 0.02], "blended {blended}");
            assert!(matches!(last.valve, Some(Valve::CloseAt(_))));
            assert!(
                carry
                    .iter()
                    .all(|s| matches!(s.capture, Capture::EndingBy(t) if t == 12.5))
            );
            assert!(carry[..carry.len() - 1].iter().all(|s| s.settle == Settle::AtEnd));
            let total: f64 = carry.iter().map(|s| s.motion.as_motion().duration_s()).sum();
            assert!((total - p.carry_s()).abs() < 1e-9, "{total} vs {}", p.carry_s());
        }
        let long = place_motion(1e3, false);
        let carry = long.carry(None, payload, capture);
        assert_eq!(carry.last().unwrap().valve.map(Valve::at_s), Some(0.0));
    }
}
