//! Depth by rasterization: a z-buffer of triangles seen through the pinhole camera, each pixel
//! keeping the nearest facet whose triangle covers its centre.
//!
//! Job: project every triangle of the solids the world shows ([`crate::physics::ViewMesh`]) into
//! the image, clipped at a near plane; test each pixel centre (u + 0.5, v + 0.5, the centre of
//! [`Camera::pixel_dir`]) inside it by edge functions (a wide triangle's rows only over the
//! columns its edges allow, and a column either side), interpolate 1/z (exact for a plane under
//! perspective) and keep the nearest facet. The buffer only decides which facet each pixel sees;
//! the capture then cuts the pixel's ray with that facet's plane in f64, so depths are the exact
//! ray-plane distances. Rows are split into bands rasterized in parallel: the result does not
//! depend on the threads (each pixel takes the first facet, in the meshes' order, of the
//! largest inverse depth as f32).
//!
//! Units: m, px. Frames: world (facet planes), camera optical frame (z along the view).

use nalgebra::Vector3;
use rayon::prelude::*;

use super::{Camera, PixelWindow};
use crate::physics::{Tag, ViewMesh};

/// A triangle's plane and what it belongs to.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Facet {
    /// Unit normal (world; either side).
    pub normal: Vector3<f64>,
    /// `normal . p` for the points p of the plane (m).
    pub offset_m: f64,
    /// The solid.
    pub tag: Tag,
}

/// Nearest facet per pixel of a window of the image (the rest of the image is never drawn).
#[derive(Debug, Clone)]
pub(crate) struct ZBuffer {
    /// The pixels the buffer holds.
    pub window: PixelWindow,
    /// Inverse depth along the optical axis per pixel of the window, row-major; 0 where nothing
    /// covers it (1/m): the nearest surface has the largest.
    pub inv_depth: Vec<f32>,
    /// Facet index per pixel of the window; [`NO_FACET`] where nothing covers it.
    pub facet: Vec<u32>,
}

/// No facet covers the pixel.
pub(crate) const NO_FACET: u32 = u32::MAX;

/// Triangles closer to the optical centre than this are clipped (m).
const NEAR_M: f64 = 1e-3;

/// Rows per band rasterized by one thread.
const BAND_ROWS: usize = 16;

impl ZBuffer {
    /// An empty buffer for the pixels of `window` (within its camera's image).
    pub fn empty(window: PixelWindow) -> Self {
        let n = window.width_px * window.height_px;
        ZBuffer {
            window,
            inv_depth: vec![0.0; n],
            facet: vec![NO_FACET; n],
        }
    }
}

/// A triangle in the image: pixel coordinates and inverse depth per vertex, its facet, and the
/// pixel rows it may cover (inclusive).
#[derive(Debug)]
struct ScreenTri {
    x: [f64; 3],
    y: [f64; 3],
    inv_z: [f64; 3],
    facet: u32,
    rows: (usize, usize),
}

/// Rasterizes `meshes` into the pixels of `zb`'s window (over what it holds), appending the
/// facets of the triangles that reach the window to `facets`. A convex mesh's facets facing away
/// from the camera are skipped: a ray from outside enters a convex solid through a facet facing
/// it. A pixel gets the same facet whatever the window (the window only skips pixels).
pub(crate) fn rasterize(camera: &Camera, meshes: &[ViewMesh], zb: &mut ZBuffer, facets: &mut Vec<Facet>) {
    let window = &zb.window.clone();
    let camera_from_world = camera.world_from_camera.inverse();
    let eye = camera.world_from_camera.translation.vector;
    let mut tris: Vec<ScreenTri> = Vec::new();
    for mesh in meshes {
        let cam: Vec<Vector3<f64>> = mesh
            .vertices_m
            .iter()
            .map(|p| camera_from_world.transform_point(&(*p).into()).coords)
            .collect();
        let centre = mesh.vertices_m.iter().sum::<Vector3<f64>>() / mesh.vertices_m.len().max(1) as f64;
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.vertices_m[i as usize]);
            let n = (b - a).cross(&(c - a));
            let len = n.norm();
            if len < 1e-18 {
                continue;
            }
            let mut normal = n / len;
            if mesh.convex {
                if normal.dot(&(a - centre)) < 0.0 {
                    normal = -normal;
                }
                if normal.dot(&(a - eye)) >= 0.0 {
                    continue;
                }
            }
            let facet = facets.len() as u32;
            let before = tris.len();
            clip_and_project(
                camera,
                window,
                [cam[t[0] as usize], cam[t[1] as usize], cam[t[2] as usize]],
                facet,
                &mut tris,
            );
            if tris.len() > before {
                facets.push(Facet {
                    normal,
                    offset_m: normal.dot(&a),
                    tag: mesh.tag,
                });
            }
        }
    }
    // Bin the triangles by bands of the window's rows, in their order (their rows are the
    // window's).
    let (w, y0) = (window.width_px, window.y0_px);
    if w == 0 || window.height_px == 0 {
        return;
    }
    let bands = window.height_px.div_ceil(BAND_ROWS);
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (k, t) in tris.iter().enumerate() {
        for band in binned
            .iter_mut()
            .take((t.rows.1 - y0) / BAND_ROWS + 1)
            .skip((t.rows.0 - y0) / BAND_ROWS)
        {
            band.push(k as u32);
        }
    }
    zb.inv_depth
        .par_chunks_mut(BAND_ROWS * w)
        .zip(zb.facet.par_chunks_mut(BAND_ROWS * w))
        .zip(binned.par_iter())
        .enumerate()
        .for_each(|(band, ((depth, facet), list))| {
            let v0 = y0 + band * BAND_ROWS;
            let v1 = (v0 + BAND_ROWS).min(y0 + window.height_px) - 1;
            for &k in list {
                draw(&tris[k as usize], window, v0, v1, depth, facet);
            }
        });
}

