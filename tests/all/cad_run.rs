//! A CAD part through the whole cell: a short deterministic run of the shipped hex standoff (an
//! STL mesh workpiece) recognises it from the cloud through its part model's planar faces, grasps
//! it within a face's cup-fit region and places it, without a collision or a protective stop.

use binpick::config::{LoadedScene, LoadedWorkpiece};
use binpick::cycle::RunOptions;
use binpick::grasp::GraspSelector;
use binpick::robot::RobotModel;

fn hex_standoff() -> LoadedWorkpiece {
    LoadedWorkpiece::resolve(concat!(env!("CARGO_MANIFEST_DIR"), "/workpieces/hex-standoff.toml")).unwrap()
}

/// Three deterministic picks of seed 1: at least one placed, every grasp on a correctly
/// recognised part, 0 collisions, 0 protective stops. The grasp faces are the standoff's six
/// 8 mm flats (checked independently: unit normals perpendicular to the part's axis, 7 mm from
/// it). Negative control: with a 16 mm cup no face takes the cup, so the selector offers none.
#[test]
fn a_hex_standoff_is_recognised_grasped_and_placed() {
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = hex_standoff();
    let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &wp);
    assert_eq!(sel.faces().len(), 6, "{:?}", sel.faces());
    for f in sel.faces() {
        assert!(f.normal.z.abs() < 1e-9 && (f.normal.norm() - 1.0).abs() < 1e-9, "{f:?}");
        assert!((f.center.dot(&f.normal) - 0.007).abs() < 1e-6, "{f:?}");
    }
    let mut big = scene.clone();
    big.scene.gripper.cup_diameter_m = 0.016;
    assert!(GraspSelector::for_workpiece(&big.scene, &robot, &wp).faces().is_empty());

    let opts = RunOptions {
        picks: 3,
        seed: 1,
        deterministic: true,
        stop: None,
        keep_records: true,
    };
    let r = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut ()).unwrap();
    let s = &r.tally;
    let outcomes: Vec<String> = r
        .records
        .iter()
        .map(|p| format!("{} {}", p.outcome.name(), p.outcome.detail()))
        .collect();
    assert!(s.placed >= 1, "{} of {} placed: {outcomes:?}", s.placed, s.attempts);
    assert_eq!(s.faults.collisions, 0, "{outcomes:?}");
    assert_eq!(s.faults.protective_stops, 0, "{outcomes:?}");
    assert_eq!(s.misrecognised, 0, "{outcomes:?}");
}

/// Axis-aligned boxes (mm, `[x0, y0, z0, x1, y1, z1]`) as one OBJ of closed bodies, as CAD
/// exporters write a part of several solids.
fn boxes_obj(boxes: &[[f64; 6]]) -> String {
    let mut s = String::new();
    for (n, b) in boxes.iter().enumerate() {
        // Corners numbered by their bits, as `BOX_TRIANGLES` winds them.
        for i in 0..8 {
            let (x, y, z) = (b[3 * (i & 1)], b[1 + 3 * ((i >> 1) & 1)], b[2 + 3 * ((i >> 2) & 1)]);
            s += &format!("v {x} {y} {z}\n");
        }
        for t in crate::support::BOX_TRIANGLES {
            s += &format!("f {} {} {}\n", 8 * n + t[0] + 1, 8 * n + t[1] + 1, 8 * n + t[2] + 1);
        }
    }
    s
}

