//! The workpiece files: one kind of part to be piled and picked.
//!
//! Job: the workpiece TOML as typed structs, its shape resolved into primitives ([`Piece`]),
//! [`Workpiece::validate`] on its own and [`Workpiece::check_fits_scene`] against a cell (the part
//! fits both trays, the suction cup fits on one of its faces).
//!
//! Units: metres, kilograms, degrees only in `grasp.*_deg` (as read); a mesh file's own units are
//! named by `shape.units` (or given as `shape.mesh_scale`, metres per file unit). Frame: the part
//! frame, origin at the centre of the bounding box `size_m`, its axes along the box edges.
//!
//! For `kind = "mesh"`, `size_m` is derived from the mesh (its bounding box, after repair) when
//! the workpiece is loaded: it may be left out, and if it is given it must agree with the mesh
//! within [`MESH_SIZE_TOL_M`] (a second, hand-typed size that disagrees with the CAD file is a
//! mistake to refuse, not a value to choose between). Likewise `shape.units` is resolved into
//! `shape.mesh_scale` on load, so the resolved workpiece a run writes names the scale it used.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{Checker, ConfigError, MAX_PLACE_SLOTS, Scene, SlotPattern};
pub use crate::part::primitive::{Axis, PartRole, Piece};

/// How far a given `size_m` of a mesh workpiece may differ from the mesh's bounding box (m).
pub const MESH_SIZE_TOL_M: f64 = 0.0001;

/// A workpiece type: one kind of part to be piled and picked.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Workpiece {
    /// Short name (A ... F in the reference table).
    pub name: String,
    /// What electronic part this is.
    pub kind: String,
    /// Bounding box of the whole part (body and leads) in the part frame (m). Required for box
    /// and compound shapes; derived from the mesh for mesh shapes (absent reads as zeros).
    #[serde(default)]
    pub size_m: [f64; 3],
    /// Part mass (kg).
    pub mass_kg: f64,
    /// Coulomb friction coefficient against trays and other parts.
    pub friction: f64,
    /// Restitution coefficient.
    pub restitution: f64,
    /// Default number of parts in a pile.
    pub pile_count: u32,
    /// The cup this workpiece runs with, overriding the cell's `gripper` keys of the same name
    /// for this workpiece only (absent: the cell's cup; [`super::tool`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gripper: Option<super::CupConfig>,
    /// The hopper recipe this workpiece runs with, overriding the cell's `feeder` keys of the
    /// same name for this workpiece only (absent: the cell's; [`super::feeder`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub feeder: Option<super::FeederRecipe>,
    /// The shake this workpiece runs with, overriding the cell's `agitation` keys of the same
    /// name for this workpiece only (absent: the cell's; [`super::agitation`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agitation: Option<super::AgitationRecipe>,
    /// The sensor's scan mode this workpiece runs with: the cell's sensor at another of its
    /// resolutions over the same field of view, for this workpiece only (absent: the cell's;
    /// [`super::tool::ScanMode`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<super::ScanMode>,
    /// Collision shape.
    pub shape: ShapeConfig,
    /// Grasp hints.
    pub grasp: GraspHints,
    /// How recognition matches the part (`[recognition]`; absent: `method = "auto"`, which the
    /// resolved workpiece leaves out).
    #[serde(default, skip_serializing_if = "RecognitionHints::is_auto")]
    pub recognition: RecognitionHints,
}

/// The workpiece's `[recognition]` table.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RecognitionHints {
    /// `"faces"`, `"ppf"` or `"auto"` (the default).
    #[serde(default)]
    pub method: RecognitionMethod,
}

impl RecognitionHints {
    /// Whether the method is left to the part model.
    pub fn is_auto(&self) -> bool {
        self.method == RecognitionMethod::Auto
    }
}

/// How the cloud recognition matches the part.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RecognitionMethod {
    /// Planar patches of the cloud matched to the model's planar faces.
    Faces,
    /// Point-pair features of the model's surface voted for by the cloud.
    Ppf,
    /// Chosen from the part model: point-pair features for a mesh part without a planar face the
    /// face method matches, planar faces otherwise (and always for primitives).
    #[default]
    Auto,
}

