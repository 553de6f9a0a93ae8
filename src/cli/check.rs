//! `binpick check FILE... [--scene S]`: validates scenes, workpieces and URDFs. A mesh workpiece's
//! mesh is read and repaired (or refused naming the defect), its part model derived, and a
//! warning printed when none of its faces takes the cell's cup (or its approach always meets
//! the part's own pins), when one that does seldom looks up in a resting pose, when turns its mesh
//! lacks look the same to the sensor, when none is up in an upright placement that asks for
//! one, or when the part lies too flat for the sensor to tell it from the tray floor. The
//! physics collider is built as a run builds it, so a part whose collider needs too many convex
//! pieces is refused here, not at its first run.

use std::path::{Path, PathBuf};

use anyhow::Result;

use binpick::config::{ConfigError, LoadedScene, LoadedWorkpiece, Source};
use binpick::robot::RobotModel;

pub fn check(files: &[PathBuf], scene_path: Option<&Path>) -> Result<()> {
    let mut problems = Vec::new();
    let reference_scene = match LoadedScene::load(scene_path) {
        Ok(s) => Some(s),
        Err(e) => {
            problems.extend(e.problems);
            None
        }
    };
    for f in files {
        match check_one(f, reference_scene.as_ref()) {
            Ok(what) => println!(
                "{}",
                binpick::report::wrap(
                    &format!("ok: {} ({what})", f.display()),
                    binpick::results::table::TERMINAL_WIDTH
                )
            ),
            Err(e) => problems.extend(e.problems),
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(ConfigError { problems }.into())
    }
}

fn check_one(path: &Path, reference: Option<&LoadedScene>) -> Result<String, ConfigError> {
    let label = path.display().to_string();
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    match ext {
        "urdf" => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| ConfigError::one(&label, "", format!("cannot read file: {e}")))?;
            let base = LoadedScene::embedded_default()?;
            let robot = RobotModel::from_urdf(&label, &text, &base.scene.robot, &base.scene.gripper)?;
            Ok(format!(
                "URDF: robot {:?}, {} joints, {:.2} kg moving",
                robot.name,
                robot.joints.len(),
                robot.moving_mass_kg()
            ))
        }
        "toml" => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| ConfigError::one(&label, "", format!("cannot read file: {e}")))?;
            let table: toml::Table = binpick::config::parse_toml(&label, &text)?;
            if table.contains_key("robot") {
                let scene = LoadedScene::from_text(&label, Source::File(path.to_path_buf()), &text)?;
                let robot = RobotModel::from_scene(&scene)?;
                robot.check_scene_reach(&label, &scene.scene)?;
                Ok(format!(
                    "scene {:?}: robot {:?}, trays reachable, sensor sees the pick tray",
                    scene.scene.name, robot.name
                ))
            } else {
                let wp = LoadedWorkpiece::from_text(&label, Source::File(path.to_path_buf()), &text)?;
                // The collider every run builds (a mesh's convex decomposition, kept on disk for
                // the runs that follow): what it refuses, a run would refuse.
                binpick::physics::PartShape::build(&wp.workpiece, &wp.source)
                    .map_err(|e| ConfigError::one(&label, "shape", e.to_string()))?;
                if let Some(s) = reference {
                    wp.workpiece.check_fits_scene(&label, &s.scene)?;
                    // Its part model derives, and the warnings where it will not be picked well.
                    let scene = s.scene.set_up_for(&wp.workpiece);
                    let m = super::part::model_of(&wp, &scene)?;
                    // Where the grasp selector puts the cup on each face.
                    let sites = m.cup_sites(&binpick::grasp::approach_column(&scene));
                    let turns = super::part::look_alikes(&m, &scene);
                    for why in super::part::warnings(&m, &wp.workpiece, &scene, &sites, &turns) {
                        let text = format!("warning: {label}: {why}");
                        eprintln!(
                            "{}",
                            binpick::report::wrap(&text, binpick::results::table::TERMINAL_WIDTH)
                        );
                    }
                }
                let mesh = match &wp.mesh {
                    Some(m) => {
                        let r = &m.1;
                        format!(
                            "; mesh of {} triangles in {} {}, {:.2} x {:.2} x {:.2} mm; repaired: {} vertices welded, {} zero-area, {} duplicate and {} inner-wall triangles dropped, {} T-junctions split, {} triangles and {} bodies flipped, {} holes closed",
                            m.0.triangles.len(),
                            r.bodies,
                            if r.bodies == 1 { "body" } else { "bodies" },
                            wp.workpiece.size_m[0] * 1e3,
                            wp.workpiece.size_m[1] * 1e3,
                            wp.workpiece.size_m[2] * 1e3,
                            r.welded_vertices,
                            r.zero_area_triangles,
                            r.duplicate_triangles,
                            2 * r.inner_wall_pairs,
                            r.t_junctions_split,
                            r.flipped_triangles,
                            r.flipped_bodies,
                            r.holes_closed
                        )
                    }
                    None => String::new(),
                };
                Ok(format!(
                    "workpiece {:?}: {}{mesh}",
                    wp.workpiece.name, wp.workpiece.kind
                ))
            }
        }
        _ => Err(ConfigError::one(
            &label,
            "",
            "is neither a .toml (scene or workpiece) nor a .urdf file",
        )),
    }
}
