//! Cycle step 1, sensing: trigger the capture as soon as the arm is out of the camera's view,
//! watch the exposure, wait for the recognition result.
//!
//! Job: keep one capture pending; trigger it at the first physics step at which the arm (and the
//! held part) is outside the view frustum over the pick tray; repeat an exposure spoiled by the
//! arm entering the view; hand over the recognition result when it arrives (`latency_s` after
//! the trigger), unless its image shows new holes over the tray (a pile in motion): then look
//! again at once. When the arm stands in the view with nothing pending (at the start, after a
//! fault), move it home first.
//!
//! New holes are also what a pile shows after the cell's own disturbance (an agitation, a dose,
//! a pick) with nothing moving: steep faces turned up. So an image that shows new holes at the
//! end of its exposure is confirmed by a second exposure right after it, while its recognition
//! runs, if the arm is out of the view: holes in one image only are a pile in motion, and so
//! are holes in both wider than a face steeper than the grazing angle can look (a part sliding
//! slowly through both exposures, blurred in both); the rest are still steep faces, and the image
//! is picked from. The second exposure costs the cycle nothing (it ends 2 exposures after the
//! trigger, within the sensor's latency); where the arm enters the view during it, or the
//! latency is shorter, the check falls back to the new holes against the image before. Only a
//! part whose mean thickness is at least twice as wide as its steepest face can look is
//! confirmed (B, D): for the others (C's 5 mm strips, whose 150 x 10 mm face stood on end looks
//! 10 mm wide) a still hole and a moving part look alike.
//!
//! Units: s, rad. Frames: world.

use nalgebra::{Isometry3, Translation3};

use super::events::{Event, Stage};
use super::outcome::Fault;
use super::play::{Capture, Segment};
use super::{CycleError, Run};
use crate::planning::{CollisionModel, Environment, PlanOptions, RobotSpheres};
use crate::robot::JointVector;
use crate::sensor::{CaptureJob, CaptureProblem, Detection, RecognitionReport, evaluate};
use crate::trajectory::{CORRIDOR_CHECK_DT_S, Motion, Trajectory, accelerate_in_corridor};

/// The most captures in a row the cell takes for a pile in motion and looks at again; the next
/// one is picked from whatever it shows (a part that keeps sliding would otherwise hold the
/// cell forever).
pub const MOTION_RECAPTURES: usize = 2;

/// A recognition result to pick from.
pub struct SensedResult {
    /// The capture job (its image and timing), shared by the result's copies ([`Self::keeping`]):
    /// the image is megabytes.
    pub job: std::sync::Arc<CaptureJob>,
    /// When the capture was triggered (s).
    pub capture_s: f64,
    /// The recognised parts (`None` if the result was not available).
    pub detections: Option<Vec<Detection>>,
    /// The detections against the ground truth at the trigger: evaluation only, never read by
    /// a decision.
    pub evaluation: Option<RecognitionReport>,
    /// Wall time the recognition took (s) (not charged: it runs inside the sensor's latency).
    pub recognition_wall_s: f64,
}

impl SensedResult {
    /// The same result with only the detections `keep` says (their evaluation kept in step).
    pub fn keeping(&self, keep: &[bool]) -> SensedResult {
        let pick = |i: usize| keep.get(i).copied().unwrap_or(false);
        SensedResult {
            job: std::sync::Arc::clone(&self.job),
            capture_s: self.capture_s,
            detections: self.detections.as_ref().map(|d| {
                d.iter()
                    .enumerate()
                    .filter(|(i, _)| pick(*i))
                    .map(|(_, x)| x.clone())
                    .collect()
            }),
            evaluation: self.evaluation.as_ref().map(|e| {
                let mut e = e.clone();
                e.matches = e
                    .matches
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| pick(*i))
                    .map(|(_, m)| *m)
                    .collect();
                e
            }),
            recognition_wall_s: self.recognition_wall_s,
        }
    }
}

impl Run<'_, '_> {
    /// Takes a result that has arrived into hand, then triggers a capture if none is pending
    /// (or the pending one was spoiled and the sensor has finished exposing it), the arm is out
    /// of view and its plan keeps it out for the exposure: until `view_free_until_s` (infinite:
    /// no motion into the view is planned).
    pub(super) fn maybe_trigger(&mut self, view_free_until_s: f64) {
        self.collect_ready();
        if self.st.world.time_s() < self.st.capture_hold_until_s - 1e-9 {
            // A part let go is still falling into the pile.
            return;
        }
        if self.st.world.time_s() + self.st.sensor.exposure_s > view_free_until_s + 1e-9 {
            // The arm's plan takes it into the view before the exposure would end.
            return;
        }
        if let Some(j) = &self.st.pending
            && (j.spoiled.is_none() || self.st.world.time_s() + 1e-9 < j.exposure_end_s)
        {
            return;
        }
        if let Ok(mut job) = self.st.sensor.trigger(&self.st.world) {
            job.arm.tool_from_held_part = self.st.held_part_estimate();
            self.event(Event::Capture(job.capture.id));
            self.obs.captured(&job.capture);
            self.st.pending = Some(job);
        }
    }

