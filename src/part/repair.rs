//! Mesh repair: a raw triangle soup from a CAD file made into a closed, outward-wound solid, or
//! refused with the defect named.
//!
//! Job, in order:
//! 1. scale to metres and check the size: a part whose largest extent is under 0.5 mm or over
//!    1 m has wrong units (the message gives the extent in the file's units);
//! 2. weld vertices closer than 1e-5 of the bounding-box diagonal;
//! 3. drop triangles with no area (repeated vertex, or height under the weld tolerance);
//! 4. drop duplicated triangles: twice with the same winding keeps one; twice with opposite
//!    windings is an inner wall (two bodies meeting face to face) and both go, which leaves their
//!    union closed;
//! 5. split T-junctions: a vertex lying on another triangle's open edge, between its ends
//!    (within the weld tolerance of it), splits that triangle in two there, so the two sides of a
//!    seam meshed with different vertices (an L profile's cap cut into two rectangles, faces
//!    tessellated apart) share their edges again;
//! 6. wind each connected body consistently (flip a triangle that runs an edge in the same
//!    direction as its neighbour), then outward (positive signed volume);
//! 7. close holes: each loop of boundary edges is capped by a fan about its centroid when the cap
//!    is small (each under 5 % of the surface, all together under 10 %: missing end caps of leads,
//!    a dropped sliver); larger holes are refused as an open shell (the mass properties, stable
//!    poses and contacts of a part need its solid; a hull would invent material where a pocket or
//!    a gap between leads is, and those decide how the part lies);
//! 8. move the origin to the bounding box's centre (the part frame).
//!
//! Several bodies are kept: they make one rigid part (a body and its leads). Stated
//! simplifications: bodies that interpenetrate are not merged (their overlap counts twice in the
//! volume; CAD exporters write touching bodies, KiCad's leads meet the body at its face), and an
//! inner sheet that is not doubled (an edge with three or more triangles) is kept and counted
//! in [`RepairReport::non_manifold_edges`].
//!
//! Units: m after step 1. Frame: the part frame after step 8.

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};

use super::mesh::Mesh;
use super::raw::{Defect, RawMesh};

/// The smallest largest extent of a part (m).
pub const MIN_EXTENT_M: f64 = 0.0005;
/// The largest extent of a part (m).
pub const MAX_EXTENT_M: f64 = 1.0;
/// Weld tolerance as a share of the bounding box's diagonal.
pub const WELD_SHARE: f64 = 1e-5;
/// Largest hole closed, as a share of the surface area.
pub const HOLE_SHARE: f64 = 0.05;
/// Largest area of all holes closed, as a share of the surface area.
pub const HOLES_SHARE: f64 = 0.10;

/// What the repair did.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct RepairReport {
    /// Vertices merged into another.
    pub welded_vertices: usize,
    /// Triangles dropped for having no area.
    pub zero_area_triangles: usize,
    /// Triangles dropped as same-wound duplicates.
    pub duplicate_triangles: usize,
    /// Triangle pairs dropped as inner walls.
    pub inner_wall_pairs: usize,
    /// Triangles split at a T-junction (a vertex on their open edge).
    pub t_junctions_split: usize,
    /// Triangles flipped to agree with their body's winding.
    pub flipped_triangles: usize,
    /// Bodies turned inside out (flipped whole).
    pub flipped_bodies: usize,
    /// Holes capped.
    pub holes_closed: usize,
    /// Area of the capped holes (m^2).
    pub holes_area_m2: f64,
    /// Edges shared by more than two triangles.
    pub non_manifold_edges: usize,
    /// Connected bodies.
    pub bodies: usize,
}

/// Repairs a raw mesh in file units scaled by `metres_per_unit` (see the module header);
/// `units` names them in messages.
pub fn repair(raw: &RawMesh, metres_per_unit: f64, units: &str) -> Result<(Mesh, RepairReport), Defect> {
    repair_with(raw, metres_per_unit, units, true)
}

