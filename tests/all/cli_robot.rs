//! The robot commands on the embedded default cell, read back as JSON.

use crate::support::{binpick, stdout};

fn json(args: &[&str]) -> serde_json::Value {
    let out = binpick(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&stdout(&out)).expect("valid JSON")
}

#[test]
fn shipped_files_are_valid() {
    let out = binpick(&[
        "check",
        "scenes/default.toml",
        "scenes/viper_s650.urdf",
        "workpieces/A.toml",
        "workpieces/B.toml",
        "workpieces/C.toml",
        "workpieces/D.toml",
        "workpieces/E.toml",
        "workpieces/F.toml",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(stdout(&out).lines().filter(|l| l.starts_with("ok: ")).count(), 8);
}

#[test]
fn info_lists_six_joints_and_28_kg() {
    let v = json(&["robot", "info", "--json"]);
    assert_eq!(v["joints"].as_array().unwrap().len(), 6);
    assert_eq!(v["joints"][5]["torque_limit_nm"], 10.0);
    let base = v["links"][0]["mass_kg"].as_f64().unwrap();
    let total = v["moving_mass_kg"].as_f64().unwrap() + base;
    assert!((total - 28.0).abs() < 0.01, "arm mass {total}");
    // What binds the planned accelerations: the default cell lets the torque alone bind; a cell
    // that caps them at the specification says so.
    assert_eq!(v["accel_cap"], "none");
    let ws = crate::support::Workspace::new();
    let capped = ws.edit(
        "scenes/default.toml",
        "scenes/capped.toml",
        "accel_cap = \"none\"",
        "accel_cap = \"spec\"",
    );
    let v = json(&["robot", "info", "--json", "--scene", capped.to_str().unwrap()]);
    assert_eq!(v["accel_cap"], "spec");
    // The text fits a terminal, for either cap (the line that says which ran to 125 columns).
    for scene in ["scenes/default.toml", capped.to_str().unwrap()] {
        let text = stdout(&binpick(&["robot", "info", "--scene", scene]));
        let longest = text.lines().map(|l| l.chars().count()).max().unwrap();
        assert!(
            longest <= 110 && text.contains("accel_cap"),
            "{longest} columns:\n{text}"
        );
    }
}

#[test]
fn fk_ready_pose_from_the_command_line() {
    let v = json(&["robot", "fk", "--deg", "0", "-90", "180", "0", "0", "0", "--json"]);
    let xyz: Vec<f64> = v["world_from_flange"]["xyz_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(
        (xyz[0] - 0.450).abs() < 1e-4 && xyz[1].abs() < 1e-4 && (xyz[2] - 0.695).abs() < 1e-4,
        "{xyz:?}"
    );
    assert_eq!(v["within_limits"], true);
}

#[test]
fn ik_of_fk_returns_the_configuration() {
    let q = ["30", "-60", "150", "20", "70", "-40"];
    let mut args = vec!["robot", "fk", "--json", "--deg"];
    args.extend(q);
    let fk = json(&args);
    let tool = &fk["world_from_tool"];
    let xyz: Vec<String> = tool["xyz_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.to_string())
        .collect();
    let rpy: Vec<String> = tool["rpy_deg"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.to_string())
        .collect();
    let mut ik_args = vec!["robot", "ik", "--json", "--all", "--xyz"];
    ik_args.extend(xyz.iter().map(String::as_str));
    ik_args.push("--rpy-deg");
    ik_args.extend(rpy.iter().map(String::as_str));
    let ik = json(&ik_args);
    let sols = ik["solutions"].as_array().unwrap();
    assert!(sols.len() >= 2);
    let found = sols.iter().any(|s| {
        s["q_deg"]
            .as_array()
            .unwrap()
            .iter()
            .zip(q)
            .all(|(a, b)| (a.as_f64().unwrap() - b.parse::<f64>().unwrap()).abs() < 1e-3)
    });
    assert!(found, "{sols:?}");
}

#[test]
fn torque_holds_the_outstretched_arm() {
    let v = json(&[
        "robot",
        "torque",
        "--deg",
        "0",
        "0",
        "90",
        "0",
        "0",
        "0",
        "--no-gripper",
        "--json",
    ]);
    let j2 = v["joints"][1]["gravity_nm"].as_f64().unwrap();
    assert!((j2 + 32.4).abs() < 0.65, "J2 gravity {j2}");
    // Accelerating J1 hard with a heavy part exceeds J1's limit, and says so.
    let v = json(&[
        "robot",
        "torque",
        "--deg",
        "0",
        "0",
        "90",
        "0",
        "0",
        "0",
        "--acc-deg",
        "5000",
        "0",
        "0",
        "0",
        "0",
        "0",
        "--payload-kg",
        "2",
        "--json",
    ]);
    assert_eq!(v["within_limits"], false);
}
