//! The physics twin: piles of all six workpieces, rest, tunnelling, the suction gripper, the arm
//! pushing parts, and the health monitor. Penetration is measured by the independent overlap check.

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::physics::pile::{PileOptions, max_motion};
use binpick::physics::suction::{GraspFailure, GripperEvent};
use binpick::physics::{HealthEvent, PartShape, World};
use binpick::robot::{RobotModel, tool_down_pose};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

const WORKPIECES: [&str; 6] = ["A", "B", "C", "D", "E", "F"];

fn world(workpiece: &str) -> (World, LoadedScene, LoadedWorkpiece) {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve(workpiece).unwrap();
    let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
    (World::new(&scene.scene, &robot, shape), scene, wp)
}

fn floor_z(w: &World) -> f64 {
    w.pick_tray().world_from_tray.translation.vector.z
}

#[test]
fn piles_of_every_workpiece_settle_in_the_tray_within_0_3_mm_and_repeat_bit_for_bit() {
    for name in WORKPIECES {
        let (mut w1, _, wp) = world(name);
        let opts = PileOptions::new(wp.workpiece.pile_count as usize, 11);
        let r1 = w1.build_pile(&opts).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(r1.settled, "{name}: pile did not settle");
        assert_eq!(r1.in_tray, r1.spawned, "{name}: parts outside the tray");
        assert!(
            r1.max_penetration_m <= 0.0003,
            "{name}: penetration {:.3} mm",
            r1.max_penetration_m * 1e3
        );
        for p in &r1.poses {
            assert!(
                p.xyz_m.iter().chain(&p.quat_wxyz).all(|v| v.is_finite()),
                "{name}: NaN pose"
            );
            assert!(
                p.xyz_m[2] > floor_z(&w1),
                "{name}: part {} below the tray floor",
                p.part
            );
        }
        // Same seed, a fresh world: bit-identical poses.
        let (mut w2, _, _) = world(name);
        let r2 = w2.build_pile(&opts).unwrap();
        assert_eq!(r1.poses, r2.poses, "{name}: same seed, different pile");
        assert_eq!(r1.settle_sim_s.to_bits(), r2.settle_sim_s.to_bits());
        // Another seed, another pile.
        let (mut w3, _, _) = world(name);
        let r3 = w3.build_pile(&PileOptions::new(opts.count, 12)).unwrap();
        assert_ne!(r1.poses, r3.poses, "{name}: seed has no effect");
    }
}

#[test]
fn piles_of_the_cad_parts_settle_even_on_an_smd_cans_small_supports() {
    // A lying SMD electrolytic rests on its terminal's tip, a corner of its base and its rim:
    // three supports a few tenths of a millimetre apart in height.
    for name in ["hex-standoff", "to220", "dip8", "smd-elcap"] {
        let (mut w, _, wp) = world(&format!("workpieces/{name}.toml"));
        let r = w
            .build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, 1))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(
            r.settled && r.settle_sim_s < 5.0,
            "{name}: {:.3} s simulated, settled {}",
            r.settle_sim_s,
            r.settled
        );
        assert_eq!(r.in_tray, r.spawned, "{name}: parts outside the tray");
        assert!(
            r.max_penetration_m <= 0.0003,
            "{name}: penetration {:.3} mm",
            r.max_penetration_m * 1e3
        );
    }
    // Negative control: with rapier's contact clustering (at most four points per contact plane
    // of a pair) the cans lying on those supports rock and walk, and the pile never settles.
    let (mut w, _, wp) = world("workpieces/smd-elcap.toml");
    w.set_contact_clustering(true);
    let r = w
        .build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, 1))
        .unwrap();
    assert!(!r.settled, "clustered contacts settled in {:.3} s", r.settle_sim_s);
}

#[test]
fn cans_stacked_cap_on_cap_do_not_sink_into_each_other() {
    // D's pile of seed 13 stacks two cans cap on cap; with the cap touching as a sliver of four
    // of its sixteen corners they sank 2.03 mm into each other at 2.68 s and the health monitor
    // stopped the pour. The support slabs hold them apart.
    let (mut w, _, wp) = world("D");
    let r = w
        .build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, 13))
        .unwrap_or_else(|e| panic!("D seed 13: {e}"));
    assert!(r.settled && r.in_tray == r.spawned, "{r:?}");
    assert!(r.max_penetration_m <= 0.0003, "{:.3} mm", r.max_penetration_m * 1e3);
}

#[test]
fn settled_piles_do_not_jitter() {
    for name in ["C", "D", "F"] {
        let (mut w, _, wp) = world(name);
        let before = w
            .build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, 5))
            .unwrap()
            .poses;
        // Wake everything and watch one more second.
        w.wake_parts();
        w.run_for(1.0).unwrap();
        let after: Vec<_> = (0..w.part_count())
            .map(|i| {
                let p = w.part_pose(i);
                let q = p.rotation.quaternion();
                binpick::physics::pile::PartPose {
                    part: i,
                    xyz_m: p.translation.vector.into(),
                    quat_wxyz: [q.w, q.i, q.j, q.k],
                }
            })
            .collect();
        let (dp, dr) = max_motion(&before, &after);
        assert!(
            dp < 1e-4 && dr < 0.01,
            "{name}: parts crept {:.3} mm / {:.4} rad at rest",
            dp * 1e3,
            dr
        );
        assert!(w.max_penetration_m().0 <= 0.0003);
    }
}

#[test]
fn thin_parts_do_not_tunnel_through_the_tray_floor() {
    for name in ["C", "F"] {
        for (height, tilt) in [(0.3, 0.0), (0.3, 1.2), (0.5, 0.05)] {
            let (mut w, _, wp) = world(name);
            let c = w.pick_tray().world_from_tray.translation.vector;
            let pose = Isometry3::new(Vector3::new(c.x, c.y, c.z + height), Vector3::new(tilt, 0.3, 0.0));
            w.add_part(&pose);
            w.run_for(1.0).unwrap_or_else(|e| panic!("{name} from {height} m: {e}"));
            let z = w.part_pose(0).translation.z;
            let thinnest = wp.workpiece.size_m.iter().cloned().fold(f64::INFINITY, f64::min);
            assert!(
                z > c.z + thinnest / 2.0 - 3e-4,
                "{name} from {height} m tilted {tilt}: centre at {z}, floor at {}",
                c.z
            );
            assert!(w.max_penetration_m().0 <= 0.0003);
        }
    }
}

