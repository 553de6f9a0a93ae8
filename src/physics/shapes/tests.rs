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

/// A union of axis-aligned boxes (mm: `[lo, hi]`) as one welded, closed shell: the boundary
/// faces of the grid cells the boxes fill, on the grid of every box's bounds.
fn union_of_boxes_mm(boxes: &[([f64; 3], [f64; 3])]) -> Mesh {
    let axis = |a: usize| {
        let mut c: Vec<f64> = boxes.iter().flat_map(|(lo, hi)| [lo[a], hi[a]]).collect();
        c.sort_by(f64::total_cmp);
        c.dedup();
        c
    };
    let g = [axis(0), axis(1), axis(2)];
    let n = [g[0].len() - 1, g[1].len() - 1, g[2].len() - 1];
    let filled = |c: [i64; 3]| {
        (0..3).all(|a| c[a] >= 0 && (c[a] as usize) < n[a]) && {
            let m = [0, 1, 2].map(|a| (g[a][c[a] as usize] + g[a][c[a] as usize + 1]) / 2.0);
            boxes
                .iter()
                .any(|(lo, hi)| (0..3).all(|a| lo[a] < m[a] && m[a] < hi[a]))
        }
    };
    let mut mesh = Mesh::default();
    let mut index = std::collections::HashMap::new();
    let mut vertex = |p: [usize; 3], mesh: &mut Mesh| {
        *index.entry(p).or_insert_with(|| {
            mesh.vertices_m
                .push(nalgebra::Point3::new(g[0][p[0]], g[1][p[1]], g[2][p[2]]) * 1e-3);
            mesh.vertices_m.len() as u32 - 1
        })
    };
    // Corner bits as in `part::tessellate::box_mesh`: x bit 2, y bit 1, z bit 0.
    let faces: [([i64; 3], [usize; 4]); 6] = [
        ([-1, 0, 0], [0, 1, 3, 2]),
        ([1, 0, 0], [4, 6, 7, 5]),
        ([0, -1, 0], [0, 4, 5, 1]),
        ([0, 1, 0], [2, 3, 7, 6]),
        ([0, 0, -1], [0, 2, 6, 4]),
        ([0, 0, 1], [1, 5, 7, 3]),
    ];
    for i in 0..n[0] {
        for j in 0..n[1] {
            for k in 0..n[2] {
                let c = [i as i64, j as i64, k as i64];
                if !filled(c) {
                    continue;
                }
                for (d, quad) in faces {
                    if filled([c[0] + d[0], c[1] + d[1], c[2] + d[2]]) {
                        continue;
                    }
                    let q = quad.map(|b| vertex([i + (b >> 2 & 1), j + (b >> 1 & 1), k + (b & 1)], &mut mesh));
                    mesh.triangles.push([q[0], q[1], q[2]]);
                    mesh.triangles.push([q[0], q[2], q[3]]);
                }
            }
        }
    }
    mesh
}

fn workpiece_of_mesh(name: &str, mesh: &Mesh) -> Workpiece {
    let (lo, hi) = mesh.bounds_m().unwrap();
    let mut w = LoadedWorkpiece::resolve("B").unwrap().workpiece;
    w.name = name.into();
    w.size_m = (hi - lo).into();
    w.shape = crate::config::ShapeConfig {
        kind: ShapeKind::Mesh,
        parts: Vec::new(),
        mesh_file: Some(format!("{name}.stl")),
        mesh_scale: Some(1.0),
        units: None,
        symmetry_orders: None,
    };
    w
}

