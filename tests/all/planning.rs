//! The planner: every returned path re-checked densely with exact geometry (parry primitives,
//! independent of the planner's spheres), failure reporting, and certified edges spot-checked.

use binpick::bench::binpicking_queries;
use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::planning::{Algorithm, CollisionModel, PlanError, PlanOptions, PlanStats};
use binpick::reference::{PlannerCase, fig5_cases};
use binpick::robot::{JointVector, LinkPrimitive, RobotModel};
use nalgebra::{Isometry3, Vector3};
use rand::RngExt;
use rapier3d::parry::query::intersection_test;
use rapier3d::parry::shape::SharedShape;

/// Exact geometry in metres: the URDF primitives and the hand per link, and the environment boxes.
struct Exact {
    links: Vec<Vec<(Isometry3<f64>, SharedShape)>>,
    env: Vec<(Isometry3<f64>, SharedShape, String)>,
}

fn cyl_z(r: f64, h: f64) -> (Isometry3<f64>, SharedShape) {
    (
        Isometry3::rotation(Vector3::x() * std::f64::consts::FRAC_PI_2),
        SharedShape::cylinder(h as f32, r as f32),
    )
}

fn exact(model: &CollisionModel, scene: &LoadedScene) -> Exact {
    let robot = &model.robot;
    let mut links: Vec<Vec<(Isometry3<f64>, SharedShape)>> = robot
        .links
        .iter()
        .map(|l| {
            l.shapes
                .iter()
                .map(|s| match s.primitive {
                    LinkPrimitive::Box { half_extents_m: h } => (
                        s.link_from_shape,
                        SharedShape::cuboid(h.x as f32, h.y as f32, h.z as f32),
                    ),
                    LinkPrimitive::Cylinder {
                        radius_m,
                        half_length_m,
                    }
                    | LinkPrimitive::Capsule {
                        radius_m,
                        half_length_m,
                    } => {
                        let (rot, shape) = cyl_z(radius_m, half_length_m);
                        (s.link_from_shape * rot, shape)
                    }
                    LinkPrimitive::Sphere { radius_m } => (s.link_from_shape, SharedShape::ball(radius_m as f32)),
                })
                .collect()
        })
        .collect();
    // The hand as the physics builds it, from the one cell geometry.
    for (r, z0, z1) in binpick::geometry::HandGeometry::new(&scene.scene.gripper).cylinders() {
        let (rot, shape) = cyl_z(r, (z1 - z0) / 2.0);
        links[6].push((Isometry3::translation(0.0, 0.0, (z0 + z1) / 2.0) * rot, shape));
    }
    let mut env: Vec<(Isometry3<f64>, SharedShape, String)> = model
        .env
        .boxes
        .iter()
        .map(|b| {
            (
                b.world_from_box,
                SharedShape::cuboid(b.half_m.x as f32, b.half_m.y as f32, b.half_m.z as f32),
                b.name.clone(),
            )
        })
        .collect();
    if let Some(p) = &model.env.pile {
        let m = p.map();
        for j in 0..m.ny {
            for i in 0..m.nx {
                let h = m.height_m[j * m.nx + i];
                if !h.is_finite() || h <= 0.001 {
                    continue;
                }
                let (cx, cy) = (
                    m.origin_xy_m[0] + (i as f64 + 0.5) * m.cell_m,
                    m.origin_xy_m[1] + (j as f64 + 0.5) * m.cell_m,
                );
                if let Some((gx, gy, gr)) = p.cut_out()
                    && (cx - gx).hypot(cy - gy) < gr
                {
                    continue;
                }
                let half = (m.cell_m / 2.0) as f32;
                env.push((
                    m.world_from_tray * Isometry3::translation(cx, cy, h / 2.0),
                    SharedShape::cuboid(half, half, (h / 2.0) as f32),
                    "pile".into(),
                ));
            }
        }
    }
    Exact { links, env }
}

