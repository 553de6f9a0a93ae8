//! The fixed overhead 3D sensor: depth capture by ray casting, exposure timing, recognition.
//!
//! Job: capture the pile exactly as a fixed pinhole camera sees it: one ray per pixel into the
//! physics world (arm links, held part, parts, trays), so the arm and the parts really hide what
//! lies beneath them; add depth noise growing with range squared and drop returns at grazing
//! angles and at random. A capture needs an exposure window in which the arm stays out of the view
//! frustum over the pick tray (else it is spoiled and repeated); a part that moves more than
//! [`STILL_MOTION_M`] during the exposure is blurred and not recognised (the others are). The
//! recognition result is ready `latency_s` after the trigger. Recognition (simplified, stated in the README): a part counts as
//! detected when at least `detect_min_visible_fraction` of the pixels it would cover, unoccluded,
//! show it in the capture; its pose then comes with Gaussian noise. The ground-truth body per
//! pixel is used only for that visibility count, never to reveal a hidden part.
//!
//! Units: m, s, px. Frames: `world_from_camera` in the optical convention (x right, y down, z
//! along the view); depth is the z coordinate in the camera frame; points are in the world frame.
//! Randomness: the `sensor` stream (pixel noise, positioned per row so threads cannot reorder it)
//! and the `recognition` stream, both of the run seed, offset by the capture number.

use std::io::Write;
use std::path::Path;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use crate::config::SensorConfig;
use crate::physics::{PartState, Tag, World, sim_point};

/// The pinhole camera.
#[derive(Debug, Clone)]
pub struct Camera {
    /// `world_from_camera` (optical frame).
    pub world_from_camera: Isometry3<f64>,
    /// Image width and height [px].
    pub width: usize,
    /// Image height [px].
    pub height: usize,
    /// Focal lengths [px].
    pub fx: f64,
    /// Focal length y [px].
    pub fy: f64,
    /// Principal point [px].
    pub cx: f64,
    /// Principal point y [px].
    pub cy: f64,
    /// Measurable range [m].
    pub min_range_m: f64,
    /// Measurable range [m].
    pub max_range_m: f64,
    /// Depth noise sigma at 1 m [m]; grows with depth squared.
    pub depth_noise_at_1m_m: f64,
    /// Returns at incidence angles beyond this are lost [rad].
    pub dropout_grazing_rad: f64,
    /// Random dropout probability.
    pub dropout_probability: f64,
}

impl Camera {
    /// The camera of a cell file. `None` if its pose is degenerate (refused by validation).
    pub fn from_config(s: &SensorConfig) -> Option<Self> {
        Some(Camera {
            world_from_camera: s.world_from_camera()?,
            width: s.resolution_px[0] as usize,
            height: s.resolution_px[1] as usize,
            fx: s.focal_px[0],
            fy: s.focal_px[1],
            cx: s.principal_point_px[0],
            cy: s.principal_point_px[1],
            min_range_m: s.min_range_m,
            max_range_m: s.max_range_m,
            depth_noise_at_1m_m: s.depth_noise_at_1m_m,
            dropout_grazing_rad: s.dropout_grazing_deg.to_radians(),
            dropout_probability: s.dropout_probability,
        })
    }

    /// Unit ray direction through pixel centre (u, v), in the world frame.
    pub fn pixel_dir(&self, u: usize, v: usize) -> Vector3<f64> {
        let d = Vector3::new(
            (u as f64 + 0.5 - self.cx) / self.fx,
            (v as f64 + 0.5 - self.cy) / self.fy,
            1.0,
        );
        self.world_from_camera.rotation * d.normalize()
    }

    /// Pixel coordinates and depth of a world point, if in front of the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64, f64)> {
        let c = self.world_from_camera.inverse_transform_point(p);
        (c.z > 1e-9).then(|| (self.fx * c.x / c.z + self.cx, self.fy * c.y / c.z + self.cy, c.z))
    }

    /// Size of a pixel at depth `z` [m].
    pub fn pixel_size_at_m(&self, z: f64) -> f64 {
        z / self.fx.min(self.fy)
    }
}

