//! CAD parts: the shipped mesh workpieces pass `binpick check` and `binpick part` shows their
//! faces and poses; bad mesh files (truncated, NaN and infinite vertices, zero-area triangles,
//! open shells, millions of triangles, wrong units, bad indices, garbage) are refused by
//! `binpick check` with exit 2 and a message naming the mesh file, never a panic, within a time
//! bound.
//!
//! The truncations are drawn from `binpick::rng::stream(CUT_SEED, "cad-cuts")`, so a failing cut
//! is the same on every machine; its message names the file and the cut.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use rand::RngExt;

use crate::support::{Workspace, binpick, binpick_in, stderr, stdout, tempdir};

/// Seed of the truncation points.
const CUT_SEED: u64 = 29;
/// Truncations per shipped mesh file.
const CUTS: usize = 12;
/// The longest one `binpick check` of a bad file may take.
const BOUND: Duration = Duration::from_secs(20);

/// A workpiece file naming `mesh` with `units` (a TOML value line or empty), written beside it.
fn workpiece(dir: &Path, name: &str, mesh: &str, extra: &str) -> PathBuf {
    let p = dir.join(format!("{name}.toml"));
    std::fs::write(
        &p,
        format!(
            "name = \"{name}\"\nkind = \"fuzz case\"\nmass_kg = 0.002\nfriction = 0.4\nrestitution = 0.1\n\
             pile_count = 10\n{extra}\n[shape]\nkind = \"mesh\"\nmesh_file = \"{mesh}\"\nunits = \"mm\"\n\n\
             [grasp]\nyaw_symmetry_deg = 360.0\nplace_yaw_deg = 0.0\nface_margin_m = 0.0005\n"
        ),
    )
    .unwrap();
    p
}

/// A closed 10 x 20 x 30 mm box as OBJ text (mm), optionally without some of its faces.
fn box_obj(skip: &[usize]) -> String {
    let mut s = String::new();
    for i in 0..8 {
        let (x, y, z) = (10 * (i & 1), 20 * ((i >> 1) & 1), 30 * ((i >> 2) & 1));
        s += &format!("v {x} {y} {z}\n");
    }
    let tris = crate::support::BOX_TRIANGLES;
    for (k, t) in tris.iter().enumerate() {
        if !skip.contains(&k) {
            s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        }
    }
    s
}

/// A 1 mm cube (mm): vertices and outward-wound triangles.
fn unit_cube() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let v = (0..8)
        .map(|k| [(k & 1) as f64, (k >> 1 & 1) as f64, (k >> 2 & 1) as f64])
        .collect();
    (v, crate::support::BOX_TRIANGLES.to_vec())
}

/// An L-shaped prism (mm): the outline (0,0) (3,0) (3,1) (1,1) (1,3) (0,3), 1 mm high; not
/// convex, so its collider is decomposed.
fn l_prism() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let outline = [[0.0, 0.0], [3.0, 0.0], [3.0, 1.0], [1.0, 1.0], [1.0, 3.0], [0.0, 3.0]];
    let n = outline.len();
    let v = [0.0, 1.0]
        .iter()
        .flat_map(|&z| outline.iter().map(move |p| [p[0], p[1], z]))
        .collect();
    let mut f = Vec::new();
    for i in 1..n - 1 {
        f.push([0, i + 1, i]); // bottom, facing down
        f.push([n, n + i, n + i + 1]); // top, facing up
    }
    for i in 0..n {
        let j = (i + 1) % n;
        f.push([i, j, n + j]);
        f.push([i, n + j, n + i]);
    }
    (v, f)
}

/// Runs `binpick check FILE` and asserts exit 2, the mesh file named on stderr, no panic, and
/// the time bound; returns stderr.
fn refused(dir: &Path, toml: &Path, mesh: &str, why: &str) -> String {
    let t0 = Instant::now();
    let o = binpick_in(dir, &["check", toml.to_str().unwrap()]);
    let took = t0.elapsed();
    let err = stderr(&o);
    assert_eq!(
        o.status.code(),
        Some(2),
        "{why}: {mesh}: exit {:?}, stderr {err}",
        o.status.code()
    );
    assert!(!err.contains("panicked"), "{why}: {err}");
    assert!(err.contains(mesh), "{why}: stderr does not name {mesh}: {err}");
    assert!(took < BOUND, "{why}: took {took:?}");
    err
}

