//! Report stage: the cycle's time chart as SVG.
//!
//! Job: draw one lane per stage of the cell cycle (sensor, recognition, grasp selection, planning,
//! waiting pose, pick, blind pick, place, stall, feeder: agitations and doses while placing) with a box for every interval in which that stage is busy, plus vertical
//! markers for events (a part released, a fault), over a window of simulation time, like the time
//! chart of a bin-picking paper. All times are seconds of simulation time. The output is
//! deterministic: the same input gives a byte-identical document (fixed decimals, no hash maps).

use std::fmt::Write;

use crate::svg::escape;

pub use crate::cycle::Stage as Lane;

/// Every lane, top to bottom.
pub const LANES: [Lane; 10] = [
    Lane::Sensor,
    Lane::Recognition,
    Lane::Grasp,
    Lane::Planning,
    Lane::WaitingPose,
    Lane::Pick,
    Lane::BlindPick,
    Lane::Place,
    Lane::Stall,
    Lane::Feeder,
];

/// Label shown at the left of a lane ("sensor", "recognition", "grasp selection", "planning",
/// "waiting pose", "Pick", "blind Pick", "Place", "stall", "feeder").
pub fn lane_label(lane: Lane) -> &'static str {
    match lane {
        Lane::Sensor => "sensor",
        Lane::Recognition => "recognition",
        Lane::Grasp => "grasp selection",
        Lane::Planning => "planning",
        Lane::WaitingPose => "waiting pose",
        Lane::Pick => "Pick",
        Lane::BlindPick => "blind Pick",
        Lane::Place => "Place",
        Lane::Stall => "stall",
        Lane::Feeder => "feeder",
    }
}

fn lane_colour(lane: Lane) -> &'static str {
    match lane {
        Lane::Sensor => "#4e79a7",
        Lane::Recognition => "#f28e2b",
        Lane::Grasp => "#e15759",
        Lane::Planning => "#76b7b2",
        Lane::WaitingPose => "#bab0ac",
        Lane::Pick => "#59a14f",
        Lane::BlindPick => "#8cd17d",
        Lane::Place => "#edc948",
        Lane::Stall => "#b07aa1",
        Lane::Feeder => "#9c755f",
    }
}

/// A busy interval on one lane.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Span {
    /// The lane the box is drawn on.
    pub lane: Lane,
    /// Start of the interval (s).
    pub start_s: f64,
    /// End of the interval (s); a span with `end_s <= start_s` is not drawn.
    pub end_s: f64,
    /// Text drawn in the box (if it fits) and in its tooltip.
    pub label: String,
}

/// A vertical marker across all lanes (e.g. a release of a part, a fault).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Marker {
    /// When the event happened (s).
    pub t_s: f64,
    /// Text drawn at the top of the marker.
    pub label: String,
}

/// The observer that keeps a run's spans and markers for its time chart.
#[derive(Debug, Clone, Default)]
pub struct TimeChart {
    /// Busy intervals, in the order the run reported them.
    pub spans: Vec<Span>,
    /// Markers (releases, faults).
    pub markers: Vec<Marker>,
}

impl crate::cycle::Observer for TimeChart {
    fn span(&mut self, stage: Lane, start_s: f64, end_s: f64, label: &str) {
        self.spans.push(Span {
            lane: stage,
            start_s,
            end_s,
            label: label.to_string(),
        });
    }

    fn marker(&mut self, t_s: f64, label: &str) {
        self.markers.push(Marker {
            t_s,
            label: label.to_string(),
        });
    }
}

/// Whether a span keeps a window from showing the steady state: a refill, an agitation and the
/// pile's settling, a wait for the sensor (at the waiting pose or stalled), a fault's reset.
/// Short waits for compute are part of the steady state and do not count.
fn disturbs_steady_state(span: &Span) -> bool {
    match span.lane {
        Lane::Feeder | Lane::WaitingPose => true,
        Lane::Stall => span.label != "waiting for compute",
        _ => false,
    }
}

