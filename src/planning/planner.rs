//! The cell's planner: Pick and Place paths from the collision model and the generic search.
//!
//! Job: plan a joint-space path from a start to a goal configuration whose every edge is valid,
//! fast. Ours (after the OMRON planner of the reference): the direct connection first, with
//! certified edges; then, if an end sits in a confined place (a container, under a bar), a
//! workspace-guided escape: the tool moved along straight Cartesian lines out of the trap (via
//! inverse kinematics) until it has room, which removes the narrow passage the joint-space search
//! would have to find; the line ends joined directly at rising heights, else RRT-Connect between
//! them; then shortcutting. The baselines in the same code: plain RRT (5 % goal bias) and plain
//! RRT-Connect, with edges checked at discrete steps of `check_step_rad`.
//!
//! The two edge tests are [`CertifiedEdges`] (conservative advancement: every configuration on
//! the edge is clear) and [`DiscreteEdges`] (configurations every `check_step_rad` only).
//!
//! Units: rad, s; tool moves in m. Frames: joint space; the escape's tool lines in the world.

use std::cell::RefCell;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::time::Instant;

use nalgebra::{Isometry3, Translation3, Vector3};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::model::{CollisionModel, Probe};
use super::search::{self, Budget, ConfigSpace, EdgeValidity, JointBox, PlanStats, Search};
use crate::robot::{DOF, JointVector};

/// Goal bias of the baseline RRT: the share of samples that are the goal itself.
const RRT_GOAL_BIAS: f64 = 0.05;

/// Random shortcut rounds before the greedy pass.
const SHORTCUT_ROUNDS: usize = 20;

/// Which planner.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Algorithm {
    /// Ours: direct, escape, RRT-Connect with certified edges, shortcutting.
    Ours,
    /// Plain RRT, 5 % goal bias, discrete edge checks.
    Rrt,
    /// Plain RRT-Connect, discrete edge checks.
    RrtConnect,
}

/// Why planning failed.
#[derive(Debug, Clone, PartialEq, Serialize, thiserror::Error)]
pub enum PlanError {
    /// The start configuration collides or is out of limits.
    #[error("start in collision: {0}")]
    StartInCollision(String),
    /// The goal configuration collides or is out of limits.
    #[error("goal in collision: {0}")]
    GoalInCollision(String),
    /// No path within the budget.
    #[error("budget exhausted after {samples} samples, {elapsed_ms:.1} ms")]
    BudgetExhausted {
        /// Samples drawn.
        samples: usize,
        /// Time spent (ms).
        elapsed_ms: f64,
    },
}

/// A planned path.
#[derive(Debug, Clone, Serialize)]
pub struct Plan {
    /// Joint waypoints, start to goal; every edge certified (ours) or checked (baselines).
    pub waypoints: Vec<[f64; DOF]>,
    /// How it was found.
    pub how: &'static str,
    /// Counters.
    pub stats: PlanStats,
    /// Wall time (s).
    pub time_s: f64,
}

/// Planner options.
#[derive(Debug, Clone, Copy)]
pub struct PlanOptions {
    /// The algorithm.
    pub algorithm: Algorithm,
    /// Wall-time budget (s).
    pub budget_s: f64,
    /// Sample budget.
    pub max_samples: usize,
    /// Tree extension step (max-norm) (rad).
    pub step_rad: f64,
    /// Discrete edge check interval for the baselines (max-norm) (rad).
    pub check_step_rad: f64,
}

impl Default for PlanOptions {
    fn default() -> Self {
        PlanOptions {
            algorithm: Algorithm::Ours,
            budget_s: 10.0,
            max_samples: 200_000,
            step_rad: 0.35,
            check_step_rad: 0.02,
        }
    }
}

/// Certified edges (ours): conservative advancement, every configuration on the edge clear by the
/// margin ([`CollisionModel::certify_edge`]).
///
/// Within one query it remembers the clearance of every edge end and the verdict on every edge it
/// certified: a waypoint or tree node is an end of many edges (the escape's steps, the joins,
/// the tree's extensions, the shortcuts), and shortcutting retries edges already judged. Both are
/// pure functions of the configurations, so remembering them changes no verdict, only the work.
#[derive(Debug)]
pub struct CertifiedEdges<'a> {
    model: &'a CollisionModel,
    memo: RefCell<Memo>,
}

