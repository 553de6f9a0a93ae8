//! The raw triangle soup a mesh file is read into, the defects a file is refused for, and the
//! limits every reader keeps: what the readers ([`super::import`], [`super::vrml`]) and the
//! repair ([`super::repair`]) share.
//!
//! Units: the file's own. Frames: the file's.

use std::path::Path;

/// The most triangles a part's mesh may have: beyond, the file is refused (decimate it in the
/// CAD tool). 200k triangles is far finer than a suction cup or a depth sensor resolves on a
/// part of centimetres, and keeps every derivation of the part model well under a second.
pub const MAX_TRIANGLES: usize = 200_000;
/// The most vertices a text mesh file may declare.
pub const MAX_VERTICES: usize = 3 * MAX_TRIANGLES;
/// The most separate bodies (shells) a part's mesh may have: each is at least one convex piece
/// of the physics collider ([`crate::physics::shapes::MAX_PIECES`]). A 2 x 50 pin header is 101.
pub const MAX_BODIES: usize = 256;
/// The largest text mesh file read (bytes): an ASCII STL of [`MAX_TRIANGLES`] is ~50 MB.
pub const MAX_TEXT_BYTES: u64 = 96 * 1024 * 1024;

/// A triangle soup in the file's units, as read: no welding, no orientation fixed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RawMesh {
    /// Vertex positions (file units).
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

/// A mesh file that cannot be used, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: cannot load mesh: {defect}")]
pub struct MeshError {
    /// The mesh file as named.
    pub file: String,
    /// What is wrong with it.
    pub defect: Defect,
}

/// The defects a mesh file is refused for.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Defect {
    /// The file cannot be read.
    #[error("cannot read the file: {0}")]
    Unreadable(String),
    /// Not a format this reader knows.
    #[error("unsupported mesh format {0:?} (STL, OBJ or VRML 2.0 .wrl)")]
    Format(String),
    /// The file ends before its content does.
    #[error("truncated: {0}")]
    Truncated(String),
    /// A syntax error.
    #[error("malformed at {at}: {what}")]
    Malformed {
        /// Where (`line N`).
        at: String,
        /// What was expected or found.
        what: String,
    },
    /// A coordinate is NaN or infinite.
    #[error("non-finite vertex coordinate {value} at {at}")]
    NonFinite {
        /// Where.
        at: String,
        /// The value as written.
        value: String,
    },
    /// A face names a vertex that does not exist.
    #[error("face index {index} out of range ({vertices} vertices) at {at}")]
    IndexOutOfRange {
        /// Where.
        at: String,
        /// The index as written.
        index: i64,
        /// Vertices defined.
        vertices: usize,
    },
    /// More triangles than [`MAX_TRIANGLES`].
    #[error("{found} triangles, more than the {cap} a part may have: decimate the mesh in the CAD tool")]
    TooManyTriangles {
        /// Triangles found (or announced, or read before stopping).
        found: u64,
        /// The cap.
        cap: usize,
    },
    /// More separate bodies than [`MAX_BODIES`].
    #[error("{found} separate bodies, more than the {cap} a part may have: merge them in the CAD tool")]
    TooManyBodies {
        /// Bodies found.
        found: usize,
        /// The cap.
        cap: usize,
    },
    /// A text file larger than [`MAX_TEXT_BYTES`].
    #[error("file of {bytes} bytes, larger than the {cap} read: decimate the mesh in the CAD tool")]
    TooLarge {
        /// File size.
        bytes: u64,
        /// The cap.
        cap: u64,
    },
    /// A VRML construct this reader does not turn into triangles.
    #[error("unsupported VRML: {0}")]
    Unsupported(String),
    /// No triangle with an area is left.
    #[error("empty mesh: {0}")]
    Empty(String),
    /// Holes too large to close.
    #[error("open shell: {0}")]
    OpenShell(String),
    /// The mesh's size says its units are wrong.
    #[error("wrong units: {0}")]
    Units(String),
}

impl MeshError {
    /// A defect of `path`.
    pub fn new(path: &Path, defect: Defect) -> Self {
        MeshError {
            file: path.display().to_string(),
            defect,
        }
    }
}

/// A number token as a finite coordinate.
pub fn coordinate(token: &str, at: impl Fn() -> String) -> Result<f64, Defect> {
    let v: f64 = token.parse().map_err(|_| Defect::Malformed {
        at: at(),
        what: format!("expected a number, got {token:?}"),
    })?;
    if !v.is_finite() {
        return Err(Defect::NonFinite {
            at: at(),
            value: token.to_string(),
        });
    }
    Ok(v)
}
