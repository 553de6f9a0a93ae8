//! The planar faces of a part's mesh, and where a suction cup seals on each.
//!
//! Job: merge edge-adjacent triangles that lie in one plane (normals within
//! [`FACE_ANGLE_TOL_RAD`], corners within the distance tolerance of the seed's plane) into
//! faces; give each its outline as polygons in the face's own 2D frame (the outer boundary and
//! its holes); and for a cup of a given diameter plus the face margin, its cup-fit region: the
//! cup centres where the disc lies inside the outer boundary and outside every hole.
//!
//! The cup-fit region is kept as a grid of admissible centres (spacing [`CupFit::spacing_m`],
//! at most ~[`FIT_GRID`] per side of the face) with each centre's clearance to the nearest edge:
//! exact at the grid points, and its area (count x spacing^2) converges as the spacing shrinks.
//! A face is taken by the cup when the region is not empty.
//!
//! Units: m. Frames: the part frame; each face's 2D frame has its origin at the face's centroid
//! and axes `u`, `v = n x u` (`n` the outward normal, `u` along the face's longest boundary
//! edge), so `(u, v, n)` is right-handed.

use std::collections::{HashMap, HashSet};

use nalgebra::{Point2, Point3, Vector3};

use super::mesh::Mesh;

/// Largest angle between the normals of triangles merged into one face (rad).
pub const FACE_ANGLE_TOL_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
/// Grid points per side of a face's bounding rectangle for the cup-fit region.
pub const FIT_GRID: usize = 120;
/// The finest cup-fit grid spacing (m).
pub const MIN_FIT_SPACING_M: f64 = 0.0001;

/// A planar face of the mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarFace {
    /// The mesh triangles in the face.
    pub triangles: Vec<usize>,
    /// Area (m^2).
    pub area_m2: f64,
    /// Outward unit normal.
    pub normal: Vector3<f64>,
    /// Area-weighted centroid, the origin of the face's 2D frame (m).
    pub centroid_m: Point3<f64>,
    /// The face frame's first axis (unit, in the face).
    pub u: Vector3<f64>,
    /// The face frame's second axis, `normal x u`.
    pub v: Vector3<f64>,
    /// The outer boundary, counter-clockwise in the face frame (m).
    pub outer: Vec<Point2<f64>>,
    /// Holes, clockwise in the face frame (m).
    pub holes: Vec<Vec<Point2<f64>>>,
}

impl PlanarFace {
    /// A point of the face frame in the part frame.
    pub fn to_part(&self, p: &Point2<f64>) -> Point3<f64> {
        self.centroid_m + self.u * p.x + self.v * p.y
    }

    /// The area of its holes (m^2).
    pub fn holes_area_m2(&self) -> f64 {
        self.holes
            .iter()
            .map(|h| {
                let n = h.len();
                (0..n)
                    .map(|k| {
                        let (a, b) = (h[k], h[(k + 1) % n]);
                        a.x * b.y - b.x * a.y
                    })
                    .sum::<f64>()
                    .abs()
                    / 2.0
            })
            .sum()
    }

    /// The face's extent along `u` and `v` (m).
    pub fn extent_m(&self) -> [f64; 2] {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &self.outer {
            lo = [lo[0].min(p.x), lo[1].min(p.y)];
            hi = [hi[0].max(p.x), hi[1].max(p.y)];
        }
        [hi[0] - lo[0], hi[1] - lo[1]]
    }