/// One depth capture.
#[derive(Debug, Clone)]
pub struct Capture {
    /// Capture number within the run.
    pub id: u64,
    /// Simulation time of the trigger [s].
    pub trigger_s: f64,
    /// The camera's optical centre in the world [m].
    pub camera_position_m: Vector3<f64>,
    /// Image width [px].
    pub width: usize,
    /// Image height [px].
    pub height: usize,
    /// Depth along the optical axis per pixel, row-major; 0 where there is no return [m].
    pub depth_m: Vec<f32>,
    /// World point per pixel (NaN where there is no return) [m]: the organised point cloud.
    pub points_world: Vec<[f32; 3]>,
    /// What each valid pixel's ray hit: for visibility counts only (see the module header).
    truth: Vec<Option<Tag>>,
}

impl Capture {
    /// Number of pixels with a return.
    pub fn valid_count(&self) -> usize {
        self.depth_m.iter().filter(|d| **d > 0.0).count()
    }

    /// Writes the depth image as a 16-bit greyscale PNG in millimetres (0 = no return).
    pub fn write_depth_png(&self, path: &Path) -> std::io::Result<()> {
        let file = std::fs::File::create(path)?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), self.width as u32, self.height as u32);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Sixteen);
        let mut w = enc.write_header().map_err(std::io::Error::other)?;
        let bytes: Vec<u8> = self
            .depth_m
            .iter()
            .flat_map(|d| ((*d as f64 * 1000.0).round().clamp(0.0, 65535.0) as u16).to_be_bytes())
            .collect();
        w.write_image_data(&bytes).map_err(std::io::Error::other)?;
        w.finish().map_err(std::io::Error::other)
    }

    /// Writes the valid points as a binary little-endian PLY (x, y, z as float, world frame, m).
    pub fn write_ply(&self, path: &Path) -> std::io::Result<()> {
        let pts: Vec<&[f32; 3]> = self.points_world.iter().filter(|p| p[0].is_finite()).collect();
        let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
        write!(
            f,
            "ply\nformat binary_little_endian 1.0\ncomment binpick capture {} at t = {:.4} s, world frame, metres\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            self.id,
            self.trigger_s,
            pts.len()
        )?;
        for p in pts {
            for c in p {
                f.write_all(&c.to_le_bytes())?;
            }
        }
        f.flush()
    }
}

/// Box-Muller standard normal from two uniforms.
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Random numbers each pixel draws, whatever happens to it, so rows can be positioned exactly.
const DRAWS_PER_PIXEL: u128 = 4;

/// Casts one ray per pixel into the world, in parallel over rows, with the noise model.
pub fn capture(world: &World, camera: &Camera, seed: u64, id: u64) -> Capture {
    capture_over(world, camera, seed, id, None)
}

/// What each pixel's ray meets among the fixed colliders (table, trays, obstacles): computed once,
/// so a capture casts its rays only against what moves, no farther than this.
#[derive(Debug, Clone)]
pub struct Background {
    hits: Vec<Option<(Tag, f64, Vector3<f64>)>>,
}

impl Background {
    /// Casts every pixel of `camera` against the fixed colliders of `world`.
    pub fn new(world: &World, camera: &Camera) -> Self {
        let origin = camera.world_from_camera.translation.vector;
        let qp = world.query_pipeline_fixed();
        let hits = (0..camera.height)
            .flat_map(|v| (0..camera.width).map(move |u| (u, v)))
            .map(|(u, v)| world.cast_ray_with(&qp, &origin, &camera.pixel_dir(u, v), camera.max_range_m))
            .collect();
        Background { hits }
    }
}

