//! Report stage: `sweep.svg`, the takt against the varied parameter.
//!
//! Job: one panel per combination of the second and later keys' values (small multiples; one
//! panel when one key is varied); in each, the first key's values along x (a numeric axis when
//! they are numbers, else one evenly spaced position per value), one line per workpiece through
//! its takt means with the p5–p95 spread as a band, and the reference's takt as a diamond at the
//! right edge. Every panel has the same takt axis, so panels compare at a glance.
//!
//! Units: s on the takt axis; the key's own unit (from its name's suffix) on x.

use std::fmt::Write;

use super::SweepRow;
use crate::study::StudySpec;
use crate::svg::{Plot, colour, escape, open, tick_label, ticks};

/// The unit a key's name ends in (`_m` → m, `_s` → s, `_m_s2` → m/s², ...); `-` when it carries
/// none (counts and ratios).
pub fn unit_of(key: &str) -> &'static str {
    let last = key.rsplit('.').next().unwrap_or(key);
    let last = last.split('[').next().unwrap_or(last);
    const UNITS: [(&str, &str); 15] = [
        ("_m_s2", "m/s²"),
        ("_m_s", "m/s"),
        ("_deg_s2", "deg/s²"),
        ("_deg_s", "deg/s"),
        ("_kg_m2", "kg m²"),
        ("_nm_s_per_rad", "N m s/rad"),
        ("_nm", "N m"),
        ("_kpa", "kPa"),
        ("_hz", "Hz"),
        ("_px", "px"),
        ("_kg", "kg"),
        ("_deg", "deg"),
        ("_mm", "mm"),
        ("_s", "s"),
        ("_m", "m"),
    ];
    UNITS
        .iter()
        .find(|(suffix, _)| last.ends_with(suffix))
        .map_or("-", |(_, u)| u)
}

/// The x axis label of a key: the key and its unit.
pub fn axis_label(key: &str) -> String {
    format!("{key} [{}]", unit_of(key))
}

/// The x axis of every panel: the first key's distinct values, numeric if they all are.
struct XValues {
    /// The values as written, in order of appearance.
    texts: Vec<String>,
    /// Their numbers, when every one is a finite number.
    numeric: Option<Vec<f64>>,
}

impl XValues {
    fn of(spec: &StudySpec) -> Self {
        let mut texts: Vec<String> = Vec::new();
        for v in &spec.variants {
            if !texts.contains(&v[0]) {
                texts.push(v[0].clone());
            }
        }
        let numeric = texts
            .iter()
            .map(|x| x.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect();
        XValues { texts, numeric }
    }

    /// Where a value goes on the axis: its number, else its position.
    fn pos(&self, x: &str) -> f64 {
        let i = self.texts.iter().position(|v| v == x).unwrap_or(0);
        self.numeric.as_ref().map_or(i as f64, |n| n[i])
    }

    /// The axis' range, padded.
    fn range(&self) -> (f64, f64) {
        match &self.numeric {
            Some(n) => {
                let (a, b) = n
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
                let pad = if b > a { (b - a) * 0.06 } else { a.abs().max(1e-3) * 0.1 };
                (a - pad, b + pad)
            }
            None => (-0.5, self.texts.len() as f64 - 0.5),
        }
    }

    /// The ticks: the values themselves, labelled with the decimals their spacing needs.
    fn ticks(&self, svg: &mut String, plot: &Plot) {
        let step = self.numeric.as_ref().map_or(1.0, |n| {
            let mut s: Vec<f64> = n.clone();
            s.sort_by(f64::total_cmp);
            s.windows(2)
                .map(|w| w[1] - w[0])
                .filter(|d| *d > 0.0)
                .fold(1.0, f64::min)
        });
        for x in &self.texts {
            let px = plot.x(self.pos(x));
            let text = match &self.numeric {
                Some(_) => tick_label(self.pos(x), step),
                None => x.clone(),
            };
            let _ = writeln!(
                svg,
                r##"<line x1="{px:.1}" y1="{:.1}" x2="{px:.1}" y2="{:.1}" stroke="#888"/><text x="{px:.1}" y="{:.1}" text-anchor="middle" class="tick">{}</text>"##,
                plot.y0 + plot.h,
                plot.y0 + plot.h + 5.0,
                plot.y0 + plot.h + 18.0,
                escape(&text)
            );
        }
    }
}

/// One takt axis for every panel, from 0 to well above the means and the references: the p95
/// of a run with tray refills is several times its mean, and would flatten the lines, so a band
/// reaching above the axis is clipped (and noted). Returns the ticks and the axis' ends.
fn takt_axis(svg: &mut String, rows: &[SweepRow], left: f64) -> (Vec<f64>, f64, f64) {
    let finite_max = |it: &mut dyn Iterator<Item = f64>| it.filter(|v| v.is_finite()).fold(f64::NAN, f64::max);
    let mean_top = finite_max(
        &mut rows
            .iter()
            .flat_map(|r| [r.row.takt.mean_s, r.row.reference_takt_s.unwrap_or(f64::NAN)]),
    );
    let p95_top = finite_max(&mut rows.iter().map(|r| r.row.takt.p95_s));
    let y_top = if mean_top.is_finite() {
        (mean_top * 1.6).min(p95_top.max(mean_top) * 1.05)
    } else {
        1.0
    };
    let (yt, y_lo, y_hi) = ticks(0.0, y_top, 6.0);
    if p95_top > y_hi {
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="78" class="note">bands above the axis are clipped: the p95 reaches {p95_top:.1} s (intervals spanning a tray refill or a re-capture)</text>"#,
            left
        );
    }
    (yt, y_lo, y_hi)
}

