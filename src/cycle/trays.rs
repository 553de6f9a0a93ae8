//! Cycle step 5, the trays' policies: which slot the next part goes to, what happens when the
//! pick tray has nothing to pick, and when the place tray is full.
//!
//! Job: count captures in a row that gave nothing to pick; after `empty_after_captures` of them
//! follow the cell file's `on_empty` policy: end the run, or exchange the pick tray for a full
//! one (`refill_s`, a new seeded pile) unless a refilled tray gave nothing either. Fill the place
//! tray's slots in order; when they are used up, exchange it for an empty one
//! (`place_tray_exchange_s`). Keep the bookkeeping the takt needs: the last release, and whether
//! a refill happened since.
//!
//! Units: s. Frames: none.

use super::events::{EndReason, Event, Stage};
use super::{CycleError, Run};
use crate::config::OnEmpty;
use crate::physics::PartState;
use crate::physics::pile::PileOptions;

/// The trays' state.
#[derive(Debug, Clone)]
pub struct TrayState {
    /// The slot the next part goes to (modulo the slots).
    pub next_slot: usize,
    /// Piles poured so far (the first one included).
    pub fills: u64,
    /// Picks attempted since the last pour.
    pub attempts_since_fill: usize,
    /// Captures in a row that gave nothing to pick.
    pub empty_in_row: u32,
    /// Pick-tray refills.
    pub refills: usize,
    /// Place-tray exchanges.
    pub exchanges: usize,
    /// A pick-tray refill happened since the last release.
    pub refilled_since_release: bool,
    /// The last release [s].
    pub last_release_s: Option<f64>,
}

impl Default for TrayState {
    fn default() -> Self {
        TrayState {
            next_slot: 0,
            fills: 1,
            attempts_since_fill: 0,
            empty_in_row: 0,
            refills: 0,
            exchanges: 0,
            refilled_since_release: false,
            last_release_s: None,
        }
    }
}

impl TrayState {
    /// A pick was attempted: the pile is not empty.
    pub fn attempted(&mut self) {
        self.empty_in_row = 0;
        self.attempts_since_fill += 1;
    }
}

impl Run<'_, '_> {
    /// A capture gave nothing to pick: after enough of them in a row, refill or end by policy.
    /// Returns why the run ends, if it does.
    pub(super) fn nothing_to_pick(&mut self) -> Result<Option<EndReason>, CycleError> {
        let policy = &self.cell.scene.cycle;
        let trays = &mut self.st.trays;
        trays.empty_in_row += 1;
        if trays.empty_in_row < policy.empty_after_captures {
            return Ok(None);
        }
        trays.empty_in_row = 0;
        match policy.on_empty {
            OnEmpty::End => Ok(Some(EndReason::TrayEmpty)),
            OnEmpty::Refill if trays.attempts_since_fill == 0 && trays.fills > 1 => {
                Ok(Some(EndReason::NothingGraspableInFullTray))
            }
            OnEmpty::Refill => {
                trays.attempts_since_fill = 0;
                let fill = trays.fills;
                self.refill(fill)?;
                let trays = &mut self.st.trays;
                trays.fills += 1;
                trays.refills += 1;
                trays.refilled_since_release = true;
                Ok(None)
            }
        }
    }

    /// Takes the parts left in the pick tray out and pours pile number `fill`.
    fn refill(&mut self, fill: u64) -> Result<(), CycleError> {
        for i in self.st.world.parts_in_state(PartState::Free) {
            self.st.world.remove_part(i);
        }
        let t = self.st.world.time_s();
        self.event(Event::Refill(fill));
        self.idle_until(t + self.cell.scene.cycle.refill_s)?;
        self.st.failed_spots.clear();
        let seed = self
            .cell
            .opts
            .seed
            .wrapping_add(fill.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let obs = &mut *self.obs;
        self.st
            .world
            .build_pile_observed(&PileOptions::new(self.cell.pile_count, seed), &mut |w| obs.stepped(w))?;
        self.span(Stage::Stall, t, self.st.world.time_s(), "pick tray refill");
        self.st.arm.free_s = self.st.world.time_s();
        Ok(())
    }

    /// When the place tray's slots are used up: exchange it for an empty one.
    pub(super) fn exchange_full_place_tray(&mut self) -> Result<(), CycleError> {
        if self.st.trays.next_slot < self.cell.slots.len() {
            return Ok(());
        }
        self.st.trays.next_slot = 0;
        for i in self.st.world.parts_in_state(PartState::Placed) {
            self.st.world.remove_part(i);
        }
        self.st.trays.exchanges += 1;
        self.event(Event::PlaceTrayExchange);
        let t = self.st.world.time_s() + self.cell.scene.cycle.place_tray_exchange_s;
        self.idle_until(t)?;
        self.st.arm.free_s = self.st.arm.free_s.max(self.st.world.time_s());
        Ok(())
    }
}
