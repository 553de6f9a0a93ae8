//! Mass properties of a closed, outward-wound triangle mesh.
//!
//! Job: volume, centroid and inertia tensor of the solid by signed tetrahedra (each triangle with
//! the origin: `det = a . (b x c)`, volume `det / 6`, second moment
//! `det / 120 (a a^T + b b^T + c c^T + s s^T)` with `s = a + b + c`), exact for any closed
//! polyhedron; the density is uniform, from the part's mass or given.
//!
//! Units: m, m^3, kg, kg m^2. Frame: the mesh's (the part frame); the inertia is about the centre
//! of mass along the part axes.

use nalgebra::{Matrix3, Point3, Vector3};

use super::mesh::Mesh;

/// The mass properties of a uniform solid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    /// Volume (m^3).
    pub volume_m3: f64,
    /// Mass (kg).
    pub mass_kg: f64,
    /// Density (kg/m^3).
    pub density_kg_m3: f64,
    /// Centre of mass in the part frame (m).
    pub com_m: Point3<f64>,
    /// Inertia about the centre of mass, part axes (kg m^2).
    pub inertia_com_kg_m2: Matrix3<f64>,
}

/// How the mass is given.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MassSpec {
    /// The part's mass (kg): the density follows from the volume.
    MassKg(f64),
    /// The material's density (kg/m^3): the mass follows from the volume.
    DensityKgM3(f64),
}

/// The mass properties of `mesh` as a uniform solid; `None` when its volume is not positive
/// (not closed, or wound inward).
pub fn mass_properties(mesh: &Mesh, spec: MassSpec) -> Option<MassProperties> {
    // Tetrahedra from a reference point near the part (its bounding box's centre), not the
    // origin: the sums then do not cancel for a part far from its frame's origin.
    let (lo, hi) = mesh.bounds_m()?;
    let origin = nalgebra::center(&lo, &hi).coords;
    let mut vol6 = 0.0;
    let mut first = Vector3::zeros();
    let mut second = Matrix3::zeros();
    for k in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(k).map(|p| p.coords - origin);
        let det = a.dot(&b.cross(&c));
        vol6 += det;
        let s = a + b + c;
        first += det * s;
        second += det * (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
    }
    let volume = vol6 / 6.0;
    if volume.is_nan() || volume <= 0.0 {
        return None;
    }
    // first moment: sum over tetrahedra of vol * s / 4 = det/6 * s/4.
    let com = first / 24.0 / volume;
    let cov = second / 120.0 - volume * com * com.transpose();
    let (mass, density) = match spec {
        MassSpec::MassKg(m) => (m, m / volume),
        MassSpec::DensityKgM3(d) => (d * volume, d),
    };
    let inertia = density * (Matrix3::identity() * cov.trace() - cov);
    Some(MassProperties {
        volume_m3: volume,
        mass_kg: mass,
        density_kg_m3: density,
        com_m: Point3::from(com + origin),
        inertia_com_kg_m2: inertia,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A box mesh with corners at `lo` and `hi`, wound outward (written out here, independently of
    /// any tessellation in the crate).
    pub(crate) fn box_mesh(lo: [f64; 3], hi: [f64; 3]) -> Mesh {
        let v = |i: usize| {
            Point3::new(
                if i & 1 == 0 { lo[0] } else { hi[0] },
                if i & 2 == 0 { lo[1] } else { hi[1] },
                if i & 4 == 0 { lo[2] } else { hi[2] },
            )
        };
        Mesh {
            vertices_m: (0..8).map(v).collect(),
            triangles: vec![
                [0, 2, 3],
                [0, 3, 1], // z-
                [4, 5, 7],
                [4, 7, 6], // z+
                [0, 1, 5],
                [0, 5, 4], // y-
                [2, 6, 7],
                [2, 7, 3], // y+
                [0, 4, 6],
                [0, 6, 2], // x-
                [1, 3, 7],
                [1, 7, 5], // x+
            ],
        }
    }

    #[test]
    fn a_box_has_the_closed_form_mass_properties() {
        let (a, b, c) = (0.01, 0.02, 0.03);
        let m = box_mesh([1.0, -0.5, 0.2], [1.0 + a, -0.5 + b, 0.2 + c]);
        let mp = mass_properties(&m, MassSpec::MassKg(0.6)).unwrap();
        assert!((mp.volume_m3 - a * b * c).abs() < 1e-9 * a * b * c);
        assert!((mp.com_m - Point3::new(1.0 + a / 2.0, -0.5 + b / 2.0, 0.2 + c / 2.0)).norm() < 1e-12);
        let want = Matrix3::from_diagonal(&Vector3::new(
            0.6 / 12.0 * (b * b + c * c),
            0.6 / 12.0 * (a * a + c * c),
            0.6 / 12.0 * (a * a + b * b),
        ));
        assert!(
            (mp.inertia_com_kg_m2 - want).amax() < 1e-9 * want.amax(),
            "{} vs {}",
            mp.inertia_com_kg_m2,
            want
        );
        let d = mass_properties(&m, MassSpec::DensityKgM3(1000.0)).unwrap();
        assert!((d.mass_kg - 1000.0 * a * b * c).abs() < 1e-12);
        // Negative control: the same box wound inward has no positive volume.
        let mut inward = m.clone();
        inward.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        assert!(mass_properties(&inward, MassSpec::MassKg(0.6)).is_none());
    }
}
