//! The scene (cell) file: robot, gripper, sensor, trays, table, obstacles, budgets and rates.
//!
//! Job: the scene's TOML sections as typed structs, the SI accessors the rest of the crate uses
//! (`world_from_base`, `home_rad`, `world_from_camera`, slot poses). [`Scene::validate`], which
//! checks every value and the layout that needs no robot model (the sensor sees the pick tray
//! from above, the trays stand on the table), is in `scene_checks`.
//!
//! Units: the key names carry the units (`_m`, `_s`, `_kg`, `_deg`, `_px`, ...); degrees exist
//! only in the file structs, the accessors return radians. Frames: world (z up, the table top at
//! `table.top_z_m`) unless a key says otherwise: `gripper.com_m` is in the flange frame, slot poses
//! in the place tray's frame, the camera's optical frame is x right, y down, z along the view.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::Workpiece;

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
    /// The hopper that doses parts into the pick tray when the sensor sees few (absent: none).
    #[serde(default)]
    pub feeder: super::FeederConfig,
}

/// The arm: its URDF, where it stands, and the drive data a URDF cannot hold.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RobotConfig {
    /// URDF path, relative to the scene file's folder.
    pub urdf: String,
    /// The URDF link whose frame is the flange (tool mounting face).
    pub flange_link: String,
    /// Base position in the world (m).
    pub world_from_base_xyz_m: [f64; 3],
    /// Base orientation in the world, roll-pitch-yaw (fixed axes x, y, z) (deg).
    pub world_from_base_rpy_deg: [f64; 3],
    /// A parking configuration clear of trays and sensor view (deg).
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
    /// Distance from the flange face to the cup lip along the flange z axis (m) (the tool frame).
    pub tool_length_m: f64,
    /// Diameter of the tool body (for collision) (m).
    pub body_diameter_m: f64,
    /// Suction cup outer diameter at the lip (m).
    pub cup_diameter_m: f64,
    /// Flatness the cup lip tolerates across its diameter (m).
    pub cup_flatness_tolerance_m: f64,
    /// Largest tilt of the approach from the face normal at which the cup still seals (deg).
    pub max_tilt_deg: f64,
    /// The largest lean of the tool from vertical at which the grasp selector takes a face (deg),
    /// 0 to 60: a face tilted up to `max_tilt_deg` is approached straight down, one tilted
    /// further (up to this) along its normal, the tool leaning with it, and lifted straight up.
    /// Left out, or below `max_tilt_deg`: every face is approached straight down.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_lean_deg: Option<f64>,
    /// The smallest radius of a convex round surface (a can's side) the cup's lip seals on, as a
    /// bellows cup's datasheet gives it (m); left out, the cup seals on flat faces only. Must
    /// exceed the cup's radius. The grasp selector then also offers a part's round body's side,
    /// where its radius is at least this, and the physical cup's seal follows a surface that
    /// curves away from its centre by up to what a sphere of this radius does under the lip.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round_min_radius_m: Option<f64>,
    /// Vacuum level once sealed (below ambient) (kPa).
    pub vacuum_kpa: f64,
    /// Friction coefficient of the cup's lip on the part (0.05 to 1.5): the shear the seal holds
    /// per newton of its holding force, as suction makers size cups moved sideways (Schmalz's
    /// load cases: 0.5 for dry smooth parts, 0.1 oily, 0.6 rough). Left out: 0.5.
    #[serde(default = "lip_friction")]
    pub lip_friction: f64,
    /// Time from valve open to full vacuum (s).
    pub vacuum_build_up_s: f64,
    /// Time from valve closed to part released (s).
    pub release_s: f64,
    /// Hand mass (kg).
    pub mass_kg: f64,
    /// Hand centre of mass in the flange frame (m).
    pub com_m: [f64; 3],
    /// Hand principal moments of inertia about its centre of mass, axes along the flange frame [kg m^2].
    pub inertia_kg_m2: [f64; 3],
    /// Whether parts pressing on the held part load the seal (their pull off the cup and its peel
    /// moment, [`crate::physics::ContactLoad`]), not only its own weight and the tool's
    /// acceleration. On by default: off, a strip lying on the end of the held one is lifted
    /// rigidly, kinder than a real cup (docs/model.md).
    #[serde(default = "seal_loaded_by_parts")]
    pub seal_loaded_by_parts: bool,
}

