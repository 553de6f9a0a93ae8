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
use super::{CycleError, InHand, Run};
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
    /// The last Place's part, measured once the retreat has left it.
    pub(super) late: Option<LatePlacement>,
}

/// A part whose Place's retreat runs into the next Pick: its placement error is measured once
/// that retreat has left it.
pub(super) struct LatePlacement {
    /// The pick's record index.
    pub record: usize,
    /// The part.
    pub part: usize,
    /// Where it should lie in its slot (the grasp's `world_from_part_place`).
    pub world_from_part_place: Isometry3<f64>,
}

/// A later pick from the same result takes only a part whose centre is this much farther from
/// every earlier pick's than both parts' bounding radii (or the tool's, whichever is larger) (m).
pub const BLIND_PICK_MARGIN_M: f64 = 0.005;

impl Run<'_, '_> {
    /// The result in hand with only the detections the next pick may take, and the number of
    /// picks made since its trigger (0: the image shows the pile as it is). `None` if the cell
    /// file allows no more picks from it, or (when picks were made since its trigger) none of its
    /// detections is clear of them: each taken must be recognised clear of every pick made after
    /// the trigger (centres at least two bounding radii, or the tool's radius plus the part's,
    /// plus [`BLIND_PICK_MARGIN_M`] apart horizontally), so neither the parts lifted nor the
    /// tool's column over them touched it. A real cell can decide this from its recognition and
    /// its own picks alone; whether the part is still there the seal check tells.
    pub(super) fn usable(&self) -> Option<(SensedResult, usize)> {
        let h = self.st.in_hand.as_ref()?;
        if h.taken >= self.cell.scene.cycle.max_picks_per_capture as usize {
            return None;
        }
        let since: Vec<Vector3<f64>> = self
            .st
            .pick_spots
            .iter()
            .filter(|(t, _)| *t >= h.result.capture_s)
            .map(|(_, c)| *c)
            .collect();
        if since.is_empty() {
            return Some((
                h.result
                    .keeping(&vec![true; h.result.detections.as_ref().map_or(0, Vec::len)]),
                0,
            ));
        }
        let r_part = self.cell.shape.bounding_radius_m;
        let reach_m = r_part + r_part.max(self.cell.scene.gripper.body_diameter_m / 2.0) + BLIND_PICK_MARGIN_M;
        let keep: Vec<bool> = h
            .result
            .detections
            .as_deref()?
            .iter()
            .map(|d| {
                let c = d.world_from_part.translation.vector;
                since.iter().all(|u| (c - u).xy().norm() >= reach_m)
            })
            .collect();
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
            Some(dets) if !dets.is_empty() => {
                // This part is in the current slot: the next goes to the one after.
                let slot = self.st.trays.next_slot + 1;
                self.prepare(dets, &result.job, compute_from_s, slot, Some(up)).ok()
            }
            _ => None,
        };
        let now = self.st.world.time_s();
        let taken_here = prepared.and_then(|(prep, wall)| {
            let head_s = prep.retreat_blend.as_ref()?.motion.start_s();
            let charged = if opts.deterministic { cell.budgets } else { wall };
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
            late: None,
        };
        Some((next, head_s))
    }

    /// A retreat left for a next Pick that will not come (the run ends): played alone now, and
    /// the placement error of the part it left measured.
    pub(super) fn play_held_retreat(&mut self, next: Option<Prefetched>) -> Result<Option<PlacementError>, CycleError> {
        let Some(p) = next else {
            return Ok(None);
        };
        let retreat = Segment::new(&p.retreat, self.cell.hand).capturing(Capture::ANY);
        if let Played::Failed(o) = self.play(&retreat)? {
            self.event(Event::Outcome(o));
        }
        Ok(p.late.map(|l| self.measure_placement(l)))
    }

    /// The placement error of a part whose retreat ran into the next Pick, once the cup has
    /// left it.
    pub(super) fn measure_placement(&mut self, late: LatePlacement) -> PlacementError {
        self.placement_error(late.record, late.part, &late.world_from_part_place)
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