/// Draws one triangle into the image rows `v0..=v1` of a band of `window`'s rows (`depth`,
/// `facet` start at the window's pixel of row `v0`), within the window's columns (its rows are in
/// the triangle's).
fn draw(t: &ScreenTri, window: &PixelWindow, v0: usize, v1: usize, inv_depth: &mut [f32], facet: &mut [u32]) {
    let [x0, x1, x2] = t.x;
    let [y0, y1, y2] = t.y;
    let area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
    if area.abs() < 1e-12 {
        return;
    }
    let inv = 1.0 / area;
    // Barycentric weight i = (a_i x + b_i y + c_i) / area, the edge function of the opposite edge.
    let edge =
        |(xa, ya): (f64, f64), (xb, yb): (f64, f64)| ((ya - yb) * inv, (xb - xa) * inv, (xa * yb - xb * ya) * inv);
    let e0 = edge((x1, y1), (x2, y2));
    let e1 = edge((x2, y2), (x0, y0));
    let e2 = edge((x0, y0), (x1, y1));
    let xmin = x0.min(x1).min(x2);
    let xmax = x0.max(x1).max(x2);
    let u_lo = (xmin - 0.5).ceil().max(window.x0_px as f64);
    let u_hi = (xmax - 0.5).floor().min((window.x0_px + window.width_px) as f64 - 1.0);
    if u_lo > u_hi {
        return;
    }
    let (u_lo, u_hi) = (u_lo as usize, u_hi as usize);
    // Inclusive edges, a hair wide: a pixel centre on an edge shared by two triangles is covered.
    const EPS: f64 = -1e-12;
    let spans = (u_hi - u_lo >= SPAN_MIN_COLUMNS).then(|| RowSpans::new([e0, e1, e2], EPS));
    for v in t.rows.0.max(v0)..=t.rows.1.min(v1) {
        let py = v as f64 + 0.5;
        let row = (v - v0) * window.width_px;
        // The row's columns that may be inside, widened by a pixel each way: a long thin
        // triangle across the image covers a small part of its bounding box. The test below
        // still decides every pixel, so the span changes no result, only the pixels tried.
        let Some((s_lo, s_hi)) = spans.as_ref().map_or(Some((u_lo, u_hi)), |sp| sp.at(py, u_lo, u_hi)) else {
            continue;
        };
        for u in s_lo..=s_hi {
            let px = u as f64 + 0.5;
            let b0 = e0.0 * px + e0.1 * py + e0.2;
            let b1 = e1.0 * px + e1.1 * py + e1.2;
            let b2 = e2.0 * px + e2.1 * py + e2.2;
            if b0 < EPS || b1 < EPS || b2 < EPS {
                continue;
            }
            let inv_z = (b0 * t.inv_z[0] + b1 * t.inv_z[1] + b2 * t.inv_z[2]) as f32;
            let i = row + u - window.x0_px;
            if inv_z > inv_depth[i] {
                inv_depth[i] = inv_z;
                facet[i] = t.facet;
            }
        }
    }
}

