//! The overhead sensor and the grasp selector: occlusion by the arm, exposure timing, recall on
//! settled piles of every workpiece, and grasps re-checked densely against the true world.

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::grasp::GraspSelector;
use binpick::physics::pile::PileOptions;
use binpick::physics::{PartShape, Tag, World};
use binpick::robot::{JointVector, RobotModel, tool_down_pose};
use binpick::sensor::{CaptureProblem, Detection, HeightMap, Sensor, TruthAtTrigger, evaluate};
use nalgebra::{Isometry3, Vector3};

/// The parts the detections correctly found (within 2 mm and 5 deg), by the evaluation.
fn found_parts(sensor: &Sensor, truth: &TruthAtTrigger, detections: &[Detection]) -> Vec<usize> {
    evaluate(truth, detections, &sensor.symmetry)
        .matches
        .iter()
        .flatten()
        .filter(|m| m.correct)
        .map(|m| m.part)
        .collect()
}

fn cell(workpiece: &str, seed: u64) -> (World, LoadedScene, LoadedWorkpiece, RobotModel) {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve(workpiece).unwrap();
    let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let mut w = World::new(&scene.scene, &robot, shape);
    w.build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, seed))
        .unwrap();
    (w, scene, wp, robot)
}

/// Parks the arm with the tool 12 cm above the pile's middle, in the sensor's view.
fn park_over_tray(w: &mut World) {
    let c = w.pick_tray().world_from_tray.translation.vector;
    w.place_tool(&tool_down_pose(c + Vector3::z() * 0.12, 0.0)).unwrap();
}

#[test]
fn the_arm_hides_what_is_under_it() {
    let (mut w, scene, wp, _) = cell("F", 4);
    let sensor = Sensor::new(&scene.scene.sensor, &w, 4, &wp.workpiece).unwrap();
    let clear = binpick::sensor::capture(&w, &sensor.camera, 4, 0);
    let clear_truth = TruthAtTrigger::take(&w, &sensor, &clear);
    let seen_clear = found_parts(&sensor, &clear_truth, &sensor.recognize_cloud(&clear));
    park_over_tray(&mut w);
    let blocked = binpick::sensor::capture(&w, &sensor.camera, 4, 1);
    let blocked_truth = TruthAtTrigger::take(&w, &sensor, &blocked);
    let seen_blocked = found_parts(&sensor, &blocked_truth, &sensor.recognize_cloud(&blocked));
    // Parts found with the arm away that the arm hides entirely (none of their pixels shows)
    // are not found under it.
    let hidden: Vec<usize> = seen_clear
        .iter()
        .copied()
        .filter(|&i| blocked_truth.visible_px[i] == 0)
        .collect();
    assert!(!hidden.is_empty(), "the arm hides no found part to test with");
    for i in &hidden {
        assert!(!seen_blocked.contains(i), "part {i} hidden by the arm was detected");
    }
    assert!(seen_blocked.len() < seen_clear.len());
    assert!(blocked.valid_count() > 0 && clear.valid_count() > 0);
}