    /// A new recognition result to pick from: triggers a capture if none is pending (moving the
    /// arm out of view first if needed), goes to the waiting pose and waits for it; a result
    /// that arrives meanwhile is the one. `None` if the arm cannot leave the view.
    pub(super) fn next_result(&mut self) -> Result<Option<SensedResult>, CycleError> {
        let collected = self.st.results_collected;
        let mut waiting_tried = false;
        loop {
            // A result that arrived is the one; a capture now would only be spoiled by the Pick.
            self.collect_ready();
            if self.st.results_collected != collected {
                return Ok(self.st.in_hand.take().map(|h| h.result));
            }
            if self.st.pending.as_ref().is_none_or(|j| j.spoiled.is_some())
                && self.st.world.time_s() < self.st.capture_hold_until_s
            {
                let hold = self.st.capture_hold_until_s;
                self.idle_until(hold)?;
            }
            self.maybe_trigger(f64::INFINITY);
            // No capture to wait for: none pending, or a spoiled one whose exposure is over and
            // which the trigger could not replace (the arm is in the view, as after a failed
            // grasp): get out of the view and trigger. Before, a spoiled job the trigger could
            // not replace was waited for again and again without a step (a hang: F, seed 11,
            // one pick per capture).
            let no_capture = |r: &Self| {
                r.st.pending
                    .as_ref()
                    .is_none_or(|j| j.spoiled.is_some() && r.st.world.time_s() + 1e-9 >= j.exposure_end_s)
            };
            if no_capture(self) {
                if !self.move_out_of_view()? {
                    return Ok(None);
                }
                self.maybe_trigger(f64::INFINITY);
                if no_capture(self) {
                    return Ok(None);
                }
                continue;
            }
            let (exposure_end_s, ready_s, spoiled) = match &self.st.pending {
                Some(j) => (j.exposure_end_s, j.ready_s, j.spoiled.is_some()),
                None => return Ok(None),
            };
            if spoiled {
                self.idle_until(exposure_end_s)?;
                continue;
            }
            if ready_s > self.st.world.time_s() && !waiting_tried {
                waiting_tried = true;
                if self.go_to_waiting_pose()? {
                    // Look again: a result may have arrived, or the way there crossed the view
                    // during the exposure.
                    continue;
                }
            }
            // A spoiled exposure is known when it ends: expose again right away.
            self.idle_until(exposure_end_s)?;
            if self.st.pending.as_ref().is_some_and(|j| j.spoiled.is_some()) {
                continue;
            }
            self.idle_until(ready_s)?;
        }
    }

    /// At the end of the pending capture's exposure: if its image shows new holes over the tray
    /// (as many as a pile in motion) and the arm is out of the view, takes the confirming
    /// exposure (see the module's header). Once per capture.
    pub(super) fn maybe_confirm(&mut self) {
        let now = self.st.world.time_s();
        let st = &mut self.st;
        let Some(job) = st.pending.as_mut() else { return };
        if job.confirm_decided || job.spoiled.is_some() || now + 1e-9 < job.exposure_end_s {
            return;
        }
        job.confirm_decided = true;
        // After two recaptures in a row the image is picked from whatever it shows; a part whose
        // still holes may be as wide as a moving one's is not confirmed; nor is an image whose
        // result comes before a second exposure could end (a latency under two exposures).
        if st.moving_in_a_row >= MOTION_RECAPTURES
            || !st.sensor.confirms()
            || now + st.sensor.exposure_s > job.ready_s + 1e-9
        {
            return;
        }
        job.apply_blur();
        let holes = st.sensor.hole_px(&job.capture);
        let unseen = st.sensor.unseen_holes(&holes);
        job.holes = Some(holes);
        if unseen < st.sensor.motion_hole_min_px() {
            return;
        }
        let Ok(mut confirm) = st.sensor.trigger(&st.world) else {
            return;
        };
        confirm.arm.tool_from_held_part = st.held_part_estimate();
        self.event(Event::ConfirmingCapture(confirm.capture.id));
        self.obs.confirming_captured(&confirm.capture);
        if let Some(job) = self.st.pending.as_mut() {
            job.confirm = Some(Box::new(confirm));
        }
    }

