//! Recordings: `binpick run` writes `run.mcap`; read back with the mcap crate's reader and
//! compared with what the run did (its events, its placed picks, its metadata).

use crate::support::{Workspace, binpick_in, stderr};

#[test]
fn run_mcap_holds_what_the_run_did() {
    let ws = Workspace::new();
    let out = ws.path("out");
    let args = [
        "run",
        "--workpiece",
        "E",
        "--picks",
        "3",
        "--deterministic",
        "--out",
        out.to_str().unwrap(),
    ];
    let o = binpick_in(ws.dir.path(), &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = out.join("run-E-seed1-det");
    let bytes = std::fs::read(dir.join("run.mcap")).unwrap();
    let events: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(dir.join("events.json")).unwrap()).unwrap();
    let csv = std::fs::read_to_string(dir.join("picks.csv")).unwrap();
    // Placed picks with a takt: the takt column (7th) is set.
    let takts = csv
        .lines()
        .skip(1)
        .filter(|l| !l.split(',').nth(6).unwrap().is_empty())
        .count();

    let summary = mcap::read::Summary::read(&bytes).unwrap().expect("a summary section");
    let mut schemas: Vec<String> = summary.schemas.values().map(|s| s.name.clone()).collect();
    schemas.sort();
    assert_eq!(
        schemas,
        [
            "binpick.CycleEvent",
            "binpick.JointState",
            "binpick.Takt",
            "foxglove.FrameTransforms",
            "foxglove.Log",
            "foxglove.RawImage",
            "foxglove.SceneUpdate"
        ]
    );
    assert!(summary.schemas.values().all(|s| s.encoding == "jsonschema"));
    assert!(summary.channels.values().all(|c| c.message_encoding == "json"));
    assert!(!summary.chunk_indexes.is_empty(), "chunked");
    assert!(summary.chunk_indexes.iter().all(|c| c.compression == "zstd"));
    let meta = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).unwrap();
    assert_eq!(meta.name, "binpick");
    assert_eq!(meta.metadata["seed"], "1");
    assert_eq!(meta.metadata["workpiece"], "E");
    assert_eq!(meta.metadata["deterministic"], "true");

    let mut count = std::collections::BTreeMap::<String, usize>::new();
    let mut last = 0u64;
    let mut parts_span = (u64::MAX, 0u64);
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert!(m.log_time >= last, "log times go back on {}", m.channel.topic);
        last = m.log_time;
        *count.entry(m.channel.topic.clone()).or_default() += 1;
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        if m.channel.topic == "/camera/depth" {
            use base64::Engine;
            let data = base64::engine::general_purpose::STANDARD
                .decode(v["data"].as_str().unwrap())
                .unwrap();
            let (w, h) = (v["width"].as_u64().unwrap(), v["height"].as_u64().unwrap());
            assert_eq!(data.len() as u64, 2 * w * h);
            assert_eq!(v["encoding"], "16UC1");
        }
        if m.channel.topic == "/parts" {
            parts_span = (parts_span.0.min(m.log_time), parts_span.1.max(m.log_time));
            assert_eq!(v["entities"].as_array().unwrap().len(), 1, "all parts as one entity");
            assert!(!v["entities"][0]["cubes"].as_array().unwrap().is_empty());
        }
        if m.channel.topic == "/robot/joint_states" {
            let tau = v["torque_nm"].as_array().unwrap();
            let limit = v["torque_limit_nm"].as_array().unwrap();
            assert_eq!(tau.len(), 6);
            for (t, l) in tau.iter().zip(limit) {
                assert!(t.as_f64().unwrap().abs() <= l.as_f64().unwrap() + 1e-9);
            }
        }
    }
    assert_eq!(count["/cycle/events"], events.len());
    assert_eq!(count["/log"], events.len());
    assert_eq!(count.get("/cycle/takt").copied().unwrap_or(0), takts);
    assert!(takts >= 1);
    assert!(count["/robot/joint_states"] > 100 && count["/tf"] > 50, "{count:?}");
    // Each pick plays at least its transfer, descent and lift: a path each, planned and executed.
    assert!(count["/paths"] >= 3 * takts, "{count:?}");
    // One depth image per capture triggered; the parts every 0.1 s of simulated time.
    let run_summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(
        count["/camera/depth"] as u64,
        run_summary["captures"][0].as_u64().unwrap()
    );
    // Part frames every 0.1 s of simulated time, from the first cycle step to the end.
    let (first, last) = parts_span;
    let span_s = (last - first) as f64 * 1e-9;
    let frames = count["/parts"] as f64;
    assert!(
        (frames - (span_s / 0.1 + 1.0)).abs() <= 2.0,
        "{frames} part frames over {span_s} s"
    );
    assert!(last as f64 * 1e-9 <= run_summary["sim_time_s"].as_f64().unwrap() + 1e-6);

    // --no-mcap: no recording.
    let mut args = args.to_vec();
    args.push("--no-mcap");
    let o = binpick_in(ws.dir.path(), &args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!dir.join("run.mcap").exists());
}

/// Ctrl-C during a run: the pick under way finishes, every file is written and readable, the
/// summary says `interrupted`, and the exit code is 130.
#[cfg(unix)]
#[test]
fn ctrl_c_finishes_the_files_and_says_interrupted() {
    let ws = Workspace::new();
    let out = ws.path("out");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_binpick"))
        .args(["run", "--workpiece", "F", "--picks", "500", "--deterministic", "--out"])
        .arg(&out)
        .current_dir(ws.dir.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let killed = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted"), "{err}");
    let dir = out.join("run-F-seed1-det");
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["ended"], "interrupted");
    assert!(summary["attempts"].as_u64().unwrap() < 500);
    let bytes = std::fs::read(dir.join("run.mcap")).unwrap();
    let summary = mcap::read::Summary::read(&bytes)
        .unwrap()
        .expect("finished: a summary section");
    assert_eq!(summary.channels.len(), 8);
    assert!(mcap::MessageStream::new(&bytes).unwrap().all(|m| m.is_ok()));
}
