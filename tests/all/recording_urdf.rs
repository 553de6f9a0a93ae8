//! The MCAP's robot description: `binpick run` writes the URDF the arm was built from on
//! `/robot_description` (the JSON form of `std_msgs/String`, where Foxglove's 3D panel reads a
//! URDF), and `/tf` carries the URDF's tree (world -> root link, then parent link -> child link
//! per joint), so the URDF's visuals drawn on those frames follow the arm. Read back with the
//! mcap crate; the URDF parsed with urdf-rs; every joint transform recomputed here from the
//! URDF's joint origin and axis and the recorded joint position, and compared with `/tf`.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::recording::McapDecoder;
use crate::support::{Workspace, binpick_in, stderr};

/// A `/tf` transform: (parent, child) -> parent_from_child.
type Tf = BTreeMap<(String, String), Isometry3<f64>>;

fn iso(t: &serde_json::Value) -> Isometry3<f64> {
    let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or(0.0);
    let (p, r) = (&t["translation"], &t["rotation"]);
    Isometry3::from_parts(
        Translation3::new(f(p, "x"), f(p, "y"), f(p, "z")),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(f(r, "w"), f(r, "x"), f(r, "y"), f(r, "z"))),
    )
}

/// Checks the robot description of the MCAP `bytes` (its URDF passed through `doctor` first, the
/// negative control's way in) against its `/tf` and `/robot/joint_states`: returns how many
/// joint transforms were compared, or what is wrong.
fn check_robot_description(bytes: &[u8], doctor: impl Fn(String) -> String) -> Result<usize, String> {
    let mut decoder = McapDecoder::default();
    let mut urdf_text = None;
    let mut tfs: BTreeMap<u64, Tf> = BTreeMap::new();
    let mut joints: BTreeMap<u64, BTreeMap<String, f64>> = BTreeMap::new();
    for m in mcap::MessageStream::new(bytes).map_err(|e| e.to_string())? {
        let m = m.map_err(|e| e.to_string())?;
        let topic = m.channel.topic.as_str();
        if !["/robot_description", "/tf", "/robot/joint_states"].contains(&topic) {
            continue;
        }
        let v = decoder.decode(&m)?;
        match topic {
            "/robot_description" => {
                let schema = m.channel.schema.as_ref().ok_or("no schema")?;
                if schema.name != "std_msgs/String" {
                    return Err(format!("/robot_description has schema {}", schema.name));
                }
                urdf_text = Some(v["data"].as_str().ok_or("no data string")?.to_string());
            }
            "/tf" => {
                let tf = tfs.entry(m.log_time).or_default();
                for t in v["transforms"].as_array().ok_or("no transforms")? {
                    let key = (
                        t["parent_frame_id"].as_str().unwrap_or("").to_string(),
                        t["child_frame_id"].as_str().unwrap_or("").to_string(),
                    );
                    tf.insert(key, iso(t));
                }
            }
            _ => {
                let js = joints.entry(m.log_time).or_default();
                for j in v["joints"].as_array().ok_or("no joints")? {
                    js.insert(
                        j["name"].as_str().unwrap_or("").to_string(),
                        j["position"].as_f64().ok_or("no position")?,
                    );
                }
            }
        }
    }
    let text = doctor(urdf_text.ok_or("no /robot_description message")?);
    let robot = urdf_rs::read_from_string(&text).map_err(|e| format!("the URDF does not parse: {e}"))?;
    // The root link: the one no joint has as its child.
    let children: Vec<&str> = robot.joints.iter().map(|j| j.child.link.as_str()).collect();
    let roots: Vec<&str> = robot
        .links
        .iter()
        .map(|l| l.name.as_str())
        .filter(|l| !children.contains(l))
        .collect();
    let [root] = roots[..] else {
        return Err(format!("roots {roots:?}"));
    };
    let mut compared = 0;
    for (t, tf) in &tfs {
        if !tf.contains_key(&("world".to_string(), root.to_string())) {
            return Err(format!("no world -> {root} at {t} ns"));
        }
        let Some(q) = joints.get(t) else { continue };
        for j in &robot.joints {
            let key = (j.parent.link.clone(), j.child.link.clone());
            let got = tf
                .get(&key)
                .ok_or_else(|| format!("no /tf {} -> {} at {t} ns", key.0, key.1))?;
            let origin = Isometry3::from_parts(
                Translation3::new(j.origin.xyz[0], j.origin.xyz[1], j.origin.xyz[2]),
                UnitQuaternion::from_euler_angles(j.origin.rpy[0], j.origin.rpy[1], j.origin.rpy[2]),
            );
            let position = *q.get(&j.name).ok_or_else(|| format!("no joint state for {}", j.name))?;
            let axis = Unit::new_normalize(Vector3::new(j.axis.xyz[0], j.axis.xyz[1], j.axis.xyz[2]));
            let want = origin * UnitQuaternion::from_axis_angle(&axis, position);
            let (dp, dr) = (
                (got.translation.vector - want.translation.vector).norm(),
                got.rotation.angle_to(&want.rotation),
            );
            if dp > 1e-6 || dr > 1e-6 {
                return Err(format!(
                    "{} at {t} ns: /tf is {dp:.2e} m, {dr:.2e} rad from the URDF's joint at {position:.4} rad",
                    j.name
                ));
            }
            compared += 1;
        }
    }
    Ok(compared)
}

