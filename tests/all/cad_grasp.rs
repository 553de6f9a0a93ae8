//! Grasps on CAD parts read the part model: the hand's approach stays clear of the part's own
//! features above a face (a face whose every cup site would bring the cup or the tool body onto
//! a post of the part is not offered), and the suction peel model reads the part model's true
//! centre of mass, not the bounding box's centre.
//!
//! The parts are written here as OBJ files (mm) of boxes; the expected centres of mass are
//! computed from the boxes' volumes, independently of the part model's mass properties.

use std::path::{Path, PathBuf};

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::grasp::GraspSelector;
use binpick::robot::RobotModel;

use crate::support::{binpick_in, stderr, stdout, tempdir};

/// OBJ text (mm) of axis-aligned boxes given by their corners, each a closed body.
fn boxes_obj(boxes: &[([f64; 3], [f64; 3])]) -> String {
    let mut s = String::new();
    let tris = crate::support::BOX_TRIANGLES;
    for (k, (lo, hi)) in boxes.iter().enumerate() {
        for i in 0..8 {
            let x = if i & 1 == 0 { lo[0] } else { hi[0] };
            let y = if (i >> 1) & 1 == 0 { lo[1] } else { hi[1] };
            let z = if (i >> 2) & 1 == 0 { lo[2] } else { hi[2] };
            s += &format!("v {x} {y} {z}\n");
        }
        for t in &tris {
            s += &format!("f {} {} {}\n", 8 * k + t[0] + 1, 8 * k + t[2] + 1, 8 * k + t[1] + 1);
        }
    }
    s
}

/// A mesh workpiece of `boxes` (mm) in `dir`, loaded.
fn workpiece(dir: &Path, name: &str, boxes: &[([f64; 3], [f64; 3])]) -> LoadedWorkpiece {
    std::fs::write(dir.join(format!("{name}.obj")), boxes_obj(boxes)).unwrap();
    let p: PathBuf = dir.join(format!("{name}.toml"));
    std::fs::write(
        &p,
        format!(
            "name = \"{name}\"\nkind = \"grasp test part\"\nmass_kg = 0.004\nfriction = 0.4\nrestitution = 0.1\n\
             pile_count = 10\n\n[shape]\nkind = \"mesh\"\nmesh_file = \"{name}.obj\"\nunits = \"mm\"\n\n\
             [grasp]\nyaw_symmetry_deg = 360.0\nplace_yaw_deg = 0.0\nface_margin_m = 0.0005\n"
        ),
    )
    .unwrap();
    LoadedWorkpiece::resolve(p.to_str().unwrap()).unwrap()
}

/// A 20 x 20 x 2 mm plate with a 2 x 2 mm post of height `post_mm` standing in its middle.
fn plate_with_post(post_mm: f64) -> Vec<([f64; 3], [f64; 3])> {
    vec![
        ([0.0, 0.0, 0.0], [20.0, 20.0, 2.0]),
        ([9.0, 9.0, 2.0], [11.0, 11.0, 2.0 + post_mm]),
    ]
}

