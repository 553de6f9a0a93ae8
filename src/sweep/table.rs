//! A sweep's results: every run kept per variant, the table (one row per variant and workpiece,
//! the batch table's columns after the variant's values), as Markdown and CSV, and the merge of
//! a sweep's shards.
//!
//! Units: s, counts. Rows are variant-major, then in workpiece order as given.

use serde::{Deserialize, Serialize};

use super::{SweepError, SweepSpec};
use crate::batch::{Row, RunEntry};

/// One run of a sweep: the variant it ran and what a batch keeps of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepRun {
    /// Index into [`SweepSpec::variants`].
    pub variant: usize,
    /// The run's values, as a batch keeps them.
    pub run: RunEntry,
}

/// What `sweep.json` holds besides the table: the sweep, which shard, every run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SweepFile {
    /// binpick version.
    pub version: String,
    /// The whole sweep.
    pub spec: SweepSpec,
    /// This file's shard (K, N); (1, 1) for a whole sweep or a merge.
    pub shard: (usize, usize),
    /// Runs, in job order.
    pub runs: Vec<SweepRun>,
}

/// One row of the sweep table: a workpiece under one variant.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepRow {
    /// Index into [`SweepSpec::variants`] (0-based; tables print it 1-based).
    pub variant: usize,
    /// The variant's values, in key order.
    pub values: Vec<String>,
    /// 5th percentile of the takt (nearest rank) [s]: the lower edge of the charts' band.
    pub takt_p5_s: f64,
    /// The batch table's row over this variant's runs of the workpiece.
    pub row: Row,
}

/// The table: for each variant, one row per workpiece that has runs.
pub fn table(spec: &SweepSpec, runs: &[SweepRun]) -> Vec<SweepRow> {
    let mut rows = Vec::new();
    for (v, values) in spec.variants.iter().enumerate() {
        let entries: Vec<RunEntry> = runs.iter().filter(|r| r.variant == v).map(|r| r.run.clone()).collect();
        for row in crate::batch::table(&spec.workpieces, &entries) {
            let takts: Vec<f64> = entries
                .iter()
                .filter(|e| e.workpiece == row.workpiece)
                .flat_map(|e| e.takts_s.iter().copied())
                .collect();
            rows.push(SweepRow {
                variant: v,
                values: values.clone(),
                takt_p5_s: crate::stats::percentile_sorted(&crate::stats::sorted(&takts), 0.05),
                row,
            });
        }
    }
    rows
}

fn num(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "-".into()
    }
}

/// The table as Markdown: the figures a comparison reads first, one row per variant and
/// workpiece (the full batch columns are in `sweep.csv`).
pub fn markdown(spec: &SweepSpec, rows: &[SweepRow]) -> String {
    let mut md = String::from("| variant |");
    for k in &spec.keys {
        md += &format!(" `{k}` |");
    }
    md += " part | placed / attempts | success | takt mean [s] | p5 | p95 | reference [s] | motion floor [s] \
           | grasps sealed / attempted | sensor waits (mean s) | picks / capture | faults |\n|---:|";
    md += &"---|".repeat(spec.keys.len());
    md += "---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    for r in rows {
        let w = &r.row;
        md += &format!("| {} |", r.variant + 1);
        for v in &r.values {
            md += &format!(" {v} |");
        }
        let faults = w.protective_stops + w.collisions + w.drops + w.parts_lost;
        md += &format!(
            " {} | {}/{} | {} % | {} | {} | {} | {} | {} | {}/{} | {} ({}) | {} | {} |\n",
            w.workpiece,
            w.placed,
            w.attempts,
            num(100.0 * w.success_rate, 1),
            num(w.takt.mean_s, 3),
            num(r.takt_p5_s, 3),
            num(w.takt.p95_s, 3),
            w.reference_takt_s.map_or("-".into(), |t| num(t, 1)),
            num(w.motion_floor_s, 3),
            w.grasps.1,
            w.grasps.0,
            w.sensor_waits.0,
            num(w.sensor_waits.1, 3),
            num(w.picks_per_capture, 2),
            faults,
        );
    }
    md
}

/// Quotes a CSV field where it needs it (commas, quotes, line breaks).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The table as CSV (`sweep.csv`): `variant`, one column per key (named by the key), the batch
/// table's columns (`takt.csv`'s), then `takt_p5_s`.
pub fn csv(spec: &SweepSpec, rows: &[SweepRow]) -> String {
    let mut out = String::from("variant");
    for k in &spec.keys {
        out += &format!(",{}", csv_field(k));
    }
    out += &format!(",{},takt_p5_s\n", crate::batch::table::TAKT_CSV_HEADER.join(","));
    for r in rows {
        let body = crate::batch::csv(std::slice::from_ref(&r.row));
        let line = body.lines().nth(1).unwrap_or_default();
        out += &(r.variant + 1).to_string();
        for v in &r.values {
            out += &format!(",{}", csv_field(v));
        }
        let p5 = if r.takt_p5_s.is_finite() {
            format!("{:.6}", r.takt_p5_s)
        } else {
            String::new()
        };
        out += &format!(",{line},{p5}\n");
    }
    out
}

/// Joins the `sweep.json` of every shard of one sweep: the specs must agree, and together the
/// shards must cover each run exactly once. The runs come back in job order.
pub fn merge(files: &[(String, SweepFile)]) -> Result<SweepFile, SweepError> {
    let Some((first_path, first)) = files.first() else {
        return Err(SweepError::Input("merge: no shard results given".into()));
    };
    let mut runs: Vec<&SweepRun> = Vec::new();
    for (path, f) in files {
        if f.spec != first.spec {
            return Err(SweepError::Input(format!(
                "merge: {path} is from another sweep than {first_path} ({} vs {})",
                f.spec.name(),
                first.spec.name()
            )));
        }
        runs.extend(&f.runs);
    }
    let mut ordered = Vec::new();
    for (v, w, s) in first.spec.jobs() {
        let found: Vec<&&SweepRun> = runs
            .iter()
            .filter(|r| r.variant == v && r.run.workpiece == w && r.run.seed == s)
            .collect();
        match found.len() {
            1 => ordered.push((*found[0]).clone()),
            n => {
                return Err(SweepError::Input(format!(
                    "merge: run {w} seed {s} of variant {} ({}) is in {} of the shards given",
                    v + 1,
                    first.spec.describe(v),
                    if n == 0 { "none".to_string() } else { n.to_string() }
                )));
            }
        }
    }
    Ok(SweepFile {
        version: first.version.clone(),
        spec: first.spec.clone(),
        shard: (1, 1),
        runs: ordered,
    })
}
