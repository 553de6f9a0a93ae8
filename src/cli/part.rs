//! `binpick part WORKPIECE [--scene S] [--json] [--svg FILE]`: what the cell will see and take of
//! a part, before a run: its part model (mass properties, planar faces with the cup-fit regions
//! for the cell's cup, stable resting poses with their likelihoods, symmetry, what the mesh
//! repair did), what a few simulated piles offer the cup and how well the cell's sensor (in the
//! workpiece's scan mode) recognises them, and an SVG picture of it with its grasp faces.
//!
//! Units: mm, g and degrees in the text and JSON (named in the keys); SI inside.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use serde_json::json;

use binpick::config::{ConfigError, LoadedScene, LoadedWorkpiece, Scene};
use binpick::part::PartModel;
use binpick::part::model::ModelFace;
use binpick::part::poses::RestingPose;
use binpick::part::repair::RepairReport;
use binpick::part::svg::CupSites;
use binpick::sensor::{RecognitionSummary, RecognitionTotals};

use super::{InputError, round};

/// Arguments of `binpick part`.
#[derive(Args)]
pub struct PartArgs {
    /// The workpiece: A ... F (embedded) or a workpiece file (a mesh or primitives).
    pub workpiece: String,
    /// Scene whose gripper the faces are fitted for (default: the embedded default cell).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Machine-readable JSON output.
    #[arg(long)]
    pub json: bool,
    /// Where the SVG picture is written (default: NAME.part.svg in the current folder).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Simulated piles (seeds 1..N, the workpiece's pile count each) from which the share of
    /// settled parts that offer a graspable face is measured (0: none).
    #[arg(long, default_value_t = 3)]
    pub piles: u64,
    /// Parts dropped one at a time on the bare tray floor (seed 1) to check the predicted
    /// resting poses against the physics (0: none).
    #[arg(long, default_value_t = 60)]
    pub drops: usize,
}

/// How far a dropped part's support may lie from a predicted pose's to count as resting in it
/// (rad): a few degrees, so a pose the collider turns by a facet (5 degrees and more) counts as
/// none.
const DROP_MATCH_RAD: f64 = 3.0 * std::f64::consts::PI / 180.0;
/// A part of a simulated pile counts in the predicted pose nearest its own (its up direction
/// against the pose's) within this (rad); one tilted farther lies propped up on others.
const PILE_POSE_MATCH_RAD: f64 = 20.0 * std::f64::consts::PI / 180.0;

/// An axis about which the part's symmetry has this order or more is round for the drops: a drop
/// turned about it onto a predicted pose counts in that pose (a can on its side rests on
/// whichever facet of its simplified collider comes down, all alike).
const DROP_ROUND_ORDER: u32 = 8;

/// Where parts dropped one at a time come to rest, against the predicted poses.
#[derive(Debug, Clone, Default)]
struct DropShare {
    /// Parts dropped.
    dropped: usize,
    /// Per predicted pose, in the part model's order: the drops resting in it.
    per_pose: Vec<usize>,
    /// Drops resting in none of them (no support within [`DROP_MATCH_RAD`]).
    in_none: usize,
    /// Their supports: the world's down in the part frame (unit).
    in_none_down: Vec<nalgebra::Vector3<f64>>,
    /// Drops that came to rest near another dropped part (they may have met).
    crowded: usize,
}

impl DropShare {
    fn share(&self, n: usize) -> f64 {
        if self.dropped == 0 {
            f64::NAN
        } else {
            n as f64 / self.dropped as f64
        }
    }
}

/// Drops `count` parts one at a time on the bare pick-tray floor from random orientations
/// ([`binpick::physics::World::drop_trials`], seed 1) and reads each settled part's support (the
/// world's down in the part frame) against the part model's predicted poses
/// ([`binpick::part::poses::pose_resting_on`]), or turned about a round axis of the part onto one
/// ([`DROP_ROUND_ORDER`]). Read from the simulated world: the physics' collider (a simplified
/// one: docs/model.md) against the file's hull.
fn drop_share(loaded: &LoadedScene, sim: Option<&Sim>, m: &PartModel, count: usize) -> Result<DropShare> {
    use binpick::physics::drops::DropOptions;
    let mut out = DropShare {
        per_pose: vec![0; m.poses.len()],
        ..DropShare::default()
    };
    let Some(sim) = sim.filter(|_| count > 0) else {
        return Ok(out);
    };
    let mut world = sim.world(loaded);
    let r = world.drop_trials(&DropOptions::new(count, 1))?;
    // The part's round axes (through the centre of mass: angles to them are what turning about
    // them keeps).
    let round: Vec<nalgebra::Vector3<f64>> = (0..3)
        .filter(|&a| m.symmetry.orders[a] >= DROP_ROUND_ORDER)
        .map(|a| nalgebra::Vector3::ith(a, 1.0))
        .collect();
    let about_round_axis = |down: &nalgebra::Vector3<f64>| {
        round
            .iter()
            .flat_map(|axis| {
                m.poses
                    .iter()
                    .enumerate()
                    .map(move |(i, p)| (i, (down.angle(axis) - p.normal.angle(axis)).abs()))
            })
            .filter(|(_, off)| *off <= DROP_MATCH_RAD)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    };
    for pose in &r.rest_poses {
        let down_in_part = pose.rotation.inverse() * -nalgebra::Vector3::z();
        match binpick::part::poses::pose_resting_on(&m.poses, &down_in_part, DROP_MATCH_RAD)
            .or_else(|| about_round_axis(&down_in_part))
        {
            Some(i) => out.per_pose[i] += 1,
            None => {
                out.in_none += 1;
                out.in_none_down.push(down_in_part);
            }
        }
    }
    out.dropped = r.rest_poses.len();
    out.crowded = r.crowded;
    Ok(out)
}

/// The cell's robot and the part's physics shape, built once for the simulated drops and piles.
struct Sim {
    robot: binpick::robot::RobotModel,
    shape: binpick::physics::PartShape,
}

impl Sim {
    fn new(loaded: &LoadedScene, wp: &LoadedWorkpiece) -> Result<Self> {
        Ok(Sim {
            robot: binpick::robot::RobotModel::from_scene(loaded)?,
            shape: binpick::physics::PartShape::build(&wp.workpiece, &wp.source)?,
        })
    }

    /// An empty cell with the part's shape.
    fn world(&self, loaded: &LoadedScene) -> binpick::physics::World {
        binpick::physics::World::new(&loaded.scene, &self.robot, self.shape.clone())
    }
}

