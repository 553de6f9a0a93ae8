//! Report stage: the takt charts as SVG (no scripts, no fonts or files fetched: any browser
//! shows them offline).
//!
//! Job: `takt.svg` of a batch (per workpiece: the takt's mean, its p5–p95 spread and min–max,
//! the reference's takt and the physical floor as marks; success beside it), and the drawing
//! helpers a sweep's chart shares (axes with units, ticks, one colour per workpiece). Like the
//! time chart ([`crate::chart`]), the output is deterministic: fixed decimals, no hash maps.
//!
//! Units: s on the takt axes, % on the success axis; SVG user units (px) for the drawing.

use std::fmt::Write;

/// One colour per workpiece, by its position in the table (Tableau 10, as the time chart's lanes).
pub const COLOURS: [&str; 10] = [
    "#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7", "#9c755f", "#bab0ac",
];

/// The colour of the `i`-th workpiece.
pub fn colour(i: usize) -> &'static str {
    COLOURS[i % COLOURS.len()]
}

/// Escapes text for SVG.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A "nice" tick step (1, 2 or 5 times a power of ten) giving about `n` ticks over `span`.
pub fn tick_step(span: f64, n: f64) -> f64 {
    if span.is_nan() || span <= 0.0 || span.is_infinite() {
        return 1.0;
    }
    let raw = span / n.max(1.0);
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= raw * 0.999)
        .unwrap_or(10.0 * p)
}

/// Ticks from `lo` to `hi` (both rounded outward to the step) and the rounded ends.
pub fn ticks(lo: f64, hi: f64, n: f64) -> (Vec<f64>, f64, f64) {
    let (lo, hi) = if hi > lo { (lo, hi) } else { (lo - 0.5, lo + 0.5) };
    let step = tick_step(hi - lo, n);
    let (a, b) = ((lo / step).floor() * step, (hi / step).ceil() * step);
    let count = ((b - a) / step).round() as usize;
    ((0..=count).map(|i| a + i as f64 * step).collect(), a, b)
}

/// A tick label: as many decimals as the step needs.
pub fn tick_label(v: f64, step: f64) -> String {
    let d = (-step.log10().floor()).max(0.0) as usize;
    let v = if v.abs() < step * 1e-9 { 0.0 } else { v };
    format!("{v:.d$}")
}

/// A plot area: SVG box and the data range on each axis.
#[derive(Debug, Clone, Copy)]
pub struct Plot {
    /// Left edge [px].
    pub x0: f64,
    /// Top edge [px].
    pub y0: f64,
    /// Width [px].
    pub w: f64,
    /// Height [px].
    pub h: f64,
    /// Data value at the left and right edges.
    pub x_range: (f64, f64),
    /// Data value at the bottom and top edges.
    pub y_range: (f64, f64),
}

impl Plot {
    /// x of a data value [px].
    pub fn x(&self, v: f64) -> f64 {
        self.x0 + (v - self.x_range.0) / (self.x_range.1 - self.x_range.0) * self.w
    }

    /// y of a data value [px].
    pub fn y(&self, v: f64) -> f64 {
        self.y0 + self.h - (v - self.y_range.0) / (self.y_range.1 - self.y_range.0) * self.h
    }

    /// The frame, horizontal grid lines and y tick labels every `step`, and the y axis label.
    pub fn y_axis(&self, svg: &mut String, ticks: &[f64], label: &str) {
        let step = if ticks.len() > 1 { ticks[1] - ticks[0] } else { 1.0 };
        for t in ticks {
            let y = self.y(*t);
            let _ = writeln!(
                svg,
                r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#e5e5e5"/><text x="{:.1}" y="{:.1}" text-anchor="end" class="tick">{}</text>"##,
                self.x0,
                self.x0 + self.w,
                self.x0 - 6.0,
                y + 4.0,
                tick_label(*t, step)
            );
        }
        let (cx, cy) = (self.x0 - 46.0, self.y0 + self.h / 2.0);
        let _ = writeln!(
            svg,
            r##"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#888"/><text x="{cx:.1}" y="{cy:.1}" transform="rotate(-90 {cx:.1} {cy:.1})" text-anchor="middle" class="axis">{}</text>"##,
            self.x0,
            self.y0,
            self.w,
            self.h,
            escape(label)
        );
    }

    /// The x axis label, centred under the plot.
    pub fn x_label(&self, svg: &mut String, label: &str) {
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" class="axis">{}</text>"#,
            self.x0 + self.w / 2.0,
            self.y0 + self.h + 38.0,
            escape(label)
        );
    }
}

