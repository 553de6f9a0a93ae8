//! Checks of the scene (cell) file: every value on its own, then the layout that needs no robot
//! model (the sensor sees the whole pick tray floor from above, the trays stand on the table).
//!
//! Job: [`Scene::validate`], one check per section of the file in the file's order, each problem
//! named by its key and bad value. Units and frames: as in [`super::scene`] (the keys carry the
//! units; world frame, z up).

use nalgebra::Vector3;

use super::scene::{
    CAPTURE_BYTES_PER_PIXEL, MAX_CELL_EXTENT_M, MAX_LEAN_DEG, MAX_SENSOR_PIXELS, MIN_CAMERA_ABOVE_RIM_M,
    MIN_VIEW_BASE_PER_DISTANCE, Scene, SlotPattern, TrayConfig,
};
use super::{Checker, ConfigError};

fn check_tray(c: &mut Checker, key: &str, t: &TrayConfig) {
    c.finite_all(&format!("{key}.center_m"), &t.center_m);
    c.finite(&format!("{key}.yaw_deg"), t.yaw_deg);
    c.positive_all(&format!("{key}.inner_size_m"), &t.inner_size_m);
    c.positive(&format!("{key}.wall_height_m"), t.wall_height_m);
    c.positive(&format!("{key}.wall_thickness_m"), t.wall_thickness_m);
    c.positive(&format!("{key}.floor_thickness_m"), t.floor_thickness_m);
}

impl Scene {
    /// Checks every value of the scene on its own (no robot model needed). Geometric checks that
    /// need the robot (reach) are in [`crate::robot::RobotModel::check_scene_reach`].
    pub fn validate(&self, file: &str) -> Result<(), ConfigError> {
        let mut c = Checker::new(file);
        if self.name.trim().is_empty() {
            c.fail("name", "must not be empty");
        }
        self.check_robot(&mut c);
        self.check_gripper(&mut c);
        self.check_sensor(&mut c);
        self.check_trays(&mut c);
        self.check_fixtures(&mut c);
        self.check_cycle(&mut c);
        self.check_sim(&mut c);
        if c.problems.is_empty() {
            self.check_layout(&mut c);
        }
        c.finish()
    }

    /// `robot` and `robot.drives`.
    fn check_robot(&self, c: &mut Checker) {
        let r = &self.robot;
        if r.urdf.trim().is_empty() {
            c.fail("robot.urdf", "must name a URDF file");
        }
        c.finite_all("robot.world_from_base_xyz_m", &r.world_from_base_xyz_m);
        c.finite_all("robot.world_from_base_rpy_deg", &r.world_from_base_rpy_deg);
        c.finite_all("robot.home_deg", &r.home_deg);
        let d = &r.drives;
        c.non_negative_all("robot.drives.armature_kg_m2", &d.armature_kg_m2);
        c.non_negative_all("robot.drives.coulomb_friction_nm", &d.coulomb_friction_nm);
        c.non_negative_all(
            "robot.drives.viscous_friction_nm_s_per_rad",
            &d.viscous_friction_nm_s_per_rad,
        );
        c.positive("robot.drives.coulomb_smoothing_deg_s", d.coulomb_smoothing_deg_s);
        c.positive_all("robot.drives.max_accel_deg_s2", &d.max_accel_deg_s2);
        if let Some(t) = &d.torque_limit_nm {
            c.positive_all("robot.drives.torque_limit_nm", t);
        }
    }

