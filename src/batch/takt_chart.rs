//! Report stage: `takt.svg` of a batch (per workpiece: the takt's mean, its p5–p95 spread and
//! min–max, the reference's takt and the physical floor as marks; success beside it), drawn
//! with the shared helpers of [`crate::svg`].
//!
//! The takt axis is scaled to the means, the references and the floors, not to the longest
//! interval: one interval that spans a tray refill (ten times the takt) would squash the means
//! at the bottom. When a maximum or a 95th percentile lies beyond 1.25 times that scale
//! ([`CUT_FACTOR`] times the largest mean, reference or floor), the axis is cut there: whisker
//! and box end at the top edge, a red triangle marks a maximum beyond it with its value written
//! above, and a note under the chart says where the axis is cut.
//!
//! Units: s on the takt axis, % on the success axis; SVG user units (px) for the drawing.

use std::fmt::Write;

use crate::svg::{Plot, colour, escape, open, ticks};

/// One workpiece of a batch as `takt.svg` draws it.
#[derive(Debug, Clone, PartialEq)]
pub struct TaktBar {
    /// Workpiece.
    pub workpiece: String,
    /// Takt mean, 5th and 95th percentiles, min, max (s) (NaN when the runs placed too little).
    pub mean_s: f64,
    /// 5th percentile (s).
    pub p5_s: f64,
    /// 95th percentile (s).
    pub p95_s: f64,
    /// Minimum (s).
    pub min_s: f64,
    /// Maximum (s).
    pub max_s: f64,
    /// The reference's takt (s), if it has one for this workpiece.
    pub reference_s: Option<f64>,
    /// The physical floor (s) (mean Pick + Place), if known.
    pub floor_s: Option<f64>,
    /// The success rate (placed within the place tray's tolerance / attempts).
    pub success: f64,
}

/// The takt axis reaches this many times the largest mean, reference or floor when it is cut.
pub const CUT_FACTOR: f64 = 1.6;

/// The plots' top edge (px): room above for the legend and the values beyond a cut axis.
const PLOT_TOP: f64 = 84.0;