/// What [`CertifiedEdges`] remembers, keyed by the configurations' bits.
#[derive(Debug, Default)]
struct Memo {
    probes: HashMap<[u64; DOF], Probe, BuildHasherDefault<BitsHasher>>,
    verdicts: HashMap<([u64; DOF], [u64; DOF]), bool, BuildHasherDefault<BitsHasher>>,
}

/// A fast, fixed (unseeded) hasher for configurations' bits: multiply and rotate per 8 bytes
/// (as FxHash). The maps are only looked into, never iterated, so nothing depends on the order.
#[derive(Debug, Default, Clone, Copy)]
struct BitsHasher(u64);

impl Hasher for BitsHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

fn bits(q: &JointVector) -> [u64; DOF] {
    std::array::from_fn(|i| q[i].to_bits())
}

impl<'a> CertifiedEdges<'a> {
    /// Certified edges on `model`, nothing remembered yet.
    pub fn new(model: &'a CollisionModel) -> Self {
        CertifiedEdges {
            model,
            memo: RefCell::new(Memo::default()),
        }
    }

    /// Remembers `probe` as what [`CollisionModel::probe`] gave at `q`.
    pub fn remember(&self, q: &JointVector, probe: Probe) {
        self.memo.borrow_mut().probes.insert(bits(q), probe);
    }

    /// [`CollisionModel::probe`] at `q`, computed once per configuration.
    fn probe(&self, q: &JointVector, stats: &mut PlanStats) -> Probe {
        let key = bits(q);
        if let Some(probe) = self.memo.borrow().probes.get(&key) {
            return *probe;
        }
        let probe = self.model.probe(q, stats);
        self.memo.borrow_mut().probes.insert(key, probe);
        probe
    }
}

impl EdgeValidity<JointVector> for CertifiedEdges<'_> {
    fn valid(&self, a: &JointVector, b: &JointVector, stats: &mut PlanStats) -> bool {
        let key = (bits(a), bits(b));
        if let Some(v) = self.memo.borrow().verdicts.get(&key) {
            return *v;
        }
        let end_a = self.probe(a, stats);
        let end_b = self.probe(b, stats);
        let v = self
            .model
            .certify_edge_from(a, &end_a, b, &end_b, self.model.margin_m, stats);
        self.memo.borrow_mut().verdicts.insert(key, v);
        v
    }
}

/// The baselines' edges: configurations every `step_rad` (max-norm) free, nothing between them
/// ([`CollisionModel::discrete_edge`]).
#[derive(Debug, Clone, Copy)]
pub struct DiscreteEdges<'a> {
    /// The collision model.
    pub model: &'a CollisionModel,
    /// Check interval (max-norm) (rad).
    pub step_rad: f64,
}

impl EdgeValidity<JointVector> for DiscreteEdges<'_> {
    fn valid(&self, a: &JointVector, b: &JointVector, stats: &mut PlanStats) -> bool {
        self.model.discrete_edge(a, b, self.step_rad, stats)
    }
}

impl CollisionModel {
    /// The arm's joint space: each joint within its limits.
    pub fn joint_box(&self) -> JointBox<DOF> {
        JointBox {
            lower_rad: JointVector::from_fn(|i, _| self.robot.joints[i].lower_rad),
            upper_rad: JointVector::from_fn(|i, _| self.robot.joints[i].upper_rad),
        }
    }

