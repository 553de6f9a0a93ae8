//! The part model: one description of a workpiece's geometry, derived once, that every stage
//! reads (physics, sensor, recognition, grasp, place, recordings).
//!
//! Job: hold the part's surface as a triangle mesh ([`mesh::Mesh`]) in the part frame, whether it
//! came from a CAD file or from the workpiece file's primitives.
//!
//! Units: m. Frame: the part frame (origin at the centre of the part's bounding box, axes along
//! its edges).

pub mod mesh;
pub mod tessellate;
