//! Record stage, Rerun: a run written to `run.rrd` through the rerun SDK's file sink, part by part
//! as it goes.
//!
//! Entities (all in `world`, z up; see the module [`super`] for what is recorded and why):
//! - `world/cell`: table, trays and obstacles as boxes (static);
//! - `world/camera`: the camera's pose and pinhole intrinsics, cropped to the recorded window over
//!   the pick tray (static; the viewer draws its frustum), `world/camera/depth` each window's
//!   depth image (mm) at its trigger time;
//! - `world/cloud`: each capture's point cloud (world frame, every
//!   [`super::CLOUD_EVERY_PX`]-th pixel each way: under the camera's pinhole the viewer draws the
//!   depth image itself in 3D at every pixel) at its trigger time;
//! - `world/arm/<link>`: each link's `world_from_link` over time (50 Hz), its collision primitives
//!   (static) under `world/arm/<link>/geometry`;
//! - `world/parts`: all parts as one batch of boxes (10 Hz), coloured by state;
//! - `world/recognition/detections` (the poses the recognition computed: cyan when within 2 mm
//!   and 5 deg of a part, red and labelled with the error when not) and
//!   `world/recognition/candidates` (arrows down to the grasp points, best first, the chosen one
//!   green and labelled) when each result arrived;
//! - `world/recognition/truth_at_trigger`: the true poses, at the trigger, of the parts the
//!   capture showed (evaluation only), when the result arrived;
//! - `world/paths/planned`, `world/paths/executed`: each motion's tool path at its start;
//! - `joints/position`, `joints/velocity`, `joints/tracking_error` (six series each, 100 Hz),
//!   `joints/torque/J<i>` (the applied torque beside +/- the joint's limit and the torque the
//!   controller demanded before saturation);
//! - `events`: the cycle's events as text log entries (faults and failed picks as warnings);
//! - `cycle/takt`: the takt of every placed pick, at its release.
//!
//! Timelines: `sim_time` (duration, s) and `step` (physics steps); the SDK's wall-clock
//! `log_time` is switched off. Units: m, rad, rad/s, N m, s; depth in mm (`meter` = 1000).

use std::path::Path;

use nalgebra::{Isometry3, Vector3};
use rerun::{RecordingStream, TimeColumn};

use super::Recording;
use super::{
    CANDIDATE_ARROW_M, RecordError, RunInfo, arm_samples, event_level, event_text, joint_state_ticks, link_name,
    part_rgb,
};
use crate::config::Scene;
use crate::physics::PartState;
use crate::robot::{DOF, LinkPrimitive, RobotModel};

fn rr(e: impl std::fmt::Display) -> RecordError {
    RecordError::Rerun(e.to_string())
}

fn v3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

fn quat(p: &Isometry3<f64>) -> rerun::Quaternion {
    let q = p.rotation.quaternion();
    rerun::Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32])
}

fn rgb(c: [f32; 3]) -> rerun::Color {
    rerun::Color::from_rgb((c[0] * 255.0) as u8, (c[1] * 255.0) as u8, (c[2] * 255.0) as u8)
}

/// The stream, and the physics step that turns simulation time into the `step` timeline.
struct Rec {
    stream: RecordingStream,
    step_s: f64,
}

impl Rec {
    fn step(&self, t_s: f64) -> i64 {
        (t_s / self.step_s).round() as i64
    }

    fn at(&self, t_s: f64) {
        self.stream.set_duration_secs("sim_time", t_s);
        self.stream.set_time_sequence("step", self.step(t_s));
    }

    fn log(&mut self, t_s: f64, path: &str, what: &impl rerun::AsComponents) -> Result<(), RecordError> {
        self.at(t_s);
        self.stream.log(path, what).map_err(rr)
    }

    fn log_static(&mut self, path: &str, what: &impl rerun::AsComponents) -> Result<(), RecordError> {
        self.stream.log_static(path, what).map_err(rr)
    }

    /// Sends `values`, `per_row` scalars (series) a row, at `times_s` in one columnar call.
    fn series(&mut self, path: &str, times_s: &[f64], values: Vec<f64>, per_row: usize) -> Result<(), RecordError> {
        let columns = rerun::Scalars::new(values)
            .columns(std::iter::repeat_n(per_row, times_s.len()))
            .map_err(rr)?;
        self.columns(path, times_s, columns)
    }