/// Which of the arm's exact shapes intersect each other at `q`, if any: every pair of
/// non-adjacent links (link 6 with the hand), whatever the planner's `SELF_PAIRS` say.
fn self_collides(ex: &Exact, robot: &RobotModel, q: &JointVector) -> Option<String> {
    let frames = robot.world_from_links(q);
    for a in 0..ex.links.len() {
        for b in (a + 2)..ex.links.len() {
            for (la, sa) in &ex.links[a] {
                let pa: rapier3d::math::Pose = (frames[a] * la).cast::<f32>().into();
                for (lb, sb) in &ex.links[b] {
                    let pb: rapier3d::math::Pose = (frames[b] * lb).cast::<f32>().into();
                    if intersection_test(&pa, &**sa, &pb, &**sb).is_ok_and(|r| r.intersecting) {
                        return Some(format!("{} hits {}", robot.links[a].name, robot.links[b].name));
                    }
                }
            }
        }
    }
    None
}

/// What collides at `q`, if anything (links 1-6 and the hand against the environment; the base
/// stands on the table and is not checked against it; then the links against each other).
fn collides(ex: &Exact, robot: &RobotModel, q: &JointVector) -> Option<String> {
    if let Some(hit) = self_collides(ex, robot, q) {
        return Some(hit);
    }
    let frames = robot.world_from_links(q);
    for (li, shapes) in ex.links.iter().enumerate().skip(1) {
        for (local, shape) in shapes {
            let pose: rapier3d::math::Pose = (frames[li] * local).cast::<f32>().into();
            for (epose, eshape, name) in &ex.env {
                let ep: rapier3d::math::Pose = epose.cast::<f32>().into();
                if intersection_test(&pose, &**shape, &ep, &**eshape).is_ok_and(|r| r.intersecting) {
                    return Some(format!("{} hits {name}", robot.links[li].name));
                }
            }
        }
    }
    None
}

/// Dense re-check of a path: samples at most 0.5 deg per joint and 1 mm of tool travel apart.
fn dense_check(ex: &Exact, robot: &RobotModel, path: &[[f64; 6]]) -> Result<usize, String> {
    let mut samples = 0;
    for w in path.windows(2) {
        let (a, b) = (JointVector::from(w[0]), JointVector::from(w[1]));
        let mut n = ((b - a).amax() / 0.5f64.to_radians()).ceil().max(1.0) as usize;
        loop {
            let tools: Vec<Vector3<f64>> = (0..=n)
                .map(|k| {
                    robot
                        .world_from_tool(&(a + (b - a) * (k as f64 / n as f64)))
                        .translation
                        .vector
                })
                .collect();
            if tools.windows(2).all(|t| (t[1] - t[0]).norm() <= 0.001) {
                break;
            }
            n *= 2;
        }
        for k in 0..=n {
            let q = a + (b - a) * (k as f64 / n as f64);
            if let Some(hit) = collides(ex, robot, &q) {
                return Err(format!(
                    "{hit} at {:.3} of edge {:?} -> {:?}",
                    k as f64 / n as f64,
                    w[0],
                    w[1]
                ));
            }
            samples += 1;
        }
    }
    Ok(samples)
}

fn setup() -> (LoadedScene, RobotModel) {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    (scene, robot)
}

fn plan_and_check(case: &PlannerCase, scene: &LoadedScene, robot: &RobotModel, alg: Algorithm, seed: u64) {
    let ex = exact(&case.model, scene);
    let opts = PlanOptions {
        algorithm: alg,
        ..PlanOptions::default()
    };
    let mut rng = binpick::rng::stream(seed, "planner");
    let plan = case
        .model
        .plan(&case.start, &case.goal, &opts, &mut rng)
        .unwrap_or_else(|e| panic!("{}: {e}", case.name));
    assert_eq!(plan.waypoints.first().map(|q| JointVector::from(*q)), Some(case.start));
    assert_eq!(plan.waypoints.last().map(|q| JointVector::from(*q)), Some(case.goal));
    for q in &plan.waypoints {
        assert!(
            robot.within_limits(&JointVector::from(*q), 1e-9),
            "{}: waypoint out of limits",
            case.name
        );
    }
    if let Err(e) = dense_check(&ex, robot, &plan.waypoints) {
        panic!("{} ({alg:?}, seed {seed}, {}): {e}", case.name, plan.how);
    }
}

