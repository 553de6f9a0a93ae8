//! The primitives a workpiece file builds a part from (boxes and cylinders, each a body or a lead)
//! and the flat faces of its body that follow from them analytically.
//!
//! Job: the primitive types ([`Piece`], its [`PartRole`] and cylinder [`Axis`]; the workpiece
//! file's format re-exports them) and [`body_faces`]: the flat faces of the body on which nothing
//! else of the part stands out, each as a [`Face`] (centre, normal, extents, disc or rectangle):
//! what the grasp selector fits the cup on and what recognition matches patches of the cloud to.
//!
//! Units: m. Frame: the part frame.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Roles of compound parts: the body carries the suction faces; leads do not.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PartRole {
    /// The part's body (suction faces).
    Body,
    /// A lead or pin.
    Lead,
}

/// Axes of the part frame.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    /// Part x.
    X,
    /// Part y.
    Y,
    /// Part z.
    Z,
}

impl Axis {
    /// The unit vector of this axis in the part frame.
    pub fn unit(self) -> Vector3<f64> {
        match self {
            Axis::X => Vector3::x(),
            Axis::Y => Vector3::y(),
            Axis::Z => Vector3::z(),
        }
    }
}

/// A workpiece primitive resolved to its geometry, in the part frame (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Piece {
    /// A box.
    Box {
        /// Centre.
        center_m: Vector3<f64>,
        /// Half extents.
        half_m: Vector3<f64>,
    },
    /// A cylinder.
    Cylinder {
        /// Centre.
        center_m: Vector3<f64>,
        /// Radius.
        radius_m: f64,
        /// Half length along `axis`.
        half_length_m: f64,
        /// Axis.
        axis: Axis,
    },
}

impl Piece {
    /// How far the piece reaches along the part-frame unit direction `n` from the part origin:
    /// the largest `p . n` over its points (m).
    pub fn support_m(&self, n: &Vector3<f64>) -> f64 {
        match self {
            Piece::Box { center_m, half_m } => {
                center_m.dot(n) + half_m.iter().zip(n.iter()).map(|(h, v)| h * v.abs()).sum::<f64>()
            }
            Piece::Cylinder {
                center_m,
                radius_m,
                half_length_m,
                axis,
            } => {
                let a = axis.unit().dot(n).abs();
                center_m.dot(n) + half_length_m * a + radius_m * (1.0 - a * a).max(0.0).sqrt()
            }
        }
    }
}

/// A flat face of a workpiece's body, in the part frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Face {
    /// Centre (m).
    pub center: Vector3<f64>,
    /// Outward normal (unit).
    pub normal: Vector3<f64>,
    /// Direction of the face's first extent (unit, in the face).
    pub along: Vector3<f64>,
    /// Extents along `along` and across it (m); equal for a disc (its diameter).
    pub extent_m: [f64; 2],
    /// A round face (cylinder cap).
    pub disc: bool,
    /// A round face's concentric round hole's radius (m; a washer's bore); 0 for none.
    pub hole_radius_m: f64,
}

/// The centre of a piece in the part frame (m).
fn piece_center(piece: &Piece) -> Vector3<f64> {
    match piece {
        Piece::Box { center_m, .. } | Piece::Cylinder { center_m, .. } => *center_m,
    }
}

/// The flat faces of a part's body pieces (box faces, cylinder caps) on which nothing else of the
/// part stands out: a capacitor's leads rule out the face they leave from, a can on a base rules
/// out the base's face under it and the can's end on the base. `pieces` as the workpiece lists
/// them (`Workpiece::pieces`); a mesh workpiece has none (its faces are the part model's
/// planar faces).
pub fn body_faces(pieces: &[(PartRole, Piece)]) -> Vec<Face> {
    let mut faces = Vec::new();
    for (k, (role, piece)) in pieces.iter().enumerate() {
        if *role != PartRole::Body {
            continue;
        }
        for f in piece_faces(piece) {
            let blocked = pieces.iter().enumerate().any(|(j, (_, other))| {
                let beyond = other.support_m(&f.normal) - f.center.dot(&f.normal) > 1e-4;
                let offset = piece_center(other) - f.center;
                let in_plane = (offset - f.normal * offset.dot(&f.normal)).norm();
                j != k && beyond && in_plane <= 0.5 * f.extent_m[0].max(f.extent_m[1])
            });
            if !blocked {
                faces.push(f);
            }
        }
    }
    faces
}

/// The flat faces of one piece.
fn piece_faces(piece: &Piece) -> Vec<Face> {
    let mut faces = Vec::new();
    match *piece {
        Piece::Box {
            center_m: c,
            half_m: he,
        } => {
            for a in 0..3 {
                let (b, d) = ((a + 1) % 3, (a + 2) % 3);
                for s in [-1.0, 1.0] {
                    faces.push(Face {
                        center: c + Vector3::ith(a, s * he[a]),
                        normal: Vector3::ith(a, s),
                        along: Vector3::ith(b, 1.0),
                        extent_m: [2.0 * he[b], 2.0 * he[d]],
                        disc: false,
                        hole_radius_m: 0.0,
                    });
                }
            }
        }
        Piece::Cylinder {
            center_m: c,
            radius_m: r,
            half_length_m: h,
            axis,
        } => {
            let a = axis.unit();
            let along = if axis == Axis::X { Vector3::y() } else { Vector3::x() };
            for s in [-1.0, 1.0] {
                faces.push(Face {
                    center: c + a * (s * h),
                    normal: a * s,
                    along,
                    extent_m: [2.0 * r, 2.0 * r],
                    disc: true,
                    hole_radius_m: 0.0,
                });
            }
        }
    }
    faces
}
