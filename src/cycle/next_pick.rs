//! Which recognition result the next pick comes from, and the next pick prepared early.
//!
//! Job: the result in hand while it still offers a part clear of the picks made since its
//! capture (several picks per capture), else the pending capture's or a new one's; and, at a
//! release, the next pick prepared from the result in hand so that its Pick may start while this
//! Place's retreat ends ([`Run::prefetch_next`]), or that retreat played alone when the run ends.
//!
//! Units: s, m. Frames: world.

use nalgebra::{Isometry3, Vector3};

use super::events::{Event, PlacementError};
use super::motions::Prepared;
use super::play::{Capture, Played, Segment};
use super::records::StageCompute;
use super::sensing::SensedResult;
use super::{CycleError, InHand, PickSpot, Run};
use crate::physics::PartState;
use crate::sensor::Detection;
use crate::trajectory::{LineMotion, Motion};

/// The next pick, prepared at a release from the result in hand (see `Run::prefetch_next`),
/// whose Pick the last Place's retreat runs into (the retreat has not been played yet).
pub(super) struct Prefetched {
    /// The result it comes from, the picks taken from it before and made since its trigger.
    pub(super) result: SensedResult,
    pub(super) taken: usize,
    pub(super) since: usize,
    /// When its compute started (s).
    pub(super) compute_from_s: f64,
    /// Its motions (with the retreat overlapped) and the wall time of each stage (s).
    pub(super) prep: Prepared,
    pub(super) wall: StageCompute,
    /// The retreat it overlaps, not played yet.
    pub(super) retreat: LineMotion,
}

/// A part released over its slot whose placement error is not measured yet: it is, once the
/// part has come to rest (a part dropped from the release height rocks for a few tenths of a
/// second, and measured while it rocks it looked misplaced), or [`SETTLE_TIMEOUT_S`] after its
/// release, or at once if it left the place tray, or as it lies when its tray goes.
pub(super) struct Settling {
    /// The pick's record index.
    pub record: usize,
    /// The part.
    pub part: usize,
    /// Where it should lie in its slot (the grasp's `world_from_part_place`).
    pub world_from_part_place: Isometry3<f64>,
    /// When it was released (s).
    pub released_s: f64,
}

/// A placed part not at rest this long after its release is measured as it lies (s).
pub(super) const SETTLE_TIMEOUT_S: f64 = 2.0;

/// At a run's end, how often the released parts are looked at while they settle (s).
const SETTLE_POLL_S: f64 = 0.05;

/// A later pick from the same result takes only a part whose recognised box keeps this much
/// clear of what each earlier pick may have moved (m).
pub const BLIND_PICK_MARGIN_M: f64 = 0.005;

/// How far above its grasp the tool's column is followed beyond its approach pose (m): the
/// hand's body stands over the cup all the way up.
const TOOL_COLUMN_UP_M: f64 = 0.3;

/// Which of `detections` (boxes of half extents `half_m` at their recognised poses) keep
/// [`BLIND_PICK_MARGIN_M`] clear of what the picks `since` may have moved: each picked part's
/// box, the boxes of the detections touching it, and the tool's columns (radius `tool_r_m` about
/// each line from its grasp up through its approach pose, and through the end of its lift, and
/// [`TOOL_COLUMN_UP_M`] beyond).
fn clear_of_picks(detections: &[Detection], since: &[&PickSpot], half_m: &Vector3<f64>, tool_r_m: f64) -> Vec<bool> {
    let apart = |a: &Isometry3<f64>, b: &Isometry3<f64>| {
        crate::geometry::box_box_distance_m(a, half_m, b, half_m) >= BLIND_PICK_MARGIN_M
    };
    // The boxes a pick may have moved: the picked part's and its recognised neighbours'.
    let mut moved: Vec<Isometry3<f64>> = Vec::new();
    for spot in since {
        moved.push(spot.world_from_part);
        moved.extend(
            detections
                .iter()
                .map(|d| d.world_from_part)
                .filter(|d| !apart(d, &spot.world_from_part)),
        );
    }
    let columns: Vec<[Vector3<f64>; 2]> = since
        .iter()
        .flat_map(|spot| spot.tool_lines_m)
        .map(|[top, grasp]| {
            let up = (top - grasp).try_normalize(1e-9).unwrap_or_else(Vector3::z);
            [grasp, top + up * TOOL_COLUMN_UP_M]
        })
        .collect();
    detections
        .iter()
        .map(|d| {
            let p = &d.world_from_part;
            moved.iter().all(|m| apart(p, m))
                && columns.iter().all(|[from, to]| {
                    crate::geometry::box_column_distance_m(p, half_m, from, to, tool_r_m) >= BLIND_PICK_MARGIN_M
                })
        })
        .collect()
}

