//! The set-up per workpiece: the suction cup a workpiece file may bring, overriding the cell's for
//! that workpiece only (and the hopper recipe and shake it may bring,
//! [`crate::config::FeederRecipe`], [`crate::config::AgitationRecipe`], and the sensor's scan mode,
//! [`ScanMode`]).
//!
//! Job: the workpiece file's optional `[gripper]` and `[sensor]` sections ([`CupConfig`],
//! [`ScanMode`]), their checks, and the one resolution every stage reads: [`Scene::set_up_for`]
//! gives the cell with the workpiece's cup, recipes and scan mode in place of its own,
//! [`crate::config::LoadedScene::for_workpiece`] the same for a loaded cell.
//! A run resolves its cell once ([`crate::cycle::run`]); the grasp selector's cup fit, the
//! suction force model, the hand's collision model, the physics gripper, the recordings and the
//! resolved inputs written beside the run all read that resolved cell.
//!
//! The design (docs/formats.md, "The tool per workpiece"): one tool per workpiece, not a tool
//! changer with the grasp selector choosing. A cell runs one part type at a time and a real line
//! changes the cup with the product; a changer would add change time to the cycle and a second
//! decision (which cup) to the grasp selector, for a gain only mixed piles would see. What a cup
//! change changes is the cup's: its diameter, the flatness its lip tolerates, the tilt at which
//! it still seals, the roundest surface it seals on (a bellows cup's), and the time the vacuum
//! takes to build up in it and to vent. The tool body (its length, diameter, mass and inertia)
//! and the vacuum generator's level stay the cell's: a cup is screwed onto the same tool, so the
//! arm's model (flange to tool frame) is the same for every workpiece.
//!
//! Units: metres, seconds, degrees (as read; the cell's accessors convert). Frames: none.

use serde::{Deserialize, Serialize};

use super::{Checker, GripperConfig, MAX_LEAN_DEG, Scene, SensorConfig, Workpiece};

/// The cup a workpiece brings (`[gripper]` in a workpiece file): each key given replaces the
/// cell's `gripper.` key of the same name for this workpiece; a key left out keeps the cell's.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CupConfig {
    /// Suction cup outer diameter at the lip (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cup_diameter_m: Option<f64>,
    /// Flatness the cup lip tolerates across its diameter (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cup_flatness_tolerance_m: Option<f64>,
    /// Largest tilt of the approach from the face normal at which the cup still seals (deg).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_tilt_deg: Option<f64>,
    /// The largest lean of the tool from vertical at which a face is taken, approached along its
    /// normal beyond `max_tilt_deg` (deg); left out, the cell's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_lean_deg: Option<f64>,
    /// The smallest radius of a round surface this cup seals on (m) (a bellows cup's datasheet
    /// figure); left out, the cell's (which may be none: a cup for flat faces only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round_min_radius_m: Option<f64>,
    /// Time from valve open to full vacuum in this cup (s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vacuum_build_up_s: Option<f64>,
    /// Time from valve closed to part released from this cup (s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub release_s: Option<f64>,
}

impl CupConfig {
    /// Checks each key given, as the cell file's `gripper.` key of the same name is checked.
    pub fn check(&self, c: &mut Checker) {
        if let Some(v) = self.cup_diameter_m {
            c.positive("gripper.cup_diameter_m", v);
        }
        if let Some(v) = self.cup_flatness_tolerance_m {
            c.non_negative("gripper.cup_flatness_tolerance_m", v);
        }
        if let Some(v) = self.max_tilt_deg {
            c.within("gripper.max_tilt_deg", v, 0.0, 90.0);
        }
        if let Some(v) = self.max_lean_deg {
            c.within("gripper.max_lean_deg", v, 0.0, MAX_LEAN_DEG);
        }
        if let Some(v) = self.round_min_radius_m {
            c.positive("gripper.round_min_radius_m", v);
        }
        if let Some(v) = self.vacuum_build_up_s {
            c.non_negative("gripper.vacuum_build_up_s", v);
        }
        if let Some(v) = self.release_s {
            c.non_negative("gripper.release_s", v);
        }
    }

    /// This cup with every key the workpiece left out filled in from the cell's `gripper`: the
    /// tool the workpiece runs with, written in full beside a run.
    pub fn completed(&self, g: &GripperConfig) -> CupConfig {
        let r = g.with_cup(self);
        CupConfig {
            cup_diameter_m: Some(r.cup_diameter_m),
            cup_flatness_tolerance_m: Some(r.cup_flatness_tolerance_m),
            max_tilt_deg: Some(r.max_tilt_deg),
            max_lean_deg: r.max_lean_deg,
            round_min_radius_m: r.round_min_radius_m,
            vacuum_build_up_s: Some(r.vacuum_build_up_s),
            release_s: Some(r.release_s),
        }
    }
}