/// Kinds of workpiece shape.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    /// The bounding box `size_m`.
    Box,
    /// A compound of boxes and cylinders (`parts`), e.g. a body with leads.
    Compound,
    /// A triangle mesh file (STL, OBJ or VRML 2.0), convex-decomposed for the physics.
    Mesh,
}

/// The units of a mesh file's coordinates.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
pub enum MeshUnits {
    /// Metres.
    #[serde(rename = "m")]
    M,
    /// Millimetres (most STL exports).
    #[serde(rename = "mm")]
    Mm,
    /// Inches.
    #[serde(rename = "inch")]
    Inch,
    /// KiCad's 3D-model VRML unit: 0.1 inch (2.54 mm).
    #[serde(rename = "kicad_vrml")]
    KicadVrml,
}

impl MeshUnits {
    /// Metres per file unit.
    pub fn metres_per_unit(self) -> f64 {
        match self {
            MeshUnits::M => 1.0,
            MeshUnits::Mm => 0.001,
            MeshUnits::Inch => 0.0254,
            MeshUnits::KicadVrml => 0.00254,
        }
    }

    /// The name as written in the file.
    pub fn name(self) -> &'static str {
        match self {
            MeshUnits::M => "m",
            MeshUnits::Mm => "mm",
            MeshUnits::Inch => "inch",
            MeshUnits::KicadVrml => "kicad_vrml",
        }
    }
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
    /// Mesh: the file's units (`"m"`, `"mm"`, `"inch"`, `"kicad_vrml"`); resolved into
    /// `mesh_scale` on load. Give this or `mesh_scale`, not both; neither means metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub units: Option<MeshUnits>,
    /// Mesh: scale from file units to metres, for units `units` does not name.
    #[serde(default)]
    pub mesh_scale: Option<f64>,
    /// Mesh: orders of rotational symmetry about the part's x, y, z axes through the centre of
    /// mass (1: none), overriding what is detected from the mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub symmetry_orders: Option<[u32; 3]>,
}

impl ShapeConfig {
    /// Metres per unit of the mesh file (1 when neither `units` nor `mesh_scale` is given), and
    /// the units' name for messages.
    pub fn mesh_units(&self) -> (f64, String) {
        match (self.units, self.mesh_scale) {
            (Some(u), _) => (u.metres_per_unit(), format!("shape.units = \"{}\"", u.name())),
            (None, Some(s)) => (s, format!("shape.mesh_scale = {s}")),
            (None, None) => (1.0, "metres (no shape.units)".into()),
        }
    }
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

/// One primitive of a compound shape.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ShapePart {
    /// Box or cylinder.
    pub primitive: Primitive,
    /// Body or lead.
    pub role: PartRole,
    /// Centre in the part frame (m).
    pub center_m: [f64; 3],
    /// Box: edge lengths (m).
    #[serde(default)]
    pub size_m: Option<[f64; 3]>,
    /// Cylinder: radius (m).
    #[serde(default)]
    pub radius_m: Option<f64>,
    /// Cylinder: length (m).
    #[serde(default)]
    pub length_m: Option<f64>,
    /// Cylinder: axis.
    #[serde(default)]
    pub axis: Option<Axis>,
}

impl ShapePart {
    /// Half extents of the primitive's axis-aligned bounding box (m).
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

impl Workpiece {
    /// The primitives of a box or compound workpiece as one closed mesh, one shell per primitive
    /// (cylinders as the physics' prisms); `None` for a mesh workpiece, whose surface lives in its
    /// file. For validated workpieces.
    pub fn primitive_mesh(&self) -> Option<crate::part::mesh::Mesh> {
        (self.shape.kind != ShapeKind::Mesh)
            .then(|| crate::part::tessellate::pieces_mesh(self.pieces().iter().map(|(_, p)| p)))
    }