#[test]
fn a_face_under_a_tall_post_of_the_part_is_not_offered() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let tmp = tempdir().unwrap();
    // A 12 mm post: the tool body (15 mm radius from 9 mm above the cup lip) would meet it from
    // every cup site on the 20 mm plate's top, so only the bottom is offered. Independent: the
    // farthest a cup site can be from the post's axis is the plate's corner region, under
    // 10 sqrt(2) = 14.1 mm, less than the body's radius.
    let tall = workpiece(tmp.path(), "tall", &plate_with_post(12.0));
    let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &tall);
    assert_eq!(sel.blocked_faces(), 1, "{:?}", sel.faces());
    // Its bottom is up only where it lies on the post's top and the plate's rim, tilted by at
    // least atan(12 / 12.7) = 43 deg (12 mm of post against at most 12.7 mm from the post's
    // corner to the plate's), beyond the tool's 40 deg lean: a part held by it could not be set
    // down as held, so it is not offered either.
    assert_eq!(sel.unplaceable_faces(), 1);
    assert!(sel.faces().is_empty(), "{:?}", sel.faces());
    // Negative control: a 6 mm post stays under the tool body and 3.5 mm from the cup's site:
    // both the top (around the post) and the bottom are offered.
    let short = workpiece(tmp.path(), "short", &plate_with_post(6.0));
    let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &short);
    assert_eq!(sel.blocked_faces(), 0);
    assert_eq!(sel.faces().len(), 2, "{:?}", sel.faces());
    let top = sel.faces().iter().position(|f| f.normal.z > 0.999).unwrap();
    let site = sel.sites_m()[top];
    // The top's site keeps the cup (3 mm, plus the pose's noise) off the post's sides, which
    // stand 1 mm from its axis: independently, its distance from the axis in the plane.
    let post_axis = nalgebra::Vector3::new(0.0, 0.0, 0.0);
    let d = (site - post_axis).xy().norm();
    assert!(d >= 0.001 + 0.003, "site {site:?} is {d} m from the post's axis");
    // `binpick part` marks the blocked face within the terminal's 110 columns and says why (its
    // row ran to 122 with the reason in it); the short post's part has no such mark.
    let part = |name: &str| {
        let toml = tmp.path().join(format!("{name}.toml"));
        let o = binpick_in(tmp.path(), &["part", toml.to_str().unwrap()]);
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let text = part("tall");
    let longest = text.lines().map(|l| l.chars().count()).max().unwrap();
    assert!(longest <= 110, "a line of {longest} characters:\n{text}");
    assert!(
        text.contains("blocked *") && text.contains("its approach meets the part's own features"),
        "{text}"
    );
    assert!(!part("short").contains("blocked"));
}

#[test]
fn the_peel_model_reads_the_true_centre_of_mass() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let tmp = tempdir().unwrap();
    // A 40 x 20 x 2 mm plate with a 10 x 20 x 8 mm block on one end (x from 30 to 40 mm). The
    // bounding box is 40 x 20 x 10 mm, centred at (20, 10, 5) mm. Independent centre of mass:
    // plate 1600 mm^3 at (20, 10, 1), block 1600 mm^3 at (35, 10, 6): (27.5, 10, 3.5) mm,
    // 7.5 mm along x and -1.5 mm along z from the box's centre.
    let heavy_end = workpiece(
        tmp.path(),
        "heavy",
        &[
            ([0.0, 0.0, 0.0], [40.0, 20.0, 2.0]),
            ([30.0, 0.0, 2.0], [40.0, 20.0, 10.0]),
        ],
    );
    let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &heavy_end);
    let com = sel.peel_com_m();
    let want = nalgebra::Vector3::new(0.0075, 0.0, -0.0015);
    assert!((com - want).norm() < 1e-6, "{com:?} vs {want:?}");
    // Negative control: the bounding box's centre, which the peel model read before, is 7.6 mm
    // off; and a symmetric part's centre of mass is its box's centre.
    assert!(com.norm() > 0.007);
    let plate = workpiece(tmp.path(), "plate", &[([0.0, 0.0, 0.0], [40.0, 20.0, 2.0])]);
    assert!(
        GraspSelector::for_workpiece(&scene.scene, &robot, &plate)
            .peel_com_m()
            .norm()
            < 1e-9
    );
    // A built-in part reads its meshed primitives' centre of mass too. Independent: the relay's
    // 20 x 30 x 7 mm body centred 1.5 mm up, and five 3 mm pins centred 3.5 mm down (16-sided
    // prisms of radius 0.5 mm: area 8 r^2 sin 22.5 deg), four at the corners, one at y = -4 mm.
    let a = LoadedWorkpiece::resolve("A").unwrap();
    let (body, pin) = (20.0 * 30.0 * 7.0, 8.0 * 0.25 * 22.5f64.to_radians().sin() * 3.0);
    let total = body + 5.0 * pin;
    let want = nalgebra::Vector3::new(0.0, pin * -4.0 / total, (body * 1.5 + 5.0 * pin * -3.5) / total) * 1e-3;
    let com = GraspSelector::for_workpiece(&scene.scene, &robot, &a).peel_com_m();
    assert!((com - want).norm() < 1e-8, "{com:?} vs {want:?}");
    assert!(com.norm() > 1e-3, "the bounding box's centre would be 1.49 mm off");
}

