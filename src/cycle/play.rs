//! Cycle step 4, execution: motions played through the servo into the physics world, faults
//! caught, and the way out of a fault.
//!
//! Job: run a motion through the torque-limited servo from the arm's actual state, move the
//! arm's bodies to the servo's positions every physics step, poll for the next capture while
//! the arm is out of view, and watch every step: parts that left their tray are taken out as
//! lost; a collision of the arm or the held part, or a part pressed into the tray, stops the
//! motion; the servo's protective stop and a part slipping off the cup end it. After a stop or
//! a collision the vacuum goes off, the controller waits its reset time and the arm backs out
//! (straight up out of the pick tray, else back along the faulted motion, slowly).
//!
//! Units: s, rad, m. Frames: joint space; world for the tool.

use std::borrow::Cow;

use nalgebra::{Isometry3, Translation3};

use super::events::{Event, LeftDuring, PartLoss, Stage, StartMismatch};
use super::outcome::{Fault, Outcome, Slip, Stop};
use super::{CycleError, Run};
use crate::geometry::TrayVolume;
use crate::physics::suction::GripperEvent;
use crate::physics::{HealthEvent, PartState};
use crate::robot::{DOF, JointVector, Payload};
pub(super) use crate::servo::Settle;
use crate::servo::execute_from;
use crate::trajectory::{LineLimits, LineMotion, Motion, Overlapped, Trajectory, straight_line};

/// How a motion ended.
pub(super) enum Played {
    /// Done.
    Done,
    /// Ended the pick.
    Failed(Outcome),
}

/// A switch of the vacuum valve during a motion, at a time from the motion's start (s).
#[derive(Debug, Clone, Copy)]
pub(super) enum Valve {
    /// The valve opens: the vacuum builds up (the Pick's descent).
    OpenAt(f64),
    /// The valve closes: the vacuum vents and the part comes off (the Place's descent).
    CloseAt(f64),
}

impl Valve {
    /// When it switches, from the motion's start (s).
    pub fn at_s(self) -> f64 {
        match self {
            Valve::OpenAt(t) | Valve::CloseAt(t) => t,
        }
    }
}

/// Whether the sensor may be triggered while a segment plays (once the arm is out of view).
#[derive(Debug, Clone, Copy)]
pub(super) enum Capture {
    /// Never: the arm is over the pile or heading there.
    Never,
    /// If the exposure ends by this simulation time (s): the arm's plan takes it into the view
    /// then (infinite: no motion into the view is planned).
    EndingBy(f64),
}

impl Capture {
    /// A capture at any time the arm is out of view.
    pub const ANY: Capture = Capture::EndingBy(f64::INFINITY);
}

/// The motion of a segment: one of the kinds the cycle plays, each through its own instance
/// of the servo loop (as fast as a loop over one known motion type).
#[derive(Debug)]
pub(super) enum SegmentMotion<'m> {
    /// A straight tool line (a descent, a lift, a retreat, a way out).
    Line(&'m LineMotion),
    /// A planned and accelerated transfer.
    Transfer(&'m Trajectory),
    /// A lift with the Place transfer started before it ends (or a window of it).
    LiftTransfer(Overlapped<LineMotion, Trajectory>),
    /// A transfer with the descent started before it ends (or a window of it).
    TransferDescent(Cow<'m, Overlapped<Trajectory, LineMotion>>),
    /// A line (a retreat, a lift) with a transfer and descent started before it ends.
    LineThenPick(Overlapped<LineMotion, Overlapped<Trajectory, LineMotion>>),
}

impl SegmentMotion<'_> {
    /// The motion, whichever its kind.
    pub fn as_motion(&self) -> &dyn Motion {
        match self {
            SegmentMotion::Line(m) => *m,
            SegmentMotion::Transfer(m) => *m,
            SegmentMotion::LiftTransfer(m) => m,
            SegmentMotion::TransferDescent(m) => m.as_ref(),
            SegmentMotion::LineThenPick(m) => m,
        }
    }
}

impl<'m> From<&'m LineMotion> for SegmentMotion<'m> {
    fn from(m: &'m LineMotion) -> Self {
        SegmentMotion::Line(m)
    }
}

