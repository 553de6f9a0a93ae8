//! Random piles: N parts dropped in waves from seeded random poses above the pick tray, simulated
//! until they settle.
//!
//! Job: drop waves of up to 12 parts just above the pile so far, over the central 70 % of the
//! tray floor (so they heap as poured parts do); orientations uniformly random (parts more than
//! three times longer than wide, like the 150 mm connector strip, pour lying: yaw and roll uniform,
//! long axis within 30 deg of level, as strips slide out of a box), positions uniformly
//! random where the part's rotated box fits inside the walls and clears the wave's other parts
//! (else a layer higher). Between waves the world runs until the wave has slowed down; at the end
//! until every part is asleep or none moved more than 0.05 mm or 0.005 rad in the last 0.1 s
//! (a pile built before a run; a pour into a running cell ends with its last wave, and the cell
//! finds out by looking whether the pile still moves: [`PileOptions::into_running_cell`]).
//!
//! Randomness: the `pile` stream of the run seed. Units: m, s. Frames: world.

use std::time::Instant;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rand::RngExt;
use serde::Serialize;

use super::{HealthError, HealthEvent, PartState, World};

/// How to build a pile.
#[derive(Debug, Clone, Copy)]
pub struct PileOptions {
    /// Parts to drop.
    pub count: usize,
    /// Run seed (the `pile` stream is drawn from it).
    pub seed: u64,
    /// Give up settling after this much simulated time (s).
    pub max_settle_s: f64,
    /// A part that bounces out of the pick tray is taken out of the world and reported in
    /// [`PileReport::spilled`] (a hopper dose or a refill in a running cell: a real feeder loses
    /// the part, not the shift); without it, the pour ends with the health error.
    pub lose_spilled: bool,
    /// Step on after the last wave until the pile has settled (or `max_settle_s` have passed).
    /// A pile built before a run does; a pour into a running cell does not: the cell waits the
    /// time it is set to wait, and its sensor tells whether the pile still moves.
    pub settle: bool,
    /// Lowest height above the tray floor a wave starts from (m): a hopper chute's exit, which
    /// the parts fall from unless the pile stands higher (then from just above its top, as with
    /// 0, the default).
    pub drop_from_m: f64,
}

impl PileOptions {
    /// `count` parts with seed `seed`, settling for at most 10 s.
    pub fn new(count: usize, seed: u64) -> Self {
        PileOptions {
            count,
            seed,
            max_settle_s: 10.0,
            lose_spilled: false,
            settle: true,
            drop_from_m: 0.0,
        }
    }

    /// The cell's first pile, poured before a run: settled as [`PileOptions::new`], with a part
    /// the pour spills out of the tray lost, as in a dose or a refill, not the run. Every command
    /// that pours a pile as the cell does (`run`, `pile`, `sense`, `part`, `bench sensor`) uses it.
    pub fn cells_first_pile(count: usize, seed: u64) -> Self {
        PileOptions::new(count, seed).losing_spilled()
    }

    /// A pour into a running cell (a hopper dose, a refill): parts that bounce out of the tray
    /// are lost, and the pour ends when its last wave has been dropped, not when the physics says
    /// the pile has settled (that is the cell's to find out, by looking).
    pub fn into_running_cell(count: usize, seed: u64) -> Self {
        PileOptions {
            settle: false,
            ..PileOptions::new(count, seed).losing_spilled()
        }
    }

    /// As these options, with parts that bounce out of the tray lost instead of a fault.
    pub fn losing_spilled(mut self) -> Self {
        self.lose_spilled = true;
        self
    }

    /// As these options, the waves starting at least `height_m` above the tray floor (a hopper
    /// chute's exit).
    pub fn dropped_from(mut self, height_m: f64) -> Self {
        self.drop_from_m = height_m;
        self
    }
}

/// A settled part's pose.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PartPose {
    /// Index of the part in the world.
    pub part: usize,
    /// Position in the world (m).
    pub xyz_m: [f64; 3],
    /// Orientation as a unit quaternion (w, x, y, z).
    pub quat_wxyz: [f64; 4],
}