/// [`repair`], with step 5 (T-junctions) on or off (off: the tests' control).
fn repair_with(
    raw: &RawMesh,
    metres_per_unit: f64,
    units: &str,
    split_t: bool,
) -> Result<(Mesh, RepairReport), Defect> {
    let mut rep = RepairReport::default();
    if raw.triangles.is_empty() {
        return Err(Defect::Empty("the file holds no triangles".into()));
    }
    // 1. Size of the referenced vertices.
    let used = used_vertices(raw);
    let Extent {
        centre,
        tol,
        longest_axis,
    } = checked_extent(raw, &used, metres_per_unit, units)?;
    // 2. Weld on a grid of cells of the tolerance.
    let (mut verts, remap) = weld(raw, &used, metres_per_unit, centre, tol, &mut rep);
    // 3. Zero-area triangles.
    let mut tris = drop_zero_area(raw, &remap, &verts, tol, &mut rep);
    // 4. Duplicates and inner walls.
    drop_duplicates(&mut tris, &mut rep);
    if tris.is_empty() {
        return Err(Defect::Empty("no triangle with an area is left".into()));
    }
    // 5. T-junctions.
    if split_t {
        split_t_junctions(&verts, &mut tris, tol, longest_axis, &mut rep);
    }
    // 6. Consistent winding per body, then outward.
    orient(&verts, &mut tris, &mut rep);
    // 7. Holes.
    close_holes(&mut verts, &mut tris, &mut rep)?;
    rep.non_manifold_edges = edge_uses(&tris).values().filter(|u| u.len() > 2).count();
    rep.bodies = bodies(&tris).1;
    if rep.bodies > super::raw::MAX_BODIES {
        return Err(Defect::TooManyBodies {
            found: rep.bodies,
            cap: super::raw::MAX_BODIES,
        });
    }
    Ok((
        Mesh {
            vertices_m: verts,
            triangles: tris,
        },
        rep,
    ))
}

/// The indices of the vertices some triangle references, ascending.
fn used_vertices(raw: &RawMesh) -> Vec<usize> {
    let mut u = vec![false; raw.vertices.len()];
    for t in &raw.triangles {
        for &i in t {
            u[i as usize] = true;
        }
    }
    (0..raw.vertices.len()).filter(|&i| u[i]).collect()
}

/// The used vertices' box, as the repair reads it.
struct Extent {
    /// The box's centre (m, file frame).
    centre: [f64; 3],
    /// The weld tolerance (m).
    tol: f64,
    /// The axis along which the box is longest (0, 1, 2: x, y, z).
    longest_axis: usize,
}

/// The used vertices' box, after checking that its size in metres is one a part can have (else
/// the units are wrong).
fn checked_extent(raw: &RawMesh, used: &[usize], metres_per_unit: f64, units: &str) -> Result<Extent, Defect> {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for &i in used {
        for a in 0..3 {
            lo[a] = lo[a].min(raw.vertices[i][a]);
            hi[a] = hi[a].max(raw.vertices[i][a]);
        }
    }
    let ext_file = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let ext_m = ext_file.map(|e| e * metres_per_unit);
    let largest = ext_m.iter().cloned().fold(0.0, f64::max);
    let spans = format!(
        "the mesh spans {:.6} x {:.6} x {:.6} file units, {:.6} x {:.6} x {:.6} mm as {units}",
        ext_file[0],
        ext_file[1],
        ext_file[2],
        ext_m[0] * 1e3,
        ext_m[1] * 1e3,
        ext_m[2] * 1e3
    );
    if !largest.is_finite() || largest > MAX_EXTENT_M {
        return Err(Defect::Units(format!(
            "{spans}: larger than {} m; check shape.units",
            MAX_EXTENT_M
        )));
    }
    if largest < MIN_EXTENT_M {
        return Err(Defect::Units(format!(
            "{spans}: smaller than {} mm; check shape.units",
            MIN_EXTENT_M * 1e3
        )));
    }
    let diag = ext_m.iter().map(|e| e * e).sum::<f64>().sqrt();
    let centre = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]) * metres_per_unit);
    let longest_axis = (0..3).max_by(|&a, &b| ext_m[a].total_cmp(&ext_m[b])).unwrap_or(0);
    Ok(Extent {
        centre,
        tol: WELD_SHARE * diag,
        longest_axis,
    })
}

