//! Recordings: `binpick run` writes `run.rrd` and `run.mcap`; each is read back with its format's
//! own reader (the rerun decoder; the mcap crate's reader, with the protobuf messages decoded by
//! prost-reflect from the schemas the file carries, not by the writer's message types) and
//! compared with what the run did (its events, captures, recognition results, placed picks,
//! properties) and with each other.

use std::collections::BTreeMap;

use crate::support::{Workspace, binpick_in, stderr};

/// What an .rrd holds, read with rerun's own decoder: rows per entity path (static rows counted
/// apart), the timelines of the temporal chunks, the property names, the application id.
#[derive(Debug, Default)]
struct RrdContents {
    rows: BTreeMap<String, usize>,
    static_rows: BTreeMap<String, usize>,
    timelines: std::collections::BTreeSet<String>,
    properties: std::collections::BTreeSet<String>,
    /// Distinct recording stores (the run) and blueprint stores (the viewer layout).
    stores: usize,
    blueprints: usize,
    store_ids: std::collections::BTreeSet<String>,
    /// Rows of the layout's views.
    blueprint_views: usize,
    /// Per joint (1-based): the rows of `joints/torque/J<i>` as [applied, +limit, -limit, demanded].
    torques: BTreeMap<usize, Vec<Vec<f64>>>,
    /// The rows of `world/cloud`: each capture's points [m, world].
    clouds: Vec<Vec<[f32; 3]>>,
}

fn read_rrd(path: &std::path::Path) -> RrdContents {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::external::re_log_types::LogMsg;
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut c = RrdContents::default();
    for msg in DecoderApp::decode_eager(file).expect("an rrd stream") {
        match msg.expect("every message decodes") {
            LogMsg::SetStoreInfo(info) => {
                assert_eq!(info.info.application_id().as_str(), "binpick");
                if c.store_ids.insert(format!("{:?}", info.info.store_id)) {
                    if info.info.store_id.is_blueprint() {
                        c.blueprints += 1;
                    } else {
                        c.stores += 1;
                    }
                }
            }
            LogMsg::ArrowMsg(store, arrow) => {
                let chunk = rerun::log::Chunk::from_arrow_msg(&arrow).expect("a chunk");
                let entity = chunk.entity_path().to_string();
                if store.is_blueprint() {
                    if entity.starts_with("/view/") && !entity.ends_with("ViewContents") {
                        c.blueprint_views += chunk.num_rows();
                    }
                    continue;
                }
                if entity.starts_with("/__properties") {
                    c.properties
                        .extend(chunk.components_identifiers().map(|i| i.to_string()));
                }
                if let Some(j) = entity.strip_prefix("/joints/torque/J")
                    && !chunk.is_static()
                {
                    let rows = c.torques.entry(j.parse().unwrap()).or_default();
                    for values in chunk.iter_slices::<f64>("Scalars:scalars".into()) {
                        rows.push(values.to_vec());
                    }
                }
                if entity == "/world/cloud" {
                    for points in chunk.iter_slices::<[f32; 3]>("Points3D:positions".into()) {
                        c.clouds.push(points.to_vec());
                    }
                }
                if chunk.is_static() {
                    *c.static_rows.entry(entity).or_default() += chunk.num_rows();
                } else {
                    c.timelines.extend(chunk.timelines().keys().map(|t| t.to_string()));
                    *c.rows.entry(entity).or_default() += chunk.num_rows();
                }
            }
            LogMsg::BlueprintActivationCommand(_) => {}
        }
    }
    c
}

/// A protobuf field's value as JSON: bytes as base64, enums as their numbers.
fn proto_value_json(v: &prost_reflect::Value) -> serde_json::Value {
    use prost_reflect::Value as V;
    use serde_json::json;
    match v {
        V::Bool(b) => json!(b),
        V::I32(x) | V::EnumNumber(x) => json!(x),
        V::I64(x) => json!(x),
        V::U32(x) => json!(x),
        V::U64(x) => json!(x),
        V::F32(x) => json!(x),
        V::F64(x) => json!(x),
        V::String(x) => json!(x),
        V::Bytes(b) => {
            use base64::Engine;
            json!(base64::engine::general_purpose::STANDARD.encode(b))
        }
        V::Message(m) => proto_json(m),
        V::List(l) => l.iter().map(proto_value_json).collect(),
        V::Map(_) => panic!("no map fields in the recorded schemas"),
    }
}