    /// Every boundary segment (outer and holes).
    fn segments(&self) -> impl Iterator<Item = (Point2<f64>, Point2<f64>)> + '_ {
        std::iter::once(&self.outer)
            .chain(self.holes.iter())
            .flat_map(|r| (0..r.len()).map(move |k| (r[k], r[(k + 1) % r.len()])))
    }

    /// Whether `p` is inside the outer boundary and outside every hole (even-odd over all rings).
    pub fn contains(&self, p: &Point2<f64>) -> bool {
        let mut inside = false;
        for (a, b) in self.segments() {
            if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x) {
                inside = !inside;
            }
        }
        inside
    }

    /// Distance from `p` to the nearest boundary edge (m).
    pub fn clearance_m(&self, p: &Point2<f64>) -> f64 {
        self.segments()
            .map(|(a, b)| {
                let ab = b - a;
                let t = ((p - a).dot(&ab) / ab.norm_squared().max(1e-30)).clamp(0.0, 1.0);
                (p - (a + ab * t)).norm()
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// The cup-fit region for a disc of `radius_m` (cup radius plus the face margin).
    pub fn cup_fit(&self, radius_m: f64) -> CupFit {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &self.outer {
            lo = [lo[0].min(p.x), lo[1].min(p.y)];
            hi = [hi[0].max(p.x), hi[1].max(p.y)];
        }
        let spacing = ((hi[0] - lo[0]).max(hi[1] - lo[1]) / FIT_GRID as f64).max(MIN_FIT_SPACING_M);
        let mut centres = Vec::new();
        let mut best: Option<(Point2<f64>, f64)> = None;
        // Only centres at least `radius` inside the bounding rectangle can fit.
        let (x0, x1) = (lo[0] + radius_m, hi[0] - radius_m);
        let (y0, y1) = (lo[1] + radius_m, hi[1] - radius_m);
        if x0 <= x1 && y0 <= y1 {
            let nx = ((x1 - x0) / spacing).floor() as usize + 1;
            let ny = ((y1 - y0) / spacing).floor() as usize + 1;
            // Centre the grid in the admissible rectangle.
            let ox = x0 + 0.5 * ((x1 - x0) - (nx - 1) as f64 * spacing);
            let oy = y0 + 0.5 * ((y1 - y0) - (ny - 1) as f64 * spacing);
            for j in 0..ny {
                for i in 0..nx {
                    let p = Point2::new(ox + i as f64 * spacing, oy + j as f64 * spacing);
                    if !self.contains(&p) {
                        continue;
                    }
                    let c = self.clearance_m(&p);
                    if c >= radius_m {
                        centres.push((p, c));
                        // The clearest centre; of equally clear ones (a long strip), the one
                        // nearest the face's centroid.
                        if best
                            .is_none_or(|(q, b)| c > b + 1e-9 || (c >= b - 1e-9 && p.coords.norm() < q.coords.norm()))
                        {
                            best = Some((p, c));
                        }
                    }
                }
            }
        }
        CupFit {
            radius_m,
            spacing_m: spacing,
            area_m2: centres.len() as f64 * spacing * spacing,
            best: best.map(|(p, _)| p),
            best_clearance_m: best.map_or(0.0, |(_, c)| c),
            centres: centres.into_iter().map(|(p, _)| p).collect(),
        }
    }
}

/// Where a cup seals on a face: the admissible cup centres on a grid, in the face frame.
#[derive(Debug, Clone, PartialEq)]
pub struct CupFit {
    /// The disc's radius (cup radius plus face margin) (m).
    pub radius_m: f64,
    /// Grid spacing (m).
    pub spacing_m: f64,
    /// The admissible centres (face frame, m).
    pub centres: Vec<Point2<f64>>,
    /// The region's area: centres x spacing^2 (m^2).
    pub area_m2: f64,
    /// The admissible centre farthest from every edge, if any.
    pub best: Option<Point2<f64>>,
    /// Its distance to the nearest edge (m).
    pub best_clearance_m: f64,
}

impl CupFit {
    /// Whether the cup seals anywhere on the face.
    pub fn takes_cup(&self) -> bool {
        !self.centres.is_empty()
    }
}

/// The planar faces of a closed mesh, largest first. `dist_tol_m` is how far a corner may lie
/// off the face's plane.
pub fn planar_faces(mesh: &Mesh, dist_tol_m: f64) -> Vec<PlanarFace> {
    let n = mesh.triangles.len();
    let normals: Vec<Vector3<f64>> = (0..n)
        .map(|k| mesh.area_normal(k).try_normalize(0.0).unwrap_or_else(Vector3::z))
        .collect();
    let mut edges: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (k, t) in mesh.triangles.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push(k);
        }
    }
    let cos_tol = FACE_ANGLE_TOL_RAD.cos();
    let mut face_of = vec![usize::MAX; n];
    // Seeds in order of area (largest first), so a face grows from its largest triangle.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| mesh.area_m2(b).total_cmp(&mesh.area_m2(a)).then(a.cmp(&b)));
    let mut faces = Vec::new();
    for &s in &order {
        if face_of[s] != usize::MAX {
            continue;
        }
        let id = faces.len();
        let n0 = normals[s];
        let p0 = mesh.corners(s)[0];
        face_of[s] = id;
        let mut members = vec![s];
        let mut stack = vec![s];
        while let Some(k) = stack.pop() {
            let t = mesh.triangles[k];
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                for &o in &edges[&(a.min(b), a.max(b))] {
                    if face_of[o] != usize::MAX || normals[o].dot(&n0) < cos_tol {
                        continue;
                    }
                    if mesh.corners(o).iter().any(|c| (c - p0).dot(&n0).abs() > dist_tol_m) {
                        continue;
                    }
                    face_of[o] = id;
                    members.push(o);
                    stack.push(o);
                }
            }
        }
        faces.push(members);
    }
    let built: Vec<PlanarFace> = faces.into_iter().map(|m| build_face(mesh, m, &normals)).collect();
    let mut out = merge_coplanar(mesh, built, dist_tol_m);
    out.sort_by(|a, b| b.area_m2.total_cmp(&a.area_m2));
    out
}