#[test]
fn capture_is_refused_or_spoiled_with_the_arm_in_view_and_ready_exactly_after_latency() {
    let (mut w, scene, wp, _) = cell("B", 2);
    let mut sensor = Sensor::new(&scene.scene.sensor, &w, 2, &wp.workpiece).unwrap();
    let home = w.joints();
    // In view: refused.
    park_over_tray(&mut w);
    assert!(matches!(sensor.trigger(&w), Err(CaptureProblem::ArmInView(_))));
    // Out of view: accepted; the arm swings in during exposure: spoiled.
    w.place_arm(&home);
    let mut job = sensor.trigger(&w).unwrap();
    let over = w
        .robot()
        .ik_tool_nearest(
            &tool_down_pose(
                w.pick_tray().world_from_tray.translation.vector + Vector3::z() * 0.25,
                0.0,
            ),
            &home,
        )
        .unwrap()
        .q;
    let mut spoiled = None;
    let steps = (scene.scene.sensor.exposure_s / w.dt_s()).ceil() as usize;
    for k in 1..=steps {
        w.set_joint_target(&(home + (over - home) * (k as f64 / steps as f64)));
        w.step().unwrap();
        if let Some(p) = sensor.watch(&mut job, &w) {
            spoiled = Some(p);
            break;
        }
    }
    assert!(
        matches!(spoiled, Some(CaptureProblem::ArmEnteredDuringExposure(_))),
        "{spoiled:?}"
    );
    assert_eq!(sensor.spoiled, 1);
    assert!(sensor.result(&mut job, w.time_s()).is_none());
    // Arm away, a clean capture: no result before latency_s, a result at exactly latency_s.
    w.place_arm(&home);
    let trigger = w.time_s();
    let mut job = sensor.trigger(&w).unwrap();
    assert_eq!(job.ready_s, trigger + scene.scene.sensor.latency_s);
    let mut first_ready = None;
    while first_ready.is_none() {
        w.step().unwrap();
        assert!(sensor.watch(&mut job, &w).is_none());
        if sensor.result(&mut job, w.time_s()).is_some() {
            first_ready = Some(w.time_s());
        }
    }
    let t = first_ready.unwrap();
    assert!(
        t + 1e-9 >= trigger + 1.1 && t < trigger + 1.1 + w.dt_s() + 1e-9,
        "ready at {t}, triggered at {trigger}"
    );
}

/// Dense check of a grasp's straight approach and retreat against the true world: the tool and
/// the flange links every 1 mm of tool travel, against every collider but the target part near
/// the grasp point (within the cup's reach of the face).
fn approach_collides(
    w: &World,
    robot: &RobotModel,
    approach: &Isometry3<f64>,
    grasp: &Isometry3<f64>,
    q_start: &JointVector,
    target: usize,
) -> Option<String> {
    let n = ((grasp.translation.vector - approach.translation.vector).norm() / 0.001).ceil() as usize;
    let mut q = *q_start;
    for s in 0..=n {
        let pose = approach.lerp_slerp(grasp, s as f64 / n as f64);
        q = robot.ik_tool_nearest(&pose, &q).ok()?.q;
        // The cup's last 2 mm meet the target by design (it is planned on the measured surface,
        // with the sensor's depth noise).
        let near_face = (pose.translation.vector - grasp.translation.vector).norm() < 0.002;
        let skip = |t: Tag| near_face && t == Tag::Part(target as u32);
        if let Some(tag) = w.arm_touches_at(&q, &skip) {
            return Some(format!(
                "{} at {:.1} mm before the grasp",
                w.describe(Some(tag)),
                (n - s) as f64
            ));
        }
    }
    None
}

#[test]
fn cloud_recognition_finds_the_top_layer_and_chosen_grasps_are_reachable_and_clear() {
    for name in ["A", "B", "C", "D", "E", "F"] {
        let (mut top, mut found, mut detected, mut correct) = (0, 0, 0, 0);
        for seed in [1, 2] {
            let (mut w, scene, wp, robot) = cell(name, seed);
            let mut sensor = Sensor::new(&scene.scene.sensor, &w, seed, &wp.workpiece).unwrap();
            let mut job = sensor.trigger(&w).unwrap();
            w.run_for(sensor.latency_s).unwrap();
            let detections = sensor.result(&mut job, w.time_s()).expect("ready");
            let report = evaluate(&job.truth, &detections, &sensor.symmetry);
            let f = &report.figures;
            assert!(f.top_layer > 0, "{name}: empty top layer");
            (top, found) = (top + f.top_layer, found + f.top_layer_found);
            (detected, correct) = (detected + f.detected, correct + f.correct);
            let hm = HeightMap::from_capture(&job.capture, w.pick_tray(), 0.002, None);
            let selector = GraspSelector::for_workpiece(&scene.scene, &robot, &wp);
            let slot = scene.scene.world_from_slots(&wp.workpiece)[0];
            let plan = selector.select(&detections, &hm, &slot, &w.joints());
            let best = plan
                .best()
                .unwrap_or_else(|| panic!("{name} seed {seed}: no grasp; rejected {:?}", plan.rejected_counts()));
            for g in plan.ranked.iter().take(3) {
                for q in [g.q_approach, g.q_grasp, g.q_place] {
                    assert!(robot.within_limits(&JointVector::from(q), 1e-9));
                }
                let reached = robot.world_from_tool(&JointVector::from(g.q_grasp));
                assert!((reached.translation.vector - g.world_from_tool.translation.vector).norm() < 1e-6);
                // The part the detection is, by the evaluation (a wrong detection has none to
                // spare the cup's last millimetres for).
                let target = report.matches[g.detection]
                    .filter(|m| m.correct)
                    .map_or(usize::MAX, |m| m.part);
                if let Some(hit) = approach_collides(
                    &w,
                    &robot,
                    &g.world_from_tool_approach,
                    &g.world_from_tool,
                    &JointVector::from(g.q_approach),
                    target,
                ) {
                    panic!(
                        "{name} seed {seed}: the approach of grasp on detection {} meets {hit}",
                        g.detection
                    );
                }
            }
            assert!(best.score.total.is_finite());
        }
        let (recall, precision) = (found as f64 / top as f64, correct as f64 / detected.max(1) as f64);
        let (recall_min, precision_min) = FLOORS[name.as_bytes()[0] as usize - b'A' as usize];
        assert!(recall >= recall_min, "{name}: top-layer recall {found} / {top}");
        assert!(precision >= precision_min, "{name}: precision {correct} / {detected}");
    }
}