/// What a few simulated piles offer the cup.
#[derive(Debug, Clone, Default)]
struct PileShare {
    /// Piles built.
    piles: u64,
    /// Parts settled inside the pick tray, over all piles.
    in_tray: usize,
    /// Of those, the parts with a grasp face up whose cup disc is uncovered.
    offered: usize,
    /// Piles still moving when the pour gave up waiting for them to settle
    /// ([`binpick::physics::pile::PileReport::settled`]).
    unsettled: u64,
    /// The pour's limit on settling, simulated (s).
    max_settle_s: f64,
    /// The cell's cloud recognition on one capture of each pile, against the truth (`None`
    /// when the cell's recognition is the oracle).
    recognition: Option<RecognitionTotals>,
    /// The same at twice the sensor's resolution over the same field of view (the scan mode a
    /// workpiece may choose), with that resolution; `None` where twice would exceed the cell's
    /// pixel bound or the recognition is the oracle.
    recognition_finer: Option<([u32; 2], RecognitionTotals)>,
    /// The cell's recognition by resting pose: per predicted pose (the part model's order), the
    /// top-layer parts lying in it ([`PILE_POSE_MATCH_RAD`]) and of those the ones found.
    by_pose: Vec<Found>,
    /// The same for top-layer parts in no predicted pose (propped up on others).
    by_pose_none: Found,
}

/// Top-layer parts, and of those the ones a correct detection found.
#[derive(Debug, Clone, Copy, Default)]
struct Found {
    found: usize,
    of: usize,
}

impl Found {
    fn add(&mut self, o: Found) {
        self.found += o.found;
        self.of += o.of;
    }
}

/// The predicted pose (index into `m.poses`) a part turned `world_from_part` rests in: the one
/// whose support is nearest the part's within [`PILE_POSE_MATCH_RAD`]
/// ([`binpick::part::poses::pose_resting_on`], as the drops are read).
fn pose_of(m: &PartModel, world_from_part: &nalgebra::Isometry3<f64>) -> Option<usize> {
    let down_in_part = world_from_part.rotation.inverse() * -nalgebra::Vector3::z();
    binpick::part::poses::pose_resting_on(&m.poses, &down_in_part, PILE_POSE_MATCH_RAD)
}

impl PileShare {
    fn share(&self) -> f64 {
        if self.in_tray == 0 {
            0.0
        } else {
            self.offered as f64 / self.in_tray as f64
        }
    }
}

/// Builds `piles` piles (seeds 1..=piles) and counts the settled parts in the tray that offer a
/// graspable face: a face that takes the cup looks up within `lean` (the cup's tilt, or the
/// tool's lean, `gripper.max_lean_deg`, where the cell sets one), and a vertical ray
/// from above at its cup-fit centre and at eight points of the cup's rim about it meets this part
/// first, within 1 mm of the face (nothing lies on the cup's disc). Each pile is also captured
/// once and recognised from the cloud, as the cell does, and the detections judged against the
/// parts' poses (`binpick sense`'s evaluation), and once more at twice the sensor's resolution.
/// Read from the simulated world: a prediction for the user, not a decision of the cell.
fn pile_share(
    loaded: &LoadedScene,
    wp: &LoadedWorkpiece,
    sim: Option<&Sim>,
    m: &PartModel,
    piles: u64,
    lean: f64,
    sites: &CupSites,
) -> Result<PileShare> {
    use binpick::physics::{Tag, pile::PileOptions};
    use nalgebra::{Point3, Vector3};
    let mut out = PileShare {
        by_pose: vec![Found::default(); m.poses.len()],
        ..PileShare::default()
    };
    let Some(sim) = sim.filter(|_| piles > 0) else {
        return Ok(out);
    };
    let cloud = loaded.scene.sensor.recognition == binpick::config::RecognitionMode::Cloud;
    let mut recognition = RecognitionTotals::default();
    let [w, h] = loaded.scene.sensor.resolution_px;
    let finer_px = [2 * w, 2 * h];
    let mut finer = (cloud && u64::from(finer_px[0]) * u64::from(finer_px[1]) <= binpick::config::MAX_SENSOR_PIXELS)
        .then(|| {
            let mode = binpick::config::ScanMode {
                resolution_px: Some(finer_px),
                depth_noise_at_1m_m: None,
            };
            (loaded.scene.sensor.with_mode(&mode), RecognitionTotals::default())
        });
    let r_cup = 0.5 * m.cup.diameter_m;
    // The cup's disc at each face's site, as the grasp selector puts it (a face whose approach
    // meets the part's own pins has none): its centre and eight rim points, in the part frame.
    let discs: Vec<(Vector3<f64>, Vec<Point3<f64>>)> = m
        .faces
        .iter()
        .zip(sites)
        .filter_map(|(f, site)| {
            let (c, _) = (*site)?;
            let pts = std::iter::once(c)
                .chain((0..8).map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / 8.0;
                    c + (f.face.u * a.cos() + f.face.v * a.sin()) * r_cup
                }))
                .collect();
            Some((f.face.normal, pts))
        })
        .collect();
    for seed in 1..=piles {
        let mut world = sim.world(loaded);
        let options = PileOptions::cells_first_pile(wp.workpiece.pile_count as usize, seed);
        out.max_settle_s = options.max_settle_s;
        out.unsettled += u64::from(!world.build_pile(&options)?.settled);
        if cloud {
            use binpick::sensor::{Sensor, TruthAtTrigger, capture, evaluate};
            let recognise = |config: &binpick::config::SensorConfig,
                             totals: &mut RecognitionTotals|
             -> Result<(TruthAtTrigger, Vec<bool>)> {
                let sensor = Sensor::new(config, &world, seed, &wp.workpiece)
                    .ok_or_else(|| anyhow::anyhow!("the sensor's pose is degenerate"))?;
                let c = capture(&world, &sensor.camera, seed, 0);
                let truth = TruthAtTrigger::take(&world, &sensor, &c);
                let report = evaluate(&truth, &sensor.recognize_cloud(&c), &sensor.symmetry);
                totals.add(&report);
                let mut found = vec![false; truth.world_from_part.len()];
                for m in report.matches.iter().flatten().filter(|m| m.correct) {
                    found[m.part] = true;
                }
                Ok((truth, found))
            };
            let (truth, found) = recognise(&loaded.scene.sensor, &mut recognition)?;
            for &i in &truth.top_layer {
                let this = Found {
                    found: usize::from(found[i]),
                    of: 1,
                };
                match pose_of(m, &truth.world_from_part[i]) {
                    Some(k) => out.by_pose[k].add(this),
                    None => out.by_pose_none.add(this),
                }
            }
            if let Some((config, totals)) = &mut finer {
                recognise(config, totals)?;
            }
        }
        let down = -Vector3::z();
        for i in world.parts_in_pick_tray() {
            out.in_tray += 1;
            let pose = world.part_pose(i);
            let offered = discs.iter().any(|(n, pts)| {
                (pose.rotation * n).z >= lean.cos()
                    && pts.iter().all(|p| {
                        let w = pose * p;
                        let origin = w.coords + Vector3::z() * 0.2;
                        world
                            .cast_ray(&origin, &down, 0.3, &|t: Tag| t.is_robot())
                            .is_some_and(|h| h.tag == Tag::Part(i as u32) && (h.distance_m - 0.2).abs() < 0.001)
                    })
            });
            out.offered += usize::from(offered);
        }
        out.piles += 1;
    }
    out.recognition = cloud.then_some(recognition);
    out.recognition_finer = finer.map(|(_, totals)| (finer_px, totals));
    Ok(out)
}

