//! A tune's result files: `tune.json` (every evaluation: round, values, training figures,
//! feasibility and cost; the best; the best and the untuned cell on the test seeds), `tune.md`
//! (the same for people: the test result beside the untuned cell, train beside test) and
//! `tune.svg` (convergence: each evaluation's training takt as a dot, infeasible ones hollow
//! and red, refused ones as ticks under the plot, and the best feasible so far as a step line).
//!
//! Deterministic: no wall times, no paths, fixed decimals in the text and the chart; in
//! deterministic mode the same command gives the same bytes.
//!
//! Units: s (takt), % (success in Markdown), the keys' own.

use std::fmt::Write;

use serde_json::{Value, json};

use super::journal::Header;
use super::{Constraints, Evaluation, Figures, Outcome};
use crate::report::wrap;
use crate::results::table::{TERMINAL_WIDTH, aligned, aligned_keyed, num, pct};
use crate::svg::{Plot, escape, open, tick_label, ticks};

/// What a tune found.
#[derive(Debug, Clone)]
pub struct Report<'a> {
    /// The tune's identity (cell, workpiece, keys, training seeds, picks, mode, seed, population).
    pub header: &'a Header,
    /// Candidates asked for.
    pub budget: usize,
    /// What a best must meet.
    pub constraints: Constraints,
    /// The test seeds.
    pub test_seeds: &'a [u64],
    /// Every evaluation, in order.
    pub evaluations: &'a [Evaluation],
    /// The best (none if none is feasible).
    pub best: Option<&'a Evaluation>,
    /// The best and the untuned cell on the test seeds.
    pub test: Option<(Figures, Figures)>,
}

