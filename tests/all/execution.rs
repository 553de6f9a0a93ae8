//! The torque-limited servo: optimised motions on planned paths execute within the tracking
//! tolerance (also with a payload the controller does not know), and an overload trips a
//! protective stop.

use crate::support::planned_fig5_paths;
use binpick::config::LoadedScene;
use binpick::execution::{Servo, Trip, execute};
use binpick::robot::{JointVector, Payload, RobotModel};
use binpick::trajectory::{MotionLimits, TORQUE_DT_S, TORQUE_THRESHOLD, Trajectory, optimise_accelerations};

#[test]
fn optimised_motions_execute_within_tolerance_and_an_overload_trips_a_protective_stop() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let servo = Servo::from_config(&scene.scene.sim);
    let hand = Payload::from_gripper(&scene.scene.gripper);
    let held = hand.combined(&Payload::point(0.03, robot.flange_from_tool.translation.vector));
    let limit = robot.torque_limit_nm();
    for (case, via) in planned_fig5_paths(&scene, &robot) {
        let plant = robot.dynamics(&held);
        let motion = optimise_accelerations(&robot, &plant, &via, TORQUE_DT_S, TORQUE_THRESHOLD).trajectory;
        // The controller knows the part, and then does not.
        for model in [robot.dynamics(&held), robot.dynamics(&hand)] {
            let run = execute(&robot, &model, &plant, &servo, &motion);
            assert!(run.trip.is_none(), "{}: tripped {:?}", case.name, run.trip);
            assert!(
                run.max_error_rad.iter().all(|e| *e < servo.tolerance_rad),
                "{}: error {:?}",
                case.name,
                run.max_error_rad
            );
            let last = run.ticks.last().unwrap();
            assert!(
                (last.q - via[via.len() - 1]).amax() < 1e-3,
                "{}: ends {:?} off",
                case.name,
                last.q - via[via.len() - 1]
            );
            for t in &run.ticks {
                for i in 0..6 {
                    assert!(t.tau_nm[i].abs() <= limit[i] + 1e-9);
                }
            }
        }
    }
    // Three times the specification acceleration with 4.4 kg on the tool: the drives cannot follow.
    let plant = robot.dynamics(&hand.combined(&Payload::point(4.4, robot.flange_from_tool.translation.vector)));
    let a = JointVector::new(1.2, -0.6, 2.4, 0.0, 0.8, 0.0);
    let b = JointVector::new(-1.2, -0.2, 2.0, 0.0, 0.8, 0.0);
    let brutal = MotionLimits {
        vel_rad_s: robot.max_vel_rad_s(),
        accel_rad_s2: robot.max_accel_rad_s2() * 3.0,
    };
    let run = execute(&robot, &plant, &plant, &servo, &Trajectory::through(&[a, b], &brutal));
    match run.trip {
        Some((t, Trip::Saturation { .. } | Trip::TrackingError { .. })) => assert!(t < 0.5, "tripped late, at {t}"),
        None => panic!("no protective stop"),
    }
}
