//! Derives which link pairs of the arm the planner must check for self-collision
//! (`planning::SELF_PAIRS`): every non-adjacent pair that can come within reach over the joint
//! ranges, measured on the exact shapes (the URDF primitives, the hand's cylinders, and the
//! envelope of any held part), independent of the planner's spheres.
//!
//! Method: the relative pose of links a < b depends only on the joints between them (0-based
//! a..b). J1 is left out for the base, a cylinder about J1's axis; J6 for link 6, whose flange, hand
//! and held-part envelopes are all solids of revolution about J6's axis. The remaining joints'
//! box of ranges (a range over a full turn cut to one turn: the pose is periodic) is searched by
//! branch and bound: at a sub-box's centre the exact distance d between the two links' shapes is
//! measured (parry); the distance is Lipschitz in the joints: moving joint i by dq moves link b's
//! points relative to link a by at most r_i |dq|, r_i the chain's offsets from joint i to link b
//! plus link b's reach from its origin, so inside the sub-box it is at least d less
//! sum_i r_i w_i / 2 (w_i the sub-box widths). A sub-box with d above that slack is proved clear;
//! one whose centre intersects proves the pair can meet (the search stops there); otherwise it is
//! split in two across its widest (in metres) joint, down to a slack of `TOLERANCE_M`, below which
//! the pair is reported as coming within that tolerance (it belongs in the set: it comes inside
//! the planner's margin). A pair whose whole box is proved clear cannot meet anywhere.
//! Adjacent pairs share a joint housing and are not candidates, except link 5 against the hand
//! and the held part (their flange excluded), reported separately.
//!
//! The held part: for every shipped workpiece and every face the cup can grasp (both extents at
//! least the cup's diameter plus twice the face margin), a cylinder about the tool axis from the
//! cup lip as deep as the part along that face's normal, with the radius of the part's bounding
//! box across it plus 2 mm for the recognised pose's error: all of them at once, on link 6.
//!
//! Units: m, rad (degrees printed). Frames: link frames, the base at the origin.
//!
//! Run: `cargo run --release --example derive_self_pairs` (with `DEBUG_PAIRS=1`, the intersecting
//! shapes are printed to stderr).

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::grasp::GraspSelector;
use binpick::planning::SELF_PAIRS;
use binpick::robot::{DOF, JointVector, LinkPrimitive, RobotModel};
use nalgebra::{Isometry3, Vector3};
use rapier3d::parry::query::distance;
use rapier3d::parry::shape::SharedShape;

/// Sub-boxes are split down to this Lipschitz slack [m].
const TOLERANCE_M: f64 = 0.0002;
/// Radius added to a held part's envelope for the recognised pose's error [m].
const HELD_POSE_SLACK_M: f64 = 0.002;
/// Workpieces shipped with the cell.
const WORKPIECES: [&str; 7] = ["A", "B", "C", "D", "E", "F", "workpieces/capacitor-radial.toml"];

/// An exact shape in its link's frame, with the radius of a sphere about the link origin that
/// contains it [m].
#[derive(Clone)]
struct Piece {
    link_from_shape: Isometry3<f64>,
    shape: SharedShape,
    reach_m: f64,
}

/// A cylinder about z of radius `r` and half length `h` centred at `at`.
fn cylinder(at: Isometry3<f64>, r: f64, h: f64) -> Piece {
    Piece {
        link_from_shape: at * Isometry3::rotation(Vector3::x() * std::f64::consts::FRAC_PI_2),
        shape: SharedShape::cylinder(h as f32, r as f32),
        reach_m: at.translation.vector.norm() + r.hypot(h),
    }
}

/// The URDF shapes of every link.
fn links(robot: &RobotModel) -> Vec<Vec<Piece>> {
    robot
        .links
        .iter()
        .map(|l| {
            l.shapes
                .iter()
                .map(|s| match s.primitive {
                    LinkPrimitive::Box { half_extents_m: h } => Piece {
                        link_from_shape: s.link_from_shape,
                        shape: SharedShape::cuboid(h.x as f32, h.y as f32, h.z as f32),
                        reach_m: s.link_from_shape.translation.vector.norm() + h.norm(),
                    },
                    LinkPrimitive::Cylinder {
                        radius_m,
                        half_length_m,
                    }
                    | LinkPrimitive::Capsule {
                        radius_m,
                        half_length_m,
                    } => {
                        // A capsule is inside the cylinder as long as it plus its end caps.
                        let h = match s.primitive {
                            LinkPrimitive::Capsule { .. } => half_length_m + radius_m,
                            _ => half_length_m,
                        };
                        cylinder(s.link_from_shape, radius_m, h)
                    }
                    LinkPrimitive::Sphere { radius_m } => Piece {
                        link_from_shape: s.link_from_shape,
                        shape: SharedShape::ball(radius_m as f32),
                        reach_m: s.link_from_shape.translation.vector.norm() + radius_m,
                    },
                })
                .collect()
        })
        .collect()
}