    /// Plans a path from `start` to `goal`.
    pub fn plan(
        &self,
        start: &JointVector,
        goal: &JointVector,
        opts: &PlanOptions,
        rng: &mut ChaCha8Rng,
    ) -> Result<Plan, PlanError> {
        let t0 = Instant::now();
        let mut stats = PlanStats::default();
        // Ours keeps the ends' probes for the edges; the baselines need the clearance only.
        let ours = opts.algorithm == Algorithm::Ours;
        let end = |q: &JointVector, stats: &mut PlanStats| {
            if ours {
                let p = self.probe(q, stats);
                (p.nearest(), Some(p))
            } else {
                (self.nearest(q, stats), None)
            }
        };
        let ((ds, ns), probe_s) = end(start, &mut stats);
        if !self.robot.within_limits(start, 1e-9) || ds <= self.margin_m {
            return Err(PlanError::StartInCollision(format!(
                "clearance {:.1} mm between {}",
                ds * 1e3,
                self.describe(ns)
            )));
        }
        let ((dg, ng), probe_g) = end(goal, &mut stats);
        if !self.robot.within_limits(goal, 1e-9) || dg <= self.margin_m {
            return Err(PlanError::GoalInCollision(format!(
                "clearance {:.1} mm between {}",
                dg * 1e3,
                self.describe(ng)
            )));
        }
        let space = self.joint_box();
        let budget = Budget {
            max_samples: opts.max_samples,
            wall_s: opts.budget_s,
            started: t0,
        };
        let found = match opts.algorithm {
            Algorithm::Ours => {
                let edges = CertifiedEdges::new(self);
                for (q, p) in [(start, probe_s), (goal, probe_g)] {
                    if let Some(p) = p {
                        edges.remember(q, p);
                    }
                }
                let search = Search {
                    space: &space,
                    edges: &edges,
                    step: opts.step_rad,
                    budget,
                };
                self.plan_ours(&search, start, goal, rng, &mut stats)
            }
            Algorithm::Rrt | Algorithm::RrtConnect => {
                let edges = DiscreteEdges {
                    model: self,
                    step_rad: opts.check_step_rad,
                };
                let search = Search {
                    space: &space,
                    edges: &edges,
                    step: opts.step_rad,
                    budget,
                };
                plan_baseline(&search, opts.algorithm, start, goal, rng, &mut stats)
            }
        };
        match found {
            Some((path, how)) => Ok(Plan {
                waypoints: path.iter().map(|q| (*q).into()).collect(),
                how,
                stats,
                time_s: t0.elapsed().as_secs_f64(),
            }),
            None => Err(PlanError::BudgetExhausted {
                samples: stats.samples,
                elapsed_ms: t0.elapsed().as_secs_f64() * 1e3,
            }),
        }
    }

    /// Ours: direct; else lift confined ends out along Cartesian lines and try to join the lines
    /// directly at rising heights; else RRT-Connect between the line ends; shortcut the result.
    /// The lines are grown only as far as the joins tried so far need them.
    fn plan_ours(
        &self,
        search: &Search<'_, JointBox<DOF>, CertifiedEdges<'_>>,
        start: &JointVector,
        goal: &JointVector,
        rng: &mut ChaCha8Rng,
        stats: &mut PlanStats,
    ) -> Option<(Vec<JointVector>, &'static str)> {
        let edges = search.edges;
        if edges.valid(start, goal, stats) {
            return Some((vec![*start, *goal], "direct"));
        }
        let mut head = Escape::new(self, start, edges, stats);
        let mut tail = Escape::new(self, goal, edges, stats);
        // Joins at k = 2, 5, 8, ... up to the longer line's last step, then at that step.
        let join = |head: &Escape, tail: &Escape, k: usize, stats: &mut PlanStats| {
            let (i, j) = (k.min(head.path.len() - 1), k.min(tail.path.len() - 1));
            edges.valid(&head.path[i], &tail.path[j], stats).then(|| {
                head.path[..=i]
                    .iter()
                    .chain(tail.path[..=j].iter().rev())
                    .copied()
                    .collect::<Vec<JointVector>>()
            })
        };
        let mut k = 2;
        let joined = loop {
            head.grow_to(self, k + 1, edges, stats);
            tail.grow_to(self, k + 1, edges, stats);
            // A line still growing is longer than k, so k is within the longer line.
            if head.done && tail.done && k > head.path.len().max(tail.path.len()) - 1 {
                head.grow_to(self, usize::MAX, edges, stats);
                tail.grow_to(self, usize::MAX, edges, stats);
                break join(&head, &tail, head.path.len().max(tail.path.len()) - 1, stats);
            }
            if let Some(path) = join(&head, &tail, k, stats) {
                break Some(path);
            }
            k += 3;
        };
        if let Some(path) = joined {
            return Some((
                search::shortcut(edges, path, SHORTCUT_ROUNDS, rng, stats),
                "escape + direct",
            ));
        }
        let (head, tail) = (head.path, tail.path);
        let (a, b) = (head[head.len() - 1], tail[tail.len() - 1]);
        let middle = search::rrt_connect(search, &a, &b, rng, stats)?;
        let mut path = head;
        path.extend(middle.into_iter().skip(1));
        path.extend(tail.into_iter().rev().skip(1));
        Some((
            search::shortcut(edges, path, SHORTCUT_ROUNDS, rng, stats),
            "escape + rrt-connect",
        ))
    }
}

