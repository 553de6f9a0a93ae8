//! Workpiece shapes for the physics world: boxes, compounds of boxes and cylinders (bodies with
//! leads), and triangle meshes (OBJ or STL, or a [`Mesh`] in memory).
//!
//! A mesh's collider: each shell (connected part of the surface) whose convex hull lies within
//! [`HULL_TOLERANCE_M`] of it is that hull; any other shell is decomposed by parry's VHACD into at
//! most [`MAX_PIECES_PER_SHELL`] convex pieces (pins and leads keep pieces of their own). The view
//! for rays is the same pieces, axis-aligned boxes among them as cuboids. So a box or compound
//! workpiece exported as a mesh gets the same convex pieces as its primitives.
//!
//! Every large flat face of more than four corners gets a support slab inside the solid
//! ([`supports`]: parry's contact clipper sees only four corners of a face), so a can rests on
//! its whole cap.
//!
//! Mass properties are the collider's (volume of its pieces at the density that gives the file's
//! mass; overlapping pieces count twice, a hull counts its bridged concavities): the mesh's own
//! centroid and inertia are to come from the part model.
//!
//! Units: m, kg. Frame: the part frame of the workpiece file (origin at the bounding-box centre).
//! rapier's cylinders run along their local +y; workpiece cylinders along x, y or z are rotated.

use nalgebra::{Matrix3, Vector3};
use rapier3d::math::{Pose, Vector};
use rapier3d::prelude::SharedShape;

use rapier3d::parry::transformation::vhacd::{VHACD, VHACDParameters};

use crate::config::{Piece, ShapeKind, Source, Workpiece};
use crate::part::mesh::Mesh;

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
    /// Mass (kg).
    pub mass_kg: f64,
    /// Centre of mass in the part frame (m).
    pub com_m: Vector3<f64>,
    /// Inertia about the centre of mass, part axes [kg m^2].
    pub inertia_com_kg_m2: Matrix3<f64>,
    /// Radius of the bounding sphere about the part origin (m).
    pub bounding_radius_m: f64,
    /// Half extents of the bounding box (m).
    pub half_extents_m: Vector3<f64>,
    /// The workpiece's bounding box as its file gives it or its mesh derives it (`size_m`) (m).
    pub size_m: [f64; 3],
    /// The convex pieces for the independent overlap check: the primitives' polytopes, or a
    /// mesh collider's convex pieces.
    pub pieces: Option<Vec<super::overlap::Polytope>>,
    /// Convex pieces of the collider (1 for a single convex shape).
    pub convex_pieces: usize,
    /// Coulomb friction coefficient.
    pub friction: f64,
    /// Restitution coefficient.
    pub restitution: f64,
    /// A mesh workpiece's surface (m, part frame), from which the sensor's recognition derives
    /// its part model; `None` for primitives.
    pub mesh: Option<std::sync::Arc<Mesh>>,
}

/// A convex piece (box or prism, in metres) as a rapier convex polyhedron in rapier units.
fn polytope_shape(p: &super::overlap::Polytope, name: &str) -> Result<SharedShape, ShapeError> {
    let pts: Vec<Vector> = p.vertices.iter().map(|v| super::sim_point(&v.coords)).collect();
    SharedShape::convex_hull(&pts).ok_or_else(|| ShapeError::Degenerate(name.to_string()))
}

/// A mesh's vertices in rapier units about its bounding-box centre (the part frame's origin),
/// once its bounding box is checked against `size_m` (within 1 mm).
fn centred_sim_vertices(workpiece: &Workpiece, mesh: &Mesh) -> Result<Vec<Vector>, ShapeError> {
    let err = |reason: String| ShapeError::Mesh {
        file: workpiece.name.clone(),
        reason,
    };
    let (lo, hi) = mesh.bounds_m().ok_or_else(|| err("has no vertices".into()))?;
    let centre = (lo.coords + hi.coords) / 2.0;
    let extent = hi - lo;
    if (extent - Vector3::from(workpiece.size_m)).amax() > 1e-3 {
        return Err(err(format!(
            "its bounding box {:.4} x {:.4} x {:.4} m differs from the workpiece's size_m {:?} by more than 1 mm",
            extent.x, extent.y, extent.z, workpiece.size_m
        )));
    }
    if let Some(bad) = mesh
        .triangles
        .iter()
        .flatten()
        .find(|&&i| i as usize >= mesh.vertices_m.len())
    {
        return Err(err(format!(
            "triangle index {bad} out of range ({} vertices)",
            mesh.vertices_m.len()
        )));
    }
    Ok(mesh
        .vertices_m
        .iter()
        .map(|v| super::sim_point(&(v.coords - centre)))
        .collect())
}

