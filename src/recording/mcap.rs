//! Record stage, MCAP: a run written to `run.mcap` for Foxglove, part by part as it goes.
//!
//! Topics (Foxglove's well-known schemas where one exists; see the module [`super`] for what is
//! recorded and why):
//! - `/cell` (`foxglove.SceneUpdate`, once): table, trays, obstacles, the camera's frustum;
//! - `/robot/geometry` (`foxglove.SceneUpdate`, once): each link's collision primitives, locked to
//!   the link's frame;
//! - `/robot_description` (`std_msgs/String` as JSON, once at time 0): the URDF the arm was built
//!   from, its text in `data`, where Foxglove's 3D panel looks for a robot description (it draws
//!   the URDF's visuals on the link frames `/tf` moves; turn the topic on in the panel);
//! - `/tf` (`foxglove.FrameTransforms`, 50 Hz): the URDF's tree, as a robot state publisher
//!   sends it: `world` -> the root link (where the base stands), then each joint's parent link ->
//!   child link at the joint's recorded position; and `world` -> `camera`;
//! - `/robot/joint_states` (`foxglove.JointStates`, 100 Hz): per joint (named as in the URDF) its
//!   position, velocity and applied torque (`effort`);
//! - `/robot/servo` (`binpick.ServoState`, 100 Hz, at the same times): what `foxglove.JointStates`
//!   has no field for: the torque the controller demanded before saturation, each joint's torque
//!   limit, the tracking errors (single precision);
//! - `/parts` (`foxglove.SceneUpdate`, 10 Hz): all parts as one entity, a cube per part;
//! - `/camera/calibration` (`foxglove.CameraCalibration`), `/camera/depth` (`foxglove.RawImage`,
//!   16UC1, mm) and `/camera/points` (`foxglove.PointCloud`, world frame, float32 x, y, z on
//!   the [`super::CLOUD_GRID_M`] grid) at each trigger time;
//! - `/recognition` (`foxglove.SceneUpdate`): detections (cyan, red and labelled when more than
//!   2 mm or 5 deg from every part) and ranked grasp candidates (the chosen one green and
//!   labelled) when each result arrived;
//! - `/recognition/truth_at_trigger` (`foxglove.SceneUpdate`): the true poses, at the trigger, of
//!   the parts the capture showed (evaluation only), when the result arrived;
//! - `/paths` (`foxglove.SceneUpdate`): every motion's tool path, planned and executed;
//! - `/log` (`foxglove.Log`) and `/cycle/events` (`binpick.CycleEvent`): the cycle's events;
//! - `/cycle/takt` (`binpick.Takt`): the takt of every placed pick;
//! - `/cycle/properties` (`binpick.Properties`, once): the run's properties.
//!
//! Encoding: the `foxglove.*` messages are protobuf, with the schemas (file descriptor sets) the
//! `foxglove` crate carries; the few `binpick.*` messages are JSON with JSON Schemas. Log time is
//! simulation time (ns); chunks are zstd-compressed at level 1 on the writer's own thread (the
//! default level 3 on a pool of threads cost more CPU for a file a fifth smaller); the file's
//! metadata holds the run's properties. The writer is finished explicitly and its error reported.
//!
//! Units: s (ns as log time), rad, rad/s, N m, m (depth in mm). Frames: `world`, `camera` (optical:
//! x right, y down, z forward), and one frame per link named after it.

use std::collections::BTreeMap;
use std::io::Write;

use foxglove::Encode;
use foxglove::messages as fg;
use nalgebra::{Isometry3, Vector3};
use serde::Serialize;

use super::{
    CANDIDATE_ARROW_M, CaptureImage, RecordError, Recording, RunInfo, arm_samples, event_level, event_text,
    frustum_corners, joint_state_ticks, link_name, part_rgb,
};
use crate::config::Scene;
use crate::robot::{DOF, RobotModel};

