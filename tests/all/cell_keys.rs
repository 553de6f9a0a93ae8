//! The waiting pose (`cycle.waiting_tool_m`) and the place tray's slot spacing
//! (`place_tray.pitch_x_m`, `pitch_y_m`) as cell keys: a waiting pose the tool cannot reach or
//! one in the sensor's view, and a spacing below the part's place footprint, exit 2 naming the
//! file, the key and the value before anything runs; a valid spacing lays the slots that far
//! apart (checked from the slot poses), and `sweep --set` reaches both keys.

use binpick::config::LoadedScene;

use crate::support::{Workspace, binpick_in, stderr};

/// `binpick run` of `workpiece` in `scene` (2 picks): exit code and stderr; nothing is written
/// when it fails.
fn run(ws: &Workspace, scene: &std::path::Path, workpiece: &str) -> (Option<i32>, String) {
    let out = ws.path("runs");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "run",
            "--scene",
            scene.to_str().unwrap(),
            "--workpiece",
            workpiece,
            "--picks",
            "2",
            "--deterministic",
            "--no-rrd",
            "--no-mcap",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    if !o.status.success() {
        assert!(!out.exists(), "a refused run wrote {}", out.display());
    }
    (o.status.code(), stderr(&o))
}

const WAIT: &str = "waiting_tool_m = [0.10, 0.29, 0.12]";

#[test]
fn a_waiting_pose_in_view_or_out_of_reach_exits_2_naming_file_key_and_value() {
    let ws = Workspace::new();
    // Over the middle of the pick tray: in the sensor's view.
    let in_view = ws.edit(
        "scenes/default.toml",
        "scenes/in-view.toml",
        WAIT,
        "waiting_tool_m = [0.10, 0.45, 0.20]",
    );
    let (code, err) = run(&ws, &in_view, "E");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("in-view.toml: cycle.waiting_tool_m = [0.1, 0.45, 0.2]: the arm's")
            && err.contains("in the sensor's view"),
        "{err}"
    );
    // Two metres away: out of reach.
    let far = ws.edit(
        "scenes/default.toml",
        "scenes/far.toml",
        WAIT,
        "waiting_tool_m = [2.0, 0.0, 0.20]",
    );
    let (code, err) = run(&ws, &far, "E");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("far.toml: cycle.waiting_tool_m = [2.0, 0.0, 0.2]: the tool cannot point down there"),
        "{err}"
    );
    // Negative control: another waiting pose just outside the view runs.
    let ok = ws.edit(
        "scenes/default.toml",
        "scenes/ok.toml",
        WAIT,
        "waiting_tool_m = [0.10, 0.28, 0.16]",
    );
    let (code, err) = run(&ws, &ok, "E");
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn a_slot_spacing_below_the_footprint_exits_2_and_a_valid_one_spaces_the_slots() {
    let ws = Workspace::new();
    // B is 30 x 30 mm: a 25 mm spacing would overlap the parts.
    let tight = ws.edit(
        "scenes/default.toml",
        "scenes/tight.toml",
        "gap_m = 0.01",
        "gap_m = 0.01\npitch_x_m = 0.025",
    );
    let (code, err) = run(&ws, &tight, "B");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("place_tray.pitch_x_m (the cell's) must not be below this part's place footprint, 0.03 m")
            && err.contains("got 0.025"),
        "{err}"
    );
    let bad = ws.edit(
        "scenes/default.toml",
        "scenes/bad.toml",
        "gap_m = 0.01",
        "gap_m = 0.01\npitch_y_m = -0.04",
    );
    let (code, err) = run(&ws, &bad, "B");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("bad.toml: place_tray.pitch_y_m must be > 0, got -0.04"),
        "{err}"
    );
    // Negative control: a spacing the part fits runs.
    let wide = ws.edit(
        "scenes/default.toml",
        "scenes/wide.toml",
        "gap_m = 0.01",
        "gap_m = 0.01\npitch_x_m = 0.05\npitch_y_m = 0.032",
    );
    let (code, err) = run(&ws, &wide, "B");
    assert_eq!(code, Some(0), "{err}");
    // The slots lie the given spacing apart, inside the floor less the wall clearance.
    let scene = LoadedScene::from_file(&wide).unwrap();
    let p = &scene.scene.place_tray;
    let slots = p.slots_in_tray([0.03, 0.03]);
    let mut xs: Vec<f64> = slots.iter().map(|s| s.0).collect();
    let mut ys: Vec<f64> = slots.iter().map(|s| s.1).collect();
    for v in [&mut xs, &mut ys] {
        v.sort_by(f64::total_cmp);
        v.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
    }
    // 240 x 200 mm floor, 10 mm to the walls: (240 - 20 - 30) / 50 + 1 = 4 columns,
    // (200 - 20 - 30) / 32 + 1 = 5 rows.
    assert_eq!((xs.len(), ys.len()), (4, 5));
    assert_eq!(slots.len(), 20);
    for w in xs.windows(2) {
        assert!((w[1] - w[0] - 0.05).abs() < 1e-12, "{xs:?}");
    }
    for w in ys.windows(2) {
        assert!((w[1] - w[0] - 0.032).abs() < 1e-12, "{ys:?}");
    }
    assert!(xs[3] + 0.015 <= 0.12 - 0.01 + 1e-12 && ys[4] + 0.015 <= 0.10 - 0.01 + 1e-12);
}

