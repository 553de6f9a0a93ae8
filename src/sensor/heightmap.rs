//! The height map: a capture's point cloud binned over the pick tray, the highest point per cell,
//! as the grasp selector and the planner see the pile, and the mean per cell, the surface a cup
//! touches.
//!
//! Units: m. Frames: the pick tray frame (origin at the centre of the inner floor surface, z up).

use nalgebra::{Isometry3, Point3};

use super::Capture;

/// A cell's mean height within this of the median cell's under a disc is on the same surface (m):
/// four times the spread of a cell's mean over a flat face (0.3 mm of noise over the 4 to 9
/// points of a 2 mm cell at 0.85 mm pixels), well below a part's step (1 mm and more).
pub const SAME_SURFACE_M: f64 = 0.0006;

/// What a height map holds beyond the pick tray's outer walls ([`HeightMap::from_capture`]).
pub struct BeyondWalls<'a> {
    /// How far beyond the outer walls the map reaches (m): rounded to whole cells.
    pub reach_m: f64,
    /// Only points higher than this above the tray floor count outside the view frustum over the
    /// tray (m): what stands over the rim.
    pub above_m: f64,
    /// Whether a world point is on the arm, its hand or the part it holds, as the controller knows
    /// them at the trigger (the self-filter).
    pub is_arm: &'a dyn Fn(&Point3<f64>) -> bool,
}

/// A height map of the pick tray built from a capture's point cloud: the highest point per cell,
/// and the mean of its points.
#[derive(Debug, Clone)]
pub struct HeightMap {
    /// `world_from_tray` of the pick tray.
    pub world_from_tray: Isometry3<f64>,
    /// Cell edge (m).
    pub cell_m: f64,
    /// Cells along x and y.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
    /// Lower corner of cell (0, 0) in the tray frame (m).
    pub origin_xy_m: [f64; 2],
    /// Highest point per cell above the tray floor, NaN where nothing was seen (m).
    pub height_m: Vec<f64>,
    /// Mean height of each cell's points, NaN where nothing was seen (m): the surface without the
    /// highest point's bias from depth noise. `None` on maps not binned from a capture (each cell
    /// one height), where [`HeightMap::surface_within`] reads `height_m`.
    pub mean_m: Option<Vec<f64>>,
}

impl HeightMap {
    /// Bins the capture's points over the tray (walls included) into `cell_m` cells. Only points
    /// inside the view frustum over the tray count (their ray meets the floor plane within the
    /// tray): a point above the tray's footprint but outside the frustum is seen through the air
    /// beside the tray, not over it, and may be the arm's (the cell keeps the arm out of the
    /// frustum only). With `beyond`, the map reaches [`BeyondWalls::reach_m`] farther around
    /// the tray, and a point outside the frustum over the tray but inside the one over that wider
    /// footprint counts too, if it stands higher than [`BeyondWalls::above_m`] and is not the
    /// arm's ([`BeyondWalls::is_arm`]): a part lying across the rim, its end beyond the wall.
    /// Every point the map without `beyond` holds lands in the same cell with it.
    pub fn from_capture(
        c: &Capture,
        t: &crate::geometry::TrayVolume,
        cell_m: f64,
        beyond: Option<&BeyondWalls<'_>>,
    ) -> Self {
        let [hx, hy] = t.half_xy_m;
        let (nx0, ny0) = (
            ((2.0 * hx) / cell_m).ceil() as usize,
            ((2.0 * hy) / cell_m).ceil() as usize,
        );
        // Whole cells beyond the walls each side.
        let k = beyond.map_or(0, |b| (b.reach_m / cell_m).round() as usize);
        let reach_m = k as f64 * cell_m;
        let (nx, ny) = (nx0 + 2 * k, ny0 + 2 * k);
        let mut hm = HeightMap {
            world_from_tray: t.world_from_tray,
            cell_m,
            nx,
            ny,
            origin_xy_m: [-hx - reach_m, -hy - reach_m],
            height_m: vec![f64::NAN; nx * ny],
            mean_m: None,
        };
        // Each cell's points' sum, then their mean.
        let mut mean_m = vec![0.0; nx * ny];
        let mut count = vec![0u32; nx * ny];
        let tray_from_world = t.world_from_tray.inverse();
        let apex = tray_from_world * Point3::from(c.camera_position_m);
        // The cell of tray point (x, y), counted from the tray's outer corner as the map without
        // `beyond` counts it (`over_tray`: within that map), then shifted by the cells beyond.
        let cell_of = |x: f64, y: f64, over_tray: bool| {
            let i = ((x + hx) / cell_m).floor() + k as f64;
            let j = ((y + hy) / cell_m).floor() + k as f64;
            let (lo, hi_x, hi_y) = if over_tray {
                (k as f64, (k + nx0) as f64, (k + ny0) as f64)
            } else {
                (0.0, nx as f64, ny as f64)
            };
            (i >= lo && j >= lo && i < hi_x && j < hi_y).then(|| j as usize * nx + i as usize)
        };
        // The capture holds its window's points only: no other pixel sees the tray.
        for p in &c.points_world {
            if !p[0].is_finite() {
                continue;
            }
            let world = Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let l = tray_from_world * world;
            let mut over_tray = true;
            if apex.z - l.z > 1e-6 {
                let f = apex.z / (apex.z - l.z);
                let floor = apex + (l - apex) * f;
                if floor.x.abs() > hx || floor.y.abs() > hy {
                    let Some(b) = beyond else { continue };
                    if floor.x.abs() > hx + reach_m
                        || floor.y.abs() > hy + reach_m
                        || l.z <= b.above_m
                        || (b.is_arm)(&world)
                    {
                        continue;
                    }
                    over_tray = false;
                }
            }
            if let Some(k) = cell_of(l.x, l.y, over_tray) {
                let h = &mut hm.height_m[k];
                if h.is_nan() || l.z > *h {
                    *h = l.z;
                }
                mean_m[k] += l.z;
                count[k] += 1;
            }
        }
        for (m, &n) in mean_m.iter_mut().zip(&count) {
            *m = if n > 0 { *m / n as f64 } else { f64::NAN };
        }
        hm.mean_m = Some(mean_m);
        hm
    }

