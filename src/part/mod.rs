//! The part model: one description of a workpiece's geometry, derived once, that every stage
//! reads (physics, sensor, recognition, grasp, place, recordings).
//!
//! Job: hold the part's surface as a triangle mesh ([`mesh::Mesh`]) in the part frame, whether it
//! came from a CAD file or from the workpiece file's primitives, and what follows from it
//! ([`model::PartModel`]: mass properties, planar faces with their cup-fit regions, stable poses,
//! symmetry; [`round_side`]: where a bellows cup takes a round body by its side). The data flow:
//! [`import`] (and [`vrml`]) read a CAD file into a raw triangle soup ([`raw`]), [`repair`] makes
//! it a closed solid in metres (or refuses it), [`model`] derives the rest; [`svg`] draws it.
//! [`primitive`] holds the workpiece file's primitives and the flat body faces that follow from
//! them (what grasp and recognition fit and match). [`load_mesh`] is the one entry from a file to
//! a repaired mesh.
//!
//! This module depends on nothing else in the crate (the workpiece file's keys are read by
//! `config`, which calls [`load_mesh`]).
//!
//! Units: m. Frame: the part frame (origin at the centre of the part's bounding box, axes along
//! its edges).

pub mod approach;
pub mod faces;
pub mod import;
pub mod mass;
pub mod mesh;
pub mod model;
pub mod poses;
pub mod primitive;
pub mod raw;
pub mod repair;
pub mod round_side;
pub mod svg;
pub mod symmetry;
pub mod tessellate;
pub mod vrml;

use std::path::Path;

pub use model::{CupSpec, PartModel};
pub use raw::{Defect, MeshError};

/// Reads a mesh file (STL, OBJ or VRML 2.0) in units of `metres_per_unit` (named `units` in
/// messages) and repairs it into a closed, outward-wound mesh in metres about its bounding box's
/// centre, with what the repair did; or the defect that refuses it, naming the file.
pub fn load_mesh(
    path: &Path,
    metres_per_unit: f64,
    units: &str,
) -> Result<(mesh::Mesh, repair::RepairReport), MeshError> {
    let raw = import::read(path)?;
    repair::repair(&raw, metres_per_unit, units).map_err(|d| MeshError::new(path, d))
}
