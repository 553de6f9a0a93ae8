//! Depth capture by ray casting: one ray per pixel into the physics world, with the sensor's
//! noise model; the capture's depth image and organised point cloud, written as 16-bit PNG and
//! binary PLY.
//!
//! Job: cast every pixel's ray against everything in the cell (the arm and the held part, the
//! parts, the trays and table), so the arm and the parts really hide what lies beneath them;
//! add depth noise growing with range squared and drop returns at grazing angles and at random.
//! What the fixed cell shows each pixel is computed once ([`Background`]), so a capture casts
//! only against what moves: each pixel against the targets whose box's image holds it (binned
//! per 8 x 8 px tile), tested as the broad phase's tree tests its leaves, and the arm's
//! cylinders in closed form.
//!
//! Units: m, px. Frames: depth along the camera's optical axis; points in the world frame.
//! Randomness: the `sensor` stream of the run seed, positioned per row (and capture), so the
//! threads cannot reorder it.

use std::io::Write;
use std::path::Path;

use nalgebra::{Point3, Vector3};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::Camera;
use crate::physics::{RayHit, RayTargetBox, RayTargets, Tag, World};

/// One depth capture.
#[derive(Debug, Clone)]
pub struct Capture {
    /// Capture number within the run.
    pub id: u64,
    /// Simulation time of the trigger (s).
    pub trigger_s: f64,
    /// The camera's optical centre in the world (m).
    pub camera_position_m: Vector3<f64>,
    /// Image width (px).
    pub width_px: usize,
    /// Image height (px).
    pub height_px: usize,
    /// Depth along the optical axis per pixel, row-major; 0 where there is no return (m).
    pub depth_m: Vec<f32>,
    /// World point per pixel (NaN where there is no return) (m): the organised point cloud.
    pub points_world: Vec<[f32; 3]>,
    /// What each valid pixel's ray hit: ground truth for the recognition model's visibility
    /// counts and for evaluation only (see [`super::recognition`]).
    pub(super) truth: Vec<Option<Tag>>,
}

impl Capture {
    /// Number of pixels with a return.
    pub fn valid_count(&self) -> usize {
        self.depth_m.iter().filter(|d| **d > 0.0).count()
    }