/// A decoded protobuf message as JSON with the schema's own field names: every field the schema
/// declares, at its default when unset, but fields with presence left out when unset.
fn proto_json(m: &prost_reflect::DynamicMessage) -> serde_json::Value {
    use prost_reflect::ReflectMessage;
    let mut o = serde_json::Map::new();
    for f in m.descriptor().fields() {
        if f.supports_presence() && !m.has_field(&f) {
            continue;
        }
        o.insert(f.name().to_string(), proto_value_json(&m.get_field(&f)));
    }
    serde_json::Value::Object(o)
}

/// Decodes MCAP messages by their channel's encoding: JSON as is, protobuf from the descriptor
/// set in the channel's schema (the message named as the schema).
#[derive(Default)]
pub(crate) struct McapDecoder(BTreeMap<u16, prost_reflect::MessageDescriptor>);

impl McapDecoder {
    pub(crate) fn decode(&mut self, m: &mcap::Message) -> Result<serde_json::Value, String> {
        let schema = m.channel.schema.as_ref().ok_or("no schema")?;
        match (m.channel.message_encoding.as_str(), schema.encoding.as_str()) {
            ("json", "jsonschema") => serde_json::from_slice(&m.data).map_err(|e| e.to_string()),
            ("protobuf", "protobuf") => {
                let desc = match self.0.entry(schema.id) {
                    std::collections::btree_map::Entry::Occupied(e) => e.get().clone(),
                    std::collections::btree_map::Entry::Vacant(e) => {
                        let pool =
                            prost_reflect::DescriptorPool::decode(&schema.data[..]).map_err(|e| e.to_string())?;
                        let desc = pool
                            .get_message_by_name(&schema.name)
                            .ok_or(format!("{} is not in its descriptor set", schema.name))?;
                        e.insert(desc).clone()
                    }
                };
                let message = prost_reflect::DynamicMessage::decode(desc, &m.data[..]).map_err(|e| e.to_string())?;
                Ok(proto_json(&message))
            }
            (e, s) => Err(format!("message encoding {e} with schema encoding {s}")),
        }
    }
}

