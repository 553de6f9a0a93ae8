//! Benchmark of the physics: pile build-and-settle wall time per workpiece and the step time of
//! resting parts with the arm moving, beside rapier's default solver settings; and CAD parts
//! beside primitives: piles of a workpiece as a mesh (its primitives tessellated,
//! [`crate::part::tessellate`]) beside the same workpiece as primitives, and a hex standoff blank
//! (a 6-sided prism mesh, 14 mm across corners, 6 mm thick) beside a primitive can of its size
//! (a 16-sided prism, 14 mm across, 6 mm) and beside its collider before the part model (parry's VHACD
//! of the raw mesh with default parameters); a CAD can of that size tessellated with 64 sides
//! beside the same primitive can.
//!
//! Units: s of wall time (ms for steps); medians over runs.

use std::time::Instant;

use serde::Serialize;

use crate::robot::RobotModel;
use crate::stats::median_min_max as median_of;

/// One workpiece's pile timing, ours beside rapier's default solver settings.
#[derive(Debug, Clone, Serialize)]
pub struct PileTiming {
    /// Workpiece name.
    pub workpiece: String,
    /// Parts in the pile.
    pub count: usize,
    /// Wall time to build and settle, median of runs (s).
    pub median_wall_s: f64,
    /// Fastest and slowest run (s).
    pub min_max_wall_s: (f64, f64),
    /// Simulated settle time (s).
    pub settle_sim_s: f64,
    /// Deepest overlap after settling, independent check (m).
    pub max_penetration_m: f64,
    /// Whether it settled.
    pub settled: bool,
    /// The same pile with rapier's default contact stiffness and solver iterations, no adaptive
    /// substeps: wall time (s), deepest overlap (m), or the health error that stopped it.
    pub rapier_defaults: Result<(f64, f64), String>,
}

/// The physics benchmark: piles of each workpiece and the step time of a resting pile with the arm moving.
#[derive(Debug, Clone, Serialize)]
pub struct PhysicsBench {
    /// Per workpiece.
    pub piles: Vec<PileTiming>,
    /// Step time with 100 resting parts and the arm moving, median of runs (ms).
    pub step_ms_median: f64,
    /// Fastest and slowest run (ms).
    pub step_ms_min_max: (f64, f64),
    /// Parts in the resting pile, and which workpiece.
    pub step_pile: (usize, String),
    /// Targets: settle wall time per pile (s) and step time (ms).
    pub targets: (f64, f64),
    /// CAD parts beside primitives of similar size and count.
    pub meshes: Vec<MeshPileTiming>,
    /// Target: a CAD part's pile costs at most this many times the primitive's wall time.
    pub mesh_target_ratio: f64,
}

/// A pile of a mesh part beside a pile of a primitive part of similar size and count (same seeds).
#[derive(Debug, Clone, Serialize)]
pub struct MeshPileTiming {
    /// The mesh part and what it is compared with.
    pub mesh: String,
    /// The primitive part.
    pub primitive: String,
    /// Parts in each pile.
    pub count: usize,
    /// Convex pieces of the mesh part's collider.
    pub mesh_pieces: usize,
    /// Wall time to build and settle the mesh pile: median, min, max of runs (s).
    pub mesh_wall_s: (f64, f64, f64),
    /// The same for the primitive pile (s).
    pub primitive_wall_s: (f64, f64, f64),
    /// Median mesh wall time over median primitive wall time.
    pub ratio: f64,
    /// Simulated time from the first drop to settled, median of runs, mesh and primitive (s):
    /// a pile that rolls longer costs more wall time at the same cost per step.
    pub settle_sim_s: (f64, f64),
    /// The cost of the colliders and their contacts alone: the median over runs of wall time per
    /// simulated second, the mesh pile's over the primitive's.
    pub per_sim_s_ratio: f64,
    /// One agitation of the settled pile and its settling: simulated seconds per wall second,
    /// median of runs, mesh and primitive.
    pub agitation_real_time: (f64, f64),
    /// Deepest overlap after settling, mesh and primitive pile of the last run (m).
    pub max_penetration_m: (f64, f64),
    /// Pile height above the tray floor, mesh and primitive pile of the last run (m).
    pub pile_height_m: (f64, f64),
    /// Runs the health monitor stopped (seed and why), mesh and primitive: left out of the
    /// medians.
    pub stops: (Vec<String>, Vec<String>),
}

