//! The cell's collision model for planning: the arm as spheres, the cell as boxes and pile columns.
//!
//! Job: answer "how far is the arm from touching anything at `q`?" with a lower bound, fast, and
//! from it whether a configuration is free and whether a straight joint-space edge is certified
//! free (conservative advancement) or checked at discrete steps (the baselines' test).
//!
//! Every link's primitives (and the hand, and a held part) are covered by spheres that contain
//! them, so a clearance computed on the spheres is a lower bound on the true clearance; each link
//! also has one bounding sphere for early rejection. The environment is boxes (table, trays,
//! obstacles) plus the pile as the sensor saw it: columns of a height map, never ground truth,
//! with the part to be grasped cut out around the grasp point, and what the sensor did not see
//! inside the tray occupied, never free ([`PileColumns`]). The link pairs of [`SELF_PAIRS`]
//! are checked against each other.
//!
//! Queries skip only what a bound proves no nearer than the best distance so far (per link, the
//! boxes and the pile its bounding sphere comes within reach of; self pairs by their bounding
//! spheres), so they return the same number as examining everything. With the clearance, a query
//! can also give how far each link reaches from each joint's axis ([`AxisReach`]), which the
//! edge certification ([`super::certify`]: conservative advancement) bounds the motion with.
//! `lever_m` keeps the configuration-independent bound per joint (the corridor checks use it).
//!
//! Units: m, rad. Frames: sphere centres in their link frame (the hand and a held part in the
//! flange link's frame), boxes by `world_from_box`, pile columns in the tray frame of the height
//! map; distances are computed in the world frame.

use nalgebra::{Isometry3, Point3, Vector3};

use super::axis_reach::AxisReach;
pub use super::pile_columns::PileColumns;
use super::search::PlanStats;
use crate::config::Scene;
use crate::geometry::NamedBox;
use crate::robot::{DOF, JointVector, LinkPrimitive, RobotModel};

/// A sphere (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Centre in its frame (m).
    pub center_m: Vector3<f64>,
    /// Radius (m).
    pub radius_m: f64,
}

/// Spheres covering a box of half extents `he` centred at the origin: along its longest axis.
fn cover_box(he: &Vector3<f64>) -> Vec<Sphere> {
    let a = he.iamax();
    let cross = Vector3::from_fn(|i, _| if i == a { 0.0 } else { he[i] }).norm();
    let n = ((he[a] / cross.max(1e-4)).ceil() as usize).clamp(1, 16);
    let half = he[a] / n as f64;
    (0..n)
        .map(|k| Sphere {
            center_m: Vector3::ith(a, -he[a] + (2 * k + 1) as f64 * half),
            radius_m: (cross * cross + half * half).sqrt(),
        })
        .collect()
}

/// Spheres covering a cylinder along z of radius `r` and half length `h`.
fn cover_cylinder(r: f64, h: f64) -> Vec<Sphere> {
    let n = ((h / r.max(1e-4)).ceil() as usize).clamp(1, 16);
    let half = h / n as f64;
    (0..n)
        .map(|k| Sphere {
            center_m: Vector3::z() * (-h + (2 * k + 1) as f64 * half),
            radius_m: (r * r + half * half).sqrt(),
        })
        .collect()
}

/// The robot as spheres per link (link 6 carries the hand and any held part).
#[derive(Debug, Clone)]
pub struct RobotSpheres {
    /// Spheres per link, in link frames.
    pub links: Vec<Vec<Sphere>>,
    /// One sphere per link enclosing all of its spheres.
    pub bounds: Vec<Sphere>,
    /// Upper bound on how far any robot point moves per radian of each joint [m/rad].
    pub lever_m: [f64; DOF],
    /// Per link k (base first) and joint j < k: upper bound on the distance of link k's sphere
    /// points from joint j's axis in every configuration (0 for j >= k) (m).
    pub chain_lever_m: Vec<[f64; DOF]>,
}

