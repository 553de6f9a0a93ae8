//! Cycle step 3, one pick: charge the compute, wait where the motion is not ready, Pick, Place,
//! and account for the outcome.
//!
//! Job: from the prepared motions, place the compute on the simulation clock (grasp selection,
//! then Pick motion generation, then Place motion generation, all after the recognition
//! result), stall the arm until the Pick is ready (waiting for the sensor, then for compute),
//! then play the Pick (transfer, descent with the vacuum valve opening `vacuum_lead_s` before
//! the cup touches, vacuum build-up, lift) and the Place (transfer, descent with the valve
//! closing the plan's `release_lead_s` before its end, the release as the vacuum vents, retreat
//! `release_s` after the valve closed), and record the pick: its stages' times, its outcome, the
//! takt since the last release (when the part came off).
//!
//! Units: s, m, rad. Frames: world.

use super::events::{Event, MISRECOGNISED, Outcome, Planned, Stage, StallCause};
use super::execute::{Played, Valve};
use super::motions::{PlaceMotion, Prepared};
use super::records::PickRecord;
use super::{CycleError, Run};
use crate::physics::suction::GripperEvent;
use crate::robot::JointVector;
use crate::trajectory::{Motion, Overlapped};

impl Run<'_, '_> {
    /// The pick of `prep`, whose compute could start at `ready_s`, with `charged` compute
    /// (grasp selection, Pick and Place motion generation [s]), aimed at the part recognised at
    /// `aimed_m` [m, world]: stalls, motions, outcome.
    pub(super) fn pick_and_place(
        &mut self,
        prep: &Prepared,
        charged: [f64; 3],
        ready_s: f64,
        aimed_m: Option<nalgebra::Vector3<f64>>,
        rec: &mut PickRecord,
    ) -> Result<(), CycleError> {
        rec.compute = crate::cycle::StageCompute {
            grasp_s: charged[0],
            pick_s: charged[1],
            place_s: charged[2],
        };
        let grasp_done = ready_s + charged[0];
        let pick_ready = grasp_done + charged[1];
        let place_ready = pick_ready + charged[2];
        self.span(Stage::Grasp, ready_s, grasp_done, "grasp selection");
        self.span(Stage::Planning, grasp_done, pick_ready, "Pick motion");
        self.span(Stage::Planning, pick_ready, place_ready, "Place motion");
        self.event_at(
            grasp_done,
            Event::GraspChosen {
                detection: prep.grasp.detection,
                face: prep.grasp.face,
                score: prep.grasp.score.total,
            },
        );
        // Stall before the Pick: waiting for the sensor, then for compute.
        let free = self.st.arm.free_s;
        rec.stall_sensor_s = (ready_s.min(pick_ready) - free).max(0.0);
        rec.stall_compute_s = (pick_ready - free.max(ready_s)).max(0.0);
        let pick_planned = match &prep.pick_transfer {
            Ok(t) => Planned::Pick {
                transfer_s: t.duration_s(),
                descent_s: prep.descent.duration_s(),
                compute_s: charged[1],
            },
            Err(e) => Planned::Failed {
                motion: "Pick",
                why: e.clone(),
            },
        };
        let place_planned = match &prep.place {
            Ok(p) => Planned::Place {
                lift_s: prep.lift.duration_s(),
                transfer_s: p.transfer.duration_s(),
                descent_s: p.descent.duration_s(),
                retreat_s: p.retreat.duration_s(),
                compute_s: charged[2],
            },
            Err(e) => Planned::Failed {
                motion: "Place",
                why: e.clone(),
            },
        };
        let mut stages = vec![
            (pick_ready, Event::Planned(pick_planned)),
            (place_ready, Event::Planned(place_planned)),
        ];
        if rec.stall_sensor_s > 0.0 {
            self.span(Stage::Stall, free, ready_s, "waiting for the sensor");
            let duration_s = rec.stall_sensor_s;
            stages.push((
                free,
                Event::Stall {
                    cause: StallCause::Sensor,
                    duration_s,
                },
            ));
        }
        if rec.stall_compute_s > 0.0 {
            self.span(Stage::Stall, free.max(ready_s), pick_ready, "waiting for compute");
            let duration_s = rec.stall_compute_s;
            stages.push((
                free.max(ready_s),
                Event::Stall {
                    cause: StallCause::Compute,
                    duration_s,
                },
            ));
        }
        for (t_s, event) in stages {
            self.event_at(t_s, event);
        }
        // With the last retreat overlapped, the Pick was ready before the retreat's head ends.
        if prep.retreat_blend.is_none() {
            self.idle_until(pick_ready.max(self.st.world.time_s()))?;
        }
        let outcome = self.motions(prep, rec, place_ready, aimed_m)?;
        self.st.view_free_until_s = f64::INFINITY;
        // Compute for the next pick may start with this Place if it went as planned.
        self.st.compute_from_s = match (&outcome, self.st.planned_end_q) {
            (Outcome::Placed, Some(_)) => self.st.compute_from_s,
            _ => {
                self.st.planned_end_q = None;
                self.st.world.time_s()
            }
        };
        if outcome != Outcome::Placed && self.st.world.held_part().is_some() {
            // A pick that ended with the part still on the cup (no Place motion): let it go where
            // the arm is, over the pick tray, before anything else moves.
            self.st.world.vacuum_off();
            let t = self.st.world.time_s() + self.st.world.gripper().release_s + self.st.world.dt_s();
            self.idle_until(t)?;
            self.st.world.take_gripper_events();
            self.event(Event::PartLetGo);
            // The part falls back into the pile: no capture until it has come to rest there.
            self.st.capture_hold_until_s = self.st.world.time_s() + super::LET_GO_SETTLE_S;
            self.st.arm.free_s = self.st.arm.free_s.max(self.st.world.time_s());
        }
        // No motion for it is a failure at that spot too: the same pile gives the same plan.
        if matches!(
            outcome,
            Outcome::GraspFailed(_) | Outcome::Collision(_) | Outcome::ProtectiveStop(_) | Outcome::NoMotion(_)
        ) && rec.place_s == 0.0
        {
            self.st.failed_spots.push(prep.grasp.world_from_tool.translation.vector);
        }
        if rec.place_s > 0.0 && matches!(outcome, Outcome::Collision(_) | Outcome::ProtectiveStop(_)) {
            // Something is in the slot (a part that bounced there): the next part goes to the next.
            self.event(Event::SlotSkipped(self.st.trays.next_slot % self.cell.slots.len()));
            self.st.trays.next_slot += 1;
        }
        rec.outcome = outcome;
        self.event(Event::Outcome(rec.outcome.clone()));
        if rec.outcome == Outcome::Placed {
            let release = rec.release_s.unwrap_or(self.st.world.time_s());
            rec.takt_s = self.st.trays.last_release_s.map(|r| release - r);
            rec.spans_refill = rec.takt_s.is_some() && self.st.trays.refilled_since_release;
            self.st.trays.refilled_since_release = false;
            self.st.trays.last_release_s = Some(release);
            self.st.trays.next_slot += 1;
        }
        self.exchange_full_place_tray()?;
        let arm = &self.st.arm;
        rec.max_tracking_error_deg = arm.max_error_rad.to_degrees();
        let (joint, peak) = arm
            .peak_demand_ratio
            .iter()
            .enumerate()
            .fold((0, 0.0), |best, (i, r)| if *r > best.1 { (i, *r) } else { best });
        rec.peak_demand_ratio = peak;
        rec.peak_demand_joint = joint + 1;
        rec.saturated_s = arm.saturated_s;
        Ok(())
    }

