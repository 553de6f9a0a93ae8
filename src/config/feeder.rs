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
//! A dose of `dose_parts` parts takes at least `dose_parts / dose_rate_parts_per_s` too: the
//! hopper's chute conveys parts at a finite rate, so a larger dose costs more time.
//! `dose_below = 0` (or no section) switches the hopper off: the tray runs down to the
//! `[agitation]` and `cycle.on_empty` policies, as before.
//! With `dose_while_placing`, a result that shows few parts but still offers a grasp is picked
//! from first, and the dose starts once that part has been carried out of the sensor's view: it
//! runs while the arm places (the cycle's side of it is in `crate::cycle`, its trays step).
//!
//! Simplified model: the dose's parts are dropped in waves at its start, as a pile is poured
//! (see [`crate::physics::pile`]), above the pile as it lies, or from the chute's exit
//! (`chute_height_m`) where that is higher; the cell waits `dose_s` or the
//! chute's time, whichever is longer, from the dose's start, then looks: whether the pour has
//! come to rest is its sensor's to tell (a capture showing the pile moving is taken again), never
//! the physics'.
//!
//! A workpiece file may bring its own recipe for the hopper (`[feeder]` in it, [`FeederRecipe`]):
//! how many parts a dose holds and below what count the cell doses depend on the part (its pile
//! size, how many of a pile the sensor finds), as a real feeder's recipe is set per product; the
//! hopper itself (its chute's flow, a dose's shortest time) stays the cell's.
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
    /// The hopper chute's flow (parts/s): a dose takes at least `dose_parts` over this.
    #[serde(default = "default_dose_rate")]
    pub dose_rate_parts_per_s: f64,
    /// A dose called for by a result that still offers a grasp starts when the arm has carried
    /// that part out of the sensor's view, and runs while it places (`true`); with `false`, the
    /// default, the cell doses at once and the arm waits out the dose. Doses of more parts than
    /// one wave of a pour ([`crate::physics::pile::POUR_WAVE`]) are always dosed at once.
    #[serde(default)]
    pub dose_while_placing: bool,
    /// Height of the hopper chute's exit above the pick tray's floor (m): a dose's parts fall
    /// from there, or from just above the pile where it stands higher. 0, the default: from just
    /// above the pile's top (3 mm), wherever it is.
    #[serde(default)]
    pub chute_height_m: f64,
}

/// The flow of a vibratory hopper chute for small parts when a cell file leaves it out (parts/s):
/// an estimate at the low end of the 10 to 20 parts a second such chutes convey, so a large
/// dose is never cheaper in the twin than on the line.
pub const DEFAULT_DOSE_RATE_PARTS_PER_S: f64 = 10.0;

fn default_dose_rate() -> f64 {
    DEFAULT_DOSE_RATE_PARTS_PER_S
}

impl Default for FeederConfig {
    /// No hopper (a cell file without the section).
    fn default() -> Self {
        FeederConfig {
            dose_below: 0,
            dose_parts: 0,
            dose_s: 0.0,
            dose_rate_parts_per_s: DEFAULT_DOSE_RATE_PARTS_PER_S,
            dose_while_placing: false,
            chute_height_m: 0.0,
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

    /// The shortest time a dose of `parts` parts takes (s): `dose_s`, or the chute's time to
    /// convey them, whichever is longer.
    pub fn dose_time_s(&self, parts: usize) -> f64 {
        self.dose_s.max(parts as f64 / self.dose_rate_parts_per_s)
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
        c.within("feeder.dose_rate_parts_per_s", self.dose_rate_parts_per_s, 0.1, 1000.0);
        c.within("feeder.chute_height_m", self.chute_height_m, 0.0, 0.5);
        if self.on() && self.dose_parts == 0 {
            c.fail(
                "feeder.dose_parts",
                format!("must be at least 1 while dose_below > 0, got {}", self.dose_parts),
            );
        }
    }
}

/// The hopper's recipe a workpiece brings (`[feeder]` in a workpiece file): each key given
/// replaces the cell's `feeder.` key of the same name for this workpiece; a key left out keeps
/// the cell's.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FeederRecipe {
    /// Dose when a result shows fewer detections than this (0: no hopper for this part).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dose_below: Option<u32>,
    /// Parts per dose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dose_parts: Option<u32>,
}

impl FeederRecipe {
    /// Checks each key given, as the cell file's `feeder.` key of the same name is checked.
    pub fn check(&self, c: &mut Checker) {
        if let Some(v) = self.dose_below {
            c.within("feeder.dose_below", f64::from(v), 0.0, f64::from(MAX_PARTS));
        }
        if let Some(v) = self.dose_parts {
            c.within("feeder.dose_parts", f64::from(v), 0.0, f64::from(MAX_PARTS));
        }
    }

    /// This recipe with every key the workpiece left out filled in from the cell's `feeder`.
    pub fn completed(&self, f: &FeederConfig) -> FeederRecipe {
        let r = f.with_recipe(self);
        FeederRecipe {
            dose_below: Some(r.dose_below),
            dose_parts: Some(r.dose_parts),
        }
    }
}

impl FeederConfig {
    /// The hopper with `recipe`'s keys in place of its own.
    pub fn with_recipe(&self, recipe: &FeederRecipe) -> FeederConfig {
        FeederConfig {
            dose_below: recipe.dose_below.unwrap_or(self.dose_below),
            dose_parts: recipe.dose_parts.unwrap_or(self.dose_parts),
            ..*self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dose_takes_its_shortest_time_or_the_chutes_whichever_is_longer() {
        let f = FeederConfig {
            dose_below: 12,
            dose_parts: 40,
            dose_s: 2.0,
            dose_rate_parts_per_s: 10.0,
            dose_while_placing: false,
            chute_height_m: 0.0,
        };
        assert_eq!(f.dose_time_s(10), 2.0);
        assert_eq!(f.dose_time_s(40), 4.0);
        // Negative control: a chute ten times faster leaves the dose at its shortest time.
        let fast = FeederConfig {
            dose_rate_parts_per_s: 100.0,
            ..f
        };
        assert_eq!(fast.dose_time_s(40), 2.0);
    }

    #[test]
    fn a_recipe_replaces_only_the_keys_it_gives() {
        let cell = FeederConfig {
            dose_below: 12,
            dose_parts: 10,
            dose_s: 2.0,
            dose_rate_parts_per_s: 10.0,
            dose_while_placing: false,
            chute_height_m: 0.0,
        };
        let r = FeederRecipe {
            dose_below: None,
            dose_parts: Some(40),
        };
        let f = cell.with_recipe(&r);
        assert_eq!((f.dose_below, f.dose_parts, f.dose_s), (12, 40, 2.0));
        assert_eq!(
            r.completed(&cell),
            FeederRecipe {
                dose_below: Some(12),
                dose_parts: Some(40)
            }
        );
        // Negative control: no recipe, the cell's hopper.
        assert_eq!(cell.with_recipe(&FeederRecipe::default()), cell);
    }
}
