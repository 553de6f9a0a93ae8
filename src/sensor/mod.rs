//! The fixed overhead 3D sensor: depth capture by rasterization, exposure timing, recognition.
//!
//! Files: [`camera`] (the pinhole camera), [`capture`](mod@capture) (rasterized depth images),
//! `raster` (the z-buffer), [`recognition`]
//! (parts found in a capture, and their evaluation against ground truth), [`heightmap`] (the
//! point cloud binned over the pick tray); this file: the sensor's timing (trigger, exposure,
//! latency) and its view frustum.
//!
//! Job: capture the pile exactly as a fixed pinhole camera sees it: the physics world's solids
//! (arm links, held part, parts, trays) rasterized into a z-buffer, so the arm and the parts
//! really hide what lies beneath them; add depth noise growing with range squared and drop returns at grazing
//! angles and at random. A capture needs an exposure window in which the arm stays out of the view
//! frustum over the pick tray (else it is spoiled and repeated); a part that moves more than
//! [`STILL_MOTION_M`] during the exposure is blurred and not recognised (the others are). The
//! recognition result is ready `latency_s` after the trigger. Recognition ([`Sensor::result`]) runs
//! on the image as exposed: the pixels of a part that moved during the exposure come back empty
//! (a blurred part gives no usable depth); by default from that image and the part's model alone
//! ([`cloud`]), or, as the explicit what-if, by the oracle ([`recognition`]).
//!
//! Units: m, s, px. Frames: `world_from_camera` in the optical convention (x right, y down, z
//! along the view); depth is the z coordinate in the camera frame; points are in the world frame.
//! Randomness: the `sensor` stream (pixel noise, positioned per row so threads cannot reorder it)
//! and the `recognition` stream, both of the run seed, offset by the capture number.

pub mod camera;
pub mod capture;
pub mod cloud;
pub mod heightmap;
mod raster;
pub mod recognition;

use serde::Serialize;

pub use camera::{Camera, PixelWindow};
pub use capture::{Background, Capture, capture, capture_over};
pub use cloud::{CloudDetection, CloudModel, Symmetry};
pub use heightmap::HeightMap;
pub use recognition::{
    CORRECT_WITHIN_M, CORRECT_WITHIN_RAD, Detection, RecognitionReport, RecognitionSummary, RecognitionTotals,
    TruthAtTrigger, TruthMatch, evaluate, ser_pose, top_layer,
};

use crate::config::{RecognitionMode, SensorConfig, Workpiece};
use crate::physics::{PartState, Tag, TrayVolume, ViewVolume, World};

/// The camera's view frustum over the pick tray: the pyramid from the optical centre to the tray's
/// outer rim at floor level. The arm must be outside it to expose.
#[derive(Clone)]
pub struct ViewFrustum {
    /// The pyramid.
    volume: ViewVolume,
}

impl ViewFrustum {
    /// The frustum of `camera` over the pick tray `tray`; `None` if it spans no volume (the
    /// cell file's validation refuses such a camera).
    pub fn over_tray(tray: &TrayVolume, camera: &Camera) -> Option<Self> {
        let mut pts = vec![camera.world_from_camera.translation.vector];
        pts.extend(tray.rim_corners_at_floor().iter().map(|p| p.coords));
        ViewVolume::hull(&pts).map(|volume| ViewFrustum { volume })
    }

    /// The first part of the robot (link, tool, cup or held part) inside the frustum, named.
    pub fn arm_inside(&self, world: &World) -> Option<String> {
        world.robot_inside(&self.volume)
    }
}

/// The arm as the controller knew it at a trigger: its joints as the encoders read them then, and
/// with a part on the cup, where the grasp put that part on the tool (from its recognised pose).
/// What the self-filter masks out of the image beyond the tray (`pipeline::SensedPile`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmAtTrigger {
    /// Joint positions (rad).
    pub q: crate::robot::JointVector,
    /// `tool_from_part` of the part on the cup, as the grasp estimated it; `None` with the cup
    /// empty.
    pub tool_from_held_part: Option<nalgebra::Isometry3<f64>>,
}

