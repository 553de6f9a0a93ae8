//! Cell configuration: the scene (cell) file and the workpiece files.
//!
//! Job: parse the strict TOML formats, validate every value, and report each problem with the
//! file, the key path and the bad value (`workpieces/C.toml: size_m[2] must be > 0, got -0.005`).
//!
//! Units: every key carries its unit in its name (`_m`, `_s`, `_kg`, `_deg`, `_nm`, ...). Degrees
//! exist only here, at the file boundary; the accessors that the rest of the crate uses return SI
//! values (radians, metres, seconds). Frames: positions and orientations in the scene file are in
//! the world frame (z up, the table top at `table.top_z_m`), except where a key says otherwise
//! (`gripper.com_m` is in the flange frame, slot poses in the place tray's frame).
//!
//! The default cell and the six workpieces are embedded in the binary ([`embedded`]), so the
//! main job runs from any directory; a path given on the command line is read from disk instead.

use std::fmt;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// One problem found in an input file: which file, which key, what is wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// The file as the user named it (or `embedded:NAME` for built-in files).
    pub file: String,
    /// Dotted key path with indices, e.g. `robot.drives.armature_kg_m2[2]`; empty for whole-file problems.
    pub key: String,
    /// What is wrong, including the bad value.
    pub message: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.key.is_empty() {
            write!(f, "{}: {}", self.file, self.message)
        } else {
            write!(f, "{}: {} {}", self.file, self.key, self.message)
        }
    }
}

/// Every problem found in a set of input files. Display prints one line per problem.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct ConfigError {
    /// The problems, in the order they were found.
    pub problems: Vec<Problem>,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, p) in self.problems.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{p}")?;
        }
        Ok(())
    }
}

impl ConfigError {
    /// A single problem as an error.
    pub fn one(file: &str, key: &str, message: impl Into<String>) -> Self {
        ConfigError {
            problems: vec![Problem {
                file: file.to_string(),
                key: key.to_string(),
                message: message.into(),
            }],
        }
    }
}

/// Accumulates problems for one file while validating.
#[derive(Debug)]
pub struct Checker {
    file: String,
    /// Problems found so far.
    pub problems: Vec<Problem>,
}

impl Checker {
    /// A checker for the file labelled `file`.
    pub fn new(file: &str) -> Self {
        Checker {
            file: file.to_string(),
            problems: Vec::new(),
        }
    }

    /// Records a problem at `key`.
    pub fn fail(&mut self, key: &str, message: impl Into<String>) {
        self.problems.push(Problem {
            file: self.file.clone(),
            key: key.to_string(),
            message: message.into(),
        });
    }

    /// `value` must be finite; returns whether it is.
    pub fn finite(&mut self, key: &str, value: f64) -> bool {
        if value.is_finite() {
            true
        } else {
            self.fail(key, format!("must be a finite number, got {value}"));
            false
        }
    }

    /// `value` must be finite and > 0.
    pub fn positive(&mut self, key: &str, value: f64) {
        if self.finite(key, value) && value <= 0.0 {
            self.fail(key, format!("must be > 0, got {value}"));
        }
    }

    /// `value` must be finite and >= 0.
    pub fn non_negative(&mut self, key: &str, value: f64) {
        if self.finite(key, value) && value < 0.0 {
            self.fail(key, format!("must be >= 0, got {value}"));
        }
    }

    /// `value` must be finite and within `[lo, hi]`.
    pub fn within(&mut self, key: &str, value: f64, lo: f64, hi: f64) {
        if self.finite(key, value) && !(lo..=hi).contains(&value) {
            self.fail(key, format!("must be within [{lo}, {hi}], got {value}"));
        }
    }

    /// Every element finite.
    pub fn finite_all(&mut self, key: &str, values: &[f64]) {
        for (i, v) in values.iter().enumerate() {
            self.finite(&format!("{key}[{i}]"), *v);
        }
    }

    /// Every element finite and > 0.
    pub fn positive_all(&mut self, key: &str, values: &[f64]) {
        for (i, v) in values.iter().enumerate() {
            self.positive(&format!("{key}[{i}]"), *v);
        }
    }

    /// Every element finite and >= 0.
    pub fn non_negative_all(&mut self, key: &str, values: &[f64]) {
        for (i, v) in values.iter().enumerate() {
            self.non_negative(&format!("{key}[{i}]"), *v);
        }
    }

    /// Turns the accumulated problems into a result.
    pub fn finish(self) -> Result<(), ConfigError> {
        if self.problems.is_empty() {
            Ok(())
        } else {
            Err(ConfigError {
                problems: self.problems,
            })
        }
    }
}

/// Parses strict TOML into `T`, reporting the key path, line and column of a bad or unknown key.
pub fn parse_toml<T: serde::de::DeserializeOwned>(file: &str, text: &str) -> Result<T, ConfigError> {
    let located = |span: Option<std::ops::Range<usize>>| -> String {
        match span {
            Some(s) => {
                let before = &text[..s.start.min(text.len())];
                let line = before.matches('\n').count() + 1;
                let col = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
                format!(" (line {line}, column {col})")
            }
            None => String::new(),
        }
    };
    let de = toml::de::Deserializer::parse(text).map_err(|e| {
        ConfigError::one(
            file,
            "",
            format!("malformed TOML: {}{}", e.message().trim(), located(e.span())),
        )
    })?;
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let key = if path == "." { String::new() } else { path };
        let inner = e.into_inner();
        ConfigError::one(
            file,
            &key,
            format!("{}{}", inner.message().trim(), located(inner.span())),
        )
    })
}