#[test]
fn bad_mesh_files_are_refused_naming_the_file_and_the_defect() {
    let tmp = tempdir().unwrap();
    let d = tmp.path();
    let stl_ascii = |v: &str| {
        format!(
            "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 10 0 0\nvertex {v}\nendloop\nendfacet\nendsolid t\n"
        )
    };
    let mut binary_nan = vec![0u8; 84 + 50];
    binary_nan[80] = 1;
    binary_nan[84 + 12..84 + 16].copy_from_slice(&f32::NAN.to_le_bytes());
    // A binary STL whose header begins with "solid" (as many exporters write it), cut short: one
    // of its two triangles kept.
    let mut solid_binary = vec![b' '; 84 + 50];
    solid_binary[..11].copy_from_slice(b"solid part1");
    solid_binary[80..84].copy_from_slice(&2u32.to_le_bytes());
    solid_binary[84 + 12..84 + 16].copy_from_slice(&1.5f32.to_le_bytes());
    let cases: Vec<(&str, Vec<u8>, &str, &str)> = vec![
        (
            "nan.obj",
            format!("{}v nan 0 0\n", box_obj(&[])).into_bytes(),
            "",
            "non-finite",
        ),
        ("inf.stl", stl_ascii("0 inf 0").into_bytes(), "", "non-finite"),
        ("nanbin.stl", binary_nan, "", "non-finite"),
        (
            "solidbin.stl",
            solid_binary,
            "",
            "binary STL whose header begins with \"solid\": its header announces 2 triangles (184 bytes), the file has 134 bytes",
        ),
        (
            "flat.obj",
            b"v 0 0 0\nv 10 0 0\nv 20 0 0\nf 1 2 3\nf 1 3 2\n".to_vec(),
            "",
            "empty mesh",
        ),
        (
            "zero.obj",
            b"v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 1 2\nf 2 3 3\n".to_vec(),
            "",
            "empty mesh",
        ),
        ("open.obj", box_obj(&[8, 9]).into_bytes(), "", "open shell"),
        (
            "grains.obj",
            {
                // 300 separate 1 mm cubes: more bodies than a part may have.
                let mut s = String::new();
                for i in 0..300 {
                    let (x, y) = ((i % 20) as f64 * 1.5, (i / 20) as f64 * 1.5);
                    for k in 0..8 {
                        s += &format!("v {} {} {}\n", x + (k & 1) as f64, y + (k >> 1 & 1) as f64, (k >> 2 & 1) as f64);
                    }
                    for t in crate::support::BOX_TRIANGLES {
                        s += &format!("f {} {} {}\n", 8 * i + t[0] + 1, 8 * i + t[1] + 1, 8 * i + t[2] + 1);
                    }
                }
                s.into_bytes()
            },
            "",
            "300 separate bodies, more than the 256",
        ),
        (
            "lumps.obj",
            {
                // 250 separate 1 mm cubes and 4 L-shaped prisms: 254 bodies, but each L is cut in
                // two or more convex pieces, so the collider needs more than its 256.
                let mut s = String::new();
                let mut base = 0;
                for i in 0..254 {
                    let (x, y) = ((i % 20) as f64 * 4.0, (i / 20) as f64 * 4.0);
                    let (v, f) = if i < 250 { unit_cube() } else { l_prism() };
                    for p in &v {
                        s += &format!("v {} {} {}\n", x + p[0], y + p[1], p[2]);
                    }
                    for t in &f {
                        s += &format!("f {} {} {}\n", base + t[0] + 1, base + t[1] + 1, base + t[2] + 1);
                    }
                    base += v.len();
                }
                s.into_bytes()
            },
            "",
            "convex pieces, more than 256: 4 of its bodies are not convex",
        ),
        (
            "index.obj",
            b"v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 9\n".to_vec(),
            "",
            "out of range",
        ),
        (
            "cut.obj",
            b"v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2".to_vec(),
            "",
            "truncated",
        ),
        ("empty.stl", Vec::new(), "", "truncated"),
        (
            "garbage.stl",
            (0..999u32).map(|i| (i * 7919 % 251) as u8).collect(),
            "",
            "cannot load mesh",
        ),
        (
            "nan.wrl",
            b"#VRML V2.0 utf8\nShape { geometry IndexedFaceSet { coordIndex [0 1 2 -1]\n coord Coordinate { point [0 0 0, 10 0 0, 0 nan 0] } } }\n".to_vec(),
            "",
            "non-finite",
        ),
        (
            "notvrml.wrl",
            b"#VRML V1.0 ascii\nSeparator { }\n".to_vec(),
            "",
            "not VRML 2.0",
        ),
        (
            "boxnode.wrl",
            b"#VRML V2.0 utf8\nShape { geometry Box { size 1 1 1 } }\n".to_vec(),
            "",
            "unsupported",
        ),
        // Wrong units: a 10 x 20 x 30 mm box read as metres (30 m), as micrometres by scale
        // (0.03 mm), and as inches (0.76 m: not in the tray).
        ("metres.obj", box_obj(&[]).into_bytes(), "units_m", "wrong units"),
        ("tiny.obj", box_obj(&[]).into_bytes(), "scale", "wrong units"),
        (
            "inches.obj",
            box_obj(&[]).into_bytes(),
            "units_inch",
            "larger than the pick tray",
        ),
        (
            "sized.obj",
            box_obj(&[]).into_bytes(),
            "size",
            "size_m is derived from the mesh",
        ),
    ];
    for (mesh, bytes, how, want) in &cases {
        std::fs::write(d.join(mesh), bytes).unwrap();
        let stem = mesh.replace('.', "_");
        let toml = workpiece(
            d,
            &stem,
            mesh,
            if *how == "size" {
                "size_m = [0.01, 0.02, 0.031]"
            } else {
                ""
            },
        );
        let text = std::fs::read_to_string(&toml).unwrap();
        let text = match *how {
            "units_m" => text.replace("units = \"mm\"", "units = \"m\""),
            "units_inch" => text.replace("units = \"mm\"", "units = \"inch\""),
            "scale" => text.replace("units = \"mm\"", "mesh_scale = 0.000001"),
            _ => text,
        };
        std::fs::write(&toml, text).unwrap();
        let err = refused(d, &toml, mesh, want);
        assert!(err.contains(want), "{mesh}: expected {want:?} in: {err}");
    }
    // Negative control: the same box in the right units is accepted.
    let toml = workpiece(d, "good", "metres.obj", "");
    let o = binpick_in(d, &["check", toml.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("ok: "), "{}", stdout(&o));
    // ... and 254 cubes without the L-shaped prisms: 254 pieces fit.
    let mut s = String::new();
    for i in 0..254 {
        let (x, y) = ((i % 20) as f64 * 4.0, (i / 20) as f64 * 4.0);
        let (v, f) = unit_cube();
        for p in &v {
            s += &format!("v {} {} {}\n", x + p[0], y + p[1], p[2]);
        }
        for t in &f {
            s += &format!("f {} {} {}\n", 8 * i + t[0] + 1, 8 * i + t[1] + 1, 8 * i + t[2] + 1);
        }
    }
    std::fs::write(d.join("cubes.obj"), s).unwrap();
    let toml = workpiece(d, "cubes", "cubes.obj", "");
    let o = binpick_in(d, &["check", toml.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn millions_of_triangles_are_refused_at_once() {
    let tmp = tempdir().unwrap();
    let d = tmp.path();
    // A binary STL announcing 3 million triangles, of the size that holds them (a sparse file
    // of 150 MB): refused from its header, without reading it.
    let n: u32 = 3_000_000;
    let mut f = std::fs::File::create(d.join("huge.stl")).unwrap();
    let mut head = vec![b' '; 80];
    head.extend(n.to_le_bytes());
    std::io::Write::write_all(&mut f, &head).unwrap();
    f.set_len(84 + 50 * n as u64).unwrap();
    drop(f);
    let toml = workpiece(d, "huge", "huge.stl", "");
    let err = refused(d, &toml, "huge.stl", "3M triangles");
    assert!(err.contains("3000000 triangles"), "{err}");
    // A text OBJ of 250,000 triangles (a triangle strip): refused when the cap is passed.
    let mut s = String::with_capacity(12_000_000);
    for i in 0..250_002 {
        s += &format!("v {} {} 0\n", i / 2, i % 2);
    }
    for i in 1..=250_000 {
        s += &format!("f {} {} {}\n", i, i + 1, i + 2);
    }
    std::fs::write(d.join("strip.obj"), s).unwrap();
    let toml = workpiece(d, "strip", "strip.obj", "");
    let err = refused(d, &toml, "strip.obj", "250k triangles");
    assert!(err.contains("more than the 200000"), "{err}");
}

#[test]
fn truncated_shipped_meshes_are_refused() {
    let ws = Workspace::new();
    let mut rng = binpick::rng::stream(CUT_SEED, "cad-cuts");
    for (toml, mesh, always) in [
        ("hex-standoff.toml", "hex-standoff.stl", true),
        ("to220.toml", "to220.wrl", true),
        ("dip8.toml", "dip8.wrl", true),
        // An OBJ has no end marker: a cut at a line end between two bodies leaves a valid part.
        // It must be refused or accepted, never crash.
        ("smd-elcap.toml", "smd-elcap.obj", false),
    ] {
        let bytes = std::fs::read(ws.path(&format!("workpieces/{mesh}"))).unwrap();
        for k in 0..CUTS {
            let cut = rng.random_range(16..bytes.len() - 8);
            let name = format!("cut{k}-{mesh}");
            std::fs::write(ws.path(&format!("workpieces/{name}")), &bytes[..cut]).unwrap();
            let t = ws.edit(
                &format!("workpieces/{toml}"),
                &format!("workpieces/cut{k}-{toml}"),
                &format!("mesh_file = \"{mesh}\""),
                &format!("mesh_file = \"{name}\""),
            );
            let why = format!("{mesh} cut at byte {cut} of {}", bytes.len());
            // A VRML cut between two top-level nodes is a whole file of fewer shapes.
            let between_nodes = mesh.ends_with(".wrl") && brace_depth(&bytes[..cut]) == 0;
            if always && !between_nodes {
                refused(ws.dir.path(), &t, &name, &why);
            } else {
                let o = binpick_in(ws.dir.path(), &["check", t.to_str().unwrap()]);
                let err = stderr(&o);
                assert!(
                    matches!(o.status.code(), Some(0 | 2)),
                    "{why}: {:?} {err}",
                    o.status.code()
                );
                assert!(o.status.code() == Some(0) || err.contains(&name), "{why}: {err}");
            }
        }
    }
}

/// How many braces and brackets are open at the end of `text` (comments skipped).
fn brace_depth(text: &[u8]) -> i64 {
    let mut depth = 0;
    let mut comment = false;
    for &c in text {
        match c {
            b'\n' => comment = false,
            b'#' => comment = true,
            b'{' | b'[' if !comment => depth += 1,
            b'}' | b']' if !comment => depth -= 1,
            _ => {}
        }
    }
    depth
}

#[test]
fn shipped_cad_parts_check_and_show_their_faces() {
    let ws = Workspace::new();
    let files: Vec<String> = ["hex-standoff", "to220", "dip8", "smd-elcap"]
        .iter()
        .map(|n| ws.path(&format!("workpieces/{n}.toml")).display().to_string())
        .collect();
    let mut args = vec!["check"];
    args.extend(files.iter().map(|s| s.as_str()));
    let o = binpick_in(ws.dir.path(), &args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stdout(&o).matches("ok: ").count(), 4, "{}", stdout(&o));
    // Each part's summary (mesh, size, repairs: 290 characters for the DIP-8) fits a terminal.
    let longest = stdout(&o).lines().map(|l| l.chars().count()).max().unwrap();
    assert!(longest <= 110, "a line of {longest} characters:\n{}", stdout(&o));
    // So does each part's `part` text (a face's row, the recognition's figures), with no `NaN`.
    for f in &files {
        let o = binpick_in(ws.dir.path(), &["part", f]);
        assert!(o.status.success(), "{f}: {}", stderr(&o));
        let text = stdout(&o);
        let longest = text.lines().map(|l| l.chars().count()).max().unwrap();
        assert!(
            longest <= 110 && !text.contains("NaN"),
            "{f}: a line of {longest} characters:\n{text}"
        );
    }
    // The DIP-8 (6.35 mm body) brings its own 4 mm cup: every shipped part has a face for its cup.
    assert_eq!(stderr(&o).matches("warning: ").count(), 0, "{}", stderr(&o));
    // Negative control: without its own cup, the cell's 6 mm cup fits no face, and check says so.
    let bare = ws.edit(
        "workpieces/dip8.toml",
        "workpieces/dip8-cell-cup.toml",
        "[gripper]\ncup_diameter_m = 0.004\n",
        "",
    );
    let o = binpick_in(ws.dir.path(), &["check", &bare.display().to_string()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert_eq!(err.matches("warning: ").count(), 1, "{err}");
    assert!(
        err.contains("dip8-cell-cup.toml: no planar face takes the cell's 6.0 mm cup"),
        "{err}"
    );

    let part = |name: &str| -> serde_json::Value {
        let svg = ws.path(&format!("{name}.svg"));
        let o = binpick_in(
            ws.dir.path(),
            &[
                "part",
                &ws.path(&format!("workpieces/{name}.toml")).display().to_string(),
                "--json",
                "--svg",
                &svg.display().to_string(),
            ],
        );
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let svg_text = std::fs::read_to_string(&svg).unwrap();
        assert!(svg_text.starts_with("<svg") && svg_text.trim_end().ends_with("</svg>"));
        serde_json::from_str(&stdout(&o)).unwrap()
    };
    // The hex standoff: 20 mm long, 14 mm across flats. Independently: each of its six flats
    // is 14 / sqrt(3) = 8.083 mm wide and 20 mm long, and only those take the 7 mm disc (the
    // ends are rings 3.6 mm wide about the 6.8 mm bore).
    let hex = part("hex-standoff");
    let size: Vec<f64> = hex["size_mm"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        (size[1] - 14.0).abs() < 1e-3 && (size[2] - 20.0).abs() < 1e-3,
        "{size:?}"
    );
    let faces = hex["faces"].as_array().unwrap();
    let takes: Vec<&serde_json::Value> = faces.iter().filter(|f| f["cup_fit"]["takes_cup"] == true).collect();
    assert_eq!(takes.len(), 6, "{faces:?}");
    let flat = 14.0 / 3f64.sqrt() * 20.0;
    for f in &takes {
        assert!((f["area_mm2"].as_f64().unwrap() - flat).abs() < 0.01, "{f}");
    }
    let ends: Vec<&serde_json::Value> = faces.iter().filter(|f| f["holes"] == 1).collect();
    assert_eq!(ends.len(), 2);
    assert!(ends.iter().all(|f| f["cup_fit"]["takes_cup"] == false));
    // Its mass properties: the hexagon minus the bore, times the length.
    let vol = (3f64.sqrt() / 2.0 * 14.0 * 14.0 - 18.0 * 3.4 * 3.4 * (2.0 * std::f64::consts::PI / 36.0).sin()) * 20.0;
    assert!(
        (hex["volume_mm3"].as_f64().unwrap() - vol).abs() < 0.05,
        "{} vs {vol}",
        hex["volume_mm3"]
    );
    // Resting: on a flat (six, equally likely by symmetry) or on an end.
    let poses = hex["poses"].as_array().unwrap();
    let sum: f64 = poses.iter().map(|p| p["likelihood"].as_f64().unwrap()).sum();
    assert!((sum - 1.0).abs() < 1e-5);
    assert_eq!(poses.len(), 8, "{poses:?}");
    assert_eq!(hex["symmetry_orders"][2], 6);
    // Three simulated piles: every part is counted, and most offer a flat with nothing on it
    // (a flat looks up in 81 % of the single-part poses; a pile covers some).
    let pile = &hex["pile"];
    assert_eq!(pile["piles"], 3);
    assert!(pile["parts_in_tray"].as_u64().unwrap() >= 3 * 30 - 3, "{pile}");
    let share = pile["share"].as_f64().unwrap();
    assert!(share > 0.3 && share < 0.9, "{pile}");
    // Negative control: the DIP-8 with the cell's 6 mm cup has no face for it, so no part of
    // its piles offers one; with its own 4 mm cup most do.
    let dip = part("dip8-cell-cup");
    assert_eq!(dip["pile"]["parts_offering_a_cup_face"], 0, "{}", dip["pile"]);
    assert!(dip["pile"]["parts_in_tray"].as_u64().unwrap() > 0);
    let dip = part("dip8");
    assert!(dip["pile"]["share"].as_f64().unwrap() > 0.3, "{}", dip["pile"]);
    // Each pile captured once and recognised as the cell does, judged against the parts: most
    // of the top layer found. The control, the figures follow the sensor: in a scan mode of a
    // quarter of the cell's pixels each way (3.4 mm pixels, a DIP's top face 3 x 2 of them) it
    // finds far fewer.
    let rec = &dip["pile"]["recognition"];
    assert_eq!(rec["captures"], 3, "{rec}");
    let recall = rec["recall"].as_f64().unwrap();
    assert!(recall > 0.8 && rec["precision"].as_f64().unwrap() > 0.9, "{rec}");
    // By resting pose: every top-layer part is counted once, in the pose nearest its own or
    // propped up, and the ones found add up to the recall's count.
    let by_pose = |key: &str| -> u64 {
        let poses = dip["poses"].as_array().unwrap();
        poses
            .iter()
            .map(|p| p["top_layer_recognised"][key].as_u64().unwrap())
            .sum::<u64>()
            + dip["pile"]["top_layer_recognised_propped_up"][key].as_u64().unwrap()
    };
    assert_eq!(by_pose("of"), rec["top_layer"].as_u64().unwrap(), "{rec}");
    assert_eq!(by_pose("found"), rec["top_layer_found"].as_u64().unwrap(), "{rec}");
    ws.edit(
        "workpieces/dip8.toml",
        "workpieces/dip8-coarse.toml",
        "[shape]",
        "[sensor]\nresolution_px = [258, 193]\n\n[shape]",
    );
    let coarse_part = part("dip8-coarse");
    let coarse = &coarse_part["pile"]["recognition"];
    assert!(
        coarse["recall"].as_f64().unwrap() < recall - 0.3,
        "coarse {coarse}, the cell's {rec}"
    );
    // And once more at twice the resolution over the same field of view, what a user choosing
    // a finer scan mode gets: the coarse mode's double (516 x 386) finds more than the coarse
    // mode, the cell's double (2064 x 1544) about what the cell finds or more. A mode whose
    // double exceeds the cell's 4 MP bound gives none.
    let twice = |v: &serde_json::Value| v["pile"]["recognition_at_twice_the_resolution"].clone();
    let finds_more = |v: &serde_json::Value, px: [u32; 2], recall_above: f64| {
        let t = twice(v);
        assert_eq!(t["resolution_px"], serde_json::json!(px), "{t}");
        assert!(
            t["summary"]["recall"].as_f64().unwrap() > recall_above,
            "{t}, against {recall_above}"
        );
    };
    finds_more(&coarse_part, [516, 386], coarse["recall"].as_f64().unwrap() + 0.2);
    finds_more(&dip, [2064, 1544], recall - 0.05);
    ws.edit(
        "workpieces/dip8.toml",
        "workpieces/dip8-fine.toml",
        "[shape]",
        "[sensor]\nresolution_px = [2064, 1544]\n\n[shape]",
    );
    assert!(twice(&part("dip8-fine")).is_null());

    // The TO-220: three bodies and more (body, tab, leads), the tab's hole found; its body's top
    // and back take the cup.
    let to = part("to220");
    assert!(to["repair"]["bodies"].as_u64().unwrap() >= 5, "{}", to["repair"]);
    let size: Vec<f64> = to["size_mm"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(
        (size[0] - 10.0).abs() < 1e-3 && (size[1] - 28.5).abs() < 1e-3 && (size[2] - 4.4).abs() < 1e-3,
        "{size:?}"
    );
    let faces = to["faces"].as_array().unwrap();
    assert!(faces.iter().any(|f| f["holes"] == 1), "the tab's hole");
    assert!(faces.iter().filter(|f| f["cup_fit"]["takes_cup"] == true).count() >= 2);

    // The SMD capacitor: the can's top takes the cup, centred within the 0.5 mm the 8 mm can
    // leaves about a 7 mm disc.
    let cap = part("smd-elcap");
    let takes: Vec<&serde_json::Value> = cap["faces"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["cup_fit"]["takes_cup"] == true)
        .collect();
    assert!(!takes.is_empty());
    let top = takes
        .iter()
        .find(|f| f["normal"][2].as_f64().unwrap() > 0.999)
        .expect("the can's top");
    let c = &top["cup_fit"]["best_centre_mm"];
    assert!(c[0].as_f64().unwrap().hypot(c[1].as_f64().unwrap()) < 0.5, "{c}");
}

/// A valid mesh just under the triangle cap (a cylinder of 2000 sides in 46 rings, 188,000
/// triangles) is read, repaired and modelled within the bound: large files are no hang, and the
/// part reads as round about its axis.
#[test]
fn a_mesh_near_the_cap_is_modelled_within_the_bound() {
    let tmp = tempdir().unwrap();
    let d = tmp.path();
    let (n, rings, r, h) = (2000usize, 46usize, 10.0f32, 20.0f32);
    let p = |k: usize, j: usize| {
        let a = 2.0 * std::f32::consts::PI * (k % n) as f32 / n as f32;
        [r * a.cos(), r * a.sin(), h * j as f32 / rings as f32]
    };
    let mut tris: Vec<[[f32; 3]; 3]> = Vec::new();
    for j in 0..rings {
        for k in 0..n {
            tris.push([p(k, j), p(k + 1, j), p(k + 1, j + 1)]);
            tris.push([p(k, j), p(k + 1, j + 1), p(k, j + 1)]);
        }
    }
    for k in 0..n {
        tris.push([[0.0, 0.0, 0.0], p(k + 1, 0), p(k, 0)]);
        tris.push([[0.0, 0.0, h], p(k, rings), p(k + 1, rings)]);
    }
    let mut bytes = vec![b' '; 80];
    bytes.extend((tris.len() as u32).to_le_bytes());
    for t in &tris {
        bytes.extend([0u8; 12]);
        for v in t {
            for c in v {
                bytes.extend(c.to_le_bytes());
            }
        }
        bytes.extend([0u8; 2]);
    }
    std::fs::write(d.join("cyl.stl"), bytes).unwrap();
    let toml = workpiece(d, "cyl", "cyl.stl", "");
    let t0 = Instant::now();
    let o = binpick_in(
        d,
        &[
            "part",
            toml.to_str().unwrap(),
            "--json",
            "--piles",
            "0",
            "--svg",
            d.join("cyl.svg").to_str().unwrap(),
        ],
    );
    let took = t0.elapsed();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(took < 3 * BOUND, "took {took:?}");
    let j: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(j["triangles"], 188_000);
    assert_eq!(j["symmetry_orders"][2], 64, "round about its axis");
    // Its flat ends take the cup (independently: a 20 mm disc holds a 7 mm one).
    let ends = j["faces"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["cup_fit"]["takes_cup"] == true)
        .count();
    assert_eq!(ends, 2);
}

/// `binpick part` reads a built-in part too: its primitives meshed are the part model every
/// stage reads. B, a 30 x 30 x 20 mm block with its own 16 mm cup: six faces (two of 900 mm^2,
/// four of 600), every one wide enough for the 17 mm disc (cup and both margins); 18,000 mm^3;
/// the box's own turns (half turns about x and y, quarter turns about z), detected; the cup's
/// site at each face's centre. Independent: the box's arithmetic.
#[test]
fn the_part_command_reads_a_built_in_part_through_its_meshed_primitives() {
    let tmp = tempdir().unwrap();
    let svg = tmp.path().join("B.svg");
    let o = binpick(&["part", "B", "--json", "--piles", "0", "--svg", svg.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let faces = j["faces"].as_array().unwrap();
    let mut areas: Vec<f64> = faces.iter().map(|f| f["area_mm2"].as_f64().unwrap()).collect();
    areas.sort_by(f64::total_cmp);
    assert_eq!(areas.len(), 6, "{faces:?}");
    for (a, want) in areas.iter().zip([600.0, 600.0, 600.0, 600.0, 900.0, 900.0]) {
        assert!((a - want).abs() < 1e-6, "{areas:?}");
    }
    assert!(faces.iter().all(|f| f["cup_fit"]["takes_cup"] == true), "{faces:?}");
    // The cup's site, the grasp selector's: a box face's centre (nothing of the part above it),
    // to the fit grid's spacing (the grid need not hold the exact centre).
    for f in faces {
        let (site, centre) = (&f["cup_fit"]["cup_site_mm"], &f["centroid_mm"]);
        let grid = f["cup_fit"]["grid_spacing_mm"].as_f64().unwrap();
        for k in 0..3 {
            let (a, b) = (site[k].as_f64().unwrap(), centre[k].as_f64().unwrap());
            assert!((a - b).abs() <= grid, "site {site} vs centre {centre} (grid {grid} mm)");
        }
    }
    assert!((j["volume_mm3"].as_f64().unwrap() - 18_000.0).abs() < 1e-6);
    assert_eq!(j["symmetry_orders"], serde_json::json!([2, 2, 4]));
    // B has no round body, and its cup seals on flat faces only: no round side.
    assert!(j["round_side"].is_null(), "{}", j["round_side"]);
}

/// D's bellows cup seals on radii of 4 mm and up; `binpick part` says what it takes of D's 5 mm
/// can's side: of the 24 tangent strips every one has a clear site (the base plate stands proud
/// 1.9 mm, below the 6 mm cup's length), and the four a lying pose has up (within 3 deg: D rests
/// on its can and its base's flat side, four ways round) are offered. Independent: D's drawing.
#[test]
fn the_part_command_says_what_a_bellows_cup_takes_of_a_cans_side() {
    let tmp = tempdir().unwrap();
    let svg = tmp.path().join("D.svg");
    let o = binpick(&["part", "D", "--json", "--piles", "0", "--svg", svg.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let side = &j["round_side"];
    assert_eq!(side["cup_round_min_radius_mm"].as_f64(), Some(4.0), "{side}");
    assert_eq!(side["body_radius_mm"].as_f64(), Some(5.0), "{side}");
    assert_eq!(side["strips"].as_u64(), Some(24), "{side}");
    assert_eq!(side["strips_with_a_clear_site"].as_u64(), Some(24), "{side}");
    assert_eq!(side["strips_offered"].as_u64(), Some(4), "{side}");
}

/// `grasp.place_orientation`: `binpick check` warns when an upright part cannot be picked at
/// all (the hex standoff's bored ends do not take the 6 mm cup, and only they are up when it
/// stands on its end), not when one face can (the DIP-8's top, its legs down; the control), and
/// refuses an unknown orientation with exit 2 naming the file and the key.
#[test]
fn check_warns_when_no_face_can_be_placed_upright_and_refuses_an_unknown_orientation() {
    let ws = Workspace::new();
    let with = |file: &str, line: &str| {
        let src = ws.path(&format!("workpieces/{file}.toml"));
        let text = std::fs::read_to_string(&src).unwrap().replace(
            "face_margin_m = 0.0005",
            &format!("face_margin_m = 0.0005\nplace_orientation = {line}"),
        );
        let out = ws.path(&format!("workpieces/{file}-{}.toml", line.trim_matches('"')));
        std::fs::write(&out, text).unwrap();
        binpick_in(ws.dir.path(), &["check", out.to_str().unwrap()])
    };
    let hex = with("hex-standoff", "\"upright\"");
    assert!(hex.status.success(), "{}", stderr(&hex));
    assert!(
        stderr(&hex).contains("warning") && stderr(&hex).contains("grasp.place_orientation = \"upright\""),
        "{}",
        stderr(&hex)
    );
    let dip = with("dip8", "\"upright\"");
    assert!(
        dip.status.success() && !stderr(&dip).contains("warning"),
        "{}",
        stderr(&dip)
    );
    // `binpick part` lists the faces placed upright: the DIP-8's top (face 2), none of the
    // standoff's.
    let upright = |file: &str| {
        let svg = ws.path(&format!("{file}.svg"));
        let toml = ws.path(&format!("workpieces/{file}.toml"));
        let o = binpick_in(
            ws.dir.path(),
            &["part", toml.to_str().unwrap(), "--svg", svg.to_str().unwrap(), "--json"],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        v["upright_faces"].clone()
    };
    assert_eq!(upright("dip8"), serde_json::json!([2]));
    assert_eq!(upright("hex-standoff"), serde_json::json!([]));
    let bad = with("dip8", "\"sideways\"");
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("dip8-sideways.toml") && stderr(&bad).contains("grasp.place_orientation"),
        "{}",
        stderr(&bad)
    );
}

/// A D-shaped prism (mm) as OBJ text: an arc of radius `r` cut by a flat `d` from its axis, in
/// `segments` straight pieces, `len` long along z; and three 0.45 x 0.4 mm leads 12.7 mm long
/// out of its -z end (a TO-92, as a CAD library would tessellate it).
fn d_prism_obj(r: f64, d: f64, segments: usize, len: f64) -> String {
    let mut v: Vec<[f64; 3]> = Vec::new();
    let mut f: Vec<[usize; 3]> = Vec::new();
    let mut prism = |poly: &[[f64; 2]], z0: f64, z1: f64| {
        let (n, b) = (poly.len(), v.len());
        v.extend(poly.iter().map(|p| [p[0], p[1], z0]));
        v.extend(poly.iter().map(|p| [p[0], p[1], z1]));
        for i in 1..n - 1 {
            f.push([b, b + i + 1, b + i]);
            f.push([b + n, b + n + i, b + n + i + 1]);
        }
        for i in 0..n {
            let j = (i + 1) % n;
            f.push([b + i, b + j, b + n + j]);
            f.push([b + i, b + n + j, b + n + i]);
        }
    };
    let a0 = (d / r).asin();
    let arc: Vec<[f64; 2]> = (0..=segments)
        .map(|k| {
            let t = -a0 + (std::f64::consts::PI + 2.0 * a0) * k as f64 / segments as f64;
            [r * t.cos(), r * t.sin()]
        })
        .collect();
    prism(&arc, 0.0, len);
    for x in [-1.27, 0.0, 1.27] {
        prism(
            &[[x - 0.225, -0.4], [x + 0.225, -0.4], [x + 0.225, 0.0], [x - 0.225, 0.0]],
            -12.7,
            0.05,
        );
    }
    let mut s = String::new();
    for p in &v {
        s.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for t in &f {
        s.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    s
}

/// `binpick part` drops parts one at a time and counts where they rest against the poses it
/// predicts from the file's hull. A box rests in them; a TO-92 whose arc is in 40 pieces does
/// not: its body's hull has 82 vertices, the physics' collider keeps 64 (a piece's most), so its
/// arc loses facets and the body rests on others than the file's, most of its drops in no
/// predicted pose, and the text says what that means (docs/model.md: a tessellated round side).
/// (In 24 pieces, 50 vertices, the collider is the file's hull, and the drops rest in its
/// likeliest poses.)
#[test]
fn the_part_command_checks_its_predicted_poses_against_drops() {
    let tmp = tempdir().unwrap();
    std::fs::write(tmp.path().join("box.obj"), box_obj(&[])).unwrap();
    std::fs::write(tmp.path().join("to92.obj"), d_prism_obj(2.4, 1.3, 40, 4.8)).unwrap();
    std::fs::write(tmp.path().join("to92-24.obj"), d_prism_obj(2.4, 1.3, 24, 4.8)).unwrap();
    let part = |name: &str, json: bool| {
        let toml = workpiece(tmp.path(), name, &format!("{name}.obj"), "");
        let svg = tmp.path().join(format!("{name}.svg"));
        let mut args = vec![
            "part",
            toml.to_str().unwrap(),
            "--piles",
            "0",
            "--svg",
            svg.to_str().unwrap(),
        ];
        if json {
            args.push("--json");
        }
        let o = binpick(&args);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        stdout(&o)
    };
    let in_none = |name: &str| {
        let j: serde_json::Value = serde_json::from_str(&part(name, true)).unwrap();
        let drops = &j["drops"];
        let dropped = drops["dropped"].as_u64().unwrap() as f64;
        assert_eq!(dropped, 60.0, "{drops}");
        // The shares per pose and in none add up to every drop.
        let per_pose: f64 = j["poses"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p["dropped_share"].as_f64().unwrap())
            .sum();
        let none = drops["in_no_predicted_pose"].as_u64().unwrap() as f64 / dropped;
        assert!((per_pose + none - 1.0).abs() < 1e-5, "{j}");
        none
    };
    let boxed = in_none("box");
    assert!(boxed <= 0.05, "box: {boxed}");
    // C's 150 x 10 x 5 mm strip rests on its 5 mm sides in a fifth of the drops, which the model
    // predicts since a pose's tip is measured against its own radius (before: 22 % in none).
    let o = binpick(&["part", "C", "--piles", "0", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let c: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(
        c["drops"]["in_no_predicted_pose"].as_u64().unwrap() <= 3,
        "{}",
        c["drops"]
    );
    let d = in_none("to92");
    assert!(d >= 0.5, "to92: {d}");
    // Its arc in 24 pieces, the collider is the file's hull: the likeliest poses (on the round
    // back rolled 5.1 deg either way, 64.6 % together, 0.19 mm of margin) take a third of the
    // drops or more (45 %; a collider of 32 vertices a piece, every other facet, rests none
    // there).
    let j: serde_json::Value = serde_json::from_str(&part("to92-24", true)).unwrap();
    let on_back: f64 = j["poses"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["down_normal"][1].as_f64().unwrap() > 0.99)
        .map(|p| p["dropped_share"].as_f64().unwrap())
        .sum();
    assert!(on_back >= 0.33, "{j}");
    let text = part("to92", false);
    assert!(text.contains("the physics' collider rests otherwise"), "{text}");
    assert!(!part("box", false).contains("rests otherwise"));
}

/// A user's part in `dir`: its OBJ text written as `NAME.obj` and a workpiece file naming it with
/// its own cup of `cup_m` (a 0.3 mm face margin) and `shape_extra` (lines under `[shape]`);
/// returns the workpiece file and what `binpick check` said of it (asserted to pass).
fn user_part(dir: &Path, name: &str, obj: &str, cup_m: f64, shape_extra: &str) -> (PathBuf, std::process::Output) {
    std::fs::write(dir.join(format!("{name}.obj")), obj).unwrap();
    let toml = workpiece(dir, name, &format!("{name}.obj"), "");
    let text = std::fs::read_to_string(&toml)
        .unwrap()
        .replace(
            "face_margin_m = 0.0005",
            &format!("face_margin_m = 0.0003\n\n[gripper]\ncup_diameter_m = {cup_m}"),
        )
        .replace("units = \"mm\"", &format!("units = \"mm\"\n{shape_extra}"));
    std::fs::write(&toml, text).unwrap();
    let check = binpick_in(dir, &["check", toml.to_str().unwrap()]);
    assert!(check.status.success(), "{}", stderr(&check));
    (toml, check)
}

/// `binpick part TOML --json` with `piles` simulated piles and no drops.
fn part_json(dir: &Path, toml: &Path, piles: u32) -> serde_json::Value {
    let svg = toml.with_extension("svg");
    let piles = piles.to_string();
    let o = binpick_in(
        dir,
        &[
            "part",
            toml.to_str().unwrap(),
            "--json",
            "--piles",
            &piles,
            "--drops",
            "0",
            "--svg",
            svg.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_str(&stdout(&o)).unwrap()
}

/// A prism (mm) as OBJ text: the polygon `ring` (counter-clockwise, x y) from `z0` up to `z1`,
/// its vertices numbered from 1.
fn prism_obj(ring: &[(f64, f64)], z0: f64, z1: f64) -> String {
    let n = ring.len();
    let mut s = String::new();
    for z in [z0, z1] {
        for (x, y) in ring {
            s += &format!("v {x:.6} {y:.6} {z}\n");
        }
    }
    for i in 1..n - 1 {
        s += &format!("f 1 {} {}\n", i + 2, i + 1);
        s += &format!("f {} {} {}\n", n + 1, n + i + 1, n + i + 2);
    }
    for i in 0..n {
        let j = (i + 1) % n;
        s += &format!(
            "f {} {} {}\nf {} {} {}\n",
            i + 1,
            j + 1,
            n + j + 1,
            i + 1,
            n + j + 1,
            n + i + 1
        );
    }
    s
}

/// A disc (mm) as OBJ text: a regular prism of `sides` sides, 14 mm across its corners and 6 mm
/// thick.
fn disc_obj(sides: usize) -> String {
    let ring: Vec<(f64, f64)> = (0..sides)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / sides as f64;
            (7.0 * a.cos(), 7.0 * a.sin())
        })
        .collect();
    prism_obj(&ring, -3.0, 3.0)
}

/// A pile of 60 discs 14 mm across and 6 mm thick, 64-sided, does not come to rest within the
/// pour's 10 s (seed 1: a disc rolls on its rim on the pile's top, which the physics, with no
/// rolling resistance, keeps up), and `part` says so. Control: a pile of hexagonal prisms of the
/// same size settles, and is not flagged.
#[test]
fn part_says_when_its_piles_do_not_come_to_rest() {
    let dir = tempdir().unwrap();
    for sides in [64, 6] {
        let (toml, _) = user_part(dir.path(), &format!("disc{sides}"), &disc_obj(sides), 0.006, "");
        let text = std::fs::read_to_string(&toml)
            .unwrap()
            .replace("pile_count = 10", "pile_count = 60")
            .replace("mass_kg = 0.002", "mass_kg = 0.0065");
        std::fs::write(&toml, text).unwrap();
        let v = part_json(dir.path(), &toml, 1);
        let expected = u64::from(sides == 64);
        assert_eq!(
            v["pile"]["unsettled_piles"].as_u64(),
            Some(expected),
            "{sides} sides: {}",
            v["pile"]
        );
    }
}

/// A flat washer (mm) as OBJ text: 16 mm across, an 8.4 mm bore, `thick` mm thick, 72 sides.
fn washer_obj(thick: f64) -> String {
    let n = 72;
    let mut s = String::new();
    for (r, z) in [(8.0, 0.0), (8.0, thick), (4.2, 0.0), (4.2, thick)] {
        for k in 0..n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            s += &format!("v {:.6} {:.6} {z}\n", r * a.cos(), r * a.sin());
        }
    }
    let (o0, o1, i0, i1) = (1, 1 + n, 1 + 2 * n, 1 + 3 * n);
    for k in 0..n {
        let j = (k + 1) % n;
        for [a, b, c] in [
            [o0 + k, o0 + j, o1 + j],
            [o0 + k, o1 + j, o1 + k],
            [i0 + k, i1 + j, i0 + j],
            [i0 + k, i1 + k, i1 + j],
            [o1 + k, o1 + j, i1 + j],
            [o1 + k, i1 + j, i1 + k],
            [o0 + k, i0 + j, o0 + j],
            [o0 + k, i0 + k, i0 + j],
        ] {
            s += &format!("f {a} {b} {c}\n");
        }
    }
    s
}

/// A user's M8 washer (a face with a round bore, the same either side up) is recognised in the
/// piles `binpick part` pours and placed by the cell (3 of 5 picks or more, nothing hit or
/// lost), and `check` says nothing against it; a washer 1 mm thick, which
/// lies inside the band the sensor takes for the tray floor, is warned about by `check` and
/// `part`, and is seldom found (the negative control).
#[test]
fn a_washer_is_recognised_and_one_too_flat_to_see_is_warned_about() {
    let dir = tempdir().unwrap();
    let mut recall = Vec::new();
    for (name, thick) in [("washer", 1.6), ("thin-washer", 1.0)] {
        let (toml, check) = user_part(dir.path(), name, &washer_obj(thick), 0.003, "");
        let v = part_json(dir.path(), &toml, 2);
        let warnings = v["warnings"].as_array().unwrap().clone();
        recall.push(v["pile"]["recognition"]["recall"].as_f64().unwrap());
        if thick > 1.5 {
            assert!(!stderr(&check).contains("warning"), "{}", stderr(&check));
            assert!(warnings.is_empty(), "{warnings:?}");
            // In the cell: picked by its ring and set down, nothing hit or lost.
            let out = dir.path().join("runs");
            let run = binpick_in(
                dir.path(),
                &[
                    "run",
                    "--workpiece",
                    toml.to_str().unwrap(),
                    "--picks",
                    "5",
                    "--deterministic",
                    "--no-rrd",
                    "--no-mcap",
                    "--json",
                    "--out",
                    out.to_str().unwrap(),
                ],
            );
            assert!(run.status.success(), "{}", stderr(&run));
            let s: serde_json::Value = serde_json::from_str(&stdout(&run)).unwrap();
            let s = &s["summary"];
            assert!(s["placed"].as_u64().unwrap() >= 3, "{s}");
            assert_eq!(
                (&s["collisions"], &s["parts_lost"]),
                (&serde_json::json!(0), &serde_json::json!(0)),
                "{s}"
            );
        } else {
            assert!(
                stderr(&check).contains("thin-washer.toml: in ") && stderr(&check).contains("stands 1.00 mm high"),
                "{}",
                stderr(&check)
            );
            assert_eq!(warnings.len(), 1, "{warnings:?}");
        }
    }
    assert!(recall[0] > 0.6 && recall[1] < 0.3, "recall {recall:?}");
}

/// An HC-49/S crystal (mm) as OBJ text: a stadium body 11.05 x 4.65 x 3.5 mm, 16 segments a
/// round end, and, with `leads`, two 0.43 mm leads 13 mm long out of its bottom, 4.88 mm apart.
fn crystal_obj(leads: bool) -> String {
    let (r, c, h) = (2.325, 11.05 / 2.0 - 2.325, 3.5);
    let mut ring = Vec::new();
    for (cx, a0) in [(c, -std::f64::consts::FRAC_PI_2), (-c, std::f64::consts::FRAC_PI_2)] {
        for k in 0..=16 {
            let a = a0 + std::f64::consts::PI * k as f64 / 16.0;
            ring.push((cx + r * a.cos(), r * a.sin()));
        }
    }
    let n = ring.len();
    let mut s = prism_obj(&ring, 0.0, h);
    if leads {
        for (i, x) in [-2.44, 2.44].into_iter().enumerate() {
            let base = 2 * n + 8 * i;
            for k in 0..8 {
                let (dx, dy, z) = (
                    if k & 1 == 0 { -0.215 } else { 0.215 },
                    if k & 2 == 0 { -0.215 } else { 0.215 },
                    if k & 4 == 0 { -13.0 } else { 0.0 },
                );
                s += &format!("v {:.6} {dy} {z}\n", x + dx);
            }
            for t in crate::support::BOX_TRIANGLES {
                s += &format!("f {} {} {}\n", base + t[0] + 1, base + t[1] + 1, base + t[2] + 1);
            }
        }
    }
    s
}

/// A crystal whose only face the cup takes is its top, which no resting pose has up (it lies
/// on its side, or on its top with its leads in the air, its bottom's cup sites blocked by
/// them): `check` warns that nothing will be picked (a part held by its top could not be set
/// down as held, so the selector offers it not even propped up on others), and `part` says no pose and no
/// pile part offers a face. Negative control: the same body without leads offers its bottom,
/// and nothing is warned.
#[test]
fn a_part_with_no_cup_face_up_in_any_pose_is_warned_about() {
    let dir = tempdir().unwrap();
    for leads in [true, false] {
        let name = if leads { "crystal" } else { "crystal-no-leads" };
        let (toml, check) = user_part(dir.path(), name, &crystal_obj(leads), 0.003, "");
        let v = part_json(dir.path(), &toml, 1);
        let share = v["graspable_share"].as_f64().unwrap();
        let offered = v["pile"]["parts_offering_a_cup_face"].as_u64().unwrap();
        // The message as one line (the terminal wraps it at 110 columns).
        let message = stderr(&check).split_whitespace().collect::<Vec<_>>().join(" ");
        let warned =
            message.contains("in none of its resting poses does a face") && message.contains("nothing will be picked");
        if leads {
            assert!(warned, "{}", stderr(&check));
            assert_eq!((share, offered), (0.0, 0), "{}", v["pile"]);
            assert_eq!(v["warnings"].as_array().unwrap().len(), 1, "{}", v["warnings"]);
            // The faces the cup reaches (the top) are the ones no pose sets down as held.
            let sited: Vec<_> = v["faces"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|f| !f["cup_fit"]["cup_site_mm"].is_null())
                .collect();
            assert!(
                !sited.is_empty() && sited.iter().all(|f| f["cup_fit"]["placeable"] == false),
                "{}",
                v["faces"]
            );
        } else {
            assert!(!warned, "{}", stderr(&check));
            assert!(share > 0.1 && offered > 0, "{share} {}", v["pile"]);
        }
    }
}

/// An M4 hex bolt (mm) as OBJ text: a hex head 7 mm across its flats and 2.8 mm high, and a
/// round shank 4 mm across (24 sides) and `shank_mm` long under it (a second body, 0.5 mm into
/// the head); none for 0.
fn bolt_obj(shank_mm: f64) -> String {
    let mut s = String::new();
    let mut n = 0;
    let mut prism = |s: &mut String, outline: &[[f64; 2]], z0: f64, z1: f64| {
        let k = outline.len();
        for z in [z0, z1] {
            for p in outline {
                *s += &format!("v {} {} {z}\n", p[0], p[1]);
            }
        }
        let v = |i: usize| n + i + 1;
        for i in 1..k - 1 {
            *s += &format!("f {} {} {}\n", v(0), v(i + 1), v(i));
            *s += &format!("f {} {} {}\n", v(k), v(k + i), v(k + i + 1));
        }
        for i in 0..k {
            let j = (i + 1) % k;
            *s += &format!(
                "f {} {} {}\nf {} {} {}\n",
                v(i),
                v(j),
                v(k + j),
                v(i),
                v(k + j),
                v(k + i)
            );
        }
        n += 2 * k;
    };
    let ring = |sides: usize, r: f64, phase: f64| -> Vec<[f64; 2]> {
        (0..sides)
            .map(|i| {
                let a = phase + std::f64::consts::TAU * i as f64 / sides as f64;
                [r * a.cos(), r * a.sin()]
            })
            .collect()
    };
    let across_corners = 3.5 / (std::f64::consts::PI / 6.0).cos();
    prism(&mut s, &ring(6, across_corners, std::f64::consts::PI / 6.0), 0.0, 2.8);
    if shank_mm > 0.0 {
        prism(&mut s, &ring(24, 2.0, 0.0), -shank_mm, 0.5);
    }
    s
}

/// A bolt stands on its head, the one face its 4 mm cup takes up, in under 1 % of its resting
/// poses: `check` warns that the cup face is seldom up. Negative control: its head alone (a hex
/// prism) lies on a flat as often as not, and nothing is warned.
#[test]
fn a_part_seldom_with_a_cup_face_up_is_warned_about() {
    let dir = tempdir().unwrap();
    for shank_mm in [16.0, 0.0] {
        let name = if shank_mm > 0.0 { "bolt" } else { "bolt-head" };
        let (toml, check) = user_part(dir.path(), name, &bolt_obj(shank_mm), 0.004, "");
        let v = part_json(dir.path(), &toml, 0);
        let share = v["graspable_share"].as_f64().unwrap();
        let warned = stderr(&check).contains("in only");
        if shank_mm > 0.0 {
            assert!(warned, "{}", stderr(&check));
            assert!(share > 0.0 && share < 0.05, "{share}");
        } else {
            assert!(!warned, "{}", stderr(&check));
            assert!(share > 0.3, "{share}");
        }
    }
}

/// A bolt lying on its round shank shows its turn about its axis only at its hex head: the
/// recogniser does not report a turn its image does not decide (before, 17 of 20 detections on
/// this pile were 8-30 deg off about the axis; now 4 of 4, from other paths). Negative control:
/// declared round about its axis, the turn does not matter, and a quarter of the top layer or
/// more is found, every detection right.
#[test]
fn a_lying_part_whose_turn_about_its_axis_is_not_seen_is_not_reported() {
    let dir = tempdir().unwrap();
    for round in [false, true] {
        let name = if round { "bolt-round" } else { "bolt" };
        let extra = if round { "symmetry_orders = [1, 1, 64]" } else { "" };
        let (toml, _) = user_part(dir.path(), name, &bolt_obj(16.0), 0.004, extra);
        let text = std::fs::read_to_string(&toml).unwrap();
        std::fs::write(&toml, text.replace("pile_count = 10", "pile_count = 40")).unwrap();
        let r = part_json(dir.path(), &toml, 1)["pile"]["recognition"].clone();
        let (correct, detected) = (r["correct"].as_u64().unwrap(), r["detected"].as_u64().unwrap());
        if round {
            assert!(correct >= 10 && correct == detected, "{r}");
        } else {
            assert!(detected - correct <= 5, "{r}");
        }
    }
}

/// An IC body (mm) as OBJ text: a 9.3 x 6.35 x 3.3 mm block and, on its top near a corner, a
/// 1 x 1 mm pin-1 mark 0.1 mm high (a second body).
fn marked_ic_obj() -> String {
    let mut s = String::new();
    for (n, (lo, hi)) in [
        ([-4.65, -3.175, 0.0], [4.65, 3.175, 3.3]),
        ([-3.9, 1.7, 3.3], [-2.9, 2.7, 3.4]),
    ]
    .into_iter()
    .enumerate()
    {
        for i in 0..8 {
            let c = |a: usize| if i >> a & 1 == 0 { lo[a] } else { hi[a] };
            s += &format!("v {} {} {}\n", c(0), c(1), c(2));
        }
        for t in crate::support::BOX_TRIANGLES {
            s += &format!("f {} {} {}\n", 8 * n + t[0] + 1, 8 * n + t[1] + 1, 8 * n + t[2] + 1);
        }
    }
    s
}

/// A pin-1 mark 0.1 mm high leaves an IC without a half turn that maps its mesh onto itself,
/// but no depth image tells the turns apart: `check` warns and names the orders to declare,
/// and `part` finds few of a pile. Declared (the control), nothing is warned and most are found.
#[test]
fn turns_the_sensor_cannot_tell_apart_are_warned_about() {
    let dir = tempdir().unwrap();
    let mut recall = Vec::new();
    for declared in [false, true] {
        let name = if declared { "ic-declared" } else { "ic" };
        let declare = if declared { "symmetry_orders = [2, 2, 2]" } else { "" };
        let (toml, check) = user_part(dir.path(), name, &marked_ic_obj(), 0.004, declare);
        let warned = stderr(&check).contains("the sensor cannot tell those turns apart");
        assert_eq!(warned, !declared, "{}", stderr(&check));
        if !declared {
            assert!(
                stderr(&check).contains("`shape.symmetry_orders = [2, 2, 2]`"),
                "{}",
                stderr(&check)
            );
        }
        let v = part_json(dir.path(), &toml, 1);
        recall.push(v["pile"]["recognition"]["recall"].as_f64().unwrap());
        // The turns, listed for tools: the half turns about x, y and z, undeclared only.
        let turns = v["look_alike_turns"].as_array().unwrap();
        assert_eq!(turns.len(), if declared { 0 } else { 3 }, "{turns:?}");
    }
    assert!(recall[0] < 0.3 && recall[1] > 0.7, "recall {recall:?}");
}
