//! A workpiece's own scan mode (`[sensor]` in its file): the cell's sensor at another resolution
//! over the same field of view reaches what a run of that workpiece captures, and only that
//! workpiece's; its key is checked naming file, key and value; a sweep of the cell's key it sets
//! is refused.

use crate::support::{Workspace, batch_is_refused, binpick_in, cell_sweep_is_refused, stderr};

/// E with `section` before its `[grasp]`, as `workpieces/{name}.toml`.
fn e_with(ws: &Workspace, name: &str, section: &str) -> std::path::PathBuf {
    ws.edit(
        "workpieces/E.toml",
        &format!("workpieces/{name}.toml"),
        "[grasp]",
        &format!("{section}\n[grasp]"),
    )
}

/// What `sense` (seed 1) of `workpiece` printed: the capture's size and the count of parts
/// recognised.
fn sensed(ws: &Workspace, workpiece: &str) -> ([u64; 2], u64) {
    let out = ws.path("sensed");
    let o = binpick_in(
        ws.dir.path(),
        &[
            "sense",
            "--workpiece",
            workpiece,
            "--seed",
            "1",
            "--json",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let c = &j["capture"];
    let size = [c["width_px"].as_u64().unwrap(), c["height_px"].as_u64().unwrap()];
    (size, j["recognition"]["detected"].as_u64().unwrap())
}

/// E's captures are the cell's 1032 x 772 pixels; with `[sensor] resolution_px = [2064, 1544]`
/// in its file, twice that each way over the same tray (its parts are still recognised, so the
/// focal lengths and principal point scaled with the image: a sensor whose field of view shrank
/// to a quarter would show a quarter of the tray). The control: plain E, the cell's size. Its
/// own `depth_noise_at_1m_m` reaches the capture too: at twice the cell's 0.3 mm the
/// recognition, whose tolerances are set for the cell's noise, finds less than half as many
/// parts (docs/formats.md).
#[test]
fn a_workpiece_brings_its_own_scan_mode() {
    let ws = Workspace::new();
    let (plain, plain_found) = sensed(&ws, "E");
    assert_eq!(plain, [1032, 772]);
    let fine = e_with(&ws, "fine", "[sensor]\nresolution_px = [2064, 1544]\n");
    let (size, found) = sensed(&ws, fine.to_str().unwrap());
    assert_eq!(size, [2064, 1544]);
    assert!(
        found as f64 >= 0.8 * plain_found as f64,
        "{found} parts recognised at 2064 x 1544, {plain_found} at 1032 x 772"
    );
    let noisy = e_with(&ws, "noisy", "[sensor]\ndepth_noise_at_1m_m = 0.0006\n");
    let (size, found) = sensed(&ws, noisy.to_str().unwrap());
    assert_eq!(size, [1032, 772]);
    assert!(
        (found as f64) < 0.5 * plain_found as f64,
        "{found} parts recognised at 0.6 mm of depth noise, {plain_found} at 0.3 mm"
    );
}

/// A bad scan mode exits 2 naming the file, the key and the value, writing nothing: a height
/// that does not scale with the width (another field of view), a key the section does not have,
/// and more pixels than a capture may hold (checked on the cell resolved for the workpiece). A
/// sweep of the cell's resolution over a workpiece that brings its own is refused: it would vary
/// nothing for it.
#[test]
fn a_bad_scan_mode_exits_2_naming_file_key_and_value() {
    let ws = Workspace::new();
    for (section, why) in [
        (
            "resolution_px = [2064, 1500]\n",
            "sensor.resolution_px must scale the cell's 1032 x 772 image alike along both axes",
        ),
        ("binning = 2\n", "binning"),
        (
            "depth_noise_at_1m_m = -0.001\n",
            "sensor.depth_noise_at_1m_m must be >= 0, got -0.001",
        ),
        (
            "resolution_px = [4128, 3088]\n",
            "got [4128, 3088] (with this workpiece's sensor)",
        ),
    ] {
        let bad = e_with(&ws, "bad", &format!("[sensor]\n{section}"));
        batch_is_refused(&ws, &["--workpieces", bad.to_str().unwrap()], why);
    }
    let bad = e_with(&ws, "bad", "[sensor]\nresolution_px = [2064, 1544]\n");
    cell_sweep_is_refused(&ws, "sensor.resolution_px=[1032,772],[516,386]", &bad);
}