/// Largest distance of a shell's convex hull from the shell's surface for the hull to stand in
/// for the shell (m): sampled over the hull's surface, at most [`HULL_SAMPLE_SPACING_M`] apart.
pub const HULL_TOLERANCE_M: f64 = 0.0001;
/// Spacing of the samples on a hull's triangles for [`HULL_TOLERANCE_M`] (m; at most 16 per edge).
pub const HULL_SAMPLE_SPACING_M: f64 = 0.0005;
/// Most convex pieces a non-convex shell is decomposed into.
pub const MAX_PIECES_PER_SHELL: u32 = 16;
/// Most vertices of one convex piece of a mesh collider: a piece with more is simplified
/// (greedily, dropping the vertex whose removal moves the hull least), so a finely tessellated
/// CAD cylinder costs at most what a 32-sided prism costs. A cylinder of up to 32 sides (the
/// usual CAD export) keeps every facet, so it rests where its part model, built from the file's
/// hull, says it rests (a 24-sided one kept to 32 vertices, every other facet, rests up to 10
/// degrees off).
pub const MAX_PIECE_VERTICES: usize = 64;
/// Most points `decimate`'s greedy simplification starts from: each step builds hulls of all
/// that are left, so a finely tessellated can (a 500-sided one: 1,000 hull vertices) took
/// minutes. A hull of more vertices is first thinned (`thin`: one point per cell of a grid).
pub const MAX_DECIMATE_INPUT: usize = 256;
/// Most points a shell's hull is built from where parry's hull of all its vertices fails (a
/// 2000-sided can's 4,002 or, in 46 rings, 94,000 vertices): the rest thinned (`thin`: one
/// point per cell of a grid).
pub const MAX_HULL_INPUT: usize = 1024;
/// Most convex pieces of a whole mesh collider: a mesh that needs more is refused (one of more
/// bodies than [`crate::part::raw::MAX_BODIES`] already where it is read; where decomposed
/// shells push the pieces past this, when the collider is built).
pub const MAX_PIECES: usize = crate::part::raw::MAX_BODIES;
/// VHACD's voxel grid across the shell's longest edge (a 30 mm part: 0.23 mm voxels, so a
/// 0.5 mm pin is two voxels wide; at parry's default of 64 the test relay's 0.5 mm pins merge).
const VHACD_RESOLUTION: u32 = 128;

/// Where decompositions are kept between processes (read once per process).
static CACHE_DIR: std::sync::LazyLock<Option<std::path::PathBuf>> =
    std::sync::LazyLock::new(decomposition_cache::folder);

/// One convex piece of a mesh collider: its polyhedron (rapier units, part frame) and what rays
/// see of it (an axis-aligned box as a cuboid at its centre, else the same polyhedron).
struct MeshPiece {
    shape: SharedShape,
    view: (Pose, SharedShape),
}

