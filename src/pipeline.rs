//! Sense and grasp: from one capture and its recognition result to the grasp the cell will try
//! and the planning scene around it. One function, used by the cell cycle, by `binpick sense`
//! and by the benchmarks, so they all decide the same way.
//!
//! Job: bin the capture's point cloud into a height map over the pick tray and as far around it
//! as a part lying across the rim can reach, with the arm masked out there as the controller knew
//! it at the trigger (the self-filter); rank suction grasps
//! on the recognised parts ([`crate::grasp::GraspSelector`]); keep the pile inside the tray's
//! inner walls, and what stands over the rim and beyond the walls, as the planner's obstacle
//! columns (max-pooled, conservative; unseen cells inside occupied up to the highest seen cell
//! around them, never free), with a disc around
//! the grasp point cut out (the part to be picked); take the best-ranked grasp that is not at a
//! spot where a grasp just failed and whose approach pose is clear in that planning scene, both
//! with the hand alone (where the Pick ends) and with the part on the cup as recognised (where
//! the Place starts).
//! Everything here comes from what the sensor measured: no ground truth.
//!
//! Units: m, rad. Frames: world; the pick tray frame for the height map and the cut-out.

use std::collections::BTreeMap;
use std::fmt;

use nalgebra::{Point3, Vector3};

use crate::config::Scene;
use crate::grasp::{GraspCandidate, GraspPlan, GraspSelector};
use crate::physics::TrayVolume;
use crate::planning::{CollisionModel, Environment, PileColumns, PlanStats, RobotSpheres};
use crate::robot::{JointVector, RobotModel};
use crate::sensor::heightmap::BeyondWalls;
use crate::sensor::{ArmAtTrigger, Capture, Detection, HeightMap};

/// Height-map cell edge (m).
pub const HEIGHT_MAP_CELL_M: f64 = 0.002;
/// Height-map cells per planning column side (the columns keep the highest point of 5 x 5).
pub const PILE_POOL_CELLS: usize = 5;
/// A point beyond the pick tray's rim within this of the arm's spheres (links, hand, held part)
/// at the trigger is the arm's, not a part's (m): the spheres cover the links' shapes and the held
/// part's recognised pose is good to a millimetre; the rest is depth noise and margin.
pub const SELF_FILTER_MARGIN_M: f64 = 0.01;
/// Radius of the disc around the grasp point whose columns the planner ignores (m).
pub const CUT_OUT_RADIUS_M: f64 = 0.02;
/// A grasp within this distance of a spot where one failed in the same pile is not tried (m).
pub const FAILED_SPOT_RADIUS_M: f64 = 0.004;
/// How many of the best-ranked grasps are tried for a clear approach.
pub const APPROACH_CANDIDATES: usize = 8;

/// What sense-and-grasp needs besides the capture: the cell, the arm, the selector.
#[derive(Clone, Copy)]
pub struct GraspContext<'a> {
    /// The cell file.
    pub scene: &'a Scene,
    /// The arm.
    pub robot: &'a RobotModel,
    /// The grasp selector for the workpiece.
    pub selector: &'a GraspSelector,
    /// The pick tray's volume (height map extent).
    pub pick_tray: &'a TrayVolume,
    /// Half extents of the part's bounding box (m) (the held part in the planner's model).
    pub part_half_extents_m: Vector3<f64>,
}

/// The grasp chosen on one recognition result, with its planning scene.
#[derive(Debug, Clone)]
pub struct ChosenGrasp {
    /// Index into the ranked candidates.
    pub rank: usize,
    /// The grasp.
    pub grasp: GraspCandidate,
    /// The cell and the pile as seen, the grasp's part cut out.
    pub env: Environment,
    /// The planner's model of the arm with the hand (no part) in `env`.
    pub model: CollisionModel,
}

/// What one capture shows of the pick tray, derived once for every grasp choice made on it (the
/// cycle chooses on one capture for several picks, and ahead of the pick it is for).
#[derive(Debug, Clone)]
pub struct SensedPile {
    /// The capture's number within its run.
    pub capture_id: u64,
    /// The capture's height map over the pick tray (walls included), in the tray's pose then.
    pub height_map: HeightMap,
    /// The pile as the planner sees it ([`pile_map`]).
    pub pile: HeightMap,
}

