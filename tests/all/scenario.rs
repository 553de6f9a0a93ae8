//! Scenario tests: the whole cell, end to end, for each of the six workpiece types; the same seed
//! repeats byte for byte; a batch split into shards and merged gives the whole batch's table.
//!
//! Torques are re-checked independently of the servo: from the executed positions and velocities
//! (accelerations by differences), with Euler-Lagrange dynamics built from the mass matrix and
//! the potential energy by finite differences, not the recursive Newton-Euler code the servo
//! uses.

use crate::support::demand_check;
use crate::support::{Workspace, binpick_in, stderr};
use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::cycle::{RunOptions, RunResult};
use binpick::recording::{Recorder, Recording};
use binpick::robot::{DOF, DynamicsModel, JointVector, Payload, RobotModel};
use binpick::sensor::Camera;
use binpick::servo::Tick;

/// Torque the motion between two consecutive servo ticks needs: M(q) qdd + C(q, qd) qd + g(q)
/// plus friction, with C qd = dM/dt qd - 1/2 d(qd' M qd)/dq and g = dV/dq, by central
/// differences; friction at `qd_end`, the velocity the step ends at (the plant takes it
/// implicitly).
fn euler_lagrange(
    d: &DynamicsModel,
    q: &JointVector,
    qd: &JointVector,
    qdd: &JointVector,
    qd_end: &JointVector,
) -> JointVector {
    const H: f64 = 1e-6;
    let m = d.mass_matrix(q);
    let mut coriolis = JointVector::zeros();
    let mut gravity = JointVector::zeros();
    let mut m_dot = m * 0.0;
    for k in 0..DOF {
        let mut qp = *q;
        let mut qm = *q;
        qp[k] += H;
        qm[k] -= H;
        let dm = (d.mass_matrix(&qp) - d.mass_matrix(&qm)) / (2.0 * H);
        m_dot += dm * qd[k];
        coriolis[k] = -0.5 * qd.dot(&(dm * qd));
        gravity[k] = (d.potential_energy(&qp) - d.potential_energy(&qm)) / (2.0 * H);
    }
    coriolis += m_dot * qd;
    let friction = JointVector::from_fn(|i, _| d.friction_nm(i, qd_end[i]));
    m * qdd + coriolis + gravity + friction
}

/// Re-checks the executed motion against the plant, independently of the servo's own dynamics
/// code: for every pair of consecutive ticks of one motion (one integration step apart), the
/// torque the plant needs for the motion (Euler-Lagrange on `plant`, with the hand alone or with
/// the part at the tool tip) must be the torque the servo applied (within 2 % of each limit).
/// Returns how many tick pairs matched, and how many were checked.
fn recheck_plant(plant: &RobotModel, hand: &Payload, part_kg: f64, trace: &[Tick], dt: f64) -> (usize, usize) {
    let limit = plant.torque_limit_nm();
    let tool = plant.flange_from_tool.translation.vector;
    let models = [
        plant.dynamics(hand),
        plant.dynamics(&hand.combined(&Payload::point(part_kg, tool))),
    ];
    let (mut matched, mut checked) = (0, 0);
    for w in trace.windows(2).step_by(3) {
        let (a, b) = (&w[0], &w[1]);
        // One integration step: q_b = q_a + qd_b dt (semi-implicit Euler), one dt apart.
        if ((b.t_s - a.t_s) - dt).abs() > 1e-9 || (b.q - (a.q + b.qd * dt)).amax() > 1e-9 {
            continue;
        }
        let qdd = (b.qd - a.qd) / dt;
        let needs: Vec<JointVector> = models
            .iter()
            .map(|m| euler_lagrange(m, &a.q, &a.qd, &qdd, &b.qd))
            .collect();
        if needs
            .iter()
            .any(|n| (0..DOF).all(|i| (n[i] - a.tau_nm[i]).abs() <= 0.02 * limit[i]))
        {
            matched += 1;
        }
        checked += 1;
    }
    (matched, checked)
}

/// Deterministic options: `picks` picks of seed `seed`, every record kept.
fn deterministic(picks: usize, seed: u64) -> RunOptions {
    RunOptions {
        picks,
        seed,
        deterministic: true,
        stop: None,
        keep_records: true,
    }
}