/// The cloud recognition's floors on the pooled top-layer recall and the precision of seeds 1
/// and 2, per workpiece A..F: regression guards a little below what it reaches. With the 0.85 mm
/// pixels of the default sensor, flat E and F parts show a 12 px top face that pins the yaw
/// (`bench sensor`, seeds 1-8: recall 92.0 and 92.8 %, precision 99.5 and 100 %; with 1.43 mm
/// pixels 54 and 51 %); D's lying cans still come out 5-7 deg off in yaw now and then.
const FLOORS: [(f64, f64); 6] = [
    (0.85, 0.95),
    (0.90, 0.99),
    (0.90, 0.97),
    (0.85, 0.95),
    (0.85, 0.97),
    (0.85, 0.97),
];

/// The sensor's fast capture (the fixed cell rasterized once, only what moves rasterized per
/// capture) gives the same image as rasterizing the whole world: with the arm away and with it
/// over the pile.
#[test]
fn cached_background_captures_equal_full_captures() {
    for (name, seed) in [("E", 3), ("C", 2)] {
        let (mut w, scene, wp, _) = cell(name, seed);
        let sensor = Sensor::new(&scene.scene.sensor, &w, seed, &wp.workpiece).unwrap();
        let bg = binpick::sensor::Background::new(&w, &sensor.camera);
        for pose in 0..2 {
            if pose == 1 {
                park_over_tray(&mut w);
            }
            let full = binpick::sensor::capture(&w, &sensor.camera, seed, pose);
            let fast = binpick::sensor::capture_over(&w, &sensor.camera, seed, pose, Some(&bg));
            assert_eq!(full.depth_m, fast.depth_m, "{name} pose {pose}: depth differs");
            let bits = |c: &binpick::sensor::Capture| -> Vec<[u32; 3]> {
                c.points_world.iter().map(|p| p.map(f32::to_bits)).collect()
            };
            assert_eq!(bits(&full), bits(&fast), "{name} pose {pose}: points differ");
            assert!(full.valid_count() > 10_000);
        }
    }
}

/// Turns part `i` 0.05 rad about its own centre during `job`'s exposure (one physics step) with
/// the sensor watching: a C strip's ends move 3.7 mm, its centre stays put. Returns its pose
/// before.
fn turn_during_exposure(
    w: &mut World,
    sensor: &mut Sensor,
    job: &mut binpick::sensor::CaptureJob,
    i: usize,
) -> Isometry3<f64> {
    let p = w.part_pose(i);
    let turned = Isometry3::from_parts(
        p.translation,
        nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.05) * p.rotation,
    );
    w.set_part_pose(i, &turned);
    w.step().unwrap();
    sensor.watch(job, w);
    p
}

