//! `binpick batch` as a user's CI runs it: the printed table's width, `--expect` limits (exit 1 on
//! a missed one, `takt.junit.xml`), bad limit files (exit 2, nothing written), and no NaN in any
//! output of a run that places nothing.
//!
//! The runs are of the radial capacitor, a part the default cup cannot take, for 2 picks: a few
//! seconds each, and nothing is placed.

use std::path::Path;

use crate::support::{Workspace, binpick_in, stderr, stdout};

const PART: &str = "capacitor-radial";

/// `binpick batch` of the capacitor for 2 picks into `ws/out`, with `extra` arguments.
fn batch(ws: &Workspace, extra: &[&str]) -> std::process::Output {
    let out = ws.path("out");
    let mut args = vec![
        "batch",
        "--workpieces",
        "workpieces/capacitor-radial.toml",
        "--picks",
        "2",
        "--deterministic",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    binpick_in(ws.dir.path(), &args)
}

/// Every file below `dir` with its text.
fn files_below(dir: &Path) -> Vec<(String, String)> {
    let mut out = Vec::new();
    if !dir.exists() {
        return out;
    }
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(files_below(&p));
        } else {
            let text = String::from_utf8_lossy(&std::fs::read(&p).unwrap()).into_owned();
            out.push((p.display().to_string(), text));
        }
    }
    out
}

/// The longest line of `text` (characters).
fn widest(text: &str) -> usize {
    text.lines().map(|l| l.chars().count()).max().unwrap_or(0)
}

/// A missed limit exits 1 naming the part, the figure, its value and the limit, and the JUnit
/// file holds one case per limit with a failure for the missed one; the printed lines fit 110
/// characters, and no output of this run (nothing placed) holds a NaN.
#[test]
fn a_missed_limit_exits_1_and_is_written_as_junit() {
    let ws = Workspace::new();
    let limits = ws.path("expect.toml");
    std::fs::write(&limits, format!("[{PART}]\ntakt_max_s = 100\ncollisions_max = 0\n")).unwrap();
    let o = batch(&ws, &["--expect", limits.to_str().unwrap()]);
    let text = stdout(&o);
    assert_eq!(o.status.code(), Some(1), "{text}\n{}", stderr(&o));
    let missed = text
        .lines()
        .find(|l| l.contains("MISSED"))
        .unwrap_or_else(|| panic!("{text}"));
    for word in [PART, "takt mean", "nothing placed", "100.000 s", "takt_max_s"] {
        assert!(missed.contains(word), "{word:?} not in {missed:?}");
    }
    assert!(stderr(&o).contains("1 of 2 limits"), "{}", stderr(&o));
    let files = files_below(&ws.path("out"));
    let junit = &files
        .iter()
        .find(|(p, _)| p.ends_with("takt.junit.xml"))
        .expect("takt.junit.xml written")
        .1;
    assert_eq!(junit.matches("<testcase ").count(), 2, "{junit}");
    assert_eq!(junit.matches("<failure ").count(), 1, "{junit}");
    assert!(junit.contains("tests=\"2\" failures=\"1\""), "{junit}");
    // The printed lines fit a terminal.
    assert!(widest(&text) <= 110, "{} characters wide:\n{text}", widest(&text));
    // No NaN anywhere (the takt.* files, the JUnit file, the resolved inputs, stdout).
    assert!(files.len() >= 5, "{files:?}");
    for (path, body) in files.iter().chain([&("stdout".to_string(), text.clone())]) {
        assert!(!body.to_lowercase().contains("nan"), "NaN in {path}");
    }
    // Negative control of the NaN check: the check sees the word when it is there.
    assert!("takt NaN s".to_lowercase().contains("nan"));
}

/// Negative control of the exit code: the same run with limits it keeps exits 0, and `--wide`
/// prints the full table, wider than a terminal (the width check fails on it).
#[test]
fn met_limits_exit_0_and_wide_is_wider() {
    let ws = Workspace::new();
    let limits = ws.path("expect.toml");
    std::fs::write(&limits, format!("[{PART}]\ncollisions_max = 0\nplaced_min = 0\n")).unwrap();
    let o = batch(&ws, &["--expect", limits.to_str().unwrap(), "--wide"]);
    let text = stdout(&o);
    assert_eq!(o.status.code(), Some(0), "{text}\n{}", stderr(&o));
    assert_eq!(text.lines().filter(|l| l.starts_with("  met: ")).count(), 2, "{text}");
    assert!(widest(&text) > 110, "--wide is {} characters wide", widest(&text));
    assert!(text.contains("compute grasp/Pick/Place [ms]"), "{text}");
}

/// Bad limit files exit 2 before any run, naming the file, the key and the value, and write
/// nothing: an unknown figure, an unknown workpiece, a value that is not a number, a share out of
/// range, a count that is not whole.
#[test]
fn bad_limit_files_exit_2_and_write_nothing() {
    let ws = Workspace::new();
    for (body, key, value) in [
        (format!("[{PART}]\ncycle_time_max_s = 2\n"), "cycle_time_max_s", "2"),
        ("[Z]\ntakt_max_s = 2\n".to_string(), "[Z]", "takt_max_s = 2"),
        (format!("[{PART}]\ntakt_max_s = \"fast\"\n"), "takt_max_s", "\"fast\""),
        (format!("[{PART}]\nsuccess_min = 95\n"), "success_min", "95"),
        (format!("[{PART}]\ncollisions_max = 0.5\n"), "collisions_max", "0.5"),
    ] {
        let limits = ws.path("bad.toml");
        std::fs::write(&limits, &body).unwrap();
        let o = batch(&ws, &["--expect", limits.to_str().unwrap()]);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{body}: {err}");
        for word in ["bad.toml", key, value] {
            assert!(err.contains(word), "{body}: {word:?} not in {err}");
        }
        assert_eq!(files_below(&ws.path("out")), Vec::new(), "{body}: wrote files");
    }
}