impl<'m> From<&'m Trajectory> for SegmentMotion<'m> {
    fn from(m: &'m Trajectory) -> Self {
        SegmentMotion::Transfer(m)
    }
}

impl From<Overlapped<LineMotion, Trajectory>> for SegmentMotion<'_> {
    fn from(m: Overlapped<LineMotion, Trajectory>) -> Self {
        SegmentMotion::LiftTransfer(m)
    }
}

impl From<Overlapped<Trajectory, LineMotion>> for SegmentMotion<'_> {
    fn from(m: Overlapped<Trajectory, LineMotion>) -> Self {
        SegmentMotion::TransferDescent(Cow::Owned(m))
    }
}

impl<'m> From<&'m Overlapped<Trajectory, LineMotion>> for SegmentMotion<'m> {
    fn from(m: &'m Overlapped<Trajectory, LineMotion>) -> Self {
        SegmentMotion::TransferDescent(Cow::Borrowed(m))
    }
}

impl From<Overlapped<LineMotion, Overlapped<Trajectory, LineMotion>>> for SegmentMotion<'_> {
    fn from(m: Overlapped<LineMotion, Overlapped<Trajectory, LineMotion>>) -> Self {
        SegmentMotion::LineThenPick(m)
    }
}

/// One motion as the arm plays it: what the controller believes the cup carries, the valve's
/// switch, how it ends and whether the sensor may be triggered meanwhile.
pub(super) struct Segment<'m> {
    /// The motion.
    pub motion: SegmentMotion<'m>,
    /// The payload the controller models (hand, or hand and part).
    pub payload: Payload,
    /// The valve's switch during it, if any.
    pub valve: Option<Valve>,
    /// How it ends.
    pub settle: Settle,
    /// Whether a capture may be triggered.
    pub capture: Capture,
}

impl<'m> Segment<'m> {
    /// `motion` with `payload`, no valve switch, ending in position, no capture.
    pub fn new(motion: impl Into<SegmentMotion<'m>>, payload: Payload) -> Self {
        Segment {
            motion: motion.into(),
            payload,
            valve: None,
            settle: Settle::InPosition,
            capture: Capture::Never,
        }
    }

    /// The same, handing over to the next segment while still moving.
    pub fn flowing_on(self) -> Self {
        Segment {
            settle: Settle::AtEnd,
            ..self
        }
    }

    /// The same, switching the valve.
    pub fn switching(self, valve: Valve) -> Self {
        Segment {
            valve: Some(valve),
            ..self
        }
    }

    /// The same, a capture allowed as `capture` says.
    pub fn capturing(self, capture: Capture) -> Self {
        Segment { capture, ..self }
    }
}

