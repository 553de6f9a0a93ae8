//! Cycle step 5, the trays' policies: which slot the next part goes to, what happens when the
//! pick tray has nothing to pick, and when the place tray is full.
//!
//! Job: when a capture gives nothing to pick, shake the pick tray (the cell file's
//! `[agitation]`, up to `max_tries` times in a row) and look again; without agitation, count
//! captures in a row that gave nothing to pick. When the agitations are used up (or after
//! `empty_after_captures` empty captures without agitation) follow the cell file's `on_empty`
//! policy: end the run, or exchange the pick tray for a full one (`refill_s`, a new seeded pile)
//! unless a refilled tray gave nothing either. Fill the place
//! tray's slots in order; when they are used up, exchange it for an empty one
//! (`place_tray_exchange_s`). Keep the bookkeeping the takt needs: the last release, and whether
//! a refill happened since. With a hopper (the cell file's `[feeder]`, see
//! [`crate::config::feeder`]): dose parts onto the pile when a result the cell takes up shows
//! fewer detections than `dose_below`, unless the dose could fill the tray beyond its pile.
//!
//! Units: s. Frames: none.

use super::events::{EndReason, Event, LeftDuring, PartLoss, Stage};
use super::{CycleError, Run};
use crate::config::OnEmpty;
use crate::physics::pile::PileOptions;
use crate::physics::{HealthEvent, PartState};

/// The trays' state.
#[derive(Debug, Clone)]
pub struct TrayState {
    /// The slot the next part goes to (modulo the slots).
    pub next_slot: usize,
    /// Piles poured so far (the first one included).
    pub fills: u64,
    /// Picks attempted since the last pour.
    pub attempts_since_fill: usize,
    /// Full trays in a row (the current one included, once it is given up on) on which not one
    /// pick was attempted.
    pub fruitless_fills_in_row: u32,
    /// Captures in a row that gave nothing to pick.
    pub empty_in_row: u32,
    /// Pick-tray refills.
    pub refills: usize,
    /// Agitations of the pick tray, in all.
    pub agitations: usize,
    /// Agitations since the last pick attempt (or pour).
    pub agitations_in_row: u32,
    /// Place-tray exchanges.
    pub exchanges: usize,
    /// A pick-tray refill happened since the last release.
    pub refilled_since_release: bool,
    /// A pick failed (any outcome but placed) since the last release.
    pub failed_since_release: bool,
    /// Hopper doses (`doses`) at the last release.
    pub doses_at_release: usize,
    /// The last release (s).
    pub last_release_s: Option<f64>,
    /// Hopper doses, in all.
    pub doses: usize,
    /// Parts dosed since the last pour of a whole pile.
    pub dosed_since_fill: usize,
    /// Parts placed (the run's count) at the last pour of a whole pile.
    pub placed_at_fill: usize,
    /// A dose or a refill is under way: its parts are still falling in (a part that leaves the
    /// tray now was spilled by the pour).
    pub pouring: bool,
    /// A dose the cell called for on the result it is picking from, to start once the arm has
    /// carried the part out of the sensor's view (`feeder.dose_while_placing`): its parts.
    pub dose_due: Option<usize>,
    /// A dose started during the Place under way: the interval that ends at its release does
    /// not hold the dose's wait, the next one does.
    pub dose_during_place: bool,
    /// A dose started during a Place pours until then (s): a part that leaves the tray before
    /// was spilled by it.
    pub dose_pours_until_s: f64,
}

impl Default for TrayState {
    fn default() -> Self {
        TrayState {
            next_slot: 0,
            fills: 1,
            attempts_since_fill: 0,
            fruitless_fills_in_row: 0,
            empty_in_row: 0,
            refills: 0,
            agitations: 0,
            agitations_in_row: 0,
            exchanges: 0,
            refilled_since_release: false,
            failed_since_release: false,
            doses_at_release: 0,
            last_release_s: None,
            doses: 0,
            dosed_since_fill: 0,
            placed_at_fill: 0,
            pouring: false,
            dose_due: None,
            dose_during_place: false,
            dose_pours_until_s: f64::NEG_INFINITY,
        }
    }
}

