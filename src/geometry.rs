//! Cell geometry: the one description of the cell's solid shapes and of the suction cup's force
//! model, from the cell file.
//!
//! Job: turn the cell file's table, trays, obstacles and gripper into named boxes, the hand's two
//! cylinders and the cup's holding-force model, once. The physics world builds its colliders from
//! them, the planner its obstacles and the hand's spheres, the overlap check its tray pieces, the
//! grasp selector its cup length, the recordings their cell boxes and the benchmarks their scenes,
//! so none of these can drift apart. Also the plane's convex hull and the distance outside it,
//! which the sensor's silhouette fits and the grasp selector's part outlines share.
//!
//! Units: m, N, kg, m/s^2. Frames: each box is placed in a frame (the world for the table, the
//! tray frame for tray pieces, the obstacle's own yawed frame) at a centre in that frame, and
//! kept as `world_from_box`; the hand's cylinders lie along the flange z axis, from the flange face (z = 0) to
//! the tool frame at the cup lip (z = `tool_length_m`).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::config::{GripperConfig, Scene, TrayConfig};

/// A named solid box of the cell (and of the planner's scenes: a placed part, a test's obstacle).
#[derive(Debug, Clone, PartialEq)]
pub struct NamedBox {
    /// What it is (`table`, `pick tray wall +x`, `obstacle "sensor post"`, ...).
    pub name: String,
    /// `world_from_box`: the box's own frame (its centre, its axes).
    pub world_from_box: Isometry3<f64>,
    /// Half extents along the box's axes (m).
    pub half_m: Vector3<f64>,
}

impl NamedBox {
    /// The box centred at `center_m` in a frame placed at `world_from_frame`, with the frame's axes.
    pub fn in_frame(
        name: String,
        world_from_frame: &Isometry3<f64>,
        center_m: &Vector3<f64>,
        half_m: Vector3<f64>,
    ) -> Self {
        NamedBox {
            name,
            world_from_box: world_from_frame * Isometry3::translation(center_m.x, center_m.y, center_m.z),
            half_m,
        }
    }
}

/// Which part of the cell a box belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoxRole {
    /// The table top.
    Table,
    /// A piece of the pick tray (floor or wall).
    PickTray,
    /// A piece of the place tray.
    PlaceTray,
    /// An obstacle from the cell file.
    Obstacle,
}

/// The table top as a box.
pub fn table_box(scene: &Scene) -> NamedBox {
    let t = &scene.table;
    NamedBox::in_frame(
        "table".into(),
        &Isometry3::identity(),
        &Vector3::new(t.center_xy_m[0], t.center_xy_m[1], t.top_z_m - t.thickness_m / 2.0),
        Vector3::new(t.size_m[0] / 2.0, t.size_m[1] / 2.0, t.thickness_m / 2.0),
    )
}

/// Names of a tray's pieces, in the order [`tray_boxes`] returns them.
pub const TRAY_PIECES: [&str; 5] = ["floor", "wall +x", "wall -x", "wall +y", "wall -y"];

/// A tray's floor and four walls in the tray frame (origin at the centre of the inner floor
/// surface), in [`TRAY_PIECES`] order: (centre, half extents) (m). The floor reaches under the
/// walls; the x walls span the whole outer length, the y walls fit between them.
pub fn tray_pieces_m(t: &TrayConfig) -> [(Vector3<f64>, Vector3<f64>); 5] {
    let [lx, ly] = t.inner_size_m;
    let (w, h, f) = (t.wall_thickness_m, t.wall_height_m, t.floor_thickness_m);
    let zc = (h - f) / 2.0;
    let hz = (h + f) / 2.0;
    [
        (
            Vector3::new(0.0, 0.0, -f / 2.0),
            Vector3::new(lx / 2.0 + w, ly / 2.0 + w, f / 2.0),
        ),
        (
            Vector3::new(lx / 2.0 + w / 2.0, 0.0, zc),
            Vector3::new(w / 2.0, ly / 2.0 + w, hz),
        ),
        (
            Vector3::new(-lx / 2.0 - w / 2.0, 0.0, zc),
            Vector3::new(w / 2.0, ly / 2.0 + w, hz),
        ),
        (
            Vector3::new(0.0, ly / 2.0 + w / 2.0, zc),
            Vector3::new(lx / 2.0, w / 2.0, hz),
        ),
        (
            Vector3::new(0.0, -ly / 2.0 - w / 2.0, zc),
            Vector3::new(lx / 2.0, w / 2.0, hz),
        ),
    ]
}