/// Margin drawn before the first and after the last release of a steady-state window (s).
const STEADY_MARGIN_S: f64 = 0.2;

impl TimeChart {
    /// The run's time chart over its whole length (`end_s` of simulation time), and a close-up
    /// of three takts in the steady state, as SVG documents. The close-up spans four
    /// consecutive releases of `releases_s` (after the first takt) in which the cell neither
    /// refills, agitates, waits for the sensor nor resets a fault, the one nearest the middle of
    /// the run; a run without such a window shows its middle three takts and says so in the
    /// title. No close-up for a run of fewer than five releases.
    pub fn svgs(&self, title: &str, end_s: f64, releases_s: &[f64]) -> (String, Option<String>) {
        let whole = time_chart_svg(title, &self.spans, &self.markers, 0.0, end_s);
        let steady = (releases_s.len() >= 5).then(|| {
            let window = |i: usize| {
                (
                    releases_s[i] - STEADY_MARGIN_S,
                    releases_s[(i + 3).min(releases_s.len() - 1)] + STEADY_MARGIN_S,
                )
            };
            let clean = |i: usize| {
                let (t0, t1) = window(i);
                !self
                    .spans
                    .iter()
                    .any(|s| disturbs_steady_state(s) && s.end_s > t0 && s.start_s < t1 && s.end_s > s.start_s)
                    && !self
                        .markers
                        .iter()
                        .any(|m| m.label == "fault" && m.t_s > t0 && m.t_s < t1)
            };
            let middle = releases_s.len() / 2 - 1;
            let mut starts: Vec<usize> = (1..releases_s.len() - 3).collect();
            starts.sort_by_key(|i| i.abs_diff(middle));
            let (i, caption) = match starts.into_iter().find(|i| clean(*i)) {
                Some(i) => (i, "three takts in the steady state (no refill, agitation or wait for the sensor)"),
                None => (
                    middle,
                    "three takts in the middle of the run (it has none without a refill, an agitation or a wait for the sensor)",
                ),
            };
            let (t0, t1) = window(i);
            time_chart_svg(&format!("{title}: {caption}"), &self.spans, &self.markers, t0, t1)
        });
        (whole, steady)
    }
}

const WIDTH: f64 = 1200.0;
const LABEL_W: f64 = 130.0;
const RIGHT_PAD: f64 = 30.0;
const TOP: f64 = 48.0;
const LANE_H: f64 = 36.0;
const AXIS_H: f64 = 44.0;
const CHAR_W: f64 = 6.0;
/// Width of a character of a marker's 10 px label, an estimate (px).
const MARKER_CHAR_W: f64 = 5.5;

