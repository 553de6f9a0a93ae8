//! `binpick sense`: the run folder's depth image, point cloud and report.

use crate::support::{Workspace, binpick_in, stderr, stdout};

#[test]
fn sense_writes_depth_png_cloud_ply_and_a_report() {
    let ws = Workspace::new();
    let out = ws.path("out");
    // `sense` of B, seed 2, with `extra` arguments: its standard output.
    let sense = |extra: &[&str]| {
        let mut args = vec![
            "sense",
            "--workpiece",
            "B",
            "--seed",
            "2",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = binpick_in(ws.dir.path(), &args);
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let json = sense(&["--json"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(v["recognition"]["recall"].as_f64().unwrap() >= 0.9, "{v}");
    assert!(v["recognition"]["precision"].as_f64().unwrap() >= 0.99, "{v}");
    assert!(v["grasp"]["chosen"].is_object(), "no grasp chosen: {v}");
    let dir = out.join("sense-B-seed2");
    // 16-bit PNG in millimetres: the tray floor is about 1000 mm from the camera.
    let buf = read_png(&dir.join("depth.png"), png::BitDepth::Sixteen);
    let centre = (386 * 1032 + 516) * 2;
    let mm = u16::from_be_bytes([buf[centre], buf[centre + 1]]);
    assert!((950..=1001).contains(&mm), "depth at the image centre {mm} mm");
    // The same for the eye: 8-bit, the same size, the pile's tops bright over a darker floor.
    let grey = read_png(&dir.join("depth-view.png"), png::BitDepth::Eight);
    let shades = |lo: u8, hi: u8| grey.iter().filter(|g| (lo..=hi).contains(*g)).count();
    assert!(
        shades(200, 255) > 1000 && shades(49, 160) > 10_000,
        "{} {}",
        shades(200, 255),
        shades(49, 160)
    );
    // PLY header and size agree.
    let ply = std::fs::read(dir.join("cloud.ply")).unwrap();
    let header_end = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = String::from_utf8_lossy(&ply[..header_end]);
    let n: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(ply.len() - header_end, n * 12);
    assert_eq!(n as u64, v["capture"]["valid_px"].as_u64().unwrap());
    assert!(dir.join("sense.json").is_file() && dir.join("scene.toml").is_file());
    // The text a user reads fits a terminal (its recognition and grasp rows ran to 127 columns).
    let text = sense(&[]);
    let longest = text.lines().map(|l| l.chars().count()).max().unwrap();
    assert!(
        longest <= 110 && text.contains("recognition") && text.contains("chosen grasp"),
        "a line of {longest} characters:\n{text}"
    );
}

/// The pixels of the PNG at `path`, checked to be the default sensor's 1032 x 772 at `depth`.
fn read_png(path: &std::path::Path, depth: png::BitDepth) -> Vec<u8> {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let info = reader.info().clone();
    assert_eq!(
        (info.width, info.height, info.bit_depth),
        (1032, 772, depth),
        "{path:?}"
    );
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    reader.next_frame(&mut buf).unwrap();
    buf
}

#[test]
fn sense_rejects_bad_input_before_writing() {
    let ws = Workspace::new();
    let out = ws.path("out");
    ws.edit(
        "workpieces/E.toml",
        "workpieces/tiny.toml",
        "size_m = [0.010, 0.005, 0.010]",
        "size_m = [0.004, 0.005, 0.004]",
    );
    let o = binpick_in(
        ws.dir.path(),
        &[
            "sense",
            "--workpiece",
            "workpieces/tiny.toml",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("no face the suction cup fits on"));
    assert!(!out.exists());
}