impl SensedPile {
    /// The height map of `capture` over `ctx`'s pick tray and as far around it as the capture
    /// measured (as far as a part across the rim reaches: [`Capture::beyond_walls_m`]), the arm
    /// at the trigger (`arm`) masked out there, and the planner's pile from it.
    pub fn new(ctx: &GraspContext<'_>, capture: &Capture, arm: &ArmAtTrigger) -> Self {
        let held = arm
            .tool_from_held_part
            .map(|tool_from_part| (tool_from_part, ctx.part_half_extents_m));
        let spheres = RobotSpheres::new(ctx.robot, ctx.scene, held);
        let at_trigger = spheres.at(ctx.robot, &arm.q);
        let is_arm = |p: &Point3<f64>| at_trigger.cover(p, SELF_FILTER_MARGIN_M);
        let beyond = BeyondWalls {
            reach_m: capture.beyond_walls_m,
            above_m: ctx.pick_tray.wall_height_m + OVER_RIM_M,
            is_arm: &is_arm,
        };
        let height_map = HeightMap::from_capture(capture, ctx.pick_tray, HEIGHT_MAP_CELL_M, Some(&beyond));
        let pile = pile_map(ctx.scene, &height_map);
        SensedPile {
            capture_id: capture.id,
            height_map,
            pile,
        }
    }

    /// Whether these are the maps of `capture` with the pick tray at `tray`.
    pub fn is_of(&self, capture: &Capture, tray: &TrayVolume) -> bool {
        self.capture_id == capture.id && self.height_map.world_from_tray == tray.world_from_tray
    }
}

/// The result of sense-and-grasp.
#[derive(Debug, Clone)]
pub struct GraspChoice {
    /// The selector's ranking and rejections.
    pub plan: GraspPlan,
    /// The grasp to try, if any.
    pub chosen: Option<ChosenGrasp>,
}

impl GraspChoice {
    /// Why nothing was chosen (see [`why_none`]).
    pub fn why_none(&self) -> NoGrasp {
        why_none(&self.plan)
    }
}

/// Why no grasp can be tried.
#[derive(Debug, Clone, PartialEq)]
pub enum NoGrasp {
    /// No feasible grasp: how many candidates each reason rejected.
    NoneFeasible(BTreeMap<&'static str, usize>),
    /// None of the best-ranked (this many) has a clear approach.
    NoClearApproach(usize),
}

impl fmt::Display for NoGrasp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NoGrasp::NoneFeasible(rejected) => {
                let reasons = rejected
                    .iter()
                    .map(|(k, v)| format!("{k} {v}"))
                    .collect::<Vec<_>>()
                    .join(", ");
                if reasons.is_empty() {
                    f.write_str("no feasible grasp")
                } else {
                    write!(f, "no feasible grasp ({reasons})")
                }
            }
            NoGrasp::NoClearApproach(among) => write!(f, "no grasp with a clear approach among {among}"),
        }
    }
}