/// The recognition result is what the picture showed at the trigger: a part moved after the
/// exposure is reported where it was (not where it is when the result is read); and a long part
/// turning about its centre during the exposure is blurred although its centre stays put.
#[test]
fn recognition_reports_the_trigger_and_blurs_a_turning_strip() {
    let (mut w, scene, wp, _) = cell("C", 3);
    let mut sensor = Sensor::new(&scene.scene.sensor, &w, 3, &wp.workpiece).unwrap();
    let mut job = sensor.trigger(&w).unwrap();
    let before = sensor.result(&mut job.clone(), job.ready_s).expect("ready");
    let i = found_parts(&sensor, &job.truth, &before)[0];
    let at_trigger = w.part_pose(i);
    // After the exposure, the part is moved 3 cm; the result is read later.
    w.run_for(scene.scene.sensor.exposure_s + 0.01).unwrap();
    let moved = Isometry3::from_parts(
        (at_trigger.translation.vector + Vector3::new(0.03, 0.0, 0.0)).into(),
        at_trigger.rotation,
    );
    w.set_part_pose(i, &moved);
    let ready_s = job.ready_s;
    let after = sensor.result(&mut job, ready_s).expect("ready");
    let near = |p: &Isometry3<f64>| {
        after
            .iter()
            .map(|d| (d.world_from_part.translation.vector - p.translation.vector).norm())
            .fold(f64::INFINITY, f64::min)
    };
    assert!(
        near(&at_trigger) < binpick::sensor::CORRECT_WITHIN_M,
        "not reported where it was"
    );
    // Negative control: the part really is elsewhere now, and nothing is reported there (a
    // neighbour may lie a centimetre or two away).
    assert!(near(&moved) > binpick::sensor::CORRECT_WITHIN_M);

    // A strip turning 0.05 rad about its own centre during the exposure: its centre does not
    // move, its ends move 3.7 mm. Blurred: its pixels come back empty and it is not recognised.
    let (mut w, scene, wp, _) = cell("C", 3);
    let mut sensor = Sensor::new(&scene.scene.sensor, &w, 3, &wp.workpiece).unwrap();
    let mut job = sensor.trigger(&w).unwrap();
    let blurred_still = job.blurred();
    let p = turn_during_exposure(&mut w, &mut sensor, &mut job, i);
    let centre_moved = (w.part_pose(i).translation.vector - p.translation.vector).norm();
    assert!(
        centre_moved < binpick::sensor::STILL_MOTION_M,
        "centre moved {centre_moved}"
    );
    assert!(job.blurred() > blurred_still, "a turning strip is not blurred");
    let ready_s = job.ready_s;
    let seen = sensor.result(&mut job, ready_s).expect("ready");
    assert!(
        !found_parts(&sensor, &job.truth, &seen).contains(&i),
        "a blurred strip is recognised"
    );
    // Negative control: the same capture without the turn finds it.
    assert!(found_parts(&sensor, &job.truth, &before).contains(&i));
}

/// The recognition the cell uses takes the capture, the camera, the fixed pick tray and the
/// part's model, and nothing else: its signature admits no physics world and no ground truth.
#[test]
fn cloud_recognition_cannot_reach_the_world() {
    use binpick::geometry::TrayVolume;
    use binpick::sensor::{Camera, Capture, CloudDetection, CloudModel, cloud};
    let _pure: fn(&Capture, &Camera, &TrayVolume, &CloudModel) -> Vec<CloudDetection> = cloud::recognize;
    let _cell: fn(&Sensor, &Capture) -> Vec<Detection> = Sensor::recognize_cloud;
}

/// What the trigger check needs of a run: every physics step's time and whether the arm (or the
/// held part) was in the sensor's view, judged here with the sensor's own frustum on the world
/// as stepped, and the captures, results and spoiled exposures from the events.
#[derive(Default)]
struct TriggerWatch {
    frustum: Option<binpick::sensor::ViewFrustum>,
    cfg: Option<(binpick::config::SensorConfig, binpick::config::Workpiece)>,
    steps: Vec<(f64, bool)>,
    captures: Vec<f64>,
    ready: Vec<f64>,
    spoiled: Vec<f64>,
}