impl GripperConfig {
    /// The largest tilt from vertical of a face the grasp selector takes (rad): the larger of
    /// `max_lean_deg` and `max_tilt_deg`.
    pub fn max_lean_rad(&self) -> f64 {
        self.max_lean_deg.unwrap_or(0.0).max(self.max_tilt_deg).to_radians()
    }
}

/// The largest `gripper.max_lean_deg` (deg): the grasp selector counts a face tilted up to 60 deg
/// as facing up, and a tool leaning further would sweep its body through the pile beside it.
pub const MAX_LEAN_DEG: f64 = 60.0;

/// The default of `gripper.lip_friction`.
fn lip_friction() -> f64 {
    0.5
}

/// The default of `gripper.seal_loaded_by_parts`.
fn seal_loaded_by_parts() -> bool {
    true
}

/// A silhouette fit whose consistent yaws span more than this does not pin the yaw down (rad)
/// (the default of `sensor.max_yaw_ambiguity_deg`; precision first: half of it is the largest
/// yaw error reported).
pub const YAW_SPAN_MAX_RAD: f64 = 8.0 * std::f64::consts::PI / 180.0;

fn default_max_yaw_ambiguity_deg() -> f64 {
    YAW_SPAN_MAX_RAD.to_degrees()
}

/// How the sensor's captures are turned into recognised parts.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RecognitionMode {
    /// From the depth capture and the workpiece model alone (the sensor's cloud recognition).
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
    /// Optical centre in the world (m).
    pub position_m: [f64; 3],
    /// A world point on the optical axis (m).
    pub look_at_m: [f64; 3],
    /// World direction that appears toward the top of the image (must not be parallel to the view).
    pub image_up: [f64; 3],
    /// Image size, width and height (px).
    pub resolution_px: [u32; 2],
    /// Focal lengths fx, fy (px).
    pub focal_px: [f64; 2],
    /// Principal point cx, cy (px).
    pub principal_point_px: [f64; 2],
    /// Nearest measurable range (m).
    pub min_range_m: f64,
    /// Farthest measurable range (m).
    pub max_range_m: f64,
    /// From trigger to recognition result available (s) (1.1 s in the reference system).
    pub latency_s: f64,
    /// Exposure window during which the scene must be still and the arm out of view (s).
    pub exposure_s: f64,
    /// Depth noise standard deviation at 1 m range; grows with range squared (m).
    pub depth_noise_at_1m_m: f64,
    /// Surfaces seen more obliquely than this return nothing (deg).
    pub dropout_grazing_deg: f64,
    /// Probability that a valid pixel drops out anyway.
    pub dropout_probability: f64,
    /// How parts are recognised: `cloud` (from the depth capture and the part's model, the
    /// default) or `oracle` (the what-if of perfect recognition: the parts the capture showed, at
    /// their poses at the trigger plus `pose_noise_*`).
    #[serde(default)]
    pub recognition: RecognitionMode,
    /// Cloud recognition: a face whose outline leaves its yaw open by more than this is not
    /// reported (deg) (default 8: precision first; half of it is the largest yaw error reported).
    #[serde(default = "default_max_yaw_ambiguity_deg")]
    pub max_yaw_ambiguity_deg: f64,
    /// Oracle recognition: a part counts as detected when at least this fraction of its camera-facing surface is visible.
    pub detect_min_visible_fraction: f64,
    /// Oracle recognition pose noise, position standard deviation (m); also the recognition
    /// accuracy the place release height allows for.
    pub pose_noise_m: f64,
    /// Oracle recognition pose noise, rotation standard deviation (deg); also the recognition
    /// accuracy the place release height allows for.
    pub pose_noise_deg: f64,
}

