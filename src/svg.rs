//! SVG drawing helpers every chart of binpick shares: the document's opening, axes with units
//! and ticks, plot areas, one colour per series, escaping. Charts drawn with them are
//! deterministic (fixed decimals, no hash maps) and need no scripts, fonts or files fetched: any
//! browser shows them offline.
//!
//! Units: SVG user units (px) for the drawing; the data's own on the axes.

use std::fmt::Write;

/// One colour per workpiece, by its position in the table (Tableau 10, as the time chart's lanes).
pub const COLOURS: [&str; 10] = [
    "#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7", "#9c755f", "#bab0ac",
];

/// The colour of the `i`-th workpiece.
pub fn colour(i: usize) -> &'static str {
    COLOURS[i % COLOURS.len()]
}

/// Escapes the XML special characters `& < > " '` for text and attributes of any XML file we
/// write (SVG, JUnit); characters XML 1.0 does not allow are written as U+FFFD.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c if (c as u32) < 0x20 && !matches!(c, '\t' | '\n' | '\r') => out.push('\u{fffd}'),
            _ => out.push(c),
        }
    }
    out
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
    /// Left edge (px).
    pub x0: f64,
    /// Top edge (px).
    pub y0: f64,
    /// Width (px).
    pub w: f64,
    /// Height (px).
    pub h: f64,
    /// Data value at the left and right edges.
    pub x_range: (f64, f64),
    /// Data value at the bottom and top edges.
    pub y_range: (f64, f64),
}

impl Plot {
    /// x of a data value (px).
    pub fn x(&self, v: f64) -> f64 {
        self.x0 + (v - self.x_range.0) / (self.x_range.1 - self.x_range.0) * self.w
    }

    /// y of a data value (px).
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