impl binpick::cycle::Observer for TriggerWatch {
    fn stepped(&mut self, world: &World) {
        if self.frustum.is_none() {
            let (cfg, wp) = self.cfg.as_ref().unwrap();
            self.frustum = Some(Sensor::new(cfg, world, 0, wp).unwrap().frustum.clone());
        }
        let inside = self.frustum.as_ref().unwrap().arm_inside(world).is_some();
        self.steps.push((world.time_s(), inside));
    }
    fn event(&mut self, t_s: f64, _pick: Option<usize>, event: &binpick::cycle::Event) {
        match event {
            binpick::cycle::Event::Capture(_) => self.captures.push(t_s),
            binpick::cycle::Event::RecognitionReady { .. } => self.ready.push(t_s),
            binpick::cycle::Event::CaptureSpoiled(_) => self.spoiled.push(t_s),
            _ => {}
        }
    }
}

/// The captures of `w` that could have fired a step earlier: at the step before, the arm was out
/// of the view, no earlier capture was pending (triggered, its result not yet in, and not spoiled
/// with its exposure over), and the arm stayed out of the view for a whole exposure from there.
fn late_captures(w: &TriggerWatch, captures: &[f64], exposure_s: f64) -> Vec<f64> {
    let mut late = Vec::new();
    for (k, &t) in captures.iter().enumerate().skip(1) {
        let Some(i) = w.steps.iter().position(|(ts, _)| *ts >= t - 1e-9) else {
            continue;
        };
        let (t_prev, in_view) = w.steps[i - 1];
        let prev = captures[k - 1];
        let prev_ready = w.ready.iter().copied().find(|r| *r >= prev - 1e-9);
        let prev_spoiled = w
            .spoiled
            .iter()
            .any(|s| *s >= prev - 1e-9 && *s <= prev + exposure_s + 1e-9);
        let pending = if prev_spoiled {
            t_prev < prev + exposure_s - 1e-9
        } else {
            prev_ready.is_none_or(|r| t_prev < r - 1e-9)
        };
        let enters = w.steps[i - 1..]
            .iter()
            .take_while(|(ts, _)| *ts <= t_prev + exposure_s + 1e-9)
            .any(|(_, v)| *v);
        if !in_view && !pending && !enters {
            late.push(t);
        }
    }
    late
}

/// The trigger fires at the earliest moment a capture can be exposed: for every capture of a
/// steady run, at the physics step before it the arm was in the view, the previous capture was
/// still pending, or the arm entered the view within an exposure from there (checked on the
/// world as stepped, with the frustum, not the cycle's own bookkeeping). Negative control: the
/// same captures 50 ms later are found late.
#[test]
fn the_capture_fires_at_the_earliest_moment() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("E").unwrap();
    let opts = binpick::cycle::RunOptions {
        picks: 8,
        seed: 1,
        deterministic: true,
        stop: None,
        keep_records: true,
    };
    let mut watch = TriggerWatch {
        cfg: Some((scene.scene.sensor.clone(), wp.workpiece.clone())),
        ..Default::default()
    };
    let r = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut watch).unwrap();
    assert_eq!((r.tally.agitations, r.tally.refills), (0, 0), "a steady run");
    assert!(watch.captures.len() >= 5, "{:?}", watch.captures);
    let exposure_s = scene.scene.sensor.exposure_s;
    assert_eq!(late_captures(&watch, &watch.captures, exposure_s), Vec::<f64>::new());
    let delayed: Vec<f64> = watch.captures.iter().map(|t| t + 0.05).collect();
    assert!(
        !late_captures(&watch, &delayed, exposure_s).is_empty(),
        "negative control: captures 50 ms late must be found"
    );
}