impl Run<'_, '_> {
    /// One physics step, watched. Parts that left their tray are taken out of the cell (lost);
    /// the first collision of the arm or part pressed into the tray is returned; a non-finite
    /// state ends the run.
    pub(super) fn step(&mut self) -> Result<Option<HealthEvent>, CycleError> {
        let result = self.st.world.step();
        self.obs.stepped(&self.st.world);
        if let Some(job) = self.st.pending.as_mut() {
            if let Some(confirm) = job.confirm.as_mut() {
                // A confirming exposure the arm enters is not used (the check falls back).
                self.st.sensor.watch(confirm, &self.st.world);
            }
            if let Some(problem) = self.st.sensor.watch(job, &self.st.world) {
                self.event(Event::CaptureSpoiled(problem));
            }
        }
        self.maybe_confirm();
        let Err(report) = result else {
            return Ok(None);
        };
        if report.is_fatal() {
            return Err(report.into());
        }
        // Every problem of the step: parts out of their tray are taken out of the cell (all at
        // once), a collision or a part pressed into the tray stops the motion.
        let mut fault = None;
        let mut lost_removed = false;
        let dose_pouring = self.st.world.time_s() < self.st.trays.dose_pours_until_s;
        let during = match self.st.world.held_part() {
            _ if dose_pouring => LeftDuring::Pour,
            Some(held) => LeftDuring::Holding(held),
            None if self.st.trays.pouring => LeftDuring::Pour,
            None => LeftDuring::CupEmpty,
        };
        for event in report.events {
            match event {
                HealthEvent::LeftVolume {
                    body,
                    volume,
                    with_held,
                    ..
                } => {
                    if !lost_removed {
                        self.remove_lost_parts();
                        lost_removed = true;
                    }
                    let during = match during {
                        LeftDuring::Holding(held) if with_held => LeftDuring::CarriedWith(held),
                        d => d,
                    };
                    self.event(Event::PartLost(PartLoss::LeftTray {
                        body,
                        tray: volume,
                        during,
                    }));
                }
                e @ (HealthEvent::ArmCollision { .. } | HealthEvent::DeepPenetration { .. }) => {
                    fault.get_or_insert(e);
                }
                HealthEvent::NonFinite { .. } => {}
            }
        }
        Ok(fault)
    }

    /// Takes every part that is out of the tray it belongs in out of the cell, counting it lost.
    fn remove_lost_parts(&mut self) {
        self.st.parts_lost += self.st.world.remove_parts_out_of_their_trays();
    }

    /// Steps the world to `t` with the arm still. Contacts of a resting arm are not new faults.
    pub(super) fn idle_until(&mut self, t: f64) -> Result<(), CycleError> {
        while self.st.world.time_s() + 1e-9 < t {
            self.step()?;
        }
        Ok(())
    }