impl RobotSpheres {
    /// Covers the robot's links, the hand of `scene`, and a held part (a box of half extents
    /// `he` at `tool_from_part`), if any.
    pub fn new(robot: &RobotModel, scene: &Scene, held: Option<(Isometry3<f64>, Vector3<f64>)>) -> Self {
        let mut links: Vec<Vec<Sphere>> = Vec::new();
        for link in &robot.links {
            let mut v = Vec::new();
            for s in &link.shapes {
                let local = match s.primitive {
                    LinkPrimitive::Box { half_extents_m } => cover_box(&half_extents_m),
                    LinkPrimitive::Cylinder {
                        radius_m,
                        half_length_m,
                    }
                    | LinkPrimitive::Capsule {
                        radius_m,
                        half_length_m,
                    } => cover_cylinder(radius_m, half_length_m),
                    LinkPrimitive::Sphere { radius_m } => vec![Sphere {
                        center_m: Vector3::zeros(),
                        radius_m,
                    }],
                };
                v.extend(local.into_iter().map(|sp| Sphere {
                    center_m: (s.link_from_shape * Point3::from(sp.center_m)).coords,
                    radius_m: sp.radius_m,
                }));
            }
            links.push(v);
        }
        // The hand: body cylinder from the flange, cup to the tool frame (as in the physics).
        let flange = links.len() - 1;
        for (r, z0, z1) in crate::geometry::HandGeometry::new(&scene.gripper).cylinders() {
            links[flange].extend(cover_cylinder(r, (z1 - z0) / 2.0).into_iter().map(|s| Sphere {
                center_m: s.center_m + Vector3::z() * (z0 + z1) / 2.0,
                radius_m: s.radius_m,
            }));
        }
        if let Some((tool_from_part, he)) = held {
            let flange_from_part = robot.flange_from_tool * tool_from_part;
            links[flange].extend(cover_box(&he).into_iter().map(|s| Sphere {
                center_m: (flange_from_part * Point3::from(s.center_m)).coords,
                radius_m: s.radius_m,
            }));
        }
        let bounds: Vec<Sphere> = links
            .iter()
            .map(|v| {
                if v.is_empty() {
                    return Sphere {
                        center_m: Vector3::zeros(),
                        radius_m: 0.0,
                    };
                }
                let c = v.iter().map(|s| s.center_m).sum::<Vector3<f64>>() / v.len() as f64;
                let r = v
                    .iter()
                    .map(|s| (s.center_m - c).norm() + s.radius_m)
                    .fold(0.0, f64::max);
                Sphere {
                    center_m: c,
                    radius_m: r,
                }
            })
            .collect();
        // Lever bound for joint i: the chain's origin offsets beyond it plus the farthest sphere
        // point from its own link origin (triangle inequality, valid in every configuration).
        let mut lever_m = [0.0; DOF];
        for (i, lever) in lever_m.iter_mut().enumerate() {
            let chain: f64 = robot.joints[(i + 1)..].iter().map(|j| j.origin_pos_m.norm()).sum();
            let reach = links[(i + 1)..]
                .iter()
                .flatten()
                .map(|s| s.center_m.norm() + s.radius_m)
                .fold(0.0, f64::max);
            *lever = chain + reach;
        }
        // Joint j's axis passes through link j + 1's origin; link k's origin is the chain of
        // joint origins j + 1 .. k - 1 away from it; its sphere points at most `far` from that.
        let chain_lever_m = links
            .iter()
            .enumerate()
            .map(|(k, spheres)| {
                let far = spheres
                    .iter()
                    .map(|s| s.center_m.norm() + s.radius_m)
                    .fold(0.0, f64::max);
                std::array::from_fn(|j| {
                    if j < k {
                        robot.joints[(j + 1)..k]
                            .iter()
                            .map(|jt| jt.origin_pos_m.norm())
                            .sum::<f64>()
                            + far
                    } else {
                        0.0
                    }
                })
            })
            .collect();
        RobotSpheres {
            links,
            bounds,
            lever_m,
            chain_lever_m,
        }
    }

