//! The scene (cell) file: robot, gripper, sensor, trays, table, obstacles, budgets and rates.
//!
//! Job: the scene's TOML sections as typed structs, the SI accessors the rest of the crate uses
//! (`world_from_base`, `home_rad`, `world_from_camera`, slot poses), and [`Scene::validate`],
//! which checks every value and the layout that needs no robot model (the sensor sees the pick
//! tray from above, the trays stand on the table).
//!
//! Units: the key names carry the units (`_m`, `_s`, `_kg`, `_deg`, `_px`, ...); degrees exist
//! only in the file structs, the accessors return radians. Frames: world (z up, the table top at
//! `table.top_z_m`) unless a key says otherwise: `gripper.com_m` is in the flange frame, slot poses
//! in the place tray's frame, the camera's optical frame is x right, y down, z along the view.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::{Checker, ConfigError, Workpiece};

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
    /// How far the simulated plant is from the controller's model (on by default).
    #[serde(default)]
    pub model_error: super::ModelErrorConfig,
    /// How the pick tray is shaken when nothing in it can be picked (absent: never).
    #[serde(default)]
    pub agitation: super::AgitationConfig,
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
    /// Specification acceleration per joint [deg/s^2]: the controller's default parameters stay
    /// within it, and it caps every planned motion when `accel_cap` is `spec`.
    pub max_accel_deg_s2: [f64; 6],
    /// What binds a planned motion's joint accelerations besides the torque limits: `none` (the
    /// default) lets the torque alone bind; `spec` caps each joint at `max_accel_deg_s2` too.
    #[serde(default)]
    pub accel_cap: AccelCap,
    /// Overrides the URDF effort limits when present [N m].
    #[serde(default)]
    pub torque_limit_nm: Option<[f64; 6]>,
}

/// Whether the specification accelerations cap the planned motions
/// (`robot.drives.accel_cap`).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
pub enum AccelCap {
    /// No cap: the motion accelerator raises each joint's acceleration until its torque binds,
    /// and the time-optimal bound has torque and speed rows only.
    #[default]
    #[serde(rename = "none")]
    TorqueOnly,
    /// Each joint's acceleration is capped at its specification acceleration as well.
    #[serde(rename = "spec")]
    Spec,
}

impl AccelCap {
    /// The name in the cell file and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            AccelCap::TorqueOnly => "none",
            AccelCap::Spec => "spec",
        }
    }
}

impl std::str::FromStr for AccelCap {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(AccelCap::TorqueOnly),
            "spec" => Ok(AccelCap::Spec),
            _ => Err(format!("unknown acceleration cap `{s}` (none or spec)")),
        }
    }
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

fn default_max_yaw_ambiguity_deg() -> f64 {
    crate::sensor::cloud::YAW_SPAN_MAX_RAD.to_degrees()
}

/// How the sensor's captures are turned into recognised parts.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RecognitionMode {
    /// From the depth capture and the workpiece model alone ([`crate::sensor::cloud`]).
    #[default]
    Cloud,
    /// The what-if of perfect recognition: the parts the capture showed enough of, at their poses
    /// at the trigger plus Gaussian noise.
    Oracle,
}

impl RecognitionMode {
    /// The name in the cell file and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            RecognitionMode::Cloud => "cloud",
            RecognitionMode::Oracle => "oracle",
        }
    }
}