/// A mesh part's place slots come from its footprint in its place orientation, a stable pose:
/// the hex standoff grasped on a flat lies on the opposite flat, its axis level, so it needs
/// 20 mm along its axis and 16.17 mm (across corners) beside it, where its bounding box's
/// 16.17 x 14 mm (standing on its end) would let neighbours overlap. Independent: the hexagon's
/// across-corners width is 14 / cos 30 deg, and the flat-down part's axis is 7 mm above the
/// floor (half the 14 mm across flats).
#[test]
fn place_slots_fit_the_footprint_of_a_stable_pose() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let hex = LoadedWorkpiece::resolve(concat!(env!("CARGO_MANIFEST_DIR"), "/workpieces/hex-standoff.toml")).unwrap();
    let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &hex);
    let corners = 0.014 / (30f64.to_radians()).cos();
    let mut fp = sel.place_footprint_m();
    fp.sort_by(f64::total_cmp);
    assert!((fp[0] - corners).abs() < 1e-6 && (fp[1] - 0.02).abs() < 1e-6, "{fp:?}");
    for fi in 0..sel.faces().len() {
        let p = sel.place_pose(fi).expect("a flat has a place pose");
        assert!((p.origin_height_m - 0.007).abs() < 1e-6, "{p:?}");
        // The grasped flat looks straight up in the slot.
        let up = p.slot_from_part * sel.faces()[fi].normal;
        assert!(up.z > 1.0 - 1e-9, "{up:?}");
    }
    // The slots are spaced for it: neighbours' centres at least the footprint apart.
    let slots = scene
        .scene
        .world_from_slots_for(&hex.workpiece, sel.place_footprint_m());
    assert!(!slots.is_empty());
    for (i, a) in slots.iter().enumerate() {
        for b in &slots[i + 1..] {
            let d = (a.translation.vector - b.translation.vector).abs();
            let fpr = sel.place_footprint_m();
            assert!(d.x >= fpr[0] - 1e-9 || d.y >= fpr[1] - 1e-9, "{d:?}");
        }
    }
    // Negative control: the bounding box's footprint is 4 mm short of the lying part's length.
    let bbox = [hex.workpiece.size_m[0], hex.workpiece.size_m[1]];
    assert!(bbox[0].max(bbox[1]) < 0.02 - 0.003, "{bbox:?}");
    // A built-in part is placed in its meshed primitives' stable poses too: the relay grasped
    // on its top stands on its pins, its centre 5 mm up (the pins reach 5 mm below it), where
    // its box's placement put it 5 mm up on a floor its pins would go through.
    let a = LoadedWorkpiece::resolve("A").unwrap();
    let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &a);
    let top = sel
        .faces()
        .iter()
        .position(|f| f.normal.z > 1.0 - 1e-9)
        .expect("the top takes the cup");
    let p = sel.place_pose(top).expect("standing on its pins is a stable pose");
    assert!((p.origin_height_m - 0.005).abs() < 1e-9, "{p:?}");
    assert!((p.slot_from_part * nalgebra::Vector3::z()).z > 1.0 - 1e-9);
}

/// A part declared symmetric where its mesh is not (the relay A: a half turn about z, which its
/// fifth pin at y = -4 mm breaks) is recognised only up to that turn, so a cup site on its pinned
/// face must clear the pins of both poses: the pins at (0, -4) and, turned, (0, +4) mm.
/// Independent: the site's distance in the face's plane from both pins' axes, against the cup's
/// radius plus the pin's. Negative control: sites chosen on the mesh alone (the part as it is,
/// not as the cell may find it) put the cup on the turned pin (the half turn of A seed 8, pick 8,
/// which pressed a relay 2.5 mm into the tray floor).
#[test]
fn a_cup_site_clears_the_features_of_every_pose_recognition_cannot_tell_apart() {
    use binpick::part::approach::{ColumnPiece, clear_site};
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let a = LoadedWorkpiece::resolve("A").unwrap();
    let cup_m = scene.scene.gripper.cup_diameter_m;
    let (cup_r, pin_r) = (cup_m / 2.0, 0.0005);
    let pins = [nalgebra::Vector2::new(0.0, -0.004), nalgebra::Vector2::new(0.0, 0.004)];
    let clear = |site: &nalgebra::Vector3<f64>| pins.iter().all(|p| (site.xy() - p).norm() >= cup_r + pin_r);
    let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &a);
    let pinned = sel
        .faces()
        .iter()
        .position(|f| f.normal.z < -1.0 + 1e-9)
        .expect("the pinned face is offered");
    let site = sel.sites_m()[pinned];
    assert!(clear(&site), "the cup on the pinned face at {site:?} meets a pin");
    // Negative control: the same search on the mesh alone.
    let w = &a.workpiece;
    let pm = w.part_model(&w.primitive_mesh().unwrap(), cup_m).unwrap();
    let face = pm.grasp_faces().find(|f| f.face.normal.z < -1.0 + 1e-9).unwrap();
    let column = [ColumnPiece {
        radius_m: cup_r,
        from_m: 0.0,
        to_m: 0.008,
    }];
    let (alone, _) = clear_site(&pm.mesh, &face.face, &face.fit.centres, &column).unwrap();
    let alone = face.face.to_part(&alone).coords;
    assert!(
        !clear(&alone),
        "without the turned images the site {alone:?} would clear both pins"
    );
}