/// A deterministic run of seed 1, recorded: its result and what the recorder kept.
fn run(workpiece: &str, picks: usize) -> (RunResult, Recording, RobotModel, LoadedScene, LoadedWorkpiece) {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve(workpiece).unwrap();
    let camera = Camera::from_config(&scene.scene.sensor).unwrap();
    let mut recorder = Recorder::new(
        &robot,
        &camera,
        &binpick::geometry::TrayVolume::new(&scene.scene.pick_tray),
        wp.workpiece.size_m,
    );
    let opts = deterministic(picks, 1);
    let r = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut recorder).unwrap();
    let rec = recorder.finish();
    (r, rec, robot, scene, wp)
}

/// Six deterministic picks with the cell file's model error on: at least four placed, no
/// collision, no protective stop; the torques demanded never beyond a limit and the tracking
/// error within the tolerance (checked on every servo tick, the demand before saturation); the
/// plant, re-checked independently, is what moved the arm, and it is not the controller's model;
/// the median takt below the reference system's (leaving out intervals in which the cell looked
/// again at a pile in motion).
fn scenario(workpiece: &str) {
    let (r, rec, robot, scene, wp) = run(workpiece, 6);
    let s = &r.tally;
    let outcomes: Vec<String> = r
        .records
        .iter()
        .map(|p| format!("{} {}", p.outcome.name(), p.outcome.detail()))
        .collect();
    assert!(
        s.placed >= 4,
        "{workpiece}: {} of {} placed: {outcomes:?}",
        s.placed,
        s.attempts
    );
    assert_eq!(s.faults.collisions, 0, "{workpiece}: {outcomes:?}");
    assert_eq!(s.faults.protective_stops, 0, "{workpiece}: {outcomes:?}");
    // No incident either: no part lost, no motion that started off the arm's state or with a
    // step in its commanded velocity.
    assert!(s.incidents.is_empty(), "{workpiece}: {:?}", s.incidents);
    let servo = binpick::servo::Servo::from_config(&scene.scene.sim);
    let check = demand_check(&robot, &servo, &rec.trace);
    assert!(check.is_ok(), "{workpiece}: {check:?}");
    assert!(
        s.peak_demand_ratio.iter().all(|r| *r <= 1.0),
        "{workpiece}: demanded torque beyond a limit: {:?}",
        s.peak_demand_ratio
    );
    assert!(s.saturated_s == 0.0, "{workpiece}: saturated {} s", s.saturated_s);
    // The plant moved the arm: the torques applied are what the plant (with its model error)
    // needs; the controller's nominal model would need others.
    let hand = Payload::from_gripper(&scene.scene.gripper);
    let dt = scene.scene.sim.control_dt_s;
    let plant = robot.with_model_error(&scene.scene.model_error, 1);
    let (matched, checked) = recheck_plant(&plant, &hand, wp.workpiece.mass_kg, &rec.trace, dt);
    assert!(checked > 1000, "{workpiece}: only {checked} tick pairs checked");
    assert!(
        matched as f64 >= 0.99 * checked as f64,
        "{workpiece}: the plant explains only {matched} of {checked} tick pairs"
    );
    let (nominal, _) = recheck_plant(&robot, &hand, wp.workpiece.mass_kg, &rec.trace, dt);
    assert!(
        (nominal as f64) < 0.5 * checked as f64,
        "{workpiece}: the nominal model explains {nominal} of {checked} tick pairs: the plant is the model"
    );
    let reference = binpick::reference::reference_takt(workpiece).unwrap();
    // The reference's definition: every release-to-release interval after the first release.
    let releases: Vec<f64> = r.records.iter().filter_map(|p| p.release_s).collect();
    let takts: Vec<f64> = releases.windows(2).map(|w| w[1] - w[0]).collect();
    assert_eq!(
        takts,
        r.records.iter().filter_map(|p| p.takt_s).collect::<Vec<_>>(),
        "{workpiece}: the records' takts are not the release-to-release intervals"
    );
    assert!(takts.len() >= 3, "{workpiece}: {takts:?}");
    assert_eq!(s.attempts, r.records.len(), "{workpiece}: every pick is an attempt");
    // The median: one failed grasp in six picks (a takt of two cycles) must not decide it. Nor
    // do the intervals in which the cell looked again at a pile in motion (a capture spoiled by
    // new holes, a whole capture and recognition more): C's first lifts set strips sliding. The
    // batch's takt keeps them; this short run's median leaves them out, and at least two
    // intervals must remain (C, seed 1: two of four).
    let moving: Vec<f64> = rec
        .events
        .iter()
        .filter(|e| e.kind == "capture_spoiled" && e.detail.starts_with("PileMoving"))
        .map(|e| e.t_s)
        .collect();
    let mut sorted: Vec<f64> = releases
        .windows(2)
        .filter(|w| !moving.iter().any(|t| *t > w[0] && *t <= w[1]))
        .map(|w| w[1] - w[0])
        .collect();
    assert!(
        sorted.len() >= 2,
        "{workpiece}: {} intervals without a look again at a moving pile: {takts:?}",
        sorted.len()
    );
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    assert!(
        median < reference,
        "{workpiece}: median takt {median:.3} s >= the reference's {reference} s: {sorted:?} of {takts:?}"
    );
    let mut sorted_takts = takts.clone();
    sorted_takts.sort_by(f64::total_cmp);
    let mean = sorted_takts.iter().sum::<f64>() / takts.len() as f64;
    let summary_takt_s = binpick::results::Summary::of(s).takt.mean_s;
    assert!(
        (summary_takt_s - mean).abs() < 1e-9,
        "{workpiece}: the summary's takt {summary_takt_s} is not {mean}"
    );
    // The trace is in time order and the cycle's events are too.
    assert!(rec.trace.windows(2).all(|w| w[1].t_s >= w[0].t_s - 1e-9));
    assert!(rec.events.windows(2).all(|w| w[1].t_s >= w[0].t_s - 1e-9));
}