impl std::str::FromStr for RecognitionMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "cloud" => Ok(RecognitionMode::Cloud),
            "oracle" => Ok(RecognitionMode::Oracle),
            _ => Err(format!("unknown recognition `{s}` (cloud or oracle)")),
        }
    }
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
    /// How parts are recognised: `cloud` (from the depth capture and the part's model, the
    /// default) or `oracle` (the what-if of perfect recognition: the parts the capture showed, at
    /// their poses at the trigger plus `pose_noise_*`).
    #[serde(default)]
    pub recognition: RecognitionMode,
    /// Cloud recognition: a face whose outline leaves its yaw open by more than this is not
    /// reported [deg] (default 8: precision first; half of it is the largest yaw error reported).
    #[serde(default = "default_max_yaw_ambiguity_deg")]
    pub max_yaw_ambiguity_deg: f64,
    /// Oracle recognition: a part counts as detected when at least this fraction of its camera-facing surface is visible.
    pub detect_min_visible_fraction: f64,
    /// Oracle recognition pose noise, position standard deviation [m]; also the recognition
    /// accuracy the place release height allows for.
    pub pose_noise_m: f64,
    /// Oracle recognition pose noise, rotation standard deviation [deg]; also the recognition
    /// accuracy the place release height allows for.
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
    /// The vacuum is switched off this long before the Place's descent ends, so it vents while
    /// the cup brings the part down the last millimetres [s] (0: when the cup has stopped; at
    /// most `gripper.release_s`). The holding force falls as the vacuum vents, and the physics
    /// decides when the part comes off (README: the suction cup); the retreat starts no earlier
    /// than `release_s` after the valve closed. Absent: 0.
    #[serde(default)]
    pub release_lead_s: f64,
    /// Fraction of each joint's torque limit every planned motion (accelerated transfers and
    /// straight lines) keeps back for what the controller's model does not know: the plant's
    /// model error and the servo's feedback.
    #[serde(default = "default_torque_margin")]
    pub torque_margin: f64,
    /// Most picks from one recognition result (1: a capture per pick). A later pick takes only
    /// a part recognised clear of every earlier pick's footprint and the tool's swept column
    /// (README: several picks per capture); the seal check tells whether it was still there.
    #[serde(default = "default_max_picks_per_capture")]
    pub max_picks_per_capture: u32,
    /// Where the arm waits when it has nothing to do but wait for a recognition result: the
    /// cup's position [m, world], the tool pointing straight down. It must lie outside the
    /// sensor's view, so a capture exposes while the arm waits there (checked when a run
    /// starts); from there only the last stretch of the Pick depends on the result. Absent: the
    /// arm waits where its last motion ended.
    #[serde(default)]
    pub waiting_tool_m: Option<[f64; 3]>,
    /// The straight lines overlap the transfers next to them: the Place transfer starts while
    /// the part still rises, and the descents (the Pick's onto the part, the Place's into the
    /// slot) start while the transfer before them ends, each by the largest share of the line
    /// (60, 40 or 20 %) whose overlap is clear, within the torques and within the cup's holding
    /// force. Absent: false (every motion from rest to rest).
    #[serde(default)]
    pub overlap_lines: bool,
}

fn default_max_picks_per_capture() -> u32 {
    1
}

/// The default torque margin: 15 % was the smallest of 0 / 5 / 10 / 15 % at which no pick of
/// the six workpieces demanded more than a limit with the default model error, but only just
/// (C: 99.9 %, and 100.2 % in a deterministic batch); 20 % leaves headroom at no measurable
/// takt cost (README: trade-off).
pub const DEFAULT_TORQUE_MARGIN: f64 = 0.20;