/// Renders the spans (and markers) whose time overlaps [t0_s, t1_s] as a standalone SVG document.
///
/// Spans are clipped to the window; spans with a non-finite time, with `end_s <= start_s` or with
/// no overlap of positive length with the window are skipped, as are markers outside it. An empty
/// or invalid window (`t1_s <= t0_s`, non-finite) becomes a 1 s window from `t0_s` (from 0 if
/// `t0_s` is not finite). Never panics; the document ends with `</svg>` and a newline.
pub fn time_chart_svg(title: &str, spans: &[Span], markers: &[Marker], t0_s: f64, t1_s: f64) -> String {
    let (t0, t1) = if t0_s.is_finite() && t1_s.is_finite() && t1_s > t0_s && (t1_s - t0_s).is_finite() {
        (t0_s, t1_s)
    } else {
        let t0 = if t0_s.is_finite() { t0_s } else { 0.0 };
        if t0 + 1.0 > t0 { (t0, t0 + 1.0) } else { (0.0, 1.0) } // |t0| so large that t0 + 1 == t0
    };
    let plot_w = WIDTH - LABEL_W - RIGHT_PAD;
    let right = LABEL_W + plot_w;
    let x_of = |t: f64| LABEL_W + ((t - t0) / (t1 - t0)).clamp(0.0, 1.0) * plot_w;
    let lanes_bottom = TOP + LANE_H * LANES.len() as f64;
    let height = lanes_bottom + AXIS_H;
    let mut s = String::new();
    // Writing to a String cannot fail.
    macro_rules! out {
        ($($arg:tt)*) => {
            let _ = writeln!(s, $($arg)*);
        };
    }
    out!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"{WIDTH:.0}\" height=\"{height:.0}\" \
         viewBox=\"0 0 {WIDTH:.0} {height:.0}\" font-family=\"sans-serif\" font-size=\"12\">"
    );
    out!("<rect x=\"0\" y=\"0\" width=\"{WIDTH:.0}\" height=\"{height:.0}\" fill=\"#ffffff\"/>");
    let title = escape(title);
    out!("<text x=\"{LABEL_W:.1}\" y=\"22.0\" font-size=\"16\">{title}</text>");
    for (i, lane) in LANES.iter().enumerate() {
        let y = TOP + LANE_H * i as f64;
        let fill = if i % 2 == 0 { "#f4f4f4" } else { "#ffffff" };
        out!("<rect x=\"{LABEL_W:.1}\" y=\"{y:.1}\" width=\"{plot_w:.1}\" height=\"{LANE_H:.1}\" fill=\"{fill}\"/>");
        let (lx, ly, label) = (LABEL_W - 8.0, y + LANE_H / 2.0 + 4.0, lane_label(*lane));
        out!("<text x=\"{lx:.1}\" y=\"{ly:.1}\" text-anchor=\"end\">{label}</text>");
    }
    // Grid lines and the time axis.
    let step = tick_step(t1 - t0);
    let decimals = (-step.log10()).ceil().clamp(0.0, 6.0) as usize;
    let k0 = (t0 / step - 1e-9).ceil();
    let (tick_bottom, tick_label_y, caption_y) = (lanes_bottom + 5.0, lanes_bottom + 18.0, lanes_bottom + 36.0);
    out!(
        "<line x1=\"{LABEL_W:.1}\" y1=\"{lanes_bottom:.1}\" x2=\"{right:.1}\" y2=\"{lanes_bottom:.1}\" \
         stroke=\"#999999\"/>"
    );
    for i in 0..=20 {
        let t = (k0 + f64::from(i)) * step + 0.0; // + 0.0 turns -0.0 into 0.0
        if t.is_nan() || t > t1 + step * 1e-9 {
            break;
        }
        let x = x_of(t);
        out!("<line x1=\"{x:.1}\" y1=\"{TOP:.1}\" x2=\"{x:.1}\" y2=\"{lanes_bottom:.1}\" stroke=\"#e0e0e0\"/>");
        out!("<line x1=\"{x:.1}\" y1=\"{lanes_bottom:.1}\" x2=\"{x:.1}\" y2=\"{tick_bottom:.1}\" stroke=\"#999999\"/>");
        out!("<text class=\"tick\" x=\"{x:.1}\" y=\"{tick_label_y:.1}\" text-anchor=\"middle\">{t:.decimals$}</text>");
    }
    out!("<text x=\"{right:.1}\" y=\"{caption_y:.1}\" text-anchor=\"end\">time (s)</text>");
    // Spans, clipped to the window.
    for span in spans {
        let (a, b) = (span.start_s, span.end_s);
        if !(a.is_finite() && b.is_finite()) || b <= a || b <= t0 || a >= t1 {
            continue;
        }
        let lane_i = LANES.iter().position(|l| *l == span.lane).unwrap_or(0);
        let (x, y, h) = (x_of(a), TOP + LANE_H * lane_i as f64 + 6.0, LANE_H - 12.0);
        let w = (x_of(b) - x).max(1.0);
        let (text, lane, colour, d) = (
            escape(&span.label),
            lane_label(span.lane),
            lane_colour(span.lane),
            b - a,
        );
        out!(
            "<rect class=\"span\" x=\"{x:.1}\" y=\"{y:.1}\" width=\"{w:.1}\" height=\"{h:.1}\" fill=\"{colour}\" \
             stroke=\"#333333\" stroke-width=\"0.5\">\
             <title>{lane}: {text}, {a:.3} s to {b:.3} s ({d:.3} s)</title></rect>"
        );
        if !text.is_empty() && w >= span.label.chars().count() as f64 * CHAR_W + 6.0 {
            let (tx, ty) = (x + w / 2.0, y + h / 2.0 + 4.0);
            out!("<text x=\"{tx:.1}\" y=\"{ty:.1}\" text-anchor=\"middle\" font-size=\"11\">{text}</text>");
        }
    }
    // Event markers. A label that would run into the one before is left out (its line keeps it
    // as a tooltip): releases a second apart at a 40 s scale would print over each other.
    let (line_top, marker_label_y) = (TOP - 4.0, TOP - 7.0);
    let mut labels_end_x = f64::NEG_INFINITY;
    for m in markers
        .iter()
        .filter(|m| m.t_s.is_finite() && m.t_s >= t0 && m.t_s <= t1)
    {
        let (x, label) = (x_of(m.t_s), escape(&m.label));
        out!(
            "<line class=\"marker\" x1=\"{x:.1}\" y1=\"{line_top:.1}\" x2=\"{x:.1}\" y2=\"{lanes_bottom:.1}\" \
             stroke=\"#cc0000\" stroke-dasharray=\"4 3\"><title>{label}</title></line>"
        );
        let half_w = m.label.chars().count() as f64 * MARKER_CHAR_W / 2.0;
        if x - half_w < labels_end_x + 4.0 {
            continue;
        }
        labels_end_x = x + half_w;
        out!(
            "<text x=\"{x:.1}\" y=\"{marker_label_y:.1}\" text-anchor=\"middle\" font-size=\"10\" \
             fill=\"#cc0000\">{label}</text>"
        );
    }
    s.push_str("</svg>\n");
    s
}