/// Where a scene came from, to resolve the paths inside it.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// Built into the binary.
    Embedded,
    /// Read from this file; relative paths inside resolve against its folder.
    File(PathBuf),
}

/// Files built into the binary: the default cell, its robot and the six workpieces.
pub mod embedded {
    /// The default cell file (`scenes/default.toml`).
    pub const DEFAULT_SCENE: &str = include_str!("../scenes/default.toml");
    /// The Viper s650 URDF (`scenes/viper_s650.urdf`).
    pub const VIPER_S650_URDF: &str = include_str!("../scenes/viper_s650.urdf");
    /// The six workpieces of the reference system's takt table, by name.
    pub const WORKPIECES: [(&str, &str); 6] = [
        ("A", include_str!("../workpieces/A.toml")),
        ("B", include_str!("../workpieces/B.toml")),
        ("C", include_str!("../workpieces/C.toml")),
        ("D", include_str!("../workpieces/D.toml")),
        ("E", include_str!("../workpieces/E.toml")),
        ("F", include_str!("../workpieces/F.toml")),
    ];

    /// An embedded file that a scene may refer to by its bare name.
    pub fn file(name: &str) -> Option<&'static str> {
        match name {
            "viper_s650.urdf" => Some(VIPER_S650_URDF),
            _ => None,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Scene file
// ---------------------------------------------------------------------------------------------

/// A cell: robot, gripper, sensor, trays, obstacles, compute budgets and rates.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Short name of the cell.
    pub name: String,
    /// Free text: what this cell is.
    #[serde(default)]
    pub description: String,
    /// The arm.
    pub robot: RobotConfig,
    /// The hand on the flange.
    pub gripper: GripperConfig,
    /// The fixed overhead 3D sensor.
    pub sensor: SensorConfig,
    /// The tray the parts are piled in.
    pub pick_tray: TrayConfig,
    /// The tray the parts are placed into, with its placement poses.
    pub place_tray: PlaceTrayConfig,
    /// The table everything stands on.
    pub table: TableConfig,
    /// Further box obstacles (sensor stand, guards, ...).
    #[serde(default)]
    pub obstacles: Vec<ObstacleConfig>,
    /// Compute budgets charged to the simulation clock in deterministic mode.
    pub compute: ComputeConfig,
    /// What the cycle does when the pick tray runs empty, and how faults are handled.
    pub cycle: CycleConfig,
    /// Simulation and control rates.
    pub sim: SimConfig,
}

/// The arm: its URDF, where it stands, and the drive data a URDF cannot hold.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// URDF path, relative to the scene file's folder.
    pub urdf: String,
    /// The URDF link whose frame is the flange (tool mounting face).
    pub flange_link: String,
    /// Base position in the world [m].
    pub world_from_base_xyz_m: [f64; 3],
    /// Base orientation in the world, roll-pitch-yaw (fixed axes x, y, z) [deg].
    pub world_from_base_rpy_deg: [f64; 3],
    /// A parking configuration clear of trays and sensor view [deg].
    pub home_deg: [f64; 6],
    /// Drive data per joint.
    pub drives: DrivesConfig,
}

/// Per-joint drive data: what the URDF cannot hold.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DrivesConfig {
    /// Reflected rotor inertia per joint [kg m^2].
    pub armature_kg_m2: [f64; 6],
    /// Coulomb friction per joint (joint side) [N m].
    pub coulomb_friction_nm: [f64; 6],
    /// Viscous friction per joint [N m s/rad].
    pub viscous_friction_nm_s_per_rad: [f64; 6],
    /// Coulomb friction is smoothed as tanh(qd / this) [deg/s].
    pub coulomb_smoothing_deg_s: f64,
    /// Specification (maximum) joint acceleration per joint [deg/s^2].
    pub max_accel_deg_s2: [f64; 6],
    /// Overrides the URDF effort limits when present [N m].
    #[serde(default)]
    pub torque_limit_nm: Option<[f64; 6]>,
}

/// Kinds of hand.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum GripperKind {
    /// A single suction cup at the tool tip.
    Suction,
}

/// The hand: a suction tool on the flange.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GripperConfig {
    /// Kind of hand.
    pub kind: GripperKind,
    /// Distance from the flange face to the cup lip along the flange z axis [m] (the tool frame).
    pub tool_length_m: f64,
    /// Diameter of the tool body (for collision) [m].
    pub body_diameter_m: f64,
    /// Suction cup outer diameter at the lip [m].
    pub cup_diameter_m: f64,
    /// Flatness the cup lip tolerates across its diameter [m].
    pub cup_flatness_tolerance_m: f64,
    /// Largest tilt of the approach from the face normal at which the cup still seals [deg].
    pub max_tilt_deg: f64,
    /// Vacuum level once sealed (below ambient) [kPa].
    pub vacuum_kpa: f64,
    /// Time from valve open to full vacuum [s].
    pub vacuum_build_up_s: f64,
    /// Time from valve closed to part released [s].
    pub release_s: f64,
    /// Hand mass [kg].
    pub mass_kg: f64,
    /// Hand centre of mass in the flange frame [m].
    pub com_m: [f64; 3],
    /// Hand principal moments of inertia about its centre of mass, axes along the flange frame [kg m^2].
    pub inertia_kg_m2: [f64; 3],
}