impl Report<'_> {
    fn values_json(&self, values: &[f64]) -> Value {
        let m: serde_json::Map<String, Value> = self
            .header
            .keys
            .iter()
            .zip(values)
            .map(|(d, x)| (d.key.clone(), if d.integer { json!(*x as i64) } else { json!(x) }))
            .collect();
        Value::Object(m)
    }

    fn values_text(&self, values: &[f64]) -> String {
        super::cell::texts(&self.header.keys, values)
            .iter()
            .zip(&self.header.keys)
            .map(|(v, d)| format!("{}={v}", d.key))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// `tune.json`.
pub fn json(r: &Report<'_>) -> Value {
    let evals: Vec<Value> = r
        .evaluations
        .iter()
        .map(|e| {
            let (train, refused) = match &e.outcome {
                Outcome::Measured(f) => (json!(f), Value::Null),
                Outcome::Refused(m) => (Value::Null, json!(m)),
            };
            json!({
                "index": e.index, "round": e.round, "values": r.values_json(&e.values),
                "train": train, "refused": refused, "feasible": e.feasible(),
                "violations": e.violations, "cost": e.cost,
            })
        })
        .collect();
    let best = r
        .best
        .map(|b| json!({"index": b.index, "values": r.values_json(&b.values), "train": b.figures()}));
    let test = r.test.as_ref().map(|(tuned, untuned)| {
        json!({
            "seeds": r.test_seeds,
            "tuned": tuned, "tuned_violations": r.constraints.violations(tuned),
            "untuned": untuned, "untuned_violations": r.constraints.violations(untuned),
        })
    });
    json!({"tune": {
        "spec": r.header, "budget": r.budget, "constraints": r.constraints, "test_seeds": r.test_seeds,
        "optimizer": match r.header.optimizer {
            super::Optimizer::Swarm => "argmin 0.11 particle swarm",
            super::Optimizer::Grid => "grid",
        },
        "evaluations": evals, "best": best, "test": test,
    }})
}

fn figs_row(name: &str, seeds: &str, f: &Figures, c: &Constraints) -> String {
    let v = c.violations(f);
    format!(
        "| {name} | {seeds} | {} | {} % | {} | {} | {} | {} | {} |\n",
        f.takt_s.map_or("-".into(), |t| num(t, 3)),
        f.success_rate.map_or("-".into(), |s| num(100.0 * s, 1)),
        f.takt_count,
        f.collisions,
        f.protective_stops,
        f.parts_lost,
        if v.is_empty() {
            "yes".into()
        } else {
            format!("no: {}", v.join("; "))
        }
    )
}

fn seeds_text(s: &[u64]) -> String {
    s.iter().map(u64::to_string).collect::<Vec<_>>().join(",")
}

/// The head of `tune.md` and of the terminal's text: the run's paragraph (candidates, picks,
/// objective, seeds, mode, optimizer) and the constraints'.
fn intro(r: &Report<'_>) -> [String; 2] {
    let h = r.header;
    let c = &r.constraints;
    [
        format!(
            "{} candidates ({} per round), {} picks per run, objective: the {} takt, training seeds {}, test seeds {}, {}; optimizer: {}.",
            r.evaluations.len(),
            h.population,
            h.picks,
            match h.objective {
                super::Objective::Sustained => "sustained (every interval)",
                super::Objective::First20 => "reference's 20-pick (each run's first 21 picks)",
            },
            seeds_text(&h.train_seeds),
            seeds_text(r.test_seeds),
            if h.deterministic {
                "deterministic compute budgets"
            } else {
                "measured compute"
            },
            match h.optimizer {
                super::Optimizer::Swarm => format!("argmin particle swarm, seed {}", h.seed),
                super::Optimizer::Grid => "an even grid over the keys (the baseline)".to_string(),
            },
        ),
        format!(
            "Constraints: success >= {:.1} %, collisions <= {}, protective stops <= {}, parts lost <= {}, runs ended by a physics fault: none.",
            100.0 * c.min_success,
            c.max_collisions,
            c.max_stops,
            c.max_parts_lost
        ),
    ]
}

/// The line naming the best, and the sentence on which figure to quote.
fn best_text(r: &Report<'_>, b: &Evaluation) -> [String; 2] {
    [
        format!(
            "Best (lowest training takt that meets every constraint): evaluation {}, {}.",
            b.index + 1,
            r.values_text(&b.values)
        ),
        "The figure to quote is the tuned cell on the test seeds (never evaluated by the optimizer).".to_string(),
    ]
}

/// What is printed where no candidate met every constraint.
const NO_BEST: &str =
    "No candidate met every constraint on the training seeds: there is no best, and nothing was run on the test seeds.";

/// `tune.md`.
pub fn markdown(r: &Report<'_>) -> String {
    let h = r.header;
    let c = &r.constraints;
    let [run, limits] = intro(r);
    let mut md = format!(
        "# tune: workpiece {} in {}\n\n{run}\n\n{limits}\n\n",
        h.workpiece, h.scene
    );
    let header = "| cell | seeds | takt [s] | success | intervals | collisions | stops | lost | meets the constraints |\n|---|---|---:|---:|---:|---:|---:|---:|---|\n";
    match (r.best, &r.test) {
        (Some(b), Some((tuned, untuned))) => {
            let [best, quote] = best_text(r, b);
            let _ = write!(md, "{best}\n\n{quote}\n\n");
            md += header;
            if let Some(f) = b.figures() {
                md += &figs_row("tuned", &format!("train {}", seeds_text(&h.train_seeds)), f, c);
            }
            md += &figs_row("tuned", &format!("test {}", seeds_text(r.test_seeds)), tuned, c);
            md += &figs_row("untuned", &format!("test {}", seeds_text(r.test_seeds)), untuned, c);
        }
        _ => {
            let _ = writeln!(md, "**{NO_BEST}**");
        }
    }
    md += "\n## Evaluations (training seeds)\n\n| # | round | values | takt [s] | success | collisions | stops | lost | feasible |\n|---:|---:|---|---:|---:|---:|---:|---:|---|\n";
    for e in r.evaluations {
        let vals = r.values_text(&e.values);
        let feas = if e.feasible() {
            "yes".into()
        } else {
            format!("no: {}", e.violations.join("; "))
        };
        let _ = match e.figures() {
            Some(f) => writeln!(
                md,
                "| {} | {} | {vals} | {} | {} % | {} | {} | {} | {feas} |",
                e.index + 1,
                e.round,
                f.takt_s.map_or("-".into(), |t| num(t, 3)),
                f.success_rate.map_or("-".into(), |s| num(100.0 * s, 1)),
                f.collisions,
                f.protective_stops,
                f.parts_lost
            ),
            None => writeln!(
                md,
                "| {} | {} | {vals} | - | - | - | - | - | {} |",
                e.index + 1,
                e.round,
                escape_pipe(&feas)
            ),
        };
    }
    md
}

/// The terminal's text, within [`TERMINAL_WIDTH`]: `tune.md`'s paragraphs wrapped, the tuned and
/// untuned cells' figures, and the evaluations (a column per key where the columns fit, else
/// their values are left to `tune.md`), each constraint a row missed listed under its table.
pub fn terminal(r: &Report<'_>) -> String {
    let width = TERMINAL_WIDTH;
    let h = r.header;
    let c = &r.constraints;
    let para = |text: &str| wrap(text, width) + "\n\n";
    let notes_text = |notes: &[(String, String)]| -> String {
        if notes.is_empty() {
            return String::new();
        }
        let under = |(head, text): &(String, String)| crate::report::wrap_under(head, head.len(), text, width);
        "\n".to_string() + &notes.iter().map(under).collect::<String>()
    };
    let mut out = para(&format!("tune: workpiece {} in {}", h.workpiece, h.scene));
    for p in intro(r) {
        out += &para(&p);
    }
    match (r.best, &r.test) {
        (Some(b), Some((tuned, untuned))) => {
            for p in best_text(r, b) {
                out += &para(&p);
            }
            let (mut rows, mut notes) = (Vec::new(), Vec::new());
            let train = format!("train {}", seeds_text(&h.train_seeds));
            let test = format!("test {}", seeds_text(r.test_seeds));
            let figures = b.figures().map(|f| ("tuned", train, f));
            for (name, seeds, f) in figures
                .into_iter()
                .chain([("tuned", test.clone(), tuned), ("untuned", test, untuned)])
            {
                let v = c.violations(f);
                if !v.is_empty() {
                    notes.push((format!("{name}, {seeds}: "), v.join("; ")));
                }
                rows.push(vec![
                    name.to_string(),
                    seeds,
                    f.takt_s.map_or("-".into(), |t| num(t, 3)),
                    f.success_rate.map_or("-".into(), |s| pct(s, 1)),
                    f.takt_count.to_string(),
                    f.collisions.to_string(),
                    f.protective_stops.to_string(),
                    f.parts_lost.to_string(),
                    if v.is_empty() { "yes" } else { "no" }.to_string(),
                ]);
            }
            let headers = [
                ("cell", false),
                ("seeds", false),
                ("takt [s]", true),
                ("success", true),
                ("intervals", true),
                ("collisions", true),
                ("stops", true),
                ("lost", true),
                ("meets the constraints", false),
            ];
            out += &aligned(&headers, &rows);
            out += &notes_text(&notes);
            out += "\n";
        }
        _ => out += &para(NO_BEST),
    }
    // The evaluations: a column per key where they fit.
    let (mut rows, mut notes) = (Vec::new(), Vec::new());
    for e in r.evaluations {
        if !e.feasible() {
            notes.push((format!("evaluation {}: ", e.index + 1), e.violations.join("; ")));
        }
        let f = e.figures();
        rows.push((
            vec![(e.index + 1).to_string(), e.round.to_string()],
            super::cell::texts(&h.keys, &e.values),
            vec![
                f.and_then(|f| f.takt_s).map_or("-".into(), |t| num(t, 3)),
                f.and_then(|f| f.success_rate).map_or("-".into(), |s| pct(s, 1)),
                if e.feasible() { "yes" } else { "no" }.to_string(),
            ],
        ));
    }
    let head = [("#", true), ("round", true)];
    let keys: Vec<(&str, bool)> = h.keys.iter().map(|d| (d.key.as_str(), true)).collect();
    let tail = [("takt [s]", true), ("success", true), ("feasible", false)];
    let (table, keyed) = aligned_keyed(&head, &keys, &tail, &rows);
    out += &para(if keyed {
        "Evaluations (training seeds):"
    } else {
        "Evaluations (training seeds; their values are in tune.md):"
    });
    out += &table;
    out + &notes_text(&notes)
}

fn escape_pipe(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// `tune.svg`: convergence over the evaluations.
pub fn svg(r: &Report<'_>) -> String {
    let (width, height) = (760.0, 420.0);
    let title = format!(
        "tune: workpiece {}, takt on the training seeds{}",
        r.header.workpiece,
        match r.header.optimizer {
            super::Optimizer::Swarm => "",
            super::Optimizer::Grid => " (the grid baseline)",
        }
    );
    let mut svg = open(width, height, &title);
    let n = r.evaluations.len().max(1);
    let takts: Vec<f64> = r
        .evaluations
        .iter()
        .filter_map(|e| e.figures().and_then(|f| f.takt_s))
        .collect();
    let lo = takts.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = takts.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    // A takt over 3 times the lowest (a cell that hardly picks) would flatten the rest: such
    // points are drawn as triangles on the top edge, and counted in a note.
    let cap = if hi > 3.0 * lo && lo > 0.0 { 3.0 * lo } else { hi };
    let above = takts.iter().filter(|t| **t > cap).count();
    let hi = cap;
    let (yt, y0, y1) = ticks(lo, hi, 6.0);
    let (xt, x0, x1) = ticks(0.0, n as f64, 8.0);
    let plot = Plot {
        x0: 76.0,
        y0: 48.0,
        w: width - 76.0 - 200.0,
        h: height - 48.0 - 72.0,
        x_range: (x0, x1),
        y_range: (y0, y1),
    };
    plot.y_axis(&mut svg, &yt, "takt, mean over the training seeds (s)");
    let xstep = if xt.len() > 1 { xt[1] - xt[0] } else { 1.0 };
    for t in &xt {
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" class="tick">{}</text>"#,
            plot.x(*t),
            plot.y0 + plot.h + 16.0,
            tick_label(*t, xstep)
        );
    }
    plot.x_label(&mut svg, "evaluation (in the order the optimizer asked)");
    // Best feasible so far: a step line.
    let mut best = f64::INFINITY;
    let mut pts: Vec<(f64, f64)> = Vec::new();
    for e in r.evaluations {
        if e.feasible()
            && let Some(t) = e.figures().and_then(|f| f.takt_s)
            && t < best
        {
            if best.is_finite() {
                pts.push((e.index as f64 + 1.0, best));
            }
            best = t;
            pts.push((e.index as f64 + 1.0, t));
        }
    }
    if best.is_finite() {
        pts.push((n as f64, best));
        let path: Vec<String> = pts
            .iter()
            .map(|(x, y)| format!("{:.1},{:.1}", plot.x(*x), plot.y(*y)))
            .collect();
        let _ = writeln!(
            svg,
            r##"<polyline points="{}" fill="none" stroke="#4e79a7" stroke-width="2"/>"##,
            path.join(" ")
        );
    }
    for e in r.evaluations {
        let x = plot.x(e.index as f64 + 1.0);
        match e.figures().and_then(|f| f.takt_s) {
            Some(t) if t > cap => {
                let y = plot.y0;
                let fill = if e.feasible() { "#4e79a7" } else { "white" };
                let _ = writeln!(
                    svg,
                    r##"<path d="M{:.1},{:.1} L{:.1},{:.1} L{x:.1},{:.1} Z" fill="{fill}" stroke="{}" stroke-width="1.5"/>"##,
                    x - 4.0,
                    y + 7.0,
                    x + 4.0,
                    y + 7.0,
                    y,
                    if e.feasible() { "#4e79a7" } else { "#e15759" }
                );
            }
            Some(t) if e.feasible() => {
                let _ = writeln!(
                    svg,
                    r##"<circle cx="{x:.1}" cy="{:.1}" r="3.5" fill="#4e79a7"/>"##,
                    plot.y(t)
                );
            }
            Some(t) => {
                let _ = writeln!(
                    svg,
                    r##"<circle cx="{x:.1}" cy="{:.1}" r="3.5" fill="white" stroke="#e15759" stroke-width="1.5"/>"##,
                    plot.y(t)
                );
            }
            None => {
                let y = plot.y0 + plot.h;
                let _ = writeln!(
                    svg,
                    r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#888" stroke-width="1.5"/>"##,
                    y - 8.0,
                    y
                );
            }
        }
    }
    let lx = plot.x0 + plot.w + 16.0;
    let legend = [
        (r##"<circle cx="{X}" cy="{Y}" r="3.5" fill="#4e79a7"/>"##, "feasible"),
        (
            r##"<circle cx="{X}" cy="{Y}" r="3.5" fill="white" stroke="#e15759" stroke-width="1.5"/>"##,
            "violates a constraint",
        ),
        (
            r##"<line x1="{X}" y1="{Y0}" x2="{X}" y2="{Y}" stroke="#888" stroke-width="1.5"/>"##,
            "refused by the file checks",
        ),
        (
            r##"<line x1="{XL}" y1="{Y}" x2="{XR}" y2="{Y}" stroke="#4e79a7" stroke-width="2"/>"##,
            "best feasible so far",
        ),
    ];
    for (i, (mark, text)) in legend.iter().enumerate() {
        let y = plot.y0 + 12.0 + 22.0 * i as f64;
        let m = mark
            .replace("{XL}", &format!("{:.1}", lx - 6.0))
            .replace("{XR}", &format!("{:.1}", lx + 6.0))
            .replace("{X}", &format!("{lx:.1}"))
            .replace("{Y0}", &format!("{:.1}", y - 8.0))
            .replace("{Y}", &format!("{y:.1}"));
        let _ = writeln!(
            svg,
            r#"{m}<text x="{:.1}" y="{:.1}" class="note">{}</text>"#,
            lx + 12.0,
            y + 4.0,
            escape(text)
        );
    }
    if above > 0 {
        let note = [
            format!("{above} above {} s:", num(cap, 2)),
            "triangles on the top edge".into(),
        ];
        for (i, l) in note.iter().enumerate() {
            let _ = writeln!(
                svg,
                r#"<text x="{lx:.1}" y="{:.1}" class="note">{}</text>"#,
                plot.y0 + 104.0 + 14.0 * i as f64,
                escape(l)
            );
        }
    }
    if let (Some(b), Some((tuned, untuned))) = (r.best, &r.test) {
        let lines = [
            format!("best: evaluation {}", b.index + 1),
            format!("test seeds: tuned {} s", tuned.takt_s.map_or("-".into(), |t| num(t, 3))),
            format!("untuned {} s", untuned.takt_s.map_or("-".into(), |t| num(t, 3))),
        ];
        for (i, l) in lines.iter().enumerate() {
            let _ = writeln!(
                svg,
                r#"<text x="{lx:.1}" y="{:.1}" class="note">{}</text>"#,
                plot.y0 + 142.0 + 16.0 * i as f64,
                escape(l)
            );
        }
    }
    svg + "</svg>\n"
}
