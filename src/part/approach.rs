//! Whether the hand's approach to a cup site is clear of the part's own geometry: pins, tabs, a
//! can above its base plate.
//!
//! Job: the suction hand comes down along a face's normal onto a cup site; its solid is a stack
//! of coaxial cylinders above the face (the cup, then the wider tool body), each a
//! [`ColumnPiece`]. The approach is clear when no triangle of the part's mesh enters any of
//! them above the face's plane (by more than a tolerance). Exact for a triangle against a
//! cylinder slab: the triangle is clipped to the slab's heights, and the clipped polygon's
//! projection along the axis is tested against the cylinder's radius.
//!
//! Units: m. Frame: the part frame; heights along the face's outward normal from its plane.

use nalgebra::{Point2, Point3, Vector2};

use super::faces::PlanarFace;
use super::mesh::Mesh;

/// Heights within this of the face's plane belong to the face (and to its edges' neighbours
/// going down) (m).
pub const ABOVE_FACE_TOL_M: f64 = 5e-5;

/// One coaxial cylinder of the hand above the cup site.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColumnPiece {
    /// Radius about the approach axis (m).
    pub radius_m: f64,
    /// Lowest height above the face (m).
    pub from_m: f64,
    /// Highest height above the face (m).
    pub to_m: f64,
}

/// Whether the hand's column (`column`) standing on the face `face` at the cup site `site` (face
/// frame) meets no triangle of `mesh` above the face's plane.
pub fn column_clear(mesh: &Mesh, face: &PlanarFace, site: &Point2<f64>, column: &[ColumnPiece]) -> bool {
    let origin = face.to_part(site);
    let local = |p: &Point3<f64>| {
        let d = p - origin;
        (Vector2::new(d.dot(&face.u), d.dot(&face.v)), d.dot(&face.normal))
    };
    let top = column.iter().map(|c| c.to_m).fold(0.0, f64::max);
    let widest = column.iter().map(|c| c.radius_m).fold(0.0, f64::max);
    for t in &mesh.triangles {
        let pts = t.map(|i| local(&mesh.vertices_m[i as usize]));
        // Quick rejections: wholly at or below the face, above the column, or beyond its widest
        // radius on one side.
        if pts.iter().all(|(_, h)| *h <= ABOVE_FACE_TOL_M) || pts.iter().all(|(_, h)| *h >= top) {
            continue;
        }
        if (0..2).any(|k| pts.iter().all(|(q, _)| q[k] > widest) || pts.iter().all(|(q, _)| q[k] < -widest)) {
            continue;
        }
        for c in column {
            let lo = c.from_m.max(ABOVE_FACE_TOL_M);
            if lo >= c.to_m {
                continue;
            }
            let poly = clip_slab(&pts, lo, c.to_m);
            if !poly.is_empty() && distance_to_polygon(&poly) < c.radius_m {
                return false;
            }
        }
    }
    true
}

/// The polygon of a triangle `(xy, h)` clipped to `lo <= h <= hi`, as its points' xy.
fn clip_slab(tri: &[(Vector2<f64>, f64); 3], lo: f64, hi: f64) -> Vec<Vector2<f64>> {
    let mut poly: Vec<(Vector2<f64>, f64)> = tri.to_vec();
    for (bound, keep_below) in [(lo, false), (hi, true)] {
        let inside = |h: f64| if keep_below { h <= bound } else { h >= bound };
        let mut out = Vec::with_capacity(poly.len() + 1);
        for k in 0..poly.len() {
            let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
            if inside(a.1) {
                out.push(a);
            }
            if inside(a.1) != inside(b.1) {
                let t = (bound - a.1) / (b.1 - a.1);
                out.push((a.0 + (b.0 - a.0) * t, bound));
            }
        }
        poly = out;
        if poly.is_empty() {
            break;
        }
    }
    poly.into_iter().map(|(q, _)| q).collect()
}

