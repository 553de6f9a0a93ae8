//! A sweep's results: the table (one row per variant and workpiece, the batch table's columns
//! after the variant's values), as Markdown and CSV, and the sweep's files.
//!
//! Units: s, counts. Rows are variant-major, then in workpiece order as given.

use serde::Serialize;
use serde_json::json;

use crate::results::Summary;
use crate::results::table::{KeyedRow, TERMINAL_WIDTH, aligned_keyed, num, pct};
use crate::study::{Outputs, StudyFile, StudySpec};

/// One row of the sweep table: a workpiece under one variant.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepRow {
    /// Index into [`StudySpec::variants`] (0-based; tables print it 1-based).
    pub variant: usize,
    /// The variant's values, in key order.
    pub values: Vec<String>,
    /// 5th percentile of the takt (nearest rank) (s): the lower edge of the charts' band.
    pub takt_p5_s: f64,
    /// The batch table's row over this variant's runs of the workpiece.
    pub row: Summary,
}

/// The table: for each variant, one row per workpiece that has runs.
pub fn table(file: &StudyFile) -> Vec<SweepRow> {
    let spec = &file.spec;
    let mut rows = Vec::new();
    for (v, values) in spec.variants.iter().enumerate() {
        let tallies = file.runs.iter().filter(|r| r.variant == v).map(|r| &r.tally);
        for row in crate::results::per_workpiece(&spec.workpieces, tallies) {
            rows.push(SweepRow {
                variant: v,
                values: values.clone(),
                takt_p5_s: row.takt_p5_s,
                row,
            });
        }
    }
    rows
}

/// The table as Markdown: the figures a comparison reads first, one row per variant and
/// workpiece (the full batch columns are in `sweep.csv`).
pub fn markdown(spec: &StudySpec, rows: &[SweepRow]) -> String {
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
        let f = w.tally.faults;
        let faults = f.protective_stops + f.collisions + f.drops + f.parts_lost;
        md += &format!(
            " {} | {}/{} | {} % | {} | {} | {} | {} | {} | {}/{} | {} ({}) | {} | {} |\n",
            w.tally.workpiece,
            w.tally.placed,
            w.tally.attempts,
            num(100.0 * w.success_rate, 1),
            num(w.takt.mean_s, 3),
            num(r.takt_p5_s, 3),
            num(w.takt.p95_s, 3),
            w.reference_takt_s.map_or("-".into(), |t| num(t, 1)),
            num(w.motion_floor_s, 3),
            w.tally.grasps.1,
            w.tally.grasps.0,
            w.tally.sensor_waits.count,
            num(w.tally.sensor_waits.mean_s(), 3),
            num(w.picks_per_capture, 2),
            faults,
        );
    }
    md + &notes(rows)
}

/// The notes under the table: why a row has no takt, and its incidents.
fn notes(rows: &[SweepRow]) -> String {
    let mut out = String::new();
    for r in rows {
        if let Some(why) = crate::results::table::no_takt_why(&r.row) {
            out += &format!("\nvariant {}, {why}\n", r.variant + 1);
        }
        let label = format!("variant {}, {}", r.variant + 1, r.row.tally.workpiece);
        out += &crate::results::table::incident_note(&label, &r.row);
    }
    out
}