    /// Plays segments in order until one fails.
    pub(super) fn play_all(&mut self, segments: &[Segment<'_>]) -> Result<Played, CycleError> {
        for segment in segments {
            if let failed @ Played::Failed(_) = self.play(segment)? {
                return Ok(failed);
            }
        }
        Ok(Played::Done)
    }

    /// Plays a segment through the servo into the world, switching the vacuum valve and polling
    /// for the next capture as it says.
    pub(super) fn play(&mut self, segment: &Segment<'_>) -> Result<Played, CycleError> {
        match &segment.motion {
            SegmentMotion::Line(m) => self.play_motion(*m, segment),
            SegmentMotion::Transfer(m) => self.play_motion(*m, segment),
            SegmentMotion::LiftTransfer(m) => self.play_motion(m, segment),
            SegmentMotion::TransferDescent(m) => self.play_motion(m.as_ref(), segment),
            SegmentMotion::LineThenPick(m) => self.play_motion(m, segment),
        }
    }

    /// [`Run::play`] of `motion`, the segment's motion as its own type.
    fn play_motion<M: Motion>(&mut self, motion: &M, segment: &Segment<'_>) -> Result<Played, CycleError> {
        let Segment {
            payload,
            valve,
            settle,
            capture,
            ..
        } = segment;
        let robot = self.cell.robot;
        let start = motion.at(0.0);
        let mismatch = StartMismatch {
            q_rad: (start.q - self.st.world.joints()).amax(),
            qd_rad_s: (start.qd - self.st.arm.commanded_qd).amax(),
        };
        if mismatch.is_logged() {
            self.event(Event::MotionStartMismatch(mismatch));
        }
        // The controller's model with the payload it believes; the plant with its own model
        // error and the part as it actually sits on the cup.
        let model = robot.dynamics(payload);
        let plant = self.cell.plant.dynamics(&self.plant_payload(payload));
        let run = execute_from(
            robot,
            &model,
            &plant,
            &self.cell.servo,
            motion,
            self.st.arm.servo,
            *settle,
        );
        self.st.arm.servo = run.end_state;
        self.st.arm.commanded_qd = motion.at(motion.duration_s()).qd;
        let t0 = self.st.world.time_s();
        let arm = &mut self.st.arm;
        for i in 0..DOF {
            arm.peak_demand_ratio[i] = arm.peak_demand_ratio[i].max(run.peak_demand_ratio[i]);
            let run_peak = &mut self.st.run_peak_demand_ratio[i];
            *run_peak = run_peak.max(run.peak_demand_ratio[i]);
        }
        arm.saturated_s += run.saturated_ticks as f64 * self.cell.servo.dt_s;
        arm.max_error_rad = run.max_error_rad.iter().fold(arm.max_error_rad, |a, e| a.max(*e));
        let per_step = (self.st.world.dt_s() / self.cell.servo.dt_s).round().max(1.0) as usize;
        let mut dropped = None;
        let mut k = per_step;
        let mut played = 0;
        // Until the last tick is played, once (a motion that ends moving must not stand still
        // for a step at its end).
        while k < run.ticks.len() - 1 + per_step {
            let end = k.min(run.ticks.len() - 1);
            self.st.world.set_joint_target(&run.ticks[end].q);
            match *valve {
                Some(Valve::OpenAt(t)) if run.ticks[end].t_s + 1e-9 >= t => self.st.world.vacuum_on(),
                Some(Valve::CloseAt(t)) if run.ticks[end].t_s + 1e-9 >= t => self.st.world.vacuum_off(),
                _ => {}
            }
            played = end + 1;
            if let Some(what) = self.step()? {
                self.obs.executed(t0, motion, &run.ticks, played);
                let path: Vec<JointVector> = run.ticks[..=end].iter().map(|tk| tk.q).collect();
                self.recover(&path, Fault::Collision(what.clone()))?;
                return Ok(Played::Failed(Outcome::Collision(what)));
            }
            if let Capture::EndingBy(until_s) = capture {
                // A dose due starts once the part being placed has left the view.
                if self.st.trays.dose_due.is_some() && self.st.world.held_part().is_some() {
                    self.start_due_dose()?;
                }
                self.maybe_trigger(*until_s);
            }
            for ev in self.st.world.take_gripper_events() {
                if let GripperEvent::Slipped {
                    required_n,
                    holding_n,
                    time_s,
                    ..
                } = ev
                {
                    let tool_m = self.st.world.world_from_tool().translation.vector;
                    dropped.get_or_insert(Slip::Moving {
                        after_s: time_s - t0,
                        required_n,
                        holding_n,
                        over_place_tray: TrayVolume::new(&self.cell.scene.place_tray.tray).contains(&tool_m),
                    });
                } else {
                    self.st.gripper_events.push(ev);
                }
            }
            k += per_step;
        }
        self.obs.executed(t0, motion, &run.ticks, played);
        if let Some((after_s, trip)) = run.trip {
            let stop = Stop { trip, after_s };
            // Back along what the arm executed before the drive stopped.
            let path: Vec<JointVector> = run.ticks.iter().map(|tk| tk.q).collect();
            self.recover(&path, Fault::ProtectiveStop(stop.clone()))?;
            return Ok(Played::Failed(Outcome::ProtectiveStop(stop)));
        }
        if let Some(why) = dropped {
            return Ok(Played::Failed(Outcome::Dropped(why)));
        }
        Ok(Played::Done)
    }

    /// What the plant carries while the controller believes `believed`: with the cell file's
    /// `held_part_as_sealed`, the hand and the part as the physics holds it on the cup (its
    /// mass, inertia and centre of mass where the cup sealed), or the hand alone when nothing is
    /// held; otherwise what the controller believes.
    fn plant_payload(&self, believed: &Payload) -> Payload {
        if !self.cell.scene.model_error.held_part_as_sealed {
            return *believed;
        }
        match self.st.world.held_payload() {
            Some(part) => self.cell.hand.combined(&part),
            None => self.cell.hand,
        }
    }

    /// After a fault: the vacuum goes off, the controller waits its reset time, then the arm
    /// retraces `path` (the executed positions of the faulted motion) back to where it started.
    fn recover(&mut self, path: &[JointVector], fault: Fault) -> Result<(), CycleError> {
        let t = self.st.world.time_s();
        self.event(Event::Fault(fault));
        self.obs.marker(t, "fault");
        self.st.world.vacuum_off();
        self.idle_until(t + self.cell.scene.sim.protective_stop_reset_s)?;
        self.st.arm.rest_at(self.st.world.joints());
        self.clear_deep_penetrations();
        let tool = self.st.world.world_from_tool();
        let tray = self.st.world.pick_tray();
        let above_z = tray.world_from_tray.translation.z + self.cell.scene.pick_tray.wall_height_m + 0.1;
        let local = tray.world_from_tray.inverse() * nalgebra::Point3::from(tool.translation.vector);
        let over_pick_tray = local.x.abs() < tray.half_xy_m[0] && local.y.abs() < tray.half_xy_m[1];
        let hand = self.cell.hand;
        if over_pick_tray && tool.translation.z < above_z {
            // In the tray: straight up, slowly, out of whatever it touches.
            let up = Isometry3::from_parts(
                Translation3::new(tool.translation.x, tool.translation.y, above_z),
                tool.rotation,
            );
            let limits = LineLimits {
                speed_m_s: 0.1,
                accel_m_s2: 1.0,
                ..self.cell.line_limits()
            };
            if let Some(line) = straight_line(
                &self.cell.accel_robot,
                &self.cell.accel_robot.dynamics(&hand),
                &self.st.arm.servo.q,
                &tool,
                &up,
                &limits,
                None,
            ) {
                let path: Vec<JointVector> = line.sampled(self.cell.servo.dt_s).iter().map(|s| s.q).collect();
                self.retrace(&path, 1)?;
            }
        } else {
            // Elsewhere: back along the faulted motion, at a third of its speed.
            let back: Vec<JointVector> = path.iter().rev().copied().collect();
            self.retrace(&back, 3)?;
        }
        self.st.arm.rest_at(self.st.world.joints());
        self.st.world.take_gripper_events();
        self.st.gripper_events.clear();
        self.span(Stage::Stall, t, self.st.world.time_s(), "fault reset and retreat");
        self.st.arm.free_s = self.st.world.time_s();
        Ok(())
    }

    /// After a fault: parts the arm pressed into the tray or into each other (deeper than the
    /// health monitor allows) are damaged goods: taken out of the cell and counted as lost.
    fn clear_deep_penetrations(&mut self) {
        for _ in 0..8 {
            let (depth, pair) = self.st.world.max_penetration_m();
            let Some((a, b)) = pair.filter(|_| depth > self.st.world.health_limits().deep_penetration_m) else {
                return;
            };
            let mut removed = false;
            for tag in [a, b] {
                if let crate::physics::Tag::Part(i) = tag
                    && self.st.world.part_state(i as usize) != PartState::Held
                {
                    self.st.world.remove_part(i as usize);
                    self.st.parts_lost += 1;
                    self.event(Event::PartLost(PartLoss::PressedDeep {
                        part: i as usize,
                        depth_m: depth,
                    }));
                    removed = true;
                }
            }
            if !removed {
                return;
            }
        }
    }

    /// Moves the arm's bodies through servo-rate positions `path`, `slow` times slower, without
    /// treating contacts as new faults (the arm is getting out of one).
    fn retrace(&mut self, path: &[JointVector], slow: usize) -> Result<(), CycleError> {
        let per_step = (self.st.world.dt_s() / self.cell.servo.dt_s).round().max(1.0) as usize;
        for q in path.iter().step_by(per_step) {
            for _ in 0..slow {
                self.st.world.set_joint_target(q);
                self.step()?;
            }
        }
        Ok(())
    }
}