/// A tray: a floor and four walls. Its frame: origin at the centre of the inner floor surface,
/// z up, x along `inner_size_m[0]`, rotated by `yaw_deg` about world z.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TrayConfig {
    /// Centre of the inner floor surface in the world (m).
    pub center_m: [f64; 3],
    /// Rotation about world z (deg).
    pub yaw_deg: f64,
    /// Inner length and width (m).
    pub inner_size_m: [f64; 2],
    /// Wall height above the inner floor (m).
    pub wall_height_m: f64,
    /// Wall thickness (m).
    pub wall_thickness_m: f64,
    /// Floor thickness (m).
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
    /// Grid: clearance between neighbouring parts and to the walls (m).
    #[serde(default)]
    pub gap_m: Option<f64>,
    /// Grid: yaw of every placed part in the tray frame (deg).
    #[serde(default)]
    pub slot_yaw_deg: Option<f64>,
    /// Grid: centre-to-centre spacing of the slots along the tray's x axis (m); absent: the
    /// part's place footprint along x plus `gap_m`. It must not be below that footprint (the
    /// parts would overlap); `gap_m` stays the clearance to the walls.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch_x_m: Option<f64>,
    /// Grid: the same along the tray's y axis (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch_y_m: Option<f64>,
    /// List: placement poses in the tray frame, each `[x_m, y_m, yaw_deg]`.
    #[serde(default)]
    pub poses: Option<Vec<[f64; 3]>>,
    /// A placed part lying farther than this from its place pose, horizontally, is misplaced
    /// (m): what the tray's pockets or the next machine allow (default 2 mm, the bound a
    /// recognised pose is judged right by).
    #[serde(default = "default_place_tolerance_m")]
    pub tolerance_m: f64,
    /// ... or turned farther than this from it (deg), over the turns that leave the part
    /// looking the same (default 5).
    #[serde(default = "default_place_tolerance_deg")]
    pub tolerance_deg: f64,
}

/// A pose within this position error of another is the same pose (m): a detection of a part
/// counts as correct within it (the sensor's `CORRECT_WITHIN_M`), and a placed part is in its
/// slot within it (`place_tray.tolerance_m`'s default).
pub const POSE_WITHIN_M: f64 = 0.002;
/// ... and within this rotation error, the part's symmetries allowed (rad) (5 deg).
pub const POSE_WITHIN_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// `place_tray.tolerance_m` when the cell file leaves it out.
fn default_place_tolerance_m() -> f64 {
    POSE_WITHIN_M
}

/// `place_tray.tolerance_deg` when the cell file leaves it out.
fn default_place_tolerance_deg() -> f64 {
    POSE_WITHIN_RAD.to_degrees()
}

/// The table top: a box whose upper face is at `top_z_m`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TableConfig {
    /// Height of the table top in the world (m).
    pub top_z_m: f64,
    /// Centre of the table top in x, y (m).
    pub center_xy_m: [f64; 2],
    /// Table top length and width (m).
    pub size_m: [f64; 2],
    /// Table top thickness (m).
    pub thickness_m: f64,
}

/// A box obstacle.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ObstacleConfig {
    /// What it is.
    pub name: String,
    /// Box centre in the world (m).
    pub center_m: [f64; 3],
    /// Box edge lengths (m).
    pub size_m: [f64; 3],
    /// Rotation about world z (deg).
    #[serde(default)]
    pub yaw_deg: f64,
}

/// Compute budgets (the reference system's figures), charged in deterministic mode.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ComputeConfig {
    /// Grasp estimation per capture (s) (reference: 0.050).
    pub grasp_estimation_s: f64,
    /// Motion generation per motion, planning and acceleration (s) (reference: 0.100).
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
    /// Time to exchange the pick tray for a full one (s) (the arm waits).
    pub refill_s: f64,
    /// The place tray is exchanged for an empty one when its slots are used up, outside the
    /// arm's cycle (a conveyor) [s of arm time: 0 when buffered].
    pub place_tray_exchange_s: f64,
    /// Height of the Pick's approach pose (where the straight descent starts) above the pick
    /// tray's rim (m).
    pub approach_above_rim_m: f64,
    /// Top tool speed of the straight descents, lifts and retreats [m/s].
    pub line_speed_m_s: f64,
    /// Tool acceleration of the straight lines before the torque and suction checks [m/s^2].
    pub line_accel_m_s2: f64,
    /// A straight line the arm cannot follow exactly because it passes the wrist's singularity
    /// (J5 = 0, where J4 and J6 would have to spin) moves the wrist joints linearly from end
    /// to end instead, the tool centre point still on the line, if the tool's orientation then
    /// stays within this of the line's (deg), as industrial controllers offer (docs/model.md,
    /// "Straight lines"). Absent: 0, such a line fails.
    #[serde(default)]
    pub wrist_deviation_max_deg: f64,
    /// The vacuum is switched on this long before the descent ends, so it builds up while the
    /// cup closes the last millimetres (s) (0: at contact).
    pub vacuum_lead_s: f64,
    /// The vacuum is switched off this long before the Place's descent ends, so it vents while
    /// the cup brings the part down the last millimetres (s) (0: when the cup has stopped; at
    /// most `gripper.release_s`). The holding force falls as the vacuum vents, and the physics
    /// decides when the part comes off (docs/model.md, "Physics"); the retreat starts no earlier
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
    /// (docs/model.md, "The cell cycle"); the seal check tells whether it was still there.
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
    /// A part the grasp selector saw hemmed in by its neighbours beyond this
    /// ([`crate::grasp::Score::hemmed`]) is lifted gently where the seal has no room for a
    /// neighbour's push: at the largest acceleration, down to a tenth of `line_accel_m_s2`, at
    /// which the lift leaves in the cup's budget what one part's weight pushing across the cup's
    /// axis at the part's centre of mass would ask (docs/model.md, "The cell cycle"). Absent:
    /// every lift at `line_accel_m_s2`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gentle_lift_hemmed: Option<f64>,
}

