//! The hopper on the flexible feeder (`[feeder]` in the cell file): its keys refused with file,
//! key and value; in a run it doses only when the result the cell takes up shows fewer parts
//! than the threshold (checked from the run's own events by an observer: the detections the
//! sensor reported before each dose), and never above it.

use crate::support::{Workspace, binpick_in, stderr};
use binpick::config::{FeederConfig, LoadedScene, LoadedWorkpiece};
use binpick::cycle::{Event, Observer, RunOptions, Stage, Tally};
use binpick::physics::pile::PileOptions;
use binpick::robot::RobotModel;

#[test]
fn bad_feeder_keys_exit_2_naming_file_key_and_value_and_write_nothing() {
    let ws = Workspace::new();
    for (from, to, why) in [
        (
            "dose_parts = 10",
            "dose_parts = 0",
            "feeder.dose_parts must be at least 1 while dose_below > 0, got 0",
        ),
        (
            "dose_s = 2.0",
            "dose_s = -1.0",
            "feeder.dose_s must be within [0, 60], got -1",
        ),
        (
            "dose_parts = 10",
            "dose_parts = 5000",
            "feeder.dose_parts must be within [0, 1000], got 5000",
        ),
        ("dose_below = 12", "dose_below = 2.5", "dose_below"),
        ("dose_below = 12", "dose_below = -3", "dose_below"),
        ("dose_s = 2.0", "dose_s = 2.0\ndose_rate = 3", "dose_rate"),
        (
            "dose_rate_parts_per_s = 10.0",
            "dose_rate_parts_per_s = 0.0",
            "feeder.dose_rate_parts_per_s must be within [0.1, 1000], got 0",
        ),
        (
            "chute_height_m = 0.0",
            "chute_height_m = 0.9",
            "feeder.chute_height_m must be within [0, 0.5], got 0.9",
        ),
    ] {
        // The first case needs the hopper on to be wrong.
        let on = ws.edit(
            "scenes/default.toml",
            "scenes/on.toml",
            "dose_below = 12",
            "dose_below = 4",
        );
        let base = if from == "dose_below = 12" {
            "scenes/default.toml"
        } else {
            "scenes/on.toml"
        };
        assert!(on.exists());
        let bad = ws.edit(base, "scenes/bad.toml", from, to);
        crate::support::batch_is_refused(&ws, &["--scene", bad.to_str().unwrap(), "--workpieces", "E"], why);
    }
    // Negative control: the hopper on with valid keys runs, and writes its batch.
    let on = ws.path("scenes/on.toml");
    let out = ws.path("runs-on");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "batch",
            "--scene",
            on.to_str().unwrap(),
            "--workpieces",
            "E",
            "--picks",
            "2",
            "--deterministic",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(out.exists());
}

/// Keeps, for each hopper dose, the detections of the last recognition result reported before
/// it, and every result's detections.
#[derive(Default)]
struct Doses {
    last_detected: Option<usize>,
    detected: Vec<usize>,
    before_dose: Vec<Option<usize>>,
    /// Each dose's span: how long the arm waited for it (s).
    dose_spans_s: Vec<f64>,
    /// Each pick-tray refill's span (s).
    refill_spans_s: Vec<f64>,
    /// The parts of each dose the event log reported, and when.
    dose_events: Vec<(f64, usize)>,
    /// When each dose's wait began (s).
    dose_starts_s: Vec<f64>,
}

impl Observer for Doses {
    fn event(&mut self, t_s: f64, _pick: Option<usize>, event: &Event) {
        if let Event::Dose(parts) = event {
            self.dose_events.push((t_s, *parts));
        }
        if let Event::RecognitionReady { detected, .. } = event {
            self.last_detected = Some(*detected);
            self.detected.push(*detected);
        }
    }
    fn span(&mut self, stage: Stage, start_s: f64, end_s: f64, label: &str) {
        if stage == Stage::Stall && label == "hopper dose" {
            self.before_dose.push(self.last_detected);
            self.dose_spans_s.push(end_s - start_s);
            self.dose_starts_s.push(start_s);
        }
        if stage == Stage::Stall && label == "pick tray refill" {
            self.refill_spans_s.push(end_s - start_s);
        }
    }
}

