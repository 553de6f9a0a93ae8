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
//! takt since the last release (when the part came off). Each motion is played as a
//! `Segment` (its motion, payload, valve switch, how it ends and whether a capture may run),
//! the Pick's and the Place's carry as lists built once from the prepared motions.
//!
//! Units: s, m, rad. Frames: world.

use nalgebra::Isometry3;

use super::events::{Event, Planned, Stage, StallCause};
use super::motions::{PlaceMotion, Prepared};
use super::next_pick::{Prefetched, Settling};
use super::outcome::{NoSeal, Outcome, Slip, WrongPose};
use super::play::{Capture, Played, Segment, Valve};
use super::records::StageCompute;
use super::records::{IntervalCause, PickRecord};
use super::{CycleError, PickSpot, Run};
use crate::physics::suction::GripperEvent;
use crate::robot::JointVector;
use crate::trajectory::Motion;

impl Run<'_, '_> {
    /// The pick of `prep`, whose compute could start at `ready_s`, with `charged` compute, aimed
    /// at the part recognised at `aimed` (`world_from_part`, m): stalls, motions, outcome. Hands
    /// on the next pick when it was prepared at this one's release, its Pick running into this
    /// Place's retreat (not played yet).
    pub(super) fn pick_and_place(
        &mut self,
        prep: &Prepared,
        charged: StageCompute,
        ready_s: f64,
        aimed: Option<Isometry3<f64>>,
        rec: &mut PickRecord,
    ) -> Result<Option<Prefetched>, CycleError> {
        let (pick_ready, place_ready) = self.charge(prep, charged, ready_s, rec);
        // With the last retreat overlapped, the Pick was ready before the retreat's head ends.
        if prep.retreat_blend.is_none() {
            self.idle_until(pick_ready.max(self.st.world.time_s()))?;
        }
        let (outcome, next) = self.motions(prep, rec, place_ready, aimed)?;
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
        let slot_taken = outcome.leaves_slot_taken(rec.place_s > 0.0);
        // No motion for it is a failure at that spot too: the same pile gives the same plan. A
        // part torn off the cup falls back where it lay, under what tore it off.
        if ((outcome.grasp_failed()
            || matches!(
                outcome,
                Outcome::Collision(_) | Outcome::ProtectiveStop(_) | Outcome::NoMotion(_)
            ))
            && rec.place_s == 0.0)
            || (matches!(outcome, Outcome::Dropped(_)) && !slot_taken)
        {
            self.st.failed_spots.push(prep.grasp.world_from_tool.translation.vector);
        }
        if slot_taken {
            // Something may be in the slot (a part that bounced there, or the one the cup let go
            // of over it): the next part goes to the next.
            self.event(Event::SlotSkipped(self.st.trays.next_slot % self.cell.slots.len()));
            self.st.trays.next_slot += 1;
        }
        rec.outcome = outcome;
        self.event(Event::Outcome(rec.outcome.clone()));
        if rec.outcome == Outcome::Placed {
            let release = rec.release_s.unwrap_or(self.st.world.time_s());
            rec.takt_s = self.st.trays.last_release_s.map(|r| release - r);
            let trays = &mut self.st.trays;
            rec.spans_refill = rec.takt_s.is_some() && trays.refilled_since_release;
            // A dose started during this Place counts for the next interval, whose wait it is.
            let doses_before = trays.doses - usize::from(trays.dose_during_place);
            rec.interval_cause = rec.takt_s.map(|_| {
                IntervalCause::of(
                    trays.refilled_since_release,
                    trays.failed_since_release,
                    doses_before > trays.doses_at_release,
                )
            });
            trays.refilled_since_release = false;
            trays.failed_since_release = false;
            trays.doses_at_release = doses_before;
            trays.last_release_s = Some(release);
            trays.next_slot += 1;
        }
        self.st.trays.dose_during_place = false;
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
        Ok(next)
    }