const EVENT_SCHEMA: &str = r#"{"title":"binpick.CycleEvent","type":"object","properties":{
"t_s":{"type":"number","description":"simulation time [s]"},
"pick":{"type":["integer","null"]},"kind":{"type":"string"},"detail":{"type":"string"}}}"#;

const SERVO_SCHEMA: &str = r#"{"title":"binpick.ServoState","type":"object","properties":{
"t_s":{"type":"number","description":"simulation time [s]"},
"torque_demand_nm":{"type":"array","items":{"type":"number"},"description":"torque the controller demanded, before saturation, per joint [N m]"},
"torque_limit_nm":{"type":"array","items":{"type":"number"},"description":"each joint's torque limit [N m]"},
"tracking_error_rad":{"type":"array","items":{"type":"number"},"description":"commanded minus measured position [rad]"}}}"#;

const TAKT_SCHEMA: &str = r#"{"title":"binpick.Takt","type":"object","properties":{
"t_s":{"type":"number","description":"release time [s]"},"pick":{"type":"integer"},
"takt_s":{"type":"number"},"spans_refill":{"type":"boolean"}}}"#;

/// The JSON form of ROS's `std_msgs/String`: what Foxglove's 3D panel reads a URDF from.
const STRING_SCHEMA: &str = r#"{"title":"std_msgs/String","type":"object","properties":{"data":{"type":"string"}}}"#;

const PROPERTIES_SCHEMA: &str =
    r#"{"title":"binpick.Properties","type":"object","additionalProperties":{"type":"string"}}"#;

/// A recorded topic; its index in [`TOPICS`] is its declaration order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Topic {
    Cell,
    RobotGeometry,
    RobotDescription,
    Tf,
    JointStates,
    Servo,
    Parts,
    Calibration,
    Depth,
    ConfirmingDepth,
    Points,
    Recognition,
    Truth,
    Paths,
    Log,
    Events,
    Takt,
    Properties,
}

/// How a topic's messages are encoded: protobuf with a well-known Foxglove schema, or JSON with
/// one of ours (name, JSON Schema).
#[derive(Clone, Copy)]
enum Encoding {
    Protobuf(fn() -> Option<foxglove::Schema>),
    Json(&'static str, &'static str),
}

/// The topics, in the order their channels are declared (the order of [`Topic`]).
const TOPICS: [(Topic, &str, Encoding); 18] = [
    (Topic::Cell, "/cell", Encoding::Protobuf(fg::SceneUpdate::get_schema)),
    (
        Topic::RobotGeometry,
        "/robot/geometry",
        Encoding::Protobuf(fg::SceneUpdate::get_schema),
    ),
    (
        Topic::RobotDescription,
        "/robot_description",
        Encoding::Json("std_msgs/String", STRING_SCHEMA),
    ),
    (Topic::Tf, "/tf", Encoding::Protobuf(fg::FrameTransforms::get_schema)),
    (
        Topic::JointStates,
        "/robot/joint_states",
        Encoding::Protobuf(fg::JointStates::get_schema),
    ),
    (
        Topic::Servo,
        "/robot/servo",
        Encoding::Json("binpick.ServoState", SERVO_SCHEMA),
    ),
    (Topic::Parts, "/parts", Encoding::Protobuf(fg::SceneUpdate::get_schema)),
    (
        Topic::Calibration,
        "/camera/calibration",
        Encoding::Protobuf(fg::CameraCalibration::get_schema),
    ),
    (
        Topic::Depth,
        "/camera/depth",
        Encoding::Protobuf(fg::RawImage::get_schema),
    ),
    (
        Topic::ConfirmingDepth,
        "/camera/confirming_depth",
        Encoding::Protobuf(fg::RawImage::get_schema),
    ),
    (
        Topic::Points,
        "/camera/points",
        Encoding::Protobuf(fg::PointCloud::get_schema),
    ),
    (
        Topic::Recognition,
        "/recognition",
        Encoding::Protobuf(fg::SceneUpdate::get_schema),
    ),
    (
        Topic::Truth,
        "/recognition/truth_at_trigger",
        Encoding::Protobuf(fg::SceneUpdate::get_schema),
    ),
    (Topic::Paths, "/paths", Encoding::Protobuf(fg::SceneUpdate::get_schema)),
    (Topic::Log, "/log", Encoding::Protobuf(fg::Log::get_schema)),
    (
        Topic::Events,
        "/cycle/events",
        Encoding::Json("binpick.CycleEvent", EVENT_SCHEMA),
    ),
    (Topic::Takt, "/cycle/takt", Encoding::Json("binpick.Takt", TAKT_SCHEMA)),
    // The run's properties (also the file's metadata), once at time 0.
    (
        Topic::Properties,
        "/cycle/properties",
        Encoding::Json("binpick.Properties", PROPERTIES_SCHEMA),
    ),
];