/// CCD runs only in steps in which a part may travel over 1 mm: a part flung at the floor
/// gets it and stays on the floor; a pile's pour gets it while parts fall, not while they
/// rock into rest. Negative control: with a zero travel threshold, CCD runs in nearly every
/// solved step of the same pour (what rapier's own test for a thin part's pieces did).
#[test]
fn ccd_runs_only_in_steps_where_a_part_may_travel_over_a_millimetre() {
    for name in ["C", "F"] {
        let (mut w, _, wp) = world(name);
        let c = w.pick_tray().world_from_tray.translation.vector;
        let thinnest = wp.workpiece.size_m.iter().cloned().fold(f64::INFINITY, f64::min);
        // Lying flat 11 mm above the floor, out of its predicted contacts' reach, at 10 m/s.
        let z0 = c.z + thinnest / 2.0 + 0.011;
        w.add_part(&Isometry3::new(Vector3::new(c.x, c.y, z0), Vector3::new(0.0, 0.0, 0.3)));
        w.set_part_velocity(0, &Vector3::new(0.0, 0.0, -10.0));
        w.run_for(0.5)
            .unwrap_or_else(|e| panic!("{name} flung at the floor: {e}"));
        let z = w.part_pose(0).translation.z;
        assert!(
            z > c.z + thinnest / 2.0 - 3e-4,
            "{name} flung at the floor: centre at {z}, floor at {}",
            c.z
        );
        assert!(w.max_penetration_m().0 <= 0.0003);
        let (ccd, steps) = (w.ccd_steps(), w.steps());
        assert!(ccd >= 1 && ccd * 4 < steps, "{name} flung: {ccd} CCD steps of {steps}");
    }
    let pour = |travel_m: f64| {
        let (mut w, _, wp) = world("E");
        w.set_ccd_travel_m(travel_m);
        let pile = w
            .build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, 3))
            .unwrap();
        assert!(pile.settled && pile.max_penetration_m <= 0.0003);
        (w.ccd_steps(), w.steps())
    };
    let (ccd, steps) = pour(binpick::physics::quiet::CCD_TRAVEL_M);
    assert!(ccd * 3 < steps, "pour: {ccd} CCD steps of {steps}");
    let (ccd, steps) = pour(0.0);
    assert!(
        ccd * 10 > steps * 9,
        "pour, CCD whenever anything moves: {ccd} CCD steps of {steps}"
    );
}

#[test]
fn a_part_poured_after_one_was_taken_out_reuses_its_body_and_falls_like_a_new_one() {
    let (mut w, _, _) = world("E");
    let c = w.pick_tray().world_from_tray.translation.vector;
    let drop = Isometry3::new(Vector3::new(c.x, c.y, c.z + 0.05), Vector3::new(0.4, 0.2, 0.0));
    let fresh = w.add_part(&drop);
    w.run_for(1.0).unwrap();
    let rest = w.part_pose(fresh);
    w.remove_part(fresh);
    w.run_for(0.1).unwrap();
    // Negative control: taken out, it is parked far below the table and no longer in the tray.
    assert_eq!(w.part_state(fresh), binpick::physics::PartState::Removed);
    assert!(!w.pick_tray().contains(&w.part_pose(fresh).translation.vector));
    let again = w.add_part(&drop);
    assert_eq!(
        (again, w.part_count()),
        (fresh, 1),
        "the removed part's index and body are reused"
    );
    assert_eq!(w.part_state(again), binpick::physics::PartState::Free);
    w.run_for(0.05).unwrap();
    assert!(w.part_pose(again).translation.z < drop.translation.z - 1e-3, "it falls");
    w.run_for(0.95).unwrap();
    let now = w.part_pose(again);
    assert!(w.pick_tray().contains(&now.translation.vector));
    assert!(
        (now.translation.vector - rest.translation.vector).norm() < 3e-4,
        "rests where the first one did: {:?} against {:?}",
        now.translation.vector,
        rest.translation.vector
    );
    // A new part now gets a new index.
    assert_eq!(w.add_part(&drop), 1);
}

/// A single part lying on the pick tray floor at `xy` (tray frame), settled; returns its top face centre.
fn lone_part(w: &mut World, size_z: f64, xy: (f64, f64), rot: UnitQuaternion<f64>) -> Vector3<f64> {
    let tray = w.pick_tray().world_from_tray;
    let pose = tray * Isometry3::from_parts(Translation3::new(xy.0, xy.1, size_z / 2.0 + 0.0005), rot);
    let i = w.add_part(&pose);
    w.run_for(0.5).unwrap();
    let p = w.part_pose(i);
    p.translation.vector + p.rotation * Vector3::new(0.0, 0.0, size_z / 2.0)
}

/// Lowers the tool onto `tool` from 4 cm above, switches the vacuum on and waits for it to build
/// up; returns what the gripper reported (the grasp, or its failure, and anything after it).
fn grasp_events(w: &mut World, tool: Isometry3<f64>) -> Vec<GripperEvent> {
    let above = Isometry3::from_parts(
        Translation3::from(tool.translation.vector + Vector3::z() * 0.04),
        tool.rotation,
    );
    w.place_tool(&above).unwrap();
    w.move_tool_line(&tool, 0.3).unwrap();
    w.vacuum_on();
    w.run_for(w.gripper().build_up_s + 0.01).unwrap();
    w.take_gripper_events()
}

fn grasp_at(w: &mut World, tool: Isometry3<f64>) -> GripperEvent {
    let events = grasp_events(w, tool);
    assert_eq!(events.len(), 1, "{events:?}");
    events[0].clone()
}