/// As [`capture`], with the fixed colliders' hits known (`background`): identical images, rays
/// cast only against the parts and the arm, stopping at the background.
pub fn capture_over(world: &World, camera: &Camera, seed: u64, id: u64, background: Option<&Background>) -> Capture {
    let (w, h) = (camera.width, camera.height);
    let origin = camera.world_from_camera.translation.vector;
    let optical = camera.world_from_camera.rotation * Vector3::z();
    let stream = crate::rng::stream(seed, "sensor");
    // Pixels whose rays may meet something that moves: the image boxes of the moving colliders'
    // bounding boxes, a pixel wider each side (all of them if a box reaches behind the camera).
    let mask: Option<Vec<bool>> = background.map(|_| {
        let mut mask = vec![false; w * h];
        for (lo, hi) in world.moving_view_boxes() {
            let mut box_px = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
            let mut behind = false;
            for k in 0..8 {
                let p = Point3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                );
                match camera.project(&p) {
                    Some((x, y, _)) => {
                        box_px = (box_px.0.min(x), box_px.1.min(y), box_px.2.max(x), box_px.3.max(y));
                    }
                    None => behind = true,
                }
            }
            if behind {
                mask.iter_mut().for_each(|m| *m = true);
                break;
            }
            let clamp = |x: f64, n: usize| x.clamp(0.0, (n - 1) as f64) as usize;
            if box_px.2 < -1.0 || box_px.3 < -1.0 || box_px.0 > w as f64 + 1.0 || box_px.1 > h as f64 + 1.0 {
                continue;
            }
            let (u0, v0) = (clamp(box_px.0.floor() - 1.0, w), clamp(box_px.1.floor() - 1.0, h));
            let (u1, v1) = (clamp(box_px.2.floor() + 1.0, w), clamp(box_px.3.floor() + 1.0, h));
            for v in v0..=v1 {
                mask[v * w + u0..=v * w + u1].iter_mut().for_each(|m| *m = true);
            }
        }
        mask
    });
    /// One image row: depths, points, what each ray hit.
    type Row = (Vec<f32>, Vec<[f32; 3]>, Vec<Option<Tag>>);
    let rows: Vec<Row> = (0..h)
        .into_par_iter()
        .map(|v| {
            let mut rng = stream.clone();
            // Each u64 draw takes two 32-bit words.
            rng.set_word_pos(((id as u128 * h as u128 + v as u128) * w as u128) * DRAWS_PER_PIXEL * 2);
            let mut depth = vec![0f32; w];
            let mut pts = vec![[f32::NAN; 3]; w];
            let mut truth = vec![None; w];
            let qp = match background {
                Some(_) => world.query_pipeline_moving(),
                None => world.query_pipeline(),
            };
            for u in 0..w {
                let dir = camera.pixel_dir(u, v);
                let (noise, drop_draw) = (gaussian(&mut rng), rng.random::<f64>());
                let _ = rng.random::<u64>();
                let hit = match (background, &mask) {
                    (Some(bg), Some(mask)) if !mask[v * w + u] => bg.hits[v * w + u],
                    (Some(bg), _) => {
                        let behind = bg.hits[v * w + u];
                        let reach = behind.map_or(camera.max_range_m, |b| b.1);
                        world.cast_ray_with(&qp, &origin, &dir, reach).or(behind)
                    }
                    (None, _) => world.cast_ray_with(&qp, &origin, &dir, camera.max_range_m),
                };
                let Some((tag, range, normal)) = hit else {
                    continue;
                };
                let z = range * dir.dot(&optical);
                let incidence = (-dir.dot(&normal)).clamp(-1.0, 1.0).acos();
                if range < camera.min_range_m
                    || incidence > camera.dropout_grazing_rad
                    || drop_draw < camera.dropout_probability
                {
                    continue;
                }
                let zn = z + noise * camera.depth_noise_at_1m_m * z * z;
                let p = origin + dir * (zn / dir.dot(&optical));
                depth[u] = zn as f32;
                pts[u] = [p.x as f32, p.y as f32, p.z as f32];
                truth[u] = Some(tag);
            }
            (depth, pts, truth)
        })
        .collect();
    let mut c = Capture {
        id,
        trigger_s: world.time_s,
        camera_position_m: origin,
        width: w,
        height: h,
        depth_m: Vec::with_capacity(w * h),
        points_world: Vec::with_capacity(w * h),
        truth: Vec::with_capacity(w * h),
    };
    for (d, p, t) in rows {
        c.depth_m.extend(d);
        c.points_world.extend(p);
        c.truth.extend(t);
    }
    c
}

/// The camera's view frustum over the pick tray: the pyramid from the optical centre to the tray's
/// outer rim at floor level. The arm must be outside it to expose.
#[derive(Clone)]
pub struct ViewFrustum {
    /// The pyramid as a convex polyhedron, in rapier units.
    shape: rapier3d::prelude::SharedShape,
}