    /// The spheres with the robot at `q`: for point queries ([`SpheresAt::cover`]).
    pub fn at(&self, robot: &RobotModel, q: &JointVector) -> SpheresAt<'_> {
        let base_from_links = robot.base_from_links(q);
        SpheresAt {
            spheres: self,
            link_from_world: (0..self.links.len())
                .map(|li| (robot.world_from_base * base_from_links[li].to_isometry()).inverse())
                .collect(),
        }
    }
}

/// [`RobotSpheres`] with the robot at one configuration.
pub struct SpheresAt<'a> {
    spheres: &'a RobotSpheres,
    /// `link_from_world` per link.
    link_from_world: Vec<Isometry3<f64>>,
}

impl SpheresAt<'_> {
    /// Whether the world point `p` lies within `margin_m` of a sphere (a link, the hand or the
    /// held part): a point on the robot as the controller models it. Each link's bounding sphere
    /// is tried first.
    pub fn cover(&self, p: &Point3<f64>, margin_m: f64) -> bool {
        let s = self.spheres;
        s.links
            .iter()
            .zip(&s.bounds)
            .zip(&self.link_from_world)
            .any(|((spheres, bound), link_from_world)| {
                let local = (link_from_world * p).coords;
                let near = |sp: &Sphere| (local - sp.center_m).norm() <= sp.radius_m + margin_m;
                near(bound) && spheres.iter().any(near)
            })
    }
}

/// Signed distance from a point to a box (negative inside) (m): the plain formula, the reference
/// [`box_distance_below`] is tested against.
#[cfg(test)]
fn point_box_distance(p_world: &Vector3<f64>, b: &NamedBox) -> f64 {
    let l = b.world_from_box.inverse_transform_point(&Point3::from(*p_world)).coords;
    let q = l.abs() - b.half_m;
    let outside = q.sup(&Vector3::zeros()).norm();
    outside + q.max().min(0.0)
}

/// Everything the robot must not touch.
#[derive(Debug, Clone)]
pub struct Environment {
    /// Boxes: table, trays, obstacles, case obstacles.
    pub boxes: Vec<NamedBox>,
    /// The pile, if any.
    pub pile: Option<PileColumns>,
}

impl Environment {
    /// The cell's fixed geometry: table, both trays, obstacles.
    pub fn from_scene(scene: &Scene) -> Self {
        let boxes = crate::geometry::cell_boxes(scene).into_iter().map(|(_, b)| b).collect();
        Environment { boxes, pile: None }
    }

    /// The environment near a link's bounding sphere (world centre `c`, radius `r`) given the best
    /// clearance so far `best` (m): whether anything is nearer than `best` (the link's spheres must
    /// then be examined), and which boxes, and whether the pile, could be nearer than `best` to any
    /// sphere inside the bounding sphere (the others cannot: a sphere inside it is no nearer to
    /// anything than the bounding sphere is, up to [`BOUND_SLACK_M`]).
    fn near_link(&self, c: &Vector3<f64>, r: f64, best: f64) -> NearLink {
        let thr = best + BOUND_SLACK_M;
        let mut near = NearLink {
            open: false,
            boxes: 0,
            all_boxes: self.boxes.len() > 64,
            pile: false,
        };
        for (k, b) in self.boxes.iter().enumerate() {
            if let Some(d) = box_distance_below(c, r, b, thr) {
                near.open |= d < best;
                if k < 64 {
                    near.boxes |= 1 << k;
                }
            }
        }
        if let Some(p) = &self.pile
            && let Some(d) = p.sphere_distance(c, r, thr)
        {
            near.open |= d < best;
            near.pile = true;
        }
        near
    }
}

/// Slack on lower bounds (m): far above the rounding of distances of a few metres, far below
/// anything the planner resolves. Work is skipped only when a bound exceeds the best distance by
/// this much, so rounding never skips a distance that would have been the nearest.
const BOUND_SLACK_M: f64 = 1e-9;