fn nanos(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

fn stamp(t_s: f64) -> Option<fg::Timestamp> {
    let ns = nanos(t_s);
    // u32 seconds: 136 years of simulated time.
    Some(fg::Timestamp::new(
        (ns / 1_000_000_000) as u32,
        (ns % 1_000_000_000) as u32,
    ))
}

fn xyz(v: &Vector3<f64>) -> Option<fg::Vector3> {
    Some(fg::Vector3 { x: v.x, y: v.y, z: v.z })
}

fn point(v: &Vector3<f64>) -> fg::Point3 {
    fg::Point3 { x: v.x, y: v.y, z: v.z }
}

fn quaternion(p: &Isometry3<f64>) -> Option<fg::Quaternion> {
    let q = p.rotation.quaternion();
    Some(fg::Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    })
}

fn pose(p: &Isometry3<f64>) -> Option<fg::Pose> {
    Some(fg::Pose {
        position: xyz(&p.translation.vector),
        orientation: quaternion(p),
    })
}

fn rgba([r, g, b]: [f32; 3], a: f64) -> Option<fg::Color> {
    Some(fg::Color {
        r: r.into(),
        g: g.into(),
        b: b.into(),
        a,
    })
}

fn cube(p: &Isometry3<f64>, size_m: &Vector3<f64>, colour: [f32; 3], alpha: f64) -> fg::CubePrimitive {
    fg::CubePrimitive {
        pose: pose(p),
        size: xyz(size_m),
        color: rgba(colour, alpha),
    }
}

fn text(p: &Isometry3<f64>, colour: [f32; 3], text: String) -> fg::TextPrimitive {
    fg::TextPrimitive {
        pose: pose(p),
        billboard: true,
        font_size: 12.0,
        scale_invariant: true,
        color: rgba(colour, 1.0),
        text,
    }
}

/// A line strip or a line list of `points` in the entity's frame.
fn line(kind: fg::line_primitive::Type, points: &[Vector3<f64>], colour: [f32; 3]) -> fg::LinePrimitive {
    fg::LinePrimitive {
        r#type: kind as i32,
        pose: pose(&Isometry3::identity()),
        thickness: 2.0,
        scale_invariant: true,
        points: points.iter().map(point).collect(),
        color: rgba(colour, 1.0),
        ..Default::default()
    }
}

/// A `foxglove.SceneEntity` named `id` at `t_s`, in `world` (change `frame_id` for another),
/// shown until replaced (lifetime zero, written out as the JSON form of the schema requires it).
fn entity(t_s: f64, id: impl Into<String>) -> fg::SceneEntity {
    fg::SceneEntity {
        timestamp: stamp(t_s),
        frame_id: "world".into(),
        id: id.into(),
        lifetime: Some(fg::Duration::new(0, 0)),
        ..Default::default()
    }
}