    /// Writes the depth image as a 16-bit greyscale PNG in millimetres (0 = no return).
    pub fn write_depth_png(&self, path: &Path) -> std::io::Result<()> {
        let file = std::fs::File::create(path)?;
        let mut enc = png::Encoder::new(
            std::io::BufWriter::new(file),
            self.width_px as u32,
            self.height_px as u32,
        );
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
pub(super) fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let (u1, u2) = gaussian_uniforms(rng);
    gaussian_from(u1, u2)
}

/// The two uniforms [`gaussian`] draws, in its order.
fn gaussian_uniforms(rng: &mut ChaCha8Rng) -> (f64, f64) {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (u1, u2)
}

/// Box-Muller's transform of [`gaussian_uniforms`].
fn gaussian_from(u1: f64, u2: f64) -> f64 {
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Random numbers each pixel draws, whatever happens to it, so rows can be positioned exactly.
const DRAWS_PER_PIXEL: u128 = 4;

/// The pixels (u0, v0, u1, v1, inclusive) of `camera`'s image that the box `lo`..`hi` [m, world]
/// may show, a pixel wider each side: the whole image if the box reaches behind the camera,
/// `None` if it lies outside the image.
fn image_rect(camera: &Camera, lo: &Vector3<f64>, hi: &Vector3<f64>) -> Option<(usize, usize, usize, usize)> {
    let (w, h) = (camera.width_px, camera.height_px);
    let mut box_px = (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for k in 0..8 {
        let p = Point3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        match camera.project(&p) {
            Some((x, y, _)) => box_px = (box_px.0.min(x), box_px.1.min(y), box_px.2.max(x), box_px.3.max(y)),
            None => return Some((0, 0, w - 1, h - 1)),
        }
    }
    if box_px.2 < -1.0 || box_px.3 < -1.0 || box_px.0 > w as f64 + 1.0 || box_px.1 > h as f64 + 1.0 {
        return None;
    }
    let clamp = |x: f64, n: usize| x.clamp(0.0, (n - 1) as f64) as usize;
    Some((
        clamp(box_px.0.floor() - 1.0, w),
        clamp(box_px.1.floor() - 1.0, h),
        clamp(box_px.2.floor() + 1.0, w),
        clamp(box_px.3.floor() + 1.0, h),
    ))
}

/// Side of the square image tiles the ray targets are binned into (px).
const TILE_PX: usize = 8;

/// The ray targets binned by the image rectangles of their boxes ([`image_rect`]), per
/// [`TILE_PX`] tile.
struct TargetBins {
    tiles_across: usize,
    /// Each tile's targets (indices), in the targets' order.
    tiles: Vec<Vec<u32>>,
    /// Each target's image rectangle (u0, v0, u1, v1, inclusive), if in the image.
    rects: Vec<Option<(usize, usize, usize, usize)>>,
}

impl TargetBins {
    fn new(camera: &Camera, targets: &[RayTargetBox]) -> Self {
        let tiles_across = camera.width_px.div_ceil(TILE_PX);
        let mut tiles = vec![Vec::new(); tiles_across * camera.height_px.div_ceil(TILE_PX)];
        let rects: Vec<_> = targets
            .iter()
            .map(|t| {
                let (lo, hi) = t.aabb_m();
                image_rect(camera, &lo, &hi)
            })
            .collect();
        for (k, r) in rects.iter().enumerate() {
            if let Some((u0, v0, u1, v1)) = *r {
                for tv in v0 / TILE_PX..=v1 / TILE_PX {
                    for tu in u0 / TILE_PX..=u1 / TILE_PX {
                        tiles[tv * tiles_across + tu].push(k as u32);
                    }
                }
            }
        }
        TargetBins {
            tiles_across,
            tiles,
            rects,
        }
    }

    /// The targets whose image rectangle holds pixel (u, v).
    fn at<'t>(&'t self, targets: &'t [RayTargetBox], u: usize, v: usize) -> impl Iterator<Item = &'t RayTargetBox> {
        self.tiles[(v / TILE_PX) * self.tiles_across + u / TILE_PX]
            .iter()
            .filter(move |&&k| {
                self.rects[k as usize].is_some_and(|(u0, v0, u1, v1)| (u0..=u1).contains(&u) && (v0..=v1).contains(&v))
            })
            .map(move |&k| &targets[k as usize])
    }
}

/// Casts one ray per pixel into the world, in parallel over rows, with the noise model.
pub fn capture(world: &World, camera: &Camera, seed: u64, id: u64) -> Capture {
    capture_over(world, camera, seed, id, None)
}

/// What each pixel's ray meets among the fixed colliders (table, trays, obstacles): computed once,
/// so a capture casts its rays only against what moves, no farther than this.
#[derive(Debug, Clone)]
pub struct Background {
    hits: Vec<Option<RayHit>>,
}

impl Background {
    /// Casts every pixel of `camera` against the fixed colliders of `world`.
    pub fn new(world: &World, camera: &Camera) -> Self {
        let origin = camera.world_from_camera.translation.vector;
        let rays = world.ray_caster(RayTargets::Fixed);
        let hits = (0..camera.height_px)
            .flat_map(|v| (0..camera.width_px).map(move |u| (u, v)))
            .map(|(u, v)| rays.cast(&origin, &camera.pixel_dir(u, v), camera.max_range_m))
            .collect();
        Background { hits }
    }
}

/// As [`capture`], with the fixed colliders' hits known (`background`): identical images, rays
/// cast only against the parts and the arm, stopping at the background.
pub fn capture_over(world: &World, camera: &Camera, seed: u64, id: u64, background: Option<&Background>) -> Capture {
    let (w, h) = (camera.width_px, camera.height_px);
    let origin = camera.world_from_camera.translation.vector;
    let optical = camera.world_from_camera.rotation * Vector3::z();
    let stream = crate::rng::stream(seed, "sensor");
    let kind = match background {
        Some(_) => RayTargets::Moving,
        None => RayTargets::All,
    };
    let caster = world.ray_caster(kind);
    // The arm's cylinders, cast in closed form: each pixel tests only those whose image box
    // holds it.
    let cylinder_rects: Vec<Option<(usize, usize, usize, usize)>> = caster
        .arm_cylinder_boxes_m()
        .iter()
        .map(|(lo, hi)| image_rect(camera, lo, hi))
        .collect();
    let cylinder_bits = |u: usize, v: usize| {
        cylinder_rects.iter().enumerate().fold(0u64, |bits, (k, r)| match r {
            Some((u0, v0, u1, v1)) if (*u0..=*u1).contains(&u) && (*v0..=*v1).contains(&v) => bits | (1u64 << k),
            _ => bits,
        })
    };
    // With a background, what moves is cast without the pipeline's tree: each target's tree box
    // is binned by its image into tiles, and each pixel tests only the targets whose image box
    // holds it (as the tree would, box first, then shape). A pixel that neither a target's nor a
    // cylinder's image holds shows the background.
    let targets = match background {
        Some(_) => caster.target_boxes(),
        None => Vec::new(),
    };
    let target_bins = background.map(|_| TargetBins::new(camera, &targets));
    let cos_grazing = camera.dropout_grazing_rad.cos();
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
            let rays = world.ray_caster(kind);
            for u in 0..w {
                let dir = camera.pixel_dir(u, v);
                // The noise's two uniforms are drawn for every pixel (rows start at fixed stream
                // positions), its Box-Muller transform only for the pixels that report a depth.
                let (u1, u2) = gaussian_uniforms(&mut rng);
                let drop_draw = rng.random::<f64>();
                let _ = rng.random::<u64>();
                let bits = cylinder_bits(u, v);
                let hit = match (background, &target_bins) {
                    (Some(bg), Some(bins)) => {
                        let behind = bg.hits[v * w + u];
                        let mut near = bins.at(&targets, u, v).peekable();
                        if bits == 0 && near.peek().is_none() {
                            behind
                        } else {
                            let reach = behind.map_or(camera.max_range_m, |b| b.distance_m);
                            rays.cast_listed(&origin, &dir, reach, near, bits).or(behind)
                        }
                    }
                    _ => rays.cast_among(&origin, &dir, camera.max_range_m, bits),
                };
                let Some(RayHit {
                    tag,
                    distance_m: range,
                    normal,
                }) = hit
                else {
                    continue;
                };
                let z = range * dir.dot(&optical);
                // Incidence beyond the grazing angle, compared as cosines (acos is decreasing).
                let cos_incidence = (-dir.dot(&normal)).clamp(-1.0, 1.0);
                if range < camera.min_range_m || cos_incidence < cos_grazing || drop_draw < camera.dropout_probability {
                    continue;
                }
                let noise = gaussian_from(u1, u2);
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
        trigger_s: world.time_s(),
        camera_position_m: origin,
        width_px: w,
        height_px: h,
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