#[test]
fn suction_seals_on_a_flat_top_face_lifts_and_places_within_tolerance() {
    let (mut w, scene, wp) = world("B");
    let top = lone_part(&mut w, 0.020, (0.0, 0.0), UnitQuaternion::identity());
    let ev = grasp_at(&mut w, tool_down_pose(top, 0.0));
    assert!(matches!(ev, GripperEvent::Grasped { .. }), "{ev:?}");
    assert_eq!(w.held_part(), Some(0));
    let payload = w.held_payload().unwrap();
    assert!((payload.mass_kg - wp.workpiece.mass_kg).abs() < 1e-12);
    // Lift 10 cm and swing toward the place tray: the part keeps its place on the tool.
    let tool_from_part = w.world_from_tool().inverse() * w.part_pose(0);
    let lifted = tool_down_pose(top + Vector3::z() * 0.10, 0.0);
    w.move_tool_line(&lifted, 0.5).unwrap();
    let slot = scene.scene.world_from_slots(&wp.workpiece)[0];
    // The part was grasped square to the tool: turn the tool to the slot's heading.
    let slot_x = slot.rotation * Vector3::x();
    let heading = slot_x.y.atan2(slot_x.x);
    let over_slot = tool_down_pose(slot.translation.vector + Vector3::z() * 0.12, heading);
    // Swing over in joint space (a straight tool line would pass near the base).
    let q_over = w.robot().ik_tool_nearest(&over_slot, &w.joints()).unwrap().q;
    w.move_joints(&q_over, 1.2).unwrap();
    let drift = w.world_from_tool().inverse() * w.part_pose(0) * tool_from_part.inverse();
    assert!(
        drift.translation.vector.norm() < 1e-4 && drift.rotation.angle() < 1e-3,
        "part moved on the cup: {drift}"
    );
    // Lower until the part is 1 mm above the slot floor, release, and let it land.
    let release = tool_down_pose(slot.translation.vector + Vector3::z() * (0.010 + 0.001), heading);
    w.move_tool_line(&release, 0.5).unwrap();
    w.vacuum_off();
    w.run_for(w.gripper().release_s + 0.01).unwrap();
    assert!(matches!(
        w.take_gripper_events()[..],
        [GripperEvent::Released { part: 0, .. }]
    ));
    w.move_tool_line(&over_slot, 0.3).unwrap();
    w.run_for(0.5).unwrap();
    // Off the slot horizontally, and turned from its heading modulo B's quarter turn.
    let placed = w.part_pose(0);
    let dp = (placed.translation.vector - slot.translation.vector).xy().norm();
    let x = placed.rotation * Vector3::x();
    let quarter = std::f64::consts::FRAC_PI_2;
    let dyaw = (x.y.atan2(x.x) - heading).rem_euclid(quarter);
    let dyaw = dyaw.min(quarter - dyaw);
    assert!(
        dp < 0.0015 && dyaw < 2f64.to_radians(),
        "placed {:.2} mm / {:.2} deg off",
        dp * 1e3,
        dyaw.to_degrees()
    );
    // At rest in its slot the part is fixed there (a body put to sleep by hand could fall
    // through the floor): the cup coming down on it is a collision, and it does not move.
    assert!(w.part_sleeping(0));
    let placed = w.part_pose(0);
    let top_now = placed.translation.vector + placed.rotation * Vector3::new(0.0, 0.0, 0.010);
    let err = w
        .move_tool_line(&tool_down_pose(top_now - Vector3::z() * 0.003, heading), 0.3)
        .unwrap_err();
    let binpick::physics::script::ScriptError::Health(report) = err else {
        panic!("{err:?}");
    };
    match report.first() {
        Some(HealthEvent::ArmCollision { obstacle, .. }) => assert_eq!(obstacle, "placed part 0"),
        other => panic!("{other:?}"),
    }
    assert_eq!(w.part_pose(0), placed);
}

/// The cup holding `workpiece` lifted 5 cm off the tray, at rest; returns the world, the
/// lifted tool pose, and the seal's required holding force at rest [N].
fn held_and_lifted(workpiece: &str, size_z: f64) -> (World, Isometry3<f64>, f64) {
    let (mut w, _, wp) = world(workpiece);
    let top = lone_part(&mut w, size_z, (0.0, 0.0), UnitQuaternion::identity());
    let ev = grasp_at(&mut w, tool_down_pose(top, 0.0));
    let GripperEvent::Grasped { seal, .. } = ev else {
        panic!("{ev:?}")
    };
    let lifted = tool_down_pose(top + Vector3::z() * 0.05, 0.0);
    w.move_tool_line(&lifted, 0.5).unwrap();
    w.run_for(0.05).unwrap();
    let g = binpick::robot::GRAVITY_M_S2;
    // Straight down and still: the cup pulls against gravity alone (tool z down).
    let still = Vector3::new(0.0, 0.0, -g);
    let required_n = w
        .gripper()
        .model
        .required_n(wp.workpiece.mass_kg, &still, &seal.com_from_cup_m);
    (w, lifted, required_n)
}

#[test]
fn a_venting_cup_lets_the_part_go_when_it_needs_more_than_is_left_and_not_before() {
    // The holding force falls linearly to zero over `release_s` once the valve closes: a part at
    // rest comes off when its weight (peel included) exceeds what is left, at
    // (1 - required / holding) of `release_s`, to a physics step.
    let (mut w, _, required_n) = held_and_lifted("B", 0.020);
    let (holding_n, release_s, dt) = (w.gripper().holding_n, w.gripper().release_s, w.dt_s());
    let expected_s = (1.0 - required_n / holding_n) * release_s;
    w.vacuum_off();
    let closed_s = w.time_s();
    w.run_for(release_s + 0.01).unwrap();
    let events = w.take_gripper_events();
    let [GripperEvent::Released { time_s, part: 0 }] = events[..] else {
        panic!("{events:?}")
    };
    let after_s = time_s - closed_s;
    assert!(
        (after_s - expected_s).abs() <= dt + 1e-9,
        "came off {:.1} ms after the valve closed, expected {:.1} ms",
        after_s * 1e3,
        expected_s * 1e3
    );
    assert!(w.held_part().is_none());

    // Negative control: the arm retreats 10 mm upward (peak 23 m/s^2) 10 ms after the valve
    // closed. The vacuum is not vented yet and the part goes up with the cup, what the cycle's
    // wait for `release_s` before the retreat prevents.
    let (mut w, lifted, _) = held_and_lifted("B", 0.020);
    let z0 = w.part_pose(0).translation.z;
    w.vacuum_off();
    w.run_for(0.01).unwrap();
    let up = Isometry3::from_parts(
        Translation3::from(lifted.translation.vector + Vector3::z() * 0.01),
        lifted.rotation,
    );
    w.move_tool_line(&up, 0.05).unwrap();
    let risen_m = w.part_pose(0).translation.z - z0;
    assert!(risen_m > 0.005, "the part rose {:.1} mm with the cup", risen_m * 1e3);
}