    /// Sends rows at `times_s` in one columnar call.
    fn columns(
        &mut self,
        path: &str,
        times_s: &[f64],
        columns: impl IntoIterator<Item = rerun::SerializedComponentColumn>,
    ) -> Result<(), RecordError> {
        let steps: Vec<i64> = times_s.iter().map(|t| self.step(*t)).collect();
        self.stream
            .send_columns(
                path,
                [
                    TimeColumn::new_duration_secs("sim_time", times_s.iter().copied()),
                    TimeColumn::new_sequence("step", steps),
                ],
                columns,
            )
            .map_err(rr)
    }
}

/// A `.rrd` file being written: to `<path>.partial` until [`RrdFile::finish`] flushes and
/// finalises it and renames it to `path`, so that a failed or abandoned write never leaves a
/// truncated `run.rrd` (dropped unfinished, it removes the partial file).
pub struct RrdFile {
    path: std::path::PathBuf,
    partial: std::path::PathBuf,
    rec: Option<Rec>,
    /// The pick tray's centre (m, world): the camera's image plane is drawn at its distance.
    pick_tray_center_m: Vector3<f64>,
}

impl RrdFile {
    /// Starts the recording at `path` of a run in `scene` described by `info`: the viewer's
    /// layout and the run's properties.
    pub fn create(path: &Path, scene: &Scene, info: &RunInfo) -> Result<Self, RecordError> {
        let partial = path.with_extension("rrd.partial");
        // The SDK's file sink creates the file on its own thread: a folder that is not there
        // must fail here.
        std::fs::File::create(&partial)?;
        let stream = rerun::RecordingStreamBuilder::new("binpick")
            .with_blueprint(layout())
            .enabled(true)
            .recording_name(format!("binpick {} seed {}", info.workpiece, info.seed))
            .save(&partial)
            .map_err(|e| {
                let _ = std::fs::remove_file(&partial);
                rr(e)
            })?;
        stream.set_log_time_enabled(false);
        stream.set_log_tick_enabled(false);
        let mut file = RrdFile {
            path: path.to_path_buf(),
            partial,
            rec: Some(Rec {
                stream,
                step_s: scene.sim.physics_dt_s,
            }),
            pick_tray_center_m: Vector3::from(scene.pick_tray.center_m),
        };
        let mut props = rerun::AnyValues::default();
        for (k, v) in info.properties() {
            props = props.with_component::<rerun::components::Text>(k, [v]);
        }
        let rec = file.rec.as_mut().expect("just made");
        rec.stream.send_property("binpick", &props).map_err(rr)?;
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        Ok(file)
    }

    /// Logs one part of the recording (the first one with the static cell and arm geometry).
    pub fn write(&mut self, part: &Recording, robot: &RobotModel) -> Result<(), RecordError> {
        let rec = self
            .rec
            .as_mut()
            .ok_or_else(|| RecordError::Rerun("the stream is closed".into()))?;
        if part.opening {
            log_cell(rec, part, self.pick_tray_center_m)?;
            log_arm_geometry(rec, robot)?;
        }
        log_arm(rec, part, robot)?;
        log_parts(rec, part)?;
        log_sensing(rec, part)?;
        log_paths(rec, part)?;
        log_events(rec, part)
    }

    /// Flushes and finalises the file, checks its footer and renames it to its final name.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.close()?;
        check_footer(&self.partial)?;
        std::fs::rename(&self.partial, &self.path)?;
        Ok(())
    }

    /// Flushes what was logged and reports a failed write; then hands the file sink over to a
    /// buffer, which drops it: its writer thread finishes the file (footer and manifest).
    fn close(&mut self) -> Result<(), RecordError> {
        let Some(rec) = self.rec.take() else { return Ok(()) };
        let flushed = rec.stream.flush_blocking().map_err(rr);
        rec.stream.disconnect();
        drop(rec.stream);
        flushed
    }
}

impl Drop for RrdFile {
    /// Closes the stream and removes the partial file: a finished file was renamed away.
    fn drop(&mut self) {
        let _ = self.close();
        let _ = std::fs::remove_file(&self.partial);
    }
}