    /// `gripper`.
    fn check_gripper(&self, c: &mut Checker) {
        let g = &self.gripper;
        c.positive("gripper.tool_length_m", g.tool_length_m);
        c.positive("gripper.body_diameter_m", g.body_diameter_m);
        c.positive("gripper.cup_diameter_m", g.cup_diameter_m);
        c.non_negative("gripper.cup_flatness_tolerance_m", g.cup_flatness_tolerance_m);
        c.within("gripper.max_tilt_deg", g.max_tilt_deg, 0.0, 90.0);
        if let Some(lean) = g.max_lean_deg {
            c.within("gripper.max_lean_deg", lean, 0.0, MAX_LEAN_DEG);
        }
        if let Some(r) = g.round_min_radius_m {
            c.positive("gripper.round_min_radius_m", r);
            if r.is_finite() && r <= g.cup_diameter_m / 2.0 {
                c.fail(
                    "gripper.round_min_radius_m",
                    format!(
                        "must exceed the cup's radius (gripper.cup_diameter_m / 2 = {} m): no lip seals on a \
                         surface rounder than itself, got {r}",
                        g.cup_diameter_m / 2.0
                    ),
                );
            }
        }
        c.within("gripper.vacuum_kpa", g.vacuum_kpa, 0.0, 101.325);
        c.within("gripper.lip_friction", g.lip_friction, 0.05, 1.5);
        c.non_negative("gripper.vacuum_build_up_s", g.vacuum_build_up_s);
        c.non_negative("gripper.release_s", g.release_s);
        c.positive("gripper.mass_kg", g.mass_kg);
        c.finite_all("gripper.com_m", &g.com_m);
        c.positive_all("gripper.inertia_kg_m2", &g.inertia_kg_m2);
        let [a, b, cc] = g.inertia_kg_m2;
        if a + b < cc || a + cc < b || b + cc < a {
            c.fail(
                "gripper.inertia_kg_m2",
                format!(
                    "violates the triangle inequality of principal moments, got {:?}",
                    g.inertia_kg_m2
                ),
            );
        }
    }

    /// `sensor`.
    fn check_sensor(&self, c: &mut Checker) {
        let s = &self.sensor;
        c.finite_all("sensor.position_m", &s.position_m);
        c.finite_all("sensor.look_at_m", &s.look_at_m);
        c.finite_all("sensor.image_up", &s.image_up);
        c.resolution("sensor.resolution_px", &s.resolution_px);
        let pixels = u64::from(s.resolution_px[0]) * u64::from(s.resolution_px[1]);
        if pixels > MAX_SENSOR_PIXELS {
            c.fail(
                "sensor.resolution_px",
                format!(
                    "must have at most {MAX_SENSOR_PIXELS} pixels (4 MP, e.g. 2048 x 2048): a capture holds {CAPTURE_BYTES_PER_PIXEL} bytes per pixel and a run keeps several, so {} x {} = {pixels} pixels would need {:.1} GB per capture; got {:?}",
                    s.resolution_px[0],
                    s.resolution_px[1],
                    (pixels * CAPTURE_BYTES_PER_PIXEL) as f64 / 1e9,
                    s.resolution_px
                ),
            );
        }
        c.positive_all("sensor.focal_px", &s.focal_px);
        c.finite_all("sensor.principal_point_px", &s.principal_point_px);
        c.positive("sensor.min_range_m", s.min_range_m);
        c.positive("sensor.max_range_m", s.max_range_m);
        if s.min_range_m.is_finite() && s.max_range_m.is_finite() && s.min_range_m >= s.max_range_m {
            c.fail(
                "sensor.max_range_m",
                format!(
                    "must be > sensor.min_range_m ({}), got {}",
                    s.min_range_m, s.max_range_m
                ),
            );
        }
        c.non_negative("sensor.latency_s", s.latency_s);
        c.positive("sensor.exposure_s", s.exposure_s);
        c.non_negative("sensor.depth_noise_at_1m_m", s.depth_noise_at_1m_m);
        c.within("sensor.dropout_grazing_deg", s.dropout_grazing_deg, 0.0, 90.0);
        c.within("sensor.dropout_probability", s.dropout_probability, 0.0, 1.0);
        c.within(
            "sensor.detect_min_visible_fraction",
            s.detect_min_visible_fraction,
            0.0,
            1.0,
        );
        c.non_negative("sensor.pose_noise_m", s.pose_noise_m);
        c.non_negative("sensor.pose_noise_deg", s.pose_noise_deg);
        c.within("sensor.max_yaw_ambiguity_deg", s.max_yaw_ambiguity_deg, 0.0, 90.0);
        if s.position_m
            .iter()
            .chain(&s.look_at_m)
            .chain(&s.image_up)
            .all(|v| v.is_finite())
            && s.world_from_camera().is_none()
        {
            c.fail(
                "sensor.image_up",
                format!(
                    "must not be parallel to the view direction (position_m -> look_at_m), got {:?}",
                    s.image_up
                ),
            );
        }
    }

