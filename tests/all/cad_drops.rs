//! The part model's stable resting poses checked against the physics: CAD parts dropped one at a
//! time on the bare tray floor from uniformly random orientations
//! ([`binpick::physics::World::drop_trials`]) rest in the poses the model predicts, about as
//! often as it predicts (poses the shape cannot tell apart pooled, e.g. a hex prism's six flats).
//! The settled orientation is classified by the support normal nearest to the world's down
//! direction, an independent reading of the simulated pose.
//!
//! Negative control: the same drops against a model given a wrong centre of mass (moved within
//! the part) disagree beyond the bound, so the check catches a wrong model.

use nalgebra::Vector3;

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::part::PartModel;
use binpick::part::poses::{RestingPose, pose_classes, pose_resting_on, resting_poses};
use binpick::physics::drops::DropOptions;
use binpick::physics::{PartShape, World};
use binpick::robot::RobotModel;

/// How far the settled support normal may be from the predicted one (rad).
const CLASSIFY_TOL_RAD: f64 = 0.05;

/// The part model of a shipped CAD workpiece and the down direction (part frame) of each of
/// `count` drops.
fn drops(name: &str, count: usize, seed: u64) -> (PartModel, Vec<Vector3<f64>>) {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve(&format!("{}/workpieces/{name}.toml", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let mesh = &wp.mesh.as_ref().unwrap().0;
    let pm = wp
        .workpiece
        .part_model(mesh, scene.scene.gripper.cup_diameter_m)
        .unwrap();
    let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let mut world = World::new(&scene.scene, &robot, shape);
    let r = world.drop_trials(&DropOptions::new(count, seed)).unwrap();
    assert_eq!(r.rest_poses.len(), count);
    // A can on its side may still rock when a grid's settling time runs out; its support normal
    // is read all the same.
    assert_eq!(r.crowded, 0, "{name}: dropped parts met");
    let down = r
        .rest_poses
        .iter()
        .map(|p| p.rotation.inverse() * -Vector3::z())
        .collect();
    (pm, down)
}

/// Poses whose support normals are within this of each other are pooled (rad, 50 deg): the ways
/// a capacitor lies on its side (on its base plate's edges and corners, 45 deg apart), among
/// which a rolling can picks at random. Distinct poses of the parts here are 60 deg or more apart.
const POOL_RAD: f64 = 0.87;

/// Each pose's class: [`pose_classes`] (poses the support cannot tell apart), joined with every
/// class whose support normal lies within [`POOL_RAD`] of one of its own (single linkage),
/// numbered in the order of first appearance.
fn pooled(poses: &[RestingPose]) -> Vec<usize> {
    let mut class = pose_classes(poses);
    loop {
        let mut merged = false;
        for i in 0..poses.len() {
            for j in 0..poses.len() {
                if class[i] != class[j] && poses[i].normal.angle(&poses[j].normal) < POOL_RAD {
                    let (keep, gone) = (class[i].min(class[j]), class[i].max(class[j]));
                    class.iter_mut().filter(|c| **c == gone).for_each(|c| *c = keep);
                    merged = true;
                }
            }
        }
        if !merged {
            break;
        }
    }
    let mut order: Vec<usize> = Vec::new();
    class
        .iter()
        .map(|c| match order.iter().position(|o| o == c) {
            Some(k) => k,
            None => {
                order.push(*c);
                order.len() - 1
            }
        })
        .collect()
}

/// The total variation distance between the predicted pose-class shares of `poses` and the
/// observed shares of `down` (drops resting in no predicted pose form a class of their own,
/// predicted 0), with the table of both.
fn disagreement(poses: &[RestingPose], down: &[Vector3<f64>]) -> (f64, String) {
    let class = pooled(poses);
    let k = class.iter().max().map_or(0, |m| m + 1);
    let mut predicted = vec![0.0; k + 1];
    for (p, c) in poses.iter().zip(&class) {
        predicted[*c] += p.likelihood;
    }
    let mut seen = vec![0.0; k + 1];
    for d in down {
        match pose_resting_on(poses, d, CLASSIFY_TOL_RAD) {
            Some(i) => seen[class[i]] += 1.0,
            None => seen[k] += 1.0,
        }
    }
    let n = down.len() as f64;
    let mut table = String::new();
    let mut tv = 0.0;
    for c in 0..=k {
        let head = class.iter().position(|x| *x == c);
        let label = head.map_or("none".to_string(), |h| {
            format!("{:?}", poses[h].normal.map(|v| (v * 100.0).round() / 100.0).as_slice())
        });
        table += &format!(
            "  {label:<24} predicted {:5.1} %  dropped {:5.1} %\n",
            100.0 * predicted[c],
            100.0 * seen[c] / n
        );
        tv += 0.5 * (predicted[c] - seen[c] / n).abs();
    }
    (tv, table)
}

/// Drops per part.
const DROPS: usize = 160;

/// The most the predicted and dropped pose shares may differ (total variation distance) for
/// parts the quasi-static estimate describes: the hex standoff, the TO-220, the SMD capacitor.
const BOUND: f64 = 0.10;
/// The DIP-8's bound: its thin leads make it tip onto its back from its ends more often than the
/// quasi-static estimate says (measured: 63 % predicted on its back, 79 % dropped).
const BOUND_DIP8: f64 = 0.25;

#[test]
fn drops_rest_as_the_part_models_predict() {
    // (part, bound, a wrong centre of mass: shifted within the part (m)). The TO-220's 1.5 mm
    // up its thickness was caught while a pose counted as unstable below 1 % of the part's reach;
    // measured against the tip's own radius, that model keeps its side pose too and its shares
    // pass (0.060, as the right one's): 2 mm is caught (0.277).
    let cases = [
        ("hex-standoff", BOUND, [0.0, 0.0, 0.007]),
        ("to220", BOUND, [0.0, 0.0, 0.002]),
        ("smd-elcap", BOUND, [0.0, 0.0, 0.003]),
        ("dip8", BOUND_DIP8, [0.0, 0.0, -0.0015]),
    ];
    let mut failed = Vec::new();
    for (name, bound, shift) in cases {
        let (pm, down) = drops(name, DROPS, 1);
        let (tv, table) = disagreement(&pm.poses, &down);
        println!("{name}: disagreement {tv:.3} (bound {bound})\n{table}");
        if tv > bound {
            failed.push(format!("{name}: {tv:.3} > {bound}\n{table}"));
        }
        // Negative control: the model with the centre of mass moved is caught.
        let wrong = resting_poses(&pm.hull, &(pm.com_m() + Vector3::from(shift)));
        let (tv, table) = disagreement(&wrong, &down);
        println!("{name}, centre of mass moved by {shift:?} m: disagreement {tv:.3}\n{table}");
        if tv <= bound {
            failed.push(format!(
                "{name}: a wrong centre of mass {shift:?} passes ({tv:.3})\n{table}"
            ));
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}