/// A through-hole RJ45 jack (mm): a 15.9 x 21.3 x 13.5 mm housing with its plug's cavity open at
/// the front, eight 3 mm pins and two 3.2 mm posts beneath.
fn jack_obj() -> String {
    let (w, d, h, cw, ch) = (15.9, 21.3, 13.5, 11.7, 8.0);
    let (y0, cavity_end) = (-d / 2.0, -d / 2.0 + 14.0);
    let mut boxes = vec![
        [-w / 2.0, cavity_end, 0.0, w / 2.0, d / 2.0, h],
        [-w / 2.0, y0, 0.0, -cw / 2.0, cavity_end, h],
        [cw / 2.0, y0, 0.0, w / 2.0, cavity_end, h],
        [-cw / 2.0, y0, 0.0, cw / 2.0, cavity_end, (h - ch) / 2.0],
        [-cw / 2.0, y0, (h + ch) / 2.0, cw / 2.0, cavity_end, h],
    ];
    for k in 0..8 {
        let x = -4.445 + 1.27 * k as f64;
        let y = if k % 2 == 1 { 4.0 } else { 6.54 };
        boxes.push([x - 0.25, y - 0.25, -3.0, x + 0.25, y + 0.25, 0.0]);
    }
    for x in [-5.715, 5.715] {
        boxes.push([x - 1.6, -1.6, -3.2, x + 1.6, 1.6, 0.0]);
    }
    boxes_obj(&boxes)
}

/// The cycle's motion plans: the Place motions generated, and the failures passed over; the
/// largest wrist deviation of a Place line made with the wrist joints interpolated (rad).
#[derive(Default)]
struct PlannedMotions {
    failed: Vec<String>,
    planned: usize,
    wrist_deviation_rad: Option<f64>,
}

impl binpick::cycle::Observer for PlannedMotions {
    fn event(&mut self, _t_s: f64, _pick: Option<usize>, event: &binpick::cycle::Event) {
        match event {
            binpick::cycle::Event::Planned(binpick::cycle::Planned::Failed { why }) => {
                self.failed.push(why.to_string())
            }
            binpick::cycle::Event::Planned(binpick::cycle::Planned::Place {
                wrist_deviation_rad, ..
            }) => {
                self.planned += 1;
                if let Some(d) = wrist_deviation_rad {
                    self.wrist_deviation_rad = Some(self.wrist_deviation_rad.unwrap_or(0.0).max(*d));
                }
            }
            _ => {}
        }
    }
}

/// The jack's workpiece file (its mesh `jack.obj` beside it, [`jack_obj`]).
const JACK_TOML: &str = "name = \"jack\"\nkind = \"RJ45 jack\"\nmass_kg = 0.004\nfriction = 0.4\n\
    restitution = 0.1\npile_count = 25\n\n[shape]\nkind = \"mesh\"\nmesh_file = \"jack.obj\"\nunits = \"mm\"\n\n\
    [grasp]\nyaw_symmetry_deg = 360.0\nplace_yaw_deg = 0.0\nface_margin_m = 0.0005\n";

/// The jack's run (2 picks, seed 1, deterministic) with the controller's wrist interpolation
/// allowed up to `wrist_deviation_max_deg`: the motion failures passed over, and the run.
fn jack_run(wrist_deviation_max_deg: f64) -> (PlannedMotions, binpick::cycle::RunResult) {
    let dir = crate::support::tempdir().unwrap();
    std::fs::write(dir.path().join("jack.obj"), jack_obj()).unwrap();
    let toml = dir.path().join("jack.toml");
    std::fs::write(&toml, JACK_TOML).unwrap();
    let wp = LoadedWorkpiece::resolve(toml.to_str().unwrap()).unwrap();
    let mut scene = LoadedScene::embedded_default().unwrap();
    scene.scene.cycle.wrist_deviation_max_deg = wrist_deviation_max_deg;
    let robot = RobotModel::from_scene(&scene).unwrap();
    let opts = RunOptions {
        picks: 2,
        seed: 1,
        deterministic: true,
        stop: None,
        keep_records: true,
    };
    let mut seen = PlannedMotions::default();
    let r = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut seen).unwrap();
    (seen, r)
}

fn outcomes(r: &binpick::cycle::RunResult) -> Vec<String> {
    r.records
        .iter()
        .map(|p| format!("{} {} sealed {:?}", p.outcome.name(), p.outcome.detail(), p.sealed))
        .collect()
}