/// Every recognition result a recorded run used is judged in its recordings: each detection
/// with its error against the truth at its trigger. (The recorder once matched a result to its
/// evaluation by the time its grasps were ranked, which is later than its arrival whenever the
/// arm was still moving: only the first result of a run was labelled.)
#[test]
fn every_recorded_detection_is_judged_against_the_truth() {
    let (_, rec, ..) = run("E", 6);
    let used: Vec<_> = rec.recognitions.iter().filter(|r| !r.detections.is_empty()).collect();
    assert!(used.len() >= 4, "{} results used", used.len());
    for r in used {
        assert!(
            r.detection_errors.iter().all(Option::is_some),
            "the result used at {} s: {:?}",
            r.t_s,
            r.detection_errors
        );
    }
}

#[test]
fn scenario_a() {
    scenario("A");
}

#[test]
fn scenario_b() {
    scenario("B");
}

#[test]
fn scenario_c() {
    scenario("C");
}

#[test]
fn scenario_d() {
    scenario("D");
}

#[test]
fn scenario_e() {
    scenario("E");
}

#[test]
fn scenario_f() {
    scenario("F");
}

/// Misrecognition is an outcome: with the oracle's pose noise raised to 5 mm / 4 deg (a case
/// built to fail), grasps on wrong detections fail and are named `misrecognised`, with the
/// believed pose's error in the record; with the cell's default recognition the same picks name
/// none, and every pick's believed pose is scored. B runs with the cell's 6 mm cup here: with
/// its own 16 mm cup, one blind pick of these 8 misses its part and is scored misrecognised.
#[test]
fn misrecognition_is_a_named_outcome() {
    let robot_scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&robot_scene).unwrap();
    let mut wp = LoadedWorkpiece::resolve("B").unwrap();
    wp.workpiece.gripper = None;
    let opts = deterministic(8, 1);
    let mut bad = robot_scene.clone();
    bad.scene.sensor.recognition = binpick::config::RecognitionMode::Oracle;
    bad.scene.sensor.pose_noise_m = 0.005;
    bad.scene.sensor.pose_noise_deg = 4.0;
    let r = binpick::cycle::run(&bad, &robot, &wp, &opts, &mut ()).unwrap();
    let named: Vec<_> = r.records.iter().filter(|p| p.outcome.misrecognised()).collect();
    assert!(
        !named.is_empty(),
        "no misrecognised grasp: {:?}",
        r.records.iter().map(|p| p.outcome.detail()).collect::<Vec<_>>()
    );
    assert_eq!(r.tally.misrecognised, named.len());
    for p in &named {
        let m = p.aimed_at.expect("a misrecognised pick has its believed pose scored");
        assert!(!m.correct && p.sealed == Some(false), "{p:?}");
    }
    let recognition = binpick::results::Summary::of(&r.tally).recognition;
    assert!(recognition.precision < 0.5, "{recognition:?}");

    let good = binpick::cycle::run(&robot_scene, &robot, &wp, &opts, &mut ()).unwrap();
    assert_eq!(good.tally.misrecognised, 0, "{:?}", good.records);
    assert!(
        good.records
            .iter()
            .filter(|p| p.outcome.set_out())
            .all(|p| p.aimed_at.is_some())
    );
}

