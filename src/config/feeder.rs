//! The cell file's `[feeder]` section: a hopper on the flexible feeder that doses parts into the
//! pick tray when the sensor sees few, so the pile never runs dry and the arm never waits for a
//! tray exchange.
//!
//! Job: keep the hopper's keys and check them. When a recognition result the cell takes up
//! between picks holds fewer than `dose_below` detections (what the sensor measured, never the
//! truth), the hopper pours `dose_parts` parts into the pick tray; the dose takes at least
//! `dose_s` on the simulation clock (the arm waits out of the sensor's view), the parts fall in
//! through the physics, and the cell looks again. The feeder never fills the tray beyond the
//! workpiece's `pile_count`: it counts what it poured and what the cell placed (its own
//! bookkeeping, an upper bound of the parts in the tray), and skips a dose that could exceed it.
//! `dose_below = 0` (or no section) switches the hopper off: the tray runs down to the
//! `[agitation]` and `cycle.on_empty` policies, as before.
//!
//! Simplified model: the dose's parts are dropped in waves at its start, as a pile is poured
//! (see [`crate::physics::pile`]), above the pile as it lies; the cell waits until the pour has
//! settled or `dose_s` has passed, whichever is later.
//!
//! Units: s, counts.

use serde::{Deserialize, Serialize};

use super::Checker;

/// The hopper on the flexible feeder.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FeederConfig {
    /// Dose when a result shows fewer detections than this (0: no hopper).
    pub dose_below: u32,
    /// Parts per dose.
    pub dose_parts: u32,
    /// Shortest time a dose takes, the arm waiting (s).
    pub dose_s: f64,
}

impl Default for FeederConfig {
    /// No hopper (a cell file without the section).
    fn default() -> Self {
        FeederConfig {
            dose_below: 0,
            dose_parts: 0,
            dose_s: 0.0,
        }
    }
}

/// Most parts a threshold or a dose may name.
const MAX_PARTS: u32 = 1000;

impl FeederConfig {
    /// Whether the hopper doses at all.
    pub fn on(&self) -> bool {
        self.dose_below > 0
    }

    /// Checks the ranges; a hopper that is on needs a dose of at least one part.
    pub(super) fn check(&self, c: &mut Checker) {
        c.within(
            "feeder.dose_below",
            f64::from(self.dose_below),
            0.0,
            f64::from(MAX_PARTS),
        );
        c.within(
            "feeder.dose_parts",
            f64::from(self.dose_parts),
            0.0,
            f64::from(MAX_PARTS),
        );
        c.within("feeder.dose_s", self.dose_s, 0.0, 60.0);
        if self.on() && self.dose_parts == 0 {
            c.fail(
                "feeder.dose_parts",
                format!("must be at least 1 while dose_below > 0, got {}", self.dose_parts),
            );
        }
    }
}