/// A `foxglove.SceneUpdate` of `entities`.
fn scene_update(entities: Vec<fg::SceneEntity>) -> fg::SceneUpdate {
    fg::SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

/// Messages of one recording before they are merged in log-time order: (log time ns, topic,
/// encoded message).
#[derive(Default)]
struct Messages(Vec<(u64, Topic, Vec<u8>)>);

impl Messages {
    /// A well-known Foxglove message, protobuf-encoded.
    fn proto(&mut self, t_s: f64, topic: Topic, message: &impl Encode) -> Result<(), RecordError> {
        let mut data = Vec::with_capacity(message.encoded_len().unwrap_or(0));
        message
            .encode(&mut data)
            .map_err(|e| RecordError::Encode(e.to_string()))?;
        self.0.push((nanos(t_s), topic, data));
        Ok(())
    }

    /// One of our messages, JSON-encoded.
    fn json(&mut self, t_s: f64, topic: Topic, message: &impl Serialize) -> Result<(), RecordError> {
        self.0.push((nanos(t_s), topic, serde_json::to_vec(message)?));
        Ok(())
    }
}

/// A `.mcap` file being written: to `<path>.partial` until [`McapFile::finish`] writes its
/// summary and renames it to `path`, so that a failed or abandoned write never leaves a truncated
/// file (dropped unfinished, it removes the partial file).
pub struct McapFile {
    path: std::path::PathBuf,
    partial: std::path::PathBuf,
    writer: Option<mcap::Writer<std::io::BufWriter<std::fs::File>>>,
    /// Channel id per topic, in the order of [`Topic`].
    channels: Vec<u16>,
    /// The last sequence number per topic.
    sequence: [u32; TOPICS.len()],
    /// The run's properties (a message at time 0 and the file's metadata).
    properties: BTreeMap<String, String>,
    /// The URDF text (`/robot_description`).
    robot_description: String,
    /// The pick tray's centre (m, world): the camera's frustum is drawn out to its distance.
    pick_tray_center_m: Vector3<f64>,
}

impl McapFile {
    /// Starts the recording at `path` of a run in `scene` described by `info`: the schemas and
    /// the channels of every topic.
    pub fn create(path: &std::path::Path, scene: &Scene, info: &RunInfo) -> Result<Self, RecordError> {
        let partial = path.with_extension("mcap.partial");
        let out = std::io::BufWriter::new(std::fs::File::create(&partial)?);
        let mut file = McapFile {
            path: path.to_path_buf(),
            partial,
            writer: None,
            channels: Vec::new(),
            sequence: [0; TOPICS.len()],
            properties: info.properties().into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
            robot_description: info.robot_description.clone(),
            pick_tray_center_m: Vector3::from(scene.pick_tray.center_m),
        };
        let w = file.writer.insert(
            mcap::WriteOptions::new()
                .compression(Some(mcap::Compression::Zstd))
                .compression_level(1)
                .compression_threads(0)
                .profile("")
                .create(out)?,
        );
        let none = BTreeMap::new();
        for (k, (topic, name, encoding)) in TOPICS.iter().enumerate() {
            debug_assert_eq!(*topic as usize, k, "TOPICS in the order of Topic");
            let (schema, message_encoding) = match encoding {
                Encoding::Protobuf(schema) => {
                    let s = schema().ok_or_else(|| RecordError::Encode(format!("no schema for {name}")))?;
                    (w.add_schema(&s.name, &s.encoding, &s.data)?, "protobuf")
                }
                Encoding::Json(schema_name, schema) => {
                    (w.add_schema(schema_name, "jsonschema", schema.as_bytes())?, "json")
                }
            };
            file.channels
                .push(w.add_channel(schema, name, message_encoding, &none)?);
        }
        Ok(file)
    }

    /// Writes one part of the recording (the first one with the cell, the arm's geometry, the
    /// robot description and the properties), its messages in log-time order.
    pub fn write(&mut self, part: &Recording, robot: &RobotModel) -> Result<(), RecordError> {
        let mut m = Messages::default();
        if part.opening {
            cell_messages(&mut m, part, self.pick_tray_center_m)?;
            m.json(
                0.0,
                Topic::RobotDescription,
                &serde_json::json!({"data": self.robot_description}),
            )?;
            arm_geometry_messages(&mut m, robot)?;
        }
        arm_messages(&mut m, part, robot)?;
        part_messages(&mut m, part)?;
        sensing_messages(&mut m, part)?;
        path_messages(&mut m, part)?;
        event_messages(&mut m, part)?;
        if part.opening {
            m.json(0.0, Topic::Properties, &self.properties)?;
        }
        let w = self
            .writer
            .as_mut()
            .ok_or_else(|| RecordError::Encode("the file is closed".into()))?;
        // Messages go in log-time order (stable: same-time messages keep their order).
        m.0.sort_by_key(|(t, _, _)| *t);
        for (time, topic, data) in &m.0 {
            let k = *topic as usize;
            self.sequence[k] += 1;
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: self.channels[k],
                    sequence: self.sequence[k],
                    log_time: *time,
                    publish_time: *time,
                },
                data,
            )?;
        }
        Ok(())
    }

    /// Writes the metadata and the summary, flushes and renames the file to its final name.
    pub fn finish(mut self) -> Result<(), RecordError> {
        let mut w = self
            .writer
            .take()
            .ok_or_else(|| RecordError::Encode("the file is closed".into()))?;
        w.write_metadata(&mcap::records::Metadata {
            name: "binpick".into(),
            metadata: self.properties.clone(),
        })?;
        w.finish()?;
        // Flush what the writer buffered and report it: a full disk shows up here.
        w.into_inner().flush()?;
        std::fs::rename(&self.partial, &self.path)?;
        Ok(())
    }
}