    /// The map with every cell whose centre lies outside the tray's inner walls (`inner_half_m`,
    /// tray frame) cleared, but those seen higher than `keep_above_m`: the walls themselves are
    /// not pile (they are in the planner's cell model), a part lying across the rim and standing
    /// above it is. (The map holds only points inside the view frustum, which the arm is out of
    /// while the sensor exposes: nothing else stands over the rim.)
    pub fn without_walls(&self, inner_half_m: [f64; 2], keep_above_m: f64) -> HeightMap {
        let mut m = self.clone();
        for j in 0..m.ny {
            for i in 0..m.nx {
                let x = m.origin_xy_m[0] + (i as f64 + 0.5) * m.cell_m;
                let y = m.origin_xy_m[1] + (j as f64 + 0.5) * m.cell_m;
                let outside = x.abs() > inner_half_m[0] || y.abs() > inner_half_m[1];
                let stands_over_rim = m.height_m[j * m.nx + i] > keep_above_m;
                if outside && !stands_over_rim {
                    m.height_m[j * m.nx + i] = f64::NAN;
                    if let Some(mean) = m.mean_m.as_mut() {
                        mean[j * m.nx + i] = f64::NAN;
                    }
                }
            }
        }
        m
    }

    /// The map with every unseen cell inside the tray's inner walls (`inner_half_m`, tray frame)
    /// filled as occupied: nothing seen there (occlusion, shadow, dropout) is not evidence of free
    /// space. Each connected region of unseen inner cells (8-connected) is filled up to the highest
    /// seen inner cell bordering it, or to `rim_height_m` if none borders it (nothing inside the
    /// walls was seen at all). Cells outside the inner walls are left as they are.
    ///
    /// Why the bordering maximum: a shadow or occlusion is cast by what borders it (the occluder's
    /// top is seen), and the line of sight past the occluder only descends behind it, so nothing
    /// hidden there reaches above the occluder's top. An isolated dropout is bounded by the same
    /// rule by its seen neighbours (a spike narrower than a cell would be assumed away; at 2 mm
    /// cells that is below what the planner's columns resolve anyway).
    pub fn unseen_filled(&self, inner_half_m: [f64; 2], rim_height_m: f64) -> HeightMap {
        let (nx, ny) = (self.nx, self.ny);
        let inside: Vec<bool> = (0..nx * ny)
            .map(|k| {
                let x = self.origin_xy_m[0] + ((k % nx) as f64 + 0.5) * self.cell_m;
                let y = self.origin_xy_m[1] + ((k / nx) as f64 + 0.5) * self.cell_m;
                x.abs() <= inner_half_m[0] && y.abs() <= inner_half_m[1]
            })
            .collect();
        let unseen = |k: usize| inside[k] && self.height_m[k].is_nan();
        let neighbours = move |k: usize| {
            let (i, j) = ((k % nx) as isize, (k / nx) as isize);
            (-1..=1isize)
                .flat_map(move |dj| (-1..=1isize).map(move |di| (i + di, j + dj)))
                .filter(move |&(a, b)| (a, b) != (i, j) && a >= 0 && b >= 0 && a < nx as isize && b < ny as isize)
                .map(move |(a, b)| b as usize * nx + a as usize)
        };
        let mut m = self.clone();
        let mut done = vec![false; nx * ny];
        let mut region = Vec::new();
        for start in 0..nx * ny {
            if done[start] || !unseen(start) {
                continue;
            }
            // Flood the region, keeping the highest seen inner cell on its border.
            region.clear();
            region.push(start);
            done[start] = true;
            let mut border = f64::NAN;
            let mut next = 0;
            while next < region.len() {
                let k = region[next];
                next += 1;
                for n in neighbours(k) {
                    if unseen(n) {
                        if !done[n] {
                            done[n] = true;
                            region.push(n);
                        }
                    } else if inside[n] && (border.is_nan() || self.height_m[n] > border) {
                        border = self.height_m[n];
                    }
                }
            }
            let fill = if border.is_nan() { rim_height_m } else { border };
            for &k in &region {
                m.height_m[k] = fill;
            }
        }
        m
    }

