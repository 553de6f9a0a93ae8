//! The torque-limited servo: optimised motions on planned paths execute within the tracking
//! tolerance (also with a payload the controller does not know), and an overload trips a
//! protective stop.

use crate::support::{demand_check, planned_fig5_paths};
use binpick::config::LoadedScene;
use binpick::robot::{JointVector, Payload, RobotModel};
use binpick::servo::{Servo, Trip, execute};
use binpick::trajectory::{MotionLimits, TORQUE_DT_S, TORQUE_THRESHOLD, Trajectory, optimise_accelerations, torques};

#[test]
fn optimised_motions_execute_within_tolerance_and_an_overload_trips_a_protective_stop() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let servo = Servo::from_config(&scene.scene.sim);
    let hand = Payload::from_gripper(&scene.scene.gripper);
    let held = hand.combined(&Payload::point(0.03, robot.flange_from_tool.translation.vector));
    for (case, via) in planned_fig5_paths(&scene, &robot) {
        let plant = robot.dynamics(&held);
        // Planned within the cell's torque margin, as the cycle plans (with the caps lifted, a
        // motion at the full limit leaves the feedback no headroom).
        let planner = robot.with_torque_share(1.0 - binpick::config::DEFAULT_TORQUE_MARGIN);
        let motion =
            optimise_accelerations(&planner, &planner.dynamics(&held), &via, TORQUE_DT_S, TORQUE_THRESHOLD).trajectory;
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
            // What the controller demanded (before saturation) stays within the limits.
            let check = demand_check(&robot, &servo, &run.ticks);
            assert!(check.is_ok(), "{}: {check:?}", case.name);
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

/// Negative control of the torque check: a motion built to need 120 % of a joint's torque (the
/// planned path timed with every joint's acceleration raised until the model's peak torque
/// reaches 120 % of a limit) is caught: the servo reports the demand beyond the limit and the
/// time saturated, trips a protective stop, and the demand check fails. A check on the applied
/// (clamped) torques would have passed: it cannot fail.
#[test]
fn a_motion_needing_120_percent_of_a_torque_limit_is_caught() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let servo = Servo::from_config(&scene.scene.sim);
    let hand = Payload::from_gripper(&scene.scene.gripper);
    let held = hand.combined(&Payload::point(0.03, robot.flange_from_tool.translation.vector));
    let dynamics = robot.dynamics(&held);
    let (case, via) = planned_fig5_paths(&scene, &robot).remove(0);
    let timed = |scale: f64| {
        let t = Trajectory::through(
            &via,
            &MotionLimits {
                vel_rad_s: robot.max_vel_rad_s(),
                accel_rad_s2: robot.max_accel_rad_s2() * scale,
            },
        );
        let need = torques(&dynamics, &robot, &t.samples(TORQUE_DT_S), TORQUE_DT_S)
            .peak_ratio
            .iter()
            .cloned()
            .fold(0.0, f64::max);
        (t, need)
    };
    let mut scale = 1.0;
    while timed(scale).1 < 1.2 && scale < 10.0 {
        scale *= 1.02;
    }
    let (trajectory, needed) = timed(scale);
    assert!(
        (1.2..1.3).contains(&needed),
        "{}: the motion needs {needed:.3} of a limit",
        case.name
    );
    let run = execute(&robot, &dynamics, &dynamics, &servo, &trajectory);
    let demand = run.peak_demand_ratio.iter().cloned().fold(0.0, f64::max);
    assert!(demand > 1.05, "{}: peak demand reported {demand:.3}", case.name);
    assert!(run.saturated_ticks > 0, "{}: no saturation reported", case.name);
    assert!(run.trip.is_some(), "{}: no protective stop", case.name);
    let check = demand_check(&robot, &servo, &run.ticks);
    assert!(check.is_err(), "{}: the demand check passed: {check:?}", case.name);
    // The applied torques are clamped: a check on them cannot see the overload.
    let limit = robot.torque_limit_nm();
    assert!(
        run.ticks
            .iter()
            .all(|t| (0..6).all(|i| t.tau_nm[i].abs() <= limit[i] + 1e-9))
    );
}