#[test]
fn a_relay_welded_with_its_pins_keeps_its_pins() {
    // A 20 x 30 x 7 mm body with five 0.5 mm square pins, 3 mm long, out of its bottom face.
    let pins = [(-6.0, -11.0), (6.0, -11.0), (-6.0, 11.0), (6.0, 11.0), (0.0, -4.0)];
    let mut boxes = vec![([-10.0, -15.0, -2.0], [10.0, 15.0, 5.0])];
    boxes.extend(
        pins.iter()
            .map(|&(x, y)| ([x - 0.25, y - 0.25, -5.0], [x + 0.25, y + 0.25, -2.0])),
    );
    let mesh = union_of_boxes_mm(&boxes);
    assert_eq!(
        shells(
            &mesh
                .vertices_m
                .iter()
                .map(|v| super::super::sim_point(&v.coords))
                .collect::<Vec<_>>(),
            &mesh.triangles
        )
        .len(),
        1
    );
    let s = PartShape::from_mesh(&workpiece_of_mesh("relay", &mesh), &mesh).unwrap();
    assert!(
        (2..=MAX_PIECES_PER_SHELL as usize).contains(&s.convex_pieces),
        "{} pieces",
        s.convex_pieces
    );
    // Every pin's tip is solid; the space between the pins under the body is not.
    let at = |x: f64, y: f64, z: f64| Vector::new(x as f32, y as f32, z as f32);
    for &(x, y) in &pins {
        assert!(
            s.shape.contains_point(&Pose::IDENTITY, at(x, y, -4.7)),
            "pin at ({x}, {y})"
        );
        assert!(
            s.view_shape.contains_point(&Pose::IDENTITY, at(x, y, -4.7)),
            "pin at ({x}, {y}) for rays"
        );
    }
    for (x, y) in [(0.0, 4.0), (-3.0, -11.0), (3.0, 0.0), (0.0, -8.0)] {
        assert!(
            !s.shape.contains_point(&Pose::IDENTITY, at(x, y, -4.0)),
            "between the pins at ({x}, {y})"
        );
    }
    // Negative control: the relay's convex hull (what a loose tolerance would give) fills
    // the space between the pins.
    let hull = SharedShape::convex_hull(
        &mesh
            .vertices_m
            .iter()
            .map(|v| super::super::sim_point(&v.coords))
            .collect::<Vec<_>>(),
    )
    .unwrap();
    assert!(hull.contains_point(&Pose::IDENTITY, at(0.0, 4.0, -4.0)));
}

#[test]
fn a_convex_mesh_is_its_hull_and_the_meshed_builtins_get_their_primitives_pieces() {
    use crate::part::tessellate;
    // A hex prism, 14 mm across corners, 6 mm thick: one convex piece.
    let hex = tessellate::prism_mesh(Vector3::zeros(), 0.007, 0.003, crate::config::Axis::Z, 6);
    let s = PartShape::from_mesh(&workpiece_of_mesh("hex", &hex), &hex).unwrap();
    assert_eq!(s.convex_pieces, 1);
    let piece = &s
        .shape
        .as_compound()
        .expect("a compound, as a compound workpiece's")
        .shapes()[0]
        .1;
    assert!(piece.as_convex_polyhedron().is_some_and(|c| c.points().len() == 12));
    for wp in LoadedWorkpiece::all_embedded().unwrap() {
        let w = &wp.workpiece;
        let prim = PartShape::build(w, &wp.source).unwrap();
        let mesh = w.primitive_mesh().unwrap();
        let meshed = PartShape::from_mesh(w, &mesh).unwrap();
        assert_eq!(meshed.convex_pieces, prim.convex_pieces, "{}", w.name);
        assert!((meshed.com_m - prim.com_m).amax() < 1e-7, "{}", w.name);
        let rel = (meshed.inertia_com_kg_m2 - prim.inertia_com_kg_m2).amax() / prim.inertia_com_kg_m2.amax();
        assert!(rel < 1e-4, "{}: inertia differs by {rel}", w.name);
        assert!(
            (meshed.half_extents_m - prim.half_extents_m).amax() < 1e-7,
            "{}",
            w.name
        );
        // The same convex pieces for the overlap check.
        let (a, b) = (prim.pieces.unwrap(), meshed.pieces.unwrap());
        assert_eq!(a.len(), b.len(), "{}", w.name);
        // Each direction set covers the other up to sign (the primitives' list some twice).
        let covers =
            |x: &[Vector3<f64>], y: &[Vector3<f64>]| x.iter().all(|d| y.iter().any(|e| d.dot(e).abs() > 1.0 - 1e-6));
        for (pa, pb) in a.iter().zip(&b) {
            assert_eq!(pa.vertices.len(), pb.vertices.len(), "{}", w.name);
            for v in &pa.vertices {
                assert!(pb.vertices.iter().any(|u| (u - v).norm() < 1e-7), "{}: {v}", w.name);
            }
            assert!(
                covers(&pa.normals, &pb.normals) && covers(&pb.normals, &pa.normals),
                "{}",
                w.name
            );
            assert!(
                covers(&pa.edges, &pb.edges) && covers(&pb.edges, &pa.edges),
                "{}",
                w.name
            );
        }
        // Rays see the same: boxes as cuboids.
        let cuboids = |v: &SharedShape| match v.as_compound() {
            Some(c) => c.shapes().iter().filter(|(_, s)| s.as_cuboid().is_some()).count(),
            None => usize::from(v.as_cuboid().is_some()),
        };
        assert_eq!(cuboids(&meshed.view_shape), cuboids(&prim.view_shape), "{}", w.name);
    }
}