impl Drop for McapFile {
    /// Removes the partial file: a finished file was renamed away.
    fn drop(&mut self) {
        drop(self.writer.take());
        let _ = std::fs::remove_file(&self.partial);
    }
}

/// `/cell`: table, trays and obstacles as grey cubes, the camera's frustum out to the pick tray.
fn cell_messages(m: &mut Messages, result: &Recording, pick_tray_center_m: Vector3<f64>) -> Result<(), RecordError> {
    let mut cell = entity(0.0, "cell");
    for b in &result.cell_boxes {
        cell.cubes
            .push(cube(&b.world_from_box, &(2.0 * b.half_m), [0.6, 0.6, 0.6], 1.0));
    }
    let c = &result.camera;
    let range_m = (pick_tray_center_m - c.world_from_camera.translation.vector).norm();
    let [apex, a, b, cc, d] = frustum_corners(c, range_m);
    cell.lines.push(line(
        fg::line_primitive::Type::LineList,
        &[apex, a, apex, b, apex, cc, apex, d, a, b, b, cc, cc, d, d, a],
        [0.9, 0.9, 0.2],
    ));
    m.proto(0.0, Topic::Cell, &scene_update(vec![cell]))
}

/// The torque the controller demanded, the limits and the tracking errors (what
/// `foxglove.JointStates` has no field for).
/// Single precision: these are plotted, and shorter numbers keep the file small.
#[derive(Serialize)]
struct ServoState {
    t_s: f64,
    torque_demand_nm: [f32; DOF],
    torque_limit_nm: [f32; DOF],
    tracking_error_rad: [f32; DOF],
}

/// A joint vector in single precision.
fn single(v: &crate::robot::JointVector) -> [f32; DOF] {
    std::array::from_fn(|j| v[j] as f32)
}

