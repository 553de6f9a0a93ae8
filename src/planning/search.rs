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
    /// Lower limit per joint (rad).
    pub lower_rad: SVector<f64, N>,
    /// Upper limit per joint (rad).
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
    /// Wall time allowed from `started` (s).
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Vector2, Vector3};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    type P = Vector2<f64>;

    /// The unit square.
    const SQUARE: JointBox<2> = JointBox {
        lower_rad: Vector2::new(0.0, 0.0),
        upper_rad: Vector2::new(1.0, 1.0),
    };
    const START: P = Vector2::new(0.1, 0.2);
    const GOAL: P = Vector2::new(0.9, 0.2);

    /// Closed axis-aligned rectangles (lo, hi) a point must stay out of.
    struct Walls(Vec<(P, P)>);

    impl Walls {
        /// A wall across the square at x in [0.45, 0.55], open at y in `gap` if any.
        fn across(gap: Option<(f64, f64)>) -> Self {
            let (x0, x1) = (0.45, 0.55);
            Walls(match gap {
                Some((y0, y1)) => vec![(P::new(x0, -1.0), P::new(x1, y0)), (P::new(x0, y1), P::new(x1, 2.0))],
                None => vec![(P::new(x0, -1.0), P::new(x1, 2.0))],
            })
        }

        fn inside(&self, p: &P) -> bool {
            self.0
                .iter()
                .any(|(lo, hi)| (0..2).all(|i| p[i] >= lo[i] && p[i] <= hi[i]))
        }
    }

    impl EdgeValidity<P> for Walls {
        /// Exact: the segment misses every rectangle (slab clipping).
        fn valid(&self, a: &P, b: &P, stats: &mut PlanStats) -> bool {
            stats.edges += 1;
            let d = b - a;
            self.0.iter().all(|(lo, hi)| {
                let (mut t0, mut t1) = (0.0f64, 1.0f64);
                for i in 0..2 {
                    if d[i] == 0.0 {
                        if a[i] < lo[i] || a[i] > hi[i] {
                            return true;
                        }
                    } else {
                        let (u, v) = ((lo[i] - a[i]) / d[i], (hi[i] - a[i]) / d[i]);
                        t0 = t0.max(u.min(v));
                        t1 = t1.min(u.max(v));
                        if t0 > t1 {
                            return true;
                        }
                    }
                }
                false
            })
        }
    }

    /// Accepts every edge: the control that the dense check below can fail.
    struct AnyEdge;

    impl EdgeValidity<P> for AnyEdge {
        fn valid(&self, _: &P, _: &P, stats: &mut PlanStats) -> bool {
            stats.edges += 1;
            true
        }
    }

    /// Independent of the slab test: points every 0.1 mm along every edge, none in a wall.
    fn dense_check(walls: &Walls, path: &[P]) -> Result<(), String> {
        for (k, w) in path.windows(2).enumerate() {
            let n = ((w[1] - w[0]).norm() / 1e-4).ceil().max(1.0) as usize;
            for s in 0..=n {
                let p = w[0] + (w[1] - w[0]) * (s as f64 / n as f64);
                if walls.inside(&p) {
                    return Err(format!("edge {k} enters a wall at {p:?}"));
                }
            }
        }
        Ok(())
    }

    fn length(path: &[P]) -> f64 {
        path.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    fn search<'a, V>(edges: &'a V, max_samples: usize) -> Search<'a, JointBox<2>, V> {
        Search {
            space: &SQUARE,
            edges,
            step: 0.1,
            budget: Budget {
                max_samples,
                wall_s: 30.0,
                started: Instant::now(),
            },
        }
    }

    /// Both searches, seeded.
    fn both(
        s: &Search<'_, JointBox<2>, impl EdgeValidity<P>>,
        seed: u64,
    ) -> [(&'static str, Option<Vec<P>>, usize); 2] {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (mut a, mut b) = (PlanStats::default(), PlanStats::default());
        let p = rrt(s, &START, &GOAL, 0.05, &mut rng, &mut a);
        let q = rrt_connect(s, &START, &GOAL, &mut rng, &mut b);
        [("rrt", p, a.samples), ("rrt-connect", q, b.samples)]
    }

    #[test]
    fn rrt_and_rrt_connect_go_through_the_gap_and_shortcutting_never_lengthens() {
        let walls = Walls::across(Some((0.6, 0.7)));
        let s = search(&walls, 20_000);
        for seed in 1..=5 {
            for (name, path, _) in both(&s, seed) {
                let path = path.unwrap_or_else(|| panic!("{name}, seed {seed}: no path"));
                assert_eq!((path[0], path[path.len() - 1]), (START, GOAL), "{name}");
                assert!(path.iter().all(|p| p.iter().all(|x| (0.0..=1.0).contains(x))), "{name}");
                assert!(
                    path.windows(2).all(|w| (w[1] - w[0]).amax() <= 0.1 + 1e-12),
                    "{name}: step"
                );
                dense_check(&walls, &path).unwrap_or_else(|e| panic!("{name}, seed {seed}: {e}"));
                let before = length(&path);
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                let short = shortcut(&walls, path, 20, &mut rng, &mut PlanStats::default());
                assert_eq!((short[0], short[short.len() - 1]), (START, GOAL), "{name}");
                dense_check(&walls, &short).unwrap_or_else(|e| panic!("{name}, seed {seed}, shortcut: {e}"));
                assert!(
                    length(&short) <= before + 1e-12,
                    "{name}, seed {seed}: shortcut lengthened"
                );
                // Through the gap and round its corners: not much longer than the two straight legs.
                assert!(length(&short) < 1.2 * 2.0 * (0.5f64.powi(2) + 0.45f64.powi(2)).sqrt());
            }
        }
    }

    #[test]
    fn a_wall_without_a_gap_exhausts_the_budget() {
        let walls = Walls::across(None);
        for (name, path, samples) in both(&search(&walls, 2_000), 1) {
            assert!(path.is_none(), "{name} crossed a closed wall");
            assert_eq!(samples, 2_000, "{name}");
        }
    }

    #[test]
    fn the_dense_check_catches_a_path_through_a_wall() {
        let walls = Walls::across(Some((0.6, 0.7)));
        for (name, path, _) in both(&search(&AnyEdge, 20_000), 1) {
            let path = path.expect("any edge will do");
            assert!(dense_check(&walls, &path).is_err(), "{name}: {path:?}");
        }
    }

    #[test]
    fn a_seeded_search_is_repeatable() {
        let walls = Walls::across(Some((0.6, 0.7)));
        let s = search(&walls, 20_000);
        let [(_, a, _), (_, b, _)] = both(&s, 7);
        let [(_, c, _), (_, d, _)] = both(&s, 7);
        assert_eq!((a, b), (c, d));
    }

    #[test]
    fn the_joint_box_samples_within_limits_and_steers_by_the_largest_joint_motion() {
        let space = JointBox {
            lower_rad: Vector3::new(-1.0, 0.0, 2.0),
            upper_rad: Vector3::new(1.0, 0.5, 2.0),
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..100 {
            let q = space.sample(&mut rng);
            assert!(
                (0..3).all(|i| q[i] >= space.lower_rad[i] && q[i] <= space.upper_rad[i]),
                "{q:?}"
            );
        }
        let (a, b) = (Vector3::new(0.0, 0.0, 2.0), Vector3::new(1.0, 0.5, 2.0));
        let s = space.steer(&a, &b, 0.2);
        assert!((s - Vector3::new(0.2, 0.1, 2.0)).amax() < 1e-15);
        assert!((space.step_length(&a, &s) - 0.2).abs() < 1e-15);
        assert_eq!(space.steer(&a, &b, 1.0), b);
        assert!((space.distance_sq(&a, &b) - 1.25).abs() < 1e-15);
    }
}