/// The fixed overhead 3D sensor (pinhole; optical frame x right, y down, z along the view).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SensorConfig {
    /// Optical centre in the world [m].
    pub position_m: [f64; 3],
    /// A world point on the optical axis [m].
    pub look_at_m: [f64; 3],
    /// World direction that appears toward the top of the image (must not be parallel to the view).
    pub image_up: [f64; 3],
    /// Image size, width and height [px].
    pub resolution_px: [u32; 2],
    /// Focal lengths fx, fy [px].
    pub focal_px: [f64; 2],
    /// Principal point cx, cy [px].
    pub principal_point_px: [f64; 2],
    /// Nearest measurable range [m].
    pub min_range_m: f64,
    /// Farthest measurable range [m].
    pub max_range_m: f64,
    /// From trigger to recognition result available [s] (1.1 s in the reference system).
    pub latency_s: f64,
    /// Exposure window during which the scene must be still and the arm out of view [s].
    pub exposure_s: f64,
    /// Depth noise standard deviation at 1 m range; grows with range squared [m].
    pub depth_noise_at_1m_m: f64,
    /// Surfaces seen more obliquely than this return nothing [deg].
    pub dropout_grazing_deg: f64,
    /// Probability that a valid pixel drops out anyway.
    pub dropout_probability: f64,
    /// Recognition: a part counts as detected when at least this fraction of its camera-facing surface is visible.
    pub detect_min_visible_fraction: f64,
    /// Recognition pose noise, position standard deviation [m].
    pub pose_noise_m: f64,
    /// Recognition pose noise, rotation standard deviation [deg].
    pub pose_noise_deg: f64,
}

/// A tray: a floor and four walls. Its frame: origin at the centre of the inner floor surface,
/// z up, x along `inner_size_m[0]`, rotated by `yaw_deg` about world z.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrayConfig {
    /// Centre of the inner floor surface in the world [m].
    pub center_m: [f64; 3],
    /// Rotation about world z [deg].
    pub yaw_deg: f64,
    /// Inner length and width [m].
    pub inner_size_m: [f64; 2],
    /// Wall height above the inner floor [m].
    pub wall_height_m: f64,
    /// Wall thickness [m].
    pub wall_thickness_m: f64,
    /// Floor thickness [m].
    pub floor_thickness_m: f64,
}

/// How placement poses are laid out in the place tray.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum SlotPattern {
    /// A grid computed from the workpiece footprint, `gap_m` apart, filling the tray.
    Grid,
    /// The explicit list `poses`.
    List,
}

/// The place tray and its placement poses.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlaceTrayConfig {
    /// The tray itself.
    pub tray: TrayConfig,
    /// Grid or list.
    pub pattern: SlotPattern,
    /// Grid: clearance between neighbouring parts and to the walls [m].
    #[serde(default)]
    pub gap_m: Option<f64>,
    /// Grid: yaw of every placed part in the tray frame [deg].
    #[serde(default)]
    pub slot_yaw_deg: Option<f64>,
    /// List: placement poses in the tray frame, each `[x_m, y_m, yaw_deg]`.
    #[serde(default)]
    pub poses: Option<Vec<[f64; 3]>>,
}

/// The table top: a box whose upper face is at `top_z_m`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TableConfig {
    /// Height of the table top in the world [m].
    pub top_z_m: f64,
    /// Centre of the table top in x, y [m].
    pub center_xy_m: [f64; 2],
    /// Table top length and width [m].
    pub size_m: [f64; 2],
    /// Table top thickness [m].
    pub thickness_m: f64,
}

/// A box obstacle.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ObstacleConfig {
    /// What it is.
    pub name: String,
    /// Box centre in the world [m].
    pub center_m: [f64; 3],
    /// Box edge lengths [m].
    pub size_m: [f64; 3],
    /// Rotation about world z [deg].
    #[serde(default)]
    pub yaw_deg: f64,
}

/// Compute budgets (the reference system's figures), charged in deterministic mode.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ComputeConfig {
    /// Grasp estimation per capture [s] (reference: 0.050).
    pub grasp_estimation_s: f64,
    /// Motion generation per motion, planning and acceleration [s] (reference: 0.100).
    pub motion_generation_s: f64,
}

/// What to do when nothing graspable is left in the pick tray.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum OnEmpty {
    /// Exchange the pick tray for a full one (a new pile) and go on.
    Refill,
    /// End the run.
    End,
}

/// Cycle policies.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CycleConfig {
    /// Captures in a row with nothing graspable after which the tray counts as empty.
    pub empty_after_captures: u32,
    /// What to do then.
    pub on_empty: OnEmpty,
    /// Time to exchange the pick tray for a full one [s] (the arm waits).
    pub refill_s: f64,
    /// The place tray is exchanged for an empty one when its slots are used up, outside the
    /// arm's cycle (a conveyor) [s of arm time: 0 when buffered].
    pub place_tray_exchange_s: f64,
    /// Height of the Pick's approach pose (where the straight descent starts) above the pick
    /// tray's rim [m].
    pub approach_above_rim_m: f64,
    /// Top tool speed of the straight descents, lifts and retreats [m/s].
    pub line_speed_m_s: f64,
    /// Tool acceleration of the straight lines before the torque and suction checks [m/s^2].
    pub line_accel_m_s2: f64,
    /// The vacuum is switched on this long before the descent ends, so it builds up while the
    /// cup closes the last millimetres [s] (0: at contact).
    pub vacuum_lead_s: f64,
}

