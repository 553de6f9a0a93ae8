//! Bad input: each case gives one clear line naming file, key and bad value, exit code 2,
//! no panic, and nothing written.

use crate::support::{Workspace, binpick_in, stderr};

/// Runs `binpick check FILE` in the workspace and asserts exit 2, no panic, no new files,
/// and that stderr contains every expected fragment.
fn rejects(ws: &Workspace, file: &str, expected: &[&str]) -> String {
    let before = ws.listing();
    let out = binpick_in(ws.dir.path(), &["check", file]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "exit code for {file}; stderr:\n{err}");
    assert!(!err.contains("panicked"), "panic for {file}: {err}");
    for e in expected {
        assert!(err.contains(e), "stderr for {file} lacks {e:?}:\n{err}");
    }
    assert_eq!(ws.listing(), before, "check wrote files");
    err
}

#[test]
fn malformed_toml() {
    let ws = Workspace::new();
    ws.edit("workpieces/B.toml", "workpieces/bad.toml", "name = \"B\"", "name = \"B");
    rejects(
        &ws,
        "workpieces/bad.toml",
        &["workpieces/bad.toml: malformed TOML", "line 3"],
    );
}

#[test]
fn unknown_key_names_the_key() {
    let ws = Workspace::new();
    ws.edit(
        "workpieces/B.toml",
        "workpieces/bad.toml",
        "friction = 0.40",
        "friction = 0.40\ncolour = \"grey\"",
    );
    rejects(
        &ws,
        "workpieces/bad.toml",
        &["workpieces/bad.toml:", "unknown field `colour`"],
    );
    ws.edit(
        "scenes/default.toml",
        "scenes/bad.toml",
        "latency_s = 1.1",
        "latency_s = 1.1\nlatency_ms = 1100",
    );
    rejects(
        &ws,
        "scenes/bad.toml",
        &["scenes/bad.toml: sensor", "unknown field `latency_ms`"],
    );
}

#[test]
fn negative_size_names_file_key_and_value() {
    let ws = Workspace::new();
    ws.edit(
        "workpieces/C.toml",
        "workpieces/C.toml",
        "size_m = [0.150, 0.010, 0.005]",
        "size_m = [0.150, 0.010, -0.005]",
    );
    let err = rejects(
        &ws,
        "workpieces/C.toml",
        &["workpieces/C.toml: size_m[2] must be > 0, got -0.005"],
    );
    assert_eq!(err.lines().count(), 1, "one line per problem: {err}");
}