#[test]
fn suction_fails_on_an_edge_on_a_small_face_and_when_tilted() {
    // Cup centred on the edge of B's 30 mm top face.
    let (mut w, _, _) = world("B");
    let top = lone_part(&mut w, 0.020, (0.0, 0.0), UnitQuaternion::identity());
    let edge = top + Vector3::new(0.015, 0.0, 0.0);
    let ev = grasp_at(&mut w, tool_down_pose(edge, 0.0));
    assert!(
        matches!(
            ev,
            GripperEvent::GraspFailed {
                reason: GraspFailure::OnEdge { .. },
                ..
            }
        ),
        "{ev:?}"
    );
    // E standing on end: its top face is 10 x 5 mm, narrower than the 6 mm cup.
    let (mut w, _, _) = world("E");
    let top = lone_part(&mut w, 0.010, (0.0, 0.0), UnitQuaternion::identity());
    let ev = grasp_at(&mut w, tool_down_pose(top, 0.0));
    match ev {
        GripperEvent::GraspFailed {
            reason: GraspFailure::FaceTooSmall { width_mm, .. },
            ..
        } => {
            assert!((width_mm - 5.0).abs() < 0.6, "measured face width {width_mm}")
        }
        other => panic!("{other:?}"),
    }
    // Tilted 30 deg from the face normal (the cup tolerates 20).
    let (mut w, _, _) = world("B");
    let top = lone_part(&mut w, 0.020, (0.0, 0.0), UnitQuaternion::identity());
    let tilted = tool_down_pose(top, 0.0) * Isometry3::rotation(Vector3::x() * 30f64.to_radians());
    let tilted = Isometry3::from_parts(
        Translation3::from(top - (tilted.rotation * Vector3::z()) * 0.0003),
        tilted.rotation,
    );
    let ev = grasp_at(&mut w, tilted);
    match ev {
        GripperEvent::GraspFailed {
            reason: GraspFailure::Tilted { tilt_deg, .. },
            ..
        } => {
            assert!((tilt_deg - 30.0).abs() < 2.0, "{tilt_deg}")
        }
        other => panic!("{other:?}"),
    }
    // Nothing there.
    let (mut w, _, _) = world("B");
    let floor = w.pick_tray().world_from_tray.translation.vector;
    let ev = grasp_at(&mut w, tool_down_pose(floor, 0.0));
    assert!(
        matches!(
            ev,
            GripperEvent::GraspFailed {
                reason: GraspFailure::NoPart(_),
                ..
            }
        ),
        "{ev:?}"
    );
}

#[test]
fn an_off_centre_grasp_on_a_heavy_part_slips_with_the_reason() {
    let (mut w, _, _) = world("B");
    let top = lone_part(&mut w, 0.020, (0.0, 0.0), UnitQuaternion::identity());
    let off = top + Vector3::new(0.010, 0.0, 0.0);
    // The seal forms (the lip is on the face) but the peel moment of the 30 g part, 10 mm off the
    // cup axis, exceeds what the 6 mm cup holds: it tears off when lifted, or already at rest.
    let mut events = grasp_events(&mut w, tool_down_pose(off, 0.0));
    assert!(matches!(events[0], GripperEvent::Grasped { .. }), "{events:?}");
    if events.len() == 1 {
        w.move_tool_line(&tool_down_pose(off + Vector3::z() * 0.05, 0.0), 0.3)
            .unwrap();
        events.extend(w.take_gripper_events());
    }
    let slipped = events.iter().find_map(|e| match e {
        GripperEvent::Slipped {
            required_n, holding_n, ..
        } => Some((*required_n, *holding_n)),
        _ => None,
    });
    let (required, holding) = slipped.unwrap_or_else(|| panic!("no slip: {events:?}"));
    assert!(required > holding);
    assert_eq!(w.held_part(), None);
}

#[test]
fn the_moving_arm_pushes_a_part_it_sweeps_through() {
    let (mut w, _, _) = world("F");
    let top = lone_part(&mut w, 0.005, (0.0, 0.0), UnitQuaternion::identity());
    let start = w.part_pose(0).translation.vector;
    // Sweep the cup through the part 2 mm above the floor, 60 mm along x.
    let low = top - Vector3::z() * 0.003;
    w.place_tool(&tool_down_pose(low - Vector3::x() * 0.03, 0.0)).unwrap();
    w.move_tool_line(&tool_down_pose(low + Vector3::x() * 0.03, 0.0), 0.6)
        .unwrap();
    w.run_for(0.3).unwrap();
    let moved = (w.part_pose(0).translation.vector - start).norm();
    assert!(moved > 0.005, "the part moved only {:.2} mm", moved * 1e3);
}

#[test]
fn the_arm_entering_a_tray_wall_is_reported() {
    let (mut w, _, _) = world("F");
    let tray = w.pick_tray().world_from_tray;
    let half = w.pick_tray().half_xy_m;
    // Above the middle of the +x wall, then down into it.
    let wall_top = tray * nalgebra::Point3::new(half[0] - 0.004, 0.0, w.pick_tray().wall_height_m);
    w.place_tool(&tool_down_pose(wall_top.coords + Vector3::z() * 0.03, 0.0))
        .unwrap();
    let err = w
        .move_tool_line(&tool_down_pose(wall_top.coords - Vector3::z() * 0.01, 0.0), 0.5)
        .unwrap_err();
    let binpick::physics::script::ScriptError::Health(report) = err else {
        panic!("{err:?}");
    };
    match report.first() {
        Some(HealthEvent::ArmCollision { robot, obstacle, .. }) => {
            assert!(robot.contains("cup") || robot.contains("tool"), "{robot}");
            assert!(obstacle.contains("pick tray wall +x"), "{obstacle}");
        }
        other => panic!("{other:?}"),
    }
}

/// A step reports every problem it has: a part off its tray does not hide the arm pressing into
/// a wall in the same step (before, the monitor returned the first problem only).
#[test]
fn every_problem_of_a_step_is_reported() {
    let (mut w, _, _) = world("F");
    let tray = w.pick_tray().world_from_tray;
    let half = w.pick_tray().half_xy_m;
    let wall_top = tray * nalgebra::Point3::new(half[0] - 0.004, 0.0, w.pick_tray().wall_height_m);
    // The cup 5 mm down into the wall, and a part on the table outside both trays.
    w.place_tool(&tool_down_pose(wall_top.coords - Vector3::z() * 0.005, 0.0))
        .unwrap();
    w.add_part(&Isometry3::translation(-0.3, -0.3, 0.01));
    let report = w.step().unwrap_err();
    let left = report
        .events
        .iter()
        .any(|e| matches!(e, HealthEvent::LeftVolume { body, .. } if body == "part 0"));
    let hit = report
        .events
        .iter()
        .any(|e| matches!(e, HealthEvent::ArmCollision { obstacle, .. } if obstacle.contains("wall +x")));
    assert!(left && hit, "{report}");
    assert!(!report.is_fatal());
}