/// Several picks per capture: with `max_picks_per_capture = 3` (the default cell's) blind picks
/// come from a result whose capture is older than some pick (no wait for the sensor), only on
/// parts recognised clear of those picks, with no fault and (the seal check) still there; with
/// 1 (the negative control) there are none, and the takt is longer.
#[test]
fn several_picks_per_capture() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("E").unwrap();
    let opts = deterministic(10, 1);
    let mut multi = scene.clone();
    multi.scene.cycle.max_picks_per_capture = 3;
    let r = binpick::cycle::run(&multi, &robot, &wp, &opts, &mut ()).unwrap();
    let s = &r.tally;
    assert!(s.blind_picks.0 >= 2, "{:?}", s.blind_picks);
    assert!(s.blind_picks.1 * 10 >= s.blind_picks.0 * 9, "{:?}", s.blind_picks);
    assert_eq!((s.faults.collisions, s.faults.protective_stops), (0, 0));
    for p in r.records.iter().filter(|p| p.blind) {
        assert!(p.picks_since_capture > 0);
        assert_eq!(p.stall_sensor_s, 0.0, "pick {}", p.index);
        // Evaluation: the part aimed at was where its (older) capture saw it.
        assert!(p.aimed_at.is_some_and(|m| m.correct), "pick {}", p.index);
    }
    let mut single = scene.clone();
    single.scene.cycle.max_picks_per_capture = 1;
    let one = binpick::cycle::run(&single, &robot, &wp, &opts, &mut ()).unwrap();
    assert_eq!(one.tally.blind_picks, (0, 0));
    assert!(one.records.iter().all(|p| !p.blind && p.from_result == 0));
    let takt = |r: &binpick::cycle::RunResult| binpick::results::Summary::of(&r.tally).takt.mean_s;
    assert!(takt(&one) > takt(&r) + 0.1, "{} vs {}", takt(&one), takt(&r));
}

#[test]
fn deterministic_runs_repeat_byte_for_byte() {
    let ws = Workspace::new();
    for w in ["A", "C"] {
        let mut files = Vec::new();
        for out in ["out1", "out2"] {
            let dir = ws.path(out);
            let o = binpick_in(
                ws.dir.path(),
                &[
                    "run",
                    "--workpiece",
                    w,
                    "--picks",
                    "4",
                    "--deterministic",
                    "--out",
                    dir.to_str().unwrap(),
                ],
            );
            assert!(o.status.success(), "{w}: {}", stderr(&o));
            let run = dir.join(format!("run-{w}-seed1-det"));
            for f in ["scene.toml", "workpiece.toml", "timechart.svg"] {
                assert!(run.join(f).is_file(), "{w}: {f} missing");
            }
            let read = |f: &str| std::fs::read(run.join(f)).unwrap();
            files.push((read("summary.json"), read("picks.csv"), read("events.json")));
        }
        assert!(files[0] == files[1], "{w}: the same seed gave different results");
    }
}