/// The document's opening: size, white background, fonts, title.
pub fn open(width: f64, height: f64, title: &str) -> String {
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="Helvetica, Arial, sans-serif" font-size="12">"#
    );
    let _ = writeln!(svg, "<title>{}</title>", escape(title));
    svg += "<style>.tick{font-size:11px;fill:#555}.axis{font-size:13px;fill:#222}.note{font-size:11px;fill:#444}</style>\n";
    let _ = writeln!(svg, r#"<rect width="{width:.0}" height="{height:.0}" fill="white"/>"#);
    let _ = writeln!(
        svg,
        r#"<text x="16" y="24" font-size="15" font-weight="bold">{}</text>"#,
        escape(title)
    );
    svg
}

/// One workpiece of a batch as `takt.svg` draws it.
#[derive(Debug, Clone, PartialEq)]
pub struct TaktBar {
    /// Workpiece.
    pub workpiece: String,
    /// Takt mean, 5th and 95th percentiles, min, max [s] (NaN when the runs placed too little).
    pub mean_s: f64,
    /// 5th percentile [s].
    pub p5_s: f64,
    /// 95th percentile [s].
    pub p95_s: f64,
    /// Minimum [s].
    pub min_s: f64,
    /// Maximum [s].
    pub max_s: f64,
    /// The reference's takt [s], if it has one for this workpiece.
    pub reference_s: Option<f64>,
    /// The physical floor [s] (mean Pick + Place), if known.
    pub floor_s: Option<f64>,
    /// placed / attempts.
    pub success: f64,
}

/// `takt.svg`: per workpiece the takt (mean as a dot, p5–p95 as a box, min–max as a whisker),
/// the reference's takt (a black diamond) and the physical floor (a dashed bar); success [%] in
/// a panel beside it.
pub fn takt_svg(title: &str, bars: &[TaktBar]) -> String {
    let n = bars.len().max(1) as f64;
    let slot = 90.0;
    let takt_w = (slot * n).max(360.0);
    let width = 90.0 + takt_w + 90.0 + (48.0 * n).max(200.0) + 40.0;
    let height = 460.0;
    let mut svg = open(width, height, title);
    let top = bars
        .iter()
        .flat_map(|b| [b.max_s, b.p95_s, b.reference_s.unwrap_or(0.0), b.floor_s.unwrap_or(0.0)])
        .filter(|v| v.is_finite())
        .fold(1.0, f64::max);
    let (yt, _, y_hi) = ticks(0.0, top * 1.05, 6.0);
    let plot = Plot {
        x0: 90.0,
        y0: 70.0,
        w: takt_w,
        h: 320.0,
        x_range: (0.0, n),
        y_range: (0.0, y_hi),
    };
    plot.y_axis(&mut svg, &yt, "takt [s]");
    plot.x_label(&mut svg, "workpiece");
    for (i, b) in bars.iter().enumerate() {
        let c = colour(i);
        let cx = plot.x(i as f64 + 0.5);
        let _ = writeln!(
            svg,
            r#"<g class="series" data-workpiece="{}"><title>{}: takt mean {:.3} s, p5–p95 {:.3}–{:.3} s, min–max {:.3}–{:.3} s</title>"#,
            escape(&b.workpiece),
            escape(&b.workpiece),
            b.mean_s,
            b.p5_s,
            b.p95_s,
            b.min_s,
            b.max_s
        );
        if b.min_s.is_finite() && b.max_s.is_finite() {
            let _ = writeln!(
                svg,
                r##"<line x1="{cx:.1}" y1="{:.1}" x2="{cx:.1}" y2="{:.1}" stroke="#666"/>"##,
                plot.y(b.min_s),
                plot.y(b.max_s)
            );
        }
        if b.p5_s.is_finite() && b.p95_s.is_finite() {
            let _ = writeln!(
                svg,
                r##"<rect x="{:.1}" y="{:.1}" width="28" height="{:.1}" fill="{c}" fill-opacity="0.35" stroke="{c}"/>"##,
                cx - 14.0,
                plot.y(b.p95_s),
                (plot.y(b.p5_s) - plot.y(b.p95_s)).max(1.0)
            );
        }
        if b.mean_s.is_finite() {
            let y = plot.y(b.mean_s);
            let _ = writeln!(
                svg,
                r##"<circle cx="{cx:.1}" cy="{y:.1}" r="5" fill="{c}" stroke="#222"/><text x="{:.1}" y="{:.1}" class="note">{:.2}</text>"##,
                cx + 18.0,
                y + 4.0,
                b.mean_s
            );
        }
        if let Some(r) = b.reference_s {
            let y = plot.y(r);
            let _ = writeln!(
                svg,
                r##"<path d="M{:.1} {y:.1} l6 -6 l6 6 l-6 6 z" fill="#111"><title>reference takt {r:.1} s</title></path>"##,
                cx - 30.0
            );
        }
        if let Some(f) = b.floor_s.filter(|f| f.is_finite()) {
            let y = plot.y(f);
            let _ = writeln!(
                svg,
                r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#111" stroke-width="2" stroke-dasharray="4 3"><title>physical floor {f:.3} s</title></line>"##,
                cx - 22.0,
                cx + 22.0
            );
        }
        let _ = writeln!(
            svg,
            r#"<text x="{cx:.1}" y="{:.1}" text-anchor="middle" class="axis">{}</text></g>"#,
            plot.y0 + plot.h + 18.0,
            escape(&b.workpiece)
        );
    }
    // Success beside it.
    let (st, _, _) = ticks(0.0, 100.0, 5.0);
    let sp = Plot {
        x0: plot.x0 + plot.w + 90.0,
        y0: 70.0,
        w: (48.0 * n).max(200.0),
        h: 320.0,
        x_range: (0.0, n),
        y_range: (0.0, 100.0),
    };
    sp.y_axis(&mut svg, &st, "success [%]");
    sp.x_label(&mut svg, "workpiece");
    for (i, b) in bars.iter().enumerate() {
        let cx = sp.x(i as f64 + 0.5);
        let pct = 100.0 * b.success;
        if pct.is_finite() {
            let _ = writeln!(
                svg,
                r#"<rect x="{:.1}" y="{:.1}" width="24" height="{:.1}" fill="{}"><title>{}: success {pct:.1} %</title></rect><text x="{cx:.1}" y="{:.1}" text-anchor="middle" class="note">{pct:.0}</text>"#,
                cx - 12.0,
                sp.y(pct),
                sp.y(0.0) - sp.y(pct),
                colour(i),
                escape(&b.workpiece),
                sp.y(pct) - 4.0
            );
        }
        let _ = writeln!(
            svg,
            r#"<text x="{cx:.1}" y="{:.1}" text-anchor="middle" class="axis">{}</text>"#,
            sp.y0 + sp.h + 18.0,
            escape(&b.workpiece)
        );
    }
    let ly = 48.0;
    let _ = writeln!(
        svg,
        r##"<g class="legend"><circle cx="96" cy="{ly:.1}" r="5" fill="#999" stroke="#222"/><text x="106" y="{:.1}" class="note">takt mean</text><rect x="180" y="{:.1}" width="14" height="12" fill="#999" fill-opacity="0.35" stroke="#999"/><text x="200" y="{:.1}" class="note">p5–p95</text><line x1="260" y1="{:.1}" x2="260" y2="{:.1}" stroke="#666"/><text x="268" y="{:.1}" class="note">min–max</text><path d="M330 {ly:.1} l6 -6 l6 6 l-6 6 z" fill="#111"/><text x="348" y="{:.1}" class="note">reference takt</text><line x1="440" y1="{ly:.1}" x2="470" y2="{ly:.1}" stroke="#111" stroke-width="2" stroke-dasharray="4 3"/><text x="476" y="{:.1}" class="note">physical floor (Pick + Place)</text></g>"##,
        ly + 4.0,
        ly - 6.0,
        ly + 4.0,
        ly - 7.0,
        ly + 7.0,
        ly + 4.0,
        ly + 4.0,
        ly + 4.0
    );
    svg += "</svg>\n";
    svg
}