    /// `pick_tray` and `place_tray` (its slot pattern).
    fn check_trays(&self, c: &mut Checker) {
        check_tray(c, "pick_tray", &self.pick_tray);
        let p = &self.place_tray;
        check_tray(c, "place_tray.tray", &p.tray);
        c.positive("place_tray.tolerance_m", p.tolerance_m);
        c.within("place_tray.tolerance_deg", p.tolerance_deg, 1e-9, 180.0);
        match p.pattern {
            SlotPattern::Grid => {
                match p.gap_m {
                    Some(g) => c.non_negative("place_tray.gap_m", g),
                    None => c.fail("place_tray.gap_m", "is required when pattern = \"grid\""),
                }
                if let Some(y) = p.slot_yaw_deg {
                    c.finite("place_tray.slot_yaw_deg", y);
                }
                for (key, pitch) in [
                    ("place_tray.pitch_x_m", p.pitch_x_m),
                    ("place_tray.pitch_y_m", p.pitch_y_m),
                ] {
                    if let Some(v) = pitch {
                        c.positive(key, v);
                    }
                }
                if p.poses.is_some() {
                    c.fail("place_tray.poses", "is only allowed when pattern = \"list\"");
                }
            }
            SlotPattern::List if p.pitch_x_m.is_some() || p.pitch_y_m.is_some() => {
                c.fail("place_tray.pitch_x_m", "is only allowed when pattern = \"grid\"");
            }
            SlotPattern::List => match &p.poses {
                None => c.fail("place_tray.poses", "is required when pattern = \"list\""),
                Some(v) if v.is_empty() => c.fail("place_tray.poses", "must list at least one pose"),
                Some(v) => {
                    let [lx, ly] = p.tray.inner_size_m;
                    for (i, pose) in v.iter().enumerate() {
                        c.finite_all(&format!("place_tray.poses[{i}]"), pose);
                        if pose[0].abs() > lx / 2.0 || pose[1].abs() > ly / 2.0 {
                            c.fail(
                                &format!("place_tray.poses[{i}]"),
                                format!(
                                    "must lie inside the tray's inner floor (±{}, ±{}), got {:?}",
                                    lx / 2.0,
                                    ly / 2.0,
                                    pose
                                ),
                            );
                        }
                    }
                }
            },
        }
    }

    /// `table` and `obstacles`.
    fn check_fixtures(&self, c: &mut Checker) {
        let t = &self.table;
        c.finite("table.top_z_m", t.top_z_m);
        c.finite_all("table.center_xy_m", &t.center_xy_m);
        c.positive_all("table.size_m", &t.size_m);
        c.positive("table.thickness_m", t.thickness_m);
        for (i, o) in self.obstacles.iter().enumerate() {
            let k = format!("obstacles[{i}]");
            c.finite_all(&format!("{k}.center_m"), &o.center_m);
            c.positive_all(&format!("{k}.size_m"), &o.size_m);
            c.finite(&format!("{k}.yaw_deg"), o.yaw_deg);
        }
    }