/// The table as the terminal prints it, within [`TERMINAL_WIDTH`] where the values allow: the
/// variant, its values (a column per key; where those columns would not fit, the values are
/// listed above the table instead), part, success, takt mean and p95, the motion floor and
/// faults. Every column is in `sweep.md` and `sweep.csv`.
pub fn terminal(spec: &StudySpec, rows: &[SweepRow]) -> String {
    let figures = |r: &SweepRow| -> Vec<String> {
        let w = &r.row;
        vec![
            w.tally.workpiece.clone(),
            format!(
                "{} ({}/{})",
                pct(w.success_rate, 1),
                w.tally.placed_in_tolerance(),
                w.tally.attempts
            ),
            crate::results::table::takt_text(w, w.takt.mean_s),
            num(w.takt.p95_s, 3),
            num(w.motion_floor_s, 3),
            crate::results::table::faults(w).to_string(),
        ]
    };
    let tail = [
        ("part", false),
        ("success", true),
        ("takt [s]", true),
        ("p95", true),
        ("floor [s]", true),
        ("faults", true),
    ];
    let keys: Vec<(&str, bool)> = spec.keys.iter().map(|k| (k.as_str(), false)).collect();
    let keyed_rows: Vec<KeyedRow> = rows
        .iter()
        .map(|r| (vec![(r.variant + 1).to_string()], r.values.clone(), figures(r)))
        .collect();
    let (table, keyed) = aligned_keyed(&[("variant", true)], &keys, &tail, &keyed_rows);
    let table = if keyed {
        table
    } else {
        // Each variant's values above the table, those that run on under the first.
        let mut legend = String::new();
        for (v, values) in spec.variants.iter().enumerate() {
            let pairs: Vec<String> = spec
                .keys
                .iter()
                .zip(values)
                .map(|(k, x)| format!("{k} = {x}"))
                .collect();
            let head = format!("variant {}: ", v + 1);
            legend += &crate::report::wrap_under(&head, head.len(), &pairs.join(", "), TERMINAL_WIDTH);
        }
        legend + "\n" + &table
    };
    let notes: String = notes(rows)
        .lines()
        .map(|l| crate::report::wrap(l, TERMINAL_WIDTH) + "\n")
        .collect();
    table + &notes
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
pub fn csv(spec: &StudySpec, rows: &[SweepRow]) -> String {
    let mut out = String::from("variant");
    for k in &spec.keys {
        out += &format!(",{}", csv_field(k));
    }
    out += &format!(",{},takt_p5_s\n", crate::results::table::csv_header().join(","));
    for r in rows {
        let body = crate::results::table::csv(std::slice::from_ref(&r.row));
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

/// The sweep's files (`sweep.json`, `sweep.csv`, `sweep.md`, `sweep.svg`) and its table.
pub fn outputs(file: &StudyFile) -> Outputs {
    let rows = table(file);
    let table = json!(rows);
    let markdown = markdown(&file.spec, &rows);
    let doc = json!({"sweep": file.to_json(), "table": table});
    let files = vec![
        ("sweep.json", crate::report::pretty_json(&doc)),
        ("sweep.csv", csv(&file.spec, &rows)),
        ("sweep.md", markdown.clone()),
        ("sweep.svg", super::sweep_chart::sweep_svg(&file.spec, &rows)),
    ];
    Outputs { files, markdown, table }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A spec of `keys` (values `values` per variant) over workpiece E with one run each.
    fn rows_of(keys: &[&str], values: &[Vec<String>]) -> (StudySpec, Vec<SweepRow>) {
        let spec = StudySpec {
            scene: "s".into(),
            keys: keys.iter().map(|k| k.to_string()).collect(),
            variants: values.to_vec(),
            workpieces: vec!["E".into()],
            seeds: vec![1],
            picks: 3,
            deterministic: true,
        };
        let rows = (0..values.len())
            .flat_map(|v| {
                let tally = crate::cycle::Tally {
                    workpiece: "E".into(),
                    ..Default::default()
                };
                crate::results::per_workpiece(&spec.workpieces, std::iter::once(&tally))
                    .into_iter()
                    .map(move |row| SweepRow {
                        variant: v,
                        values: values[v].clone(),
                        takt_p5_s: f64::NAN,
                        row,
                    })
            })
            .collect();
        (spec, rows)
    }

    /// Short keys get a column each; keys whose columns would not fit in the terminal's width
    /// are listed above the table, a long value's line indented under its variant. Control: the
    /// Markdown table (`sweep.md`) of the same long keys runs past the width.
    #[test]
    fn the_terminal_table_fits_its_width() {
        let (spec, rows) = rows_of(&["sensor.latency_s"], &[vec!["0.3".into()], vec!["1.1".into()]]);
        let t = terminal(&spec, &rows);
        assert!(t.starts_with("| variant | sensor.latency_s | part |"), "{t}");
        assert!(t.lines().all(|l| l.chars().count() <= TERMINAL_WIDTH), "{t}");
        let long = [
            "sensor.position_m",
            "workpiece.grasp.face_margin_m",
            "cycle.max_picks_per_capture",
        ];
        let value = vec!["[0.1, 0.45, 1.008]".to_string(), "0.0005".into(), "3".into()];
        let (spec, rows) = rows_of(&long, &[value.clone(), value]);
        let t = terminal(&spec, &rows);
        assert!(t.lines().all(|l| l.chars().count() <= TERMINAL_WIDTH), "{t}");
        assert!(
            t.starts_with("variant 1: sensor.position_m = [0.1, 0.45, 1.008], "),
            "{t}"
        );
        assert!(t.contains("\n\n| variant | part |"), "{t}");
        assert!(
            markdown(&spec, &rows)
                .lines()
                .any(|l| l.chars().count() > TERMINAL_WIDTH)
        );
    }
}
