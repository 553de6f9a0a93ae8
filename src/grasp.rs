//! The grasp selector: suction grasps from what the sensor saw, filtered and ranked.
//!
//! Job: from the recognised parts (noisy poses) and the point cloud's height map, propose suction
//! points on body faces large enough for the cup whose normal is within the tool's lean of
//! vertical (`gripper.max_lean_deg`): straight down onto a face tilted up to the cup's tilt, along
//! the normal of one tilted further, the part lifted straight up from both; drop those the tool
//! would not clear along its approach (height map), whose straight approach or retreat would meet
//! the tray walls (cell geometry), or that the arm cannot reach within its limits along the whole
//! straight descent and lift. The faces are the part model's planar faces that take the cup
//! (a CAD part's, or a built-in part's meshed primitives': the selector does not know which),
//! each grasped at the centre of its cup-fit region farthest from its edges whose approach, cup
//! and tool body, misses the part's own features above the face (pins, tabs); with a cup that
//! seals on round surfaces (`gripper.round_min_radius_m`), also a round body's side, as tangent
//! strips all round ([`crate::part::round_side`]). Pick the tool yaw
//! that makes the place motion quickest; rank by exposure, clearance, expected grasp success and
//! expected motion time, and score how hemmed in by its neighbours each part is (the lift reads
//! it). Nothing here reads the world's ground truth.
//!
//! Units: m, rad, s. Frames: `world_from_part` (detected), `world_from_tool` (z out of the cup,
//! into the face), the pick tray frame for the height map and the walls.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use serde::Serialize;

use crate::config::{PlaceOrientation, Scene};
use crate::part::approach::ColumnPiece;
use crate::part::primitive::Face;
use crate::robot::{JointVector, RobotModel};
use crate::sensor::{Detection, HeightMap};

/// How far the cloud may stand above a face's plane over the face before something counts as
/// lying on it (m): depth noise (0.5 mm-class), the cell's highest point, and the face's tilt
/// across a cell, well below the thinnest part (C: 5 mm).
pub const COVER_TOLERANCE_M: f64 = 0.003;

/// A round body's side strip is offered only where a stable pose has it up within this (rad):
/// the part is set down lying as held, with the strip straight up
/// ([`PlacePose::with_face_up`]), and settles by at most this into its pose, well within the
/// place tray's 5 degree tolerance. Allowing the cup's whole tilt instead would set parts down
/// far from a pose they stay in, with the tool leaning over the slot toward the tray's wall.
pub const SIDE_PLACE_OFF_MAX_RAD: f64 = 3.0 * std::f64::consts::PI / 180.0;

/// How far beyond a part's outline the grasp selector reads its neighbours for
/// [`Score::hemmed`] (m): the gap a neighbour touching or leaning on the part leaves in the
/// cloud, a cell or two, not the next part over.
pub const HEM_RING_M: f64 = 0.003;

/// The round body's side strips `scene`'s cup takes, when it seals on round surfaces
/// (`gripper.round_min_radius_m`), each with the pose the part is set down in
/// ([`PlacePose::with_face_up`]): those with a clear cup site that a stable pose has up within
/// [`SIDE_PLACE_OFF_MAX_RAD`]. The grasp selector offers them (on an upright line, those whose
/// pose is upright); `binpick part` counts them.
pub fn offered_side_strips(
    pm: &crate::part::PartModel,
    scene: &Scene,
) -> Vec<(crate::part::round_side::SideStrip, PlacePose)> {
    let Some(round_min_radius_m) = scene.gripper.round_min_radius_m else {
        return Vec::new();
    };
    pm.round_side_strips(round_min_radius_m, &approach_column(scene))
        .into_iter()
        .filter_map(|strip| {
            let place = PlacePose::with_face_up(pm, &strip.face.normal, SIDE_PLACE_OFF_MAX_RAD)?;
            Some((strip, place))
        })
        .collect()
}

/// Where on a detected part's face the cup would go, in the world.
struct FacePoint {
    /// The grasp point on the face (m).
    point: Vector3<f64>,
    /// The face's outward normal.
    normal: Vector3<f64>,
    /// Height the approach pose must lift the part's bottom to, clear of the pile (m).
    clear_z: f64,
    /// The line the tool comes down along and leaves by (world, unit, upward): vertical, or the
    /// face's normal where the face is tilted beyond the cup's tilt (the tool leaning with it).
    approach_dir: Vector3<f64>,
}

/// Why a candidate was dropped.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Rejection {
    /// The face's normal is tilted beyond what the cup seals.
    FaceTilted,
    /// The face is smaller than the cup plus margins.
    FaceTooSmall,
    /// Points of the cloud rise into the cup's or tool's path around the grasp point.
    Crowded,
    /// Points of the cloud stand above the face somewhere over the part: something lies on it
    /// (a part across a long strip is lifted with it and flung out of the tray).
    Covered,
    /// The straight approach or retreat would meet a tray wall.
    TrayWall,
    /// The tool at the place pose would meet the place tray's wall, at every tool yaw that
    /// reaches it.
    PlaceTrayWall,
    /// No joint solution within limits along the straight descent, or at the place pose.
    Unreachable,
    /// None of the faces offered to the cup points up within 60 deg (nor within the cup's tilt):
    /// a can lying on its side, a part on its edge, or, on an upright line, a part lying another
    /// way up. Counted once per recognised part, with the face index 0.
    NoFaceUp,
}

impl Rejection {
    /// Short name for tables.
    pub fn name(&self) -> &'static str {
        match self {
            Rejection::FaceTilted => "face tilted",
            Rejection::FaceTooSmall => "face too small",
            Rejection::Crowded => "crowded",
            Rejection::Covered => "covered",
            Rejection::TrayWall => "tray wall",
            Rejection::PlaceTrayWall => "place tray wall",
            Rejection::Unreachable => "unreachable",
            Rejection::NoFaceUp => "no face up",
        }
    }
}

/// A feasible grasp with the motion it implies.
#[derive(Debug, Clone, Serialize)]
pub struct GraspCandidate {
    /// Index of the detection.
    pub detection: usize,
    /// Which face (index into [`GraspSelector::faces`]: the part model's faces that take the cup).
    pub face: usize,
    /// The tool at the grasp: cup lip on the face.
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_tool: Isometry3<f64>,
    /// The tool above the grasp, where the straight descent starts.
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_tool_approach: Isometry3<f64>,
    /// The tool above the grasp where the straight lift with the part ends: the approach pose,
    /// or straight above the grasp where the tool came down along a leaning face's normal.
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_tool_lifted: Isometry3<f64>,
    /// The tool when the part touches down in its slot.
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_tool_place: Isometry3<f64>,
    /// Where the part should then lie: the slot turned into the part's place pose (and by the
    /// multiple of its yaw symmetry the place motion takes). Its placement error is measured
    /// from this, not from the slot's own frame.
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_part_place: Isometry3<f64>,
    /// The tool's lean from vertical where it comes down along the face's normal, the face
    /// being tilted beyond what the cup seals on coming straight down (`gripper.max_lean_deg`)
    /// (rad); `None` where it comes straight down.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lean_rad: Option<f64>,
    /// Joint positions at the approach pose (rad).
    pub q_approach: [f64; 6],
    /// Joint positions at the grasp (rad).
    pub q_grasp: [f64; 6],
    /// Joint positions at the end of the lift (rad).
    pub q_lifted: [f64; 6],
    /// Joint positions at the place pose (rad).
    pub q_place: [f64; 6],
    /// Score components and total (higher is better).
    pub score: Score,
}

/// How a candidate was ranked.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Score {
    /// Face height in the pile (0 floor, 1 top of the pile) and how much of the part was visible.
    pub exposure: f64,
    /// Free radius around the grasp point in the cloud (m) (capped at 20 mm).
    pub clearance_m: f64,
    /// Expected grasp success (tilt, face margin, centre-of-mass offset, pose certainty), 0..1.
    pub success: f64,
    /// Estimated time of the place motion at full speed (s).
    pub motion_s: f64,
    /// exposure + clearance/20 mm + 2 success - motion time.
    pub total: f64,
    /// How hemmed in by its neighbours the cloud shows the part ([`GraspSelector::hemmed`]):
    /// 0 free, about 1 and more standing in a well. Not part of `total`: the lift reads it.
    pub hemmed: f64,
}

/// The selector's answer.
#[derive(Debug, Clone, Serialize)]
pub struct GraspPlan {
    /// Feasible grasps, best first.
    pub ranked: Vec<GraspCandidate>,
    /// Dropped candidates: (detection, face, reason).
    pub rejected: Vec<(usize, usize, Rejection)>,
}

impl GraspPlan {
    /// The chosen grasp.
    pub fn best(&self) -> Option<&GraspCandidate> {
        self.ranked.first()
    }

    /// Rejections counted by reason.
    pub fn rejected_counts(&self) -> BTreeMap<&'static str, usize> {
        let mut m = BTreeMap::new();
        for (_, _, r) in &self.rejected {
            *m.entry(r.name()).or_insert(0) += 1;
        }
        m
    }
}