/// The legend: one line per workpiece, then the marks.
fn legend(svg: &mut String, workpieces: &[String]) {
    let mut lx = 96.0;
    for (i, w) in workpieces.iter().enumerate() {
        let _ = write!(
            svg,
            r#"<line x1="{lx:.1}" y1="52" x2="{:.1}" y2="52" stroke="{}" stroke-width="3"/><text x="{:.1}" y="56" class="note">{}</text>"#,
            lx + 22.0,
            colour(i),
            lx + 27.0,
            escape(w)
        );
        lx += 40.0 + 7.0 * w.len() as f64;
    }
    let _ = writeln!(
        svg,
        r##"<rect x="{lx:.1}" y="46" width="22" height="12" fill="#999" fill-opacity="0.25"/><text x="{:.1}" y="56" class="note">takt p5–p95</text><circle cx="{:.1}" cy="52" r="3.5" fill="#999"/><text x="{:.1}" y="56" class="note">takt mean</text><path d="M{:.1} 52 l6 -6 l6 6 l-6 6 z" fill="#111"/><text x="{:.1}" y="56" class="note">reference takt (right edge)</text>"##,
        lx + 27.0,
        lx + 120.0,
        lx + 128.0,
        lx + 200.0,
        lx + 218.0
    );
}

/// One workpiece in panel `p`: its p5–p95 band, its line through the takt means, a dot per
/// variant with the figures as its tooltip. `pts` are its rows with their x values, in x order.
fn series(svg: &mut String, plot: &Plot, p: usize, col: &str, w: &str, pts: &[(f64, &SweepRow)]) {
    let _ = writeln!(svg, r#"<g class="series" data-workpiece="{}">"#, escape(w));
    let band: Vec<(f64, f64, f64)> = pts
        .iter()
        .filter(|(_, r)| r.takt_p5_s.is_finite() && r.row.takt.p95_s.is_finite())
        .map(|(x, r)| (plot.x(*x), plot.y(r.takt_p5_s), plot.y(r.row.takt.p95_s)))
        .collect();
    if band.len() > 1 {
        let mut d = String::new();
        for (k, (x, _, y)) in band.iter().enumerate() {
            let _ = write!(d, "{}{x:.1} {y:.1} ", if k == 0 { "M" } else { "L" });
        }
        for (x, y, _) in band.iter().rev() {
            let _ = write!(d, "L{x:.1} {y:.1} ");
        }
        let _ = writeln!(
            svg,
            r#"<path d="{}Z" fill="{col}" fill-opacity="0.1" stroke="none" clip-path="url(#plot{p})"/>"#,
            d
        );
    } else if let Some((x, y5, y95)) = band.first() {
        let _ = writeln!(
            svg,
            r#"<rect x="{:.1}" y="{y95:.1}" width="8" height="{:.1}" fill="{col}" fill-opacity="0.25" clip-path="url(#plot{p})"/>"#,
            x - 4.0,
            (y5 - y95).max(1.0)
        );
    }
    let line: Vec<(f64, f64, &SweepRow)> = pts
        .iter()
        .filter(|(_, r)| r.row.takt.mean_s.is_finite())
        .map(|(x, r)| (plot.x(*x), plot.y(r.row.takt.mean_s), *r))
        .collect();
    if line.len() > 1 {
        let d: Vec<String> = line.iter().map(|(x, y, _)| format!("{x:.1},{y:.1}")).collect();
        let _ = writeln!(
            svg,
            r#"<polyline points="{}" fill="none" stroke="{col}" stroke-width="2.5" clip-path="url(#plot{p})"/>"#,
            d.join(" ")
        );
    }
    for (x, y, r) in &line {
        let _ = writeln!(
            svg,
            r#"<circle cx="{x:.1}" cy="{y:.1}" r="3.5" fill="{col}"><title>{} at {}: takt mean {:.3} s, p5–p95 {:.3}–{:.3} s, success {:.1} %</title></circle>"#,
            escape(w),
            escape(&r.values.join(", ")),
            r.row.takt.mean_s,
            r.takt_p5_s,
            r.row.takt.p95_s,
            100.0 * r.row.success_rate
        );
    }
    *svg += "</g>\n";
}

/// The reference's takt: one mark per distinct value at the panel's right edge, naming its
/// workpieces.
fn reference_marks(svg: &mut String, plot: &Plot, workpieces: &[String]) {
    let mut marks: Vec<(f64, Vec<&str>)> = Vec::new();
    for w in workpieces {
        if let Some(r) = crate::reference::reference_takt(w) {
            match marks.iter_mut().find(|(v, _)| (v - r).abs() < 1e-9) {
                Some((_, names)) => names.push(w),
                None => marks.push((r, vec![w])),
            }
        }
    }
    marks.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut last_y = f64::INFINITY;
    for (r, names) in &marks {
        let y = plot.y(*r);
        let x = plot.x0 + plot.w + 4.0;
        // Labels of close values are pushed apart (higher values drawn higher).
        let ty = (y + 4.0).min(last_y - 13.0);
        last_y = ty;
        let _ = writeln!(
            svg,
            r##"<g class="reference"><path d="M{x:.1} {y:.1} l6 -6 l6 6 l-6 6 z" fill="#111"><title>reference takt {r:.1} s: {}</title></path><text x="{:.1}" y="{ty:.1}" class="note">ref {} {r:.1} s</text></g>"##,
            escape(&names.join(", ")),
            x + 15.0,
            escape(&names.join(" "))
        );
    }
}

/// `sweep.svg` of a sweep's table.
pub fn sweep_svg(spec: &StudySpec, rows: &[SweepRow]) -> String {
    let xs = XValues::of(spec);
    // The panels: the other keys' value combinations, in order of appearance.
    let mut panels: Vec<Vec<String>> = Vec::new();
    for v in &spec.variants {
        let rest = v[1..].to_vec();
        if !panels.contains(&rest) {
            panels.push(rest);
        }
    }
    let cols = panels.len().clamp(1, 3);
    let prow = panels.len().div_ceil(cols);
    let (pw, ph) = (if panels.len() == 1 { 640.0 } else { 400.0 }, 300.0);
    let (left, top, gap_x, gap_y) = (90.0, 96.0, 150.0, 110.0);
    let width = left + cols as f64 * (pw + gap_x);
    let height = top + prow as f64 * (ph + gap_y);
    let title = format!(
        "takt against {} — {} seed{}, {} picks per run",
        spec.keys.join(" × "),
        spec.seeds.len(),
        if spec.seeds.len() == 1 { "" } else { "s" },
        spec.picks
    );
    let mut svg = open(width, height, &title);
    let (yt, y_lo, y_hi) = takt_axis(&mut svg, rows, left);
    let x_range = xs.range();
    legend(&mut svg, &spec.workpieces);
    for (p, rest) in panels.iter().enumerate() {
        let (c, r) = (p % cols, p / cols);
        let plot = Plot {
            x0: left + c as f64 * (pw + gap_x),
            y0: top + r as f64 * (ph + gap_y),
            w: pw,
            h: ph,
            x_range,
            y_range: (y_lo, y_hi),
        };
        let _ = writeln!(
            svg,
            r#"<g class="panel"><defs><clipPath id="plot{p}"><rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}"/></clipPath></defs>"#,
            plot.x0, plot.y0, plot.w, plot.h
        );
        if !rest.is_empty() {
            let name = spec.keys[1..]
                .iter()
                .zip(rest)
                .map(|(k, v)| format!("{k} = {v}"))
                .collect::<Vec<_>>()
                .join(", ");
            let _ = writeln!(
                svg,
                r#"<text x="{:.1}" y="{:.1}" class="axis" font-weight="bold">{}</text>"#,
                plot.x0,
                plot.y0 - 8.0,
                escape(&name)
            );
        }
        plot.y_axis(&mut svg, &yt, "takt [s]");
        plot.x_label(&mut svg, &axis_label(&spec.keys[0]));
        xs.ticks(&mut svg, &plot);
        for (i, w) in spec.workpieces.iter().enumerate() {
            let mut pts: Vec<(f64, &SweepRow)> = rows
                .iter()
                .filter(|r| &r.row.tally.workpiece == w && r.values[1..] == rest[..])
                .map(|r| (xs.pos(&r.values[0]), r))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            series(&mut svg, &plot, p, colour(i), w, &pts);
        }
        reference_marks(&mut svg, &plot, &spec.workpieces);
        svg += "</g>\n";
    }
    svg += "</svg>\n";
    svg
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_come_from_the_key_names() {
        assert_eq!(axis_label("gripper.cup_diameter_m"), "gripper.cup_diameter_m [m]");
        assert_eq!(unit_of("sensor.latency_s"), "s");
        assert_eq!(unit_of("cycle.line_accel_m_s2"), "m/s²");
        assert_eq!(unit_of("place_tray.tray.center_m[0]"), "m");
        assert_eq!(unit_of("cycle.max_picks_per_capture"), "-");
    }
}
