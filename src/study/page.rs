//! A study's page: `report.html` of a batch or a sweep, from its result file and the files its
//! front end wrote ([`crate::report::html`] writes the page; a tune gives it its own pieces).
//!
//! Job: say what ran, take the tables (the study's Markdown) and the charts (its SVG files), find
//! each run's time charts and recordings in the folder ([`super::runner::run_stem`] names them)
//! and list the folder's other files.
//!
//! Units: none of its own.

use std::path::Path;

use super::{Outputs, StudyFile, runner::run_stem};
use crate::report::html::{Page, RunFiles, folder_files, page_html, run_files};

/// `report.html` of the study `file` whose files (`outputs`, and any others: inputs, recordings)
/// are in `dir`.
pub fn report_html(file: &StudyFile, outputs: &Outputs, dir: &Path) -> String {
    let spec = &file.spec;
    let several = spec.variants.len() > 1;
    let runs: Vec<RunFiles> = spec
        .jobs()
        .iter()
        .map(|job| {
            let label = if several {
                format!(
                    "variant {} ({}): {} seed {}",
                    job.variant + 1,
                    spec.describe(job.variant),
                    job.workpiece,
                    job.seed
                )
            } else {
                format!("{} seed {}", job.workpiece, job.seed)
            };
            run_files(dir, label, &run_stem(several, job))
        })
        .collect();
    let charts: Vec<(&str, &str)> = outputs
        .files
        .iter()
        .filter(|(name, _)| name.ends_with(".svg"))
        .map(|(name, text)| (*name, text.as_str()))
        .collect();
    let files = folder_files(dir, &runs);
    let (k, n) = file.shard;
    let shard = if n > 1 {
        format!(", shard {k} of {n}")
    } else {
        String::new()
    };
    let mode = if spec.deterministic {
        "deterministic compute budgets"
    } else {
        "measured compute"
    };
    let seeds = spec.seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", ");
    let variants = if several {
        format!(
            "{} variants of {} ({}) x ",
            spec.variants.len(),
            spec.scene,
            spec.keys.join(", ")
        )
    } else {
        String::new()
    };
    let about = format!(
        "{} runs{shard}: {variants}workpieces {} x seeds {seeds}, {} picks each, {mode}.",
        file.runs.len(),
        spec.workpieces.join(", "),
        spec.picks
    );
    let title = format!("binpick {}: {}", file.key(), spec.name());
    page_html(&Page {
        title: &title,
        about: &about,
        markdown: &outputs.markdown,
        charts: &charts,
        runs: &runs,
        files: &files,
    })
}
