//! The sensor's pinhole camera: pose, intrinsics, range and noise settings, pixel rays and
//! projection.
//!
//! Units: m, px, rad. Frames: `world_from_camera` in the optical convention (x right, y down, z
//! along the view).

use nalgebra::{Isometry3, Point3, Vector3};

use crate::config::SensorConfig;

/// The pinhole camera.
#[derive(Debug, Clone)]
pub struct Camera {
    /// `world_from_camera` (optical frame).
    pub world_from_camera: Isometry3<f64>,
    /// Image width (px).
    pub width_px: usize,
    /// Image height (px).
    pub height_px: usize,
    /// Focal length along the image x axis (px).
    pub fx_px: f64,
    /// Focal length along the image y axis (px).
    pub fy_px: f64,
    /// Principal point, x (px).
    pub cx_px: f64,
    /// Principal point, y (px).
    pub cy_px: f64,
    /// Measurable range (m).
    pub min_range_m: f64,
    /// Measurable range (m).
    pub max_range_m: f64,
    /// Depth noise sigma at 1 m (m); grows with depth squared.
    pub depth_noise_at_1m_m: f64,
    /// Returns at incidence angles beyond this are lost (rad).
    pub dropout_grazing_rad: f64,
    /// Random dropout probability.
    pub dropout_probability: f64,
}

impl Camera {
    /// The camera of a cell file. `None` if its pose is degenerate (refused by validation).
    pub fn from_config(s: &SensorConfig) -> Option<Self> {
        Some(Camera {
            world_from_camera: s.world_from_camera()?,
            width_px: s.resolution_px[0] as usize,
            height_px: s.resolution_px[1] as usize,
            fx_px: s.focal_px[0],
            fy_px: s.focal_px[1],
            cx_px: s.principal_point_px[0],
            cy_px: s.principal_point_px[1],
            min_range_m: s.min_range_m,
            max_range_m: s.max_range_m,
            depth_noise_at_1m_m: s.depth_noise_at_1m_m,
            dropout_grazing_rad: s.dropout_grazing_deg.to_radians(),
            dropout_probability: s.dropout_probability,
        })
    }

    /// Unit ray direction through pixel centre (u, v), in the world frame.
    pub fn pixel_dir(&self, u: usize, v: usize) -> Vector3<f64> {
        let d = Vector3::new(
            (u as f64 + 0.5 - self.cx_px) / self.fx_px,
            (v as f64 + 0.5 - self.cy_px) / self.fy_px,
            1.0,
        );
        self.world_from_camera.rotation * d.normalize()
    }

    /// Pixel coordinates and depth of a world point, if in front of the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64, f64)> {
        let c = self.world_from_camera.inverse_transform_point(p);
        (c.z > 1e-9).then(|| {
            (
                self.fx_px * c.x / c.z + self.cx_px,
                self.fy_px * c.y / c.z + self.cy_px,
                c.z,
            )
        })
    }

    /// Size of a pixel at depth `z` (m).
    pub fn pixel_size_at_m(&self, z: f64) -> f64 {
        z / self.fx_px.min(self.fy_px)
    }
}
