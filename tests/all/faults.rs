//! Long runs lose nothing: a physics fault ends its run with a typed record and the run's tally
//! so far, not the caller; a batch with a faulted run writes every run and its table, marks
//! the run and exits 3.
//!
//! The fault is made on purpose: a monitor limit of 1 micrometre (`sim.deep_penetration_limit_m`),
//! which any pour's landing parts press past. (The real fault these tests were first written on,
//! D's pile of seed 13, was cured: its cans sank into each other cap on cap.)

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::cycle::{self, Cell, EndReason, FaultDuring, IncidentKind, RunOptions};
use binpick::physics::{HealthEvent, HealthLimits, PartState};
use binpick::robot::RobotModel;

fn opts(picks: usize, seed: u64) -> RunOptions {
    RunOptions::deterministic(picks, seed)
}

/// A run of D whose pick tray is emptied before its first capture, so the cell shakes the empty
/// tray, then refills it; with `limit_m` as the monitor's deep-penetration limit from then on.
fn run_into_refill(limit_m: Option<f64>) -> binpick::cycle::RunResult {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("D").unwrap();
    let scene = scene.for_workpiece(&wp);
    let cell = Cell::new(&scene, &robot, &wp, opts(6, 5)).unwrap();
    let mut st = cell.start(&mut ()).unwrap();
    for i in st.world.parts_in_state(PartState::Free) {
        st.world.remove_part(i);
    }
    if let Some(l) = limit_m {
        st.world.set_health_limits(HealthLimits {
            deep_penetration_m: l,
            ..st.world.health_limits()
        });
    }
    cycle::run_from(&cell, st, &mut ()).unwrap()
}

#[test]
fn a_fault_in_a_refill_pour_ends_the_run_with_its_typed_record_and_keeps_the_tally() {
    // 1 micrometre: the parts of a pour landing on the floor and on each other press deeper.
    let r = run_into_refill(Some(1e-6));
    let t = &r.tally;
    assert_eq!(t.ended, Some(EndReason::PhysicsFault));
    assert_eq!(t.physics_faults.len(), 1);
    let f = &t.physics_faults[0];
    assert_eq!(f.during, FaultDuring::Pour);
    assert!(f.step > 0 && f.time_s > 0.0);
    // The record names the bodies and the depth; it is deeper than the limit.
    let deep: Vec<_> = f
        .problems
        .iter()
        .filter_map(|p| match p {
            HealthEvent::DeepPenetration { a, b, depth_mm, .. } => Some((a, b, *depth_mm)),
            _ => None,
        })
        .collect();
    assert!(!deep.is_empty(), "{:?}", f.problems);
    assert!(deep.iter().all(|(a, b, d)| !a.is_empty() && !b.is_empty() && *d > 1e-3));
    // The tally up to the fault is kept: the empty tray was captured and shaken before.
    assert!(t.captures.0 > 0 && t.agitations == 3, "{t:?}");
    assert_eq!(t.runs, 1);
    assert!(t.sim_time_s >= f.time_s);
    // The fault is also the run's last incident, with the log's line for it.
    let last = t.incidents.last().expect("an incident");
    assert_eq!(
        (last.kind, last.t_s),
        (IncidentKind::PhysicsFault, f.time_s),
        "{last:?}"
    );
    assert!(last.detail.contains("deep penetration"), "{last:?}");
    // The record survives a shard file and reads back as it was.
    let back: binpick::cycle::Tally = serde_json::from_value(serde_json::to_value(t).unwrap()).unwrap();
    assert_eq!((&back.physics_faults, back.ended), (&t.physics_faults, t.ended));
    // A merge of a faulted run with a run that ended well keeps the fault and its count.
    let mut merged = binpick::cycle::Tally {
        ended: Some(EndReason::PicksDone),
        runs: 1,
        ..Default::default()
    };
    merged.merge(t);
    assert_eq!((merged.runs, merged.physics_faults.len()), (2, 1));
    assert_eq!(merged.ended, Some(EndReason::PhysicsFault));
}

#[test]
fn negative_control_the_same_refill_at_the_monitors_limit_ends_without_a_fault() {
    let r = run_into_refill(None);
    let t = &r.tally;
    assert!(t.physics_faults.is_empty(), "{:?}", t.physics_faults);
    assert_ne!(t.ended, Some(EndReason::PhysicsFault));
    assert_eq!(t.refills, 1);
}