    /// The compute of the pick on the simulation clock from `ready_s`: its spans, the grasp
    /// chosen, the motions generated and the stalls before the Pick, recorded. Returns when the
    /// Pick and when the Place are ready (s).
    fn charge(&mut self, prep: &Prepared, charged: StageCompute, ready_s: f64, rec: &mut PickRecord) -> (f64, f64) {
        rec.compute = charged;
        let grasp_done = ready_s + charged.grasp_s;
        let pick_ready = grasp_done + charged.pick_s;
        let place_ready = pick_ready + charged.place_s;
        self.span(Stage::Grasp, ready_s, grasp_done, "grasp selection");
        self.span(Stage::Planning, grasp_done, pick_ready, "Pick motion");
        self.span(Stage::Planning, pick_ready, place_ready, "Place motion");
        self.event_at(
            grasp_done,
            Event::GraspChosen {
                detection: prep.grasp.detection,
                face: prep.grasp.face,
                score: prep.grasp.score.total,
                hemmed: prep.grasp.score.hemmed,
                lean_rad: prep.grasp.lean_rad,
            },
        );
        // Stall before the Pick: waiting for the sensor, then for compute.
        let free = self.st.arm.free_s;
        rec.stall_sensor_s = (ready_s.min(pick_ready) - free).max(0.0);
        rec.stall_compute_s = (pick_ready - free.max(ready_s)).max(0.0);
        let pick_planned = Planned::Pick {
            transfer_s: prep.pick_transfer.duration_s(),
            descent_s: prep.descent.duration_s(),
            wrist_deviation_rad: prep.descent.wrist_deviation_rad,
            compute_s: charged.pick_s,
        };
        let p = &prep.place;
        let place_planned = Planned::Place {
            lift_s: prep.lift.duration_s(),
            gentle_lift_m_s2: prep.gentle_lift_m_s2,
            transfer_s: p.transfer.duration_s(),
            descent_s: p.descent.duration_s(),
            retreat_s: p.retreat.duration_s(),
            wrist_deviation_rad: [&prep.lift, &p.descent, &p.retreat]
                .iter()
                .filter_map(|l| l.wrist_deviation_rad)
                .reduce(f64::max),
            compute_s: charged.place_s,
        };
        // The grasps passed over before this one: their motions failed as the compute ran.
        let mut stages: Vec<(f64, Event)> = prep
            .passed_over
            .iter()
            .map(|why| (grasp_done, Event::Planned(Planned::Failed { why: why.clone() })))
            .collect();
        stages.extend([
            (pick_ready, Event::Planned(pick_planned)),
            (place_ready, Event::Planned(place_planned)),
        ]);
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
        (pick_ready, place_ready)
    }

    /// Pick (transfer, descent, vacuum, lift) and Place (transfer, descent, release, retreat),
    /// after the last Place's retreat when it runs into this Pick.
    fn motions(
        &mut self,
        prep: &Prepared,
        rec: &mut PickRecord,
        place_ready: f64,
        aimed: Option<Isometry3<f64>>,
    ) -> Result<(Outcome, Option<Prefetched>), CycleError> {
        self.st.arm.max_error_rad = 0.0;
        self.st.arm.peak_demand_ratio = [0.0; crate::robot::DOF];
        self.st.arm.saturated_s = 0.0;
        // The last Place's retreat, alone up to where this Pick starts (that Place's end; its
        // servo errors and torques count for this pick). A capture may start only if its
        // exposure ends before the Pick does.
        if let Some(rb) = &prep.retreat_blend {
            let until_s = self.st.world.time_s() + rb.motion.start_s();
            let head = rb.motion.head();
            let played = self.play(
                &Segment::new(head, self.cell.hand)
                    .flowing_on()
                    .capturing(Capture::EndingBy(until_s)),
            )?;
            if let Played::Failed(o) = played {
                return Ok((o, None));
            }
        }
        let t_pick = self.st.world.time_s();
        if let Some(o) = self.pick(prep, rec, t_pick, aimed)? {
            return Ok((o, None));
        }
        self.lift_and_place(prep, rec, t_pick, place_ready)
    }

    /// The Pick ends now: its time, its span, the arm free.
    fn pick_done(&mut self, rec: &mut PickRecord, t_pick: f64) {
        let lane = if rec.blind { Stage::BlindPick } else { Stage::Pick };
        rec.pick_s = self.st.world.time_s() - t_pick;
        self.span(lane, t_pick, self.st.world.time_s(), "Pick");
        self.st.arm.free_s = self.st.world.time_s();
    }