/// The layout the viewer opens with: the cell in 3D beside the
/// camera's depth image and the event log, the joint series in tabs; the `sim_time` timeline.
fn layout() -> rerun::blueprint::Blueprint {
    use rerun::blueprint::{
        Blueprint, ContainerLike, Horizontal, Spatial2DView, Spatial3DView, Tabs, TextLogView, TimePanel,
        TimeSeriesView, Vertical,
    };
    let mut series: Vec<ContainerLike> = (1..=DOF)
        .map(|j| {
            TimeSeriesView::new(format!("torque J{j} [N m]"))
                .with_origin(format!("/joints/torque/J{j}"))
                .into()
        })
        .collect();
    series.push(
        TimeSeriesView::new("joint positions [rad]")
            .with_origin("/joints/position")
            .into(),
    );
    series.push(
        TimeSeriesView::new("joint velocities [rad/s]")
            .with_origin("/joints/velocity")
            .into(),
    );
    series.push(
        TimeSeriesView::new("tracking error [rad]")
            .with_origin("/joints/tracking_error")
            .into(),
    );
    series.push(TimeSeriesView::new("takt [s]").with_origin("/cycle/takt").into());
    let cell = Spatial3DView::new("cell").with_origin("/world");
    // The confirming exposures (where the part has them) in a tab behind the camera's images.
    let cameras = Tabs::new([
        Spatial2DView::new("depth camera").with_origin("/world/camera").into(),
        Spatial2DView::new("confirming exposure")
            .with_origin("/sensor/confirming_depth")
            .into(),
    ]);
    let sensing = Vertical::new([cameras.into(), TextLogView::new("events").with_origin("/events").into()]);
    Blueprint::new(
        Horizontal::new([cell.into(), sensing.into(), Tabs::new(series).into()]).with_column_shares([3.0, 2.0, 2.0]),
    )
    .with_time_panel(TimePanel::new().with_timeline("sim_time"))
}

/// Reads the stream footer at the end of a finished .rrd file.
fn check_footer(path: &Path) -> Result<(), RecordError> {
    use rerun::external::re_log_encoding::{Decodable, StreamFooter};
    use std::io::{Read, Seek, SeekFrom};
    let size = StreamFooter::ENCODED_SIZE_BYTES;
    let mut f = std::fs::File::open(path)?;
    let len = f.metadata()?.len();
    if len < size as u64 {
        return Err(RecordError::Rerun(format!(
            "{} is {len} bytes: not finalised",
            path.display()
        )));
    }
    f.seek(SeekFrom::End(-(size as i64)))?;
    let mut tail = vec![0; size];
    f.read_exact(&mut tail)?;
    StreamFooter::from_rrd_bytes(&tail)
        .map(|_| ())
        .map_err(|e| RecordError::Rerun(format!("{}: not finalised: {e}", path.display())))
}

/// Table, trays, obstacles and the camera (static).
fn log_cell(rec: &mut Rec, result: &Recording, pick_tray_center_m: Vector3<f64>) -> Result<(), RecordError> {
    let cell = &result.cell_boxes;
    let boxes = rerun::Boxes3D::from_centers_and_half_sizes(
        cell.iter().map(|b| v3(&b.world_from_box.translation.vector)),
        cell.iter().map(|b| v3(&b.half_m)),
    )
    .with_quaternions(cell.iter().map(|b| quat(&b.world_from_box)))
    .with_labels(cell.iter().map(|b| b.name.clone()))
    .with_show_labels(false)
    .with_colors(
        cell.iter()
            .map(|_| rerun::Color::from_unmultiplied_rgba(150, 150, 150, 255)),
    )
    .with_fill_mode(rerun::FillMode::Solid);
    rec.log_static("world/cell", &boxes)?;
    let c = &result.camera;
    let p = &c.world_from_camera;
    rec.log_static(
        "world/camera",
        &rerun::Transform3D::from_translation_rotation(v3(&p.translation.vector), quat(p)),
    )?;
    let range_m = (pick_tray_center_m - p.translation.vector).norm();
    rec.log_static(
        "world/camera",
        &rerun::Pinhole::from_focal_length_and_resolution(
            [c.fx_px as f32, c.fy_px as f32],
            [c.width_px as f32, c.height_px as f32],
        )
        .with_principal_point([c.cx_px as f32, c.cy_px as f32])
        .with_camera_xyz(rerun::components::ViewCoordinates::RDF)
        .with_image_plane_distance(range_m as f32),
    )?;
    Ok(())
}