/// What of the environment is near a link ([`Environment::near_link`]).
#[derive(Debug, Clone, Copy)]
struct NearLink {
    /// Something is nearer than the best so far: examine the link's spheres.
    open: bool,
    /// Bit k: box k may be nearer than the best so far.
    boxes: u64,
    /// More than 64 boxes: examine them all.
    all_boxes: bool,
    /// The pile may be nearer than the best so far.
    pile: bool,
}

impl NearLink {
    fn box_near(&self, k: usize) -> bool {
        self.all_boxes || (k < 64 && self.boxes & (1 << k) != 0)
    }
}

/// [`point_box_distance`] minus `r`, the same number, when it may be below `thr`; `None` when it
/// surely is not (by [`BOUND_SLACK_M`]): the sphere is beyond the ball around the box by `thr`
/// (no rotation, no square root), or outside the box by more than `thr + r` (no square root).
/// A box that is not turned is not rotated into (the same numbers: the identity leaves them).
#[inline]
fn box_distance_below(p_world: &Vector3<f64>, r: f64, b: &NamedBox, thr: f64) -> Option<f64> {
    let t = thr + r + BOUND_SLACK_M;
    let rel = p_world - b.world_from_box.translation.vector;
    // The box lies within |he| <= |he|_1 of its centre.
    let ball = t + b.half_m.x + b.half_m.y + b.half_m.z;
    if ball <= 0.0 || rel.norm_squared() >= ball * ball {
        return None;
    }
    let rot = &b.world_from_box.rotation;
    let l = if (rot.w, rot.i, rot.j, rot.k) == (1.0, 0.0, 0.0, 0.0) {
        rel
    } else {
        rot.inverse_transform_vector(&rel)
    };
    let q = l.abs() - b.half_m;
    let o = q.sup(&Vector3::zeros());
    let o2 = o.x * o.x + o.y * o.y + o.z * o.z;
    if o2 > 0.0 && (t <= 0.0 || o2 >= t * t) {
        return None;
    }
    Some(o.norm() + q.max().min(0.0) - r)
}

/// What is nearest to the arm at a clearance query (named by [`CollisionModel::describe`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Nearest {
    /// Nothing within the horizon.
    Nothing,
    /// Link `link` of the robot and the environment's box `k` (`Environment::boxes[k]`).
    Box {
        /// Index of the robot's link.
        link: usize,
        /// Index of the box.
        k: usize,
    },
    /// Link `link` of the robot and the pile.
    Pile {
        /// Index of the robot's link.
        link: usize,
    },
    /// Two links of the robot (a pair of [`SELF_PAIRS`]).
    Links(usize, usize),
}

/// The arm posed at one configuration ([`CollisionModel::nearest`]'s first step).
struct Posed {
    /// `world_from_link` per link, base first.
    world_from_links: [Isometry3<f64>; DOF + 1],
    /// Centres of the links' bounding spheres in the world.
    bound_centers: [Vector3<f64>; DOF + 1],
    /// Link `li`'s sphere centres are `centers[first[li]..first[li + 1]]`.
    first: [usize; DOF + 2],
}

/// What the edge certification needs at one configuration ([`CollisionModel::probe`]).
#[derive(Debug, Clone, Copy)]
pub struct Probe {
    /// Clearance to the environment, capped at the horizon (m), and what is nearest.
    pub env: (f64, Nearest),
    /// Clearance of each pair of [`SELF_PAIRS`], capped at the horizon (m).
    pub pairs_m: [f64; SELF_PAIRS.len()],
    /// How far each link reaches from each joint's axis.
    pub reach: AxisReach,
}

impl Probe {
    /// The clearance and what is nearest, as [`CollisionModel::nearest`] gives them.
    pub fn nearest(&self) -> (f64, Nearest) {
        let mut best = self.env;
        for (&d, &(a, b)) in self.pairs_m.iter().zip(&SELF_PAIRS) {
            if d < best.0 {
                best = (d, Nearest::Links(a, b));
            }
        }
        best
    }
}