/// `takt.svg`: per workpiece the takt (mean as a dot, p5–p95 as a box, min–max as a whisker),
/// the reference's takt (a black diamond) and the physical floor (a dashed bar); success [%] in
/// a panel beside it.
pub fn takt_svg(title: &str, bars: &[TaktBar]) -> String {
    let n = bars.len().max(1) as f64;
    let slot = name_slot_px(bars).max(90.0);
    let takt_w = (slot * n).max(360.0);
    let width = 90.0 + takt_w + 90.0 + success_width_px(bars) + 40.0;
    let height = PLOT_TOP + 400.0;
    let mut svg = open(width, height, title);
    let finite = |v: &f64| v.is_finite();
    let data_top = bars
        .iter()
        .flat_map(|b| [b.max_s, b.p95_s, b.reference_s.unwrap_or(0.0), b.floor_s.unwrap_or(0.0)])
        .filter(finite)
        .fold(1.0, f64::max);
    let core_top = CUT_FACTOR
        * bars
            .iter()
            .flat_map(|b| [b.mean_s, b.reference_s.unwrap_or(0.0), b.floor_s.unwrap_or(0.0)])
            .filter(finite)
            .fold(0.0, f64::max);
    // Cut only when something lies well beyond the means' scale.
    let cut = core_top > 0.0 && data_top > 1.25 * core_top;
    let (yt, _, y_hi) = ticks(0.0, if cut { core_top } else { data_top * 1.05 }, 6.0);
    let plot = Plot {
        x0: 90.0,
        y0: PLOT_TOP,
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
            r#"<g class="series" data-workpiece="{}"><title>{}: {}</title>"#,
            escape(&b.workpiece),
            escape(&b.workpiece),
            if b.mean_s.is_finite() {
                format!(
                    "takt mean {:.3} s, p5–p95 {:.3}–{:.3} s, min–max {:.3}–{:.3} s",
                    b.mean_s, b.p5_s, b.p95_s, b.min_s, b.max_s
                )
            } else {
                "no takt (fewer than two parts placed in a run)".into()
            }
        );
        let clip = |v: f64| v.min(y_hi);
        if b.min_s.is_finite() && b.max_s.is_finite() {
            let _ = writeln!(
                svg,
                r##"<line x1="{cx:.1}" y1="{:.1}" x2="{cx:.1}" y2="{:.1}" stroke="#666"/>"##,
                plot.y(clip(b.min_s)),
                plot.y(clip(b.max_s))
            );
        }
        if b.p5_s.is_finite() && b.p95_s.is_finite() {
            let _ = writeln!(
                svg,
                r##"<rect x="{:.1}" y="{:.1}" width="28" height="{:.1}" fill="{c}" fill-opacity="0.35" stroke="{c}"/>"##,
                cx - 14.0,
                plot.y(clip(b.p95_s)),
                (plot.y(clip(b.p5_s)) - plot.y(clip(b.p95_s))).max(1.0)
            );
        }
        // Values beyond the cut axis: a triangle on the top edge, the maximum written above it
        // (the box reaching the edge shows a 95th percentile beyond it; the tooltip says which).
        if b.max_s.is_finite() && b.max_s > y_hi {
            let _ = writeln!(
                svg,
                r##"<g class="beyond"><title>{}: beyond the axis: {}max {:.2} s</title><path d="M{:.1} {:.1} l7 10 l-14 0 z" fill="#c00"/><text x="{cx:.1}" y="{:.1}" text-anchor="middle" class="note" fill="#c00">max {:.1}</text></g>"##,
                escape(&b.workpiece),
                if b.p95_s > y_hi {
                    format!("p95 {:.2} s, ", b.p95_s)
                } else {
                    String::new()
                },
                b.max_s,
                cx,
                plot.y0 - 1.0,
                plot.y0 - 5.0,
                b.max_s
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
    success_panel(&mut svg, &plot, bars);
    legend(&mut svg);
    if cut {
        let _ = writeln!(
            svg,
            r##"<text x="{:.1}" y="{:.1}" class="note" fill="#c00">Axis cut at {y_hi:.0} s to keep the means readable: a red triangle marks a maximum beyond it (its value above), e.g. an interval spanning a tray refill.</text>"##,
            plot.x0,
            height - 10.0
        );
    }
    svg += "</svg>\n";
    svg
}

/// The bars of a batch table: its rows.
pub fn takt_bars(rows: &[crate::results::Summary]) -> Vec<TaktBar> {
    rows.iter()
        .map(|r| TaktBar {
            workpiece: r.tally.workpiece.clone(),
            mean_s: r.takt.mean_s,
            p5_s: r.takt_p5_s,
            p95_s: r.takt.p95_s,
            min_s: r.takt.min_s,
            max_s: r.takt.max_s,
            reference_s: r.reference_takt_s,
            floor_s: r.motion_floor_s.is_finite().then_some(r.motion_floor_s),
            success: r.success_rate,
        })
        .collect()
}

/// Room for a workpiece's name under its slot (px): the longest name at the axis font (about
/// 7 px a character) and a gap, at least 48.
fn name_slot_px(bars: &[TaktBar]) -> f64 {
    let longest = bars.iter().map(|b| b.workpiece.chars().count()).max().unwrap_or(0);
    (7.0 * longest as f64 + 12.0).max(48.0)
}

/// The success panel's width (px): a name's slot per workpiece, at least 200.
fn success_width_px(bars: &[TaktBar]) -> f64 {
    (name_slot_px(bars) * bars.len().max(1) as f64).max(200.0)
}

/// Success (%) per workpiece, in a panel to the right of the takt's.
fn success_panel(svg: &mut String, plot: &Plot, bars: &[TaktBar]) {
    let n = bars.len().max(1) as f64;
    let (st, _, _) = ticks(0.0, 100.0, 5.0);
    let sp = Plot {
        x0: plot.x0 + plot.w + 90.0,
        y0: PLOT_TOP,
        w: success_width_px(bars),
        h: 320.0,
        x_range: (0.0, n),
        y_range: (0.0, 100.0),
    };
    sp.y_axis(svg, &st, "success [%]");
    sp.x_label(svg, "workpiece");
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
}

/// The legend of the takt marks, above the plots.
fn legend(svg: &mut String) {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bar(w: &str, mean_s: f64, max_s: f64) -> TaktBar {
        TaktBar {
            workpiece: w.into(),
            mean_s,
            p5_s: mean_s * 0.8,
            p95_s: mean_s * 1.3,
            min_s: mean_s * 0.7,
            max_s,
            reference_s: Some(2.7),
            floor_s: Some(mean_s * 0.8),
            success: 1.0,
        }
    }

    /// The label of the takt axis's top tick (its ticks come bottom to top, before its label).
    fn top_tick(svg: &str) -> f64 {
        let axis = svg.find(">takt [s]<").expect("the takt axis");
        let last = svg[..axis].rfind("class=\"tick\">").expect("ticks");
        let rest = &svg[last + 13..];
        rest[..rest.find('<').unwrap()].parse().unwrap()
    }

    #[test]
    fn a_refill_interval_ten_times_the_takt_cuts_the_axis_and_is_marked() {
        // Means 1.4 to 3.9 s, one maximum of 20 s: the axis stops near the means.
        let bars = [bar("A", 1.4, 2.0), bar("B", 3.9, 20.3), bar("C", 2.0, 2.6)];
        let svg = takt_svg("t", &bars);
        let top = top_tick(&svg);
        assert!((3.9..=8.0).contains(&top), "axis top {top} s");
        assert_eq!(svg.matches("class=\"beyond\"").count(), 1, "one bar has a value beyond");
        assert!(svg.contains(">max 20.3</text>"), "the value is written");
        assert!(svg.contains("Axis cut at"));
        // No whisker runs above the plot's top edge.
        for line in svg
            .lines()
            .filter(|l| l.starts_with("<line x1=\"") && l.contains("stroke=\"#666\""))
        {
            for k in ["y1=\"", "y2=\""] {
                let i = line.find(k).unwrap() + k.len();
                let y: f64 = line[i..i + line[i..].find('"').unwrap()].parse().unwrap();
                assert!(y >= PLOT_TOP - 1e-9, "{line}");
            }
        }
        // Negative control: without the outlier the axis is not cut and nothing is marked.
        let calm = [bar("A", 1.4, 2.0), bar("B", 3.9, 5.0), bar("C", 2.0, 2.6)];
        let svg = takt_svg("t", &calm);
        assert!(!svg.contains("class=\"beyond\"") && !svg.contains("Axis cut at"));
        assert!(top_tick(&svg) >= 5.0, "the whole range is shown");
    }
}