/// The selector's fixed inputs: the cell, the arm, the workpiece.
#[derive(Debug, Clone)]
pub struct GraspSelector {
    robot: RobotModel,
    faces: Vec<Face>,
    /// Per face: where the cup goes (part frame), the face's clearest admissible cup centre,
    /// and its distance to the face's nearest edge (m).
    sites: Vec<(Vector3<f64>, f64)>,
    /// The centre of mass the peel model reads (part frame, m): the part model's.
    peel_com_m: Vector3<f64>,
    /// A part model's faces that take the cup but on which every cup site's approach meets the
    /// part's own geometry (pins, tabs, a can above its base): not offered.
    blocked_faces: usize,
    /// Faces that take the cup but would place the part another way up than its workpiece file
    /// allows (`grasp.place_orientation`): not offered.
    not_upright_faces: usize,
    /// A part model's faces that take the cup but that no stable pose has up within the tool's
    /// lean (`gripper.max_lean_deg`): a part held by one could not be set down as held, and
    /// would tip over in its slot. Not offered.
    unplaceable_faces: usize,
    /// Per face, how the part lies in its slot when grasped there: the stable pose whose support
    /// is opposite the face, set down with the tool leaning as the face then tilts.
    place: Vec<PlacePose>,
    /// The part's footprint in its place orientations, along the slot's x and y (m).
    place_footprint_m: [f64; 2],
    /// The workpiece's own face margin, for which the part model's cup-fit regions were made (m).
    fit_margin_m: f64,
    cup_radius_m: f64,
    /// The cup's holding model, the part's mass (kg) and how far its recognised centre of mass
    /// may be off (m): what the controller's seal budget will slow a carry for.
    suction: crate::geometry::SuctionModel,
    mass_kg: f64,
    com_uncertainty_m: f64,
    face_margin_m: f64,
    max_tilt_rad: f64,
    /// Faces tilted from vertical beyond `max_tilt_rad` and up to this are approached along their
    /// normal (`gripper.max_lean_deg`) (rad).
    max_lean_rad: f64,
    tool_radius_m: f64,
    cup_length_m: f64,
    /// The pick tray's inner walls (and its frame, the height map's), which the approach and
    /// retreat must clear.
    pick_walls: Walls,
    /// The place tray's inner walls, which the tool at the place pose must clear.
    place_walls: Walls,
    /// Height of the approach pose above the tray rim (m).
    pub approach_above_rim_m: f64,
    size_m: [f64; 3],
    yaw_symmetry_rad: f64,
    /// Cloud points within this of the face plane belong to it (noise) (m).
    pub height_tolerance_m: f64,
    /// Per face (as `faces`), the points of the part model's surface standing more than
    /// [`OWN_OFF_FACE_M`] out of the face's plane (part frame, m): its vertices and points at
    /// most [`OWN_SURFACE_SPACING_M`] apart on each triangle, where they are the part's features
    /// beside the face (pins, legs, a tab). What of the height map around a grasp the recognised
    /// part itself explains.
    own_features_m: Vec<Vec<Point3<f64>>>,
}

/// Spacing of [`GraspSelector`]'s samples of the part's own surface (m): half a height-map cell,
/// so every cell the surface crosses holds one.
const OWN_SURFACE_SPACING_M: f64 = 0.001;
/// A height-map cell whose highest point lies at most this above the recognised part's own
/// surface in it is the part itself, not something crowding the tool (m): a cell holds its
/// highest point (depth noise, +0.15 to 0.5 mm) and the pose is off by a few tenths.
const OWN_EXPLAINS_M: f64 = 0.001;
/// The part's own surface explains the map only where it stands more than this out of the
/// grasped face's plane (m): its features, not the face (nor what lies below it).
const OWN_OFF_FACE_M: f64 = 0.0002;

/// Points on `mesh`'s surface: its vertices, and on each triangle a grid of barycentric points at
/// most `spacing_m` apart along its longest edge (part frame, m).
fn surface_samples(mesh: &crate::part::mesh::Mesh, spacing_m: f64) -> Vec<Point3<f64>> {
    let mut out = mesh.vertices_m.clone();
    for k in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(k);
        let longest = (b - a).norm().max((c - b).norm()).max((a - c).norm());
        let n = (longest / spacing_m).ceil() as usize;
        for i in 0..=n {
            for j in 0..=(n - i) {
                let (u, v) = (i as f64 / n.max(1) as f64, j as f64 / n.max(1) as f64);
                out.push(a + (b - a) * u + (c - a) * v);
            }
        }
    }
    out
}

/// How a part model's part lies in its place slot: resting on the floor in one of its stable
/// poses, turned so that the pose's support normal points straight down and, about the
/// vertical, so that its footprint's box is smallest (before the slot's yaw).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacePose {
    /// The part's rotation in the slot frame (before the slot's yaw).
    pub slot_from_part: UnitQuaternion<f64>,
    /// Height of the part frame's origin above the floor (m): its hull's lowest point on it.
    pub origin_height_m: f64,
    /// Its footprint along the slot's x and y (m).
    pub footprint_m: [f64; 2],
}

impl PlacePose {
    /// The stable pose in which the part rests with the face of outward normal `face_normal`
    /// (part frame) up: the pose whose support normal is most nearly opposite it, if the face
    /// then tilts within `max_lean_rad` (the grasp selector's: the tool leans with the face as
    /// it sets the part down; a face tilted further in every pose is not grasped, since its part
    /// would tip over in its slot).
    pub fn of_face(pm: &crate::part::PartModel, face_normal: &Vector3<f64>, max_lean_rad: f64) -> Option<Self> {
        let pose = Self::supporting(pm, face_normal, max_lean_rad)?;
        let down = -Vector3::z();
        let tip = UnitQuaternion::rotation_between(&pose.normal, &down)
            .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
        Some(Self::tipped(pm, tip))
    }

    /// The part set down with the face of outward normal `face_normal` exactly up (the tool
    /// straight down on it), where a stable pose has that face up within `max_off_rad`: the part
    /// then settles by at most that into the pose. A round body's side strip is placed so: a tool
    /// tilted by a lying pose's small skew over a slot where the wrist hangs straight (J5 near
    /// 0) finds no straight descent, where a tool straight down does (the wrist's singular
    /// case, which the straight line handles).
    pub fn with_face_up(pm: &crate::part::PartModel, face_normal: &Vector3<f64>, max_off_rad: f64) -> Option<Self> {
        Self::supporting(pm, face_normal, max_off_rad)?;
        let tip = UnitQuaternion::rotation_between(face_normal, &Vector3::z())
            .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
        Some(Self::tipped(pm, tip))
    }

    /// The stable pose whose support normal is most nearly opposite `face_normal`, if that has
    /// the face up within `max_tilt_rad`.
    fn supporting<'m>(
        pm: &'m crate::part::PartModel,
        face_normal: &Vector3<f64>,
        max_tilt_rad: f64,
    ) -> Option<&'m crate::part::poses::RestingPose> {
        let pose = pm
            .poses
            .iter()
            .max_by(|a, b| (-a.normal.dot(face_normal)).total_cmp(&(-b.normal.dot(face_normal))))?;
        (-pose.normal.dot(face_normal) >= max_tilt_rad.cos()).then_some(pose)
    }

    /// The part turned by `tip` (its support down), then about the vertical so that its
    /// footprint's box is smallest, resting on its hull's lowest point.
    fn tipped(pm: &crate::part::PartModel, tip: UnitQuaternion<f64>) -> Self {
        let bounds = |rot: &UnitQuaternion<f64>| {
            let placed = pm.hull.vertices_m.iter().map(|v| rot * v.coords);
            placed.fold(
                (Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)),
                |(lo, hi), v| (lo.inf(&v), hi.sup(&v)),
            )
        };
        // Turned about the vertical so that its footprint's box is smallest (whole degrees),
        // its longer side along the slot's x.
        let turned = |deg: u32| UnitQuaternion::from_axis_angle(&Vector3::z_axis(), f64::from(deg).to_radians()) * tip;
        let extent = |deg: u32| {
            let (lo, hi) = bounds(&turned(deg));
            (hi.x - lo.x, hi.y - lo.y)
        };
        let area = |deg: u32| {
            let (x, y) = extent(deg);
            x * y
        };
        let least = (0..180).map(area).fold(f64::INFINITY, f64::min);
        let deg = (0..180)
            .filter(|d| area(*d) <= least * (1.0 + 1e-6))
            .max_by(|a, b| {
                let (ea, eb) = (extent(*a), extent(*b));
                (ea.0 - ea.1).total_cmp(&(eb.0 - eb.1)).then(b.cmp(a))
            })
            .unwrap_or(0);
        let rot = turned(deg);
        let (lo, hi) = bounds(&rot);
        PlacePose {
            slot_from_part: rot,
            origin_height_m: -lo.z,
            footprint_m: [hi.x - lo.x, hi.y - lo.y],
        }
    }

    /// Whether the part rests in this pose on the stable pose most nearly on its frame's -z
    /// side, or one its symmetry makes look the same (`grasp.place_orientation = "upright"`):
    /// recognition reports a symmetric part's pose only up to its symmetry, so a block seen
    /// with its bottom up is placed upright all the same.
    pub fn is_upright(&self, pm: &crate::part::PartModel) -> bool {
        let Some(upright) = pm.poses.iter().max_by(|a, b| (-a.normal.z).total_cmp(&(-b.normal.z))) else {
            return false;
        };
        let down = |turn: &UnitQuaternion<f64>| (self.slot_from_part * (turn * upright.normal)).z < -0.9999;
        match crate::sensor::Symmetry::of_orders(pm.symmetry.orders) {
            crate::sensor::Symmetry::Finite(turns) => turns.iter().any(down),
            // Any turn about the part's z leaves its -z side down; a part that looks the same
            // upside down is upright either way up.
            crate::sensor::Symmetry::AboutZ { flip } => {
                down(&UnitQuaternion::identity())
                    || (flip
                        && down(&UnitQuaternion::from_axis_angle(
                            &Vector3::x_axis(),
                            std::f64::consts::PI,
                        )))
            }
        }
    }

    /// The footprint the slots must hold for every place pose in `place` (m): the largest
    /// extents along x and y; when the part may be turned in its slot by its yaw symmetry
    /// (`yaw_symmetry_rad`, 0: a quarter turn), both the larger of the two for quarter turns and
    /// the diagonal for finer ones.
    /// `None` when no face has a place pose.
    fn footprint_m(place: &[PlacePose], yaw_symmetry_rad: f64) -> Option<[f64; 2]> {
        let mut fp: Option<[f64; 2]> = None;
        for p in place {
            let f = fp.get_or_insert([0.0, 0.0]);
            f[0] = f[0].max(p.footprint_m[0]);
            f[1] = f[1].max(p.footprint_m[1]);
        }
        let sym = if yaw_symmetry_rad > 0.0 {
            yaw_symmetry_rad
        } else {
            std::f64::consts::FRAC_PI_2
        };
        let turns = (std::f64::consts::TAU / sym).round().max(1.0) as usize;
        fp.map(|[x, y]| match turns {
            1 | 2 => [x, y],
            4 => [x.max(y); 2],
            _ => [x.hypot(y); 2],
        })
    }
}

/// The hand's solid above a cup site, as the approach sweeps it down the face normal: the cup
/// from the lip up its length, then the tool body, each widened by two standard deviations of
/// the recognised pose's noise (the site lands that far off).
pub fn approach_column(scene: &Scene) -> [ColumnPiece; 2] {
    let hand = crate::geometry::HandGeometry::new(&scene.gripper);
    let slack = 2.0 * scene.sensor.pose_noise_m;
    [
        ColumnPiece {
            radius_m: hand.cup_radius_m + slack,
            from_m: 0.0,
            to_m: hand.cup_length_m,
        },
        ColumnPiece {
            radius_m: hand.body_radius_m + slack,
            from_m: hand.cup_length_m,
            to_m: hand.tool_length_m,
        },
    ]
}