/// A hopper: its threshold, dose, shortest dose time (s) and chute flow (parts/s).
fn feeder(dose_below: u32, dose_parts: u32, dose_s: f64, dose_rate_parts_per_s: f64) -> FeederConfig {
    FeederConfig {
        dose_below,
        dose_parts,
        dose_s,
        dose_rate_parts_per_s,
        dose_while_placing: false,
        chute_height_m: 0.0,
    }
}

/// A deterministic run of `picks` picks of `workpiece`, seed 1, with the hopper `feeder` (the
/// workpiece's own recipe, if it brings one, left out), watched by `O`.
fn run<O: Observer + Default>(workpiece: &str, picks: usize, feeder: FeederConfig) -> (Tally, O) {
    let mut wp = LoadedWorkpiece::resolve(workpiece).unwrap();
    wp.workpiece.feeder = None;
    run_wp(&wp, picks, feeder)
}

/// [`run`] of a loaded workpiece.
fn run_wp<O: Observer + Default>(wp: &LoadedWorkpiece, picks: usize, feeder: FeederConfig) -> (Tally, O) {
    let mut scene = LoadedScene::embedded_default().unwrap();
    scene.scene.feeder = feeder;
    let robot = RobotModel::from_scene(&scene).unwrap();
    let opts = RunOptions::deterministic(picks, 1);
    let mut seen = O::default();
    let r = binpick::cycle::run(&scene, &robot, wp, &opts, &mut seen).unwrap();
    (r.tally, seen)
}

#[test]
fn the_hopper_doses_only_below_its_threshold_and_keeps_the_pile_from_running_dry() {
    let hopper = |dose_below| feeder(dose_below, 6, 1.5, 10.0);
    // B's 16-part pile over 60 picks: without a hopper it runs dry and is exchanged.
    let (without, seen_without) = run::<Doses>("B", 60, FeederConfig::default());
    assert!(without.refills >= 2 && without.doses == 0, "{without:?}");
    // Each exchange takes the cell's `refill_s`, the fresh pile poured in it, however long the
    // physics takes to settle it (a 16-block pile settles in well under a second of it).
    let scene = LoadedScene::embedded_default().unwrap().scene;
    assert_eq!(seen_without.refill_spans_s.len(), without.refills);
    assert!(
        seen_without
            .refill_spans_s
            .iter()
            .all(|&s| (s - scene.cycle.refill_s).abs() < scene.sim.physics_dt_s + 1e-6),
        "{:?}",
        seen_without.refill_spans_s
    );
    let threshold = 6;
    let (with, seen) = run::<Doses>("B", 60, hopper(threshold));
    assert!(with.doses >= 2, "doses {}", with.doses);
    assert_eq!(seen.before_dose.len(), with.doses);
    // The event log names each dose, with its parts, where its wait begins.
    assert_eq!(seen.dose_events.len(), with.doses);
    assert!(
        seen.dose_events.iter().all(|&(_, parts)| parts == 6),
        "{:?}",
        seen.dose_events
    );
    assert!(
        seen.dose_events.iter().zip(&seen.dose_starts_s).all(|(e, s)| e.0 == *s),
        "{:?} {:?}",
        seen.dose_events,
        seen.dose_starts_s
    );
    assert!(seen_without.dose_events.is_empty());
    // Every dose followed a result that showed fewer parts than the threshold.
    for d in &seen.before_dose {
        assert!(
            d.is_some_and(|n| n < threshold as usize),
            "a dose after {d:?} detections"
        );
    }
    // Results at or above the threshold happened too, and no dose followed them.
    assert!(
        seen.detected.iter().any(|&n| n >= threshold as usize),
        "{:?}",
        seen.detected
    );
    assert!(
        with.refills < without.refills,
        "refills {} vs {}",
        with.refills,
        without.refills
    );
    // Negative control: with the threshold 1 the hopper doses only on an empty view; E's 60-part
    // pile over 20 picks always shows parts, so no dose, though the feeder's count leaves room.
    let (full, seen_full) = run::<Doses>("E", 20, hopper(1));
    assert!(seen_full.detected.iter().all(|&n| n >= 1), "{:?}", seen_full.detected);
    assert_eq!((full.doses, seen_full.before_dose.len()), (0, 0));
}

