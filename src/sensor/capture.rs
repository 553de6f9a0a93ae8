//! Depth capture by rasterization: the physics world's visible solids in a z-buffer, with the
//! sensor's noise model; the capture's depth image and organised point cloud, written as 16-bit
//! PNG and binary PLY.
//!
//! Job: render everything in the cell as the physics world holds it (the arm's links, tool and
//! cup, the held part, the parts through their view shapes, the trays and table: the colliders'
//! shapes at their poses, [`World::view_meshes`], never the recognised parts) into a z-buffer
//! (`sensor/raster.rs`), so the arm and the parts really hide what lies beneath them; each
//! pixel's depth is its ray cut with the nearest facet's plane. Round surfaces are faceted within
//! [`FACET_CHORD_M`] (a simplification: a ray cast met the true cylinder). Then add depth noise
//! growing with range squared and drop returns at grazing angles and at random. What the fixed
//! cell shows each pixel is rasterized once ([`Background`]), so a capture rasterizes only what
//! moves.
//!
//! Units: m, px. Frames: depth along the camera's optical axis; points in the world frame.
//! Randomness: the `sensor` stream of the run seed, positioned per row (and capture), so the
//! threads cannot reorder it.

use std::io::Write;
use std::path::Path;

use nalgebra::Vector3;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::raster::{Facet, NO_FACET, ZBuffer, rasterize};
use super::{Camera, PixelWindow};
use crate::physics::{RayTargets, Tag, World};

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
    /// The sensor's region of interest: the pixels that see the pick tray (its outer walls,
    /// floor to rim) and [`TRAY_WINDOW_MARGIN_PX`] around them. Only these are measured; every
    /// other pixel has no return. No other pixel's ray meets the tray, so nothing the cell
    /// decides from looks outside it.
    pub tray_window: PixelWindow,
}

/// The margin of a capture's [`Capture::tray_window`] around the tray's image (px): 8.5 mm at
/// the tray floor with the default sensor, a wall's thickness, so a part resting on the rim is
/// in the image.
pub const TRAY_WINDOW_MARGIN_PX: usize = 10;

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
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A uniform in (0, 1) from 32 random bits (never 0: Box-Muller takes its logarithm).
#[inline]
fn unit_from_bits(bits: u32) -> f64 {
    (bits as f64 + 0.5) * (1.0 / 4_294_967_296.0)
}

/// Random 64-bit draws per pair of neighbouring pixels in a row, whatever happens to them, so
/// rows can be positioned exactly: one for the two uniforms of a Box-Muller transform (whose two
/// normals go to the two pixels), one for the two pixels' dropout draws.
const DRAWS_PER_PAIR: u128 = 2;

/// Round surfaces (the can, leads, the arm's links) are faceted within this of the true surface
/// (m): a sixth of the depth noise's sigma at 1 m.
pub const FACET_CHORD_M: f64 = 5e-5;

/// Captures the world as the camera sees it (rasterized), in parallel over rows, with the noise
/// model.
pub fn capture(world: &World, camera: &Camera, seed: u64, id: u64) -> Capture {
    capture_over(world, camera, seed, id, None)
}

/// What the fixed cell (table, trays, obstacles) shows each pixel, rasterized once: a capture
/// rasterizes only what moves over a copy of it.
#[derive(Debug, Clone)]
pub struct Background {
    zbuffer: ZBuffer,
    facets: Vec<Facet>,
}

impl Background {
    /// Rasterizes the fixed colliders of `world` into `camera`'s image.
    pub fn new(world: &World, camera: &Camera) -> Self {
        let mut zbuffer = ZBuffer::empty(camera);
        let mut facets = Vec::new();
        rasterize(
            camera,
            &camera.window_over(world.pick_tray(), TRAY_WINDOW_MARGIN_PX),
            &world.view_meshes(RayTargets::Fixed, FACET_CHORD_M),
            &mut zbuffer,
            &mut facets,
        );
        Background { zbuffer, facets }
    }
}

