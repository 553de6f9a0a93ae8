//! Generic sampling-based path search: RRT, RRT-Connect and shortcutting over any configuration
//! space and any test of edge validity. Nothing here knows of robots, obstacles or collision.
//!
//! Job: grow trees of configurations joined by straight edges until the start and the goal are
//! connected, within a budget of samples and wall time, and shorten the path found. A
//! [`ConfigSpace`] says how to draw a configuration, which tree node is nearest and how far one
//! step goes; an [`EdgeValidity`] says whether the straight edge between two configurations may
//! be used (the cell's planner offers certified edges and discrete checks). [`JointBox`] is the
//! space of an arm's joints within their limits, in any dimension.
//!
//! Every random draw comes from the caller's generator in a fixed order (one uniform number for
//! the goal bias, then the sample's coordinates in index order), so a seeded search is repeatable.
//!
//! Units: those of the space (rad for [`JointBox`]); wall time in s. Frames: none.

use std::time::Instant;

use nalgebra::SVector;
use rand::{Rng, RngExt};
use serde::Serialize;

/// Counters of one planning query.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct PlanStats {
    /// Random samples drawn.
    pub samples: usize,
    /// Configurations whose clearance was computed.
    pub clearance_checks: usize,
    /// Edges certified or rejected.
    pub edges: usize,
}

/// A configuration space the search can sample and move in.
pub trait ConfigSpace {
    /// One configuration (a point of the space).
    type Config: Copy;
    /// A configuration drawn uniformly from the space.
    fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Self::Config;
    /// Squared distance from `a` to `b` in the metric that picks a tree's nearest node.
    fn distance_sq(&self, a: &Self::Config, b: &Self::Config) -> f64;
    /// Length of the straight move from `a` to `b` in the metric that bounds one extension step
    /// (it may differ from the nearest-node metric: [`JointBox`] uses the largest joint motion).
    fn step_length(&self, a: &Self::Config, b: &Self::Config) -> f64;
    /// The configuration reached from `from` toward `to` by one step of at most `step` (in the
    /// [`ConfigSpace::step_length`] metric): `to` itself when it is that close.
    fn steer(&self, from: &Self::Config, to: &Self::Config, step: f64) -> Self::Config;
}

/// Whether a straight edge between two configurations may be used.
pub trait EdgeValidity<C> {
    /// True if every configuration on the straight edge `a` -> `b` is acceptable; the work done
    /// is counted in `stats` (`edges`, and `clearance_checks` for configurations examined).
    fn valid(&self, a: &C, b: &C, stats: &mut PlanStats) -> bool;
}

/// A box of joint positions: each of `N` joints between its limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointBox<const N: usize> {
    /// Lower limit per joint [rad].
    pub lower_rad: SVector<f64, N>,
    /// Upper limit per joint [rad].
    pub upper_rad: SVector<f64, N>,
}

impl<const N: usize> ConfigSpace for JointBox<N> {
    type Config = SVector<f64, N>;

    /// Each joint uniform in its closed range, joint 0 first.
    fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Self::Config {
        SVector::from_fn(|i, _| rng.random_range(self.lower_rad[i]..=self.upper_rad[i]))
    }

    /// Euclidean, squared.
    fn distance_sq(&self, a: &Self::Config, b: &Self::Config) -> f64 {
        (a - b).norm_squared()
    }

    /// The largest joint motion (max-norm).
    fn step_length(&self, a: &Self::Config, b: &Self::Config) -> f64 {
        (a - b).amax()
    }

    /// Along the straight line, scaled so that no joint moves more than `step`.
    fn steer(&self, from: &Self::Config, to: &Self::Config, step: f64) -> Self::Config {
        let d = to - from;
        let m = d.amax();
        if m <= step { *to } else { from + d * (step / m) }
    }
}

/// How much a search may spend: samples and wall time.
#[derive(Debug, Clone, Copy)]
pub struct Budget {
    /// Samples allowed (counted in [`PlanStats::samples`], from the query's start).
    pub max_samples: usize,
    /// Wall time allowed from `started` [s].
    pub wall_s: f64,
    /// When the query started.
    pub started: Instant,
}

impl Budget {
    /// Whether the samples or the time are used up.
    pub fn exhausted(&self, stats: &PlanStats) -> bool {
        stats.samples >= self.max_samples || self.started.elapsed().as_secs_f64() > self.wall_s
    }
}

/// One search: the space, the edge test, the extension step and the budget.
#[derive(Debug, Clone, Copy)]
pub struct Search<'a, S, V> {
    /// The configuration space.
    pub space: &'a S,
    /// The edge test every tree edge must pass.
    pub edges: &'a V,
    /// Longest tree extension, in the space's step metric.
    pub step: f64,
    /// Samples and wall time.
    pub budget: Budget,
}

/// A tree of configurations, each node knowing its parent.
struct Tree<C> {
    nodes: Vec<C>,
    parent: Vec<usize>,
}

impl<C: Copy> Tree<C> {
    fn new(root: C) -> Self {
        Tree {
            nodes: vec![root],
            parent: vec![usize::MAX],
        }
    }

