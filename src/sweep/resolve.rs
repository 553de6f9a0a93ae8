//! A sweep's variants resolved and checked, before anything runs.
//!
//! Job: apply each variant's `--set` values to the parsed TOML tree of the cell file (and of each
//! workpiece file), then deserialise and validate the tree exactly as the file would be (an
//! unknown key or a value of the wrong type is refused naming the key), build the arm, and run the
//! checks `binpick check` and `batch` run: the trays within reach, each workpiece fitting the
//! pick tray, the cup and the place tray, its shape building. The first variant refused stops the
//! sweep; its error names the variant, the key and the value. Variants whose arm and hand are the
//! same share one arm model; every run of a variant shares its resolved files.
//!
//! Units: the files' own. Frames: none.

use std::path::Path;

use super::{Segment, SetArg, Target, value_text};
use crate::config::{ConfigError, LoadedScene, LoadedWorkpiece, scene_text, workpiece_text};
use crate::robot::RobotModel;
use crate::study::{Resolved, StudyError, Variant};

/// Sets `path` in `table` to `value`: missing tables on the way are created (an unknown key is
/// then refused by the strict deserialisation, as in a file); an index must name an element.
pub fn set_in(table: &mut toml::Table, path: &[Segment], value: toml::Value) -> Result<(), String> {
    fn walk(slot: &mut toml::Value, path: &[Segment], value: toml::Value, at: &str) -> Result<(), String> {
        let Some((first, rest)) = path.split_first() else {
            *slot = value;
            return Ok(());
        };
        match first {
            Segment::Key(k) => {
                let here = format!("{at}{}{k}", if at.is_empty() { "" } else { "." });
                let t = slot
                    .as_table_mut()
                    .ok_or_else(|| format!("{at} is not a table, so it has no key {k}"))?;
                if rest.is_empty() {
                    t.insert(k.clone(), value);
                    return Ok(());
                }
                let next = t
                    .entry(k.clone())
                    .or_insert_with(|| toml::Value::Table(toml::Table::new()));
                walk(next, rest, value, &here)
            }
            Segment::Index(i) => {
                let a = slot
                    .as_array_mut()
                    .ok_or_else(|| format!("{at} is not an array, so it has no element [{i}]"))?;
                let len = a.len();
                let next = a
                    .get_mut(*i)
                    .ok_or_else(|| format!("{at} has {len} elements, so no element [{i}]"))?;
                walk(next, rest, value, &format!("{at}[{i}]"))
            }
        }
    }
    let mut root = toml::Value::Table(std::mem::take(table));
    let r = walk(&mut root, path, value, "");
    if let toml::Value::Table(t) = root {
        *table = t;
    }
    r
}

/// The label a variant's files carry in messages: the file, then the variant's values.
fn variant_label(file: &str, index: usize, sets: &[SetArg], values: &[toml::Value]) -> String {
    let vals = sets
        .iter()
        .zip(values)
        .map(|(s, v)| format!("{}={}", s.key, value_text(v)))
        .collect::<Vec<_>>()
        .join(", ");
    format!("{file} (sweep variant {}: {vals})", index + 1)
}

/// Parses a file's text into its TOML tree (a malformed file is refused as `check` would).
fn tree(label: &str, text: &str) -> Result<toml::Table, ConfigError> {
    crate::config::parse_toml(label, text)
}