#[test]
fn paths_of_the_three_reference_cases_pass_a_dense_exact_check() {
    let (scene, robot) = setup();
    for case in fig5_cases(&scene.scene, &robot).unwrap() {
        for seed in 1..=5 {
            plan_and_check(&case, &scene, &robot, Algorithm::Ours, seed);
        }
        plan_and_check(&case, &scene, &robot, Algorithm::RrtConnect, 1);
    }
}

#[test]
fn bin_picking_paths_pass_a_dense_exact_check() {
    let (scene, robot) = setup();
    let wps: Vec<LoadedWorkpiece> = ["B", "D"]
        .iter()
        .map(|n| LoadedWorkpiece::resolve(n).unwrap())
        .collect();
    let queries = binpicking_queries(&scene, &robot, &wps, 12).unwrap();
    assert_eq!(queries.len(), 12);
    for (k, q) in queries.iter().enumerate() {
        plan_and_check(q, &scene, &robot, Algorithm::Ours, k as u64);
    }
}

#[test]
fn certified_edges_are_collision_free_in_the_exact_check() {
    let (scene, robot) = setup();
    let mut rng = binpick::rng::stream(9, "edges");
    let (mut certified, mut rejected, mut stats) = (0, 0, PlanStats::default());
    for case in fig5_cases(&scene.scene, &robot).unwrap() {
        let ex = exact(&case.model, &scene);
        for _ in 0..60 {
            // Random edges around the start, many of them grazing the obstacle.
            let a = case.start + JointVector::from_fn(|_, _| rng.random_range(-0.4..0.4));
            let b = a + JointVector::from_fn(|_, _| rng.random_range(-0.8..0.8));
            if !(robot.within_limits(&a, 0.0) && robot.within_limits(&b, 0.0)) {
                continue;
            }
            if case.model.certify_edge(&a, &b, &mut stats) {
                certified += 1;
                if let Err(e) = dense_check(&ex, &robot, &[a.into(), b.into()]) {
                    panic!("{}: certified edge collides: {e}", case.name);
                }
            } else {
                rejected += 1;
            }
        }
    }
    assert!(
        certified > 20 && rejected > 20,
        "too few edges of either kind to mean anything: {certified} certified, {rejected} rejected"
    );
}

#[test]
fn failures_are_reported_with_their_reason() {
    let (scene, robot) = setup();
    let cases = fig5_cases(&scene.scene, &robot).unwrap();
    let case = &cases[2];
    let mut rng = binpick::rng::stream(1, "planner");
    // A start inside the container wall.
    let in_wall = robot
        .ik_tool_nearest(
            &binpick::robot::tool_down_pose(Vector3::new(0.40 + 0.065, 0.26, 0.05), 0.0),
            &case.start,
        )
        .unwrap()
        .q;
    match case.model.plan(&in_wall, &case.goal, &PlanOptions::default(), &mut rng) {
        Err(PlanError::StartInCollision(why)) => assert!(why.contains("container 1"), "{why}"),
        other => panic!("{other:?}"),
    }
    match case
        .model
        .plan(&case.start, &in_wall, &PlanOptions::default(), &mut rng)
    {
        Err(PlanError::GoalInCollision(_)) => {}
        other => panic!("{other:?}"),
    }
    // Plain RRT on the container case with a tiny budget runs out and says so.
    let opts = PlanOptions {
        algorithm: Algorithm::Rrt,
        budget_s: 0.05,
        ..PlanOptions::default()
    };
    match case.model.plan(&case.start, &case.goal, &opts, &mut rng) {
        Err(PlanError::BudgetExhausted { samples, .. }) => assert!(samples > 0),
        other => panic!("{other:?}"),
    }
}