#[test]
fn shards_merge_into_the_whole_batch() {
    let ws = Workspace::new();
    let out = ws.path("runs");
    let o = out.to_str().unwrap();
    let common = [
        "--workpieces",
        "A,E",
        "--picks",
        "2",
        "--seeds",
        "1-2",
        "--deterministic",
        "--out",
        o,
    ];
    let batch = |extra: &[&str]| {
        let mut args = vec!["batch"];
        args.extend_from_slice(&common);
        args.extend_from_slice(extra);
        let r = binpick_in(ws.dir.path(), &args);
        assert!(r.status.success(), "{args:?}: {}", stderr(&r));
    };
    // The whole batch recorded, the shards not: recording must not change the table.
    batch(&["--jobs", "2", "--record"]);
    let whole_dir = out.join("batch-AE-seeds1-2-picks2-det");
    for (w, s) in [("A", 1), ("A", 2), ("E", 1), ("E", 2)] {
        let f = whole_dir.join(format!("run-{w}-seed{s}.mcap"));
        let bytes = std::fs::read(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert!(mcap::read::Summary::read(&bytes).unwrap().is_some());
        let rrd = whole_dir.join(format!("run-{w}-seed{s}.rrd"));
        assert!(std::fs::metadata(&rrd).is_ok_and(|m| m.len() > 0), "{}", rrd.display());
    }
    let whole = std::fs::read_to_string(whole_dir.join("takt.csv")).unwrap();
    std::fs::rename(&whole_dir, out.join("whole")).unwrap();
    batch(&["--shard", "1/2", "--jobs", "1"]);
    batch(&["--shard", "2/2", "--jobs", "1"]);
    let shard = |k| out.join(format!("batch-AE-seeds1-2-picks2-det-shard{k}of2"));
    let r = binpick_in(
        ws.dir.path(),
        &[
            "merge",
            shard(1).to_str().unwrap(),
            shard(2).to_str().unwrap(),
            "--out",
            o,
        ],
    );
    assert!(r.status.success(), "merge: {}", stderr(&r));
    let merged = std::fs::read_to_string(whole_dir.join("takt.csv")).unwrap();
    assert_eq!(merged, whole, "merged shards differ from the whole batch");
    assert!(whole_dir.join("scene.toml").is_file());
    // One shard alone is not the batch.
    let r = binpick_in(ws.dir.path(), &["merge", shard(1).to_str().unwrap(), "--out", o]);
    assert_eq!(r.status.code(), Some(2), "{}", stderr(&r));
    assert!(stderr(&r).contains("in none of the shards"), "{}", stderr(&r));
}

/// The waiting pose must leave the view free: one over the middle of the pick tray is refused
/// with the key and the value named (the default cell's, at the tray's near side, runs).
#[test]
fn a_waiting_pose_in_the_view_is_refused() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("F").unwrap();
    let opts = deterministic(1, 1);
    let mut bad = scene.clone();
    bad.scene.cycle.waiting_tool_m = Some([0.10, 0.45, 0.15]);
    let Err(err) = binpick::cycle::run(&bad, &robot, &wp, &opts, &mut ()) else {
        panic!("a waiting pose in the view must be refused")
    };
    let msg = err.to_string();
    assert!(
        msg.contains("cycle.waiting_tool_m = [0.1, 0.45, 0.15]") && msg.contains("view"),
        "{msg}"
    );
    assert!(binpick::cycle::run(&scene, &robot, &wp, &opts, &mut ()).is_ok());
}

/// A run that keeps no records (a batch's) tallies its picks as they end: its summary is the
/// same as the one of the same run keeping them, and the tally agrees with the records,
/// recounted here from them.
#[test]
fn a_run_without_records_summarises_the_same_as_one_with_them() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("D").unwrap();
    let go = |keep_records| {
        let opts = RunOptions {
            keep_records,
            ..deterministic(8, 2)
        };
        binpick::cycle::run(&scene, &robot, &wp, &opts, &mut ()).unwrap()
    };
    let (kept, lean) = (go(true), go(false));
    assert!(lean.records.is_empty() && lean.recognition_per_capture.is_empty());
    assert_eq!(kept.records.len(), 8);
    assert!(!kept.recognition_per_capture.is_empty());
    let json = |r: &binpick::cycle::RunResult| {
        let summary = binpick::results::Summary::of(&r.tally);
        let run = binpick::results::RunSummary {
            summary: &summary,
            deterministic: true,
            per_capture: &[],
        };
        serde_json::to_string(&run).unwrap()
    };
    assert_eq!(json(&kept), json(&lean));
    assert_eq!(kept.tally, lean.tally);
    let r = &kept.records;
    let placed: Vec<_> = r
        .iter()
        .filter(|p| p.outcome == binpick::cycle::Outcome::Placed)
        .collect();
    let t = &lean.tally;
    assert_eq!(t.takts_s, binpick::cycle::takts(r));
    assert_eq!(t.pick_s, placed.iter().map(|p| p.pick_s).collect::<Vec<_>>());
    assert_eq!(t.place_s, placed.iter().map(|p| p.place_s).collect::<Vec<_>>());
    assert_eq!((t.attempts, t.placed), (r.len(), placed.len()));
    assert_eq!(t.set_out, r.iter().filter(|p| p.outcome.set_out()).count());
    assert_eq!(t.grasps.0, r.iter().filter(|p| p.sealed.is_some()).count());
    let recounted: f64 = r.iter().filter(|p| p.outcome.set_out()).map(|p| p.compute.pick_s).sum();
    assert!((t.compute_sum.pick_s - recounted).abs() < 1e-12);
    assert_eq!(
        t.recognition.captures,
        kept.recognition_per_capture.len(),
        "every result evaluated is tallied"
    );
}