    /// Takes the pending capture's result into hand if it has arrived by now (a newer result
    /// replaces the one in hand).
    pub(super) fn collect_ready(&mut self) {
        let now = self.st.world.time_s();
        if !self
            .st
            .pending
            .as_ref()
            .is_some_and(|j| j.spoiled.is_none() && j.ready_s <= now + 1e-9)
        {
            return;
        }
        if let Some(job) = self.st.pending.take() {
            let capture_s = job.exposure_end_s - self.st.sensor.exposure_s;
            let result = self.finish(job, capture_s);
            if result.job.spoiled.is_some() {
                // The image shows a pile in motion: neither it nor the result in hand (taken
                // before the motion) is picked from; the next capture is taken at once.
                self.st.in_hand = None;
                return;
            }
            self.st.in_hand = Some(super::InHand { result, taken: 0 });
            self.st.results_collected += 1;
        }
    }

    /// The recognition result of a capture whose result time has come: recognised from the
    /// image as exposed, evaluated against the truth at its trigger (evaluation only), reported.
    fn finish(&mut self, mut job: CaptureJob, capture_s: f64) -> SensedResult {
        self.span(Stage::Sensor, capture_s, job.exposure_end_s, "exposure");
        self.span(Stage::Recognition, job.exposure_end_s, job.ready_s, "recognition");
        let wall = std::time::Instant::now();
        let detections = self.st.sensor.result(&mut job, self.st.world.time_s());
        let recognition_wall_s = wall.elapsed().as_secs_f64();
        // New holes in the image: something moved during the exposure. Looked at again, up to
        // [`MOTION_RECAPTURES`] times in a row; a hole that stays put is a steep face. With a
        // confirming exposure whole (the arm kept out of it), the holes in one of the two images
        // only and those in both wider than a steep face.
        let holes = job.holes.take().unwrap_or_else(|| self.st.sensor.hole_px(&job.capture));
        let new_holes = match job.confirm.take() {
            Some(mut confirm) if confirm.spoiled.is_none() && confirm.exposure_end_s <= job.ready_s + 1e-9 => {
                confirm.apply_blur();
                let confirm_s = confirm.exposure_end_s - self.st.sensor.exposure_s;
                self.span(Stage::Sensor, confirm_s, confirm.exposure_end_s, "confirming exposure");
                let confirming = self.st.sensor.hole_px(&confirm.capture);
                self.st.sensor.changed_holes(holes, &confirming, job.capture.width_px)
            }
            _ => self.st.sensor.new_holes(holes),
        };
        if new_holes >= self.st.sensor.motion_hole_min_px() && self.st.moving_in_a_row < MOTION_RECAPTURES {
            self.st.moving_in_a_row += 1;
            self.st.sensor.spoiled += 1;
            let problem = CaptureProblem::PileMoving(new_holes);
            job.spoiled = Some(problem.clone());
            self.event_at(job.ready_s, Event::CaptureSpoiled(problem));
            return SensedResult {
                job: job.into(),
                capture_s,
                detections: None,
                evaluation: None,
                recognition_wall_s,
            };
        }
        self.st.moving_in_a_row = 0;
        let evaluation = detections
            .as_ref()
            .map(|d| evaluate(&job.truth, d, &self.st.sensor.symmetry));
        if let Some(e) = &evaluation {
            self.st.tally.recognition.add(e);
            if self.cell.opts.keep_records {
                self.st.recognitions.push(RecognitionReport {
                    matches: Vec::new(),
                    ..e.clone()
                });
            }
            self.obs.evaluated(job.ready_s, &job.truth, e);
        }
        self.event_at(
            job.ready_s,
            Event::RecognitionReady {
                detected: detections.as_ref().map_or(0, Vec::len),
                blurred: job.blurred(),
            },
        );
        SensedResult {
            job: job.into(),
            capture_s,
            detections,
            evaluation,
            recognition_wall_s,
        }
    }