#[test]
fn sweep_set_reaches_the_waiting_pose_and_the_slot_spacing() {
    let ws = Workspace::new();
    let out = ws.path("runs");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "sweep",
            "--workpieces",
            "B",
            "--set",
            "place_tray.pitch_x_m=0.035,0.02",
            "--picks",
            "1",
            "--deterministic",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("sweep variant 2: place_tray.pitch_x_m=0.02"), "{err}");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "sweep",
            "--workpieces",
            "B",
            "--set",
            "cycle.waiting_tool_m=[0.10, 0.45, 0.20]",
            "--picks",
            "1",
            "--deterministic",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("cycle.waiting_tool_m = [0.1, 0.45, 0.2]"), "{err}");
    assert!(!out.exists());
}

/// `place_tray.tolerance_m`: a placed part farther than it from its place pose is a `misplaced`
/// incident. With 0.01 mm every part E places is one (its event log, and the summary's
/// incidents); with the default 2 mm, none in the same run (the control). A tolerance of zero
/// exits 2 naming the key.
#[test]
fn the_place_tolerance_decides_which_placed_parts_are_misplaced() {
    let ws = Workspace::new();
    let key = "tolerance_m = 0.002";
    let misplaced = |scene: &std::path::Path| {
        let (code, err) = run(&ws, scene, "E");
        assert_eq!(code, Some(0), "{err}");
        let read = |file: &str| -> serde_json::Value {
            let path = ws.path(&format!("runs/run-E-seed1-det/{file}"));
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
        };
        let (summary, events) = (read("summary.json"), read("events.json"));
        // The placement errors picks.csv lists, read here on their own.
        let picks = std::fs::read_to_string(ws.path("runs/run-E-seed1-det/picks.csv")).unwrap();
        let mut rows = picks.lines();
        let header: Vec<&str> = rows.next().unwrap().split(',').collect();
        let col = header.iter().position(|h| *h == "placement_error_mm").unwrap();
        let mut errors_mm: Vec<f64> = rows
            .filter_map(|r| r.split(',').nth(col).and_then(|v| v.parse().ok()))
            .collect();
        errors_mm.sort_by(f64::total_cmp);
        std::fs::remove_dir_all(ws.path("runs")).unwrap();
        let events = events.as_array().cloned().unwrap_or_default();
        let misplaced = events.iter().filter(|e| e["kind"] == "misplaced").count();
        // The summary lists the same incidents, counts them, and gives the median placement
        // error of the placed parts (the upper middle one).
        let listed = summary["incidents"].as_array().unwrap();
        assert_eq!(listed.iter().filter(|i| i["kind"] == "misplaced").count(), misplaced);
        let placement = &summary["placement"];
        assert_eq!(placement["misplaced"].as_u64().unwrap() as usize, misplaced);
        assert_eq!(placement["measured"].as_u64().unwrap() as usize, errors_mm.len());
        let median = placement["position_error_mm"][0].as_f64().unwrap();
        assert!(
            (median - errors_mm[errors_mm.len() / 2]).abs() < 1e-5,
            "{median} {errors_mm:?}"
        );
        (misplaced, summary["placed"].as_u64().unwrap())
    };
    let tight = ws.edit("scenes/default.toml", "scenes/tight.toml", key, "tolerance_m = 0.00001");
    let (n, placed) = misplaced(&tight);
    assert!(placed >= 1 && n as u64 == placed, "{n} misplaced of {placed}");
    let (n, _) = misplaced(&ws.path("scenes/default.toml"));
    assert_eq!(n, 0);
    let zero = ws.edit("scenes/default.toml", "scenes/zero.toml", key, "tolerance_m = 0.0");
    let (code, err) = run(&ws, &zero, "E");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("zero.toml") && err.contains("place_tray.tolerance_m"),
        "{err}"
    );
}