impl ViewFrustum {
    /// The frustum of `camera` over the pick tray of `world`.
    pub fn over_pick_tray(world: &World, camera: &Camera) -> Self {
        let t = &world.pick_tray;
        let [hx, hy] = t.half_xy_m;
        let apex = camera.world_from_camera.translation.vector;
        let mut pts = vec![sim_point(&apex)];
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let c = t.world_from_tray * Point3::new(sx * hx, sy * hy, 0.0);
            pts.push(sim_point(&c.coords));
        }
        ViewFrustum {
            shape: rapier3d::prelude::SharedShape::convex_hull(&pts).expect("a camera above a tray spans a pyramid"),
        }
    }

    /// The first arm collider (link, tool, cup or held part) inside the frustum, named.
    pub fn arm_inside(&self, world: &World) -> Option<String> {
        let id = rapier3d::math::Pose::IDENTITY;
        for (_, c) in world.colliders.iter() {
            let Some(tag) = Tag::decode(c.user_data) else { continue };
            let held =
                matches!(tag, Tag::Part(i) if world.parts.get(i as usize).is_some_and(|p| p.state == PartState::Held));
            if !(tag.is_robot() || held) {
                continue;
            }
            if rapier3d::parry::query::intersection_test(&id, &*self.shape, c.position(), c.shape())
                .is_ok_and(|r| r.intersecting)
            {
                return Some(world.describe(Some(tag)));
            }
        }
        None
    }
}

/// Why a capture could not be taken or was spoiled.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum CaptureProblem {
    /// The arm was in the view frustum at the trigger.
    ArmInView(String),
    /// The arm entered the view frustum during exposure.
    ArmEnteredDuringExposure(String),
}

/// A capture in progress: exposing, then processing, then ready (or spoiled).
#[derive(Debug, Clone)]
pub struct CaptureJob {
    /// The image taken at the trigger.
    pub capture: Capture,
    /// End of the exposure window [s].
    pub exposure_end_s: f64,
    /// When the recognition result is available [s].
    pub ready_s: f64,
    /// Set if the exposure was spoiled.
    pub spoiled: Option<CaptureProblem>,
    /// Part positions at the trigger, to tell whether the scene stays still [m].
    positions_at_trigger: Vec<Vector3<f64>>,
    /// How far each part moved during the exposure [m].
    moved_m: Vec<f64>,
}

impl CaptureJob {
    /// Parts that moved more than [`STILL_MOTION_M`] during the exposure: blurred, not recognised.
    pub fn blurred(&self) -> usize {
        self.moved_m.iter().filter(|m| **m > STILL_MOTION_M).count()
    }
}

/// A part moving more than this during the exposure is blurred [m]: a third of a pixel at the
/// tray floor. Motion, not velocity: a part resting on a flat face can keep a small solver
/// velocity that moves nothing.
pub const STILL_MOTION_M: f64 = 0.0005;

/// The sensor: camera, frustum, timing, noise and recognition settings.
#[derive(Clone)]
pub struct Sensor {
    /// The camera.
    pub camera: Camera,
    /// The frustum over the pick tray.
    pub frustum: ViewFrustum,
    /// What every pixel sees of the fixed cell (shared by the clones).
    background: std::sync::Arc<Background>,
    /// Trigger to recognition result [s].
    pub latency_s: f64,
    /// Exposure window [s].
    pub exposure_s: f64,
    /// Detection threshold on the visible fraction.
    pub detect_min_visible_fraction: f64,
    /// Pose noise, position sigma [m].
    pub pose_noise_m: f64,
    /// Pose noise, rotation sigma [rad].
    pub pose_noise_rad: f64,
    /// Run seed.
    pub seed: u64,
    /// Captures triggered so far (spoiled ones included).
    pub triggered: u64,
    /// Captures spoiled so far.
    pub spoiled: u64,
}