/// Whether `v` [m] lies on the recorded clouds' grid.
fn on_cloud_grid(v: f32) -> bool {
    let k = f64::from(v) / binpick::recording::CLOUD_GRID_M;
    (k - k.round()).abs() < 1e-3
}

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
            "binpick.Properties",
            "binpick.ServoState",
            "binpick.Takt",
            "foxglove.CameraCalibration",
            "foxglove.FrameTransforms",
            "foxglove.JointStates",
            "foxglove.Log",
            "foxglove.PointCloud",
            "foxglove.RawImage",
            "foxglove.SceneUpdate",
            "std_msgs/String"
        ]
    );
    let mut topics: Vec<&str> = summary.channels.values().map(|c| c.topic.as_str()).collect();
    topics.sort();
    assert_eq!(
        topics,
        [
            "/camera/calibration",
            "/camera/confirming_depth",
            "/camera/depth",
            "/camera/points",
            "/cell",
            "/cycle/events",
            "/cycle/properties",
            "/cycle/takt",
            "/log",
            "/parts",
            "/paths",
            "/recognition",
            "/recognition/truth_at_trigger",
            "/robot/geometry",
            "/robot/joint_states",
            "/robot/servo",
            "/robot_description",
            "/tf"
        ]
    );
    // Foxglove's well-known schemas as protobuf (descriptor sets), ours as JSON.
    for c in summary.channels.values() {
        let schema = c.schema.as_ref().unwrap();
        let (schema_encoding, message_encoding) = if schema.name.starts_with("foxglove.") {
            ("protobuf", "protobuf")
        } else {
            ("jsonschema", "json")
        };
        assert_eq!(
            (schema.encoding.as_str(), c.message_encoding.as_str()),
            (schema_encoding, message_encoding),
            "{}",
            c.topic
        );
    }
    assert!(!summary.chunk_indexes.is_empty(), "chunked");
    assert!(summary.chunk_indexes.iter().all(|c| c.compression == "zstd"));
    let meta = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).unwrap();
    assert_eq!(meta.name, "binpick");
    assert_eq!(meta.metadata["seed"], "1");
    assert_eq!(meta.metadata["workpiece"], "E");
    assert_eq!(meta.metadata["deterministic"], "true");

    let mut count = BTreeMap::<String, usize>::new();
    let mut chosen = 0;
    let mut mcap_torques: Vec<Vec<f64>> = Vec::new();
    let mut mcap_demands: Vec<Vec<f64>> = Vec::new();
    let mut joint_times = (Vec::new(), Vec::new());
    let mut mcap_clouds: Vec<Vec<[f32; 3]>> = Vec::new();
    let mut last = 0u64;
    let mut parts_span = (u64::MAX, 0u64);
    let mut decoder = McapDecoder::default();
    let mut truncated_seen = false;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        assert!(m.log_time >= last, "log times go back on {}", m.channel.topic);
        last = m.log_time;
        *count.entry(m.channel.topic.clone()).or_default() += 1;
        let v = decoder
            .decode(&m)
            .unwrap_or_else(|e| panic!("{} does not decode: {e}", m.channel.topic));
        // Negative control: the decoder notices a message cut short.
        if m.channel.topic == "/camera/depth" && !truncated_seen {
            let mut cut = m.clone();
            cut.data = std::borrow::Cow::Owned(m.data[..m.data.len() - 1].to_vec());
            assert!(decoder.decode(&cut).is_err(), "a truncated RawImage decodes");
            truncated_seen = true;
        }
        if m.channel.topic == "/camera/depth" {
            use base64::Engine;
            let data = base64::engine::general_purpose::STANDARD
                .decode(v["data"].as_str().unwrap())
                .unwrap();
            let (w, h) = (v["width"].as_u64().unwrap(), v["height"].as_u64().unwrap());
            assert_eq!(data.len() as u64, 2 * w * h);
            assert_eq!(v["encoding"], "16UC1");
        }
        if m.channel.topic == "/camera/points" {
            use base64::Engine;
            let data = base64::engine::general_purpose::STANDARD
                .decode(v["data"].as_str().unwrap())
                .unwrap();
            assert_eq!(v["point_stride"], 12);
            assert_eq!(v["frame_id"], "world");
            let fields: Vec<(&str, u64, u64)> = v["fields"]
                .as_array()
                .unwrap()
                .iter()
                .map(|f| {
                    let (name, offset, kind) = (&f["name"], &f["offset"], &f["type"]);
                    (name.as_str().unwrap(), offset.as_u64().unwrap(), kind.as_u64().unwrap())
                })
                .collect();
            assert_eq!(fields, [("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], "float32 x, y, z");
            assert!(!data.is_empty() && data.len().is_multiple_of(12));
            let cloud: Vec<[f32; 3]> = data
                .chunks(12)
                .map(|p| std::array::from_fn(|k| f32::from_le_bytes(p[4 * k..4 * k + 4].try_into().unwrap())))
                .collect();
            // Points lie in the cell: above the table, below the camera; on the recorded grid.
            for p in &cloud {
                assert!((-0.01..1.1).contains(&p[2]), "point at z {}", p[2]);
                assert!(p.iter().all(|v| on_cloud_grid(*v)), "{p:?} off the grid");
            }
            mcap_clouds.push(cloud);
        }
        if m.channel.topic == "/recognition" {
            let entities = v["entities"].as_array().unwrap();
            assert_eq!(entities.len(), 2, "detections and candidates");
            chosen += entities[1]["texts"].as_array().unwrap().len();
        }
        if m.channel.topic == "/robot/geometry" {
            for e in v["entities"].as_array().unwrap() {
                assert_eq!(e["frame_locked"], true);
                let shapes = ["cubes", "cylinders", "spheres"]
                    .iter()
                    .map(|k| e[k].as_array().unwrap().len())
                    .sum::<usize>();
                assert!(shapes > 0, "{e}");
            }
        }
        if m.channel.topic == "/parts" {
            parts_span = (parts_span.0.min(m.log_time), parts_span.1.max(m.log_time));
            assert_eq!(v["entities"].as_array().unwrap().len(), 1, "all parts as one entity");
            assert!(!v["entities"][0]["cubes"].as_array().unwrap().is_empty());
        }
        if m.channel.topic == "/robot/joint_states" {
            // foxglove.JointStates: the URDF's joints with position, velocity and applied torque.
            let joints = v["joints"].as_array().unwrap();
            let names: Vec<&str> = joints.iter().map(|j| j["name"].as_str().unwrap()).collect();
            assert_eq!(
                names,
                ["joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6"]
            );
            for j in joints {
                assert!(["position", "velocity", "effort"].iter().all(|k| j[k].is_f64()), "{j}");
            }
            mcap_torques.push(joints.iter().map(|j| j["effort"].as_f64().unwrap()).collect());
            joint_times.0.push(m.log_time);
        }
        if m.channel.topic == "/robot/servo" {
            let demand = v["torque_demand_nm"].as_array().unwrap();
            let limit = v["torque_limit_nm"].as_array().unwrap();
            mcap_demands.push(demand.iter().map(|t| t.as_f64().unwrap()).collect());
            assert_eq!(
                (
                    demand.len(),
                    limit.len(),
                    v["tracking_error_rad"].as_array().unwrap().len()
                ),
                (6, 6, 6)
            );
            // What was demanded, not what the clamp let through, stays within each limit.
            for (d, l) in demand.iter().zip(limit) {
                assert!(d.as_f64().unwrap().abs() <= l.as_f64().unwrap());
            }
            joint_times.1.push(m.log_time);
        }
    }
    // Every stage of the cycle is a log entry.
    for kind in [
        "capture",
        "recognition_ready",
        "grasp_chosen",
        "planned",
        "stall",
        "pick_start",
        "place_start",
        "released",
        "outcome",
    ] {
        assert!(events.iter().any(|e| e["kind"] == kind), "no {kind} event");
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
    // Part frames every 0.1 s of simulated time, from the first pile pour's first step to the end.
    let (first, last) = parts_span;
    assert!(
        first <= 10_000_000,
        "parts recorded from the pour on: first frame at {first} ns"
    );
    let span_s = (last - first) as f64 * 1e-9;
    let frames = count["/parts"] as f64;
    assert!(
        (frames - (span_s / 0.1 + 1.0)).abs() <= 2.0,
        "{frames} part frames over {span_s} s"
    );
    assert!(last as f64 * 1e-9 <= run_summary["sim_time_s"].as_f64().unwrap() + 1e-6);

    let captures = run_summary["captures"][0].as_u64().unwrap() as usize;
    assert_eq!(count["/camera/points"], captures);
    assert_eq!(count["/camera/calibration"], captures);
    let ready = events.iter().filter(|e| e["kind"] == "recognition_ready").count();
    let used = events.iter().filter(|e| e["kind"] == "result_used").count();
    assert_eq!(
        count["/recognition"], used,
        "a recognition message per pick's look into a result"
    );
    assert_eq!(
        count["/recognition/truth_at_trigger"], ready,
        "the true poses at the trigger beside every result"
    );
    let grasps = events.iter().filter(|e| e["kind"] == "grasp_chosen").count();
    assert_eq!(chosen, grasps, "the chosen candidate is marked once per chosen grasp");
    assert_eq!(count["/cell"], 1);
    assert_eq!(count["/robot/geometry"], 1);
    assert_eq!(joint_times.0, joint_times.1, "servo states beside the joint states");
    // Negative control of the grid check: a point off the grid is seen.
    assert!(!on_cloud_grid(0.123_456_7));

    // The Rerun file, read with rerun's decoder: the same run.
    let rrd = read_rrd(&dir.join("run.rrd"));
    assert_eq!(rrd.stores, 1, "one recording");
    assert_eq!(rrd.blueprints, 1, "one viewer layout");
    // The layout: the cell, the depth camera and the confirming exposures, the events, six
    // torques, positions, velocities, tracking errors, takt.
    assert_eq!(rrd.blueprint_views, 14);
    let rows = |e: &str| rrd.rows.get(e).copied().unwrap_or(0);
    // E is never confirmed: no confirming exposure in either file.
    assert_eq!(count.get("/camera/confirming_depth"), None);
    assert_eq!(rows("/sensor/confirming_depth"), 0);
    assert_eq!(
        rrd.timelines,
        ["sim_time", "step"].iter().map(|s| s.to_string()).collect(),
        "simulation time only, no wall clock"
    );
    for p in ["seed", "workpiece", "scene", "deterministic", "binpick_version"] {
        assert!(
            rrd.properties.iter().any(|c| c.ends_with(p)),
            "property {p}: {:?}",
            rrd.properties
        );
    }
    assert_eq!(rows("/events"), events.len());
    assert_eq!(rows("/cycle/takt"), takts);
    assert_eq!(rows("/world/camera/depth"), captures);
    assert_eq!(rows("/world/cloud"), captures);
    // The same cloud in both files, point for point (both on the same grid).
    assert_eq!(rrd.clouds.len(), mcap_clouds.len());
    for (rrd_cloud, cloud) in rrd.clouds.iter().zip(&mcap_clouds) {
        let key = |p: &[f32; 3]| p.map(f32::to_bits);
        assert!(cloud.len() > 1000, "{} points", cloud.len());
        assert!(rrd_cloud.iter().map(key).eq(cloud.iter().map(key)), "the clouds differ");
        // Negative control: a point moved by one grid step is not in the cloud.
        let all: std::collections::BTreeSet<[u32; 3]> = cloud.iter().map(key).collect();
        let mut moved = rrd_cloud[0];
        moved[0] += binpick::recording::CLOUD_GRID_M as f32;
        assert!(!all.contains(&key(&moved)));
    }
    assert_eq!(rows("/world/recognition/detections"), used);
    assert_eq!(rows("/world/recognition/candidates"), used);
    assert_eq!(rows("/world/recognition/truth_at_trigger"), ready);
    assert_eq!(
        rows("/world/parts"),
        count["/parts"],
        "parts at the same times in both files"
    );
    assert_eq!(rows("/world/paths/planned"), count["/paths"]);
    assert_eq!(rows("/joints/position"), count["/robot/joint_states"]);
    assert_eq!(rows("/joints/tracking_error"), count["/robot/joint_states"]);
    for j in 1..=6 {
        assert_eq!(rows(&format!("/joints/torque/J{j}")), count["/robot/joint_states"]);
        assert_eq!(rows(&format!("/world/arm/link_{j}")), count["/tf"]);
    }
    // The torque series hold the same torques as the MCAP's joint states, within the limits.
    let scene = binpick::config::LoadedScene::embedded_default().unwrap();
    let limit = binpick::robot::RobotModel::from_scene(&scene)
        .unwrap()
        .torque_limit_nm();
    for j in 1..=6 {
        let rows = &rrd.torques[&j];
        assert_eq!(rows.len(), mcap_torques.len());
        for ((row, mcap), demand) in rows.iter().zip(&mcap_torques).zip(&mcap_demands) {
            assert_eq!(row.len(), 4);
            // The MCAP's servo states are single precision.
            let single = 1e-6 * row[3].abs().max(1.0);
            assert!((row[3] - demand[j - 1]).abs() <= single, "J{j} demand {row:?}");
            assert!(
                (row[0] - mcap[j - 1]).abs() <= 1e-9,
                "J{j}: {} against {}",
                row[0],
                mcap[j - 1]
            );
            assert!(
                row[1] == limit[j - 1] && row[2] == -limit[j - 1],
                "J{j} limit lines {row:?}"
            );
            assert!(row[0].abs() <= limit[j - 1] + 1e-9);
        }
    }
    for e in ["/world/cell", "/world/camera", "/world/arm/link_3/geometry/0"] {
        assert!(
            rrd.static_rows.get(e).copied().unwrap_or(0) >= 1,
            "{e} static: {:?}",
            rrd.static_rows
        );
    }

    // --no-rrd and --no-mcap each skip one file; both skip both.
    for (skip, rrd_kept, mcap_kept) in [
        (&["--no-rrd"][..], false, true),
        (&["--no-mcap"][..], true, false),
        (&["--no-rrd", "--no-mcap"][..], false, false),
    ] {
        let mut a = args.to_vec();
        a.extend_from_slice(skip);
        let o = binpick_in(ws.dir.path(), &a);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(dir.join("run.rrd").exists(), rrd_kept, "{skip:?}");
        assert_eq!(dir.join("run.mcap").exists(), mcap_kept, "{skip:?}");
        assert!(
            std::fs::read_dir(&dir)
                .unwrap()
                .all(|f| !f.unwrap().path().to_string_lossy().ends_with(".partial"))
        );
    }
}

/// Ctrl-C during a run: the pick under way finishes, every file is written and readable, the
/// summary says `interrupted`, and the exit code is 130.
#[cfg(unix)]
/// A confirming exposure (B's blocks are confirmed) is in both files apart from the images
/// recognition read: one `/camera/confirming_depth` image and `/sensor/confirming_depth` row per
/// `confirming_capture` event, and the camera's depth images and clouds one per other capture.
/// (The control, E, which is never confirmed, has none: `run_mcap_holds_what_the_run_did`.)
#[test]
fn confirming_exposures_are_recorded_apart_from_the_images_recognition_read() {
    let ws = Workspace::new();
    let out = ws.path("out");
    let args = ["run", "--workpiece", "B", "--picks", "25", "--deterministic", "--out"];
    let o = binpick_in(ws.dir.path(), &[&args[..], &[out.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = out.join("run-B-seed1-det");
    let events: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(dir.join("events.json")).unwrap()).unwrap();
    let kind = |k: &str| events.iter().filter(|e| e["kind"] == k).count();
    let (confirming, captures) = (kind("confirming_capture"), kind("capture"));
    assert!(confirming >= 1 && captures > confirming, "{confirming} of {captures}");
    let bytes = std::fs::read(dir.join("run.mcap")).unwrap();
    let mut count = BTreeMap::<String, usize>::new();
    let mut decoder = McapDecoder::default();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let v = decoder.decode(&m).unwrap();
        if m.channel.topic == "/camera/confirming_depth" {
            assert_eq!(
                (v["encoding"].as_str(), v["frame_id"].as_str()),
                (Some("16UC1"), Some("camera"))
            );
        }
        *count.entry(m.channel.topic.clone()).or_default() += 1;
    }
    assert_eq!(count["/camera/confirming_depth"], confirming);
    assert_eq!(count["/camera/depth"], captures);
    assert_eq!(count["/camera/points"], captures);
    let rrd = read_rrd(&dir.join("run.rrd"));
    let rows = |e: &str| rrd.rows.get(e).copied().unwrap_or(0);
    assert_eq!(rows("/sensor/confirming_depth"), confirming);
    assert_eq!(rows("/world/camera/depth"), captures);
    assert_eq!(rows("/world/cloud"), captures);
    // The run's capture count holds every exposure the sensor took.
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["captures"][0].as_u64(), Some((captures + confirming) as u64));
}

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
    assert_eq!(summary.channels.len(), 18);
    assert!(mcap::MessageStream::new(&bytes).unwrap().all(|m| m.is_ok()));
    let rrd = read_rrd(&dir.join("run.rrd"));
    assert_eq!(rrd.stores, 1);
    assert!(
        rrd.rows.get("/events").copied().unwrap_or(0) > 0,
        "{:?}",
        rrd.rows.keys()
    );
}

/// A recording that cannot be written is an error naming the cause, and leaves no file behind
/// (neither the final name nor the `.partial` one).
#[test]
fn a_failed_write_is_reported_and_leaves_nothing() {
    use binpick::config::{LoadedScene, LoadedWorkpiece};
    use binpick::cycle::RunOptions;
    use binpick::recording::{Formats, RunInfo, write_recordings};
    use binpick::robot::RobotModel;
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("E").unwrap();
    let camera = binpick::sensor::Camera::from_config(&scene.scene.sensor).unwrap();
    let mut recorder = binpick::recording::Recorder::new(
        &robot,
        &camera,
        &binpick::geometry::TrayVolume::new(&scene.scene.pick_tray),
        wp.workpiece.size_m,
    );
    let opts = RunOptions {
        picks: 1,
        seed: 1,
        deterministic: true,
        stop: None,
        keep_records: true,
    };
    binpick::cycle::run(&scene, &robot, &wp, &opts, &mut recorder).unwrap();
    let r = recorder.finish();
    let info = RunInfo {
        scene: scene.label.clone(),
        workpiece: "E".into(),
        seed: 1,
        deterministic: true,
        picks: 1,
        robot_description: scene.urdf_text.clone(),
    };
    let ws = Workspace::new();
    let formats = Formats { rrd: true, mcap: true };
    // A folder that does not exist: both writers fail before writing anything.
    let missing = ws.path("missing");
    let (path, e) = write_recordings(&missing, "run", formats, &r, &robot, &scene.scene, &info).unwrap_err();
    assert!(path.starts_with(&missing), "{}", path.display());
    assert!(!e.to_string().is_empty());
    assert!(!missing.exists());
    // The folder exists: both files are written, nothing partial stays.
    let dir = ws.path("ok");
    std::fs::create_dir_all(&dir).unwrap();
    let written = write_recordings(&dir, "run", formats, &r, &robot, &scene.scene, &info).unwrap();
    assert_eq!(written, [dir.join("run.rrd"), dir.join("run.mcap")]);
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|f| f.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["run.mcap", "run.rrd"]);
    let rrd = read_rrd(&dir.join("run.rrd"));
    assert_eq!(rrd.rows.get("/world/camera/depth").copied(), Some(r.captures.len()));
}