fn default_max_picks_per_capture() -> u32 {
    1
}

/// The default torque margin: 15 % was the smallest of 0 / 5 / 10 / 15 % at which no pick of
/// the six workpieces demanded more than a limit with the default model error, but only just
/// (C: 99.9 %, and 100.2 % in a deterministic batch); 20 % leaves headroom at no measurable
/// takt cost (docs/model.md, "The torque margin").
pub const DEFAULT_TORQUE_MARGIN: f64 = 0.20;

fn default_torque_margin() -> f64 {
    DEFAULT_TORQUE_MARGIN
}

/// Simulation and control rates.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Physics (rapier) timestep (s).
    pub physics_dt_s: f64,
    /// Joint servo period (s).
    pub control_dt_s: f64,
    /// Closed-loop bandwidth of the joint servo's PD feedback (Hz).
    pub servo_bandwidth_hz: f64,
    /// Tracking error beyond which the controller trips a protective stop (deg).
    pub tracking_tolerance_deg: f64,
    /// Torque saturation lasting longer than this trips a protective stop (s).
    pub saturation_trip_s: f64,
    /// Time to reset after a protective stop before the cycle resumes (s).
    pub protective_stop_reset_s: f64,
    /// How the physics is stepped: `"event-driven"` (the default: no solver step where nothing
    /// can move, continuous collision detection only for poured, dropped and shaken parts) or
    /// `"always"` (every step solved with continuous collision detection on, as before event
    /// stepping; for comparing the two).
    #[serde(default)]
    pub stepping: Stepping,
    /// Overlap between two parts, or a part and the cell, beyond which the physics health
    /// monitor ends the run on a physics fault (m). Default 2 mm.
    #[serde(default = "default_deep_penetration_limit_m")]
    pub deep_penetration_limit_m: f64,
}

/// The physics health monitor's default deep-penetration limit (m): parts of a few grams
/// resting on each other sink well under 0.3 mm; 2 mm is a solver failure.
pub const DEFAULT_DEEP_PENETRATION_LIMIT_M: f64 = 0.002;

fn default_deep_penetration_limit_m() -> f64 {
    DEFAULT_DEEP_PENETRATION_LIMIT_M
}

/// How the physics world is stepped (`sim.stepping`).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Stepping {
    /// A step where every part sleeps, the pick tray rests, the gripper holds or is idle and
    /// no kinematic body (arm, tool, cup, held part) can come near a part or the cell within
    /// it only moves the kinematic bodies and advances the clock; continuous collision detection
    /// runs only while a poured, dropped or shaken part is awake, or the tray moves.
    #[default]
    EventDriven,
    /// Every step solved, continuous collision detection on every step.
    Always,
}

/// Largest sensor image (px): 4 MP, e.g. 2048 x 2048, five times the default cell's 1032 x 772 and
/// above the 3.2 MP of the 3D sensors' class used for bin picking (2064 x 1544). A capture holds per pixel an f32
/// depth, three f32 world coordinates and a hit tag (24 bytes), the sensor keeps per pixel what the
/// fixed cell shows, and a run keeps a few captures at once, in every parallel run of a batch: at
/// this cap a capture takes about 100 MB and a run under a gigabyte, while the 8192 x 8192 that
/// each axis alone allows would take 1.6 GB per capture.
pub const MAX_SENSOR_PIXELS: u64 = 1 << 22;

/// Bytes a capture holds per pixel: depth (f32), world point (3 x f32), hit tag (8).
pub(super) const CAPTURE_BYTES_PER_PIXEL: u64 = 24;