#[test]
fn the_nearest_pair_is_named_only_on_request_and_the_same() {
    let (scene, robot) = setup();
    let mut rng = binpick::rng::stream(3, "nearest");
    let mut stats = PlanStats::default();
    let mut named = 0;
    for case in fig5_cases(&scene.scene, &robot).unwrap() {
        for _ in 0..50 {
            let q = case.start + JointVector::from_fn(|_, _| rng.random_range(-0.5..0.5));
            let (d, nearest) = case.model.nearest(&q, &mut stats);
            let (again, _) = case.model.nearest(&q, &mut stats);
            assert_eq!(d.to_bits(), again.to_bits());
            let name = case.model.describe(nearest);
            assert_eq!(name.is_empty(), d >= case.model.horizon_m, "{d} {name:?}");
            named += usize::from(!name.is_empty());
        }
    }
    assert!(named > 20, "only {named} configurations near anything");
}

/// The planner does not assume what it did not see. A hole in the height map (an
/// occlusion: nothing seen over a 6 x 6 cm patch of the pick tray) with the top of a 5 cm part
/// seen at its border hides that part. Left as a hole, the pile model certifies the tool's
/// descent into it (the negative control: the old behaviour); filled, it refuses it, as the
/// hidden part itself (ground truth, a box under the hole) does.
#[test]
fn the_planner_does_not_descend_into_what_it_did_not_see() {
    use binpick::geometry::NamedBox;
    use binpick::physics::TrayVolume;
    use binpick::pipeline::{HEIGHT_MAP_CELL_M, PILE_POOL_CELLS, pile_map};
    use binpick::planning::{Environment, PileColumns, RobotSpheres};
    use binpick::sensor::HeightMap;
    let (scene, robot) = setup();
    let tray = TrayVolume::new(&scene.scene.pick_tray);
    let [hx, hy] = tray.half_xy_m;
    let cell = HEIGHT_MAP_CELL_M;
    let (nx, ny) = (((2.0 * hx) / cell).ceil() as usize, ((2.0 * hy) / cell).ceil() as usize);
    // The floor seen everywhere at 0 (the walls' cells too; they are cleared as not pile).
    let mut hm = HeightMap {
        world_from_tray: tray.world_from_tray,
        cell_m: cell,
        nx,
        ny,
        origin_xy_m: [-hx, -hy],
        height_m: vec![0.0; nx * ny],
        mean_m: None,
    };
    let (hole_x, hole_y, hole_half) = (0.05, 0.0, 0.03);
    let cell_of = |x: f64, y: f64| (((y + hy) / cell).floor() as usize) * nx + ((x + hx) / cell).floor() as usize;
    for j in 0..ny {
        for i in 0..nx {
            let x = -hx + (i as f64 + 0.5) * cell;
            let y = -hy + (j as f64 + 0.5) * cell;
            if (x - hole_x).abs() < hole_half && (y - hole_y).abs() < hole_half {
                hm.height_m[j * nx + i] = f64::NAN;
            }
        }
    }
    // The hidden part's top edge, seen just outside the hole's corner.
    hm.height_m[cell_of(hole_x + hole_half + 0.001, hole_y + hole_half + 0.001)] = 0.05;
    let inner = [
        scene.scene.pick_tray.inner_size_m[0] / 2.0,
        scene.scene.pick_tray.inner_size_m[1] / 2.0,
    ];
    let model_of = |pile: &HeightMap| {
        let mut env = Environment::from_scene(&scene.scene);
        env.pile = Some(PileColumns::new(pile, PILE_POOL_CELLS, None));
        CollisionModel::new(&robot, RobotSpheres::new(&robot, &scene.scene, None), env)
    };
    let as_hole = model_of(&hm.without_walls(inner, f64::INFINITY));
    let filled = model_of(&pile_map(&scene.scene, &hm));
    // Ground truth: a 4 cm square part 4.5 cm tall under the hole's middle.
    let floor = tray.world_from_tray * nalgebra::Point3::new(hole_x, hole_y, 0.0);
    let mut truth_env = Environment::from_scene(&scene.scene);
    truth_env.boxes.push(NamedBox {
        name: "hidden part".into(),
        world_from_box: Isometry3::translation(floor.x, floor.y, floor.z + 0.0225),
        half_m: Vector3::new(0.02, 0.02, 0.0225),
    });
    let truth = CollisionModel::new(&robot, RobotSpheres::new(&robot, &scene.scene, None), truth_env);
    // The tool straight down into the hole: from 12 cm to 2 cm above the floor.
    let above = robot
        .ik_tool_nearest(
            &binpick::robot::tool_down_pose(floor.coords + Vector3::z() * 0.12, 0.0),
            &JointVector::from(scene.scene.robot.home_rad()),
        )
        .unwrap()
        .q;
    let into = robot
        .ik_tool_nearest(
            &binpick::robot::tool_down_pose(floor.coords + Vector3::z() * 0.02, 0.0),
            &above,
        )
        .unwrap()
        .q;
    let mut stats = PlanStats::default();
    assert!(
        as_hole.free(&above, &mut stats) && filled.free(&above, &mut stats),
        "the start above the tray must be free in both"
    );
    // The negative control: the hole, read as free, certifies a descent into the hidden part.
    assert!(as_hole.certify_edge(&above, &into, &mut stats));
    assert!(!truth.free(&into, &mut stats), "the hidden part is where the tool goes");
    // Filled, the pile refuses it.
    assert!(!filled.free(&into, &mut stats), "the unseen hole was taken as free");
    assert!(!filled.certify_edge(&above, &into, &mut stats));
    match filled.plan(
        &above,
        &into,
        &PlanOptions::default(),
        &mut binpick::rng::stream(1, "planner"),
    ) {
        Err(PlanError::GoalInCollision(why)) => assert!(why.contains("pile"), "{why}"),
        other => panic!("{other:?}"),
    }
}