/// `/robot/geometry` once: each link's primitives locked to its frame.
fn arm_geometry_messages(m: &mut Messages, robot: &RobotModel) -> Result<(), RecordError> {
    use crate::robot::LinkPrimitive;
    let name = |i: usize| link_name(robot, i);
    let colour = [0.9, 0.78, 0.24];
    let diameters = |r: f64, length_m: f64| xyz(&Vector3::new(2.0 * r, 2.0 * r, length_m));
    let mut links = Vec::new();
    for (i, link) in robot.links.iter().enumerate().take(DOF + 1) {
        let mut e = entity(0.0, format!("link {}", name(i)));
        e.frame_id = name(i);
        e.frame_locked = true;
        for s in &link.shapes {
            let at = &s.link_from_shape;
            let cylinder = |radius_m: f64, half_length_m: f64| fg::CylinderPrimitive {
                pose: pose(at),
                size: diameters(radius_m, 2.0 * half_length_m),
                bottom_scale: 1.0,
                top_scale: 1.0,
                color: rgba(colour, 1.0),
            };
            let sphere = |p: &Isometry3<f64>, radius_m: f64| fg::SpherePrimitive {
                pose: pose(p),
                size: diameters(radius_m, 2.0 * radius_m),
                color: rgba(colour, 1.0),
            };
            match &s.primitive {
                LinkPrimitive::Box { half_extents_m } => e.cubes.push(cube(at, &(2.0 * half_extents_m), colour, 1.0)),
                LinkPrimitive::Cylinder {
                    radius_m,
                    half_length_m,
                } => e.cylinders.push(cylinder(*radius_m, *half_length_m)),
                LinkPrimitive::Sphere { radius_m } => e.spheres.push(sphere(at, *radius_m)),
                LinkPrimitive::Capsule {
                    radius_m,
                    half_length_m,
                } => {
                    // A cylinder and two end spheres.
                    e.cylinders.push(cylinder(*radius_m, *half_length_m));
                    for end in [-half_length_m, *half_length_m] {
                        e.spheres
                            .push(sphere(&(at * nalgebra::Translation3::new(0.0, 0.0, end)), *radius_m));
                    }
                }
            }
        }
        links.push(e);
    }
    m.proto(0.0, Topic::RobotGeometry, &scene_update(links))
}

/// `/tf` at 50 Hz, `/robot/joint_states` and `/robot/servo` at 100 Hz.
fn arm_messages(m: &mut Messages, result: &Recording, robot: &RobotModel) -> Result<(), RecordError> {
    let name = |i: usize| link_name(robot, i);
    let limit = robot.torque_limit_nm();
    let joint_names: Vec<String> = (0..DOF)
        .map(|j| {
            robot
                .joints
                .get(j)
                .map_or_else(|| format!("joint_{}", j + 1), |jt| jt.name.clone())
        })
        .collect();
    for t in joint_state_ticks(result) {
        let joints = (0..DOF)
            .map(|j| fg::JointState {
                name: joint_names[j].clone(),
                position: Some(t.q[j]),
                velocity: Some(t.qd[j]),
                acceleration: None,
                effort: Some(t.tau_nm[j]),
            })
            .collect();
        m.proto(
            t.t_s,
            Topic::JointStates,
            &fg::JointStates {
                timestamp: stamp(t.t_s),
                joints,
            },
        )?;
        m.json(
            t.t_s,
            Topic::Servo,
            &ServoState {
                t_s: t.t_s,
                torque_demand_nm: single(&t.demand_nm),
                torque_limit_nm: single(&limit),
                tracking_error_rad: single(&t.error_rad),
            },
        )?;
    }
    let transform = |t_s: f64, parent: String, child: String, p: &Isometry3<f64>| fg::FrameTransform {
        timestamp: stamp(t_s),
        parent_frame_id: parent,
        child_frame_id: child,
        translation: xyz(&p.translation.vector),
        rotation: quaternion(p),
    };
    // The serial chain's tree: link i's parent is link i - 1 (the model is built from the URDF's
    // chain, base to flange), so a URDF drawn from `/robot_description` moves with the arm.
    for (t_s, q) in arm_samples(result) {
        let world_from_links = robot.world_from_links(&q);
        let mut transforms = Vec::with_capacity(DOF + 2);
        for (i, world_from_link) in world_from_links.iter().enumerate().take(DOF + 1) {
            let (parent, parent_from_link) = match i {
                0 => ("world".to_string(), *world_from_link),
                _ => (name(i - 1), world_from_links[i - 1].inv_mul(world_from_link)),
            };
            transforms.push(transform(t_s, parent, name(i), &parent_from_link));
        }
        transforms.push(transform(
            t_s,
            "world".into(),
            "camera".into(),
            &result.camera.world_from_camera,
        ));
        m.proto(t_s, Topic::Tf, &fg::FrameTransforms { transforms })?;
    }
    Ok(())
}