    /// `compute`, `cycle`, `model_error`, `agitation`, and the cycle's leads against the gripper's times.
    fn check_cycle(&self, c: &mut Checker) {
        c.non_negative("compute.grasp_estimation_s", self.compute.grasp_estimation_s);
        c.non_negative("compute.motion_generation_s", self.compute.motion_generation_s);
        if self.cycle.empty_after_captures == 0 {
            c.fail("cycle.empty_after_captures", "must be at least 1, got 0".to_string());
        }
        c.non_negative("cycle.refill_s", self.cycle.refill_s);
        if !(1..=10).contains(&self.cycle.max_picks_per_capture) {
            c.fail(
                "cycle.max_picks_per_capture",
                format!("must be within [1, 10], got {}", self.cycle.max_picks_per_capture),
            );
        }
        if let Some(w) = &self.cycle.waiting_tool_m {
            c.finite_all("cycle.waiting_tool_m", w);
        }
        c.non_negative("cycle.place_tray_exchange_s", self.cycle.place_tray_exchange_s);
        c.non_negative("cycle.approach_above_rim_m", self.cycle.approach_above_rim_m);
        c.positive("cycle.line_speed_m_s", self.cycle.line_speed_m_s);
        c.positive("cycle.line_accel_m_s2", self.cycle.line_accel_m_s2);
        c.within(
            "cycle.wrist_deviation_max_deg",
            self.cycle.wrist_deviation_max_deg,
            0.0,
            10.0,
        );
        c.non_negative("cycle.vacuum_lead_s", self.cycle.vacuum_lead_s);
        c.non_negative("cycle.release_lead_s", self.cycle.release_lead_s);
        if let Some(h) = self.cycle.gentle_lift_hemmed {
            c.non_negative("cycle.gentle_lift_hemmed", h);
        }
        c.within("cycle.torque_margin", self.cycle.torque_margin, 0.0, 0.5);
        self.model_error.check(c);
        self.agitation.check(c);
        self.feeder.check(c);
        if self.cycle.vacuum_lead_s > self.gripper.vacuum_build_up_s {
            c.fail(
                "cycle.vacuum_lead_s",
                format!(
                    "must not exceed gripper.vacuum_build_up_s ({} s), got {}",
                    self.gripper.vacuum_build_up_s, self.cycle.vacuum_lead_s
                ),
            );
        }
        if self.cycle.release_lead_s > self.gripper.release_s {
            c.fail(
                "cycle.release_lead_s",
                format!(
                    "must not exceed gripper.release_s ({} s), got {}",
                    self.gripper.release_s, self.cycle.release_lead_s
                ),
            );
        }
    }

    /// `sim`.
    fn check_sim(&self, c: &mut Checker) {
        c.within("sim.physics_dt_s", self.sim.physics_dt_s, 1e-5, 0.02);
        c.within("sim.control_dt_s", self.sim.control_dt_s, 1e-5, 0.01);
        c.within("sim.servo_bandwidth_hz", self.sim.servo_bandwidth_hz, 0.1, 200.0);
        c.positive("sim.tracking_tolerance_deg", self.sim.tracking_tolerance_deg);
        c.positive("sim.saturation_trip_s", self.sim.saturation_trip_s);
        c.non_negative("sim.protective_stop_reset_s", self.sim.protective_stop_reset_s);
        c.within(
            "sim.deep_penetration_limit_m",
            self.sim.deep_penetration_limit_m,
            1e-6,
            0.01,
        );
        if self.sim.control_dt_s.is_finite()
            && self.sim.physics_dt_s.is_finite()
            && self.sim.control_dt_s > self.sim.physics_dt_s
        {
            c.fail(
                "sim.control_dt_s",
                format!(
                    "must be <= sim.physics_dt_s ({}), got {}",
                    self.sim.physics_dt_s, self.sim.control_dt_s
                ),
            );
        }
    }

    /// Layout checks that need only the scene: the sensor looks at the pick tray, the pick tray
    /// lies in the image and within range, trays stand on the table.
    fn check_layout(&self, c: &mut Checker) {
        self.check_view(c);
        for (key, t) in [
            ("pick_tray", &self.pick_tray),
            ("place_tray.tray", &self.place_tray.tray),
        ] {
            let bottom = t.center_m[2] - t.floor_thickness_m;
            if (bottom - self.table.top_z_m).abs() > 1e-3 {
                c.fail(
                    &format!("{key}.center_m[2]"),
                    format!(
                        "puts the tray bottom at z = {bottom:.4} m, not on the table top (table.top_z_m = {}); got {}",
                        self.table.top_z_m, t.center_m[2]
                    ),
                );
            }
        }
    }