    /// The rotational symmetry a workpiece declares, as orders about its x, y, z axes: the
    /// file's `shape.symmetry_orders`; else, for a compound, the turns about z its
    /// `grasp.yaw_symmetry_deg` steps through, or any turn about z when its body has a cylinder
    /// along z (its leads and bases break the symmetry the mesh would show only where the file
    /// says they matter). `None`: detected from the mesh (a box's own turns, a CAD part's).
    pub fn declared_symmetry_orders(&self) -> Option<[u32; 3]> {
        use crate::part::symmetry::MAX_ORDER;
        if self.shape.symmetry_orders.is_some() || self.shape.kind != ShapeKind::Compound {
            return self.shape.symmetry_orders;
        }
        let round = self
            .pieces()
            .iter()
            .any(|(role, p)| *role == PartRole::Body && matches!(p, Piece::Cylinder { axis: Axis::Z, .. }));
        let step_deg = self.grasp.yaw_symmetry_deg;
        let about_z = if round {
            MAX_ORDER
        } else if step_deg > 0.0 {
            ((360.0 / step_deg).round().max(1.0) as u32).min(MAX_ORDER)
        } else {
            1
        };
        Some([1, 1, about_z])
    }

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
    /// The part looks the same after this yaw about its top face normal (deg)
    /// (90 for a square top, 180 for a rectangle, 360 for none, 0 for a round top: any yaw).
    pub yaw_symmetry_deg: f64,
    /// Yaw of the part's x axis in its place slot, relative to the slot (deg).
    pub place_yaw_deg: f64,
    /// Smallest margin between cup edge and face edge that still seals (m).
    pub face_margin_m: f64,
    /// Which way up the part may lie in its slot (`any` when left out).
    #[serde(default)]
    pub place_orientation: PlaceOrientation,
}

/// Which way up a placed part may lie in its slot.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PlaceOrientation {
    /// Any of its stable poses: each grasped face is placed up, in the stable pose that has it
    /// up (a relay may land on its back, its top or a side).
    #[default]
    Any,
    /// Only resting on the part frame's -z side, as the file's frame stands it (a relay or a DIP
    /// on its pins, a can on its base), as a tray's pockets, a tape or the next machine need it:
    /// the faces that would place the part another way up are not grasped.
    Upright,
}