/// The hand's cylinders in the flange frame.
fn hand(scene: &LoadedScene) -> Vec<Piece> {
    binpick::geometry::HandGeometry::new(&scene.scene.gripper)
        .cylinders()
        .iter()
        .map(|&(r, z0, z1)| cylinder(Isometry3::translation(0.0, 0.0, (z0 + z1) / 2.0), r, (z1 - z0) / 2.0))
        .collect()
}

/// The held parts' envelopes in the flange frame (see the header), with a description.
fn held_envelopes(robot: &RobotModel, scene: &LoadedScene) -> anyhow::Result<(Vec<Piece>, Vec<String>)> {
    let lip = robot.flange_from_tool.translation.vector.z;
    let need = |wp: &LoadedWorkpiece| {
        scene.scene.gripper.cup_diameter_m
            + 2.0 * (wp.workpiece.grasp.face_margin_m + 2.0 * scene.scene.sensor.pose_noise_m)
    };
    let mut out = Vec::new();
    let mut what = Vec::new();
    for name in WORKPIECES {
        let wp = if name.ends_with(".toml") {
            LoadedWorkpiece::resolve(&format!("{}/{name}", env!("CARGO_MANIFEST_DIR")))?
        } else {
            LoadedWorkpiece::resolve(name)?
        };
        let sel = GraspSelector::for_workpiece(&scene.scene, robot, &wp);
        let size = wp.workpiece.size_m;
        for f in sel.faces() {
            if f.extent_m[0].min(f.extent_m[1]) < need(&wp) {
                continue;
            }
            let k = f.normal.iamax();
            let depth = size[k];
            let across: f64 = (0..3)
                .filter(|&i| i != k)
                .map(|i| size[i] * size[i])
                .sum::<f64>()
                .sqrt()
                / 2.0;
            let r = across + HELD_POSE_SLACK_M;
            out.push(cylinder(
                Isometry3::translation(0.0, 0.0, lip + depth / 2.0),
                r,
                depth / 2.0,
            ));
            what.push(format!("{name}: {:.0} mm deep, r {:.1} mm", depth * 1e3, r * 1e3));
        }
    }
    what.sort();
    what.dedup();
    Ok((out, what))
}

/// Smallest exact distance between two shape sets on links a and b at `q` (0 when they
/// intersect) [m].
fn pair_distance(robot: &RobotModel, a: (usize, &[Piece]), b: (usize, &[Piece]), q: &JointVector) -> f64 {
    let frames = robot.world_from_links(q);
    let mut best = f64::INFINITY;
    for pa in a.1 {
        let wa: rapier3d::math::Pose = (frames[a.0] * pa.link_from_shape).cast::<f32>().into();
        for pb in b.1 {
            let wb: rapier3d::math::Pose = (frames[b.0] * pb.link_from_shape).cast::<f32>().into();
            let d = distance(&wa, &*pa.shape, &wb, &*pb.shape).map_or(0.0, |d| d.distance as f64);
            if std::env::var("DEBUG_PAIRS").is_ok() && d <= 0.0 {
                eprintln!(
                    "{} {:?} {} {:?} at {:?}",
                    a.0,
                    pa.link_from_shape.translation,
                    b.0,
                    pb.link_from_shape.translation,
                    q.map(f64::to_degrees)
                );
            }
            best = best.min(d);
        }
    }
    best
}

/// What the branch and bound found for one pair.
enum Verdict {
    /// The shapes intersect at this configuration.
    Meet(JointVector),
    /// They come within [`TOLERANCE_M`] of touching near this configuration (distance there).
    Within(JointVector, f64),
    /// Proved apart everywhere; the smallest distance measured, where.
    Apart(f64, JointVector),
}