impl Sensor {
    /// The sensor of a cell over `world`'s pick tray.
    pub fn new(cfg: &SensorConfig, world: &World, seed: u64) -> Option<Self> {
        let camera = Camera::from_config(cfg)?;
        Some(Sensor {
            frustum: ViewFrustum::over_pick_tray(world, &camera),
            background: std::sync::Arc::new(Background::new(world, &camera)),
            camera,
            latency_s: cfg.latency_s,
            exposure_s: cfg.exposure_s,
            detect_min_visible_fraction: cfg.detect_min_visible_fraction,
            pose_noise_m: cfg.pose_noise_m,
            pose_noise_rad: cfg.pose_noise_deg.to_radians(),
            seed,
            triggered: 0,
            spoiled: 0,
        })
    }

    /// Triggers a capture now: refused while the arm is in view; otherwise exposes from now.
    pub fn trigger(&mut self, world: &World) -> Result<CaptureJob, CaptureProblem> {
        if let Some(link) = self.frustum.arm_inside(world) {
            return Err(CaptureProblem::ArmInView(link));
        }
        let capture = capture_over(world, &self.camera, self.seed, self.triggered, Some(&self.background));
        self.triggered += 1;
        Ok(CaptureJob {
            exposure_end_s: world.time_s + self.exposure_s,
            ready_s: world.time_s + self.latency_s,
            capture,
            spoiled: None,
            positions_at_trigger: (0..world.parts.len())
                .map(|i| world.part_pose(i).translation.vector)
                .collect(),
            moved_m: vec![0.0; world.parts.len()],
        })
    }

    /// Watches an exposing job after a world step: spoils it if the arm entered the frustum, and
    /// notes how far each free part has moved. Returns the problem the first time it happens.
    pub fn watch(&mut self, job: &mut CaptureJob, world: &World) -> Option<CaptureProblem> {
        if job.spoiled.is_some() || world.time_s > job.exposure_end_s + 1e-9 {
            return None;
        }
        for (i, p) in job.positions_at_trigger.iter().enumerate() {
            if world.parts[i].state == PartState::Free {
                let d = (world.part_pose(i).translation.vector - p).norm();
                job.moved_m[i] = job.moved_m[i].max(d);
            }
        }
        let problem = self
            .frustum
            .arm_inside(world)
            .map(CaptureProblem::ArmEnteredDuringExposure);
        if problem.is_some() {
            self.spoiled += 1;
            job.spoiled = problem.clone();
        }
        problem
    }

    /// The recognition result of a job, once `ready_s` has come and if it was not spoiled: the
    /// recognised parts less those blurred by moving during the exposure.
    pub fn result(&self, job: &CaptureJob, world: &World) -> Option<Vec<Detection>> {
        (job.spoiled.is_none() && world.time_s + 1e-9 >= job.ready_s).then(|| {
            let mut d = self.recognize(world, &job.capture);
            d.retain(|d| job.moved_m.get(d.truth_part).is_none_or(|m| *m <= STILL_MOTION_M));
            d
        })
    }

    /// Recognition on a capture: detected parts with noisy poses (see the module header).
    pub fn recognize(&self, world: &World, c: &Capture) -> Vec<Detection> {
        let mut visible = vec![0usize; world.parts.len()];
        for t in c.truth.iter().flatten() {
            if let Tag::Part(i) = t {
                visible[*i as usize] += 1;
            }
        }
        let mut rng = crate::rng::stream(self.seed, "recognition");
        rng.set_word_pos(c.id as u128 * 1_000_000);
        let mut out = Vec::new();
        for (i, p) in world.parts.iter().enumerate() {
            // Parts in view only: free parts in the pick tray column.
            if p.state != PartState::Free || visible[i] == 0 {
                continue;
            }
            let full = self.unoccluded_pixels(world, i);
            if full == 0 {
                continue;
            }
            let fraction = visible[i] as f64 / full as f64;
            if fraction < self.detect_min_visible_fraction {
                continue;
            }
            let truth = world.part_pose(i);
            let dp = Vector3::new(gaussian(&mut rng), gaussian(&mut rng), gaussian(&mut rng)) * self.pose_noise_m;
            let dr = Vector3::new(gaussian(&mut rng), gaussian(&mut rng), gaussian(&mut rng)) * self.pose_noise_rad;
            let pose = Isometry3::from_parts(
                (truth.translation.vector + dp).into(),
                UnitQuaternion::from_scaled_axis(dr) * truth.rotation,
            );
            out.push(Detection {
                world_from_part: pose,
                visible_fraction: fraction.min(1.0),
                truth_part: i,
            });
        }
        out
    }

