//! `binpick pile`: the run folder, determinism of its result file, and bad input.

use crate::support::{Workspace, binpick_in, stderr, stdout};

#[test]
fn pile_writes_a_self_contained_run_folder_and_repeats_byte_for_byte() {
    let ws = Workspace::new();
    let out = ws.path("out");
    let outs = out.to_str().unwrap();
    let run = |dir: &str| {
        let o = binpick_in(
            ws.dir.path(),
            &[
                "pile",
                "--workpiece",
                "F",
                "--count",
                "25",
                "--seed",
                "3",
                "--out",
                dir,
                "--json",
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_str::<serde_json::Value>(&stdout(&o)).unwrap()
    };
    let v = run(outs);
    assert_eq!(v["report"]["in_tray"], 25);
    assert!(v["report"]["max_penetration_m"].as_f64().unwrap() <= 3e-4);
    let dir = out.join("pile-F-seed3");
    for f in ["pile.json", "scene.toml", "workpiece.toml", "viper_s650.urdf"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let first = std::fs::read(dir.join("pile.json")).unwrap();
    let poses = serde_json::from_slice::<serde_json::Value>(&first).unwrap()["report"]["poses"]
        .as_array()
        .unwrap()
        .len();
    assert_eq!(poses, 25);
    // The resolved scene in the run folder is itself a valid cell.
    let check = binpick_in(
        ws.dir.path(),
        &[
            "check",
            dir.join("scene.toml").to_str().unwrap(),
            dir.join("workpiece.toml").to_str().unwrap(),
        ],
    );
    assert!(check.status.success(), "{}", stderr(&check));
    // Same seed again: the same bytes (wall time is printed, never written).
    let out2 = ws.path("out2");
    run(out2.to_str().unwrap());
    assert_eq!(
        first,
        std::fs::read(out2.join("pile-F-seed3").join("pile.json")).unwrap()
    );
    // And re-running from the run folder's own scene gives the same pile again.
    let o = binpick_in(
        ws.dir.path(),
        &[
            "pile",
            "--workpiece",
            dir.join("workpiece.toml").to_str().unwrap(),
            "--scene",
            dir.join("scene.toml").to_str().unwrap(),
            "--count",
            "25",
            "--seed",
            "3",
            "--out",
            ws.path("out3").to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let a: serde_json::Value = serde_json::from_slice(&first).unwrap();
    let b: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ws.path("out3/pile-F-seed3/pile.json")).unwrap()).unwrap();
    assert_eq!(a["report"]["poses"], b["report"]["poses"]);
}

#[test]
fn pile_rejects_bad_input_and_leaves_nothing_behind() {
    let ws = Workspace::new();
    let out = ws.path("out");
    for (args, expect) in [
        (vec!["pile", "--workpiece", "Z"], "names no built-in workpiece"),
        (
            vec!["pile", "--workpiece", "F", "--count", "0"],
            "--count must be within [1, 1000], got 0",
        ),
        (
            vec!["pile", "--workpiece", "workpieces/missing.toml"],
            "cannot read file",
        ),
    ] {
        let mut a = args.clone();
        a.extend(["--out", out.to_str().unwrap()]);
        let o = binpick_in(ws.dir.path(), &a);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
        assert!(
            !out.exists() || std::fs::read_dir(&out).unwrap().next().is_none(),
            "{args:?} left output behind"
        );
    }
}

/// C's first pour of seed 56 throws a strip over the tray's wall: `pile` (and `sense`, `part`,
/// `bench sensor`) pours as the cell pours its first pile, so the strip is lost and the command
/// goes on, where before it ended on the spill. The negative control, the strict pour ending on
/// the same spill, is in `faults.rs` (`a_part_the_first_pour_spills_is_lost_and_the_run_goes_on`).
#[test]
fn a_pile_whose_pour_spills_a_part_loses_it_as_the_cell_does() {
    let ws = Workspace::new();
    let out = ws.path("out");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "pile",
            "--workpiece",
            "C",
            "--seed",
            "56",
            "--out",
            out.to_str().unwrap(),
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let (spawned, in_tray) = (
        v["report"]["spawned"].as_u64().unwrap(),
        v["report"]["in_tray"].as_u64().unwrap(),
    );
    assert_eq!(in_tray + 1, spawned, "{v}");
}