/// Simulation and control rates.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Physics (rapier) timestep [s].
    pub physics_dt_s: f64,
    /// Joint servo period [s].
    pub control_dt_s: f64,
    /// Closed-loop bandwidth of the joint servo's PD feedback [Hz].
    pub servo_bandwidth_hz: f64,
    /// Tracking error beyond which the controller trips a protective stop [deg].
    pub tracking_tolerance_deg: f64,
    /// Torque saturation lasting longer than this trips a protective stop [s].
    pub saturation_trip_s: f64,
    /// Time to reset after a protective stop before the cycle resumes [s].
    pub protective_stop_reset_s: f64,
}

fn deg(v: f64) -> f64 {
    v.to_radians()
}

/// World pose from a translation and roll-pitch-yaw in radians (fixed axes x, y, z).
pub fn pose_from_xyz_rpy(xyz: [f64; 3], rpy_rad: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy_rad[0], rpy_rad[1], rpy_rad[2]),
    )
}

impl RobotConfig {
    /// `world_from_base` as an isometry.
    pub fn world_from_base(&self) -> Isometry3<f64> {
        let r = self.world_from_base_rpy_deg;
        pose_from_xyz_rpy(self.world_from_base_xyz_m, [deg(r[0]), deg(r[1]), deg(r[2])])
    }

    /// Home configuration [rad].
    pub fn home_rad(&self) -> [f64; 6] {
        self.home_deg.map(deg)
    }
}

impl DrivesConfig {
    /// Specification acceleration per joint [rad/s^2].
    pub fn max_accel_rad_s2(&self) -> [f64; 6] {
        self.max_accel_deg_s2.map(deg)
    }
}

impl GripperConfig {
    /// `flange_from_tool`: the tool frame sits `tool_length_m` along the flange z axis, same orientation.
    pub fn flange_from_tool(&self) -> Isometry3<f64> {
        Isometry3::translation(0.0, 0.0, self.tool_length_m)
    }
}

impl TrayConfig {
    /// `world_from_tray`: origin at the centre of the inner floor surface.
    pub fn world_from_tray(&self) -> Isometry3<f64> {
        pose_from_xyz_rpy(self.center_m, [0.0, 0.0, deg(self.yaw_deg)])
    }
}

impl SensorConfig {
    /// `world_from_camera` with the optical frame convention (x right, y down, z along the view).
    /// `None` when the view direction is degenerate or parallel to `image_up`.
    pub fn world_from_camera(&self) -> Option<Isometry3<f64>> {
        let p = Vector3::from(self.position_m);
        let z = Vector3::from(self.look_at_m) - p;
        let z = z.try_normalize(1e-9)?;
        let up = Vector3::from(self.image_up);
        // Image y points down, i.e. opposite to `up` projected onto the image plane.
        let y = -(up - z * up.dot(&z));
        let y = y.try_normalize(1e-6)?;
        let x = y.cross(&z);
        let rot = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[x, y, z]));
        Some(Isometry3::from_parts(
            Translation3::from(p),
            UnitQuaternion::from_rotation_matrix(&rot),
        ))
    }
}

impl PlaceTrayConfig {
    /// Placement poses in the tray frame, `(x_m, y_m, yaw_rad)`, for a part with the given
    /// footprint `[length_m, width_m]` (along the slot's own x and y).
    pub fn slots_in_tray(&self, footprint_m: [f64; 2]) -> Vec<(f64, f64, f64)> {
        match self.pattern {
            SlotPattern::List => self.poses.iter().flatten().map(|p| (p[0], p[1], deg(p[2]))).collect(),
            SlotPattern::Grid => {
                let gap = self.gap_m.unwrap_or(0.0);
                let yaw = deg(self.slot_yaw_deg.unwrap_or(0.0));
                // Footprint of the part rotated by yaw, as an axis-aligned box in the tray frame.
                let (c, s) = (yaw.cos().abs(), yaw.sin().abs());
                let fx = footprint_m[0] * c + footprint_m[1] * s;
                let fy = footprint_m[0] * s + footprint_m[1] * c;
                let [lx, ly] = self.tray.inner_size_m;
                let nx = ((lx - gap) / (fx + gap)).floor().max(0.0) as usize;
                let ny = ((ly - gap) / (fy + gap)).floor().max(0.0) as usize;
                let mut out = Vec::with_capacity(nx * ny);
                for j in 0..ny {
                    for i in 0..nx {
                        let x = (i as f64 - (nx as f64 - 1.0) / 2.0) * (fx + gap);
                        let y = (j as f64 - (ny as f64 - 1.0) / 2.0) * (fy + gap);
                        out.push((x, y, yaw));
                    }
                }
                out
            }
        }
    }
}