/// Full trays in a row on which not one pick was attempted before the run ends ("nothing
/// graspable in a full tray"): one such pile is bad luck (a 2,000-pick C run met one at pick
/// 1619, and the tray exchanged for the next full one would have gone on), three in a row say
/// the cell cannot take this part.
pub const FRUITLESS_FILLS_MAX: u32 = 3;

impl TrayState {
    /// A pick was attempted: the pile is not empty.
    pub fn attempted(&mut self) {
        self.empty_in_row = 0;
        self.agitations_in_row = 0;
        self.attempts_since_fill += 1;
    }
}

impl Run<'_, '_> {
    /// A capture gave nothing to pick: after enough of them in a row, refill or end by policy.
    /// Returns why the run ends, if it does.
    pub(super) fn nothing_to_pick(&mut self) -> Result<Option<EndReason>, CycleError> {
        let policy = &self.cell.scene.cycle;
        let max_tries = self.cell.scene.agitation.max_tries;
        let trays = &mut self.st.trays;
        if max_tries > 0 {
            // A vibrating tray: shake at once (a second look at a still pile shows the same
            // pile); when the tries are used up, the pile is stuck: follow the policy now.
            if trays.agitations_in_row < max_tries {
                trays.agitations_in_row += 1;
                trays.agitations += 1;
                let k = trays.agitations_in_row;
                self.agitate(k)?;
                return Ok(None);
            }
        } else {
            trays.empty_in_row += 1;
            if trays.empty_in_row < policy.empty_after_captures {
                return Ok(None);
            }
        }
        let trays = &mut self.st.trays;
        trays.empty_in_row = 0;
        trays.agitations_in_row = 0;
        if trays.attempts_since_fill == 0 {
            trays.fruitless_fills_in_row += 1;
        } else {
            trays.fruitless_fills_in_row = 0;
        }
        match policy.on_empty {
            OnEmpty::End => Ok(Some(EndReason::TrayEmpty)),
            OnEmpty::Refill if trays.fruitless_fills_in_row >= FRUITLESS_FILLS_MAX => {
                Ok(Some(EndReason::NothingGraspableInFullTray))
            }
            OnEmpty::Refill => {
                trays.attempts_since_fill = 0;
                let fill = trays.fills;
                self.refill(fill)?;
                let placed = self.st.tally.placed;
                let trays = &mut self.st.trays;
                trays.fills += 1;
                trays.refills += 1;
                trays.dosed_since_fill = 0;
                trays.placed_at_fill = placed;
                trays.refilled_since_release = true;
                Ok(None)
            }
        }
    }

    /// Shakes the pick tray (the cell file's `[agitation]`): the tray's body is driven through
    /// the vibration step by step, the parts ride it, then the pile settles with the tray at
    /// rest. The arm stands still out of the sensor's view meanwhile.
    fn agitate(&mut self, k: u32) -> Result<(), CycleError> {
        let a = self.cell.scene.agitation;
        self.forget_pile();
        let t0 = self.st.world.time_s();
        self.event(Event::Agitation(k));
        let tray = self.st.world.pick_tray().world_from_tray.rotation;
        while self.st.world.time_s() + 1e-9 < t0 + a.duration_s {
            let t_next = self.st.world.time_s() + self.st.world.dt_s() - t0;
            let offset = tray * nalgebra::Vector3::from(a.offset_m(t_next));
            self.st.world.set_pick_tray_offset(offset);
            self.step()?;
        }
        self.st.world.set_pick_tray_offset(nalgebra::Vector3::zeros());
        self.step()?;
        self.span(Stage::Feeder, t0, self.st.world.time_s(), "agitation");
        let settled = self.st.world.time_s();
        self.idle_until(settled + a.settle_s)?;
        self.span(Stage::Stall, settled, self.st.world.time_s(), "pile settling");
        self.st.arm.free_s = self.st.world.time_s();
        self.st.compute_from_s = self.st.world.time_s();
        Ok(())
    }

    /// The pile is about to change as a whole: no result from before counts, no capture under
    /// way either.
    fn forget_pile(&mut self) {
        self.forget_results();
        self.st.planned_end_q = None;
    }

