//! The pile as the planner sees it: height-map columns, and a max-pooled pyramid over them that
//! answers a sphere's clearance to the columns without visiting every column within reach.
//!
//! Job: the nearest pile column to a sphere, exactly as a loop over every column would find it,
//! in O(log) typical time. Each column is a box from the tray floor to its height over one
//! planning cell. Level k of the pyramid holds, per block of 2^k x 2^k columns, the highest
//! column in it; the box over a block's footprint from the floor to that height contains every
//! column of the block, so the distance from a sphere to it is a lower bound on the distance to
//! any of them. A block whose bound is not below the best distance found so far is skipped (it
//! cannot change the answer); the others are opened, nearest first, down to the columns, whose
//! distance is computed by the same formula as the plain loop ([`PileColumns::sphere_distance_brute`],
//! the reference the tests compare against). The answer is therefore the same number, bit for bit.
//!
//! Units: m. Frames: columns and block boxes in the tray frame of the height map (floor at z = 0);
//! sphere centres are given in the world and transformed once per query.

use nalgebra::{Point3, Vector3};

use crate::sensor::HeightMap;

/// Slack on a block's lower bound (m): far above the rounding of distances of a few metres, far
/// below anything the planner resolves. A block is skipped only if its bound exceeds the best
/// distance by this much, so rounding never skips a column the plain loop would have taken.
const BOUND_SLACK_M: f64 = 1e-9;

/// Columns no higher than this above the floor are no obstacle (the floor itself) (m).
const FLOOR_COLUMN_M: f64 = 0.001;

/// The pile as the sensor saw it: height-map columns, with a disc around the grasp cut out.
///
/// A NaN column is not pile: it lies outside the tray's inner walls (the walls are boxes of the
/// cell). Cells the sensor did not see inside the walls must come filled as occupied
/// ([`HeightMap::unseen_filled`], which [`crate::pipeline::pile_map`] applies): a hole in the map
/// is not free space. Max-pooling keeps a filled cell's height, so no column is lower than any of
/// its cells, seen or filled.
///
/// Built once per height map and grasp ([`PileColumns::new`]); read-only afterwards (the pyramid
/// is derived from the map and the cut-out, so they are only readable).
#[derive(Debug, Clone)]
pub struct PileColumns {
    /// The height map (heights above the tray floor), max-pooled to planning cells.
    map: HeightMap,
    /// Tray-frame disc (x, y, radius) whose columns are ignored (the part to be grasped) (m).
    cut_out: Option<(f64, f64, f64)>,
    /// Highest column above the tray floor (m).
    max_height_m: f64,
    /// Column centres along x, per column index i (m) (tray frame).
    center_x_m: Vec<f64>,
    /// Column centres along y, per row index j (m) (tray frame).
    center_y_m: Vec<f64>,
    /// Level k: per block of 2^k x 2^k columns, the highest column that counts (above the floor
    /// threshold, outside the cut-out), `-inf` where none does (m). Level 0 is the columns.
    levels: Vec<Level>,
}

/// One level of the pyramid.
#[derive(Debug, Clone)]
struct Level {
    nx: usize,
    ny: usize,
    top_m: Vec<f64>,
}

