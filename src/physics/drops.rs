//! Drop trials: single parts dropped on the bare pick-tray floor from uniformly random
//! orientations and settled, to check the part model's predicted resting poses
//! ([`crate::part::poses`]) against the physics.
//!
//! Job: lay out a grid of drop spots over the tray floor far enough apart that no two parts
//! meet (spacing: twice the part's bounding radius plus [`SPOT_GAP_M`]); release one part per
//! spot, at rest, in a uniformly random orientation (the `drops` stream of the seed), its lowest
//! point `height_m` above the floor; let the world run until every part is still; record the
//! settled poses; take the parts out and drop the next grid until `count` parts have fallen.
//!
//! Stated simplification: a part rests on the bare floor, alone (a pile's parts also rest on
//! each other); the release is at rest from a small height, so the drop's momentum is small.
//!
//! Randomness: the `drops` stream of the seed. Units: m, s. Frames: world.

use nalgebra::{Isometry3, Translation3, Vector3};

use super::{HealthError, World};

/// Free space between two neighbouring parts' bounding spheres at release (m).
pub const SPOT_GAP_M: f64 = 0.03;

/// How to drop.
#[derive(Debug, Clone, Copy)]
pub struct DropOptions {
    /// Parts to drop in all.
    pub count: usize,
    /// Seed of the `drops` stream.
    pub seed: u64,
    /// Height of the part's lowest point above the floor at release (m).
    pub height_m: f64,
    /// Give up settling a grid after this much simulated time (s).
    pub max_settle_s: f64,
}

impl DropOptions {
    /// `count` drops with `seed`, released 10 mm above the floor, settling for at most 5 s each
    /// grid.
    pub fn new(count: usize, seed: u64) -> Self {
        DropOptions {
            count,
            seed,
            height_m: 0.01,
            max_settle_s: 5.0,
        }
    }
}

/// What came of the drops.
#[derive(Debug, Clone)]
pub struct DropReport {
    /// Each dropped part's settled `world_from_part`, in drop order.
    pub rest_poses: Vec<Isometry3<f64>>,
    /// Whether each grid settled within `max_settle_s` (false: its parts may still move).
    pub settled: Vec<bool>,
    /// Parts per grid.
    pub per_grid: usize,
    /// Dropped parts that came to rest within two bounding radii of another (they may have met
    /// on the way, which the single-part estimate does not model).
    pub crowded: usize,
}

impl World {
    /// Drops parts one per spot on the bare pick-tray floor, grid after grid (see the module
    /// header). The world must hold no free part; the dropped parts are taken out afterwards.
    pub fn drop_trials(&mut self, opts: &DropOptions) -> Result<DropReport, HealthError> {
        let mut rng = crate::rng::stream(opts.seed, "drops");
        let tray = self.pick_tray.world_from_tray;
        let inner = [
            self.pick_tray.half_xy_m[0] - self.pick_tray.wall_thickness_m,
            self.pick_tray.half_xy_m[1] - self.pick_tray.wall_thickness_m,
        ];
        let r = self.part_shape.bounding_radius_m;
        let spacing = 2.0 * r + SPOT_GAP_M;
        let n = |half: f64| (((2.0 * half - 2.0 * r - 0.01) / spacing).floor() as usize + 1).max(1);
        let (nx, ny) = (n(inner[0]), n(inner[1]));
        let spots: Vec<[f64; 2]> = (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| {
                    [
                        (i as f64 - 0.5 * (nx - 1) as f64) * spacing,
                        (j as f64 - 0.5 * (ny - 1) as f64) * spacing,
                    ]
                })
            })
            .collect();
        let mut report = DropReport {
            rest_poses: Vec::with_capacity(opts.count),
            settled: Vec::new(),
            per_grid: spots.len(),
            crowded: 0,
        };
        while report.rest_poses.len() < opts.count {
            let batch = spots.len().min(opts.count - report.rest_poses.len());
            let mut dropped = Vec::with_capacity(batch);
            for s in &spots[..batch] {
                let rot = super::pile::random_rotation(&mut rng);
                // The lowest point of the part's hull under this rotation, from its collider's
                // box in that orientation.
                let probe = super::to_pose(&Isometry3::from_parts(Translation3::identity(), rot));
                let low = self.part_shape.shape.compute_aabb(&probe).mins.z as f64 / super::SIM_UNITS_PER_M;
                let c = Vector3::new(s[0], s[1], opts.height_m - low);
                dropped.push(self.add_part(&(tray * Isometry3::from_parts(Translation3::from(c), rot))));
            }
            let start = self.time_s;
            let settled = self.settle_pile(start, opts.max_settle_s, None, &mut |_| {})?;
            report.settled.push(settled);
            let at: Vec<Isometry3<f64>> = dropped.iter().map(|&i| self.part_pose(i)).collect();
            report.crowded += at
                .iter()
                .enumerate()
                .filter(|(k, p)| {
                    at.iter()
                        .enumerate()
                        .any(|(m, q)| m != *k && (p.translation.vector - q.translation.vector).xy().norm() < 2.0 * r)
                })
                .count();
            report.rest_poses.extend(at);
            for &i in &dropped {
                self.remove_part(i);
            }
        }
        Ok(report)
    }
}