    /// Pixels part `i` would cover with nothing in front of it (rays against it alone).
    fn unoccluded_pixels(&self, world: &World, i: usize) -> usize {
        let cam = &self.camera;
        let collider = &world.colliders[world.parts[i].view_collider];
        let aabb = collider.compute_aabb();
        let s = crate::physics::SIM_UNITS_PER_M;
        let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for k in 0..8 {
            let pick = |bit: usize, lo: f32, hi: f32| if k & bit == 0 { lo } else { hi } as f64 / s;
            let p = Point3::new(
                pick(1, aabb.mins.x, aabb.maxs.x),
                pick(2, aabb.mins.y, aabb.maxs.y),
                pick(4, aabb.mins.z, aabb.maxs.z),
            );
            if let Some((u, v, _)) = cam.project(&p) {
                u0 = u0.min(u);
                v0 = v0.min(v);
                u1 = u1.max(u);
                v1 = v1.max(v);
            }
        }
        if u0 > u1 {
            return 0;
        }
        let clamp = |x: f64, n: usize| (x.floor().max(0.0) as usize).min(n.saturating_sub(1));
        let origin = sim_point(&cam.world_from_camera.translation.vector);
        let mut n = 0;
        for v in clamp(v0, cam.height)..=clamp(v1, cam.height) {
            for u in clamp(u0, cam.width)..=clamp(u1, cam.width) {
                let d = cam.pixel_dir(u, v);
                let ray = rapier3d::prelude::Ray::new(origin, crate::physics::sim_dir(&d));
                if collider
                    .shape()
                    .intersects_ray(collider.position(), &ray, (cam.max_range_m * s) as f32)
                {
                    n += 1;
                }
            }
        }
        n
    }
}

/// A recognised part.
#[derive(Debug, Clone, Serialize)]
pub struct Detection {
    /// Estimated `world_from_part` (truth plus recognition noise).
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_part: Isometry3<f64>,
    /// Fraction of its unoccluded image the capture showed.
    pub visible_fraction: f64,
    /// Which part this is, for evaluation only: the grasp selector never reads it.
    pub truth_part: usize,
}

/// Serialises a pose as `{xyz_m, quat_wxyz}`.
pub fn ser_pose<S: serde::Serializer>(p: &Isometry3<f64>, s: S) -> Result<S::Ok, S::Error> {
    let q = p.rotation.quaternion();
    let v = serde_json::json!({"xyz_m": [p.translation.x, p.translation.y, p.translation.z], "quat_wxyz": [q.w, q.i, q.j, q.k]});
    v.serialize(s)
}

/// Evaluation against ground truth: which parts are in the pile's top layer, recall, pose error.
#[derive(Debug, Clone, Serialize)]
pub struct RecognitionReport {
    /// Parts in the pick tray.
    pub parts: usize,
    /// Parts in the top layer (at least two thirds of their footprint uncovered from straight above).
    pub top_layer: usize,
    /// Top-layer parts detected.
    pub top_layer_detected: usize,
    /// Detections in all.
    pub detected: usize,
    /// top_layer_detected / top_layer.
    pub top_layer_recall: f64,
    /// Mean and max position error of detections [m].
    pub position_error_m: (f64, f64),
    /// Mean and max rotation error of detections [rad].
    pub rotation_error_rad: (f64, f64),
}