/// What came of building a pile.
#[derive(Debug, Clone, Serialize)]
pub struct PileReport {
    /// Parts dropped.
    pub spawned: usize,
    /// Parts whose centre rests inside the tray's walls.
    pub in_tray: usize,
    /// Highest point of the pile above the tray floor (m).
    pub pile_height_m: f64,
    /// Simulated time from the first drop to settled (s).
    pub settle_sim_s: f64,
    /// Whether every part came to rest within `max_settle_s` (false when the pour did not wait
    /// for it: [`PileOptions::settle`]).
    pub settled: bool,
    /// Deepest part-part or part-tray overlap after settling, exact (independent check) (m).
    pub max_penetration_m: f64,
    /// Between which bodies the deepest overlap is.
    pub max_penetration_between: String,
    /// Waves dropped.
    pub waves: usize,
    /// Settled poses, in part order.
    pub poses: Vec<PartPose>,
    /// With [`PileOptions::lose_spilled`]: the parts that left the tray during the pour (one
    /// health event each), taken out of the world.
    #[serde(skip)]
    pub spilled: Vec<HealthEvent>,
    /// Wall-clock time to build and settle (s) (not part of any result file).
    #[serde(skip)]
    pub wall_s: f64,
}

/// Parts poured at once, one wave, before the pour lets them fall and slow down for the next.
pub const POUR_WAVE: usize = 12;

/// Uniformly random rotation (Shoemake).
pub(super) fn random_rotation(rng: &mut impl RngExt) -> UnitQuaternion<f64> {
    let (u1, u2, u3): (f64, f64, f64) = (rng.random(), rng.random(), rng.random());
    let tau = std::f64::consts::TAU;
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    UnitQuaternion::from_quaternion(Quaternion::new(
        b * (tau * u3).cos(),
        a * (tau * u2).sin(),
        a * (tau * u2).cos(),
        b * (tau * u3).sin(),
    ))
}

impl World {
    /// Highest point of the free parts (the pile, and any still falling into it), or the pick
    /// tray's floor (m). A part on the cup is left out (a dose poured while the arm carries one
    /// out of the view would otherwise start above it and fly out of the tray), and so are the
    /// parts placed in the other tray, whose height has nothing to do with this pile's.
    fn pile_top_z(&self) -> f64 {
        let floor = self.pick_tray.world_from_tray.translation.vector.z;
        self.parts
            .iter()
            .filter(|p| p.state == PartState::Free)
            .map(|p| self.colliders[p.collider].compute_aabb().maxs.z as f64 / super::SIM_UNITS_PER_M)
            .fold(floor, f64::max)
    }

    /// Drops `opts.count` parts into the pick tray in waves and lets them settle.
    pub fn build_pile(&mut self, opts: &PileOptions) -> Result<PileReport, HealthError> {
        self.build_pile_observed(opts, &mut |_| {})
    }