#[test]
fn a_dose_takes_its_set_time_and_the_chutes_not_the_piles_settling() {
    // B's 16-part pile topped up 12 parts at a time by a chute of 2 parts/s: 6 s a dose, where
    // its shortest time is 0.5 s.
    let slow = feeder(6, 12, 0.5, 2.0);
    let step_s = LoadedScene::embedded_default().unwrap().scene.sim.physics_dt_s;
    let (tally, seen) = run::<Doses>("B", 40, slow);
    assert!(tally.doses >= 1, "doses {}", tally.doses);
    assert!(
        seen.dose_spans_s
            .iter()
            .all(|&s| (6.0 - 1e-6..6.0 + step_s + 1e-6).contains(&s)),
        "{:?}",
        seen.dose_spans_s
    );
    // A chute fast enough not to bind: the cell waits its 0.5 s and looks; when the pile still
    // moves, its sensor has to tell (the truth of the physics does not end the wait).
    let fast = FeederConfig {
        dose_rate_parts_per_s: 1000.0,
        ..slow
    };
    let (tally, seen) = run::<Doses>("B", 40, fast);
    assert!(tally.doses >= 1, "doses {}", tally.doses);
    assert!(
        seen.dose_spans_s
            .iter()
            .all(|&s| (0.5 - 1e-6..0.5 + step_s + 1e-6).contains(&s)),
        "{:?}",
        seen.dose_spans_s
    );
    // Negative control: the same 12 blocks poured onto B's pile and stepped until the physics
    // says they have settled take longer than 0.5 s: a wait that ended at the settling would
    // not have been 0.5 s.
    let wp = LoadedWorkpiece::resolve("B").unwrap();
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let shape = binpick::physics::PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let mut world = binpick::physics::World::new(&scene.scene, &robot, shape);
    world.build_pile(&PileOptions::new(16, 1)).unwrap();
    let dose = world.build_pile(&PileOptions::new(12, 2)).unwrap();
    assert!(dose.settled && dose.settle_sim_s > 0.5 + 0.1, "{:?}", dose.settle_sim_s);
    // And poured as the running cell pours, the pour itself ends at once (one wave of 12).
    let mut world = binpick::physics::World::new(&scene.scene, &robot, {
        binpick::physics::PartShape::build(&wp.workpiece, &wp.source).unwrap()
    });
    world.build_pile(&PileOptions::new(16, 1)).unwrap();
    let dose = world.build_pile(&PileOptions::into_running_cell(12, 2)).unwrap();
    assert!(
        !dose.settled && dose.settle_sim_s < step_s / 2.0,
        "{:?}",
        dose.settle_sim_s
    );
}

/// B's built-in file with its own hopper recipe replaced by `section`.
fn b_with(section: &str) -> Result<LoadedWorkpiece, binpick::config::ConfigError> {
    let text = std::fs::read_to_string(crate::support::repo().join("workpieces/B.toml")).unwrap();
    assert!(text.contains(B_RECIPE), "B.toml's recipe is not {B_RECIPE:?}");
    LoadedWorkpiece::from_text(
        "B.toml",
        binpick::config::Source::Embedded,
        &text.replace(B_RECIPE, section),
    )
}

/// B's own hopper recipe, as its file writes it.
const B_RECIPE: &str = "[feeder]\ndose_below = 4\ndose_parts = 10\n";

#[test]
fn a_workpiece_brings_its_own_hopper_recipe() {
    let cell = feeder(6, 6, 1.5, 10.0);
    // The cell's hopper doses B's 16-part pile over 60 picks ...
    let (plain, _) = run::<Doses>("B", 60, cell);
    assert!(plain.doses >= 2 && plain.refills == 0, "{plain:?}");
    // ... B's recipe switches it off for B: the pile runs dry and is exchanged.
    let off = b_with("[feeder]\ndose_below = 0\n").unwrap();
    let (tally, seen) = run_wp::<Doses>(&off, 60, cell);
    assert_eq!((tally.doses, seen.before_dose.len()), (0, 0), "{tally:?}");
    assert!(tally.refills >= 1, "{tally:?}");
    // A recipe's dose size reaches the run: doses of 2 parts, so more of them.
    let small = b_with("[feeder]\ndose_parts = 2\n").unwrap();
    let (tally, _) = run_wp::<Doses>(&small, 60, cell);
    assert!(tally.doses > plain.doses, "{} vs {}", tally.doses, plain.doses);
}