/// Welds the used vertices closer than `tol` on a grid of cells of the tolerance (a vertex checks
/// the 27 cells about it): the welded vertices in metres about `centre`, and the map from a raw
/// vertex index to its welded one.
fn weld(
    raw: &RawMesh,
    used: &[usize],
    metres_per_unit: f64,
    centre: [f64; 3],
    tol: f64,
    rep: &mut RepairReport,
) -> (Vec<Point3<f64>>, Vec<u32>) {
    let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    let mut verts: Vec<Point3<f64>> = Vec::new();
    let mut remap = vec![u32::MAX; raw.vertices.len()];
    for &i in used {
        let p = Point3::from([0, 1, 2].map(|a| raw.vertices[i][a] * metres_per_unit - centre[a]));
        let key = [0, 1, 2].map(|a| (p[a] / tol).floor() as i64);
        let mut found = None;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(c) = cells.get(&[key[0] + dx, key[1] + dy, key[2] + dz]) {
                        for &j in c {
                            if (verts[j as usize] - p).norm() <= tol {
                                found = Some(j);
                                break 'search;
                            }
                        }
                    }
                }
            }
        }
        remap[i] = match found {
            Some(j) => {
                rep.welded_vertices += 1;
                j
            }
            None => {
                let j = verts.len() as u32;
                verts.push(p);
                cells.entry(key).or_default().push(j);
                j
            }
        };
    }
    (verts, remap)
}

/// The raw triangles on the welded vertices, without those of (near) zero area.
fn drop_zero_area(
    raw: &RawMesh,
    remap: &[u32],
    verts: &[Point3<f64>],
    tol: f64,
    rep: &mut RepairReport,
) -> Vec<[u32; 3]> {
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(raw.triangles.len());
    for t in &raw.triangles {
        let t = t.map(|i| remap[i as usize]);
        let (a, b, c) = (verts[t[0] as usize], verts[t[1] as usize], verts[t[2] as usize]);
        let longest = (b - a).norm().max((c - b).norm()).max((a - c).norm());
        let twice_area = (b - a).cross(&(c - a)).norm();
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || twice_area <= tol * longest {
            rep.zero_area_triangles += 1;
        } else {
            tris.push(t);
        }
    }
    tris
}

/// Drops the triangles on the same three vertices: a pair wound opposite ways is an inner wall
/// (both go), of those wound alike one stays.
fn drop_duplicates(tris: &mut Vec<[u32; 3]>, rep: &mut RepairReport) {
    let mut seen: HashMap<[u32; 3], Vec<usize>> = HashMap::new();
    for (k, t) in tris.iter().enumerate() {
        let mut s = *t;
        s.sort_unstable();
        seen.entry(s).or_default().push(k);
    }
    let mut keep = vec![true; tris.len()];
    let mut groups: Vec<&Vec<usize>> = seen.values().filter(|g| g.len() > 1).collect();
    groups.sort();
    for g in groups {
        let parity = |t: &[u32; 3]| {
            let r = t.iter().position(|&v| v == *t.iter().min().unwrap_or(&0)).unwrap_or(0);
            t[(r + 1) % 3] < t[(r + 2) % 3]
        };
        let (mut fwd, mut back): (Vec<usize>, Vec<usize>) = (Vec::new(), Vec::new());
        for &k in g {
            if parity(&tris[k]) { fwd.push(k) } else { back.push(k) }
        }
        let pairs = fwd.len().min(back.len());
        rep.inner_wall_pairs += pairs;
        for &k in fwd.iter().take(pairs).chain(back.iter().take(pairs)) {
            keep[k] = false;
        }
        let (rest, rest_len) = if fwd.len() > pairs {
            (&fwd[pairs..], fwd.len() - pairs)
        } else {
            (&back[pairs..], back.len() - pairs)
        };
        for &k in rest.iter().skip(1) {
            keep[k] = false;
        }
        rep.duplicate_triangles += rest_len.saturating_sub(1);
    }
    let mut k = 0;
    tris.retain(|_| {
        k += 1;
        keep[k - 1]
    });
}