    /// As [`World::build_pile`], calling `on_step` with the world after every physics step
    /// (for recordings of the pour).
    pub fn build_pile_observed(
        &mut self,
        opts: &PileOptions,
        on_step: &mut dyn FnMut(&World),
    ) -> Result<PileReport, HealthError> {
        let wall = Instant::now();

        let mut rng = crate::rng::stream(opts.seed, "pile");
        let tray = self.pick_tray.world_from_tray;
        let floor_z = tray.translation.vector.z;
        let inner = [
            self.pick_tray.half_xy_m[0] - self.pick_tray.wall_thickness_m,
            self.pick_tray.half_xy_m[1] - self.pick_tray.wall_thickness_m,
        ];
        let he = self.part_shape.half_extents_m;
        // A part more than three times longer than its width is poured lying (see below).
        let (long_i, long) = he.argmax();
        let mut others = [he.x, he.y, he.z];
        others[long_i] = 0.0;
        let elongated = long > 3.0 * others.iter().cloned().fold(0.0, f64::max);
        let long_axis = nalgebra::Unit::new_unchecked(Vector3::ith(long_i, 1.0));
        let long_normal = nalgebra::Unit::new_unchecked(Vector3::ith((long_i + 1) % 3, 1.0));
        // Parts are poured over the central `POUR_FRACTION` of the tray floor, so they heap.
        const POUR_FRACTION: f64 = 0.7;
        let start_time = self.time_s;
        let mut spawned = 0usize;
        let mut waves = 0usize;
        let mut spilled = Vec::new();
        let mut lost = opts.lose_spilled.then_some(&mut spilled);
        while spawned < opts.count {
            waves += 1;
            let mut layer_z = (self.pile_top_z() - floor_z + 0.003).max(opts.drop_from_m);
            let mut layer_top = layer_z;
            // World-aligned boxes of this wave's parts, to keep them apart at spawn.
            let mut boxes: Vec<(Vector3<f64>, Vector3<f64>)> = Vec::new();
            for _ in 0..POUR_WAVE.min(opts.count - spawned) {
                let rot = if elongated {
                    // Long parts pour lying down: yaw uniform, long axis within 30 deg of level.
                    let yaw = rng.random_range(0.0..std::f64::consts::TAU);
                    let tilt = rng.random_range(-std::f64::consts::FRAC_PI_6..std::f64::consts::FRAC_PI_6);
                    let roll = rng.random_range(0.0..std::f64::consts::TAU);
                    UnitQuaternion::from_euler_angles(0.0, 0.0, yaw)
                        * UnitQuaternion::from_axis_angle(&long_normal, tilt)
                        * UnitQuaternion::from_axis_angle(&long_axis, roll)
                } else {
                    random_rotation(&mut rng)
                };
                let m = rot.to_rotation_matrix();
                let hw = m.matrix().abs() * he;
                let mut placed = None;
                for attempt in 0..60 {
                    if attempt > 0 && attempt % 20 == 0 {
                        // This layer is full: start another above it.
                        layer_z = layer_top + 0.002;
                    }
                    let span = |half_inner: f64, h: f64| ((half_inner - h) * POUR_FRACTION).max(0.0);
                    let (sx, sy) = (span(inner[0], hw.x), span(inner[1], hw.y));
                    let c = Vector3::new(
                        if sx > 0.0 { rng.random_range(-sx..=sx) } else { 0.0 },
                        if sy > 0.0 { rng.random_range(-sy..=sy) } else { 0.0 },
                        layer_z + hw.z,
                    );
                    let clear = boxes
                        .iter()
                        .all(|(bc, bh)| (0..3).any(|k| (c[k] - bc[k]).abs() > hw[k] + bh[k] + 0.001));
                    if clear {
                        placed = Some(c);
                        break;
                    }
                }
                let c = placed.unwrap_or_else(|| Vector3::new(0.0, 0.0, layer_top + 0.002 + hw.z));
                layer_top = layer_top.max(c.z + hw.z);
                boxes.push((c, hw));
                let pose = tray * Isometry3::from_parts(Translation3::from(c), rot);
                self.add_part(&pose);
                spawned += 1;
            }
            // Let the wave fall and slow down before the next one (a pour into a running cell
            // ends with its last wave dropped: the cell's own wait runs from there).
            if !opts.settle && spawned == opts.count {
                break;
            }
            let wave_start = self.time_s;
            loop {
                self.pour_step(lost.as_deref_mut())?;
                on_step(self);
                let t = self.time_s - wave_start;
                if t >= 0.6 || (t >= 0.1 && self.parts_at_rest(0.05, 1.0)) {
                    break;
                }
            }
        }
        let settled = opts.settle && self.settle_pile(start_time, opts.max_settle_s, lost, on_step)?;
        let in_tray = self.parts_in_pick_tray();
        let pile_height_m = in_tray
            .iter()
            .map(|&i| {
                self.colliders[self.parts[i].collider].compute_aabb().maxs.z as f64 / super::SIM_UNITS_PER_M - floor_z
            })
            .fold(0.0, f64::max);
        let poses = (0..self.parts.len())
            .map(|i| {
                let p = self.part_pose(i);
                let q = p.rotation.quaternion();
                PartPose {
                    part: i,
                    xyz_m: p.translation.vector.into(),
                    quat_wxyz: [q.w, q.i, q.j, q.k],
                }
            })
            .collect();
        let deepest = self.max_penetration_m();
        Ok(PileReport {
            spawned,
            in_tray: in_tray.len(),
            pile_height_m,
            settle_sim_s: self.time_s - start_time,
            settled,
            max_penetration_m: deepest.0,
            max_penetration_between: deepest.1.map_or_else(String::new, |(a, b)| {
                format!("{} / {}", self.describe(Some(a)), self.describe(Some(b)))
            }),
            waves,
            poses,
            spilled,
            wall_s: wall.elapsed().as_secs_f64(),
        })
    }

    /// One step of a pour. With `spilled`, a step whose only problems are parts out of their
    /// tray takes those parts out of the world and adds the events to it; any other
    /// problem ends the pour.
    fn pour_step(&mut self, spilled: Option<&mut Vec<HealthEvent>>) -> Result<(), HealthError> {
        match (self.step(), spilled) {
            (Err(e), Some(spilled)) if e.events.iter().all(|ev| matches!(ev, HealthEvent::LeftVolume { .. })) => {
                self.remove_parts_out_of_their_trays();
                spilled.extend(e.events);
                Ok(())
            }
            (result, _) => result,
        }
    }