#[test]
fn the_health_monitor_stops_on_a_stray_part_and_on_nan() {
    let (mut w, _, _) = world("F");
    // A part on the table, outside both trays.
    w.add_part(&Isometry3::translation(-0.3, -0.3, 0.01));
    match w.step().unwrap_err().first() {
        Some(HealthEvent::LeftVolume { body, volume, .. }) => {
            assert_eq!(body, "part 0");
            assert_eq!(*volume, "pick tray");
        }
        other => panic!("{other:?}"),
    }
    let (mut w, _, _) = world("F");
    lone_part(&mut w, 0.005, (0.0, 0.0), UnitQuaternion::identity());
    let mut pose = w.part_pose(0);
    pose.translation.x = f64::NAN;
    w.set_part_pose(0, &pose);
    let e = w.step().unwrap_err();
    assert!(e.is_fatal(), "{e:?}");
    assert!(matches!(e.first(), Some(HealthEvent::NonFinite { .. })), "{e:?}");
    assert!(e.to_string().contains("part 0 has a non-finite"), "{e}");
}

/// Agitation: the pick tray driven through the cell file's vibration moves the pile (parts turn
/// over and shift), loses none, and comes back to rest exactly where it was built: a capture with
/// the sensor's cached background (the fixed cell's hits, cast before the shake) equals a full
/// ray cast afterwards. Negative control: the same time without the shake moves nothing.
#[test]
fn an_agitated_tray_shakes_the_pile_and_returns_exactly_to_rest() {
    let moved_after = |shake: bool| {
        let (mut w, scene, wp) = world("A");
        w.build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, 3))
            .unwrap();
        let camera = binpick::sensor::Camera::from_config(&scene.scene.sensor).unwrap();
        let background = binpick::sensor::Background::new(&w, &camera);
        let before: Vec<Isometry3<f64>> = (0..w.part_count()).map(|i| w.part_pose(i)).collect();
        let a = scene.scene.agitation;
        assert!(a.max_tries > 0, "the default cell agitates");
        let tray = w.pick_tray().world_from_tray.rotation;
        let t0 = w.time_s();
        let mut peak_offset_m = 0.0f64;
        while w.time_s() < t0 + a.duration_s + a.settle_s {
            let t = w.time_s() + w.dt_s() - t0;
            let offset = if shake {
                tray * Vector3::from(a.offset_m(t))
            } else {
                Vector3::zeros()
            };
            peak_offset_m = peak_offset_m.max(offset.norm());
            w.set_pick_tray_offset(offset);
            w.step().unwrap();
        }
        assert!(!w.pick_tray_moving(), "the tray is back at rest, fixed");
        assert_eq!(w.parts_in_pick_tray().len(), w.part_count(), "a part left the tray");
        let full = binpick::sensor::capture(&w, &camera, 3, 0);
        let cached = binpick::sensor::capture_over(&w, &camera, 3, 0, Some(&background));
        assert_eq!(full.depth_m, cached.depth_m, "the tray is not back where it was built");
        let turned = (0..w.part_count())
            .filter(|&i| before[i].rotation.angle_to(&w.part_pose(i).rotation) > 0.5)
            .count();
        let shifted = (0..w.part_count())
            .filter(|&i| (before[i].translation.vector - w.part_pose(i).translation.vector).norm() > 0.002)
            .count();
        (peak_offset_m, turned, shifted)
    };
    let (peak, turned, shifted) = moved_after(true);
    assert!(peak > 0.002, "peak offset {peak}");
    assert!(shifted >= 10, "only {shifted} parts shifted by the shake");
    assert!(turned >= 1, "no part turned over");
    let (_, still_turned, still_shifted) = moved_after(false);
    assert_eq!((still_turned, still_shifted), (0, 0), "a still tray moved the pile");
}

/// The bellows take up what the kinematic cup pressed the part into the tray floor at the seal:
/// a cup that ends 0.8 mm below a lying part's top face seals, and the held part does not sit in
/// the floor (no collision while the vacuum builds up and the tool lifts; without the take-up this
/// case reported the held part 0.53 mm in the floor, as the cycle did). Negative control: a cup
/// driven 3 mm into the part squeezes it deeper than the bellows take up, and the health monitor
/// reports the collision.
#[test]
fn the_bellows_take_up_the_cups_overtravel_at_the_seal() {
    for (press_m, ok) in [(0.0008, true), (0.003, false)] {
        let (mut w, _, _) = world("E");
        // Lying on its 10 x 10 mm face.
        let flat = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
        lone_part(&mut w, 0.005, (0.0, 0.0), flat);
        let top = w.part_pose(0).translation.vector + Vector3::z() * 0.0025;
        let tool = tool_down_pose(top - Vector3::z() * press_m, 0.0);
        let above = Isometry3::from_parts(
            Translation3::from(tool.translation.vector + Vector3::z() * 0.04),
            tool.rotation,
        );
        w.place_tool(&above).unwrap();
        let outcome = w.move_tool_line(&tool, 0.3).and_then(|_| {
            w.vacuum_on();
            w.run_for(w.gripper().build_up_s + 0.01)?;
            w.move_tool_line(&above, 0.3)
        });
        if ok {
            outcome.unwrap_or_else(|e| panic!("pressed {press_m} m: {e}"));
            assert_eq!(w.held_part(), Some(0));
        } else {
            let e = outcome.expect_err("a cup 3 mm into the part must be reported");
            assert!(e.to_string().contains("penetrat"), "{e}");
        }
    }
}