/// Distance from the origin to a convex polygon (0 inside it; a degenerate polygon is its edges).
fn distance_to_polygon(poly: &[Vector2<f64>]) -> f64 {
    let n = poly.len();
    let seg = |a: &Vector2<f64>, b: &Vector2<f64>| {
        let ab = b - a;
        let t = if ab.norm_squared() > 0.0 {
            (-a.dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (a + ab * t).norm()
    };
    if n == 1 {
        return poly[0].norm();
    }
    let cross: Vec<f64> = (0..n)
        .map(|k| {
            let (a, b) = (poly[k], poly[(k + 1) % n]);
            a.x * b.y - a.y * b.x
        })
        .collect();
    let area2: f64 = cross.iter().sum();
    if area2.abs() > 1e-18 && cross.iter().all(|c| c * area2.signum() >= 0.0) {
        return 0.0;
    }
    (0..n)
        .map(|k| seg(&poly[k], &poly[(k + 1) % n]))
        .fold(f64::INFINITY, f64::min)
}

/// The cup site on `face` whose approach is clear of the part's own geometry: among the face's
/// admissible cup centres (`centres`, face frame), the one farthest from the face's edges whose
/// column is clear; of centres equally far (within [`SITE_TIE_M`]: the middle line of a long
/// strip), the one nearest the face's centroid, as [`PlanarFace::cup_fit`]'s best; with its
/// distance to the nearest edge (m). `None` when every centre's approach meets the part. At most
/// [`MAX_SITES_TRIED`] centres are tried, evenly spread over the centres so ranked.
pub fn clear_site(
    mesh: &Mesh,
    face: &PlanarFace,
    centres: &[Point2<f64>],
    column: &[ColumnPiece],
) -> Option<(Point2<f64>, f64)> {
    let mut ranked: Vec<(Point2<f64>, f64)> = centres.iter().map(|c| (*c, face.clearance_m(c))).collect();
    // Clearances compared on a grid of SITE_TIE_M: the centres of a strip's middle line differ
    // only by rounding, and the first of them in grid order sat at the strip's end, far from
    // the centre of mass (C as a mesh: no lift held).
    let key = |c: f64| (c / SITE_TIE_M).round() as i64;
    // Of centres equally far from the edges and from the centroid (mirror images on a symmetric
    // face), the one lowest in x, then in y, on the same grid: a part read from a file in single
    // precision picks the site its primitives pick.
    ranked.sort_by(|a, b| {
        key(b.1)
            .cmp(&key(a.1))
            .then(key(a.0.coords.norm()).cmp(&key(b.0.coords.norm())))
            .then(key(a.0.x).cmp(&key(b.0.x)))
            .then(key(a.0.y).cmp(&key(b.0.y)))
    });
    let step = ranked.len().div_ceil(MAX_SITES_TRIED).max(1);
    ranked
        .into_iter()
        .step_by(step)
        .find(|(c, _)| column_clear(mesh, face, c, column))
}

/// The most cup centres [`clear_site`] tries on one face.
pub const MAX_SITES_TRIED: usize = 200;
/// Clearances to the face's edges closer than this are equal when [`clear_site`] ranks cup
/// centres (m).
pub const SITE_TIE_M: f64 = 1e-6;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::faces::planar_faces;
    use crate::part::mass::tests::box_mesh;

    /// Two boxes as one mesh (a plate with a post on it: the post's bottom on the plate's top).
    fn union(a: Mesh, b: Mesh) -> Mesh {
        let off = a.vertices_m.len() as u32;
        let mut m = a;
        m.vertices_m.extend(b.vertices_m);
        m.triangles.extend(b.triangles.iter().map(|t| t.map(|i| i + off)));
        m
    }

    #[test]
    fn a_post_beside_the_site_blocks_the_tool_body_but_not_a_short_one() {
        // A 60 x 20 x 2 mm plate; a 2 x 2 mm post at x = -20 mm on its top, 12 mm tall. The hand:
        // a 3 mm cup 9 mm long, then a 15 mm body.
        let plate = box_mesh([-0.03, -0.01, -0.001], [0.03, 0.01, 0.001]);
        let column = [
            ColumnPiece {
                radius_m: 0.003,
                from_m: 0.0,
                to_m: 0.009,
            },
            ColumnPiece {
                radius_m: 0.015,
                from_m: 0.009,
                to_m: 0.12,
            },
        ];
        let post = |h: f64| box_mesh([-0.021, -0.001, 0.001], [-0.019, 0.001, 0.001 + h]);
        let top_of = |m: &Mesh| {
            planar_faces(m, 1e-9)
                .into_iter()
                .find(|f| f.normal.z > 0.999 && f.area_m2 > 1e-4)
                .unwrap()
        };
        let tall = union(plate.clone(), post(0.012));
        let face = top_of(&tall);
        let at = |x: f64| {
            let p = Point3::new(x, 0.0, 0.001) - face.centroid_m;
            Point2::new(p.dot(&face.u), p.dot(&face.v))
        };
        // The tool body (from 9 mm up) reaches the 12 mm post within 15 mm of it: a site 10 mm
        // from the post is blocked, one 17 mm away is clear. Independent: the post's nearest
        // side is 9 mm from the first site, under the body's 15 mm.
        assert!(!column_clear(&tall, &face, &at(-0.01), &column));
        assert!(column_clear(&tall, &face, &at(-0.003), &column));
        // The cup itself (3 mm) meets the post from 1 mm up: a site 3.5 mm from its axis.
        assert!(!column_clear(&tall, &face, &at(-0.0165), &column[..1]));
        // Negative control: a post 6 mm tall stays under the body: the site 10 mm from it is
        // clear.
        let short = union(plate.clone(), post(0.006));
        let face_s = top_of(&short);
        let at_s = |x: f64| {
            let p = Point3::new(x, 0.0, 0.001) - face_s.centroid_m;
            Point2::new(p.dot(&face_s.u), p.dot(&face_s.v))
        };
        assert!(column_clear(&short, &face_s, &at_s(-0.01), &column));
        // The bare plate's top is clear everywhere (its own face and its sides are not above it).
        let bare_face = top_of(&plate);
        assert!(column_clear(&plate, &bare_face, &Point2::origin(), &column));
        // The site chooser moves the cup away from a tall post beside the face's clearest
        // centre: at least 15 + 1 mm from its axis, where the clearest centre is 5 mm from it.
        let mid = union(plate.clone(), box_mesh([0.004, -0.001, 0.001], [0.006, 0.001, 0.013]));
        let face_m = top_of(&mid);
        let fit = face_m.cup_fit(0.0035);
        let best = face_m.to_part(&fit.best.unwrap());
        assert!((best.x - 0.005).abs() < 0.016, "{best:?}");
        let (site, _) = clear_site(&mid, &face_m, &fit.centres, &column).unwrap();
        let p = face_m.to_part(&site);
        assert!((p.x - 0.005).abs() >= 0.016 - 1e-9, "{p:?}");
        // A long strip (150 x 10 mm): the centres of its middle line are equally far from its
        // edges; the site is the one nearest the face's centroid (the primitive's face centre),
        // not the first of the line. Checked in the part frame: the strip's middle is x = 0.
        let strip = box_mesh([-0.075, -0.005, -0.0025], [0.075, 0.005, 0.0025]);
        let face_t = top_of(&strip);
        let fit = face_t.cup_fit(0.0035);
        let (site, clearance) = clear_site(&strip, &face_t, &fit.centres, &column).unwrap();
        let p = face_t.to_part(&site);
        assert!(p.x.abs() <= fit.spacing_m && (clearance - 0.005).abs() < 1e-9, "{p:?}");
        // Negative control: a tall post across the strip's middle moves the site off it, to the
        // nearest clear centre (16 mm from the post's axis, within a grid step), not to the end.
        let blocked = union(
            strip.clone(),
            box_mesh([-0.001, -0.001, 0.0025], [0.001, 0.001, 0.0145]),
        );
        let face_b = top_of(&blocked);
        let fit = face_b.cup_fit(0.0035);
        let (site, _) = clear_site(&blocked, &face_b, &fit.centres, &column).unwrap();
        let p = face_b.to_part(&site);
        assert!(
            p.x.abs() >= 0.016 - 1e-9 && p.x.abs() <= 0.016 + 2.0 * fit.spacing_m,
            "{p:?}"
        );
        // With no room left on the face (a 20 mm plate with a tall post in its middle), no site.
        let small = union(
            box_mesh([-0.01, -0.01, -0.001], [0.01, 0.01, 0.001]),
            box_mesh([-0.001, -0.001, 0.001], [0.001, 0.001, 0.013]),
        );
        let face_small = top_of(&small);
        let fit = face_small.cup_fit(0.0035);
        assert!(!fit.centres.is_empty());
        assert!(clear_site(&small, &face_small, &fit.centres, &column).is_none());
    }
}
