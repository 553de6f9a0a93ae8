//! Workpiece shapes for the physics world: boxes, compounds of boxes and cylinders (bodies with
//! leads), and triangle meshes (OBJ or STL) convex-decomposed for their dynamic collider.
//!
//! Units: m, kg. Frame: the part frame of the workpiece file (origin at the bounding-box centre).
//! rapier's cylinders run along their local +y; workpiece cylinders along x, y or z are rotated.

use std::path::Path;

use nalgebra::{Matrix3, Vector3};
use rapier3d::math::{Pose, Vector};
use rapier3d::prelude::SharedShape;

use crate::config::{Piece, ShapeKind, Source, Workpiece};

/// Why a workpiece shape could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ShapeError {
    /// The mesh file could not be read or parsed.
    #[error("{file}: cannot load mesh: {reason}")]
    Mesh {
        /// The mesh file.
        file: String,
        /// What went wrong.
        reason: String,
    },
    /// A primitive has no volume.
    #[error("workpiece {0:?} has a degenerate primitive")]
    Degenerate(String),
    /// An embedded workpiece names a mesh (embedded workpieces must be self-contained).
    #[error("workpiece {0:?} is embedded but names a mesh file; give its path instead")]
    EmbeddedMesh(String),
}

/// A workpiece's collision shape and mass properties, built once and shared by every part.
#[derive(Clone)]
pub struct PartShape {
    /// The collider shape in the part frame, in rapier units (millimetres):
    /// convex polyhedra, whose contacts rest parts stably.
    pub(super) shape: SharedShape,
    /// The same geometry for rays (sensor, suction probes): boxes as cuboids, whose ray test is
    /// analytic and twice as fast as a polyhedron's.
    pub(super) view_shape: SharedShape,
    /// Mass [kg].
    pub mass_kg: f64,
    /// Centre of mass in the part frame [m].
    pub com_m: Vector3<f64>,
    /// Inertia about the centre of mass, part axes [kg m^2].
    pub inertia_com_kg_m2: Matrix3<f64>,
    /// Radius of the bounding sphere about the part origin [m].
    pub bounding_radius_m: f64,
    /// Half extents of the bounding box [m].
    pub half_extents_m: Vector3<f64>,
    /// The convex pieces for the independent overlap check (`None` for meshes).
    pub pieces: Option<Vec<super::overlap::Polytope>>,
    /// Coulomb friction coefficient.
    pub friction: f64,
    /// Restitution coefficient.
    pub restitution: f64,
}

/// Loads a triangle mesh from an OBJ or STL file, scaled to metres.
pub(crate) fn load_mesh(path: &Path, scale: f64) -> Result<(Vec<Vector>, Vec<[u32; 3]>), ShapeError> {
    let err = |reason: String| ShapeError::Mesh {
        file: path.display().to_string(),
        reason,
    };
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let (verts, tris): (Vec<[f64; 3]>, Vec<[u32; 3]>) = match ext.as_str() {
        "obj" => {
            let opts = tobj::LoadOptions {
                triangulate: true,
                single_index: true,
                ..Default::default()
            };
            let (models, _) = tobj::load_obj(path, &opts).map_err(|e| err(e.to_string()))?;
            let mut verts = Vec::new();
            let mut tris = Vec::new();
            for m in models {
                let base = verts.len() as u32;
                verts.extend(
                    m.mesh
                        .positions
                        .chunks_exact(3)
                        .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]),
                );
                tris.extend(
                    m.mesh
                        .indices
                        .chunks_exact(3)
                        .map(|t| [base + t[0], base + t[1], base + t[2]]),
                );
            }
            (verts, tris)
        }
        "stl" => {
            let mut f = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
            let mesh = stl_io::read_stl(&mut f).map_err(|e| err(e.to_string()))?;
            let verts = mesh
                .vertices
                .iter()
                .map(|v| [v[0] as f64, v[1] as f64, v[2] as f64])
                .collect();
            let tris = mesh
                .faces
                .iter()
                .map(|f| [f.vertices[0] as u32, f.vertices[1] as u32, f.vertices[2] as u32])
                .collect();
            (verts, tris)
        }
        other => return Err(err(format!("unsupported mesh format {other:?} (OBJ or STL)"))),
    };
    if verts.len() < 4 || tris.is_empty() {
        return Err(err(format!(
            "needs a closed mesh, got {} vertices and {} triangles",
            verts.len(),
            tris.len()
        )));
    }
    if let Some(bad) = tris.iter().flatten().find(|&&i| i as usize >= verts.len()) {
        return Err(err(format!(
            "triangle index {bad} out of range ({} vertices)",
            verts.len()
        )));
    }
    if verts.iter().flatten().any(|v| !v.is_finite()) {
        return Err(err("non-finite vertex coordinate".into()));
    }
    let verts = verts
        .into_iter()
        .map(|v| Vector::new((v[0] * scale) as f32, (v[1] * scale) as f32, (v[2] * scale) as f32))
        .collect();
    Ok((verts, tris))
}