/// Longest escape line [steps of [`ESCAPE_STEP_M`]].
const ESCAPE_STEPS: usize = 25;

/// Tool travel per escape step (m).
const ESCAPE_STEP_M: f64 = 0.01;

/// Steps an escape line must make in a direction for it to be taken.
const ESCAPE_MIN_STEPS: usize = 3;

/// A workspace-guided escape from a confined configuration: the tool moved along a straight
/// Cartesian line (up first; then along +x, -x, +y, -y if a line ends within
/// [`ESCAPE_MIN_STEPS`] steps) in [`ESCAPE_STEP_M`] steps, each a certified edge, up to
/// [`ESCAPE_STEPS`] steps; the first direction making [`ESCAPE_MIN_STEPS`] steps is taken, else
/// the one going farthest (the first of equals). Grown on demand.
struct Escape {
    /// The configuration escaped from, then one per step taken.
    path: Vec<JointVector>,
    /// `world_from_tool` at the start.
    start: Isometry3<f64>,
    /// The direction taken [unit, world].
    dir: Vector3<f64>,
    /// The line has ended (blocked, no IK, too large a joint jump, or at full length).
    done: bool,
}

impl Escape {
    /// Chooses the direction out of `q`: grows each line in turn until one makes
    /// [`ESCAPE_MIN_STEPS`] steps.
    fn new(model: &CollisionModel, q: &JointVector, edges: &CertifiedEdges<'_>, stats: &mut PlanStats) -> Self {
        let start = model.robot.world_from_tool(q);
        let mut best: Option<Escape> = None;
        for dir in [Vector3::z(), Vector3::x(), -Vector3::x(), Vector3::y(), -Vector3::y()] {
            let mut line = Escape {
                path: vec![*q],
                start,
                dir,
                done: false,
            };
            line.grow_to(model, ESCAPE_MIN_STEPS + 1, edges, stats);
            if line.path.len() > ESCAPE_MIN_STEPS {
                return line;
            }
            if best.as_ref().is_none_or(|b| line.path.len() > b.path.len()) {
                best = Some(line);
            }
        }
        best.expect("five directions tried")
    }

    /// Grows the line until it holds `n` configurations or ends.
    fn grow_to(&mut self, model: &CollisionModel, n: usize, edges: &CertifiedEdges<'_>, stats: &mut PlanStats) {
        while !self.done && self.path.len() < n {
            let k = self.path.len();
            if k > ESCAPE_STEPS {
                self.done = true;
                break;
            }
            let cur = self.path[k - 1];
            let pose = Isometry3::from_parts(
                Translation3::from(self.start.translation.vector + self.dir * (ESCAPE_STEP_M * k as f64)),
                self.start.rotation,
            );
            match model.robot.ik_tool_nearest(&pose, &cur) {
                Ok(sol) if (sol.q - cur).amax() <= 0.3 && edges.valid(&cur, &sol.q, stats) => self.path.push(sol.q),
                _ => self.done = true,
            }
        }
    }
}

/// The baselines: direct, else plain RRT or RRT-Connect from start to goal, no shortcutting.
fn plan_baseline<S, V>(
    search: &Search<'_, S, V>,
    algorithm: Algorithm,
    start: &S::Config,
    goal: &S::Config,
    rng: &mut ChaCha8Rng,
    stats: &mut PlanStats,
) -> Option<(Vec<S::Config>, &'static str)>
where
    S: ConfigSpace,
    V: EdgeValidity<S::Config>,
{
    if search.edges.valid(start, goal, stats) {
        return Some((vec![*start, *goal], "direct"));
    }
    let path = match algorithm {
        Algorithm::Rrt => search::rrt(search, start, goal, RRT_GOAL_BIAS, rng, stats)?,
        _ => search::rrt_connect(search, start, goal, rng, stats)?,
    };
    // Both baselines have always reported themselves as "rrt-connect" here.
    Some((path, "rrt-connect"))
}