/// The sensor's scan mode a workpiece runs with (`[sensor]` in a workpiece file): the cell's
/// sensor at another of its resolutions, over the same field of view, as a structured-light
/// scanner's capture settings are chosen per product (a PhoXi M's 1032 x 772 or 2064 x 1544),
/// and the depth noise per pixel in that mode. Each key given replaces the cell's; the focal
/// lengths and principal point scale with the image; the rest (latency, exposure, range) stays
/// the cell's: docs/formats.md, "The scan mode per workpiece".
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScanMode {
    /// Image size, width and height (px): the same multiple of the cell's along both.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resolution_px: Option<[u32; 2]>,
    /// Depth noise standard deviation at 1 m range in this mode (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_noise_at_1m_m: Option<f64>,
}

/// How far a scan mode's two axes may scale the cell's image differently (px of its height).
pub const SCAN_MODE_ASPECT_TOL_PX: f64 = 1.0;

impl ScanMode {
    /// Checks the key on its own (the cell's check of the resolved sensor follows in
    /// [`Workpiece::check_fits_scene`]).
    pub fn check(&self, c: &mut Checker) {
        if let Some(v) = self.depth_noise_at_1m_m {
            c.non_negative("sensor.depth_noise_at_1m_m", v);
        }
        if let Some(r) = &self.resolution_px {
            c.resolution("sensor.resolution_px", r);
        }
    }

    /// The factor the mode scales the cell sensor `s`'s image by (its width's; 1 without a
    /// resolution of its own).
    pub fn scale(&self, s: &SensorConfig) -> f64 {
        self.resolution_px
            .map_or(1.0, |r| f64::from(r[0]) / f64::from(s.resolution_px[0].max(1)))
    }

    /// Whether the mode keeps `s`'s field of view: its height scaled as its width, within
    /// [`SCAN_MODE_ASPECT_TOL_PX`].
    pub fn keeps_field_of_view(&self, s: &SensorConfig) -> bool {
        self.resolution_px.is_none_or(|r| {
            (f64::from(s.resolution_px[1]) * self.scale(s) - f64::from(r[1])).abs() <= SCAN_MODE_ASPECT_TOL_PX
        })
    }
}

impl SensorConfig {
    /// The sensor in scan mode `mode`: its resolution, the focal lengths and principal point
    /// scaled with it (pixel centres at half-integers: the optical axis stays where it is).
    pub fn with_mode(&self, mode: &ScanMode) -> SensorConfig {
        let k = mode.scale(self);
        SensorConfig {
            resolution_px: mode.resolution_px.unwrap_or(self.resolution_px),
            focal_px: self.focal_px.map(|f| f * k),
            principal_point_px: self.principal_point_px.map(|p| p * k),
            depth_noise_at_1m_m: mode.depth_noise_at_1m_m.unwrap_or(self.depth_noise_at_1m_m),
            ..self.clone()
        }
    }
}

impl super::LoadedWorkpiece {
    /// The workpiece as written beside a run in `cell`: a cup and a hopper recipe it brings with
    /// every key filled in from the cell's ([`CupConfig::completed`],
    /// [`super::FeederRecipe::completed`]); unchanged where it brings none.
    pub fn with_set_up_completed(&self, cell: &Scene) -> super::LoadedWorkpiece {
        let mut w = self.clone();
        if let Some(cup) = &mut w.workpiece.gripper {
            *cup = cup.completed(&cell.gripper);
        }
        if let Some(recipe) = &mut w.workpiece.feeder {
            *recipe = recipe.completed(&cell.feeder);
        }
        w
    }
}

impl GripperConfig {
    /// The gripper with `cup`'s keys in place of its own.
    pub fn with_cup(&self, cup: &CupConfig) -> GripperConfig {
        GripperConfig {
            cup_diameter_m: cup.cup_diameter_m.unwrap_or(self.cup_diameter_m),
            cup_flatness_tolerance_m: cup.cup_flatness_tolerance_m.unwrap_or(self.cup_flatness_tolerance_m),
            max_tilt_deg: cup.max_tilt_deg.unwrap_or(self.max_tilt_deg),
            max_lean_deg: cup.max_lean_deg.or(self.max_lean_deg),
            round_min_radius_m: cup.round_min_radius_m.or(self.round_min_radius_m),
            vacuum_build_up_s: cup.vacuum_build_up_s.unwrap_or(self.vacuum_build_up_s),
            release_s: cup.release_s.unwrap_or(self.release_s),
            ..self.clone()
        }
    }
}

