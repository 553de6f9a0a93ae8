//! `binpick sweep` end to end: bad sweeps refused before anything runs (exit 2, the key and the
//! value named, no folder left behind), the shards of a sweep merging into the whole sweep's
//! `sweep.csv` byte for byte, a variant giving what `batch` gives on the same cell, and the
//! charts (`sweep.svg`, `takt.svg`) as well-formed SVG with one series per workpiece and axis
//! labels with units.

use std::path::Path;

use crate::support::{binpick, stderr};

/// Runs `binpick sweep ARGS --out OUT` and asserts exit 2, no panic, every fragment in stderr,
/// and nothing written under `out`.
fn refused(args: &[&str], expected: &[&str]) {
    let out = crate::support::tempdir().unwrap();
    let dest = out.path().join("runs");
    let mut all = vec!["sweep"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--picks", "2", "--out", dest.to_str().unwrap()]);
    let o = binpick(&all);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{args:?}: stderr {err}");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for e in expected {
        assert!(err.contains(e), "{args:?}: stderr lacks {e:?}:\n{err}");
    }
    assert!(!dest.exists(), "{args:?} left {}", dest.display());
}

#[test]
fn bad_sweeps_are_refused_naming_the_key_and_the_value() {
    // An unknown key: the strict cell file refuses it, naming the key and the variant's value.
    refused(
        &["--set", "sensor.latency_ms=300"],
        &["sensor.latency_ms=300", "unknown field `latency_ms`"],
    );
    // A value of the wrong type.
    refused(
        &["--set", "sensor.latency_s=0.3,fast"],
        &[
            "sweep variant 2: sensor.latency_s=fast",
            "sensor.latency_s",
            "invalid type",
            "\"fast\"",
        ],
    );
    refused(
        &["--set", "cycle.max_picks_per_capture=2.5"],
        &["cycle.max_picks_per_capture=2.5", "invalid type"],
    );
    refused(
        &["--set", "cycle.gentle_lift_hemmed=0.3,-1"],
        &["sweep variant 2", "cycle.gentle_lift_hemmed", "must be >= 0, got -1"],
    );
    // An empty list, an empty value in a list.
    refused(
        &["--set", "sensor.latency_s="],
        &["--set sensor.latency_s: the list of values is empty"],
    );
    refused(
        &["--set", "sensor.latency_s=0.3,,1.1"],
        &["sensor.latency_s", "an empty value"],
    );
    // A range with a zero step.
    refused(
        &["--set", "gripper.cup_diameter_m=0.004:0.012:0"],
        &["gripper.cup_diameter_m", "range \"0.004:0.012:0\" has a zero step"],
    );
    // Variants the cell checks refuse: a cup larger than every face of C (which runs with the
    // cell's cup), a tray out of reach, a latency out of range.
    refused(
        &["--workpieces", "C", "--set", "gripper.cup_diameter_m=0.006,0.04"],
        &[
            "sweep variant 2: gripper.cup_diameter_m=0.04",
            "no face the suction cup fits on",
        ],
    );
    refused(
        &[
            "--set",
            "place_tray.tray.center_m=[0.40, -0.22, 0.006],[1.2, -0.22, 0.006]",
        ],
        &[
            "sweep variant 2: place_tray.tray.center_m=[1.2, -0.22, 0.006]",
            "place_tray.tray is out of the arm's reach",
        ],
    );
    refused(
        &["--set", "sensor.latency_s=-1"],
        &["sensor.latency_s=-1", "sensor.latency_s must be"],
    );
    // The same key twice.
    refused(
        &["--set", "sensor.latency_s=0.3", "--set", "sensor.latency_s=1.1"],
        &["--set sensor.latency_s: the same key is set twice"],
    );
    // A workpiece key that no workpiece file has.
    refused(
        &["--workpieces", "E", "--set", "workpiece.grasp.margin_m=0.001"],
        &["workpiece.grasp.margin_m=0.001", "unknown field `margin_m`"],
    );
}

