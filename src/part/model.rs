//! The part model derived once from a part's closed mesh: what every stage needs to know about
//! the part's geometry.
//!
//! Job: from the repaired mesh ([`super::repair`]) and the part's mass, derive the mass
//! properties ([`super::mass`]), the planar faces with their cup-fit regions for the cell's cup
//! ([`super::faces`]), the convex hull and the stable resting poses with their likelihoods
//! ([`super::poses`]), and the rotational symmetry ([`super::symmetry`], or the file's override).
//!
//! Units: m, kg. Frame: the part frame (origin at the bounding box's centre).

use nalgebra::Point3;

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
}

impl PartModel {
    /// Derives the model from a closed, outward-wound mesh in the part frame.
    pub fn derive(mesh: Mesh, mass: MassSpec, cup: CupSpec, symmetry: Option<Symmetry>) -> Result<Self, ModelError> {
        let mp = mass_properties(&mesh, mass).ok_or(ModelError::NoVolume)?;
        let size_m = mesh.extent_m();
        let diag = size_m.iter().map(|e| e * e).sum::<f64>().sqrt();
        let tol = 1e-5 * diag;
        let raw = planar_faces(&mesh, tol.max(1e-9));
        let largest = raw.first().map_or(0.0, |f| f.area_m2);
        let faces = raw
            .into_iter()
            .filter(|f| f.area_m2 >= MIN_FACE_SHARE * largest && !f.outer.is_empty())
            .map(|face| {
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
        })
    }

    /// The faces the cup seals on, largest first.
    pub fn grasp_faces(&self) -> impl Iterator<Item = &ModelFace> {
        self.faces.iter().filter(|f| f.fit.takes_cup())
    }

    /// The share of resting poses (by likelihood) in which a face that takes the cup looks up
    /// (its normal within `tilt_rad` of the floor's up direction at rest).
    pub fn graspable_share(&self, tilt_rad: f64) -> f64 {
        self.poses
            .iter()
            .filter(|p| {
                // At rest, the pose's normal points down: a face looks up when its normal is
                // opposite the pose's.
                self.grasp_faces()
                    .any(|f| (-f.face.normal.dot(&p.normal)) >= tilt_rad.cos())
            })
            .map(|p| p.likelihood)
            .fold(0.0, |a, b| a + b)
    }

    /// The centre of mass (m).
    pub fn com_m(&self) -> Point3<f64> {
        self.mass.com_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::mass::tests::box_mesh;

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
        let share = pm.graspable_share(0.1);
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
        assert_eq!(pm.graspable_share(0.1), 0.0);
    }
}