#[test]
fn a_meshed_prism_overlaps_as_the_primitive_prism_does() {
    use crate::physics::overlap::{Polytope, depth};
    use rand::{RngExt, SeedableRng};
    let c = Vector3::zeros();
    let prism = Polytope::prism(c, 0.007, 0.003, crate::config::Axis::Z);
    let mesh = crate::part::tessellate::prism_mesh(c, 0.007, 0.003, crate::config::Axis::Z, 16);
    let s = PartShape::from_mesh(&workpiece_of_mesh("can", &mesh), &mesh).unwrap();
    let ours = &s.pieces.as_ref().unwrap()[0];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        let t = Vector3::new(
            rng.random_range(-0.014..0.014),
            rng.random_range(-0.014..0.014),
            rng.random_range(-0.008..0.008),
        );
        let r = Vector3::new(
            rng.random_range(-3.2..3.2),
            rng.random_range(-3.2..3.2),
            rng.random_range(-3.2..3.2),
        );
        let (a, b) = (nalgebra::Isometry3::identity(), nalgebra::Isometry3::new(t, r));
        worst = worst.max((depth(&a, &prism, &b, &prism) - depth(&a, ours, &b, ours)).abs());
    }
    assert!(worst < 1e-6, "depths differ by {worst}");
}

#[test]
fn a_finely_tessellated_cylinder_is_simplified_to_a_32_sided_prism() {
    use rapier3d::parry::query::PointQuery;
    // A CAD can: 64 sides, 7 mm radius, 6 mm tall.
    let mesh = crate::part::tessellate::prism_mesh(Vector3::zeros(), 0.007, 0.003, crate::config::Axis::Z, 64);
    let pts: Vec<Vector> = mesh
        .vertices_m
        .iter()
        .map(|v| super::super::sim_point(&v.coords))
        .collect();
    // Negative control: its hull has all 128 vertices.
    let full = SharedShape::convex_hull(&pts).unwrap();
    assert_eq!(full.as_convex_polyhedron().unwrap().points().len(), 128);
    let s = PartShape::from_mesh(&workpiece_of_mesh("can64", &mesh), &mesh).unwrap();
    let piece = &s.shape.as_compound().unwrap().shapes()[0].1;
    let kept = piece.as_convex_polyhedron().unwrap();
    assert!(
        kept.points().len() <= MAX_PIECE_VERTICES,
        "{} vertices",
        kept.points().len()
    );
    // Every original vertex lies within 0.1 mm of the simplified piece (an even 32-gon of
    // this radius lies 0.034 mm inside the circle; the greedy choice is uneven: 0.067 mm).
    let worst = pts
        .iter()
        .map(|p| kept.distance_to_local_point(*p, true))
        .fold(0.0, f32::max);
    assert!(worst < 0.1, "a vertex is {worst} mm off");
    // Negative control: a 16-gon (every fourth ring vertex, 32 vertices: the built-in prism's)
    // fails the bound.
    let coarse: Vec<Vector> = pts
        .iter()
        .enumerate()
        .filter(|(i, _)| i % 4 == 0)
        .map(|(_, p)| *p)
        .collect();
    let coarse = SharedShape::convex_hull(&coarse).unwrap();
    let coarse = coarse.as_convex_polyhedron().unwrap();
    let coarse_worst = pts
        .iter()
        .map(|p| coarse.distance_to_local_point(*p, true))
        .fold(0.0, f32::max);
    assert!(coarse_worst >= 0.1, "{coarse_worst}");
}

