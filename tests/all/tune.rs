//! `binpick tune` end to end: bad tunes refused before anything runs (exit 2, nothing written),
//! a tiny deterministic tune repeating byte for byte, resuming from its journal without running
//! the journalled candidates again (and giving what an uninterrupted run gives), its best checked
//! against its own evaluations, its tuned files reproducing its test figure through `batch`, and
//! a tune whose every candidate the file checks refuse ending without a best (exit 1, the table
//! written, no cell run).

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::support::{binpick, stderr, stdout};

const KEY: &str = "workpiece.gripper.cup_diameter_m=0.004:0.02";

/// `binpick tune` of workpiece B on seed 1, tested on seed 2, 3 picks, deterministic, with
/// `extra` arguments, into `out`.
fn tune(out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "tune",
        "--workpiece",
        "B",
        "--train-seeds",
        "1",
        "--test-seeds",
        "2",
        "--picks",
        "3",
        "--deterministic",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    binpick(&args)
}

/// The one result folder under `out` (the journal lies beside it).
fn folder(out: &Path) -> PathBuf {
    let dirs: Vec<PathBuf> = std::fs::read_dir(out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    dirs[0].clone()
}

fn journal_lines(out: &Path) -> usize {
    let j: Vec<PathBuf> = std::fs::read_dir(out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".journal.jsonl"))
        .collect();
    assert_eq!(j.len(), 1, "{j:?}");
    std::fs::read_to_string(&j[0]).unwrap().lines().count()
}

fn json(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("tune.json")).unwrap()).unwrap()
}

