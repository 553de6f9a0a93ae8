//! Record stage, MCAP: a finished run written to `run.mcap` for Foxglove.
//!
//! Topics (Foxglove's well-known schemas where one exists; see the module [`super`] for what is
//! recorded and why):
//! - `/cell` (`foxglove.SceneUpdate`, once): table, trays, obstacles, the camera's frustum;
//! - `/robot/geometry` (`foxglove.SceneUpdate`, once): each link's collision primitives, locked to
//!   the link's frame;
//! - `/tf` (`foxglove.FrameTransforms`, 50 Hz): `world` -> each link, `world` -> `camera`;
//! - `/robot/joint_states` (`binpick.JointState`, 100 Hz): positions, velocities, applied and
//!   demanded torques beside each joint's limit, tracking errors;
//! - `/parts` (`foxglove.SceneUpdate`, 10 Hz): all parts as one entity, a cube per part;
//! - `/camera/calibration` (`foxglove.CameraCalibration`), `/camera/depth` (`foxglove.RawImage`,
//!   16UC1, mm) and `/camera/points` (`foxglove.PointCloud`, world frame) at each trigger time;
//! - `/recognition` (`foxglove.SceneUpdate`): detections (cyan, red and labelled when more than
//!   2 mm or 5 deg from every part) and ranked grasp candidates (the chosen one green and
//!   labelled) when each result arrived;
//! - `/recognition/truth_at_trigger` (`foxglove.SceneUpdate`): the true poses, at the trigger, of
//!   the parts the capture showed (evaluation only), when the result arrived;
//! - `/paths` (`foxglove.SceneUpdate`): every motion's tool path, planned and executed;
//! - `/log` (`foxglove.Log`) and `/cycle/events` (`binpick.CycleEvent`): the cycle's events;
//! - `/cycle/takt` (`binpick.Takt`): the takt of every placed pick.
//!
//! Messages are JSON with JSON Schemas; log time is simulation time (ns); chunks are
//! zstd-compressed; the file's metadata holds the run's properties. The writer is finished
//! explicitly and its error reported.
//!
//! Units: s (ns as log time), rad, rad/s, N m, m (depth in mm). Frames: `world`, `camera` (optical:
//! x right, y down, z forward), and one frame per link named after it.

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use serde_json::json;

use super::Recording;
use super::{
    CANDIDATE_ARROW_M, JOINT_STATE_EVERY, RecordError, RunInfo, arm_samples, event_level, event_text, frustum_corners,
    part_rgb,
};
use crate::config::Scene;
use crate::robot::{DOF, RobotModel};

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
"torque_demand_nm":{"type":"array","items":{"type":"number"},"description":"torque the controller demanded, before saturation"},
"torque_limit_nm":{"type":"array","items":{"type":"number"}},
"tracking_error_rad":{"type":"array","items":{"type":"number"}}}}"#;