impl Run<'_, '_> {
    /// The result in hand with only the detections the next pick may take, and the number of
    /// picks made since its trigger (0: the image shows the pile as it is). `None` if the cell
    /// file allows no more picks from it, or (when picks were made since its trigger) none of its
    /// detections is clear of them.
    ///
    /// What a pick may have moved, as the cell knows it from its recognition and its own motion:
    /// the picked part's box at its recognised pose, the boxes of the parts this result
    /// recognised touching it (within [`BLIND_PICK_MARGIN_M`]: lifted off, they shift), and the
    /// tool's columns (its body's radius about the lines from its grasp up through its approach
    /// pose and through the end of its lift). A detection is taken only if its box keeps [`BLIND_PICK_MARGIN_M`] clear of all of
    /// them, for every pick made after the trigger. Whether the part is still there the seal
    /// check tells.
    pub(super) fn usable(&self) -> Option<(SensedResult, usize)> {
        let h = self.st.in_hand.as_ref()?;
        if h.taken >= self.cell.scene.cycle.max_picks_per_capture as usize {
            return None;
        }
        let since: Vec<&PickSpot> = self
            .st
            .pick_spots
            .iter()
            .filter(|p| p.t_s >= h.result.capture_s)
            .collect();
        let detections = h.result.detections.as_deref();
        if since.is_empty() {
            return Some((h.result.keeping(&vec![true; detections.map_or(0, <[_]>::len)]), 0));
        }
        let keep = clear_of_picks(
            detections?,
            &since,
            &self.cell.shape.half_extents_m,
            self.cell.scene.gripper.body_diameter_m / 2.0,
        );
        keep.iter().any(|k| *k).then(|| (h.result.keeping(&keep), since.len()))
    }

    /// The result the next pick comes from: the newest one that has arrived, if it still has
    /// a part to offer ([`Run::usable`]); else the pending capture's, awaited at the waiting
    /// pose; else a new capture's. Returns the result, the picks taken from it before and the
    /// picks made since its trigger; `None` if the arm cannot leave the view.
    pub(super) fn result_for_pick(&mut self) -> Result<Option<(SensedResult, usize, usize)>, CycleError> {
        loop {
            self.collect_ready();
            if let Some((r, since)) = self.usable() {
                let taken = self.st.in_hand.as_ref().map_or(0, |h| h.taken);
                return Ok(Some((r, taken, since)));
            }
            // Nothing to take from the result in hand: wait for the next one.
            self.st.in_hand = None;
            let Some(r) = self.next_result()? else {
                return Ok(None);
            };
            self.st.in_hand = Some(InHand { result: r, taken: 0 });
        }
    }