/// A pick starts only with its Place in hand. An RJ45 jack taken by its top is set down on its
/// pins, the tool 2.2 deg off vertical, and in the first slot the straight descent into it
/// passes the arm's wrist singularity: with a controller that cannot interpolate the wrist
/// there (`cycle.wrist_deviation_max_deg = 0`), no joint path. The cell passes such a grasp
/// over for the next (another face, another place pose) and places the part, where it used to
/// grasp the jack, find no Place, and let it go (seed 1: 5 of 21 picks, 76 % success). The case
/// is exercised: the cell's first choice had no Place (the failure is logged); no pick grasps a
/// part that it does not place or drop.
#[test]
fn a_grasp_whose_place_cannot_be_generated_is_passed_over() {
    let (seen, r) = jack_run(0.0);
    let outcomes = outcomes(&r);
    assert!(
        seen.failed.iter().any(|why| why.contains("place descent")),
        "no Place failed: the case is not exercised ({:?}; {outcomes:?})",
        seen.failed
    );
    assert_eq!(r.tally.placed, 2, "{outcomes:?}");
    for p in &r.records {
        let grasped_and_kept = p.sealed == Some(true) && p.outcome.name() == "no_motion";
        assert!(!grasped_and_kept, "a part grasped without a Place: {outcomes:?}");
    }
    assert!(seen.planned >= 2, "{} Place motions planned", seen.planned);
}

/// The same jack with the default cell's controller, which moves the wrist joints linearly
/// where a line passes the wrist singularity (within 1 deg of the line's orientation): the
/// first choice's descent into the first slot exists, nothing is passed over, both are placed.
/// (The control is the test above: the same run without it fails that descent.)
#[test]
fn a_descent_through_the_wrist_singularity_is_made_with_the_wrist_interpolated() {
    let (seen, r) = jack_run(1.0);
    let outcomes = outcomes(&r);
    assert!(
        seen.failed.is_empty(),
        "motions failed: {:?}; {outcomes:?}",
        seen.failed
    );
    assert_eq!(r.tally.placed, 2, "{outcomes:?}");
    // The event log says so, and by how much the tool strayed.
    let deviation_rad = seen
        .wrist_deviation_rad
        .expect("a Place line with the wrist interpolated");
    assert!(
        deviation_rad > 0.0 && deviation_rad <= 1f64.to_radians(),
        "{deviation_rad} rad"
    );
}

/// `binpick sense` shows the grasp the cell takes, its motions generated, not only the grasp
/// selector's first choice: with a controller that cannot interpolate the wrist, the jack's first
/// choice has no Place into the first slot (seed 1), and `sense` says it is passed over and what
/// is taken instead, if anything. Control: with the default cell's controller nothing is passed
/// over and a grasp is taken.
#[test]
fn sense_shows_the_grasp_the_cell_takes_with_its_motions() {
    let ws = crate::support::Workspace::new();
    std::fs::write(ws.path("jack.obj"), jack_obj()).unwrap();
    std::fs::write(ws.path("jack.toml"), JACK_TOML).unwrap();
    ws.edit(
        "scenes/default.toml",
        "scenes/no-wrist-interpolation.toml",
        "wrist_deviation_max_deg = 1.0",
        "wrist_deviation_max_deg = 0.0",
    );
    let sense = |scene: &str| -> serde_json::Value {
        let args = [
            "sense",
            "--workpiece",
            "jack.toml",
            "--seed",
            "1",
            "--scene",
            scene,
            "--out",
            "out",
            "--json",
        ];
        let o = crate::support::binpick_in(ws.dir.path(), &args);
        assert!(o.status.success(), "{}", crate::support::stderr(&o));
        serde_json::from_str(&crate::support::stdout(&o)).unwrap()
    };
    let without = sense("scenes/no-wrist-interpolation.toml");
    let passed_over = without["grasp"]["passed_over"].as_array().unwrap();
    assert!(
        passed_over
            .iter()
            .any(|why| why.as_str().unwrap().contains("place descent")),
        "{}",
        without["grasp"]
    );
    let with = sense("scenes/default.toml");
    assert_eq!(with["grasp"]["passed_over"], serde_json::json!([]), "{}", with["grasp"]);
    assert!(with["grasp"]["chosen"].is_object(), "{}", with["grasp"]);
}