#[test]
fn a_bad_hopper_recipe_exits_2_naming_file_key_and_value() {
    let ws = Workspace::new();
    for (to, why) in [
        (
            "[feeder]\ndose_parts = 0\n",
            "feeder.dose_parts must be at least 1 while dose_below > 0, got 0 (with this workpiece's feeder)",
        ),
        (
            "[feeder]\ndose_below = 5000\n",
            "feeder.dose_below must be within [0, 1000], got 5000",
        ),
        ("[feeder]\ndose_s = 1.0\n", "dose_s"),
    ] {
        let bad = ws.edit("workpieces/B.toml", "workpieces/bad.toml", B_RECIPE, to);
        crate::support::batch_is_refused(&ws, &["--workpieces", bad.to_str().unwrap()], why);
    }
}

/// Classifies each release-to-release interval from the run's own event stream, apart from the
/// cycle's bookkeeping: a refill, else a pick that ended in anything but `placed`, else a hopper
/// dose since the previous placed pick (one poured while a part was being placed belongs to the
/// interval after that part's release, whose wait it is); each takt the run reports pairs with
/// the last placed pick's interval.
#[derive(Default)]
struct Intervals {
    refilled: bool,
    failed: bool,
    dosed: bool,
    /// Between a Place's start and its release.
    placing: bool,
    /// A dose poured during the Place under way.
    dosed_while_placing: bool,
    last: Option<&'static str>,
    /// (cause, takt) per interval.
    seen: Vec<(&'static str, f64)>,
}

impl Observer for Intervals {
    fn event(&mut self, _t_s: f64, _pick: Option<usize>, event: &Event) {
        match event {
            Event::Refill(_) => self.refilled = true,
            Event::PlaceStart => self.placing = true,
            Event::Released => self.placing = false,
            Event::Dose(_) if self.placing => self.dosed_while_placing = true,
            Event::Dose(_) => self.dosed = true,
            Event::Outcome(o) if o.name() == "placed" => {
                self.last = Some(if self.refilled {
                    "refill"
                } else if self.failed {
                    "failed"
                } else if self.dosed {
                    "dose"
                } else {
                    "clean"
                });
                (self.refilled, self.failed, self.dosed) = (false, false, self.dosed_while_placing);
                self.dosed_while_placing = false;
            }
            Event::Outcome(_) => {
                self.failed = true;
                self.placing = false;
                self.dosed |= std::mem::take(&mut self.dosed_while_placing);
            }
            _ => {}
        }
    }
    fn takt(&mut self, takt: &binpick::cycle::Takt) {
        self.seen
            .push((self.last.expect("a takt ends a placed pick's interval"), takt.takt_s));
    }
}

/// The tally's takt by cause against [`Intervals`]' count and total per cause.
fn causes_match(tally: &Tally, seen: &Intervals) {
    use binpick::cycle::IntervalCause;
    let c = &tally.takt_causes;
    for cause in IntervalCause::ALL {
        let mine: Vec<f64> = seen.seen.iter().filter(|s| s.0 == cause.name()).map(|s| s.1).collect();
        assert_eq!(c.count(cause), mine.len(), "{}", cause.name());
        assert!(
            (c.total_s(cause) - mine.iter().sum::<f64>()).abs() < 1e-9,
            "{}",
            cause.name()
        );
    }
    let mean = tally.takts_s.iter().sum::<f64>() / tally.takts_s.len() as f64;
    let shares: f64 = IntervalCause::ALL.iter().map(|&k| c.share_s(k)).sum();
    assert!((shares - mean).abs() < 1e-9, "{shares} against {mean}");
}

#[test]
fn the_takt_by_cause_counts_each_interval_as_the_event_log_tells_it() {
    use binpick::cycle::IntervalCause;
    // B's 16-part pile over 60 picks, topped up by a hopper: doses, and clean cycles between.
    let (with, seen) = run::<Intervals>("B", 60, feeder(6, 6, 1.5, 10.0));
    causes_match(&with, &seen);
    let c = &with.takt_causes;
    assert!(
        c.count(IntervalCause::Dose) >= 1 && c.count(IntervalCause::Clean) >= 1,
        "{c:?}"
    );
    // Doses poured while a part is placed count for the interval after its release.
    let overlapped = FeederConfig {
        dose_while_placing: true,
        ..feeder(6, 6, 1.5, 10.0)
    };
    let (with, seen) = run::<Intervals>("B", 60, overlapped);
    causes_match(&with, &seen);
    assert!(
        with.takt_causes.count(IntervalCause::Dose) >= 1,
        "{:?}",
        with.takt_causes
    );
    // Negative control: without the hopper the pile runs dry and is exchanged: refills, no dose.
    let (without, seen) = run::<Intervals>("B", 60, FeederConfig::default());
    causes_match(&without, &seen);
    let c = &without.takt_causes;
    assert!(
        c.count(IntervalCause::Refill) >= 1 && c.count(IntervalCause::Dose) == 0,
        "{c:?}"
    );
}

/// The times of the events a dose while placing is judged by (s).
#[derive(Default)]
struct PlaceDoses {
    place_starts_s: Vec<f64>,
    releases_s: Vec<f64>,
    doses_s: Vec<f64>,
    captures_s: Vec<f64>,
    /// Doses the arm waited for (a "hopper dose" stall).
    waited_doses: usize,
    /// Doses drawn on the feeder's lane, poured while the arm goes on (start, end) (s).
    fed_doses_s: Vec<(f64, f64)>,
}

impl Observer for PlaceDoses {
    fn event(&mut self, t_s: f64, _pick: Option<usize>, event: &Event) {
        match event {
            Event::PlaceStart => self.place_starts_s.push(t_s),
            Event::Released => self.releases_s.push(t_s),
            Event::Dose(_) => self.doses_s.push(t_s),
            Event::Capture(_) => self.captures_s.push(t_s),
            _ => {}
        }
    }
    fn span(&mut self, stage: Stage, start_s: f64, end_s: f64, label: &str) {
        match (stage, label) {
            (Stage::Stall, "hopper dose") => self.waited_doses += 1,
            (Stage::Feeder, "hopper dose") => self.fed_doses_s.push((start_s, end_s)),
            _ => {}
        }
    }
}

impl PlaceDoses {
    /// The doses that started during a Place: after its start, before its release.
    fn during_places(&self) -> Vec<f64> {
        self.doses_s
            .iter()
            .copied()
            .filter(|&d| {
                self.place_starts_s
                    .iter()
                    .zip(&self.releases_s)
                    .any(|(&p, &r)| p < d && d < r)
            })
            .collect()
    }
}

#[test]
fn a_dose_while_placing_pours_once_the_part_has_left_the_view_and_holds_the_next_capture() {
    let dose_s = 1.5;
    let hopper = |dose_while_placing| FeederConfig {
        dose_while_placing,
        ..feeder(6, 6, dose_s, 10.0)
    };
    let (tally, seen) = run::<PlaceDoses>("B", 60, hopper(true));
    let during = seen.during_places();
    assert!(!during.is_empty(), "doses {:?}", seen.doses_s);
    // The arm waited only for the doses that could not wait for a Place (nothing to pick).
    assert_eq!(seen.waited_doses + during.len(), tally.doses, "{:?}", seen.doses_s);
    // No capture while a dose is pouring: the first after it comes once its time is up.
    for &d in &during {
        assert!(
            seen.captures_s.iter().all(|&c| c <= d || c >= d + dose_s - 1e-6),
            "a capture within {dose_s} s of the dose at {d:.3} s: {:?}",
            seen.captures_s
        );
    }
    // The time chart shows each on the feeder's lane, from its start for its time.
    let drawn: Vec<f64> = seen.fed_doses_s.iter().map(|&(s, _)| s).collect();
    assert_eq!(drawn, during, "feeder spans {:?}", seen.fed_doses_s);
    assert!(seen.fed_doses_s.iter().all(|&(s, e)| (e - s - dose_s).abs() < 1e-9));
    // Negative control: dosed at once, no dose falls inside a Place, and the arm waits out each.
    let (tally_off, off) = run::<PlaceDoses>("B", 60, hopper(false));
    assert!(tally_off.doses >= 2, "{tally_off:?}");
    assert!(off.during_places().is_empty(), "{:?}", off.doses_s);
    assert_eq!(off.waited_doses, tally_off.doses);
    assert!(off.fed_doses_s.is_empty(), "{:?}", off.fed_doses_s);
}