/// Sphere centres kept on the stack in [`CollisionModel::nearest`] (more go to the heap).
const STACK_SPHERES: usize = 128;

/// Link pairs checked for self-collision: every pair that can meet over the joint ranges, on the
/// exact shapes (URDF primitives; link 6 with the flange, the hand, and the envelope of any
/// shipped workpiece held on any face the cup can grasp), derived by
/// `cargo run --release --example derive_self_pairs`: a branch and bound over the joints between
/// the two links with a Lipschitz bound on the exact distance (parry), which either finds the
/// shapes intersecting, or within 0.2 mm, or proves them apart over the whole range.
///
/// Can meet (exact shapes, example configuration): base-link3 (J2 -181, J3 10 deg),
/// base-link4/5/6, link1-link3 (J2 -156, J3 -7), link1-link4/5, link1-link6 (within 0.2 mm),
/// link2-link6, link4-link6 (the flange clips link 4's casing beyond J5 ~110 deg).
/// Proved apart: base-link2 (62.8 mm at least), link2-link4 (35.4), link2-link5 (44.5),
/// link3-link5 (147.0), link3-link6 (133.4; 62.3 with a held part: J5's +-120 deg keeps the hand
/// off the forearm), link5 with the hand and a held part, its flange excluded (15.0). Adjacent
/// links share a joint housing and are not checked.
pub const SELF_PAIRS: [(usize, usize); 10] = [
    (0, 3),
    (0, 4),
    (0, 5),
    (0, 6),
    (1, 3),
    (1, 4),
    (1, 5),
    (1, 6),
    (2, 6),
    (4, 6),
];

/// The planning scene: robot spheres plus environment, and the queries on them.
#[derive(Debug, Clone)]
pub struct CollisionModel {
    /// The arm.
    pub robot: RobotModel,
    /// Its spheres.
    pub spheres: RobotSpheres,
    /// The environment.
    pub env: Environment,
    /// Required clearance (m): configurations closer than this count as colliding.
    pub margin_m: f64,
    /// Distances beyond this are not resolved further (m).
    pub horizon_m: f64,
}

impl CollisionModel {
    /// A model with a 2 mm margin and a 10 cm horizon.
    pub fn new(robot: &RobotModel, spheres: RobotSpheres, env: Environment) -> Self {
        CollisionModel {
            robot: robot.clone(),
            spheres,
            env,
            margin_m: 0.002,
            horizon_m: 0.10,
        }
    }

    /// Lower bound on the robot's clearance at `q` (environment and self) (m), capped at the
    /// horizon, and what is nearest, unnamed: the hot path of [`CollisionModel::free`] and the
    /// edge checks, which never need the name ([`CollisionModel::describe`] gives it).
    pub fn nearest(&self, q: &JointVector, stats: &mut PlanStats) -> (f64, Nearest) {
        stats.clearance_checks += 1;
        self.nearest_inner(q)
    }

    /// What the edge certification needs at `q` ([`Probe`]): the clearance to the environment,
    /// of each self pair, and how far each link reaches from each joint's axis.
    pub fn probe(&self, q: &JointVector, stats: &mut PlanStats) -> Probe {
        stats.clearance_checks += 1;
        self.posed(q, |posed, centers| {
            let env = self.nearest_env(posed, centers, (self.horizon_m, Nearest::Nothing));
            let mut reach = AxisReach::zero();
            self.axis_reach(posed, centers, &mut reach);
            let pairs_m = std::array::from_fn(|p| self.pair_distance(posed, centers, p));
            Probe { env, pairs_m, reach }
        })
    }

    fn nearest_inner(&self, q: &JointVector) -> (f64, Nearest) {
        self.posed(q, |posed, centers| {
            let best = self.nearest_env(posed, centers, (self.horizon_m, Nearest::Nothing));
            self.nearest_self(posed, centers, best)
        })
    }