const SCENE_SCHEMA: &str = r##"{"title":"foxglove.SceneUpdate","type":"object","properties":{
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
"arrows":{"type":"array","items":{"type":"object","properties":{"pose":{"$ref":"#/$defs/pose"},
"shaft_length":{"type":"number"},"shaft_diameter":{"type":"number"},"head_length":{"type":"number"},"head_diameter":{"type":"number"},
"color":{"$ref":"#/$defs/color"}}}},
"spheres":{"type":"array","items":{"type":"object","properties":{"pose":{"$ref":"#/$defs/pose"},"size":{"$ref":"#/$defs/vector3"},"color":{"$ref":"#/$defs/color"}}}},
"cylinders":{"type":"array","items":{"type":"object","properties":{"pose":{"$ref":"#/$defs/pose"},"size":{"$ref":"#/$defs/vector3"},
"bottom_scale":{"type":"number"},"top_scale":{"type":"number"},"color":{"$ref":"#/$defs/color"}}}},
"texts":{"type":"array","items":{"type":"object","properties":{"pose":{"$ref":"#/$defs/pose"},"billboard":{"type":"boolean"},
"font_size":{"type":"number"},"scale_invariant":{"type":"boolean"},"color":{"$ref":"#/$defs/color"},"text":{"type":"string"}}}},
"lines":{"type":"array","items":{"type":"object","properties":{
"type":{"type":"integer","description":"0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
"thickness":{"type":"number"},"scale_invariant":{"type":"boolean"},
"points":{"type":"array","items":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}}},
"color":{"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}}}}}}}}}},
"$defs":{"vector3":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"color":{"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}},
"pose":{"type":"object","properties":{"position":{"$ref":"#/$defs/vector3"},
"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}}}"##;

const POINTS_SCHEMA: &str = r#"{"title":"foxglove.PointCloud","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},
"frame_id":{"type":"string"},
"pose":{"type":"object","properties":{
"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},
"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}},
"point_stride":{"type":"integer","minimum":0},
"fields":{"type":"array","items":{"type":"object","properties":{"name":{"type":"string"},"offset":{"type":"integer","minimum":0},
"type":{"type":"integer","description":"7 FLOAT32"}}}},
"data":{"type":"string","contentEncoding":"base64"}}}"#;

const CALIBRATION_SCHEMA: &str = r#"{"title":"foxglove.CameraCalibration","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},
"frame_id":{"type":"string"},"width":{"type":"integer","minimum":0},"height":{"type":"integer","minimum":0},
"distortion_model":{"type":"string"},"D":{"type":"array","items":{"type":"number"}},
"K":{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9},
"R":{"type":"array","items":{"type":"number"},"minItems":9,"maxItems":9},
"P":{"type":"array","items":{"type":"number"},"minItems":12,"maxItems":12}}}"#;

const IMAGE_SCHEMA: &str = r#"{"title":"foxglove.RawImage","type":"object","properties":{
"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},
"frame_id":{"type":"string"},"width":{"type":"integer","minimum":0},"height":{"type":"integer","minimum":0},
"encoding":{"type":"string"},"step":{"type":"integer","minimum":0},
"data":{"type":"string","contentEncoding":"base64"}}}"#;

const TAKT_SCHEMA: &str = r#"{"title":"binpick.Takt","type":"object","properties":{
"t_s":{"type":"number","description":"release time [s]"},"pick":{"type":"integer"},
"takt_s":{"type":"number"},"spans_refill":{"type":"boolean"}}}"#;

fn nanos(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

fn stamp(t_s: f64) -> serde_json::Value {
    let ns = nanos(t_s);
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn xyz(v: &nalgebra::Vector3<f64>) -> serde_json::Value {
    json!({"x": v.x, "y": v.y, "z": v.z})
}

fn pose(p: &nalgebra::Isometry3<f64>) -> serde_json::Value {
    let q = p.rotation.quaternion();
    json!({"position": xyz(&p.translation.vector), "orientation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w}})
}

fn rgba([r, g, b]: [f32; 3], a: f64) -> serde_json::Value {
    json!({"r": r, "g": g, "b": b, "a": a})
}

/// A line strip (`type` 0) or a line list (`type` 2) of `points` in the entity's frame.
fn line(kind: u8, points: &[nalgebra::Vector3<f64>], colour: [f32; 3]) -> serde_json::Value {
    json!({
        "type": kind, "thickness": 2.0, "scale_invariant": true,
        "pose": pose(&nalgebra::Isometry3::identity()),
        "points": points.iter().map(xyz).collect::<Vec<_>>(),
        "color": rgba(colour, 1.0), "colors": [], "indices": [],
    })
}

/// One `foxglove.SceneEntity`: primitives in one frame.
#[derive(Default)]
struct Entity {
    id: String,
    /// Frame the primitives' poses are in (`world` if empty).
    frame_id: String,
    /// Follow the frame as it moves (link geometry).
    frame_locked: bool,
    /// How long it is shown [ns] (0: until replaced).
    lifetime_ns: u64,
    cubes: Vec<serde_json::Value>,
    spheres: Vec<serde_json::Value>,
    cylinders: Vec<serde_json::Value>,
    arrows: Vec<serde_json::Value>,
    lines: Vec<serde_json::Value>,
    texts: Vec<serde_json::Value>,
}

impl Entity {
    fn new(id: impl Into<String>) -> Self {
        Entity {
            id: id.into(),
            ..Entity::default()
        }
    }

    fn json(self, t_s: f64) -> serde_json::Value {
        let frame = if self.frame_id.is_empty() {
            "world".to_string()
        } else {
            self.frame_id
        };
        json!({
            "timestamp": stamp(t_s), "frame_id": frame, "id": self.id,
            "lifetime": {"sec": self.lifetime_ns / 1_000_000_000, "nsec": self.lifetime_ns % 1_000_000_000},
            "frame_locked": self.frame_locked, "metadata": [],
            "arrows": self.arrows, "cubes": self.cubes, "spheres": self.spheres, "cylinders": self.cylinders,
            "lines": self.lines, "triangles": [], "texts": self.texts, "models": [],
        })
    }
}

/// A `foxglove.SceneUpdate` of `entities` at `t_s`.
fn scene_update(t_s: f64, entities: Vec<Entity>) -> serde_json::Value {
    json!({
        "deletions": [],
        "entities": entities.into_iter().map(|e| e.json(t_s)).collect::<Vec<_>>(),
    })
}

/// Writes the recording of `result` to a new file at `path` (see [`write_mcap`]): first to
/// `<path>.partial`, then renamed once finished, so a failed write never leaves a truncated file.
pub fn write_mcap_file(
    path: &std::path::Path,
    result: &Recording,
    robot: &RobotModel,
    scene: &Scene,
    info: &RunInfo,
) -> Result<(), RecordError> {
    let partial = path.with_extension("mcap.partial");
    let file = std::fs::File::create(&partial)?;
    write_mcap(std::io::BufWriter::new(file), result, robot, scene, info).inspect_err(|_| {
        let _ = std::fs::remove_file(&partial);
    })?;
    std::fs::rename(&partial, path)?;
    Ok(())
}

/// The topics, in the order their channels are declared: (topic, schema name, JSON Schema).
const TOPICS: [(&str, &str, &str); 15] = [
    ("/cell", "foxglove.SceneUpdate", SCENE_SCHEMA),
    ("/robot/geometry", "foxglove.SceneUpdate", SCENE_SCHEMA),
    ("/tf", "foxglove.FrameTransforms", TRANSFORMS_SCHEMA),
    ("/robot/joint_states", "binpick.JointState", JOINT_SCHEMA),
    ("/parts", "foxglove.SceneUpdate", SCENE_SCHEMA),
    ("/camera/calibration", "foxglove.CameraCalibration", CALIBRATION_SCHEMA),
    ("/camera/depth", "foxglove.RawImage", IMAGE_SCHEMA),
    ("/camera/points", "foxglove.PointCloud", POINTS_SCHEMA),
    ("/recognition", "foxglove.SceneUpdate", SCENE_SCHEMA),
    ("/recognition/truth_at_trigger", "foxglove.SceneUpdate", SCENE_SCHEMA),
    ("/paths", "foxglove.SceneUpdate", SCENE_SCHEMA),
    ("/log", "foxglove.Log", LOG_SCHEMA),
    ("/cycle/events", "binpick.CycleEvent", EVENT_SCHEMA),
    ("/cycle/takt", "binpick.Takt", TAKT_SCHEMA),
    // The run's properties (also the file's metadata), once at time 0.
    ("/cycle/properties", "binpick.Properties", PROPERTIES_SCHEMA),
];

const PROPERTIES_SCHEMA: &str =
    r#"{"title":"binpick.Properties","type":"object","additionalProperties":{"type":"string"}}"#;

/// Messages of one recording before they are merged in log-time order: (log time ns, topic
/// index into [`TOPICS`], JSON).
struct Messages(Vec<(u64, usize, Vec<u8>)>);

impl Messages {
    fn push(&mut self, t_s: f64, topic: &str, message: &serde_json::Value) -> Result<(), RecordError> {
        let k = TOPICS
            .iter()
            .position(|(t, _, _)| *t == topic)
            .expect("a declared topic");
        self.0.push((nanos(t_s), k, serde_json::to_vec(message)?));
        Ok(())
    }
}

/// Writes the recording `result` to `out`.
pub fn write_mcap<W: Write + Seek>(
    out: W,
    result: &Recording,
    robot: &RobotModel,
    scene: &Scene,
    info: &RunInfo,
) -> Result<(), RecordError> {
    let mut m = Messages(Vec::new());
    cell_messages(&mut m, result, scene)?;
    arm_messages(&mut m, result, robot)?;
    part_messages(&mut m, result)?;
    sensing_messages(&mut m, result)?;
    path_messages(&mut m, result)?;
    event_messages(&mut m, result)?;
    let properties: BTreeMap<String, String> = info.properties().into_iter().map(|(k, v)| (k.to_string(), v)).collect();
    m.push(0.0, "/cycle/properties", &json!(properties))?;

    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile("")
        .create(out)?;
    let none = BTreeMap::new();
    let mut channels = Vec::new();
    for (topic, name, schema) in TOPICS {
        let s = w.add_schema(name, "jsonschema", schema.as_bytes())?;
        channels.push(w.add_channel(s, topic, "json", &none)?);
    }
    // Messages go in log-time order (stable: same-time messages keep their order).
    m.0.sort_by_key(|(t, _, _)| *t);
    let mut sequence = vec![0u32; TOPICS.len()];
    for (time, k, data) in &m.0 {
        sequence[*k] += 1;
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channels[*k],
                sequence: sequence[*k],
                log_time: *time,
                publish_time: *time,
            },
            data,
        )?;
    }
    w.write_metadata(&mcap::records::Metadata {
        name: "binpick".into(),
        metadata: properties,
    })?;
    w.finish()?;
    // Flush what the writer buffered and report it: a full disk shows up here.
    w.into_inner().flush()?;
    Ok(())
}

/// `/cell`: table, trays and obstacles as grey cubes, the camera's frustum out to the pick tray.
fn cell_messages(m: &mut Messages, result: &Recording, scene: &Scene) -> Result<(), RecordError> {
    let mut cell = Entity::new("cell");
    for (_, b) in crate::geometry::cell_boxes(scene) {
        cell.cubes.push(json!({
            "pose": pose(&b.world_from_box()), "size": xyz(&(2.0 * b.half_m)), "color": rgba([0.6, 0.6, 0.6], 1.0),
        }));
    }
    let c = &result.camera;
    let range_m = (nalgebra::Vector3::from(scene.pick_tray.center_m) - c.world_from_camera.translation.vector).norm();
    let [apex, a, b, cc, d] = frustum_corners(c, range_m);
    cell.lines.push(line(
        2,
        &[apex, a, apex, b, apex, cc, apex, d, a, b, b, cc, cc, d, d, a],
        [0.9, 0.9, 0.2],
    ));
    m.push(0.0, "/cell", &scene_update(0.0, vec![cell]))
}

/// `/robot/geometry` once (each link's primitives locked to its frame), `/tf` at 50 Hz and
/// `/robot/joint_states` at 100 Hz.
fn arm_messages(m: &mut Messages, result: &Recording, robot: &RobotModel) -> Result<(), RecordError> {
    use crate::robot::Primitive;
    let name = |i: usize| {
        robot
            .links
            .get(i)
            .map_or_else(|| format!("link_{i}"), |l| l.name.clone())
    };
    let colour = [0.9, 0.78, 0.24];
    let mut links = Vec::new();
    for (i, link) in robot.links.iter().enumerate().take(DOF + 1) {
        let mut e = Entity::new(format!("link {}", name(i)));
        e.frame_id = name(i);
        e.frame_locked = true;
        for s in &link.shapes {
            let at = &s.link_from_shape;
            match &s.primitive {
                Primitive::Box { half_extents_m } => e.cubes.push(json!({
                    "pose": pose(at), "size": xyz(&(2.0 * half_extents_m)), "color": rgba(colour, 1.0),
                })),
                Primitive::Cylinder {
                    radius_m,
                    half_length_m,
                } => e.cylinders.push(json!({
                    "pose": pose(at), "bottom_scale": 1.0, "top_scale": 1.0, "color": rgba(colour, 1.0),
                    "size": {"x": 2.0 * radius_m, "y": 2.0 * radius_m, "z": 2.0 * half_length_m},
                })),
                Primitive::Sphere { radius_m } => e.spheres.push(json!({
                    "pose": pose(at), "color": rgba(colour, 1.0),
                    "size": {"x": 2.0 * radius_m, "y": 2.0 * radius_m, "z": 2.0 * radius_m},
                })),
                Primitive::Capsule {
                    radius_m,
                    half_length_m,
                } => {
                    // A cylinder and two end spheres.
                    e.cylinders.push(json!({
                        "pose": pose(at), "bottom_scale": 1.0, "top_scale": 1.0, "color": rgba(colour, 1.0),
                        "size": {"x": 2.0 * radius_m, "y": 2.0 * radius_m, "z": 2.0 * half_length_m},
                    }));
                    for end in [-half_length_m, *half_length_m] {
                        let p = at * nalgebra::Translation3::new(0.0, 0.0, end);
                        e.spheres.push(json!({
                            "pose": pose(&p), "color": rgba(colour, 1.0),
                            "size": {"x": 2.0 * radius_m, "y": 2.0 * radius_m, "z": 2.0 * radius_m},
                        }));
                    }
                }
            }
        }
        links.push(e);
    }
    m.push(0.0, "/robot/geometry", &scene_update(0.0, links))?;
    let limit = robot.torque_limit_nm();
    let transform = |t_s: f64, child: &str, p: &nalgebra::Isometry3<f64>| {
        let q = p.rotation.quaternion();
        json!({
            "timestamp": stamp(t_s), "parent_frame_id": "world", "child_frame_id": child,
            "translation": xyz(&p.translation.vector),
            "rotation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w},
        })
    };
    for t in result.trace.iter().step_by(JOINT_STATE_EVERY) {
        m.push(
            t.t_s,
            "/robot/joint_states",
            &json!({
                "t_s": t.t_s,
                "position_rad": t.q.as_slice(),
                "velocity_rad_s": t.qd.as_slice(),
                "torque_nm": t.tau_nm.as_slice(),
                "torque_demand_nm": t.demand_nm.as_slice(),
                "torque_limit_nm": limit.as_slice(),
                "tracking_error_rad": t.error_rad.as_slice(),
            }),
        )?;
    }
    for (t_s, q) in arm_samples(result) {
        let world_from_links = robot.world_from_links(&q);
        let mut transforms: Vec<serde_json::Value> = world_from_links
            .iter()
            .enumerate()
            .take(DOF + 1)
            .map(|(i, f)| transform(t_s, &name(i), f))
            .collect();
        transforms.push(transform(t_s, "camera", &result.camera.world_from_camera));
        m.push(t_s, "/tf", &json!({ "transforms": transforms }))?;
    }
    Ok(())
}

/// `/parts`: all parts as one entity, a cube per part (its bounding box), coloured by state.
fn part_messages(m: &mut Messages, result: &Recording) -> Result<(), RecordError> {
    let size = nalgebra::Vector3::from(result.part_size_m);
    for f in &result.scene_frames {
        let mut e = Entity::new("parts");
        e.cubes = f
            .parts
            .iter()
            .filter(|(state, _)| *state != crate::physics::PartState::Removed)
            .map(|(state, p)| json!({"pose": pose(p), "size": xyz(&size), "color": rgba(part_rgb(*state), 1.0)}))
            .collect();
        m.push(f.t_s, "/parts", &scene_update(f.t_s, vec![e]))?;
    }
    Ok(())
}

/// `/camera/*` at each trigger time; `/recognition` when each result arrived.
fn sensing_messages(m: &mut Messages, result: &Recording) -> Result<(), RecordError> {
    use base64::Engine;
    let b64 = |bytes: &[u8]| base64::engine::general_purpose::STANDARD.encode(bytes);
    let c = &result.camera;
    for cap in &result.captures {
        let t = cap.t_s;
        m.push(
            t,
            "/camera/calibration",
            &json!({
                "timestamp": stamp(t), "frame_id": "camera", "width": c.width_px, "height": c.height_px,
                "distortion_model": "plumb_bob", "D": [0.0, 0.0, 0.0, 0.0, 0.0],
                "K": [c.fx_px, 0.0, c.cx_px, 0.0, c.fy_px, c.cy_px, 0.0, 0.0, 1.0],
                "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                "P": [c.fx_px, 0.0, c.cx_px, 0.0, 0.0, c.fy_px, c.cy_px, 0.0, 0.0, 0.0, 1.0, 0.0],
            }),
        )?;
        let depth: Vec<u8> = cap.depth_mm.iter().flat_map(|d| d.to_le_bytes()).collect();
        m.push(
            t,
            "/camera/depth",
            &json!({
                "timestamp": stamp(t), "frame_id": "camera",
                "width": cap.size_px.0, "height": cap.size_px.1, "encoding": "16UC1",
                "step": 2 * cap.size_px.0, "data": b64(&depth),
            }),
        )?;
        let points: Vec<u8> = cap
            .points_world_m
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        m.push(
            t,
            "/camera/points",
            &json!({
                "timestamp": stamp(t), "frame_id": "world", "pose": pose(&nalgebra::Isometry3::identity()),
                "point_stride": 12,
                "fields": [
                    {"name": "x", "offset": 0, "type": 7},
                    {"name": "y", "offset": 4, "type": 7},
                    {"name": "z", "offset": 8, "type": 7},
                ],
                "data": b64(&points),
            }),
        )?;
    }
    let size = nalgebra::Vector3::from(result.part_size_m);
    // Arrows point along their pose's +x: turn +x to -z (down onto the grasp point).
    let down = nalgebra::UnitQuaternion::from_axis_angle(&nalgebra::Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    for t in &result.truths {
        let mut truth = Entity::new("true poses at the trigger");
        truth.cubes = t
            .parts
            .iter()
            .map(|(_, p)| json!({"pose": pose(p), "size": xyz(&size), "color": rgba([0.25, 0.85, 0.25], 0.25)}))
            .collect();
        m.push(
            t.t_s,
            "/recognition/truth_at_trigger",
            &scene_update(t.t_s, vec![truth]),
        )?;
    }
    for r in &result.recognitions {
        let mut detections = Entity::new("detections");
        for ((p, _), e) in r.detections.iter().zip(&r.detection_errors) {
            let wrong = matches!(e, Some((_, _, false)));
            let colour = if wrong { [1.0, 0.15, 0.15] } else { [0.0, 0.8, 1.0] };
            detections
                .cubes
                .push(json!({"pose": pose(p), "size": xyz(&size), "color": rgba(colour, 0.35)}));
            if let Some((dp, dr, false)) = e {
                detections.texts.push(json!({
                    "pose": pose(p), "billboard": true, "font_size": 12.0, "scale_invariant": true,
                    "color": rgba(colour, 1.0),
                    "text": format!("wrong: {:.1} mm / {:.1} deg off", dp * 1e3, dr.to_degrees()),
                }));
            }
        }
        let mut candidates = Entity::new("grasp candidates");
        for (k, (p, score)) in r.candidates.iter().enumerate() {
            let chosen = r.chosen == Some(k);
            let tip = p.translation.vector + nalgebra::Vector3::z() * CANDIDATE_ARROW_M;
            let at = nalgebra::Isometry3::from_parts(nalgebra::Translation3::from(tip), down);
            let colour = if chosen { [0.0, 0.9, 0.0] } else { [0.95, 0.8, 0.0] };
            candidates.arrows.push(json!({
                "pose": pose(&at), "shaft_length": 0.7 * CANDIDATE_ARROW_M, "shaft_diameter": 0.001,
                "head_length": 0.3 * CANDIDATE_ARROW_M, "head_diameter": 0.003, "color": rgba(colour, 1.0),
            }));
            if chosen {
                candidates.texts.push(json!({
                    "pose": pose(&at), "billboard": true, "font_size": 12.0, "scale_invariant": true,
                    "color": rgba(colour, 1.0), "text": format!("chosen: #{} score {score:.2}", k + 1),
                }));
            }
        }
        m.push(
            r.t_s,
            "/recognition",
            &scene_update(r.t_s, vec![detections, candidates]),
        )?;
    }
    Ok(())
}

/// `/paths`: each motion's tool path, planned (blue) and executed (orange), shown for the motion's
/// duration plus a second.
fn path_messages(m: &mut Messages, result: &Recording) -> Result<(), RecordError> {
    for (k, p) in result.tool_paths.iter().enumerate() {
        let mut e = Entity::new(format!("motion {k}"));
        e.lifetime_ns = nanos(p.duration_s + 1.0);
        e.lines = vec![
            line(0, &p.planned_m, [0.2, 0.4, 1.0]),
            line(0, &p.executed_m, [1.0, 0.5, 0.0]),
        ];
        m.push(p.t_s, "/paths", &scene_update(p.t_s, vec![e]))?;
    }
    Ok(())
}

/// `/log` and `/cycle/events` for every cycle event; `/cycle/takt` at every placed pick's release.
fn event_messages(m: &mut Messages, result: &Recording) -> Result<(), RecordError> {
    for e in &result.events {
        let name = e.pick.map_or("cell".to_string(), |p| format!("pick {p}"));
        m.push(
            e.t_s,
            "/log",
            &json!({
                "timestamp": stamp(e.t_s), "level": event_level(e), "message": event_text(e),
                "name": name, "file": "", "line": 0
            }),
        )?;
        m.push(e.t_s, "/cycle/events", &serde_json::to_value(e)?)?;
    }
    for r in &result.records {
        if let (Some(release), Some(t)) = (r.release_s, r.takt_s) {
            m.push(
                release,
                "/cycle/takt",
                &json!({"t_s": release, "pick": r.index, "takt_s": t, "spans_refill": r.spans_refill}),
            )?;
        }
    }
    Ok(())
}