fn median(v: Vec<f64>) -> (f64, f64, f64) {
    median_of(&v)
}

/// Runs the physics benchmark on one core.
pub fn physics_bench(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    workpieces: &[crate::config::LoadedWorkpiece],
    runs: usize,
) -> Result<PhysicsBench, Box<dyn std::error::Error + Send + Sync>> {
    use crate::physics::{PartShape, World, pile::PileOptions};
    let runs = runs.max(1);
    let mut piles = Vec::new();
    for wp in workpieces {
        let shape = PartShape::build(&wp.workpiece, &wp.source)?;
        let count = wp.workpiece.pile_count as usize;
        let mut walls = Vec::new();
        let mut last = None;
        for run in 0..runs {
            let mut w = World::new(&scene.scene, robot, shape.clone());
            let t0 = Instant::now();
            let r = w.build_pile(&PileOptions::new(count, 1 + run as u64))?;
            walls.push(t0.elapsed().as_secs_f64());
            last = Some(r);
        }
        let r = last.expect("at least one run");
        let (med, lo, hi) = median(walls);
        // Peer: rapier's defaults for contact stiffness and iterations, one step per step.
        let mut w = World::new(&scene.scene, robot, shape.clone());
        w.set_solver(crate::physics::Solver::RapierDefaults);
        let t0 = Instant::now();
        let peer = w
            .build_pile(&PileOptions::new(count, 1))
            .map(|p| (t0.elapsed().as_secs_f64(), p.max_penetration_m))
            .map_err(|e| e.to_string());
        piles.push(PileTiming {
            workpiece: wp.workpiece.name.clone(),
            count,
            median_wall_s: med,
            min_max_wall_s: (lo, hi),
            settle_sim_s: r.settle_sim_s,
            max_penetration_m: r.max_penetration_m,
            settled: r.settled,
            rapier_defaults: peer,
        });
    }
    // 100 resting parts of F, the arm sweeping between the trays above them.
    let f = workpieces
        .iter()
        .find(|w| w.workpiece.name == "F")
        .or(workpieces.first())
        .ok_or("no workpiece given")?;
    let shape = PartShape::build(&f.workpiece, &f.source)?;
    let mut w = World::new(&scene.scene, robot, shape);
    w.build_pile(&PileOptions::new(100, 1))?;
    let home = w.joints();
    let over_pick = robot
        .ik_tool_nearest(
            &crate::robot::tool_down_pose(
                w.pick_tray().world_from_tray.translation.vector + nalgebra::Vector3::z() * 0.15,
                0.0,
            ),
            &home,
        )
        .map_err(|e| e.to_string())?
        .q;
    let mut per_run = Vec::new();
    for _ in 0..runs {
        let steps = 2000;
        let t0 = Instant::now();
        for k in 0..steps {
            // Back and forth between home and over the pick tray, 0.8 s each way.
            let u = (k % 800) as f64 / 400.0;
            let s = crate::physics::script::quintic(if u <= 1.0 { u } else { 2.0 - u });
            w.set_joint_target(&(home + (over_pick - home) * s));
            w.step()?;
        }
        per_run.push(t0.elapsed().as_secs_f64() * 1e3 / steps as f64);
    }
    let (med, lo, hi) = median(per_run);
    Ok(PhysicsBench {
        piles,
        step_ms_median: med,
        step_ms_min_max: (lo, hi),
        step_pile: (100, f.workpiece.name.clone()),
        targets: (1.0, 0.3),
        meshes: mesh_piles(scene, robot, workpieces, runs)?,
        mesh_target_ratio: 2.0,
    })
}

