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

/// One depth capture. Only the pixels of its [`Capture::tray_window`] are measured and stored;
/// every other pixel of the image has no return ([`Capture::depth_at_m`] reads any pixel).
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
    /// Depth along the optical axis per pixel of the tray window, row-major; 0 where there is no
    /// return (m).
    pub depth_m: Vec<f32>,
    /// World point per pixel of the tray window, row-major (NaN where there is no return) (m):
    /// the organised point cloud.
    pub points_world: Vec<[f32; 3]>,
    /// What each valid pixel's ray hit, per pixel of the tray window: ground truth for the
    /// recognition model's visibility counts and for evaluation only (see
    /// [`super::recognition`]).
    pub(super) truth: Vec<Option<Tag>>,
    /// The sensor's region of interest ([`capture_window`]): the pixels that see the pick tray
    /// (its outer walls, floor to rim) and what can lie across its rim around and above it, and
    /// [`TRAY_WINDOW_MARGIN_PX`] around them. Only these are measured; every other pixel has no
    /// return. No other pixel's ray meets the tray or a part across its rim.
    pub tray_window: PixelWindow,
    /// How far beyond the tray's outer walls and above its rim the window reaches
    /// ([`beyond_walls_m`] of the part) (m); 0 for a window over the tray alone.
    pub beyond_walls_m: f64,
}

/// The grey of the farthest return in [`Capture::write_depth_view_png`], apart from the black of
/// no return.
pub const DEPTH_VIEW_FARTHEST: u8 = 48;

/// The percentile of the returns' depths that [`Capture::write_depth_view_png`] shows white, and
/// everything nearer.
pub const DEPTH_VIEW_NEAR_PERCENT: usize = 10;

/// The margin of a capture's [`Capture::tray_window`] around the tray's image (px): 8.5 mm at
/// the tray floor with the default sensor, a wall's thickness, so a part resting on the rim is
/// in the image.
pub const TRAY_WINDOW_MARGIN_PX: usize = 10;

/// How far beyond the pick tray's outer walls, and above its rim, a part lying across the rim can
/// reach (m), for parts of bounding box `part_size_m` (the workpiece's `size_m`): its half
/// diagonal (a part hanging out by more than half its length has its centre of mass outside and
/// falls off), rounded up to a whole [`BEYOND_WALLS_STEP_M`]. A capture measures that far around
/// the tray ([`capture_window`]), and the height map reaches it.
pub fn beyond_walls_m(part_size_m: &[f64; 3]) -> f64 {
    let half_diagonal_m = 0.5 * Vector3::from(*part_size_m).norm();
    (half_diagonal_m / BEYOND_WALLS_STEP_M - 1e-9).ceil().max(1.0) * BEYOND_WALLS_STEP_M
}

/// The step [`beyond_walls_m`] rounds to (m): a whole number of the planner's pooled pile cells,
/// so a map grown by it pools every cell over the tray as before (checked in `pipeline`).
pub const BEYOND_WALLS_STEP_M: f64 = 0.01;

/// The window of `camera`'s image a capture over `tray` measures: the tray and what can lie
/// across its rim, [`beyond_walls_m`] of parts of bounding box `part_size_m` around its
/// outer walls and above its rim, with [`TRAY_WINDOW_MARGIN_PX`] around that.
pub fn capture_window(camera: &Camera, tray: &crate::geometry::TrayVolume, part_size_m: &[f64; 3]) -> PixelWindow {
    camera.window_over(&tray.grown_by(beyond_walls_m(part_size_m)), TRAY_WINDOW_MARGIN_PX)
}

impl Capture {
    /// A capture of an image `width_px` x `height_px` with no return in any pixel, measuring the
    /// pixels of `tray_window`.
    pub fn blank(
        id: u64,
        trigger_s: f64,
        camera_position_m: Vector3<f64>,
        (width_px, height_px): (usize, usize),
        tray_window: PixelWindow,
    ) -> Self {
        let n = tray_window.width_px * tray_window.height_px;
        Capture {
            id,
            trigger_s,
            camera_position_m,
            width_px,
            height_px,
            depth_m: vec![0.0; n],
            points_world: vec![[f32::NAN; 3]; n],
            truth: vec![None; n],
            tray_window,
            beyond_walls_m: 0.0,
        }
    }