/// One B block lying flat, settled at `offset_x_m` from the pick tray's centre; what the cell's
/// sense-and-grasp makes of it (cloud recognition) and whether its best-ranked grasp's approach
/// pose is clear with the hand alone.
fn lone_block_grasp(offset_x_m: f64) -> (binpick::pipeline::GraspChoice, bool) {
    use binpick::pipeline::{GraspContext, SensedPile, planning_environment, sense_and_grasp};
    use binpick::planning::{CollisionModel, PlanStats, RobotSpheres};
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("B").unwrap();
    let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let half = shape.half_extents_m;
    let mut w = World::new(&scene.scene, &robot, shape);
    let c = w.pick_tray().world_from_tray.translation.vector;
    w.add_part(&Isometry3::translation(c.x + offset_x_m, c.y, c.z + half.z + 0.001));
    w.run_for(0.5).unwrap();
    let mut sensor = Sensor::new(&scene.scene.sensor, &w, 1, &wp.workpiece).unwrap();
    let mut job = sensor.trigger(&w).unwrap();
    w.run_for(sensor.latency_s).unwrap();
    let detections = sensor.result(&mut job, w.time_s()).expect("ready");
    let selector = GraspSelector::for_workpiece(&scene.scene, &robot, &wp);
    let ctx = GraspContext {
        scene: &scene.scene,
        robot: &robot,
        selector: &selector,
        pick_tray: w.pick_tray(),
        part_half_extents_m: half,
    };
    let slot = scene.scene.world_from_slots(&wp.workpiece)[0];
    let sensed = SensedPile::new(&ctx, &job.capture, &job.arm);
    let choice = sense_and_grasp(&ctx, &sensed, &detections, &slot, &w.joints(), &[]);
    let best = choice.plan.best().expect("the selector ranks a grasp on the block");
    let env = planning_environment(&scene.scene, &sensed.pile, best);
    let hand_alone = CollisionModel::new(&robot, RobotSpheres::new(&robot, &scene.scene, None), env)
        .free(&JointVector::from(best.q_approach), &mut PlanStats::default());
    (choice, hand_alone)
}

/// A block lying against the tray's wall: the hand alone clears the wall at the approach pose,
/// but the block, lifted there on the cup, would hang into it and the Place could not start
/// (B, seed 1 once tried it five times in a row). Sense-and-grasp does not choose it. Negative
/// control: the same block in the tray's middle is chosen.
#[test]
fn a_part_that_would_hang_into_the_wall_when_lifted_is_not_chosen() {
    let (at_wall, hand_alone) = lone_block_grasp(0.15 - 0.0155);
    assert!(hand_alone, "the hand alone clears the wall at the approach pose");
    assert!(
        at_wall.chosen.is_none(),
        "chosen: {:?}",
        at_wall.chosen.map(|c| c.grasp.world_from_tool.translation)
    );
    let (in_middle, _) = lone_block_grasp(0.0);
    assert!(in_middle.chosen.is_some(), "{}", in_middle.why_none());
}

/// A pile in motion as the cell can tell it from the image alone: a strip turning during the
/// exposure leaves a hole over the tray floor (its pixels return nothing), at least
/// `Sensor::motion_hole_min_px` pixels that were not holes in the last image looked at. Negative
/// controls: the same pile standing still shows none; and the same image looked at twice shows
/// no new hole the second time (a hole that stays put is a steep face, not motion).
#[test]
fn a_strip_moving_during_the_exposure_leaves_new_holes_and_a_still_pile_none() {
    let (mut w, scene, wp, _) = cell("C", 3);
    let mut sensor = Sensor::new(&scene.scene.sensor, &w, 3, &wp.workpiece).unwrap();
    let min_px = sensor.motion_hole_min_px();
    let mut still = sensor.trigger(&w).unwrap();
    let ready_s = still.ready_s;
    sensor.result(&mut still, ready_s).expect("ready");
    let first = sensor.new_hole_px(&still.capture);
    assert!(first < min_px, "a still pile shows {first} hole pixels");
    assert_eq!(
        sensor.new_hole_px(&still.capture),
        0,
        "the same image again shows new holes"
    );

    let mut job = sensor.trigger(&w).unwrap();
    let i = binpick::sensor::top_layer(&w)[0];
    turn_during_exposure(&mut w, &mut sensor, &mut job, i);
    assert!(job.blurred() > 0, "the turning strip is not blurred");
    let ready_s = job.ready_s;
    sensor.result(&mut job, ready_s).expect("ready");
    let moved = sensor.new_hole_px(&job.capture);
    assert!(moved >= min_px, "a turning strip leaves only {moved} new hole pixels");
    assert_eq!(sensor.new_hole_px(&job.capture), 0, "the hole is new twice");
}

