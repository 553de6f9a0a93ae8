//! Event-driven stepping: a sleeping part with the arm away is not solved (the step is quiet),
//! and the arm sweeping into it is (the negative control: a skipped step could not push it).

use binpick::config::{LoadedScene, LoadedWorkpiece, Stepping};
use binpick::physics::{PartShape, World};
use binpick::robot::{RobotModel, tool_down_pose};
use nalgebra::{Isometry3, Translation3, Vector3};

/// A world of F parts stepped as `stepping` says, with one part at rest on the pick tray floor
/// (asleep); returns the world and the part's top face centre (m).
fn resting_part(stepping: Stepping) -> (World, Vector3<f64>) {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("F").unwrap();
    let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let half_z = shape.half_extents_m.z;
    let mut w = World::new(&scene.scene, &robot, shape);
    w.set_stepping(stepping);
    let tray = w.pick_tray().world_from_tray;
    let i =
        w.add_part(&(tray * Isometry3::from_parts(Translation3::new(0.0, 0.0, half_z + 0.0005), Default::default())));
    for _ in 0..1500 {
        if w.part_sleeping(i) {
            break;
        }
        w.step().unwrap();
    }
    assert!(w.part_sleeping(i), "the part did not come to rest in 3 s");
    let p = w.part_pose(i);
    (w, p.translation.vector + p.rotation * Vector3::new(0.0, 0.0, half_z))
}

#[test]
fn a_sleeping_part_with_the_arm_away_is_not_solved_and_a_sweeping_arm_is() {
    let (mut w, top) = resting_part(Stepping::EventDriven);
    let before = w.part_pose(0);
    // The arm at home, far from the tray: every step is quiet, the clock runs, nothing moves.
    let (steps, quiet, t) = (w.steps(), w.quiet_steps(), w.time_s());
    w.run_for(0.2).unwrap();
    assert_eq!(w.steps() - steps, 100);
    assert_eq!(w.quiet_steps() - quiet, 100, "steps with nothing to move were solved");
    assert!((w.time_s() - t - 0.2).abs() < 1e-6);
    assert_eq!(w.part_pose(0), before);
    // The arm moving far from the part is quiet too, and queries see it where it went.
    let away = top + Vector3::new(-0.05, 0.0, 0.05);
    w.place_tool(&tool_down_pose(away, 0.0)).unwrap();
    let quiet = w.quiet_steps();
    w.move_tool_line(&tool_down_pose(away + Vector3::z() * 0.05, 0.0), 0.2)
        .unwrap();
    assert_eq!(w.quiet_steps() - quiet, 100);
    // A ray across the cup's lip (3 mm above the tool point) meets the cup where it is now; the
    // arm's colliders as they were before the move are 5 cm lower.
    let tool = w.world_from_tool().translation.vector;
    let hit = w
        .cast_ray(&(tool + Vector3::new(0.1, 0.0, 0.003)), &-Vector3::x(), 0.2, &|_| false)
        .expect("a ray across the cup");
    assert!(hit.tag.is_robot(), "{:?}", hit.tag);
    assert!(hit.distance_m > 0.07 && hit.distance_m < 0.1, "{:.4} m", hit.distance_m);
    // Negative control: the cup sweeps through the part's top millimetre from 50 mm away. The
    // first steps are quiet, the ones near the part are solved, and the part is pushed.
    let low = top - Vector3::z() * 0.001;
    w.place_tool(&tool_down_pose(low - Vector3::x() * 0.05, 0.0)).unwrap();
    let (steps, quiet) = (w.steps(), w.quiet_steps());
    w.move_tool_line(&tool_down_pose(low + Vector3::x() * 0.03, 0.0), 0.6)
        .unwrap();
    let (solved, skipped) = (w.steps() - steps - (w.quiet_steps() - quiet), w.quiet_steps() - quiet);
    assert!(skipped > 10, "no quiet step while the cup was far ({skipped})");
    assert!(solved > 10, "the sweep through the part was not solved ({solved})");
    let moved = (w.part_pose(0).translation.vector - before.translation.vector).norm();
    assert!(moved > 0.005, "the part moved only {:.2} mm", moved * 1e3);
}

#[test]
fn stepping_always_solves_every_step() {
    let (mut w, _) = resting_part(Stepping::Always);
    w.run_for(0.2).unwrap();
    assert_eq!(w.quiet_steps(), 0);
}