/// A minimal XML well-formedness check: tags nest and close, attributes are quoted, entities are
/// XML's, one root. Returns the start tags in document order (name and attribute text).
fn parse_xml(doc: &str) -> Vec<(String, String)> {
    let check_entities = |s: &str| {
        for (i, _) in s.match_indices('&') {
            let rest = &s[i..];
            let end = rest
                .find(';')
                .unwrap_or_else(|| panic!("unterminated entity at {rest:.20}"));
            let ent = &rest[1..end];
            assert!(
                ["amp", "lt", "gt", "quot", "apos"].contains(&ent) || ent.starts_with('#'),
                "unknown entity &{ent};"
            );
        }
    };
    let mut stack: Vec<String> = Vec::new();
    let mut tags = Vec::new();
    let mut roots = 0;
    let mut rest = doc;
    while let Some(open) = rest.find('<') {
        let text = &rest[..open];
        check_entities(text);
        assert!(
            !stack.is_empty() || text.trim().is_empty(),
            "text outside the root: {text:.40}"
        );
        rest = &rest[open..];
        if let Some(r) = rest.strip_prefix("<!--") {
            rest = &r[r.find("-->").expect("comment closes") + 3..];
            continue;
        }
        if let Some(r) = rest.strip_prefix("<?") {
            rest = &r[r.find("?>").expect("declaration closes") + 2..];
            continue;
        }
        // The tag ends at the first '>' outside quotes.
        let mut quote = None;
        let end = rest
            .char_indices()
            .find(|(_, c)| match quote {
                Some(q) if *c == q => {
                    quote = None;
                    false
                }
                Some(_) => false,
                None if *c == '"' || *c == '\'' => {
                    quote = Some(*c);
                    false
                }
                None => *c == '>',
            })
            .expect("tag closes")
            .0;
        let tag = &rest[1..end];
        rest = &rest[end + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            let open = stack.pop().expect("a close tag without an open one");
            assert_eq!(open, name.trim(), "</{name}> closes <{open}>");
            continue;
        }
        let self_closing = tag.ends_with('/');
        let tag = tag.trim_end_matches('/');
        let name: String = tag.chars().take_while(|c| !c.is_whitespace()).collect();
        assert!(
            !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || "-_:".contains(c)),
            "bad tag name {name:?}"
        );
        // Attributes: name="value" pairs, each value quoted, no '<' inside.
        let mut attrs = tag[name.len()..].trim();
        let attr_text = attrs.to_string();
        while !attrs.is_empty() {
            let eq = attrs
                .find('=')
                .unwrap_or_else(|| panic!("attribute without a value in <{tag}>"));
            let q = attrs[eq + 1..].chars().next().expect("a quoted value");
            assert!(q == '"' || q == '\'', "unquoted attribute in <{tag}>");
            let v_end = attrs[eq + 2..].find(q).expect("the value's quote closes") + eq + 2;
            let value = &attrs[eq + 2..v_end];
            assert!(!value.contains('<'), "'<' in an attribute of <{tag}>");
            check_entities(value);
            attrs = attrs[v_end + 1..].trim_start();
        }
        if stack.is_empty() {
            roots += 1;
        }
        tags.push((name.clone(), attr_text));
        if !self_closing {
            stack.push(name);
        }
    }
    assert!(rest.trim().is_empty(), "text after the root");
    assert!(stack.is_empty(), "unclosed tags {stack:?}");
    assert_eq!(roots, 1, "one root element");
    tags
}