    /// `f` of the arm posed at `q` ([`CollisionModel::pose`]), the sphere centres on the stack
    /// when they fit in [`STACK_SPHERES`] (every clearance query poses the arm once).
    fn posed<T>(&self, q: &JointVector, f: impl FnOnce(&Posed, &[Vector3<f64>]) -> T) -> T {
        let total: usize = self.spheres.links.iter().map(Vec::len).sum();
        let mut on_stack = [Vector3::zeros(); STACK_SPHERES];
        let mut on_heap = Vec::new();
        let centers: &mut [Vector3<f64>] = if total <= STACK_SPHERES {
            &mut on_stack[..total]
        } else {
            on_heap.resize(total, Vector3::zeros());
            &mut on_heap
        };
        let posed = self.pose(q, centers);
        f(&posed, centers)
    }

    /// The link frames, sphere centres (into `centers`, link after link) and bounding-sphere
    /// centres at `q`, in the world.
    fn pose(&self, q: &JointVector, centers: &mut [Vector3<f64>]) -> Posed {
        let base_from_links = self.robot.base_from_links(q);
        let base = self.robot.world_from_base;
        let mut posed = Posed {
            world_from_links: [Isometry3::identity(); DOF + 1],
            bound_centers: [Vector3::zeros(); DOF + 1],
            first: [0; DOF + 2],
        };
        for (li, spheres) in self.spheres.links.iter().enumerate() {
            let world_from_link = base * base_from_links[li].to_isometry();
            posed.world_from_links[li] = world_from_link;
            posed.first[li + 1] = posed.first[li] + spheres.len();
            for (c, s) in centers[posed.first[li]..posed.first[li + 1]].iter_mut().zip(spheres) {
                *c = (world_from_link * Point3::from(s.center_m)).coords;
            }
            posed.bound_centers[li] = (world_from_link * Point3::from(self.spheres.bounds[li].center_m)).coords;
        }
        posed
    }

    /// The nearest of the environment to the links' spheres, if nearer than `best`.
    fn nearest_env(&self, posed: &Posed, centers: &[Vector3<f64>], mut best: (f64, Nearest)) -> (f64, Nearest) {
        // The base stands on the table: it is not checked against the environment.
        for (li, spheres) in self.spheres.links.iter().enumerate().skip(1) {
            let near = self
                .env
                .near_link(&posed.bound_centers[li], self.spheres.bounds[li].radius_m, best.0);
            if !near.open {
                continue;
            }
            for (p, s) in centers[posed.first[li]..posed.first[li + 1]].iter().zip(spheres) {
                for (k, bx) in self.env.boxes.iter().enumerate() {
                    if near.box_near(k)
                        && let Some(d) = box_distance_below(p, s.radius_m, bx, best.0)
                        && d < best.0
                    {
                        best = (d, Nearest::Box { link: li, k });
                    }
                }
                if near.pile
                    && let Some(pile) = &self.env.pile
                    && let Some(d) = pile.sphere_distance(p, s.radius_m, best.0)
                {
                    best = (d, Nearest::Pile { link: li });
                }
            }
        }
        best
    }

    /// How far each link's spheres reach from each joint's axis.
    fn axis_reach(&self, posed: &Posed, centers: &[Vector3<f64>], reach: &mut AxisReach) {
        // Joint i turns about its axis through link i + 1's origin.
        let axes: [(Vector3<f64>, Vector3<f64>); DOF] = std::array::from_fn(|i| {
            let f = &posed.world_from_links[i + 1];
            (f.translation.vector, f.rotation * self.robot.joints[i].axis)
        });
        for (k, spheres) in self.spheres.links.iter().enumerate().skip(1) {
            let row = &mut reach.reach_m[k];
            for (c, s) in centers[posed.first[k]..posed.first[k + 1]].iter().zip(spheres) {
                for (i, (o, w)) in axes.iter().enumerate().take(k) {
                    row[i] = row[i].max((c - o).cross(w).norm() + s.radius_m);
                }
            }
        }
    }

