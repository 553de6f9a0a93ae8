//! Record stage: a run written to MCAP for Foxglove (first slice of the recording issue).
//!
//! Job: from a finished run ([`RunResult`] with its servo trace and scene), write `run.mcap`: the
//! cycle's events as Foxglove `foxglove.Log` messages and as structured `binpick.CycleEvent`
//! messages, the joint states (positions, velocities, applied torques beside each joint's torque
//! limit, tracking errors) at 100 Hz, the arm's link frames as `foxglove.FrameTransforms` at
//! 50 Hz, all parts as one `foxglove.SceneUpdate` entity (a cube per part, coloured by state) at
//! 10 Hz, each capture's depth image as `foxglove.RawImage` (16UC1, mm) at its trigger time,
//! every motion's tool path as planned and as executed (`foxglove.SceneUpdate` lines), and the
//! takt of every placed pick. Messages are JSON with JSON Schemas; log time is simulation
//! time (ns); chunks are zstd-compressed; the file's metadata names the scene, workpiece, seed,
//! mode and binpick version. The writer is finished explicitly and its error reported.
//!
//! Not yet recorded (the rest of the recording issue): point clouds, camera calibration,
//! detections and grasp candidates, the arm's geometry, and the Rerun file.
//!
//! Units: s (ns as log time), rad, rad/s, N m, m. Frames: `world`, and one frame per link named
//! after it (`world` -> link transforms, from forward kinematics of the executed positions).

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use serde_json::json;

use crate::cycle::RunResult;
use crate::robot::{DOF, RobotModel};

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The MCAP writer failed.
    #[error("mcap: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A message could not be serialised.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    /// Writing the file failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// What the recording's metadata says about the run.
#[derive(Debug, Clone)]
pub struct RunInfo {
    /// Scene label (file or `embedded default`).
    pub scene: String,
    /// Workpiece name.
    pub workpiece: String,
    /// Seed.
    pub seed: u64,
    /// Deterministic compute budgets.
    pub deterministic: bool,
}

/// Joint states are written every this many servo ticks (1 kHz servo: 100 Hz).
const JOINT_STATE_EVERY: usize = 10;
/// Link frames are written every this many servo ticks (50 Hz).
const TRANSFORMS_EVERY: usize = 20;

const LOG_SCHEMA: &str = r#"{"title":"foxglove.Log","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},
"level":{"type":"integer","description":"0 UNKNOWN, 1 DEBUG, 2 INFO, 3 WARNING, 4 ERROR, 5 FATAL"},
"message":{"type":"string"},"name":{"type":"string"},"file":{"type":"string"},"line":{"type":"integer","minimum":0}}}"#;

const TRANSFORMS_SCHEMA: &str = r#"{"title":"foxglove.FrameTransforms","type":"object","properties":{
"transforms":{"type":"array","items":{"type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},
"parent_frame_id":{"type":"string"},"child_frame_id":{"type":"string"},
"translation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"rotation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}}"#;

const EVENT_SCHEMA: &str = r#"{"title":"binpick.CycleEvent","type":"object","properties":{
"t_s":{"type":"number","description":"simulation time [s]"},
"pick":{"type":["integer","null"]},"kind":{"type":"string"},"detail":{"type":"string"}}}"#;

const JOINT_SCHEMA: &str = r#"{"title":"binpick.JointState","type":"object","properties":{
"t_s":{"type":"number","description":"simulation time [s]"},
"position_rad":{"type":"array","items":{"type":"number"}},
"velocity_rad_s":{"type":"array","items":{"type":"number"}},
"torque_nm":{"type":"array","items":{"type":"number"},"description":"applied (saturated) motor torque"},
"torque_limit_nm":{"type":"array","items":{"type":"number"}},
"tracking_error_rad":{"type":"array","items":{"type":"number"}}}}"#;