/// The tool's lean beyond 60 deg, in the cell and in a workpiece's cup; the control: 60 passes.
#[test]
fn a_lean_beyond_sixty_degrees_names_file_key_and_value() {
    let ws = Workspace::new();
    ws.edit(
        "scenes/default.toml",
        "scenes/lean.toml",
        "max_lean_deg = 40.0",
        "max_lean_deg = 75.0",
    );
    rejects(
        &ws,
        "scenes/lean.toml",
        &["scenes/lean.toml: gripper.max_lean_deg must be within [0, 60], got 75"],
    );
    ws.edit(
        "workpieces/A.toml",
        "workpieces/lean.toml",
        "cup_diameter_m = 0.0055",
        "cup_diameter_m = 0.0055\nmax_lean_deg = -5.0",
    );
    rejects(
        &ws,
        "workpieces/lean.toml",
        &["workpieces/lean.toml: gripper.max_lean_deg must be within [0, 60], got -5"],
    );
    ws.edit(
        "scenes/default.toml",
        "scenes/lean60.toml",
        "max_lean_deg = 40.0",
        "max_lean_deg = 60.0",
    );
    let out = binpick_in(ws.dir.path(), &["check", "scenes/lean60.toml"]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
}

#[test]
fn zero_size() {
    let ws = Workspace::new();
    ws.edit(
        "scenes/default.toml",
        "scenes/bad.toml",
        "inner_size_m = [0.30, 0.24]",
        "inner_size_m = [0.0, 0.24]",
    );
    rejects(
        &ws,
        "scenes/bad.toml",
        &["scenes/bad.toml: pick_tray.inner_size_m[0] must be > 0, got 0"],
    );
}

#[test]
fn several_problems_one_line_each() {
    let ws = Workspace::new();
    let p = ws.edit(
        "workpieces/F.toml",
        "workpieces/bad.toml",
        "mass_kg = 0.0025",
        "mass_kg = -1.0",
    );
    let text = std::fs::read_to_string(&p)
        .unwrap()
        .replace("friction = 0.40", "friction = 7.0");
    std::fs::write(&p, text).unwrap();
    let err = rejects(
        &ws,
        "workpieces/bad.toml",
        &["mass_kg must be > 0, got -1", "friction must be within [0, 2], got 7"],
    );
    assert_eq!(err.lines().count(), 2, "{err}");
}

#[test]
fn non_finite_number() {
    let ws = Workspace::new();
    ws.edit(
        "workpieces/D.toml",
        "workpieces/bad.toml",
        "mass_kg = 0.0015",
        "mass_kg = nan",
    );
    rejects(
        &ws,
        "workpieces/bad.toml",
        &["workpieces/bad.toml: mass_kg must be a finite number, got NaN"],
    );
    ws.edit(
        "scenes/default.toml",
        "scenes/bad.toml",
        "latency_s = 1.1",
        "latency_s = inf",
    );
    rejects(
        &ws,
        "scenes/bad.toml",
        &["scenes/bad.toml: sensor.latency_s must be a finite number, got inf"],
    );
}

#[test]
fn missing_urdf() {
    let ws = Workspace::new();
    ws.edit(
        "scenes/default.toml",
        "scenes/bad.toml",
        "urdf = \"viper_s650.urdf\"",
        "urdf = \"nope.urdf\"",
    );
    rejects(
        &ws,
        "scenes/bad.toml",
        &["scenes/bad.toml: robot.urdf cannot read", "nope.urdf"],
    );
}

#[test]
fn urdf_lacking_a_joint() {
    let ws = Workspace::new();
    let text = std::fs::read_to_string(ws.path("scenes/viper_s650.urdf")).unwrap();
    let start = text.find("<joint name=\"joint_4\"").unwrap();
    let end = start + text[start..].find("</joint>").unwrap() + "</joint>".len();
    std::fs::write(
        ws.path("scenes/no_j4.urdf"),
        format!("{}{}", &text[..start], &text[end..]),
    )
    .unwrap();
    rejects(
        &ws,
        "scenes/no_j4.urdf",
        &[
            "scenes/no_j4.urdf:",
            "chain of 6 revolute joints",
            "found 2",
            "\"link_4\"",
        ],
    );
    // And through a scene that names it.
    ws.edit(
        "scenes/default.toml",
        "scenes/bad.toml",
        "urdf = \"viper_s650.urdf\"",
        "urdf = \"no_j4.urdf\"",
    );
    rejects(&ws, "scenes/bad.toml", &["no_j4.urdf:", "chain of 6 revolute joints"]);
}

#[test]
fn urdf_not_xml() {
    let ws = Workspace::new();
    std::fs::write(ws.path("scenes/garbage.urdf"), "this is not xml").unwrap();
    rejects(
        &ws,
        "scenes/garbage.urdf",
        &["scenes/garbage.urdf: is not a valid URDF"],
    );
}

#[test]
fn joint_limits_inverted() {
    let ws = Workspace::new();
    ws.edit(
        "scenes/viper_s650.urdf",
        "scenes/inverted.urdf",
        "lower=\"-0.506145\" upper=\"4.468043\"",
        "lower=\"4.468043\" upper=\"-0.506145\"",
    );
    rejects(
        &ws,
        "scenes/inverted.urdf",
        &["scenes/inverted.urdf: joint[joint_3].limit is inverted or empty: lower 4.468043 must be < upper -0.506145"],
    );
}

#[test]
fn tray_out_of_reach() {
    let ws = Workspace::new();
    ws.edit(
        "scenes/default.toml",
        "scenes/bad.toml",
        "center_m = [0.40, -0.22, 0.006]",
        "center_m = [1.10, -0.22, 0.006]",
    );
    rejects(
        &ws,
        "scenes/bad.toml",
        &[
            "scenes/bad.toml: place_tray.tray is out of the arm's reach",
            "target out of reach",
        ],
    );
}

#[test]
fn sensor_not_looking_at_the_pick_tray() {
    let ws = Workspace::new();
    ws.edit(
        "scenes/default.toml",
        "scenes/bad.toml",
        "look_at_m = [0.10, 0.45, 0.008]",
        "look_at_m = [0.60, 0.45, 0.008]",
    );
    rejects(
        &ws,
        "scenes/bad.toml",
        &["scenes/bad.toml: sensor does not see the whole pick tray floor"],
    );
}

#[test]
fn cup_larger_than_every_face() {
    let ws = Workspace::new();
    ws.edit(
        "workpieces/E.toml",
        "workpieces/tiny.toml",
        "size_m = [0.010, 0.005, 0.010]",
        "size_m = [0.004, 0.005, 0.004]",
    );
    rejects(
        &ws,
        "workpieces/tiny.toml",
        &["workpieces/tiny.toml: size_m has no face the suction cup fits on"],
    );
}

#[test]
fn workpiece_larger_than_the_tray() {
    let ws = Workspace::new();
    ws.edit(
        "workpieces/C.toml",
        "workpieces/long.toml",
        "size_m = [0.150, 0.010, 0.005]",
        "size_m = [0.450, 0.010, 0.005]",
    );
    rejects(
        &ws,
        "workpieces/long.toml",
        &["workpieces/long.toml: size_m is larger than the pick tray"],
    );
}

#[test]
fn unreadable_and_unknown_files() {
    let ws = Workspace::new();
    rejects(
        &ws,
        "scenes/does_not_exist.toml",
        &["scenes/does_not_exist.toml: cannot read file"],
    );
    std::fs::write(ws.path("notes.txt"), "hello").unwrap();
    rejects(&ws, "notes.txt", &["notes.txt: is neither a .toml"]);
}

#[test]
fn bad_robot_arguments_exit_2() {
    let ws = Workspace::new();
    for (args, expect) in [
        (
            &["robot", "ik", "--xyz", "2", "0", "0", "--rpy-deg", "180", "0", "0"][..],
            "target out of reach",
        ),
        (
            &["robot", "fk", "--deg", "nan", "0", "0", "0", "0", "0"][..],
            "--deg must be finite numbers, got NaN",
        ),
        (
            &[
                "robot",
                "torque",
                "--deg",
                "0",
                "0",
                "0",
                "0",
                "0",
                "0",
                "--payload-kg",
                "-1",
            ][..],
            "--payload-kg must be a finite number >= 0",
        ),
        (&["robot", "fk", "--deg", "0", "0"][..], "6 values required"),
        (
            &["robot", "info", "--scene", "scenes/missing.toml"][..],
            "scenes/missing.toml: cannot read file",
        ),
    ] {
        let before = ws.listing();
        let out = binpick_in(ws.dir.path(), args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(expect), "{args:?}: stderr lacks {expect:?}: {err}");
        assert!(!err.contains("panicked"));
        assert_eq!(ws.listing(), before);
    }
}

/// `binpick run` and `binpick batch` on a bad cell or workpiece: the same clear error before the
/// run starts, exit 2, and no output folder left behind.
#[test]
fn runs_and_batches_refuse_bad_cells_before_starting() {
    let ws = Workspace::new();
    ws.edit(
        "scenes/default.toml",
        "scenes/far.toml",
        "center_m = [0.40, -0.22, 0.006]",
        "center_m = [1.10, -0.22, 0.006]",
    );
    ws.edit(
        "workpieces/C.toml",
        "workpieces/long.toml",
        "size_m = [0.150, 0.010, 0.005]",
        "size_m = [0.450, 0.010, 0.005]",
    );
    ws.edit(
        "workpieces/E.toml",
        "workpieces/tiny.toml",
        "size_m = [0.010, 0.005, 0.010]",
        "size_m = [0.004, 0.005, 0.004]",
    );
    let cases: [(&[&str], &str); 5] = [
        (
            &["run", "--workpiece", "A", "--scene", "scenes/far.toml"],
            "scenes/far.toml: place_tray.tray is out of the arm's reach",
        ),
        (
            &["run", "--workpiece", "workpieces/long.toml"],
            "workpieces/long.toml: size_m is larger than the pick tray",
        ),
        (
            &["run", "--workpiece", "workpieces/tiny.toml"],
            "workpieces/tiny.toml: size_m has no face the suction cup fits on",
        ),
        (
            &["batch", "--workpieces", "A,workpieces/tiny.toml"],
            "workpieces/tiny.toml: size_m has no face the suction cup fits on",
        ),
        (&["batch", "--seeds", "3-1"], "--seeds: range 3-1 is reversed"),
    ];
    for (args, expected) in cases {
        let before = ws.listing();
        let mut all = args.to_vec();
        all.extend_from_slice(&["--out", "out"]);
        let out = binpick_in(ws.dir.path(), &all);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(err.contains(expected), "{args:?}: stderr lacks {expected:?}:\n{err}");
        assert_eq!(ws.listing(), before, "{args:?} wrote files");
        assert!(!ws.path("out").exists(), "{args:?} left an output folder");
    }
}

/// Runs `binpick ARGS --out out` in the workspace and asserts exit 2, no panic, the expected
/// fragments on stderr, nothing written and no output folder.
fn refuses_to_start(ws: &Workspace, args: &[&str], expected: &[&str]) {
    let before = ws.listing();
    let mut all = args.to_vec();
    all.extend_from_slice(&["--out", "out"]);
    let out = binpick_in(ws.dir.path(), &all);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for e in expected {
        assert!(err.contains(e), "{args:?}: stderr lacks {e:?}:\n{err}");
    }
    assert_eq!(ws.listing(), before, "{args:?} wrote files");
    assert!(!ws.path("out").exists(), "{args:?} left an output folder");
}

/// `--seeds` ranges: reversed, past u64::MAX, and more seeds than a batch runs; a range ending at
/// u64::MAX itself is valid (see the unit tests of `parse_seeds`).
#[test]
fn batch_seeds_reversed_overflowing_or_too_many() {
    let ws = Workspace::new();
    let max = u64::MAX;
    for (seeds, expected) in [
        (
            "5-3".to_string(),
            "--seeds: range 5-3 is reversed (it ends below its start); write 3-5",
        ),
        (
            format!("{}-{max}1", max - 1),
            "--seeds: seed 184467440737095516151 is out of range: seeds are 0 to 18446744073709551615",
        ),
        (
            "18446744073709551615-18446744073709551616".to_string(),
            "seed 18446744073709551616 is out of range",
        ),
        (
            format!("0-{max}"),
            "gives more than 10000 seeds, the most one batch runs",
        ),
        ("1-6000,7000-12000".to_string(), "gives more than 10000 seeds"),
    ] {
        refuses_to_start(&ws, &["batch", "--seeds", &seeds], &[expected]);
    }
}

/// A camera level with the pick tray (beside it at floor height, looking across it, it sees the
/// floor's corners in one image row, and its view over the tray is a flat pyramid) or so far from
/// it that the tray is a point: the cell file is refused naming `sensor.position_m` and its value,
/// by `check` and before a `sense` starts.
#[test]
fn camera_level_with_or_far_from_the_tray() {
    let ws = Workspace::new();
    let p = ws.edit(
        "scenes/default.toml",
        "scenes/level.toml",
        "position_m = [0.10, 0.45, 1.008]",
        "position_m = [0.10, 1.45, 0.008]",
    );
    let text =
        std::fs::read_to_string(&p)
            .unwrap()
            .replacen("image_up = [0.0, 1.0, 0.0]", "image_up = [0.0, 0.0, 1.0]", 1);
    std::fs::write(&p, text).unwrap();
    let expected = [
        "scenes/level.toml: sensor.position_m must be at least 0.05 m above the pick tray's rim (z = 0.068 m) so its view over the tray spans a pyramid, got [0.1, 1.45, 0.008]",
    ];
    let err = rejects(&ws, "scenes/level.toml", &expected);
    assert_eq!(err.lines().count(), 1, "{err}");
    refuses_to_start(
        &ws,
        &[
            "sense",
            "--workpiece",
            "C",
            "--count",
            "2",
            "--scene",
            "scenes/level.toml",
        ],
        &expected,
    );
    // A camera 500 m above the tray sees it as a point: the frustum over it degenerates into a line
    // (before this check, `sense` panicked building it: "a camera above a tray spans a pyramid").
    let p = ws.edit(
        "scenes/default.toml",
        "scenes/far.toml",
        "position_m = [0.10, 0.45, 1.008]",
        "position_m = [0.10, 0.45, 500.008]",
    );
    let text = std::fs::read_to_string(&p)
        .unwrap()
        .replacen("min_range_m = 0.5", "min_range_m = 499.0", 1)
        .replacen("max_range_m = 1.5", "max_range_m = 501.0", 1);
    std::fs::write(&p, text).unwrap();
    let expected = [
        "scenes/far.toml: sensor.position_m is 500.000 m from the pick tray's rim, more than 100 times its width of 0.256 m",
        "spans no pyramid; got [0.1, 0.45, 500.008]",
    ];
    rejects(&ws, "scenes/far.toml", &expected);
    refuses_to_start(
        &ws,
        &[
            "sense",
            "--workpiece",
            "C",
            "--count",
            "1",
            "--scene",
            "scenes/far.toml",
        ],
        &expected,
    );
    // Just above the rim plus the margin is a pyramid, and accepted.
    ws.edit(
        "scenes/level.toml",
        "scenes/low.toml",
        "position_m = [0.10, 1.45, 0.008]",
        "position_m = [0.10, 1.45, 0.20]",
    );
    let out = binpick_in(ws.dir.path(), &["check", "scenes/low.toml"]);
    assert!(!stderr(&out).contains("sensor.position_m"), "{}", stderr(&out));
}

/// An 8192 x 8192 image is within each axis's range but would need 1.6 GB per capture: refused,
/// with the cap and the reason.
#[test]
fn sensor_resolution_needing_gigabytes_per_capture() {
    let ws = Workspace::new();
    ws.edit(
        "scenes/default.toml",
        "scenes/huge.toml",
        "resolution_px = [1032, 772]",
        "resolution_px = [8192, 8192]",
    );
    let err = rejects(
        &ws,
        "scenes/huge.toml",
        &[
            "scenes/huge.toml: sensor.resolution_px must have at most 4194304 pixels (4 MP, e.g. 2048 x 2048)",
            "8192 x 8192 = 67108864 pixels would need 1.6 GB per capture; got [8192, 8192]",
        ],
    );
    assert_eq!(err.lines().count(), 1, "{err}");
    // The cap itself is accepted.
    ws.edit(
        "scenes/default.toml",
        "scenes/cap.toml",
        "resolution_px = [1032, 772]",
        "resolution_px = [2048, 2048]",
    );
    let out = binpick_in(ws.dir.path(), &["check", "scenes/cap.toml"]);
    assert!(!stderr(&out).contains("resolution_px"), "{}", stderr(&out));
}

/// A part 1 nm long in a place tray without gaps would give 5 billion grid slots: refused with the
/// count (before, building the slot list aborted the process: "memory allocation ... failed").
#[test]
fn a_part_giving_billions_of_place_slots() {
    let ws = Workspace::new();
    ws.edit("scenes/default.toml", "scenes/gap0.toml", "gap_m = 0.01", "gap_m = 0.0");
    ws.edit(
        "workpieces/E.toml",
        "workpieces/thin.toml",
        "size_m = [0.010, 0.005, 0.010]",
        "size_m = [0.000000001, 0.01, 0.01]",
    );
    let before = ws.listing();
    let out = binpick_in(
        ws.dir.path(),
        &["check", "--scene", "scenes/gap0.toml", "workpieces/thin.toml"],
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("workpieces/thin.toml: size_m gives 4799999980 placement slots in the place tray")
            && err.contains("more than 10000: check the units"),
        "{err}"
    );
    assert_eq!(ws.listing(), before);
}

/// A mesh workpiece whose mesh cannot be built is bad input for `run` and `batch` as for `pile`
/// (before, `run` started, failed in the cycle and exited 1): exit 2, the mesh file named,
/// nothing written.
#[test]
fn a_broken_mesh_workpiece_is_bad_input_for_every_command() {
    let ws = Workspace::new();
    // Two vertices and one degenerate triangle: no closed mesh.
    std::fs::write(ws.path("workpieces/flat.obj"), "v 0 0 0\nv 0.01 0 0\nf 1 2 1\n").unwrap();
    std::fs::write(
        ws.path("workpieces/flat.toml"),
        "name = \"flat\"\nkind = \"a mesh that is not closed\"\nsize_m = [0.03, 0.03, 0.02]\nmass_kg = 0.01\n\
         friction = 0.4\nrestitution = 0.1\npile_count = 10\n\n[shape]\nkind = \"mesh\"\nmesh_file = \"flat.obj\"\n\n\
         [grasp]\nyaw_symmetry_deg = 90.0\nplace_yaw_deg = 0.0\nface_margin_m = 0.0005\n",
    )
    .unwrap();
    for cmd in [
        &["pile", "--workpiece", "workpieces/flat.toml"][..],
        &["sense", "--workpiece", "workpieces/flat.toml"],
        &["run", "--workpiece", "workpieces/flat.toml", "--picks", "2"],
        &["batch", "--workpieces", "workpieces/flat.toml", "--picks", "2"],
    ] {
        refuses_to_start(&ws, cmd, &["flat.obj", "cannot load mesh"]);
    }
}

/// The planner benchmark's seeds wrap instead of overflowing: `--seed` at u64::MAX runs (one
/// trials per case and no baseline trials keep it short).
#[test]
fn bench_planner_with_the_largest_seed_runs() {
    let o = crate::support::binpick(&[
        "bench",
        "planner",
        "--trials",
        "2",
        "--baseline-trials",
        "0",
        "--seed",
        "18446744073709551615",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rows: serde_json::Value = serde_json::from_str(&crate::support::stdout(&o)).unwrap();
    assert!(rows.as_array().is_some_and(|r| !r.is_empty()));
}
