//! Where a cup that seals on round surfaces (a bellows cup, `gripper.round_min_radius_m`) takes a
//! part by its round body's side: a can lying on its side.
//!
//! Job: the side of the part's round body ([`PartModel::round_body`]) as [`SIDE_STRIPS`] tangent
//! strips, evenly turned about its axis: each a flat face (a [`PlanarFace`] with no triangles)
//! on the plane that touches the body's circle along one line of its side, as long as the body
//! and as wide as the cup. Whatever the body's turn about its axis (recognition cannot tell it
//! for a round part), one strip's normal is within half a strip's turn of up. On each strip the
//! cup goes at the point along the axis nearest the centre of mass whose approach clears the
//! part's own geometry ([`super::approach::column_clear`]: a can's base plate, its leads), at
//! least the cup's radius and the face margin from the body's ends.
//!
//! *Simplified*: the strip is a plane; the cup's lip on the real side touches along the line and
//! follows the surface where it falls away (the physical cup decides, `physics::suction`).
//!
//! Units: m, rad. Frame: the part frame.

use nalgebra::{Point2, Point3, Vector3};

use super::PartModel;
use super::approach::ColumnPiece;
use super::faces::PlanarFace;

/// Strips around a round body's side: 15 degrees apart, so that one is within 7.5 degrees of any
/// direction across the axis.
pub const SIDE_STRIPS: usize = 24;

/// A round body this much narrower than the cup's smallest radius still takes it (m): the rounding
/// of a mesh's vertices, not a different can.
const RADIUS_SLACK_M: f64 = 1e-6;

/// The step along the axis in which a strip's cup site is searched (m).
const SITE_STEP_M: f64 = 0.00025;

/// One tangent strip of a round body's side, with its cup site.
#[derive(Debug, Clone)]
pub struct SideStrip {
    /// The strip as a face: centred on the body's centre along the axis, `u` along the axis,
    /// extent the body's length by the cup's diameter.
    pub face: PlanarFace,
    /// Where the cup goes (part frame, m).
    pub site_m: Point3<f64>,
    /// The site's distance along the axis to the body's nearer end (m).
    pub clearance_m: f64,
}

impl PartModel {
    /// The tangent strips of the round body's side on which a cup of this model's diameter
    /// seals, for a cup that seals on surfaces of radius `round_min_radius_m` and up: empty when
    /// the part has no round body, its radius is smaller, or it is too short for the cup and the
    /// face margin. A strip on which every site's approach meets the part's own geometry
    /// (`column`) is left out.
    pub fn round_side_strips(&self, round_min_radius_m: f64, column: &[ColumnPiece]) -> Vec<SideStrip> {
        let Some(body) = self.round_body() else {
            return Vec::new();
        };
        let cup_r = self.cup.diameter_m / 2.0;
        let keep_off = cup_r + self.cup.face_margin_m;
        // A micron of slack: a CAD file's 4 mm can is 4 mm within its vertices' rounding.
        if body.radius_m < round_min_radius_m - RADIUS_SLACK_M || body.half_length_m < keep_off {
            return Vec::new();
        }
        let axis = body.axis.normalize();
        let e1 = if axis.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let e1 = (e1 - axis * e1.dot(&axis)).normalize();
        let e2 = axis.cross(&e1);
        // The sites along the axis (from the body's centre), nearest the centre of mass first.
        let reach = body.half_length_m - keep_off;
        let com_along = (self.com_m().coords - body.center_m).dot(&axis).clamp(-reach, reach);
        let mut stations = vec![com_along];
        let mut k = 1.0;
        loop {
            let (lo, hi) = (com_along - k * SITE_STEP_M, com_along + k * SITE_STEP_M);
            if lo < -reach && hi > reach {
                break;
            }
            for t in [hi, lo] {
                if t.abs() <= reach {
                    stations.push(t);
                }
            }
            k += 1.0;
        }
        let features = self.mesh_under_symmetry();
        (0..SIDE_STRIPS)
            .filter_map(|i| {
                let turn = i as f64 * std::f64::consts::TAU / SIDE_STRIPS as f64;
                let normal = e1 * turn.cos() + e2 * turn.sin();
                let face = tangent_strip(body.center_m, axis, normal, body.radius_m, body.half_length_m, cup_r);
                let t = stations
                    .iter()
                    .copied()
                    .find(|t| super::approach::column_clear(&features, &face, &Point2::new(*t, 0.0), column))?;
                Some(SideStrip {
                    site_m: face.to_part(&Point2::new(t, 0.0)),
                    clearance_m: body.half_length_m - t.abs(),
                    face,
                })
            })
            .collect()
    }
}