/// Self-collision is caught by the planner and by the dense exact re-check alike. The pair the
/// planner used to miss: link 4 against the flange and hand (link 6), which meet beyond J5 ~110
/// deg (the derivation in `examples/derive_self_pairs.rs`; link 3 cannot reach the hand within
/// J5's +-120 deg, it stays 133 mm away). The negative control: the old eight pairs did not
/// include it, and the exact check sees the collision on its own shapes.
#[test]
fn self_collision_is_caught_by_the_planner_and_the_dense_check() {
    use binpick::planning::{Nearest, SELF_PAIRS};
    const OLD_PAIRS: [(usize, usize); 8] = [(0, 3), (0, 4), (0, 5), (0, 6), (1, 4), (1, 5), (1, 6), (2, 6)];
    let (scene, robot) = setup();
    let case = &fig5_cases(&scene.scene, &robot).unwrap()[0];
    let ex = exact(&case.model, &scene);
    let home = JointVector::from(scene.scene.robot.home_rad());
    let mut bent = home;
    bent[4] = 116f64.to_radians();
    let mut stats = PlanStats::default();
    // The exact shapes intersect, link 4 and link 6, and nothing else is hit.
    let hit = self_collides(&ex, &robot, &bent).expect("the exact shapes meet at J5 116 deg");
    assert!(hit.contains("link_4") && hit.contains("link_6"), "{hit}");
    assert!(collides(&ex, &robot, &home).is_none(), "home is clear");
    // The planner sees it, as the pair it used to miss.
    let (d, nearest) = case.model.nearest(&bent, &mut stats);
    assert_eq!(nearest, Nearest::Links(4, 6), "{d}");
    assert!(d <= case.model.margin_m && !case.model.free(&bent, &mut stats));
    assert!(SELF_PAIRS.contains(&(4, 6)) && !OLD_PAIRS.contains(&(4, 6)));
    // A path bending the wrist into it: refused by the planner, caught by the dense check.
    assert!(!case.model.certify_edge(&home, &bent, &mut stats));
    let e = dense_check(&ex, &robot, &[home.into(), bent.into()]).expect_err("the dense check misses it");
    assert!(e.contains("link_4 hits link_6"), "{e}");
    // Link 1 against link 3, the other pair that was missing, at the derivation's configuration.
    let mut folded = JointVector::zeros();
    folded[1] = (-156f64).to_radians();
    folded[2] = (-7f64).to_radians();
    let hit = self_collides(&ex, &robot, &folded).expect("link 1 and link 3 meet");
    assert!(hit.contains("link_1") && hit.contains("link_3"), "{hit}");
    assert!(!case.model.free(&folded, &mut stats));
}