/// Most passes of [`split_t_junctions`]: each splits a triangle at most once, so an open edge with
/// more vertices on it than this keeps the rest (and the hole check judges what is left).
const T_JUNCTION_PASSES: usize = 64;
/// Most work of [`split_t_junctions`] in all (vertex tests, and a triangle's share of each pass's
/// edge table): a soup whose open edges all overlap along the sorted axis stops here instead of
/// hanging, and the hole check judges what is left.
const T_JUNCTION_BUDGET: usize = 10_000_000;

/// Splits each triangle whose open edge (an edge of one triangle) has another open edge's vertex
/// on it, strictly between its ends and within `tol` of it, into two at that vertex (the one
/// nearest the edge's start first), pass by pass until no open edge has one. Open edges' vertices
/// are looked up along `axis` (the mesh's longest), so a closed mesh costs one pass over its edges.
fn split_t_junctions(verts: &[Point3<f64>], tris: &mut Vec<[u32; 3]>, tol: f64, axis: usize, rep: &mut RepairReport) {
    let key = |i: u32| verts[i as usize][axis];
    let mut work = 0usize;
    for _ in 0..T_JUNCTION_PASSES {
        work += tris.len();
        if work > T_JUNCTION_BUDGET {
            return;
        }
        let uses = edge_uses(tris);
        let open: Vec<((u32, u32), usize)> = {
            let mut e: Vec<((u32, u32), usize)> = uses
                .iter()
                .filter(|(_, u)| u.len() == 1)
                .map(|(&k, u)| (k, u[0]))
                .collect();
            e.sort_unstable();
            e
        };
        if open.is_empty() {
            return;
        }
        // The open edges' vertices, along the axis.
        let mut rim: Vec<u32> = open.iter().flat_map(|&((a, b), _)| [a, b]).collect();
        rim.sort_unstable_by(|&i, &j| key(i).total_cmp(&key(j)).then(i.cmp(&j)));
        rim.dedup();
        let mut split = vec![false; tris.len()];
        let mut added: Vec<[u32; 3]> = Vec::new();
        let mut exhausted = false;
        'edges: for &((a, b), k) in &open {
            if split[k] {
                continue;
            }
            let (pa, pb) = (verts[a as usize], verts[b as usize]);
            let d = pb - pa;
            let len2 = d.norm_squared();
            let (x0, x1) = (pa[axis].min(pb[axis]) - tol, pa[axis].max(pb[axis]) + tol);
            let from = rim.partition_point(|&i| key(i) < x0);
            // The vertex on the edge nearest its start, as the parameter along it.
            let mut best: Option<(f64, u32)> = None;
            for &v in rim[from..].iter().take_while(|&&i| key(i) <= x1) {
                work += 1;
                if work > T_JUNCTION_BUDGET {
                    // The splits made so far stand (each kept its two halves).
                    exhausted = true;
                    break 'edges;
                }
                if v == a || v == b {
                    continue;
                }
                let q = verts[v as usize] - pa;
                let t = q.dot(&d) / len2;
                if t * len2.sqrt() <= tol || (1.0 - t) * len2.sqrt() <= tol {
                    continue;
                }
                if (q - d * t).norm() <= tol && best.is_none_or(|(bt, _)| t < bt) {
                    best = Some((t, v));
                }
            }
            let Some((_, v)) = best else { continue };
            // The triangle as it runs the edge: (s, e, c) with s -> e along its winding.
            let t = tris[k];
            let r = (0..3).find(|&r| t[r] == a && t[(r + 1) % 3] == b || t[r] == b && t[(r + 1) % 3] == a);
            let Some(r) = r else { continue };
            let (s, e, c) = (t[r], t[(r + 1) % 3], t[(r + 2) % 3]);
            tris[k] = [s, v, c];
            added.push([v, e, c]);
            split[k] = true;
            rep.t_junctions_split += 1;
        }
        if added.is_empty() {
            return;
        }
        tris.extend(added);
        if exhausted {
            return;
        }
    }
}

