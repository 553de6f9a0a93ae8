//! The built-in parts as CAD: `binpick export-mesh` writes an STL and a mesh workpiece that
//! `binpick check` accepts, and a pile of the meshed part settles like a pile of its primitives
//! (the physics half of the meshed-six control).

use std::collections::HashMap;

use binpick::config::{LoadedScene, LoadedWorkpiece, ShapeKind};
use binpick::physics::pile::{PileOptions, PileReport};
use binpick::physics::{PartShape, World};
use binpick::robot::RobotModel;

use crate::support::{binpick, stderr, stdout, tempdir};

/// Every directed edge of the read-back STL appears once, and its reverse once.
fn closed(mesh: &stl_io::IndexedMesh) -> bool {
    let mut directed: HashMap<(usize, usize), usize> = HashMap::new();
    for f in &mesh.faces {
        for k in 0..3 {
            *directed.entry((f.vertices[k], f.vertices[(k + 1) % 3])).or_default() += 1;
        }
    }
    directed
        .iter()
        .all(|(&(a, b), &n)| n == 1 && directed.get(&(b, a)) == Some(&1))
}

#[test]
fn exported_parts_are_closed_meshes_whose_workpiece_files_check_and_keep_every_value() {
    let dir = tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let o = binpick(&["export-mesh", "--workpiece", "A,B,C,D,E,F", "--out", out]);
    assert!(o.status.success(), "{}", stderr(&o));
    for name in ["A", "B", "C", "D", "E", "F"] {
        let stl = dir.path().join(format!("{name}.stl"));
        let mesh = stl_io::read_stl(&mut std::fs::File::open(&stl).unwrap()).unwrap();
        assert!(closed(&mesh), "{name}: the STL is not closed");
        let toml = dir.path().join(format!("{name}-mesh.toml"));
        let c = binpick(&["check", toml.to_str().unwrap()]);
        assert!(c.status.success(), "{name}: {}", stderr(&c));
        assert!(
            stdout(&c).contains(&format!("ok: {}", toml.display())),
            "{}",
            stdout(&c)
        );
        let meshed = LoadedWorkpiece::from_file(&toml).unwrap().workpiece;
        let orig = LoadedWorkpiece::resolve(name).unwrap().workpiece;
        assert_eq!(meshed.shape.kind, ShapeKind::Mesh);
        assert_eq!(meshed.name, format!("{name}-mesh"));
        assert_eq!(
            (
                meshed.size_m,
                meshed.mass_kg,
                meshed.friction,
                meshed.restitution,
                meshed.pile_count,
                &meshed.grasp
            ),
            (
                orig.size_m,
                orig.mass_kg,
                orig.friction,
                orig.restitution,
                orig.pile_count,
                &orig.grasp
            ),
            "{name}"
        );
        // The STL's size (mm) matches size_m: the mesh workpiece's shape builds.
        let wp = LoadedWorkpiece::from_file(&toml).unwrap();
        PartShape::build(&wp.workpiece, &wp.source).unwrap();
    }
    // Negative control: a broken STL is caught by the same route (one triangle dropped).
    let stl = dir.path().join("E.stl");
    let mut mesh = stl_io::read_stl(&mut std::fs::File::open(&stl).unwrap()).unwrap();
    mesh.faces.pop();
    assert!(!closed(&mesh));
}

#[test]
fn export_refuses_a_mesh_workpiece_and_an_unknown_one_with_exit_2() {
    let dir = tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    assert!(
        binpick(&["export-mesh", "--workpiece", "E", "--out", out])
            .status
            .success()
    );
    let meshed = dir.path().join("E-mesh.toml");
    let o = binpick(&["export-mesh", "--workpiece", meshed.to_str().unwrap(), "--out", out]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("already a mesh workpiece"), "{}", stderr(&o));
    let sub = dir.path().join("none");
    let o = binpick(&["export-mesh", "--workpiece", "E,Q", "--out", sub.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(!sub.exists(), "nothing is written for bad input");
}

fn pile(wp: &LoadedWorkpiece, count: usize, seed: u64) -> PileReport {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let shape = PartShape::build(&wp.workpiece, &wp.source).unwrap();
    let mut w = World::new(&scene.scene, &robot, shape);
    w.build_pile(&PileOptions::new(count, seed)).unwrap()
}

/// Two piles are alike: both settled with every part in the tray, overlaps under 0.3 mm, heights
/// within 2 mm, and the share of parts lying flat (z axis within 10 deg of vertical) within
/// 25 points.
fn alike(a: &PileReport, b: &PileReport) -> Result<(), String> {
    let flat = |r: &PileReport| {
        let n = r
            .poses
            .iter()
            .filter(|p| {
                let [w, x, y, z] = p.quat_wxyz;
                let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
                (q * nalgebra::Vector3::z()).z.abs() > 10f64.to_radians().cos()
            })
            .count();
        n as f64 / r.poses.len() as f64
    };
    for r in [a, b] {
        if !r.settled || r.in_tray != r.spawned || r.max_penetration_m > 0.0003 {
            return Err(format!(
                "settled {} in tray {}/{} penetration {:.3} mm",
                r.settled,
                r.in_tray,
                r.spawned,
                r.max_penetration_m * 1e3
            ));
        }
    }
    let dh = (a.pile_height_m - b.pile_height_m).abs();
    if dh > 0.002 {
        return Err(format!("heights differ by {:.2} mm", dh * 1e3));
    }
    let df = (flat(a) - flat(b)).abs();
    if df > 0.25 {
        return Err(format!("flat shares {:.2} and {:.2}", flat(a), flat(b)));
    }
    Ok(())
}

#[test]
fn piles_of_meshed_parts_settle_like_piles_of_their_primitives() {
    let dir = tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    assert!(
        binpick(&["export-mesh", "--workpiece", "A,E", "--out", out])
            .status
            .success()
    );
    for (name, count) in [("A", 12), ("E", 24)] {
        let prim = LoadedWorkpiece::resolve(name).unwrap();
        let meshed = LoadedWorkpiece::from_file(&dir.path().join(format!("{name}-mesh.toml"))).unwrap();
        for seed in [1, 2] {
            let (p, m) = (pile(&prim, count, seed), pile(&meshed, count, seed));
            alike(&p, &m).unwrap_or_else(|e| panic!("{name} seed {seed}: {e}"));
        }
    }
    // Negative control: a pile of F (10 x 10 x 5 mm) is not like a pile of E (10 x 5 x 10 mm).
    let (e, f) = (
        LoadedWorkpiece::resolve("E").unwrap(),
        LoadedWorkpiece::resolve("F").unwrap(),
    );
    assert!(alike(&pile(&e, 24, 1), &pile(&f, 24, 1)).is_err());
}