fn default_torque_margin() -> f64 {
    DEFAULT_TORQUE_MARGIN
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

/// Largest sensor image [px]: 4 MP, e.g. 2048 x 2048, twelve times the default cell's 320 x 256 and
/// above the 3 MP class of the 3D sensors used for bin picking. A capture holds per pixel an f32
/// depth, three f32 world coordinates and a hit tag (24 bytes), the sensor keeps per pixel what the
/// fixed cell shows, and a run keeps a few captures at once, in every parallel run of a batch: at
/// this cap a capture takes about 100 MB and a run under a gigabyte, while the 8192 x 8192 that
/// each axis alone allows would take 1.6 GB per capture.
pub const MAX_SENSOR_PIXELS: u64 = 1 << 22;

/// Bytes a capture holds per pixel: depth (f32), world point (3 x f32), hit tag (8).
const CAPTURE_BYTES_PER_PIXEL: u64 = 24;

/// How far the camera's optical centre must be above the pick tray's rim plane at least [m]. The
/// view frustum over the tray (apex at the optical centre, base the tray's outer rim at floor
/// level) is then a pyramid of positive height, and the view over the rim reaches into the tray; a
/// camera level with the tray would flatten the pyramid into a plane.
pub const MIN_CAMERA_ABOVE_RIM_M: f64 = 0.05;

/// The sensor's view over the pick tray is a pyramid only while the tray is more than a point in
/// it: the tray's outer rim (inner size plus walls) must span, each way, at least this fraction of
/// the camera's distance to the farthest rim corner (0.6 deg of view). A camera hundreds of metres
/// from a tray sees it as a point, and the frustum degenerates into a line.
pub const MIN_VIEW_BASE_PER_DISTANCE: f64 = 0.01;

/// The camera and the pick tray must lie within this distance of the world origin along each axis
/// [m]: the physics queries the view frustum in single precision (millimetres), where a cell
/// farther out would lose its shape.
pub const MAX_CELL_EXTENT_M: f64 = 1000.0;

/// Most placement slots a grid place tray may offer one workpiece: more is a unit mistake (a part
/// of micrometres, a tray of kilometres), and the grid's slots are built as a list.
pub const MAX_PLACE_SLOTS: f64 = 10_000.0;

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
    /// The grid pattern for a footprint: gap [m], slot yaw [rad], the rotated footprint's extent
    /// along the tray's x and y [m], and the slot counts along them (whole numbers, as f64 so a
    /// tiny footprint cannot overflow them).
    fn grid(&self, footprint_m: [f64; 2]) -> (f64, f64, [f64; 2], [f64; 2]) {
        let gap = self.gap_m.unwrap_or(0.0);
        let yaw = deg(self.slot_yaw_deg.unwrap_or(0.0));
        // Footprint of the part rotated by yaw, as an axis-aligned box in the tray frame.
        let (c, s) = (yaw.cos().abs(), yaw.sin().abs());
        let fx = footprint_m[0] * c + footprint_m[1] * s;
        let fy = footprint_m[0] * s + footprint_m[1] * c;
        let [lx, ly] = self.tray.inner_size_m;
        let nx = ((lx - gap) / (fx + gap)).floor().max(0.0);
        let ny = ((ly - gap) / (fy + gap)).floor().max(0.0);
        (gap, yaw, [fx, fy], [nx, ny])
    }

    /// How many placement slots [`Self::slots_in_tray`] gives for a footprint, without building
    /// them.
    pub fn slot_count(&self, footprint_m: [f64; 2]) -> f64 {
        match self.pattern {
            SlotPattern::List => self.poses.as_ref().map_or(0, Vec::len) as f64,
            SlotPattern::Grid => {
                let [nx, ny] = self.grid(footprint_m).3;
                nx * ny
            }
        }
    }

    /// Placement poses in the tray frame, `(x_m, y_m, yaw_rad)`, for a part with the given
    /// footprint `[length_m, width_m]` (along the slot's own x and y).
    pub fn slots_in_tray(&self, footprint_m: [f64; 2]) -> Vec<(f64, f64, f64)> {
        match self.pattern {
            SlotPattern::List => self.poses.iter().flatten().map(|p| (p[0], p[1], deg(p[2]))).collect(),
            SlotPattern::Grid => {
                let (gap, yaw, [fx, fy], [nx, ny]) = self.grid(footprint_m);
                let (nx, ny) = (nx as usize, ny as usize);
                let mut out = Vec::with_capacity(nx.saturating_mul(ny));
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
        c.non_negative("cycle.vacuum_lead_s", self.cycle.vacuum_lead_s);
        c.non_negative("cycle.release_lead_s", self.cycle.release_lead_s);
        c.within("cycle.torque_margin", self.cycle.torque_margin, 0.0, 0.5);
        self.model_error.check(&mut c);
        self.agitation.check(&mut c);
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

#[cfg(test)]
mod accel_cap_tests {
    use super::*;

    /// The default cell with its `accel_cap` line replaced by `line` (empty: left out).
    fn scene_with(line: &str) -> Result<Scene, crate::config::ConfigError> {
        let text = crate::config::embedded::DEFAULT_SCENE.replace("accel_cap = \"none\"", line);
        crate::config::parse_toml::<Scene>("cell.toml", &text)
    }

    #[test]
    fn the_acceleration_cap_is_optional_strict_and_none_by_default() {
        assert_eq!(scene_with("").unwrap().robot.drives.accel_cap, AccelCap::TorqueOnly);
        assert_eq!(
            scene_with("accel_cap = \"none\"").unwrap().robot.drives.accel_cap,
            AccelCap::TorqueOnly
        );
        assert_eq!(
            scene_with("accel_cap = \"spec\"").unwrap().robot.drives.accel_cap,
            AccelCap::Spec
        );
        let e = scene_with("accel_cap = \"fast\"").unwrap_err().to_string();
        assert!(
            e.contains("robot.drives.accel_cap") && e.contains("`none` or `spec`"),
            "{e}"
        );
        for cap in [AccelCap::TorqueOnly, AccelCap::Spec] {
            assert_eq!(cap.name().parse::<AccelCap>(), Ok(cap));
        }
        assert!("fast".parse::<AccelCap>().is_err());
    }
}