#[test]
fn bad_tunes_exit_2_and_write_nothing() {
    for (args, why) in [
        (
            vec!["--train-seeds", "1-3", "--test-seeds", "3-5", "--vary", KEY],
            "overlap (3)",
        ),
        (vec!["--vary", "gripper.cup_radius_m=0.004:0.02"], "has no such key"),
        (vec!["--vary", "sensor.recognition=0:1"], "not a numeric key"),
        (vec!["--vary", "gripper.cup_diameter_m=0.02:0.004"], "reversed"),
        (vec!["--vary", "gripper.cup_diameter_m=0.004"], "LO:HI"),
        (vec!["--vary", "gripper.cup_diameter_m=a:b"], "finite numbers"),
        (vec!["--vary", "agitation.max_tries=1.5:8"], "whole numbers"),
        (vec!["--vary", KEY, "--min-success", "1.5"], "--min-success"),
        (vec!["--vary", KEY, "--budget", "0"], "--budget"),
        (vec!["--vary", KEY, "--objective", "fastest"], "--objective"),
        (vec!["--vary", KEY, "--optimizer", "random"], "--optimizer"),
    ] {
        let tmp = crate::support::tempdir().unwrap();
        let out = tmp.path().join("runs");
        let mut all = vec![
            "tune",
            "--workpiece",
            "B",
            "--picks",
            "3",
            "--out",
            out.to_str().unwrap(),
        ];
        if !args.contains(&"--train-seeds") {
            all.extend_from_slice(&["--train-seeds", "1", "--test-seeds", "2"]);
        }
        all.extend_from_slice(&args);
        let o = binpick(&all);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(why) && !err.contains("panicked"), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
}

#[test]
fn a_tiny_deterministic_tune_repeats_resumes_and_its_files_reproduce_its_test_figure() {
    let tmp = crate::support::tempdir().unwrap();
    let (a, b, c) = (tmp.path().join("a"), tmp.path().join("b"), tmp.path().join("c"));
    let small = ["--vary", KEY, "--budget", "4", "--population", "4"];
    for out in [&a, &b] {
        let o = tune(out, &small);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let (da, db) = (folder(&a), folder(&b));
    let ja = std::fs::read(da.join("tune.json")).unwrap();
    assert_eq!(ja, std::fs::read(db.join("tune.json")).unwrap());
    for f in [
        "tune.md",
        "tune.svg",
        "tuned/scene.toml",
        "tuned/workpiece-B.toml",
        "untuned/scene.toml",
    ] {
        assert!(da.join(f).is_file(), "{f}");
    }
    let doc = json(&da);
    let t = &doc["tune"];
    let evals = t["evaluations"].as_array().unwrap();
    assert_eq!(evals.len(), 4);
    // The best: feasible, and no feasible evaluation has a lower training takt (checked here
    // from the evaluations, not by the code that chose it).
    let best = &t["best"];
    let best_takt = best["train"]["takt_s"].as_f64().unwrap();
    let feasible: Vec<f64> = evals
        .iter()
        .filter(|e| e["feasible"] == true)
        .map(|e| e["train"]["takt_s"].as_f64().unwrap())
        .collect();
    assert!(feasible.iter().all(|x| *x >= best_takt), "{feasible:?} vs {best_takt}");
    assert_eq!(evals[best["index"].as_u64().unwrap() as usize]["feasible"], true);
    assert_eq!(t["test"]["seeds"], serde_json::json!([2]));
    assert!(t["test"]["untuned"]["takt_s"].is_f64());
    // The tuned files, run by batch on the test seed, give the test figure tune.json reports.
    let batch_out = tmp.path().join("batch");
    let o = binpick(&[
        "batch",
        "--scene",
        da.join("tuned/scene.toml").to_str().unwrap(),
        "--workpieces",
        da.join("tuned/workpiece-B.toml").to_str().unwrap(),
        "--seeds",
        "2",
        "--picks",
        "3",
        "--deterministic",
        "--json",
        "--out",
        batch_out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let row: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let batch_takt = row["table"][0]["takt"]["mean_s"].as_f64().unwrap();
    let tuned_test = t["test"]["tuned"]["takt_s"].as_f64().unwrap();
    assert_eq!(batch_takt, tuned_test);

    // Resume: a larger budget in the same folder answers the 4 journalled candidates from the
    // journal and gives what a fresh run with that budget gives.
    // The header, 4 evaluations, and the best's and the untuned cell's test figures.
    assert_eq!(journal_lines(&a), 1 + 4 + 2);
    let more = ["--vary", KEY, "--budget", "7", "--population", "4"];
    let o = tune(&a, &more);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("7 evaluations (4 from the journal"),
        "{}",
        stdout(&o)
    );
    // The terminal's text fits 110 columns (but the folder's path, and the journal's, which
    // stands whole on a line of its own: cut, it could not be copied); the control: tune.md,
    // which it printed before, does not.
    let said = stdout(&o);
    assert!(
        said.lines()
            .filter(|l| !l.starts_with("wrote ") && l.trim().contains(' '))
            .all(|l| l.chars().count() <= 110),
        "{said}"
    );
    assert!(said.contains("|   7 |"), "{said}");
    let md = std::fs::read_to_string(folder(&a).join("tune.md")).unwrap();
    assert!(md.lines().any(|l| l.chars().count() > 110), "{md}");
    let o = tune(&c, &more);
    assert!(o.status.success(), "{}", stderr(&o));
    // Negative control: a fresh folder has no journal to answer from.
    assert!(
        stdout(&o).contains("7 evaluations (0 from the journal"),
        "{}",
        stdout(&o)
    );
    assert_eq!(
        std::fs::read(folder(&a).join("tune.json")).unwrap(),
        std::fs::read(folder(&c).join("tune.json")).unwrap()
    );
    let resumed = json(&folder(&a));
    assert_eq!(resumed["tune"]["evaluations"].as_array().unwrap()[..4], evals[..]);
    // A journal of another tune (another population) is refused, nothing run.
    let o = tune(&a, &["--vary", KEY, "--budget", "7", "--population", "3"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("a journal of another tune"), "{}", stderr(&o));
}

#[test]
fn a_tune_without_a_feasible_candidate_writes_its_table_and_fails() {
    let tmp = crate::support::tempdir().unwrap();
    let out = tmp.path().join("runs");
    // Cups too wide for any face of B: the file checks refuse every candidate.
    let o = tune(
        &out,
        &[
            "--vary",
            "workpiece.gripper.cup_diameter_m=0.04:0.05",
            "--budget",
            "3",
            "--population",
            "3",
        ],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("no candidate met every constraint"),
        "{}",
        stderr(&o)
    );
    assert!(stdout(&o).contains("0 cell runs"), "{}", stdout(&o));
    let doc = json(&folder(&out));
    let t = &doc["tune"];
    assert!(t["best"].is_null() && t["test"].is_null());
    let evals = t["evaluations"].as_array().unwrap();
    assert_eq!(evals.len(), 3);
    assert!(evals.iter().all(|e| e["feasible"] == false && e["train"].is_null()));
    assert!(
        evals[0]["refused"]
            .as_str()
            .unwrap()
            .contains("no face the suction cup fits on"),
        "{}",
        evals[0]
    );
    assert!(!folder(&out).join("tuned").exists());
}

/// `binpick tune` as [`tune`] does, started and not waited for.
fn spawn_tune(out: &Path, extra: &[&str]) -> std::process::Child {
    let mut args = vec![
        "tune",
        "--workpiece",
        "B",
        "--train-seeds",
        "1",
        "--test-seeds",
        "2",
        "--picks",
        "3",
        "--deterministic",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    std::process::Command::new(env!("CARGO_BIN_EXE_binpick"))
        .args(&args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("binpick starts")
}

#[test]
fn the_shards_of_a_tune_write_the_tune_json_one_process_writes() {
    let tmp = crate::support::tempdir().unwrap();
    let (one, shared, lone) = (
        tmp.path().join("one"),
        tmp.path().join("shared"),
        tmp.path().join("lone"),
    );
    let small = ["--vary", KEY, "--budget", "4", "--population", "4", "--jobs", "1"];
    let o = tune(&one, &small);
    assert!(o.status.success(), "{}", stderr(&o));
    let whole = std::fs::read(folder(&one).join("tune.json")).unwrap();
    // Two shards at once in one shared folder, as two machines of a job array would run them.
    let shards: Vec<_> = ["1/2", "2/2"]
        .iter()
        .map(|k| {
            let mut args = small.to_vec();
            args.extend_from_slice(&["--shard", k]);
            spawn_tune(&shared, &args)
        })
        .collect();
    for s in shards {
        let o = s.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let name = folder(&one).file_name().unwrap().to_string_lossy().into_owned();
    for k in 1..=2 {
        let got = std::fs::read(shared.join(format!("{name}-shard{k}of2/tune.json"))).unwrap();
        assert!(got == whole, "shard {k}'s tune.json differs from one process's");
        // Each shard ran its share: two of the four candidates and one of the two test rows.
        let j = std::fs::read_to_string(shared.join(format!("{name}.shard{k}of2.journal.jsonl"))).unwrap();
        assert_eq!(j.lines().count(), 1 + 2 + 1, "{j}");
    }
    // Negative control: a shard alone has only its share; it waits for the others' and fails.
    let mut args = small.to_vec();
    args.extend_from_slice(&["--shard", "2/3", "--shard-wait-s", "1"]);
    let o = tune(&lone, &args);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("evaluation(s) of the other shards did not appear"),
        "{}",
        stderr(&o)
    );
    let j = std::fs::read_to_string(lone.join(format!("{name}.shard2of3.journal.jsonl"))).unwrap();
    assert_eq!(j.lines().count(), 1 + 1, "{j}");
}