const SCENE_SCHEMA: &str = r#"{"title":"foxglove.SceneUpdate","type":"object","properties":{
"deletions":{"type":"array","items":{"type":"object"}},
"entities":{"type":"array","items":{"type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},
"frame_id":{"type":"string"},"id":{"type":"string"},
"lifetime":{"type":"object","properties":{"sec":{"type":"integer"},"nsec":{"type":"integer"}}},
"frame_locked":{"type":"boolean"},
"cubes":{"type":"array","items":{"type":"object","properties":{
"pose":{"type":"object","properties":{
"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}},
"size":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"color":{"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}}}}},
"lines":{"type":"array","items":{"type":"object","properties":{
"type":{"type":"integer","description":"0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
"thickness":{"type":"number"},"scale_invariant":{"type":"boolean"},
"points":{"type":"array","items":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}}},
"color":{"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}}}}}}}}}}"#;

const IMAGE_SCHEMA: &str = r#"{"title":"foxglove.RawImage","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},
"frame_id":{"type":"string"},"width":{"type":"integer","minimum":0},"height":{"type":"integer","minimum":0},
"encoding":{"type":"string"},"step":{"type":"integer","minimum":0},
"data":{"type":"string","contentEncoding":"base64"}}}"#;

const TAKT_SCHEMA: &str = r#"{"title":"binpick.Takt","type":"object","properties":{
"t_s":{"type":"number","description":"release time [s]"},"pick":{"type":"integer"},
"takt_s":{"type":"number"},"first_of_pile":{"type":"boolean"}}}"#;

fn nanos(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

fn stamp(t_s: f64) -> serde_json::Value {
    let ns = nanos(t_s);
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

/// A `foxglove.SceneUpdate` with one entity in the world frame made of `cubes` and `lines`,
/// shown from `t_s` for `lifetime_ns` (0: until replaced).
fn scene_update(
    t_s: f64,
    id: &str,
    lifetime_ns: u64,
    cubes: Vec<serde_json::Value>,
    lines: Vec<serde_json::Value>,
) -> serde_json::Value {
    json!({
        "deletions": [],
        "entities": [{
            "timestamp": stamp(t_s), "frame_id": "world", "id": id,
            "lifetime": {"sec": lifetime_ns / 1_000_000_000, "nsec": lifetime_ns % 1_000_000_000},
            "frame_locked": false, "metadata": [],
            "arrows": [], "cubes": cubes, "spheres": [], "cylinders": [], "lines": lines,
            "triangles": [], "texts": [], "models": [],
        }],
    })
}

/// Counts of what a recording holds, per topic, for checks.
pub type TopicCounts = BTreeMap<String, u64>;

/// Writes the recording of `result` to a new file at `path` (see [`write_mcap`]).
pub fn write_mcap_file(
    path: &std::path::Path,
    result: &RunResult,
    robot: &RobotModel,
    info: &RunInfo,
) -> Result<TopicCounts, RecordError> {
    let file = std::fs::File::create(path)?;
    write_mcap(std::io::BufWriter::new(file), result, robot, info)
}

/// Writes the recording of `result` (which must have been run with `keep_trace`) to `out`.
/// Returns the message count per topic.
pub fn write_mcap<W: Write + Seek>(
    out: W,
    result: &RunResult,
    robot: &RobotModel,
    info: &RunInfo,
) -> Result<TopicCounts, RecordError> {
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile("")
        .create(out)?;
    let none = BTreeMap::new();
    let mut channel = |name: &str, topic: &str, schema: &str| -> Result<u16, RecordError> {
        let s = w.add_schema(name, "jsonschema", schema.as_bytes())?;
        Ok(w.add_channel(s, topic, "json", &none)?)
    };
    let log = channel("foxglove.Log", "/log", LOG_SCHEMA)?;
    let events = channel("binpick.CycleEvent", "/cycle/events", EVENT_SCHEMA)?;
    let joints = channel("binpick.JointState", "/robot/joint_states", JOINT_SCHEMA)?;
    let tf = channel("foxglove.FrameTransforms", "/tf", TRANSFORMS_SCHEMA)?;
    let takt = channel("binpick.Takt", "/cycle/takt", TAKT_SCHEMA)?;
    let parts = channel("foxglove.SceneUpdate", "/parts", SCENE_SCHEMA)?;
    let depth = channel("foxglove.RawImage", "/camera/depth", IMAGE_SCHEMA)?;
    let paths = channel("foxglove.SceneUpdate", "/paths", SCENE_SCHEMA)?;
    // Messages go in log-time order, one channel after another would not: merge them.
    let mut messages: Vec<(u64, u16, Vec<u8>)> = Vec::new();
    for e in &result.events {
        let level = match e.kind {
            "fault" | "part_lost" => 3,
            "outcome" if !e.detail.starts_with("placed") => 3,
            _ => 2,
        };
        let message = if e.detail.is_empty() {
            e.kind.to_string()
        } else {
            format!("{}: {}", e.kind, e.detail)
        };
        let name = e.pick.map_or("cell".to_string(), |p| format!("pick {p}"));
        messages.push((
            nanos(e.t_s),
            log,
            serde_json::to_vec(&json!({
                "timestamp": stamp(e.t_s), "level": level, "message": message,
                "name": name, "file": "", "line": 0
            }))?,
        ));
        messages.push((nanos(e.t_s), events, serde_json::to_vec(e)?));
    }
    let limit = robot.torque_limit_nm();
    for (k, t) in result.trace.iter().enumerate() {
        if k % JOINT_STATE_EVERY == 0 {
            messages.push((
                nanos(t.t),
                joints,
                serde_json::to_vec(&json!({
                    "t_s": t.t,
                    "position_rad": t.q.as_slice(),
                    "velocity_rad_s": t.qd.as_slice(),
                    "torque_nm": t.tau.as_slice(),
                    "torque_limit_nm": limit.as_slice(),
                    "tracking_error_rad": t.error.as_slice(),
                }))?,
            ));
        }
        if k % TRANSFORMS_EVERY == 0 {
            let frames = robot.world_from_links(&t.q);
            let transforms: Vec<serde_json::Value> = frames
                .iter()
                .enumerate()
                .take(DOF + 1)
                .map(|(i, f)| {
                    let q = f.rotation.quaternion();
                    json!({
                        "timestamp": stamp(t.t),
                        "parent_frame_id": "world",
                        "child_frame_id": robot.links.get(i).map_or_else(|| format!("link_{i}"), |l| l.name.clone()),
                        "translation": {"x": f.translation.x, "y": f.translation.y, "z": f.translation.z},
                        "rotation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w},
                    })
                })
                .collect();
            messages.push((
                nanos(t.t),
                tf,
                serde_json::to_vec(&json!({ "transforms": transforms }))?,
            ));
        }
    }
    for r in &result.records {
        if let (Some(release), Some(t)) = (r.release_s, r.takt_s) {
            messages.push((
                nanos(release),
                takt,
                serde_json::to_vec(&json!({
                    "t_s": release, "pick": r.index, "takt_s": t, "first_of_pile": r.first_of_pile
                }))?,
            ));
        }
    }
    // All parts as one entity: a cube per part (its bounding box), coloured by state.
    let size = result.part_size_m;
    for f in &result.scene_frames {
        let cubes: Vec<serde_json::Value> = f
            .parts
            .iter()
            .filter(|(state, _)| *state != crate::physics::PartState::Removed)
            .map(|(state, p)| {
                let q = p.rotation.quaternion();
                let (r, g, b) = match state {
                    crate::physics::PartState::Held => (1.0, 0.6, 0.0),
                    crate::physics::PartState::Placed => (0.2, 0.7, 0.3),
                    _ => (0.3, 0.5, 0.9),
                };
                json!({
                    "pose": {
                        "position": {"x": p.translation.x, "y": p.translation.y, "z": p.translation.z},
                        "orientation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w},
                    },
                    "size": {"x": size[0], "y": size[1], "z": size[2]},
                    "color": {"r": r, "g": g, "b": b, "a": 1.0},
                })
            })
            .collect();
        messages.push((
            nanos(f.t_s),
            parts,
            serde_json::to_vec(&scene_update(f.t_s, "parts", 0, cubes, Vec::new()))?,
        ));
    }
    // Each motion's tool path, planned (blue) and executed (orange), shown for the motion's
    // duration plus a second.
    let line = |pts: &[nalgebra::Vector3<f64>], (r, g, b): (f64, f64, f64)| {
        json!({
            "type": 0, "thickness": 2.0, "scale_invariant": true,
            "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
            "points": pts.iter().map(|p| json!({"x": p.x, "y": p.y, "z": p.z})).collect::<Vec<_>>(),
            "color": {"r": r, "g": g, "b": b, "a": 1.0}, "colors": [], "indices": [],
        })
    };
    for (k, p) in result.tool_paths.iter().enumerate() {
        let life = nanos(p.duration_s + 1.0);
        messages.push((
            nanos(p.t_s),
            paths,
            serde_json::to_vec(&scene_update(
                p.t_s,
                &format!("motion {k}"),
                life,
                Vec::new(),
                vec![
                    line(&p.planned_m, (0.2, 0.4, 1.0)),
                    line(&p.executed_m, (1.0, 0.5, 0.0)),
                ],
            ))?,
        ));
    }
    // Each capture's depth image at its trigger time (millimetres, 16-bit).
    for c in &result.captures {
        use base64::Engine;
        let bytes: Vec<u8> = c.depth_mm.iter().flat_map(|d| d.to_le_bytes()).collect();
        messages.push((
            nanos(c.t_s),
            depth,
            serde_json::to_vec(&json!({
                "timestamp": stamp(c.t_s), "frame_id": "camera",
                "width": c.size_px.0, "height": c.size_px.1, "encoding": "16UC1",
                "step": 2 * c.size_px.0,
                "data": base64::engine::general_purpose::STANDARD.encode(bytes),
            }))?,
        ));
    }
    messages.sort_by_key(|m| m.0);
    let mut counts = TopicCounts::new();
    let topics = [
        (log, "/log"),
        (events, "/cycle/events"),
        (joints, "/robot/joint_states"),
        (tf, "/tf"),
        (takt, "/cycle/takt"),
        (parts, "/parts"),
        (depth, "/camera/depth"),
        (paths, "/paths"),
    ];
    let mut sequence = BTreeMap::<u16, u32>::new();
    for (time, ch, data) in &messages {
        let seq = sequence.entry(*ch).or_default();
        *seq += 1;
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: *ch,
                sequence: *seq,
                log_time: *time,
                publish_time: *time,
            },
            data,
        )?;
        if let Some((_, name)) = topics.iter().find(|(id, _)| id == ch) {
            *counts.entry(name.to_string()).or_default() += 1;
        }
    }
    let metadata = BTreeMap::from([
        ("scene".to_string(), info.scene.clone()),
        ("workpiece".to_string(), info.workpiece.clone()),
        ("seed".to_string(), info.seed.to_string()),
        ("deterministic".to_string(), info.deterministic.to_string()),
        ("binpick_version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
    ]);
    w.write_metadata(&mcap::records::Metadata {
        name: "binpick".into(),
        metadata,
    })?;
    w.finish()?;
    // Flush what the writer buffered and report it: a full disk shows up here.
    w.into_inner().flush()?;
    Ok(counts)
}
