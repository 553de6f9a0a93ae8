//! Recognition from the point cloud: parts found in a depth capture from the capture alone, the
//! workpiece model and the fixed cell. It never sees the physics world: its inputs are
//! [`Capture`] (depth and organised points), [`Camera`], [`TrayVolume`] and [`CloudModel`].
//!
//! Pipeline: (1) background removal: points within [`FLOOR_TOL_M`] of the tray floor, outside its
//! inner walls or outside the view frustum over the tray (where the arm may be); pixels without a
//! return (dropouts, and parts blurred by motion, which the cycle invalidates: depth 0) are neither
//! part nor background, they say nothing; (2) normals per pixel from a ring of 8 neighbours
//! [`NORMAL_RING_M`] away (in whole pixels: the next ones at the default sensor, two away at its
//! full resolution);
//! (3) region growing from smooth seed pixels, highest first: a 4-neighbour joins when it lies
//! within [`PLANE_TOL_M`] of the region's plane (refitted as it doubles) and its normal within
//! [`NORMAL_TOL_RAD`] of the plane's; (4) per patch the least-squares plane, and each pixel's ray
//! cut with that plane (noise-free in-plane positions; not those measured more than
//! [`PLANE_TRIM_M`] behind it, the side walls' rim near the tray's corners); the neighbours whose
//! measured point lies behind the plane are "outside" (the ray passed the face), those in front or
//! missing say nothing; (5) per model face (not smaller than the patch) an exact silhouette fit
//! (`fit`): every placement of the face's rectangle (or disc) holding every inside point and no
//! outside point, yaws scanned around the patch's minimum-area rectangle (a square face also a
//! quarter turn round, unless the part is the same so turned); the estimate is the
//! middle of the consistent yaws and the mean of the consistent centres; a face whose centre is not
//! pinned down (both edges of an axis hidden) or whose yaw is open by more than the model's
//! `yaw_span_max_rad` (the cell file's `sensor.max_yaw_ambiguity_deg`, [`YAW_SPAN_MAX_RAD`] by
//! default) is no hypothesis; (6) a hypothesis reaching under the tray floor is impossible; the
//! others are rendered into the depth image (a primitive model by ray casting, each ray at the
//! pieces whose image box holds its pixel; a mesh model by rasterizing its triangles) and compared: agreeing within [`AGREE_TOL_M`] (3 sigma of the depth
//! noise), measured in front (occluded, allowed) or measured behind (a contradiction, unless the
//! ray only grazes a lead); score = agree / (agree + contradict), evidence = agree - 3 contradict;
//! (7) per patch the hypothesis with the most evidence if it scores at least [`MIN_SCORE`] and no
//! different pose (beyond [`SAME_POSE_M`], [`SAME_POSE_RAD`], up to the part's symmetries) comes
//! within [`CLOSE_CALL_PX`] of it (a CAD part's hypotheses joined by their twin faces' at the same
//! placements); else, a close call, each contender refined and weighed at every pixel by how well
//! its pixels agree (a log-likelihood under the depth noise; a contender with a stepped face
//! up, not settled on the floor, first moved along the optical axis to the mean depth its
//! agreeing pixels are measured at, since each face is placed on the patch's plane), the
//! winner needing
//! [`CLOSE_CALL_LOG_ODDS`] over every different pose; refined (`refine`: settled onto the floor in
//! one of the part's resting poses where the patch's points allow it; else a CAD part's tilt the
//! patch leaves open scanned by rendering; an outline-fitted face turned to its best-verified
//! yaw), then non-maximum suppression by centre distance; (8) a
//! part with a body cylinder (D's can) lying on its curved side (`lying`): per patch no flat face
//! explains, a cylinder of known radius fitted to the points around it, kept if its axis's standard
//! error is within `lying::AXIS_SIGMA_MAX_RAD`; per distinct axis, verification picks the turn
//! about the axis (where the part's symmetry leaves it to matter, only if no other turn comes
//! within [`CLOSE_CALL_PX`]) and the station along it for either way round; which end is the base is decided
//! at every pixel (each way placed by the evidence of every pixel; one way must have
//! `lying::END_EVIDENCE_MARGIN_PX` more, or explain at least `lying::END_VOTES_MIN` pixels the
//! other does not, three times as many as the other); reported only if that decides and the station
//! moved either way has `lying::PIN_MARGIN_PX` less evidence ([`CloudDetection::curved_side_up`]).
//!
//! Precision first: a pose the image does not pin down is not reported. Limits:
//! - a flat-lying E or F shows one 7 px face and no side (its sides are past the sensor's
//!   grazing dropout): its yaw is open by 5-20 degrees in most cases, so most are not reported;
//! - a relay (A) on its back whose 1 mm pins no pixel hit looks like one on its face: it is
//!   reported only where the floor or a pixel on a pin decides;
//! - a can (D) lying on its side is found when its axis fits within 4 degrees (standard error)
//!   and both its base end and its station are decided; about 6 in 400 are off by 5-7 degrees;
//! - a mesh workpiece (a CAD part) is matched through its part model's planar faces
//!   ([`CloudModel::of_part_model`]): a face that is its rectangle (or a disc) is fitted as
//!   above; any other face by its true outline (module `outline`: a polygon with the holes the sensor
//!   sees through, with the features beside it that a patch takes in, such as a DIP's leg
//!   shoulders), and the patch's plane is then refitted without the pixels off it, which those
//!   features would tilt. Hypotheses are verified by rendering the real mesh. A part whose
//!   visible surface is not a large planar face is recognised by point-pair features instead
//!   ([`ppf`], chosen by the workpiece's `recognition.method`).
//!
//! Units: m, rad, px. Frames: world (`world_from_part`), the pick tray frame for the background,
//! a patch's plane basis (e1, e2, normal toward the camera) for the silhouette fits.
//! Deterministic: no randomness, fixed iteration orders.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use super::{Camera, Capture};
use crate::config::{PartRole, Piece, ShapeKind, Workpiece};
use crate::geometry::TrayVolume;
use crate::part::primitive::{Face, body_faces};

/// Points lower than this above the tray floor are background (m): depth noise is 0.3 mm at 1 m.
pub const FLOOR_TOL_M: f64 = 0.0012;
/// A pixel joins a patch when its point lies this close to the patch's plane (m).
pub const PLANE_TOL_M: f64 = 0.001;
/// ... and its local normal lies within this of the plane's (rad).
pub const NORMAL_TOL_RAD: f64 = 0.6;
/// A neighbour measured this far behind a patch's plane shows the ray passed the face (m).
pub const BEHIND_TOL_M: f64 = 0.0015;
/// Rendered and measured depth agree within this (m).
pub const AGREE_TOL_M: f64 = 0.001;
/// Smallest patch considered (px).
pub const MIN_PATCH_PX: usize = 8;

/// How many times in a row a patch larger than every face is cut in two ([`Cloud::cut_candidates`]):
/// twice tells up to four parts lying level side by side apart.
const MAX_PATCH_CUTS: usize = 2;
/// A silhouette fit may violate its constraints by this much (plane error) (m).
pub const FIT_VIOLATION_M: f64 = 0.0006;
/// A silhouette fit whose feasible interval is wider than this does not pin the part down (m).
pub const FIT_AMBIGUITY_M: f64 = 0.0025;
pub use crate::config::YAW_SPAN_MAX_RAD;
/// Two hypotheses closer than this (and [`SAME_POSE_RAD`]) are the same (m).
pub const SAME_POSE_M: f64 = 0.002;
/// Two hypotheses closer than this (and [`SAME_POSE_M`]) are the same (rad).
pub const SAME_POSE_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// A hypothesis reaching this far under the tray floor is impossible (m).
pub const UNDER_FLOOR_M: f64 = 0.001;
/// A different pose within this many points of the best (on the verification grid, or at every
/// pixel for a part verified so) is a close call, decided at every pixel by how well the pixels
/// agree (`Cloud::decide`). Chosen on `sense` seeds 1-8 of the DIP-8
/// (recall 78.7 -> 81.3 %, precision 93.0 -> 93.9 %, the same from 6 to every hypothesis); no
/// change for A-F, the hex standoff and the TO-220.
pub const CLOSE_CALL_PX: i64 = 10;
/// A close call's evidence per agreeing pixel, at zero residual: the log-likelihood ratio of the
/// depth noise's normal density (sigma [`refine::DEPTH_NOISE_M`]) against a depth spread evenly
/// over [`BACKGROUND_SPREAD_M`], what a pixel of a neighbour or the floor would show;
/// a residual r takes r^2 / (2 sigma^2) off it, a contradicting pixel counts as three
/// agreeing ones against (as in the counted evidence).
fn agree_log_ratio() -> f64 {
    (BACKGROUND_SPREAD_M / (refine::DEPTH_NOISE_M * (2.0 * std::f64::consts::PI).sqrt())).ln()
}
/// The depths a pixel not on the hypothesised part may show: a pile a few small parts deep (m).
pub const BACKGROUND_SPREAD_M: f64 = 0.010;
/// A close call goes to the pose whose every-pixel log-likelihood beats every different pose's
/// by at least this (odds of 100 to 1); else the patch stays unrecognised. It tells a part's
/// sides apart by what the agreement band (1 mm) does not see: an SOIC-8 on its back shows its
/// feet 0.7 mm above its leads' shoulders, and its top face 0.1 mm lower over the floor.
pub const CLOSE_CALL_LOG_ODDS: f64 = 2.0 * std::f64::consts::LN_10;
/// Hypotheses of a part without leads are verified on a grid of pixels about this far apart at
/// the part (m), whatever the sensor's resolution: every other pixel of the default sensor's
/// 0.85 mm (evidence then counts grid points, and the floors in pixels below are on that grid).
/// It keeps verification's cost flat where a finer image pays only for the silhouette fits
/// (E and F: 120 and 93 ms per capture at every pixel, 19 and 20 ms on the grid, same recall).
/// A part with leads is verified at every pixel: on the grid, A's recall in the cycle fell from
/// 80 to 63 % (its 1 mm pins decide between on its back and on its face).
pub const VERIFY_SPACING_M: f64 = 0.0014;
/// Fewest rendered pixels on the [`VERIFY_SPACING_M`] grid for the grid to decide: twice
/// the agreeing pixels a verification needs ([`MIN_PATCH_PX`]).
pub const MIN_GRID_SAMPLES: usize = 2 * MIN_PATCH_PX;
/// Verification casts a pixel's ray only at the pieces whose image box, this much wider each
/// side (px), holds the pixel's centre: a margin for the box's and the ray's rounding.
const PIECE_BOX_MARGIN_PX: f64 = 1.0;
/// Lowest verification score kept.
pub const MIN_SCORE: f64 = 0.8;
/// An outline fit whose middle yaw fails verification with at least this score is scanned over
/// its yaw span (a near miss; lower scores are other poses, and the scan renders at every pixel
/// of up to 25 yaws).
pub const YAW_SCAN_MIN_SCORE: f64 = 0.7;
/// A patch with a flat-face hypothesis verified this well is not tried as a lying part's top.
pub const LYING_SKIP_SCORE: f64 = 0.95;