type BenchResult<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// Wall times of `runs` piles of `count` parts (seeds 1..=runs): building and settling each
/// (median, min, max, in s), then one agitation of the cell file's `[agitation]` and its settling
/// as simulated seconds per wall second (median); the last completed pile's report; and the runs
/// the health monitor stopped (left out of the medians). An error if every run stopped.
fn time_piles(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    shape: &crate::physics::PartShape,
    count: usize,
    runs: usize,
) -> BenchResult<PileRuns> {
    use crate::physics::{HealthError, World, pile::PileOptions};
    let mut walls = Vec::new();
    let mut sims = Vec::new();
    let mut shakes = Vec::new();
    let mut last = None;
    let mut stops = Vec::new();
    for run in 0..runs.max(1) {
        let mut w = World::new(&scene.scene, robot, shape.clone());
        let t0 = Instant::now();
        let mut one = || -> Result<(f64, f64, crate::physics::pile::PileReport), HealthError> {
            let r = w.build_pile(&PileOptions::new(count, 1 + run as u64))?;
            let wall = t0.elapsed().as_secs_f64();
            // One agitation as the cell shakes its tray, then the pile settles.
            let a = scene.scene.agitation;
            let tray = w.pick_tray().world_from_tray.rotation;
            let (sim0, t1) = (w.time_s(), Instant::now());
            while w.time_s() + 1e-9 < sim0 + a.duration_s {
                let t_next = w.time_s() + w.dt_s() - sim0;
                w.set_pick_tray_offset(tray * nalgebra::Vector3::from(a.offset_m(t_next)));
                w.step()?;
            }
            w.set_pick_tray_offset(nalgebra::Vector3::zeros());
            w.step()?;
            w.run_for(a.settle_s)?;
            Ok((wall, (w.time_s() - sim0) / t1.elapsed().as_secs_f64(), r))
        };
        match one() {
            Ok((wall, shake, r)) => {
                walls.push(wall);
                sims.push(r.settle_sim_s);
                shakes.push(shake);
                last = Some(r);
            }
            Err(e) => stops.push(format!("seed {}: {e}", 1 + run)),
        }
    }
    let last = last.ok_or_else(|| format!("every run stopped: {}", stops.join("; ")))?;
    let per_sim: Vec<f64> = walls.iter().zip(&sims).map(|(w, s)| w / s.max(1e-9)).collect();
    Ok(PileRuns {
        wall_s: median(walls),
        settle_sim_s: median(sims).0,
        wall_per_sim_s: median(per_sim).0,
        shake_real_time: median(shakes).0,
        last,
        stops,
    })
}

/// What [`time_piles`] measured.
#[derive(Clone)]
struct PileRuns {
    wall_s: (f64, f64, f64),
    /// Simulated time to settled, median of runs (s).
    settle_sim_s: f64,
    /// Wall time per simulated second, median of runs.
    wall_per_sim_s: f64,
    shake_real_time: f64,
    last: crate::physics::pile::PileReport,
    stops: Vec<String>,
}