    /// The index of image pixel (`u_px`, `v_px`) in the capture's buffers; `None` outside its
    /// tray window.
    pub fn index_of(&self, u_px: usize, v_px: usize) -> Option<usize> {
        let w = &self.tray_window;
        let (u, v) = (u_px.checked_sub(w.x0_px)?, v_px.checked_sub(w.y0_px)?);
        (u < w.width_px && v < w.height_px).then_some(v * w.width_px + u)
    }

    /// Depth of image pixel (`u_px`, `v_px`) (m); 0 where there is no return, as everywhere
    /// outside the tray window.
    pub fn depth_at_m(&self, u_px: usize, v_px: usize) -> f32 {
        self.index_of(u_px, v_px).map_or(0.0, |i| self.depth_m[i])
    }

    /// World point of image pixel (`u_px`, `v_px`) (m); NaN where there is no return, as
    /// everywhere outside the tray window.
    pub fn point_at_world(&self, u_px: usize, v_px: usize) -> [f32; 3] {
        self.index_of(u_px, v_px)
            .map_or([f32::NAN; 3], |i| self.points_world[i])
    }

    /// Sets image pixel (`u_px`, `v_px`)'s return: its depth (m) and world point (m). A pixel
    /// outside the tray window is not measured, and is left without a return.
    pub fn set_return(&mut self, u_px: usize, v_px: usize, depth_m: f32, point_world: [f32; 3]) {
        if let Some(i) = self.index_of(u_px, v_px) {
            self.depth_m[i] = depth_m;
            self.points_world[i] = point_world;
        }
    }

    /// Clears image pixel (`u_px`, `v_px`)'s return (no return), if it had one.
    pub fn clear_return(&mut self, u_px: usize, v_px: usize) {
        if let Some(i) = self.index_of(u_px, v_px) {
            self.depth_m[i] = 0.0;
            self.points_world[i] = [f32::NAN; 3];
            self.truth[i] = None;
        }
    }

    /// Number of pixels with a return.
    pub fn valid_count(&self) -> usize {
        self.depth_m.iter().filter(|d| **d > 0.0).count()
    }

    /// Writes the depth image as a 16-bit greyscale PNG in millimetres (0 = no return).
    pub fn write_depth_png(&self, path: &Path) -> std::io::Result<()> {
        self.write_grey_png(path, png::BitDepth::Sixteen, |d, out| {
            out.copy_from_slice(&((d as f64 * 1000.0).round().clamp(0.0, 65535.0) as u16).to_be_bytes());
        })
    }

    /// Writes the depth image for the eye as an 8-bit greyscale PNG: the nearest returns white
    /// (255), the farthest dark grey ([`DEPTH_VIEW_FARTHEST`]), no return black; between them the
    /// grey rises with the square root of the height over the farthest return (the tray floor),
    /// so that parts a few millimetres high stand out from the floor under walls ten times their
    /// height. "Nearest" is the [`DEPTH_VIEW_NEAR_PERCENT`]th percentile, so that an arm over the
    /// tray, a fraction of the returns, does not take the greys from the pile. The millimetres
    /// are [`Capture::write_depth_png`]'s: there a tray's depths (about 0.6-0.9 m) fill only the
    /// darkest hundredth of the 16-bit range, and an ordinary viewer shows the image black.
    pub fn write_depth_view_png(&self, path: &Path) -> std::io::Result<()> {
        let mut valid: Vec<f32> = self.depth_m.iter().copied().filter(|d| *d > 0.0).collect();
        valid.sort_unstable_by(f32::total_cmp);
        let near_m = valid
            .get(valid.len() * DEPTH_VIEW_NEAR_PERCENT / 100)
            .copied()
            .unwrap_or(0.0);
        let far_m = valid.last().copied().unwrap_or(0.0);
        let span_m = (far_m - near_m).max(1e-6);
        let top = f32::from(u8::MAX);
        let bottom = f32::from(DEPTH_VIEW_FARTHEST);
        self.write_grey_png(path, png::BitDepth::Eight, |d, out| {
            if d > 0.0 {
                let rise = ((far_m - d) / span_m).clamp(0.0, 1.0).sqrt();
                out[0] = (bottom + (top - bottom) * rise).round() as u8;
            }
        })
    }