/// The workpiece as recognition sees it: its flat body faces (to match patches) and all its
/// pieces, leads included (to render hypotheses).
#[derive(Debug, Clone)]
pub struct CloudModel {
    /// The flat body faces, as [`body_faces`] gives them; `face_up` indexes this.
    pub faces: Vec<Face>,
    /// Every primitive, in the part frame.
    pieces: Vec<Piece>,
    /// Per piece: a lead (thin: a ray grazing it may miss it when the pose is slightly off).
    lead: Vec<bool>,
    /// Half the bounding box (m).
    half_size_m: Vector3<f64>,
    /// Whether a half turn about a face's normal can change the part (compounds: leads, bases).
    half_turn_matters: bool,
    /// The turns that leave the part looking the same (two hypotheses differing by one are one).
    symmetry: Symmetry,
    /// Its body has a cylinder it can lie on: hypotheses on the curved side are tried.
    round_side: bool,
    /// A face whose outline leaves its yaw open by more than this is no hypothesis (rad).
    pub yaw_span_max_rad: f64,
    /// A mesh workpiece's surface, rendered instead of `pieces` (which are then empty).
    mesh: Option<std::sync::Arc<render::MeshView>>,
    /// A mesh workpiece's round body (centre, unit axis, radius; part frame, m): its part
    /// model's [`crate::part::model::RoundBody`], the cylinder a lying part is fitted to.
    round: Option<(Vector3<f64>, Vector3<f64>, f64)>,
    /// Hypotheses are verified at every pixel, not on the [`VERIFY_SPACING_M`] grid: the part
    /// has features thinner than the grid (a primitive's leads; a part model's round bodies
    /// narrower than the grid: pins), which decide between poses.
    fine_verify: bool,
    /// Set: recognised by point-pair features ([`ppf`]) instead of planar faces.
    ppf: Option<std::sync::Arc<ppf::PpfModel>>,
    /// Per face: a mesh face's true outline ([`outline`]), fitted in place of its rectangle;
    /// `None` for a primitive's faces and round faces (empty for a primitive model).
    outlines: Vec<Option<std::sync::Arc<outline::Outline>>>,
    /// Some face has features beside it within the plane band ([`outline::BAND_M`]: a DIP's
    /// leg shoulders): a patch's plane is refitted without the pixels off it
    /// ([`PLANE_TRIM_M`]), which would tilt it.
    trim_plane: bool,
    /// The part's resting poses' support normals (part frame, unit, pointing down at rest): a
    /// detection near one, on the floor, is tried settled ([`refine`]). A primitive workpiece's
    /// come from its meshed primitives ([`CloudModel::with_resting`]); empty: not tried.
    resting: Vec<Vector3<f64>>,
    /// Per face: another planar face of the part faces the same way within [`PLANE_TOL_M`] of
    /// its plane, a step a patch may take in with it (a coin cell's cap over its can's rim): a
    /// hypothesis with it up is tried settled by its rendered surface where its plane fails
    /// ([`refine`]), and weighed in a close call at its measured depth. All false for a
    /// primitive model.
    stepped: Vec<bool>,
}

/// Two planar faces whose normals agree within this face the same way for [`CloudModel`]'s
/// `stepped` (rad).
pub const STEP_NORMAL_TOL_RAD: f64 = 0.01;

/// A patch's plane is refitted (twice) without its pixels farther than this from it, when the
/// model's faces have features beside them within the plane band (m): two sigma of the depth
/// noise.
pub const PLANE_TRIM_M: f64 = 0.0006;
/// A planar face of a part model smaller than this share of the largest is not matched.
pub const MESH_FACE_MIN_SHARE: f64 = 0.03;
/// A planar face of a part model narrower than this is not matched (m): a 1 mm strip is a pixel
/// or two wide in the image.
pub const MESH_FACE_MIN_WIDTH_M: f64 = 0.0015;
/// A face outline whose vertices lie within this share of one radius from its centre (and has at
/// least [`DISC_MIN_VERTICES`]) is fitted as a disc.
pub const DISC_RADIUS_SPREAD: f64 = 0.03;
/// Fewest outline vertices of a face fitted as a disc.
pub const DISC_MIN_VERTICES: usize = 12;

/// A part model's planar face as recognition and the grasp selector fit it: a disc when its outer
/// outline is round and it has no hole or one round hole about the same centre (a washer), else
/// its minimum-area bounding rectangle, in the part frame.
pub fn face_of_planar(face: &crate::part::faces::PlanarFace) -> Face {
    let pts: Vec<[f64; 2]> = face.outer.iter().map(|p| [p.x, p.y]).collect();
    let hull = convex_hull(&pts);
    let (lo, hi) = fit::bounds_at(&hull, 0.0);
    let mid = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    // A ring is round when its vertices lie within the spread of one radius about the outer
    // ring's middle: its mean and largest radius.
    let round = |ring: &[[f64; 2]]| -> Option<(f64, f64)> {
        let radii: Vec<f64> = ring.iter().map(|p| (p[0] - mid[0]).hypot(p[1] - mid[1])).collect();
        let r_max = radii.iter().cloned().fold(0.0, f64::max);
        let r_min = radii.iter().cloned().fold(f64::INFINITY, f64::min);
        (ring.len() >= DISC_MIN_VERTICES && r_max - r_min <= DISC_RADIUS_SPREAD * r_max)
            .then(|| (radii.iter().sum::<f64>() / radii.len() as f64, r_max))
    };
    // A disc, or a disc with one concentric round hole (a washer's bore).
    let hole_radius_m = match face.holes.as_slice() {
        [] => Some(0.0),
        [hole] => round(&hole.iter().map(|p| [p.x, p.y]).collect::<Vec<_>>()).map(|(mean, _)| mean),
        _ => None,
    };
    if let (Some((_, r_max)), Some(hole_radius_m)) = (round(&pts), hole_radius_m) {
        return Face {
            center: face.centroid_m.coords + face.u * mid[0] + face.v * mid[1],
            normal: face.normal,
            along: face.u,
            extent_m: [2.0 * r_max, 2.0 * r_max],
            disc: true,
            hole_radius_m,
        };
    }
    let theta = min_area_theta(&hull);
    let (lo, hi) = fit::bounds_at(&hull, theta);
    let (c, s) = (theta.cos(), theta.sin());
    let m = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    // Back from the turned frame (q = R(-theta) p) to the face frame.
    let p = [c * m[0] - s * m[1], s * m[0] + c * m[1]];
    Face {
        center: face.centroid_m.coords + face.u * p[0] + face.v * p[1],
        normal: face.normal,
        along: face.u * c + face.v * s,
        extent_m: [hi[0] - lo[0], hi[1] - lo[1]],
        disc: false,
        hole_radius_m: 0.0,
    }
}

impl CloudModel {
    /// Face `fi`'s true outline, where it is fitted by one (a mesh face with one); `None` for a
    /// face fitted as its rectangle or disc.
    fn outline(&self, fi: usize) -> Option<&outline::Outline> {
        self.outlines.get(fi).and_then(|o| o.as_deref())
    }

    /// The model of a primitive workpiece (a mesh workpiece gets no faces here: its model is
    /// [`CloudModel::of_part_model`], as the sensor builds it). The faces
    /// are [`body_faces`] (same indices), then the body's faces that only leads stand out of (a
    /// relay lying on its back shows its pinned face: it must be matched to be told apart).
    pub fn new(w: &Workpiece) -> Self {
        let pieces = w.pieces();
        let mut faces = body_faces(&pieces);
        let bare: Vec<(PartRole, Piece)> = pieces.into_iter().filter(|(r, _)| *r == PartRole::Body).collect();
        for f in body_faces(&bare) {
            if !faces
                .iter()
                .any(|g| (g.center - f.center).norm() < 1e-9 && (g.normal - f.normal).norm() < 1e-9)
            {
                faces.push(f);
            }
        }
        CloudModel {
            faces,
            pieces: w.pieces().into_iter().map(|(_, p)| p).collect(),
            lead: w.pieces().into_iter().map(|(r, _)| r == PartRole::Lead).collect(),
            half_size_m: Vector3::from(w.size_m) / 2.0,
            half_turn_matters: w.shape.kind == ShapeKind::Compound,
            symmetry: Symmetry::of(w),
            yaw_span_max_rad: YAW_SPAN_MAX_RAD,
            round_side: w
                .pieces()
                .iter()
                .any(|(r, p)| *r == PartRole::Body && matches!(p, Piece::Cylinder { .. })),
            mesh: None,
            round: None,
            fine_verify: w.pieces().iter().any(|(r, _)| *r == PartRole::Lead),
            ppf: None,
            outlines: Vec::new(),
            trim_plane: false,
            resting: Vec::new(),
            stepped: Vec::new(),
        }
        .with_stepped_faces(&[])
    }

    /// The model with `pm`'s resting poses (a primitive workpiece's, from its meshed primitives):
    /// its detections lying on the floor in one of them are tried settled (`refine`).
    pub fn with_resting(mut self, pm: &crate::part::PartModel) -> Self {
        self.resting = pm.poses.iter().map(|p| p.normal).collect();
        self
    }