impl Scene {
    /// Where each placed part should end up: `world_from_part` per slot, the part lying on its
    /// -z face on the place tray floor, turned by the slot's yaw plus the part's `place_yaw_deg`.
    pub fn world_from_slots(&self, w: &Workpiece) -> Vec<Isometry3<f64>> {
        let world_from_tray = self.place_tray.tray.world_from_tray();
        let place_yaw = deg(w.grasp.place_yaw_deg);
        self.place_tray
            .slots_in_tray([w.size_m[0], w.size_m[1]])
            .into_iter()
            .map(|(x, y, yaw)| {
                world_from_tray
                    * Isometry3::from_parts(
                        Translation3::new(x, y, w.size_m[2] / 2.0),
                        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw + place_yaw),
                    )
            })
            .collect()
    }
}

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

        let g = &self.gripper;
        c.positive("gripper.tool_length_m", g.tool_length_m);
        c.positive("gripper.body_diameter_m", g.body_diameter_m);
        c.positive("gripper.cup_diameter_m", g.cup_diameter_m);
        c.non_negative("gripper.cup_flatness_tolerance_m", g.cup_flatness_tolerance_m);
        c.within("gripper.max_tilt_deg", g.max_tilt_deg, 0.0, 90.0);
        c.within("gripper.vacuum_kpa", g.vacuum_kpa, 0.0, 101.325);
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

        let s = &self.sensor;
        c.finite_all("sensor.position_m", &s.position_m);
        c.finite_all("sensor.look_at_m", &s.look_at_m);
        c.finite_all("sensor.image_up", &s.image_up);
        for (i, v) in s.resolution_px.iter().enumerate() {
            if !(1..=8192).contains(v) {
                c.fail(
                    &format!("sensor.resolution_px[{i}]"),
                    format!("must be within [1, 8192], got {v}"),
                );
            }
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

        check_tray(&mut c, "pick_tray", &self.pick_tray);
        let p = &self.place_tray;
        check_tray(&mut c, "place_tray.tray", &p.tray);
        match p.pattern {
            SlotPattern::Grid => {
                match p.gap_m {
                    Some(g) => c.non_negative("place_tray.gap_m", g),
                    None => c.fail("place_tray.gap_m", "is required when pattern = \"grid\""),
                }
                if let Some(y) = p.slot_yaw_deg {
                    c.finite("place_tray.slot_yaw_deg", y);
                }
                if p.poses.is_some() {
                    c.fail("place_tray.poses", "is only allowed when pattern = \"list\"");
                }
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
        c.non_negative("compute.grasp_estimation_s", self.compute.grasp_estimation_s);
        c.non_negative("compute.motion_generation_s", self.compute.motion_generation_s);
        if self.cycle.empty_after_captures == 0 {
            c.fail("cycle.empty_after_captures", "must be at least 1, got 0".to_string());
        }
        c.non_negative("cycle.refill_s", self.cycle.refill_s);
        c.non_negative("cycle.place_tray_exchange_s", self.cycle.place_tray_exchange_s);
        c.non_negative("cycle.approach_above_rim_m", self.cycle.approach_above_rim_m);
        c.positive("cycle.line_speed_m_s", self.cycle.line_speed_m_s);
        c.positive("cycle.line_accel_m_s2", self.cycle.line_accel_m_s2);
        c.non_negative("cycle.vacuum_lead_s", self.cycle.vacuum_lead_s);
        if self.cycle.vacuum_lead_s > self.gripper.vacuum_build_up_s {
            c.fail(
                "cycle.vacuum_lead_s",
                format!(
                    "must not exceed gripper.vacuum_build_up_s ({} s), got {}",
                    self.gripper.vacuum_build_up_s, self.cycle.vacuum_lead_s
                ),
            );
        }
        c.within("sim.physics_dt_s", self.sim.physics_dt_s, 1e-5, 0.02);
        c.within("sim.control_dt_s", self.sim.control_dt_s, 1e-5, 0.01);
        c.within("sim.servo_bandwidth_hz", self.sim.servo_bandwidth_hz, 0.1, 200.0);
        c.positive("sim.tracking_tolerance_deg", self.sim.tracking_tolerance_deg);
        c.positive("sim.saturation_trip_s", self.sim.saturation_trip_s);
        c.non_negative("sim.protective_stop_reset_s", self.sim.protective_stop_reset_s);
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
        if c.problems.is_empty() {
            self.check_layout(&mut c);
        }
        c.finish()
    }

    /// Layout checks that need only the scene: the sensor looks at the pick tray, the pick tray
    /// lies in the image and within range, trays stand on the table.
    fn check_layout(&self, c: &mut Checker) {
        let Some(world_from_camera) = self.sensor.world_from_camera() else {
            return;
        };
        let camera_from_world = world_from_camera.inverse();
        let s = &self.sensor;
        let tray = &self.pick_tray;
        let world_from_tray = tray.world_from_tray();
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
        for (key, t) in [("pick_tray", tray), ("place_tray.tray", &self.place_tray.tray)] {
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
}

/// A scene loaded and validated, with where it came from.
#[derive(Debug, Clone)]
pub struct LoadedScene {
    /// The label used in messages (path as given, or `embedded:default`).
    pub label: String,
    /// Where it came from.
    pub source: Source,
    /// The parsed, validated scene.
    pub scene: Scene,
    /// The URDF text the scene refers to, and its label.
    pub urdf_label: String,
    /// URDF XML.
    pub urdf_text: String,
}

fn read_text(label: &str, path: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|e| ConfigError::one(label, "", format!("cannot read file: {e}")))
}

impl LoadedScene {
    /// The default cell, built into the binary.
    pub fn embedded_default() -> Result<Self, ConfigError> {
        Self::from_text("embedded:default", Source::Embedded, embedded::DEFAULT_SCENE)
    }

    /// Reads a scene file from disk, with the URDF it names.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let label = path.display().to_string();
        let text = read_text(&label, path)?;
        Self::from_text(&label, Source::File(path.to_path_buf()), &text)
    }

    /// Parses and validates scene text; resolves and reads the URDF it names.
    pub fn from_text(label: &str, source: Source, text: &str) -> Result<Self, ConfigError> {
        let scene: Scene = parse_toml(label, text)?;
        scene.validate(label)?;
        let (urdf_label, urdf_text) = match &source {
            Source::Embedded => match embedded::file(&scene.robot.urdf) {
                Some(t) => (format!("embedded:{}", scene.robot.urdf), t.to_string()),
                None => {
                    return Err(ConfigError::one(
                        label,
                        "robot.urdf",
                        format!("names no built-in file, got {:?}", scene.robot.urdf),
                    ));
                }
            },
            Source::File(p) => {
                let base = p.parent().unwrap_or(Path::new("."));
                let urdf_path = base.join(&scene.robot.urdf);
                let urdf_label = urdf_path.display().to_string();
                let t = std::fs::read_to_string(&urdf_path)
                    .map_err(|e| ConfigError::one(label, "robot.urdf", format!("cannot read {urdf_label:?}: {e}")))?;
                (urdf_label, t)
            }
        };
        Ok(LoadedScene {
            label: label.to_string(),
            source,
            scene,
            urdf_label,
            urdf_text,
        })
    }

    /// Loads `path`, or the embedded default when `path` is `None`.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        match path {
            Some(p) => Self::from_file(p),
            None => Self::embedded_default(),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Workpiece file
// ---------------------------------------------------------------------------------------------

/// A workpiece type: one kind of part to be piled and picked.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Workpiece {
    /// Short name (A ... F in the reference table).
    pub name: String,
    /// What electronic part this is.
    pub kind: String,
    /// Bounding box of the whole part (body and leads) in the part frame [m].
    pub size_m: [f64; 3],
    /// Part mass [kg].
    pub mass_kg: f64,
    /// Coulomb friction coefficient against trays and other parts.
    pub friction: f64,
    /// Restitution coefficient.
    pub restitution: f64,
    /// Default number of parts in a pile.
    pub pile_count: u32,
    /// Collision shape.
    pub shape: ShapeConfig,
    /// Grasp hints.
    pub grasp: GraspHints,
}

/// Kinds of workpiece shape.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    /// The bounding box `size_m`.
    Box,
    /// A compound of boxes and cylinders (`parts`), e.g. a body with leads.
    Compound,
    /// A triangle mesh file (OBJ or STL), convex-decomposed for the physics.
    Mesh,
}