/// The collider of a triangle mesh (rapier units, part frame): vertices at the same position are
/// welded; the mesh falls into shells (connected by shared vertices); each shell whose convex hull
/// lies within [`HULL_TOLERANCE_M`] of its surface is that hull (one convex piece: the common case
/// of a box, a prism, a meshed primitive), any other shell is decomposed by parry's VHACD into at
/// most [`MAX_PIECES_PER_SHELL`] exact convex hulls of the shell's own triangles (pins and leads
/// come out as pieces of their own: see the tests), kept on disk between processes
/// ([`decomposition_cache`]). Flat shells (no volume) are dropped.
///
/// Simplification: shells are solids of their own; a shell inside another (a cavity) is filled.
/// Also returned: how many shells were decomposed (their pieces are not their exact surface: a
/// TO-220's tab hole, a standoff's bore are partly filled).
///
/// The shells needing a decomposition are decomposed in parallel, [`DECOMPOSE_BATCH`] at a time
/// in their order (the result is the same as one by one); a mesh whose pieces pass
/// [`MAX_PIECES`] is refused as soon as they do, not after every shell's decomposition.
fn mesh_collider(verts: &[Vector], tris: &[[u32; 3]]) -> Result<(Vec<MeshPiece>, usize), TooManyPieces> {
    use rayon::prelude::*;
    /// A shell: its hull, and the shell itself where the hull is not within the tolerance.
    type Shell = (SharedShape, Option<(Vec<Vector>, Vec<[u32; 3]>)>);
    let shells: Vec<Shell> = shells(verts, tris)
        .into_iter()
        .filter_map(|(sv, st)| {
            let hull =
                SharedShape::convex_hull(&sv).or_else(|| SharedShape::convex_hull(&thin(&sv, MAX_HULL_INPUT)))?;
            let convex = hull_distance(&sv, &st) <= super::sim(HULL_TOLERANCE_M);
            Some((hull, (!convex).then_some((sv, st))))
        })
        .collect();
    let params = VHACDParameters {
        resolution: VHACD_RESOLUTION,
        max_convex_hulls: MAX_PIECES_PER_SHELL,
        ..VHACDParameters::default()
    };
    let decompose = |sv: &[Vector], st: &[[u32; 3]]| -> Vec<SharedShape> {
        decomposition_cache::decomposition(CACHE_DIR.as_deref(), sv, st, &format!("{params:?}"), || {
            VHACD::decompose(&params, sv, st, true)
                .compute_exact_convex_hulls(sv, st)
                .into_iter()
                .map(|(v, _)| v)
                .collect()
        })
        .into_iter()
        .filter_map(|v| SharedShape::convex_hull(&v))
        .collect()
    };
    // Each shell's pieces: its hull, or its decomposition (the hull where that gives nothing).
    let mut pieces_of: Vec<Option<Vec<SharedShape>>> = shells
        .iter()
        .map(|(hull, cut)| cut.is_none().then(|| vec![hull.clone()]))
        .collect();
    let to_cut: Vec<usize> = (0..shells.len()).filter(|&i| shells[i].1.is_some()).collect();
    // At least one piece for each shell still to be cut.
    let at_least = |pieces_of: &[Option<Vec<SharedShape>>]| -> usize {
        pieces_of.iter().map(|p| p.as_ref().map_or(1, Vec::len)).sum()
    };
    if at_least(&pieces_of) > MAX_PIECES {
        return Err(TooManyPieces {
            at_least: at_least(&pieces_of),
            exact: to_cut.is_empty(),
            decomposed: 0,
        });
    }
    for batch in to_cut.chunks(DECOMPOSE_BATCH) {
        let done: Vec<Vec<SharedShape>> = batch
            .par_iter()
            .map(|&i| {
                let (hull, cut) = &shells[i];
                let (sv, st) = cut.as_ref().expect("a shell to cut");
                let d = decompose(sv, st);
                if d.is_empty() { vec![hull.clone()] } else { d }
            })
            .collect();
        for (&i, d) in batch.iter().zip(done) {
            pieces_of[i] = Some(d);
        }
        if at_least(&pieces_of) > MAX_PIECES {
            let decomposed = pieces_of
                .iter()
                .zip(&shells)
                .filter(|(p, s)| p.is_some() && s.1.is_some())
                .count();
            return Err(TooManyPieces {
                at_least: at_least(&pieces_of),
                exact: batch.last() == to_cut.last(),
                decomposed,
            });
        }
    }
    let pieces = pieces_of.into_iter().flatten().flatten().map(mesh_piece).collect();
    Ok((pieces, to_cut.len()))
}

/// Shells decomposed in parallel at a time ([`mesh_collider`]): a fixed number, so that where a
/// mesh is refused, and the count it is refused with, do not depend on the machine's cores.
const DECOMPOSE_BATCH: usize = 8;

/// A mesh collider past [`MAX_PIECES`]: at least this many pieces (`exact` when every shell was
/// decomposed), `decomposed` of its shells cut into pieces so far.
struct TooManyPieces {
    at_least: usize,
    exact: bool,
    decomposed: usize,
}

