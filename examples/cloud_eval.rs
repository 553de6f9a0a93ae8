//! Evaluates recognition from the point cloud (`binpick::sensor::cloud`) on the default pile of
//! each workpiece: per workpiece (A-F, or workpiece files) over seeds 1-8, a settled pile, one
//! capture, recognition from the capture alone with the model the cell's sensor builds (a mesh
//! part's from its part model), then against the ground truth (evaluation only): recall of the
//! top layer, precision (a detection is right within 2 mm and 5 deg of a part, with the part's
//! symmetries), pose errors of the right ones (median and p95), compute time per capture (median
//! and max). `CLOUD_EVAL_VERBOSE=1` lists the wrong detections (`CLOUD_EVAL_POSES=1`: with the
//! poses), `CLOUD_EVAL_MISSED=1` the top-layer parts missed.
//!
//! Run: `cargo run --release --example cloud_eval [-- A workpieces/dip8.toml --seeds 4 --yaw-deg 12]`
//! (`--yaw-deg`: the yaw ambiguity accepted, as `sensor.max_yaw_ambiguity_deg`; default the
//! embedded cell's).

use std::time::Instant;

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::physics::{PartShape, World, pile::PileOptions};
use binpick::robot::RobotModel;
use binpick::sensor::{Camera, Sensor, capture, top_layer};

/// A detection is right within these of a part.
const RIGHT_M: f64 = 0.002;
const RIGHT_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;

fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut names: Vec<String> = Vec::new();
    let mut seeds = 8u64;
    let mut yaw_deg: Option<f64> = None;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--seeds" {
            seeds = it.next().and_then(|s| s.parse().ok()).unwrap_or(8);
        } else if a == "--yaw-deg" {
            yaw_deg = it.next().and_then(|s| s.parse().ok());
        } else {
            names.push(a.clone());
        }
    }
    if names.is_empty() {
        names = ["A", "B", "C", "D", "E", "F"].map(String::from).to_vec();
    }
    let scene = LoadedScene::embedded_default()?;
    let robot = RobotModel::from_scene(&scene)?;
    let camera = Camera::from_config(&scene.scene.sensor).ok_or_else(|| anyhow::anyhow!("degenerate camera"))?;
    println!(
        "wp  top  found  recall%  det  right  prec%   pos_med/p95_mm   rot_med/p95_deg   ms_med/max  (seeds 1..={seeds})"
    );
    for name in &names {
        let wp = LoadedWorkpiece::resolve(name)?;
        let mut sensor_cfg = scene.scene.sensor.clone();
        if let Some(y) = yaw_deg {
            sensor_cfg.max_yaw_ambiguity_deg = y;
        }
        let (mut top_n, mut top_found, mut det_n, mut right_n) = (0, 0, 0, 0);
        let (mut pos, mut rot, mut ms) = (Vec::new(), Vec::new(), Vec::new());
        let (mut wrong_rot, mut wrong_pos, mut wrong_rot_deg) = (0, 0, Vec::new());
        for seed in 1..=seeds {
            let shape = PartShape::build(&wp.workpiece, &wp.source)?;
            let mut world = World::new(&scene.scene, &robot, shape);
            world.build_pile(&PileOptions::new(wp.workpiece.pile_count as usize, seed))?;
            // The model as the cell's sensor builds it (a mesh workpiece's from its part model).
            let sensor = Sensor::new(&sensor_cfg, &world, seed, &wp.workpiece)
                .ok_or_else(|| anyhow::anyhow!("degenerate camera"))?;
            let cap = capture(&world, &camera, seed, 0);
            let t0 = Instant::now();
            let found = sensor.recognize_cloud(&cap);
            ms.push(t0.elapsed().as_secs_f64() * 1e3);
            // Ground truth, for evaluation only.
            let parts = world.parts_in_pick_tray();
            let top = top_layer(&world);
            let mut right_parts = std::collections::BTreeSet::new();
            for d in &found {
                let best = parts
                    .iter()
                    .map(|&i| (i, sensor.symmetry.pose_error(&world.part_pose(i), &d.world_from_part)))
                    .min_by(|a, b| (a.1.0 + a.1.1 * 0.01).total_cmp(&(b.1.0 + b.1.1 * 0.01)));
                det_n += 1;
                if let Some((i, (dp, dr))) = best
                    && dp <= RIGHT_M
                    && dr <= RIGHT_RAD
                {
                    right_n += 1;
                    right_parts.insert(i);
                    pos.push(dp * 1e3);
                    rot.push(dr.to_degrees());
                } else if let Some((bi, (dp, dr))) = best {
                    if dp <= RIGHT_M {
                        wrong_rot += 1;
                        wrong_rot_deg.push(dr.to_degrees());
                    } else {
                        wrong_pos += 1;
                    }
                    if std::env::var_os("CLOUD_EVAL_VERBOSE").is_some() {
                        eprintln!(
                            "{name} seed {seed}: wrong face {:?} score {:.2} vis {:.2}: {:.2} mm {:.1} deg",
                            d.face_up,
                            d.score,
                            d.visible_fraction,
                            dp * 1e3,
                            dr.to_degrees()
                        );
                        if std::env::var_os("CLOUD_EVAL_AXES").is_some() {
                            let z = nalgebra::Vector3::z();
                            let (a, b) = (d.world_from_part.rotation * z, world.part_pose(bi).rotation * z);
                            eprintln!("    z found {:.3?} truth {:.3?}", a.as_slice(), b.as_slice());
                        }
                        if std::env::var_os("CLOUD_EVAL_POSES").is_some() {
                            let show = |p: &nalgebra::Isometry3<f64>| {
                                let t = p.translation.vector * 1e3;
                                let (r, q, y) = p.rotation.euler_angles();
                                format!(
                                    "({:.1} {:.1} {:.1}) rpy ({:.0} {:.0} {:.0})",
                                    t.x,
                                    t.y,
                                    t.z,
                                    r.to_degrees(),
                                    q.to_degrees(),
                                    y.to_degrees()
                                )
                            };
                            eprintln!("    found {}", show(&d.world_from_part));
                            eprintln!("    truth {}", show(&world.part_pose(bi)));
                            for &j in &parts {
                                let p = world.part_pose(j);
                                if j != bi
                                    && (p.translation.vector - d.world_from_part.translation.vector).norm() < 0.03
                                {
                                    eprintln!("    other {}", show(&p));
                                }
                            }
                        }
                    }
                }
            }
            if std::env::var_os("CLOUD_EVAL_MISSED").is_some() {
                for &i in top.iter().filter(|i| !right_parts.contains(i)) {
                    let r = world.part_pose(i).rotation;
                    let tilt = [nalgebra::Vector3::x(), nalgebra::Vector3::y(), nalgebra::Vector3::z()]
                        .iter()
                        .map(|a| (r * a).z.abs().clamp(0.0, 1.0).acos().to_degrees())
                        .fold(f64::INFINITY, f64::min);
                    eprintln!("{name} seed {seed}: missed, tilt {tilt:.0} deg");
                }
            }
            top_n += top.len();
            top_found += top.iter().filter(|i| right_parts.contains(i)).count();
        }
        let (pm, pp) = (quantile(&mut pos, 0.5), quantile(&mut pos, 0.95));
        let (rm, rp) = (quantile(&mut rot, 0.5), quantile(&mut rot, 0.95));
        println!(
            "{name:<3} {top_n:>4} {top_found:>6} {:>8.1} {det_n:>4} {right_n:>6} {:>6.1}   {pm:>6.2} / {pp:>5.2}    {rm:>6.2} / {rp:>5.2}    {:>5.1} / {:>5.1}",
            100.0 * top_found as f64 / top_n.max(1) as f64,
            100.0 * right_n as f64 / det_n.max(1) as f64,
            quantile(&mut ms, 0.5),
            quantile(&mut ms, 1.0)
        );
        println!(
            "      wrong: {wrong_rot} by rotation only (median {:.1} deg), {wrong_pos} by position",
            quantile(&mut wrong_rot_deg, 0.5)
        );
    }
    Ok(())
}