    /// Pick (transfer, descent, vacuum, lift) and Place (transfer, descent, release, retreat).
    fn motions(
        &mut self,
        prep: &Prepared,
        rec: &mut PickRecord,
        place_ready: f64,
        aimed_m: Option<nalgebra::Vector3<f64>>,
    ) -> Result<Outcome, CycleError> {
        let hand = self.cell.hand;
        self.st.arm.max_error_rad = 0.0;
        self.st.arm.peak_demand_ratio = [0.0; crate::robot::DOF];
        self.st.arm.saturated_s = 0.0;
        // The last Place's retreat, alone up to where this Pick starts (that Place's end; its
        // servo errors and torques count for this pick). A capture may start only if its
        // exposure ends before the Pick does.
        if let Some(rb) = &prep.retreat_blend {
            self.st.view_free_until_s = self.st.world.time_s() + rb.motion.start_s();
            let head = self.play_with(&rb.motion.head(), &hand, true, None, false)?;
            self.st.view_free_until_s = f64::INFINITY;
            self.measure_late_placement();
            if let Played::Failed(o) = head {
                return Ok(o);
            }
        }
        let t_pick = self.st.world.time_s();
        self.st.planned_end_q = None;
        let pick_lane = if rec.blind { Stage::BlindPick } else { Stage::Pick };
        self.event(Event::PickStart);
        let pick_transfer = match &prep.pick_transfer {
            Ok(t) => t,
            Err(e) => return Ok(Outcome::NoMotion(e.clone())),
        };
        self.st.gripper_events.clear();
        let pick_done = |run: &mut Self, rec: &mut PickRecord| {
            rec.pick_s = run.st.world.time_s() - t_pick;
            run.span(pick_lane, t_pick, run.st.world.time_s(), "Pick");
            run.st.arm.free_s = run.st.world.time_s();
        };
        // The transfer, then the descent (or the overlap's head, then its rest: the descent
        // starts while the transfer ends).
        rec.overlaps.pick_descent_s = prep.pick_blend.as_ref().map_or(0.0, |b| b.both().duration_s());
        let transferred = match (&prep.retreat_blend, &prep.pick_blend) {
            (Some(rb), _) => {
                rec.overlaps.retreat_s = rb.motion.both().duration_s();
                let s = rb.motion.start_s();
                self.play_with(&rb.motion.window(s, s + rb.descent_from_s), &hand, false, None, false)?
            }
            (None, Some(b)) => self.play_with(&b.head(), &hand, false, None, false)?,
            (None, None) => self.play_with(pick_transfer, &hand, false, None, false)?,
        };
        if let Played::Failed(o) = transferred {
            pick_done(self, rec);
            return Ok(o);
        }
        // The vacuum valve opens `vacuum_lead_s` before the cup reaches the face.
        let lead = self.cell.scene.cycle.vacuum_lead_s;
        let t_descent = self.st.world.time_s();
        let vacuum_at;
        // From here on the pile is touched: results captured before do not show it.
        if let Some(c) = aimed_m {
            self.st.pick_spots.push((t_descent, c));
        }
        let descended = match (&prep.retreat_blend, &prep.pick_blend) {
            (Some(rb), _) => {
                let m = &rb.motion;
                let rest = m.window(m.start_s() + rb.descent_from_s, m.duration_s());
                vacuum_at = (rest.duration_s() - lead).max(0.0);
                self.play_with(&rest, &hand, false, Some(Valve::OpenAt(vacuum_at)), true)?
            }
            (None, Some(b)) => {
                let rest = b.rest();
                vacuum_at = (rest.duration_s() - lead).max(0.0);
                self.play_with(&rest, &hand, false, Some(Valve::OpenAt(vacuum_at)), true)?
            }
            (None, None) => {
                vacuum_at = (prep.descent.duration_s() - lead).max(0.0);
                self.play_with(&prep.descent, &hand, false, Some(Valve::OpenAt(vacuum_at)), true)?
            }
        };
        if let Played::Failed(o) = descended {
            pick_done(self, rec);
            return Ok(o);
        }
        self.st.world.vacuum_on();
        let t = (t_descent + vacuum_at).min(self.st.world.time_s())
            + self.st.world.gripper().build_up_s
            + self.st.world.dt_s();
        self.idle_until(t)?;
        let mut failure = None;
        let mut events = std::mem::take(&mut self.st.gripper_events);
        events.extend(self.st.world.take_gripper_events());
        for ev in events {
            match ev {
                GripperEvent::Grasped { seal, .. } => {
                    self.event(Event::Grasped {
                        part: seal.part,
                        aimed_at: rec.aimed_at.map(|m| m.part),
                        com_offset_m: seal.com_offset_m,
                        tilt_rad: seal.tilt_rad,
                    });
                }
                GripperEvent::GraspFailed { reason, .. } => failure = Some(Outcome::GraspFailed(reason.to_string())),
                GripperEvent::Slipped { required_n, .. } => {
                    failure = Some(Outcome::Dropped(format!("slipped at rest: {required_n:.2} N")))
                }
                GripperEvent::Released { .. } => {}
            }
        }
        rec.sealed = Some(self.st.world.held_part().is_some());
        if self.st.world.held_part().is_none() {
            self.st.world.vacuum_off();
            self.play(&prep.lift, &hand, false)?;
            pick_done(self, rec);
            let failure = failure.unwrap_or_else(|| Outcome::GraspFailed("no seal".into()));
            // Evaluation only: a failure on a wrong detection is named for what started it.
            return Ok(match (failure, rec.aimed_at) {
                (Outcome::GraspFailed(why), Some(m)) if !m.correct => Outcome::GraspFailed(format!(
                    "{MISRECOGNISED}: believed pose {:.1} mm / {:.1} deg from part {} ({why})",
                    m.position_error_m * 1e3,
                    m.rotation_error_rad.to_degrees(),
                    m.part
                )),
                (Outcome::GraspFailed(why), None) => {
                    Outcome::GraspFailed(format!("{MISRECOGNISED}: no part there ({why})"))
                }
                (f, _) => f,
            });
        }
        let held = prep.held;
        // The lift and the Place transfer overlapped, if they could be and the Place is ready
        // when the transfer would start: the Pick ends where the transfer starts.
        let now = self.st.world.time_s();
        let blend = match &prep.place {
            Ok(PlaceMotion {
                lift_blend: Some(b), ..
            }) if place_ready <= now + b.start_s() + 1e-9 => Some(b),
            _ => None,
        };
        let lifted = match blend {
            Some(b) => {
                rec.overlaps.lift_s = b.both().duration_s();
                self.play_with(&b.head(), &held, true, None, false)?
            }
            None => self.play_with(&prep.lift, &held, true, None, false)?,
        };
        if let Played::Failed(o) = lifted {
            pick_done(self, rec);
            return Ok(o);
        }
        pick_done(self, rec);
        // Place: the motions were generated while the Pick ran; wait if they are not ready yet.
        if place_ready > self.st.world.time_s() {
            let t = self.st.world.time_s();
            rec.stall_compute_s += place_ready - t;
            self.span(Stage::Stall, t, place_ready, "waiting for compute");
            self.idle_until(place_ready)?;
            self.st.arm.servo.qd = JointVector::zeros();
        }
        let place = match &prep.place {
            Ok(p) => p,
            Err(e) => return Ok(Outcome::NoMotion(e.clone())),
        };
        let up = &place.retreat;
        rec.suction_speed_factor = place.suction_speed_factor;
        rec.overlaps.place_descent_s = place.descent_blend.as_ref().map_or(0.0, |d| d.both().duration_s());
        let t_place = self.st.world.time_s();
        // The controller knows from now where the arm ends: the next pick's compute may start.
        self.st.planned_end_q = Some(up.end_q());
        self.st.compute_from_s = t_place;
        // The next Pick may follow the Place at once: no exposure may run past its end.
        let release_lead_s = place.release_lead_s;
        rec.release_lead_s = release_lead_s;
        let release_wait_s = (self.st.world.gripper().release_s - release_lead_s).max(0.0) + self.st.world.dt_s();
        self.st.view_free_until_s = t_place + place.carry_s() + release_wait_s + up.duration_s();
        self.event(Event::PlaceStart);
        // The Place ends `after_s` from now: 0, or the head of a retreat that runs into the
        // next Pick (played with it).
        let place_done_after = |run: &mut Self, rec: &mut PickRecord, after_s: f64| {
            let end = run.st.world.time_s() + after_s;
            rec.place_s = end - t_place;
            run.span(Stage::Place, t_place, end, "Place");
            run.st.arm.free_s = end;
        };
        let place_done = |run: &mut Self, rec: &mut PickRecord| place_done_after(run, rec, 0.0);
        // The transfer (its start overlapping the lift's end, if so) and the descent (its
        // start overlapping the transfer's end, if so), played as one motion when they overlap.
        // The valve closes `release_lead_s` before the descent ends (the motion's end).
        let part = self.st.world.held_part();
        let close = |end_s: f64| Some(Valve::CloseAt((end_s - release_lead_s).max(0.0)));
        let carried = match (blend, &place.descent_blend) {
            (Some(b), Some(d)) => {
                let rest = Overlapped::new(b.first().clone(), d.clone(), b.start_s()).rest();
                self.play_with(&rest, &held, true, close(rest.duration_s()), true)?
            }
            (None, Some(d)) => self.play_with(d, &held, true, close(d.duration_s()), true)?,
            (Some(b), None) => match self.play_with(&b.rest(), &held, true, None, false)? {
                Played::Failed(o) => Played::Failed(o),
                _ => {
                    let d = &place.descent;
                    self.play_with(d, &held, true, close(d.duration_s()), true)?
                }
            },
            (None, None) => match self.play_with(&place.transfer, &held, true, None, false)? {
                Played::Failed(o) => Played::Failed(o),
                _ => {
                    let d = &place.descent;
                    self.play_with(d, &held, true, close(d.duration_s()), true)?
                }
            },
        };
        if let Played::Failed(o) = carried {
            place_done(self, rec);
            return Ok(o);
        }
        // The part comes off as the vacuum vents: the arm stays until it has surely vented,
        // `release_s` after the valve closed (the controller's timing, not what the part did).
        self.st.world.vacuum_off();
        let closed_s = self
            .st
            .world
            .gripper()
            .valve_closed_since_s()
            .unwrap_or(self.st.world.time_s());
        self.idle_until(closed_s + self.st.world.gripper().release_s + self.st.world.dt_s())?;
        let mut events = std::mem::take(&mut self.st.gripper_events);
        events.extend(self.st.world.take_gripper_events());
        let came_off_s = events.iter().find_map(|e| match e {
            GripperEvent::Released { time_s, .. } => Some(*time_s),
            _ => None,
        });
        let release = came_off_s.unwrap_or(self.st.world.time_s());
        self.event_at(release, Event::Released);
        self.obs.marker(release, &format!("release {}", rec.index));
        if let Some(head_s) = self.prefetch_next(up) {
            // The retreat runs into the next Pick, prepared now: its head alone ends this Place.
            place_done_after(self, rec, head_s);
            if let Some(i) = part {
                self.st.late_placement = Some((rec.index, i, prep.slot));
            }
            rec.release_s = Some(release);
            return Ok(Outcome::Placed);
        }
        if let Played::Failed(o) = self.play(up, &hand, true)? {
            place_done(self, rec);
            return Ok(o);
        }
        place_done(self, rec);
        if let Some(i) = part {
            let (d, yaw) = self.st.world.placement_error(i, &prep.slot, self.cell.yaw_symmetry_rad);
            rec.placement_error_mm = Some(d * 1e3);
            rec.yaw_error_deg = Some(yaw.to_degrees());
        }
        rec.release_s = Some(release);
        Ok(Outcome::Placed)
    }
}