/// Parts whose footprint is at least two thirds uncovered seen from straight above (arm ignored):
/// vertical rays over a 7 x 7 grid of the part's box, counted where the part alone would be hit.
pub fn top_layer(world: &World) -> Vec<usize> {
    let skip = |t: Tag| t.is_robot();
    let s = crate::physics::SIM_UNITS_PER_M;
    world
        .parts_in_pick_tray()
        .into_iter()
        .filter(|&i| {
            let c = &world.colliders[world.parts[i].view_collider];
            let aabb = c.compute_aabb();
            let top = aabb.maxs.z as f64 / s + 0.5;
            let (mut covered, mut exposed) = (0, 0);
            for a in 0..7 {
                for b in 0..7 {
                    let x = aabb.mins.x as f64 / s + (aabb.maxs.x - aabb.mins.x) as f64 / s * (a as f64 + 0.5) / 7.0;
                    let y = aabb.mins.y as f64 / s + (aabb.maxs.y - aabb.mins.y) as f64 / s * (b as f64 + 0.5) / 7.0;
                    let origin = Vector3::new(x, y, top);
                    let ray =
                        rapier3d::prelude::Ray::new(sim_point(&origin), rapier3d::math::Vector::new(0.0, 0.0, -1.0));
                    if !c.shape().intersects_ray(c.position(), &ray, (1.0 * s) as f32) {
                        continue;
                    }
                    covered += 1;
                    if let Some((Tag::Part(j), _, _)) = world.cast_ray(&origin, &-Vector3::z(), 1.0, &skip)
                        && j as usize == i
                    {
                        exposed += 1;
                    }
                }
            }
            covered > 0 && 3 * exposed >= 2 * covered
        })
        .collect()
}

/// Scores detections against the world's ground truth.
pub fn evaluate(world: &World, detections: &[Detection]) -> RecognitionReport {
    let top = top_layer(world);
    let found: std::collections::BTreeSet<usize> = detections.iter().map(|d| d.truth_part).collect();
    let top_found = top.iter().filter(|i| found.contains(i)).count();
    let (mut sp, mut mp, mut sr, mut mr) = (0.0, 0.0f64, 0.0, 0.0f64);
    for d in detections {
        let truth = world.part_pose(d.truth_part);
        let ep = (truth.translation.vector - d.world_from_part.translation.vector).norm();
        let er = truth.rotation.angle_to(&d.world_from_part.rotation);
        sp += ep;
        sr += er;
        mp = mp.max(ep);
        mr = mr.max(er);
    }
    let n = detections.len().max(1) as f64;
    RecognitionReport {
        parts: world.parts_in_pick_tray().len(),
        top_layer: top.len(),
        top_layer_detected: top_found,
        detected: detections.len(),
        top_layer_recall: if top.is_empty() {
            1.0
        } else {
            top_found as f64 / top.len() as f64
        },
        position_error_m: (sp / n, mp),
        rotation_error_rad: (sr / n, mr),
    }
}

/// A height map of the pick tray built from a capture's point cloud: the highest point per cell.
#[derive(Debug, Clone)]
pub struct HeightMap {
    /// `world_from_tray` of the pick tray.
    pub world_from_tray: Isometry3<f64>,
    /// Cell edge [m].
    pub cell_m: f64,
    /// Cells along x and y.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
    /// Lower corner of cell (0, 0) in the tray frame [m].
    pub origin_xy_m: [f64; 2],
    /// Highest point per cell above the tray floor, NaN where nothing was seen [m].
    pub height_m: Vec<f64>,
}

impl HeightMap {
    /// Bins the capture's points over the tray (walls included) into `cell_m` cells. Only points
    /// inside the view frustum over the tray count (their ray meets the floor plane within the
    /// tray): a point above the tray's footprint but outside the frustum (the arm passing by
    /// high up near the rim) is seen through the air beside the tray, not over it.
    pub fn from_capture(c: &Capture, t: &crate::physics::TrayVolume, cell_m: f64) -> Self {
        let [hx, hy] = t.half_xy_m;
        let nx = ((2.0 * hx) / cell_m).ceil() as usize;
        let ny = ((2.0 * hy) / cell_m).ceil() as usize;
        let mut hm = HeightMap {
            world_from_tray: t.world_from_tray,
            cell_m,
            nx,
            ny,
            origin_xy_m: [-hx, -hy],
            height_m: vec![f64::NAN; nx * ny],
        };
        let tray_from_world = t.world_from_tray.inverse();
        for p in &c.points_world {
            if !p[0].is_finite() {
                continue;
            }
            let l = tray_from_world * Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let apex = tray_from_world * Point3::from(c.camera_position_m);
            if apex.z - l.z > 1e-6 {
                let f = apex.z / (apex.z - l.z);
                let floor = apex + (l - apex) * f;
                if floor.x.abs() > hx || floor.y.abs() > hy {
                    continue;
                }
            }
            if let Some(k) = hm.index(l.x, l.y) {
                let h = &mut hm.height_m[k];
                if h.is_nan() || l.z > *h {
                    *h = l.z;
                }
            }
        }
        hm
    }