    /// The model of a mesh workpiece from its part model: the planar faces large enough to be
    /// matched ([`MESH_FACE_MIN_SHARE`], [`MESH_FACE_MIN_WIDTH_M`]) as [`face_of_planar`] fits
    /// them, less the faces a symmetry of the part maps onto an earlier one; hypotheses are
    /// rendered from the mesh. Both half turns about a face are tried (the symmetry decides
    /// whether they differ). A round body's side faces are its curved side, fitted as a lying
    /// part's cylinder (as a primitive's body cylinder), not matched as flat faces.
    pub fn of_part_model(pm: &crate::part::PartModel) -> Self {
        let symmetry = Symmetry::of_orders(pm.symmetry.orders);
        let largest = pm.faces.first().map_or(0.0, |f| f.face.area_m2);
        let round = pm.round_body();
        let mut faces: Vec<Face> = Vec::new();
        let mut outlines = Vec::new();
        for (i, mf) in pm.faces.iter().enumerate() {
            if mf.face.area_m2 < MESH_FACE_MIN_SHARE * largest || round.as_ref().is_some_and(|r| r.faces.contains(&i)) {
                continue;
            }
            let f = face_of_planar(&mf.face);
            if f.extent_m[0].min(f.extent_m[1]) < MESH_FACE_MIN_WIDTH_M {
                continue;
            }
            if !faces.iter().any(|g| symmetry.maps_onto(&f, g)) {
                // A face that is its rectangle, with nothing beside it a patch takes in, keeps
                // the (exact, faster) rectangle fit.
                let outline = (!f.disc)
                    .then(|| outline::Outline::new(&mf.face, &f, &pm.mesh))
                    .filter(|o| !o.is_rectangle(&f, mf.face.area_m2, mf.face.holes_area_m2()));
                outlines.push(outline.map(std::sync::Arc::new));
                faces.push(f);
            }
        }
        CloudModel {
            faces,
            pieces: Vec::new(),
            lead: Vec::new(),
            half_size_m: Vector3::from(pm.size_m) / 2.0,
            half_turn_matters: true,
            symmetry,
            round_side: round.is_some(),
            yaw_span_max_rad: YAW_SPAN_MAX_RAD,
            mesh: render::MeshView::new(&pm.mesh).map(std::sync::Arc::new),
            round: round.map(|r| (r.center_m, r.axis, r.radius_m)),
            fine_verify: pm.round.iter().any(|r| 2.0 * r.radius_m < VERIFY_SPACING_M),
            ppf: None,
            trim_plane: outlines.iter().flatten().any(|o| o.has_band()),
            outlines,
            resting: pm.poses.iter().map(|p| p.normal).collect(),
            stepped: Vec::new(),
        }
        .with_stepped_faces(
            &pm.faces
                .iter()
                .map(|f| (f.face.normal, f.face.centroid_m.coords))
                .collect::<Vec<_>>(),
        )
    }

    /// Whether face `fi` has a step beside it (`stepped`).
    fn is_stepped(&self, fi: usize) -> bool {
        self.stepped.get(fi).copied().unwrap_or(false)
    }

    /// Sets `stepped` per face from the part's planar faces (normal, a point on the plane; part
    /// frame): parallel within [`STEP_NORMAL_TOL_RAD`], its plane off by more than 10 um and
    /// at most [`PLANE_TOL_M`].
    fn with_stepped_faces(mut self, planes: &[(Vector3<f64>, Vector3<f64>)]) -> Self {
        self.stepped = self
            .faces
            .iter()
            .map(|f| {
                planes.iter().any(|(n, p)| {
                    let off = f.normal.dot(&(p - f.center)).abs();
                    n.dot(&f.normal) >= STEP_NORMAL_TOL_RAD.cos() && off > 1e-5 && off <= PLANE_TOL_M
                })
            })
            .collect();
        self
    }

    /// The turns that leave the part looking the same.
    pub fn symmetry(&self) -> &Symmetry {
        &self.symmetry
    }

    /// The face whose outward normal at `pose` is turned most toward `to_camera` (world).
    fn face_nearest_up(&self, pose: &Isometry3<f64>, to_camera: &Vector3<f64>) -> usize {
        let up = pose.rotation.inverse() * to_camera.normalize();
        (0..self.faces.len())
            .max_by(|&a, &b| self.faces[a].normal.dot(&up).total_cmp(&self.faces[b].normal.dot(&up)))
            .unwrap_or(0)
    }

    /// Lowest point of the model at `pose` along the world direction `up` [m, along `up`].
    fn lowest_along(&self, pose: &Isometry3<f64>, up: &Vector3<f64>) -> f64 {
        let d = pose.rotation.inverse() * -up;
        let t = pose.translation.vector.dot(up);
        let pieces = self.pieces.iter().map(|p| t - p.support_m(&d));
        match &self.mesh {
            Some(m) => m
                .vertices_m
                .iter()
                .map(|v| t - v.dot(&d))
                .chain(pieces)
                .fold(f64::INFINITY, f64::min),
            None => pieces.fold(f64::INFINITY, f64::min),
        }
    }

    /// Whether two poses of the part look alike (within [`SAME_POSE_M`] and [`SAME_POSE_RAD`],
    /// up to its symmetries).
    fn same_pose(&self, a: &Isometry3<f64>, b: &Isometry3<f64>) -> bool {
        let (dp, dr) = self.symmetry.pose_error(a, b);
        dp <= SAME_POSE_M && dr <= SAME_POSE_RAD
    }

    /// Smallest edge of the bounding box (m).
    fn min_size_m(&self) -> f64 {
        2.0 * self.half_size_m.min()
    }
}

/// A part recognised in the point cloud.
#[derive(Debug, Clone, Serialize)]
pub struct CloudDetection {
    /// Estimated `world_from_part`.
    #[serde(serialize_with = "crate::sensor::ser_pose")]
    pub world_from_part: Isometry3<f64>,
    /// The model face seen on top (index into [`CloudModel::faces`]).
    pub face_up: usize,
    /// Verification score: agreeing pixels over agreeing plus contradicting ones.
    pub score: f64,
    /// Agreeing pixels over the pixels the part would cover unoccluded.
    pub visible_fraction: f64,
    /// The part lies on its body cylinder's curved side (a can on its side): no flat face is
    /// up, and `face_up` is only the flat face turned most toward the camera (not a suction face).
    pub curved_side_up: bool,
    /// The yaws about the face normal its outline fit (`outline`) allows: a span centred on its
    /// yaw (rad), which `refine` scans; 0 for every other fit (a rectangle, a disc, a lying part,
    /// point-pair features).
    #[serde(skip)]
    yaw_span_rad: f64,
    /// The verification grid's stride where this hypothesis, too small for the grid, was
    /// verified at every pixel instead (its evidence counts pixels), else 0 (evidence in the
    /// model's own units: grid points, or pixels for a part verified at every pixel).
    #[serde(skip)]
    fell_back_from: usize,
}

/// Recognises parts in a capture from the capture, the camera, the pick tray's geometry and the
/// workpiece model only (no physics world, no ground truth). Best first.
pub fn recognize(capture: &Capture, camera: &Camera, tray: &TrayVolume, model: &CloudModel) -> Vec<CloudDetection> {
    recognize_in(&Cloud::new(capture, camera, tray), model)
}

/// [`recognize`] on the capture prepared.
fn recognize_in(cloud: &Cloud, model: &CloudModel) -> Vec<CloudDetection> {
    if let Some(p) = &model.ppf {
        return ppf::detect(cloud, model, p);
    }
    let patches = cloud.segment();
    // Patches in parallel, collected in their order: deterministic.
    let per_patch: Vec<(Vec<CloudDetection>, Vec<lying::AxisFit>)> = patches
        .par_iter()
        .map(|patch| cloud.patch_hypotheses(patch, model))
        .collect();
    let mut found: Vec<CloudDetection> = Vec::new();
    let mut fits = Vec::new();
    for (d, f) in per_patch {
        found.extend(d);
        fits.extend(f);
    }
    // Parts lying on their curved side: each distinct axis once.
    let fits = lying::distinct(fits, 2.0 * model.half_size_m.max());
    found.extend(cloud.lying_detections(model, &fits));
    found.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<CloudDetection> = Vec::new();
    let radius = 0.5 * model.min_size_m();
    for d in found {
        let c = d.world_from_part.translation.vector;
        if kept
            .iter()
            .all(|k| (k.world_from_part.translation.vector - c).norm() > radius)
        {
            kept.push(d);
        }
    }
    kept
}

/// A verification's (score, visible fraction, evidence = agreeing less 3 x contradicting pixels).
type Verdict = (f64, f64, i64);

/// The capture prepared for recognition: the window of the image over the tray's inside.
struct Cloud<'a> {
    camera: &'a Camera,
    /// The window's first column and row in the image (px).
    u0: usize,
    v0: usize,
    /// The window's width and height (px); pixel indices below are within it.
    w: usize,
    h: usize,
    origin: Vector3<f64>,
    optical: Vector3<f64>,
    /// World point per pixel (NaN: no return).
    pts: Vec<Vector3<f64>>,
    /// Depth per pixel, 0 where no return (m).
    depth: Vec<f64>,
    /// Foreground: a return inside the tray's inner walls, above the floor.
    fg: Vec<bool>,
    /// Local normal toward the camera (zero where not computable).
    normal: Vec<Vector3<f64>>,
    /// Height above the tray floor (m).
    height: Vec<f64>,
    /// The tray floor: a point and the upward normal (world).
    floor: Plane,
    /// The normals' ring of neighbours: this many pixels from the centre ([`NORMAL_RING_M`]).
    ring_px: i64,
}

/// A patch's plane, its in-plane basis (e1, e2), the in-plane points of its pixels' rays (inside)
/// and of the neighbours seen behind the plane (outside) (m).
/// A patch's plane, its basis (e1, e2), its inside points, its boundary's inside points (those
/// with a 4-neighbour not in the patch) and its outside points, in that basis (m).
type Silhouette = (Plane, [Vector3<f64>; 2], Vec<[f64; 2]>, Vec<[f64; 2]>, Vec<[f64; 2]>);

/// A smooth surface patch: its pixels.
struct Patch {
    pixels: Vec<usize>,
}

/// Whether `count` interior pixels of `patch` (all 8 neighbours in it) are enough to stand for
/// it: at least [`MIN_PATCH_PX`] and a quarter of its pixels. A narrower patch (a DIP-8 on its
/// end, 7 x 4 pixels) is read whole.
fn interior_suffices(count: usize, patch: &Patch) -> bool {
    count >= MIN_PATCH_PX.max(patch.pixels.len() / 4)
}

/// The 8-ring around a pixel, in circular order.
const RING: [(i64, i64); 8] = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)];

/// A pixel's local normal is taken from the ring of neighbours this far away at the tray floor,
/// in whole pixels (at least one) (m): the default sensor's pixel there. On a finer sensor the
/// nearest neighbours are closer than the depth noise allows a normal from (0.42 mm pixels under
/// 0.3 mm of noise: a normal 30-40 degrees off, and a flat DIP-8's face broken into patches).
pub const NORMAL_RING_M: f64 = 0.00085;