/// An L-shaped bracket (mm): a 20 x 15 x 1.5 mm base and a 20 x 1.5 x 8.5 mm upright on one long
/// edge. Lying with its base's underside up it rests tilted on the upright's edge and the base's
/// far edge, the underside 32.2 deg off level (independently: the hull's edge from (y, z) =
/// (15, 1.5) to (1.5, 10) has the outward normal (8.5, 13.5) / 15.95 in y, z; cos = 0.846).
/// That face is offered, its part set down tilted so (a face grasped and set down level tipped
/// over in its slot: misplaced by 32.2 deg in every such pick); the upright's outer face, up
/// in no stable pose within the tool's 40 deg lean, is not. Negative control: with no lean
/// beyond the 20 deg tilt, the underside is not offered either.
#[test]
fn a_face_no_stable_pose_has_up_within_the_lean_is_not_offered() {
    let mut scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let tmp = tempdir().unwrap();
    let l = workpiece(
        tmp.path(),
        "bracket",
        &[
            ([0.0, 0.0, 0.0], [20.0, 15.0, 1.5]),
            ([0.0, 0.0, 1.5], [20.0, 1.5, 10.0]),
        ],
    );
    let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &l);
    let under = sel
        .faces()
        .iter()
        .position(|f| f.normal.z < -0.999 && f.extent_m[0] * f.extent_m[1] > 2.9e-4)
        .expect("the base's underside is offered");
    let place = sel.place_pose(under).expect("a place pose");
    let up = place.slot_from_part * sel.faces()[under].normal;
    assert!((up.z - 0.846).abs() < 0.002, "the underside in its slot: {up:?}");
    assert!(!sel.faces().iter().any(|f| f.normal.y < -0.999), "{:?}", sel.faces());
    let unplaceable = sel.unplaceable_faces();
    assert!(unplaceable >= 1);
    // `binpick part` says so: the upright's face not placeable, marked in the faces' table.
    let toml = tmp.path().join("bracket.toml");
    let o = binpick_in(
        tmp.path(),
        &["part", toml.to_str().unwrap(), "--json", "--piles", "0", "--drops", "0"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let placeable = |ny: f64| {
        v["faces"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|f| (f["normal"][1].as_f64().unwrap() - ny).abs() < 1e-3 && f["area_mm2"].as_f64().unwrap() > 100.0)
            .map(|f| f["cup_fit"]["placeable"].as_bool().unwrap())
            .collect::<Vec<_>>()
    };
    assert_eq!(placeable(-1.0), [false], "{}", v["faces"]);
    assert!(placeable(0.0).iter().all(|p| *p), "{}", v["faces"]);
    let o = binpick_in(
        tmp.path(),
        &["part", toml.to_str().unwrap(), "--piles", "0", "--drops", "0"],
    );
    assert!(stdout(&o).contains("no pose +"), "{}", stdout(&o));
    scene.scene.gripper.max_lean_deg = Some(scene.scene.gripper.max_tilt_deg);
    let level = GraspSelector::for_workpiece(&scene.scene, &robot, &l);
    assert_eq!(level.unplaceable_faces(), unplaceable + 1);
    assert!(
        !level
            .faces()
            .iter()
            .any(|f| f.normal.z < -0.999 && f.extent_m[0] * f.extent_m[1] > 2.9e-4)
    );
}
