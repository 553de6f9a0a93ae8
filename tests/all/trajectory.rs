//! Trajectories on planned paths: the accelerated motion re-checked at 1 kHz with torques from an
//! independent code path (Lagrange's equations by finite differences of the kinetic and potential
//! energy), and its position, speed and acceleration limits.

use binpick::bench::fig5_cases;
use binpick::config::LoadedScene;
use binpick::planning::{Algorithm, PlanOptions};
use binpick::robot::{DOF, DynamicsModel, JointVector, Payload, RobotModel};
use binpick::trajectory::{Trajectory, default_limits, optimise_accelerations};

/// Torques by Lagrange: d/dt(M q') - dT/dq + dV/dq + friction, with the time derivative and the
/// partials taken by central differences of the energy functions (not the RNEA).
fn lagrange_torques(d: &DynamicsModel, traj: &Trajectory, t: f64) -> JointVector {
    let h = 1e-6;
    let p = |t: f64| {
        let s = traj.sample(t);
        d.mass_matrix(&s.q) * s.qd
    };
    let s = traj.sample(t);
    let (ta, tb) = ((t - h).max(0.0), (t + h).min(traj.duration_s));
    let dpdt = (p(tb) - p(ta)) / (tb - ta);
    let e = 1e-6;
    JointVector::from_fn(|i, _| {
        let mut qa = s.q;
        let mut qb = s.q;
        qa[i] -= e;
        qb[i] += e;
        let dt_dq = (d.kinetic_energy(&qb, &s.qd) - d.kinetic_energy(&qa, &s.qd)) / (2.0 * e);
        let dv_dq = (d.potential_energy(&qb) - d.potential_energy(&qa)) / (2.0 * e);
        dpdt[i] - dt_dq + dv_dq + d.friction_nm(i, s.qd[i])
    })
}

#[test]
fn accelerated_motions_stay_within_torque_speed_and_position_limits_in_an_independent_check() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let hand = Payload::from_gripper(&scene.scene.gripper);
    let held = hand.combined(&Payload::point(0.03, robot.flange_from_tool.translation.vector));
    let limit = robot.torque_limit_nm();
    for (k, case) in fig5_cases(&scene.scene, &robot).unwrap().iter().enumerate() {
        let mut rng = binpick::rng::stream(k as u64, "planner");
        let plan = case
            .model
            .plan(
                &case.start,
                &case.goal,
                &PlanOptions {
                    algorithm: Algorithm::Ours,
                    ..PlanOptions::default()
                },
                &mut rng,
            )
            .unwrap();
        let via: Vec<JointVector> = plan.waypoints.iter().map(|q| JointVector::from(*q)).collect();
        for payload in [hand, held] {
            let dynamics = robot.dynamics(&payload);
            let fast = optimise_accelerations(&robot, &dynamics, &via, 0.001, 0.05);
            let slow = Trajectory::through(&via, &default_limits(&robot, &hand, 5.0, 20_000));
            assert!(
                fast.trajectory.duration_s < slow.duration_s,
                "{}: optimised {} s not faster than default {} s",
                case.name,
                fast.trajectory.duration_s,
                slow.duration_s
            );
            let n = (fast.trajectory.duration_s / 0.001).ceil() as usize;
            let mut worst = [0.0f64; DOF];
            for j in 0..=n {
                let t = (j as f64 * 0.001).min(fast.trajectory.duration_s);
                let s = fast.trajectory.sample(t);
                assert!(
                    robot.within_limits(&s.q, 1e-9),
                    "{}: position limit at t = {t}",
                    case.name
                );
                for i in 0..DOF {
                    assert!(
                        s.qd[i].abs() <= robot.joints[i].max_vel_rad_s + 1e-9,
                        "speed limit J{} at {t}",
                        i + 1
                    );
                    assert!(
                        s.qdd[i].abs() <= robot.joints[i].max_accel_rad_s2 + 1e-9,
                        "acceleration limit J{} at {t}",
                        i + 1
                    );
                }
                let tau = lagrange_torques(&dynamics, &fast.trajectory, t);
                let rnea = dynamics.inverse_dynamics(&s.q, &s.qd, &s.qdd);
                for i in 0..DOF {
                    worst[i] = worst[i].max(tau[i].abs() / limit[i]);
                    // The two code paths agree (away from the instants where the acceleration jumps).
                    assert!(
                        (tau[i] - rnea[i]).abs() < 0.02 * limit[i] + 0.5,
                        "J{} at {t}: Lagrange {} vs RNEA {}",
                        i + 1,
                        tau[i],
                        rnea[i]
                    );
                }
            }
            for (i, w) in worst.iter().enumerate() {
                // The optimiser leaves 5 % below the limit; the finite differences may add a little.
                assert!(
                    *w <= 1.0,
                    "{}: J{} torque reaches {:.3} of its limit",
                    case.name,
                    i + 1,
                    w
                );
            }
            assert!(
                fast.torques.peak_ratio.iter().any(|r| *r > 0.9),
                "{}: no joint near its limit: {:?}",
                case.name,
                fast.torques.peak_ratio
            );
        }
    }
}
