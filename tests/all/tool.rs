//! The tool per workpiece (`[gripper]` in a workpiece file): the cup it brings is the one every
//! stage of a run reads. A cell whose own cup fits none of B's faces places B parts when B brings
//! a cup that fits, and places none when B brings none (negative control); the other way round,
//! B bringing a cup too large for its faces places nothing in a cell whose cup fits. On the
//! command line the cup that fits no face is refused naming the file, the key and the value, and
//! `sweep --set workpiece.gripper.cup_diameter_m` reaches it.

use binpick::config::{LoadedScene, LoadedWorkpiece, OnEmpty, Source};
use binpick::cycle::RunOptions;
use binpick::robot::RobotModel;

use crate::support::{Workspace, binpick_in, stderr, without_cup_section};

/// B's file (30 x 30 x 20 mm) without the cup it brings (its `[gripper]` section and the
/// comment above it).
fn b_without_cup(text: &str) -> String {
    let own = text
        .find("[gripper]")
        .map_or(text.len(), |i| text[..i].rfind("\n\n").map_or(i, |j| j + 1));
    text[..own].to_string()
}

/// B without its own cup, with `section` appended.
fn b_with(section: &str) -> LoadedWorkpiece {
    let text = format!(
        "{}\n{section}",
        b_without_cup(binpick::config::embedded::WORKPIECES[1].1)
    );
    LoadedWorkpiece::from_text("B-cup.toml", Source::Embedded, &text).unwrap()
}

/// Parts placed in 3 deterministic picks of `wp` in the default cell with a cup of `cell_cup_m`,
/// the run ending when nothing is graspable.
fn placed(cell_cup_m: f64, wp: &LoadedWorkpiece) -> usize {
    let mut scene = LoadedScene::embedded_default().unwrap();
    scene.scene.gripper.cup_diameter_m = cell_cup_m;
    scene.scene.cycle.on_empty = OnEmpty::End;
    let robot = RobotModel::from_scene(&scene).unwrap();
    let opts = RunOptions::deterministic(3, 1);
    let r = binpick::cycle::run(&scene, &robot, wp, &opts, &mut ()).unwrap();
    r.tally.placed
}

#[test]
fn the_cup_a_workpiece_brings_decides_what_the_cell_can_place() {
    // The cell's 35 mm cup fits none of B's faces (30 x 30 and 30 x 20 mm). (A 6 mm cup fits
    // them too, but holds the 30 g block, its centre of mass 10-15 mm below the lip, only
    // while nothing pushes it sideways: its lifts tear it off.)
    let own_fits = b_with("[gripper]\ncup_diameter_m = 0.010\n");
    assert!(placed(0.035, &own_fits) > 0, "B's own 10 mm cup must place parts");
    // Negative control: the same cell, B without a cup of its own.
    let plain = b_with("");
    assert_eq!(placed(0.035, &plain), 0, "the cell's 35 mm cup fits no face of B");
    // And the other way: B's own 35 mm cup in a cell whose 6 mm cup fits.
    let own_too_large = b_with("[gripper]\ncup_diameter_m = 0.035\n");
    assert_eq!(placed(0.006, &own_too_large), 0, "B's own 35 mm cup fits no face");
}

#[test]
fn a_cell_not_resolved_for_the_workpieces_cup_is_refused_by_the_cycle() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let b = b_with("[gripper]\ncup_diameter_m = 0.012\n");
    let opts = RunOptions::deterministic(1, 1);
    let e = binpick::cycle::Cell::new(&scene, &robot, &b, opts)
        .err()
        .expect("refused");
    assert!(e.to_string().contains("not resolved"), "{e}");
    // Negative control: resolved, the same cell sets up, with the workpiece's cup in its models.
    let resolved = scene.for_workpiece(&b);
    let cell = binpick::cycle::Cell::new(&resolved, &robot, &b, opts).unwrap();
    assert_eq!(cell.scene.gripper.cup_diameter_m, 0.012);
    let here = nalgebra::Isometry3::identity();
    let seal = cell.selector.seal_budget(&here, &here);
    assert!((seal.model.cup_radius_m - 0.006).abs() < 1e-12);
}