/// Why a capture could not be taken or was spoiled.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum CaptureProblem {
    /// The arm was in the view frustum at the trigger.
    ArmInView(String),
    /// The arm entered the view frustum during exposure.
    ArmEnteredDuringExposure(String),
    /// The image shows this many new hole pixels over the tray floor
    /// ([`Sensor::new_hole_px`], at least [`Sensor::motion_hole_min_px`]): something moved during the
    /// exposure, and the pile may still be moving. Found once the image is processed; the cell
    /// does not pick from it.
    PileMoving(usize),
}

/// A capture whose image shows new holes over the tray floor covering at least this area at the
/// floor ([`Sensor::motion_hole_min_px`] pixels) is taken for a pile in motion
/// ([`CaptureProblem::PileMoving`]) (m^2): 20 pixels of 1.43 mm. With that sensor, on
/// deterministic seeds 1-4 of A, C, D and E, captures with no part blurred had at most 18 hole
/// pixels (A: steep faces beyond the grazing angle), captures with a part blurred at least 25 (D)
/// and up to 5,210 (C).
pub const MOTION_HOLE_MIN_M2: f64 = 20.0 * 0.00143 * 0.00143;

/// The pixels of `mask` (rows of `width` pixels) in a part of it wider than `width_px - 1`:
/// those in a `width_px` x `width_px` square of set pixels (every square that fits, each of its
/// pixels counted once): the mask opened by the square, eroded then dilated along rows and
/// columns.
fn wide_px(mask: &[bool], width: usize, width_px: usize) -> usize {
    if width == 0 || width_px == 0 {
        return 0;
    }
    let height = mask.len() / width;
    let eroded = along_lines(
        &along_lines(mask, width, height, width_px, true, true),
        width,
        height,
        width_px,
        false,
        true,
    );
    let opened = along_lines(
        &along_lines(&eroded, width, height, width_px, true, false),
        width,
        height,
        width_px,
        false,
        false,
    );
    opened.iter().filter(|x| **x).count()
}

/// One pass of a run of `n` pixels along every row (`rows`) or column of a `width` x `height`
/// mask: eroding, a pixel stays set if the `n` pixels from it on (right or down) are all set;
/// dilating, a pixel is set if any of the `n` pixels up to it (left or up) is.
fn along_lines(mask: &[bool], width: usize, height: usize, n: usize, rows: bool, erode: bool) -> Vec<bool> {
    let (lines, len) = if rows { (height, width) } else { (width, height) };
    let at = |line: usize, k: usize| if rows { line * width + k } else { k * width + line };
    let mut out = vec![false; mask.len()];
    for line in 0..lines {
        let mut run = 0usize;
        for step in 0..len {
            if erode {
                // From the line's end: the set pixels in a row from here on.
                let k = len - 1 - step;
                run = if mask[at(line, k)] { run + 1 } else { 0 };
                out[at(line, k)] = run >= n;
            } else {
                // From the line's start: how many pixels on a set one still reaches.
                run = if mask[at(line, step)] { n } else { run.saturating_sub(1) };
                out[at(line, step)] = run > 0;
            }
        }
    }
    out
}