/// The entity of the arm's link `i`.
fn link_path(robot: &RobotModel, i: usize) -> String {
    format!("world/arm/{}", link_name(robot, i))
}

/// The arm's static part: each link's primitives (in the link's frame), the series' styles.
fn log_arm_geometry(rec: &mut Rec, robot: &RobotModel) -> Result<(), RecordError> {
    let link_path = |i: usize| link_path(robot, i);
    for (i, link) in robot.links.iter().enumerate().take(DOF + 1) {
        let path = format!("{}/geometry", link_path(i));
        let colour = rerun::Color::from_rgb(230, 200, 60);
        for (k, s) in link.shapes.iter().enumerate() {
            let at = v3(&s.link_from_shape.translation.vector);
            let q = quat(&s.link_from_shape);
            let shape_path = format!("{path}/{k}");
            match &s.primitive {
                LinkPrimitive::Box { half_extents_m } => rec.log_static(
                    &shape_path,
                    &rerun::Boxes3D::from_centers_and_half_sizes([at], [v3(half_extents_m)])
                        .with_quaternions([q])
                        .with_colors([colour])
                        .with_fill_mode(rerun::FillMode::Solid),
                )?,
                LinkPrimitive::Cylinder {
                    radius_m,
                    half_length_m,
                } => rec.log_static(
                    &shape_path,
                    &rerun::Cylinders3D::from_lengths_and_radii([2.0 * *half_length_m as f32], [*radius_m as f32])
                        .with_centers([at])
                        .with_quaternions([q])
                        .with_colors([colour])
                        .with_fill_mode(rerun::FillMode::Solid),
                )?,
                LinkPrimitive::Sphere { radius_m } => rec.log_static(
                    &shape_path,
                    &rerun::Ellipsoids3D::from_centers_and_radii([at], [*radius_m as f32])
                        .with_colors([colour])
                        .with_fill_mode(rerun::FillMode::Solid),
                )?,
                LinkPrimitive::Capsule {
                    radius_m,
                    half_length_m,
                } => {
                    // Rerun's capsules run along +z from their origin: start at the lower end.
                    let start = s.link_from_shape * nalgebra::Point3::new(0.0, 0.0, -half_length_m);
                    rec.log_static(
                        &shape_path,
                        &rerun::Capsules3D::from_lengths_and_radii([2.0 * *half_length_m as f32], [*radius_m as f32])
                            .with_translations([v3(&start.coords)])
                            .with_quaternions([q])
                            .with_colors([colour])
                            .with_fill_mode(rerun::FillMode::Solid),
                    )?
                }
            }
        }
    }
    let names: Vec<String> = (1..=DOF).map(|j| format!("J{j}")).collect();
    rec.log_static("joints/position", &rerun::SeriesLines::new().with_names(names.clone()))?;
    rec.log_static("joints/velocity", &rerun::SeriesLines::new().with_names(names.clone()))?;
    rec.log_static("joints/tracking_error", &rerun::SeriesLines::new().with_names(names))?;
    for j in 0..DOF {
        rec.log_static(
            &format!("joints/torque/J{}", j + 1),
            &rerun::SeriesLines::new()
                .with_names(["applied [N m]", "+limit", "-limit", "demanded [N m]"])
                .with_colors([
                    rerun::Color::from_rgb(30, 120, 230),
                    rerun::Color::from_rgb(220, 40, 40),
                    rerun::Color::from_rgb(220, 40, 40),
                    rerun::Color::from_rgb(240, 160, 20),
                ]),
        )?;
    }
    rec.log_static("cycle/takt", &rerun::SeriesPoints::new().with_names(["takt [s]"]))
}