/// A tray's floor and four walls ([`tray_pieces_m`]) in the world, named `"{name} floor"`,
/// `"{name} wall +x"`, ...
pub fn tray_boxes(name: &str, t: &TrayConfig) -> Vec<NamedBox> {
    let world_from_tray = t.world_from_tray();
    tray_pieces_m(t)
        .into_iter()
        .zip(TRAY_PIECES)
        .map(|((center_m, half_m), piece)| {
            NamedBox::in_frame(format!("{name} {piece}"), &world_from_tray, &center_m, half_m)
        })
        .collect()
}

/// The cell file's obstacles as boxes, named as in the file.
pub fn obstacle_boxes(scene: &Scene) -> Vec<NamedBox> {
    scene
        .obstacles
        .iter()
        .map(|o| {
            NamedBox::in_frame(
                o.name.clone(),
                &Isometry3::from_parts(
                    Translation3::new(o.center_m[0], o.center_m[1], o.center_m[2]),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, o.yaw_deg.to_radians()),
                ),
                &Vector3::zeros(),
                Vector3::from(o.size_m) / 2.0,
            )
        })
        .collect()
}

/// Every fixed box of the cell with its role, in a fixed order: the table, the pick tray's five
/// pieces, the place tray's five pieces, the obstacles in file order.
pub fn cell_boxes(scene: &Scene) -> Vec<(BoxRole, NamedBox)> {
    let mut out = vec![(BoxRole::Table, table_box(scene))];
    out.extend(
        tray_boxes("pick tray", &scene.pick_tray)
            .into_iter()
            .map(|b| (BoxRole::PickTray, b)),
    );
    out.extend(
        tray_boxes("place tray", &scene.place_tray.tray)
            .into_iter()
            .map(|b| (BoxRole::PlaceTray, b)),
    );
    out.extend(obstacle_boxes(scene).into_iter().map(|b| (BoxRole::Obstacle, b)));
    out
}

/// A tray's volume in the world: its footprint (walls included), from just below the floor up
/// to 1 m; a part of the tray's belongs inside it.
#[derive(Debug, Clone, Copy)]
pub struct TrayVolume {
    /// `world_from_tray`.
    pub world_from_tray: Isometry3<f64>,
    /// Half the inner size plus the wall thickness (m).
    pub half_xy_m: [f64; 2],
    /// Wall height above the inner floor (m).
    pub wall_height_m: f64,
    /// Wall thickness (m).
    pub wall_thickness_m: f64,
}

impl TrayVolume {
    /// The volume of a tray of the cell file.
    pub fn new(t: &TrayConfig) -> Self {
        TrayVolume {
            world_from_tray: t.world_from_tray(),
            half_xy_m: [
                t.inner_size_m[0] / 2.0 + t.wall_thickness_m,
                t.inner_size_m[1] / 2.0 + t.wall_thickness_m,
            ],
            wall_height_m: t.wall_height_m,
            wall_thickness_m: t.wall_thickness_m,
        }
    }

    /// The tray's volume grown by `m` beyond its outer walls and above its rim: where a part
    /// lying across the rim can reach.
    pub fn grown_by(&self, m: f64) -> TrayVolume {
        TrayVolume {
            half_xy_m: [self.half_xy_m[0] + m, self.half_xy_m[1] + m],
            wall_height_m: self.wall_height_m + m,
            ..*self
        }
    }