/// The plane touching a body's circle of radius `radius_m` about `axis` (through `center_m`)
/// along the line in direction `normal` (across the axis), as a face `2 half_length_m` long and
/// `2 half_width_m` wide.
fn tangent_strip(
    center_m: Vector3<f64>,
    axis: Vector3<f64>,
    normal: Vector3<f64>,
    radius_m: f64,
    half_length_m: f64,
    half_width_m: f64,
) -> PlanarFace {
    let (l, w) = (half_length_m, half_width_m);
    PlanarFace {
        triangles: Vec::new(),
        area_m2: 4.0 * l * w,
        normal,
        centroid_m: Point3::from(center_m + normal * radius_m),
        u: axis,
        v: normal.cross(&axis),
        outer: vec![
            Point2::new(-l, -w),
            Point2::new(l, -w),
            Point2::new(l, w),
            Point2::new(-l, w),
        ],
        holes: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::CupSpec;
    use crate::part::mass::MassSpec;

    /// A can of `can_radius_m` and 8 mm long about z on a 9.8 x 9.8 x 2 mm base plate below it
    /// (about as the workpiece D is built), meshed, for a 4 mm cup with a 0.5 mm margin.
    fn can_on_base(can_radius_m: f64) -> PartModel {
        can_on(can_radius_m, 0.0049)
    }

    /// The same can on a base plate `2 base_half_m` square.
    fn can_on(can_radius_m: f64, base_half_m: f64) -> PartModel {
        use crate::part::primitive::Axis;
        use crate::part::tessellate::{PRISM_SIDES, append, box_mesh, prism_mesh};
        let mut mesh = prism_mesh(Vector3::new(0.0, 0.0, 0.001), can_radius_m, 0.004, Axis::Z, PRISM_SIDES);
        let base = box_mesh(
            Vector3::new(0.0, 0.0, -0.004),
            Vector3::new(base_half_m, base_half_m, 0.001),
        );
        append(&mut mesh, &base);
        let cup = CupSpec {
            diameter_m: 0.004,
            face_margin_m: 0.0005,
        };
        PartModel::derive(mesh, MassSpec::MassKg(0.0015), cup, None).unwrap()
    }

    fn column() -> [ColumnPiece; 2] {
        [
            ColumnPiece {
                radius_m: 0.0021,
                from_m: 0.0,
                to_m: 0.006,
            },
            ColumnPiece {
                radius_m: 0.0151,
                from_m: 0.006,
                to_m: 0.12,
            },
        ]
    }

    #[test]
    fn a_can_offers_its_side_all_round_clear_of_its_base() {
        let pm = can_on_base(0.005);
        let strips = pm.round_side_strips(0.004, &column());
        assert_eq!(strips.len(), SIDE_STRIPS, "every turn of the side");
        let body = pm.round_body().unwrap().clone();
        for s in &strips {
            let n = s.face.normal;
            assert!(n.dot(&body.axis).abs() < 1e-9 && (n.norm() - 1.0).abs() < 1e-9);
            // On the body's surface along the line the strip touches.
            let r = s.site_m.coords - body.center_m;
            let radial = r - body.axis * r.dot(&body.axis);
            assert!((radial.norm() - body.radius_m).abs() < 1e-9 && radial.dot(&n) > 0.0);
            // Clear of the base: the base's corners stand 1.9 mm proud of the side, and the cup's
            // lip (2 mm, with its slack 2.1) stays above the base's top (z = -3 mm).
            assert!(s.site_m.z - 0.0021 >= -0.003 - 1e-9, "site at z {}", s.site_m.z);
            assert!(s.clearance_m >= 0.0025 - 1e-9);
        }
        // Strips evenly turned: one within 7.5 degrees of any direction across the axis.
        for deg in 0..360 {
            let a = f64::from(deg).to_radians();
            let d = Vector3::new(a.cos(), a.sin(), 0.0);
            let best = strips.iter().map(|s| s.face.normal.dot(&d)).fold(-1.0, f64::max);
            assert!(best >= 7.5f64.to_radians().cos() - 1e-9, "{deg} deg");
        }
    }

    #[test]
    fn a_can_too_round_too_short_or_overhung_by_its_base_offers_no_side() {
        // Negative controls: a cup that seals on radii of 6 mm and up finds no side on a 5 mm
        // can; a 4 mm can does not reach 5 mm either; a cup larger than the can's length finds
        // no station.
        assert!(can_on_base(0.005).round_side_strips(0.006, &column()).is_empty());
        assert!(can_on_base(0.004).round_side_strips(0.005, &column()).is_empty());
        let mut pm = can_on_base(0.005);
        pm.cup = CupSpec {
            diameter_m: 0.011,
            face_margin_m: 0.0005,
        };
        assert!(pm.round_side_strips(0.004, &column()).is_empty());
        // A base plate 24 mm square stands at least 7 mm proud of the side, into the tool body's column
        // (15 mm about the axis, from 6 mm up) wherever the cup goes on the 8 mm can.
        assert!(can_on(0.005, 0.012).round_side_strips(0.004, &column()).is_empty());
        let narrow = [column()[0]];
        assert_eq!(
            can_on(0.005, 0.012).round_side_strips(0.004, &narrow).len(),
            SIDE_STRIPS
        );
    }
}