/// The series of an SVG: `data-workpiece` of every `<g class="series">`, in order.
fn series(tags: &[(String, String)]) -> Vec<String> {
    tags.iter()
        .filter(|(n, a)| n == "g" && a.contains("class=\"series\""))
        .map(|(_, a)| {
            let i = a.find("data-workpiece=\"").unwrap() + 16;
            a[i..i + a[i..].find('"').unwrap()].to_string()
        })
        .collect()
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn run_ok(args: &[&str]) {
    let o = binpick(args);
    assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
}

#[test]
fn shards_merge_into_the_whole_sweep_and_a_variant_runs_as_batch_does() {
    let tmp = crate::support::tempdir().unwrap();
    let out = |s: &str| tmp.path().join(s).to_str().unwrap().to_string();
    let sweep = [
        "sweep",
        "--set",
        "sensor.latency_s=0.3,1.1",
        "--set",
        "cycle.max_picks_per_capture=1,3",
        "--workpieces",
        "E,F",
        "--picks",
        "3",
        "--deterministic",
        "--jobs",
        "2",
    ];
    let name = "sweep-sensor.latency_s+cycle.max_picks_per_capture-EF-seeds1-picks3-det";
    let with = |extra: &[&str]| -> Vec<String> { sweep.iter().chain(extra).map(|s| s.to_string()).collect() };
    let (whole, shards) = (out("whole"), out("shards"));
    // The whole sweep's text fits the terminal's 110 columns (the control: sweep.md, which it
    // printed before, does not).
    let o = binpick(&with(&["--out", &whole]).iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let said = crate::support::stdout(&o);
    assert!(said.lines().all(|l| l.chars().count() <= 110), "{said}");
    // Two keys' columns would not fit: each variant's values are listed above the table.
    assert!(
        said.contains("variant 4: sensor.latency_s = 1.1, cycle.max_picks_per_capture = 3\n"),
        "{said}"
    );
    assert!(said.contains("| variant | part |       success | takt [s] |"), "{said}");
    let md = read(&Path::new(&whole).join(name).join("sweep.md"));
    assert!(md.lines().any(|l| l.chars().count() > 110), "{md}");
    for a in [
        with(&["--shard", "1/3", "--out", &shards]),
        with(&["--shard", "2/3", "--out", &shards]),
        with(&["--shard", "3/3", "--out", &shards]),
    ] {
        run_ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    }
    let shard_dirs: Vec<String> = (1..=3).map(|k| format!("{shards}/{name}-shard{k}of3")).collect();
    let merged = out("merged");
    let mut margs = vec!["merge"];
    margs.extend(shard_dirs.iter().rev().map(String::as_str));
    margs.extend(["--out", &merged]);
    let o = binpick(&margs);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // Deterministic shards carry no run times: the merge says so rather than stop at "simulated".
    let said = crate::support::stdout(&o);
    assert!(said.contains("(deterministic results keep no run times"), "{said}");
    let whole_dir = Path::new(&whole).join(name);
    let merged_dir = Path::new(&merged).join(name);
    let csv = read(&whole_dir.join("sweep.csv"));
    assert_eq!(
        read(&merged_dir.join("sweep.csv")),
        csv,
        "merged shards differ from the whole sweep"
    );
    assert_eq!(read(&merged_dir.join("sweep.md")), read(&whole_dir.join("sweep.md")));
    assert_eq!(csv.lines().count(), 1 + 4 * 2, "{csv}");
    assert!(csv.starts_with("variant,sensor.latency_s,cycle.max_picks_per_capture,workpiece,runs,"));
    // Each variant's resolved files, in the sweep and in the merge.
    for v in 1..=4 {
        for f in ["scene.toml", "viper_s650.urdf", "workpiece-E.toml", "workpiece-F.toml"] {
            assert!(whole_dir.join(format!("variant-{v}/{f}")).is_file(), "variant-{v}/{f}");
            assert!(
                merged_dir.join(format!("variant-{v}/{f}")).is_file(),
                "merge: variant-{v}/{f}"
            );
        }
    }
    assert!(read(&whole_dir.join("variant-3/scene.toml")).contains("latency_s = 1.1"));
    // A shard missing: refused.
    let o = binpick(&["merge", &shard_dirs[0], &shard_dirs[1], "--out", &out("bad")]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("is in none of the shards given"), "{}", stderr(&o));

    // Variant 4 (latency 1.1 s, 3 picks per capture) is the default cell: its rows are the batch's.
    let batch = out("batch");
    run_ok(&[
        "batch",
        "--workpieces",
        "E,F",
        "--picks",
        "3",
        "--deterministic",
        "--out",
        &batch,
    ]);
    let batch_dir = Path::new(&batch).join("batch-EF-seeds1-picks3-det");
    let takt = read(&batch_dir.join("takt.csv"));
    for (w, line) in takt.lines().skip(1).enumerate() {
        let sweep_line = csv.lines().nth(1 + 3 * 2 + w).unwrap();
        let body = sweep_line.strip_prefix("4,1.1,3,").expect("variant 4's values");
        assert_eq!(&body[..body.rfind(',').unwrap()], line, "variant 4 against batch");
    }

    // The charts: well-formed, one series per workpiece per panel, axis labels with units.
    let svg = read(&whole_dir.join("sweep.svg"));
    let tags = parse_xml(&svg);
    assert_eq!(tags[0].0, "svg");
    let panels = tags
        .iter()
        .filter(|(n, a)| n == "g" && a.contains("class=\"panel\""))
        .count();
    assert_eq!(panels, 2, "two values of the second key: two small multiples");
    assert_eq!(series(&tags), ["E", "F", "E", "F"]);
    for label in ["sensor.latency_s [s]", "takt [s]", "cycle.max_picks_per_capture = 1"] {
        assert!(
            svg.contains(&format!(">{label}<")),
            "sweep.svg lacks the label {label:?}"
        );
    }
    let svg = read(&batch_dir.join("takt.svg"));
    let tags = parse_xml(&svg);
    assert_eq!(series(&tags), ["E", "F"]);
    for label in ["takt [s]", "success [%]", "workpiece"] {
        assert!(
            svg.contains(&format!(">{label}<")),
            "takt.svg lacks the label {label:?}"
        );
    }
}

#[test]
fn the_xml_check_catches_what_a_browser_refuses() {
    parse_xml(r#"<svg a="1"><g><text>a &amp; b</text></g><rect/></svg>"#);
    for bad in [
        "<svg><g></svg>",
        "<svg a=1></svg>",
        "<svg>a & b</svg>",
        "<svg></svg><svg></svg>",
        "<svg><text>x</g></svg>",
    ] {
        assert!(std::panic::catch_unwind(|| parse_xml(bad)).is_err(), "{bad}");
    }
}

/// A workpiece given as a file with a mesh: each variant's folder holds the mesh beside the
/// variant's workpiece file, so `binpick check` (and a re-run) finds it.
#[test]
fn a_mesh_workpiece_goes_beside_each_variant() {
    let tmp = crate::support::tempdir().unwrap();
    let mut obj = String::new();
    for z in [-0.005, 0.005] {
        for (x, y) in [(-0.015, -0.01), (0.015, -0.01), (0.015, 0.01), (-0.015, 0.01)] {
            obj += &format!("v {x} {y} {z}\n");
        }
    }
    for f in [
        "1 3 2", "1 4 3", "5 6 7", "5 7 8", "1 2 6", "1 6 5", "2 3 7", "2 7 6", "3 4 8", "3 8 7", "4 1 5", "4 5 8",
    ] {
        obj += &format!("f {f}\n");
    }
    std::fs::write(tmp.path().join("box.obj"), obj).unwrap();
    std::fs::write(
        tmp.path().join("M.toml"),
        "name = \"M\"\nkind = \"a box as a mesh\"\nsize_m = [0.03, 0.02, 0.01]\nmass_kg = 0.005\nfriction = 0.4\n\
         restitution = 0.1\npile_count = 10\n\n[shape]\nkind = \"mesh\"\nmesh_file = \"box.obj\"\n\n[grasp]\n\
         yaw_symmetry_deg = 180.0\nplace_yaw_deg = 0.0\nface_margin_m = 0.0005\n",
    )
    .unwrap();
    let wp = tmp.path().join("M.toml");
    let out = tmp.path().join("runs");
    run_ok(&[
        "sweep",
        "--workpieces",
        wp.to_str().unwrap(),
        "--set",
        "workpiece.friction=0.4,0.5",
        "--picks",
        "1",
        "--deterministic",
        "--out",
        out.to_str().unwrap(),
    ]);
    let dir = out.join("sweep-workpiece.friction-M-seeds1-picks1-det");
    for v in [1, 2] {
        let sub = dir.join(format!("variant-{v}"));
        assert!(sub.join("box.obj").is_file(), "variant-{v}/box.obj");
        let o = crate::support::binpick_in(&sub, &["check", "workpiece-M.toml", "scene.toml"]);
        assert_eq!(o.status.code(), Some(0), "variant-{v}: {}", stderr(&o));
    }
    assert!(read(&dir.join("variant-2/workpiece-M.toml")).contains("friction = 0.5"));
}

/// Shards written before the study pipeline still merge: the golden `takt.json` (a batch
/// written by an earlier binpick) split into two shard files reads back, merges into the same
/// file as the whole one read, and is written again as the same document, table included.
/// Negative controls: a run left out is refused, and one changed count shows in the document.
#[test]
fn shards_written_before_merge_into_the_same_file() {
    use binpick::study::{StudyFile, merge};
    let golden = crate::support::repo().join("tests/golden/batch-ABCDEF-seeds1-2-picks21-det/takt.json");
    let text = std::fs::read_to_string(&golden).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let whole = StudyFile::from_json(&doc).expect("the golden takt.json reads");
    assert!(whole.spec.is_batch() && whole.runs.len() == 12);
    // Split as `--shard K/2` would, each shard file written in the old layout.
    let shard = |k: usize| {
        let mut v = doc["batch"].clone();
        let runs: Vec<serde_json::Value> = v["runs"]
            .as_array()
            .unwrap()
            .iter()
            .skip(k - 1)
            .step_by(2)
            .cloned()
            .collect();
        v["runs"] = runs.into();
        v["shard"] = serde_json::json!([k, 2]);
        let f = StudyFile::from_json(&serde_json::json!({ "batch": v })).unwrap();
        (format!("shard{k}"), f)
    };
    let merged = merge(&[shard(2), shard(1)]).unwrap();
    assert_eq!(merged, whole);
    let takt_json = |f: &StudyFile| {
        let files = binpick::batch::outputs(f).files;
        files.into_iter().find(|(n, _)| *n == "takt.json").unwrap().1
    };
    let written = takt_json(&merged);
    assert!(
        written == takt_json(&whole),
        "the merge is not the whole batch's takt.json"
    );
    // The same document as the golden one: every key, every count, every number (serde_json
    // reads a decimal to within one unit in the last place, so numbers compare to 1e-15).
    let written: serde_json::Value = serde_json::from_str(&written).unwrap();
    assert_eq!(same_numbers(&written, &doc), Ok(()));
    // A run left out: refused.
    let (p, mut f) = shard(1);
    f.runs.pop();
    let e = merge(&[(p, f), shard(2)]).unwrap_err().to_string();
    assert!(e.contains("is in none of the shards given"), "{e}");
    // A count changed: the table written differs.
    let mut changed = merged.clone();
    changed.runs[0].tally.agitations += 1;
    let changed: serde_json::Value = serde_json::from_str(&takt_json(&changed)).unwrap();
    assert!(same_numbers(&changed, &doc).is_err(), "a changed count must show");
}

/// Whether two JSON documents have the same keys, texts and counts, and numbers equal to a
/// relative 1e-15; else the first path that differs.
fn same_numbers(a: &serde_json::Value, b: &serde_json::Value) -> Result<(), String> {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) if x.is_f64() || y.is_f64() => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            if (x - y).abs() <= 1e-15 * x.abs().max(y.abs()) {
                Ok(())
            } else {
                Err(format!("{x} vs {y}"))
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .try_for_each(|(i, (x, y))| same_numbers(x, y).map_err(|e| format!("[{i}] {e}"))),
        (Value::Object(x), Value::Object(y)) if x.keys().eq(y.keys()) => x
            .iter()
            .try_for_each(|(k, v)| same_numbers(v, &y[k]).map_err(|e| format!(".{k} {e}"))),
        _ if a == b => Ok(()),
        _ => Err(format!("{a} vs {b}")),
    }
}