/// The part model of a loaded workpiece for the scene's cup: of its mesh file, or of its
/// primitives meshed ([`binpick::config::Workpiece::part_model`], the derivation every stage
/// reads).
pub fn model_of(wp: &LoadedWorkpiece, scene: &Scene) -> Result<PartModel, ConfigError> {
    let w = &wp.workpiece;
    let primitive = w.primitive_mesh();
    let (mesh, key) = match (&wp.mesh, &primitive) {
        (Some(m), _) => (&m.0, "shape.mesh_file"),
        (None, Some(m)) => (m, "shape"),
        (None, None) => {
            return Err(ConfigError::one(
                &wp.label,
                "shape",
                "no mesh to derive a part model from".to_string(),
            ));
        }
    };
    w.part_model(mesh, scene.gripper.cup_diameter_m).map_err(|e| {
        ConfigError::one(
            &wp.label,
            key,
            format!(
                "{}: {e}",
                w.shape.mesh_file.clone().unwrap_or_else(|| "primitives".into())
            ),
        )
    })
}

/// Where a workpiece's surface comes from, as the text and the picture name it: its mesh file,
/// or its primitives.
fn surface_of(wp: &LoadedWorkpiece) -> String {
    wp.workpiece
        .shape
        .mesh_file
        .clone()
        .unwrap_or_else(|| "primitives, meshed".into())
}

/// The faces (1-based, as listed) that take the cup at a site its approach reaches (`sites`) and
/// are up when the part rests upright, on its -z side (up to its symmetry): those
/// `grasp.place_orientation = "upright"` grasps.
fn upright_faces(m: &PartModel, max_lean_rad: f64, sites: &CupSites) -> Vec<usize> {
    (0..m.faces.len())
        .filter(|&i| {
            let f = &m.faces[i];
            sites[i].is_some()
                && binpick::grasp::PlacePose::of_face(m, &f.face.normal, max_lean_rad).is_some_and(|p| p.is_upright(m))
        })
        .map(|i| i + 1)
        .collect()
}

/// Why a workpiece that must be placed upright (`grasp.place_orientation = "upright"`) cannot
/// be, or `None` when a face that takes the cup is up in its upright pose (or any pose will do).
fn no_upright_face(
    m: &PartModel,
    w: &binpick::config::Workpiece,
    max_lean_rad: f64,
    sites: &CupSites,
) -> Option<String> {
    if w.grasp.place_orientation != binpick::config::PlaceOrientation::Upright
        || !upright_faces(m, max_lean_rad, sites).is_empty()
    {
        return None;
    }
    Some(
        "grasp.place_orientation = \"upright\": no face that takes the cup is up when the part rests on its \
         -z side, so nothing will be picked (`binpick part` lists the faces and poses)"
            .to_string(),
    )
}

/// Why the sensor will seldom see the part, or `None`: in resting poses that make up at least
/// half its likelihood, its top stands less than the depth noise at 1 m
/// (`sensor.depth_noise_at_1m_m`) above the height under which recognition takes every point for
/// the tray floor ([`binpick::sensor::cloud::FLOOR_TOL_M`]), so most of its pixels on the floor
/// fall into that band (an M8 washer 1.3 mm thick: 23 % of the top layer found, 1.6 mm thick:
/// 80 %).
fn too_flat_to_see(m: &PartModel, scene: &binpick::config::Scene) -> Option<String> {
    use binpick::sensor::cloud::FLOOR_TOL_M;
    let limit_m = FLOOR_TOL_M + scene.sensor.depth_noise_at_1m_m;
    // Each pose's height: the part's extent along its support normal.
    let height_m = |n: &nalgebra::Vector3<f64>| {
        let (lo, hi) = m
            .mesh
            .vertices_m
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v.coords.dot(n)), hi.max(v.coords.dot(n)))
            });
        hi - lo
    };
    let flat: Vec<(f64, f64)> = m
        .poses
        .iter()
        .map(|p| (height_m(&p.normal), p.likelihood))
        .filter(|(h, _)| *h < limit_m)
        .collect();
    let share = flat.iter().map(|(_, l)| l).sum::<f64>();
    let highest_m = flat.iter().map(|(h, _)| *h).fold(0.0, f64::max);
    (share >= 0.5).then(|| {
        format!(
            "in {:.0} % of its resting poses the part stands {:.2} mm high or less, under {:.2} mm (the {:.1} mm \
             under which the sensor takes every point for the tray floor, plus its depth noise at 1 m): it is \
             found mostly where it lies on other parts (`binpick part` predicts the share)",
            100.0 * share,
            highest_m * 1e3,
            limit_m * 1e3,
            FLOOR_TOL_M * 1e3
        )
    })
}

/// Below this share of its resting poses (by likelihood) with a face that takes the cup up, a
/// part is seldom offered to the cup where it lies on the floor (an M4 bolt: 0.7 %, on its head
/// with its shank up; the shipped parts' least, the SMD electrolytic with its own cup: 14.3 %).
pub const SELDOM_CUP_FACE_UP: f64 = 0.05;

/// Why the part will seldom offer the cup a face, or `None`: faces take it (`sites`), but in
/// resting poses making up less than [`SELDOM_CUP_FACE_UP`] of the likelihood does one look up
/// within `lean` (a crystal lying on its side, whose only face the cup takes is its top, with its
/// leads under it: none; a bolt, whose head's top looks up only when it stands on its head), and
/// the cup takes no strip of a round side. In none (a share of 0) no such face can be set down
/// as held (a face is placeable where a resting pose has it up within the same lean,
/// [`binpick::grasp::PlacePose::of_face`]), so the grasp selector offers none: nothing is picked.
fn no_cup_face_up(m: &PartModel, scene: &Scene, sites: &CupSites) -> Option<String> {
    let lean = scene.gripper.max_lean_rad();
    let share = m.graspable_share(lean, sites);
    if !sites.iter().any(Option::is_some)
        || share >= SELDOM_CUP_FACE_UP
        || round_side(m, scene).is_some_and(|r| r.offered > 0)
    {
        return None;
    }
    Some(if share == 0.0 {
        format!(
            "in none of its resting poses does a face that takes the cup look up within {:.0} deg: a part held \
             by one could not be set down as held, so none is grasped and nothing will be picked, not even a \
             part propped up on others (`binpick part` lists the poses and marks the faces `no pose`)",
            lean.to_degrees()
        )
    } else {
        format!(
            "in only {:.1} % of its resting poses (by likelihood) does a face that takes the cup look up \
             within {:.0} deg: the cell picks mostly parts propped up on others, and few of a pile \
             (`binpick part` lists the poses and predicts a pile's share)",
            100.0 * share,
            lean.to_degrees()
        )
    })
}

