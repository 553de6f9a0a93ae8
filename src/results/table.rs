//! The takt table's columns, listed once: each metric with its JSON keys (`takt.json`'s and
//! `sweep.json`'s table rows), its CSV columns (`takt.csv`, `sweep.csv`: the header is this
//! list's names) and its Markdown columns (`takt.md`). Adding a metric to the table is one entry
//! here.
//!
//! The terminal's table ([`terminal`], what `binpick batch` prints) is a short list of its own:
//! the figures a user decides on, aligned, at most [`TERMINAL_WIDTH`] characters wide.
//!
//! Units: as the names say (s; ms in the Markdown's compute column; % in its rates); CSV numbers
//! with 6 decimals, empty where absent; Markdown `-` where absent, and the takt cell says why
//! there is no takt ("nothing placed", "too few placed").

use serde::{Serialize, Serializer};
use serde_json::{Value, json};

use super::Summary;
use crate::cycle::IntervalCause;
use crate::report::wrap;

/// A JSON key of a row and its value (`None`: the key is left out).
type JsonCell = (&'static str, fn(&Summary) -> Option<Value>);
/// A CSV column: its name and its text.
type CsvCell = (&'static str, fn(&Summary) -> String);
/// A Markdown column: its header, whether it is right-aligned, and its text.
type MdCell = (&'static str, bool, fn(&Summary) -> String);

/// One metric of the table, as each format writes it.
pub struct Column {
    /// Keys of the JSON row.
    pub json: &'static [JsonCell],
    /// Columns of the CSV file, in file order.
    pub csv: &'static [CsvCell],
    /// Columns of the Markdown table.
    pub md: &'static [MdCell],
}

/// A number with `d` decimals; `-` when not finite (Markdown).
pub fn num(v: f64, d: usize) -> String {
    if v.is_finite() { format!("{v:.d$}") } else { "-".into() }
}

/// A number with 6 decimals; empty when not finite (CSV).
pub fn f6(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.6}")
    } else {
        String::new()
    }
}

/// The takt cell's text: `v` with 3 decimals, or why a row has no takt (a takt is an interval
/// between two releases of one run).
pub fn takt_text(s: &Summary, v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else if s.tally.placed == 0 {
        "nothing placed".into()
    } else {
        "too few placed".into()
    }
}

/// Why a row has no takt, for the line under a table: what its picks ended in, or, when no pick
/// was attempted, what the sensor found; `None` for a row with a takt.
pub fn no_takt_why(s: &Summary) -> Option<String> {
    if s.takt.mean_s.is_finite() && s.takt.count > 0 {
        return None;
    }
    let t = &s.tally;
    let f = &t.faults;
    let placed = if t.placed == 0 {
        "nothing placed".to_string()
    } else {
        format!("only {} placed, no release-to-release interval", t.placed)
    };
    let r = &t.recognition;
    let sensed = format!(
        "{} detections in {} captures ({} of {} top-layer parts found), {} agitations, {} refills",
        r.detected, r.captures, r.top_layer_found, r.top_layer, t.agitations, t.refills
    );
    let ended = t
        .ended
        .map_or(String::new(), |e| format!("; the run ended: {}", e.text()));
    let why = if t.attempts == 0 {
        format!("no pick was attempted: no detection offered a grasp the cup takes; {sensed}")
    } else {
        // An attempt whose cup never reached a part ended on no feasible grasp, or on a fault
        // on the way there.
        let short = t.attempts.saturating_sub(t.grasps.0);
        let short = if short > 0 {
            format!(" {short} ended before the cup reached a part (no feasible grasp, or a fault on the way),")
        } else {
            String::new()
        };
        format!(
            "of {} attempts,{short} {} grasps sealed of {} tried, {} drops, {} grasps failed, {} protective stops, \
             {} collisions; {sensed}",
            t.attempts, t.grasps.1, t.grasps.0, f.drops, f.grasp_failures, f.protective_stops, f.collisions
        )
    };
    Some(format!("{}: {placed}: {why}{ended}", t.workpiece))
}

/// Faults of a row: protective stops + collisions + drops + parts lost (grasp failures are
/// counted in success, not here).
pub fn faults(s: &Summary) -> usize {
    let f = s.tally.faults;
    f.protective_stops + f.collisions + f.drops + f.parts_lost
}

/// The share of the takt spent waiting for the sensor or for compute: the waits within the takt
/// intervals over the intervals' sum (NaN without a takt).
pub fn wait_share(s: &Summary) -> f64 {
    let takts_s: f64 = s.tally.takts_s.iter().sum();
    if takts_s > 0.0 {
        (s.tally.sensor_waits.total_s + s.tally.compute_waits.total_s) / takts_s
    } else {
        f64::NAN
    }
}

/// A share as a percentage with `d` decimals; `-` when not finite.
pub fn pct(v: f64, d: usize) -> String {
    if v.is_finite() {
        format!("{:.d$} %", 100.0 * v)
    } else {
        "-".into()
    }
}

/// The widest line the terminal's table may print (characters).
pub const TERMINAL_WIDTH: usize = 110;

/// The terminal's columns: header, right-aligned, text.
const TERMINAL: &[MdCell] = &[
    ("part", false, |s| s.tally.workpiece.clone()),
    ("takt [s]", true, |s| takt_text(s, s.takt.mean_s)),
    ("first 20 [s]", true, |s| num(s.takt_first.mean_s, 3)),
    ("ref. [s]", true, |s| {
        s.reference_takt_s.map_or("-".into(), |t| num(t, 1))
    }),
    ("success", true, |s| {
        format!(
            "{} ({}/{})",
            pct(s.success_rate, 1),
            s.tally.placed_in_tolerance(),
            s.tally.attempts
        )
    }),
    ("floor [s]", true, |s| num(s.motion_floor_s, 3)),
    ("waits", true, |s| pct(wait_share(s), 0)),
    ("faults", true, |s| faults(s).to_string()),
];

/// Each column's width in [`aligned`]: its widest cell or header, at least 3 (characters).
fn column_widths(headers: &[(&str, bool)], cells: &[Vec<String>]) -> Vec<usize> {
    (0..headers.len())
        .map(|i| {
            cells
                .iter()
                .map(|r| r[i].chars().count())
                .chain([headers[i].0.chars().count(), 3])
                .max()
                .unwrap_or(3)
        })
        .collect()
}

/// An aligned Markdown table: `headers` (text, right-aligned) over the rows of `cells`, each
/// column as wide as its widest cell (at least 3).
pub fn aligned(headers: &[(&str, bool)], cells: &[Vec<String>]) -> String {
    let widths = column_widths(headers, cells);
    let pad = |text: &str, i: usize| {
        let fill = " ".repeat(widths[i] - text.chars().count());
        if headers[i].1 {
            format!("{fill}{text}")
        } else {
            format!("{text}{fill}")
        }
    };
    let line = |texts: Vec<String>| format!("| {} |\n", texts.join(" | "));
    let mut out = line(headers.iter().enumerate().map(|(i, h)| pad(h.0, i)).collect());
    out += &line(
        headers
            .iter()
            .enumerate()
            .map(|(i, h)| {
                let dashes = "-".repeat(widths[i] - 1);
                if h.1 {
                    format!("{dashes}:")
                } else {
                    format!("{dashes}-")
                }
            })
            .collect(),
    );
    for r in cells {
        out += &line(r.iter().enumerate().map(|(i, t)| pad(t, i)).collect());
    }
    out
}

/// One row of [`aligned_keyed`]: the cells before the key columns, one value per key, the cells
/// after them.
pub type KeyedRow = (Vec<String>, Vec<String>, Vec<String>);

/// [`aligned`] with a column per key (`keys`) between the `head` and `tail` columns where every
/// line then fits [`TERMINAL_WIDTH`], else the table without the key columns; and whether the
/// keys' columns are in it (where not, the caller lists the values elsewhere).
pub fn aligned_keyed(
    head: &[(&str, bool)],
    keys: &[(&str, bool)],
    tail: &[(&str, bool)],
    rows: &[KeyedRow],
) -> (String, bool) {
    let table = |with_keys: bool| {
        let keys = if with_keys { keys } else { &[] };
        let headers: Vec<(&str, bool)> = head.iter().chain(keys).chain(tail).copied().collect();
        let cells: Vec<Vec<String>> = rows
            .iter()
            .map(|(a, v, b)| {
                let v: &[String] = if with_keys { v } else { &[] };
                a.iter().chain(v).chain(b).cloned().collect()
            })
            .collect();
        aligned(&headers, &cells)
    };
    let full = table(true);
    if full.lines().all(|l| l.chars().count() <= TERMINAL_WIDTH) {
        (full, true)
    } else {
        (table(false), false)
    }
}

/// The table as the terminal prints it: the figures a user decides on (part, takt mean over
/// every pick, the takt of each run's first 20 picks, the reference system's takt, success,
/// motion floor, the share of the takt spent waiting, faults), as an aligned Markdown table;
/// the full table is [`markdown`] (`takt.md`, `--wide`). A part name too long for
/// [`TERMINAL_WIDTH`] is cut, ending in `…`.
pub fn terminal(rows: &[Summary]) -> String {
    let mut cells: Vec<Vec<String>> = rows
        .iter()
        .map(|s| TERMINAL.iter().map(|c| (c.2)(s)).collect())
        .collect();
    let headers: Vec<(&str, bool)> = TERMINAL.iter().map(|c| (c.0, c.1)).collect();
    let others: usize = column_widths(&headers, &cells)[1..].iter().sum();
    // "| " + cells joined by " | " + " |".
    let part_chars = TERMINAL_WIDTH
        .saturating_sub(others + 3 * (TERMINAL.len() - 1) + 4)
        .max(8);
    for r in &mut cells {
        if r[0].chars().count() > part_chars {
            r[0] = r[0].chars().take(part_chars - 1).chain(['…']).collect();
        }
    }
    let out = aligned(&headers, &cells);
    out + &no_takt_notes(rows) + &incident_notes(rows)
}

/// The lines under a table that say why rows have no takt (empty when every row has one), in
/// lines of at most [`TERMINAL_WIDTH`] characters.
pub fn no_takt_notes(rows: &[Summary]) -> String {
    rows.iter()
        .filter_map(no_takt_why)
        .map(|w| format!("\n{}\n", wrap(&w, TERMINAL_WIDTH)))
        .collect()
}

/// Most incidents listed under a table per row; the JSON results hold them all.
pub const INCIDENTS_LISTED: usize = 5;

/// The lines under a table that list each row's incidents (collisions, protective stops, lost
/// parts, physics faults: when, in which run and pick, what happened), at most
/// [`INCIDENTS_LISTED`] a row; empty when there are none.
pub fn incident_notes(rows: &[Summary]) -> String {
    rows.iter().map(|s| incident_note(&s.tally.workpiece, s)).collect()
}

/// The lines that list the incidents of the row `label` (see [`incident_notes`]).
pub fn incident_note(label: &str, s: &Summary) -> String {
    let list = &s.tally.incidents;
    if list.is_empty() {
        return String::new();
    }
    let plural = if list.len() == 1 { "" } else { "s" };
    let mut out = format!("\n{label}: {} incident{plural}\n", list.len());
    for i in list.iter().take(INCIDENTS_LISTED) {
        let pick = i.pick.map_or(String::new(), |p| format!(", pick {p}"));
        // A list item; its continuation lines indented, so Markdown keeps them in the item.
        let line = format!("- seed {}{pick}, t = {:.1} s: {}", i.seed, i.t_s, i.detail);
        out += &wrap(&line, TERMINAL_WIDTH - 2).replace('\n', "\n  ");
        out.push('\n');
    }
    if list.len() > INCIDENTS_LISTED {
        out += &format!("- and {} more in the JSON results\n", list.len() - INCIDENTS_LISTED);
    }
    out
}

fn val(v: impl Serialize) -> Option<Value> {
    Some(json!(v))
}

/// The takt by what happened in its intervals: per cause ([`IntervalCause`]), how many
/// intervals and what they add to the mean takt (s; the shares add up to it).
pub fn takt_by_cause_json(s: &Summary) -> Value {
    let c = &s.tally.takt_causes;
    let mut m = serde_json::Map::new();
    for cause in IntervalCause::ALL {
        m.insert(
            cause.name().into(),
            json!({"intervals": c.count(cause), "share_s": c.share_s(cause)}),
        );
    }
    Value::Object(m)
}

/// The table's metrics, in CSV order.
pub const COLUMNS: &[Column] = &[
    Column {
        json: &[("workpiece", |s| val(&s.tally.workpiece))],
        csv: &[("workpiece", |s| s.tally.workpiece.clone())],
        md: &[("part", false, |s| s.tally.workpiece.clone())],
    },
    Column {
        // Runs that ended on a physics fault are marked (the JSON key and the Markdown mark only
        // when there are some, so tables without faults read as before).
        json: &[
            ("runs", |s| val(s.tally.runs)),
            ("runs_ended_on_physics_fault", |s| {
                let n = s.tally.physics_faults.len();
                (n > 0).then(|| json!(n))
            }),
        ],
        csv: &[("runs", |s| s.tally.runs.to_string())],
        md: &[("runs", true, |s| match s.tally.physics_faults.len() {
            0 => s.tally.runs.to_string(),
            n => format!("{} ({n} ended on a physics fault)", s.tally.runs),
        })],
    },
    Column {
        json: &[
            ("attempts", |s| val(s.tally.attempts)),
            ("placed", |s| val(s.tally.placed)),
        ],
        csv: &[
            ("attempts", |s| s.tally.attempts.to_string()),
            ("placed", |s| s.tally.placed.to_string()),
        ],
        md: &[("placed / attempts", true, |s| {
            format!("{}/{}", s.tally.placed, s.tally.attempts)
        })],
    },
    Column {
        json: &[("success_rate", |s| val(s.success_rate))],
        csv: &[("success_rate", |s| f6(s.success_rate))],
        md: &[("success", true, |s| format!("{} %", num(100.0 * s.success_rate, 1)))],
    },
    Column {
        json: &[("takt", |s| val(s.takt))],
        csv: &[
            ("takt_mean_s", |s| f6(s.takt.mean_s)),
            ("takt_p95_s", |s| f6(s.takt.p95_s)),
            ("takt_min_s", |s| f6(s.takt.min_s)),
            ("takt_max_s", |s| f6(s.takt.max_s)),
            ("takt_count", |s| s.takt.count.to_string()),
        ],
        md: &[
            ("takt mean [s]", true, |s| takt_text(s, s.takt.mean_s)),
            ("p95", true, |s| num(s.takt.p95_s, 3)),
            ("min", true, |s| num(s.takt.min_s, 3)),
            ("max", true, |s| num(s.takt.max_s, 3)),
        ],
    },
    Column {
        json: &[("takt_first20", |s| val(s.takt_first))],
        csv: &[
            ("takt_first20_mean_s", |s| f6(s.takt_first.mean_s)),
            ("takt_first20_count", |s| s.takt_first.count.to_string()),
        ],
        md: &[("takt first 20 [s]", true, |s| takt_text(s, s.takt_first.mean_s))],
    },
    Column {
        json: &[("parts_per_hour", |s| val(s.parts_per_hour))],
        csv: &[("parts_per_hour", |s| f6(s.parts_per_hour))],
        md: &[("parts/h", true, |s| num(s.parts_per_hour, 0))],
    },
    Column {
        json: &[("pile_loads_placed", |s| val(s.pile_loads))],
        csv: &[("pile_loads_placed", |s| f6(s.pile_loads))],
        md: &[("pile loads placed / run", true, |s| num(s.pile_loads, 2))],
    },
    Column {
        json: &[("reference_takt_s", |s| val(s.reference_takt_s))],
        csv: &[("reference_takt_s", |s| s.reference_takt_s.map_or(String::new(), f6))],
        md: &[("reference [s]", true, |s| {
            s.reference_takt_s.map_or("-".into(), |t| num(t, 1))
        })],
    },
    Column {
        json: &[("takt_excl_refills", |s| val(s.takt_excl_refills))],
        csv: &[("takt_excl_refills_mean_s", |s| f6(s.takt_excl_refills.mean_s))],
        md: &[("takt excl. tray refills [s]", true, |s| {
            num(s.takt_excl_refills.mean_s, 3)
        })],
    },
    Column {
        json: &[("takt_by_cause", |s| Some(takt_by_cause_json(s)))],
        csv: &[
            ("takt_clean_share_s", |s| {
                f6(s.tally.takt_causes.share_s(IntervalCause::Clean))
            }),
            ("takt_failed_share_s", |s| {
                f6(s.tally.takt_causes.share_s(IntervalCause::Failed))
            }),
            ("takt_dose_share_s", |s| {
                f6(s.tally.takt_causes.share_s(IntervalCause::Dose))
            }),
            ("takt_refill_share_s", |s| {
                f6(s.tally.takt_causes.share_s(IntervalCause::Refill))
            }),
        ],
        md: &[("takt by cause: clean/failed/dose/refill [s]", true, |s| {
            IntervalCause::ALL
                .map(|c| num(s.tally.takt_causes.share_s(c), 3))
                .join("/")
        })],
    },
    Column {
        json: &[("mean_pick_s", |s| val(s.mean_pick_s))],
        csv: &[("mean_pick_s", |s| f6(s.mean_pick_s))],
        md: &[("Pick [s]", true, |s| num(s.mean_pick_s, 3))],
    },
    Column {
        json: &[("mean_place_s", |s| val(s.mean_place_s))],
        csv: &[("mean_place_s", |s| f6(s.mean_place_s))],
        md: &[("Place [s]", true, |s| num(s.mean_place_s, 3))],
    },
    Column {
        json: &[("motion_floor_s", |s| val(s.motion_floor_s))],
        csv: &[("motion_floor_s", |s| f6(s.motion_floor_s))],
        md: &[("motion floor [s]", true, |s| num(s.motion_floor_s, 3))],
    },
    Column {
        json: &[("mean_compute_s", |s| val(s.mean_compute))],
        csv: &[
            ("mean_grasp_compute_s", |s| f6(s.mean_compute.grasp_s)),
            ("mean_pick_compute_s", |s| f6(s.mean_compute.pick_s)),
            ("mean_place_compute_s", |s| f6(s.mean_compute.place_s)),
        ],
        md: &[("compute grasp/Pick/Place [ms]", true, |s| {
            let c = s.mean_compute;
            format!(
                "{}/{}/{}",
                num(c.grasp_s * 1e3, 1),
                num(c.pick_s * 1e3, 1),
                num(c.place_s * 1e3, 1)
            )
        })],
    },
    Column {
        json: &[("median_result_to_motion_s", |s| val(s.median_result_to_motion_s))],
        csv: &[("median_result_to_motion_compute_s", |s| f6(s.median_result_to_motion_s))],
        md: &[("result to motion median [ms]", true, |s| {
            num(s.median_result_to_motion_s * 1e3, 1)
        })],
    },
    Column {
        json: &[("sensor_waits", |s| {
            val((s.tally.sensor_waits.count, s.tally.sensor_waits.mean_s()))
        })],
        csv: &[
            ("sensor_waits", |s| s.tally.sensor_waits.count.to_string()),
            ("sensor_wait_mean_s", |s| f6(s.tally.sensor_waits.mean_s())),
        ],
        md: &[("sensor waits (mean s)", true, |s| {
            let w = s.tally.sensor_waits;
            format!("{} ({})", w.count, num(w.mean_s(), 3))
        })],
    },
    Column {
        json: &[("compute_waits", |s| {
            val((s.tally.compute_waits.count, s.tally.compute_waits.mean_s()))
        })],
        csv: &[
            ("compute_waits", |s| s.tally.compute_waits.count.to_string()),
            ("compute_wait_mean_s", |s| f6(s.tally.compute_waits.mean_s())),
        ],
        md: &[("compute waits (mean s)", true, |s| {
            let w = s.tally.compute_waits;
            format!("{} ({})", w.count, num(w.mean_s(), 3))
        })],
    },
    Column {
        json: &[("protective_stops", |s| val(s.tally.faults.protective_stops))],
        csv: &[("protective_stops", |s| s.tally.faults.protective_stops.to_string())],
        md: &[("stops", true, |s| s.tally.faults.protective_stops.to_string())],
    },
    Column {
        json: &[("collisions", |s| val(s.tally.faults.collisions))],
        csv: &[("collisions", |s| s.tally.faults.collisions.to_string())],
        md: &[("collisions", true, |s| s.tally.faults.collisions.to_string())],
    },
    Column {
        json: &[("drops", |s| val(s.tally.faults.drops))],
        csv: &[("drops", |s| s.tally.faults.drops.to_string())],
        md: &[("drops", true, |s| s.tally.faults.drops.to_string())],
    },
    Column {
        json: &[("grasp_failures", |s| val(s.tally.faults.grasp_failures))],
        csv: &[("grasp_failures", |s| s.tally.faults.grasp_failures.to_string())],
        md: &[("grasp fails", true, |s| s.tally.faults.grasp_failures.to_string())],
    },
    Column {
        json: &[("parts_lost", |s| val(s.tally.faults.parts_lost))],
        csv: &[("parts_lost", |s| s.tally.faults.parts_lost.to_string())],
        md: &[("lost", true, |s| s.tally.faults.parts_lost.to_string())],
    },
    Column {
        json: &[("agitations", |s| val(s.tally.agitations))],
        csv: &[("agitations", |s| s.tally.agitations.to_string())],
        md: &[("agitations", true, |s| s.tally.agitations.to_string())],
    },
    Column {
        json: &[("doses", |s| val(s.tally.doses))],
        csv: &[("doses", |s| s.tally.doses.to_string())],
        md: &[("doses", true, |s| s.tally.doses.to_string())],
    },
    Column {
        json: &[("refills", |s| val(s.tally.refills))],
        csv: &[("refills", |s| s.tally.refills.to_string())],
        md: &[("refills", true, |s| s.tally.refills.to_string())],
    },
    Column {
        json: &[
            ("grasps", |s| val(s.tally.grasps)),
            ("grasp_success_rate", |s| val(s.grasp_success_rate)),
        ],
        csv: &[
            ("grasps_attempted", |s| s.tally.grasps.0.to_string()),
            ("grasps_sealed", |s| s.tally.grasps.1.to_string()),
        ],
        md: &[("grasps sealed", true, |s| {
            format!("{} %", num(100.0 * s.grasp_success_rate, 1))
        })],
    },
    Column {
        json: &[("misrecognised", |s| val(s.tally.misrecognised))],
        csv: &[("misrecognised", |s| s.tally.misrecognised.to_string())],
        md: &[("misrecognised", true, |s| s.tally.misrecognised.to_string())],
    },
    Column {
        json: &[("picks_per_capture", |s| val(s.picks_per_capture))],
        csv: &[("picks_per_capture", |s| f6(s.picks_per_capture))],
        md: &[("picks / capture", true, |s| num(s.picks_per_capture, 2))],
    },
    Column {
        json: &[("blind_picks", |s| val(s.tally.blind_picks))],
        csv: &[
            ("blind_picks", |s| s.tally.blind_picks.0.to_string()),
            ("blind_picks_placed", |s| s.tally.blind_picks.1.to_string()),
        ],
        md: &[("blind picks placed", true, |s| {
            format!("{}/{}", s.tally.blind_picks.1, s.tally.blind_picks.0)
        })],
    },
    Column {
        json: &[("recognition", |s| val(s.recognition))],
        csv: &[
            ("recognition_recall", |s| f6(s.recognition.recall)),
            ("recognition_precision", |s| f6(s.recognition.precision)),
            ("pose_error_median_mm", |s| f6(s.recognition.position_error_mm[0])),
            ("pose_error_p95_mm", |s| f6(s.recognition.position_error_mm[1])),
            ("pose_error_median_deg", |s| f6(s.recognition.rotation_error_deg[0])),
            ("pose_error_p95_deg", |s| f6(s.recognition.rotation_error_deg[1])),
        ],
        md: &[
            ("recognition recall / precision", true, |s| {
                let r = &s.recognition;
                format!("{} % / {} %", num(100.0 * r.recall, 1), num(100.0 * r.precision, 1))
            }),
            ("pose error med mm / deg", true, |s| {
                let r = &s.recognition;
                format!(
                    "{} / {}",
                    num(r.position_error_mm[0], 2),
                    num(r.rotation_error_deg[0], 2)
                )
            }),
        ],
    },
    Column {
        json: &[("placement", |s| val(s.placement))],
        csv: &[
            ("placement_error_median_mm", |s| f6(s.placement.position_error_mm[0])),
            ("placement_error_p95_mm", |s| f6(s.placement.position_error_mm[1])),
            ("placement_rotation_median_deg", |s| {
                f6(s.placement.rotation_error_deg[0])
            }),
            ("placement_rotation_p95_deg", |s| f6(s.placement.rotation_error_deg[1])),
            ("misplaced", |s| s.placement.misplaced.to_string()),
        ],
        md: &[
            ("placement error med mm / deg", true, |s| {
                let p = &s.placement;
                format!(
                    "{} / {}",
                    num(p.position_error_mm[0], 2),
                    num(p.rotation_error_deg[0], 2)
                )
            }),
            ("misplaced", true, |s| s.placement.misplaced.to_string()),
        ],
    },
    Column {
        json: &[("peak_demand_ratio", |s| val(s.peak_demand_ratio()))],
        csv: &[("peak_demand_ratio", |s| f6(s.peak_demand_ratio()))],
        md: &[("peak torque demand", true, |s| {
            format!("{} %", num(100.0 * s.peak_demand_ratio(), 1))
        })],
    },
    Column {
        json: &[("saturated_s", |s| val(s.tally.saturated_s))],
        csv: &[("saturated_s", |s| f6(s.tally.saturated_s))],
        md: &[("saturated [s]", true, |s| num(s.tally.saturated_s, 3))],
    },
    Column {
        json: &[("max_tracking_error_deg", |s| val(s.tally.max_tracking_error_deg))],
        csv: &[("max_tracking_error_deg", |s| f6(s.tally.max_tracking_error_deg))],
        md: &[("max tracking error [deg]", true, |s| {
            num(s.tally.max_tracking_error_deg, 3)
        })],
    },
    Column {
        json: &[
            ("sim_time_s", |s| val(s.tally.sim_time_s)),
            ("wall_s", |s| s.tally.wall_s.map(|w| json!(w))),
        ],
        csv: &[("sim_time_s", |s| f6(s.tally.sim_time_s))],
        md: &[],
    },
];

fn csv_cells() -> impl Iterator<Item = &'static CsvCell> {
    COLUMNS.iter().flat_map(|c| c.csv.iter())
}