    /// The map with every cell whose centre lies outside the tray's inner walls (`inner_half_m`,
    /// tray frame) cleared: what the sensor saw over the walls (the arm passing by outside the
    /// frustum, the walls themselves) is not pile; the walls are in the planner's cell model.
    pub fn inner_only(&self, inner_half_m: [f64; 2]) -> HeightMap {
        let mut m = self.clone();
        for j in 0..m.ny {
            for i in 0..m.nx {
                let x = m.origin_xy_m[0] + (i as f64 + 0.5) * m.cell_m;
                let y = m.origin_xy_m[1] + (j as f64 + 0.5) * m.cell_m;
                if x.abs() > inner_half_m[0] || y.abs() > inner_half_m[1] {
                    m.height_m[j * m.nx + i] = f64::NAN;
                }
            }
        }
        m
    }

    fn index(&self, x: f64, y: f64) -> Option<usize> {
        let i = ((x - self.origin_xy_m[0]) / self.cell_m).floor();
        let j = ((y - self.origin_xy_m[1]) / self.cell_m).floor();
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.nx && (j as usize) < self.ny)
            .then(|| j as usize * self.nx + i as usize)
    }

    /// Stored heights [m] (NaN where unseen) of the cells whose centres lie within `radius_m` of
    /// tray point (x, y), in row-major order.
    fn heights_within(&self, x: f64, y: f64, radius_m: f64) -> impl Iterator<Item = f64> + '_ {
        let r = (radius_m / self.cell_m).ceil() as isize + 1;
        let i0 = ((x - self.origin_xy_m[0]) / self.cell_m).floor() as isize;
        let j0 = ((y - self.origin_xy_m[1]) / self.cell_m).floor() as isize;
        let (nx, ny) = (self.nx as isize, self.ny as isize);
        ((j0 - r).max(0)..=(j0 + r).min(ny - 1))
            .flat_map(move |j| ((i0 - r).max(0)..=(i0 + r).min(nx - 1)).map(move |i| (i, j)))
            .filter(move |&(i, j)| {
                let cx = self.origin_xy_m[0] + (i as f64 + 0.5) * self.cell_m;
                let cy = self.origin_xy_m[1] + (j as f64 + 0.5) * self.cell_m;
                (cx - x).hypot(cy - y) <= radius_m
            })
            .map(move |(i, j)| self.height_m[j as usize * self.nx + i as usize])
    }

    /// Median of the cell heights within `radius_m` of tray point (x, y) and within `band_m` of
    /// `expected_m` [m] (NaN if none): the surface under a small disc near where it should be,
    /// robust to depth noise (which the maximum picks up) and, by the band, to neighbouring
    /// surfaces. (Cells hold their highest point, already +0.15 mm on a flat face; an upper
    /// quartile on top put the cup 0.4 mm high on average and up to 1.1 mm, beyond the seal's
    /// 0.8 mm touch tolerance: one grasp in twenty failed.)
    pub fn surface_within(&self, x: f64, y: f64, radius_m: f64, expected_m: f64, band_m: f64) -> f64 {
        let mut v: Vec<f64> = self
            .heights_within(x, y, radius_m)
            .filter(|h| h.is_finite() && (h - expected_m).abs() <= band_m)
            .collect();
        if v.is_empty() {
            return f64::NAN;
        }
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    }

    /// Highest seen point above the tray floor within `radius_m` of tray point (x, y) [m]
    /// (NaN if nothing was seen there). Cells count when any part of them may lie in the disc
    /// (centre within `radius_m` plus half a cell diagonal).
    pub fn max_within(&self, x: f64, y: f64, radius_m: f64) -> f64 {
        self.heights_within(x, y, radius_m + self.cell_m * 0.71)
            .filter(|h| !h.is_nan())
            .fold(f64::NAN, |best, h| if best.is_nan() || h > best { h } else { best })
    }
}