/// The confirming exposure (`cycle::sensing`): a block tipped up onto a face steeper than the
/// sensor's grazing angle shows new holes against the image before (the check against that image
/// alone would take the pile for moving), and the same holes in a second exposure right after it,
/// so the holes in one of the two images only are too few to be motion. Negative controls: a
/// block turning during the first exposure leaves holes the second exposure does not have; a
/// block creeping through both exposures leaves a hole in both, wider than a steep face.
#[test]
fn a_confirming_exposure_tells_a_steep_face_turned_up_from_a_pile_in_motion() {
    let (mut w, scene, wp, _) = cell("B", 2);
    let mut sensor = Sensor::new(&scene.scene.sensor, &w, 2, &wp.workpiece).unwrap();
    let min_px = sensor.motion_hole_min_px();
    let exposed = |sensor: &mut Sensor, w: &World| {
        let mut job = sensor.trigger(w).unwrap();
        job.apply_blur();
        job
    };
    let before = exposed(&mut sensor, &w);
    sensor.new_hole_px(&before.capture);
    // A top-layer block stood up on an edge, a largest face 8 degrees from vertical, 8 cm above
    // where it lay (clear of the pile): nothing moves during either exposure.
    let i = binpick::sensor::top_layer(&w)[0];
    let p = w.part_pose(i);
    let tipped = Isometry3::from_parts(
        (p.translation.vector + Vector3::z() * 0.08).into(),
        nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 82f64.to_radians()),
    );
    w.set_part_pose(i, &tipped);
    // One step brings the colliders the capture sees to the new pose (the block falls 0.1 mm).
    w.step().unwrap();
    let image = exposed(&mut sensor, &w);
    let against_before = sensor.unseen_hole_px(&image.capture);
    assert!(
        against_before >= min_px,
        "the tipped block's steep face shows only {against_before} new hole pixels (min {min_px})"
    );
    let confirming = exposed(&mut sensor, &w);
    let changed = sensor.changed_hole_px(&image.capture, &confirming.capture);
    assert!(
        changed < min_px,
        "a still pile changes {changed} hole pixels between two exposures"
    );

    let mut moving = sensor.trigger(&w).unwrap();
    turn_during_exposure(&mut w, &mut sensor, &mut moving, i);
    assert!(moving.blurred() > 0, "the turning block is not blurred");
    moving.apply_blur();
    let after = exposed(&mut sensor, &w);
    let changed = sensor.changed_hole_px(&moving.capture, &after.capture);
    assert!(
        changed >= min_px,
        "a block turning in the first exposure changes only {changed} hole pixels"
    );

    // A block creeping 0.6 mm through each of the two exposures is blurred in both, its hole
    // nearly where it was: the hole, wider than any steep face, is motion all the same.
    let slide = |w: &mut World, sensor: &mut Sensor, job: &mut binpick::sensor::CaptureJob| {
        let p = w.part_pose(i);
        w.set_part_pose(
            i,
            &Isometry3::from_parts((p.translation.vector + Vector3::x() * 0.0006).into(), p.rotation),
        );
        w.step().unwrap();
        sensor.watch(job, w);
        job.apply_blur();
    };
    let mut first = sensor.trigger(&w).unwrap();
    slide(&mut w, &mut sensor, &mut first);
    let mut second = sensor.trigger(&w).unwrap();
    slide(&mut w, &mut sensor, &mut second);
    assert!(
        first.blurred() > 0 && second.blurred() > 0,
        "the creeping block is not blurred"
    );
    let changed = sensor.changed_hole_px(&first.capture, &second.capture);
    assert!(
        changed >= min_px,
        "a block creeping through both exposures changes only {changed} hole pixels"
    );
}

/// Which parts the cell confirms with a second exposure: those whose moving silhouette (their
/// mean thickness) is at least twice as wide as their steepest still face can look (B's 30 mm
/// blocks, D's cans), not those where the two can look alike (C's strips, A's relays, E's and
/// F's 5 mm parts).
#[test]
fn a_second_exposure_confirms_only_parts_thicker_than_twice_their_steepest_face() {
    for (workpiece, confirms) in [
        ("A", false),
        ("B", true),
        ("C", false),
        ("D", true),
        ("E", false),
        ("F", false),
    ] {
        let (w, scene, wp, _) = cell(workpiece, 1);
        let sensor = Sensor::new(&scene.scene.sensor, &w, 1, &wp.workpiece).unwrap();
        assert_eq!(sensor.confirms(), confirms, "{workpiece}");
    }
}

