//! Sustained operation: a run spanning several pile cycles; its sustained takt and parts per
//! hour re-computed from the pick records' release times (not from the tally), its first-20
//! figure the takt of a 21-pick run of the same seed, and `batch --sustained` on the command
//! line.

use crate::support::{binpick, stderr};
use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::cycle::{FIRST_PICKS, RunOptions, RunResult};
use binpick::results::Summary;
use binpick::robot::RobotModel;

/// A deterministic run of workpiece B (a 16-part pile: a few refills in 60 picks, with the
/// default cell's hopper off, and B's own recipe for it left out), seed 1.
fn run_b(picks: usize) -> RunResult {
    let mut scene = LoadedScene::embedded_default().unwrap();
    scene.scene.feeder.dose_below = 0;
    let robot = RobotModel::from_scene(&scene).unwrap();
    let mut wp = LoadedWorkpiece::resolve("B").unwrap();
    wp.workpiece.feeder = None;
    let opts = RunOptions {
        picks,
        seed: 1,
        deterministic: true,
        stop: None,
        keep_records: true,
    };
    binpick::cycle::run(&scene, &robot, &wp, &opts, &mut ()).unwrap()
}

/// From release times in order: the mean interval (s) and releases per hour, by the span.
fn by_span(releases_s: &[f64]) -> (f64, f64) {
    let n = releases_s.len() - 1;
    let span_s = releases_s[n] - releases_s[0];
    (span_s / n as f64, 3600.0 * n as f64 / span_s)
}

#[test]
fn sustained_figures_match_the_release_times_and_the_first_20_match_a_21_pick_run() {
    let long = run_b(60);
    let s = Summary::of(&long.tally);
    // The run spans several pile cycles: refills happened, and more than two piles were placed.
    assert!(long.tally.refills >= 2, "refills {}", long.tally.refills);
    assert_eq!(long.tally.pile_count, 16);
    assert!(s.pile_loads > 2.0, "pile loads {}", s.pile_loads);
    assert_eq!(s.pile_loads, long.tally.placed as f64 / 16.0);
    // Independent: the releases of the placed picks, in order, from the records.
    let releases: Vec<f64> = long.records.iter().filter_map(|r| r.release_s).collect();
    assert_eq!(releases.len(), long.tally.placed);
    let (takt_s, per_hour) = by_span(&releases);
    assert!((s.takt.mean_s - takt_s).abs() < 1e-9, "{} vs {takt_s}", s.takt.mean_s);
    assert!(
        (s.parts_per_hour - per_hour).abs() < 1e-6,
        "{} vs {per_hour}",
        s.parts_per_hour
    );
    // The first-20 figure: exactly the takts of a 21-pick run of the same seed.
    let short = run_b(FIRST_PICKS);
    assert_eq!(long.tally.takts_first_s, short.tally.takts_s);
    assert_eq!(Summary::of(&short.tally).takt.mean_s, s.takt_first.mean_s);
    assert!(s.takt_first.count >= 10 && s.takt.count > s.takt_first.count);
    // Negative controls: the span check tells a figure that leaves the refills' intervals out
    // from the sustained one, and the first-20 figure stops at 21 picks (a 26-pick run has more
    // intervals, the first-20 ones first).
    let excl = Summary::of(&long.tally).takt_excl_refills.mean_s;
    assert!((excl - takt_s).abs() > 1e-3, "excl. refills {excl} vs {takt_s}");
    let longer = run_b(FIRST_PICKS + 5);
    assert_ne!(long.tally.takts_first_s, longer.tally.takts_s);
    assert!(longer.tally.takts_s.starts_with(&long.tally.takts_first_s));
}

#[test]
fn batch_sustained_refuses_a_pick_count_beside_it() {
    let o = binpick(&["batch", "--sustained", "--picks", "5", "--workpieces", "B"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("--sustained") && err.contains("--picks"), "{err}");
    // The option exists (so the refusal above is the conflict, not an unknown option).
    let help = binpick(&["batch", "--help"]);
    assert!(String::from_utf8_lossy(&help.stdout).contains("--sustained"));
}

/// A part the cup cannot take (the radial capacitor): the cell exchanges a full tray that gave
/// it nothing to attempt, and ends the run only after `FRUITLESS_FILLS_MAX` such trays in a row,
/// not on the first (an all-day line must not stop on one unlucky pile). The picks asked for are
/// far more than it gets to, so it is the policy that ends the run.
#[test]
fn a_run_ends_after_three_fruitless_full_trays_in_a_row_not_one() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp =
        LoadedWorkpiece::resolve(concat!(env!("CARGO_MANIFEST_DIR"), "/workpieces/capacitor-radial.toml")).unwrap();
    let opts = RunOptions::deterministic(200, 1);
    let t = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut ()).unwrap().tally;
    assert_eq!(
        t.ended,
        Some(binpick::cycle::EndReason::NothingGraspableInFullTray),
        "{t:?}"
    );
    assert_eq!(t.placed, 0);
    assert!(t.attempts < 200);
    assert_eq!(t.refills as u32, binpick::cycle::trays::FRUITLESS_FILLS_MAX - 1);
}

/// A capture from which nothing is taken is charged its grasp selection before the cell decides
/// so, as a capture a pick is made from is (the capacitor: every capture `nothing_graspable`).
/// Checked on the event log's clock, not on the record: each such outcome is announced no
/// earlier than its result's arrival plus the cell file's grasp estimation budget.
#[test]
fn a_capture_with_nothing_graspable_is_charged_its_grasp_selection() {
    use binpick::cycle::{Event, Observer, Outcome};
    /// When each pick's outcome was announced, and what it was.
    #[derive(Default)]
    struct Outcomes(Vec<(usize, f64, Outcome)>);
    impl Observer for Outcomes {
        fn event(&mut self, t_s: f64, pick: Option<usize>, event: &Event) {
            if let (Some(pick), Event::Outcome(o)) = (pick, event) {
                self.0.push((pick, t_s, o.clone()));
            }
        }
    }
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp =
        LoadedWorkpiece::resolve(concat!(env!("CARGO_MANIFEST_DIR"), "/workpieces/capacitor-radial.toml")).unwrap();
    let opts = RunOptions {
        picks: 6,
        seed: 1,
        deterministic: true,
        stop: None,
        keep_records: true,
    };
    let mut seen = Outcomes::default();
    let run = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut seen).unwrap();
    let budget_s = scene.scene.compute.grasp_estimation_s;
    assert!(budget_s > 0.01, "{budget_s}");
    let graspless: Vec<_> = seen
        .0
        .iter()
        .filter(|(_, _, o)| matches!(o, Outcome::NothingGraspable(_)))
        .collect();
    assert!(graspless.len() >= 3, "{:?}", seen.0);
    for (pick, t_s, _) in graspless {
        let rec = &run.records[*pick];
        assert!(
            t_s + 1e-9 >= rec.ready_s + budget_s,
            "pick {pick}: at {t_s} s, result at {} s",
            rec.ready_s
        );
        assert_eq!(rec.compute.grasp_s, budget_s, "pick {pick}");
    }
}
