//! The part model derived once from a part's closed mesh: what every stage needs to know about
//! the part's geometry.
//!
//! Job: from the repaired mesh ([`super::repair`]) and the part's mass, derive the mass
//! properties ([`super::mass`]), the planar faces with their cup-fit regions for the cell's cup
//! ([`super::faces`]), the convex hull and the stable resting poses with their likelihoods
//! ([`super::poses`]), and the rotational symmetry ([`super::symmetry`], or the file's override).
//!
//! Units: m, kg. Frame: the part frame (origin at the bounding box's centre).

use nalgebra::{Point3, Vector3};

use super::faces::{CupFit, PlanarFace, planar_faces};
use super::mass::{MassProperties, MassSpec, mass_properties};
use super::mesh::Mesh;
use super::poses::{Hull, RestingPose, convex_hull, resting_poses};
use super::symmetry::{Symmetry, detect};

/// Faces smaller than this share of the largest face are not kept as faces.
pub const MIN_FACE_SHARE: f64 = 0.002;

/// The cup the faces are fitted for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CupSpec {
    /// Cup diameter (m).
    pub diameter_m: f64,
    /// Smallest margin between the cup's edge and the face's edge that still seals (m).
    pub face_margin_m: f64,
}

impl CupSpec {
    /// The radius of the disc that must lie on a face: cup radius plus margin (m).
    pub fn disc_radius_m(&self) -> f64 {
        0.5 * self.diameter_m + self.face_margin_m
    }
}

/// A planar face with its cup-fit region.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelFace {
    /// The face.
    pub face: PlanarFace,
    /// Where the cup seals on it.
    pub fit: CupFit,
}

/// Why a part model could not be derived.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// The mesh encloses no volume.
    #[error("the mesh encloses no volume (not a closed solid)")]
    NoVolume,
    /// The mesh's vertices are flat: no hull.
    #[error("the mesh is flat: it has no convex hull with a volume")]
    Flat,
}

/// The part model.
#[derive(Debug, Clone, PartialEq)]
pub struct PartModel {
    /// The surface.
    pub mesh: Mesh,
    /// Bounding box edge lengths (m).
    pub size_m: [f64; 3],
    /// Mass properties of the solid.
    pub mass: MassProperties,
    /// Planar faces, largest first, each with its cup-fit region.
    pub faces: Vec<ModelFace>,
    /// The convex hull.
    pub hull: Hull,
    /// Stable resting poses, most likely first.
    pub poses: Vec<RestingPose>,
    /// Rotational symmetry (detected, or as overridden).
    pub symmetry: Symmetry,
    /// Whether the symmetry was detected (false: from the file).
    pub symmetry_detected: bool,
    /// The cup the faces were fitted for.
    pub cup: CupSpec,
    /// Its round bodies (regular prisms about a part axis: a can, pins), found among all its
    /// planar faces (the smallest included); each one's side faces as indices into `faces`
    /// (those kept there).
    pub round: Vec<RoundBody>,
}

/// Turns a declared round symmetry stands for in [`PartModel::mesh_under_symmetry`].
pub const ROUND_TURNS: u32 = 16;
/// Most images of the mesh in [`PartModel::mesh_under_symmetry`].
pub const MAX_SYMMETRY_IMAGES: usize = 64;