    /// The sensor's view of the pick tray: its frustum over the tray (apex at the optical centre,
    /// base the tray's outer rim at floor level, as [`crate::sensor::ViewFrustum`] builds it) spans
    /// a pyramid, and the whole tray floor lies in the image and within range.
    fn check_view(&self, c: &mut Checker) {
        let Some(world_from_camera) = self.sensor.world_from_camera() else {
            return;
        };
        let camera_from_world = world_from_camera.inverse();
        let s = &self.sensor;
        let tray = &self.pick_tray;
        // A pyramid: near enough the origin for single-precision geometry, the camera well above the
        // rim plane (the tray frame is world z up), the base more than a point from the camera.
        let mut pyramid = true;
        for (key, p) in [
            ("sensor.position_m", s.position_m),
            ("pick_tray.center_m", tray.center_m),
        ] {
            if p.iter().any(|v| v.abs() > MAX_CELL_EXTENT_M) {
                c.fail(
                    key,
                    format!("must lie within {MAX_CELL_EXTENT_M} m of the world origin, got {p:?}"),
                );
                pyramid = false;
            }
        }
        let rim_z = tray.center_m[2] + tray.wall_height_m;
        if s.position_m[2] < rim_z + MIN_CAMERA_ABOVE_RIM_M {
            c.fail(
                "sensor.position_m",
                format!(
                    "must be at least {MIN_CAMERA_ABOVE_RIM_M} m above the pick tray's rim (z = {rim_z:.3} m) so its view over the tray spans a pyramid, got {:?}",
                    s.position_m
                ),
            );
            pyramid = false;
        }
        let outer = tray.inner_size_m.map(|l| l + 2.0 * tray.wall_thickness_m);
        let world_from_tray = tray.world_from_tray();
        let farthest_m = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|(sx, sy)| {
                let corner = world_from_tray * nalgebra::Point3::new(sx * outer[0] / 2.0, sy * outer[1] / 2.0, 0.0);
                (corner.coords - Vector3::from(s.position_m)).norm()
            })
            .fold(0.0, f64::max);
        let smallest_m = outer[0].min(outer[1]);
        if pyramid && smallest_m < MIN_VIEW_BASE_PER_DISTANCE * farthest_m {
            c.fail(
                "sensor.position_m",
                format!(
                    "is {farthest_m:.3} m from the pick tray's rim, more than {} times its width of {smallest_m:.3} m: the tray is a point in its view, which spans no pyramid; got {:?}",
                    1.0 / MIN_VIEW_BASE_PER_DISTANCE,
                    s.position_m
                ),
            );
            pyramid = false;
        }
        if !pyramid {
            return;
        }
        let [lx, ly] = tray.inner_size_m;
        let mut outside = Vec::new();
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let corner = world_from_tray * nalgebra::Point3::new(sx * lx / 2.0, sy * ly / 2.0, 0.0);
            let pc = camera_from_world * corner;
            let in_view = pc.z > 0.0 && {
                let u = s.focal_px[0] * pc.x / pc.z + s.principal_point_px[0];
                let v = s.focal_px[1] * pc.y / pc.z + s.principal_point_px[1];
                (0.0..=s.resolution_px[0] as f64).contains(&u) && (0.0..=s.resolution_px[1] as f64).contains(&v)
            };
            let range = pc.coords.norm();
            if !in_view || range < s.min_range_m || range > s.max_range_m {
                outside.push(format!("({:.3}, {:.3}, {:.3})", corner.x, corner.y, corner.z));
            }
        }
        if !outside.is_empty() {
            c.fail(
                "sensor",
                format!(
                    "does not see the whole pick tray floor within its image and range: corners {} are outside",
                    outside.join(", ")
                ),
            );
        }
    }
}