    /// Writes a greyscale PNG of the whole image at `bit_depth` (8 or 16), each tray-window pixel
    /// encoded from its depth (m; 0: no return) by `encode` into its bytes (big-endian), every
    /// other pixel 0.
    fn write_grey_png(
        &self,
        path: &Path,
        bit_depth: png::BitDepth,
        encode: impl Fn(f32, &mut [u8]),
    ) -> std::io::Result<()> {
        let file = std::fs::File::create(path)?;
        let mut enc = png::Encoder::new(
            std::io::BufWriter::new(file),
            self.width_px as u32,
            self.height_px as u32,
        );
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(bit_depth);
        let mut w = enc.write_header().map_err(std::io::Error::other)?;
        let px = if bit_depth == png::BitDepth::Sixteen { 2 } else { 1 };
        let mut bytes = vec![0u8; px * self.width_px * self.height_px];
        let win = &self.tray_window;
        for (v, row) in self.depth_m.chunks_exact(win.width_px.max(1)).enumerate() {
            let first = px * ((win.y0_px + v) * self.width_px + win.x0_px);
            for (out, d) in bytes[first..first + px * row.len()].chunks_exact_mut(px).zip(row) {
                encode(*d, out);
            }
        }
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
    /// Rasterizes the fixed colliders of `world` into the pixels of `camera`'s image over the
    /// pick tray (its tray window, [`capture_window`]).
    pub fn new(world: &World, camera: &Camera) -> Self {
        let mut zbuffer = ZBuffer::empty(capture_window(camera, world.pick_tray(), &world.part_shape().size_m));
        let mut facets = Vec::new();
        rasterize(
            camera,
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
    let window = capture_window(camera, world.pick_tray(), &world.part_shape().size_m);
    // A background rasterized over another window (another tray) does not hold these pixels.
    let fresh;
    let bg = match background {
        Some(b) if b.zbuffer.window == window => b,
        _ => {
            fresh = Background::new(world, camera);
            &fresh
        }
    };
    let mut zb = bg.zbuffer.clone();
    let mut facets = bg.facets.clone();
    rasterize(
        camera,
        &world.view_meshes(RayTargets::Moving, FACET_CHORD_M),
        &mut zb,
        &mut facets,
    );
    let cos_grazing = camera.dropout_grazing_rad.cos();
    let pairs = w.div_ceil(2);
    // Beyond the tray's own window only what moves is measured (parts, the arm, the held part):
    // the fixed cell there (the table, the walls' outer faces) lies below the rim, where nothing
    // the cell reads looks. Facets from `fixed` on are the moving ones.
    let tray_window = camera.window_over(world.pick_tray(), TRAY_WINDOW_MARGIN_PX);
    let fixed = bg.facets.len() as u32;
    let mut c = Capture::blank(id, world.time_s(), origin, (w, h), window);
    c.beyond_walls_m = beyond_walls_m(&world.part_shape().size_m);
    // The pairs of pixels that hold the window's columns.
    let window_pairs = window.x0_px / 2..(window.x0_px + window.width_px).div_ceil(2).min(pairs);
    let ww = window.width_px.max(1);
    c.depth_m
        .par_chunks_mut(ww)
        .zip(c.points_world.par_chunks_mut(ww))
        .zip(c.truth.par_chunks_mut(ww))
        .zip(zb.facet.par_chunks(ww))
        .enumerate()
        .for_each(|(row, (((depth, pts), truth), row_facets))| {
            let v = window.y0_px + row;
            let mut rng = stream.clone();
            // Each u64 draw takes two 32-bit words; pair p of row v draws from its own position
            // in the stream, whichever pairs before it were measured.
            let word_of =
                |p: usize| ((id as u128 * h as u128 + v as u128) * pairs as u128 + p as u128) * DRAWS_PER_PAIR * 2;
            rng.set_word_pos(word_of(window_pairs.start));
            let row_in_tray = (tray_window.y0_px..tray_window.y0_px + tray_window.height_px).contains(&v);
            let mut skipped = false;
            // The window's pixel of image column u, if it is in the window.
            let at = |u: usize| u.checked_sub(window.x0_px).filter(|k| *k < window.width_px);
            let y = (v as f64 + 0.5 - camera.cy_px) / camera.fy_px;
            // The unnormalised ray through (u + 0.5, v + 0.5) in the world: row + u * step.
            let row_dir = rotation * Vector3::new((0.5 - camera.cx_px) / camera.fx_px, y, 1.0);
            let step = rotation.column(0) / camera.fx_px;
            for p in window_pairs.clone() {
                let in_tray =
                    row_in_tray && 2 * p + 1 >= tray_window.x0_px && 2 * p < tray_window.x0_px + tray_window.width_px;
                if !in_tray {
                    let moving = |u: usize| at(u).is_some_and(|k| row_facets[k] != NO_FACET && row_facets[k] >= fixed);
                    if !moving(2 * p) && !moving((2 * p + 1).min(w - 1)) {
                        skipped = true;
                        continue;
                    }
                }
                if skipped {
                    rng.set_word_pos(word_of(p));
                    skipped = false;
                }
                let noise_bits: u64 = rng.random();
                let drop_bits: u64 = rng.random();
                let (u_a, u_b) = (2 * p, (2 * p + 1).min(w - 1));
                let facet_at = |u: usize| at(u).map_or(NO_FACET, |k| row_facets[k]);
                if facet_at(u_a) == NO_FACET && facet_at(u_b) == NO_FACET {
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
                    let f = facet_at(u);
                    if f == NO_FACET {
                        continue;
                    }
                    // A pixel with a facet is in the window.
                    let k_px = u - window.x0_px;
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
                    depth[k_px] = zn as f32;
                    pts[k_px] = [pt.x as f32, pt.y as f32, pt.z as f32];
                    truth[k_px] = Some(facet.tag);
                }
            }
        });
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A capture stores its tray window's pixels only and reads every pixel of the image: its
    /// window's through the buffers, every other one as no return. Its depth PNG is the whole
    /// image, the window's depths at their own pixels. Negative control: the transposed pixel
    /// holds nothing, and a return set outside the window is not measured.
    #[test]
    fn a_capture_holds_its_window_and_reads_no_return_outside_it() {
        let window = PixelWindow {
            x0_px: 3,
            y0_px: 2,
            width_px: 4,
            height_px: 3,
        };
        let mut c = Capture::blank(0, 0.0, Vector3::zeros(), (10, 8), window);
        assert_eq!(c.depth_m.len(), 12);
        c.set_return(4, 3, 0.5, [1.0, 2.0, 3.0]);
        c.set_return(0, 0, 0.7, [1.0, 1.0, 1.0]);
        assert_eq!(c.index_of(4, 3), Some(5));
        assert_eq!(c.index_of(7, 3), None, "the window's columns end at 6");
        assert_eq!(c.index_of(0, 0), None);
        assert_eq!(c.depth_at_m(4, 3), 0.5);
        assert_eq!(c.point_at_world(4, 3), [1.0, 2.0, 3.0]);
        assert_eq!(c.depth_at_m(3, 4), 0.0);
        assert_eq!(c.depth_at_m(0, 0), 0.0);
        assert!(c.point_at_world(0, 0)[0].is_nan());
        assert_eq!(c.valid_count(), 1);
        let dir = std::env::temp_dir().join(format!("binpick-capture-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("depth.png");
        c.write_depth_png(&path).unwrap();
        let mut reader = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()))
            .read_info()
            .unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (10, 8));
        let mm = |u: usize, v: usize| u16::from_be_bytes([buf[2 * (v * 10 + u)], buf[2 * (v * 10 + u) + 1]]);
        assert_eq!(mm(4, 3), 500);
        assert_eq!(mm(3, 4), 0);
        assert_eq!(mm(0, 0), 0);
        assert_eq!(
            (0..8)
                .flat_map(|v| (0..10).map(move |u| (u, v)))
                .filter(|&(u, v)| mm(u, v) > 0)
                .count(),
            1
        );
        // For the eye: the nearer return white, the farther dark grey, no return black; the
        // 16-bit image above gave both under 1 % of full scale.
        let view = dir.join("depth-view.png");
        c.set_return(5, 3, 0.8, [1.0, 2.0, 3.0]);
        c.write_depth_view_png(&view).unwrap();
        let mut reader = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&view).unwrap()))
            .read_info()
            .unwrap();
        let mut grey = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut grey).unwrap();
        assert_eq!(grey.len(), 80);
        assert_eq!((grey[3 * 10 + 4], grey[3 * 10 + 5]), (255, DEPTH_VIEW_FARTHEST));
        assert_eq!(grey.iter().filter(|g| **g > 0).count(), 2);
        assert!(mm(4, 3) < 65535 / 100);
        c.clear_return(5, 3);
        c.clear_return(4, 3);
        assert_eq!((c.depth_at_m(4, 3), c.valid_count()), (0.0, 0));
        std::fs::remove_dir_all(&dir).ok();
    }
}