/// The tool's rotation (world) with its x axis along `x` and its z axis along `z_tool`, both unit
/// and orthogonal: the basis itself. (nalgebra's `from_matrix` iterates toward the nearest
/// rotation starting from the identity and never ends on a half turn from it, such as a flat
/// face's tool pointing straight down with x along -x: a run hung there.)
fn tool_rotation(x: &Vector3<f64>, z_tool: &Vector3<f64>) -> UnitQuaternion<f64> {
    let y = z_tool.cross(x);
    UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_basis_unchecked(&[*x, y, *z_tool]))
}

/// Trapezoidal single-joint move time at top speed and acceleration (s).
fn joint_move_s(d: f64, v: f64, a: f64) -> f64 {
    let d = d.abs();
    if d * a <= v * v {
        2.0 * (d / a).sqrt()
    } else {
        d / v + v / a
    }
}

/// A tray's inner walls, as the tool's axis must clear them.
#[derive(Debug, Clone, Copy)]
struct Walls {
    world_from_tray: Isometry3<f64>,
    inner_half_m: [f64; 2],
    rim_height_m: f64,
}

impl Walls {
    fn of(t: &crate::config::TrayConfig) -> Self {
        Walls {
            world_from_tray: t.world_from_tray(),
            inner_half_m: [t.inner_size_m[0] / 2.0, t.inner_size_m[1] / 2.0],
            rim_height_m: t.wall_height_m,
        }
    }
}

impl GraspSelector {
    /// The selector for a loaded workpiece in `scene` with `robot`. Its faces are the part
    /// model's planar faces that take the cell's cup (a CAD part's mesh, or a built-in part's
    /// primitives meshed: one derivation for both), each fitted as
    /// [`crate::sensor::cloud::face_of_planar`] fits it and grasped at its cup-fit region's
    /// clearest centre; the peel model reads the model's centre of mass, and each face places the
    /// part in the stable pose that has it up. A workpiece whose part model cannot be derived
    /// (a degenerate mesh, refused by `binpick check`) offers no face.
    pub fn for_workpiece(scene: &Scene, robot: &RobotModel, workpiece: &crate::config::LoadedWorkpiece) -> Self {
        let w = &workpiece.workpiece;
        let g = &scene.gripper;
        let t = &scene.pick_tray;
        let mut sel = GraspSelector {
            robot: robot.clone(),
            sites: Vec::new(),
            faces: Vec::new(),
            peel_com_m: Vector3::zeros(),
            blocked_faces: 0,
            not_upright_faces: 0,
            unplaceable_faces: 0,
            place: Vec::new(),
            place_footprint_m: [w.size_m[0], w.size_m[1]],
            fit_margin_m: w.grasp.face_margin_m,
            cup_radius_m: g.cup_diameter_m / 2.0,
            suction: crate::geometry::SuctionModel::new(g),
            mass_kg: w.mass_kg,
            com_uncertainty_m: 3.0 * scene.sensor.pose_noise_m,
            // The recognised pose is off by up to two standard deviations of its noise: the cup
            // must stay on the face that much farther from its edges.
            face_margin_m: w.grasp.face_margin_m + 2.0 * scene.sensor.pose_noise_m,
            max_tilt_rad: g.max_tilt_deg.to_radians(),
            max_lean_rad: g.max_lean_rad(),
            tool_radius_m: g.body_diameter_m / 2.0,
            cup_length_m: crate::geometry::HandGeometry::new(g).cup_length_m,
            pick_walls: Walls::of(t),
            place_walls: Walls::of(&scene.place_tray.tray),
            approach_above_rim_m: scene.cycle.approach_above_rim_m,
            size_m: w.size_m,
            yaw_symmetry_rad: w.grasp.yaw_symmetry_deg.to_radians(),
            height_tolerance_m: 0.0015,
            own_features_m: Vec::new(),
        };
        let primitive = w.primitive_mesh();
        let Some(mesh) = workpiece.mesh.as_ref().map(|m| &m.0).or(primitive.as_ref()) else {
            return sel;
        };
        let Ok(pm) = w.part_model(mesh, g.cup_diameter_m) else {
            return sel;
        };
        let sites = pm.cup_sites(&approach_column(scene));
        for (f, site) in pm.faces.iter().zip(sites) {
            if !f.fit.takes_cup() {
                continue;
            }
            let Some((site, clearance)) = site else {
                sel.blocked_faces += 1;
                continue;
            };
            let Some(place) = PlacePose::of_face(&pm, &f.face.normal, sel.max_lean_rad) else {
                sel.unplaceable_faces += 1;
                continue;
            };
            if w.grasp.place_orientation == PlaceOrientation::Upright && !place.is_upright(&pm) {
                sel.not_upright_faces += 1;
                continue;
            }
            sel.faces.push(crate::sensor::cloud::face_of_planar(&f.face));
            sel.sites.push((site.coords, clearance));
            sel.place.push(place);
        }
        // A cup that seals on round surfaces also takes the round body's side (a can lying on
        // it), as tangent strips all round; a strip no stable pose has nearly up is not offered
        // (the part could not be set down as held).
        for (strip, place) in offered_side_strips(&pm, scene) {
            if w.grasp.place_orientation == PlaceOrientation::Upright && !place.is_upright(&pm) {
                sel.not_upright_faces += 1;
                continue;
            }
            sel.faces.push(crate::sensor::cloud::face_of_planar(&strip.face));
            sel.sites.push((strip.site_m.coords, strip.clearance_m));
            sel.place.push(place);
        }
        if let Some(fp) = PlacePose::footprint_m(&sel.place, sel.yaw_symmetry_rad) {
            sel.place_footprint_m = fp;
        }
        let surface = surface_samples(&pm.mesh, OWN_SURFACE_SPACING_M);
        sel.own_features_m = sel
            .faces
            .iter()
            .map(|f| {
                let off = |p: &&Point3<f64>| (p.coords - f.center).dot(&f.normal) > OWN_OFF_FACE_M;
                surface.iter().filter(off).copied().collect()
            })
            .collect();
        sel.peel_com_m = pm.com_m().coords;
        sel
    }

    /// The faces the selector proposes grasps on.
    pub fn faces(&self) -> &[Face] {
        &self.faces
    }

    /// Where on each face the cup goes (part frame, m), in the order of [`Self::faces`].
    pub fn sites_m(&self) -> Vec<Vector3<f64>> {
        self.sites.iter().map(|s| s.0).collect()
    }

    /// The part model's faces that take the cup but were not offered: every cup site's approach
    /// meets the part's own geometry.
    pub fn blocked_faces(&self) -> usize {
        self.blocked_faces
    }

    /// The part model's faces that take the cup but were not offered because they would place
    /// the part another way up than `grasp.place_orientation` allows.
    pub fn not_upright_faces(&self) -> usize {
        self.not_upright_faces
    }

    /// The part model's faces that take the cup but were not offered because no stable pose has
    /// them up within the tool's lean (the part would tip over in its slot).
    pub fn unplaceable_faces(&self) -> usize {
        self.unplaceable_faces
    }

    /// The part's footprint in its place orientations, along the slot's x and y (m): a part
    /// model's stable poses with a grasp face up (the largest extents over the faces offered);
    /// a primitive's box, lying on its -z face.
    pub fn place_footprint_m(&self) -> [f64; 2] {
        self.place_footprint_m
    }

    /// How the part lies in its slot when grasped on face `fi` (`None`: face up on the opposite
    /// side of its box, as for primitives).
    pub fn place_pose(&self, fi: usize) -> Option<&PlacePose> {
        self.place.get(fi)
    }

    /// The centre of mass the peel model reads (part frame, m): see the field.
    pub fn peel_com_m(&self) -> Vector3<f64> {
        self.peel_com_m
    }

    /// Whether the cloud stands above the face anywhere over it: a cell whose centre lies on the
    /// face (shrunk by half a cell) higher than the face's plane there by
    /// more than [`COVER_TOLERANCE_M`]. `face_point_tray` is the face point under the cup (tray
    /// frame, its height measured). Unseen cells say nothing here (the planner treats them as
    /// occupied).
    fn covered(&self, height_map: &HeightMap, det: &Detection, face: &Face, face_point_tray: &Vector3<f64>) -> bool {
        let tray_from_part = self.pick_walls.world_from_tray.inverse() * det.world_from_part;
        let n = tray_from_part.rotation * face.normal;
        if n.z < 0.5 {
            return false;
        }
        let u_dir = tray_from_part.rotation * face.along;
        let v_dir = n.cross(&u_dir);
        // Only the cells whose centres lie on the face: a part resting on its rim or a corner
        // loads the seal as much as one on its middle, and more the farther from the cup.
        let shrink = 0.5 * height_map.cell_m;
        let half = [face.extent_m[0] / 2.0 - shrink, face.extent_m[1] / 2.0 - shrink];
        if half[0] <= 0.0 || half[1] <= 0.0 {
            return false;
        }
        // The face's centre (tray frame) on the plane through the measured point.
        let centre = {
            let c = tray_from_part * Point3::from(face.center);
            let dz =
                face_point_tray.z - (c.z - (n.x * (face_point_tray.x - c.x) + n.y * (face_point_tray.y - c.y)) / n.z);
            Vector3::new(c.x, c.y, c.z + dz)
        };
        let reach = [
            u_dir.x.abs() * half[0] + v_dir.x.abs() * half[1],
            u_dir.y.abs() * half[0] + v_dir.y.abs() * half[1],
        ];
        let cell = height_map.cell_m;
        let [ox, oy] = height_map.origin_xy_m;
        let i0 = (((centre.x - reach[0] - ox) / cell).floor().max(0.0)) as usize;
        let j0 = (((centre.y - reach[1] - oy) / cell).floor().max(0.0)) as usize;
        let i1 = ((((centre.x + reach[0] - ox) / cell).ceil()) as usize).min(height_map.nx);
        let j1 = ((((centre.y + reach[1] - oy) / cell).ceil()) as usize).min(height_map.ny);
        for j in j0..j1 {
            for i in i0..i1 {
                let h = height_map.height_m[j * height_map.nx + i];
                if !h.is_finite() {
                    continue;
                }
                let dx = ox + (i as f64 + 0.5) * cell - centre.x;
                let dy = oy + (j as f64 + 0.5) * cell - centre.y;
                // The face's plane above the cell, and the cell's position on the face.
                let dz = -(n.x * dx + n.y * dy) / n.z;
                let d = Vector3::new(dx, dy, dz);
                if d.dot(&u_dir).abs() > half[0] || d.dot(&v_dir).abs() > half[1] {
                    continue;
                }
                if h > centre.z + dz + COVER_TOLERANCE_M {
                    return true;
                }
            }
        }
        false
    }