    /// The node nearest to `q` (the first of equals).
    fn nearest<S: ConfigSpace<Config = C>>(&self, space: &S, q: &C) -> usize {
        let mut best = (f64::INFINITY, 0);
        for (i, n) in self.nodes.iter().enumerate() {
            let d = space.distance_sq(n, q);
            if d < best.0 {
                best = (d, i);
            }
        }
        best.1
    }

    fn add(&mut self, q: C, parent: usize) -> usize {
        self.nodes.push(q);
        self.parent.push(parent);
        self.nodes.len() - 1
    }

    /// Node `i`, its parent, ... the root.
    fn path_to_root(&self, mut i: usize) -> Vec<C> {
        let mut out = Vec::new();
        while i != usize::MAX {
            out.push(self.nodes[i]);
            i = self.parent[i];
        }
        out
    }
}

/// RRT: one tree from `start`; each round draws `goal` with probability `goal_bias`, else a
/// uniform sample, extends the nearest node one step toward it, and tries the goal once within a
/// step. Returns the path start..goal, or `None` when the budget runs out.
pub fn rrt<S, V, R>(
    search: &Search<'_, S, V>,
    start: &S::Config,
    goal: &S::Config,
    goal_bias: f64,
    rng: &mut R,
    stats: &mut PlanStats,
) -> Option<Vec<S::Config>>
where
    S: ConfigSpace,
    V: EdgeValidity<S::Config>,
    R: Rng + ?Sized,
{
    let Search { space, edges, step, .. } = *search;
    let mut tree = Tree::new(*start);
    while !search.budget.exhausted(stats) {
        stats.samples += 1;
        let target = if rng.random::<f64>() < goal_bias {
            *goal
        } else {
            space.sample(rng)
        };
        let near = tree.nearest(space, &target);
        let new = space.steer(&tree.nodes[near], &target, step);
        if !edges.valid(&tree.nodes[near], &new, stats) {
            continue;
        }
        let id = tree.add(new, near);
        if space.step_length(&new, goal) <= step && edges.valid(&new, goal, stats) {
            let mut p = tree.path_to_root(id);
            p.reverse();
            p.push(*goal);
            return Some(p);
        }
    }
    None
}

/// RRT-Connect: trees from `start` and `goal`, taking turns; one extends a step toward a uniform
/// sample, the other then grows toward the new node until it arrives or an edge fails. Returns
/// the path start..goal, or `None` when the budget runs out.
pub fn rrt_connect<S, V, R>(
    search: &Search<'_, S, V>,
    start: &S::Config,
    goal: &S::Config,
    rng: &mut R,
    stats: &mut PlanStats,
) -> Option<Vec<S::Config>>
where
    S: ConfigSpace,
    V: EdgeValidity<S::Config>,
    R: Rng + ?Sized,
{
    let Search { space, edges, step, .. } = *search;
    let mut trees = [Tree::new(*start), Tree::new(*goal)];
    let mut k = 0usize;
    while !search.budget.exhausted(stats) {
        stats.samples += 1;
        let target = space.sample(rng);
        let (ta, tb) = if k.is_multiple_of(2) { (0, 1) } else { (1, 0) };
        k += 1;
        let near = trees[ta].nearest(space, &target);
        let new = space.steer(&trees[ta].nodes[near], &target, step);
        if !edges.valid(&trees[ta].nodes[near], &new, stats) {
            continue;
        }
        let ia = trees[ta].add(new, near);
        // Connect: grow the other tree toward `new` until it arrives or is blocked.
        let mut ib = trees[tb].nearest(space, &new);
        loop {
            let from = trees[tb].nodes[ib];
            let next = space.steer(&from, &new, step);
            if !edges.valid(&from, &next, stats) {
                break;
            }
            ib = trees[tb].add(next, ib);
            if space.step_length(&next, &new) < 1e-12 {
                let mut pa = trees[ta].path_to_root(ia);
                let pb = trees[tb].path_to_root(ib);
                pa.reverse();
                pa.extend(pb.into_iter().skip(1));
                if ta == 1 {
                    pa.reverse();
                }
                return Some(pa);
            }
        }
    }
    None
}

/// Shortcutting: `rounds` random pairs of waypoints (i, j >= i + 2) joined when their edge is
/// valid, then a greedy pass from the start that always jumps to the farthest waypoint reachable
/// by a valid edge. Edges of the input path are assumed valid; the ends are kept.
pub fn shortcut<C, V, R>(edges: &V, mut path: Vec<C>, rounds: usize, rng: &mut R, stats: &mut PlanStats) -> Vec<C>
where
    C: Copy,
    V: EdgeValidity<C>,
    R: Rng + ?Sized,
{
    if path.is_empty() {
        return path;
    }
    for _ in 0..rounds {
        if path.len() < 3 {
            break;
        }
        let i = rng.random_range(0..path.len() - 2);
        let j = rng.random_range(i + 2..path.len());
        if edges.valid(&path[i], &path[j], stats) {
            path.drain(i + 1..j);
        }
    }
    let mut out = vec![path[0]];
    let mut i = 0;
    while i + 1 < path.len() {
        let mut j = path.len() - 1;
        while j > i + 1 && !edges.valid(&path[i], &path[j], stats) {
            j -= 1;
        }
        out.push(path[j]);
        i = j;
    }
    out
}