    /// Steps until the pile has settled (`true`) or `max_settle_s` have passed since
    /// `start_time` (s); parts that leave the tray as in [`World::pour_step`].
    pub(super) fn settle_pile(
        &mut self,
        start_time: f64,
        max_settle_s: f64,
        mut spilled: Option<&mut Vec<HealthEvent>>,
        on_step: &mut dyn FnMut(&World),
    ) -> Result<bool, HealthError> {
        // Settle: every 0.1 s of simulated time, compare poses with the last look. Settled when
        // nothing moved more than 0.05 mm or 0.005 rad since (or everything sleeps). Motion, not
        // velocity: a can standing on its cap can keep a solver velocity that moves nothing.
        let poses_now = |w: &World| -> Vec<Isometry3<f64>> { (0..w.parts.len()).map(|i| w.part_pose(i)).collect() };
        let mut last = poses_now(self);
        let mut last_look = self.time_s;
        while self.time_s - start_time < max_settle_s {
            self.pour_step(spilled.as_deref_mut())?;
            on_step(self);
            if self
                .parts
                .iter()
                .all(|p| p.state == PartState::Removed || self.bodies[p.body].is_sleeping())
            {
                return Ok(true);
            }
            if self.time_s - last_look >= 0.1 - 1e-9 {
                let now = poses_now(self);
                let still = now.iter().zip(&last).all(|(a, b)| {
                    (a.translation.vector - b.translation.vector).norm() < 5e-5
                        && a.rotation.angle_to(&b.rotation) < 0.005
                });
                if still {
                    return Ok(true);
                }
                last = now;
                last_look = self.time_s;
            }
        }
        Ok(false)
    }
}

/// The largest displacement of any part between two pose lists [m, rad].
pub fn max_motion(a: &[PartPose], b: &[PartPose]) -> (f64, f64) {
    a.iter().zip(b).fold((0.0f64, 0.0f64), |(dp, dr), (p, q)| {
        let d = (Vector3::from(p.xyz_m) - Vector3::from(q.xyz_m)).norm();
        let qa = UnitQuaternion::from_quaternion(Quaternion::new(
            p.quat_wxyz[0],
            p.quat_wxyz[1],
            p.quat_wxyz[2],
            p.quat_wxyz[3],
        ));
        let qb = UnitQuaternion::from_quaternion(Quaternion::new(
            q.quat_wxyz[0],
            q.quat_wxyz[1],
            q.quat_wxyz[2],
            q.quat_wxyz[3],
        ));
        (dp.max(d), dr.max(qa.angle_to(&qb)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::test_cell::default_cell_with;

    /// A dose is poured over this pile's top: parts on the cup or set down in the place tray do
    /// not raise it. Control: the same part, free, does.
    #[test]
    fn the_pour_height_counts_only_the_free_parts() {
        let (scene, robot, shape) = default_cell_with("A");
        let mut w = World::new(&scene.scene, &robot, shape);
        let floor_z = w.pick_tray.world_from_tray.translation.vector.z;
        let mut high_over_place_tray = w.place_tray().world_from_tray;
        high_over_place_tray.translation.vector.z = floor_z + 0.2;
        let i = w.add_part(&high_over_place_tray);
        for (state, raised) in [
            (PartState::Placed, false),
            (PartState::Held, false),
            (PartState::Removed, false),
            (PartState::Free, true),
        ] {
            w.parts[i].state = state;
            let top_z = w.pile_top_z();
            assert_eq!(
                top_z > floor_z + 0.1,
                raised,
                "{state:?}: pile top {top_z} m, floor {floor_z} m"
            );
        }
    }

    /// A dose from a hopper chute 8 cm over the floor of an empty tray falls from there; the
    /// control, from just above the pile (the floor), starts within a part's size of it.
    #[test]
    fn a_chute_drops_the_parts_from_its_height() {
        let (scene, robot, shape) = default_cell_with("A");
        // One wave into a running cell: the pour returns with its parts where they start.
        let lowest_start_m = |chute_m: f64| {
            let mut w = World::new(&scene.scene, &robot, shape.clone());
            let floor_z = w.pick_tray.world_from_tray.translation.vector.z;
            w.build_pile(&PileOptions::into_running_cell(6, 3).dropped_from(chute_m))
                .unwrap();
            w.parts
                .iter()
                .map(|p| w.colliders[p.collider].compute_aabb().mins.z as f64 / crate::physics::SIM_UNITS_PER_M)
                .fold(f64::INFINITY, f64::min)
                - floor_z
        };
        let from_chute = lowest_start_m(0.08);
        assert!(
            (0.079..0.09).contains(&from_chute),
            "lowest part {from_chute} m over the floor"
        );
        let over_pile = lowest_start_m(0.0);
        assert!(over_pile < 0.02, "control: lowest part {over_pile} m over the floor");
    }
}