impl PartModel {
    /// Derives the model from a closed, outward-wound mesh in the part frame.
    pub fn derive(mesh: Mesh, mass: MassSpec, cup: CupSpec, symmetry: Option<Symmetry>) -> Result<Self, ModelError> {
        let mp = mass_properties(&mesh, mass).ok_or(ModelError::NoVolume)?;
        let size_m = mesh.extent_m();
        let diag = size_m.iter().map(|e| e * e).sum::<f64>().sqrt();
        let tol = 1e-5 * diag;
        let raw = planar_faces(&mesh, tol.max(1e-9));
        let largest = raw.first().map_or(0.0, |f| f.area_m2);
        let mut round = round_bodies(&raw, size_m);
        let kept: Vec<bool> = raw
            .iter()
            .map(|f| f.area_m2 >= MIN_FACE_SHARE * largest && !f.outer.is_empty())
            .collect();
        // Raw face indices to kept ones.
        let index: Vec<Option<usize>> = kept
            .iter()
            .scan(0, |n, &k| {
                let i = k.then_some(*n);
                *n += usize::from(k);
                Some(i)
            })
            .collect();
        for r in &mut round {
            r.faces = r.faces.iter().filter_map(|&i| index[i]).collect();
        }
        let faces = raw
            .into_iter()
            .zip(kept)
            .filter(|(_, k)| *k)
            .map(|(face, _)| {
                let fit = face.cup_fit(cup.disc_radius_m());
                ModelFace { face, fit }
            })
            .collect();
        let hull = convex_hull(&mesh).ok_or(ModelError::Flat)?;
        let poses = resting_poses(&hull, &mp.com_m);
        let (symmetry, symmetry_detected) = match symmetry {
            Some(s) => (s, false),
            None => (detect(&mesh, &mp.com_m, (10.0 * tol).max(1e-8)), true),
        };
        Ok(PartModel {
            mesh,
            size_m,
            mass: mp,
            faces,
            hull,
            poses,
            symmetry,
            symmetry_detected,
            cup,
            round,
        })
    }

    /// The faces the cup seals on, largest first.
    pub fn grasp_faces(&self) -> impl Iterator<Item = &ModelFace> {
        self.faces.iter().filter(|f| f.fit.takes_cup())
    }

    /// Whether, resting in `pose`, the part has a face up (its normal within `tilt_rad` of the
    /// floor's up direction) that takes the cup at a site the approach reaches (`sites`, from
    /// [`PartModel::cup_sites`]: a face whose every site's approach meets the part's own pins is
    /// not one, as the grasp selector leaves it).
    pub fn cup_face_up(&self, pose: &RestingPose, tilt_rad: f64, sites: &[Option<(Point3<f64>, f64)>]) -> bool {
        // At rest, the pose's normal points down: a face looks up when its normal is opposite
        // the pose's.
        self.faces
            .iter()
            .zip(sites)
            .any(|(f, site)| site.is_some() && -f.face.normal.dot(&pose.normal) >= tilt_rad.cos())
    }

    /// The share of resting poses (by likelihood) in which a face that takes the cup looks up
    /// ([`PartModel::cup_face_up`]).
    pub fn graspable_share(&self, tilt_rad: f64, sites: &[Option<(Point3<f64>, f64)>]) -> f64 {
        self.poses
            .iter()
            .filter(|p| self.cup_face_up(p, tilt_rad, sites))
            .map(|p| p.likelihood)
            .fold(0.0, |a, b| a + b)
    }