/// A triangle's columns per pixel row: where its three edge tests `a x + b y + c >= eps` may
/// all pass, as bounds linear in the row's centre y, for a triangle spanning
/// [`SPAN_MIN_COLUMNS`] or more (a narrower one tries its few columns outright).
struct RowSpans {
    edges: [EdgeBound; 3],
    eps: f64,
}

/// One edge test as a bound on the columns of a row at y.
#[derive(Clone, Copy)]
enum EdgeBound {
    /// `x >= x0 + dx_dy * y` (`a > 0`).
    Lower { x0: f64, dx_dy: f64 },
    /// `x <= x0 + dx_dy * y` (`a < 0`).
    Upper { x0: f64, dx_dy: f64 },
    /// `a == 0`: the row passes if `b y + c >= eps`, whatever x.
    Row { b: f64, c: f64 },
    /// No bound the span uses.
    Free,
}

/// An edge bound's largest slope (columns per row) that [`RowSpans`] uses: its columns are then
/// exact to far below a column, which the span's one column of widening covers.
const MAX_SLOPE: f64 = 1e6;

/// Triangles spanning fewer columns than this are drawn without [`RowSpans`] (px).
const SPAN_MIN_COLUMNS: usize = 16;

impl RowSpans {
    fn new(edges: [(f64, f64, f64); 3], eps: f64) -> Self {
        let edges = edges.map(|(a, b, c)| {
            let (x0, dx_dy) = ((eps - c) / a, -b / a);
            // An edge within a hair of the row's direction bounds the columns only through
            // huge terms that cancel: it restricts nothing (the pixel test still applies it).
            if a != 0.0 && !(dx_dy.abs() <= MAX_SLOPE && x0.abs() <= MAX_SLOPE * 1e3) {
                EdgeBound::Free
            } else if a > 0.0 {
                EdgeBound::Lower { x0, dx_dy }
            } else if a < 0.0 {
                EdgeBound::Upper { x0, dx_dy }
            } else {
                EdgeBound::Row { b, c }
            }
        });
        RowSpans { edges, eps }
    }