impl PileColumns {
    /// Columns from a capture's height map, max-pooled by `pool` cells per side (conservative).
    pub fn new(map: &HeightMap, pool: usize, cut_out: Option<(f64, f64, f64)>) -> Self {
        let pool = pool.max(1);
        let (nx, ny) = (map.nx.div_ceil(pool), map.ny.div_ceil(pool));
        let mut heights = vec![f64::NAN; nx * ny];
        for j in 0..map.ny {
            for i in 0..map.nx {
                let h = map.height_m[j * map.nx + i];
                let c = &mut heights[(j / pool) * nx + i / pool];
                if h.is_finite() && (c.is_nan() || h > *c) {
                    *c = h;
                }
            }
        }
        let max_height_m = heights.iter().cloned().filter(|h| h.is_finite()).fold(0.0, f64::max);
        let map = HeightMap {
            world_from_tray: map.world_from_tray,
            cell_m: map.cell_m * pool as f64,
            nx,
            ny,
            origin_xy_m: map.origin_xy_m,
            height_m: heights,
            mean_m: None,
        };
        let center_x_m: Vec<f64> = (0..nx)
            .map(|i| map.origin_xy_m[0] + (i as f64 + 0.5) * map.cell_m)
            .collect();
        let center_y_m: Vec<f64> = (0..ny)
            .map(|j| map.origin_xy_m[1] + (j as f64 + 0.5) * map.cell_m)
            .collect();
        // Level 0: the columns that count, as the plain loop decides it.
        let mut base = vec![f64::NEG_INFINITY; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                let h = map.height_m[j * nx + i];
                let cut = cut_out.is_some_and(|(gx, gy, gr)| (center_x_m[i] - gx).hypot(center_y_m[j] - gy) < gr);
                if h.is_finite() && h > FLOOR_COLUMN_M && !cut {
                    base[j * nx + i] = h;
                }
            }
        }
        let mut levels = vec![Level { nx, ny, top_m: base }];
        while levels.last().is_some_and(|l| l.nx > 1 || l.ny > 1) {
            let below = &levels[levels.len() - 1];
            let (cx, cy) = (below.nx.div_ceil(2), below.ny.div_ceil(2));
            let mut top_m = vec![f64::NEG_INFINITY; cx * cy];
            for j in 0..below.ny {
                for i in 0..below.nx {
                    let t = &mut top_m[(j / 2) * cx + i / 2];
                    *t = t.max(below.top_m[j * below.nx + i]);
                }
            }
            levels.push(Level { nx: cx, ny: cy, top_m });
        }
        PileColumns {
            map,
            cut_out,
            max_height_m,
            center_x_m,
            center_y_m,
            levels,
        }
    }

    /// The height map (heights above the tray floor), max-pooled to planning cells.
    pub fn map(&self) -> &HeightMap {
        &self.map
    }

    /// Tray-frame disc (x, y, radius) whose columns are ignored (the part to be grasped) (m).
    pub fn cut_out(&self) -> Option<(f64, f64, f64)> {
        self.cut_out
    }

    /// Highest column above the tray floor (m).
    pub fn max_height_m(&self) -> f64 {
        self.max_height_m
    }

    /// Signed distance from the sphere (world centre `c`, radius `r`) to the nearest column, if it
    /// is below `best` (m); `None` when no column is nearer than `best`. The same number as
    /// [`PileColumns::sphere_distance_brute`] gives, bit for bit.
    pub fn sphere_distance(&self, c: &Vector3<f64>, r: f64, best: f64) -> Option<f64> {
        let l = self
            .map
            .world_from_tray
            .inverse_transform_point(&Point3::from(*c))
            .coords;
        let cell = self.map.cell_m;
        let [ox, oy] = self.map.origin_xy_m;
        let top = self.levels.len() - 1;
        let mut found: Option<f64> = None;
        let mut best = best;
        // Depth first, nearest block first: (level, i, j, lower bound).
        let mut stack: Vec<(usize, usize, usize, f64)> = Vec::with_capacity(4 * self.levels.len());
        let bound = |k: usize, i: usize, j: usize| -> f64 {
            let lv = &self.levels[k];
            let h = lv.top_m[j * lv.nx + i];
            if h == f64::NEG_INFINITY {
                return f64::INFINITY;
            }
            let span = (1usize << k) as f64 * cell;
            let (x0, y0) = (ox + i as f64 * span, oy + j as f64 * span);
            let dx = (x0 - l.x).max(l.x - (x0 + span)).max(0.0);
            let dy = (y0 - l.y).max(l.y - (y0 + span)).max(0.0);
            let dz = (-l.z).max(l.z - h).max(0.0);
            (dx * dx + dy * dy + dz * dz).sqrt() - r
        };
        let b = bound(top, 0, 0);
        if b < best + BOUND_SLACK_M {
            stack.push((top, 0, 0, b));
        }
        while let Some((k, i, j, lb)) = stack.pop() {
            if lb >= best + BOUND_SLACK_M {
                continue;
            }
            if k == 0 {
                let h = self.levels[0].top_m[j * self.map.nx + i];
                let d = column_distance(&l, r, self.center_x_m[i], self.center_y_m[j], cell, h);
                if d < best {
                    best = d;
                    found = Some(d);
                }
                continue;
            }
            let lv = &self.levels[k - 1];
            let mut kids = [(0usize, 0usize, f64::INFINITY); 4];
            let mut n = 0;
            for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (ci, cj) = (2 * i + di, 2 * j + dj);
                if ci < lv.nx && cj < lv.ny {
                    let b = bound(k - 1, ci, cj);
                    if b < best + BOUND_SLACK_M {
                        kids[n] = (ci, cj, b);
                        n += 1;
                    }
                }
            }
            // Farthest pushed first: the nearest is opened next.
            kids[..n].sort_unstable_by(|a, b| b.2.total_cmp(&a.2));
            stack.extend(kids[..n].iter().map(|&(ci, cj, b)| (k - 1, ci, cj, b)));
        }
        found
    }

    /// The plain loop: every column within reach of the sphere, as the planner computed it before
    /// the pyramid (the reference [`PileColumns::sphere_distance`] is tested against).
    pub fn sphere_distance_brute(&self, c: &Vector3<f64>, r: f64, best: f64) -> Option<f64> {
        let m = &self.map;
        let mut best = best;
        let mut found = None;
        let l = m.world_from_tray.inverse_transform_point(&Point3::from(*c)).coords;
        // Columns within reach of the sphere (plus the horizon) only.
        let reach = r + best.max(0.0);
        let i0 = (((l.x - reach - m.origin_xy_m[0]) / m.cell_m).floor().max(0.0)) as usize;
        let j0 = (((l.y - reach - m.origin_xy_m[1]) / m.cell_m).floor().max(0.0)) as usize;
        let i1 = (((l.x + reach - m.origin_xy_m[0]) / m.cell_m).floor()) as isize;
        let j1 = (((l.y + reach - m.origin_xy_m[1]) / m.cell_m).floor()) as isize;
        if i1 >= 0 && j1 >= 0 && l.z - r < self.max_height_m + best {
            for j in j0..=(j1 as usize).min(m.ny.saturating_sub(1)) {
                for i in i0..=(i1 as usize).min(m.nx.saturating_sub(1)) {
                    let h = m.height_m[j * m.nx + i];
                    if !h.is_finite() || h <= FLOOR_COLUMN_M {
                        continue;
                    }
                    let cx = m.origin_xy_m[0] + (i as f64 + 0.5) * m.cell_m;
                    let cy = m.origin_xy_m[1] + (j as f64 + 0.5) * m.cell_m;
                    if let Some((gx, gy, gr)) = self.cut_out
                        && (cx - gx).hypot(cy - gy) < gr
                    {
                        continue;
                    }
                    let d = column_distance(&l, r, cx, cy, m.cell_m, h);
                    if d < best {
                        best = d;
                        found = Some(d);
                    }
                }
            }
        }
        found
    }
}

