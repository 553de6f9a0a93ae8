//! Golden outputs: the deterministic results of the embedded cell, kept byte for byte.
//!
//! `tests/golden/` holds what `binpick batch --deterministic --seeds 1-2` (`takt.csv`,
//! `takt.json`) and `binpick run --workpiece C --deterministic --picks 10` (`summary.json`,
//! `picks.csv`, `events.json`) wrote before the architecture redesign, with two
//! stated differences: `picks.csv` quotes a reason that holds commas (the old file replaced the
//! commas by spaces) and `takt.json` has no wall times in deterministic mode (they are
//! measurements, not results). A refactoring must leave them byte-identical; a change that is
//! meant to alter the results regenerates them with `BINPICK_BLESS=1 cargo test golden` and
//! says so in its commit.

use std::path::Path;

use crate::support::{Workspace, binpick_in, repo, stderr};

/// Compares `got` with the golden file `rel` (or rewrites it under `BINPICK_BLESS=1`).
fn same_as_golden(rel: &str, got: &Path) -> Result<(), String> {
    let golden = repo().join("tests/golden").join(rel);
    let got_bytes = std::fs::read(got).map_err(|e| format!("{}: {e}", got.display()))?;
    if std::env::var_os("BINPICK_BLESS").is_some() {
        std::fs::create_dir_all(golden.parent().unwrap()).unwrap();
        std::fs::write(&golden, &got_bytes).unwrap();
        return Ok(());
    }
    let want = std::fs::read(&golden).map_err(|e| format!("{}: {e}", golden.display()))?;
    if want == got_bytes {
        return Ok(());
    }
    let (w, g) = (String::from_utf8_lossy(&want), String::from_utf8_lossy(&got_bytes));
    let line = w.lines().zip(g.lines()).position(|(a, b)| a != b).unwrap_or(0);
    Err(format!(
        "{rel} differs from the golden file at line {}:\n  golden: {}\n  now:    {}",
        line + 1,
        w.lines().nth(line).unwrap_or(""),
        g.lines().nth(line).unwrap_or("")
    ))
}

#[test]
fn deterministic_outputs_match_the_golden_files() {
    let ws = Workspace::new();
    let out = ws.path("out");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "run",
            "--workpiece",
            "C",
            "--deterministic",
            "--picks",
            "10",
            "--no-rrd",
            "--no-mcap",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = binpick_in(
        ws.dir.path(),
        &[
            "batch",
            "--deterministic",
            "--seeds",
            "1-2",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let mut failures = Vec::new();
    for rel in [
        "run-C-seed1-det/summary.json",
        "run-C-seed1-det/picks.csv",
        "run-C-seed1-det/events.json",
        "batch-ABCDEF-seeds1-2-picks21-det/takt.csv",
        "batch-ABCDEF-seeds1-2-picks21-det/takt.json",
    ] {
        if let Err(e) = same_as_golden(rel, &out.join(rel)) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The check can fail: a golden file with one digit changed is reported (negative control).
#[test]
fn a_changed_result_is_caught() {
    let ws = Workspace::new();
    let golden = repo().join("tests/golden/run-C-seed1-det/summary.json");
    let text = std::fs::read_to_string(&golden).unwrap();
    let edited = text.replacen("\"workpiece\": \"C\"", "\"workpiece\": \"D\"", 1);
    assert_ne!(text, edited, "the golden summary has no workpiece C to edit");
    let p = ws.path("summary.json");
    std::fs::write(&p, edited).unwrap();
    if std::env::var_os("BINPICK_BLESS").is_none() {
        let e = same_as_golden("run-C-seed1-det/summary.json", &p).unwrap_err();
        assert!(e.contains("\"workpiece\": \"D\""), "{e}");
    }
}