/// `binpick sweep` of D, seed 12, deterministic, 2 picks, over the monitor limits `limits`: its
/// exit code, stderr and the written sweep.md and sweep.json.
fn sweep_d(limits: &str) -> (Option<i32>, String, String, serde_json::Value) {
    let tmp = crate::support::tempdir().unwrap();
    let out = tmp.path().to_str().unwrap();
    let set = format!("sim.deep_penetration_limit_m={limits}");
    let o = crate::support::binpick(&[
        "sweep",
        "--workpieces",
        "D",
        "--seeds",
        "12",
        "--picks",
        "2",
        "--deterministic",
        "--set",
        &set,
        "--out",
        out,
    ]);
    let dir = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.join("sweep.md").is_file())
        .unwrap_or_else(|| panic!("no results folder: {}", crate::support::stderr(&o)));
    let md = std::fs::read_to_string(dir.join("sweep.md")).unwrap();
    let json = serde_json::from_str(&std::fs::read_to_string(dir.join("sweep.json")).unwrap()).unwrap();
    (o.status.code(), crate::support::stderr(&o), md, json)
}

#[test]
fn a_study_with_a_faulted_run_writes_every_run_marks_it_and_exits_3() {
    let (code, err, md, json) = sweep_d("0.000001,0.002");
    assert_eq!(code, Some(3), "{err}");
    assert!(err.contains("deep penetration"), "{err}");
    // The faulted variant is marked under the table, with why; the other is whole.
    assert!(
        md.contains("| 2 | 0.002 | D | 2/2 |")
            && md.contains("variant 1, D: nothing placed")
            && md.contains("physics fault"),
        "{md}"
    );
    let runs = json["sweep"]["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    assert_eq!(runs[1]["run"]["ended"], "picks done");
    assert!(runs[1]["run"].get("physics_faults").is_none());
    assert_eq!(runs[0]["run"]["ended"], "physics fault");
    let f = &runs[0]["run"]["physics_faults"][0];
    assert_eq!(
        (f["during"].as_str(), f["problems"][0]["kind"].as_str()),
        (Some("pour"), Some("deep_penetration"))
    );
    assert!(f["problems"][0]["depth_mm"].as_f64().unwrap() > 0.001);
    // Listed as an incident in the JSON and under the table.
    assert_eq!(runs[0]["run"]["incidents"][0]["kind"], "physics_fault");
    assert!(md.contains("variant 1, D: 1 incident\n- seed 1"), "{md}");
}

#[test]
fn negative_control_a_study_without_a_fault_exits_0_unmarked() {
    let (code, err, md, json) = sweep_d("0.002");
    assert_eq!(code, Some(0), "{err}");
    assert!(md.contains("| 1 | 0.002 | D | 2/2 |"), "{md}");
    assert!(!md.contains("physics fault") && !md.contains("nothing placed"), "{md}");
    assert!(json["sweep"]["runs"][0]["run"].get("physics_faults").is_none());
    assert!(json["sweep"]["runs"][0]["run"].get("incidents").is_none());
    assert!(!md.contains("incident"), "{md}");
}

#[test]
fn a_part_the_first_pour_spills_is_lost_and_the_run_goes_on() {
    // C's first pile of seed 56 throws a strip over the tray's wall while it is poured (found in
    // a 200-seed batch, where the run ended there). The part is lost, as one a refill or a dose
    // spills, and the run makes its picks.
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("C").unwrap();
    let r = cycle::run(&scene, &robot, &wp, &opts(2, 56), &mut ()).unwrap();
    let t = &r.tally;
    assert!(t.physics_faults.is_empty(), "{:?}", t.physics_faults);
    assert_eq!(t.ended, Some(EndReason::PicksDone));
    assert_eq!(
        t.faults.parts_lost, 1,
        "the pile of seed 56 no longer spills: pick another seed whose pour does"
    );
    let lost: Vec<_> = t
        .incidents
        .iter()
        .filter(|i| i.kind == IncidentKind::PartLost)
        .collect();
    assert_eq!(lost.len(), 1, "{:?}", t.incidents);
    assert_eq!(lost[0].pick, None, "lost before the first pick");
    assert!(lost[0].detail.contains("pour"), "{}", lost[0].detail);
    // Negative control: the same pour, the spilled part not taken out, ends on the spill.
    let shape = binpick::physics::PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let mut w = binpick::physics::World::new(&scene.scene, &robot, shape);
    let err = w
        .build_pile(&binpick::physics::pile::PileOptions::new(
            wp.workpiece.pile_count as usize,
            56,
        ))
        .expect_err("the pour ends on the spill");
    assert!(
        err.events.iter().any(|e| matches!(e, HealthEvent::LeftVolume { .. })),
        "{err:?}"
    );
}

#[test]
fn a_part_torn_off_the_cup_in_a_blended_lift_leaves_the_arm_on_its_planned_place() {
    // With `gripper.seal_loaded_by_parts` (the default), a C strip another strip presses on tears off the
    // 6 mm cup early in the lift (seed 4, pick 3, 0.034 s into it). The lift is played blended
    // into the Place transfer and ends at the transfer's speed; the arm goes on along the planned
    // Place with its cup empty, and the pick is a drop. Seen failing against the handling before,
    // where the pick ended at the lift's end, mid-swing: no drop went on along the Place, and on
    // seed 2 (with an earlier form of the load) the next motion's commanded velocity stepped by
    // 2.9 rad/s and a protective stop ended the run.
    let mut scene = LoadedScene::embedded_default().unwrap();
    scene.scene.gripper.seal_loaded_by_parts = true;
    // The cases were found on the cell whose tool came straight down onto every face; a tool
    // that leans takes other parts in these runs.
    scene.scene.gripper.max_lean_deg = None;
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("C").unwrap();
    let r = cycle::run(
        &scene,
        &robot,
        &wp,
        &RunOptions {
            keep_records: true,
            ..opts(5, 4)
        },
        &mut (),
    )
    .unwrap();
    let t = &r.tally;
    // The drop went on along the Place (its Place time counted) and released nothing.
    let in_lift = r
        .records
        .iter()
        .filter(|p| {
            matches!(p.outcome, binpick::cycle::Outcome::Dropped(_)) && p.overlaps.lift_s > 0.0 && p.place_s > 0.0
        })
        .inspect(|p| assert_eq!(p.release_s, None))
        .count();
    assert!(in_lift >= 1, "the case needs a drop in a blended lift: {:?}", t.faults);
    assert_eq!(t.faults.protective_stops, 0, "{:?}", t.incidents);
    assert_eq!(t.ended, Some(EndReason::PicksDone));
    // A drop releases nothing: every takt interval ends at a placed part's release.
    assert_eq!(t.takts_s.len() + 1, t.placed.max(1), "{t:?}");
    // Negative control: the key off, no load on the seal, no drop on these picks.
    let mut unloaded = scene.clone();
    unloaded.scene.gripper.seal_loaded_by_parts = false;
    let r = cycle::run(&unloaded, &robot, &wp, &opts(5, 4), &mut ()).unwrap();
    assert_eq!(r.tally.faults.drops, 0, "{:?}", r.tally.faults);
    // The slot a drop leaves empty takes the next part: A seed 28 drops picks 11 and 17 (seed 23
    // dropped picks 15 and 16 until the seal's load counted shear and peel; seed 6 picks 2 and
    // 4 in blended lifts until the cup aimed at the cells' mean surface). Seen failing when the
    // next pick was prepared for the slot after the dropped one's: pick 5 went one slot on,
    // pick 6 into pick 5's part (a collision, 0.99 mm). Found with every lift at the cell's
    // acceleration: the gentle lift of a hemmed part (`cycle.gentle_lift_hemmed`) keeps both.
    let wp = LoadedWorkpiece::resolve("A").unwrap();
    let mut brisk = scene.clone();
    brisk.scene.cycle.gentle_lift_hemmed = None;
    let r = cycle::run(&brisk, &robot, &wp, &opts(18, 28), &mut ()).unwrap();
    assert!(r.tally.faults.drops >= 2, "{:?}", r.tally.faults);
    assert_eq!(r.tally.faults.collisions, 0, "{:?}", r.tally.incidents);
}

/// The gentle lift of a hemmed part (`cycle.gentle_lift_hemmed`) keeps A's relays that a lift at
/// the cell's acceleration loses to a neighbour's push: seed 28, 18 picks, the case above, drops
/// both with every lift brisk (the control) and neither gently, and its `planned` events say
/// which lifts were gentle.
#[test]
fn a_hemmed_relay_lifted_gently_stays_on_the_cup() {
    /// The lifts the `planned` events name gentle, by pick (m/s^2).
    #[derive(Default)]
    struct GentleLifts(Vec<(usize, f64)>);
    impl binpick::cycle::Observer for GentleLifts {
        fn event(&mut self, _t_s: f64, pick: Option<usize>, event: &binpick::cycle::Event) {
            if let (
                Some(p),
                binpick::cycle::Event::Planned(binpick::cycle::Planned::Place {
                    gentle_lift_m_s2: Some(a),
                    ..
                }),
            ) = (pick, event)
            {
                self.0.push((p, *a));
            }
        }
    }
    let mut scene = LoadedScene::embedded_default().unwrap();
    scene.scene.gripper.max_lean_deg = None;
    let line_accel_m_s2 = scene.scene.cycle.line_accel_m_s2;
    assert!(
        scene.scene.cycle.gentle_lift_hemmed.is_some(),
        "the default cell lifts gently"
    );
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("A").unwrap();
    let run = |scene: &LoadedScene| {
        let mut lifts = GentleLifts::default();
        let r = cycle::run(scene, &robot, &wp, &opts(18, 28), &mut lifts).unwrap();
        (r, lifts.0)
    };
    let (gentle, lifts) = run(&scene);
    assert_eq!(gentle.tally.faults.drops, 0, "{:?}", gentle.tally.faults);
    assert!(lifts.len() >= 2, "{lifts:?}");
    assert!(
        lifts
            .iter()
            .all(|&(_, a)| a >= 0.1 * line_accel_m_s2 - 1e-9 && a < line_accel_m_s2),
        "{lifts:?}"
    );
    let mut brisk = scene.clone();
    brisk.scene.cycle.gentle_lift_hemmed = None;
    let (brisk, lifts) = run(&brisk);
    assert!(brisk.tally.faults.drops >= 2, "{:?}", brisk.tally.faults);
    assert!(lifts.is_empty(), "{lifts:?}");
}

/// A crawling carry ends where it was planned to: A with a 4.5 mm cup and weighing 20 g, seed 11,
/// is held with its centre of mass well below and off the lip, which the cup barely holds, so
/// its Place transfers crawl (time scale below 0.15: picks 3 and 9, 4-5 s each; the grasp
/// selector, which ranks a carry by what its seal allows, leaves the 12 g relay on this cup no
/// such carry). The servo's hold target at such a transfer's end jumped 0.32 rad (the end fell
/// off the last blend by rounding) and pick 12 tripped a protective stop, J1 18 deg behind;
/// seen failing so before the fix, when those carries were at the time scale's floor (0.05,
/// about 9 s).
#[test]
fn a_crawling_carry_ends_without_a_protective_stop() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let mut wp = LoadedWorkpiece::resolve("A").unwrap();
    wp.workpiece.gripper.as_mut().unwrap().cup_diameter_m = Some(0.0045);
    wp.workpiece.mass_kg = 0.020;
    let options = RunOptions {
        keep_records: true,
        ..opts(13, 11)
    };
    let r = cycle::run(&scene, &robot, &wp, &options, &mut ()).unwrap();
    let crawling = r.records.iter().filter(|p| p.suction_speed_factor < 0.15).count();
    assert!(crawling >= 2, "the case needs crawling carries");
    assert_eq!(r.tally.faults.protective_stops, 0, "{:?}", r.tally.incidents);
    assert_eq!(r.tally.ended, Some(EndReason::PicksDone));
}

/// What hangs out beyond the pick tray's wall is an obstacle: on C's seed 4 (38 picks) the refill
/// before pick 37 leaves a strip lying across the rim at 34 deg, its end 25 mm beyond the wall's
/// outer face and 26 mm above the rim. The capture pick 37 is chosen on sees that end (the map
/// reaches beyond the walls, the arm masked out), and the Place carries its strip clear of it.
/// Seen failing while the map stopped at the outer walls: the carried strip, 10 mm over the rim,
/// struck the end 0.2 s into the transfer (deep penetration 2.96 mm, a collision).
#[test]
fn a_strip_hanging_out_beyond_the_wall_is_an_obstacle_to_the_carry() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("C").unwrap();
    let r = cycle::run(&scene, &robot, &wp, &opts(38, 4), &mut ()).unwrap();
    assert_eq!(r.tally.faults.collisions, 0, "{:?}", r.tally.incidents);
    assert_eq!(r.tally.ended, Some(EndReason::PicksDone));
}