/// The arm over time: the link frames (50 Hz), the joint series (100 Hz).
fn log_arm(rec: &mut Rec, result: &Recording, robot: &RobotModel) -> Result<(), RecordError> {
    // Link frames at 50 Hz, one columnar call per link.
    let samples = arm_samples(result);
    if samples.is_empty() {
        return Ok(());
    }
    let times: Vec<f64> = samples.iter().map(|(t, _)| *t).collect();
    let world_from_links: Vec<Vec<Isometry3<f64>>> = samples.iter().map(|(_, q)| robot.world_from_links(q)).collect();
    for i in 0..=DOF.min(robot.links.len().saturating_sub(1)) {
        let columns = rerun::Transform3D::update_fields()
            .with_many_translation(world_from_links.iter().map(|f| v3(&f[i].translation.vector)))
            .with_many_quaternion(world_from_links.iter().map(|f| quat(&f[i])))
            .columns_of_unit_batches()
            .map_err(rr)?;
        rec.columns(&link_path(robot, i), &times, columns)?;
    }
    // Joint series at 100 Hz: positions and velocities (six series each), torque beside its limit.
    let ticks: Vec<&crate::servo::Tick> = joint_state_ticks(result).collect();
    if ticks.is_empty() {
        return Ok(());
    }
    let times: Vec<f64> = ticks.iter().map(|t| t.t_s).collect();
    let position: Vec<f64> = ticks
        .iter()
        .flat_map(|t| t.q.iter().copied().collect::<Vec<_>>())
        .collect();
    rec.series("joints/position", &times, position, DOF)?;
    let velocity: Vec<f64> = ticks
        .iter()
        .flat_map(|t| t.qd.iter().copied().collect::<Vec<_>>())
        .collect();
    rec.series("joints/velocity", &times, velocity, DOF)?;
    let error: Vec<f64> = ticks
        .iter()
        .flat_map(|t| t.error_rad.iter().copied().collect::<Vec<_>>())
        .collect();
    rec.series("joints/tracking_error", &times, error, DOF)?;
    let limit = robot.torque_limit_nm();
    for j in 0..DOF {
        let path = format!("joints/torque/J{}", j + 1);
        let values: Vec<f64> = ticks
            .iter()
            .flat_map(|t| [t.tau_nm[j], limit[j], -limit[j], t.demand_nm[j]])
            .collect();
        rec.series(&path, &times, values, 4)?;
    }
    Ok(())
}

/// All parts as one batch of boxes per frame (taken-out parts left out), coloured by state.
fn log_parts(rec: &mut Rec, result: &Recording) -> Result<(), RecordError> {
    let half = Vector3::from(result.part_size_m) / 2.0;
    for f in &result.scene_frames {
        let parts: Vec<&(PartState, Isometry3<f64>)> =
            f.parts.iter().filter(|(s, _)| *s != PartState::Removed).collect();
        rec.log(
            f.t_s,
            "world/parts",
            &rerun::Boxes3D::from_centers_and_half_sizes(
                parts.iter().map(|(_, p)| v3(&p.translation.vector)),
                parts.iter().map(|_| v3(&half)),
            )
            .with_quaternions(parts.iter().map(|(_, p)| quat(p)))
            .with_colors(parts.iter().map(|(s, _)| rgb(part_rgb(*s))))
            .with_fill_mode(rerun::FillMode::Solid),
        )?;
    }
    Ok(())
}