    /// Estimated time of a joint move at top speed and half the specification acceleration (s).
    pub fn motion_time_s(&self, a: &JointVector, b: &JointVector) -> f64 {
        (0..6)
            .map(|i| {
                let j = &self.robot.joints[i];
                joint_move_s(b[i] - a[i], j.max_vel_rad_s, 0.5 * j.max_accel_rad_s2)
            })
            .fold(0.0, f64::max)
    }

    /// What the plans let the part ask of the cup with the tool at `world_from_tool` and the part
    /// recognised at `world_from_part`: [`crate::geometry::SealBudget::planned`] with the part's
    /// mass, the centre of mass the peel model reads where the recognition puts it, and three
    /// standard deviations of the recognition's position noise. The controller's budget for the
    /// chosen grasp, and the one each candidate's carry is ranked by.
    pub fn seal_budget(
        &self,
        world_from_tool: &Isometry3<f64>,
        world_from_part: &Isometry3<f64>,
    ) -> crate::geometry::SealBudget {
        let tool_from_part = world_from_tool.inverse() * world_from_part;
        crate::geometry::SealBudget::planned(
            self.suction,
            self.mass_kg,
            (tool_from_part * Point3::from(self.peel_com_m)).coords,
            self.com_uncertainty_m,
        )
    }

    /// The uniform time scale (1: full speed) by which the controller's seal budget will slow
    /// the carry of candidate `c` on detection `det`: [`crate::trajectory::limit_tool_force`]
    /// on the joint move from its lifted pose to its place pose, at the speeds and accelerations
    /// [`Self::motion_time_s`] assumes, the part's centre of mass where the detection puts it
    /// ([`crate::geometry::SealBudget::planned`], as the controller reads it). A part held with
    /// its centre of mass far below or beside the lip is carried slower.
    fn carry_time_scale(&self, det: &Detection, c: &GraspCandidate) -> f64 {
        let seal = self.seal_budget(&c.world_from_tool, &det.world_from_part);
        let limits = crate::trajectory::MotionLimits {
            vel_rad_s: JointVector::from_fn(|i, _| self.robot.joints[i].max_vel_rad_s),
            accel_rad_s2: JointVector::from_fn(|i, _| 0.5 * self.robot.joints[i].max_accel_rad_s2),
        };
        let via = [JointVector::from(c.q_lifted), JointVector::from(c.q_place)];
        crate::trajectory::limit_tool_force(&self.robot, &via, &limits, &seal).1
    }

    /// Proposes, filters and ranks grasps on `detections`, to be placed at `world_from_slot`
    /// (the part's upright pose in its slot), starting from joints `q_now`.
    pub fn select(
        &self,
        detections: &[Detection],
        height_map: &HeightMap,
        world_from_slot: &Isometry3<f64>,
        q_now: &JointVector,
    ) -> GraspPlan {
        let mut plan = GraspPlan {
            ranked: Vec::new(),
            rejected: Vec::new(),
        };
        let tray_from_world = self.pick_walls.world_from_tray.inverse();
        let floor_z = self.pick_walls.world_from_tray.translation.vector.z;
        let pile_top = height_map
            .height_m
            .iter()
            .cloned()
            .filter(|h| h.is_finite())
            .fold(0.0, f64::max)
            .max(1e-3);
        let need = 2.0 * (self.cup_radius_m + self.face_margin_m);
        // The collision decisions (crowding under the cup and the body, the clear height of the
        // approach, the free radius) read the map with its unseen cells occupied: a hole in the
        // map is not free space. The face height is measured on what was seen only.
        let occupied = height_map.unseen_filled(self.pick_walls.inner_half_m, self.pick_walls.rim_height_m);
        for (di, det) in detections.iter().enumerate() {
            let counted = plan.rejected.len() + plan.ranked.len();
            // How hemmed in the part is: the part's, not a face's; read once it has a candidate.
            let mut hemmed = None;
            for (fi, face) in self.faces.iter().enumerate() {
                let n = det.world_from_part.rotation * face.normal;
                let tilt = n.z.clamp(-1.0, 1.0).acos();
                if tilt > self.max_lean_rad {
                    // Faces pointing sideways or down are not candidates at all; only count the
                    // ones that face up, within 60 deg, but too steeply for the cup.
                    if tilt < std::f64::consts::FRAC_PI_3 {
                        plan.rejected.push((di, fi, Rejection::FaceTilted));
                    }
                    continue;
                }
                let (site, site_clearance) = self.sites[fi];
                // A face takes the cup where its cup-fit region (cup radius and the workpiece's
                // face margin) holds the site.
                // Where the recognised pose is off, the lip may overhang the edge: the plant's
                // seal probes decide, and the pick counts as a grasp failure.
                let (too_small, width) = (
                    site_clearance < self.cup_radius_m + self.fit_margin_m,
                    2.0 * site_clearance,
                );
                if too_small {
                    plan.rejected.push((di, fi, Rejection::FaceTooSmall));
                    continue;
                }
                let mut point = det.world_from_part * Point3::from(site);
                let mut local = tray_from_world * point;
                // Correct the recognised face height by the surface the sensor measured under the
                // cup, its cells within 3 mm of the recognised height (robust to depth noise and
                // to neighbouring surfaces): the cup goes to the surface their points' mean
                // heights give; what lies on or beside the face is judged against the median of
                // their highest points, as the other cells hold theirs.
                let expected = local.z;
                let surface = height_map.surface_within(local.x, local.y, self.cup_radius_m, expected, 0.003);
                if surface.is_finite() {
                    point.z += surface - expected;
                }
                let top = height_map.top_within(local.x, local.y, self.cup_radius_m, expected, 0.003);
                if top.is_finite() {
                    local.z = top;
                }
                let face_h = local.z;
                // A face tilted beyond what a cup coming straight down seals on is approached
                // along its normal, the tool leaning with it.
                let approach_dir = if tilt > self.max_tilt_rad { n } else { Vector3::z() };
                // Clearance from the cloud: nothing higher than the face (plus noise) under the
                // cup, nothing higher than the cup's top under the tool body, along the approach.
                let tray_from_part = tray_from_world * det.world_from_part;
                let axis_tray = tray_from_world.rotation * approach_dir;
                if self.crowded(&occupied, &tray_from_part, fi, &local, &axis_tray) {
                    plan.rejected.push((di, fi, Rejection::Crowded));
                    continue;
                }
                if self.covered(height_map, det, face, &local.coords) {
                    plan.rejected.push((di, fi, Rejection::Covered));
                    continue;
                }
                let clearance = self.clearance_radius(&occupied, local.x, local.y, face_h);
                // Tray walls: the tool's axis from the face up past the rim, at each height its
                // radius (cup near the lip, body above) inside the inner walls.
                if !self.clear_of_walls(&self.pick_walls, &point.coords, &(-n)) {
                    plan.rejected.push((di, fi, Rejection::TrayWall));
                    continue;
                }
                // The approach pose also lifts the part clear of the pile around it: its bottom
                // (its height along the face normal below the face) 15 mm above the highest surface
                // within half its length plus 10 mm.
                let half_length = 0.5 * self.size_m.iter().cloned().fold(0.0, f64::max);
                let hang = self.size_m[face.normal.iamax()];
                let around = occupied.max_within(local.x, local.y, half_length + 0.01);
                let clear_z = if around.is_finite() {
                    self.pick_walls.world_from_tray.translation.vector.z + around + hang + 0.015
                } else {
                    f64::NEG_INFINITY
                };
                let at = FacePoint {
                    point: point.coords,
                    normal: n,
                    clear_z,
                    approach_dir,
                };
                match self.best_yaw(det, fi, &at, world_from_slot, q_now) {
                    Ok(mut c) => {
                        c.detection = di;
                        c.face = fi;
                        let com = (det.world_from_part * Point3::from(self.peel_com_m)).coords;
                        let lateral = {
                            let r = com - point.coords;
                            (r - n * r.dot(&n)).norm()
                        };
                        let margin = ((width - need) / need).clamp(0.0, 1.0);
                        let success = tilt.cos()
                            * (0.5 + 0.5 * margin)
                            * (1.0 / (1.0 + 20.0 * lateral))
                            * (0.5 + 0.5 * det.visible_fraction);
                        let exposure =
                            ((point.z - floor_z) / pile_top).clamp(0.0, 1.0) * 0.5 + 0.5 * det.visible_fraction;
                        let motion = self.motion_time_s(&JointVector::from(c.q_grasp), &JointVector::from(c.q_place))
                            / self.carry_time_scale(det, &c);
                        let cl = clearance.min(0.02);
                        c.score = Score {
                            exposure,
                            clearance_m: cl,
                            success,
                            motion_s: motion,
                            total: exposure + cl / 0.02 + 2.0 * success - motion,
                            hemmed: *hemmed.get_or_insert_with(|| self.hemmed(height_map, &tray_from_part)),
                        };
                        plan.ranked.push(c);
                    }
                    Err(why) => plan.rejected.push((di, fi, why)),
                }
            }
            if plan.rejected.len() + plan.ranked.len() == counted {
                plan.rejected.push((di, 0, Rejection::NoFaceUp));
            }
        }
        plan.ranked.sort_by(|a, b| {
            b.score
                .total
                .total_cmp(&a.score.total)
                .then(a.detection.cmp(&b.detection))
        });
        plan
    }