/// `/parts`: all parts as one entity, a cube per part (its bounding box), coloured by state.
fn part_messages(m: &mut Messages, result: &Recording) -> Result<(), RecordError> {
    let size = Vector3::from(result.part_size_m);
    for f in &result.scene_frames {
        let mut e = entity(f.t_s, "parts");
        e.cubes = f
            .parts
            .iter()
            .filter(|(state, _)| *state != crate::physics::PartState::Removed)
            .map(|(state, p)| cube(p, &size, part_rgb(*state), 1.0))
            .collect();
        m.proto(f.t_s, Topic::Parts, &scene_update(vec![e]))?;
    }
    Ok(())
}

/// A capture's depth image as Foxglove's raw image (16-bit mm, camera frame).
fn raw_depth(t_s: f64, cap: &CaptureImage) -> fg::RawImage {
    fg::RawImage {
        timestamp: stamp(t_s),
        frame_id: "camera".into(),
        width: cap.size_px.0 as u32,
        height: cap.size_px.1 as u32,
        encoding: "16UC1".into(),
        step: 2 * cap.size_px.0 as u32,
        data: cap.depth_le_bytes().into(),
    }
}

/// `/camera/*` at each trigger time; `/recognition` and `/recognition/truth_at_trigger` when each
/// result arrived.
fn sensing_messages(m: &mut Messages, result: &Recording) -> Result<(), RecordError> {
    let c = &result.camera;
    let float32 = |name: &str, offset: u32| fg::PackedElementField {
        name: name.into(),
        offset,
        r#type: fg::packed_element_field::NumericType::Float32 as i32,
    };
    for cap in &result.captures {
        let t = cap.t_s;
        if cap.confirming {
            m.proto(t, Topic::ConfirmingDepth, &raw_depth(t, cap))?;
            continue;
        }
        m.proto(
            t,
            Topic::Calibration,
            &fg::CameraCalibration {
                timestamp: stamp(t),
                frame_id: "camera".into(),
                width: c.width_px as u32,
                height: c.height_px as u32,
                distortion_model: "plumb_bob".into(),
                d: vec![0.0; 5],
                k: vec![c.fx_px, 0.0, c.cx_px, 0.0, c.fy_px, c.cy_px, 0.0, 0.0, 1.0],
                r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                p: vec![
                    c.fx_px, 0.0, c.cx_px, 0.0, 0.0, c.fy_px, c.cy_px, 0.0, 0.0, 0.0, 1.0, 0.0,
                ],
            },
        )?;
        m.proto(t, Topic::Depth, &raw_depth(t, cap))?;
        let points = cap.points_le_bytes();
        m.proto(
            t,
            Topic::Points,
            &fg::PointCloud {
                timestamp: stamp(t),
                frame_id: "world".into(),
                pose: pose(&Isometry3::identity()),
                point_stride: 12,
                fields: vec![float32("x", 0), float32("y", 4), float32("z", 8)],
                data: points.into(),
            },
        )?;
    }
    let size = Vector3::from(result.part_size_m);
    // Arrows point along their pose's +x: turn +x to -z (down onto the grasp point).
    let down = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    for t in &result.truths {
        let mut truth = entity(t.t_s, "true poses at the trigger");
        truth.cubes = t
            .parts
            .iter()
            .map(|(_, p)| cube(p, &size, [0.25, 0.85, 0.25], 0.25))
            .collect();
        m.proto(t.t_s, Topic::Truth, &scene_update(vec![truth]))?;
    }
    for r in &result.recognitions {
        let mut detections = entity(r.t_s, "detections");
        for ((p, _), e) in r.detections.iter().zip(&r.detection_errors) {
            let wrong = matches!(e, Some((_, _, false)));
            let colour = if wrong { [1.0, 0.15, 0.15] } else { [0.0, 0.8, 1.0] };
            detections.cubes.push(cube(p, &size, colour, 0.35));
            if let Some((dp, dr, false)) = e {
                let label = format!("wrong: {:.1} mm / {:.1} deg off", dp * 1e3, dr.to_degrees());
                detections.texts.push(text(p, colour, label));
            }
        }
        let mut candidates = entity(r.t_s, "grasp candidates");
        for (k, (p, score)) in r.candidates.iter().enumerate() {
            let chosen = r.chosen == Some(k);
            let tip = p.translation.vector + Vector3::z() * CANDIDATE_ARROW_M;
            let at = Isometry3::from_parts(nalgebra::Translation3::from(tip), down);
            let colour = if chosen { [0.0, 0.9, 0.0] } else { [0.95, 0.8, 0.0] };
            candidates.arrows.push(fg::ArrowPrimitive {
                pose: pose(&at),
                shaft_length: 0.7 * CANDIDATE_ARROW_M,
                shaft_diameter: 0.001,
                head_length: 0.3 * CANDIDATE_ARROW_M,
                head_diameter: 0.003,
                color: rgba(colour, 1.0),
            });
            if chosen {
                let label = format!("chosen: #{} score {score:.2}", k + 1);
                candidates.texts.push(text(&at, colour, label));
            }
        }
        m.proto(r.t_s, Topic::Recognition, &scene_update(vec![detections, candidates]))?;
    }
    Ok(())
}

