//! The sensor's pinhole camera: pose, intrinsics, range and noise settings, pixel rays and
//! projection.
//!
//! Units: m, px, rad. Frames: `world_from_camera` in the optical convention (x right, y down, z
//! along the view).

use nalgebra::{Isometry3, Point3, Vector3};

use crate::config::SensorConfig;
use crate::geometry::TrayVolume;

/// A rectangle of an image's pixels: columns `x0_px..x0_px + width_px`, rows
/// `y0_px..y0_px + height_px`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelWindow {
    /// First column (px).
    pub x0_px: usize,
    /// First row (px).
    pub y0_px: usize,
    /// Columns (px).
    pub width_px: usize,
    /// Rows (px).
    pub height_px: usize,
}

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

    /// The smallest window of the image that shows the tray `tray` (its outer walls, floor to
    /// rim) with `margin_px` pixels around it, clipped to the image; the whole image if the tray
    /// is behind the camera.
    pub fn window_over(&self, tray: &TrayVolume, margin_px: usize) -> PixelWindow {
        let whole = PixelWindow {
            x0_px: 0,
            y0_px: 0,
            width_px: self.width_px,
            height_px: self.height_px,
        };
        let [hx, hy] = tray.half_xy_m;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for z in [0.0, tray.wall_height_m] {
            for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                let Some((u, v, _)) = self.project(&(tray.world_from_tray * Point3::new(sx * hx, sy * hy, z))) else {
                    return whole;
                };
                lo = [lo[0].min(u), lo[1].min(v)];
                hi = [hi[0].max(u), hi[1].max(v)];
            }
        }
        let m = margin_px as f64;
        let clip = |x: f64, n: usize| x.clamp(0.0, n as f64) as usize;
        let (x0, x1) = (
            clip((lo[0] - m).floor(), self.width_px),
            clip((hi[0] + m).ceil(), self.width_px),
        );
        let (y0, y1) = (
            clip((lo[1] - m).floor(), self.height_px),
            clip((hi[1] + m).ceil(), self.height_px),
        );
        if x1 <= x0 || y1 <= y0 {
            return whole;
        }
        PixelWindow {
            x0_px: x0,
            y0_px: y0,
            width_px: x1 - x0,
            height_px: y1 - y0,
        }
    }

    /// The camera whose image is the window `w` of this camera's: the same pose and focal
    /// lengths, the window's size, the principal point moved with the window's origin.
    pub fn cropped(&self, w: &PixelWindow) -> Camera {
        Camera {
            width_px: w.width_px,
            height_px: w.height_px,
            cx_px: self.cx_px - w.x0_px as f64,
            cy_px: self.cy_px - w.y0_px as f64,
            ..self.clone()
        }
    }

    /// Size of a pixel at depth `z` (m).
    pub fn pixel_size_at_m(&self, z: f64) -> f64 {
        z / self.fx_px.min(self.fy_px)
    }

    /// Size of a pixel at the depth of the world point `p` (m).
    pub fn pixel_size_at_point_m(&self, p: &Vector3<f64>) -> f64 {
        let z = (p - self.world_from_camera.translation.vector).dot(&(self.world_from_camera.rotation * Vector3::z()));
        self.pixel_size_at_m(z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LoadedScene;

    #[test]
    fn the_window_over_the_tray_holds_its_rim_and_the_cropped_camera_sees_through_it() {
        let s = LoadedScene::embedded_default().unwrap().scene;
        let cam = Camera::from_config(&s.sensor).unwrap();
        let tray = TrayVolume::new(&s.pick_tray);
        let w = cam.window_over(&tray, 20);
        // Smaller than the image, inside it.
        assert!(w.width_px < cam.width_px && w.height_px < cam.height_px);
        assert!(w.x0_px + w.width_px <= cam.width_px && w.y0_px + w.height_px <= cam.height_px);
        let crop = cam.cropped(&w);
        let [hx, hy] = tray.half_xy_m;
        for (sx, sy, z) in [
            (-1.0, -1.0, tray.wall_height_m),
            (1.0, 1.0, 0.0),
            (1.0, -1.0, tray.wall_height_m),
        ] {
            let p = tray.world_from_tray * Point3::new(sx * hx, sy * hy, z);
            let (u, v, d) = cam.project(&p).unwrap();
            let (uc, vc, dc) = crop.project(&p).unwrap();
            // The same ray: shifted by the window's origin, the same depth.
            assert!((u - w.x0_px as f64 - uc).abs() < 1e-9 && (v - w.y0_px as f64 - vc).abs() < 1e-9);
            assert!((d - dc).abs() < 1e-12);
            // The rim corner lies inside the window, at least the margin from its edges.
            assert!(
                uc >= 19.0 && uc <= crop.width_px as f64 - 19.0,
                "u {uc} of {}",
                crop.width_px
            );
            assert!(
                vc >= 19.0 && vc <= crop.height_px as f64 - 19.0,
                "v {vc} of {}",
                crop.height_px
            );
        }
        // A pixel's ray is the same through either camera.
        let (pu, pv) = (w.x0_px + 7, w.y0_px + 11);
        assert!((cam.pixel_dir(pu, pv) - crop.pixel_dir(7, 11)).norm() < 1e-12);
        // Negative control: a tray behind the camera gives the whole image.
        let mut behind = tray;
        behind.world_from_tray.translation.vector.z = cam.world_from_camera.translation.vector.z + 1.0;
        let whole = cam.window_over(&behind, 20);
        assert_eq!((whole.x0_px, whole.y0_px), (0, 0));
        assert_eq!((whole.width_px, whole.height_px), (cam.width_px, cam.height_px));
    }
}