/// Deepest penetration of the arm's exact shapes (links 1-6 and the hand) into the environment at
/// `q` [m] (0 when nothing intersects).
fn penetration_m(ex: &Exact, robot: &RobotModel, q: &JointVector) -> f64 {
    let frames = robot.world_from_links(q);
    let mut deepest = 0.0f64;
    for (li, shapes) in ex.links.iter().enumerate().skip(1) {
        for (local, shape) in shapes {
            let pose: rapier3d::math::Pose = (frames[li] * local).cast::<f32>().into();
            for (epose, eshape, _) in &ex.env {
                let ep: rapier3d::math::Pose = epose.cast::<f32>().into();
                if let Ok(Some(c)) = rapier3d::parry::query::contact(&pose, &**shape, &ep, &**eshape, 0.0) {
                    deepest = deepest.max(-(c.dist as f64));
                }
            }
        }
    }
    deepest
}

/// The three reference cases are not trivial: the straight joint-space edge from start to goal
/// collides, over a good part of its length and deeply, on the exact shapes (so a planner that
/// returned it, or a case edited until it became free, would show). Measured (2001 samples):
/// J1 case 31.4 % of the edge, 60.0 mm deep (link 3 into the wall); J2 case 46.7 %, 56.2 mm
/// (link 5 into the bar); J3 case 16.0 %, 19.9 mm (link 6 into container 1's wall). The floors
/// are about half of that.
#[test]
fn the_direct_edge_of_each_reference_case_collides_deeply() {
    let (scene, robot) = setup();
    // (least fraction of the edge in collision, least deepest penetration [m]) per case.
    let floors = [(0.15, 0.03), (0.20, 0.025), (0.08, 0.01)];
    let mut report = Vec::new();
    for (case, (min_fraction, min_depth_m)) in fig5_cases(&scene.scene, &robot).unwrap().iter().zip(floors) {
        let ex = exact(&case.model, &scene);
        let (a, b) = (case.start, case.goal);
        let n = 2000;
        let (mut hits, mut deepest, mut what) = (0, 0.0f64, String::new());
        for k in 0..=n {
            let q = a + (b - a) * (k as f64 / n as f64);
            if let Some(hit) = collides(&ex, &robot, &q) {
                hits += 1;
                let d = penetration_m(&ex, &robot, &q);
                if d > deepest {
                    (deepest, what) = (d, hit);
                }
            }
        }
        let fraction = hits as f64 / (n + 1) as f64;
        let line = format!(
            "{}: {:.1} % of the direct edge in collision, {:.1} mm deep at most ({what})",
            case.name,
            100.0 * fraction,
            deepest * 1e3
        );
        assert!(!case.model.certify_edge(&a, &b, &mut PlanStats::default()), "{line}");
        assert!(fraction >= min_fraction && deepest >= min_depth_m, "too easy: {line}");
        report.push(line);
    }
    println!("{}", report.join("\n"));
}

