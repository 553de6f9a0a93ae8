//! Scenario tests of the first slice of the cell cycle: short deterministic runs end to end.

use crate::support::{Workspace, binpick_in, stderr};

#[test]
fn deterministic_runs_place_parts_and_repeat_byte_for_byte() {
    let ws = Workspace::new();
    for w in ["A", "E"] {
        let mut files = Vec::new();
        for out in ["out1", "out2"] {
            let dir = ws.path(out);
            let o = binpick_in(
                ws.dir.path(),
                &[
                    "run",
                    "--workpiece",
                    w,
                    "--picks",
                    "5",
                    "--deterministic",
                    "--out",
                    dir.to_str().unwrap(),
                    "--json",
                ],
            );
            assert!(o.status.success(), "{w}: {}", stderr(&o));
            let run = dir.join(format!("run-{w}-seed1-det"));
            let summary: serde_json::Value =
                serde_json::from_slice(&std::fs::read(run.join("summary.json")).unwrap()).unwrap();
            assert!(summary["placed"].as_u64().unwrap() >= 4, "{w}: {summary}");
            let takt = summary["takt"]["mean_s"].as_f64().unwrap();
            assert!(takt < 3.5, "{w}: takt {takt} s");
            let csv = std::fs::read_to_string(run.join("picks.csv")).unwrap();
            assert!(!csv.contains("protective_stop"), "{w}: {csv}");
            assert!(run.join("scene.toml").is_file());
            files.push((std::fs::read(run.join("summary.json")).unwrap(), csv));
        }
        assert_eq!(files[0], files[1], "{w}: the same seed gave different results");
    }
}