    /// The mesh as the cell may find the part: where the symmetry is the file's (declared, not
    /// detected), recognition reports a pose only up to turns that do not map the mesh onto
    /// itself (a relay declared symmetric under a half turn, whose fifth pin is not), so what
    /// stands above a face is the union of the mesh's images under those turns (about the part
    /// frame's axes through the centre of mass; a round order as [`ROUND_TURNS`] turns, at most
    /// [`MAX_SYMMETRY_IMAGES`] images). A detected symmetry maps the mesh onto itself: the mesh.
    pub fn mesh_under_symmetry(&self) -> std::borrow::Cow<'_, Mesh> {
        use nalgebra::Rotation3;
        if self.symmetry_detected || self.symmetry.orders.iter().all(|&n| n <= 1) {
            return std::borrow::Cow::Borrowed(&self.mesh);
        }
        let turns = |axis: Vector3<f64>, order: u32| {
            let n = if order >= super::symmetry::MAX_ORDER {
                ROUND_TURNS
            } else {
                order.max(1)
            };
            (0..n).map(move |k| {
                Rotation3::from_axis_angle(
                    &nalgebra::Unit::new_normalize(axis),
                    k as f64 * std::f64::consts::TAU / n as f64,
                )
            })
        };
        let [ox, oy, oz] = self.symmetry.orders;
        let mut images = Vec::new();
        for rx in turns(Vector3::x(), ox) {
            for ry in turns(Vector3::y(), oy) {
                for rz in turns(Vector3::z(), oz) {
                    images.push(rx * ry * rz);
                }
            }
        }
        images.truncate(MAX_SYMMETRY_IMAGES);
        let com = self.mass.com_m;
        let mut out = Mesh {
            vertices_m: Vec::with_capacity(self.mesh.vertices_m.len() * images.len()),
            triangles: Vec::with_capacity(self.mesh.triangles.len() * images.len()),
        };
        for r in &images {
            let off = out.vertices_m.len() as u32;
            out.vertices_m
                .extend(self.mesh.vertices_m.iter().map(|p| com + r * (p - com)));
            out.triangles
                .extend(self.mesh.triangles.iter().map(|t| t.map(|i| i + off)));
        }
        std::borrow::Cow::Owned(out)
    }

    /// Per face (in [`PartModel::faces`] order), where the cup goes: the clearest centre of its
    /// cup-fit region whose approach (`column`: cup, then tool body) misses the part's features
    /// above the face in every pose recognition cannot tell apart
    /// ([`PartModel::mesh_under_symmetry`]), as a part-frame point with its distance to the
    /// face's nearest edge (m); `None` where the face does not take the cup or every site's
    /// approach meets the part. The grasp selector and `binpick part` read this one answer.
    pub fn cup_sites(&self, column: &[super::approach::ColumnPiece]) -> Vec<Option<(Point3<f64>, f64)>> {
        let features = self.mesh_under_symmetry();
        self.faces
            .iter()
            .map(|f| {
                if !f.fit.takes_cup() {
                    return None;
                }
                super::approach::clear_site(&features, &f.face, &f.fit.centres, column)
                    .map(|(site, clearance)| (f.face.to_part(&site), clearance))
            })
            .collect()
    }

    /// The centre of mass (m).
    pub fn com_m(&self) -> Point3<f64> {
        self.mass.com_m
    }

    /// The part's round body, if it has one: the largest of its `round` bodies (a can, a
    /// round standoff), on whose curved side the part can lie.
    pub fn round_body(&self) -> Option<&RoundBody> {
        self.round
            .iter()
            .fold(None, |best: Option<&RoundBody>, body| match best {
                Some(b) if b.radius_m * b.half_length_m >= body.radius_m * body.half_length_m => Some(b),
                _ => Some(body),
            })
    }
}

/// The round bodies among `faces`: each regular prism of at least [`ROUND_MIN_SIDES`] side faces
/// about a part axis (a cylinder as CAD and the tessellation draw it: a can, a pin). Side
/// faces of one prism: normal across the axis, the same span along it, each next to the
/// next (centroids within 1.5 face widths), the same distance from the axis through their
/// centroids' mean, normals turned in equal steps.
fn round_bodies(faces: &[PlanarFace], size_m: [f64; 3]) -> Vec<RoundBody> {
    let cos_tol = super::faces::FACE_ANGLE_TOL_RAD.cos();
    let tol = 1e-4 * size_m.iter().map(|e| e * e).sum::<f64>().sqrt();
    let mut found: Vec<RoundBody> = Vec::new();
    for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
        let face = |i: usize| &faces[i];
        let span = |i: usize| {
            let f = face(i);
            f.outer
                .iter()
                .map(|p| f.to_part(p).coords.dot(&axis))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| (lo.min(t), hi.max(t)))
        };
        let width = |i: usize| {
            let e = face(i).extent_m();
            e[0].min(e[1])
        };
        let mut left: Vec<usize> = (0..faces.len())
            .filter(|&i| face(i).normal.dot(&axis).abs() < (1.0 - cos_tol * cos_tol).sqrt())
            .collect();
        while let Some(&seed) = left.first() {
            let (lo, hi) = span(seed);
            // Grown from the seed through neighbours of the same span.
            let mut prism = vec![seed];
            left.retain(|&i| i != seed);
            let mut k = 0;
            while k < prism.len() {
                let a = prism[k];
                let near: Vec<usize> = left
                    .iter()
                    .copied()
                    .filter(|&i| {
                        let (l, h) = span(i);
                        (l - lo).abs() < tol
                            && (h - hi).abs() < tol
                            && (face(i).centroid_m - face(a).centroid_m).norm() < 1.5 * width(a).max(width(i))
                    })
                    .collect();
                left.retain(|i| !near.contains(i));
                prism.extend(near);
                k += 1;
            }
            if prism.len() < ROUND_MIN_SIDES as usize {
                continue;
            }
            let mean = prism.iter().map(|&i| face(i).centroid_m.coords).sum::<Vector3<f64>>() / prism.len() as f64;
            let centre = mean - axis * axis.dot(&mean) + axis * (0.5 * (lo + hi));
            let apothem = |i: usize| face(i).normal.dot(&(face(i).centroid_m.coords - centre));
            let d0 = apothem(prism[0]);
            if d0 <= 0.0 || prism.iter().any(|&i| (apothem(i) - d0).abs() > tol) {
                continue;
            }
            let n = prism.len();
            let e1 = axis.cross(&Vector3::new(axis.z, axis.x, axis.y));
            let e2 = axis.cross(&e1);
            let mut angles: Vec<f64> = prism
                .iter()
                .map(|&i| face(i).normal.dot(&e1).atan2(face(i).normal.dot(&e2)))
                .collect();
            angles.sort_by(f64::total_cmp);
            let step = std::f64::consts::TAU / n as f64;
            let regular = (0..n).all(|j| {
                let next = if j + 1 < n {
                    angles[j + 1]
                } else {
                    angles[0] + std::f64::consts::TAU
                };
                (next - angles[j] - step).abs() < 0.01
            });
            if regular {
                prism.sort_unstable();
                found.push(RoundBody {
                    center_m: centre,
                    axis,
                    radius_m: d0 / (std::f64::consts::PI / n as f64).cos(),
                    half_length_m: 0.5 * (hi - lo),
                    faces: prism,
                });
            }
        }
    }
    found
}