/// A recording streamed as the run goes (handed on part by part, `STREAM_LAG_S` behind the
/// simulation, so that an all-day run's memory stays flat) is the recording of the whole run: its
/// MCAP holds the same bytes as the one written from the whole run at its end, its messages in
/// log-time order, nothing reported late, and its .rrd the same rows. Negative control: the whole
/// run's file without its last takt differs.
#[test]
fn a_streamed_recording_is_the_whole_runs() {
    use binpick::config::{LoadedScene, LoadedWorkpiece};
    use binpick::cycle::RunOptions;
    use binpick::recording::{Formats, Recorder, RecordingFiles, RunInfo, write_recordings};
    use binpick::robot::RobotModel;
    let scene = LoadedScene::embedded_default().unwrap();
    let robot = RobotModel::from_scene(&scene).unwrap();
    let wp = LoadedWorkpiece::resolve("E").unwrap();
    let camera = binpick::sensor::Camera::from_config(&scene.scene.sensor).unwrap();
    let opts = RunOptions::deterministic(30, 1);
    let info = RunInfo {
        scene: scene.label.clone(),
        workpiece: "E".into(),
        seed: 1,
        deterministic: true,
        picks: 30,
        robot_description: scene.urdf_text.clone(),
    };
    let formats = Formats { rrd: true, mcap: true };
    let ws = Workspace::new();
    let (whole_dir, streamed_dir) = (ws.path("whole"), ws.path("streamed"));
    std::fs::create_dir_all(&whole_dir).unwrap();
    std::fs::create_dir_all(&streamed_dir).unwrap();

    let pick_tray = binpick::geometry::TrayVolume::new(&scene.scene.pick_tray);
    let mut whole = Recorder::new(&robot, &camera, &pick_tray, wp.workpiece.size_m);
    let r = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut whole).unwrap();
    let mut whole = whole.finish();
    write_recordings(&whole_dir, "run", formats, &whole, &robot, &scene.scene, &info).unwrap();

    let files = RecordingFiles::create(&streamed_dir, "run", formats, &scene.scene, &info).unwrap();
    let mut streamed = Recorder::streaming(&robot, &camera, &pick_tray, wp.workpiece.size_m, files);
    let s = binpick::cycle::run(&scene, &robot, &wp, &opts, &mut streamed).unwrap();
    assert_eq!(s.tally.sim_time_s, r.tally.sim_time_s, "deterministic runs");
    assert!(
        s.tally.sim_time_s > 2.0 * binpick::recording::STREAM_LAG_S,
        "{} s: too short to stream in parts",
        s.tally.sim_time_s
    );
    // Handed on while the run went (the last part is handed on by finish_files).
    assert!(streamed.handed_on() >= 2, "{} parts", streamed.handed_on());
    assert_eq!(streamed.late(), 0);
    streamed.finish_files().unwrap();

    let whole_mcap = std::fs::read(whole_dir.join("run.mcap")).unwrap();
    let streamed_mcap = std::fs::read(streamed_dir.join("run.mcap")).unwrap();
    if whole_mcap != streamed_mcap {
        let list = |bytes: &[u8]| -> Vec<(String, u64, u32, Vec<u8>)> {
            mcap::MessageStream::new(bytes)
                .unwrap()
                .map(|m| {
                    let m = m.unwrap();
                    (m.channel.topic.clone(), m.log_time, m.sequence, m.data.to_vec())
                })
                .collect()
        };
        let (w, s) = (list(&whole_mcap), list(&streamed_mcap));
        let first = w.iter().zip(&s).position(|(a, b)| a != b);
        let show = |m: Option<&(String, u64, u32, Vec<u8>)>| m.map(|m| (m.0.clone(), m.1, m.2, m.3.len()));
        panic!(
            "the streamed MCAP differs from the whole run's: {} against {} messages; first difference at {first:?}: {:?} against {:?}",
            w.len(),
            s.len(),
            first.and_then(|k| show(w.get(k))),
            first.and_then(|k| show(s.get(k)))
        );
    }
    let mut last = 0u64;
    let mut messages = 0;
    for m in mcap::MessageStream::new(&streamed_mcap).unwrap() {
        let m = m.unwrap();
        assert!(m.log_time >= last, "log times go back on {}", m.channel.topic);
        last = m.log_time;
        messages += 1;
    }
    assert!(messages > 1000, "{messages} messages");
    let (a, b) = (
        read_rrd(&whole_dir.join("run.rrd")),
        read_rrd(&streamed_dir.join("run.rrd")),
    );
    assert_eq!(a.rows, b.rows);
    assert_eq!(a.static_rows, b.static_rows);

    // Negative control: one takt fewer is another file.
    assert!(!whole.takts.is_empty());
    whole.takts.pop();
    let cut_dir = ws.path("cut");
    std::fs::create_dir_all(&cut_dir).unwrap();
    write_recordings(&cut_dir, "run", formats, &whole, &robot, &scene.scene, &info).unwrap();
    assert!(std::fs::read(cut_dir.join("run.mcap")).unwrap() != whole_mcap);
}