/// Closes each boundary loop with a fan about its centroid, unless a hole (or all holes together)
/// is too large a share of the surface to be a meshing gap; then winds capped bodies outward again.
fn close_holes(verts: &mut Vec<Point3<f64>>, tris: &mut Vec<[u32; 3]>, rep: &mut RepairReport) -> Result<(), Defect> {
    let surface = tris.iter().map(|t| area(verts, t)).sum::<f64>();
    let loops = boundary_loops(tris).map_err(Defect::OpenShell)?;
    let mut caps = Vec::new();
    let mut hole_total = 0.0;
    for lp in &loops {
        let (c, cap, a) = hole_cap(verts, lp, (verts.len() + caps.len()) as u32);
        if a > HOLE_SHARE * surface {
            return Err(Defect::OpenShell(format!(
                "a hole of {} edges and {:.3} mm^2 ({:.1} % of the surface; at most {} % is closed): export a closed solid",
                lp.len(),
                a * 1e6,
                100.0 * a / surface,
                HOLE_SHARE * 100.0
            )));
        }
        hole_total += a;
        caps.push((c, cap));
    }
    if hole_total > HOLES_SHARE * surface {
        return Err(Defect::OpenShell(format!(
            "{} holes of {:.3} mm^2 together ({:.1} % of the surface; at most {} % is closed): export a closed solid",
            loops.len(),
            hole_total * 1e6,
            100.0 * hole_total / surface,
            HOLES_SHARE * 100.0
        )));
    }
    rep.holes_closed = caps.len();
    rep.holes_area_m2 = hole_total;
    for (c, cap) in caps {
        verts.push(c);
        tris.extend(cap);
    }
    if rep.holes_closed > 0 {
        // A capped body's sign is now defined: wind it outward again.
        orient(verts, tris, &mut RepairReport::default());
    }
    Ok(())
}

/// The cap of one boundary loop: its centroid (the new vertex `ci`), the fan of triangles from the
/// loop's edges to it, and the fan's area (m^2).
fn hole_cap(verts: &[Point3<f64>], lp: &[u32], ci: u32) -> (Point3<f64>, Vec<[u32; 3]>, f64) {
    let c = lp.iter().map(|&i| verts[i as usize].coords).sum::<Vector3<f64>>() / lp.len() as f64;
    let cap: Vec<[u32; 3]> = (0..lp.len()).map(|k| [lp[(k + 1) % lp.len()], lp[k], ci]).collect();
    let a: f64 = (0..lp.len())
        .map(|k| {
            let (p, q) = (
                verts[lp[k] as usize].coords,
                verts[lp[(k + 1) % lp.len()] as usize].coords,
            );
            0.5 * (p - c).cross(&(q - c)).norm()
        })
        .sum();
    (Point3::from(c), cap, a)
}

/// A triangle's area.
fn area(v: &[Point3<f64>], t: &[u32; 3]) -> f64 {
    let (a, b, c) = (v[t[0] as usize], v[t[1] as usize], v[t[2] as usize]);
    0.5 * (b - a).cross(&(c - a)).norm()
}

/// For each undirected edge (smaller index first), the triangles using it.
fn edge_uses(tris: &[[u32; 3]]) -> HashMap<(u32, u32), Vec<usize>> {
    let mut m: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (k, t) in tris.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            m.entry((a.min(b), a.max(b))).or_default().push(k);
        }
    }
    m
}

/// The body (connected over edges) of each triangle, and how many bodies.
fn bodies(tris: &[[u32; 3]]) -> (Vec<usize>, usize) {
    let uses = edge_uses(tris);
    let mut body = vec![usize::MAX; tris.len()];
    let mut n = 0;
    for s in 0..tris.len() {
        if body[s] != usize::MAX {
            continue;
        }
        body[s] = n;
        let mut stack = vec![s];
        while let Some(k) = stack.pop() {
            let t = tris[k];
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                for &o in &uses[&(a.min(b), a.max(b))] {
                    if body[o] == usize::MAX {
                        body[o] = n;
                        stack.push(o);
                    }
                }
            }
        }
        n += 1;
    }
    (body, n)
}