/// Depth images and point clouds at their trigger times; detections and grasp candidates when the
/// recognition result arrived.
fn log_sensing(rec: &mut Rec, result: &Recording) -> Result<(), RecordError> {
    for c in &result.captures {
        let bytes = c.depth_le_bytes();
        if c.confirming {
            // Apart from the camera (not drawn in 3D over the image recognition read).
            rec.log(
                c.t_s,
                "sensor/confirming_depth",
                &rerun::DepthImage::from_gray16(bytes, [c.size_px.0 as u32, c.size_px.1 as u32]).with_meter(1000.0),
            )?;
            continue;
        }
        rec.log(
            c.t_s,
            "world/camera/depth",
            &rerun::DepthImage::from_gray16(bytes, [c.size_px.0 as u32, c.size_px.1 as u32]).with_meter(1000.0),
        )?;
        rec.log(
            c.t_s,
            "world/cloud",
            &rerun::Points3D::new(c.points_world_m.iter().copied()).with_radii([0.0009]),
        )?;
    }
    let half = Vector3::from(result.part_size_m) / 2.0;
    for t in &result.truths {
        rec.log(
            t.t_s,
            "world/recognition/truth_at_trigger",
            &rerun::Boxes3D::from_centers_and_half_sizes(
                t.parts.iter().map(|(_, p)| v3(&p.translation.vector)),
                t.parts.iter().map(|_| v3(&half)),
            )
            .with_quaternions(t.parts.iter().map(|(_, p)| quat(p)))
            .with_labels(t.parts.iter().map(|(i, _)| format!("part {i} at the trigger")))
            .with_show_labels(false)
            .with_colors(t.parts.iter().map(|_| rerun::Color::from_rgb(60, 220, 60))),
        )?;
    }
    for r in &result.recognitions {
        rec.log(
            r.t_s,
            "world/recognition/detections",
            &rerun::Boxes3D::from_centers_and_half_sizes(
                r.detections.iter().map(|(p, _)| v3(&p.translation.vector)),
                r.detections.iter().map(|_| v3(&half)),
            )
            .with_quaternions(r.detections.iter().map(|(p, _)| quat(p)))
            .with_labels(r.detections.iter().zip(&r.detection_errors).map(|((_, v), e)| match e {
                Some((dp, dr, false)) => format!(
                    "wrong: {:.1} mm / {:.1} deg off, {:.0} % visible",
                    dp * 1e3,
                    dr.to_degrees(),
                    100.0 * v
                ),
                _ => format!("{:.0} % visible", 100.0 * v),
            }))
            .with_show_labels(false)
            .with_colors(r.detection_errors.iter().map(|e| match e {
                Some((_, _, false)) => rerun::Color::from_rgb(255, 40, 40),
                _ => rerun::Color::from_rgb(0, 200, 255),
            })),
        )?;
        let chosen = |k: usize| r.chosen == Some(k);
        rec.log(
            r.t_s,
            "world/recognition/candidates",
            &rerun::Arrows3D::from_vectors(r.candidates.iter().map(|_| [0.0, 0.0, -CANDIDATE_ARROW_M as f32]))
                .with_origins(
                    r.candidates
                        .iter()
                        .map(|(p, _)| v3(&(p.translation.vector + Vector3::z() * CANDIDATE_ARROW_M))),
                )
                .with_colors((0..r.candidates.len()).map(|k| {
                    if chosen(k) {
                        rerun::Color::from_rgb(0, 220, 0)
                    } else {
                        rerun::Color::from_rgb(240, 200, 0)
                    }
                }))
                .with_labels(
                    r.candidates.iter().enumerate().map(|(k, (_, score))| {
                        format!("#{} {score:.2}{}", k + 1, if chosen(k) { " chosen" } else { "" })
                    }),
                ),
        )?;
    }
    Ok(())
}

/// Each motion's tool path, planned and executed, at the motion's start.
fn log_paths(rec: &mut Rec, result: &Recording) -> Result<(), RecordError> {
    for p in &result.tool_paths {
        let strip = |pts: &[Vector3<f64>]| pts.iter().map(v3).collect::<Vec<_>>();
        rec.log(
            p.t_s,
            "world/paths/planned",
            &rerun::LineStrips3D::new([strip(&p.planned_m)]).with_colors([rerun::Color::from_rgb(50, 100, 255)]),
        )?;
        rec.log(
            p.t_s,
            "world/paths/executed",
            &rerun::LineStrips3D::new([strip(&p.executed_m)]).with_colors([rerun::Color::from_rgb(255, 130, 0)]),
        )?;
    }
    Ok(())
}

/// The cycle's events as log entries, and the takt of every placed pick at its release.
fn log_events(rec: &mut Rec, result: &Recording) -> Result<(), RecordError> {
    for e in &result.events {
        let level = if event_level(e) >= 3 {
            rerun::TextLogLevel::WARN
        } else {
            rerun::TextLogLevel::INFO
        };
        rec.log(e.t_s, "events", &rerun::TextLog::new(event_text(e)).with_level(level))?;
    }
    for t in &result.takts {
        rec.log(t.release_s, "cycle/takt", &rerun::Scalars::single(t.takt_s))?;
    }
    Ok(())
}