/// The turns the part's detected symmetry lacks that the cell's sensor cannot tell from the part
/// ([`binpick::part::symmetry::look_alike_turns`], at the pick tray floor's pixel and depth
/// noise, against the recogniser's close-call odds); none where the file declares the symmetry.
pub fn look_alikes(m: &PartModel, scene: &Scene) -> Vec<binpick::part::symmetry::LookAlike> {
    let Some(camera) = binpick::sensor::Camera::from_config(&scene.sensor).filter(|_| m.symmetry_detected) else {
        return Vec::new();
    };
    let floor = nalgebra::Vector3::from(scene.pick_tray.center_m);
    let pixel_m = camera.pixel_size_at_point_m(&floor);
    // The depth along the optical axis, as the pixel's size reads it.
    let depth_m = pixel_m * scene.sensor.focal_px[0].min(scene.sensor.focal_px[1]);
    // Each resting pose's up direction in the part frame, with its likelihood.
    let poses: Vec<(nalgebra::Vector3<f64>, f64)> = m.poses.iter().map(|p| (-p.normal, p.likelihood)).collect();
    binpick::part::symmetry::look_alike_turns(
        &m.mesh,
        &m.mass.com_m,
        m.symmetry.orders,
        &poses,
        pixel_m,
        scene.sensor.depth_noise_at_1m_m * depth_m * depth_m,
        binpick::sensor::cloud::CLOSE_CALL_LOG_ODDS,
    )
}

/// Every warning about a valid workpiece, as `check` and `part` print them and `part --json`
/// lists them: its part model `m` in `scene` (set up for it), the selector's cup `sites` and
/// the look-alike `turns` ([`look_alikes`]).
pub fn warnings(
    m: &PartModel,
    w: &binpick::config::Workpiece,
    scene: &Scene,
    sites: &CupSites,
    turns: &[binpick::part::symmetry::LookAlike],
) -> Vec<String> {
    [
        no_cup_face(m, sites),
        no_cup_face_up(m, scene, sites),
        look_alike_warning(m, turns),
        no_upright_face(m, w, scene.gripper.max_lean_rad(), sites),
        too_flat_to_see(m, scene),
    ]
    .into_iter()
    .flatten()
    .collect()
}

/// Why recognition will find few of the part, or `None`: `turns` its mesh is not the same under
/// look the same to the sensor ([`look_alikes`]), so recognition, which reports no pose it cannot
/// tell from another, reports neither; with the orders that declaring them would give.
fn look_alike_warning(m: &PartModel, turns: &[binpick::part::symmetry::LookAlike]) -> Option<String> {
    if turns.is_empty() {
        return None;
    }
    let mut orders = m.symmetry.orders;
    for t in turns {
        let (a, b) = (orders[t.axis], t.order);
        // The least common multiple: both turns' orders.
        orders[t.axis] = (1..=a * b)
            .find(|k| k.is_multiple_of(a) && k.is_multiple_of(b))
            .unwrap_or(a * b);
    }
    let names = turns
        .iter()
        .map(|t| format!("{} deg about {}", 360 / t.order, ["x", "y", "z"][t.axis]))
        .collect::<Vec<_>>()
        .join(", ");
    let off_m = turns.iter().map(|t| t.max_off_m).fold(0.0, f64::max);
    let evidence = turns.iter().map(|t| t.evidence).fold(0.0, f64::max);
    let share = turns.iter().map(|t| t.share).fold(1.0, f64::min);
    Some(format!(
        "its mesh is not the same turned {names}, but in {:.0} % of its resting poses the sensor cannot tell \
         those turns apart (the turned mesh lies within {:.2} mm of itself: evidence {:.1} of the {:.1} a decision \
         needs), so recognition reports neither and finds few; where the orientation does not matter in the \
         line, declare `shape.symmetry_orders = [{}, {}, {}]` (as the SMD electrolytic's file does)",
        100.0 * share,
        off_m * 1e3,
        evidence,
        binpick::sensor::cloud::CLOSE_CALL_LOG_ODDS,
        orders[0],
        orders[1],
        orders[2]
    ))
}

/// Why no face takes the cup at a site its approach reaches (`sites`), or `None` when one does.
fn no_cup_face(m: &PartModel, sites: &CupSites) -> Option<String> {
    if sites.iter().any(Option::is_some) {
        return None;
    }
    if m.grasp_faces().next().is_some() {
        return Some(
            "every face that takes the cup has the cup's approach meet the part's own features (pins, \
             leads, tabs) at every site, so nothing will be picked (`binpick part` marks them blocked)"
                .to_string(),
        );
    }
    let largest = m
        .faces
        .iter()
        .map(|f| {
            format!(
                "{:.1} x {:.1} mm (best clearance {:.2} mm)",
                f.face.extent_m()[0] * 1e3,
                f.face.extent_m()[1] * 1e3,
                f.face.cup_fit(0.0).best_clearance_m * 1e3
            )
        })
        .take(3)
        .collect::<Vec<_>>()
        .join(", ");
    Some(format!(
        "no planar face takes the cell's {:.1} mm cup with its {:.1} mm margin (a disc of {:.2} mm radius must lie on the face); the largest faces: {}",
        m.cup.diameter_m * 1e3,
        m.cup.face_margin_m * 1e3,
        m.cup.disc_radius_m() * 1e3,
        if largest.is_empty() {
            "none".to_string()
        } else {
            largest
        }
    ))
}