/// A convex piece with its view for rays: an axis-aligned box (8 vertices, each on a corner of
/// its bounding box) as a cuboid, whose ray test is analytic.
fn mesh_piece(shape: SharedShape) -> MeshPiece {
    let mut pts = shape
        .as_convex_polyhedron()
        .map(|c| c.points().to_vec())
        .unwrap_or_default();
    let shape = if pts.len() > MAX_PIECE_VERTICES {
        pts = decimate(&pts);
        SharedShape::convex_hull(&pts).unwrap_or(shape)
    } else {
        shape
    };
    let (lo, hi) = pts
        .iter()
        .fold((Vector::splat(f32::MAX), Vector::splat(f32::MIN)), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let eps = 1e-4 * (hi - lo).max_element().max(1.0);
    let on_corner = |v: &Vector| (0..3).all(|a| (v[a] - lo[a]).abs() < eps || (v[a] - hi[a]).abs() < eps);
    let view = if pts.len() == 8 && pts.iter().all(on_corner) {
        let he = (hi - lo) * 0.5;
        (
            Pose::from_translation((lo + hi) * 0.5),
            SharedShape::cuboid(he.x, he.y, he.z),
        )
    } else {
        (Pose::IDENTITY, shape.clone())
    };
    MeshPiece { shape, view }
}

/// A convex point set's hull simplified to at most [`MAX_PIECE_VERTICES`] vertices: one at a time,
/// the vertex whose removal moves the hull least (its distance to the hull of the others) is
/// dropped; only the neighbours of a dropped vertex are re-costed. Greedy, not optimal: a
/// 64-sided can of 7 mm radius keeps 64 vertices within 0.067 mm of its own (an even 32-gon:
/// 0.034 mm). A set whose hull cannot be built is returned as it is.
fn decimate(points: &[Vector]) -> Vec<Vector> {
    use rapier3d::parry::query::PointQuery;
    use rapier3d::parry::transformation::try_convex_hull;
    let thinned;
    let points = if points.len() > MAX_DECIMATE_INPUT {
        thinned = thin(points, MAX_DECIMATE_INPUT);
        &thinned
    } else {
        points
    };
    let Ok((hv, _)) = try_convex_hull(points) else {
        return points.to_vec();
    };
    let mut alive = vec![true; hv.len()];
    let removal_cost = |alive: &[bool], i: usize| -> f32 {
        let others: Vec<Vector> = (0..hv.len()).filter(|&j| j != i && alive[j]).map(|j| hv[j]).collect();
        rapier3d::parry::shape::ConvexPolyhedron::from_convex_hull(&others)
            .map_or(f32::INFINITY, |h| h.distance_to_local_point(hv[i], true))
    };
    // Each live vertex's neighbours on the hull of the live vertices.
    let neighbours = |alive: &[bool]| -> Option<Vec<Vec<usize>>> {
        let ids: Vec<usize> = (0..hv.len()).filter(|&j| alive[j]).collect();
        let pts: Vec<Vector> = ids.iter().map(|&j| hv[j]).collect();
        let (kept, tris) = try_convex_hull(&pts).ok()?;
        let back: Vec<usize> = kept
            .iter()
            .map(|p| ids.iter().copied().find(|&j| hv[j] == *p))
            .collect::<Option<_>>()?;
        let mut n = vec![Vec::new(); hv.len()];
        for t in tris {
            for k in 0..3 {
                let (a, b) = (back[t[k] as usize], back[t[(k + 1) % 3] as usize]);
                n[a].push(b);
                n[b].push(a);
            }
        }
        Some(n)
    };
    let mut cost: Vec<f32> = (0..hv.len()).map(|i| removal_cost(&alive, i)).collect();
    let mut count = hv.len();
    while count > MAX_PIECE_VERTICES {
        let Some(adjacent) = neighbours(&alive) else {
            break;
        };
        let Some(u) = (0..hv.len())
            .filter(|&i| alive[i])
            .min_by(|&a, &b| cost[a].total_cmp(&cost[b]))
        else {
            break;
        };
        if !cost[u].is_finite() {
            break;
        }
        alive[u] = false;
        count -= 1;
        for &w in &adjacent[u] {
            if alive[w] {
                cost[w] = removal_cost(&alive, w);
            }
        }
    }
    (0..hv.len()).filter(|&i| alive[i]).map(|i| hv[i]).collect()
}

/// At most `max` of `points`: one per cell of a cubic grid over their bounding box, the grid's
/// cell as fine as leaves no more than `max` cells occupied (from a thousandth of the box's
/// diagonal, doubling), each cell's point farthest from the box's centre (the outermost, which
/// the hull keeps). The hull of those strays from the hull of all by at most the sagitta of the
/// gap between kept points (a 500-sided can of 10 mm radius thinned to 256: about 0.01 mm),
/// under what [`decimate`] then moves it. Order: by first appearance, deterministic.
fn thin(points: &[Vector], max: usize) -> Vec<Vector> {
    if points.len() <= max {
        return points.to_vec();
    }
    let (lo, hi) = points
        .iter()
        .fold((Vector::splat(f32::MAX), Vector::splat(f32::MIN)), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let centre = (lo + hi) * 0.5;
    let mut cell = ((hi - lo).length() * 1e-3).max(f32::EPSILON);
    loop {
        let mut kept: std::collections::HashMap<[i64; 3], usize> = std::collections::HashMap::new();
        let mut order = Vec::new();
        for (i, p) in points.iter().enumerate() {
            let key = ((*p - lo) / cell).floor().to_array().map(|c| c as i64);
            match kept.get_mut(&key) {
                Some(k) if (*p - centre).length_squared() > (points[*k] - centre).length_squared() => *k = i,
                Some(_) => {}
                None => {
                    kept.insert(key, i);
                    order.push(key);
                }
            }
        }
        if kept.len() <= max {
            return order.iter().map(|k| points[kept[k]]).collect();
        }
        cell *= 2.0;
    }
}

/// The mesh's shells: vertices welded by exact position, triangles grouped by shared vertices;
/// each shell with its own vertices and indices. Degenerate triangles (repeated vertex) are dropped.
fn shells(verts: &[Vector], tris: &[[u32; 3]]) -> Vec<(Vec<Vector>, Vec<[u32; 3]>)> {
    let mut weld = std::collections::HashMap::new();
    let id: Vec<usize> = verts
        .iter()
        .map(|v| {
            let n = weld.len();
            *weld.entry(v.to_array().map(f32::to_bits)).or_insert(n)
        })
        .collect();
    let tris: Vec<[usize; 3]> = tris
        .iter()
        .map(|t| t.map(|i| id[i as usize]))
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect();
    let mut parent: Vec<usize> = (0..weld.len()).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for t in &tris {
        let a = root(&mut parent, t[0]);
        for &b in &t[1..] {
            let b = root(&mut parent, b);
            parent[b] = a;
        }
    }
    let mut pos = vec![Vector::ZERO; weld.len()];
    for (i, v) in verts.iter().enumerate() {
        pos[id[i]] = *v;
    }
    // Shells in order of their first triangle; vertices renumbered within each (a welded vertex
    // belongs to one shell).
    let mut shell_of_root = std::collections::HashMap::new();
    let mut local = vec![u32::MAX; pos.len()];
    let mut out: Vec<(Vec<Vector>, Vec<[u32; 3]>)> = Vec::new();
    for t in &tris {
        let r = root(&mut parent, t[0]);
        let k = *shell_of_root.entry(r).or_insert_with(|| {
            out.push((Vec::new(), Vec::new()));
            out.len() - 1
        });
        let (sv, st) = &mut out[k];
        let tri = t.map(|i| {
            if local[i] == u32::MAX {
                local[i] = sv.len() as u32;
                sv.push(pos[i]);
            }
            local[i]
        });
        st.push(tri);
    }
    out
}

/// How far the convex hull of a shell's vertices strays from the shell's surface (rapier units):
/// the largest distance to the surface of points sampled on the hull's triangles.
fn hull_distance(verts: &[Vector], tris: &[[u32; 3]]) -> f32 {
    use rapier3d::parry::query::PointQuery;
    let Ok(surface) = rapier3d::parry::shape::TriMesh::new(verts.to_vec(), tris.to_vec()) else {
        return f32::INFINITY;
    };
    let Ok((hv, ht)) = rapier3d::parry::transformation::try_convex_hull(verts) else {
        return f32::INFINITY;
    };
    let spacing = super::sim(HULL_SAMPLE_SPACING_M);
    let mut worst = 0.0f32;
    for t in &ht {
        let [a, b, c] = t.map(|i| hv[i as usize]);
        let longest = (b - a).length().max((c - b).length()).max((a - c).length());
        let n = ((longest / spacing).ceil() as usize).clamp(1, 16);
        for i in 0..=n {
            for j in 0..=(n - i) {
                let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                let p = a + (b - a) * u + (c - a) * v;
                let d = (surface.project_local_point(p, false).point - p).length();
                worst = worst.max(d);
            }
        }
    }
    worst
}

/// A convex polyhedron (rapier units) as a polytope for the overlap check (m): its vertices, its
/// face normals and edge directions, each direction once up to sign.
fn polytope_of(shape: &SharedShape) -> super::overlap::Polytope {
    let push_dir = |dirs: &mut Vec<Vector3<f64>>, d: Vector| {
        let d = Vector3::new(d.x as f64, d.y as f64, d.z as f64);
        if let Some(d) = d.try_normalize(1e-12)
            && !dirs.iter().any(|e| e.dot(&d).abs() > 1.0 - 1e-6)
        {
            dirs.push(d);
        }
    };
    let mut p = super::overlap::Polytope {
        vertices: Vec::new(),
        normals: Vec::new(),
        edges: Vec::new(),
    };
    if let Some(c) = shape.as_convex_polyhedron() {
        p.vertices = c.points().iter().map(|v| super::point_from_sim(*v).into()).collect();
        // The faces' own edges (parry keeps the diagonals of merged coplanar triangles in
        // `edges()`, marked deleted; the faces list only the real ones).
        for f in c.faces() {
            push_dir(&mut p.normals, f.normal);
            let first = f.first_vertex_or_edge as usize;
            for &e in &c.edges_adj_to_face()[first..first + f.num_vertices_or_edges as usize] {
                push_dir(&mut p.edges, c.edges()[e as usize].dir);
            }
        }
    }
    p
}

/// Mesh workpieces' shapes built in this process, by [`built_mesh_key`].
static BUILT_MESHES: std::sync::LazyLock<std::sync::Mutex<std::collections::HashMap<String, PartShape>>> =
    std::sync::LazyLock::new(Default::default);

/// What a mesh workpiece's shape depends on: the workpiece as read, where it was read from, and the
/// mesh file's length and modification time (a file rewritten while the process runs is read
/// again). `None` when the file cannot be inspected: the build then reports why.
fn built_mesh_key(workpiece: &Workpiece, source: &Source) -> Option<String> {
    let (Source::File(p), Some(f)) = (source, &workpiece.shape.mesh_file) else {
        return None;
    };
    let meta = std::fs::metadata(p.parent().unwrap_or(std::path::Path::new(".")).join(f)).ok()?;
    Some(format!(
        "{workpiece:?}|{source:?}|{}|{:?}",
        meta.len(),
        meta.modified().ok()
    ))
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
                if matches!(source, Source::Embedded) {
                    return Err(ShapeError::EmbeddedMesh(workpiece.name.clone()));
                }
                // A mesh's collider is decomposed once per process: the check before a study and
                // every run of it share it (the decomposition is deterministic, so this changes
                // no result, only the set-up time of each run).
                let key = built_mesh_key(workpiece, source);
                if let Some(s) = key.as_ref().and_then(|k| BUILT_MESHES.lock().ok()?.get(k).cloned()) {
                    return Ok(s);
                }
                // The part model's reader and repair: closed, outward-wound, in metres.
                let mesh_error = |file: String, reason: String| ShapeError::Mesh { file, reason };
                let (mesh, _) = workpiece
                    .repaired_mesh(source)
                    .map_err(|e| mesh_error(e.file.clone(), e.defect.to_string()))?
                    .ok_or_else(|| ShapeError::Degenerate(workpiece.name.clone()))?;
                let file = workpiece.shape.mesh_file.clone().unwrap_or_default();
                let built = Self::from_mesh(workpiece, &mesh).map_err(|e| match e {
                    ShapeError::Mesh { reason, .. } => mesh_error(file.clone(), reason),
                    e => e,
                })?;
                if let (Some(k), Ok(mut m)) = (key, BUILT_MESHES.lock()) {
                    m.insert(k, built.clone());
                }
                return Ok(built);
            }
        };
        let pieces = super::overlap::workpiece_pieces(workpiece);
        let convex_pieces = shape.as_compound().map_or(1, |c| c.shapes().len());
        Ok(Self::assemble(workpiece, shape, view_shape, pieces, convex_pieces))
    }

    /// The shape of a mesh workpiece from its surface (m, any frame: the part frame's origin is
    /// put at the mesh's bounding-box centre), whose bounding box must match `size_m` within 1 mm.
    /// The collider is described in the module header.
    pub fn from_mesh(workpiece: &Workpiece, mesh: &Mesh) -> Result<Self, ShapeError> {
        let sim_verts = centred_sim_vertices(workpiece, mesh)?;
        let (pieces, decomposed_shells) = mesh_collider(&sim_verts, &mesh.triangles).map_err(|e| ShapeError::Mesh {
            file: workpiece.name.clone(),
            reason: format!(
                "its collider needs {}{} convex pieces, more than {MAX_PIECES}: {} of its bodies are not \
                 convex within {:.1} mm and were cut into up to {MAX_PIECES_PER_SHELL} pieces each \
                 (fewer bodies, or simpler ones, would fit)",
                if e.exact { "" } else { "at least " },
                e.at_least,
                e.decomposed,
                HULL_TOLERANCE_M * 1e3
            ),
        })?;
        if pieces.is_empty() {
            return Err(ShapeError::Degenerate(workpiece.name.clone()));
        }
        let n = pieces.len();
        let polytopes = pieces.iter().map(|p| polytope_of(&p.shape)).collect();
        // A single box centred on the origin is the bare polyhedron (as a box workpiece's);
        // anything else a compound, as a compound workpiece's primitives.
        let single_box =
            n == 1 && pieces[0].view.1.as_cuboid().is_some() && pieces[0].view.0.translation.length() < 1e-6;
        // What rays see: the convex pieces where they are the mesh's exact surface; the mesh
        // itself where a shell was decomposed (the sensor sees through a tab's hole that the
        // collider's pieces fill).
        let exact_view = || {
            SharedShape::trimesh_with_flags(
                sim_verts.clone(),
                mesh.triangles.clone(),
                rapier3d::parry::shape::TriMeshFlags::ORIENTED,
            )
            .ok()
        };
        let (shape, view_shape) = if single_box {
            (pieces[0].shape.clone(), pieces[0].view.1.clone())
        } else {
            let view = (decomposed_shells > 0)
                .then(exact_view)
                .flatten()
                .unwrap_or_else(|| SharedShape::compound(pieces.iter().map(|p| p.view.clone()).collect()));
            (
                SharedShape::compound(pieces.iter().map(|p| (Pose::IDENTITY, p.shape.clone())).collect()),
                view,
            )
        };
        let mut built = Self::assemble(workpiece, shape, view_shape, Some(polytopes), n);
        let centre = mesh
            .bounds_m()
            .map_or(Vector3::zeros(), |(lo, hi)| nalgebra::center(&lo, &hi).coords);
        built.mesh = Some(std::sync::Arc::new(Mesh {
            vertices_m: mesh.vertices_m.iter().map(|p| p - centre).collect(),
            triangles: mesh.triangles.clone(),
        }));
        Ok(built)
    }

    /// The collider mesh workpieces had before the part model, kept as the physics benchmark's
    /// baseline: parry's VHACD of the whole raw mesh with its default parameters (up to 1024
    /// pieces), the same pieces for rays, no pieces for the overlap check.
    pub fn from_mesh_raw_vhacd(workpiece: &Workpiece, mesh: &Mesh) -> Result<Self, ShapeError> {
        let sim_verts = centred_sim_vertices(workpiece, mesh)?;
        let decomposed = SharedShape::convex_decomposition(&sim_verts, &mesh.triangles);
        let n = decomposed.as_compound().map_or(1, |c| c.shapes().len());
        Ok(Self::assemble(workpiece, decomposed.clone(), decomposed, None, n))
    }

    /// Mass properties and bounds of a built collider.
    fn assemble(
        workpiece: &Workpiece,
        shape: SharedShape,
        view_shape: SharedShape,
        pieces: Option<Vec<super::overlap::Polytope>>,
        convex_pieces: usize,
    ) -> Self {
        let he = Vector3::from(workpiece.size_m) / 2.0;
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
        PartShape {
            // The solid's mass properties above; contacts through the support slabs.
            shape: supports::with_support_slabs(&shape),
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
            size_m: workpiece.size_m,
            pieces,
            convex_pieces,
            friction: workpiece.friction,
            restitution: workpiece.restitution,
            mesh: None,
        }
    }
}

mod decomposition_cache;
pub mod supports;
#[cfg(test)]
mod tests;
