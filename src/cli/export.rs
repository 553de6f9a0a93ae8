//! `binpick export-mesh --workpiece A[,B...] --out DIR`: a box or compound workpiece's primitives
//! as a CAD part: `DIR/<name>.stl` (binary STL in millimetres, the tessellation of
//! [`binpick::part::tessellate`]) and `DIR/<name>-mesh.toml`, a workpiece of `kind = "mesh"` that
//! points at it with the same mass, friction, restitution, grasp hints and pile count, named
//! `<name>-mesh` so a batch can run both side by side (a compound's declared symmetry becomes the
//! mesh workpiece's `shape.symmetry_orders`):
//! `binpick batch --workpieces A,DIR/A-mesh.toml ...`.
//!
//! Every file is written to a temporary name in DIR first and renamed once all are written.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;

use super::InputError;
use binpick::config::{LoadedWorkpiece, ShapeKind, Workpiece};
use binpick::part::mesh::Mesh;

/// Arguments of `binpick export-mesh`.
#[derive(Args)]
pub struct ExportMeshArgs {
    /// Workpieces, comma-separated: A ... F (embedded) or paths to box or compound workpiece files.
    #[arg(long)]
    pub workpiece: String,
    /// Folder the STL and workpiece files are written into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

/// Millimetres per metre: the STL's unit.
const STL_UNITS_PER_M: f64 = 1000.0;

/// `binpick export-mesh`.
pub fn export_mesh(a: &ExportMeshArgs) -> Result<()> {
    let mut files: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    for name in a.workpiece.split(',').map(str::trim) {
        let wp = LoadedWorkpiece::resolve(name)?;
        let w = &wp.workpiece;
        let Some(mesh) = w.primitive_mesh() else {
            return Err(InputError(format!(
                "--workpiece {name}: {} is already a mesh workpiece; export takes box or compound workpieces",
                wp.label
            ))
            .into());
        };
        let stl_name = format!("{}.stl", w.name);
        let meshed = mesh_workpiece(w, &stl_name);
        let header = format!(
            "# Workpiece {} as a mesh: its primitives tessellated by `binpick export-mesh` \
             (cylinders as 16-sided prisms), STL in millimetres.\n",
            w.name
        );
        let toml = header + &toml::to_string(&meshed).context("serialising the workpiece")?;
        files.push((a.out.join(&stl_name), stl_bytes(&mesh)?));
        files.push((a.out.join(format!("{}-mesh.toml", w.name)), toml.into_bytes()));
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let tmp = |p: &Path| p.with_extension(format!("{}.tmp", p.extension().and_then(|e| e.to_str()).unwrap_or("")));
    for (path, bytes) in &files {
        std::fs::write(tmp(path), bytes).with_context(|| format!("writing {}", tmp(path).display()))?;
    }
    for (path, _) in &files {
        std::fs::rename(tmp(path), path).with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The workpiece `w` as a mesh workpiece whose surface is `stl_name` (millimetres).
fn mesh_workpiece(w: &Workpiece, stl_name: &str) -> Workpiece {
    let mut m = w.clone();
    m.name = format!("{}-mesh", w.name);
    m.kind = format!("{} (meshed)", w.kind);
    m.shape.kind = ShapeKind::Mesh;
    m.shape.parts.clear();
    m.shape.mesh_file = Some(stl_name.to_string());
    m.shape.mesh_scale = Some(1.0 / STL_UNITS_PER_M);
    m.shape.symmetry_orders = w.declared_symmetry_orders();
    m
}

/// The mesh as binary STL in millimetres, each facet's normal from its winding.
fn stl_bytes(mesh: &Mesh) -> Result<Vec<u8>> {
    let mm = |i: u32| {
        let p = mesh.vertices_m[i as usize] * STL_UNITS_PER_M;
        stl_io::Vertex::new([p.x as f32, p.y as f32, p.z as f32])
    };
    let triangles: Vec<stl_io::Triangle> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.vertices_m[i as usize]);
            let n = (b - a).cross(&(c - a)).try_normalize(0.0).unwrap_or_default();
            stl_io::Triangle {
                normal: stl_io::Normal::new([n.x as f32, n.y as f32, n.z as f32]),
                vertices: [mm(t[0]), mm(t[1]), mm(t[2])],
            }
        })
        .collect();
    let mut bytes = Vec::new();
    stl_io::write_stl(&mut bytes, triangles.iter()).context("writing the STL")?;
    Ok(bytes)
}