pub fn part(a: &PartArgs) -> Result<()> {
    let scene = LoadedScene::load(a.scene.as_deref())?;
    let wp = LoadedWorkpiece::resolve(&a.workpiece)?;
    wp.workpiece.check_fits_scene(&wp.label, &scene.scene)?;
    // The workpiece's own cup, if it brings one.
    let scene = scene.for_workpiece(&wp);
    let m = model_of(&wp, &scene.scene)?;
    let report = &wp.mesh.as_ref().map(|m| m.1.clone()).unwrap_or_default();
    let w = &wp.workpiece;
    // How far from vertical a face the selector takes may look (the tool leaning with it).
    let lean = scene.scene.gripper.max_lean_rad();
    let svg_path = a
        .svg
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}.part.svg", w.name)));
    let title = format!("{} ({}): {}", w.name, surface_of(&wp), w.kind);
    // Where the grasp selector puts the cup on each face (the one derivation it reads).
    let sites = m.cup_sites(&binpick::grasp::approach_column(&scene.scene));
    write_atomically(&svg_path, &binpick::part::svg::picture(&m, &title, &sites))?;
    // The physics only where piles or drops are asked for (a mesh the physics cannot take still
    // shows its model with both at 0).
    let sim = (a.piles > 0 || a.drops > 0)
        .then(|| Sim::new(&scene, &wp))
        .transpose()?;
    let piles = pile_share(&scene, &wp, sim.as_ref(), &m, a.piles, lean, &sites)?;
    let drops = drop_share(&scene, sim.as_ref(), &m, a.drops)?;
    if a.json {
        print_json(&wp, &m, &sites, report, &scene.scene, &svg_path, (&piles, &drops))
    } else {
        print_summary(&wp, &m, report);
        print_faces(&m, &sites, lean);
        let upright = upright_faces(&m, lean, &sites);
        super::say(&format!(
            "faces up when it rests upright, on its -z side (grasp.place_orientation = \"upright\"): {}",
            if upright.is_empty() {
                "none that takes the cup".to_string()
            } else {
                upright.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")
            }
        ));
        if let Some(side) = round_side(&m, &scene.scene) {
            super::say(&format!(
                "round side: the cup seals on radii of {:.2} mm and up; the round body (radius {:.2} mm) \
                 offers {} of its {} tangent strips (a clear cup site, and a stable pose with the strip up \
                 within {:.0} deg to set the part down in); the shares below count flat faces only",
                mm(side.min_radius_m),
                mm(side.radius_m),
                side.offered,
                binpick::part::round_side::SIDE_STRIPS,
                binpick::grasp::SIDE_PLACE_OFF_MAX_RAD.to_degrees()
            ));
        }
        print_poses(&m, lean, &sites, &drops);
        if piles.piles > 0 {
            // A pile that never came to rest is counted where its parts lay at the settle limit:
            // "settled" would claim what the line below denies.
            let counted = if piles.unsettled > 0 {
                format!("parts in the tray at the {:.0} s settle limit", piles.max_settle_s)
            } else {
                "settled parts".to_string()
            };
            super::say(&format!(
                "simulated piles: {} of {} {counted} ({:.1} %) offer a cup face up with nothing on the cup's disc ({} piles of {}, seeds 1-{})",
                piles.offered,
                piles.in_tray,
                100.0 * piles.share(),
                piles.piles,
                w.pile_count,
                piles.piles
            ));
        }
        if piles.unsettled > 0 {
            super::say(&format!(
                "{} of its {} piles still moved after {:.0} s simulated: parts that roll on a rim or rock on others, \
                 which the physics keeps up (it has no rolling resistance; docs/model.md, physics): the cell may see \
                 them move, and steps them for as long as they do",
                piles.unsettled, piles.piles, piles.max_settle_s
            ));
        }
        if let Some(r) = piles.recognition.as_ref().map(RecognitionTotals::summary) {
            let finer = piles.recognition_finer.as_ref().map(|(px, t)| (*px, t.summary()));
            super::say(&recognition_line(&r, finer.as_ref(), &scene.scene));
            print_recognition_by_pose(&m, lean, &sites, &piles);
        }
        for why in warnings(&m, w, &scene.scene, &sites, &look_alikes(&m, &scene.scene)) {
            super::say(&format!("warning: {why}"));
        }
        println!("picture: {}", svg_path.display());
        Ok(())
    }
}

/// What a cup that seals on round surfaces (`gripper.round_min_radius_m`) takes of the part's
/// round body's side, as the grasp selector offers it.
struct RoundSide {
    min_radius_m: f64,
    radius_m: f64,
    /// Strips with a clear cup site.
    clear: usize,
    /// Of them, those a stable pose has up within the set-down limit: the ones offered.
    offered: usize,
}

fn round_side(m: &PartModel, scene: &binpick::config::Scene) -> Option<RoundSide> {
    let min_radius_m = scene.gripper.round_min_radius_m?;
    let body = m.round_body()?;
    Some(RoundSide {
        min_radius_m,
        radius_m: body.radius_m,
        clear: m
            .round_side_strips(min_radius_m, &binpick::grasp::approach_column(scene))
            .len(),
        offered: binpick::grasp::offered_side_strips(m, scene).len(),
    })
}

/// The cell's recognition on the simulated piles by resting pose, as a table: per row of the
/// poses table (alike poses together) with parts in the piles' top layer, those found of them.
fn print_recognition_by_pose(m: &PartModel, lean: f64, sites: &CupSites, piles: &PileShare) {
    println!(
        "recognised by resting pose (the piles' top-layer parts, each in the pose nearest its own within {:.0} deg):",
        PILE_POSE_MATCH_RAD.to_degrees()
    );
    println!("  down normal               top layer   found     share");
    let (rows, _) = pose_rows(m, lean, sites);
    let row = |name: String, f: Found| {
        println!(
            "  {name:24}  {:9}  {:6}  {:>8}",
            f.of,
            f.found,
            super::percent(f.found as f64 / f.of as f64)
        )
    };
    for members in &rows {
        let mut f = Found::default();
        for &i in members {
            f.add(piles.by_pose[i]);
        }
        let n = m.poses[members[0]].normal;
        if f.of > 0 {
            row(format!("[{:6.3} {:6.3} {:6.3}]", n.x, n.y, n.z), f);
        }
    }
    if piles.by_pose_none.of > 0 {
        row("propped up on others".to_string(), piles.by_pose_none);
    }
}

/// What the recognition on the simulated piles found, as a line of text (with what a precision
/// under 99 % means for the picks, and what twice the resolution finds: `finer`).
fn recognition_line(r: &RecognitionSummary, finer: Option<&([u32; 2], RecognitionSummary)>, scene: &Scene) -> String {
    let [w, h] = scene.sensor.resolution_px;
    let mut line = format!(
        "recognition on those piles ({w} x {h} px, one capture each): recall {} of the top layer ({} of {}), precision {} ({} of {} detections within 2 mm and 5 deg of a part); pose error of those, {}",
        super::percent(r.recall),
        r.top_layer_found,
        r.top_layer,
        super::percent(r.precision),
        r.correct,
        r.detected,
        super::pose_errors_text(r),
    );
    if r.precision < 0.99 {
        line.push_str(&format!(
            "; a wrong detection may be grasped or set down off its pose (the place tray's tolerance: {:.1} mm, {:.0} deg)",
            scene.place_tray.tolerance_m * 1e3,
            scene.place_tray.tolerance_deg
        ));
    }
    // Under 99 %, or nothing detected at all: what the finer mode finds.
    if (r.precision < 0.99 || r.detected == 0)
        && let Some(([fw, fh], f)) = finer
    {
        line.push_str(&format!(
            "; at twice the resolution ({fw} x {fh} px over the same field of view, `[sensor] resolution_px = [{fw}, {fh}]` in the workpiece file, docs/formats.md): recall {}, precision {}",
            super::percent(f.recall),
            super::percent(f.precision)
        ));
    }
    line
}