/// The collision shape of a workpiece, in the part frame (origin at the bounding box centre).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ShapeConfig {
    /// Box, compound or mesh.
    pub kind: ShapeKind,
    /// Compound: the primitives.
    #[serde(default)]
    pub parts: Vec<ShapePart>,
    /// Mesh: file path relative to the workpiece file.
    #[serde(default)]
    pub mesh_file: Option<String>,
    /// Mesh: scale from file units to metres.
    #[serde(default)]
    pub mesh_scale: Option<f64>,
}

/// Primitive kinds in a compound shape.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Primitive {
    /// A box with edge lengths `size_m`.
    Box,
    /// A cylinder of `radius_m` and `length_m` along `axis`.
    Cylinder,
}

/// Roles of compound parts: the body carries the suction faces; leads do not.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PartRole {
    /// The part's body (suction faces).
    Body,
    /// A lead or pin.
    Lead,
}

/// Axes of the part frame.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    /// Part x.
    X,
    /// Part y.
    Y,
    /// Part z.
    Z,
}

/// One primitive of a compound shape.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ShapePart {
    /// Box or cylinder.
    pub primitive: Primitive,
    /// Body or lead.
    pub role: PartRole,
    /// Centre in the part frame [m].
    pub center_m: [f64; 3],
    /// Box: edge lengths [m].
    #[serde(default)]
    pub size_m: Option<[f64; 3]>,
    /// Cylinder: radius [m].
    #[serde(default)]
    pub radius_m: Option<f64>,
    /// Cylinder: length [m].
    #[serde(default)]
    pub length_m: Option<f64>,
    /// Cylinder: axis.
    #[serde(default)]
    pub axis: Option<Axis>,
}

impl ShapePart {
    /// Half extents of the primitive's axis-aligned bounding box [m].
    pub fn half_extents_m(&self) -> Option<[f64; 3]> {
        match self.primitive {
            Primitive::Box => self.size_m.map(|s| [s[0] / 2.0, s[1] / 2.0, s[2] / 2.0]),
            Primitive::Cylinder => {
                let (r, h) = (self.radius_m?, self.length_m? / 2.0);
                Some(match self.axis? {
                    Axis::X => [h, r, r],
                    Axis::Y => [r, h, r],
                    Axis::Z => [r, r, h],
                })
            }
        }
    }
}

/// A workpiece primitive resolved to its geometry, in the part frame [m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Piece {
    /// A box.
    Box {
        /// Centre.
        center_m: Vector3<f64>,
        /// Half extents.
        half_m: Vector3<f64>,
    },
    /// A cylinder.
    Cylinder {
        /// Centre.
        center_m: Vector3<f64>,
        /// Radius.
        radius_m: f64,
        /// Half length along `axis`.
        half_length_m: f64,
        /// Axis.
        axis: Axis,
    },
}