    /// The clearance of the `p`-th pair of [`SELF_PAIRS`], capped at the horizon (m).
    fn pair_distance(&self, posed: &Posed, centers: &[Vector3<f64>], p: usize) -> f64 {
        let (links, bounds, first) = (&self.spheres.links, &self.spheres.bounds, &posed.first);
        let (a, b) = SELF_PAIRS[p];
        let mut best = self.horizon_m;
        let (ba, bb) = (&bounds[a], &bounds[b]);
        let cb = &posed.bound_centers[b];
        if (posed.bound_centers[a] - cb).norm() - ba.radius_m - bb.radius_m >= best + BOUND_SLACK_M {
            return best;
        }
        for (pa, sa) in centers[first[a]..first[a + 1]].iter().zip(&links[a]) {
            if (pa - cb).norm() - sa.radius_m - bb.radius_m >= best + BOUND_SLACK_M {
                continue;
            }
            for (pb, sb) in centers[first[b]..first[b + 1]].iter().zip(&links[b]) {
                let t = best + sa.radius_m + sb.radius_m + BOUND_SLACK_M;
                let dd = (pa - pb).norm_squared();
                if t <= 0.0 || dd >= t * t {
                    continue;
                }
                let d = (pa - pb).norm() - sa.radius_m - sb.radius_m;
                if d < best {
                    best = d;
                }
            }
        }
        best
    }

    /// The nearest self pair, if nearer than `best`.
    fn nearest_self(&self, posed: &Posed, centers: &[Vector3<f64>], mut best: (f64, Nearest)) -> (f64, Nearest) {
        let (links, bounds, first) = (&self.spheres.links, &self.spheres.bounds, &posed.first);
        for (a, b) in SELF_PAIRS {
            // Bounding spheres first: a pair, or a sphere of `a`, no nearer than the best is skipped.
            let (ba, bb) = (&bounds[a], &bounds[b]);
            let cb = &posed.bound_centers[b];
            if (posed.bound_centers[a] - cb).norm() - ba.radius_m - bb.radius_m >= best.0 + BOUND_SLACK_M {
                continue;
            }
            for (pa, sa) in centers[first[a]..first[a + 1]].iter().zip(&links[a]) {
                if (pa - cb).norm() - sa.radius_m - bb.radius_m >= best.0 + BOUND_SLACK_M {
                    continue;
                }
                for (pb, sb) in centers[first[b]..first[b + 1]].iter().zip(&links[b]) {
                    let t = best.0 + sa.radius_m + sb.radius_m + BOUND_SLACK_M;
                    let dd = (pa - pb).norm_squared();
                    if t <= 0.0 || dd >= t * t {
                        continue;
                    }
                    let d = (pa - pb).norm() - sa.radius_m - sb.radius_m;
                    if d < best.0 {
                        best = (d, Nearest::Links(a, b));
                    }
                }
            }
        }
        best
    }

    /// What `nearest` names, as `"{link} and {what}"` (empty for [`Nearest::Nothing`]).
    pub fn describe(&self, nearest: Nearest) -> String {
        let link = |li: usize| &self.robot.links[li].name;
        match nearest {
            Nearest::Nothing => String::new(),
            Nearest::Box { link: li, k } => format!("{} and {}", link(li), self.env.boxes[k].name),
            Nearest::Pile { link: li } => format!("{} and the pile", link(li)),
            Nearest::Links(a, b) => format!("{} and {}", link(a), link(b)),
        }
    }

    /// Whether `q` is within limits and clear by the margin.
    pub fn free(&self, q: &JointVector, stats: &mut PlanStats) -> bool {
        self.robot.within_limits(q, 0.0) && self.nearest(q, stats).0 > self.margin_m
    }