    /// The Pick from `t_pick` up to the seal: transfer, descent with the valve opening, the
    /// vacuum's build-up. `None` if the cup holds the part; else the outcome, after the lift
    /// with nothing on the cup.
    fn pick(
        &mut self,
        prep: &Prepared,
        rec: &mut PickRecord,
        t_pick: f64,
        aimed: Option<Isometry3<f64>>,
    ) -> Result<Option<Outcome>, CycleError> {
        let hand = self.cell.hand;
        self.st.planned_end_q = None;
        self.event(Event::PickStart);
        let transfer = &prep.pick_transfer;
        self.st.gripper_events.clear();
        rec.overlaps.pick_descent_s = prep.pick_blend.as_ref().map_or(0.0, |b| b.both().duration_s());
        if let Some(rb) = &prep.retreat_blend {
            rec.overlaps.retreat_s = rb.motion.both().duration_s();
        }
        let [to, down] = prep.pick(transfer, hand, self.cell.scene.cycle.vacuum_lead_s);
        if let Played::Failed(o) = self.play(&to)? {
            self.pick_done(rec, t_pick);
            return Ok(Some(o));
        }
        // From here on the pile is touched: results captured before do not show it.
        let t_descent = self.st.world.time_s();
        if let Some(world_from_part) = aimed {
            let g = &prep.grasp;
            self.st.pick_spots.push(PickSpot {
                t_s: t_descent,
                world_from_part,
                tool_lines_m: [
                    [
                        g.world_from_tool_approach.translation.vector,
                        g.world_from_tool.translation.vector,
                    ],
                    [
                        g.world_from_tool_lifted.translation.vector,
                        g.world_from_tool.translation.vector,
                    ],
                ],
            });
        }
        if let Played::Failed(o) = self.play(&down)? {
            self.pick_done(rec, t_pick);
            return Ok(Some(o));
        }
        self.st.world.vacuum_on();
        let vacuum_at = down.valve.map_or(0.0, Valve::at_s);
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
                        com_offset_m: seal.com_offset_m(),
                        tilt_rad: seal.tilt_rad,
                    });
                }
                GripperEvent::GraspFailed { reason, .. } => {
                    failure = Some(Outcome::GraspFailed(NoSeal::Failed(reason)))
                }
                GripperEvent::Slipped { required_n, .. } => {
                    failure = Some(Outcome::Dropped(Slip::AtRest { required_n }))
                }
                GripperEvent::Released { .. } => {}
            }
        }
        rec.sealed = Some(self.st.world.held_part().is_some());
        if self.st.world.held_part().is_some() {
            return Ok(None);
        }
        self.st.world.vacuum_off();
        self.play(&Segment::new(&prep.lift, hand))?;
        self.pick_done(rec, t_pick);
        let failure = failure.unwrap_or(Outcome::GraspFailed(NoSeal::Unexplained));
        // Evaluation only: a failure on a wrong detection is named for what started it.
        Ok(Some(match (failure, rec.aimed_at) {
            (Outcome::GraspFailed(failure), Some(m)) if !m.correct => Outcome::Misrecognised {
                believed: Some(WrongPose {
                    part: m.part,
                    position_error_m: m.position_error_m,
                    rotation_error_rad: m.rotation_error_rad,
                }),
                failure,
            },
            (Outcome::GraspFailed(failure), None) => Outcome::Misrecognised {
                believed: None,
                failure,
            },
            (f, _) => f,
        }))
    }

    /// The lift (the rest of the Pick, from `t_pick`) and the Place: transfer, descent, release,
    /// retreat. With the next pick prepared at the release, the retreat is left to it (returned).
    fn lift_and_place(
        &mut self,
        prep: &Prepared,
        rec: &mut PickRecord,
        t_pick: f64,
        place_ready: f64,
    ) -> Result<(Outcome, Option<Prefetched>), CycleError> {
        let (hand, held) = (self.cell.hand, prep.held);
        self.st.held_tool_from_part = Some(prep.tool_from_part);
        // The lift and the Place transfer overlapped, if they could be and the Place is ready
        // when the transfer would start: the Pick ends where the transfer starts.
        let now = self.st.world.time_s();
        let lift_blend = match &prep.place {
            PlaceMotion {
                lift_blend: Some(b), ..
            } if place_ready <= now + b.start_s() + 1e-9 => Some(b),
            _ => None,
        };
        let lift = match lift_blend {
            Some(b) => {
                rec.overlaps.lift_s = b.both().duration_s();
                Segment::new(b.head(), held)
            }
            None => Segment::new(&prep.lift, held),
        };
        let lifted = self.play(&lift.flowing_on().capturing(Capture::ANY))?;
        self.pick_done(rec, t_pick);
        // A part that tore off the cup in a lift blended into the transfer leaves the arm at the
        // transfer's speed: it goes on along the planned Place, its cup empty (those motions are
        // checked; none starts from mid-swing), releases nothing, and the pick is the drop.
        let dropped = match lifted {
            Played::Failed(o @ Outcome::Dropped(_)) if lift_blend.is_some() => Some(o),
            Played::Failed(o) => return Ok((o, None)),
            Played::Done => None,
        };
        // Place: the motions were generated while the Pick ran; wait if they are not ready yet.
        if place_ready > self.st.world.time_s() {
            let t = self.st.world.time_s();
            rec.stall_compute_s += place_ready - t;
            self.span(Stage::Stall, t, place_ready, "waiting for compute");
            self.idle_until(place_ready)?;
            self.st.arm.servo.qd = JointVector::zeros();
        }
        let place = &prep.place;
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
        let view_free_until_s = t_place + place.carry_s() + release_wait_s + up.duration_s();
        let capture = Capture::EndingBy(view_free_until_s);
        self.event(Event::PlaceStart);
        let part = self.st.world.held_part();
        if let Played::Failed(o) = self.play_all(&place.carry(lift_blend, held, capture))? {
            self.place_done(rec, t_place, 0.0);
            return Ok((o, None));
        }
        // A next pick prepared during the retreat goes to the slot after this part's: none after
        // a drop, which releases nothing and leaves its slot empty.
        let (release, prefetched) = match dropped {
            Some(_) => {
                self.st.world.vacuum_off();
                (None, None)
            }
            None => {
                let release = self.release()?;
                self.obs.marker(release, &format!("release {}", rec.index));
                // Measured once it rests in its slot (the pick loop looks).
                if let Some(part) = part {
                    self.st.settling.push(Settling {
                        record: rec.index,
                        part,
                        world_from_part_place: prep.grasp.world_from_part_place,
                        released_s: release,
                    });
                }
                (Some(release), self.prefetch_next(up))
            }
        };
        let outcome = dropped.unwrap_or(Outcome::Placed);
        if let Some((next, head_s)) = prefetched {
            // The retreat runs into the next Pick, prepared now: its head alone ends this Place.
            self.place_done(rec, t_place, head_s);
            rec.release_s = release;
            return Ok((outcome, Some(next)));
        }
        if let Played::Failed(o) = self.play(&Segment::new(up, hand).capturing(capture))? {
            // Not a placed pick: its part is not measured as one.
            self.st.settling.retain(|s| s.record != rec.index);
            self.place_done(rec, t_place, 0.0);
            return Ok((o, None));
        }
        self.place_done(rec, t_place, 0.0);
        rec.release_s = release;
        Ok((outcome, None))
    }

    /// The Place from `t_place` ends `after_s` from now: 0, or the head of a retreat that runs
    /// into the next Pick (played with it).
    fn place_done(&mut self, rec: &mut PickRecord, t_place: f64, after_s: f64) {
        let end = self.st.world.time_s() + after_s;
        rec.place_s = end - t_place;
        self.span(Stage::Place, t_place, end, "Place");
        self.st.arm.free_s = end;
    }

    /// The release at the end of the Place's descent: the part comes off as the vacuum vents;
    /// the arm stays until it has surely vented, `release_s` after the valve closed (the
    /// controller's timing, not what the part did). Returns when the part came off (s).
    fn release(&mut self) -> Result<f64, CycleError> {
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
        Ok(release)
    }
}