/// A plane: a point and a unit normal toward the camera.
#[derive(Debug, Clone, Copy)]
struct Plane {
    point: Vector3<f64>,
    normal: Vector3<f64>,
}

impl Plane {
    /// Two unit axes in the plane (world), with the normal a right-handed frame: the first is
    /// world x (or y, for a normal near x) projected into the plane.
    fn basis(&self) -> (Vector3<f64>, Vector3<f64>) {
        let n = self.normal;
        let e1 = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let e1 = (e1 - n * n.dot(&e1)).normalize();
        (e1, n.cross(&e1))
    }
}

/// Least-squares plane of points given as sums relative to `origin`: count, sum, sum of outer
/// products. The normal is oriented toward `eye`.
fn plane_from_sums(n: f64, s: &Vector3<f64>, ss: &Matrix3<f64>, origin: &Vector3<f64>, eye: &Vector3<f64>) -> Plane {
    let mean = s / n;
    let cov = ss / n - mean * mean.transpose();
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imin();
    let mut normal: Vector3<f64> = eig.eigenvectors.column(k).into();
    let point = origin + mean;
    if normal.dot(&(eye - point)) < 0.0 {
        normal = -normal;
    }
    Plane { point, normal }
}

impl<'a> Cloud<'a> {
    fn new(c: &Capture, camera: &'a Camera, tray: &TrayVolume) -> Self {
        let tray_from_world = tray.world_from_tray.inverse();
        let inner = [
            tray.half_xy_m[0] - tray.wall_thickness_m,
            tray.half_xy_m[1] - tray.wall_thickness_m,
        ];
        // A point is the pile's only inside the view frustum over the tray, which the cell keeps
        // the arm and the part it holds out of while it exposes: above the inner floor but
        // outside the frustum is where the arm carries a part over the tray's rim.
        let eye = tray_from_world * Point3::from(camera.world_from_camera.translation.vector);
        let (u0, v0, w, h) = tray_window(camera, tray, c.width_px, c.height_px);
        let mut pts = vec![Vector3::zeros(); w * h];
        let mut depth = vec![0.0; w * h];
        let mut fg = vec![false; w * h];
        let mut height = vec![0.0; w * h];
        // Row by row in parallel (each pixel on its own).
        pts.par_chunks_mut(w)
            .zip(depth.par_chunks_mut(w))
            .zip(fg.par_chunks_mut(w))
            .zip(height.par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, (((pts, depth), fg), height))| {
                // The capture measures its own tray window; any pixel outside it has no return.
                let image = (u0..u0 + w).map(|u| (c.point_at_world(u, v0 + row), c.depth_at_m(u, v0 + row)));
                for (k, (p, d)) in image.enumerate() {
                    let v = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    let ok = d > 0.0 && v.x.is_finite();
                    let l = tray_from_world * Point3::from(v);
                    let inside = ok
                        && l.z > FLOOR_TOL_M
                        && l.z < tray.wall_height_m + 0.05
                        && l.x.abs() < inner[0] - 0.0005
                        && l.y.abs() < inner[1] - 0.0005
                        && tray.frustum_holds(&eye, &l);
                    pts[k] = v;
                    depth[k] = if ok { d as f64 } else { 0.0 };
                    fg[k] = inside;
                    height[k] = if ok { l.z } else { f64::NAN };
                }
            });
        let mut cloud = Cloud {
            camera,
            u0,
            v0,
            w,
            h,
            origin: camera.world_from_camera.translation.vector,
            optical: camera.world_from_camera.rotation * Vector3::z(),
            pts,
            depth,
            fg,
            normal: vec![Vector3::zeros(); w * h],
            height,
            floor: Plane {
                point: tray.world_from_tray.translation.vector,
                normal: tray.world_from_tray.rotation * Vector3::z(),
            },
            ring_px: (NORMAL_RING_M / camera.pixel_size_at_point_m(&tray.world_from_tray.translation.vector))
                .round()
                .max(1.0) as i64,
        };
        cloud.normal = cloud.normals();
        cloud
    }

    /// Whether pixel `i` and its 8 neighbours all lie in `member` (a patch's pixels, sorted).
    fn is_interior(&self, member: &[usize], i: usize) -> bool {
        let (u, v) = (i % self.w, i / self.w);
        (-1..=1).all(|dv| {
            (-1..=1).all(|du| {
                self.neighbour_at(u, v, du, dv)
                    .is_some_and(|j| member.binary_search(&j).is_ok())
            })
        })
    }

    /// The pixel `du` columns and `dv` rows from the pixel in column `u` and row `v` of the
    /// window, if within it.
    #[inline]
    fn neighbour_at(&self, u: usize, v: usize, du: i64, dv: i64) -> Option<usize> {
        let (u, v) = (u as i64 + du, v as i64 + dv);
        (u >= 0 && v >= 0 && (u as usize) < self.w && (v as usize) < self.h).then(|| v as usize * self.w + u as usize)
    }

    /// Local normals: the summed cross products of consecutive ring neighbours (`ring_px`
    /// pixels away) that are foreground and within 4 mm of depth.
    fn normals(&self) -> Vec<Vector3<f64>> {
        let mut normal = vec![Vector3::zeros(); self.w * self.h];
        // Row by row in parallel (each pixel on its own).
        normal.par_chunks_mut(self.w).enumerate().for_each(|(v, row)| {
            for (u, out) in row.iter_mut().enumerate() {
                let i = v * self.w + u;
                if !self.fg[i] {
                    continue;
                }
                let c = self.pts[i];
                let ring: [Option<Vector3<f64>>; 8] = RING.map(|(du, dv)| {
                    self.neighbour_at(u, v, du * self.ring_px, dv * self.ring_px)
                        .filter(|&j| self.fg[j] && (self.depth[j] - self.depth[i]).abs() < 0.004)
                        .map(|j| self.pts[j] - c)
                });
                let mut n = Vector3::zeros();
                let mut pairs = 0;
                for k in 0..8 {
                    if let (Some(a), Some(b)) = (ring[k], ring[(k + 1) % 8]) {
                        n += a.cross(&b);
                        pairs += 1;
                    }
                }
                if pairs >= 4 && n.norm() > 0.0 {
                    n.normalize_mut();
                    if n.dot(&(self.origin - c)) < 0.0 {
                        n = -n;
                    }
                    *out = n;
                }
            }
        });
        normal
    }

    /// Whether pixel `i` can seed a region: all 8 neighbours foreground, on its local plane.
    fn smooth(&self, i: usize) -> bool {
        let n = self.normal[i];
        let (u, v) = (i % self.w, i / self.w);
        n != Vector3::zeros()
            && RING.iter().all(|&(du, dv)| {
                self.neighbour_at(u, v, du, dv)
                    .is_some_and(|j| self.fg[j] && n.dot(&(self.pts[j] - self.pts[i])).abs() < 0.8 * PLANE_TOL_M)
            })
    }

    /// Region growing into smooth patches, seeds highest first.
    fn segment(&self) -> Vec<Patch> {
        let n = self.w * self.h;
        // In parallel: the seeds in index order, then sorted by a total order (the same whatever
        // the threads).
        let mut seeds: Vec<usize> = (0..n)
            .into_par_iter()
            .filter(|&i| self.fg[i] && self.smooth(i))
            .collect();
        seeds.par_sort_unstable_by(|&a, &b| self.height[b].total_cmp(&self.height[a]).then(a.cmp(&b)));
        let mut label = vec![u32::MAX; n];
        let mut patches = Vec::new();
        let mut queue = std::collections::VecDeque::new();
        for s in seeds {
            if label[s] != u32::MAX {
                continue;
            }
            let id = patches.len() as u32;
            let origin = self.pts[s];
            let mut plane = Plane {
                point: origin,
                normal: self.normal[s],
            };
            let (mut cnt, mut sum, mut sum2) = (0.0, Vector3::zeros(), Matrix3::zeros());
            let mut refit_at = 6.0;
            let mut pixels = Vec::new();
            label[s] = id;
            queue.push_back(s);
            while let Some(i) = queue.pop_front() {
                pixels.push(i);
                let r = self.pts[i] - origin;
                cnt += 1.0;
                sum += r;
                sum2 += r * r.transpose();
                if cnt >= refit_at {
                    plane = plane_from_sums(cnt, &sum, &sum2, &origin, &self.origin);
                    refit_at *= 2.0;
                }
                let (u, v) = (i % self.w, i / self.w);
                for (du, dv) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                    let Some(j) = self.neighbour_at(u, v, du, dv) else {
                        continue;
                    };
                    if label[j] != u32::MAX || !self.fg[j] {
                        continue;
                    }
                    if plane.normal.dot(&(self.pts[j] - plane.point)).abs() > PLANE_TOL_M {
                        continue;
                    }
                    let nj = self.normal[j];
                    if nj != Vector3::zeros() && nj.dot(&plane.normal) < NORMAL_TOL_RAD.cos() {
                        continue;
                    }
                    label[j] = id;
                    queue.push_back(j);
                }
            }
            patches.push(Patch { pixels });
        }
        patches.retain(|p| p.pixels.len() >= MIN_PATCH_PX);
        patches
    }

    /// Where pixel `i`'s ray meets `plane` (world), and the ray's depth there.
    fn ray_on_plane(&self, i: usize, plane: &Plane) -> Option<(Vector3<f64>, f64)> {
        let d = self.camera.pixel_dir(self.u0 + i % self.w, self.v0 + i / self.w);
        let den = plane.normal.dot(&d);
        if den.abs() < 1e-6 {
            return None;
        }
        let t = plane.normal.dot(&(plane.point - self.origin)) / den;
        (t > 0.0).then(|| (self.origin + d * t, t * d.dot(&self.optical)))
    }

    /// A patch's plane, its pixels' rays cut with the plane (inside; but those measured more
    /// than [`PLANE_TRIM_M`] behind it) and the neighbours whose measured point lies behind the
    /// plane (outside), both in the plane's basis (e1, e2).
    fn silhouette(&self, patch: &Patch, trim: bool) -> Silhouette {
        let origin = self.pts[patch.pixels[0]];
        let mut member = patch.pixels.clone();
        member.sort_unstable();
        let is_member = |j: usize| member.binary_search(&j).is_ok();
        // The least-squares plane of the pixels `keep` takes, and their count.
        let fit = |keep: &dyn Fn(usize) -> bool| {
            let (mut n, mut s, mut ss) = (0usize, Vector3::zeros(), Matrix3::zeros());
            for &i in patch.pixels.iter().filter(|&&i| keep(i)) {
                let r = self.pts[i] - origin;
                n += 1;
                s += r;
                ss += r * r.transpose();
            }
            (n, plane_from_sums(n as f64, &s, &ss, &origin, &self.origin))
        };
        let (_, mut plane) = fit(&|_| true);
        if trim {
            // Features beside the face within the plane band (a DIP's leg shoulders) join the
            // patch at its rim and tilt its least-squares plane: first the plane of the pixels
            // whose 8 neighbours are all in the patch (if enough), then refitted without the
            // pixels off it.
            let inner = |i: usize| self.is_interior(&member, i);
            let (count, interior) = fit(&inner);
            if interior_suffices(count, patch) {
                plane = interior;
            }
            for _ in 0..2 {
                let p = plane;
                let (kept, refit) = fit(&|i| p.normal.dot(&(self.pts[i] - p.point)).abs() <= PLANE_TRIM_M);
                if 2 * kept >= patch.pixels.len() {
                    plane = refit;
                }
            }
        }
        let (e1, e2) = plane.basis();
        let to2 = |p: Vector3<f64>| {
            let q = p - plane.point;
            [q.dot(&e1), q.dot(&e2)]
        };
        // A pixel measured more than PLANE_TRIM_M behind the plane is not the face's: toward the
        // tray's corners the patch takes in the upper rim of the side walls that face the
        // optical axis, whose rays cut the plane beyond the face's edge (and would hold the
        // face's outline off its true place and yaw); else a noise tail, one pixel in 40.
        let on_face = |i: usize| plane.normal.dot(&(self.pts[i] - plane.point)) >= -PLANE_TRIM_M;
        let inside: Vec<[f64; 2]> = patch
            .pixels
            .iter()
            .filter(|&&i| on_face(i))
            .filter_map(|&i| self.ray_on_plane(i, &plane).map(|(p, _)| to2(p)))
            .collect();
        let edge: Vec<[f64; 2]> = patch
            .pixels
            .iter()
            .filter(|&&i| on_face(i))
            .filter(|&&i| {
                let (u, v) = (i % self.w, i / self.w);
                [(1, 0), (-1, 0), (0, 1), (0, -1)]
                    .iter()
                    .any(|&(du, dv)| self.neighbour_at(u, v, du, dv).is_none_or(|j| !is_member(j)))
            })
            .filter_map(|&i| self.ray_on_plane(i, &plane).map(|(p, _)| to2(p)))
            .collect();
        // The 8-neighbours of the patch's pixels with a return, not in it, sorted.
        let ring = self.dilate(&patch.pixels, 1, |j| self.depth[j] > 0.0 && !is_member(j));
        let outside: Vec<[f64; 2]> = ring
            .into_iter()
            .filter_map(|j| {
                let (p, z) = self.ray_on_plane(j, &plane)?;
                (self.depth[j] > z + BEHIND_TOL_M).then(|| to2(p))
            })
            .collect();
        (plane, [e1, e2], inside, edge, outside)
    }

    /// The best verified hypothesis for a patch, if any; the lying parts' axis fits; and whether
    /// the patch is larger than every face (two parts lying level side by side look like that).
    fn best_hypothesis(
        &self,
        patch: &Patch,
        model: &CloudModel,
    ) -> (Option<CloudDetection>, Vec<lying::AxisFit>, bool) {
        let (plane, [e1, e2], inside, edge, outside) = self.silhouette(patch, model.trim_plane);
        let n = plane.normal;
        // The fits need only the inside points' convex hull (and so does the minimum-area
        // rectangle); a face smaller than the patch's bounding rectangle (at `theta0`) by more
        // than a pixel cannot be it.
        let hull = convex_hull(&inside);
        let theta0 = min_area_theta(&hull);
        let dims = {
            let (lo, hi) = fit::bounds_at(&hull, theta0);
            let d = [hi[0] - lo[0], hi[1] - lo[1]];
            [d[0].max(d[1]), d[0].min(d[1])]
        };
        let pixel_m = self
            .camera
            .pixel_size_at_m((plane.point - self.origin).dot(&self.optical));
        // (evidence, detection) of every hypothesis the image supports.
        let mut verified: Vec<(i64, CloudDetection)> = Vec::new();
        let mut larger_than_every_face = true;
        for (fi, face) in model.faces.iter().enumerate() {
            // A box's faces of equal extents look alike: the first stands for them.
            let twin = |g: &Face| {
                let (a, b) = (face.extent_m, g.extent_m);
                (a[0] - b[0]).abs() + (a[1] - b[1]).abs() < 1e-9 || (a[0] - b[1]).abs() + (a[1] - b[0]).abs() < 1e-9
            };
            if !model.half_turn_matters && model.faces[..fi].iter().any(twin) {
                continue;
            }
            let outline = model.outline(fi);
            let ext = match outline {
                Some(o) => o.reach_extent_m,
                None => [
                    face.extent_m[0].max(face.extent_m[1]),
                    face.extent_m[0].min(face.extent_m[1]),
                ],
            };
            if dims[0] > ext[0] + pixel_m || dims[1] > ext[1] + pixel_m {
                continue;
            }
            if outline.is_none() {
                larger_than_every_face = false;
            }
            let mut fits = Vec::new();
            if let Some(o) = outline {
                // A patch larger than the outline (its area, a pixel's rim around it) is not it.
                let rim_m2 = (o.reach_extent_m[0] + o.reach_extent_m[1]) * pixel_m;
                if inside.len() as f64 * pixel_m * pixel_m > o.reach_area_m2 + rim_m2 {
                    continue;
                }
                larger_than_every_face = false;
                // Its true outline, at every yaw: no half turn is added below.
                for f in outline::fit_outline(o, &inside, &edge, &outside, theta0, model.yaw_span_max_rad) {
                    let u = e1 * f.yaw_rad.cos() + e2 * f.yaw_rad.sin();
                    let center = plane.point + e1 * f.center[0] + e2 * f.center[1];
                    let pose = pose_from_face(face, &center, &n, &u);
                    // The silhouette's middle yaw, or, where that only just fails verification,
                    // the yaw in its span the image supports best: a 7 degree span leaves a
                    // TO-220's tab hole and leads far enough off to fail at the middle (0.75).
                    let checked = match self.check_scored(model, &pose, Some(fi)) {
                        Ok(d) => Some(d),
                        Err(score) if score >= YAW_SCAN_MIN_SCORE => self
                            .best_yaw(model, &pose, fi, f.yaw_span_rad)
                            .and_then(|turned| self.check(model, &turned, Some(fi))),
                        Err(_) => None,
                    };
                    if let Some(mut d) = checked {
                        d.1.yaw_span_rad = f.yaw_span_rad;
                        verified.push(d);
                    }
                }
                continue;
            }
            if face.disc {
                if let Some(c) = fit_disc(&hull, &outside, face.extent_m[0] / 2.0, face.hole_radius_m) {
                    // Any yaw looks the same: the face's first axis along the world x in the plane.
                    let x = Vector3::x() - n * n.x;
                    let x = if x.norm() > 1e-6 { x.normalize() } else { e1 };
                    fits.push((c, x.dot(&e2).atan2(x.dot(&e1))));
                }
            } else {
                let square = (face.extent_m[0] - face.extent_m[1]).abs() < 1e-9;
                for k in 0..if square { 1 } else { 2 } {
                    let t0 = theta0 + k as f64 * std::f64::consts::FRAC_PI_2;
                    if let Some(f) = fit_rect(&hull, &outside, face.extent_m, t0)
                        && f.yaw_span_rad <= model.yaw_span_max_rad
                    {
                        fits.push((f.center, f.yaw_rad));
                    }
                }
                // A square face looks the same a quarter turn round; where the part does not (a
                // heatsink's base with its fins under it), that turn is a hypothesis too, and the
                // image decides between them or the place is left.
                if square {
                    let pose_at = |c: &[f64; 2], yaw: f64| {
                        let u = e1 * yaw.cos() + e2 * yaw.sin();
                        pose_from_face(face, &(plane.point + e1 * c[0] + e2 * c[1]), &n, &u)
                    };
                    let quarter = std::f64::consts::FRAC_PI_2;
                    let turned: Vec<([f64; 2], f64)> = fits
                        .iter()
                        .filter(|(c, t)| !model.same_pose(&pose_at(c, *t), &pose_at(c, t + quarter)))
                        .map(|(c, t)| (*c, t + quarter))
                        .collect();
                    fits.extend(turned);
                }
            }
            for (c, theta) in fits {
                let turns: &[f64] = if model.half_turn_matters {
                    &[0.0, std::f64::consts::PI]
                } else {
                    &[0.0]
                };
                for &turn in turns {
                    let t = theta + turn;
                    let u = e1 * t.cos() + e2 * t.sin();
                    let center = plane.point + e1 * c[0] + e2 * c[1];
                    if let Some(d) = self.check(model, &pose_from_face(face, &center, &n, &u), Some(fi)) {
                        verified.push(d);
                    }
                }
            }
        }
        verified.extend(self.twin_hypotheses(model, &verified));
        // A patch a flat face explains is no lying part's top.
        let flat = verified.iter().any(|v| v.1.score >= LYING_SKIP_SCORE);
        let fits = if model.round_side && !flat {
            let (c, s) = (theta0.cos(), theta0.sin());
            self.lying_fits(patch, model, &plane, [e1 * c + e2 * s, e2 * c - e1 * s])
        } else {
            Vec::new()
        };
        let best = self.decide(model, &verified, |d| self.refine(model, patch, &plane, d));
        (best, fits, larger_than_every_face)
    }

    /// A patch's hypotheses: its best, or, where it is larger than every face and nothing
    /// explains it whole, the parts lying level side by side that make it one patch: the best
    /// of each piece it is cut into ([`Cloud::cut_candidates`]), or where no cut was at a
    /// junction, of a piece as long as a face at one end ([`Cloud::end_pieces`]) and of the
    /// rest. The pieces' lying fits are left out (the whole patch's stand).
    ///
    /// A cut is rarely exactly at a junction, and a face fitted to a piece can slide across the
    /// cut into its level neighbour, where rendering cannot tell (the neighbour agrees). So the
    /// pieces' detections are kept only as the patch's explanation: together their faces cover
    /// the whole patch but for a row of pixels ([`Cloud::uncovered`]), and no pixel lies inside
    /// two of them (a pixel in from their edges). One detection alone is kept only where it
    /// covers the whole patch so (one part and a few pixels of rim or noise beside it).
    fn patch_hypotheses(&self, patch: &Patch, model: &CloudModel) -> (Vec<CloudDetection>, Vec<lying::AxisFit>) {
        let (best, fits, larger) = self.best_hypothesis(patch, model);
        if best.is_some() || !larger {
            return (best.into_iter().collect(), fits);
        }
        let mut found = self.cut_candidates(patch, model, MAX_PATCH_CUTS);
        // Pieces cut off a junction hold strips of two parts, and some find nothing: where one
        // was found, or those found leave part of the patch uncovered, the rest is tried.
        if found.len() == 1 || (found.len() > 1 && self.uncovered(model, &found, patch) > self.row_px(model, &found)) {
            self.add_rest(patch, model, &mut found);
        }
        let kept = self.explanation(patch, model, &found);
        if !kept.is_empty() {
            return (kept, fits);
        }
        // No cut was at a junction: a piece as long as a face cut off either end of the patch,
        // and the rest, kept only where both (or all) explain the patch together: one face alone
        // over the whole patch would have been found whole.
        for piece in self.end_pieces(patch, model) {
            if let Some(d) = self.best_hypothesis(&piece, model).0 {
                let mut found = vec![d];
                self.add_rest(patch, model, &mut found);
                let kept = self.explanation(patch, model, &found);
                if kept.len() > 1 {
                    return (kept, fits);
                }
            }
        }
        (Vec::new(), fits)
    }

    /// Adds to `found` the best hypotheses of the rest of `patch`: its pixels more than a pixel
    /// outside every face found, tried whole, or where larger than every face, cut once; again
    /// on what is left while that finds more, up to the patch's [`MAX_PATCH_CUTS`] + 1 parts
    /// (a row of parts is taken one or two at a time).
    fn add_rest(&self, patch: &Patch, model: &CloudModel, found: &mut Vec<CloudDetection>) {
        for _ in 0..=MAX_PATCH_CUTS {
            let rest = Patch {
                pixels: patch
                    .pixels
                    .iter()
                    .copied()
                    .filter(|&i| {
                        found
                            .iter()
                            .all(|d| self.face_distance_m(model, d, &self.pts[i], false) > self.pixel_m_at(d))
                    })
                    .collect(),
            };
            if rest.pixels.len() < MIN_PATCH_PX {
                return;
            }
            let more = self.best_or_cut(&rest, model, 1);
            if more.is_empty() {
                return;
            }
            found.extend(more);
        }
    }

    /// The detections of `found` kept as the explanation of `patch`: all of them, if no pixel
    /// lies inside two faces; else each alone; the first that covers the whole patch but for a
    /// row of pixels. Empty if none does.
    fn explanation(&self, patch: &Patch, model: &CloudModel, found: &[CloudDetection]) -> Vec<CloudDetection> {
        let apart = |a: &CloudDetection, b: &CloudDetection| {
            !patch.pixels.iter().any(|&i| {
                [a, b]
                    .iter()
                    .all(|d| self.face_distance_m(model, d, &self.pts[i], false) < -self.pixel_m_at(d))
            })
        };
        let all_apart = found.len() > 1
            && found
                .iter()
                .enumerate()
                .all(|(k, a)| found[k + 1..].iter().all(|b| apart(a, b)));
        let mut options: Vec<&[CloudDetection]> = Vec::new();
        if all_apart {
            options.push(found);
        }
        options.extend(found.chunks(1));
        options
            .into_iter()
            .find(|ds| self.uncovered(model, ds, patch) <= self.row_px(model, ds))
            .map(<[CloudDetection]>::to_vec)
            .unwrap_or_default()
    }

    /// Pieces of a patch cut off either end along its principal axis (in space), each as long
    /// as one of the model's face extents (an outline face's, with the features beside it) and a
    /// pixel's slack: where parts lie level in a row, edge to edge, the first of them.
    fn end_pieces(&self, patch: &Patch, model: &CloudModel) -> Vec<Patch> {
        let n = patch.pixels.len() as f64;
        let mean = patch.pixels.iter().map(|&i| self.pts[i]).sum::<Vector3<f64>>() / n;
        let cov = patch.pixels.iter().fold(Matrix3::zeros(), |c, &i| {
            let d = self.pts[i] - mean;
            c + d * d.transpose()
        });
        let eig = cov.symmetric_eigen();
        let axis: Vector3<f64> = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
        let along: Vec<f64> = patch.pixels.iter().map(|&i| (self.pts[i] - mean).dot(&axis)).collect();
        let (lo, hi) = along
            .iter()
            .fold((f64::MAX, f64::MIN), |(lo, hi), &a| (lo.min(a), hi.max(a)));
        let pixel_m = self.camera.pixel_size_at_m((mean - self.origin).dot(&self.optical));
        let mut lengths: Vec<f64> = (0..model.faces.len())
            .flat_map(|fi| model.outline(fi).map_or(model.faces[fi].extent_m, |o| o.reach_extent_m))
            .collect();
        lengths.sort_by(f64::total_cmp);
        lengths.dedup_by(|a, b| (*a - *b).abs() < 0.5 * pixel_m);
        let mut pieces = Vec::new();
        for len in lengths.into_iter().filter(|l| l + pixel_m < hi - lo) {
            for from_lo in [true, false] {
                let pixels: Vec<usize> = patch
                    .pixels
                    .iter()
                    .zip(&along)
                    .filter(|&(_, &a)| {
                        if from_lo {
                            a <= lo + len + 0.5 * pixel_m
                        } else {
                            a >= hi - len - 0.5 * pixel_m
                        }
                    })
                    .map(|(&i, _)| i)
                    .collect();
                if pixels.len() >= MIN_PATCH_PX {
                    pieces.push(Patch { pixels });
                }
            }
        }
        pieces
    }

    /// The best hypothesis of each half of a patch larger than every face ([`Cloud::halves`]);
    /// a half that finds none and is itself larger than every face is cut again, `cuts` cuts
    /// deep in all: three or four parts lying level side by side make one patch too.
    fn cut_candidates(&self, patch: &Patch, model: &CloudModel, cuts: usize) -> Vec<CloudDetection> {
        self.halves(patch)
            .iter()
            .flat_map(|half| self.best_or_cut(half, model, cuts - 1))
            .collect()
    }

    /// A piece's best hypothesis, or where it finds none and is larger than every face, its
    /// [`Cloud::cut_candidates`] `cuts` cuts deep (none at 0).
    fn best_or_cut(&self, piece: &Patch, model: &CloudModel, cuts: usize) -> Vec<CloudDetection> {
        match self.best_hypothesis(piece, model) {
            (Some(d), _, _) => vec![d],
            (None, _, true) if cuts > 0 => self.cut_candidates(piece, model, cuts),
            _ => Vec::new(),
        }
    }

    /// The pixel size at a detection's position (m).
    fn pixel_m_at(&self, d: &CloudDetection) -> f64 {
        self.camera
            .pixel_size_at_m((d.world_from_part.translation.vector - self.origin).dot(&self.optical))
    }

    /// How far the point `p` (world) lies from the face up of `d` in its plane (m, negative
    /// inside): its rectangle or disc; for a face fitted by its outline, the outline with the
    /// features beside it within the plane band (`reach`, what its patch may hold) or the face
    /// alone (`reach` false).
    fn face_distance_m(&self, model: &CloudModel, d: &CloudDetection, p: &Vector3<f64>, reach: bool) -> f64 {
        let face = &model.faces[d.face_up];
        let q = d.world_from_part.inverse() * Point3::from(*p);
        let r = q.coords - face.center;
        let (u, v) = (r.dot(&face.along), r.dot(&face.normal.cross(&face.along)));
        if let Some(o) = model.outline(d.face_up) {
            return o.distance_m([u, v], reach);
        }
        if face.disc {
            let d = u.hypot(v);
            return (d - face.extent_m[0] / 2.0).max(face.hole_radius_m - d);
        }
        let (du, dv) = (u.abs() - face.extent_m[0] / 2.0, v.abs() - face.extent_m[1] / 2.0);
        if du > 0.0 || dv > 0.0 {
            du.max(0.0).hypot(dv.max(0.0))
        } else {
            du.max(dv)
        }
    }

    /// The pixels of `patch` that no face of `found` covers (grown by a pixel).
    fn uncovered(&self, model: &CloudModel, found: &[CloudDetection], patch: &Patch) -> usize {
        patch
            .pixels
            .iter()
            .filter(|&&i| {
                found
                    .iter()
                    .all(|d| self.face_distance_m(model, d, &self.pts[i], true) > self.pixel_m_at(d))
            })
            .count()
    }

    /// A row of pixels across the narrowest of the faces up in `found`: the slack of
    /// [`Cloud::uncovered`] (a cut a pixel off, depth noise at the rim).
    fn row_px(&self, model: &CloudModel, found: &[CloudDetection]) -> usize {
        found
            .iter()
            .map(|d| {
                let e = model.faces[d.face_up].extent_m;
                (e[0].min(e[1]) / self.pixel_m_at(d)).ceil() as usize
            })
            .min()
            .unwrap_or(0)
    }

    /// A patch cut in two by 2-means on its pixels' image positions, started at its two ends
    /// along its principal axis; empty if a half has fewer than [`MIN_PATCH_PX`] pixels.
    fn halves(&self, patch: &Patch) -> Vec<Patch> {
        let uv: Vec<[f64; 2]> = patch
            .pixels
            .iter()
            .map(|&i| [(i % self.w) as f64, (i / self.w) as f64])
            .collect();
        let n = uv.len() as f64;
        let mean = uv.iter().fold([0.0, 0.0], |m, p| [m[0] + p[0] / n, m[1] + p[1] / n]);
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        for p in &uv {
            let (x, y) = (p[0] - mean[0], p[1] - mean[1]);
            (sxx, sxy, syy) = (sxx + x * x, sxy + x * y, syy + y * y);
        }
        let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        let axis = [angle.cos(), angle.sin()];
        let along = |p: &[f64; 2]| (p[0] - mean[0]) * axis[0] + (p[1] - mean[1]) * axis[1];
        let (lo, hi) = uv.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
            let a = along(p);
            (lo.min(a), hi.max(a))
        });
        let mut centres = [
            [mean[0] + axis[0] * lo, mean[1] + axis[1] * lo],
            [mean[0] + axis[0] * hi, mean[1] + axis[1] * hi],
        ];
        let d2 = |p: &[f64; 2], c: &[f64; 2]| (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2);
        let mut second = vec![false; uv.len()];
        for _ in 0..8 {
            for (k, p) in uv.iter().enumerate() {
                second[k] = d2(p, &centres[1]) < d2(p, &centres[0]);
            }
            for (c, side) in centres.iter_mut().zip([false, true]) {
                let (mut sum, mut count) = ([0.0, 0.0], 0.0);
                for (p, _) in uv.iter().zip(&second).filter(|(_, s)| **s == side) {
                    sum = [sum[0] + p[0], sum[1] + p[1]];
                    count += 1.0;
                }
                if count > 0.0 {
                    *c = [sum[0] / count, sum[1] / count];
                }
            }
        }
        let part = |side: bool| Patch {
            pixels: patch
                .pixels
                .iter()
                .zip(&second)
                .filter(|(_, s)| **s == side)
                .map(|(i, _)| *i)
                .collect(),
        };
        let halves = vec![part(false), part(true)];
        if halves.iter().any(|h| h.pixels.len() < MIN_PATCH_PX) {
            return Vec::new();
        }
        halves
    }

    /// Each verified hypothesis's face swapped for its twins (the other model faces of the same
    /// extents), placed with the same centre, normal and first axis, and turned half about the
    /// normal; verified. Only for a model with outline-fitted faces, whose fit of one face can
    /// fail where its twin's would hold (a DIP-8 on its legs shows its top face with the leg
    /// shoulders beside it: when that outline fit finds no placement, its back's plain rectangle
    /// holds the patch and wins unrivalled, legs rendered up where the part's are down). Poses
    /// already verified are not tried again.
    fn twin_hypotheses(&self, model: &CloudModel, verified: &[(i64, CloudDetection)]) -> Vec<(i64, CloudDetection)> {
        if model.outlines.iter().all(Option::is_none) {
            return Vec::new();
        }
        let same_extents = |a: &Face, b: &Face| {
            let (a, b) = (a.extent_m, b.extent_m);
            (a[0] - b[0]).abs() + (a[1] - b[1]).abs() < 1e-6 || (a[0] - b[1]).abs() + (a[1] - b[0]).abs() < 1e-6
        };
        let mut out: Vec<(i64, CloudDetection)> = Vec::new();
        for (_, d) in verified {
            let (fi, pose) = (d.face_up, d.world_from_part);
            let face = &model.faces[fi];
            let center = pose * Point3::from(face.center);
            let n = pose.rotation * face.normal;
            for (gi, g) in model.faces.iter().enumerate() {
                if gi == fi || g.disc || face.disc || !same_extents(face, g) {
                    continue;
                }
                // The twin's first axis along the face's longer side, as the face's.
                let along = if (g.extent_m[0] >= g.extent_m[1]) == (face.extent_m[0] >= face.extent_m[1]) {
                    pose.rotation * face.along
                } else {
                    n.cross(&(pose.rotation * face.along))
                };
                for turn in [1.0, -1.0] {
                    let candidate = pose_from_face(g, &center.coords, &n, &(along * turn));
                    let known = verified
                        .iter()
                        .chain(out.iter())
                        .any(|(_, v)| model.same_pose(&v.world_from_part, &candidate));
                    if known {
                        continue;
                    }
                    if let Some(t) = self.check(model, &candidate, Some(gi)) {
                        out.push(t);
                    }
                }
            }
        }
        out
    }

    /// The pose the image prefers among a patch's verified hypotheses (evidence, detection),
    /// refined by `refine`. A close call (a different pose within [`CLOSE_CALL_PX`] points of
    /// the best) is decided at every pixel, each contender refined first (settled on the floor,
    /// so its height over the floor counts) and weighed by how well each pixel agrees
    /// ([`Cloud::log_likelihood`]): a DIP's 0.5 mm legs, which tell on its legs from on its
    /// back, fall between the grid's points; an SOIC's feet, 0.7 mm over its leads' shoulders
    /// when it lies on its back, agree within the 1 mm band either way. A different pose as well
    /// supported (within [`CLOSE_CALL_LOG_ODDS`]: a relay's pins not seen, on its back or not?)
    /// leaves the patch unrecognised.
    fn decide(
        &self,
        model: &CloudModel,
        verified: &[(i64, CloudDetection)],
        refine: impl Fn(CloudDetection) -> CloudDetection,
    ) -> Option<CloudDetection> {
        // The best, if no different pose comes within `margin` of it.
        let unrivalled = |hyps: &[(f64, &CloudDetection)], margin: f64| -> Option<CloudDetection> {
            let (evidence, best) = hyps.iter().max_by(|a, b| a.0.total_cmp(&b.0))?;
            let rival = hyps
                .iter()
                .any(|(e, d)| *e >= evidence - margin && !model.same_pose(&d.world_from_part, &best.world_from_part));
            (!rival).then(|| (*best).clone())
        };
        // Where some of a patch's hypotheses were verified on the grid and some, too small for
        // it, at every pixel, the latter's evidence counts in grid points too (a grid point
        // stands for stride^2 pixels): in pixels, a tactile switch's quarter turn that fell back
        // beat the right pose on the grid, 32 pixels against 12 points (44 pixels).
        let mixed =
            verified.iter().any(|(_, d)| d.fell_back_from > 0) && verified.iter().any(|(_, d)| d.fell_back_from == 0);
        let all: Vec<(f64, &CloudDetection)> = verified
            .iter()
            .map(|(e, d)| match d.fell_back_from {
                s if mixed && s > 1 => (*e as f64 / (s * s) as f64, d),
                _ => (*e as f64, d),
            })
            .collect();
        let (evidence, _) = all.iter().max_by(|a, b| a.0.total_cmp(&b.0))?;
        if let Some(best) = unrivalled(&all, CLOSE_CALL_PX as f64) {
            return Some(refine(best));
        }
        // Each contender refined (settled on the floor where it rests there) before it is
        // weighed: a pose's height over the floor is part of what it predicts.
        let refined: Vec<CloudDetection> = all
            .iter()
            .filter(|(e, _)| *e >= evidence - CLOSE_CALL_PX as f64)
            .map(|(_, d)| refine((*d).clone()))
            .collect();
        let close: Vec<(f64, &CloudDetection)> = refined
            .iter()
            .filter_map(|d| {
                self.log_likelihood(model, &self.at_measured_depth(model, d))
                    .map(|e| (e, d))
            })
            .collect();
        unrivalled(&close, CLOSE_CALL_LOG_ODDS)
    }

    /// `d`'s pose moved along the optical axis by the mean depth its agreeing pixels are
    /// measured off its rendering, where its face up is stepped ([`CloudModel`]'s `stepped`) and
    /// it does not rest on the floor (settled by `refine`, whose height the floor fixes): a face
    /// placed on its patch's plane where the patch also holds a second face a little lower or
    /// higher (a coin cell's cap and its can's rim, 0.3 mm apart, which one plane's band takes
    /// in) stands off the points by part of that step.
    fn at_measured_depth(&self, model: &CloudModel, d: &CloudDetection) -> Isometry3<f64> {
        let (pose, up) = (&d.world_from_part, self.floor.normal);
        if !model.is_stepped(d.face_up) || (model.lowest_along(pose, &up) - self.floor.point.dot(&up)).abs() < 1e-9 {
            return *pose;
        }
        let (mut sum, mut n) = (0.0, 0usize);
        let rendered = self.render(model, pose, 1, |i, predicted, graze| {
            if self.judge(i, predicted, graze) == Some(true) {
                sum += self.depth[i] - predicted;
                n += 1;
            }
        });
        if rendered.is_none() || n == 0 {
            return *pose;
        }
        Isometry3::from_parts(
            Translation3::from(pose.translation.vector + self.optical * (sum / n as f64)),
            pose.rotation,
        )
    }

    /// A hypothesis's evidence at every pixel, weighed by how well each agreeing pixel agrees
    /// ([`agree_log_ratio`]); `None` as `render`.
    fn log_likelihood(&self, model: &CloudModel, pose: &Isometry3<f64>) -> Option<f64> {
        let (per_pixel, two_var) = (agree_log_ratio(), 2.0 * refine::DEPTH_NOISE_M * refine::DEPTH_NOISE_M);
        let mut ll = 0.0;
        self.render(model, pose, 1, |i, predicted, graze| {
            match self.judge(i, predicted, graze) {
                Some(true) => ll += per_pixel - (self.depth[i] - predicted).powi(2) / two_var,
                Some(false) => ll -= 3.0 * per_pixel,
                None => {}
            }
        })?;
        Some(ll)
    }

    /// A hypothesis checked: physically possible (not under the tray floor) and verified by
    /// rendering; (evidence, detection). `face_up` `None`: lying on its curved side.
    fn check(
        &self,
        model: &CloudModel,
        pose: &Isometry3<f64>,
        face_up: Option<usize>,
    ) -> Option<(i64, CloudDetection)> {
        self.check_scored(model, pose, face_up).ok()
    }

    /// As [`Cloud::check`], a failed hypothesis giving its verification score (0 when it lies
    /// under the floor or shows nothing to verify).
    fn check_scored(
        &self,
        model: &CloudModel,
        pose: &Isometry3<f64>,
        face_up: Option<usize>,
    ) -> Result<(i64, CloudDetection), f64> {
        if model.lowest_along(pose, &self.floor.normal) < self.floor.point.dot(&self.floor.normal) - UNDER_FLOOR_M {
            return Err(0.0);
        }
        let ((score, visible, evidence), fell_back_from) = self.verify(model, pose).ok_or(0.0)?;
        if score < MIN_SCORE {
            return Err(score);
        }
        Ok((
            evidence,
            CloudDetection {
                world_from_part: *pose,
                face_up: face_up
                    .unwrap_or_else(|| model.face_nearest_up(pose, &(self.origin - pose.translation.vector))),
                score,
                visible_fraction: visible,
                curved_side_up: face_up.is_none(),
                yaw_span_rad: 0.0,
                fell_back_from,
            },
        ))
    }

    /// Every how many pixels (along rows and columns) a hypothesis at `pose` is verified: a
    /// grid about [`VERIFY_SPACING_M`] apart at its depth, or every pixel; every pixel for a part
    /// with thin features ([`CloudModel`]'s `fine_verify`: leads, pins), which decide between
    /// poses (a relay on its back or its face).
    fn verify_stride(&self, model: &CloudModel, pose: &Isometry3<f64>) -> usize {
        if model.fine_verify {
            return 1;
        }
        let z = (pose.translation.vector - self.origin).dot(&self.optical);
        let pixel_m = self.camera.pixel_size_at_m(z);
        ((VERIFY_SPACING_M / pixel_m).round() as usize).max(1)
    }

    /// Each piece's image box at `pose`, `margin_px` wider each side: (u, v) lowest, then
    /// highest, in continuous pixel coordinates (pixel u spans u to u + 1). A ray through a pixel
    /// centre outside a piece's box (margin 0 or more) cannot meet the piece, whose points project
    /// inside the box of its bounding box's corners (all in front of the camera, else the box is
    /// the whole image).
    fn piece_boxes(&self, model: &CloudModel, pose: &Isometry3<f64>, margin_px: f64) -> Vec<[f64; 4]> {
        model
            .pieces
            .iter()
            .map(|piece| {
                let reach = |axis: Vector3<f64>| [-piece.support_m(&-axis), piece.support_m(&axis)];
                let [x, y, z] = [reach(Vector3::x()), reach(Vector3::y()), reach(Vector3::z())];
                let mut b = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
                for k in 0..8 {
                    let p = pose * Point3::new(x[k & 1], y[(k >> 1) & 1], z[(k >> 2) & 1]);
                    let Some((u, v, _)) = self.camera.project(&p) else {
                        return [f64::MIN, f64::MIN, f64::MAX, f64::MAX];
                    };
                    b = [b[0].min(u), b[1].min(v), b[2].max(u), b[3].max(v)];
                }
                [b[0] - margin_px, b[1] - margin_px, b[2] + margin_px, b[3] + margin_px]
            })
            .collect()
    }

    /// Renders the model at `pose` into the image and compares with the measured depth: (score,
    /// visible fraction, evidence = agreeing less 3 x contradicting pixels), `None` if it renders
    /// too few agreeing pixels.
    ///
    /// A hypothesis whose grid holds fewer than [`MIN_GRID_SAMPLES`] rendered pixels is verified
    /// at every pixel instead: a small footprint (a DIP standing on its end shows 30 pixels, 8
    /// of them on the grid) would otherwise turn on a pixel or two.
    /// With the verdict, the grid's stride where it fell back to every pixel (its evidence
    /// then counts pixels, [`CloudDetection`]'s `fell_back_from`), else 0.
    fn verify(&self, model: &CloudModel, pose: &Isometry3<f64>) -> Option<(Verdict, usize)> {
        let stride = self.verify_stride(model, pose);
        let (counts, rendered) = self.verify_counts(model, pose, stride)?;
        if stride > 1 && rendered < MIN_GRID_SAMPLES {
            return self.verify_every(model, pose, 1).map(|v| (v, stride));
        }
        counts.map(|v| (v, 0))
    }

    /// [`Cloud::verify`] on every `stride`-th pixel.
    fn verify_every(&self, model: &CloudModel, pose: &Isometry3<f64>, stride: usize) -> Option<Verdict> {
        self.verify_counts(model, pose, stride)?.0
    }

    /// [`Cloud::verify_every`]'s result, and how many pixels it rendered; `None` as `render`.
    fn verify_counts(
        &self,
        model: &CloudModel,
        pose: &Isometry3<f64>,
        stride: usize,
    ) -> Option<(Option<Verdict>, usize)> {
        let (mut agree, mut contradict, mut rendered) = (0usize, 0usize, 0usize);
        self.render(model, pose, stride, |i, predicted, graze| {
            rendered += 1;
            match self.judge(i, predicted, graze) {
                Some(true) => agree += 1,
                Some(false) => contradict += 1,
                None => {}
            }
        })?;
        let counts = (agree >= MIN_PATCH_PX).then(|| {
            (
                agree as f64 / (agree + contradict) as f64,
                (agree as f64 / rendered.max(1) as f64).min(1.0),
                agree as i64 - 3 * contradict as i64,
            )
        });
        Some((counts, rendered))
    }

    /// What pixel `i`'s measured depth says of a rendered `predicted` depth: agrees within
    /// [`AGREE_TOL_M`] (`Some(true)`), measured behind it, a contradiction unless the ray only
    /// grazes a lead (`Some(false)`), or nothing (no return; measured in front: occluded).
    fn judge(&self, i: usize, predicted: f64, graze: bool) -> Option<bool> {
        let measured = self.depth[i];
        if measured <= 0.0 {
            None
        } else if (measured - predicted).abs() <= AGREE_TOL_M {
            Some(true)
        } else {
            (measured > predicted && !graze).then_some(false)
        }
    }

    /// Renders the model at `pose` on every `stride`-th pixel of the window (rows and columns of
    /// the image): `at(pixel, predicted depth, grazes a lead)` for each pixel whose ray meets
    /// the model, in row order. `None` if a corner of its box is behind the camera.
    fn render(
        &self,
        model: &CloudModel,
        pose: &Isometry3<f64>,
        stride: usize,
        mut at: impl FnMut(usize, f64, bool),
    ) -> Option<()> {
        let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        let hs = model.half_size_m;
        for k in 0..8 {
            let s = |bit: usize| if k & bit == 0 { -1.0 } else { 1.0 };
            let p = pose * Point3::new(s(1) * hs.x, s(2) * hs.y, s(4) * hs.z);
            let (u, v, _) = self.camera.project(&p)?;
            u0 = u0.min(u);
            v0 = v0.min(v);
            u1 = u1.max(u);
            v1 = v1.max(v);
        }
        // Window coordinates, on the grid (every `stride`-th pixel of the image).
        let clamp = |x: f64, first: usize, n: usize| {
            let i = (x.floor().max(first as f64) as usize).min(first + n - 1);
            i.div_ceil(stride) * stride
        };
        let inv = pose.inverse();
        let o = inv * Point3::from(self.origin);
        // Rays are cast only at the pieces whose image box holds the pixel's centre.
        let boxes = self.piece_boxes(model, pose, PIECE_BOX_MARGIN_PX);
        let mut in_row: Vec<usize> = Vec::with_capacity(boxes.len());
        let (vs, ve) = (
            clamp(v0, self.v0, self.h),
            clamp(v1, self.v0, self.h).min(self.v0 + self.h - 1),
        );
        let (us, ue) = (
            clamp(u0, self.u0, self.w),
            clamp(u1, self.u0, self.w).min(self.u0 + self.w - 1),
        );
        if let Some(mesh) = &model.mesh {
            if us > ue || vs > ve {
                return Some(());
            }
            let camera_from_part = self.camera.world_from_camera.inverse() * pose;
            let depth = mesh.depths(self.camera, &camera_from_part, [us, ue], [vs, ve], stride);
            let nu = (ue - us) / stride + 1;
            for (j, v) in (vs..=ve).step_by(stride).enumerate() {
                for (i, u) in (us..=ue).step_by(stride).enumerate() {
                    let z = depth[j * nu + i];
                    if z.is_finite() {
                        at((v - self.v0) * self.w + (u - self.u0), z, false);
                    }
                }
            }
            return Some(());
        }
        for v in (vs..=ve).step_by(stride) {
            let y = v as f64 + 0.5;
            in_row.clear();
            in_row.extend((0..boxes.len()).filter(|&k| boxes[k][1] <= y && y <= boxes[k][3]));
            if in_row.is_empty() && model.mesh.is_none() {
                continue;
            }
            for u in (us..=ue).step_by(stride) {
                let x = u as f64 + 0.5;
                let mut among = in_row
                    .iter()
                    .copied()
                    .filter(|&k| boxes[k][0] <= x && x <= boxes[k][2])
                    .peekable();
                if model.mesh.is_none() && among.peek().is_none() {
                    continue;
                }
                let d = self.camera.pixel_dir(u, v);
                let Some((t, graze)) = render::ray_among_graze(model, &o, &(inv.rotation * d), among) else {
                    continue;
                };
                at((v - self.v0) * self.w + (u - self.u0), t * d.dot(&self.optical), graze);
            }
        }
        Some(())
    }
}