    /// The columns `u_lo..=u_hi` of the row at `py` whose centres (u + 0.5) may pass all three
    /// tests, widened by a column each way; `None` if none can.
    fn at(&self, py: f64, u_lo: usize, u_hi: usize) -> Option<(usize, usize)> {
        let (mut x_lo, mut x_hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for e in &self.edges {
            match *e {
                EdgeBound::Lower { x0, dx_dy } => x_lo = x_lo.max(x0 + dx_dy * py),
                EdgeBound::Upper { x0, dx_dy } => x_hi = x_hi.min(x0 + dx_dy * py),
                EdgeBound::Row { b, c } if b * py + c < self.eps => return None,
                EdgeBound::Row { .. } | EdgeBound::Free => {}
            }
        }
        // Pixel centres u + 0.5 within [x_lo, x_hi], one column more each way.
        let first = ((x_lo - 0.5).ceil() - 1.0).max(u_lo as f64);
        let last = ((x_hi - 0.5).floor() + 1.0).min(u_hi as f64);
        (first <= last).then_some((first as usize, last as usize))
    }
}

/// Clips a triangle (camera frame, m) at the near plane and projects what is left into the
/// image as one or two screen triangles, kept if they may cover a pixel centre of `window`.
fn clip_and_project(camera: &Camera, window: &PixelWindow, v: [Vector3<f64>; 3], facet: u32, out: &mut Vec<ScreenTri>) {
    if v.iter().all(|p| p.z < NEAR_M) || v.iter().all(|p| p.z > camera.max_range_m) {
        return;
    }
    let mut poly: Vec<Vector3<f64>> = Vec::with_capacity(4);
    for k in 0..3 {
        let (a, b) = (v[k], v[(k + 1) % 3]);
        if a.z >= NEAR_M {
            poly.push(a);
        }
        if (a.z >= NEAR_M) != (b.z >= NEAR_M) {
            let s = (NEAR_M - a.z) / (b.z - a.z);
            poly.push(a + (b - a) * s);
        }
    }
    // The window's first and last pixel row and column.
    let (u_first, v_first) = (window.x0_px as f64, window.y0_px as f64);
    let u_last = (window.x0_px + window.width_px).min(camera.width_px) as f64 - 1.0;
    let v_last = (window.y0_px + window.height_px).min(camera.height_px) as f64 - 1.0;
    let project = |p: &Vector3<f64>| {
        (
            camera.fx_px * p.x / p.z + camera.cx_px,
            camera.fy_px * p.y / p.z + camera.cy_px,
            1.0 / p.z,
        )
    };
    let pts: Vec<(f64, f64, f64)> = poly.iter().map(project).collect();
    for k in 1..pts.len().saturating_sub(1) {
        let tri = [pts[0], pts[k], pts[k + 1]];
        let ymin = tri.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        let ymax = tri.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        let xmin = tri.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let xmax = tri.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
        let (v_lo, v_hi) = ((ymin - 0.5).ceil().max(v_first), (ymax - 0.5).floor().min(v_last));
        // No pixel centre of the window's columns between the triangle's extremes.
        if v_lo > v_hi || (xmax - 0.5).floor() < u_first || (xmin - 0.5).ceil() > u_last {
            continue;
        }
        out.push(ScreenTri {
            x: tri.map(|p| p.0),
            y: tri.map(|p| p.1),
            inv_z: tri.map(|p| p.2),
            facet,
            rows: (v_lo as usize, v_hi as usize),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// Every pixel of `window` whose centre the triangle's edge functions (as `draw` forms them)
    /// put inside, tried one by one: what `draw` must cover, whatever pixels it skips.
    fn covered_by_every_pixel(t: &ScreenTri, window: &PixelWindow) -> Vec<usize> {
        let ([x0, x1, x2], [y0, y1, y2]) = (t.x, t.y);
        let inv = 1.0 / ((x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0));
        let edge = |(xa, ya): (f64, f64), (xb, yb): (f64, f64)| {
            move |px: f64, py: f64| ((ya - yb) * inv) * px + ((xb - xa) * inv) * py + (xa * yb - xb * ya) * inv
        };
        let es = [
            edge((x1, y1), (x2, y2)),
            edge((x2, y2), (x0, y0)),
            edge((x0, y0), (x1, y1)),
        ];
        let mut out = Vec::new();
        for v in window.y0_px..window.y0_px + window.height_px {
            for u in window.x0_px..window.x0_px + window.width_px {
                let (px, py) = (u as f64 + 0.5, v as f64 + 0.5);
                if es.iter().all(|e| e(px, py) >= -1e-12) {
                    out.push((v - window.y0_px) * window.width_px + u - window.x0_px);
                }
            }
        }
        out
    }

    #[test]
    fn a_triangle_covers_the_same_pixels_as_a_test_of_every_pixel() {
        let window = PixelWindow {
            x0_px: 5,
            y0_px: 3,
            width_px: 60,
            height_px: 40,
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (mut thin, mut total) = (0, 0);
        for case in 0..2000 {
            // Long thin slivers at every angle (a strip's face) and ordinary triangles.
            let x: [f64; 3] = std::array::from_fn(|_| rng.random_range(-10.0..80.0));
            let y: [f64; 3] = std::array::from_fn(|_| rng.random_range(-10.0..50.0));
            let (x, y) = if case % 2 == 0 {
                let s = rng.random_range(0.001..0.05);
                (
                    [x[0], x[1], x[1] + s * (x[0] - x[1])],
                    [y[0], y[1], y[1] + s * (y[0] - y[1]) + 1.0],
                )
            } else {
                (x, y)
            };
            let ymin = y.iter().copied().fold(f64::INFINITY, f64::min);
            let ymax = y.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let (v_lo, v_hi) = ((ymin - 0.5).ceil().max(3.0), (ymax - 0.5).floor().min(42.0));
            if v_lo > v_hi {
                continue;
            }
            let t = ScreenTri {
                x,
                y,
                inv_z: [1.0, 1.0, 1.0],
                facet: 0,
                rows: (v_lo as usize, v_hi as usize),
            };
            let mut zb = ZBuffer::empty(window);
            draw(&t, &window, 3, 42, &mut zb.inv_depth, &mut zb.facet);
            let drawn: Vec<usize> = (0..zb.facet.len()).filter(|&i| zb.facet[i] == 0).collect();
            assert_eq!(drawn, covered_by_every_pixel(&t, &window), "case {case}: {t:?}");
            total += 1;
            thin += usize::from(case % 2 == 0 && !drawn.is_empty());
        }
        assert!(total > 1500 && thin > 200, "{total} triangles, {thin} slivers drawn");
    }
}
