//! The cell file's `[agitation]` section: how the pick tray is shaken when nothing in it can be
//! picked, before the tray is exchanged for a full one.
//!
//! Job: flexible feeders and vibrating trays loosen a pile that shows no graspable face (relays
//! lying pins-up, cans on their sides) in well under a second, where an exchange takes an operator
//! or a tray handler seconds. The pick tray is driven through a sinusoidal vibration of
//! `amplitude_m` (per axis, tray frame; phase-shifted by a quarter period between x and y so the
//! floor moves in an ellipse) at `frequency_hz` for `duration_s`, then the pile settles for
//! `settle_s`; the cell looks again. After `max_tries` agitations in a row that gave nothing to
//! pick, the cycle's `on_empty` policy follows (refill or end). `max_tries = 0` switches
//! agitation off (a tray without a vibrating base).
//!
//! Units: m, Hz, s. Frames: the pick tray's (x along `inner_size_m[0]`, z up).

use serde::{Deserialize, Serialize};

use super::Checker;

/// The pick tray's vibration.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AgitationConfig {
    /// Agitations in a row (without a pick between) before the `on_empty` policy; 0: none.
    pub max_tries: u32,
    /// Vibration amplitude along the tray's x, y and z (m).
    pub amplitude_m: [f64; 3],
    /// Vibration frequency (Hz).
    pub frequency_hz: f64,
    /// How long the tray vibrates (s).
    pub duration_s: f64,
    /// How long the pile is left to settle afterwards, the tray at rest (s).
    pub settle_s: f64,
}

impl Default for AgitationConfig {
    /// No agitation (a cell file without the section: a tray without a vibrating base).
    fn default() -> Self {
        AgitationConfig {
            max_tries: 0,
            amplitude_m: [0.0; 3],
            frequency_hz: 1.0,
            duration_s: 0.0,
            settle_s: 0.0,
        }
    }
}

/// A workpiece's own shake (its file's `[agitation]`): each key given replaces the cell's key of
/// the same name for this workpiece only, as a vibrating feeder runs a program per product.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AgitationRecipe {
    /// Agitations in a row before the `on_empty` policy; 0: none for this part.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_tries: Option<u32>,
    /// Vibration amplitude along the tray's x, y and z (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amplitude_m: Option<[f64; 3]>,
    /// Vibration frequency (Hz).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frequency_hz: Option<f64>,
    /// How long the tray vibrates (s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    /// How long the pile settles afterwards (s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle_s: Option<f64>,
}

impl AgitationRecipe {
    /// Checks each key given against the cell file's ranges for the key of the same name (what
    /// holds only for the whole shake, a stroke while agitation is on, is checked on the cell
    /// resolved for the workpiece).
    pub fn check(&self, c: &mut Checker) {
        check_ranges(c, self.amplitude_m, self.frequency_hz, self.duration_s, self.settle_s);
    }

    /// This recipe with every key the workpiece left out filled in from the cell's `agitation`.
    pub fn completed(&self, cell: &AgitationConfig) -> AgitationRecipe {
        let a = cell.with_recipe(self);
        AgitationRecipe {
            max_tries: Some(a.max_tries),
            amplitude_m: Some(a.amplitude_m),
            frequency_hz: Some(a.frequency_hz),
            duration_s: Some(a.duration_s),
            settle_s: Some(a.settle_s),
        }
    }
}

/// Checks each of the shake's keys given against its range (the cell's and a workpiece's alike).
fn check_ranges(
    c: &mut Checker,
    amplitude_m: Option<[f64; 3]>,
    frequency_hz: Option<f64>,
    duration_s: Option<f64>,
    settle_s: Option<f64>,
) {
    for (i, a) in amplitude_m.iter().flatten().enumerate() {
        c.within(&format!("agitation.amplitude_m[{i}]"), *a, 0.0, MAX_AMPLITUDE_M);
    }
    if let Some(f) = frequency_hz {
        c.within("agitation.frequency_hz", f, 0.1, MAX_FREQUENCY_HZ);
    }
    if let Some(d) = duration_s {
        c.within("agitation.duration_s", d, 0.0, 10.0);
    }
    if let Some(d) = settle_s {
        c.within("agitation.settle_s", d, 0.0, 10.0);
    }
}