/// The bars of a batch table: its rows, with the 5th percentile taken from the runs.
pub fn takt_bars(rows: &[super::Row], runs: &[super::RunEntry]) -> Vec<TaktBar> {
    rows.iter()
        .map(|r| {
            let takts: Vec<f64> = runs
                .iter()
                .filter(|e| e.workpiece == r.workpiece)
                .flat_map(|e| e.takts_s.iter().copied())
                .collect();
            TaktBar {
                workpiece: r.workpiece.clone(),
                mean_s: r.takt.mean_s,
                p5_s: crate::stats::percentile_sorted(&crate::stats::sorted(&takts), 0.05),
                p95_s: r.takt.p95_s,
                min_s: r.takt.min_s,
                max_s: r.takt.max_s,
                reference_s: r.reference_takt_s,
                floor_s: r.motion_floor_s.is_finite().then_some(r.motion_floor_s),
                success: r.success_rate,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        // 3.3 s over about six ticks: a step of 0.55 rounds up to 1 s.
        let (t, a, b) = ticks(0.0, 3.3, 6.0);
        assert_eq!((a, b), (0.0, 4.0));
        assert_eq!(t.len(), 5);
        let (t, a, b) = ticks(0.0, 3.3, 8.0);
        assert_eq!((a, b, t.len()), (0.0, 3.5, 8));
        assert_eq!(tick_label(0.5, 0.5), "0.5");
        assert!((tick_step(0.008, 4.0) - 0.002).abs() < 1e-12);
        assert_eq!(escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }
}