#[test]
fn a_workpiece_cup_that_fits_no_face_exits_2_and_a_sweep_reaches_the_key() {
    let ws = Workspace::new();
    let big = ws.path("workpieces/B-big.toml");
    let text = std::fs::read_to_string(ws.path("workpieces/B.toml")).unwrap();
    let text = b_without_cup(&text);
    std::fs::write(&big, format!("{text}\n[gripper]\ncup_diameter_m = 0.035\n")).unwrap();
    let out = ws.path("runs");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "run",
            "--workpiece",
            big.to_str().unwrap(),
            "--picks",
            "1",
            "--deterministic",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("B-big.toml: size_m has no face the suction cup fits on: cup 0.035 m"),
        "{err}"
    );
    assert!(!out.exists());
    // The same through a sweep of B's own cup: the variant with 35 mm is refused, naming it.
    let o = binpick_in(
        ws.dir.path(),
        &[
            "sweep",
            "--workpieces",
            "B",
            "--set",
            "workpiece.gripper.cup_diameter_m=0.008,0.035",
            "--picks",
            "1",
            "--deterministic",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("sweep variant 2: workpiece.gripper.cup_diameter_m=0.035") && err.contains("cup 0.035 m"),
        "{err}"
    );
    assert!(!out.exists());
    // Negative control: a cup that fits runs, and the variant's workpiece file names it in full.
    let o = binpick_in(
        ws.dir.path(),
        &[
            "sweep",
            "--workpieces",
            "B",
            "--set",
            "workpiece.gripper.cup_diameter_m=0.012",
            "--seeds",
            "1",
            "--picks",
            "1",
            "--deterministic",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = std::fs::read_dir(&out).unwrap().next().unwrap().unwrap().path();
    let w = std::fs::read_to_string(dir.join("variant-1/workpiece-B.toml")).unwrap();
    assert!(w.contains("[gripper]") && w.contains("cup_diameter_m = 0.012"), "{w}");
    assert!(w.contains("release_s = 0.06"), "the cup is written in full: {w}");
}

/// Counts, from the world itself, the parts the cup lifted and those of them it held by the side
/// of their can (the can's axis, the part's z, within 30 deg of level when first held).
#[derive(Default)]
struct SideGrasps {
    held: usize,
    by_the_side: usize,
    last: Option<usize>,
}

impl binpick::cycle::Observer for SideGrasps {
    fn stepped(&mut self, world: &binpick::physics::World) {
        let now = world.held_part();
        if let Some(i) = now
            && self.last != now
        {
            self.held += 1;
            let axis = world.part_pose(i).rotation * nalgebra::Vector3::z();
            if axis.z.abs() < 30f64.to_radians().sin() {
                self.by_the_side += 1;
            }
        }
        self.last = now;
    }
}

/// What 24 deterministic picks of D (seed 1) with a 4 mm cup of its own did: the placed count and
/// the grasps seen from the world. `round_min_radius_m`: the roundest surface the cup seals on.
fn d_with_cup(round_min_radius_m: Option<f64>) -> (usize, SideGrasps) {
    let mut section = String::from("[gripper]\ncup_diameter_m = 0.004\n");
    if let Some(r) = round_min_radius_m {
        section.push_str(&format!("round_min_radius_m = {r}\n"));
    }
    let text = format!(
        "{}\n{section}",
        without_cup_section(binpick::config::embedded::WORKPIECES[3].1)
    );
    let wp = LoadedWorkpiece::from_text("D-cup.toml", Source::Embedded, &text).unwrap();
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let opts = RunOptions::deterministic(24, 1);
    let mut seen = SideGrasps::default();
    let r = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut seen).unwrap();
    (r.tally.placed, seen)
}

#[test]
fn a_cup_that_seals_on_round_surfaces_picks_lying_cans_by_their_side() {
    let (placed, seen) = d_with_cup(Some(0.004));
    // Seed 1's pile offers cans standing on end first: the first 16 are taken by their ends.
    assert!(
        seen.by_the_side >= 4,
        "lying cans taken by the side: {} of {}",
        seen.by_the_side,
        seen.held
    );
    assert!(placed >= 23, "placed {placed} of 24");
    // Negative control: the same cup for flat faces only never holds a can by its side.
    let (_, seen) = d_with_cup(None);
    assert!(seen.held > 0);
    assert_eq!(
        seen.by_the_side, 0,
        "a flat-face cup held {} cans by the side",
        seen.by_the_side
    );
}

#[test]
fn a_round_surface_radius_within_the_cup_exits_2_naming_file_key_and_value() {
    let ws = Workspace::new();
    let text = without_cup_section(&std::fs::read_to_string(ws.path("workpieces/D.toml")).unwrap());
    let check = |name: &str, section: &str| {
        let path = ws.path(&format!("workpieces/{name}"));
        std::fs::write(&path, format!("{text}\n[gripper]\n{section}")).unwrap();
        binpick_in(ws.dir.path(), &["check", path.to_str().unwrap()])
    };
    // A 6 mm cup cannot seal on anything rounder than its own 3 mm radius.
    let o = check("D-bad.toml", "cup_diameter_m = 0.006\nround_min_radius_m = 0.002\n");
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("D-bad.toml") && err.contains("gripper.round_min_radius_m") && err.contains("got 0.002"),
        "{err}"
    );
    let o = check("D-neg.toml", "round_min_radius_m = -0.004\n");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("gripper.round_min_radius_m"), "{}", stderr(&o));
    // Negative control: a radius beyond the cup's is accepted.
    let o = check("D-ok.toml", "cup_diameter_m = 0.004\nround_min_radius_m = 0.004\n");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}