/// The same MCAP without one topic (the negative control's file), copied with the mcap crate.
fn without_topic(bytes: &[u8], topic: &str) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let mut w = mcap::Writer::new(&mut out).unwrap();
        for m in mcap::MessageStream::new(bytes).unwrap() {
            let m = m.unwrap();
            if m.channel.topic != topic {
                w.write(&m).unwrap();
            }
        }
        w.finish().unwrap();
    }
    out.into_inner()
}

#[test]
fn mcap_carries_the_urdf_and_its_tree_moves_with_the_joint_states() {
    let ws = Workspace::new();
    let out = ws.path("out");
    let args = [
        "run",
        "--workpiece",
        "E",
        "--picks",
        "2",
        "--deterministic",
        "--no-rrd",
        "--out",
        out.to_str().unwrap(),
    ];
    let o = binpick_in(ws.dir.path(), &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(out.join("run-E-seed1-det/run.mcap")).unwrap();
    let compared = check_robot_description(&bytes, |t| t).unwrap();
    // Six joints at every /tf sample that has joint states at its time: many samples.
    assert!(compared >= 6 * 50, "{compared} joint transforms compared");
    // The URDF recorded is the one the cell loads (the repository's).
    let repo_urdf = std::fs::read_to_string(crate::support::repo().join("scenes/viper_s650.urdf")).unwrap();
    let mut decoder = McapDecoder::default();
    let recorded = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .find(|m| m.channel.topic == "/robot_description")
        .map(|m| decoder.decode(&m).unwrap()["data"].as_str().unwrap().to_string())
        .unwrap();
    assert_eq!(recorded, repo_urdf);

    // Negative controls: a joint origin moved by 1 cm no longer matches /tf; a file without the
    // topic has no robot description.
    let shifted = check_robot_description(&bytes, shift_joint_3);
    assert!(
        shifted.as_ref().is_err_and(|e| e.contains("joint_3")),
        "a moved joint must be caught: {shifted:?}"
    );
    let stripped = check_robot_description(&without_topic(&bytes, "/robot_description"), |t| t);
    assert!(
        stripped.as_ref().is_err_and(|e| e.contains("no /robot_description")),
        "{stripped:?}"
    );
}

/// The URDF with joint_3's origin 1 cm further along x.
fn shift_joint_3(text: String) -> String {
    let start = text.find(r#"<joint name="joint_3""#).expect("joint_3 in the URDF");
    let at = start + text[start..].find("<origin xyz=\"").expect("joint_3's origin") + "<origin xyz=\"".len();
    let end = at + text[at..].find('"').unwrap();
    let mut xyz: Vec<f64> = text[at..end].split_whitespace().map(|v| v.parse().unwrap()).collect();
    xyz[0] += 0.01;
    format!("{}{} {} {}{}", &text[..at], xyz[0], xyz[1], xyz[2], &text[end..])
}