/// Resolves and checks every variant. `workpieces` are the `--workpieces` arguments (names or
/// paths); `values` each variant's values in `sets` order (see [`super::variants`]).
pub fn resolve(
    scene: Option<&Path>,
    workpieces: &[String],
    sets: &[SetArg],
    values: &[Vec<toml::Value>],
) -> Result<Resolved, StudyError> {
    let (scene_label, scene_source, text) = scene_text(scene)?;
    let scene_tree = tree(&scene_label, &text)?;
    let mut wp_trees = Vec::new();
    for w in workpieces {
        let (label, source, text) = workpiece_text(w)?;
        let t = tree(&label, &text)?;
        wp_trees.push((label, source, t));
    }
    let mut robots: Vec<(LoadedScene, RobotModel)> = Vec::new();
    let mut out = Vec::new();
    for (i, vals) in values.iter().enumerate() {
        let label = variant_label(&scene_label, i, sets, vals);
        let mut t = scene_tree.clone();
        for (s, v) in sets.iter().zip(vals).filter(|(s, _)| s.target == Target::Cell) {
            set_in(&mut t, &s.path, v.clone()).map_err(|m| ConfigError::one(&label, &s.key, m))?;
        }
        let loaded = LoadedScene::from_table(&label, scene_source.clone(), t)?;
        // The arm depends on the URDF, the robot section and the gripper only.
        let same_arm = robots.iter().position(|(s, _)| {
            s.urdf_text == loaded.urdf_text
                && s.scene.robot == loaded.scene.robot
                && s.scene.gripper == loaded.scene.gripper
        });
        let robot = match same_arm {
            Some(r) => r,
            None => {
                let model = RobotModel::from_scene(&loaded)?;
                robots.push((loaded.clone(), model));
                robots.len() - 1
            }
        };
        robots[robot].1.check_scene_reach(&label, &loaded.scene)?;
        let mut wps: Vec<LoadedWorkpiece> = Vec::new();
        for (wlabel, source, wtree) in &wp_trees {
            let wl = variant_label(wlabel, i, sets, vals);
            let mut t = wtree.clone();
            for (s, v) in sets.iter().zip(vals).filter(|(s, _)| s.target == Target::Workpiece) {
                set_in(&mut t, &s.path, v.clone()).map_err(|m| ConfigError::one(&wl, &s.key, m))?;
            }
            // A cell's gripper, feeder, agitation or sensor key that the workpiece's own
            // `[gripper]`, `[feeder]`, `[agitation]` or `[sensor]` sets would vary nothing for
            // it: refused, so that a study never reports variants that are the same cell.
            for s in sets.iter().filter(|s| s.target == Target::Cell) {
                if let [Segment::Key(g), Segment::Key(k), ..] = s.path.as_slice()
                    && ["gripper", "feeder", "agitation", "sensor"].contains(&g.as_str())
                    && wtree
                        .get(g.as_str())
                        .and_then(|v| v.as_table())
                        .is_some_and(|t| t.contains_key(k))
                {
                    return Err(ConfigError::one(
                        &wl,
                        &s.key,
                        format!(
                            "does not reach this workpiece: its file brings its own {g}.{k} (its [{g}] \
                             section), which the cell's does not override; vary workpiece.{g}.{k} instead"
                        ),
                    )
                    .into());
                }
            }
            let wp = LoadedWorkpiece::from_table(&wl, source.clone(), t)?;
            wp.workpiece.check_fits_scene(&wl, &loaded.scene)?;
            let shape = crate::physics::PartShape::build(&wp.workpiece, &wp.source)
                .map_err(|e| ConfigError::one(&wl, "shape", e.to_string()))?;
            crate::cycle::check_waiting_pose(&label, &loaded.scene, &robots[robot].1, &shape)?;
            if wps.iter().any(|w| w.workpiece.name == wp.workpiece.name) {
                return Err(StudyError::Input(format!(
                    "--workpieces: {} appears twice",
                    wp.workpiece.name
                )));
            }
            wps.push(wp);
        }
        out.push(Variant {
            values: vals.clone(),
            scene: loaded,
            robot,
            workpieces: wps,
        });
    }
    Ok(Resolved {
        variants: out,
        robots: robots.into_iter().map(|(_, r)| r).collect(),
        scene_label,
    })
}

#[cfg(test)]
mod tests {
    use super::super::{parse_sets, variants};
    use super::*;

    fn run(sets: &[&str]) -> Result<Resolved, StudyError> {
        let sets = parse_sets(&sets.iter().map(|s| s.to_string()).collect::<Vec<_>>()).unwrap();
        resolve(None, &["A".into(), "E".into()], &sets, &variants(&sets))
    }

    #[test]
    fn values_reach_the_cell_and_the_workpieces_and_the_arm_is_shared() {
        let r = run(&["sensor.latency_s=0.3,0.7", "workpiece.grasp.face_margin_m=0.0002"]).unwrap();
        assert_eq!(r.variants.len(), 2);
        assert_eq!(r.robots.len(), 1);
        assert_eq!(r.variants[1].scene.scene.sensor.latency_s, 0.7);
        assert_eq!(r.variants[0].workpieces[1].workpiece.grasp.face_margin_m, 0.0002);
        assert!(
            r.variants[0]
                .scene
                .label
                .contains("sweep variant 1: sensor.latency_s=0.3")
        );
        // A heavier hand is another arm model.
        let r = run(&["gripper.mass_kg=0.6,0.8"]).unwrap();
        assert_eq!(r.robots.len(), 2);
    }

    #[test]
    fn refused_variants_name_the_variant_the_key_and_the_value() {
        let e = |sets: &[&str]| run(sets).unwrap_err().to_string();
        let m = e(&["sensor.latency_ms=1"]);
        assert!(
            m.contains("sensor.latency_ms=1") && m.contains("unknown field `latency_ms`"),
            "{m}"
        );
        let m = e(&["sensor.latency_s=0.3,fast"]);
        assert!(
            m.contains("variant 2: sensor.latency_s=fast") && m.contains("invalid type"),
            "{m}"
        );
        // A and E bring their own cups: the cell's key would not reach them, and is refused.
        let m = e(&["gripper.cup_diameter_m=0.005,0.007"]);
        assert!(
            m.contains("A.toml (sweep variant 1: gripper.cup_diameter_m=0.005)")
                && m.contains("does not reach this workpiece")
                && m.contains("vary workpiece.gripper.cup_diameter_m instead"),
            "{m}"
        );
        // Negative control: C runs with the cell's cup, so the same key reaches it.
        let sets = parse_sets(&["gripper.cup_diameter_m=0.005,0.007".to_string()]).unwrap();
        assert!(resolve(None, &["C".into()], &sets, &variants(&sets)).is_ok());
        // The workpiece's key is the one that reaches A and E.
        let m = e(&["workpiece.gripper.cup_diameter_m=0.006,0.04"]);
        assert!(
            m.contains("cup_diameter_m=0.04") && m.contains("no face the suction cup fits on"),
            "{m}"
        );
        let m = e(&["place_tray.tray.center_m=[1.5, 0.0, 0.006]"]);
        assert!(m.contains("place_tray.tray is out of the arm's reach"), "{m}");
        let m = e(&["sensor.latency_s.x=1"]);
        assert!(m.contains("sensor.latency_s is not a table"), "{m}");
        let m = e(&["obstacles[9].size_m=[0.1, 0.1, 0.1]"]);
        assert!(m.contains("obstacles has 3 elements"), "{m}");
    }
}
