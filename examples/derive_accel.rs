//! Derives the default cell's specification accelerations (`robot.drives.max_accel_deg_s2`):
//! for each joint, 80 % of its torque limit over the largest diagonal joint-space inertia
//! (armature included) found over 200,000 seeded random in-limit postures, arm alone. Also prints
//! the same with a 5 kg payload (the conservative "default parameters" bound) for reference, and
//! the torque's own ceiling: the full limit over the smallest diagonal inertia found, the
//! acceleration the joint's inertia alone would allow at its lightest posture.
//!
//! The specification accelerations cap the planned motions only with `robot.drives.accel_cap =
//! "spec"`; by default (`"none"`) the motion accelerator raises each joint until its torque
//! binds, up to the same ceiling taken over the path's via points (`accel_top_rad_s2`).
//!
//! Run: `cargo run --release --example derive_accel`

use binpick::config::LoadedScene;
use binpick::robot::{JointVector, Payload, RobotModel};
use rand::{RngExt, SeedableRng};

fn main() -> anyhow::Result<()> {
    let scene = LoadedScene::embedded_default()?;
    let robot = RobotModel::from_scene(&scene)?;
    let bare = robot.dynamics(&Payload::none());
    let hand = Payload::from_gripper(&scene.scene.gripper);
    let max_payload = hand.combined(&Payload::point(
        5.0 - hand.mass_kg,
        robot.flange_from_tool.translation.vector,
    ));
    let loaded = robot.dynamics(&max_payload);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let (mut worst_bare, mut worst_loaded) = ([0.0f64; 6], [0.0f64; 6]);
    let mut lightest_bare = [f64::INFINITY; 6];
    for _ in 0..200_000 {
        let q = JointVector::from_fn(|i, _| rng.random_range(robot.joints[i].lower_rad..robot.joints[i].upper_rad));
        let (m0, m1) = (bare.mass_matrix(&q), loaded.mass_matrix(&q));
        for i in 0..6 {
            worst_bare[i] = worst_bare[i].max(m0[(i, i)]);
            worst_loaded[i] = worst_loaded[i].max(m1[(i, i)]);
            lightest_bare[i] = lightest_bare[i].min(m0[(i, i)]);
        }
    }
    println!(
        "joint  max_M_ii_kg_m2  0.8*tau/M_deg_s2   with_5kg: max_M_ii  0.8*tau/M_deg_s2   min_M_ii_kg_m2  tau/min_M_deg_s2"
    );
    for (i, j) in robot.joints.iter().enumerate() {
        let t = j.torque_limit_nm * 0.8;
        println!(
            "{:<6} {:14.3} {:17.0}   {:18.3} {:17.0}   {:14.3} {:16.0}",
            j.name,
            worst_bare[i],
            (t / worst_bare[i]).to_degrees(),
            worst_loaded[i],
            (t / worst_loaded[i]).to_degrees(),
            lightest_bare[i],
            (j.torque_limit_nm / lightest_bare[i]).to_degrees()
        );
    }
    Ok(())
}