/// The retreat after a release runs into the next Pick when that Pick was ready in time: in a
/// deterministic E run most picks after the first start while the last retreat ends, and the
/// part released before each still gets its placement error (measured once it rests).
/// Negative control: the same run with `cycle.overlap_lines = false` overlaps none.
#[test]
fn the_retreat_runs_into_the_next_pick_when_it_is_ready() {
    let robot_scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&robot_scene).unwrap();
    let wp = LoadedWorkpiece::resolve("E").unwrap();
    let go = |overlap: bool| {
        let mut scene = LoadedScene::embedded_default().unwrap();
        scene.scene.cycle.overlap_lines = overlap;
        let opts = deterministic(10, 1);
        binpick::cycle::run(&scene, &robot, &wp, &opts, &mut ()).unwrap()
    };
    let on = go(true);
    let overlapped: Vec<usize> = on
        .records
        .iter()
        .filter(|p| p.overlaps.retreat_s > 0.0)
        .map(|p| p.index)
        .collect();
    assert!(
        overlapped.len() >= 4,
        "only picks {overlapped:?} overlapped the retreat"
    );
    for &i in &overlapped {
        let before = &on.records[i - 1];
        assert_eq!(before.outcome, binpick::cycle::Outcome::Placed, "pick {i}");
        let err = before.placement_error_mm.expect("the placement error is measured late");
        assert!(err < 3.0, "pick {}: placed {err} mm off", i - 1);
    }
    assert_eq!(on.tally.faults.collisions + on.tally.faults.protective_stops, 0);
    let off = go(false);
    assert!(off.records.iter().all(|p| p.overlaps.retreat_s == 0.0));
}

/// A placed part is measured once it has come to rest in its slot. In E's deterministic run of
/// seed 2, pick 16's film capacitor is released from the release height over its slot and rocks
/// there: a tenth of a second after its release (when the next Pick's start used to measure it)
/// it stood more than 5 deg off the pose it settles in, and it was counted misplaced. Its
/// settled pose is checked here from the world itself, step by step after the release (the
/// control: it did rock beyond the tolerance), against the record's error (within it), with no
/// misplaced incident.
#[test]
fn a_placed_part_is_measured_once_it_rests() {
    use binpick::cycle::{Event, IncidentKind, Observer};
    use nalgebra::Isometry3;
    /// The held part of pick `pick` from its release on: its pose after each step.
    struct Watch {
        pick: usize,
        part: Option<usize>,
        released_s: Option<f64>,
        poses: Vec<(f64, Isometry3<f64>)>,
    }
    impl Observer for Watch {
        fn event(&mut self, t_s: f64, pick: Option<usize>, event: &Event) {
            match event {
                Event::Grasped { part, .. } if pick == Some(self.pick) => self.part = Some(*part),
                Event::Released if pick == Some(self.pick) => self.released_s = Some(t_s),
                _ => {}
            }
        }
        fn stepped(&mut self, world: &binpick::physics::World) {
            if let (Some(part), Some(t0)) = (self.part, self.released_s)
                && world.time_s() <= t0 + 1.0
            {
                self.poses.push((world.time_s() - t0, world.part_pose(part)));
            }
        }
    }
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("E").unwrap();
    let mut watch = Watch {
        pick: 16,
        part: None,
        released_s: None,
        poses: Vec::new(),
    };
    let run = binpick::cycle::run(&scene, &robot, &wp, &deterministic(19, 2), &mut watch).unwrap();
    let rec = &run.records[16];
    assert_eq!(rec.outcome, binpick::cycle::Outcome::Placed);
    let (last_s, settled) = *watch.poses.last().expect("the released part was watched");
    assert!(last_s > 0.5, "watched only {last_s} s after the release");
    let rocked_deg = watch
        .poses
        .iter()
        .filter(|(t, _)| *t <= 0.2)
        .map(|(_, p)| p.rotation.angle_to(&settled.rotation).to_degrees())
        .fold(0.0, f64::max);
    assert!(
        rocked_deg > 5.0,
        "the part rocked only {rocked_deg} deg: not the case this test needs"
    );
    let error_deg = rec.rotation_error_deg.expect("the placed part is measured");
    assert!(error_deg < 5.0, "measured {error_deg} deg off");
    let misplaced = run
        .tally
        .incidents
        .iter()
        .filter(|i| i.kind == IncidentKind::Misplaced && i.pick == Some(16))
        .count();
    assert_eq!(misplaced, 0);
}