/// How far the camera's optical centre must be above the pick tray's rim plane at least (m). The
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
/// (m): the physics queries the view frustum in single precision (millimetres), where a cell
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

    /// Home configuration (rad).
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
    /// The extent of a part of `footprint_m` (along the slot's x and y) turned by the grid's slot
    /// yaw, along the tray's x and y (m).
    pub fn rotated_footprint_m(&self, footprint_m: [f64; 2]) -> [f64; 2] {
        let yaw = deg(self.slot_yaw_deg.unwrap_or(0.0));
        let (c, s) = (yaw.cos().abs(), yaw.sin().abs());
        [
            footprint_m[0] * c + footprint_m[1] * s,
            footprint_m[0] * s + footprint_m[1] * c,
        ]
    }

    /// The grid's slot spacing for a footprint along the tray's x and y (m): `pitch_x_m` and
    /// `pitch_y_m` where given, else the rotated footprint plus the gap.
    pub fn pitch_m(&self, footprint_m: [f64; 2]) -> [f64; 2] {
        let gap = self.gap_m.unwrap_or(0.0);
        let [fx, fy] = self.rotated_footprint_m(footprint_m);
        [self.pitch_x_m.unwrap_or(fx + gap), self.pitch_y_m.unwrap_or(fy + gap)]
    }

    /// A given pitch below the rotated footprint, the parts overlapping: its key, the pitch and
    /// the footprint's extent along it (m).
    pub fn pitch_below_footprint(&self, footprint_m: [f64; 2]) -> Option<(&'static str, f64, f64)> {
        let f = self.rotated_footprint_m(footprint_m);
        [
            ("place_tray.pitch_x_m", self.pitch_x_m, f[0]),
            ("place_tray.pitch_y_m", self.pitch_y_m, f[1]),
        ]
        .into_iter()
        .find_map(|(key, p, extent)| p.filter(|p| *p < extent).map(|p| (key, p, extent)))
    }

    /// The grid pattern for a footprint: slot yaw (rad), the slot spacing along the tray's x and y
    /// (m), and the slot counts along them (whole numbers, as f64 so a tiny footprint cannot
    /// overflow them).
    fn grid(&self, footprint_m: [f64; 2]) -> (f64, [f64; 2], [f64; 2]) {
        let gap = self.gap_m.unwrap_or(0.0);
        let yaw = deg(self.slot_yaw_deg.unwrap_or(0.0));
        let f = self.rotated_footprint_m(footprint_m);
        let pitch = self.pitch_m(footprint_m);
        let l = self.tray.inner_size_m;
        let count = |a: usize, given: Option<f64>| match given {
            // As many slots as fit between the walls' clearances.
            Some(p) => ((l[a] - 2.0 * gap - f[a]) / p + 1.0).floor().max(0.0),
            None => ((l[a] - gap) / (f[a] + gap)).floor().max(0.0),
        };
        (yaw, pitch, [count(0, self.pitch_x_m), count(1, self.pitch_y_m)])
    }

    /// How many placement slots [`Self::slots_in_tray`] gives for a footprint, without building
    /// them.
    pub fn slot_count(&self, footprint_m: [f64; 2]) -> f64 {
        match self.pattern {
            SlotPattern::List => self.poses.as_ref().map_or(0, Vec::len) as f64,
            SlotPattern::Grid => {
                let [nx, ny] = self.grid(footprint_m).2;
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
                let (yaw, [px, py], [nx, ny]) = self.grid(footprint_m);
                let (nx, ny) = (nx as usize, ny as usize);
                let mut out = Vec::with_capacity(nx.saturating_mul(ny));
                for j in 0..ny {
                    for i in 0..nx {
                        let x = (i as f64 - (nx as f64 - 1.0) / 2.0) * px;
                        let y = (j as f64 - (ny as f64 - 1.0) / 2.0) * py;
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
        self.world_from_slots_for(w, [w.size_m[0], w.size_m[1]])
    }

    /// As [`Self::world_from_slots`], the slots spaced for a part whose footprint in its place
    /// orientation is `footprint_m` (along the slot's x and y) (m): a part model's, whose place
    /// orientation is one of its stable poses ([`crate::grasp::GraspSelector::place_footprint_m`]).
    pub fn world_from_slots_for(&self, w: &Workpiece, footprint_m: [f64; 2]) -> Vec<Isometry3<f64>> {
        let world_from_tray = self.place_tray.tray.world_from_tray();
        let place_yaw = deg(w.grasp.place_yaw_deg);
        self.place_tray
            .slots_in_tray(footprint_m)
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