/// A capture in progress: exposing, then processing, then ready (or spoiled).
#[derive(Debug, Clone)]
pub struct CaptureJob {
    /// The image taken at the trigger.
    pub capture: Capture,
    /// End of the exposure window (s).
    pub exposure_end_s: f64,
    /// When the recognition result is available (s).
    pub ready_s: f64,
    /// Set if the exposure was spoiled.
    pub spoiled: Option<CaptureProblem>,
    /// Ground truth at the trigger (evaluation and the oracle recognition only).
    pub truth: TruthAtTrigger,
    /// The arm at the trigger, as the controller knew it: the encoders latched with the trigger
    /// ([`Sensor::trigger`]); the part on the cup is the cycle's to add.
    pub arm: ArmAtTrigger,
    /// How far each part's farthest point moved during the exposure (m): its centre's travel
    /// plus its turn times its bounding radius (a 15 cm strip turning about its centre moves its
    /// ends).
    moved_m: Vec<f64>,
    /// The blurred parts' pixels have been emptied from `capture` (once the exposure ended).
    blur_applied: bool,
    /// A confirming exposure taken right after this one, when this image showed new holes
    /// over the tray at its end (see `cycle::sensing` and [`Sensor::changed_hole_px`]).
    pub confirm: Option<Box<CaptureJob>>,
    /// Whether the image was checked for new holes at its exposure's end (and the confirming
    /// exposure taken if they call for one).
    pub confirm_decided: bool,
    /// The image's hole map ([`Sensor::hole_px`], blur applied), where that check read it: the
    /// motion check at the result reads it again.
    pub holes: Option<Vec<bool>>,
}

impl CaptureJob {
    /// Parts that moved more than [`STILL_MOTION_M`] during the exposure: blurred, not recognised.
    pub fn blurred(&self) -> usize {
        self.moved_m.iter().filter(|m| **m > STILL_MOTION_M).count()
    }

    /// Whether part `i` moved more than [`STILL_MOTION_M`] during the exposure.
    fn is_blurred(&self, i: usize) -> bool {
        self.moved_m.get(i).is_some_and(|m| *m > STILL_MOTION_M)
    }

    /// Empties the pixels of the parts blurred during the exposure (no return), once: the image
    /// as the sensor delivers it (call it once the exposure has ended). Plant simulation: the
    /// ground-truth tag per pixel says which pixels a moving part smeared; nothing downstream
    /// reads the tags.
    pub fn apply_blur(&mut self) {
        if self.blur_applied {
            return;
        }
        self.blur_applied = true;
        if self.blurred() == 0 {
            return;
        }
        let c = &mut self.capture;
        for k in 0..c.depth_m.len() {
            if let Some(Tag::Part(i)) = c.truth[k]
                && self.moved_m.get(i as usize).is_some_and(|m| *m > STILL_MOTION_M)
            {
                c.depth_m[k] = 0.0;
                c.points_world[k] = [f32::NAN; 3];
                c.truth[k] = None;
            }
        }
    }
}

/// A part any point of which moves more than this during the exposure is blurred (m): a third
/// of a pixel at the tray floor. Motion, not velocity: a part resting on a flat face can keep a small solver
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
    /// The fixed pick tray (the cloud recognition's background model).
    pub pick_tray: TrayVolume,
    /// Trigger to recognition result (s).
    pub latency_s: f64,
    /// Exposure window (s).
    pub exposure_s: f64,
    /// Detection threshold on the visible fraction.
    pub detect_min_visible_fraction: f64,
    /// Pose noise, position sigma (m).
    pub pose_noise_m: f64,
    /// Pose noise, rotation sigma (rad).
    pub pose_noise_rad: f64,
    /// Cloud-based recognition or the oracle.
    pub recognition: RecognitionMode,
    /// The workpiece as the cloud-based recognition sees it (shared by the clones).
    model: std::sync::Arc<CloudModel>,
    /// The workpiece's symmetries, for evaluation.
    pub symmetry: std::sync::Arc<Symmetry>,
    /// Run seed.
    pub seed: u64,
    /// Captures triggered so far (spoiled ones included).
    pub triggered: u64,
    /// Captures spoiled so far.
    pub spoiled: u64,
    /// The hole pixels of the last image checked for motion ([`Sensor::new_hole_px`]).
    holes_seen: Vec<bool>,
    /// How wide a hole a still part can leave (px at the tray floor): a face steeper than the
    /// grazing angle, at most [`steep_face_width_m`] of the part's box. `None` unless a part in
    /// motion leaves one at least twice as wide (its [`mean_thickness_m`]): a confirming
    /// exposure could not tell the two apart, and is not taken.
    static_hole_max_px: Option<usize>,
}