/// Faces of different bodies (not edge-connected) in one plane, as the solid's surface shows
/// them: faces of the same outward direction that touch or overlap are one face (their polygon
/// union: a transistor's tab and package backs), and where a face of the opposite direction
/// lies on them (two bodies in contact: a relay's pins on its body, a can on its base), that
/// region is inside the solid and is cut out (polygon difference). A face wholly covered goes;
/// a face cut in pieces becomes one face per piece. Faces nothing coplanar touches stay as
/// they were. Polygon booleans: `i_overlay`, non-zero fill, in one 2D frame per plane.
fn merge_coplanar(mesh: &Mesh, faces: Vec<PlanarFace>, dist_tol_m: f64) -> Vec<PlanarFace> {
    let cos_tol = FACE_ANGLE_TOL_RAD.cos();
    let n = faces.len();
    // Planes: faces whose normals are parallel (either way) within the angle tolerance and whose
    // centroids lie within the distance tolerance of each other's plane. Union-find.
    let mut root: Vec<usize> = (0..n).collect();
    fn find(root: &mut [usize], mut i: usize) -> usize {
        while root[i] != i {
            root[i] = root[root[i]];
            i = root[i];
        }
        i
    }
    // Sorted by the offset along the face's dominant normal axis, so only near offsets compare.
    let offset = |f: &PlanarFace| {
        let k = f.normal.iamax();
        f.centroid_m.coords.dot(&f.normal) * f.normal[k].signum()
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| offset(&faces[a]).total_cmp(&offset(&faces[b])).then(a.cmp(&b)));
    // Two coplanar faces' offsets differ by at most the tolerance plus the tilt (within the
    // angle tolerance) times the distance between their centroids (at most the mesh's size).
    let reach = dist_tol_m + mesh.extent_m().iter().map(|e| e * e).sum::<f64>().sqrt() * FACE_ANGLE_TOL_RAD.sin();
    for (x, &i) in order.iter().enumerate() {
        for &j in &order[x + 1..] {
            if offset(&faces[j]) - offset(&faces[i]) > reach {
                break;
            }
            let (a, b) = (&faces[i], &faces[j]);
            if a.normal.dot(&b.normal).abs() >= cos_tol
                && (b.centroid_m - a.centroid_m).dot(&a.normal).abs() <= dist_tol_m
                && (a.centroid_m - b.centroid_m).dot(&b.normal).abs() <= dist_tol_m
            {
                let (ra, rb) = (find(&mut root, i), find(&mut root, j));
                root[ra.max(rb)] = ra.min(rb);
            }
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for i in 0..n {
        let r = find(&mut root, i);
        groups.entry(r).or_default().push(i);
    }
    let mut keys: Vec<usize> = groups.keys().copied().collect();
    keys.sort_unstable();
    let mut slots: Vec<Option<PlanarFace>> = faces.into_iter().map(Some).collect();
    let mut out = Vec::with_capacity(n);
    for r in keys {
        let members = &groups[&r];
        if members.len() == 1 {
            out.extend(slots[members[0]].take());
            continue;
        }
        let group: Vec<PlanarFace> = members.iter().filter_map(|&i| slots[i].take()).collect();
        out.extend(merge_plane(mesh, group));
    }
    out
}

/// The faces of one plane (see [`merge_coplanar`]).
fn merge_plane(mesh: &Mesh, group: Vec<PlanarFace>) -> Vec<PlanarFace> {
    use i_overlay::core::fill_rule::FillRule;
    use i_overlay::core::overlay_rule::OverlayRule;
    use i_overlay::float::single::SingleFloatOverlay;

    // The plane's 2D frame: the first face's.
    let (o, e1, n0) = (group[0].centroid_m, group[0].u, group[0].normal);
    let e2 = n0.cross(&e1);
    let to2 = |p: &Point3<f64>| [(p - o).dot(&e1), (p - o).dot(&e2)];
    // A face's region in the plane's frame: outer counter-clockwise, holes clockwise (non-zero
    // fill then unites overlapping faces).
    let region = |f: &PlanarFace| -> Vec<Vec<[f64; 2]>> {
        std::iter::once((&f.outer, true))
            .chain(f.holes.iter().map(|h| (h, false)))
            .map(|(ring, outer)| {
                let mut r: Vec<[f64; 2]> = ring.iter().map(|p| to2(&f.to_part(p))).collect();
                if (ring_area(&r) > 0.0) != outer {
                    r.reverse();
                }
                r
            })
            .collect()
    };
    let mut out = Vec::new();
    for dir in [1.0, -1.0] {
        let n = n0 * dir;
        let (same, other): (Vec<&PlanarFace>, Vec<&PlanarFace>) = group.iter().partition(|f| f.normal.dot(&n) > 0.0);
        if same.is_empty() {
            continue;
        }
        let subject: Vec<Vec<Vec<[f64; 2]>>> = same.iter().map(|f| region(f)).collect();
        let clip: Vec<Vec<Vec<[f64; 2]>>> = other.iter().map(|f| region(f)).collect();
        let shapes = subject.overlay(&clip, OverlayRule::Difference, FillRule::NonZero);
        let area = |shape: &Vec<Vec<[f64; 2]>>| shape.iter().map(|r| ring_area(r)).sum::<f64>().abs();
        let before: f64 = same.iter().map(|f| f.area_m2).sum();
        let after: f64 = shapes.iter().map(area).sum();
        // Nothing touched: the faces as they were.
        if shapes.len() == same.len() && (after - before).abs() <= 1e-9 * before.max(1e-30) {
            out.extend(same.into_iter().cloned());
            continue;
        }
        // Area-weighted normal of the faces united.
        let normal = same
            .iter()
            .fold(nalgebra::Vector3::zeros(), |acc, f| acc + f.normal * f.area_m2)
            .try_normalize(0.0)
            .unwrap_or(n);
        for shape in shapes {
            let rings: Vec<Vec<Point3<f64>>> = shape
                .iter()
                .map(|r| r.iter().map(|q| o + e1 * q[0] + e2 * q[1]).collect())
                .collect();
            // The mesh triangles of the united faces whose centroid lies in this piece.
            let mut triangles: Vec<usize> = same
                .iter()
                .flat_map(|f| f.triangles.iter().copied())
                .filter(|&k| {
                    let [a, b, c] = mesh.corners(k);
                    let m = to2(&Point3::from((a.coords + b.coords + c.coords) / 3.0));
                    contains_even_odd(&shape, &m)
                })
                .collect();
            triangles.sort_unstable();
            if let Some(f) = face_of_rings(triangles, normal, &rings) {
                out.push(f);
            }
        }
    }
    out
}

/// Signed area of a ring (positive: counter-clockwise) (m^2).
fn ring_area(r: &[[f64; 2]]) -> f64 {
    (0..r.len())
        .map(|k| {
            let (a, b) = (r[k], r[(k + 1) % r.len()]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Whether `p` lies inside the rings (even-odd).
fn contains_even_odd(rings: &[Vec<[f64; 2]>], p: &[f64; 2]) -> bool {
    let mut inside = false;
    for r in rings {
        for k in 0..r.len() {
            let (a, b) = (r[k], r[(k + 1) % r.len()]);
            if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
                inside = !inside;
            }
        }
    }
    inside
}

/// A face from its region's rings in the part frame (the first the outer boundary, the others
/// holes), its outward `normal` and its mesh triangles: the frame as [`build_face`] sets it
/// (origin at the region's centroid, `u` along its longest boundary edge). `None` for a region
/// without area.
fn face_of_rings(triangles: Vec<usize>, normal: Vector3<f64>, rings: &[Vec<Point3<f64>>]) -> Option<PlanarFace> {
    let outer3 = rings.first()?;
    let p0 = *outer3.first()?;
    let longest = rings
        .iter()
        .flat_map(|r| (0..r.len()).map(move |k| r[(k + 1) % r.len()] - r[k]))
        .fold(None::<Vector3<f64>>, |best, d| match best {
            Some(b) if b.norm() + 1e-12 >= d.norm() => Some(b),
            _ => Some(d),
        })?;
    let u = (longest - normal * longest.dot(&normal)).try_normalize(1e-12)?;
    let v = normal.cross(&u);
    let flat =
        |r: &Vec<Point3<f64>>| -> Vec<[f64; 2]> { r.iter().map(|p| [(p - p0).dot(&u), (p - p0).dot(&v)]).collect() };
    let flats: Vec<Vec<[f64; 2]>> = rings.iter().map(flat).collect();
    // Area and centroid: the outer ring's, less the holes'.
    let moments = |r: &Vec<[f64; 2]>| {
        let (mut a2, mut mx, mut my) = (0.0, 0.0, 0.0);
        for i in 0..r.len() {
            let (a, b) = (r[i], r[(i + 1) % r.len()]);
            let c = a[0] * b[1] - b[0] * a[1];
            a2 += c;
            mx += (a[0] + b[0]) * c;
            my += (a[1] + b[1]) * c;
        }
        // |area|, and the area times the centroid (the signs cancel).
        let area = (a2 / 2.0).abs();
        if a2 == 0.0 {
            (0.0, 0.0, 0.0)
        } else {
            (area, mx / (3.0 * a2) * area, my / (3.0 * a2) * area)
        }
    };
    let (mut area, mut sx, mut sy) = moments(&flats[0]);
    for h in &flats[1..] {
        let (a, x, y) = moments(h);
        area -= a;
        sx -= x;
        sy -= y;
    }
    if area <= 0.0 {
        return None;
    }
    let (cx, cy) = (sx / area, sy / area);
    let centroid = p0 + u * cx + v * cy;
    let ring2 = |r: &Vec<[f64; 2]>, ccw: bool| -> Vec<Point2<f64>> {
        let mut q: Vec<Point2<f64>> = r.iter().map(|p| Point2::new(p[0] - cx, p[1] - cy)).collect();
        if (ring_area(r) > 0.0) != ccw {
            q.reverse();
        }
        q
    };
    Some(PlanarFace {
        triangles,
        area_m2: area,
        normal,
        centroid_m: centroid,
        u,
        v,
        outer: ring2(&flats[0], true),
        holes: flats[1..].iter().map(|h| ring2(h, false)).collect(),
    })
}

/// A face from its triangles: normal, centroid, frame and boundary rings.
fn build_face(mesh: &Mesh, mut tris: Vec<usize>, normals: &[Vector3<f64>]) -> PlanarFace {
    tris.sort_unstable();
    let mut area = 0.0;
    let mut nsum = Vector3::zeros();
    let mut csum = Vector3::zeros();
    for &k in &tris {
        let a = mesh.area_m2(k);
        let [p, q, r] = mesh.corners(k);
        area += a;
        nsum += normals[k] * a;
        csum += (p.coords + q.coords + r.coords) / 3.0 * a;
    }
    let normal = nsum.try_normalize(0.0).unwrap_or(normals[tris[0]]);
    let centroid = Point3::from(csum / area.max(1e-300));
    // Directed boundary edges: an edge of the face whose reverse is not in the face.
    let mut directed: HashSet<(u32, u32)> = HashSet::new();
    for &k in &tris {
        let t = mesh.triangles[k];
        for e in 0..3 {
            directed.insert((t[e], t[(e + 1) % 3]));
        }
    }
    let mut next: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut longest: Option<(f64, Vector3<f64>)> = None;
    let mut bnd: Vec<(u32, u32)> = directed
        .iter()
        .filter(|(a, b)| !directed.contains(&(*b, *a)))
        .copied()
        .collect();
    bnd.sort_unstable();
    for &(a, b) in &bnd {
        next.entry(a).or_default().push(b);
        let d = mesh.vertices_m[b as usize] - mesh.vertices_m[a as usize];
        if longest.is_none_or(|(l, _)| d.norm() > l + 1e-12) {
            longest = Some((d.norm(), d));
        }
    }
    let u0 = longest.map_or_else(|| normal.cross(&Vector3::x()), |(_, d)| d);
    let u = (u0 - normal * u0.dot(&normal))
        .try_normalize(1e-12)
        .unwrap_or_else(|| normal.cross(&Vector3::y()).normalize());
    let v = normal.cross(&u);
    let to2 = |i: u32| {
        let d = mesh.vertices_m[i as usize] - centroid;
        Point2::new(d.dot(&u), d.dot(&v))
    };
    let mut rings: Vec<Vec<Point2<f64>>> = Vec::new();
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    for s in starts {
        while let Some(first) = next.get_mut(&s).and_then(|v| v.pop()) {
            let mut ring = vec![to2(s)];
            let mut at = first;
            let mut guard = 0;
            while at != s && guard <= bnd.len() {
                ring.push(to2(at));
                guard += 1;
                match next.get_mut(&at).and_then(|v| v.pop()) {
                    Some(n) => at = n,
                    None => break,
                }
            }
            if ring.len() >= 3 {
                rings.push(ring);
            }
        }
    }
    let signed = |r: &Vec<Point2<f64>>| {
        (0..r.len())
            .map(|k| {
                let (a, b) = (r[k], r[(k + 1) % r.len()]);
                a.x * b.y - b.x * a.y
            })
            .sum::<f64>()
            / 2.0
    };
    // The outer ring is the one of the largest area; the others are holes.
    let outer_k = (0..rings.len())
        .max_by(|&a, &b| signed(&rings[a]).abs().total_cmp(&signed(&rings[b]).abs()))
        .unwrap_or(0);
    let mut outer = if rings.is_empty() {
        Vec::new()
    } else {
        rings.swap_remove(outer_k)
    };
    if signed(&outer) < 0.0 {
        outer.reverse();
    }
    for h in &mut rings {
        if signed(h) > 0.0 {
            h.reverse();
        }
    }
    PlanarFace {
        triangles: tris,
        area_m2: area,
        normal,
        centroid_m: centroid,
        u,
        v,
        outer,
        holes: rings,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::mass::tests::box_mesh;

    /// A square plate 20 x 20 x 2 mm with a square 6 x 6 mm hole through its middle, wound
    /// outward: written out by hand.
    fn plate_with_hole() -> Mesh {
        let (o, i, h) = (0.010, 0.003, 0.001);
        let ring = |r: f64, z: f64| [(-r, -r), (r, -r), (r, r), (-r, r)].map(|(x, y)| Point3::new(x, y, z));
        let mut v = Vec::new();
        for (r, z) in [(o, -h), (o, h), (i, -h), (i, h)] {
            v.extend(ring(r, z));
        }
        // 0-3 outer bottom, 4-7 outer top, 8-11 inner bottom, 12-15 inner top.
        let mut t = Vec::new();
        for k in 0..4u32 {
            let n = (k + 1) % 4;
            // Top: between the outer and inner rings, counter-clockwise seen from +z.
            t.push([4 + k, 4 + n, 12 + n]);
            t.push([4 + k, 12 + n, 12 + k]);
            // Bottom, seen from -z.
            t.push([k, 8 + n, n]);
            t.push([k, 8 + k, 8 + n]);
            // Outer wall.
            t.push([k, n, 4 + n]);
            t.push([k, 4 + n, 4 + k]);
            // Inner wall (facing the hole's axis).
            t.push([8 + k, 12 + n, 8 + n]);
            t.push([8 + k, 12 + k, 12 + n]);
        }
        Mesh {
            vertices_m: v,
            triangles: t,
        }
    }

    /// Boxes as one mesh of separate bodies (shells), as CAD exports them.
    fn bodies(boxes: &[([f64; 3], [f64; 3])]) -> Mesh {
        let mut m = Mesh::default();
        for (lo, hi) in boxes {
            crate::part::tessellate::append(&mut m, &box_mesh(*lo, *hi));
        }
        m
    }

    /// The faces whose outward normal is +z, largest first: (height, area) (m, m^2).
    fn up_faces(m: &Mesh) -> Vec<(f64, f64)> {
        planar_faces(m, 1e-9)
            .iter()
            .filter(|f| f.normal.z > 0.999)
            .map(|f| (f.centroid_m.z, f.area_m2))
            .collect()
    }

    #[test]
    fn coplanar_faces_of_touching_bodies_are_one_face_and_apart_they_stay_two() {
        // A tab 10 x 6 mm and a package 10 x 8 mm, both 2 mm thick, backs (z = 0) coplanar,
        // overlapping by 1 mm along y (the package's tab end sits on the tab's edge).
        let (tab, pkg) = (
            ([0.0, 0.0, 0.0], [0.01, 0.006, 0.002]),
            ([0.0, 0.005, 0.0], [0.01, 0.013, 0.002]),
        );
        let m = bodies(&[tab, pkg]);
        let backs: Vec<PlanarFace> = planar_faces(&m, 1e-9)
            .into_iter()
            .filter(|f| f.normal.z < -0.999)
            .collect();
        assert_eq!(backs.len(), 1, "one back");
        let back = &backs[0];
        // Independent: the union of two rectangles is 10 x 13 mm.
        assert!((back.area_m2 - 0.01 * 0.013).abs() < 1e-12, "{}", back.area_m2);
        let e = back.extent_m();
        assert!(
            (e[0].max(e[1]) - 0.013).abs() < 1e-9 && (e[0].min(e[1]) - 0.01).abs() < 1e-9,
            "{e:?}"
        );
        // The union's centroid: the middle of the 13 mm span.
        assert!((back.centroid_m - Point3::new(0.005, 0.0065, 0.0)).norm() < 1e-9);
        // A 9 mm disc fits only on the united face: the tab (6 mm) and the package (8 mm) are
        // each too narrow for it, their union (10 x 13 mm) is not.
        assert!(back.cup_fit(0.0045).takes_cup());
        // Both tops (z = 2 mm) touch too: one face.
        assert_eq!(up_faces(&m).len(), 1);
        // Negative controls: 1 mm apart, the backs stay two faces, each too narrow for the disc.
        let apart = bodies(&[tab, ([0.0, 0.007, 0.0], [0.01, 0.015, 0.002])]);
        let backs: Vec<PlanarFace> = planar_faces(&apart, 1e-9)
            .into_iter()
            .filter(|f| f.normal.z < -0.999)
            .collect();
        assert_eq!(backs.len(), 2);
        assert!(backs.iter().all(|f| !f.cup_fit(0.0045).takes_cup()));
        // Parallel faces at different heights (the package 0.5 mm lower) stay apart.
        let stepped = bodies(&[tab, ([0.0, 0.005, -0.0005], [0.01, 0.013, 0.0015])]);
        let backs = planar_faces(&stepped, 1e-9)
            .into_iter()
            .filter(|f| f.normal.z < -0.999)
            .count();
        assert_eq!(backs, 2);
    }

    #[test]
    fn where_one_body_stands_on_another_the_contact_is_cut_out_of_both_faces() {
        // A 20 x 20 x 2 mm plate with a 4 x 4 mm post, 3 mm tall, on the middle of its top.
        let m = bodies(&[
            ([-0.01, -0.01, -0.002], [0.01, 0.01, 0.0]),
            ([-0.002, -0.002, 0.0], [0.002, 0.002, 0.003]),
        ]);
        let up = up_faces(&m);
        // The plate's top less the post's footprint, and the post's top: two faces up; the
        // post's bottom (inside the solid) is no face.
        assert_eq!(up.len(), 2, "{up:?}");
        assert!(
            (up[0].0 - 0.0).abs() < 1e-12 && (up[0].1 - (4e-4 - 1.6e-5)).abs() < 1e-12,
            "{up:?}"
        );
        assert!(
            (up[1].0 - 0.003).abs() < 1e-12 && (up[1].1 - 1.6e-5).abs() < 1e-12,
            "{up:?}"
        );
        let faces = planar_faces(&m, 1e-9);
        assert!(
            !faces.iter().any(|f| f.normal.z < -0.999 && f.centroid_m.z.abs() < 1e-9),
            "the post's bottom is inside"
        );
        let top = faces
            .iter()
            .find(|f| f.normal.z > 0.999 && f.centroid_m.z.abs() < 1e-9)
            .unwrap();
        assert_eq!(top.holes.len(), 1);
        // The cup stays off the post: no admissible centre within 2 + 3.5 mm of the middle
        // along both axes (checked in the part frame).
        let fit = top.cup_fit(0.0035);
        assert!(fit.takes_cup());
        for c in &fit.centres {
            let p = top.to_part(c);
            let (dx, dy) = ((p.x.abs() - 0.002).max(0.0), (p.y.abs() - 0.002).max(0.0));
            assert!(dx.hypot(dy) >= 0.0035 - 1e-9, "{p}");
        }
        // Negative control: the post lifted 1 mm off the plate touches nothing: the plate's
        // top keeps its full 20 x 20 mm.
        let lifted = bodies(&[
            ([-0.01, -0.01, -0.002], [0.01, 0.01, 0.0]),
            ([-0.002, -0.002, 0.001], [0.002, 0.002, 0.004]),
        ]);
        let up = up_faces(&lifted);
        assert!((up[0].1 - 4e-4).abs() < 1e-12, "{up:?}");
    }

    #[test]
    fn a_box_has_six_faces_with_their_areas() {
        let m = box_mesh([0.0; 3], [0.01, 0.02, 0.03]);
        let f = planar_faces(&m, 1e-7);
        assert_eq!(f.len(), 6);
        assert!((f[0].area_m2 - 0.02 * 0.03).abs() < 1e-12);
        assert!(f[0].normal.x.abs() > 0.999);
        assert_eq!(f[0].outer.len(), 4);
        assert!(f.iter().all(|f| f.holes.is_empty()));
        let e = f[0].extent_m();
        assert!((e[0].max(e[1]) - 0.03).abs() < 1e-12 && (e[0].min(e[1]) - 0.02).abs() < 1e-12);
    }

    #[test]
    fn a_face_with_a_hole_keeps_the_cup_off_the_hole() {
        let m = plate_with_hole();
        assert!(crate::part::mass::mass_properties(&m, crate::part::mass::MassSpec::MassKg(1.0)).is_some());
        let faces = planar_faces(&m, 1e-7);
        let top = faces.iter().find(|f| f.normal.z > 0.99).unwrap();
        assert!((top.area_m2 - (0.02 * 0.02 - 0.006 * 0.006)).abs() < 1e-12);
        assert_eq!(top.holes.len(), 1);
        // The centroid is the middle of the hole: not on the face.
        assert!(!top.contains(&Point2::origin()));
        // A cup of 6 mm + 0.5 mm margin (radius 3.5 mm) seals on the 7 mm band about the hole.
        // Checked independently: every admissible disc stays off the 6 mm square hole and
        // inside the 20 mm square.
        let fit = top.cup_fit(0.0035);
        assert!(fit.takes_cup());
        for c in &fit.centres {
            let p = top.to_part(c);
            let (dx, dy) = ((p.x.abs() - 0.003).max(0.0), (p.y.abs() - 0.003).max(0.0));
            assert!((dx * dx + dy * dy).sqrt() >= 0.0035 - 1e-12, "{p}");
            assert!(p.x.abs().max(p.y.abs()) <= 0.0065 + 1e-12, "{p}");
        }
        // Negative control: the same plate without its hole takes the cup in its middle.
        assert!(!top.cup_fit(0.0043).takes_cup());
        let solid = box_mesh([-0.01, -0.01, -0.001], [0.01, 0.01, 0.001]);
        let f = planar_faces(&solid, 1e-7);
        let top = f.iter().find(|f| f.normal.z > 0.99).unwrap();
        let fit = top.cup_fit(0.0043);
        assert!(
            fit.takes_cup() && fit.best_clearance_m > 0.0095,
            "{}",
            fit.best_clearance_m
        );
    }
}
