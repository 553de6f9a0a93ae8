//! A triangle mesh in the part frame: the one surface representation of a part.
//!
//! Job: vertices and triangles (counter-clockwise seen from outside, so normals point out), and
//! the few measures every user of a mesh needs.
//!
//! Units: m. Frame: the part frame.

use nalgebra::{Point3, Vector3};

/// A triangle mesh: shared vertices, triangles as vertex indices wound counter-clockwise seen
/// from outside the solid.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions in the part frame (m).
    pub vertices_m: Vec<Point3<f64>>,
    /// Triangles as indices into `vertices_m`, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// The axis-aligned bounds of the vertices (m): `(min, max)`, or `None` for an empty mesh.
    pub fn bounds_m(&self) -> Option<(Point3<f64>, Point3<f64>)> {
        let first = *self.vertices_m.first()?;
        Some(
            self.vertices_m
                .iter()
                .fold((first, first), |(lo, hi), v| (lo.inf(v), hi.sup(v))),
        )
    }

    /// The three corners of triangle `k` (m).
    pub fn corners(&self, k: usize) -> [Point3<f64>; 3] {
        self.triangles[k].map(|i| self.vertices_m[i as usize])
    }

    /// Twice the area of triangle `k` times its unit normal: the cross product of two edges
    /// (m^2), pointing out for a triangle wound counter-clockwise seen from outside.
    pub fn area_normal(&self, k: usize) -> Vector3<f64> {
        let [a, b, c] = self.corners(k);
        (b - a).cross(&(c - a))
    }

    /// Area of triangle `k` (m^2).
    pub fn area_m2(&self, k: usize) -> f64 {
        0.5 * self.area_normal(k).norm()
    }

    /// The surface's area (m^2).
    pub fn surface_m2(&self) -> f64 {
        (0..self.triangles.len()).map(|k| self.area_m2(k)).sum()
    }

    /// Edge lengths of the bounding box (m); zeros for an empty mesh.
    pub fn extent_m(&self) -> [f64; 3] {
        self.bounds_m().map_or([0.0; 3], |(lo, hi)| (hi - lo).into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_span_every_vertex_and_an_empty_mesh_has_none() {
        let m = Mesh {
            vertices_m: vec![
                Point3::new(0.0, -1.0, 2.0),
                Point3::new(3.0, 1.0, -2.0),
                Point3::new(1.0, 0.0, 0.0),
            ],
            triangles: vec![[0, 1, 2]],
        };
        let (lo, hi) = m.bounds_m().unwrap();
        assert_eq!(lo, Point3::new(0.0, -1.0, -2.0));
        assert_eq!(hi, Point3::new(3.0, 1.0, 2.0));
        assert!(Mesh::default().bounds_m().is_none());
    }
}