/// Not a check: a profiling and decision-diffing harness (`cargo test --release --test all profile_planner -- --ignored
/// --nocapture`). Plans the bench's sets (Fig. 5 cases, seeds 1..=100; the bin-picking queries)
/// `BINPICK_PROFILE_REPS` times (default 1) and prints per set the solved share, mean, p95 and
/// max time, clearance checks per plan and time per check. `BINPICK_PROFILE_ALGS`: `rrtc` adds
/// RRT-Connect, `all` RRT too (not on J3, where it fails); `BINPICK_PROFILE_WPS` (default
/// `ABCDEF`) and `BINPICK_PROFILE_BIN` (default 200) choose the bin-picking queries (small sets run
/// under valgrind). With `BINPICK_PROFILE_OUT`, one line per plan (set, query, algorithm, how,
/// samples, checks, edges, waypoints, a hash of the waypoints, ms) goes to that file: two builds'
/// files, time column aside, show whether a change altered any planning decision. Each plan
/// has a 2 s budget (the bench's: 10 s).
#[test]
#[ignore]
fn profile_planner() {
    use std::fmt::Write as _;
    let (scene, robot) = setup();
    let reps: usize = std::env::var("BINPICK_PROFILE_REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let algs: Vec<Algorithm> = match std::env::var("BINPICK_PROFILE_ALGS").as_deref() {
        Ok("all") => vec![Algorithm::Ours, Algorithm::RrtConnect, Algorithm::Rrt],
        Ok("rrtc") => vec![Algorithm::Ours, Algorithm::RrtConnect],
        _ => vec![Algorithm::Ours],
    };
    let wp_names = std::env::var("BINPICK_PROFILE_WPS").unwrap_or_else(|_| "ABCDEF".into());
    let n_bin: usize = std::env::var("BINPICK_PROFILE_BIN")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200);
    let wps: Vec<LoadedWorkpiece> = wp_names
        .chars()
        .map(|n| LoadedWorkpiece::resolve(&n.to_string()).unwrap())
        .collect();
    let mut sets: Vec<(String, Vec<(PlannerCase, u64)>)> = Vec::new();
    for case in fig5_cases(&scene.scene, &robot).unwrap() {
        let name = case.name.clone();
        sets.push((name, (0..100u64).map(|t| (clone_case(&case), 1 + t)).collect()));
    }
    let queries = binpicking_queries(&scene, &robot, &wps, n_bin).unwrap();
    sets.push((
        "bin picking".into(),
        queries
            .into_iter()
            .enumerate()
            .map(|(k, q)| (q, 1 + k as u64))
            .collect(),
    ));
    let mut out = String::new();
    for (set, cases) in &sets {
        for alg in &algs {
            if *alg == Algorithm::Rrt && set.starts_with("J3") {
                continue;
            }
            let opts = PlanOptions {
                algorithm: *alg,
                budget_s: 2.0,
                ..PlanOptions::default()
            };
            let mut times = Vec::new();
            let mut checks = 0usize;
            for rep in 0..reps {
                for (k, (case, seed)) in cases.iter().enumerate() {
                    let mut rng = binpick::rng::stream(*seed, "planner");
                    let r = case.model.plan(&case.start, &case.goal, &opts, &mut rng);
                    match &r {
                        Ok(p) => {
                            times.push(p.time_s * 1e3);
                            checks += p.stats.clearance_checks;
                            if rep == 0 {
                                let h = p
                                    .waypoints
                                    .iter()
                                    .flatten()
                                    .fold(0u64, |h, x| h.rotate_left(5) ^ x.to_bits());
                                let _ = writeln!(
                                    out,
                                    "{set}\t{k}\t{alg:?}\t{}\t{}\t{}\t{}\t{}\t{h:016x}\t{:.3}",
                                    p.how,
                                    p.stats.samples,
                                    p.stats.clearance_checks,
                                    p.stats.edges,
                                    p.waypoints.len(),
                                    p.time_s * 1e3
                                );
                            }
                        }
                        Err(e) => {
                            if rep == 0 {
                                let _ = writeln!(out, "{set}\t{k}\t{alg:?}\tfailed: {e}");
                            }
                        }
                    }
                }
            }
            times.sort_by(f64::total_cmp);
            let n = times.len().max(1);
            eprintln!(
                "{set:<50} {alg:<12?} solved {}/{} mean {:.3} p95 {:.3} max {:.3} ms, {:.0} checks, {:.2} us/check",
                times.len(),
                cases.len() * reps,
                times.iter().sum::<f64>() / n as f64,
                times
                    .get((n * 95).div_ceil(100).saturating_sub(1))
                    .copied()
                    .unwrap_or(0.0),
                times.last().copied().unwrap_or(0.0),
                checks as f64 / n as f64,
                times.iter().sum::<f64>() * 1e3 / checks.max(1) as f64
            );
        }
    }
    if let Ok(path) = std::env::var("BINPICK_PROFILE_OUT") {
        std::fs::write(path, out).unwrap();
    }
}

fn clone_case(c: &PlannerCase) -> PlannerCase {
    PlannerCase {
        name: c.name.clone(),
        model: c.model.clone(),
        start: c.start,
        goal: c.goal,
    }
}