/// The arm's link boxes are in the world at their full size: a small volume just inside a box
/// corner that no other shape of the arm covers finds the link there (checked against the robot
/// model's primitives, in metres, by code independent of the physics' unit conversion), and the
/// same volume just outside the corner finds nothing (negative control). An earlier version built the boxes
/// in metres in the millimetre world, a thousand times too small.
#[test]
fn the_arms_link_boxes_are_full_size_in_the_world() {
    use binpick::physics::ViewVolume;
    use binpick::robot::LinkPrimitive;
    let (w, scene, _) = world("E");
    let robot = RobotModel::from_scene(&scene).unwrap();
    let q = binpick::robot::JointVector::from(scene.scene.robot.home_rad());
    let world_from_links = robot.world_from_links(&q);
    // Whether the world point p [m] is inside any primitive of the arm model other than `except`.
    let inside_other = |p: &Vector3<f64>, except: (usize, usize)| {
        robot.links.iter().enumerate().any(|(i, link)| {
            link.shapes.iter().enumerate().any(|(k, s)| {
                if (i, k) == except {
                    return false;
                }
                let l = (world_from_links[i] * s.link_from_shape).inverse_transform_point(&(*p).into());
                match s.primitive {
                    LinkPrimitive::Box { half_extents_m: h } => {
                        l.x.abs() <= h.x && l.y.abs() <= h.y && l.z.abs() <= h.z
                    }
                    LinkPrimitive::Cylinder {
                        radius_m,
                        half_length_m,
                    } => l.x.hypot(l.y) <= radius_m && l.z.abs() <= half_length_m,
                    LinkPrimitive::Sphere { radius_m } => l.coords.norm() <= radius_m,
                    LinkPrimitive::Capsule {
                        radius_m,
                        half_length_m,
                    } => l.x.hypot(l.y).hypot((l.z.abs() - half_length_m).max(0.0)) <= radius_m,
                }
            })
        })
    };
    let cube = |c: &Vector3<f64>| {
        let e = 0.002;
        let pts: Vec<Vector3<f64>> = (0..8)
            .map(|k| {
                c + Vector3::new(
                    if k & 1 == 0 { -e } else { e },
                    if k & 2 == 0 { -e } else { e },
                    if k & 4 == 0 { -e } else { e },
                )
            })
            .collect();
        ViewVolume::hull(&pts).unwrap()
    };
    let mut boxes = 0;
    for (i, link) in robot.links.iter().enumerate().skip(1) {
        for (k, s) in link.shapes.iter().enumerate() {
            let LinkPrimitive::Box { half_extents_m: h } = s.primitive else {
                continue;
            };
            let world_from_shape = world_from_links[i] * s.link_from_shape;
            // A corner of the box no other shape covers (inside at 0.9, outside at 1.1 of it).
            let corner = (0..8)
                .map(|c| {
                    Vector3::new(
                        if c & 1 == 0 { -h.x } else { h.x },
                        if c & 2 == 0 { -h.y } else { h.y },
                        if c & 4 == 0 { -h.z } else { h.z },
                    )
                })
                .find(|c| {
                    let inner = (world_from_shape * nalgebra::Point3::from(c * 0.9)).coords;
                    let outer = (world_from_shape * nalgebra::Point3::from(c * 1.1)).coords;
                    !inside_other(&inner, (i, k)) && !inside_other(&outer, (i, k))
                })
                .unwrap_or_else(|| panic!("link {i}: every corner of box {k} is covered by another shape"));
            let inner = (world_from_shape * nalgebra::Point3::from(corner * 0.9)).coords;
            let outer = (world_from_shape * nalgebra::Point3::from(corner * 1.1)).coords;
            let found = w.robot_inside(&cube(&inner));
            assert!(
                found.is_some(),
                "link {i} box {k}: nothing of the arm just inside its corner"
            );
            assert_eq!(
                w.robot_inside(&cube(&outer)),
                None,
                "link {i} box {k}: something just outside its corner"
            );
            boxes += 1;
        }
    }
    assert!(boxes >= 3, "the arm model has {boxes} boxes");
}

#[test]
fn a_pour_that_spills_loses_the_part_and_goes_on_only_when_asked() {
    // A part outside the pick tray when a pour steps (as a strip that bounced over the wall of
    // a hopper dose): with `losing_spilled` it is taken out of the world and reported, and the
    // pour completes; without (the negative control), the pour ends on the health error.
    let spill = |lose: bool| {
        let (mut w, _, _) = world("E");
        let tray = *w.pick_tray();
        let outside = tray.world_from_tray * Isometry3::translation(0.0, tray.half_xy_m[1] + 0.04, 0.05);
        let stray = w.add_part(&outside);
        let opts = PileOptions::new(6, 3);
        let opts = if lose { opts.losing_spilled() } else { opts };
        let built = w.build_pile(&opts);
        (w, stray, built)
    };
    let (w, stray, built) = spill(true);
    let report = built.expect("the pour goes on");
    assert_eq!(report.spilled.len(), 1, "{:?}", report.spilled);
    assert!(matches!(report.spilled[0], HealthEvent::LeftVolume { .. }));
    assert_eq!(w.part_state(stray), binpick::physics::PartState::Removed);
    assert_eq!(report.in_tray, 6);
    let (_, _, built) = spill(false);
    let err = built.expect_err("the pour ends on the spill");
    assert!(
        err.events.iter().any(|e| matches!(e, HealthEvent::LeftVolume { .. })),
        "{err}"
    );
}