/// Fewest side faces of a regular prism taken as a round body.
pub const ROUND_MIN_SIDES: u32 = 8;

/// A part's round body ([`PartModel::round_body`]): a regular prism about a part axis, taken as
/// the cylinder through its corners.
#[derive(Debug, Clone, PartialEq)]
pub struct RoundBody {
    /// Centre of the prism (part frame, m).
    pub center_m: Vector3<f64>,
    /// Its axis (a part axis, unit).
    pub axis: Vector3<f64>,
    /// The radius of the circle through its corners (m).
    pub radius_m: f64,
    /// Half its length along the axis (m).
    pub half_length_m: f64,
    /// Its side faces kept among the model's faces (indices into [`PartModel::faces`]).
    pub faces: Vec<usize>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::mass::tests::box_mesh;

    #[test]
    fn a_declared_symmetry_adds_the_turned_images_and_a_detected_one_does_not() {
        let m = box_mesh([0.0, 0.0, 0.0], [0.02, 0.01, 0.004]);
        let cup = CupSpec {
            diameter_m: 0.006,
            face_margin_m: 0.0005,
        };
        let detected = PartModel::derive(m.clone(), MassSpec::MassKg(0.002), cup, None).unwrap();
        assert!(matches!(detected.mesh_under_symmetry(), std::borrow::Cow::Borrowed(_)));
        // Declared: a quarter turn about z, which the 20 x 10 box does not have. Its images stand
        // out 5 mm beyond the box along y, as a turned box would (independent: half of 20 mm
        // across the 10 mm side about the centre of mass).
        let declared =
            PartModel::derive(m, MassSpec::MassKg(0.002), cup, Some(Symmetry { orders: [1, 1, 4] })).unwrap();
        let images = declared.mesh_under_symmetry();
        assert_eq!(images.triangles.len(), 4 * declared.mesh.triangles.len());
        let (lo, hi) = images.bounds_m().unwrap();
        let c = declared.com_m();
        assert!(
            (hi.y - c.y - 0.01).abs() < 1e-12 && (c.y - lo.y - 0.01).abs() < 1e-12,
            "{lo:?} {hi:?}"
        );
    }