/// A convex piece (box or prism, in metres) as a rapier convex polyhedron in rapier units.
fn polytope_shape(p: &super::overlap::Polytope, name: &str) -> Result<SharedShape, ShapeError> {
    let pts: Vec<Vector> = p.vertices.iter().map(|v| super::sim_point(&v.coords)).collect();
    SharedShape::convex_hull(&pts).ok_or_else(|| ShapeError::Degenerate(name.to_string()))
}

impl PartShape {
    /// Builds the shape of a workpiece. Mesh paths resolve against the workpiece file's folder.
    pub fn build(workpiece: &Workpiece, source: &Source) -> Result<Self, ShapeError> {
        let he = Vector3::from(workpiece.size_m) / 2.0;
        let cuboid = |c: Vector3<f64>, he: Vector3<f64>| {
            (
                Pose::from_translation(super::sim_point(&c)),
                SharedShape::cuboid(super::sim(he.x), super::sim(he.y), super::sim(he.z)),
            )
        };
        let (shape, view_shape) = match workpiece.shape.kind {
            ShapeKind::Box => {
                let s = polytope_shape(&super::overlap::Polytope::cuboid(Vector3::zeros(), he), &workpiece.name)?;
                (s, cuboid(Vector3::zeros(), he).1)
            }
            ShapeKind::Compound => {
                let mut all = Vec::new();
                let mut view = Vec::new();
                for (_, piece) in workpiece.pieces() {
                    // Physics: convex polyhedra (cylinders as 16-sided prisms: polyhedral contacts
                    // rest stably where rapier's round cylinders roll and jitter; the overlap check
                    // uses the same prisms). Rays: boxes as cuboids.
                    let hull = polytope_shape(&super::overlap::Polytope::of(&piece), &workpiece.name)?;
                    view.push(match piece {
                        Piece::Box { center_m, half_m } => cuboid(center_m, half_m),
                        Piece::Cylinder { .. } => (Pose::IDENTITY, hull.clone()),
                    });
                    all.push((Pose::IDENTITY, hull));
                }
                (SharedShape::compound(all), SharedShape::compound(view))
            }
            ShapeKind::Mesh => {
                let file = workpiece.shape.mesh_file.clone().unwrap_or_default();
                let dir = match source {
                    Source::File(p) => p.parent().unwrap_or(Path::new(".")).to_path_buf(),
                    Source::Embedded => return Err(ShapeError::EmbeddedMesh(workpiece.name.clone())),
                };
                let path = dir.join(&file);
                let (mut verts, tris) = load_mesh(&path, workpiece.shape.mesh_scale.unwrap_or(1.0))?;
                // The part frame's origin is the bounding-box centre.
                let (lo, hi) = verts
                    .iter()
                    .fold((Vector::splat(f32::MAX), Vector::splat(f32::MIN)), |(lo, hi), v| {
                        (lo.min(*v), hi.max(*v))
                    });
                let centre = (lo + hi) * 0.5;
                verts.iter_mut().for_each(|v| *v -= centre);
                let extent = hi - lo;
                let want = Vector::new(
                    workpiece.size_m[0] as f32,
                    workpiece.size_m[1] as f32,
                    workpiece.size_m[2] as f32,
                );
                if (extent - want).abs().max_element() > 1e-3 {
                    return Err(ShapeError::Mesh {
                        file: path.display().to_string(),
                        reason: format!(
                            "its bounding box {:.4} x {:.4} x {:.4} m differs from the workpiece's size_m {:?} by more than 1 mm",
                            extent.x, extent.y, extent.z, workpiece.size_m
                        ),
                    });
                }
                let sim_verts: Vec<Vector> = verts.iter().map(|v| *v * super::sim(1.0)).collect();
                let decomposed = SharedShape::convex_decomposition(&sim_verts, &tris);
                (decomposed.clone(), decomposed)
            }
        };
        // Mass properties: the shape's, at the density that gives the workpiece's mass.
        let unit = shape.mass_properties(1.0);
        let volume = unit.mass() as f64;
        let density = if volume > 0.0 { workpiece.mass_kg / volume } else { 0.0 };
        let mp = shape.mass_properties(density as f32);
        let principal = mp.principal_inertia();
        let frame = mp.principal_inertia_local_frame;
        let r: nalgebra::UnitQuaternion<f32> = frame.into();
        let r = r.cast::<f64>().to_rotation_matrix();
        // rapier units: kg mm^2 and mm; back to kg m^2 and m.
        let s2 = super::SIM_UNITS_PER_M * super::SIM_UNITS_PER_M;
        let diag = Matrix3::from_diagonal(&Vector3::new(
            principal.x as f64 / s2,
            principal.y as f64 / s2,
            principal.z as f64 / s2,
        ));
        let aabb = shape.compute_local_aabb();
        let corner = aabb.mins.abs().max(aabb.maxs.abs());
        Ok(PartShape {
            shape,
            view_shape,
            mass_kg: workpiece.mass_kg,
            com_m: super::point_from_sim(mp.local_com),
            inertia_com_kg_m2: r.matrix() * diag * r.matrix().transpose(),
            bounding_radius_m: corner.length() as f64 / super::SIM_UNITS_PER_M,
            half_extents_m: Vector3::new(
                aabb.half_extents().x as f64 / super::SIM_UNITS_PER_M,
                aabb.half_extents().y as f64 / super::SIM_UNITS_PER_M,
                aabb.half_extents().z as f64 / super::SIM_UNITS_PER_M,
            )
            .sup(&he),
            pieces: super::overlap::workpiece_pieces(workpiece),
            friction: workpiece.friction,
            restitution: workpiece.restitution,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LoadedWorkpiece;

    #[test]
    fn every_embedded_workpiece_builds_with_its_mass() {
        for wp in LoadedWorkpiece::all_embedded().unwrap() {
            let s = PartShape::build(&wp.workpiece, &wp.source).unwrap();
            assert!((s.mass_kg - wp.workpiece.mass_kg).abs() < 1e-12);
            assert!(s.inertia_com_kg_m2.cholesky().is_some(), "{}", wp.workpiece.name);
            let he = Vector3::from(wp.workpiece.size_m) / 2.0;
            assert!(
                (s.half_extents_m - he).amax() < 1e-6,
                "{}: {:?} vs {:?}",
                wp.workpiece.name,
                s.half_extents_m,
                he
            );
        }
    }

    /// A temporary folder for these tests, removed when dropped (no dev-dependency: see
    /// `tests/all/support.rs`).
    struct TestDir(std::path::PathBuf);

    impl TestDir {
        fn new() -> Self {
            use std::sync::atomic::{AtomicUsize, Ordering};
            static NEXT: AtomicUsize = AtomicUsize::new(0);
            let n = NEXT.fetch_add(1, Ordering::Relaxed);
            let p = std::env::temp_dir().join(format!("binpick-unit-{}-{n}", std::process::id()));
            let _ = std::fs::remove_dir_all(&p);
            std::fs::create_dir(&p).unwrap();
            TestDir(p)
        }
        fn path(&self) -> &std::path::Path {
            &self.0
        }
    }

    impl Drop for TestDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    #[test]
    fn mesh_workpiece_is_convex_decomposed() {
        let dir = TestDir::new();
        // An L-shaped bracket, 20 x 20 x 5 mm with a 10 x 10 notch, as OBJ (mm units).
        let obj = "v 0 0 0\nv 20 0 0\nv 20 10 0\nv 10 10 0\nv 10 20 0\nv 0 20 0\n\
                   v 0 0 5\nv 20 0 5\nv 20 10 5\nv 10 10 5\nv 10 20 5\nv 0 20 5\n\
                   f 1 3 2\nf 1 4 3\nf 1 6 4\nf 4 6 5\n\
                   f 7 8 9\nf 7 9 10\nf 7 10 12\nf 10 11 12\n\
                   f 1 2 8\nf 1 8 7\nf 2 3 9\nf 2 9 8\nf 3 4 10\nf 3 10 9\n\
                   f 4 5 11\nf 4 11 10\nf 5 6 12\nf 5 12 11\nf 6 1 7\nf 6 7 12\n";
        std::fs::write(dir.path().join("bracket.obj"), obj).unwrap();
        let toml = "name = \"L\"\nkind = \"sheet-metal bracket\"\nsize_m = [0.02, 0.02, 0.005]\nmass_kg = 0.004\n\
                    friction = 0.4\nrestitution = 0.1\npile_count = 20\n[shape]\nkind = \"mesh\"\n\
                    mesh_file = \"bracket.obj\"\nmesh_scale = 0.001\n[grasp]\nyaw_symmetry_deg = 360.0\n\
                    place_yaw_deg = 0.0\nface_margin_m = 0.0005\n";
        let path = dir.path().join("L.toml");
        std::fs::write(&path, toml).unwrap();
        let wp = LoadedWorkpiece::from_file(&path).unwrap();
        let s = PartShape::build(&wp.workpiece, &wp.source).unwrap();
        let parts = s
            .shape
            .as_compound()
            .expect("a compound of convex pieces")
            .shapes()
            .len();
        assert!(parts >= 2, "an L needs at least two convex pieces, got {parts}");
        assert!((s.mass_kg - 0.004).abs() < 1e-12);
        // The notch is empty: its centre is outside the decomposed shape.
        assert!(!s.shape.contains_point(&Pose::IDENTITY, Vector::new(5.0, 5.0, 0.0)));
        assert!(s.shape.contains_point(&Pose::IDENTITY, Vector::new(-5.0, -5.0, 0.0)));
    }

    #[test]
    fn bad_mesh_is_a_clear_error() {
        let dir = TestDir::new();
        std::fs::write(dir.path().join("x.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
        let e = load_mesh(&dir.path().join("x.obj"), 1.0).unwrap_err().to_string();
        assert!(e.contains("x.obj: cannot load mesh"), "{e}");
    }
}