    /// While a result is pending and the arm has nothing else to do: to the cell's waiting
    /// pose (`cycle.waiting_tool_m`, outside the view), so that only the last stretch of the
    /// Pick waits for the result. Nothing happens without a waiting pose or when the arm is
    /// there already. Returns whether the arm moved.
    fn go_to_waiting_pose(&mut self) -> Result<bool, CycleError> {
        let Some(q_wait) = self.cell.waiting_q else {
            return Ok(false);
        };
        let q_now = self.st.world.joints();
        if (q_wait - q_now).amax() < 0.01 {
            return Ok(false);
        }
        let free = self.cell.free_model();
        let mut rng = crate::rng::stream(self.cell.opts.seed.wrapping_add(self.st.world.steps()), "planner-wait");
        let Ok(p) = free.plan(&q_now, &q_wait, &PlanOptions::default(), &mut rng) else {
            // No path: the arm waits where it is.
            return Ok(false);
        };
        let hand = self.cell.hand;
        let acc = self.cell.accelerate_free(&p.waypoints, &free);
        let t = self.st.world.time_s();
        // The controller knows from now where the arm ends: a result arriving on the way is
        // planned from there.
        self.st.planned_end_q = Some(acc.at(acc.duration_s()).q);
        self.st.compute_from_s = t;
        // A result arriving on the way sends the arm into the view from there; a capture
        // triggered on the way has its result long after.
        let end_s = t + acc.duration_s();
        let capture = if self
            .st
            .pending
            .as_ref()
            .is_some_and(|j| j.spoiled.is_none() && j.ready_s <= end_s)
        {
            Capture::EndingBy(end_s)
        } else {
            Capture::ANY
        };
        let played = self.play(&Segment::new(&acc, hand).capturing(capture))?;
        self.span(Stage::WaitingPose, t, self.st.world.time_s(), "to the waiting pose");
        self.st.arm.free_s = self.st.world.time_s();
        if !matches!(played, super::play::Played::Done) {
            self.st.planned_end_q = None;
            self.st.compute_from_s = self.st.world.time_s();
        }
        Ok(true)
    }

    /// Moves the arm home when it is in the camera's view and nothing is pending.
    fn move_out_of_view(&mut self) -> Result<bool, CycleError> {
        if self.st.sensor.frustum.arm_inside(&self.st.world).is_none() {
            return Ok(true);
        }
        let scene = self.cell.scene;
        let home = JointVector::from(scene.robot.home_rad());
        let free = self.cell.free_model();
        let mut rng = crate::rng::stream(self.cell.opts.seed.wrapping_add(self.st.world.steps()), "planner-home");
        let t = self.st.world.time_s();
        let mut plan = free.plan(&self.st.world.joints(), &home, &PlanOptions::default(), &mut rng);
        if plan.is_err() {
            // Down in the tray (after a fault): straight up above the rim first.
            let tool = self.st.world.world_from_tool();
            let rim_z = self.st.world.pick_tray().world_from_tray.translation.z + scene.pick_tray.wall_height_m + 0.1;
            let up = Isometry3::from_parts(
                Translation3::new(tool.translation.x, tool.translation.y, tool.translation.z.max(rim_z)),
                tool.rotation,
            );
            let hand = self.cell.hand;
            if let Some(line) = self.cell.line(
                &self.st.world.joints(),
                &tool,
                &up,
                &hand,
                None,
                &self.cell.line_limits(),
            ) {
                self.play(&Segment::new(&line, hand).capturing(Capture::ANY))?;
            }
            plan = free.plan(&self.st.world.joints(), &home, &PlanOptions::default(), &mut rng);
        }
        let p = match plan {
            Ok(p) => p,
            Err(why) => {
                self.event(Event::Fault(Fault::NoPathOutOfView(why)));
                return Ok(false);
            }
        };
        let hand = self.cell.hand;
        let acc = self.cell.accelerate_free(&p.waypoints, &free);
        let played = self.play(&Segment::new(&acc, hand).capturing(Capture::ANY))?;
        self.span(Stage::Place, t, self.st.world.time_s(), "out of view");
        self.st.arm.free_s = self.st.world.time_s();
        self.st.planned_end_q = None;
        self.st.compute_from_s = self.st.world.time_s();
        Ok(matches!(played, super::play::Played::Done))
    }
}

impl super::Cell<'_> {
    /// The planning model of the cell without the pile, with the bare hand: for the arm's moves
    /// above the trays (out of the view, to the waiting pose).
    fn free_model(&self) -> CollisionModel {
        CollisionModel::new(
            self.robot,
            RobotSpheres::new(self.robot, self.scene, None),
            Environment::from_scene(self.scene),
        )
    }

    /// A path planned in `model`, accelerated with the bare hand inside its certified corridor.
    fn accelerate_free(&self, waypoints: &[[f64; crate::robot::DOF]], model: &CollisionModel) -> Trajectory {
        let via: Vec<JointVector> = waypoints.iter().map(|q| JointVector::from(*q)).collect();
        accelerate_in_corridor(
            &self.accel_robot,
            &self.robot.dynamics(&self.hand),
            &via,
            model,
            CORRIDOR_CHECK_DT_S,
        )
        .1
        .trajectory
    }
}