/// Winds each body consistently across its two-triangle edges, then outward by signed volume.
fn orient(verts: &[Point3<f64>], tris: &mut [[u32; 3]], rep: &mut RepairReport) {
    let uses = edge_uses(tris);
    let mut done = vec![false; tris.len()];
    let mut body = vec![usize::MAX; tris.len()];
    let mut n = 0;
    for s in 0..tris.len() {
        if done[s] {
            continue;
        }
        done[s] = true;
        body[s] = n;
        let mut stack = vec![s];
        while let Some(k) = stack.pop() {
            let t = tris[k];
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                let u = &uses[&(a.min(b), a.max(b))];
                if u.len() != 2 {
                    continue;
                }
                let o = if u[0] == k { u[1] } else { u[0] };
                if done[o] {
                    continue;
                }
                // The neighbour must run this edge b -> a.
                let ot = tris[o];
                let same = (0..3).any(|f| ot[f] == a && ot[(f + 1) % 3] == b);
                if same {
                    tris[o] = [ot[0], ot[2], ot[1]];
                    rep.flipped_triangles += 1;
                }
                done[o] = true;
                body[o] = n;
                stack.push(o);
            }
        }
        n += 1;
    }
    // Signed volume per body: turned inside out when negative.
    let mut vol = vec![0.0; n];
    for (k, t) in tris.iter().enumerate() {
        let (a, b, c) = (verts[t[0] as usize], verts[t[1] as usize], verts[t[2] as usize]);
        vol[body[k]] += a.coords.dot(&b.coords.cross(&c.coords));
    }
    let inside_out: Vec<bool> = vol.iter().map(|v| *v < 0.0).collect();
    rep.flipped_bodies += inside_out.iter().filter(|&&f| f).count();
    for (k, t) in tris.iter_mut().enumerate() {
        if inside_out[body[k]] {
            *t = [t[0], t[2], t[1]];
        }
    }
}