impl Workpiece {
    /// Checks every value of the workpiece on its own.
    pub fn validate(&self, file: &str) -> Result<(), ConfigError> {
        let mut c = Checker::new(file);
        if self.name.trim().is_empty() {
            c.fail("name", "must not be empty");
        }
        if self.shape.kind != ShapeKind::Mesh && self.size_m == [0.0; 3] {
            c.fail(
                "size_m",
                format!(
                    "is required when shape.kind = \"{}\"",
                    match self.shape.kind {
                        ShapeKind::Box => "box",
                        _ => "compound",
                    }
                ),
            );
        } else if self.size_m != [0.0; 3] {
            c.positive_all("size_m", &self.size_m);
        }
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
        self.shape.validate(&mut c, &self.size_m);
        if let Some(cup) = &self.gripper {
            cup.check(&mut c);
        }
        if let Some(recipe) = &self.feeder {
            recipe.check(&mut c);
        }
        if let Some(shake) = &self.agitation {
            shake.check(&mut c);
        }
        if let Some(mode) = &self.sensor {
            mode.check(&mut c);
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

    /// Edge lengths of the body's bounding box (without leads) (m).
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

    /// Checks that the workpiece fits the scene: it fits in both trays, and the gripper's cup (its
    /// own, if it brings one) fits on at least one face of the body. A cup it brings must also
    /// agree with the cell's cycle (the valve leads within its build-up and release times).
    pub fn check_fits_scene(&self, file: &str, scene: &Scene) -> Result<(), ConfigError> {
        let mut c = Checker::new(file);
        if let Some(mode) = &self.sensor
            && !mode.keeps_field_of_view(&scene.sensor)
        {
            let [w, h] = scene.sensor.resolution_px;
            let r = mode.resolution_px.unwrap_or(scene.sensor.resolution_px);
            c.fail(
                "sensor.resolution_px",
                format!(
                    "must scale the cell's {w} x {h} image alike along both axes (the same field of view): got {r:?}, {:.3} times as wide and {:.3} times as high",
                    mode.scale(&scene.sensor),
                    f64::from(r[1]) / f64::from(h.max(1)),
                ),
            );
        }
        // The cell as it runs this workpiece (its cup, recipes and scan mode in place), checked
        // as a whole where the workpiece changed it.
        let resolved = scene.set_up_for(self);
        if resolved != *scene
            && let Err(e) = resolved.validate(file)
        {
            // The sections this workpiece brings.
            let brought: Vec<&str> = [
                ("gripper", self.gripper.is_some()),
                ("feeder", self.feeder.is_some()),
                ("agitation", self.agitation.is_some()),
                ("sensor", self.sensor.is_some()),
            ]
            .into_iter()
            .filter_map(|(name, given)| given.then_some(name))
            .collect();
            for p in e.problems {
                // The cell's check of a key in a section this workpiece brings names that
                // section; a check across sections (the cycle's release lead against the cup)
                // the cup, if it brings one, else every section it brings.
                let section = p.key.split('.').next().unwrap_or_default();
                let what = if brought.contains(&section) {
                    section.to_string()
                } else if brought.contains(&"gripper") {
                    "gripper".to_string()
                } else {
                    brought.join(", ")
                };
                c.fail(&p.key, format!("{} (with this workpiece's {what})", p.message));
            }
        }
        let scene = &resolved;
        // Lying flat, the part's two longest edges must fit the tray's inner floor.
        let mut dims = self.size_m;
        dims.sort_by(|a, b| b.total_cmp(a));
        let [tx, ty] = scene.pick_tray.inner_size_m;
        let (tray_long, tray_short) = (tx.max(ty), tx.min(ty));
        if dims[0] > tray_long || dims[1] > tray_short {
            let from_mesh = match (&self.shape.kind, &self.shape.mesh_file) {
                (ShapeKind::Mesh, Some(f)) => format!(
                    " (derived from the mesh {f} read in {}: check shape.units)",
                    self.shape.mesh_units().1
                ),
                _ => String::new(),
            };
            c.fail(
                "size_m",
                format!(
                    "is larger than the pick tray: a part of {} x {} m lying flat does not fit its {tx} x {ty} m inner floor{from_mesh}",
                    dims[0], dims[1]
                ),
            );
        }
        // A mesh's faces are its own, not its bounding box's: the part model checks them (and
        // `binpick check` warns when none takes the cup).
        let cup = scene.gripper.cup_diameter_m + 2.0 * self.grasp.face_margin_m;
        let faces = self.body_faces_m();
        if self.shape.kind != ShapeKind::Mesh && !faces.iter().any(|(_, [a, b])| a.min(*b) >= cup) {
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
        if scene.place_tray.pattern == SlotPattern::Grid
            && let Some((key, pitch, extent)) = scene.place_tray.pitch_below_footprint(footprint)
        {
            c.fail(
                key,
                format!(
                    "(the cell's) must not be below this part's place footprint, {extent} m along it (the parts would overlap), got {pitch}"
                ),
            );
        }
        let slots = scene.place_tray.slot_count(footprint);
        if scene.place_tray.pattern == SlotPattern::Grid && slots > MAX_PLACE_SLOTS {
            c.fail(
                "size_m",
                format!(
                    "gives {slots} placement slots in the place tray (inner {:?} m, gap {:?} m), more than {MAX_PLACE_SLOTS}: check the units",
                    scene.place_tray.tray.inner_size_m, scene.place_tray.gap_m
                ),
            );
        } else if scene.place_tray.slots_in_tray(footprint).is_empty() {
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

impl ShapeConfig {
    /// The shape's keys: those of its kind present and valid, those of other kinds absent.
    fn validate(&self, c: &mut Checker, size_m: &[f64; 3]) {
        if self.kind != ShapeKind::Mesh {
            for (key, given) in [
                ("shape.units", self.units.is_some()),
                ("shape.mesh_scale", self.mesh_scale.is_some()),
                ("shape.symmetry_orders", self.symmetry_orders.is_some()),
            ] {
                if given {
                    c.fail(key, "is only allowed when kind = \"mesh\"");
                }
            }
        }
        match self.kind {
            ShapeKind::Box => {
                if !self.parts.is_empty() {
                    c.fail("shape.parts", "is only allowed when kind = \"compound\"");
                }
                if self.mesh_file.is_some() {
                    c.fail("shape.mesh_file", "is only allowed when kind = \"mesh\"");
                }
            }
            ShapeKind::Compound => self.validate_compound(c, size_m),
            ShapeKind::Mesh => self.validate_mesh(c),
        }
    }

    /// A compound: at least one part, a body among them, each part valid and inside the
    /// bounding box `size_m`.
    fn validate_compound(&self, c: &mut Checker, size_m: &[f64; 3]) {
        if self.parts.is_empty() {
            c.fail(
                "shape.parts",
                "must list at least one primitive when kind = \"compound\"",
            );
        }
        if !self.parts.iter().any(|p| p.role == PartRole::Body) {
            c.fail("shape.parts", "must contain at least one part with role = \"body\"");
        }
        let half_size_m = size_m.map(|s| s / 2.0);
        for (i, p) in self.parts.iter().enumerate() {
            p.validate(c, i, &half_size_m);
        }
    }

    /// A mesh: a mesh file of a format read, a positive scale or units (not both), symmetry
    /// orders in range.
    fn validate_mesh(&self, c: &mut Checker) {
        match &self.mesh_file {
            None => c.fail("shape.mesh_file", "is required when kind = \"mesh\""),
            Some(f) if crate::part::import::Format::of(std::path::Path::new(f)).is_none() => c.fail(
                "shape.mesh_file",
                format!("must be an .stl, .obj or .wrl (VRML 2.0) file, got {f:?}"),
            ),
            _ => {}
        }
        if let Some(s) = self.mesh_scale {
            c.positive("shape.mesh_scale", s);
            if self.units.is_some() {
                c.fail("shape.mesh_scale", "must not be given with shape.units (give one)");
            }
        }
        if let Some(o) = self.symmetry_orders {
            for (a, n) in o.iter().enumerate() {
                if !(1..=crate::part::symmetry::MAX_ORDER).contains(n) {
                    c.fail(
                        &format!("shape.symmetry_orders[{a}]"),
                        format!("must be within [1, {}], got {n}", crate::part::symmetry::MAX_ORDER),
                    );
                }
            }
        }
    }
}

impl ShapePart {
    /// Part `i` of a compound: its primitive's dimensions given and positive, and inside the
    /// bounding box of half size `half_size_m`.
    fn validate(&self, c: &mut Checker, i: usize, half_size_m: &[f64; 3]) {
        let k = format!("shape.parts[{i}]");
        c.finite_all(&format!("{k}.center_m"), &self.center_m);
        match self.primitive {
            Primitive::Box => match self.size_m {
                Some(s) => c.positive_all(&format!("{k}.size_m"), &s),
                None => c.fail(&format!("{k}.size_m"), "is required for a box"),
            },
            Primitive::Cylinder => {
                match self.radius_m {
                    Some(r) => c.positive(&format!("{k}.radius_m"), r),
                    None => c.fail(&format!("{k}.radius_m"), "is required for a cylinder"),
                }
                match self.length_m {
                    Some(l) => c.positive(&format!("{k}.length_m"), l),
                    None => c.fail(&format!("{k}.length_m"), "is required for a cylinder"),
                }
                if self.axis.is_none() {
                    c.fail(&format!("{k}.axis"), "is required for a cylinder");
                }
            }
        }
        if let Some(he) = self.half_extents_m() {
            for a in 0..3 {
                let (lo, hi) = (self.center_m[a] - he[a], self.center_m[a] + he[a]);
                if lo < -half_size_m[a] - 1e-9 || hi > half_size_m[a] + 1e-9 {
                    c.fail(
                        &k,
                        format!(
                            "sticks out of the bounding box size_m along axis {a}: spans [{lo:.4}, {hi:.4}], box is ±{:.4}",
                            half_size_m[a]
                        ),
                    );
                    break;
                }
            }
        }
    }
}