/// `/paths`: each motion's tool path, planned (blue) and executed (orange), shown for the motion's
/// duration plus a second.
fn path_messages(m: &mut Messages, result: &Recording) -> Result<(), RecordError> {
    for p in &result.tool_paths {
        let mut e = entity(p.t_s, format!("motion {}", p.motion));
        let shown_ns = nanos(p.duration_s + 1.0);
        e.lifetime = Some(fg::Duration::new(
            (shown_ns / 1_000_000_000) as i32,
            (shown_ns % 1_000_000_000) as u32,
        ));
        let strip = fg::line_primitive::Type::LineStrip;
        e.lines = vec![
            line(strip, &p.planned_m, [0.2, 0.4, 1.0]),
            line(strip, &p.executed_m, [1.0, 0.5, 0.0]),
        ];
        m.proto(p.t_s, Topic::Paths, &scene_update(vec![e]))?;
    }
    Ok(())
}

/// The takt of a placed pick, at its release.
#[derive(Serialize)]
struct Takt {
    t_s: f64,
    pick: usize,
    takt_s: f64,
    spans_refill: bool,
}

/// `/log` and `/cycle/events` for every cycle event; `/cycle/takt` at every placed pick's release.
fn event_messages(m: &mut Messages, result: &Recording) -> Result<(), RecordError> {
    for e in &result.events {
        let name = e.pick.map_or("cell".to_string(), |p| format!("pick {p}"));
        m.proto(
            e.t_s,
            Topic::Log,
            &fg::Log {
                timestamp: stamp(e.t_s),
                level: event_level(e).into(),
                message: event_text(e),
                name,
                file: String::new(),
                line: 0,
            },
        )?;
        m.json(e.t_s, Topic::Events, e)?;
    }
    for t in &result.takts {
        let takt = Takt {
            t_s: t.release_s,
            pick: t.pick,
            takt_s: t.takt_s,
            spans_refill: t.spans_refill,
        };
        m.json(t.release_s, Topic::Takt, &takt)?;
    }
    Ok(())
}