/// A part's mean thickness across its box's largest face (m): its volume over that face's area.
/// What a part in motion leaves as a hole is its silhouette, at least about this wide; its box's
/// smallest edge can be much more (a relay's 7 mm body under pins in a 10 mm box, a DIP's 3.3
/// mm body between legs in a 6.8 mm box).
pub fn mean_thickness_m(size_m: [f64; 3], volume_m3: f64) -> f64 {
    let largest_face_m2 = (size_m[0] * size_m[1])
        .max(size_m[1] * size_m[2])
        .max(size_m[0] * size_m[2]);
    if largest_face_m2 > 0.0 {
        volume_m3 / largest_face_m2
    } else {
        0.0
    }
}

/// The widest a face steeper than the grazing angle `grazing_rad` can look from above (m), for a
/// part whose box has the edges `size_m`: a face of edges (a, b) tipped about its edge a shows
/// a by b cos(grazing), at most min(a, b cos(grazing)) across; the widest over the box's faces
/// and both edges.
pub fn steep_face_width_m(size_m: [f64; 3], grazing_rad: f64) -> f64 {
    let c = grazing_rad.cos();
    let mut widest = 0.0f64;
    for (i, j) in [(0, 1), (1, 2), (0, 2)] {
        let (a, b) = (size_m[i], size_m[j]);
        widest = widest.max(a.min(b * c)).max(b.min(a * c));
    }
    widest
}

impl Sensor {
    /// The sensor of a cell over `world`'s pick tray, recognising `workpiece`.
    pub fn new(cfg: &SensorConfig, world: &World, seed: u64, workpiece: &Workpiece) -> Option<Self> {
        let camera = Camera::from_config(cfg)?;
        // A mesh workpiece is recognised through its part model (the cup does not matter for
        // recognition: its faces are matched whatever takes the cup).
        let pm = world
            .part_shape()
            .mesh
            .as_ref()
            .and_then(|mesh| workpiece.part_model(mesh, 0.0).ok());
        // A primitive workpiece is matched by its primitives, and settled onto the floor in the
        // resting poses of its meshed primitives' part model.
        let primitive = workpiece.primitive_mesh();
        let mut model = match &pm {
            Some(pm) => CloudModel::of_part_model(pm),
            None => primitive
                .as_ref()
                .and_then(|mesh| workpiece.part_model(mesh, 0.0).ok())
                .map_or_else(
                    || CloudModel::new(workpiece),
                    |r| CloudModel::new(workpiece).with_resting(&r),
                ),
        };
        model.yaw_span_max_rad = cfg.max_yaw_ambiguity_deg.to_radians();
        // Point-pair features where the workpiece's recognition.method asks for them, sampled at
        // a step of `ppf::STEP_PX` pixels at the tray floor.
        if let Some(mesh) = cloud::ppf::ppf_mesh(workpiece.recognition.method, &model, pm.as_ref(), primitive.as_ref())
        {
            let step_m = cloud::ppf::STEP_PX
                * camera.pixel_size_at_point_m(&world.pick_tray().world_from_tray.translation.vector);
            model = model.with_ppf(mesh, step_m);
        }
        // The widest hole a still part can leave, where a moving part's is twice as wide.
        let static_hole_max_px = {
            let pixel_m = camera.pixel_size_at_point_m(&world.pick_tray().world_from_tray.translation.vector);
            let size_m = workpiece.size_m;
            let steep_px = (steep_face_width_m(size_m, camera.dropout_grazing_rad) / pixel_m).ceil() as usize;
            let solid = world.part_shape().mesh.as_deref().or(primitive.as_ref());
            let volume_m3 = solid
                .and_then(|m| crate::part::mass::mass_properties(m, crate::part::mass::MassSpec::DensityKgM3(1.0)))
                .map_or(0.0, |p| p.volume_m3);
            let thinnest_px = (mean_thickness_m(size_m, volume_m3) / pixel_m).floor() as usize;
            (thinnest_px >= 2 * steep_px).then_some(steep_px)
        };
        Some(Sensor {
            frustum: ViewFrustum::over_tray(world.pick_tray(), &camera)?,
            background: std::sync::Arc::new(Background::new(world, &camera)),
            pick_tray: *world.pick_tray(),
            camera,
            latency_s: cfg.latency_s,
            exposure_s: cfg.exposure_s,
            detect_min_visible_fraction: cfg.detect_min_visible_fraction,
            pose_noise_m: cfg.pose_noise_m,
            pose_noise_rad: cfg.pose_noise_deg.to_radians(),
            recognition: cfg.recognition,
            symmetry: std::sync::Arc::new(model.symmetry().clone()),
            model: std::sync::Arc::new(model),
            seed,
            triggered: 0,
            spoiled: 0,
            holes_seen: Vec::new(),
            static_hole_max_px,
        })
    }