/// A C strip lying across the pick tray's +x rim, its outer end rising 34 deg beyond the wall
/// (as a refill left one on C's seed 4), and the arm parked beyond the -x wall above the rim, out
/// of the view frustum. The planner's pile holds the strip's end beyond the wall, higher than the
/// rim, and nothing of the arm. Controls: the map that stops at the outer walls (as before) has no
/// cell there, so the end was no obstacle; and with the controller's joints wrong (the home pose),
/// the arm is not masked and stands beyond the -x wall as pile.
#[test]
fn a_strip_across_the_rim_is_seen_beyond_the_wall_and_the_arm_is_not() {
    use binpick::pipeline::{GraspContext, HEIGHT_MAP_CELL_M, SensedPile, pile_map};
    use binpick::sensor::ArmAtTrigger;
    use nalgebra::{Point3, Translation3, UnitQuaternion};
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("C").unwrap();
    let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let half = shape.half_extents_m;
    let mut w = World::new(&scene.scene, &robot, shape);
    let tray = *w.pick_tray();
    let [hx, _] = tray.half_xy_m;
    let rim = tray.wall_height_m;
    let t = tray.world_from_tray;
    let over_wall = hx - tray.wall_thickness_m / 2.0;
    w.add_part(
        &(t * Isometry3::from_parts(
            Translation3::new(over_wall, 0.0, rim + half.z),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -34f64.to_radians()),
        )),
    );
    w.place_tool(&tool_down_pose(
        (t * Point3::new(-hx - 0.045, 0.0, rim + 0.03)).coords,
        0.0,
    ))
    .unwrap();
    let mut sensor = Sensor::new(&scene.scene.sensor, &w, 1, &wp.workpiece).unwrap();
    let job = sensor.trigger(&w).expect("the arm is out of the view frustum");
    let selector = GraspSelector::for_workpiece(&scene.scene, &robot, &wp);
    let ctx = GraspContext {
        scene: &scene.scene,
        robot: &robot,
        selector: &selector,
        pick_tray: &tray,
        part_half_extents_m: half,
    };
    let beyond_minus_x = |m: &HeightMap| -> usize {
        let mut n = 0;
        for j in 0..m.ny {
            for i in 0..m.nx {
                let x = m.origin_xy_m[0] + (i as f64 + 0.5) * m.cell_m;
                n += usize::from(x < -hx && m.height_m[j * m.nx + i].is_finite());
            }
        }
        n
    };
    // 40 mm beyond the outer face the strip stands about 33 mm above the rim.
    let end = (hx + 0.04, 0.0);
    let sensed = SensedPile::new(&ctx, &job.capture, &job.arm);
    let k = sensed
        .pile
        .index(end.0, end.1)
        .expect("the map reaches beyond the wall");
    assert!(
        sensed.pile.height_m[k] > rim + 0.02,
        "the strip's end beyond the wall: {} m above the floor",
        sensed.pile.height_m[k]
    );
    assert_eq!(beyond_minus_x(&sensed.pile), 0, "the arm is masked out");
    // Control: the map as it was, to the outer walls only.
    let to_walls = pile_map(
        &scene.scene,
        &HeightMap::from_capture(&job.capture, &tray, HEIGHT_MAP_CELL_M, None),
    );
    assert!(
        to_walls.index(end.0, end.1).is_none(),
        "control: no cell beyond the wall"
    );
    // Control: the controller's joints wrong, the arm stands beyond the -x wall as pile.
    let wrong = ArmAtTrigger {
        q: JointVector::from(scene.scene.robot.home_rad()),
        tool_from_held_part: None,
    };
    let unmasked = SensedPile::new(&ctx, &job.capture, &wrong);
    assert!(
        beyond_minus_x(&unmasked.pile) > 20,
        "control: the arm unmasked beyond the -x wall ({} cells)",
        beyond_minus_x(&unmasked.pile)
    );
}