/// Largest amplitude accepted (m): strokes bigger than this are not a vibrating base's
const MAX_AMPLITUDE_M: f64 = 0.02;
/// Highest frequency accepted (Hz): the physics step (2 ms) samples a period in 10 steps.
const MAX_FREQUENCY_HZ: f64 = 50.0;

impl AgitationConfig {
    /// The shake with `recipe`'s keys in place of its own.
    pub fn with_recipe(&self, recipe: &AgitationRecipe) -> AgitationConfig {
        AgitationConfig {
            max_tries: recipe.max_tries.unwrap_or(self.max_tries),
            amplitude_m: recipe.amplitude_m.unwrap_or(self.amplitude_m),
            frequency_hz: recipe.frequency_hz.unwrap_or(self.frequency_hz),
            duration_s: recipe.duration_s.unwrap_or(self.duration_s),
            settle_s: recipe.settle_s.unwrap_or(self.settle_s),
        }
    }

    /// Checks the ranges; an agitation that is on needs a stroke, a frequency and a duration.
    pub(super) fn check(&self, c: &mut Checker) {
        check_ranges(
            c,
            Some(self.amplitude_m),
            Some(self.frequency_hz),
            Some(self.duration_s),
            Some(self.settle_s),
        );
        if self.max_tries > 0 {
            if self.amplitude_m.iter().all(|a| *a == 0.0) {
                c.fail(
                    "agitation.amplitude_m",
                    "all zero while max_tries > 0: the tray would not move",
                );
            }
            if self.duration_s <= 0.0 {
                c.fail(
                    "agitation.duration_s",
                    format!("must be positive while max_tries > 0, got {}", self.duration_s),
                );
            }
        }
    }

    /// The tray's offset from its rest pose at `t_s` into the vibration, in the tray frame (m):
    /// x and y a quarter period apart, z in phase with x; ramped in and out over a period each
    /// end so the stroke starts and ends at rest.
    pub fn offset_m(&self, t_s: f64) -> [f64; 3] {
        if t_s <= 0.0 || t_s >= self.duration_s {
            return [0.0; 3];
        }
        let period = 1.0 / self.frequency_hz;
        let ramp = (t_s / period).min((self.duration_s - t_s) / period).clamp(0.0, 1.0);
        let w = std::f64::consts::TAU * self.frequency_hz * t_s;
        let [ax, ay, az] = self.amplitude_m;
        [ramp * ax * w.sin(), ramp * ay * w.cos(), ramp * az * w.sin()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A recipe replaces the keys it gives and keeps the cell's others; completed, it holds every
    /// key. The control: an empty recipe is the cell's shake.
    #[test]
    fn a_recipe_replaces_only_the_keys_it_gives() {
        let cell = AgitationConfig {
            max_tries: 3,
            amplitude_m: [0.002, 0.002, 0.001],
            frequency_hz: 15.0,
            duration_s: 0.6,
            settle_s: 0.3,
        };
        let r = AgitationRecipe {
            frequency_hz: Some(22.0),
            amplitude_m: Some([0.0, 0.0, 0.004]),
            ..AgitationRecipe::default()
        };
        let a = cell.with_recipe(&r);
        assert_eq!((a.frequency_hz, a.amplitude_m), (22.0, [0.0, 0.0, 0.004]));
        assert_eq!((a.max_tries, a.duration_s, a.settle_s), (3, 0.6, 0.3));
        let full = r.completed(&cell);
        assert_eq!(cell.with_recipe(&full), a);
        assert!(full.max_tries.is_some() && full.settle_s.is_some());
        assert_eq!(cell.with_recipe(&AgitationRecipe::default()), cell);
    }
}