#[test]
fn cans_of_500_and_2000_sides_get_their_collider() {
    use rapier3d::parry::query::PointQuery;
    // A 500-sided can (1,000 hull vertices) took minutes in the greedy simplification, which
    // builds hulls of every vertex left at each step; a 2000-sided one got no collider at all
    // (parry's hull of its 4,002 vertices fails: "a degenerate primitive"). Thinned first
    // (`thin`), both get a piece of at most 64 vertices, within 0.12 mm of every vertex at 7 mm
    // radius, in proportion at others (the 500-sided one 0.067 mm off, the 2000-sided one of
    // 10 mm radius 0.11 mm). The control: parry's hull of all the 2000-sided can's vertices fails.
    // (sides, radius m, half height m): the 2000-sided can as the cap test's file has it.
    for (sides, r, hh) in [(500, 0.007, 0.003), (2000, 0.01, 0.01)] {
        let mesh = crate::part::tessellate::prism_mesh(Vector3::zeros(), r, hh, crate::config::Axis::Z, sides);
        let pts: Vec<Vector> = mesh
            .vertices_m
            .iter()
            .map(|v| super::super::sim_point(&v.coords))
            .collect();
        if sides == 2000 {
            assert!(
                SharedShape::convex_hull(&pts).is_none(),
                "parry now builds it: the fallback is moot"
            );
        }
        let thinned = super::thin(&pts, MAX_DECIMATE_INPUT);
        assert!(thinned.len() <= MAX_DECIMATE_INPUT && thinned.iter().all(|p| pts.contains(p)));
        let s = PartShape::from_mesh(&workpiece_of_mesh("can", &mesh), &mesh).unwrap();
        let piece = &s.shape.as_compound().unwrap().shapes()[0].1;
        let kept = piece.as_convex_polyhedron().unwrap();
        assert!(
            kept.points().len() <= MAX_PIECE_VERTICES,
            "{sides}: {}",
            kept.points().len()
        );
        let worst = pts
            .iter()
            .map(|p| kept.distance_to_local_point(*p, true))
            .fold(0.0, f32::max);
        let bound_mm = 0.12 * (r / 0.007) as f32;
        assert!(worst < bound_mm, "{sides}: a vertex is {worst} mm off");
    }
}

#[test]
fn a_mesh_of_more_bodies_than_pieces_allowed_is_refused() {
    use crate::part::tessellate::{append, box_mesh};
    let cubes = |n: usize| {
        let mut m = Mesh::default();
        for i in 0..n {
            let c = Vector3::new((i % 8) as f64 * 0.003, (i / 8) as f64 * 0.003, 0.0);
            append(&mut m, &box_mesh(c, Vector3::repeat(0.001)));
        }
        m
    };
    let ok = cubes(MAX_PIECES);
    let s = PartShape::from_mesh(&workpiece_of_mesh("cubes", &ok), &ok).unwrap();
    assert_eq!(s.convex_pieces, MAX_PIECES);
    let too_many = cubes(MAX_PIECES + 1);
    let e = PartShape::from_mesh(&workpiece_of_mesh("cubes", &too_many), &too_many)
        .err()
        .expect("refused")
        .to_string();
    let why = format!("{} convex pieces, more than {MAX_PIECES}", MAX_PIECES + 1);
    assert!(e.contains(&why), "{e}");
}

#[test]
fn bad_mesh_is_a_clear_error() {
    let dir = TestDir::new();
    std::fs::write(dir.path().join("x.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let toml = "name = \"x\"\nkind = \"bad\"\nmass_kg = 0.01\nfriction = 0.4\nrestitution = 0.1\npile_count = 5\n\
                [shape]\nkind = \"mesh\"\nmesh_file = \"x.obj\"\nunits = \"mm\"\n[grasp]\nyaw_symmetry_deg = 360.0\n\
                place_yaw_deg = 0.0\nface_margin_m = 0.0005\n";
    std::fs::write(dir.path().join("x.toml"), toml).unwrap();
    // The loader refuses the file on load, naming it; the physics never sees it.
    let e = match crate::config::LoadedWorkpiece::from_file(&dir.path().join("x.toml")) {
        Ok(_) => panic!("a one-triangle mesh was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("x.obj"), "{e}");
}

#[test]
fn a_mesh_past_the_pieces_cap_is_refused_after_one_batch_of_decompositions() {
    use crate::part::tessellate::append;
    // 200 L-shaped bodies (each cut into two or more pieces) and 54 cubes: 254 bodies, within the
    // bodies' cap, but past the pieces' as soon as the first L-shapes are cut.
    let mut m = Mesh::default();
    for i in 0..254 {
        let (x, y) = ((i % 20) as f64 * 4.0, (i / 20) as f64 * 4.0);
        let boxes = if i < 200 {
            vec![
                ([x, y, 0.0], [x + 3.0, y + 1.0, 1.0]),
                ([x, y, 0.0], [x + 1.0, y + 3.0, 1.0]),
            ]
        } else {
            vec![([x, y, 0.0], [x + 1.0, y + 1.0, 1.0])]
        };
        append(&mut m, &union_of_boxes_mm(&boxes));
    }
    let e = PartShape::from_mesh(&workpiece_of_mesh("ells", &m), &m)
        .err()
        .expect("refused")
        .to_string();
    let why = format!("{DECOMPOSE_BATCH} of its bodies are not convex");
    assert!(e.contains("needs at least") && e.contains(&why), "{e}");
}