    #[test]
    fn a_plate_model_has_its_faces_poses_and_symmetry() {
        let m = box_mesh([-0.01, -0.0075, -0.0025], [0.01, 0.0075, 0.0025]);
        let cup = CupSpec {
            diameter_m: 0.006,
            face_margin_m: 0.0005,
        };
        let pm = PartModel::derive(m, MassSpec::MassKg(0.002), cup, None).unwrap();
        assert_eq!(pm.faces.len(), 6);
        // The 20 x 15 faces and the 20 x 5 and 15 x 5 sides: only the two large faces take a
        // 7 mm disc.
        assert_eq!(pm.grasp_faces().count(), 2);
        assert!(pm.grasp_faces().all(|f| f.face.normal.z.abs() > 0.999));
        assert_eq!(pm.symmetry.orders, [2, 2, 2]);
        // Lying flat is most likely, and then a large face looks up.
        assert!(pm.poses[0].normal.z.abs() > 0.999);
        let share = pm.graspable_share(0.1, &pm.cup_sites(&[]));
        let flat: f64 = pm
            .poses
            .iter()
            .filter(|p| p.normal.z.abs() > 0.999)
            .map(|p| p.likelihood)
            .sum();
        assert!((share - flat).abs() < 1e-12 && share > 0.5, "{share}");
        // A cup too large for every face: none takes it (negative control).
        let big = CupSpec {
            diameter_m: 0.016,
            face_margin_m: 0.0005,
        };
        let pm = PartModel::derive(pm.mesh.clone(), MassSpec::MassKg(0.002), big, None).unwrap();
        assert_eq!(pm.grasp_faces().count(), 0);
        assert_eq!(pm.graspable_share(0.1, &pm.cup_sites(&[])), 0.0);
    }

    #[test]
    fn round_bodies_are_the_regular_prisms_a_can_and_its_pins() {
        use crate::part::primitive::{Axis, Piece};
        use crate::part::tessellate::pieces_mesh;
        use nalgebra::Vector3;
        let cup = CupSpec {
            diameter_m: 0.006,
            face_margin_m: 0.0005,
        };
        // A 10 mm can (16-sided prism, 8.5 mm long) on a 9.8 mm square base, two 1 mm pins
        // under the base along z, and a 1 mm pin along x out of the can's side.
        let pin = |c: [f64; 3], axis| Piece::Cylinder {
            center_m: Vector3::from(c),
            radius_m: 0.0005,
            half_length_m: 0.0015,
            axis,
        };
        let pieces = [
            Piece::Cylinder {
                center_m: Vector3::new(0.0, 0.0, 0.00075),
                radius_m: 0.005,
                half_length_m: 0.00425,
                axis: Axis::Z,
            },
            Piece::Box {
                center_m: Vector3::new(0.0, 0.0, -0.00425),
                half_m: Vector3::new(0.0049, 0.0049, 0.00075),
            },
            pin([0.003, 0.0, -0.0065], Axis::Z),
            pin([-0.003, 0.0, -0.0065], Axis::Z),
            pin([0.0065, 0.0, 0.002], Axis::X),
        ];
        let pm = PartModel::derive(pieces_mesh(pieces.iter()), MassSpec::MassKg(0.002), cup, None).unwrap();
        let mut found: Vec<(f64, [f64; 3])> = pm
            .round
            .iter()
            .map(|r| (r.radius_m, [r.axis.x, r.axis.y, r.axis.z]))
            .collect();
        found.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(found.len(), 4, "{found:?}");
        assert!(found[..3].iter().all(|(r, _)| (r - 0.0005).abs() < 1e-9), "{found:?}");
        assert!(
            (found[3].0 - 0.005).abs() < 1e-9 && found[3].1 == [0.0, 0.0, 1.0],
            "{found:?}"
        );
        let can = pm.round_body().unwrap();
        assert!(
            (can.center_m - Vector3::new(0.0, 0.0, 0.00075)).norm() < 1e-9,
            "{:?}",
            can.center_m
        );
        assert!((can.half_length_m - 0.00425).abs() < 1e-9);
        // Its 16 side faces are kept faces, each normal across z.
        assert_eq!(can.faces.len(), 16);
        assert!(can.faces.iter().all(|&i| pm.faces[i].face.normal.z.abs() < 1e-9));
        // Negative controls: a box and a hexagonal prism (6 sides) have no round body.
        let hex = crate::part::tessellate::prism_mesh(Vector3::zeros(), 0.007, 0.002, Axis::Z, 6);
        for m in [box_mesh([-0.01, -0.0075, -0.0025], [0.01, 0.0075, 0.0025]), hex] {
            let pm = PartModel::derive(m, MassSpec::MassKg(0.002), cup, None).unwrap();
            assert!(pm.round.is_empty() && pm.round_body().is_none());
        }
    }
}