/// A capture spoiled by the arm, then a failed grasp, leave the arm in the view with a dead
/// capture pending: the cell gets out of the view and triggers again. Such a run (F, seed 11,
/// one pick per capture, no hopper, at pick 42) used to spin forever without a physics step,
/// waiting for a capture that could never be replaced; it must now finish its picks. Since the
/// cup aims at the cells' mean surface, grasps fail so seldom that the cloud's recognition gives
/// no such case in B's first 14 picks on seeds 1-30 (B seed 1 had one at pick 12 until the
/// seal's load counted shear and peel), so the case is made: recognition by the oracle with
/// 3 mm of position noise, which puts many grasps off their faces, on the cell whose tool comes
/// straight down (`gripper.max_lean_deg` left out). B, seed 14, then has a capture spoiled by
/// the arm and a failed grasp at pick 6 (at picks 3, 6 and 9 before the grasp selector ranked a
/// carry by what its seal allows). The run goes on a thread so that a hang fails the test
/// instead of holding up the suite.
#[test]
fn a_spoiled_capture_with_the_arm_in_the_view_does_not_hang_the_cell() {
    #[derive(Default)]
    struct Spoiled(Vec<Option<usize>>);
    impl binpick::cycle::Observer for Spoiled {
        fn event(&mut self, _t_s: f64, pick: Option<usize>, event: &binpick::cycle::Event) {
            if matches!(event, binpick::cycle::Event::CaptureSpoiled(_)) {
                self.0.push(pick);
            }
        }
    }
    let mut scene = LoadedScene::embedded_default().unwrap();
    scene.scene.gripper.max_lean_deg = None;
    scene.scene.sensor.recognition = binpick::config::RecognitionMode::Oracle;
    scene.scene.sensor.pose_noise_m = 0.003;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let robot = RobotModel::from_scene(&scene).unwrap();
        let wp = LoadedWorkpiece::resolve("B").unwrap();
        let mut spoiled = Spoiled::default();
        let r = binpick::cycle::run(&scene, &robot, &wp, &deterministic(14, 14), &mut spoiled).unwrap();
        let _ = tx.send((r, spoiled.0));
    });
    let (r, spoiled) = rx
        .recv_timeout(std::time::Duration::from_secs(300))
        .expect("the run hangs");
    assert_eq!(r.tally.attempts, 14);
    // The case it is built on: a failed grasp follows a capture the arm spoiled, after the first.
    let cases = r
        .records
        .iter()
        .filter(|p| p.index > 0 && p.outcome.grasp_failed() && spoiled.contains(&Some(p.index)))
        .count();
    assert!(
        cases >= 1,
        "captures spoiled at picks {spoiled:?}; {:?}",
        r.records.iter().map(|p| p.outcome.detail()).collect::<Vec<_>>()
    );
}

/// The poses of the parts lying placed in the place tray, as of the last physics step.
#[derive(Default)]
struct PlacedPoses(Vec<nalgebra::Isometry3<f64>>);

impl binpick::cycle::Observer for PlacedPoses {
    fn stepped(&mut self, world: &binpick::physics::World) {
        let placed = world.parts_in_state(binpick::physics::PartState::Placed);
        self.0 = placed.into_iter().map(|i| world.part_pose(i)).collect();
    }
}

/// A part is placed in its place pose, which may turn it in its slot (A's relay lies with its
/// longest horizontal side along the slot's x: its 30 mm y axis, whether it lies on its back or
/// on a side), and its placement error is measured from that pose. Every relay placed in a short
/// deterministic run of A lies on a face, its longest horizontal side along the place tray's x
/// (read here from the cell file's tray yaw), and every placed pick's record gives a rotation
/// error of a few degrees. Negative control: measured from the slot's own frame (the relay's
/// frame against the slot's, up to the relay's half turn), the same relays are 45 deg or more
/// off.
#[test]
fn a_placed_part_is_measured_from_its_place_pose_not_from_the_slots_frame() {
    use nalgebra::{UnitQuaternion, Vector3};
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("A").unwrap();
    let mut watch = PlacedPoses::default();
    let run = binpick::cycle::run(&scene, &robot, &wp, &deterministic(8, 1), &mut watch).unwrap();
    let tray = &scene.scene.place_tray;
    let slot_yaw = (tray.tray.yaw_deg + tray.slot_yaw_deg.unwrap_or(0.0)).to_radians();
    // The angle between two headings, a half turn counted as none.
    let off = |a: f64, b: f64| {
        let d = (a - b).rem_euclid(std::f64::consts::PI);
        d.min(std::f64::consts::PI - d)
    };
    let size_m = wp.workpiece.size_m;
    let slot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), slot_yaw);
    let half_turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI);
    assert!(watch.0.len() >= 6, "only {} relays placed", watch.0.len());
    for p in &watch.0 {
        let axes = [Vector3::x(), Vector3::y(), Vector3::z()].map(|a| p.rotation * a);
        assert!(
            axes.iter().any(|a| a.z.abs() > 0.99),
            "a relay does not lie on a face: {axes:?}"
        );
        let longest = (0..3)
            .filter(|&k| axes[k].z.abs() < 0.1)
            .max_by(|&a, &b| size_m[a].total_cmp(&size_m[b]))
            .unwrap();
        let along = axes[longest];
        assert!(
            off(along.y.atan2(along.x), slot_yaw).to_degrees() < 5.0,
            "its longest side lies off the slot's x: {along}"
        );
        let from_slot = p.rotation.angle_to(&slot).min(p.rotation.angle_to(&(slot * half_turn)));
        assert!(from_slot.to_degrees() >= 45.0, "{} deg", from_slot.to_degrees());
    }
    let placed: Vec<f64> = run.records.iter().filter_map(|r| r.rotation_error_deg).collect();
    assert_eq!(placed.len(), run.tally.placed, "every placed pick is measured");
    assert!(placed.iter().all(|d| *d < 5.0), "rotation errors {placed:?} deg");
}