impl Scene {
    /// The cell as it runs workpiece `w`: with `w`'s cup and hopper recipe, where it brings
    /// them, in place of the cell's (the same cell otherwise). Applying it twice gives the same
    /// cell.
    pub fn set_up_for(&self, w: &Workpiece) -> Scene {
        let mut s = self.clone();
        if let Some(cup) = &w.gripper {
            s.gripper = self.gripper.with_cup(cup);
        }
        if let Some(recipe) = &w.feeder {
            s.feeder = self.feeder.with_recipe(recipe);
        }
        if let Some(shake) = &w.agitation {
            s.agitation = self.agitation.with_recipe(shake);
        }
        if let Some(mode) = &w.sensor {
            s.sensor = self.sensor.with_mode(mode);
        }
        s
    }

    /// Whether this cell is already set up for `w` (it was resolved for `w`, or `w` brings
    /// neither a cup nor a hopper recipe).
    pub fn is_set_up_for(&self, w: &Workpiece) -> bool {
        w.gripper
            .as_ref()
            .is_none_or(|cup| self.gripper.with_cup(cup) == self.gripper)
            && w.feeder
                .as_ref()
                .is_none_or(|r| self.feeder.with_recipe(r) == self.feeder)
            && w.agitation
                .as_ref()
                .is_none_or(|r| self.agitation.with_recipe(r) == self.agitation)
            && w.sensor.is_none_or(|m| self.sensor.with_mode(&m) == self.sensor)
    }
}

#[cfg(test)]
mod tests {
    use crate::config::{LoadedScene, LoadedWorkpiece, parse_toml};

    /// B's file without the cup it brings, with `section` appended.
    fn b_with(section: &str) -> Result<LoadedWorkpiece, crate::config::ConfigError> {
        let b = crate::config::embedded::WORKPIECES[1].1;
        let own = b
            .find("[gripper]")
            .map_or(b.len(), |i| b[..i].rfind("\n\n").map_or(i, |j| j + 1));
        let text = format!("{}\n{section}", &b[..own]);
        LoadedWorkpiece::from_text("B.toml", crate::config::Source::Embedded, &text)
    }

    #[test]
    fn a_workpiece_cup_overrides_the_cells_for_that_workpiece_only() {
        let cell = LoadedScene::embedded_default().unwrap();
        let b = b_with("[gripper]\ncup_diameter_m = 0.016\nmax_tilt_deg = 15.0\n").unwrap();
        let s = cell.scene.set_up_for(&b.workpiece);
        assert_eq!(s.gripper.cup_diameter_m, 0.016);
        assert_eq!(s.gripper.max_tilt_deg, 15.0);
        // The rest of the tool is the cell's, and so is the rest of the cell.
        assert_eq!(s.gripper.tool_length_m, cell.scene.gripper.tool_length_m);
        assert_eq!(s.gripper.vacuum_kpa, cell.scene.gripper.vacuum_kpa);
        assert_eq!(s.gripper.release_s, cell.scene.gripper.release_s);
        assert_eq!(s.sensor, cell.scene.sensor);
        assert_eq!(s.set_up_for(&b.workpiece), s, "resolving twice changes nothing");
        assert!(s.is_set_up_for(&b.workpiece));
        // Negative control: the cell itself does not carry B's cup. C brings only its shake; the
        // TO-220's file brings nothing.
        assert!(!cell.scene.is_set_up_for(&b.workpiece));
        let c = LoadedWorkpiece::resolve("C").unwrap();
        let for_c = cell.scene.set_up_for(&c.workpiece);
        assert_eq!(for_c.gripper, cell.scene.gripper);
        assert_ne!(for_c.agitation, cell.scene.agitation);
        let to220 = LoadedWorkpiece::resolve("workpieces/to220.toml").unwrap();
        assert_eq!(cell.scene.set_up_for(&to220.workpiece), cell.scene);
        assert!(cell.scene.is_set_up_for(&to220.workpiece));
    }