fn md_cells() -> impl Iterator<Item = &'static MdCell> {
    COLUMNS.iter().flat_map(|c| c.md.iter())
}

/// The CSV header's names, in order.
pub fn csv_header() -> Vec<&'static str> {
    csv_cells().map(|c| c.0).collect()
}

/// One summary's CSV fields, in header order (unquoted).
pub fn csv_fields(s: &Summary) -> Vec<String> {
    csv_cells().map(|c| (c.1)(s)).collect()
}

/// The table as CSV (`takt.csv`): fields quoted where they need it.
pub fn csv(rows: &[Summary]) -> String {
    crate::report::to_csv(&csv_header(), rows.iter().map(csv_fields))
}

/// The table as Markdown (`takt.md`).
pub fn markdown(rows: &[Summary]) -> String {
    let mut md = String::from("|");
    let mut rule = String::from("|");
    for (header, right, _) in md_cells() {
        md += &format!(" {header} |");
        rule += if *right { "---:|" } else { "---|" };
    }
    md += &format!("\n{rule}\n");
    for s in rows {
        md += "|";
        for (_, _, cell) in md_cells() {
            md += &format!(" {} |", cell(s));
        }
        md += "\n";
    }
    md + &no_takt_notes(rows) + &incident_notes(rows)
}