/// As [`capture`], with the fixed colliders already rasterized (`background`): identical images,
/// only the parts and the arm rasterized per capture.
pub fn capture_over(world: &World, camera: &Camera, seed: u64, id: u64, background: Option<&Background>) -> Capture {
    let (w, h) = (camera.width_px, camera.height_px);
    let origin = camera.world_from_camera.translation.vector;
    let rotation = camera.world_from_camera.rotation.to_rotation_matrix().into_inner();
    let stream = crate::rng::stream(seed, "sensor");
    let fresh;
    let bg = match background {
        Some(b) => b,
        None => {
            fresh = Background::new(world, camera);
            &fresh
        }
    };
    let window = camera.window_over(world.pick_tray(), TRAY_WINDOW_MARGIN_PX);
    let mut zb = bg.zbuffer.clone();
    let mut facets = bg.facets.clone();
    rasterize(
        camera,
        &window,
        &world.view_meshes(RayTargets::Moving, FACET_CHORD_M),
        &mut zb,
        &mut facets,
    );
    let cos_grazing = camera.dropout_grazing_rad.cos();
    let pairs = w.div_ceil(2);
    let mut c = Capture {
        id,
        trigger_s: world.time_s(),
        camera_position_m: origin,
        width_px: w,
        height_px: h,
        depth_m: vec![0.0; w * h],
        points_world: vec![[f32::NAN; 3]; w * h],
        truth: vec![None; w * h],
        tray_window: window,
    };
    // The pairs of pixels that hold the window's columns.
    let window_pairs = window.x0_px / 2..(window.x0_px + window.width_px).div_ceil(2).min(pairs);
    let window_rows = window.y0_px..window.y0_px + window.height_px;
    c.depth_m
        .par_chunks_mut(w)
        .zip(c.points_world.par_chunks_mut(w))
        .zip(c.truth.par_chunks_mut(w))
        .enumerate()
        .for_each(|(v, ((depth, pts), truth))| {
            if !window_rows.contains(&v) {
                return;
            }
            let mut rng = stream.clone();
            // Each u64 draw takes two 32-bit words; the row's draws start at its first pair, the
            // window's at its first pair.
            rng.set_word_pos(
                ((id as u128 * h as u128 + v as u128) * pairs as u128 + window_pairs.start as u128)
                    * DRAWS_PER_PAIR
                    * 2,
            );
            let row = &zb.facet[v * w..(v + 1) * w];
            let y = (v as f64 + 0.5 - camera.cy_px) / camera.fy_px;
            // The unnormalised ray through (u + 0.5, v + 0.5) in the world: row + u * step.
            let row_dir = rotation * Vector3::new((0.5 - camera.cx_px) / camera.fx_px, y, 1.0);
            let step = rotation.column(0) / camera.fx_px;
            for p in window_pairs.clone() {
                let noise_bits: u64 = rng.random();
                let drop_bits: u64 = rng.random();
                let (u_a, u_b) = (2 * p, (2 * p + 1).min(w - 1));
                if row[u_a] == NO_FACET && row[u_b] == NO_FACET {
                    continue;
                }
                // Box-Muller's two normals, one per pixel of the pair (in single precision: the
                // noise needs no more).
                let r = (-2.0 * (unit_from_bits(noise_bits as u32) as f32).ln()).sqrt();
                let (sin, cos) = (std::f32::consts::TAU * unit_from_bits((noise_bits >> 32) as u32) as f32).sin_cos();
                for (k, u) in [u_a, u_b].into_iter().enumerate() {
                    if k == 1 && u_b == u_a {
                        break;
                    }
                    let f = row[u];
                    if f == NO_FACET {
                        continue;
                    }
                    let drop = unit_from_bits((drop_bits >> (32 * k)) as u32);
                    let facet = &facets[f as usize];
                    let ray = row_dir + step * u as f64;
                    // Depth along the axis per unit of the ray's length.
                    let z_per_range = 1.0 / ray.norm();
                    let dir = ray * z_per_range;
                    let den = facet.normal.dot(&dir);
                    if den.abs() < 1e-12 {
                        continue;
                    }
                    let range = (facet.offset_m - facet.normal.dot(&origin)) / den;
                    // Incidence beyond the grazing angle, compared as cosines (acos is decreasing).
                    let cos_incidence = den.abs().min(1.0);
                    if range < camera.min_range_m
                        || range > camera.max_range_m
                        || cos_incidence < cos_grazing
                        || drop < camera.dropout_probability
                    {
                        continue;
                    }
                    let z = range * z_per_range;
                    let noise = (r * if k == 0 { cos } else { sin }) as f64;
                    let zn = z + noise * camera.depth_noise_at_1m_m * z * z;
                    let pt = origin + dir * (zn / z_per_range);
                    depth[u] = zn as f32;
                    pts[u] = [pt.x as f32, pt.y as f32, pt.z as f32];
                    truth[u] = Some(facet.tag);
                }
            }
        });
    c
}