    /// Whether the map `hm` (tray frame, unseen cells filled) shows something in the tool's way
    /// at the cup site `site` (tray frame; its height is the face's), the tool coming down along
    /// `axis` (tray frame, unit, upward): higher than the face plus the height tolerance within
    /// the cup's radius plus 1 mm, or than the cup's top within the tool body's radius plus
    /// 2 mm, both along the axis. What the recognised part's own features beside face `fi` (at
    /// `tray_from_part`) explain is not in the way: the cup site keeps the tool clear of them
    /// (pins, legs, a tab), and a fine enough map shows them beside the face.
    fn crowded(
        &self,
        hm: &HeightMap,
        tray_from_part: &Isometry3<f64>,
        fi: usize,
        site: &Point3<f64>,
        axis: &Vector3<f64>,
    ) -> bool {
        let face_h = site.z;
        let leaning = axis.z < 1.0 - 1e-12;
        // How far from the site the tool's column reaches over the pile (m): straight down, its
        // body's radius; leaning, as far as it leans over the rim's height.
        let lean_reach_m = if leaning {
            let up_m = (self.pick_walls.rim_height_m + self.approach_above_rim_m - face_h).max(0.0);
            up_m * (1.0 - axis.z * axis.z).sqrt() / axis.z
        } else {
            0.0
        };
        let in_way =
            |explained: &dyn Fn(usize, f64) -> bool| self.in_tools_way(hm, site, axis, lean_reach_m, explained);
        // The part's own surface is rendered only where the map alone says crowded.
        in_way(&|_, _| false) && {
            let own = self.own_heights(hm, tray_from_part, fi, site, lean_reach_m);
            in_way(&|k, h| own.get(&k).is_some_and(|o| h <= o + OWN_EXPLAINS_M))
        }
    }

    /// Whether a cell of `hm` (tray frame) not `explained` has its column (from the tray floor
    /// up to its height, at its centre) inside the tool coming down along `axis` (tray frame,
    /// unit, upward) onto the cup site `site`: within the cup's radius plus 1 mm of the axis and
    /// more than the height tolerance above the site along it, or within the body's radius plus
    /// 2 mm and above the cup's top less the tolerance, a cell's reach included. Straight down
    /// (`axis` vertical) that is a cell higher than the face plus the tolerance within the cup's
    /// reach, or than the cup's top within the body's; leaning, the same cylinders turned with
    /// the tool. Cells up to `lean_reach_m` beyond the body's radius from the site are looked at.
    fn in_tools_way(
        &self,
        hm: &HeightMap,
        site: &Point3<f64>,
        axis: &Vector3<f64>,
        lean_reach_m: f64,
        explained: &dyn Fn(usize, f64) -> bool,
    ) -> bool {
        let cell_reach_m = hm.cell_m * 0.71;
        let zones = [
            (self.height_tolerance_m, self.cup_radius_m + 0.001 + cell_reach_m),
            (
                self.cup_length_m - self.height_tolerance_m,
                self.tool_radius_m + 0.002 + cell_reach_m,
            ),
        ];
        // Along the column, the offset from the axis is r0 + z w (z the height above the floor).
        let w = Vector3::z() - axis * axis.z;
        let ww = w.norm_squared();
        let reach_m = self.tool_radius_m + 0.002 + cell_reach_m + lean_reach_m;
        hm.cells_at_within(site.x, site.y, reach_m)
            .filter(|&(k, _, h)| !h.is_nan() && !explained(k, h))
            .any(|(_, [cx, cy], h)| {
                let d0 = Vector3::new(cx - site.x, cy - site.y, -site.z);
                let a0 = d0.dot(axis);
                let r0 = d0 - axis * a0;
                zones.iter().any(|&(a_min_m, radius_m)| {
                    // The column's part above a_min_m along the axis: z from z_lo to h.
                    let z_lo = ((a_min_m - a0) / axis.z).max(0.0);
                    if z_lo > h {
                        return false;
                    }
                    let z = if ww > 1e-12 {
                        (-r0.dot(&w) / ww).clamp(z_lo, h)
                    } else {
                        z_lo
                    };
                    (r0 + w * z).norm_squared() < radius_m * radius_m
                })
            })
    }

    /// The highest point of the part's own features beside face `fi` (standing out of its
    /// plane: pins, legs, a tab; not the face itself, whose tilt the tilt limit judges), at the
    /// recognised pose `tray_from_part`, in each cell of `hm` within the tool's reach of the site
    /// `site` (tray frame), `lean_reach_m` farther where the tool leans (m, by cell index).
    fn own_heights(
        &self,
        hm: &HeightMap,
        tray_from_part: &Isometry3<f64>,
        fi: usize,
        site: &Point3<f64>,
        lean_reach_m: f64,
    ) -> std::collections::HashMap<usize, f64> {
        let reach_m = self.tool_radius_m + 0.002 + 2.0 * hm.cell_m + lean_reach_m;
        let mut own = std::collections::HashMap::new();
        for p in &self.own_features_m[fi] {
            let q = tray_from_part * p;
            if (q.x - site.x).hypot(q.y - site.y) > reach_m {
                continue;
            }
            if let Some(k) = hm.index(q.x, q.y) {
                let h = own.entry(k).or_insert(f64::NEG_INFINITY);
                *h = h.max(q.z);
            }
        }
        own
    }

    /// How hemmed in by its neighbours the map `hm` (tray frame, what was seen) shows a part
    /// recognised at `tray_from_part`: over the seen cells inside the walls whose centres lie
    /// within [`HEM_RING_M`] outside its outline (its bounding box at that pose, seen from
    /// above), each cell's height above the part's lowest corner in the part's height there
    /// (its highest corner's less its lowest's), f; `hemmed` = 4 x the share of those cells with
    /// f above 1/2, plus how far the highest f exceeds 0.8 (f capped at 1.5). A neighbour
    /// standing up the part's side, or leaning on it, loads the cup as the part is lifted out
    /// past it (`gripper.seal_loaded_by_parts`); a part on top of the pile or beside only lower
    /// ones scores 0, as one where nothing beside it was seen. The weights were chosen on A's
    /// drops with every lift at the cell's acceleration (docs/model.md, "The cell cycle").
    pub fn hemmed(&self, hm: &HeightMap, tray_from_part: &Isometry3<f64>) -> f64 {
        let half_m = Vector3::from(self.size_m) / 2.0;
        let corners: Vec<Point3<f64>> = (0..8)
            .map(|i| {
                let sign = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
                tray_from_part * Point3::new(sign(1) * half_m.x, sign(2) * half_m.y, sign(4) * half_m.z)
            })
            .collect();
        let low_m = corners.iter().map(|c| c.z).fold(f64::INFINITY, f64::min);
        let height_m = corners.iter().map(|c| c.z).fold(f64::NEG_INFINITY, f64::max) - low_m;
        let outline = crate::geometry::convex_hull_2d(&corners.iter().map(|c| [c.x, c.y]).collect::<Vec<_>>());
        let centre = tray_from_part.translation.vector;
        let reach_m = half_m.norm() + HEM_RING_M + hm.cell_m;
        let inner = self.pick_walls.inner_half_m;
        let (mut ring, mut up, mut highest) = (0usize, 0usize, 0.0f64);
        for (_, [x, y], h) in hm.cells_at_within(centre.x, centre.y, reach_m) {
            if h.is_nan() || x.abs() > inner[0] || y.abs() > inner[1] {
                continue;
            }
            let out_m = crate::geometry::outside_convex_m(&outline, [x, y]);
            if out_m <= 0.5 * hm.cell_m || out_m > HEM_RING_M + 0.5 * hm.cell_m {
                continue;
            }
            let f = ((h - low_m) / height_m.max(1e-4)).clamp(0.0, 1.5);
            ring += 1;
            up += usize::from(f > 0.5);
            highest = highest.max(f);
        }
        if ring == 0 {
            return 0.0;
        }
        4.0 * up as f64 / ring as f64 + (highest - 0.8).max(0.0)
    }

    /// Free radius around (x, y) in the tray frame: distance to the nearest cell higher than the
    /// face (plus tolerance), up to 20 mm (m).
    fn clearance_radius(&self, hm: &HeightMap, x: f64, y: f64, face_h: f64) -> f64 {
        let mut r = self.cup_radius_m + 0.001;
        while r < 0.02 {
            let h = hm.max_within(x, y, r);
            if h > face_h + self.height_tolerance_m {
                return r;
            }
            r += hm.cell_m;
        }
        0.02
    }

    /// Whether the tool's axis from the lip at `point` (world), pointing along `axis` (the tool's
    /// z, into the part), with the cup's radius near the lip and the body's above, stays inside
    /// the walls up to 1 cm above their rim.
    fn clear_of_walls(&self, walls: &Walls, point: &Vector3<f64>, axis: &Vector3<f64>) -> bool {
        let tray_from_world = walls.world_from_tray.inverse();
        let p = tray_from_world * Point3::from(*point);
        let a = tray_from_world.rotation * axis;
        // Walk up the tool axis (against `a`) from the lip to 1 cm above the rim.
        let mut s = 0.0;
        while s < 0.25 {
            let q = p.coords - a * s;
            if q.z > walls.rim_height_m + 0.01 {
                return true;
            }
            let radius = if s < self.cup_length_m {
                self.cup_radius_m
            } else {
                self.tool_radius_m
            };
            if q.x.abs() + radius > walls.inner_half_m[0] || q.y.abs() + radius > walls.inner_half_m[1] {
                return false;
            }
            s += 0.002;
        }
        true
    }

    /// The joints at `to` at the end of the straight tool line from `from` (joints `q_from`),
    /// if the line has a continuous joint path: IK in 6 steps along it, no joint moving more
    /// than 0.3 rad in a step.
    fn straight_joint_path(
        &self,
        from: &Isometry3<f64>,
        to: &Isometry3<f64>,
        q_from: JointVector,
    ) -> Option<JointVector> {
        let mut q = q_from;
        for s in 1..=6 {
            let pose = from.lerp_slerp(to, s as f64 / 6.0);
            match self.robot.ik_tool_nearest(&pose, &q) {
                Ok(sol) if (sol.q - q).amax() < 0.3 => q = sol.q,
                _ => return None,
            }
        }
        Some(q)
    }