/// Signed distance from a sphere (tray-frame centre `l`, radius `r`) to the column over the cell
/// centred at (`cx`, `cy`) of edge `cell`, from the floor to `h` (m).
#[inline]
fn column_distance(l: &Vector3<f64>, r: f64, cx: f64, cy: f64, cell: f64, h: f64) -> f64 {
    // Column box from the floor to h, in the tray frame.
    let q = Vector3::new(
        (l.x - cx).abs() - cell / 2.0,
        (l.y - cy).abs() - cell / 2.0,
        (l.z - h / 2.0).abs() - h / 2.0,
    );
    q.sup(&Vector3::zeros()).norm() + q.max().min(0.0) - r
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A random pile over a tray turned 0.3 rad about z: heights 0-8 cm in 2 mm cells, some
    /// floor cells, NaN borders (outside the walls), a rim of filled cells.
    fn random_map(rng: &mut ChaCha8Rng, nx: usize, ny: usize) -> HeightMap {
        let mut height_m = vec![0.0; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                height_m[j * nx + i] = if i < 3 || j < 2 || i + 3 >= nx {
                    f64::NAN
                } else if rng.random::<f64>() < 0.2 {
                    0.0005
                } else {
                    rng.random_range(0.0..0.08)
                };
            }
        }
        HeightMap {
            world_from_tray: Isometry3::new(Vector3::new(0.1, 0.45, 0.008), Vector3::z() * 0.3),
            cell_m: 0.002,
            nx,
            ny,
            origin_xy_m: [-0.001 * nx as f64, -0.001 * ny as f64],
            height_m,
            mean_m: None,
        }
    }

    /// Spheres all over and around the tray, large and small, some inside the pile.
    fn random_spheres(rng: &mut ChaCha8Rng, p: &PileColumns, n: usize) -> Vec<(Vector3<f64>, f64, f64)> {
        (0..n)
            .map(|_| {
                let l = Vector3::new(
                    rng.random_range(-0.35..0.35),
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.05..0.3),
                );
                let c = (p.map.world_from_tray * Point3::from(l)).coords;
                let best = if rng.random::<f64>() < 0.2 {
                    rng.random_range(-0.02..0.02)
                } else {
                    0.10
                };
                (c, rng.random_range(0.0..0.08), best)
            })
            .collect()
    }

    #[test]
    fn the_pyramid_gives_the_plain_loops_distance_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(18);
        let (mut hits, mut misses) = (0, 0);
        for (nx, ny, pool, cut) in [
            (155, 125, 5, Some((0.02, -0.01, 0.02))),
            (150, 120, 5, None),
            (37, 61, 3, Some((0.0, 0.0, 0.05))),
            (1, 1, 1, None),
        ] {
            let map = random_map(&mut rng, nx.max(8), ny.max(5));
            let p = PileColumns::new(&map, pool, cut);
            for (c, r, best) in random_spheres(&mut rng, &p, 4000) {
                let fast = p.sphere_distance(&c, r, best);
                let brute = p.sphere_distance_brute(&c, r, best);
                assert_eq!(
                    fast.map(f64::to_bits),
                    brute.map(f64::to_bits),
                    "sphere {c:?} r {r} best {best}: {fast:?} vs {brute:?}"
                );
                if brute.is_some() {
                    hits += 1;
                } else {
                    misses += 1;
                }
            }
        }
        assert!(hits > 2000 && misses > 2000, "{hits} near a column, {misses} not");
    }

    /// The negative control: a pyramid whose blocks understate their highest column (one level
    /// lowered by 2 cm) skips columns it must not, and the comparison with the loop sees it.
    #[test]
    fn a_pyramid_with_a_lowered_level_is_caught() {
        let mut rng = ChaCha8Rng::seed_from_u64(19);
        let map = random_map(&mut rng, 155, 125);
        let mut p = PileColumns::new(&map, 5, None);
        for t in &mut p.levels[2].top_m {
            *t -= 0.02;
        }
        let differ = random_spheres(&mut rng, &p, 4000)
            .into_iter()
            .filter(|(c, r, best)| {
                p.sphere_distance(c, *r, *best).map(f64::to_bits)
                    != p.sphere_distance_brute(c, *r, *best).map(f64::to_bits)
            })
            .count();
        assert!(differ > 50, "only {differ} of 4000 spheres differ");
    }

    #[test]
    fn the_pyramid_tops_are_the_highest_counted_column_below() {
        let mut rng = ChaCha8Rng::seed_from_u64(20);
        let map = random_map(&mut rng, 155, 125);
        let p = PileColumns::new(&map, 5, Some((0.0, 0.0, 0.03)));
        let l0 = &p.levels[0];
        for (k, lv) in p.levels.iter().enumerate() {
            for j in 0..lv.ny {
                for i in 0..lv.nx {
                    let s = 1usize << k;
                    let mut top = f64::NEG_INFINITY;
                    for jj in j * s..((j + 1) * s).min(l0.ny) {
                        for ii in i * s..((i + 1) * s).min(l0.nx) {
                            top = top.max(l0.top_m[jj * l0.nx + ii]);
                        }
                    }
                    assert_eq!(lv.top_m[j * lv.nx + i], top, "level {k} block ({i}, {j})");
                }
            }
        }
        assert_eq!(p.levels.last().map(|l| (l.nx, l.ny)), Some((1, 1)));
        // Cut-out columns and floor columns do not count.
        let (gx, gy) = (0.0, 0.0);
        let i = ((gx - p.map.origin_xy_m[0]) / p.map.cell_m) as usize;
        let j = ((gy - p.map.origin_xy_m[1]) / p.map.cell_m) as usize;
        assert_eq!(l0.top_m[j * l0.nx + i], f64::NEG_INFINITY);
    }
}