/// Millimetres from metres, rounded for the JSON output.
fn mm(v: f64) -> f64 {
    round(v * 1e3, 4)
}

/// The `--json` output: the part model with every face and pose.
fn print_json(
    wp: &LoadedWorkpiece,
    m: &PartModel,
    sites: &binpick::part::svg::CupSites,
    report: &RepairReport,
    scene: &binpick::config::Scene,
    svg_path: &Path,
    (piles, drops): (&PileShare, &DropShare),
) -> Result<()> {
    let w = &wp.workpiece;
    let lean = scene.gripper.max_lean_rad();
    let side = round_side(m, scene);
    let turns = look_alikes(m, scene);
    let out = json!({
        "workpiece": wp.label,
        "mesh_file": w.shape.mesh_file,
        "triangles": m.mesh.triangles.len(),
        "repair": report,
        "size_mm": m.size_m.map(mm),
        "volume_mm3": round(m.mass.volume_m3 * 1e9, 4),
        "mass_g": round(m.mass.mass_kg * 1e3, 6),
        "density_kg_m3": round(m.mass.density_kg_m3, 3),
        "com_mm": m.mass.com_m.iter().map(|v| mm(*v)).collect::<Vec<_>>(),
        "inertia_com_kg_mm2": m.mass.inertia_com_kg_m2.row_iter().map(|r| r.iter().map(|v| round(v * 1e6, 9)).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "symmetry_orders": m.symmetry.orders,
        "symmetry_detected": m.symmetry_detected,
        "look_alike_turns": turns,
        "cup_diameter_mm": mm(m.cup.diameter_m),
        "face_margin_mm": mm(m.cup.face_margin_m),
        "faces": m.faces.iter().zip(sites).map(|(f, site)| face_json(m, f, site, lean)).collect::<Vec<_>>(),
        "poses": m.poses.iter().zip(&drops.per_pose).zip(&piles.by_pose).map(|((p, &n), f)| {
            let mut j = pose_json(p);
            j["dropped_share"] = json!((drops.dropped > 0).then(|| round(drops.share(n), 6)));
            j["top_layer_recognised"] = json!(piles.recognition.is_some().then(|| json!({"found": f.found, "of": f.of})));
            j
        }).collect::<Vec<_>>(),
        "drops": {
            "dropped": drops.dropped,
            "in_no_predicted_pose": drops.in_none,
            "in_no_predicted_pose_down": drops.in_none_down.iter().map(|d| d.iter().map(|v| round(*v, 3)).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "crowded": drops.crowded,
            "match_within_deg": DROP_MATCH_RAD.to_degrees(),
        },
        "upright_faces": upright_faces(m, lean, sites),
        "graspable_share": round(m.graspable_share(lean, sites), 6),
        "round_side": side.map(|r| json!({
            "cup_round_min_radius_mm": mm(r.min_radius_m),
            "body_radius_mm": mm(r.radius_m),
            "strips": binpick::part::round_side::SIDE_STRIPS,
            "strips_with_a_clear_site": r.clear,
            "strips_offered": r.offered,
        })),
        "pile": {
            "piles": piles.piles,
            "parts_in_tray": piles.in_tray,
            "parts_offering_a_cup_face": piles.offered,
            "unsettled_piles": piles.unsettled,
            "share": round(piles.share(), 6),
            "recognition": piles.recognition.as_ref().map(RecognitionTotals::summary),
            "recognition_at_twice_the_resolution": piles.recognition_finer.as_ref().map(|(px, t)| serde_json::json!({
                "resolution_px": px,
                "summary": t.summary(),
            })),
            "top_layer_recognised_propped_up": piles.recognition.is_some().then(|| json!({
                "found": piles.by_pose_none.found,
                "of": piles.by_pose_none.of,
            })),
            "pose_match_within_deg": PILE_POSE_MATCH_RAD.to_degrees(),
        },
        "warnings": warnings(m, w, scene, sites, &turns),
        "svg": svg_path.display().to_string(),
    });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

/// One planar face with its cup fit, in the JSON output.
fn face_json(
    m: &PartModel,
    f: &ModelFace,
    site: &Option<(nalgebra::Point3<f64>, f64)>,
    lean: f64,
) -> serde_json::Value {
    json!({
        "normal": f.face.normal.iter().map(|v| round(*v, 6)).collect::<Vec<_>>(),
        "centroid_mm": f.face.centroid_m.iter().map(|v| mm(*v)).collect::<Vec<_>>(),
        "area_mm2": round(f.face.area_m2 * 1e6, 4),
        "extent_mm": f.face.extent_m().map(mm),
        "holes": f.face.holes.len(),
        "outline_mm": f.face.outer.iter().map(|p| [mm(p.x), mm(p.y)]).collect::<Vec<_>>(),
        "cup_fit": {
            "takes_cup": f.fit.takes_cup(),
            "area_mm2": round(f.fit.area_m2 * 1e6, 4),
            "centres": f.fit.centres.len(),
            "grid_spacing_mm": mm(f.fit.spacing_m),
            "best_centre_mm": f.fit.best.map(|b| {
                let p = f.face.to_part(&b);
                [mm(p.x), mm(p.y), mm(p.z)]
            }),
            "best_clearance_mm": mm(f.fit.best_clearance_m),
            // Where the grasp selector puts the cup: the clearest centre whose approach misses
            // the part's features in every pose recognition cannot tell apart.
            "cup_site_mm": site.map(|(p, _)| [mm(p.x), mm(p.y), mm(p.z)]),
            // Whether a resting pose has the face up within the tool's lean, so that a part
            // held by it can be set down as held: the grasp selector offers only such faces.
            "placeable": binpick::grasp::PlacePose::of_face(m, &f.face.normal, lean).is_some(),
        },
    })
}

/// One stable resting pose, in the JSON output.
fn pose_json(p: &RestingPose) -> serde_json::Value {
    json!({
        "down_normal": p.normal.iter().map(|v| round(*v, 6)).collect::<Vec<_>>(),
        "likelihood": round(p.likelihood, 6),
        "com_height_mm": mm(p.com_height_m),
        "stability_margin_mm": mm(p.stability_margin_m),
        "support_area_mm2": round(p.support_area_m2 * 1e6, 4),
    })
}

/// The text head: the mesh, what its repair did, size and mass, symmetry.
fn print_summary(wp: &LoadedWorkpiece, m: &PartModel, report: &RepairReport) {
    let w = &wp.workpiece;
    if wp.mesh.is_none() {
        super::say(&format!(
            "part {:?} ({}): {} primitives, meshed: {} triangles",
            w.name,
            wp.label,
            w.pieces().len(),
            m.mesh.triangles.len()
        ));
        println!("repair: none (primitives are meshed closed)");
    } else {
        super::say(&format!(
            "part {:?} ({}): mesh {}, {} triangles in {} {}",
            w.name,
            wp.label,
            surface_of(wp),
            m.mesh.triangles.len(),
            report.bodies,
            if report.bodies == 1 { "body" } else { "bodies" }
        ));
        super::say(&format!(
            "repair: {} vertices welded, {} zero-area and {} duplicate triangles dropped, {} inner-wall pairs dropped, {} T-junctions split, {} triangles and {} bodies flipped, {} holes closed ({:.3} mm^2), {} non-manifold edges",
            report.welded_vertices,
            report.zero_area_triangles,
            report.duplicate_triangles,
            report.inner_wall_pairs,
            report.t_junctions_split,
            report.flipped_triangles,
            report.flipped_bodies,
            report.holes_closed,
            report.holes_area_m2 * 1e6,
            report.non_manifold_edges
        ));
    }
    let c = m.mass.com_m;
    super::say(&format!(
        "size {:.2} x {:.2} x {:.2} mm, volume {:.1} mm^3, mass {:.3} g ({:.0} kg/m^3), centre of mass [{:.3} {:.3} {:.3}] mm",
        m.size_m[0] * 1e3,
        m.size_m[1] * 1e3,
        m.size_m[2] * 1e3,
        m.mass.volume_m3 * 1e9,
        m.mass.mass_kg * 1e3,
        m.mass.density_kg_m3,
        c.x * 1e3,
        c.y * 1e3,
        c.z * 1e3
    ));
    let order = |n: u32| {
        if n >= binpick::part::symmetry::MAX_ORDER {
            "round".to_string()
        } else {
            n.to_string()
        }
    };
    println!(
        "symmetry: orders {} {} {} about x, y, z through the centre of mass ({})",
        order(m.symmetry.orders[0]),
        order(m.symmetry.orders[1]),
        order(m.symmetry.orders[2]),
        if m.symmetry_detected {
            "detected"
        } else {
            "from the file"
        }
    );
}

/// The text table of the planar faces that matter to a cup (`--json` lists every face).
fn print_faces(m: &PartModel, sites: &binpick::part::svg::CupSites, lean: f64) {
    // A face with a site that no resting pose has up within the lean: the grasp selector does
    // not offer it (a part held by it could not be set down as held).
    let unplaceable = |f: &ModelFace| binpick::grasp::PlacePose::of_face(m, &f.face.normal, lean).is_none();
    println!(
        "\nplanar faces, for the {:.1} mm cup with a {:.1} mm margin (largest first):",
        m.cup.diameter_m * 1e3,
        m.cup.face_margin_m * 1e3
    );
    println!("   #  normal                  area mm^2   extent mm      holes  cup fits  fit area mm^2  cup site mm");
    let largest = m.faces.first().map_or(0.0, |f| f.face.area_m2);
    // A face that takes the cup, or one large and wide enough to be a face the recognition
    // matches (a strip of a tessellated curve, a lead's side is neither).
    let min_width_m = binpick::sensor::cloud::MESH_FACE_MIN_WIDTH_M;
    let shown = |f: &ModelFace| {
        let e = f.face.extent_m();
        f.fit.takes_cup() || (f.face.area_m2 >= 0.05 * largest && e[0].min(e[1]) >= min_width_m)
    };
    for (i, (f, site)) in m.faces.iter().zip(sites).enumerate().filter(|(_, (f, _))| shown(f)) {
        let n = f.face.normal;
        let e = f.face.extent_m();
        let best = match site {
            Some(_) if unplaceable(f) => "no pose +".to_string(),
            Some((p, _)) => format!("[{:.2} {:.2} {:.2}]", p.x * 1e3, p.y * 1e3, p.z * 1e3),
            None if f.fit.takes_cup() => "blocked *".to_string(),
            None => "-".to_string(),
        };
        println!(
            "  {:>2}  [{:6.3} {:6.3} {:6.3}]  {:10.2}  {:5.2} x {:5.2}  {:5}  {:8}  {:13.2}  {best}",
            i + 1,
            n.x,
            n.y,
            n.z,
            f.face.area_m2 * 1e6,
            e[0] * 1e3,
            e[1] * 1e3,
            f.face.holes.len(),
            if f.fit.takes_cup() { "yes" } else { "no" },
            f.fit.area_m2 * 1e6
        );
    }
    if m.faces
        .iter()
        .zip(sites)
        .any(|(f, site)| site.is_none() && f.fit.takes_cup())
    {
        println!("  * the cup fits the face, but its approach meets the part's own features (pins, tabs)");
    }
    if m.faces
        .iter()
        .zip(sites)
        .any(|(f, site)| site.is_some() && unplaceable(f))
    {
        println!(
            "  + the cup fits the face, but no resting pose has it up within the tool's {:.0} deg lean:\n    \
             a part held by it could not be set down as held, so it is not grasped",
            lean.to_degrees()
        );
    }
    let hidden = m.faces.iter().filter(|f| !shown(f)).count();
    if hidden > 0 {
        println!(
            "  (and {hidden} faces under 5 % of the largest face's area or narrower than {:.1} mm: --json lists them)",
            min_width_m * 1e3
        );
    }
}

/// The rows of the resting poses' table: each row's poses (alike by their support and in
/// whether a cup face looks up within `lean`: [`binpick::part::poses::alike_groups`]); and per
/// pose whether a cup face looks up ([`PartModel::cup_face_up`], a face with a site).
fn pose_rows(m: &PartModel, lean: f64, sites: &CupSites) -> (Vec<Vec<usize>>, Vec<bool>) {
    let up: Vec<bool> = m.poses.iter().map(|p| m.cup_face_up(p, lean, sites)).collect();
    (binpick::part::poses::alike_groups(&m.poses, &up), up)
}

/// The text table of the stable resting poses and the share with a cup face up within `lean`.
/// Poses alike by their support (`pose_classes`: a hex prism's six flats, a coin standing on
/// any facet of its rim) and alike in whether a cup face looks up are one row: the first one's
/// normal, how many, their likelihoods and drops summed (`--json` lists each).
fn print_poses(m: &PartModel, lean: f64, sites: &CupSites, drops: &DropShare) {
    println!("\nstable resting poses (the part lies on the hull face whose outward normal points down):");
    println!("  down normal               poses  likelihood  CoM height mm  margin mm  a cup face looks up  dropped");
    let (rows, up) = pose_rows(m, lean, sites);
    for members in &rows {
        let head = members[0];
        let p = &m.poses[head];
        println!(
            "  [{:6.3} {:6.3} {:6.3}]  {:5}  {:8.1} %  {:13.2}  {:9.2}  {:19}  {:>7}",
            p.normal.x,
            p.normal.y,
            p.normal.z,
            members.len(),
            100.0 * members.iter().map(|&i| m.poses[i].likelihood).sum::<f64>(),
            p.com_height_m * 1e3,
            p.stability_margin_m * 1e3,
            if up[head] { "yes" } else { "no" },
            super::percent(drops.share(members.iter().map(|&i| drops.per_pose[i]).sum()))
        );
    }
    if drops.dropped > 0 {
        let none = drops.share(drops.in_none);
        let mut text = format!(
            "dropped: {} parts one at a time on the bare tray floor (seed 1), each counted in the pose whose \
             support lies within {:.0} deg of its own; in none: {}",
            drops.dropped,
            DROP_MATCH_RAD.to_degrees(),
            super::percent(none)
        );
        if none > 0.2 {
            text.push_str(
                "; the physics' collider rests otherwise than the file's hull predicts (a part on a \
                 tessellated round side rolls to another facet of its simplified collider, docs/model.md), \
                 and the recognition and the place pose assume the predicted poses",
            );
        }
        super::say(&text);
    }
    println!();
    super::say(&format!(
        "share of resting poses with a cup face up (within {:.0} deg of vertical, as the grasp selector takes them): {:.1} %",
        lean.to_degrees(),
        100.0 * m.graspable_share(lean, sites)
    ));
}

/// Writes `text` to `path` through a temporary file beside it (never half-written). A path that
/// is not a regular file (`/dev/null`, `/dev/stdout`, a pipe) is written to, not replaced: the
/// rename would have put a regular file in the device's place (as root, `--svg /dev/null` did).
fn write_atomically(path: &Path, text: &str) -> Result<()> {
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        std::fs::write(path, text).map_err(|e| InputError(format!("cannot write {}: {e}", path.display())))?;
        return Ok(());
    }
    let tmp = path.with_extension("svg.partial");
    std::fs::write(&tmp, text).map_err(|e| InputError(format!("cannot write {}: {e}", tmp.display())))?;
    std::fs::rename(&tmp, path).map_err(|e| InputError(format!("cannot write {}: {e}", path.display())))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hex standoff's eight resting poses are two rows: its six flats and its two ends, every
    /// pose in one row, the likelihoods summing to 1; a flat tagged apart is a row of its own.
    /// Control: the part model lists them apart.
    #[test]
    fn resting_poses_alike_are_one_row() {
        let lw = binpick::config::LoadedWorkpiece::resolve(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/workpieces/hex-standoff.toml"
        ))
        .unwrap();
        let m = lw.workpiece.part_model(&lw.mesh.as_ref().unwrap().0, 0.006).unwrap();
        assert_eq!(m.poses.len(), 8);
        let sites = m.cup_sites(&[]);
        let (rows, up) = pose_rows(&m, 40f64.to_radians(), &sites);
        let sizes: Vec<usize> = rows.iter().map(Vec::len).collect();
        assert_eq!(sizes, [6, 2]);
        assert_eq!(up, [true, true, true, true, true, true, false, false]);
        let total: f64 = rows.iter().flatten().map(|&i| m.poses[i].likelihood).sum();
        assert!((total - 1.0).abs() < 1e-9);
        // A flat tagged apart (a cup face up in it alone) is a row of its own.
        let mut tag = up.clone();
        tag[0] = false;
        let sizes: Vec<usize> = binpick::part::poses::alike_groups(&m.poses, &tag)
            .iter()
            .map(Vec::len)
            .collect();
        assert_eq!(sizes, [1, 5, 2]);
    }

    /// A part of a pile counts in the resting pose its up direction is nearest: the hex
    /// standoff on an end (its axis, z, up) is in an end pose, tilted 15 deg still, tilted 25
    /// deg (leaning on another) in none; on a flat (y up, a flat's normal) in a flat pose. The
    /// standoff's frame turned about the world's vertical changes nothing.
    #[test]
    fn a_pile_part_counts_in_the_resting_pose_nearest_its_own() {
        use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
        let lw = binpick::config::LoadedWorkpiece::resolve(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/workpieces/hex-standoff.toml"
        ))
        .unwrap();
        let m = lw.workpiece.part_model(&lw.mesh.as_ref().unwrap().0, 0.006).unwrap();
        let turned = |axis: Vector3<f64>, deg: f64| {
            let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.7);
            let tilt = UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg.to_radians());
            Isometry3::from_parts(Translation3::new(0.1, 0.4, 0.02), yaw * tilt)
        };
        let up_in = |k: Option<usize>| k.map(|k| -m.poses[k].normal);
        let up_z = up_in(pose_of(&m, &turned(Vector3::x(), 0.0))).expect("on an end");
        assert!(up_z.z.abs() > 0.999, "{up_z:?}");
        assert!(pose_of(&m, &turned(Vector3::x(), 15.0)).is_some());
        assert_eq!(pose_of(&m, &turned(Vector3::x(), 25.0)), None);
        // Lying on a flat: the part's y axis (a flat's normal, the hexagon's vertices on x)
        // turned up.
        let flat = up_in(pose_of(&m, &turned(Vector3::x(), 90.0))).expect("on a flat");
        assert!(flat.z.abs() < 1e-6, "{flat:?}");
    }

    /// A pipe given as the picture's path is written to and stays a pipe (as `/dev/null` must
    /// stay a device). Control: a regular file's path gets the text through the rename.
    #[test]
    fn a_device_or_pipe_is_written_to_not_replaced() {
        use std::os::unix::fs::FileTypeExt;
        let dir = std::env::temp_dir().join(format!("binpick-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("pipe.svg");
        let _ = std::fs::remove_file(&fifo);
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().unwrap();
        assert!(made.success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap())
        };
        write_atomically(&fifo, "<svg/>").unwrap();
        // Checked before waiting for the reader, which a replaced pipe would leave waiting.
        assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
        assert_eq!(reader.join().unwrap(), "<svg/>");
        let file = dir.join("picture.svg");
        write_atomically(&file, "<svg/>").unwrap();
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "<svg/>");
        assert!(!dir.join("picture.svg.partial").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