/// The loops of boundary edges (edges of one triangle), each as its vertices in the direction
/// the mesh runs them; an error when boundary edges do not chain into closed loops.
fn boundary_loops(tris: &[[u32; 3]]) -> Result<Vec<Vec<u32>>, String> {
    let uses = edge_uses(tris);
    let mut out: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut n_edges = 0;
    for t in tris {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            if uses[&(a.min(b), a.max(b))].len() == 1 {
                out.entry(a).or_default().push(b);
                n_edges += 1;
            }
        }
    }
    let mut starts: Vec<u32> = out.keys().copied().collect();
    starts.sort_unstable();
    let mut loops = Vec::new();
    for s in starts {
        while let Some(first) = out.get_mut(&s).and_then(|v| v.pop()) {
            let mut lp = vec![s];
            let mut at = first;
            while at != s {
                lp.push(at);
                if lp.len() > n_edges {
                    return Err(format!("{n_edges} boundary edges that form no closed loop"));
                }
                at = match out.get_mut(&at).and_then(|v| v.pop()) {
                    Some(n) => n,
                    None => {
                        return Err(format!(
                            "{n_edges} boundary edges that form no closed loop (a hole's rim meets itself or another)"
                        ));
                    }
                };
            }
            loops.push(lp);
        }
    }
    Ok(loops)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::mass::tests::box_mesh;
    use crate::part::mass::{MassSpec, mass_properties};

    /// A box as a raw soup in mm: every triangle with its own three vertices (as STL writes).
    fn soup(lo: [f64; 3], hi: [f64; 3]) -> RawMesh {
        let m = box_mesh(lo, hi);
        let mut r = RawMesh::default();
        for t in &m.triangles {
            let b = r.vertices.len() as u32;
            for &i in t {
                let p = m.vertices_m[i as usize];
                r.vertices.push([p.x, p.y, p.z]);
            }
            r.triangles.push([b, b + 1, b + 2]);
        }
        r
    }

    fn volume(m: &Mesh) -> f64 {
        mass_properties(m, MassSpec::MassKg(1.0)).map_or(0.0, |p| p.volume_m3)
    }

    #[test]
    fn a_soup_is_welded_centred_and_scaled() {
        let (m, rep) = repair(&soup([0.0; 3], [10.0, 20.0, 30.0]), 0.001, "mm").unwrap();
        assert_eq!(m.vertices_m.len(), 8);
        assert_eq!(rep.welded_vertices, 36 - 8);
        assert_eq!(rep.bodies, 1);
        assert!((volume(&m) - 6e-6).abs() < 1e-15);
        let (lo, hi) = m.bounds_m().unwrap();
        assert!((lo.coords + hi.coords).norm() < 1e-15);
    }

    #[test]
    fn flipped_triangles_and_an_inside_out_body_are_wound_outward() {
        let mut r = soup([0.0; 3], [10.0, 20.0, 30.0]);
        r.triangles[3].swap(1, 2);
        r.triangles[7].swap(1, 2);
        let (m, rep) = repair(&r, 0.001, "mm").unwrap();
        assert_eq!((rep.flipped_triangles, rep.flipped_bodies), (2, 0));
        assert!((volume(&m) - 6e-6).abs() < 1e-15);
        // Every triangle wound the other way: one body flipped, volume positive.
        let mut r = soup([0.0; 3], [10.0, 20.0, 30.0]);
        r.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        let (m, rep) = repair(&r, 0.001, "mm").unwrap();
        assert_eq!(rep.flipped_bodies, 1);
        assert!((volume(&m) - 6e-6).abs() < 1e-15);
    }

    #[test]
    fn two_bodies_stay_one_part_and_a_shared_wall_goes() {
        // Two boxes side by side, touching over a 10 x 10 face: the touching faces are an inner
        // wall (same vertices, opposite windings) and go; the union is one closed body.
        let mut r = soup([0.0; 3], [10.0, 10.0, 10.0]);
        let b = soup([10.0, 0.0, 0.0], [20.0, 10.0, 10.0]);
        let n = r.vertices.len() as u32;
        r.vertices.extend(b.vertices);
        r.triangles.extend(b.triangles.iter().map(|t| t.map(|i| i + n)));
        let (m, rep) = repair(&r, 0.001, "mm").unwrap();
        assert_eq!(rep.inner_wall_pairs, 2);
        assert!((volume(&m) - 2e-6).abs() < 1e-15);
        // Two boxes apart: two bodies, both kept.
        let mut r = soup([0.0; 3], [10.0, 10.0, 10.0]);
        let b = soup([15.0, 0.0, 0.0], [25.0, 10.0, 10.0]);
        let n = r.vertices.len() as u32;
        r.vertices.extend(b.vertices);
        r.triangles.extend(b.triangles.iter().map(|t| t.map(|i| i + n)));
        let (m, rep) = repair(&r, 0.001, "mm").unwrap();
        assert_eq!(rep.bodies, 2);
        assert!((volume(&m) - 2e-6).abs() < 1e-15);
    }

    #[test]
    fn zero_area_triangles_and_small_holes_are_mended_and_large_ones_refused() {
        let mut r = soup([0.0; 3], [10.0, 20.0, 30.0]);
        r.vertices.push([1.0, 1.0, 1.0]);
        let k = r.vertices.len() as u32 - 1;
        r.triangles.push([k, k, 0]);
        r.triangles.push([0, 1, 1]);
        let (_, rep) = repair(&r, 0.001, "mm").unwrap();
        assert_eq!(rep.zero_area_triangles, 2);
        // A big hole: one 20 x 30 face missing (27 % of the surface) is refused.
        let mut r = soup([0.0; 3], [10.0, 20.0, 30.0]);
        r.triangles.drain(8..10);
        let e = repair(&r, 0.001, "mm").unwrap_err();
        assert!(matches!(e, Defect::OpenShell(_)), "{e}");
        // A small hole: a box with a 1 x 1 mm square window cut in its top, the window's rim
        // triangulated around it, is closed.
        let (m, rep) = repair(&box_with_window(), 0.001, "mm").unwrap();
        assert_eq!(rep.holes_closed, 1);
        assert!((volume(&m) - 1e-6).abs() < 1e-12, "{}", volume(&m));
    }

    /// An L-profile bracket extruded 12 mm along y (mm): a 20 x 2 mm foot and a 2 x 10 mm upright,
    /// each end cap meshed as two rectangles (the foot's and the upright's), the side walls one
    /// quad per profile edge; so the foot's cap edge has the upright's corner on it, and the back
    /// wall's edge the foot's top corner: four T-junctions.
    fn l_bracket() -> RawMesh {
        let mut r = RawMesh::default();
        let mut quad = |p: [[f64; 3]; 4]| {
            let b = r.vertices.len() as u32;
            r.vertices.extend(p);
            r.triangles.push([b, b + 1, b + 2]);
            r.triangles.push([b, b + 2, b + 3]);
        };
        let at = |x: f64, y: f64, z: f64| [x, y, z];
        for (y, out) in [(0.0, true), (12.0, false)] {
            for [x0, z0, x1, z1] in [[0.0, 0.0, 20.0, 2.0], [0.0, 2.0, 2.0, 10.0]] {
                let c = [at(x0, y, z0), at(x1, y, z0), at(x1, y, z1), at(x0, y, z1)];
                quad(if out { c } else { [c[3], c[2], c[1], c[0]] });
            }
        }
        let profile = [
            [0.0, 0.0],
            [20.0, 0.0],
            [20.0, 2.0],
            [2.0, 2.0],
            [2.0, 10.0],
            [0.0, 10.0],
        ];
        for k in 0..profile.len() {
            let ([x0, z0], [x1, z1]) = (profile[k], profile[(k + 1) % profile.len()]);
            quad([at(x0, 0.0, z0), at(x0, 12.0, z0), at(x1, 12.0, z1), at(x1, 0.0, z1)]);
        }
        r
    }

    #[test]
    fn t_junctions_are_split_and_the_solid_closes() {
        let (m, rep) = repair(&l_bracket(), 0.001, "mm").unwrap();
        assert_eq!(rep.t_junctions_split, 4);
        assert_eq!(rep.holes_closed, 0);
        assert_eq!(rep.bodies, 1);
        let v = (20.0 * 2.0 + 2.0 * 8.0) * 12.0 * 1e-9;
        assert!((volume(&m) - v).abs() < 1e-15, "{} against {v}", volume(&m));
        assert!(edge_uses(&m.triangles).values().all(|u| u.len() == 2));
        // The control: without the split, the seams' open edges chain into loops that are no
        // hole a cap could close, and the part is refused.
        let e = repair_with(&l_bracket(), 0.001, "mm", false).unwrap_err();
        assert!(matches!(e, Defect::OpenShell(_)), "{e}");
    }

    /// A 10 mm cube whose top face has a 1 mm square window (the window's rim fanned to the
    /// top's corners).
    fn box_with_window() -> RawMesh {
        let full = soup([0.0; 3], [10.0, 10.0, 10.0]);
        let mut r = RawMesh {
            vertices: full.vertices.clone(),
            triangles: full
                .triangles
                .iter()
                .enumerate()
                .filter(|(k, _)| *k != 2 && *k != 3)
                .map(|(_, t)| *t)
                .collect(),
        };
        let b = r.vertices.len() as u32;
        for p in [
            [0.0, 0.0],
            [10.0, 0.0],
            [10.0, 10.0],
            [0.0, 10.0],
            [4.5, 4.5],
            [5.5, 4.5],
            [5.5, 5.5],
            [4.5, 5.5],
        ] {
            r.vertices.push([p[0], p[1], 10.0]);
        }
        for k in 0..4u32 {
            let n = (k + 1) % 4;
            r.triangles.push([b + k, b + n, b + 4 + n]);
            r.triangles.push([b + k, b + 4 + n, b + 4 + k]);
        }
        r
    }

    #[test]
    fn wrong_units_and_empty_meshes_are_refused() {
        let r = soup([0.0; 3], [10.0, 20.0, 30.0]);
        assert!(matches!(repair(&r, 1.0, "m"), Err(Defect::Units(_))));
        assert!(matches!(repair(&r, 1e-5, "?"), Err(Defect::Units(_))));
        assert!(matches!(repair(&RawMesh::default(), 1.0, "m"), Err(Defect::Empty(_))));
        let flat = RawMesh {
            vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
            triangles: vec![[0, 1, 2]],
        };
        assert!(matches!(repair(&flat, 0.001, "mm"), Err(Defect::Empty(_))));
    }
}