/// What a part lying across the held part weighs on the cup: two C strips, one held by the cup at
/// its middle 5 cm above the tray, the other laid across it a lever away from the cup. The
/// solver's contact impulses, read as a force and its moment about the cup centre, carry the
/// upper strip's weight (checked against m g and the lever measured from the two bodies' poses,
/// not from the contacts). The cup holds it 2 cm out, and the same strip 6 cm out peels the held
/// one off: each case's need, |F| + 4 |M| / d over the held strip's own, is worked out here
/// against the holding force, one below and one above it (`gripper.seal_loaded_by_parts` on).
/// Negative controls: nothing on the held strip, no load; the key off, the strip 6 cm out stays.
#[test]
fn a_part_lying_across_the_held_part_loads_the_cup_with_its_weight_and_peels_it_far_out() {
    let held_and_loaded = |lever_m: Option<f64>, loaded: bool| {
        let mut scene = LoadedScene::embedded_default().unwrap();
        scene.scene.gripper.seal_loaded_by_parts = loaded;
        let robot = RobotModel::from_scene(&scene).unwrap();
        let wp = LoadedWorkpiece::resolve("C").unwrap();
        let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
        let mut w = World::new(&scene.scene, &robot, shape);
        let top = lone_part(&mut w, 0.005, (0.0, 0.0), UnitQuaternion::identity());
        let ev = grasp_at(&mut w, tool_down_pose(top, 0.0));
        assert!(matches!(ev, GripperEvent::Grasped { .. }), "{ev:?}");
        let lifted = tool_down_pose(top + Vector3::z() * 0.05, 0.0);
        w.move_tool_line(&lifted, 0.5).unwrap();
        let upper = lever_m.map(|dx| {
            let held = w.part_pose(0);
            let at = held.translation.vector + held.rotation * Vector3::new(dx, 0.0, 0.0055);
            let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
            w.add_part(&Isometry3::from_parts(Translation3::from(at), held.rotation * turn))
        });
        w.run_for(0.3).unwrap();
        (w, wp.workpiece.mass_kg, upper)
    };
    let weight_n = |mass_kg: f64| mass_kg * binpick::robot::GRAVITY_M_S2;
    // Negative control: nothing on it.
    let (w, _, _) = held_and_loaded(None, true);
    let load = w.held_contact_load().expect("held");
    assert!(load.force_n.norm() < 1e-6, "{load:?}");
    // 2 cm out: the weight, straight down, its moment the weight times the lever across the cup
    // axis; the cup holds.
    let (w, mass_kg, upper) = held_and_loaded(Some(0.02), true);
    let upper = upper.unwrap();
    let (wn, cup) = (weight_n(mass_kg), w.world_from_tool().translation.vector);
    let load = w.held_contact_load().expect("held");
    assert!(
        (load.force_n - Vector3::new(0.0, 0.0, -wn)).norm() < 0.05 * wn,
        "{load:?} against {wn} N"
    );
    let lever = w.part_pose(upper).translation.vector - cup;
    assert!((lever.x - 0.02).abs() < 0.002 && w.part_pose(upper).translation.z > w.part_pose(0).translation.z);
    let moment = Vector3::new(lever.x, lever.y, 0.0).cross(&Vector3::new(0.0, 0.0, -wn));
    assert!(
        (load.moment_nm - moment).norm() < 0.1 * moment.norm(),
        "{load:?} against {moment}"
    );
    let (d_m, holding_n) = (2.0 * w.gripper().cup_radius_m, w.gripper().holding_n);
    let need = |lever_m: f64| 2.0 * wn + 4.0 * wn * lever_m / d_m;
    assert!(need(0.02) < holding_n, "{} N, {holding_n} N", need(0.02));
    assert_eq!(w.held_part(), Some(0));
    // 6 cm out: more than the cup holds, and the held strip tears off.
    assert!(need(0.06) > holding_n, "{} N, {holding_n} N", need(0.06));
    let (mut w, _, _) = held_and_loaded(Some(0.06), true);
    assert!(w.held_part().is_none());
    assert!(
        w.take_gripper_events()
            .iter()
            .any(|e| matches!(e, GripperEvent::Slipped { part: 0, .. })),
        "no slip"
    );
    // With the cell's key off, the seal sees no load and the strip stays on the cup.
    let (w, _, _) = held_and_loaded(Some(0.06), false);
    assert_eq!(w.held_part(), Some(0));
    assert_eq!(w.held_contact_load().map(|l| l.force_n.norm()), Some(0.0));
}

/// A double pick: a C strip lying across the held strip, carried with it out over the pick
/// tray's wall, leaves the tray with the part on the cup, as the health monitor reports it (the
/// cell counts it lost, carried with the held part). Negative controls: the strip carried out
/// with nothing on it reports nothing, and a part that leaves the tray far from the held one
/// (put down on the table) is not reported as gone with it.
#[test]
fn a_part_carried_out_on_the_held_part_is_reported_as_gone_with_it() {
    let carried_out = |with_upper: bool| {
        let (mut w, _, _) = world("C");
        let top = lone_part(&mut w, 0.005, (0.0, 0.0), UnitQuaternion::identity());
        let ev = grasp_at(&mut w, tool_down_pose(top, 0.0));
        assert!(matches!(ev, GripperEvent::Grasped { .. }), "{ev:?}");
        let lifted = top + Vector3::z() * 0.08;
        w.move_tool_line(&tool_down_pose(lifted, 0.0), 0.5).unwrap();
        if with_upper {
            let held = w.part_pose(0);
            let at = held.translation.vector + held.rotation * Vector3::new(0.02, 0.0, 0.0055);
            let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
            assert_eq!(
                w.add_part(&Isometry3::from_parts(Translation3::from(at), held.rotation * turn)),
                1
            );
            w.run_for(0.3).unwrap();
        }
        // Out over the wall along the tray's y (inner half 120 mm), slowly: 0.3 m/s^2 at most.
        let out = lifted + w.pick_tray().world_from_tray.rotation * Vector3::new(0.0, -0.22, 0.0);
        let result = w.move_tool_line(&tool_down_pose(out, 0.0), 2.0);
        (w, result)
    };
    let (w, result) = carried_out(true);
    let Err(binpick::physics::script::ScriptError::Health(report)) = result else {
        panic!("the strip on the held one did not leave the tray: {result:?}")
    };
    assert_eq!(w.held_part(), Some(0), "{report}");
    match report.first() {
        Some(HealthEvent::LeftVolume {
            body,
            volume,
            with_held,
            ..
        }) => {
            assert_eq!((body.as_str(), *volume, *with_held), ("part 1", "pick tray", true));
        }
        other => panic!("{other:?}"),
    }
    assert!(
        report
            .to_string()
            .contains("left the pick tray volume with the part on the cup"),
        "{report}"
    );
    // Nothing on it: the held strip goes out alone, nothing reported.
    let (w, result) = carried_out(false);
    assert!(result.is_ok(), "{result:?}");
    assert_eq!(w.held_part(), Some(0));
    // A part on the table while the cup holds one: left the tray, but not with the held part.
    let (mut w, _) = carried_out(false);
    w.add_part(&Isometry3::translation(-0.3, -0.3, 0.01));
    match w.step().unwrap_err().first() {
        Some(HealthEvent::LeftVolume { body, with_held, .. }) => {
            assert_eq!((body.as_str(), *with_held), ("part 1", false))
        }
        other => panic!("{other:?}"),
    }
}