/// A row as JSON: every key of the list (the order is the map's).
impl Serialize for Summary {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let row: serde_json::Map<String, Value> = COLUMNS
            .iter()
            .flat_map(|c| c.json.iter())
            .filter_map(|(k, v)| v(self).map(|v| (k.to_string(), v)))
            .collect();
        row.serialize(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cycle::Tally;

    /// Names that appear twice in a list of columns.
    fn repeated(names: &[&str]) -> Vec<String> {
        let mut seen = std::collections::BTreeSet::new();
        names
            .iter()
            .filter(|n| !seen.insert(**n))
            .map(|n| n.to_string())
            .collect()
    }

    #[test]
    fn every_format_has_one_cell_per_column_and_no_name_twice() {
        let t = Tally {
            workpiece: "A".into(),
            runs: 1,
            ..Tally::default()
        };
        let s = Summary::of(&t);
        assert_eq!(csv_fields(&s).len(), csv_header().len());
        assert_eq!(repeated(&csv_header()), Vec::<String>::new());
        let json_keys: Vec<&str> = COLUMNS.iter().flat_map(|c| c.json.iter().map(|j| j.0)).collect();
        assert_eq!(repeated(&json_keys), Vec::<String>::new());
        let md = markdown(std::slice::from_ref(&s));
        let bars: Vec<usize> = md
            .lines()
            .filter(|l| l.starts_with('|'))
            .map(|l| l.matches('|').count())
            .collect();
        assert!(bars.windows(2).all(|w| w[0] == w[1]), "{md}");
        // Empty figures: `-` in Markdown, empty in CSV, null in JSON; the wall time left out.
        assert!(
            md.lines()
                .nth(2)
                .unwrap()
                .starts_with("| A | 1 | 0/0 | - % | nothing placed | - |"),
            "{md}"
        );
        let row = serde_json::to_value(&s).unwrap();
        assert!(row["success_rate"].is_null() && row.get("wall_s").is_none());
        // Negative control: the check finds a name given twice.
        assert_eq!(repeated(&["a", "b", "a"]), vec!["a".to_string()]);
    }

    #[test]
    fn parts_per_hour_are_3600_s_over_the_mean_takt_beside_the_first_20() {
        let s = Summary::of(&Tally {
            workpiece: "E".into(),
            runs: 1,
            attempts: 4,
            placed: 4,
            pile_count: 2,
            takts_s: vec![2.0, 4.0, 3.0],
            takts_first_s: vec![2.0],
            ..Tally::default()
        });
        // 3 intervals over 9 s: 1200 releases per hour; two pile loads placed.
        assert_eq!(
            (s.parts_per_hour, s.takt_first.mean_s, s.pile_loads),
            (1200.0, 2.0, 2.0)
        );
        let md = markdown(std::slice::from_ref(&s));
        assert!(
            md.contains("| 3.000 |") && md.contains("| 2.000 |") && md.contains("| 1200 |"),
            "{md}"
        );
        // The terminal keeps the reference's columns; parts per hour is in the full table.
        assert!(terminal(std::slice::from_ref(&s)).contains(" 2.000 |"));
        // Negative control: without a takt there is no rate, and no pile size no pile loads.
        let none = Summary::of(&Tally {
            workpiece: "E".into(),
            ..Tally::default()
        });
        assert!(none.parts_per_hour.is_nan() && none.pile_loads.is_nan());
    }

    #[test]
    fn a_row_without_a_takt_says_why_under_the_table() {
        use crate::cycle::Faults;
        // Picks tried and dropped.
        let dropped = Summary::of(&Tally {
            workpiece: "C-mesh".into(),
            runs: 1,
            attempts: 5,
            grasps: (5, 5),
            faults: Faults {
                drops: 5,
                ..Faults::default()
            },
            ..Tally::default()
        });
        let why = no_takt_why(&dropped).unwrap();
        assert!(
            why.starts_with("C-mesh: nothing placed: of 5 attempts, 5 grasps sealed of 5 tried, 5 drops"),
            "{why}"
        );
        // Picks whose cup never reached a part: said so.
        let short = Summary::of(&Tally {
            workpiece: "R".into(),
            runs: 1,
            attempts: 3,
            ..Tally::default()
        });
        let why = no_takt_why(&short).unwrap();
        assert!(
            why.contains("of 3 attempts, 3 ended before the cup reached a part"),
            "{why}"
        );
        // No pick tried: what the sensor found.
        let mut blind = Tally {
            workpiece: "dip8".into(),
            runs: 1,
            agitations: 4,
            ..Tally::default()
        };
        blind.recognition.captures = 6;
        blind.recognition.top_layer = 120;
        let why = no_takt_why(&Summary::of(&blind)).unwrap();
        assert!(
            why.contains("no pick was attempted")
                && why.contains("0 detections in 6 captures")
                && why.contains("4 agitations"),
            "{why}"
        );
        let table = terminal(&[Summary::of(&blind)]);
        assert!(
            table.contains("no pick was attempted") && table.lines().all(|l| l.chars().count() <= TERMINAL_WIDTH),
            "{table}"
        );
        // Negative control: a row with a takt has no note.
        let fine = Summary::of(&Tally {
            workpiece: "E".into(),
            runs: 1,
            attempts: 3,
            placed: 3,
            takts_s: vec![1.5, 1.25],
            ..Tally::default()
        });
        assert_eq!(no_takt_why(&fine), None);
        assert_eq!(no_takt_notes(&[fine]), "");
    }

    #[test]
    fn incidents_are_listed_under_the_table_at_most_five_a_row() {
        use crate::cycle::{Incident, IncidentKind};
        let incident = |k: usize| Incident {
            seed: 3,
            pick: Some(100 + k),
            t_s: 250.0 + k as f64,
            kind: IncidentKind::Fault,
            detail: format!(
                "collision: link 6 and part {k} during the Place motion, far too long a line to print {}",
                "x ".repeat(40)
            ),
        };
        let row = |n: usize| {
            Summary::of(&Tally {
                workpiece: "B".into(),
                runs: 1,
                attempts: 10,
                placed: 9,
                takts_s: vec![1.5; 8],
                incidents: (0..n).map(incident).collect(),
                ..Tally::default()
            })
        };
        let notes = incident_notes(&[row(7)]);
        assert!(
            notes.starts_with("\nB: 7 incidents\n- seed 3, pick 100, t = 250.0 s: collision: link 6"),
            "{notes}"
        );
        assert_eq!(notes.matches("- seed 3").count(), INCIDENTS_LISTED);
        assert!(notes.ends_with("- and 2 more in the JSON results\n"), "{notes}");
        assert!(notes.lines().all(|l| l.chars().count() <= TERMINAL_WIDTH), "{notes}");
        // Every line of an item after its first is indented (Markdown keeps it in the item).
        assert!(
            notes
                .lines()
                .skip(2) // the blank line and the row's header
                .all(|l| l.starts_with("- ") || l.starts_with("  ")),
            "{notes}"
        );
        assert!(notes.lines().any(|l| l.starts_with("  ")), "{notes}");
        // In both tables.
        assert!(markdown(&[row(1)]).contains("B: 1 incident\n- seed 3, pick 100"));
        assert!(terminal(&[row(1)]).contains("B: 1 incident\n"));
        // Negative control: a row without incidents has no note.
        assert_eq!(incident_notes(&[row(0)]), "");
    }

    #[test]
    fn the_terminal_table_fits_110_characters_and_says_nothing_was_placed() {
        let long = Summary::of(&Tally {
            workpiece: "a-connector-with-a-very-long-file-name-from-cad".into(),
            runs: 3,
            attempts: 63,
            placed: 60,
            takts_s: vec![1.5, 12345.25],
            ..Tally::default()
        });
        let none = Summary::of(&Tally {
            workpiece: "E".into(),
            runs: 1,
            attempts: 2,
            ..Tally::default()
        });
        let rows = [long, none];
        let t = terminal(&rows);
        let widest = |s: &str| s.lines().map(|l| l.chars().count()).max().unwrap();
        assert!(widest(&t) <= TERMINAL_WIDTH, "{t}");
        assert!(t.contains("a-connector-with") && t.contains('…'), "{t}");
        assert!(t.contains("| nothing placed |") && t.contains("6173.375"), "{t}");
        assert!(!t.contains("NaN") && !markdown(&rows).contains("NaN"), "{t}");
        // Negative control: the full table does not fit.
        assert!(widest(&markdown(&rows)) > TERMINAL_WIDTH);
    }
}
