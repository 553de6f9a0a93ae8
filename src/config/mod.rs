//! Cell configuration: the files a user writes, read, validated and loaded.
//!
//! Job: parse the strict TOML formats, validate every value, and report each problem with the
//! file, the key path and the bad value (`workpieces/C.toml: size_m[2] must be > 0, got -0.005`).
//! This module holds what both file kinds share: the error types ([`Problem`], [`ConfigError`]),
//! the [`Checker`] that collects problems, [`parse_toml`], the embedded files and the loaders
//! ([`LoadedScene`] with its URDF, [`LoadedWorkpiece`]). The formats themselves are in [`scene`]
//! (the cell; its checks beside it, in `scene_checks`) and [`workpiece`] (a kind of part); their
//! items are re-exported here.
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

pub mod agitation;
pub mod feeder;
pub mod model_error;
pub mod scene;
mod scene_checks;
pub mod tool;
pub mod workpiece;

pub use agitation::{AgitationConfig, AgitationRecipe};
pub use feeder::{FeederConfig, FeederRecipe};
pub use model_error::ModelErrorConfig;
pub use scene::*;
pub use tool::CupConfig;
pub use tool::ScanMode;
pub use workpiece::*;

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

    /// An image size (px, width and height): each side within [1, 8192] px (the cell's sensor's
    /// and a workpiece's scan mode's).
    pub fn resolution(&mut self, key: &str, resolution_px: &[u32; 2]) {
        for (i, v) in resolution_px.iter().enumerate() {
            if !(1..=8192).contains(v) {
                self.fail(&format!("{key}[{i}]"), format!("must be within [1, 8192], got {v}"));
            }
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

/// Deserialises strict TOML already parsed into a tree into `T`, reporting the key path of a bad
/// or unknown key (no line numbers: the tree may not come from one file's text).
pub fn from_toml_table<T: serde::de::DeserializeOwned>(file: &str, table: toml::Table) -> Result<T, ConfigError> {
    serde_path_to_error::deserialize(table).map_err(|e| {
        let path = e.path().to_string();
        let key = if path == "." { String::new() } else { path };
        ConfigError::one(file, &key, e.into_inner().message().trim().to_string())
    })
}

/// The text of a scene argument: the file's, or the embedded default cell's when `path` is `None`.
pub fn scene_text(path: Option<&Path>) -> Result<(String, Source, String), ConfigError> {
    match path {
        Some(p) => {
            let label = p.display().to_string();
            let text = read_text(&label, p)?;
            Ok((label, Source::File(p.to_path_buf()), text))
        }
        None => Ok((
            "embedded:default".into(),
            Source::Embedded,
            embedded::DEFAULT_SCENE.to_string(),
        )),
    }
}

/// The text of a workpiece argument as [`LoadedWorkpiece::resolve`] reads it: a path (contains
/// `/` or ends in `.toml`) from disk, a bare name (A ... F) the embedded file.
pub fn workpiece_text(arg: &str) -> Result<(String, Source, String), ConfigError> {
    if arg.contains('/') || arg.ends_with(".toml") {
        let p = Path::new(arg);
        let label = p.display().to_string();
        let text = read_text(&label, p)?;
        return Ok((label, Source::File(p.to_path_buf()), text));
    }
    match embedded::WORKPIECES.iter().find(|(n, _)| n.eq_ignore_ascii_case(arg)) {
        Some((n, text)) => Ok((
            format!("embedded:workpieces/{n}.toml"),
            Source::Embedded,
            text.to_string(),
        )),
        None => Err(ConfigError::one(
            "--workpiece",
            "",
            format!("names no built-in workpiece (A, B, C, D, E, F) and is not a .toml path, got {arg:?}"),
        )),
    }
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
    pub const DEFAULT_SCENE: &str = include_str!("../../scenes/default.toml");
    /// The Viper s650 URDF (`scenes/viper_s650.urdf`).
    pub const VIPER_S650_URDF: &str = include_str!("../../scenes/viper_s650.urdf");
    /// The six workpieces of the reference system's takt table, by name.
    pub const WORKPIECES: [(&str, &str); 6] = [
        ("A", include_str!("../../workpieces/A.toml")),
        ("B", include_str!("../../workpieces/B.toml")),
        ("C", include_str!("../../workpieces/C.toml")),
        ("D", include_str!("../../workpieces/D.toml")),
        ("E", include_str!("../../workpieces/E.toml")),
        ("F", include_str!("../../workpieces/F.toml")),
    ];

    /// An embedded file that a scene may refer to by its bare name.
    pub fn file(name: &str) -> Option<&'static str> {
        match name {
            "viper_s650.urdf" => Some(VIPER_S650_URDF),
            _ => None,
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
        Self::from_scene(label, source, scene)
    }

    /// Deserialises and validates a scene from its parsed TOML tree (e.g. a cell file with keys
    /// changed by `binpick sweep --set`), exactly as [`Self::from_text`] would the same file:
    /// an unknown key or a value of the wrong type is refused naming the key.
    pub fn from_table(label: &str, source: Source, table: toml::Table) -> Result<Self, ConfigError> {
        let scene: Scene = from_toml_table(label, table)?;
        Self::from_scene(label, source, scene)
    }

    /// Validates a parsed scene and resolves and reads the URDF it names.
    fn from_scene(label: &str, source: Source, scene: Scene) -> Result<Self, ConfigError> {
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

    /// The cell as it runs `wp`: with the cup and the hopper recipe `wp` brings in place of the
    /// cell's ([`Scene::set_up_for`]); the same cell when it brings neither.
    pub fn for_workpiece(&self, wp: &LoadedWorkpiece) -> LoadedScene {
        LoadedScene {
            scene: self.scene.set_up_for(&wp.workpiece),
            ..self.clone()
        }
    }
}

impl Workpiece {
    /// A mesh workpiece's mesh, read from the file its `shape.mesh_file` names (relative to the
    /// workpiece file's folder) in its `shape.units`, and repaired into a closed solid in metres
    /// about its bounding box's centre (the part frame), with what the repair did; `None` for
    /// primitives and for embedded workpieces (which name no file on disk). The one loader every
    /// stage uses ([`crate::part::load_mesh`] behind it).
    pub fn repaired_mesh(
        &self,
        source: &Source,
    ) -> Result<Option<(crate::part::mesh::Mesh, crate::part::repair::RepairReport)>, crate::part::MeshError> {
        let (ShapeKind::Mesh, Source::File(p), Some(f)) = (self.shape.kind, source, &self.shape.mesh_file) else {
            return Ok(None);
        };
        let path = p.parent().unwrap_or(Path::new(".")).join(f);
        let (scale, units) = self.shape.mesh_units();
        crate::part::load_mesh(&path, scale, &units).map(Some)
    }

    /// The part model of this workpiece's repaired `mesh` (m, part frame) for a cup of
    /// `cup_diameter_m` with the workpiece's face margin: its mass, and its symmetry as the file
    /// overrides it or as detected. The one derivation the sensor and the grasp selector share.
    pub fn part_model(
        &self,
        mesh: &crate::part::mesh::Mesh,
        cup_diameter_m: f64,
    ) -> Result<crate::part::PartModel, crate::part::model::ModelError> {
        let cup = crate::part::CupSpec {
            diameter_m: cup_diameter_m,
            face_margin_m: self.grasp.face_margin_m,
        };
        let symmetry = self
            .declared_symmetry_orders()
            .map(|orders| crate::part::symmetry::Symmetry { orders });
        crate::part::PartModel::derive(
            mesh.clone(),
            crate::part::mass::MassSpec::MassKg(self.mass_kg),
            cup,
            symmetry,
        )
    }
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
    /// A mesh workpiece's repaired mesh (m, part frame) and what its repair did; `None` for
    /// primitives and for embedded workpieces.
    pub mesh: Option<std::sync::Arc<(crate::part::mesh::Mesh, crate::part::repair::RepairReport)>>,
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
        Self::from_workpiece(label, source, workpiece)
    }

    /// Deserialises and validates a workpiece from its parsed TOML tree, as [`Self::from_text`]
    /// would the same file.
    pub fn from_table(label: &str, source: Source, table: toml::Table) -> Result<Self, ConfigError> {
        let workpiece: Workpiece = from_toml_table(label, table)?;
        Self::from_workpiece(label, source, workpiece)
    }

    /// Validates a parsed workpiece; a mesh workpiece's mesh is read and repaired
    /// ([`crate::part::load_mesh`]), its `size_m` derived from it (or a given one checked against
    /// it) and its `shape.units` resolved into `shape.mesh_scale`.
    fn from_workpiece(label: &str, source: Source, mut workpiece: Workpiece) -> Result<Self, ConfigError> {
        workpiece.validate(label)?;
        let mut mesh = None;
        if let (ShapeKind::Mesh, Source::File(p), Some(f)) = (workpiece.shape.kind, &source, &workpiece.shape.mesh_file)
        {
            let path = p.parent().unwrap_or(Path::new(".")).join(f);
            if !path.is_file() {
                return Err(ConfigError::one(
                    label,
                    "shape.mesh_file",
                    format!("names a file that does not exist: {}", path.display()),
                ));
            }
            let (scale, units) = workpiece.shape.mesh_units();
            let (m, report) = workpiece
                .repaired_mesh(&source)
                .map_err(|e| ConfigError::one(label, "shape.mesh_file", e.to_string()))?
                .ok_or_else(|| ConfigError::one(label, "shape.mesh_file", "is required when kind = \"mesh\""))?;
            let derived = m.extent_m();
            if workpiece.size_m != [0.0; 3]
                && let Some(a) = (0..3).find(|&a| (workpiece.size_m[a] - derived[a]).abs() > MESH_SIZE_TOL_M)
            {
                return Err(ConfigError::one(
                    label,
                    &format!("size_m[{a}]"),
                    format!(
                        "is {} m, but the mesh {} is {:.6} x {:.6} x {:.6} m (read in {units}): size_m is derived from the mesh, leave it out",
                        workpiece.size_m[a],
                        path.display(),
                        derived[0],
                        derived[1],
                        derived[2]
                    ),
                ));
            }
            workpiece.size_m = derived;
            workpiece.shape.mesh_scale = Some(scale);
            workpiece.shape.units = None;
            mesh = Some(std::sync::Arc::new((m, report)));
        }
        Ok(LoadedWorkpiece {
            label: label.to_string(),
            source,
            workpiece,
            mesh,
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

#[cfg(test)]
mod tests {
    use super::*;

    fn default_scene() -> Scene {
        LoadedScene::embedded_default().expect("embedded default scene").scene
    }

    #[test]
    fn slot_count_counts_the_slots_without_building_them() {
        let scene = default_scene();
        for wp in LoadedWorkpiece::all_embedded().unwrap() {
            let footprint = [wp.workpiece.size_m[0], wp.workpiece.size_m[1]];
            let n = scene.place_tray.slots_in_tray(footprint).len();
            assert!(n > 0);
            assert_eq!(scene.place_tray.slot_count(footprint), n as f64, "{}", wp.label);
        }
        // A part of micrometres in a grid without gaps: refused, not built.
        let mut scene = default_scene();
        scene.place_tray.gap_m = Some(0.0);
        let mut wp = LoadedWorkpiece::all_embedded().unwrap().remove(4).workpiece;
        wp.size_m = [1e-9, 1e-9, 0.01];
        assert!(scene.place_tray.slot_count([1e-9, 1e-9]) > 1e14);
        let e = wp.check_fits_scene("w.toml", &scene).unwrap_err().to_string();
        assert!(
            e.contains("w.toml: size_m gives 47999999800000000 placement slots"),
            "{e}"
        );
    }

    #[test]
    fn sensor_resolution_is_capped_by_pixel_count() {
        let mut scene = default_scene();
        scene.sensor.resolution_px = [2048, 2048];
        scene.validate("s.toml").unwrap();
        scene.sensor.resolution_px = [2049, 2048];
        let e = scene.validate("s.toml").unwrap_err().to_string();
        assert!(
            e.starts_with("s.toml: sensor.resolution_px must have at most 4194304 pixels"),
            "{e}"
        );
        scene.sensor.resolution_px = [4096, 1024];
        scene.validate("s.toml").unwrap();
    }
}