    /// Whether a world point is in the tray's column (footprint incl. walls, floor - 2 mm to 1 m).
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        let l = self.world_from_tray.inverse_transform_point(&(*p).into());
        l.x.abs() <= self.half_xy_m[0] && l.y.abs() <= self.half_xy_m[1] && l.z >= -0.002 && l.z <= 1.0
    }

    /// Whether a world point is inside the tray's inner walls, below the rim.
    pub fn inside_inner(&self, p: &Vector3<f64>) -> bool {
        let l = self.world_from_tray.inverse_transform_point(&(*p).into());
        l.x.abs() <= self.half_xy_m[0] - self.wall_thickness_m
            && l.y.abs() <= self.half_xy_m[1] - self.wall_thickness_m
            && l.z >= -0.001
            && l.z <= self.wall_height_m
    }

    /// The outer rim's corners at floor level (world): with a camera's optical centre, the
    /// corners of the view frustum over the tray, which the arm must be out of while the sensor
    /// exposes and outside which recognition sees nothing of the pile.
    pub fn rim_corners_at_floor(&self) -> [Point3<f64>; 4] {
        let [hx, hy] = self.half_xy_m;
        [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .map(|(sx, sy)| self.world_from_tray * Point3::new(sx * hx, sy * hy, 0.0))
    }

    /// Whether the point `p_tray` (tray frame) lies inside the view frustum from `eye_tray` (the
    /// camera's optical centre, tray frame, above the floor): below the eye, with its ray from the
    /// eye meeting the floor plane inside the outer rim ([`Self::rim_corners_at_floor`]).
    pub fn frustum_holds(&self, eye_tray: &Point3<f64>, p_tray: &Point3<f64>) -> bool {
        let s = eye_tray.z / (eye_tray.z - p_tray.z);
        p_tray.z < eye_tray.z
            && (eye_tray.x + (p_tray.x - eye_tray.x) * s).abs() < self.half_xy_m[0]
            && (eye_tray.y + (p_tray.y - eye_tray.y) * s).abs() < self.half_xy_m[1]
    }
}

/// The suction hand's solid shape: a body cylinder from the flange face, then the cup, both
/// along the flange z axis, ending at the tool frame (the cup lip).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandGeometry {
    /// Flange face to cup lip (m).
    pub tool_length_m: f64,
    /// Radius of the body cylinder (m).
    pub body_radius_m: f64,
    /// Length of the body cylinder, from the flange face (m).
    pub body_length_m: f64,
    /// Radius of the cup (m).
    pub cup_radius_m: f64,
    /// Length of the cup, ending at the lip (m).
    pub cup_length_m: f64,
}

impl HandGeometry {
    /// The hand of a cell file. The cup is one and a half cup diameters long (a bellows cup),
    /// but at most half the tool.
    pub fn new(g: &GripperConfig) -> Self {
        let cup_length_m = (1.5 * g.cup_diameter_m).min(g.tool_length_m / 2.0);
        HandGeometry {
            tool_length_m: g.tool_length_m,
            body_radius_m: g.body_diameter_m / 2.0,
            body_length_m: g.tool_length_m - cup_length_m,
            cup_radius_m: g.cup_diameter_m / 2.0,
            cup_length_m,
        }
    }

    /// The two cylinders as (radius, z from, z to) along the flange z axis (m): body, then cup.
    pub fn cylinders(&self) -> [(f64, f64, f64); 2] {
        [
            (self.body_radius_m, 0.0, self.body_length_m),
            (self.cup_radius_m, self.body_length_m, self.tool_length_m),
        ]
    }
}

/// The cup's holding-force model (simplified, stated in docs/model.md, "Physics"): a full seal holds
/// vacuum x cup area. The force F the cup must exert on a part of mass m, m (a - g) with a the
/// tool's acceleration, is taken in the tool frame and split as the suction makers' load cases
/// split it (e.g. Schmalz's: m (g + a / mu) for a horizontal cup moved sideways): its pull toward
/// the cup counts in full, its shear across the lip over the lip's friction coefficient mu
/// (`gripper.lip_friction`), and its moment about the cup centre across the axis (the centre of
/// mass off the axis, or below the lip with the load sideways) peels the lip as 4 |M| / d (d the
/// cup diameter). Straight down and held still, that is m g (1 + 4 e / d), e the centre of mass's
/// offset from the axis. A load other bodies put on the part adds its force and 4 / d times its
/// moment about the cup centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SuctionModel {
    /// Cup lip radius (m).
    pub cup_radius_m: f64,
    /// Holding force of a full seal (N).
    pub holding_n: f64,
    /// Friction coefficient of the lip on the part: shear it holds per newton of holding force.
    pub lip_friction: f64,
}