    #[test]
    fn a_workpiece_cup_is_strict_and_checked_naming_file_key_and_value() {
        let e = b_with("[gripper]\ncup_diameter_m = -0.01\n").unwrap_err().to_string();
        assert_eq!(e, "B.toml: gripper.cup_diameter_m must be > 0, got -0.01");
        let e = b_with("[gripper]\nmax_tilt_deg = 95.0\n").unwrap_err().to_string();
        assert!(e.contains("gripper.max_tilt_deg must be within [0, 90], got 95"), "{e}");
        // The tool body is the cell's: a workpiece cannot bring one.
        let e = b_with("[gripper]\ntool_length_m = 0.2\n").unwrap_err().to_string();
        assert!(e.contains("gripper") && e.contains("tool_length_m"), "{e}");
        // A cup whose release is shorter than the cell's release lead is refused against the cell.
        let cell = LoadedScene::embedded_default().unwrap();
        let b = b_with("[gripper]\nrelease_s = 0.01\n").unwrap();
        let e = b
            .workpiece
            .check_fits_scene("B.toml", &cell.scene)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("B.toml: cycle.release_lead_s must not exceed gripper.release_s (0.01 s)")
                && e.ends_with("(with this workpiece's gripper)"),
            "{e}"
        );
        // Of the six built-in workpieces A, B, D, E and F bring their cups (the default cell,
        // docs/studies.md); every file round-trips, with its cup or without one, and D's keeps
        // the roundest surface its bellows cup seals on.
        for w in LoadedWorkpiece::all_embedded().unwrap() {
            let brings = ["A", "B", "D", "E", "F"].contains(&w.workpiece.name.as_str());
            let round = w.workpiece.gripper.as_ref().and_then(|g| g.round_min_radius_m);
            assert_eq!(round.is_some(), w.workpiece.name == "D", "{}", w.workpiece.name);
            assert_eq!(w.workpiece.gripper.is_some(), brings, "{}", w.workpiece.name);
            let text = toml::to_string(&w.workpiece).unwrap();
            assert_eq!(text.contains("[gripper]"), brings, "{text}");
            assert_eq!(text.contains("round_min_radius_m"), round.is_some(), "{text}");
            let back: crate::config::Workpiece = parse_toml("w", &text).unwrap();
            assert_eq!(back, w.workpiece);
        }
    }

    #[test]
    fn the_lean_and_the_image_size_are_bounded_alike_in_the_cell_and_the_workpiece_file() {
        let mut cell = LoadedScene::embedded_default().unwrap().scene;
        // At the lean's bound, and a valid image: accepted, in both files.
        cell.gripper.max_lean_deg = Some(60.0);
        cell.validate("s.toml").unwrap();
        b_with("[gripper]\nmax_lean_deg = 60.0\n\n[sensor]\nresolution_px = [2064, 1544]\n").unwrap();
        // Beyond them: refused, naming the file, the key and the value.
        cell.gripper.max_lean_deg = Some(61.0);
        cell.sensor.resolution_px = [0, 772];
        let e = cell.validate("s.toml").unwrap_err().to_string();
        assert!(e.contains("gripper.max_lean_deg must be within [0, 60], got 61"), "{e}");
        assert!(
            e.contains("sensor.resolution_px[0] must be within [1, 8192], got 0"),
            "{e}"
        );
        let e = b_with("[gripper]\nmax_lean_deg = 61.0\n").unwrap_err().to_string();
        assert_eq!(e, "B.toml: gripper.max_lean_deg must be within [0, 60], got 61");
        let e = b_with("[sensor]\nresolution_px = [1032, 9000]\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("B.toml: sensor.resolution_px[1] must be within [1, 8192], got 9000"),
            "{e}"
        );
    }

    #[test]
    fn a_scan_mode_scales_the_image_and_keeps_the_field_of_view() {
        let cell = LoadedScene::embedded_default().unwrap();
        let e = LoadedWorkpiece::from_text(
            "E.toml",
            crate::config::Source::Embedded,
            &format!(
                "{}\n[sensor]\nresolution_px = [2064, 1544]\n",
                crate::config::embedded::WORKPIECES[4].1
            ),
        )
        .unwrap();
        let (base, s) = (&cell.scene.sensor, cell.scene.set_up_for(&e.workpiece));
        assert_eq!(s.sensor.resolution_px, [2064, 1544]);
        assert_eq!(s.sensor.focal_px, base.focal_px.map(|f| 2.0 * f));
        assert_eq!(s.sensor.principal_point_px, base.principal_point_px.map(|p| 2.0 * p));
        // The same rays through the same image points: a pixel's edge-to-edge angle halves.
        let angle = |c: &crate::config::SensorConfig, u: f64| ((u - c.principal_point_px[0]) / c.focal_px[0]).atan();
        for u in [0.0, 100.0, 1032.0] {
            assert!((angle(base, u) - angle(&s.sensor, 2.0 * u)).abs() < 1e-12);
        }
        assert_eq!(s.set_up_for(&e.workpiece), s, "resolving twice changes nothing");
        assert!(s.is_set_up_for(&e.workpiece));
        // Negative control: the cell itself does not run E's scan mode.
        assert!(!cell.scene.is_set_up_for(&e.workpiece));
    }
}