impl Workpiece {
    /// The shape's primitives with their roles: a box workpiece is one body box, a compound its
    /// parts, a mesh none (its geometry lives in the mesh file). For validated workpieces.
    pub fn pieces(&self) -> Vec<(PartRole, Piece)> {
        match self.shape.kind {
            ShapeKind::Box => vec![(
                PartRole::Body,
                Piece::Box {
                    center_m: Vector3::zeros(),
                    half_m: Vector3::from(self.size_m) / 2.0,
                },
            )],
            ShapeKind::Compound => self
                .shape
                .parts
                .iter()
                .map(|p| {
                    let center_m = Vector3::from(p.center_m);
                    let piece = match p.primitive {
                        Primitive::Box => Piece::Box {
                            center_m,
                            half_m: Vector3::from(p.size_m.unwrap_or([0.0; 3])) / 2.0,
                        },
                        Primitive::Cylinder => Piece::Cylinder {
                            center_m,
                            radius_m: p.radius_m.unwrap_or(0.0),
                            half_length_m: p.length_m.unwrap_or(0.0) / 2.0,
                            axis: p.axis.unwrap_or(Axis::Z),
                        },
                    };
                    (p.role, piece)
                })
                .collect(),
            ShapeKind::Mesh => Vec::new(),
        }
    }
}

/// Grasp hints for a workpiece.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GraspHints {
    /// The part looks the same after this yaw about its top face normal [deg]
    /// (90 for a square top, 180 for a rectangle, 360 for none, 0 for a round top: any yaw).
    pub yaw_symmetry_deg: f64,
    /// Yaw of the part's x axis in its place slot, relative to the slot [deg].
    pub place_yaw_deg: f64,
    /// Smallest margin between cup edge and face edge that still seals [m].
    pub face_margin_m: f64,
}

/// A workpiece loaded and validated.
#[derive(Debug, Clone)]
pub struct LoadedWorkpiece {
    /// Label used in messages.
    pub label: String,
    /// Where it came from.
    pub source: Source,
    /// The workpiece.
    pub workpiece: Workpiece,
}

impl Workpiece {
    /// Checks every value of the workpiece on its own.
    pub fn validate(&self, file: &str) -> Result<(), ConfigError> {
        let mut c = Checker::new(file);
        if self.name.trim().is_empty() {
            c.fail("name", "must not be empty");
        }
        c.positive_all("size_m", &self.size_m);
        c.positive("mass_kg", self.mass_kg);
        c.within("friction", self.friction, 0.0, 2.0);
        c.within("restitution", self.restitution, 0.0, 1.0);
        if !(1..=1000).contains(&self.pile_count) {
            c.fail(
                "pile_count",
                format!("must be within [1, 1000], got {}", self.pile_count),
            );
        }
        c.within("grasp.yaw_symmetry_deg", self.grasp.yaw_symmetry_deg, 0.0, 360.0);
        c.finite("grasp.place_yaw_deg", self.grasp.place_yaw_deg);
        c.non_negative("grasp.face_margin_m", self.grasp.face_margin_m);
        let sh = &self.shape;
        match sh.kind {
            ShapeKind::Box => {
                if !sh.parts.is_empty() {
                    c.fail("shape.parts", "is only allowed when kind = \"compound\"");
                }
                if sh.mesh_file.is_some() {
                    c.fail("shape.mesh_file", "is only allowed when kind = \"mesh\"");
                }
            }
            ShapeKind::Compound => {
                if sh.parts.is_empty() {
                    c.fail(
                        "shape.parts",
                        "must list at least one primitive when kind = \"compound\"",
                    );
                }
                if !sh.parts.iter().any(|p| p.role == PartRole::Body) {
                    c.fail("shape.parts", "must contain at least one part with role = \"body\"");
                }
                let half = self.size_m.map(|s| s / 2.0);
                for (i, p) in sh.parts.iter().enumerate() {
                    let k = format!("shape.parts[{i}]");
                    c.finite_all(&format!("{k}.center_m"), &p.center_m);
                    match p.primitive {
                        Primitive::Box => match p.size_m {
                            Some(s) => c.positive_all(&format!("{k}.size_m"), &s),
                            None => c.fail(&format!("{k}.size_m"), "is required for a box"),
                        },
                        Primitive::Cylinder => {
                            match p.radius_m {
                                Some(r) => c.positive(&format!("{k}.radius_m"), r),
                                None => c.fail(&format!("{k}.radius_m"), "is required for a cylinder"),
                            }
                            match p.length_m {
                                Some(l) => c.positive(&format!("{k}.length_m"), l),
                                None => c.fail(&format!("{k}.length_m"), "is required for a cylinder"),
                            }
                            if p.axis.is_none() {
                                c.fail(&format!("{k}.axis"), "is required for a cylinder");
                            }
                        }
                    }
                    if let Some(he) = p.half_extents_m() {
                        for a in 0..3 {
                            let (lo, hi) = (p.center_m[a] - he[a], p.center_m[a] + he[a]);
                            if lo < -half[a] - 1e-9 || hi > half[a] + 1e-9 {
                                c.fail(
                                    &k,
                                    format!(
                                        "sticks out of the bounding box size_m along axis {a}: spans [{lo:.4}, {hi:.4}], box is ±{:.4}",
                                        half[a]
                                    ),
                                );
                                break;
                            }
                        }
                    }
                }
            }
            ShapeKind::Mesh => {
                match &sh.mesh_file {
                    None => c.fail("shape.mesh_file", "is required when kind = \"mesh\""),
                    Some(f) if !(f.ends_with(".obj") || f.ends_with(".stl")) => {
                        c.fail("shape.mesh_file", format!("must be an .obj or .stl file, got {f:?}"))
                    }
                    _ => {}
                }
                if let Some(s) = sh.mesh_scale {
                    c.positive("shape.mesh_scale", s);
                }
            }
        }
        c.finish()
    }