impl SuctionModel {
    /// The cup of a cell file.
    pub fn new(g: &GripperConfig) -> Self {
        let r = g.cup_diameter_m / 2.0;
        SuctionModel {
            cup_radius_m: r,
            holding_n: g.vacuum_kpa * 1e3 * std::f64::consts::PI * r * r,
            lip_friction: g.lip_friction,
        }
    }

    /// The force the cup must exert (N) to hold `mass_kg` under the tool's specific force
    /// `specific_force_tool` (a - g, m/s^2, in the tool frame: z out of the cup toward the part),
    /// its centre of mass at `com_from_cup_m` (tool frame, from the lip's centre): the pull toward
    /// the cup, plus the shear across the lip over [`SuctionModel::lip_friction`], plus 4 / d times
    /// the moment across the axis. A push into the cup is carried by the lip: no pull.
    pub fn required_n(&self, mass_kg: f64, specific_force_tool: &Vector3<f64>, com_from_cup_m: &Vector3<f64>) -> f64 {
        let f = specific_force_tool * mass_kg;
        let pull = (-f.z).max(0.0);
        let shear = f.xy().norm();
        let moment = com_from_cup_m.cross(&f);
        pull + shear / self.lip_friction + 4.0 * moment.xy().norm() / (2.0 * self.cup_radius_m)
    }

    /// The force the cup must exert (N) against loads other bodies put on the held part, split
    /// as [`SuctionModel::required_n`] splits the part's own: their pull off the cup along its
    /// axis `pull_n` (N) in full, their shear across the lip `shear_n` (N) over
    /// [`SuctionModel::lip_friction`], and their moment about the cup centre across the axis
    /// `moment_across_nm` (N m) as peel, 4 |M| / d. Added to [`SuctionModel::required_n`], a
    /// bound on the combined load's.
    pub fn contact_required_n(&self, pull_n: f64, shear_n: f64, moment_across_nm: f64) -> f64 {
        pull_n + shear_n / self.lip_friction + 4.0 * moment_across_nm / (2.0 * self.cup_radius_m)
    }
}

/// Fraction of the cup's holding force a held-part motion may use (the plans' [`SealBudget`]).
pub const SUCTION_MARGIN: f64 = 0.75;

/// What the plans let a held part ask of the cup: its share of [`SuctionModel::holding_n`], with
/// the part's mass and its centre of mass where the recognition put it, off by up to
/// `com_uncertainty_m` in any direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SealBudget {
    /// The cup.
    pub model: SuctionModel,
    /// The part's mass (kg).
    pub mass_kg: f64,
    /// Its centre of mass from the lip's centre, tool frame (m).
    pub com_from_cup_m: Vector3<f64>,
    /// How far the true centre of mass may be from that (m).
    pub com_uncertainty_m: f64,
    /// The share of the holding force the plans may ask.
    pub share: f64,
}

impl SealBudget {
    /// The plans' budget: [`SUCTION_MARGIN`] of the cup's holding force for a part of
    /// `mass_kg` with its centre of mass at `com_from_cup_m` (tool frame, from the lip's centre),
    /// off by up to `com_uncertainty_m`.
    pub fn planned(model: SuctionModel, mass_kg: f64, com_from_cup_m: Vector3<f64>, com_uncertainty_m: f64) -> Self {
        SealBudget {
            model,
            mass_kg,
            com_from_cup_m,
            com_uncertainty_m,
            share: SUCTION_MARGIN,
        }
    }

    /// The share of the budget (1: all of it) the part asks of the cup with the tool turned
    /// `world_from_tool` and exerting the specific force `specific_force_world` (a - g, m/s^2,
    /// world) on it: [`SuctionModel::required_n`], plus the moment an offset of
    /// `com_uncertainty_m` could add at worst, over the share of the holding force.
    pub fn load(&self, world_from_tool: &UnitQuaternion<f64>, specific_force_world: &Vector3<f64>) -> f64 {
        let sf = world_from_tool.inverse_transform_vector(specific_force_world);
        let m = &self.model;
        let worst_offset_n = 4.0 * self.com_uncertainty_m * self.mass_kg * sf.norm() / (2.0 * m.cup_radius_m);
        (m.required_n(self.mass_kg, &sf, &self.com_from_cup_m) + worst_offset_n) / (self.share * m.holding_n)
    }