/// As its text.
impl serde::Serialize for NoGrasp {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// Why sense-and-grasp chose nothing from `plan`: no feasible grasp (with the rejection counts),
/// or no clear approach among the best-ranked.
pub fn why_none(plan: &GraspPlan) -> NoGrasp {
    if plan.ranked.is_empty() {
        NoGrasp::NoneFeasible(plan.rejected_counts())
    } else {
        NoGrasp::NoClearApproach(plan.ranked.len().min(APPROACH_CANDIDATES))
    }
}

/// The planning scene of a grasp: the cell's boxes and the pile inside the tray's inner walls as
/// columns of `pile` (a height map cleared outside the inner walls), with the disc around the
/// grasp point cut out.
pub fn planning_environment(scene: &Scene, pile: &HeightMap, grasp: &GraspCandidate) -> Environment {
    let local = pile.world_from_tray.inverse() * Point3::from(grasp.world_from_tool.translation.vector);
    let mut env = Environment::from_scene(scene);
    env.pile = Some(PileColumns::new(
        pile,
        PILE_POOL_CELLS,
        Some((local.x, local.y, CUT_OUT_RADIUS_M)),
    ));
    env
}

/// The pile as the planner sees it: the height map with every cell outside the pick tray's inner
/// walls cleared (the walls are in the cell model) but where something stands more than
/// [`OVER_RIM_M`] above the rim (a part lying across it), and every unseen cell inside them
/// occupied ([`HeightMap::unseen_filled`]: up to the highest seen cell bordering its hole, or to
/// the rim): the planner does not assume what it did not see.
pub fn pile_map(scene: &Scene, height_map: &HeightMap) -> HeightMap {
    let t = &scene.pick_tray;
    let inner = [t.inner_size_m[0] / 2.0, t.inner_size_m[1] / 2.0];
    height_map
        .unseen_filled(inner, t.wall_height_m)
        .without_walls(inner, t.wall_height_m + OVER_RIM_M)
}

/// A cell over the pick tray's walls seen this much higher than their rim holds a part (m): well
/// above the rim's own measured height (its highest point's depth noise, under a millimetre).
pub const OVER_RIM_M: f64 = 0.002;

/// Sense and grasp on one capture (its maps in `sensed`): the ranked grasps for the part to go to
/// `world_from_slot` with the arm at `q_now`, and the best one as [`choose_grasp`] chooses it.
pub fn sense_and_grasp(
    ctx: &GraspContext<'_>,
    sensed: &SensedPile,
    detections: &[Detection],
    world_from_slot: &nalgebra::Isometry3<f64>,
    q_now: &JointVector,
    failed_spots: &[Vector3<f64>],
) -> GraspChoice {
    let plan = ctx
        .selector
        .select(detections, &sensed.height_map, world_from_slot, q_now);
    let chosen = choose_grasp(ctx, sensed, detections, &plan, failed_spots, |_| false);
    GraspChoice { plan, chosen }
}

/// The best of `plan`'s ranked grasps, among the first [`APPROACH_CANDIDATES`] not within
/// [`FAILED_SPOT_RADIUS_M`] of a `failed_spots` entry and not `passed_over` (by rank: grasps
/// whose motions the cycle could not generate), whose approach pose is clear with the hand
/// alone and with the part held (a part near a wall can hang into it when lifted: the Place
/// would have nowhere to start from).
pub fn choose_grasp(
    ctx: &GraspContext<'_>,
    sensed: &SensedPile,
    detections: &[Detection],
    plan: &GraspPlan,
    failed_spots: &[Vector3<f64>],
    passed_over: impl Fn(usize) -> bool,
) -> Option<ChosenGrasp> {
    // Not where a grasp has just failed: the same spot would fail the same way.
    let tried = |g: &GraspCandidate| {
        failed_spots
            .iter()
            .any(|p| (p - g.world_from_tool.translation.vector).norm() < FAILED_SPOT_RADIUS_M)
    };
    for (rank, g) in plan
        .ranked
        .iter()
        .enumerate()
        .filter(|(rank, g)| !tried(g) && !passed_over(*rank))
        .take(APPROACH_CANDIDATES)
    {
        let env = planning_environment(ctx.scene, &sensed.pile, g);
        let model = CollisionModel::new(ctx.robot, RobotSpheres::new(ctx.robot, ctx.scene, None), env.clone());
        let q_approach = JointVector::from(g.q_approach);
        if !model.free(&q_approach, &mut PlanStats::default()) {
            continue;
        }
        // A tool leaning down a face's normal brings its wrist down beside the column the
        // selector cleared: the hand at the grasp must be clear of the cell and the pile too.
        if g.lean_rad.is_some() && !model.free(&JointVector::from(g.q_grasp), &mut PlanStats::default()) {
            continue;
        }
        let tool_from_part = g.world_from_tool.inverse() * detections[g.detection].world_from_part;
        let held = RobotSpheres::new(ctx.robot, ctx.scene, Some((tool_from_part, ctx.part_half_extents_m)));
        let q_lifted = JointVector::from(g.q_lifted);
        if CollisionModel::new(ctx.robot, held, env.clone()).free(&q_lifted, &mut PlanStats::default()) {
            return Some(ChosenGrasp {
                rank,
                grasp: g.clone(),
                env,
                model,
            });
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::capture::{BEYOND_WALLS_STEP_M, beyond_walls_m};

    /// The map grown beyond the walls pools every cell over the tray into the same planning
    /// column as the map to the walls: the growth is a whole number of pooled columns. Control:
    /// a growth of one cell fewer is not.
    #[test]
    fn the_growth_beyond_the_walls_is_whole_planning_columns() {
        let column_m = HEIGHT_MAP_CELL_M * PILE_POOL_CELLS as f64;
        let whole = |m: f64| ((m / column_m) - (m / column_m).round()).abs() < 1e-9;
        for size_m in [[0.03, 0.03, 0.02], [0.150, 0.010, 0.005], [0.0065, 0.0065, 0.003]] {
            let m = beyond_walls_m(&size_m);
            assert!(whole(m), "{m} m beyond the walls for {size_m:?}");
            assert!(
                m >= 0.5 * Vector3::from(size_m).norm(),
                "{m} m short of the half diagonal"
            );
        }
        assert!(whole(BEYOND_WALLS_STEP_M));
        assert!(!whole(BEYOND_WALLS_STEP_M - HEIGHT_MAP_CELL_M), "control");
    }
}