    /// The faces of the body's bounding box as `(normal axis, [edge_a_m, edge_b_m])`:
    /// the candidate suction faces (a face is only as large as the body's box).
    pub fn body_faces_m(&self) -> Vec<(Axis, [f64; 2])> {
        let body = self.body_size_m();
        vec![
            (Axis::X, [body[1], body[2]]),
            (Axis::Y, [body[0], body[2]]),
            (Axis::Z, [body[0], body[1]]),
        ]
    }

    /// Edge lengths of the body's bounding box (without leads) [m].
    pub fn body_size_m(&self) -> [f64; 3] {
        if self.shape.kind != ShapeKind::Compound {
            return self.size_m;
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in self.shape.parts.iter().filter(|p| p.role == PartRole::Body) {
            if let Some(he) = p.half_extents_m() {
                for a in 0..3 {
                    lo[a] = lo[a].min(p.center_m[a] - he[a]);
                    hi[a] = hi[a].max(p.center_m[a] + he[a]);
                }
            }
        }
        [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]]
    }

    /// Checks that the workpiece fits the scene: it fits in both trays, and the gripper's cup fits
    /// on at least one face of the body.
    pub fn check_fits_scene(&self, file: &str, scene: &Scene) -> Result<(), ConfigError> {
        let mut c = Checker::new(file);
        // Lying flat, the part's two longest edges must fit the tray's inner floor.
        let mut dims = self.size_m;
        dims.sort_by(|a, b| b.total_cmp(a));
        let [tx, ty] = scene.pick_tray.inner_size_m;
        let (tray_long, tray_short) = (tx.max(ty), tx.min(ty));
        if dims[0] > tray_long || dims[1] > tray_short {
            c.fail(
                "size_m",
                format!(
                    "is larger than the pick tray: a part of {} x {} m lying flat does not fit its {tx} x {ty} m inner floor",
                    dims[0], dims[1]
                ),
            );
        }
        let cup = scene.gripper.cup_diameter_m + 2.0 * self.grasp.face_margin_m;
        let faces = self.body_faces_m();
        if !faces.iter().any(|(_, [a, b])| a.min(*b) >= cup) {
            let largest = faces
                .iter()
                .map(|(_, [a, b])| format!("{a}x{b}"))
                .collect::<Vec<_>>()
                .join(", ");
            c.fail(
                "size_m",
                format!(
                    "has no face the suction cup fits on: cup {} m plus margin 2x{} m, faces {largest} m",
                    scene.gripper.cup_diameter_m, self.grasp.face_margin_m
                ),
            );
        }
        let footprint = [self.size_m[0], self.size_m[1]];
        if scene.place_tray.slots_in_tray(footprint).is_empty() {
            c.fail(
                "size_m",
                format!(
                    "leaves no placement slot in the place tray (inner {:?} m, gap {:?} m)",
                    scene.place_tray.tray.inner_size_m, scene.place_tray.gap_m
                ),
            );
        }
        c.finish()
    }
}

impl LoadedWorkpiece {
    /// Resolves a workpiece argument: a path (contains `/` or ends in `.toml`) is read from disk,
    /// a bare name (A ... F) is the embedded file of that name.
    pub fn resolve(arg: &str) -> Result<Self, ConfigError> {
        if arg.contains('/') || arg.ends_with(".toml") {
            return Self::from_file(Path::new(arg));
        }
        match embedded::WORKPIECES.iter().find(|(n, _)| n.eq_ignore_ascii_case(arg)) {
            Some((n, text)) => Self::from_text(&format!("embedded:workpieces/{n}.toml"), Source::Embedded, text),
            None => Err(ConfigError::one(
                "--workpiece",
                "",
                format!("names no built-in workpiece (A, B, C, D, E, F) and is not a .toml path, got {arg:?}"),
            )),
        }
    }

    /// Reads and validates a workpiece file.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let label = path.display().to_string();
        let text = read_text(&label, path)?;
        Self::from_text(&label, Source::File(path.to_path_buf()), &text)
    }

    /// Parses and validates workpiece text.
    pub fn from_text(label: &str, source: Source, text: &str) -> Result<Self, ConfigError> {
        let workpiece: Workpiece = parse_toml(label, text)?;
        workpiece.validate(label)?;
        if let (ShapeKind::Mesh, Source::File(p), Some(f)) = (workpiece.shape.kind, &source, &workpiece.shape.mesh_file)
        {
            let mesh = p.parent().unwrap_or(Path::new(".")).join(f);
            if !mesh.is_file() {
                return Err(ConfigError::one(
                    label,
                    "shape.mesh_file",
                    format!("names a file that does not exist: {}", mesh.display()),
                ));
            }
        }
        Ok(LoadedWorkpiece {
            label: label.to_string(),
            source,
            workpiece,
        })
    }

    /// All six embedded workpieces, A ... F.
    pub fn all_embedded() -> Result<Vec<Self>, ConfigError> {
        embedded::WORKPIECES
            .iter()
            .map(|(n, t)| Self::from_text(&format!("embedded:workpieces/{n}.toml"), Source::Embedded, t))
            .collect()
    }
}