/// `grasp.place_orientation = "upright"` places every relay pins down: each relay lying placed
/// after a short deterministic run of A has its z axis up (read from the world, not from the
/// cell's records). The control: the same run with `any` places some another way up.
#[test]
fn an_upright_line_places_every_relay_pins_down() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let placed_z = |orientation: binpick::config::PlaceOrientation| {
        let mut wp = LoadedWorkpiece::resolve("A").unwrap();
        wp.workpiece.grasp.place_orientation = orientation;
        let mut watch = PlacedPoses::default();
        binpick::cycle::run(&scene, &robot, &wp, &deterministic(10, 1), &mut watch).unwrap();
        watch
            .0
            .iter()
            .map(|p| (p.rotation * nalgebra::Vector3::z()).z)
            .collect::<Vec<f64>>()
    };
    let upright = placed_z(binpick::config::PlaceOrientation::Upright);
    assert!(upright.len() >= 5, "only {} relays placed", upright.len());
    assert!(upright.iter().all(|z| *z > 0.99), "z axes' heights {upright:?}");
    let any = placed_z(binpick::config::PlaceOrientation::Any);
    assert!(any.iter().any(|z| *z < 0.99), "z axes' heights {any:?}");
}

/// The tool leans down the normal of a face tilted beyond the cup's 20 deg and the part is
/// placed: A, seed 26, whose pick 3 takes a relay lying 36 deg from flat. The plant judges the
/// pick: its seal check refuses an axis beyond the cup's 20 deg from the face the lip touches,
/// and a placed part lies in its slot within the place tray's tolerance. Negative
/// control: on the cell whose tool comes straight down, no pick leans.
#[test]
fn a_leaning_tool_takes_a_relay_lying_tilted_and_places_it() {
    #[derive(Default)]
    struct Leans(Vec<(usize, f64)>);
    impl binpick::cycle::Observer for Leans {
        fn event(&mut self, _t_s: f64, pick: Option<usize>, event: &binpick::cycle::Event) {
            if let (Some(p), binpick::cycle::Event::GraspChosen { lean_rad: Some(l), .. }) = (pick, event) {
                self.0.push((p, *l));
            }
        }
    }
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("A").unwrap();
    let mut leans = Leans::default();
    let r = binpick::cycle::run(&scene, &robot, &wp, &deterministic(4, 26), &mut leans).unwrap();
    let &(pick, lean) = leans.0.first().expect("no pick leaned");
    let lean_deg = lean.to_degrees();
    assert!(lean_deg > 20.0 && lean_deg <= 40.0 + 1e-9, "lean {lean_deg}");
    let rec = r.records.iter().find(|p| p.index == pick).unwrap();
    assert!(
        matches!(rec.outcome, binpick::cycle::Outcome::Placed),
        "{:?}",
        rec.outcome
    );
    let mut straight = scene.clone();
    straight.scene.gripper.max_lean_deg = None;
    let mut none = Leans::default();
    binpick::cycle::run(&straight, &robot, &wp, &deterministic(4, 26), &mut none).unwrap();
    assert!(none.0.is_empty(), "{:?}", none.0);
}