/// Branch and bound over `joints` (0-based) for links a and b (see the header). Returns the
/// verdict and the number of distance evaluations.
fn decide(robot: &RobotModel, a: (usize, &[Piece]), b: (usize, &[Piece]), joints: &[usize]) -> (Verdict, usize) {
    let reach = b.1.iter().map(|p| p.reach_m).fold(0.0, f64::max);
    let lever: Vec<f64> = joints
        .iter()
        .map(|&i| {
            robot.joints[(i + 1)..b.0]
                .iter()
                .map(|j| j.origin_pos_m.norm())
                .sum::<f64>()
                + reach
        })
        .collect();
    let full = std::f64::consts::TAU;
    let root: Vec<(f64, f64)> = joints
        .iter()
        .map(|&i| {
            let j = &robot.joints[i];
            (j.lower_rad, j.upper_rad.min(j.lower_rad + full))
        })
        .collect();
    let mut stack = vec![root];
    let (mut evals, mut min_d, mut min_at) = (0usize, f64::INFINITY, JointVector::zeros());
    while let Some(bx) = stack.pop() {
        let mut q = JointVector::zeros();
        for (k, &i) in joints.iter().enumerate() {
            q[i] = 0.5 * (bx[k].0 + bx[k].1);
        }
        let d = pair_distance(robot, a, b, &q);
        evals += 1;
        if d < min_d {
            (min_d, min_at) = (d, q);
        }
        if d <= 0.0 {
            return (Verdict::Meet(q), evals);
        }
        let spans: Vec<f64> = bx.iter().zip(&lever).map(|(r, l)| l * (r.1 - r.0)).collect();
        let slack = 0.5 * spans.iter().sum::<f64>();
        if d > slack {
            continue;
        }
        if slack < TOLERANCE_M {
            return (Verdict::Within(q, d), evals);
        }
        let k = (0..spans.len())
            .max_by(|&x, &y| spans[x].total_cmp(&spans[y]))
            .unwrap_or(0);
        let mid = 0.5 * (bx[k].0 + bx[k].1);
        let (mut lo, mut hi) = (bx.clone(), bx);
        lo[k].1 = mid;
        hi[k].0 = mid;
        stack.push(lo);
        stack.push(hi);
    }
    (Verdict::Apart(min_d, min_at), evals)
}

fn main() -> anyhow::Result<()> {
    let scene = LoadedScene::embedded_default()?;
    let robot = RobotModel::from_scene(&scene)?;
    let urdf = links(&robot);
    let hand = hand(&scene);
    let (envelopes, what) = held_envelopes(&robot, &scene)?;
    println!("held-part envelopes on the hand: {}", what.join("; "));
    println!();
    println!("| pair | on link 6 | joints searched | evaluations | verdict | where (deg) | in SELF_PAIRS |");
    println!("|---|---|---|---:|---|---|---|");
    let flange_hand: Vec<Piece> = urdf[DOF].iter().chain(&hand).cloned().collect();
    let flange_hand_held: Vec<Piece> = flange_hand.iter().chain(&envelopes).cloned().collect();
    let hand_held: Vec<Piece> = hand.iter().chain(&envelopes).cloned().collect();
    let mut meet = Vec::new();
    let n = robot.links.len();
    for a in 0..(n - 1) {
        let first = if a + 1 == DOF { DOF } else { a + 2 };
        for b in first..n {
            let sets: Vec<(&str, &[Piece])> = if b < DOF {
                vec![("", &urdf[b])]
            } else if a + 1 == b {
                vec![("hand", &hand), ("hand + held", &hand_held)]
            } else {
                vec![
                    ("flange + hand", &flange_hand),
                    ("flange + hand + held", &flange_hand_held),
                ]
            };
            for (label, set) in sets {
                let joints: Vec<usize> = (a.max(1)..b.min(DOF - 1)).collect();
                let (v, evals) = decide(&robot, (a, &urdf[a]), (b, set), &joints);
                let deg = |q: &JointVector| {
                    joints
                        .iter()
                        .map(|&i| format!("J{} {:.1}", i + 1, q[i].to_degrees()))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let (verdict, at, can) = match &v {
                    Verdict::Meet(q) => ("can meet".to_string(), deg(q), true),
                    Verdict::Within(q, d) => (format!("within {:.2} mm", d * 1e3), deg(q), true),
                    Verdict::Apart(d, q) => (format!("cannot meet (min {:.1} mm)", d * 1e3), deg(q), false),
                };
                if can && !meet.contains(&(a, b)) {
                    meet.push((a, b));
                }
                println!(
                    "| {a}-{b} | {label} | {} | {evals} | {verdict} | {at} | {} |",
                    joints
                        .iter()
                        .map(|i| format!("J{}", i + 1))
                        .collect::<Vec<_>>()
                        .join(" "),
                    if SELF_PAIRS.contains(&(a, b)) { "yes" } else { "no" },
                );
            }
        }
    }
    println!();
    println!("pairs that can meet: {meet:?}");
    let missing: Vec<_> = meet.iter().filter(|p| !SELF_PAIRS.contains(p)).collect();
    let extra: Vec<_> = SELF_PAIRS.iter().filter(|p| !meet.contains(p)).collect();
    println!("missing from SELF_PAIRS: {missing:?}; in SELF_PAIRS but cannot meet: {extra:?}");
    Ok(())
}