/// What a neighbour the held part drives sideways puts on the cup: a B block held on its top by
/// its own 16 mm cup, 2 mm off the floor, moved sideways into a second block 15 mm away. The
/// contacts' push is across the cup's axis: pushing the block along the floor, the held block
/// feels the floor's friction on it (mu m g, from the workpiece file, within a factor of 3) against
/// its motion, and hardly any pull; driven on until the second block is jammed against the
/// tray's wall, the push's shear and peel tear the held block off (`gripper.seal_loaded_by_parts`
/// on). Before 2026-12-06 the seal counted only a contact's pull along the axis, and a push
/// across it not at all: neither the load nor the tear-off. Negative controls: nothing in the
/// way, no load and the block stays; the key off, the jam leaves it on the cup.
#[test]
fn a_neighbour_pushed_sideways_shears_the_cup_and_a_jam_tears_the_held_part_off() {
    // The world after the push, the largest load against the motion and pull seen during it
    // (N), the block's mass and friction coefficient.
    let pushed = |neighbour: bool, jam: bool, loaded: bool| {
        let mut scene = LoadedScene::embedded_default().unwrap();
        scene.scene.gripper.seal_loaded_by_parts = loaded;
        // B's own 16 mm cup (its workpiece file's).
        scene.scene.gripper.cup_diameter_m = 0.016;
        let robot = RobotModel::from_scene(&scene).unwrap();
        let wp = LoadedWorkpiece::resolve("B").unwrap();
        let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
        let mut w = World::new(&scene.scene, &robot, shape);
        // The held block 0.03 m from the tray's centre toward its +y wall (0.12 m): the second
        // block, 15 mm beyond it, then has 0.03 m to the wall.
        let y0 = 0.03;
        let top = lone_part(&mut w, 0.020, (0.0, y0), UnitQuaternion::identity());
        if neighbour {
            lone_part(&mut w, 0.020, (0.0, y0 + 0.045), UnitQuaternion::identity());
        }
        let ev = grasp_at(&mut w, tool_down_pose(top, 0.0));
        assert!(matches!(ev, GripperEvent::Grasped { .. }), "{ev:?}");
        let up = top + Vector3::z() * 0.002;
        let toward_wall = w.pick_tray().world_from_tray.rotation * Vector3::y();
        w.move_tool_line(&tool_down_pose(up, 0.0), 0.2).unwrap();
        // 25 mm toward the wall at a steady 20 mm/s: the 15 mm gap closed, then the second
        // block pushed 10 mm. The load against the motion, its largest over the push.
        let start = w.world_from_tool();
        let n = (0.025 / 0.02 / w.dt_s()).ceil() as usize;
        let mut against_max_n: f64 = 0.0;
        let mut pull_max_n: f64 = 0.0;
        for k in 1..=n {
            let pose = Isometry3::from_parts(
                Translation3::from(start.translation.vector + toward_wall * (0.025 * k as f64 / n as f64)),
                start.rotation,
            );
            let q = w.robot().ik_tool_nearest(&pose, &w.joints()).unwrap();
            w.set_joint_target(&q.q);
            w.step().unwrap();
            if let Some(l) = w.held_contact_load() {
                against_max_n = against_max_n.max(-l.force_n.dot(&toward_wall));
                pull_max_n = pull_max_n.max(l.force_n.z.abs());
            }
        }
        if jam {
            // On until the second block meets the wall (20 mm on), and 5 mm into it.
            let _ = w.move_tool_line(&tool_down_pose(up + toward_wall * 0.050, 0.0), 1.5);
        }
        (
            w,
            [against_max_n, pull_max_n],
            wp.workpiece.mass_kg,
            wp.workpiece.friction,
        )
    };
    // Negative control: nothing in the way.
    let (w, load, _, _) = pushed(false, false, true);
    assert_eq!(w.held_part(), Some(0));
    assert!(load[0] < 1e-6 && load[1] < 1e-6, "{load:?}");
    // Pushing the block along the floor: a load across the axis, against the motion.
    let (w, [against_n, pull_n], mass_kg, friction) = pushed(true, false, true);
    assert_eq!(w.held_part(), Some(0), "the cup holds a block pushed along the floor");
    let sliding_n = friction * mass_kg * binpick::robot::GRAVITY_M_S2;
    assert!(
        against_n > sliding_n / 3.0 && against_n < 3.0 * sliding_n,
        "{against_n} N against mu m g = {sliding_n} N"
    );
    assert!(pull_n < 0.5 * against_n, "{pull_n} N: the push is across the axis");
    // Into the jam: torn off.
    let (mut w, _, _, _) = pushed(true, true, true);
    assert!(w.held_part().is_none(), "the jam's push tears the block off");
    assert!(
        w.take_gripper_events()
            .iter()
            .any(|e| matches!(e, GripperEvent::Slipped { part: 0, .. })),
        "no slip"
    );
    // The key off: the seal sees no load, and the jam leaves the block on the cup.
    let (w, _, _, _) = pushed(true, true, false);
    assert_eq!(w.held_part(), Some(0));
}

/// D lying on its side on the floor, with the cell's tool given a 4 mm cup that seals on round
/// surfaces of `round_min_radius_m` and up (`None`: a cup for flat faces); the grasp on the top
/// line of its can, over the part's centre of mass along the can's axis.
fn grasp_on_a_lying_can(round_min_radius_m: Option<f64>) -> GripperEvent {
    let scene = LoadedScene::embedded_default().unwrap();
    let mut cell = scene.scene.clone();
    cell.gripper.cup_diameter_m = 0.004;
    cell.gripper.round_min_radius_m = round_min_radius_m;
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("D").unwrap();
    let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let mut w = World::new(&cell, &robot, shape);
    let tray = w.pick_tray().world_from_tray;
    let lying = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    let i = w.add_part(&(tray * Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.0056), lying)));
    w.run_for(0.5).unwrap();
    let p = w.part_pose(i);
    let axis = p.rotation * Vector3::z();
    assert!(axis.z.abs() < 0.05, "D lies on its side: axis {axis:?}");
    let up = (Vector3::z() - axis * axis.z).normalize();
    // The can (radius 5 mm, centred 0.75 mm up its axis) at the centre of mass's station.
    let top = p.translation.vector + up * 0.005;
    grasp_at(&mut w, tool_down_pose(top, 0.0))
}

#[test]
fn a_cup_that_seals_on_round_surfaces_takes_a_lying_can_and_a_flat_cup_does_not() {
    let ev = grasp_on_a_lying_can(Some(0.004));
    assert!(matches!(ev, GripperEvent::Grasped { .. }), "{ev:?}");
    // Negative control: the same 4 mm cup for flat faces only; its lip needs one flat face, and
    // the can's top facet (a 16-sided prism's, under 2 mm) is narrower than the cup.
    match grasp_on_a_lying_can(None) {
        GripperEvent::GraspFailed {
            reason: GraspFailure::FaceTooSmall { width_mm, .. },
            ..
        } => assert!(width_mm < 2.0, "{width_mm}"),
        other => panic!("{other:?}"),
    }
}