    /// At a release, with `up` the Place's retreat still to play: the next pick prepared now,
    /// its Pick to start while the retreat ends. Taken only if the cell overlaps lines, the run
    /// has another pick to make, a result in hand offers a part without waiting, that Pick
    /// overlaps the retreat ([`motions::RetreatBlend`]), its compute is done before the overlap
    /// would start, no exposure is still running then, and nothing else happens before it (this
    /// part does not fill the place tray: its exchange would take the part away before its
    /// placement error is measured, and could take time). Returns how long the retreat runs
    /// alone (s) with that pick; the retreat is then played with its Pick. Otherwise the retreat
    /// is played as before; a next pick prepared here is dropped and prepared again after it.
    pub(super) fn prefetch_next(&mut self, up: &LineMotion) -> Option<(Prefetched, f64)> {
        let cell = self.cell;
        let opts = cell.opts;
        let next = self.st.tally.attempts + 1;
        if !cell.scene.cycle.overlap_lines
            || next >= opts.picks
            || opts.stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed))
            || self.st.trays.next_slot + 1 >= cell.slots.len()
        {
            return None;
        }
        self.collect_ready();
        let (result, since) = self.usable()?;
        let taken = self.st.in_hand.as_ref().map_or(0, |h| h.taken);
        let compute_from_s = result.job.ready_s.max(self.st.compute_from_s);
        // Planned from where the retreat ends.
        self.st.arm.free_s = self.st.world.time_s() + up.duration_s();
        let this = self.st.pick.replace(next);
        let prepared = match result.detections.as_deref() {
            Some(d) if !d.is_empty() => {
                // This part is in the current slot: the next goes to the one after.
                let slot = self.st.trays.next_slot + 1;
                self.prepare(&result, compute_from_s, slot, Some(up)).ok()
            }
            _ => None,
        };
        let now = self.st.world.time_s();
        let taken_here = prepared.and_then(|(prep, wall)| {
            let head_s = prep.retreat_blend.as_ref()?.motion.start_s();
            let charged = cell.charged(wall, prep.passed_over.len());
            let pick_ready = compute_from_s + charged.grasp_s + charged.pick_s;
            let exposing = self
                .st
                .pending
                .as_ref()
                .is_some_and(|j| j.spoiled.is_none() && j.exposure_end_s > now + head_s + 1e-9);
            (pick_ready <= now + head_s + 1e-9 && !exposing).then_some((prep, wall, head_s))
        });
        if taken_here.is_some() {
            self.event(Event::ResultUsed {
                taken,
                since_capture: since,
            });
        }
        self.st.pick = this;
        let (prep, wall, head_s) = taken_here?;
        let next = Prefetched {
            result,
            taken,
            since,
            compute_from_s,
            prep,
            wall,
            retreat: up.clone(),
        };
        Some((next, head_s))
    }

    /// A retreat left for a next Pick that will not come (the run ends): played alone now.
    pub(super) fn play_held_retreat(&mut self, next: Option<Prefetched>) -> Result<(), CycleError> {
        let Some(p) = next else {
            return Ok(());
        };
        let retreat = Segment::new(&p.retreat, self.cell.hand).capturing(Capture::ANY);
        if let Played::Failed(o) = self.play(&retreat)? {
            self.event(Event::Outcome(o));
        }
        Ok(())
    }

    /// Measures the released parts that have come to rest (every one, with `all`), in the order
    /// they were released, into `st.measured`; the others stay in waiting.
    pub(super) fn measure_settled(&mut self, all: bool) {
        let now = self.st.world.time_s();
        let waiting = std::mem::take(&mut self.st.settling);
        for s in waiting {
            let w = &self.st.world;
            let due = all
                || w.placed_part_at_rest(s.part)
                || w.part_state(s.part) != PartState::Placed
                || now - s.released_s >= SETTLE_TIMEOUT_S;
            if due {
                let error = self.placement_error(s.record, s.part, &s.world_from_part_place);
                self.st.measured.push(error);
            } else {
                self.st.settling.push(s);
            }
        }
    }

    /// Lets the world run (nothing else moving) until every released part has come to rest or
    /// its [`SETTLE_TIMEOUT_S`] has passed, and measures them: the run's end.
    pub(super) fn settle_placed(&mut self) -> Result<(), CycleError> {
        self.measure_settled(false);
        while let Some(last_s) = self.st.settling.iter().map(|s| s.released_s).reduce(f64::max) {
            let t = (self.st.world.time_s() + SETTLE_POLL_S).min(last_s + SETTLE_TIMEOUT_S);
            self.idle_until(t)?;
            self.measure_settled(false);
        }
        Ok(())
    }

    /// How far part `part`, placed by pick `pick`, lies from where it should,
    /// `world_from_part_place` (the slot turned into the part's place pose): the horizontal
    /// distance of the part frame's origin, and the rotation between the two, the least over the
    /// turns that leave the part looking the same (the recognition's scoring measure). A part
    /// that lies in its place pose but turned in its slot is off by that turn; one tipped onto
    /// another face, by the tip. A part beyond the place tray's tolerances is reported as a
    /// misplaced incident.
    pub(super) fn placement_error(
        &mut self,
        pick: usize,
        part: usize,
        world_from_part_place: &Isometry3<f64>,
    ) -> PlacementError {
        let pose = self.st.world.part_pose(part);
        let (_, rotation_rad) = self.st.sensor.symmetry.pose_error(world_from_part_place, &pose);
        let error = PlacementError {
            pick,
            part,
            error_m: (pose.translation.vector - world_from_part_place.translation.vector)
                .xy()
                .norm(),
            rotation_rad,
        };
        let tray = &self.cell.scene.place_tray;
        if error.misplaced(tray.tolerance_m, tray.tolerance_deg.to_radians()) {
            self.event(Event::Misplaced(error));
        }
        error
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A detection of a part at `(x, y)` on the tray floor (m), turned `yaw` about z.
    fn at(x: f64, y: f64, yaw: f64) -> Detection {
        Detection {
            world_from_part: Isometry3::new(Vector3::new(x, y, 0.0025), Vector3::z() * yaw),
            visible_fraction: 1.0,
            score: 1.0,
            face_up: Some(0),
        }
    }

    #[test]
    fn a_later_pick_keeps_clear_of_the_picked_strip_its_neighbours_and_the_tools_column() {
        // C's strip, 150 x 10 x 5 mm, and a cup whose body is 30 mm across.
        let half = Vector3::new(0.075, 0.005, 0.0025);
        let picked = at(0.0, 0.0, 0.0);
        let spot = PickSpot {
            t_s: 1.0,
            world_from_part: picked.world_from_part,
            tool_lines_m: [[Vector3::new(0.0, 0.0, 0.1), Vector3::new(0.0, 0.0, 0.005)]; 2],
        };
        let detections = [
            picked.clone(),
            // Parallel, 27 mm off centre: 17 mm of floor between the two, 7 mm beyond the
            // hand's body over the cup.
            at(0.0, 0.027, 0.0),
            // Lying across the picked strip's end, reaching 70 mm to one side.
            at(0.070, -0.070, std::f64::consts::FRAC_PI_2),
            // Touching that one's far end, 130 mm from the picked strip: it may be knocked.
            at(0.070 + 0.005 + 0.075, -0.140, 0.0),
            // Parallel on the other side, 13 mm off centre: 3 mm of floor, less than the margin.
            at(-0.080, -0.013, 0.0),
            // End to end beyond the tool's column, 20 mm gap.
            at(0.170, 0.0, 0.0),
        ];
        let keep = clear_of_picks(&detections, &[&spot], &half, 0.015);
        assert_eq!(keep, [false, true, false, false, false, true]);
        // The column: a short part 10 mm beside the cup, clear of the picked strip's box by
        // 5 mm, is not clear of the 15 mm body over the cup.
        let small = Vector3::new(0.0025, 0.0025, 0.0025);
        let cube = at(0.0, 0.0125, 0.0);
        let spot_small = PickSpot {
            world_from_part: Isometry3::translation(0.0, 0.0, 0.0025),
            ..spot.clone()
        };
        assert_eq!(
            clear_of_picks(std::slice::from_ref(&cube), &[&spot_small], &small, 0.015),
            [false]
        );
        // Control: with a thin hand (2 mm body) it is clear.
        assert_eq!(clear_of_picks(&[cube], &[&spot_small], &small, 0.001), [true]);
    }
}