    /// The baseline's edge check: configurations every `step_rad` (max-norm), not certified.
    pub fn discrete_edge(&self, a: &JointVector, b: &JointVector, step_rad: f64, stats: &mut PlanStats) -> bool {
        stats.edges += 1;
        let n = ((b - a).amax() / step_rad).ceil().max(1.0) as usize;
        (0..=n).all(|k| self.free(&(a + (b - a) * (k as f64 / n as f64)), stats))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covering_spheres_contain_the_box_corners() {
        let he = Vector3::new(0.135, 0.03, 0.05);
        let s = cover_box(&he);
        for sx in [-1.0, 1.0] {
            for sy in [-1.0, 1.0] {
                for sz in [-1.0, 1.0] {
                    let p = Vector3::new(sx * he.x, sy * he.y, sz * he.z);
                    assert!(
                        s.iter().any(|sp| (p - sp.center_m).norm() <= sp.radius_m + 1e-12),
                        "corner {p:?} uncovered"
                    );
                }
            }
        }
        let c = cover_cylinder(0.015, 0.055);
        for z in [-0.055, 0.055] {
            let p = Vector3::new(0.015, 0.0, z);
            assert!(c.iter().any(|sp| (p - sp.center_m).norm() <= sp.radius_m + 1e-12));
        }
    }

    /// The pruned box distance gives the plain formula's number bit for bit whenever it may be
    /// below the threshold, and declines only when the plain number is not below it. The negative
    /// control: a prefilter that forgets the sphere's radius declines distances below the
    /// threshold, which the check catches.
    #[test]
    fn box_distance_below_is_the_plain_distance_or_surely_not_below() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let turned = NamedBox {
            name: "turned".into(),
            world_from_box: Isometry3::new(Vector3::new(0.3, -0.2, 0.1), Vector3::new(0.2, -0.4, 1.1)),
            half_m: Vector3::new(0.1, 0.02, 0.05),
        };
        let straight = NamedBox {
            name: "straight".into(),
            world_from_box: Isometry3::translation(0.3, -0.2, 0.1),
            half_m: Vector3::new(0.1, 0.02, 0.0),
        };
        let (mut given, mut declined, mut missed) = (0, 0, 0);
        for k in 0..40_000 {
            let b = if k % 2 == 0 { &turned } else { &straight };
            let p = Vector3::new(0.3, -0.2, 0.1) + Vector3::from_fn(|_, _| rng.random_range(-0.2..0.2));
            let r = rng.random_range(0.0..0.08);
            let thr = rng.random_range(-0.05..0.2);
            let plain = point_box_distance(&p, b) - r;
            match box_distance_below(&p, r, b, thr) {
                Some(d) => {
                    assert_eq!(d.to_bits(), plain.to_bits(), "{p:?} {r} {thr}");
                    given += 1;
                }
                None => {
                    assert!(plain >= thr, "{p:?} {r} {thr}: {plain} declined");
                    declined += 1;
                }
            }
            // A prefilter that forgets the radius (declines when the centre is thr outside).
            if box_distance_below(&p, 0.0, b, thr).is_none() && plain < thr {
                missed += 1;
            }
        }
        assert!(given > 4000 && declined > 4000, "{given} given, {declined} declined");
        assert!(
            missed > 100,
            "the control: forgetting the radius must decline distances below: {missed}"
        );
    }

    #[test]
    fn point_box_distance_signs() {
        let b = NamedBox {
            name: "b".into(),
            world_from_box: Isometry3::identity(),
            half_m: Vector3::new(1.0, 1.0, 1.0),
        };
        assert!((point_box_distance(&Vector3::new(2.0, 0.0, 0.0), &b) - 1.0).abs() < 1e-12);
        assert!((point_box_distance(&Vector3::new(0.5, 0.0, 0.0), &b) + 0.5).abs() < 1e-12);
        assert!((point_box_distance(&Vector3::new(2.0, 2.0, 1.0), &b) - 2f64.sqrt()).abs() < 1e-12);
    }
}