    /// The index into `height_m` of the cell under tray point (x, y), if it lies on the map.
    pub fn index(&self, x: f64, y: f64) -> Option<usize> {
        let i = ((x - self.origin_xy_m[0]) / self.cell_m).floor();
        let j = ((y - self.origin_xy_m[1]) / self.cell_m).floor();
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.nx && (j as usize) < self.ny)
            .then(|| j as usize * self.nx + i as usize)
    }

    /// The cells whose centres lie within `radius_m` of tray point (x, y), in row-major order:
    /// each cell's index ([`HeightMap::index`]) and stored height (m) (NaN where unseen).
    fn cells_within(&self, x: f64, y: f64, radius_m: f64) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.cells_at_within(x, y, radius_m).map(|(k, _, h)| (k, h))
    }

    /// The cells whose centres lie within `radius_m` of tray point (x, y), in row-major order:
    /// each cell's index ([`HeightMap::index`]), its centre (tray frame, m) and its stored
    /// height (m) (NaN where unseen).
    pub fn cells_at_within(&self, x: f64, y: f64, radius_m: f64) -> impl Iterator<Item = (usize, [f64; 2], f64)> + '_ {
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
            .map(move |(i, j)| {
                let k = j as usize * self.nx + i as usize;
                let cx = self.origin_xy_m[0] + (i as f64 + 0.5) * self.cell_m;
                let cy = self.origin_xy_m[1] + (j as f64 + 0.5) * self.cell_m;
                (k, [cx, cy], self.height_m[k])
            })
    }

    /// The surface under a small disc near where it should be (m) (NaN if nothing was seen there):
    /// of the cells within `radius_m` of tray point (x, y) whose mean height
    /// ([`HeightMap::mean_m`]; their highest point on maps without means) lies within `band_m`
    /// of `expected_m`, the mean of those within [`SAME_SURFACE_M`] of their median. The band
    /// and the median keep neighbouring surfaces out, the mean over the cells the depth noise.
    /// This is where a cup touches: a cell's highest point stands above a flat face by the
    /// noise's maximum over its points (at 0.85 mm pixels in 2 mm cells under 0.3 mm of noise,
    /// about 0.35 mm): the median of those ([`HeightMap::top_within`]) would put the cup that
    /// high above the face, now and then beyond the seal's touch tolerance.
    pub fn surface_within(&self, x: f64, y: f64, radius_m: f64, expected_m: f64, band_m: f64) -> f64 {
        let v = self.band_within(x, y, radius_m, expected_m, band_m, |k, h| match &self.mean_m {
            Some(mean) if mean[k].is_finite() => mean[k],
            _ => h,
        });
        let n = v.len();
        if n == 0 {
            return f64::NAN;
        }
        let median = 0.5 * (v[(n - 1) / 2] + v[n / 2]);
        crate::stats::mean_of(v.into_iter().filter(|h| (h - median).abs() <= SAME_SURFACE_M))
    }

    /// The median of the cells' highest points within `radius_m` of tray point (x, y) and within
    /// `band_m` of `expected_m` (m) (NaN if none): the face's top as the cells' maxima see it,
    /// the level to compare other cells' maxima with (what lies on or beside the face).
    pub fn top_within(&self, x: f64, y: f64, radius_m: f64, expected_m: f64, band_m: f64) -> f64 {
        crate::stats::median_sorted(&self.band_within(x, y, radius_m, expected_m, band_m, |_, h| h))
    }

    /// The `height` (cell index, highest point) of the cells within `radius_m` of tray point
    /// (x, y) that lies within `band_m` of `expected_m`, ascending.
    fn band_within(
        &self,
        x: f64,
        y: f64,
        radius_m: f64,
        expected_m: f64,
        band_m: f64,
        height: impl Fn(usize, f64) -> f64,
    ) -> Vec<f64> {
        let v: Vec<f64> = self
            .cells_within(x, y, radius_m)
            .map(|(k, h)| height(k, h))
            .filter(|h| h.is_finite() && (h - expected_m).abs() <= band_m)
            .collect();
        crate::stats::sorted(&v)
    }

    /// Highest seen point above the tray floor within `radius_m` of tray point (x, y) (m)
    /// (NaN if nothing was seen there). Cells count when any part of them may lie in the disc
    /// (centre within `radius_m` plus half a cell diagonal).
    pub fn max_within(&self, x: f64, y: f64, radius_m: f64) -> f64 {
        self.max_within_unexplained(x, y, radius_m, |_, _| false)
    }

    /// [`HeightMap::max_within`] over the cells whose height `explained` (cell index, height)
    /// does not put down to something known (a recognised part's own surface); NaN if none.
    pub fn max_within_unexplained(&self, x: f64, y: f64, radius_m: f64, explained: impl Fn(usize, f64) -> bool) -> f64 {
        self.cells_within(x, y, radius_m + self.cell_m * 0.71)
            .filter(|&(k, h)| !h.is_nan() && !explained(k, h))
            .fold(
                f64::NAN,
                |best, (_, h)| if best.is_nan() || h > best { h } else { best },
            )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10 x 8 map of 1 cm cells over a tray of inner half size 4 x 3 cm (cells of the outer
    /// ring lie outside the inner walls), all seen at `h` except as edited.
    fn map(h: f64) -> HeightMap {
        HeightMap {
            world_from_tray: Isometry3::identity(),
            cell_m: 0.01,
            nx: 10,
            ny: 8,
            origin_xy_m: [-0.05, -0.04],
            height_m: vec![h; 80],
            mean_m: None,
        }
    }

    const INNER: [f64; 2] = [0.04, 0.03];

    /// Over the walls (the outer ring, seen at the rim's 6 cm) nothing is pile but a part lying
    /// across the rim and standing above it. Control: cleared as the walls' cells were before
    /// (no height kept), the part is gone and the planner would sweep the held part through it.
    #[test]
    fn a_part_standing_over_the_rim_stays_in_the_pile_the_walls_do_not() {
        let mut hm = map(0.01);
        let ring: Vec<usize> = (0..80)
            .filter(|k| k % 10 == 0 || k % 10 == 9 || k / 10 == 0 || k / 10 == 7)
            .collect();
        for &k in &ring {
            hm.height_m[k] = 0.0604;
        }
        let strip_end = 3 * 10 + 9; // x = +4.5 cm, over the wall
        hm.height_m[strip_end] = 0.086;
        let pile = hm.without_walls(INNER, 0.062);
        for &k in &ring {
            let kept = pile.height_m[k];
            if k == strip_end {
                assert_eq!(kept, 0.086, "the strip's end over the rim");
            } else {
                assert!(kept.is_nan(), "wall cell {k} kept at {kept}");
            }
        }
        assert!(pile.height_m[3 * 10 + 4] == 0.01, "inner cells are kept");
        assert!(
            hm.without_walls(INNER, f64::INFINITY).height_m[strip_end].is_nan(),
            "control"
        );
    }

    /// A flat face 10 mm above the floor of a 10 x 10 cm tray, seen from 1 m above by 0.85 mm
    /// pixels under 0.3 mm of depth noise: the cup goes to the cells' mean surface, on the face
    /// on average (within 0.05 mm) and nowhere 0.4 mm off; the median of the cells' highest
    /// points stands about 0.3 mm above it (the control: the old target, which put a cup
    /// beyond the seal's touch tolerance now and then).
    #[test]
    fn the_surface_under_the_cup_is_the_face_not_its_noise_peaks() {
        use rand::SeedableRng;
        let face_m = 0.010;
        let pitch_m = 0.00085;
        let n = 118; // 10 cm of pixels
        let window = crate::sensor::PixelWindow {
            x0_px: 0,
            y0_px: 0,
            width_px: n,
            height_px: n,
        };
        let mut c = Capture::blank(0, 0.0, nalgebra::Vector3::new(0.0, 0.0, 1.0), (n, n), window);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (
                    (i as f64 - n as f64 / 2.0) * pitch_m,
                    (j as f64 - n as f64 / 2.0) * pitch_m,
                );
                let z = face_m + 0.0003 * crate::sensor::capture::gaussian(&mut rng);
                c.points_world[j * n + i] = [x as f32, y as f32, z as f32];
            }
        }
        let tray = crate::geometry::TrayVolume {
            world_from_tray: Isometry3::identity(),
            half_xy_m: [0.05, 0.05],
            wall_height_m: 0.04,
            wall_thickness_m: 0.005,
        };
        let hm = HeightMap::from_capture(&c, &tray, 0.002, None);
        let (mut surface_err, mut top_err) = (Vec::new(), Vec::new());
        for k in 0..40 {
            let (x, y) = (-0.03 + 0.0015 * k as f64, 0.02 - 0.001 * k as f64);
            surface_err.push(hm.surface_within(x, y, 0.002, face_m + 0.0005, 0.003) - face_m);
            top_err.push(hm.top_within(x, y, 0.002, face_m + 0.0005, 0.003) - face_m);
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let bias = mean(&surface_err);
        assert!(
            bias.abs() < 0.00005,
            "the surface stands {bias} m off the face on average"
        );
        let worst = surface_err.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        assert!(worst < 0.0004, "the surface is off the face by up to {worst} m");
        let top_bias = mean(&top_err);
        assert!(
            top_bias > 0.0002,
            "the cells' highest points stand only {top_bias} m above the face"
        );
    }

    /// Beyond the walls the map holds what stands over the rim outside the view frustum over the
    /// tray, and not the arm; every point the map to the walls holds lands in the same cell,
    /// shifted by the cells beyond. Controls: the same points below the rim, on the arm, or beyond
    /// the wider footprint are not held; the map to the walls has no cell for them.
    #[test]
    fn beyond_the_walls_the_map_holds_what_stands_over_the_rim_and_not_the_arm() {
        // A 10 x 10 cm tray (outer), walls 4 cm, seen from 1 m above its centre.
        let tray = crate::geometry::TrayVolume {
            world_from_tray: Isometry3::identity(),
            half_xy_m: [0.05, 0.05],
            wall_height_m: 0.04,
            wall_thickness_m: 0.005,
        };
        let points: [[f32; 3]; 6] = [
            [0.001, -0.0213, 0.012],   // a part in the tray
            [-0.0449, 0.0301, 0.0401], // on the wall, in the frustum
            [0.07, 0.0, 0.06],         // a part's end beyond +x, 2 cm over the rim
            [0.07, 0.02, -0.005],      // the table beyond +x
            [-0.07, 0.0, 0.08],        // the arm beyond -x
            [0.0, 0.2, 0.06],          // beyond the wider footprint
        ];
        let window = crate::sensor::PixelWindow {
            x0_px: 0,
            y0_px: 0,
            width_px: points.len(),
            height_px: 1,
        };
        let mut c = Capture::blank(0, 0.0, nalgebra::Vector3::new(0.0, 0.0, 1.0), (points.len(), 1), window);
        c.points_world.copy_from_slice(&points);
        let is_arm = |p: &Point3<f64>| p.x < -0.06;
        let beyond = BeyondWalls {
            reach_m: 0.03,
            above_m: 0.042,
            is_arm: &is_arm,
        };
        let to_walls = HeightMap::from_capture(&c, &tray, 0.002, None);
        let wide = HeightMap::from_capture(&c, &tray, 0.002, Some(&beyond));
        assert_eq!((wide.nx, wide.ny), (to_walls.nx + 30, to_walls.ny + 30));
        let held = |m: &HeightMap| m.height_m.iter().filter(|h| h.is_finite()).count();
        assert_eq!(held(&to_walls), 2, "the tray's two points");
        assert_eq!(held(&wide), 3, "and the part's end beyond the wall");
        for [x, y, z] in points.iter().take(2).map(|p| p.map(f64::from)) {
            let (a, b) = (to_walls.index(x, y).unwrap(), wide.index(x, y).unwrap());
            assert_eq!((a % to_walls.nx + 15, a / to_walls.nx + 15), (b % wide.nx, b / wide.nx));
            assert_eq!(wide.height_m[b], z as f32 as f64);
        }
        assert_eq!(wide.height_m[wide.index(0.07, 0.0).unwrap()], 0.06f32 as f64);
        assert!(to_walls.index(0.07, 0.0).is_none(), "control: no cell beyond the wall");
        assert!(
            wide.height_m[wide.index(0.07, 0.02).unwrap()].is_nan(),
            "the table is below the rim"
        );
        assert!(
            wide.height_m[wide.index(-0.07, 0.0).unwrap()].is_nan(),
            "the arm is masked"
        );
        let unmasked = BeyondWalls {
            is_arm: &|_: &Point3<f64>| false,
            ..beyond
        };
        let seen = HeightMap::from_capture(&c, &tray, 0.002, Some(&unmasked));
        assert_eq!(
            seen.height_m[seen.index(-0.07, 0.0).unwrap()],
            0.08f32 as f64,
            "control: the arm unmasked"
        );
    }

    #[test]
    fn an_unseen_hole_is_filled_to_its_highest_seen_border() {
        let mut m = map(0.0);
        // A 2 x 2 hole, one of its bordering cells the top of a 5 cm part.
        for k in [3 * 10 + 4, 3 * 10 + 5, 4 * 10 + 4, 4 * 10 + 5] {
            m.height_m[k] = f64::NAN;
        }
        m.height_m[2 * 10 + 3] = 0.05;
        // A lone dropout elsewhere, on the floor.
        m.height_m[6 * 10 + 8] = f64::NAN;
        let f = m.unseen_filled(INNER, 0.06);
        for k in [3 * 10 + 4, 3 * 10 + 5, 4 * 10 + 4, 4 * 10 + 5] {
            assert_eq!(f.height_m[k], 0.05);
        }
        assert_eq!(f.height_m[6 * 10 + 8], 0.0);
        assert!(f.height_m.iter().all(|h| h.is_finite()));
        // Seen cells are untouched.
        assert_eq!(f.height_m[2 * 10 + 3], 0.05);
        assert_eq!(f.height_m[0], 0.0);
    }

    #[test]
    fn a_map_with_nothing_seen_inside_is_full_to_the_rim_and_the_outside_is_kept() {
        let mut m = map(f64::NAN);
        // Over the walls: the wall top seen in one cell, nothing in the others.
        m.height_m[0] = 0.06;
        m.height_m[9] = 0.02;
        let f = m.unseen_filled(INNER, 0.06);
        for j in 0..8 {
            for i in 0..10 {
                let k = j * 10 + i;
                let outside = i == 0 || i == 9 || j == 0 || j == 7;
                if outside {
                    // Left as it was (wall cells do not count as seen pile either).
                    assert_eq!(f.height_m[k].to_bits(), m.height_m[k].to_bits(), "{i} {j}");
                } else {
                    assert_eq!(f.height_m[k], 0.06, "{i} {j}");
                }
            }
        }
    }

    #[test]
    fn separate_holes_are_filled_separately() {
        let mut m = map(0.0);
        m.height_m[2 * 10 + 2] = f64::NAN;
        m.height_m[2 * 10 + 3] = 0.03;
        m.height_m[5 * 10 + 7] = f64::NAN;
        let f = m.unseen_filled(INNER, 0.06);
        assert_eq!(f.height_m[2 * 10 + 2], 0.03);
        assert_eq!(f.height_m[5 * 10 + 7], 0.0);
    }
}
