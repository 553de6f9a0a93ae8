//! A workpiece's own shake (`[agitation]` in its file): it reaches the cell a run of that
//! workpiece uses, and only that workpiece; its keys are checked naming file, key and value; a
//! sweep of the cell's key it sets is refused.

use crate::support::{Workspace, batch_is_refused, binpick_in, cell_sweep_is_refused, stderr, without_cup_section};

/// D's file with the cell's cup (its own bellows cup, which takes lying cans by their side, is
/// cut: with it, D's first 21 picks of seed 1 need no shake), as `workpieces/D-flat.toml`.
fn d_flat_cup(ws: &Workspace) -> std::path::PathBuf {
    let text = std::fs::read_to_string(ws.path("workpieces/D.toml")).unwrap();
    assert!(text.contains("[gripper]"), "D brings a cup");
    let p = ws.path("workpieces/D-flat.toml");
    std::fs::write(&p, without_cup_section(&text)).unwrap();
    p
}

/// D (with the cell's cup) with its own shake (`shake`, a section's keys) before its `[grasp]`.
fn shaken(ws: &Workspace, name: &str, shake: &str) -> std::path::PathBuf {
    d_flat_cup(ws);
    ws.edit(
        "workpieces/D-flat.toml",
        &format!("workpieces/{name}.toml"),
        "[grasp]",
        &format!("[agitation]\n{shake}\n[grasp]"),
    )
}

/// The cell a run of `picks` picks of `workpiece` (seed 1) wrote beside its results, as TOML,
/// and its summary.
fn resolved_cell(ws: &Workspace, workpiece: &str, picks: &str) -> (toml::Table, serde_json::Value) {
    let out = ws.path("runs");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "run",
            "--workpiece",
            workpiece,
            "--picks",
            picks,
            "--deterministic",
            "--no-rrd",
            "--no-mcap",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = std::fs::read_dir(&out).unwrap().next().unwrap().unwrap().path();
    let cell = std::fs::read_to_string(dir.join("scene.toml")).unwrap();
    let summary = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    std::fs::remove_dir_all(&out).unwrap();
    (toml::from_str(&cell).unwrap(), serde_json::from_str(&summary).unwrap())
}

/// The run of a workpiece with its own frequency and duration uses them, with the cell's
/// amplitude and tries; the control: D without a shake of its own runs the cell's. A shake
/// switched off in the workpiece's file (`max_tries = 0`) reaches the cycle: D's 21 picks of seed
/// 1 with the cell's flat-face cup agitate with the cell's shake and never without it.
#[test]
fn a_workpiece_brings_its_own_shake() {
    let ws = Workspace::new();
    let own = shaken(&ws, "shaken", "frequency_hz = 22.0\nduration_s = 0.4\n");
    let (cell, _) = resolved_cell(&ws, own.to_str().unwrap(), "2");
    let a = cell["agitation"].as_table().unwrap();
    assert_eq!(a["frequency_hz"].as_float(), Some(22.0), "{a:?}");
    assert_eq!(a["duration_s"].as_float(), Some(0.4), "{a:?}");
    let flat = d_flat_cup(&ws);
    let (plain, shaken_21) = resolved_cell(&ws, flat.to_str().unwrap(), "21");
    let p = plain["agitation"].as_table().unwrap();
    assert_eq!(p["frequency_hz"].as_float(), Some(15.0), "{p:?}");
    assert_eq!(p["duration_s"].as_float(), Some(0.6), "{p:?}");
    assert_eq!(a["amplitude_m"], p["amplitude_m"]);
    assert_eq!(a["max_tries"], p["max_tries"]);
    assert!(shaken_21["agitations"].as_u64().unwrap() >= 1, "{shaken_21}");
    let still = shaken(&ws, "still", "max_tries = 0\n");
    let (_, still_21) = resolved_cell(&ws, still.to_str().unwrap(), "21");
    assert_eq!(still_21["agitations"].as_u64(), Some(0), "{still_21}");
}

/// A bad shake exits 2 naming the file, the key and the value, writing nothing: a value out of
/// range, a key the section does not have, and a shake that is on without a duration (checked on
/// the cell resolved for the workpiece). A sweep of the cell's frequency over a workpiece that
/// sets its own is refused: it would vary nothing for it.
#[test]
fn a_bad_shake_exits_2_naming_file_key_and_value() {
    let ws = Workspace::new();
    for (shake, why) in [
        (
            "frequency_hz = 80.0\n",
            "agitation.frequency_hz must be within [0.1, 50], got 80",
        ),
        ("stroke_m = 0.001\n", "stroke_m"),
        (
            "duration_s = 0.0\n",
            "agitation.duration_s must be positive while max_tries > 0, got 0 (with this workpiece's agitation)",
        ),
    ] {
        let bad = shaken(&ws, "bad", shake);
        batch_is_refused(&ws, &["--workpieces", bad.to_str().unwrap()], why);
    }
    let bad = shaken(&ws, "bad", "frequency_hz = 22.0\n");
    cell_sweep_is_refused(&ws, "agitation.frequency_hz=10,20", &bad);
}