/// CAD parts beside primitives: A, B and E as meshes beside themselves as primitives; the hex
/// standoff blank as a mesh (ours, and the raw-mesh VHACD collider before) beside a primitive can;
/// a 64-sided CAD can beside the primitive can and beside a box of its size.
pub fn mesh_piles(
    scene: &crate::config::LoadedScene,
    robot: &RobotModel,
    workpieces: &[crate::config::LoadedWorkpiece],
    runs: usize,
) -> BenchResult<Vec<MeshPileTiming>> {
    use crate::config::{Axis, PartRole, Primitive, ShapeConfig, ShapeKind, ShapePart};
    use crate::part::tessellate;
    use crate::physics::PartShape;
    let mut pairs: Vec<(String, PartShape, String, PartShape, usize)> = Vec::new();
    for wp in workpieces
        .iter()
        .filter(|w| ["A", "B", "E"].contains(&w.workpiece.name.as_str()))
    {
        let w = &wp.workpiece;
        let mesh = w.primitive_mesh().ok_or("a built-in workpiece is not a mesh")?;
        pairs.push((
            format!("{}-mesh", w.name),
            PartShape::from_mesh(w, &mesh)?,
            w.name.clone(),
            PartShape::build(w, &wp.source)?,
            w.pile_count as usize,
        ));
    }
    // The hex standoff blank (6.5 g of brass) and a primitive can of its size.
    let base = workpieces.first().ok_or("no workpiece given")?.workpiece.clone();
    let hex = tessellate::prism_mesh(nalgebra::Vector3::zeros(), 0.007, 0.003, Axis::Z, 6);
    let (lo, hi) = hex.bounds_m().ok_or("empty hex mesh")?;
    let mut hex_wp = base.clone();
    hex_wp.name = "hex".into();
    hex_wp.size_m = (hi - lo).into();
    hex_wp.mass_kg = 0.0065;
    hex_wp.friction = 0.4;
    hex_wp.restitution = 0.1;
    hex_wp.shape = ShapeConfig {
        kind: ShapeKind::Mesh,
        parts: Vec::new(),
        mesh_file: Some("hex.stl".into()),
        mesh_scale: Some(1.0),
        units: None,
        symmetry_orders: None,
    };
    let mut can = hex_wp.clone();
    can.name = "can".into();
    can.size_m = [0.014, 0.014, 0.006];
    can.shape = ShapeConfig {
        kind: ShapeKind::Compound,
        parts: vec![ShapePart {
            primitive: Primitive::Cylinder,
            role: PartRole::Body,
            center_m: [0.0; 3],
            size_m: None,
            radius_m: Some(0.007),
            length_m: Some(0.006),
            axis: Some(Axis::Z),
        }],
        mesh_file: None,
        mesh_scale: None,
        units: None,
        symmetry_orders: None,
    };
    let can_shape = PartShape::build(&can, &crate::config::Source::Embedded)?;
    pairs.push((
        "hex-mesh".into(),
        PartShape::from_mesh(&hex_wp, &hex)?,
        "can".into(),
        can_shape.clone(),
        60,
    ));
    // A CAD can tessellated finer than the built-in prisms: 64 sides, 7 mm radius, 6 mm tall.
    let can64 = tessellate::prism_mesh(nalgebra::Vector3::zeros(), 0.007, 0.003, Axis::Z, 64);
    let mut can64_wp = hex_wp.clone();
    can64_wp.name = "can64".into();
    can64_wp.size_m = can.size_m;
    pairs.push((
        "can64-mesh".into(),
        PartShape::from_mesh(&can64_wp, &can64)?,
        "can".into(),
        can_shape.clone(),
        60,
    ));
    // The same can beside a box of its size: the peer the speed issue names ("a box part of the
    // same size"), whose flat faces neither roll nor need a polyhedron's contacts.
    let mut box_wp = can.clone();
    box_wp.name = "box".into();
    box_wp.shape.parts = vec![ShapePart {
        primitive: Primitive::Box,
        role: PartRole::Body,
        center_m: [0.0; 3],
        size_m: Some(can.size_m),
        radius_m: None,
        length_m: None,
        axis: None,
    }];
    pairs.push((
        "can64-mesh".into(),
        PartShape::from_mesh(&can64_wp, &can64)?,
        "box".into(),
        PartShape::build(&box_wp, &crate::config::Source::Embedded)?,
        60,
    ));
    pairs.push((
        "hex-mesh, raw VHACD (before)".into(),
        PartShape::from_mesh_raw_vhacd(&hex_wp, &hex)?,
        "can".into(),
        can_shape,
        60,
    ));
    // Each pile is timed once, in whichever rows it stands (the can beside three meshes, the
    // 64-sided can beside the can and the box).
    let mut timed: std::collections::HashMap<(String, usize), PileRuns> = std::collections::HashMap::new();
    let mut time = |name: &str, shape: &PartShape, count: usize| -> BenchResult<PileRuns> {
        let key = (name.to_string(), count);
        if let Some(r) = timed.get(&key) {
            return Ok(r.clone());
        }
        let r = time_piles(scene, robot, shape, count, runs)?;
        timed.insert(key, r.clone());
        Ok(r)
    };
    let mut rows = Vec::new();
    for (mesh_name, mesh_shape, prim_name, prim_shape, count) in pairs {
        let m = time(&mesh_name, &mesh_shape, count)?;
        let p = time(&prim_name, &prim_shape, count)?;
        rows.push(MeshPileTiming {
            mesh: mesh_name,
            primitive: prim_name,
            count,
            mesh_pieces: mesh_shape.convex_pieces,
            mesh_wall_s: m.wall_s,
            primitive_wall_s: p.wall_s,
            ratio: m.wall_s.0 / p.wall_s.0,
            settle_sim_s: (m.settle_sim_s, p.settle_sim_s),
            per_sim_s_ratio: m.wall_per_sim_s / p.wall_per_sim_s,
            agitation_real_time: (m.shake_real_time, p.shake_real_time),
            max_penetration_m: (m.last.max_penetration_m, p.last.max_penetration_m),
            pile_height_m: (m.last.pile_height_m, p.last.pile_height_m),
            stops: (m.stops, p.stops),
        });
    }
    Ok(rows)
}
