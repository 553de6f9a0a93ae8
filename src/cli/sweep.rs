//! `binpick sweep`: the takt table over variants of the cell (`--set KEY=V1,V2,...`): a study
//! of several variants ([`super::study`]; `binpick merge` joins a sweep's shards as a batch's).
//!
//! Every variant is resolved and checked before anything runs or is written (exit 2 naming the
//! variant, the key and the value); the runs go in parallel with a progress bar; the folder
//! holds `sweep.md`, `sweep.csv`, `sweep.json`, `sweep.svg` and each variant's resolved files.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;

use super::OutArgs;
use super::study::{StudyArgs, finish, results_dir, study_error};
use binpick::config::{ShapeKind, Source};
use binpick::study::{Resolved, StudySpec};

/// Arguments of `binpick sweep`.
#[derive(Args)]
pub struct SweepArgs {
    /// A key of the cell file (`gripper.cup_diameter_m`) or, prefixed `workpiece.`, of every
    /// workpiece file (`workpiece.grasp.face_margin_m`), and its values in the file's types:
    /// `0.004,0.006`, a range `0.004:0.012:0.002`, arrays `[0.4,-0.2,0.006]`, words `oracle`.
    /// Repeat for more keys: the variants are the product of the lists.
    #[arg(long = "set", value_name = "KEY=V1,V2,...", required = true)]
    pub sets: Vec<String>,
    #[command(flatten)]
    pub study: StudyArgs,
    /// Scene file the variants start from (default: the embedded default cell).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    #[command(flatten)]
    pub out: OutArgs,
}

/// `binpick sweep`.
pub fn sweep(a: &SweepArgs) -> Result<()> {
    let study = a.study.checked()?;
    let sets = binpick::sweep::parse_sets(&a.sets).map_err(study_error)?;
    // Every variant is resolved and checked before anything runs or is written.
    let values = binpick::sweep::variants(&sets);
    let resolved =
        binpick::sweep::resolve(a.scene.as_deref(), &study.workpieces, &sets, &values).map_err(study_error)?;
    let spec = StudySpec {
        scene: resolved.scene_label.clone(),
        keys: sets.iter().map(|s| s.key.clone()).collect(),
        variants: values
            .iter()
            .map(|v| v.iter().map(binpick::sweep::value_text).collect())
            .collect(),
        workpieces: resolved.variants[0]
            .workpieces
            .iter()
            .map(|w| w.workpiece.name.clone())
            .collect(),
        seeds: study.seeds.clone(),
        picks: study.picks,
        deterministic: a.study.mode.deterministic,
    };
    let dir = results_dir(&a.out.out, &spec, study.shard)?;
    let (file, times) = super::study::run(&resolved, spec, &study, &dir, None)?;
    write_variants(&dir, &resolved)?;
    finish(
        dir,
        &file,
        &times,
        super::study::Finish {
            json: a.out.json,
            ..Default::default()
        },
    )
}

/// Each variant's resolved cell (with its URDF) and workpieces, in `variant-N/`, so a variant
/// re-runs on its own (`binpick batch --scene variant-N/scene.toml --workpieces variant-N/workpiece-A.toml`).
fn write_variants(dir: &binpick::report::RunDir, resolved: &Resolved) -> Result<()> {
    for (i, v) in resolved.variants.iter().enumerate() {
        write_variant(dir, &format!("variant-{}", i + 1), v)?;
    }
    Ok(())
}

/// One variant's resolved cell (with its URDF) and workpieces (with their meshes) in `sub/`.
pub fn write_variant(dir: &binpick::report::RunDir, sub: &str, v: &binpick::study::Variant) -> Result<()> {
    std::fs::create_dir_all(dir.path(sub)).with_context(|| dir.path(sub).display().to_string())?;
    let urdf_name = Path::new(&v.scene.scene.robot.urdf)
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "robot.urdf".into());
    let mut scene = v.scene.scene.clone();
    scene.robot.urdf = urdf_name.clone();
    let header = format!(
        "# binpick {}: resolved scene, from {}\n",
        env!("CARGO_PKG_VERSION"),
        v.scene.label
    );
    dir.write(&format!("{sub}/scene.toml"), header + &toml::to_string(&scene)?)?;
    dir.write(&format!("{sub}/{urdf_name}"), &v.scene.urdf_text)?;
    for wp in &v.workpieces {
        // A mesh goes beside the variant's workpiece file, which names it by its bare name; a
        // cup the workpiece brings is written in full.
        let mut wp = wp.with_set_up_completed(&v.scene.scene);
        if let (ShapeKind::Mesh, Source::File(p), Some(mesh)) = (
            wp.workpiece.shape.kind,
            &wp.source,
            wp.workpiece.shape.mesh_file.clone(),
        ) {
            let from = p.parent().unwrap_or(Path::new(".")).join(&mesh);
            let name = Path::new(&mesh)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or(mesh);
            dir.write(
                &format!("{sub}/{name}"),
                std::fs::read(&from).with_context(|| from.display().to_string())?,
            )?;
            wp.workpiece.shape.mesh_file = Some(name);
            wp.source = Source::Embedded;
        }
        dir.write_workpiece(&wp, &format!("{sub}/workpiece-{}.toml", wp.workpiece.name))?;
    }
    Ok(())
}