/// The tick step of the time axis: the smallest 1, 2, 5 x 10^k step (0.1, 0.2, 0.5, 1, 2, 5, 10 s, ...)
/// that gives at most 15 intervals over a window `width_s` long (so 6 to 15 intervals).
fn tick_step(width_s: f64) -> f64 {
    if !(width_s.is_finite() && width_s > 0.0) {
        return 1.0;
    }
    let base = 10f64.powi((width_s / 15.0).log10().floor() as i32);
    for m in [1.0, 2.0, 5.0, 10.0] {
        let step = base * m;
        if step > 0.0 && width_s / step <= 15.0 * (1.0 + 1e-9) {
            return step;
        }
    }
    width_s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(lane: Lane, start_s: f64, end_s: f64, label: &str) -> Span {
        Span {
            lane,
            start_s,
            end_s,
            label: label.to_string(),
        }
    }

    fn is_document(svg: &str) -> bool {
        svg.starts_with("<svg xmlns=\"http://www.w3.org/2000/svg\"") && svg.ends_with("</svg>\n")
    }

    #[test]
    fn one_span_rect_per_span_in_the_window() {
        let spans = [
            span(Lane::Sensor, 0.0, 0.4, "capture"),
            span(Lane::Recognition, 0.4, 0.9, "recognise"),
            span(Lane::Pick, 1.5, 3.0, "pick 1"), // straddles t1
            span(Lane::Place, 3.5, 4.0, "outside"),
            span(Lane::Sensor, -2.0, -1.0, "before"),
            span(Lane::Sensor, -1.0, 0.0, "touching"),
            span(Lane::Stall, 1.0, 0.5, "reversed"),
            span(Lane::Stall, f64::NAN, 1.0, "nan"),
            span(Lane::Grasp, 0.2, f64::INFINITY, "inf"),
            span(Lane::Planning, 2.0, 2.0, "empty"),
        ];
        let svg = time_chart_svg("cycle", &spans, &[], 0.0, 2.0);
        assert!(is_document(&svg));
        assert_eq!(svg.matches("class=\"span\"").count(), 3);
        assert!(
            svg.contains(">capture</text>")
                && !svg.contains("outside")
                && !svg.contains("before")
                && !svg.contains("touching")
        );
        assert_eq!(svg.matches("class=\"tick\"").count(), 11, "ticks at 0, 0.2, ..., 2.0");
    }

    #[test]
    fn span_straddling_t0_starts_at_the_left_edge() {
        let svg = time_chart_svg("clip", &[span(Lane::Planning, -1.0, 0.5, "plan")], &[], 0.0, 2.0);
        let plot_w = WIDTH - LABEL_W - RIGHT_PAD;
        assert!(svg.contains(&format!(
            "class=\"span\" x=\"{LABEL_W:.1}\" y=\"{:.1}\" width=\"{:.1}\"",
            TOP + 3.0 * LANE_H + 6.0,
            plot_w / 4.0
        )));
        assert!(svg.contains("-1.000 s to 0.500 s (1.500 s)"));
    }

    #[test]
    fn marker_labels_that_would_overlap_are_left_to_their_lines_tooltip() {
        // Over 40 s, releases 0.3 s apart are 8 px apart: each keeps its line and tooltip, only
        // every few gets a printed label; releases 4 s apart (a hundred px) all get one.
        let marker = |t_s: f64, k: usize| Marker {
            t_s,
            label: format!("release {k}"),
        };
        let close: Vec<Marker> = (0..10).map(|k| marker(10.0 + 0.3 * k as f64, k)).collect();
        let svg = time_chart_svg("close", &[span(Lane::Pick, 0.0, 40.0, "")], &close, 0.0, 40.0);
        let printed = svg.matches("fill=\"#cc0000\">release").count();
        assert_eq!(svg.matches("<title>release").count(), 10);
        assert!((2..=4).contains(&printed), "{printed} labels printed");
        // Control: far apart, every label is printed.
        let far: Vec<Marker> = (0..10).map(|k| marker(2.0 + 4.0 * k as f64, k)).collect();
        let svg = time_chart_svg("far", &[span(Lane::Pick, 0.0, 40.0, "")], &far, 0.0, 40.0);
        assert_eq!(svg.matches("fill=\"#cc0000\">release").count(), 10);
    }

    #[test]
    fn user_text_is_escaped() {
        let markers = [Marker {
            t_s: 1.0,
            label: "fault <&>".into(),
        }];
        let svg = time_chart_svg(
            "run \"a\" & 'b' <x>",
            &[span(Lane::Stall, 0.0, 2.0, "<&>")],
            &markers,
            0.0,
            2.0,
        );
        assert!(svg.contains("run &quot;a&quot; &amp; &apos;b&apos; &lt;x&gt;"));
        assert!(svg.contains(">&lt;&amp;&gt;</text>") && svg.contains("fault &lt;&amp;&gt;"));
        assert!(!svg.contains("<&") && !svg.contains("<x>") && !svg.contains("'b'"));
        assert_eq!(svg.matches("class=\"marker\"").count(), 1);
    }

    #[test]
    fn rendering_is_deterministic() {
        let spans: Vec<Span> = (0..40)
            .map(|i| span(LANES[i % 7], i as f64 * 0.3, i as f64 * 0.3 + 0.25, "s"))
            .collect();
        let markers = [Marker {
            t_s: 2.0,
            label: "release".into(),
        }];
        let a = time_chart_svg("det", &spans, &markers, 0.0, 12.0);
        assert_eq!(a, time_chart_svg("det", &spans, &markers, 0.0, 12.0));
        assert_eq!(a.matches("class=\"span\"").count(), 40);
    }

    #[test]
    fn degenerate_windows_still_give_a_document() {
        let spans = [
            span(Lane::Sensor, 3.0, 3.5, "x"),
            span(Lane::Pick, f64::NEG_INFINITY, 1.0, "y"),
        ];
        let (nan, inf) = (f64::NAN, f64::INFINITY);
        for (t0, t1) in [
            (1.0, 1.0),
            (2.0, 1.0),
            (nan, 5.0),
            (inf, -inf),
            (0.0, inf),
            (-1e308, 1e308),
            (0.0, 1e-300),
        ] {
            for s in [&spans[..], &[]] {
                let svg = time_chart_svg(
                    "",
                    s,
                    &[Marker {
                        t_s: nan,
                        label: "m".into(),
                    }],
                    t0,
                    t1,
                );
                assert!(is_document(&svg), "{t0} {t1}");
                assert!(!svg.contains("NaN") && !svg.contains("inf"), "{t0} {t1}");
                assert_eq!(
                    svg.matches("text-anchor=\"end\">").count(),
                    LANES.len() + 1,
                    "all lanes and the axis caption"
                );
            }
        }
        let svg = time_chart_svg("", &spans, &[], 3.0, 3.0);
        assert!(svg.contains(">3.0</text>") && svg.contains(">4.0</text>") && !svg.contains(">4.1</text>"));
        assert_eq!(svg.matches("class=\"span\"").count(), 1);
    }

    /// Releases every 2 s from 1 s; a chart with an agitation in `disturbed` takts' windows.
    fn steady_title(disturbed: &[(f64, f64)], releases: usize) -> String {
        let releases_s: Vec<f64> = (0..releases).map(|k| 1.0 + 2.0 * k as f64).collect();
        let mut chart = TimeChart::default();
        for (a, b) in disturbed {
            chart.spans.push(span(Lane::Feeder, *a, *b, "agitation"));
        }
        chart.spans.push(span(Lane::Stall, 4.0, 4.1, "waiting for compute"));
        let (_, steady) = chart.svgs("t", 30.0, &releases_s);
        let steady = steady.expect("a close-up");
        let title = &steady[steady.find("font-size=\"16\">").unwrap() + 16..];
        title[..title.find('<').unwrap()].to_string()
    }

    #[test]
    fn the_steady_close_up_avoids_disturbances_or_says_there_is_none() {
        // Nine releases (1, 3, ..., 17 s): windows start at releases 1 to 5; the middle is 3 (7 s).
        let clean = steady_title(&[], 9);
        assert!(
            clean.ends_with("(no refill, agitation or wait for the sensor)"),
            "{clean}"
        );
        // An agitation at 8 s spoils the windows from releases 1 to 3 (3-9, 5-11, 7-13 s):
        // the close-up moves to release 4 (9 s).
        let chart = {
            let mut c = TimeChart::default();
            c.spans.push(span(Lane::Feeder, 8.0, 8.5, "agitation"));
            c
        };
        let releases_s: Vec<f64> = (0..9).map(|k| 1.0 + 2.0 * k as f64).collect();
        let (_, steady) = chart.svgs("t", 30.0, &releases_s);
        let steady = steady.unwrap();
        assert!(
            steady.contains(">9.0</text>") && !steady.contains(">8.0</text>"),
            "starts after 8 s"
        );
        assert!(!steady.contains("class=\"span\""), "nothing disturbs the window shown");
        // Disturbances everywhere: the middle three takts, and the title says so.
        let none = steady_title(&[(5.0, 5.5), (10.0, 10.5), (12.5, 13.5)], 9);
        assert!(none.contains("it has none without a refill"), "{none}");
    }

    #[test]
    fn tick_step_is_a_nice_step() {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b;
        for (width, step) in [
            (1.0, 0.1),
            (1.6, 0.2),
            (3.0, 0.2),
            (6.0, 0.5),
            (10.0, 1.0),
            (12.0, 1.0),
            (25.0, 2.0),
        ] {
            assert!(close(tick_step(width), step), "{width}: {}", tick_step(width));
        }
        assert!(close(tick_step(60.0), 5.0) && close(tick_step(120.0), 10.0) && close(tick_step(0.5), 0.05));
        assert_eq!(tick_step(0.0), 1.0);
        assert_eq!(tick_step(f64::NAN), 1.0);
        for i in 1..2000 {
            let width = i as f64 * 0.037;
            let n = width / tick_step(width);
            assert!((6.0..=15.0 + 1e-6).contains(&n), "{width}: {n} intervals");
        }
    }
}