/// The window of the image (u0, v0, width, height) (px) that can show the inside of `tray`: the
/// image box of its inner walls from the floor to 5 cm above the rim, a pixel wider each side,
/// within the image. From the camera and the fixed tray alone.
fn tray_window(camera: &Camera, tray: &TrayVolume, width_px: usize, height_px: usize) -> (usize, usize, usize, usize) {
    let [hx, hy] = [
        tray.half_xy_m[0] - tray.wall_thickness_m,
        tray.half_xy_m[1] - tray.wall_thickness_m,
    ];
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for k in 0..8 {
        let s = |bit: usize| if k & bit == 0 { -1.0 } else { 1.0 };
        let z = if k & 4 == 0 { 0.0 } else { tray.wall_height_m + 0.05 };
        let p = tray.world_from_tray * Point3::new(s(1) * hx, s(2) * hy, z);
        let Some((u, v, _)) = camera.project(&p) else {
            return (0, 0, width_px, height_px);
        };
        (lo[0], lo[1], hi[0], hi[1]) = (lo[0].min(u), lo[1].min(v), hi[0].max(u), hi[1].max(v));
    }
    let clamp = |x: f64, n: usize| (x.max(0.0) as usize).min(n - 1);
    let (u0, v0) = (
        clamp(lo[0].floor() - 1.0, width_px),
        clamp(lo[1].floor() - 1.0, height_px),
    );
    let (u1, v1) = (
        clamp(hi[0].ceil() + 1.0, width_px),
        clamp(hi[1].ceil() + 1.0, height_px),
    );
    (u0, v0, u1 - u0 + 1, v1 - v0 + 1)
}

/// `world_from_part` with face `face` centred at `center` (world), its outward normal along `n`
/// and its first axis along `u`.
fn pose_from_face(face: &Face, center: &Vector3<f64>, n: &Vector3<f64>, u: &Vector3<f64>) -> Isometry3<f64> {
    let world = Matrix3::from_columns(&[*u, n.cross(u), *n]);
    let part = Matrix3::from_columns(&[face.along, face.normal.cross(&face.along), face.normal]);
    let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(world * part.transpose()));
    Isometry3::from_parts(Translation3::from(center - r * face.center), r)
}

mod fit;
mod icp;
mod lying;
mod outline;
pub mod ppf;
mod refine;
mod render;
mod symmetry;

use crate::geometry::convex_hull_2d as convex_hull;
use fit::{fit_disc, fit_rect, min_area_theta};
#[cfg(test)]
use render::ray_model;
pub use symmetry::Symmetry;
#[cfg(test)]
mod tests;