    /// The largest lift acceleration (m/s^2) within `[lowest_m_s2, highest_m_s2]` at which the
    /// part, lifted straight out along the cup's axis with the tool turned `world_from_tool`,
    /// leaves in the budget room for a neighbour's push: one part's weight across the axis at the
    /// depth of its centre of mass below the lip ([`SealBudget::push_share`]). None where even
    /// `lowest_m_s2` leaves none.
    pub fn lift_accel_with_room(
        &self,
        world_from_tool: &UnitQuaternion<f64>,
        lowest_m_s2: f64,
        highest_m_s2: f64,
    ) -> Option<f64> {
        let g = crate::robot::GRAVITY_M_S2;
        let push_share = self.push_share(self.mass_kg * g, self.com_from_cup_m.z);
        let up = world_from_tool * -Vector3::z();
        let room =
            |accel_m_s2: f64| self.load(world_from_tool, &(up * accel_m_s2 + Vector3::z() * g)) + push_share <= 1.0;
        if room(highest_m_s2) {
            return Some(highest_m_s2);
        }
        if !room(lowest_m_s2) {
            return None;
        }
        let (mut lo, mut hi) = (lowest_m_s2, highest_m_s2);
        for _ in 0..20 {
            let mid = 0.5 * (lo + hi);
            if room(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(lo)
    }

    /// The share of the budget a push of `push_n` (N) on the held part across the cup's axis,
    /// `depth_m` below the lip, asks: its shear over the lip's friction and its moment as peel
    /// ([`SuctionModel::contact_required_n`]).
    pub fn push_share(&self, push_n: f64, depth_m: f64) -> f64 {
        let m = &self.model;
        m.contact_required_n(0.0, push_n, push_n * depth_m.abs()) / (self.share * m.holding_n)
    }
}

/// The least distance between two boxes, each given by `world_from_box` (its centre and axes)
/// and its half extents (m); 0 where they overlap. Computed by parry in millimetres and single
/// precision (a few micrometres).
pub fn box_box_distance_m(
    world_from_a: &Isometry3<f64>,
    half_a_m: &Vector3<f64>,
    world_from_b: &Isometry3<f64>,
    half_b_m: &Vector3<f64>,
) -> f64 {
    use rapier3d::parry::shape::Cuboid;
    let a = Cuboid::new(mm_vector(half_a_m));
    let b = Cuboid::new(mm_vector(half_b_m));
    rapier3d::parry::query::distance(&mm_pose(world_from_a), &a, &mm_pose(world_from_b), &b)
        .map_or(0.0, |d| d.distance as f64 / 1e3)
}

/// The least distance between a box (`world_from_box`, half extents, m) and a round column: the
/// points within `radius_m` of the segment from `from_m` to `to_m` (world, m); 0 where they
/// overlap.
pub fn box_column_distance_m(
    world_from_box: &Isometry3<f64>,
    half_m: &Vector3<f64>,
    from_m: &Vector3<f64>,
    to_m: &Vector3<f64>,
    radius_m: f64,
) -> f64 {
    use rapier3d::parry::shape::{Capsule, Cuboid};
    let cuboid = Cuboid::new(mm_vector(half_m));
    let column = Capsule::new(mm_vector(from_m), mm_vector(to_m), (radius_m * 1e3) as f32);
    rapier3d::parry::query::distance(
        &mm_pose(world_from_box),
        &cuboid,
        &rapier3d::math::Pose::IDENTITY,
        &column,
    )
    .map_or(0.0, |d| d.distance as f64 / 1e3)
}

/// Convex hull of points in a plane (Andrew's monotone chain), counter-clockwise (m).
pub fn convex_hull_2d(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = pts.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// How far the point `p` lies outside the convex polygon `hull` (counter-clockwise, as
/// [`convex_hull_2d`] gives it) (m): its distance to the nearest edge, 0 on or inside it.
pub fn outside_convex_m(hull: &[[f64; 2]], p: [f64; 2]) -> f64 {
    let n = hull.len();
    let mut inside = n >= 3;
    let mut nearest = f64::INFINITY;
    for i in 0..n {
        let (a, b) = (hull[i], hull[(i + 1) % n]);
        let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
        let (px, py) = (p[0] - a[0], p[1] - a[1]);
        if ex * py - ey * px < 0.0 {
            inside = false;
        }
        let t = ((px * ex + py * ey) / (ex * ex + ey * ey).max(1e-24)).clamp(0.0, 1.0);
        nearest = nearest.min((px - t * ex).hypot(py - t * ey));
    }
    if inside { 0.0 } else { nearest }
}

/// A vector (m) in millimetres, single precision, for parry.
fn mm_vector(v_m: &Vector3<f64>) -> rapier3d::math::Vector {
    rapier3d::math::Vector::new((v_m.x * 1e3) as f32, (v_m.y * 1e3) as f32, (v_m.z * 1e3) as f32)
}

/// An isometry (m) in millimetres, single precision, for parry.
fn mm_pose(iso: &Isometry3<f64>) -> rapier3d::math::Pose {
    let mut p: rapier3d::math::Pose = iso.cast::<f32>().into();
    p.translation = mm_vector(&iso.translation.vector);
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LoadedScene;

    /// The hull of a square's corners and an inner point is the square, counter-clockwise; a
    /// point's distance outside it is to the nearest edge or corner, 0 inside and on it.
    #[test]
    fn a_point_outside_a_convex_outline_is_as_far_as_its_nearest_edge_or_corner() {
        let hull = convex_hull_2d(&[[1.0, 1.0], [0.0, 0.0], [0.5, 0.5], [1.0, 0.0], [0.0, 1.0]]);
        assert_eq!(hull, vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        assert_eq!(outside_convex_m(&hull, [0.5, 0.5]), 0.0);
        assert_eq!(outside_convex_m(&hull, [1.0, 0.5]), 0.0);
        assert!((outside_convex_m(&hull, [1.5, 0.5]) - 0.5).abs() < 1e-12);
        assert!((outside_convex_m(&hull, [-0.3, 1.4]) - 0.5).abs() < 1e-12);
        // Control: turned clockwise, the same outline reads everything as outside its edges.
        let clockwise: Vec<[f64; 2]> = hull.iter().rev().cloned().collect();
        assert!(outside_convex_m(&clockwise, [0.5, 0.5]) > 0.0);
    }

    #[test]
    fn trays_are_five_pieces_that_enclose_the_inner_floor() {
        let s = LoadedScene::embedded_default().unwrap().scene;
        let boxes = tray_pieces_m(&s.pick_tray);
        let t = &s.pick_tray;
        // The floor's top is the tray frame's z = 0; the walls reach from under the floor to the rim.
        assert!((boxes[0].0.z + boxes[0].1.z).abs() < 1e-12);
        for ((c, h), name) in boxes[1..].iter().zip(&TRAY_PIECES[1..]) {
            assert!((c.z + h.z - t.wall_height_m).abs() < 1e-12, "{name}");
            assert!((c.z - h.z + t.floor_thickness_m).abs() < 1e-12, "{name}");
        }
        // Inner faces of the walls at +-inner/2.
        assert!((boxes[1].0.x - boxes[1].1.x - t.inner_size_m[0] / 2.0).abs() < 1e-12);
        assert!((boxes[4].0.y + boxes[4].1.y + t.inner_size_m[1] / 2.0).abs() < 1e-12);
        assert_eq!(tray_boxes("pick tray", t)[1].name, "pick tray wall +x");
        let all = cell_boxes(&s);
        assert_eq!(all.len(), 11 + s.obstacles.len());
        assert_eq!(all[0].1.name, "table");
    }

    #[test]
    fn hand_and_suction_model() {
        let s = LoadedScene::embedded_default().unwrap().scene;
        let h = HandGeometry::new(&s.gripper);
        assert!((h.body_length_m + h.cup_length_m - h.tool_length_m).abs() < 1e-15);
        let m = SuctionModel::new(&s.gripper);
        let g = crate::robot::GRAVITY_M_S2;
        let d = 2.0 * m.cup_radius_m;
        // Straight down (tool z down) and still: the cup pulls m g, peeled by 4 e / d.
        let still = Vector3::new(0.0, 0.0, -g);
        let (mass, e) = (0.01, 0.002);
        let below = Vector3::new(e, 0.0, 0.003);
        let want = mass * g * (1.0 + 4.0 * e / d);
        assert!((m.required_n(mass, &still, &below) - want).abs() < 1e-12);
        // Moved sideways at a (the makers' load case m (g + a / mu)), the centre of mass on the
        // axis and at the lip: the shear over the friction; below the lip, its moment too.
        let a = 10.0;
        let sideways = Vector3::new(a, 0.0, -g);
        let at_lip = Vector3::zeros();
        let case = mass * (g + a / m.lip_friction);
        assert!((m.required_n(mass, &sideways, &at_lip) - case).abs() < 1e-12);
        let deep = Vector3::new(0.0, 0.0, 0.003);
        let peel = 4.0 * 0.003 * mass * a / d;
        assert!((m.required_n(mass, &sideways, &deep) - case - peel).abs() < 1e-12);
        // Control: the old model's m |a - g| (1 + 4 e / d) asks less of the cup sideways.
        assert!(mass * sideways.norm() < case);
        // A push into the cup (tool z down, pressed down harder than gravity) pulls nothing.
        assert_eq!(m.required_n(mass, &Vector3::new(0.0, 0.0, 1.0), &at_lip), 0.0);
        // Other bodies' loads split the same way: a pull in full, a shear over the friction, a
        // moment as peel. The weight of the sideways case, applied by a neighbour at the centre
        // of mass instead of by the motion, asks as much.
        let (pull_n, shear_n) = (mass * g, mass * a);
        let contact = m.contact_required_n(pull_n, shear_n, 0.003 * shear_n);
        assert!((contact - case - peel).abs() < 1e-12);
        // Control: a push straight along the axis with no lever (the old model's |F|) asks less
        // than the same force across it.
        assert!(m.contact_required_n(shear_n, 0.0, 0.0) < m.contact_required_n(0.0, shear_n, 0.0));
        // The budget: a tool turned 40 degrees from straight down asks more than one straight down.
        let budget = SealBudget {
            model: m,
            mass_kg: mass,
            com_from_cup_m: deep,
            com_uncertainty_m: 0.0,
            share: 0.75,
        };
        let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let up_g = Vector3::new(0.0, 0.0, g);
        let straight = budget.load(&down, &up_g);
        assert!((straight * 0.75 * m.holding_n - mass * g).abs() < 1e-12);
        let leaning = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 40f64.to_radians()) * down;
        assert!(budget.load(&leaning, &up_g) > 2.0 * straight);
        // The uncertainty of the centre of mass adds its worst moment.
        let unsure = SealBudget {
            com_uncertainty_m: 0.001,
            ..budget
        };
        let extra = 4.0 * 0.001 * mass * g / d / (0.75 * m.holding_n);
        assert!((unsure.load(&down, &up_g) - straight - extra).abs() < 1e-12);
    }

    #[test]
    fn box_distances_are_the_gaps_between_the_shapes() {
        // Two unit-free boxes 10 mm wide side by side, 20 mm between their centres: a 10 mm gap;
        // turned a quarter turn, the second is 30 mm wide along x: a 0 mm gap (touching).
        let half = Vector3::new(0.005, 0.005, 0.005);
        let a = Isometry3::identity();
        let b = Isometry3::translation(0.020, 0.0, 0.0);
        assert!((box_box_distance_m(&a, &half, &b, &half) - 0.010).abs() < 1e-5);
        let long = Vector3::new(0.005, 0.015, 0.005);
        let turned = b * Isometry3::rotation(Vector3::z() * std::f64::consts::FRAC_PI_2);
        assert!(box_box_distance_m(&a, &half, &turned, &long) < 1e-5);
        // Control: overlapping boxes are 0 apart, not negative.
        assert_eq!(box_box_distance_m(&a, &half, &a, &half), 0.0);
        // A column of radius 5 mm standing 30 mm off the box's centre along y: a 20 mm gap; one
        // lying over the box, 10 mm above its top: 10 mm.
        let up = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        let d = box_column_distance_m(&a, &half, &up(0.0, 0.030, 0.0), &up(0.0, 0.030, 0.3), 0.005);
        assert!((d - 0.020).abs() < 1e-5, "{d}");
        let d = box_column_distance_m(&a, &half, &up(-0.1, 0.0, 0.020), &up(0.1, 0.0, 0.020), 0.005);
        assert!((d - 0.010).abs() < 1e-5, "{d}");
    }
}