/// `batch --record --no-rrd --no-mcap` keeps each run's per-pick table and event log (and its time
/// charts), no recording: byte for byte what `binpick run` writes for the same deterministic run.
/// Negative control: another seed's run writes other events, so the equality is not vacuous.
#[test]
fn a_batch_keeps_each_runs_events_without_recordings() {
    let tmp = crate::support::tempdir().unwrap();
    let out = |s: &str| tmp.path().join(s).to_str().unwrap().to_string();
    let run_ok = |args: &[&str]| {
        let o = crate::support::binpick(args);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {}", crate::support::stderr(&o));
    };
    let common = ["--picks", "5", "--deterministic", "--no-rrd", "--no-mcap"];
    run_ok(
        &[
            &[
                "batch",
                "--workpieces",
                "E",
                "--seeds",
                "1",
                "--record",
                "--out",
                &out("b"),
            ],
            &common[..],
        ]
        .concat(),
    );
    for seed in ["1", "2"] {
        run_ok(
            &[
                &["run", "--workpiece", "E", "--seed", seed, "--out", &out("r")],
                &common[..],
            ]
            .concat(),
        );
    }
    let batch = tmp.path().join("b").join("batch-E-seeds1-picks5-det");
    let read = |p: std::path::PathBuf| std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let run = |seed: &str| tmp.path().join("r").join(format!("run-E-seed{seed}-det"));
    assert_eq!(
        read(batch.join("run-E-seed1.events.json")),
        read(run("1").join("events.json"))
    );
    assert_eq!(
        read(batch.join("run-E-seed1.picks.csv")),
        read(run("1").join("picks.csv"))
    );
    assert!(batch.join("run-E-seed1.timechart.svg").is_file());
    for f in ["run-E-seed1.rrd", "run-E-seed1.mcap"] {
        assert!(!batch.join(f).exists(), "{f} written with --no-rrd --no-mcap");
    }
    let events: serde_json::Value = serde_json::from_slice(&read(batch.join("run-E-seed1.events.json"))).unwrap();
    assert!(events.as_array().is_some_and(|e| e.len() > 20), "{events}");
    assert_ne!(read(run("2").join("events.json")), read(run("1").join("events.json")));
}