    /// The results in hand, the capture under way and the picks made since the last capture
    /// no longer count: the pile changed.
    fn forget_results(&mut self) {
        self.st.in_hand = None;
        self.st.pending = None;
        self.st.pick_spots.clear();
    }

    /// Takes the parts left in the pick tray out and pours pile number `fill`.
    fn refill(&mut self, fill: u64) -> Result<(), CycleError> {
        self.forget_pile();
        for i in self.st.world.parts_in_state(PartState::Free) {
            self.st.world.remove_part(i);
        }
        let t = self.st.world.time_s();
        self.event(Event::Refill(fill));
        self.st.failed_spots.clear();
        let seed = self
            .cell
            .opts
            .seed
            .wrapping_add(fill.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        // The new pile falls in at the exchange's start and rests for the rest of it: the
        // exchange takes `refill_s`, however long the physics takes to settle it.
        self.pour(
            PileOptions::into_running_cell(self.cell.pile_count, seed),
            t + self.cell.scene.cycle.refill_s,
        )?;
        self.span(Stage::Stall, t, self.st.world.time_s(), "pick tray refill");
        self.st.arm.free_s = self.st.world.time_s();
        self.st.compute_from_s = self.st.world.time_s();
        Ok(())
    }

    /// A result the cell takes up showed `detected` parts: the parts of the dose the hopper
    /// should pour, if it has one, that count is below its threshold and the dose cannot fill the
    /// tray beyond the pile (by the feeder's own count: the pile poured, plus the parts dosed
    /// since, less the parts placed since).
    pub(super) fn dose_wanted(&self, detected: usize) -> Option<usize> {
        let f = self.cell.scene.feeder;
        if !f.on() || detected >= f.dose_below as usize {
            return None;
        }
        let t = &self.st.trays;
        let placed_since = self.st.tally.placed.saturating_sub(t.placed_at_fill);
        let at_most = (self.cell.pile_count + t.dosed_since_fill).saturating_sub(placed_since);
        (at_most + f.dose_parts as usize <= self.cell.pile_count).then_some(f.dose_parts as usize)
    }

    /// Whether a dose of `parts` may run while the arm places (`feeder.dose_while_placing`):
    /// it falls in one wave, so pouring it takes no step of its own.
    pub(super) fn dose_may_overlap(&self, parts: usize) -> bool {
        self.cell.scene.feeder.dose_while_placing && parts <= crate::physics::pile::POUR_WAVE
    }

    /// Pours `parts` parts from the hopper onto the pile now (through the physics, above the pile
    /// as it lies), the arm waiting out of the view for the dose's time
    /// ([`crate::config::FeederConfig::dose_time_s`]) from its start. Whether the pile has
    /// settled by then is the sensor's to tell: a capture that shows it moving is taken again.
    /// The results in hand are gone: the pile changed.
    pub(super) fn dose(&mut self, parts: usize) -> Result<(), CycleError> {
        self.forget_pile();
        let t0 = self.st.world.time_s();
        self.event(Event::Dose(parts));
        let dose_s = self.cell.scene.feeder.dose_time_s(parts);
        self.pour(self.dose_options(parts), t0 + dose_s)?;
        self.span(Stage::Stall, t0, self.st.world.time_s(), "hopper dose");
        self.dosed(parts);
        self.st.arm.free_s = self.st.world.time_s();
        self.st.compute_from_s = self.st.world.time_s();
        Ok(())
    }

    /// Starts the dose due ([`TrayState::dose_due`]) if the arm is out of the sensor's view:
    /// its parts fall onto the pile while the arm goes on placing, and no capture is triggered
    /// until the dose's time has passed. The results in hand and any capture under way are gone
    /// (the pile changed); the plan of the motion under way stands.
    pub(super) fn start_due_dose(&mut self) -> Result<(), CycleError> {
        let Some(parts) = self.st.trays.dose_due else {
            return Ok(());
        };
        if self.st.sensor.frustum.arm_inside(&self.st.world).is_some() {
            return Ok(());
        }
        self.st.trays.dose_due = None;
        self.forget_results();
        let t0 = self.st.world.time_s();
        self.event(Event::Dose(parts));
        let spilled = self
            .st
            .world
            .build_pile(&self.dose_options(parts))
            .map_err(CycleError::Pour)?
            .spilled;
        self.lose_spilled(spilled);
        let until_s = t0 + self.cell.scene.feeder.dose_time_s(parts);
        self.span(Stage::Feeder, t0, until_s, "hopper dose");
        self.st.capture_hold_until_s = self.st.capture_hold_until_s.max(until_s);
        self.st.trays.dose_pours_until_s = until_s;
        self.st.trays.dose_during_place = true;
        self.dosed(parts);
        Ok(())
    }

    /// The seed of the next dose's pour: its own per dose, apart from the refills' (which add
    /// multiples of another odd constant to the run seed).
    /// The pour of the next dose of `parts` parts: from the hopper's chute, into the running cell.
    fn dose_options(&self, parts: usize) -> PileOptions {
        PileOptions::into_running_cell(parts, self.dose_seed()).dropped_from(self.cell.scene.feeder.chute_height_m)
    }

    fn dose_seed(&self) -> u64 {
        let n = self.st.trays.doses as u64 + 1;
        self.cell
            .opts
            .seed
            .wrapping_add(n.wrapping_mul(0xD1B5_4A32_D192_ED03))
            .rotate_left(17)
    }

    /// A dose of `parts` parts was poured: the feeder's count, and the spots where grasps failed
    /// are forgotten (the pile changed).
    fn dosed(&mut self, parts: usize) {
        let trays = &mut self.st.trays;
        trays.doses += 1;
        trays.dosed_since_fill += parts;
        self.st.failed_spots.clear();
    }

    /// Pours a refill or a dose (`opts`, a pour into a running cell) through the physics, then
    /// waits, the arm still, until `until_s` (s): the cell's set time, not the pile's settling
    /// ([`PileOptions::into_running_cell`]). A part that bounces out of the tray meanwhile is
    /// lost to the pour, as one dragged out by a pick: taken out of the cell and counted, and the
    /// cell goes on (a feeder spills now and then; it does not end the shift).
    fn pour(&mut self, opts: PileOptions, until_s: f64) -> Result<(), CycleError> {
        let obs = &mut *self.obs;
        let report = self
            .st
            .world
            .build_pile_observed(&opts, &mut |w| obs.stepped(w))
            .map_err(CycleError::Pour)?;
        self.lose_spilled(report.spilled);
        self.st.trays.pouring = true;
        let waited = self.idle_until(until_s);
        self.st.trays.pouring = false;
        waited
    }

    /// Counts and reports the parts a pour spilled out of the pick tray (the first pile's
    /// included) as lost.
    pub(super) fn lose_spilled(&mut self, spilled: Vec<HealthEvent>) {
        for spilled in spilled {
            if let HealthEvent::LeftVolume { body, volume, .. } = spilled {
                self.st.parts_lost += 1;
                self.event(Event::PartLost(PartLoss::LeftTray {
                    body,
                    tray: volume,
                    during: LeftDuring::Pour,
                }));
            }
        }
    }

    /// When the place tray's slots are used up: exchange it for an empty one.
    pub(super) fn exchange_full_place_tray(&mut self) -> Result<(), CycleError> {
        if self.st.trays.next_slot < self.cell.slots.len() {
            return Ok(());
        }
        self.st.trays.next_slot = 0;
        self.st.trays.exchanges += 1;
        self.event(Event::PlaceTrayExchange);
        // The full tray goes at the end of the exchange, its last parts measured at rest (or as
        // they lie then): the arm places nothing meanwhile.
        let t = self.st.world.time_s() + self.cell.scene.cycle.place_tray_exchange_s;
        self.idle_until(t)?;
        self.measure_settled(true);
        for i in self.st.world.parts_in_state(PartState::Placed) {
            self.st.world.remove_part(i);
        }
        self.st.arm.free_s = self.st.arm.free_s.max(self.st.world.time_s());
        Ok(())
    }
}