    /// Triggers a capture now: refused while the arm is in view; otherwise exposes from now.
    pub fn trigger(&mut self, world: &World) -> Result<CaptureJob, CaptureProblem> {
        if let Some(link) = self.frustum.arm_inside(world) {
            return Err(CaptureProblem::ArmInView(link));
        }
        let capture = capture_over(world, &self.camera, self.seed, self.triggered, Some(&self.background));
        self.triggered += 1;
        let truth = TruthAtTrigger::take_with(world, self, &capture, self.recognition == RecognitionMode::Oracle);
        Ok(CaptureJob {
            exposure_end_s: world.time_s() + self.exposure_s,
            ready_s: world.time_s() + self.latency_s,
            capture,
            spoiled: None,
            truth,
            arm: ArmAtTrigger {
                q: world.joints(),
                tool_from_held_part: None,
            },
            moved_m: vec![0.0; world.part_count()],
            blur_applied: false,
            confirm: None,
            confirm_decided: false,
            holes: None,
        })
    }

    /// Watches an exposing job after a world step: spoils it if the arm entered the frustum, and
    /// notes how far each free part has moved. Returns the problem the first time it happens.
    pub fn watch(&mut self, job: &mut CaptureJob, world: &World) -> Option<CaptureProblem> {
        if job.spoiled.is_some() || world.time_s() > job.exposure_end_s + 1e-9 {
            return None;
        }
        let radius_m = world.part_shape().bounding_radius_m;
        for (i, at_trigger) in job.truth.world_from_part.iter().enumerate() {
            if world.part_state(i) == PartState::Free {
                let now = world.part_pose(i);
                let d = (now.translation.vector - at_trigger.translation.vector).norm()
                    + now.rotation.angle_to(&at_trigger.rotation) * radius_m;
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

    /// The recognition result of a job, once `ready_s` has come (`now_s`) and if it was not
    /// spoiled: the image as exposed (blurred parts emptied, see `CaptureJob::apply_blur`),
    /// recognised by the cell's recognition. Reads nothing of the world: what the picture showed
    /// at the trigger.
    pub fn result(&self, job: &mut CaptureJob, now_s: f64) -> Option<Vec<Detection>> {
        if job.spoiled.is_some() || now_s + 1e-9 < job.ready_s {
            return None;
        }
        job.apply_blur();
        Some(match self.recognition {
            RecognitionMode::Cloud => self.recognize_cloud(&job.capture),
            RecognitionMode::Oracle => self
                .oracle_parts(&job.truth)
                .into_iter()
                .filter(|(i, _)| !job.is_blurred(*i))
                .map(|(_, d)| d)
                .collect(),
        })
    }

    /// The pixels of `capture` over the pick tray's inner floor that have no return and whose
    /// four neighbours have none either: the inside of a hole in the image. Random dropouts
    /// leave single pixels and grazing returns thin lines along steep edges; a part that moved
    /// during the exposure leaves a hole of its size, and so does a large face steeper than the
    /// grazing angle (a static hole). From the image and the fixed tray alone.
    pub fn hole_px(&self, capture: &Capture) -> Vec<bool> {
        let (w, h) = (capture.width_px, capture.height_px);
        let origin = self.camera.world_from_camera.translation.vector;
        let tray = &self.pick_tray;
        let tray_from_world = tray.world_from_tray.inverse();
        let inner = [
            tray.half_xy_m[0] - tray.wall_thickness_m,
            tray.half_xy_m[1] - tray.wall_thickness_m,
        ];
        let floor_z = tray.world_from_tray.translation.z;
        let over_floor = |u: usize, v: usize| {
            let d = self.camera.pixel_dir(u, v);
            if d.z.abs() < 1e-9 {
                return false;
            }
            let p = tray_from_world * nalgebra::Point3::from(origin + d * ((floor_z - origin.z) / d.z));
            p.x.abs() < inner[0] && p.y.abs() < inner[1]
        };
        let empty = |u: usize, v: usize| capture.depth_at_m(u, v) <= 0.0;
        let mut holes = vec![false; w * h];
        // Pixels outside the tray's own window (within the capture's) do not look at its floor.
        let win = &self.camera.window_over(tray, capture::TRAY_WINDOW_MARGIN_PX);
        for v in win.y0_px.max(1)..(win.y0_px + win.height_px).min(h.saturating_sub(1)) {
            for u in win.x0_px.max(1)..(win.x0_px + win.width_px).min(w.saturating_sub(1)) {
                holes[v * w + u] = empty(u, v)
                    && empty(u - 1, v)
                    && empty(u + 1, v)
                    && empty(u, v - 1)
                    && empty(u, v + 1)
                    && over_floor(u, v);
            }
        }
        holes
    }

    /// New hole pixels that show a pile in motion: [`MOTION_HOLE_MIN_M2`] at the tray floor in
    /// this camera's pixels there.
    pub fn motion_hole_min_px(&self) -> usize {
        let pixel_m = self
            .camera
            .pixel_size_at_point_m(&self.pick_tray.world_from_tray.translation.vector);
        ((MOTION_HOLE_MIN_M2 / (pixel_m * pixel_m)).round() as usize).max(1)
    }

    /// The hole pixels of `capture` ([`Sensor::hole_px`]) that were not holes in the last image
    /// checked: a static hole (a steep face) shows in both, a part that moved during one
    /// exposure only in that one. Remembers this image's holes for the next call.
    pub fn new_hole_px(&mut self, capture: &Capture) -> usize {
        self.new_holes(self.hole_px(capture))
    }

    /// [`Sensor::new_hole_px`] of an image's hole map (`holes`, [`Sensor::hole_px`]).
    pub fn new_holes(&mut self, holes: Vec<bool>) -> usize {
        let new = self.unseen_holes(&holes);
        self.holes_seen = holes;
        new
    }

    /// [`Sensor::new_hole_px`] without remembering: the count alone.
    pub fn unseen_hole_px(&self, capture: &Capture) -> usize {
        self.unseen_holes(&self.hole_px(capture))
    }

    /// [`Sensor::unseen_hole_px`] of an image's hole map.
    pub fn unseen_holes(&self, holes: &[bool]) -> usize {
        holes
            .iter()
            .enumerate()
            .filter(|(i, h)| **h && !self.holes_seen.get(*i).copied().unwrap_or(false))
            .count()
    }

    /// Whether a confirming exposure can tell a still pile's holes from a moving one's (see
    /// `static_hole_max_px`).
    pub fn confirms(&self) -> bool {
        self.static_hole_max_px.is_some()
    }

    /// The hole pixels that show motion between two images of the same view (`image` then
    /// `confirming`, exposed one after the other): those in one image only (a part that moved
    /// during either exposure), and those in both that lie in a hole wider than a still part's
    /// steep face can leave (a part moving slowly through both exposures, blurred in both).
    /// Remembers `image`'s holes as [`Sensor::new_hole_px`] does. Every hole counts where the
    /// part does not allow the distinction ([`Sensor::confirms`]).
    pub fn changed_hole_px(&mut self, image: &Capture, confirming: &Capture) -> usize {
        self.changed_holes(self.hole_px(image), &self.hole_px(confirming), image.width_px)
    }

    /// [`Sensor::changed_hole_px`] of the two images' hole maps (rows of `width_px` pixels).
    pub fn changed_holes(&mut self, image: Vec<bool>, confirming: &[bool], width_px: usize) -> usize {
        let both: Vec<bool> = image.iter().zip(confirming).map(|(x, y)| *x && *y).collect();
        let in_both_moving = match self.static_hole_max_px {
            Some(steep_px) => wide_px(&both, width_px, steep_px + 1),
            None => both.iter().filter(|x| **x).count(),
        };
        let changed = image.iter().zip(confirming).filter(|(x, y)| x != y).count() + in_both_moving;
        self.holes_seen = image;
        changed
    }

    /// Recognition from the capture, the camera, the fixed pick tray and the part's model alone:
    /// the signature admits nothing else.
    pub fn recognize_cloud(&self, capture: &Capture) -> Vec<Detection> {
        cloud::recognize(capture, &self.camera, &self.pick_tray, &self.model)
            .into_iter()
            .map(Detection::from)
            .collect()
    }
}

impl From<CloudDetection> for Detection {
    /// A cloud detection as the cell reads it: its pose, visibility, score and face up.
    fn from(d: CloudDetection) -> Self {
        Detection {
            world_from_part: d.world_from_part,
            visible_fraction: d.visible_fraction,
            score: d.score,
            face_up: Some(d.face_up),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{steep_face_width_m, wide_px};

    /// `wide_px` counts the pixels of every full square of the mask, as a brute force over every
    /// square does; control: a strip one pixel narrower than the square counts nothing.
    #[test]
    fn wide_pixels_are_those_in_full_squares() {
        let (w, h) = (23, 17);
        let mut state = 12345u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) % 100
        };
        for fill in [50, 80, 95] {
            let mask: Vec<bool> = (0..w * h).map(|_| next() < fill).collect();
            for side in [1, 2, 3, 5] {
                let mut covered = vec![false; w * h];
                for v in 0..=h - side {
                    for u in 0..=w - side {
                        if (0..side).all(|dv| (0..side).all(|du| mask[(v + dv) * w + u + du])) {
                            for dv in 0..side {
                                for du in 0..side {
                                    covered[(v + dv) * w + u + du] = true;
                                }
                            }
                        }
                    }
                }
                let brute = covered.iter().filter(|c| **c).count();
                assert_eq!(wide_px(&mask, w, side), brute, "fill {fill} %, side {side}");
            }
        }
        // A strip 4 pixels wide holds squares of 4, not of 5.
        let strip: Vec<bool> = (0..w * h).map(|k| (3..7).contains(&(k % w))).collect();
        assert_eq!(wide_px(&strip, w, 4), 4 * h);
        assert_eq!(wide_px(&strip, w, 5), 0);
    }

    /// A 30 x 30 x 20 mm block's steepest face looks at most 30 cos(80 deg) = 5.2 mm wide; a
    /// 150 x 10 x 5 mm strip's 150 x 10 mm face stood on end 10 mm (its 10 mm edge is the
    /// narrower side of that look).
    #[test]
    fn a_steep_face_looks_at_most_its_edge_times_the_grazing_cosine_wide() {
        let g = 80f64.to_radians();
        assert!((steep_face_width_m([0.03, 0.03, 0.02], g) - 0.03 * g.cos()).abs() < 1e-12);
        assert!((steep_face_width_m([0.15, 0.01, 0.005], g) - 0.01).abs() < 1e-12);
    }
}