    /// For the four tool yaws about the face normal, the reachable one with the quickest place
    /// motion (ties: the first). The descent is checked for a continuous joint path, and the tool
    /// at the place pose for the place tray's walls (a tool tilted over a slot by the wall, as a
    /// can set down lying in a tilted stable pose holds it, would touch it). Why none is, when
    /// none is: [`Rejection::PlaceTrayWall`] when the place tray's walls ruled out every turn of
    /// the part in its slot, else [`Rejection::Unreachable`].
    fn best_yaw(
        &self,
        det: &Detection,
        fi: usize,
        at: &FacePoint,
        world_from_slot: &Isometry3<f64>,
        q_now: &JointVector,
    ) -> Result<GraspCandidate, Rejection> {
        let mut walled = false;
        let face = &self.faces[fi];
        let (point, clear_z) = (&at.point, at.clear_z);
        let z_tool = -at.normal;
        let along_world = det.world_from_part.rotation * face.along;
        let x0 = (along_world - z_tool * along_world.dot(&z_tool))
            .try_normalize(1e-9)
            .ok_or(Rejection::Unreachable)?;
        let floor_z = world_from_slot.translation.z - self.size_m[2] / 2.0;
        // The part rests in its slot in the stable pose with this face up, turned to the slot's
        // yaw (every offered face has one).
        let place = self.place_pose(fi).ok_or(Rejection::Unreachable)?;
        let (slot_rot, origin_height) = (world_from_slot.rotation * place.slot_from_part, place.origin_height_m);
        let part_center_in_slot = Vector3::new(
            world_from_slot.translation.x,
            world_from_slot.translation.y,
            floor_z + origin_height + 0.0005,
        );
        let mut best: Option<(f64, GraspCandidate)> = None;
        for k in 0..4 {
            let yaw = k as f64 * std::f64::consts::FRAC_PI_2;
            let x = UnitQuaternion::from_axis_angle(&Unit::new_normalize(z_tool), yaw) * x0;
            let rot = tool_rotation(&x, &z_tool);
            let grasp = Isometry3::from_parts(Translation3::from(*point), rot);
            let top_z = (self.pick_walls.world_from_tray.translation.z
                + self.pick_walls.rim_height_m
                + self.approach_above_rim_m)
                .max(clear_z);
            // Straight down onto the face and straight up with the part, whatever the face's tilt
            // up to the cup's (a part lying against a wall slides up along it, not into it);
            // along the normal of a face tilted further.
            let rise = ((top_z - point.z) / at.approach_dir.z).max(0.02);
            let approach = Isometry3::from_parts(Translation3::from(point + at.approach_dir * rise), rot);
            let Ok(qa) = self.robot.ik_tool_nearest(&approach, q_now).map(|sol| sol.q) else {
                return Err(Rejection::Unreachable);
            };
            // The straight descent.
            let Some(qg) = self.straight_joint_path(&approach, &grasp, qa) else {
                continue;
            };
            // The lift with the part: straight up, also from a face approached along its normal.
            let (lifted, q_lifted) = if at.approach_dir.z < 1.0 {
                let rise = (top_z - point.z).max(0.02);
                let lifted = Isometry3::from_parts(Translation3::from(point + Vector3::z() * rise), rot);
                let Some(q) = self.straight_joint_path(&grasp, &lifted, qg) else {
                    continue;
                };
                (lifted, q)
            } else {
                (approach, qa)
            };
            // Where the tool is when the part sits in its slot.
            let part_from_tool = det.world_from_part.inverse() * grasp;
            let part_in_slot = Isometry3::from_parts(Translation3::from(part_center_in_slot), slot_rot);
            // The part keeps its pose relative to the tool; its yaw in the slot may differ by
            // any multiple of its symmetry: pick the tool pose among those nearest in J6.
            let mut place_best: Option<(f64, Isometry3<f64>, Isometry3<f64>, JointVector)> = None;
            let sym = if self.yaw_symmetry_rad > 0.0 {
                self.yaw_symmetry_rad
            } else {
                std::f64::consts::FRAC_PI_2
            };
            let turns = (std::f64::consts::TAU / sym).round().max(1.0) as usize;
            for t in 0..turns {
                let spin = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), t as f64 * sym);
                let placed = Isometry3::from_parts(part_in_slot.translation, spin * part_in_slot.rotation);
                let tool = placed * part_from_tool;
                let tool_z = tool.rotation * Vector3::z();
                if !self.clear_of_walls(&self.place_walls, &tool.translation.vector, &tool_z) {
                    walled = true;
                    continue;
                }
                if let Ok(sol) = self.robot.ik_tool_nearest(&tool, &qg) {
                    let time = self.motion_time_s(&qg, &sol.q);
                    if place_best.as_ref().is_none_or(|(bt, ..)| time < *bt) {
                        place_best = Some((time, tool, placed, sol.q));
                    }
                }
            }
            // (No place for this yaw ends the search: the tool's axis at the place, the walls'
            // concern, is the same for every yaw about it.)
            let Some((time, tool_place, part_place, qp)) = place_best else {
                return Err(if walled {
                    Rejection::PlaceTrayWall
                } else {
                    Rejection::Unreachable
                });
            };
            if best.as_ref().is_none_or(|(bt, _)| time < *bt) {
                best = Some((
                    time,
                    GraspCandidate {
                        detection: 0,
                        face: 0,
                        world_from_tool: grasp,
                        world_from_tool_approach: approach,
                        world_from_tool_lifted: lifted,
                        world_from_tool_place: tool_place,
                        world_from_part_place: part_place,
                        lean_rad: (at.approach_dir.z < 1.0).then(|| at.approach_dir.z.clamp(-1.0, 1.0).acos()),
                        q_approach: qa.into(),
                        q_grasp: qg.into(),
                        q_lifted: q_lifted.into(),
                        q_place: qp.into(),
                        score: Score {
                            exposure: 0.0,
                            clearance_m: 0.0,
                            success: 0.0,
                            motion_s: time,
                            total: 0.0,
                            hemmed: 0.0,
                        },
                    },
                ));
            }
        }
        best.map(|(_, c)| c).ok_or(Rejection::Unreachable)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LoadedWorkpiece;
    use crate::part::primitive::body_faces;

    #[test]
    fn faces_of_a_box_and_of_capacitors() {
        let b = LoadedWorkpiece::resolve("B").unwrap().workpiece;
        let f = body_faces(&b.pieces());
        assert_eq!(f.len(), 6);
        assert!(
            f.iter()
                .any(|f| f.normal == Vector3::z() && (f.center.z - 0.01).abs() < 1e-12 && f.extent_m == [0.03, 0.03])
        );
        let radial = LoadedWorkpiece::resolve(concat!(env!("CARGO_MANIFEST_DIR"), "/workpieces/capacitor-radial.toml"))
            .unwrap()
            .workpiece;
        let caps = body_faces(&radial.pieces());
        assert_eq!(
            caps.len(),
            1,
            "a can has two flat caps; its leads rule out the one they leave"
        );
        assert!(caps[0].disc && caps[0].normal == Vector3::z() && (caps[0].extent_m[0] - 0.01).abs() < 1e-12);
        // D: the can's top, the base's bottom and its four thin sides; not the faces in between.
        let d = body_faces(&LoadedWorkpiece::resolve("D").unwrap().workpiece.pieces());
        assert_eq!(d.len(), 6, "{d:?}");
        assert!(d.iter().any(|f| f.disc && f.normal == Vector3::z()));
        assert!(
            d.iter()
                .any(|f| !f.disc && f.normal == -Vector3::z() && (f.extent_m[0] - 0.0098).abs() < 1e-12)
        );
        assert!(!d.iter().any(|f| f.disc && f.normal == -Vector3::z()));
        assert!(!d.iter().any(|f| !f.disc && f.normal == Vector3::z()));
    }

    #[test]
    fn the_tool_rotation_of_a_half_turn_is_exact() {
        // Straight down with x along -x: a half turn about y from the identity.
        let (x, z) = (-Vector3::x(), -Vector3::z());
        let r = tool_rotation(&x, &z);
        let want = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI);
        assert!(r.angle_to(&want) < 1e-12, "{r:?}");
        assert!((r * Vector3::x() - x).norm() < 1e-12 && (r * Vector3::z() - z).norm() < 1e-12);
        // Negative control: the iteration from the identity, bounded to 1000 steps, does not
        // reach it (unbounded, as `from_matrix` runs it, it never returned).
        let m = nalgebra::Matrix3::from_columns(&[x, z.cross(&x), z]);
        let it = nalgebra::Rotation3::from_matrix_eps(&m, f64::EPSILON, 1000, nalgebra::Rotation3::identity());
        assert!(
            UnitQuaternion::from_rotation_matrix(&it).angle_to(&want) > 1.0,
            "{it:?}"
        );
    }

    /// `grasp.place_orientation = "upright"` offers only the faces that are up when the part
    /// rests on its -z side, up to its symmetry: A's top (its half turn keeps its pins down),
    /// B's top and bottom (the block looks the same flipped), none of their sides. The control:
    /// with `any`, every face that takes the cup is offered, sides included.
    #[test]
    fn upright_placing_offers_only_the_faces_up_in_the_upright_pose() {
        let robot = crate::robot::test_support::default_robot();
        let offered = |name: &str, orientation: PlaceOrientation| {
            let mut wp = LoadedWorkpiece::resolve(name).unwrap();
            wp.workpiece.grasp.place_orientation = orientation;
            let scene = crate::config::LoadedScene::embedded_default()
                .unwrap()
                .for_workpiece(&wp);
            let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &wp);
            let mut normals: Vec<[i32; 3]> = sel
                .faces()
                .iter()
                .map(|f| f.normal.map(|v| v.round() as i32).into())
                .collect();
            normals.sort_unstable();
            (normals, sel.not_upright_faces())
        };
        assert_eq!(offered("A", PlaceOrientation::Upright), (vec![[0, 0, 1]], 5));
        assert_eq!(
            offered("B", PlaceOrientation::Upright),
            (vec![[0, 0, -1], [0, 0, 1]], 4)
        );
        for name in ["A", "B"] {
            let (any, dropped) = offered(name, PlaceOrientation::Any);
            assert_eq!((any.len(), dropped), (6, 0), "{name}: {any:?}");
        }
    }

    /// The tool at a place pose must clear the place tray's walls: straight down 20 mm from the
    /// +x wall it does (its body, 15 mm, stays inside); tilted 20 deg toward the wall at the
    /// same point, its body leans into it above the part. Control: the same tilt away from the
    /// wall is clear.
    #[test]
    fn a_tool_tilted_over_a_slot_by_the_wall_meets_the_place_tray() {
        let scene = crate::config::LoadedScene::embedded_default().unwrap();
        let robot = crate::robot::test_support::default_robot();
        let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &LoadedWorkpiece::resolve("E").unwrap());
        let walls = sel.place_walls;
        let near_wall = walls.world_from_tray * Point3::new(walls.inner_half_m[0] - 0.02, 0.0, 0.005);
        let down = walls.world_from_tray.rotation * -Vector3::z();
        assert!(sel.clear_of_walls(&walls, &near_wall.coords, &down));
        // Tilted: the tool's z (into the part) leans away from the wall at the lip, so its body
        // above leans toward the wall.
        let toward = walls.world_from_tray.rotation * Vector3::x();
        let tilt = |sign: f64| {
            UnitQuaternion::from_axis_angle(
                &Unit::new_normalize(walls.world_from_tray.rotation * Vector3::y()),
                sign * 20f64.to_radians(),
            ) * down
        };
        let (a, b) = (tilt(1.0), tilt(-1.0));
        let (into, away) = if a.dot(&toward) < 0.0 { (a, b) } else { (b, a) };
        assert!(!sel.clear_of_walls(&walls, &near_wall.coords, &into));
        assert!(sel.clear_of_walls(&walls, &near_wall.coords, &away));
    }

    /// A DIP-8 lying on its top, legs up, at the tray's centre, on a map of the cell's 2 mm
    /// cells rendered from its mesh apart from the selector's code (8 x 8 points per cell, each
    /// the highest triangle over it): its legs stand 3.4 mm above its back, 3.8 mm either side of
    /// the cup site, within the cup's reach on that map. They are the part's own: not crowding.
    /// Controls: read as the map alone, the legs crowd the cup; something resting on the legs,
    /// 3 mm above them, still does.
    #[test]
    fn a_parts_own_legs_beside_the_cup_do_not_crowd_it_and_what_rests_on_them_does() {
        let scene = crate::config::LoadedScene::embedded_default().unwrap();
        let robot = crate::robot::test_support::default_robot();
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/workpieces/dip8.toml");
        let wp = LoadedWorkpiece::resolve(path).unwrap();
        let scene = scene.for_workpiece(&wp);
        let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &wp);
        let mesh = &wp.mesh.as_ref().unwrap().0;
        // On its top (the part's +z side down), legs up: a half turn about x, lifted so the
        // lowest point rests on the floor.
        let turn = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let low = mesh
            .vertices_m
            .iter()
            .map(|v| (turn * v).z)
            .fold(f64::INFINITY, f64::min);
        let tray_from_part = Isometry3::from_parts(Translation3::new(0.0, 0.0, -low), turn);
        let corners: Vec<[Point3<f64>; 3]> = (0..mesh.triangles.len())
            .map(|k| mesh.corners(k).map(|c| tray_from_part * c))
            .collect();
        let top_at = |x: f64, y: f64| {
            corners
                .iter()
                .filter_map(|[a, b, c]| {
                    let d = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
                    if d.abs() < 1e-18 {
                        return None;
                    }
                    let u = ((x - a.x) * (c.y - a.y) - (c.x - a.x) * (y - a.y)) / d;
                    let v = ((b.x - a.x) * (y - a.y) - (x - a.x) * (b.y - a.y)) / d;
                    (u >= 0.0 && v >= 0.0 && u + v <= 1.0).then(|| a.z + u * (b.z - a.z) + v * (c.z - a.z))
                })
                .fold(0.0, f64::max)
        };
        let cell = crate::pipeline::HEIGHT_MAP_CELL_M;
        let n = 30;
        let mut map = HeightMap {
            world_from_tray: sel.pick_walls.world_from_tray,
            cell_m: cell,
            nx: n,
            ny: n,
            origin_xy_m: [-0.5 * n as f64 * cell; 2],
            height_m: vec![0.0; n * n],
            mean_m: None,
        };
        for j in 0..n {
            for i in 0..n {
                let (x0, y0) = (
                    map.origin_xy_m[0] + i as f64 * cell,
                    map.origin_xy_m[1] + j as f64 * cell,
                );
                let mut h: f64 = 0.0;
                for a in 0..8 {
                    for b in 0..8 {
                        h = h.max(top_at(
                            x0 + (a as f64 + 0.5) * cell / 8.0,
                            y0 + (b as f64 + 0.5) * cell / 8.0,
                        ));
                    }
                }
                map.height_m[j * n + i] = h;
            }
        }
        // The back face (the part's -z side) up, and its cup site.
        let fi = sel.faces().iter().position(|f| f.normal == -Vector3::z()).unwrap();
        let site = tray_from_part * Point3::from(sel.sites[fi].0);
        let legs_m = map.height_m.iter().cloned().fold(0.0, f64::max) - site.z;
        assert!(legs_m > 0.003, "the legs stand {legs_m} m above the back");
        // Control: the map alone reads the legs as something in the cup's way.
        let away = Isometry3::translation(1.0, 0.0, 0.0) * tray_from_part;
        assert!(
            sel.crowded(&map, &away, fi, &site, &Vector3::z()),
            "the legs do not reach the cup's ring"
        );
        assert!(
            !sel.crowded(&map, &tray_from_part, fi, &site, &Vector3::z()),
            "the part's own legs crowd it"
        );
        // Negative control: something resting on the legs, 3 mm above them.
        let mut on_legs = map.clone();
        for h in on_legs.height_m.iter_mut() {
            if *h > site.z + 0.002 {
                *h += 0.003;
            }
        }
        assert!(
            sel.crowded(&on_legs, &tray_from_part, fi, &site, &Vector3::z()),
            "what rests on the legs is not seen"
        );
    }

    /// A C strip lying flat at the tray's centre, turned 30 deg, seen on a map of 1 mm cells:
    /// the selector, its top face, the detection, the map, and the strip's pose and size.
    fn bare_strip() -> (GraspSelector, Face, Detection, HeightMap, Isometry3<f64>, [f64; 3]) {
        let scene = crate::config::LoadedScene::embedded_default().unwrap();
        let robot = crate::robot::test_support::default_robot();
        let c = LoadedWorkpiece::resolve("C").unwrap().workpiece;
        let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &LoadedWorkpiece::resolve("C").unwrap());
        let top = sel.faces().iter().position(|f| f.normal == Vector3::z()).unwrap();
        let face = sel.faces()[top];
        let tray_from_part = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, c.size_m[2] / 2.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5),
        );
        let det = Detection {
            world_from_part: sel.pick_walls.world_from_tray * tray_from_part,
            visible_fraction: 1.0,
            score: 1.0,
            face_up: None,
        };
        let mut map = empty_map(&sel);
        raise(&mut map, &tray_from_part, c.size_m[2], |x, y| {
            x.abs() <= c.size_m[0] / 2.0 && y.abs() <= c.size_m[1] / 2.0
        });
        (sel, face, det, map, tray_from_part, c.size_m)
    }

    /// A relay (A, 20 x 30 x 10 mm) lying flat at the tray's centre, turned 30 deg, is hemmed in
    /// by what stands up its side in the cloud: nothing around it, 0; a neighbour 12 mm high
    /// along its long side, 1 mm off it, more than the cell's gate (its whole side, under a
    /// third of the outline, above its top). Controls: the same neighbour 5 mm off, beyond the
    /// ring; a lower one (3 mm, under its mid-height) right beside it: 0.
    #[test]
    fn a_part_with_a_neighbour_standing_up_its_side_is_hemmed_and_one_beside_low_ones_is_not() {
        let scene = crate::config::LoadedScene::embedded_default().unwrap();
        let robot = crate::robot::test_support::default_robot();
        let a = LoadedWorkpiece::resolve("A").unwrap();
        let sel = GraspSelector::for_workpiece(&scene.scene, &robot, &a);
        let size = a.workpiece.size_m;
        let tray_from_part = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, size[2] / 2.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5),
        );
        let (hx, hy) = (size[0] / 2.0, size[1] / 2.0);
        let mut alone = empty_map(&sel);
        raise(&mut alone, &tray_from_part, size[2], |x, y| {
            x.abs() <= hx && y.abs() <= hy
        });
        assert_eq!(sel.hemmed(&alone, &tray_from_part), 0.0);
        let beside = |gap_m: f64, height_m: f64| {
            let mut map = alone.clone();
            raise(&mut map, &tray_from_part, height_m, |x, y| {
                x > hx + gap_m && x < hx + gap_m + 0.01 && y.abs() <= hy
            });
            sel.hemmed(&map, &tray_from_part)
        };
        let gate = scene.scene.cycle.gentle_lift_hemmed.unwrap();
        let hemmed = beside(0.001, 0.012);
        assert!(hemmed > gate && hemmed < 4.0 / 3.0 + 0.7, "{hemmed}");
        assert_eq!(beside(0.005, 0.012), 0.0, "a neighbour beyond the ring");
        assert_eq!(beside(0.001, 0.003), 0.0, "a low neighbour");
    }

    /// A bare tray floor seen everywhere, 200 x 200 cells of 1 mm about the pick tray's centre.
    fn empty_map(sel: &GraspSelector) -> HeightMap {
        HeightMap {
            world_from_tray: sel.pick_walls.world_from_tray,
            cell_m: 0.001,
            nx: 200,
            ny: 200,
            origin_xy_m: [-0.1, -0.1],
            height_m: vec![0.0; 200 * 200],
            mean_m: None,
        }
    }

    /// Sets the map to `height_m` wherever `inside` holds for the cell centre in the part frame.
    fn raise(map: &mut HeightMap, tray_from_part: &Isometry3<f64>, height_m: f64, inside: impl Fn(f64, f64) -> bool) {
        let inverse = tray_from_part.inverse();
        for j in 0..map.ny {
            for i in 0..map.nx {
                let c = Point3::new(
                    map.origin_xy_m[0] + (i as f64 + 0.5) * map.cell_m,
                    map.origin_xy_m[1] + (j as f64 + 0.5) * map.cell_m,
                    0.0,
                );
                let p = inverse * c;
                if inside(p.x, p.y) {
                    map.height_m[j * map.nx + i] = height_m;
                }
            }
        }
    }

    #[test]
    fn a_strip_with_a_part_across_it_is_covered() {
        let (sel, face, det, mut map, tray_from_part, size) = bare_strip();
        let face_point = (tray_from_part * Point3::from(face.center)).coords;
        assert!(!sel.covered(&map, &det, &face, &face_point), "a bare strip is covered");
        // Negative control: a 10 mm part lying across the strip 55 mm from its centre.
        raise(&mut map, &tray_from_part, size[2] + 0.01, |x, y| {
            (x - 0.055).abs() <= 0.005 && y.abs() <= 0.02
        });
        assert!(
            sel.covered(&map, &det, &face, &face_point),
            "a part across the strip is not seen"
        );
    }

    /// A part resting on the strip's corner (2 x 2 mm of it, inside the face's grasp margin) covers
    /// it: lifted, the strip would carry that part's weight 75 mm from the cup. A part as high
    /// right beside the strip's end, off the face, does not (negative control).
    #[test]
    fn a_part_on_a_strips_corner_covers_it_and_one_beside_its_end_does_not() {
        let (sel, face, det, map, tray_from_part, size) = bare_strip();
        let face_point = (tray_from_part * Point3::from(face.center)).coords;
        let (hx, hy) = (size[0] / 2.0, size[1] / 2.0);
        let mut beside = map.clone();
        raise(&mut beside, &tray_from_part, size[2] + 0.005, |x, y| {
            x > hx + 0.0015 && x < hx + 0.02 && y.abs() <= 0.02
        });
        assert!(
            !sel.covered(&beside, &det, &face, &face_point),
            "a part beside the end covers it"
        );
        let mut corner = map;
        raise(&mut corner, &tray_from_part, size[2] + 0.005, |x, y| {
            x > hx - 0.002 && x < hx + 0.02 && y > hy - 0.002 && y < hy + 0.02
        });
        assert!(
            sel.covered(&corner, &det, &face, &face_point),
            "a part on the corner is not seen"
        );
    }

    /// A grasp's carry is ranked at the speed the controller's seal budget will leave it: the
    /// flat strip's best grasp carried at full speed when the strip weighs next to nothing (the
    /// control), slowed when it weighs 50 g (its centre of mass 2.5 mm below and up to a few
    /// millimetres beside the 6 mm cup), and its ranked motion time is the full-speed one over
    /// that time scale.
    #[test]
    fn a_carry_the_seal_will_slow_ranks_as_slow() {
        let (mut sel, _, det, map, _, _) = bare_strip();
        let scene = crate::config::LoadedScene::embedded_default().unwrap();
        let c = LoadedWorkpiece::resolve("C").unwrap().workpiece;
        let slot = scene.scene.world_from_slots(&c)[0];
        let q_now = JointVector::from(scene.scene.robot.home_rad());
        sel.mass_kg = 1e-4;
        let light = sel.select(std::slice::from_ref(&det), &map, &slot, &q_now);
        let best = light.best().expect("the flat strip is a candidate").clone();
        assert_eq!(sel.carry_time_scale(&det, &best), 1.0);
        sel.mass_kg = 0.050;
        let k = sel.carry_time_scale(&det, &best);
        assert!(k < 0.9, "a 50 g strip carried at {k} of full speed");
        let heavy = sel.select(std::slice::from_ref(&det), &map, &slot, &q_now);
        let same = heavy
            .ranked
            .iter()
            .find(|h| h.face == best.face && h.q_place == best.q_place)
            .expect("the same grasp is ranked");
        assert!((same.score.motion_s - best.score.motion_s / k).abs() < 1e-9);
    }

    /// A strip lying on its 5 mm side shows the cup no face within 60 deg of up: the plan
    /// says so ("no face up", once for the part) instead of naming no reason. The control: the
    /// same strip lying flat is a candidate, and no "no face up" is counted.
    #[test]
    fn a_part_with_no_face_up_is_named_as_such() {
        let (sel, _, det, map, _, _) = bare_strip();
        let scene = crate::config::LoadedScene::embedded_default().unwrap();
        let c = LoadedWorkpiece::resolve("C").unwrap().workpiece;
        let slot = scene.scene.world_from_slots(&c)[0];
        let q_now = JointVector::from(scene.scene.robot.home_rad());
        let flat = sel.select(std::slice::from_ref(&det), &map, &slot, &q_now);
        assert!(
            !flat.rejected_counts().contains_key("no face up"),
            "{:?}",
            flat.rejected
        );
        assert!(
            !flat.ranked.is_empty(),
            "the flat strip is not a candidate: {:?}",
            flat.rejected
        );
        let mut on_side = det;
        on_side.world_from_part.rotation *=
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2);
        let plan = sel.select(&[on_side], &map, &slot, &q_now);
        assert!(plan.ranked.is_empty());
        assert_eq!(plan.rejected_counts(), [("no face up", 1)].into_iter().collect());
        assert_eq!(
            crate::pipeline::why_none(&plan).to_string(),
            "no feasible grasp (no face up 1)"
        );
    }

    /// A strip leaning 35 deg about its long axis, its top face's grasp point at the tray's
    /// centre, on an otherwise empty map of 1 mm cells: the selector built for a cell whose tool
    /// leans up to `max_lean_deg` (`None`: straight down only), the detection, the map, the
    /// face's outward normal and its grasp point (tray frame).
    fn leaning_strip(max_lean_deg: Option<f64>) -> (GraspSelector, Detection, HeightMap, Vector3<f64>, Point3<f64>) {
        let mut scene = crate::config::LoadedScene::embedded_default().unwrap().scene;
        scene.gripper.max_lean_deg = max_lean_deg;
        let robot = crate::robot::test_support::default_robot();
        let c = LoadedWorkpiece::resolve("C").unwrap();
        let sel = GraspSelector::for_workpiece(&scene, &robot, &c);
        let top = sel.faces().iter().position(|f| f.normal == Vector3::z()).unwrap();
        let rot = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 35f64.to_radians());
        let site_part = Point3::from(sel.sites[top].0);
        // The part placed so that its grasp point lies over the tray's centre, 12 mm up.
        let site_tray = Point3::new(0.0, 0.0, 0.012);
        let tray_from_part = Isometry3::from_parts(Translation3::from(site_tray.coords - rot * site_part.coords), rot);
        let normal = rot * Vector3::z();
        let mut map = empty_map(&sel);
        let half = c.workpiece.size_m.map(|v| v / 2.0);
        let inverse = tray_from_part.inverse();
        for j in 0..map.ny {
            for i in 0..map.nx {
                let (x, y) = (
                    map.origin_xy_m[0] + (i as f64 + 0.5) * map.cell_m,
                    map.origin_xy_m[1] + (j as f64 + 0.5) * map.cell_m,
                );
                // The top face's plane over (x, y).
                let z = site_tray.z - (normal.x * (x - site_tray.x) + normal.y * (y - site_tray.y)) / normal.z;
                let p = inverse * Point3::new(x, y, z);
                if p.x.abs() <= half[0] && p.y.abs() <= half[1] {
                    map.height_m[j * map.nx + i] = z;
                }
            }
        }
        let det = Detection {
            world_from_part: sel.pick_walls.world_from_tray * tray_from_part,
            visible_fraction: 1.0,
            score: 1.0,
            face_up: None,
        };
        (sel, det, map, normal, site_tray)
    }

    /// A face tilted 35 deg, beyond the cup's 20: not taken by a tool that comes straight down
    /// (the control); taken by one that may lean 40 deg, coming down along the face's normal and
    /// lifting the part straight up.
    #[test]
    fn a_leaning_tool_takes_a_face_tilted_beyond_the_cup_along_its_normal() {
        let scene = crate::config::LoadedScene::embedded_default().unwrap();
        let c = LoadedWorkpiece::resolve("C").unwrap().workpiece;
        let slot = scene.scene.world_from_slots(&c)[0];
        let q_now = JointVector::from(scene.scene.robot.home_rad());
        let (straight, det, map, ..) = leaning_strip(None);
        let plan = straight.select(std::slice::from_ref(&det), &map, &slot, &q_now);
        assert!(plan.ranked.is_empty(), "{:?}", plan.ranked.first().map(|g| g.lean_rad));
        assert!(
            plan.rejected.iter().any(|(_, _, r)| *r == Rejection::FaceTilted),
            "{:?}",
            plan.rejected
        );
        let (leaning, det, map, normal, _) = leaning_strip(Some(40.0));
        let world_normal = leaning.pick_walls.world_from_tray.rotation * normal;
        let plan = leaning.select(std::slice::from_ref(&det), &map, &slot, &q_now);
        let g = plan.best().unwrap_or_else(|| panic!("no grasp: {:?}", plan.rejected));
        assert!(
            (g.lean_rad.unwrap().to_degrees() - 35.0).abs() < 0.5,
            "{:?}",
            g.lean_rad
        );
        let down = g.world_from_tool_approach.translation.vector - g.world_from_tool.translation.vector;
        assert!(down.normalize().dot(&world_normal) > 1.0 - 1e-9, "approach {down:?}");
        let up = g.world_from_tool_lifted.translation.vector - g.world_from_tool.translation.vector;
        assert!(up.normalize().z > 1.0 - 1e-9, "lift {up:?}");
        // The cup's axis along the face's normal, into it.
        assert!((g.world_from_tool.rotation * Vector3::z()).dot(&-world_normal) > 1.0 - 1e-9);
    }

    /// A 6 mm block 22 mm from the grasp point, beyond the straight-down test's reach (the body's
    /// 15 mm radius plus 2 mm), on the side the tool leans to crowds the leaning tool; on the
    /// side it leans away from it does not (the negative control).
    #[test]
    fn what_stands_where_the_tool_leans_crowds_it_and_behind_it_does_not() {
        let (sel, _, map, normal, site) = leaning_strip(Some(40.0));
        let toward = Vector3::new(normal.x, normal.y, 0.0).normalize();
        // The map with a 30 mm high block of 3 mm radius 22 mm from the site, on the side the
        // tool leans to (1) or away from it (-1).
        let with_block = |base: &HeightMap, side: f64| {
            let mut m = base.clone();
            let at = site.coords + toward * side * 0.022;
            let cells: Vec<usize> = base.cells_at_within(at.x, at.y, 0.003).map(|(k, ..)| k).collect();
            for k in cells {
                m.height_m[k] = 0.030;
            }
            m
        };
        // (The strip has no features above its top face: where it lies does not matter here.)
        let own = Isometry3::identity();
        let clear = |m: &HeightMap, axis: &Vector3<f64>| !sel.crowded(m, &own, 0, &site, axis);
        assert!(clear(&map, &normal), "the bare leaning strip crowds the tool");
        assert!(
            !clear(&with_block(&map, 1.0), &normal),
            "a block where the tool leans does not crowd it"
        );
        assert!(
            clear(&with_block(&map, -1.0), &normal),
            "a block behind the leaning tool crowds it"
        );
        // Straight down over a bare floor, neither block crowds the tool: both lie beyond the
        // body's reach.
        let mut floor = map.clone();
        floor.height_m.fill(0.0);
        assert!(clear(&with_block(&floor, 1.0), &Vector3::z()));
        assert!(clear(&with_block(&floor, -1.0), &Vector3::z()));
    }

    #[test]
    fn trapezoid_times() {
        assert!((joint_move_s(1.0, 1.0, 1.0) - 2.0).abs() < 1e-12);
        assert!((joint_move_s(0.25, 1.0, 1.0) - 1.0).abs() < 1e-12);
    }
}
