//! Report stage, tables: the per-pick CSV and text table of a run, and the CSV writer every
//! CSV file of binpick goes through (the `csv` crate: names and reasons quoted as needed,
//! nothing replaced or lost).
//!
//! Units: as the column names say (`_s`, `_mm`, `_deg`); fixed decimals, empty where absent.

use serde::{Serialize, Serializer};

use crate::cycle::{IntervalCause, PickRecord};

/// A number written with `D` decimals in a CSV file, empty when absent or not finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fixed<const D: usize>(pub Option<f64>);

impl<const D: usize> Fixed<D> {
    /// A value (empty if not finite).
    pub fn of(v: f64) -> Self {
        Fixed(v.is_finite().then_some(v))
    }
}

impl<const D: usize> Serialize for Fixed<D> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.0 {
            Some(v) if v.is_finite() => s.serialize_str(&format!("{v:.D$}")),
            _ => s.serialize_str(""),
        }
    }
}

/// A CSV document: the `header` line, then one line per row (serialised in field order, so the
/// row type's fields must be the header's columns; a test per file checks it).
pub fn to_csv<T: Serialize>(header: &[&str], rows: impl IntoIterator<Item = T>) -> String {
    let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(Vec::new());
    // Writing to memory cannot fail; a row that does not serialise is a bug caught by the tests.
    w.write_record(header).expect("header to memory");
    for r in rows {
        w.serialize(r).expect("a CSV row of plain fields");
    }
    let bytes = w.into_inner().expect("flush to memory");
    String::from_utf8(bytes).expect("CSV of UTF-8 fields")
}

/// The columns of `picks.csv`.
pub const PICKS_CSV_HEADER: [&str; 37] = [
    "pick",
    "outcome",
    "detail",
    "capture_s",
    "ready_s",
    "release_s",
    "takt_s",
    "spans_refill",
    "interval_cause",
    "pick_s",
    "place_s",
    "stall_sensor_s",
    "stall_compute_s",
    "grasp_compute_s",
    "pick_compute_s",
    "place_compute_s",
    "placement_error_mm",
    "rotation_error_deg",
    "max_tracking_error_deg",
    "peak_demand_ratio",
    "peak_demand_joint",
    "saturated_s",
    "suction_speed_factor",
    "lift_overlap_s",
    "pick_descent_overlap_s",
    "place_descent_overlap_s",
    "retreat_overlap_s",
    "release_lead_s",
    "blind",
    "from_result",
    "picks_since_capture",
    "sealed",
    "detections",
    "correct_detections",
    "believed_pose_error_mm",
    "believed_pose_error_deg",
    "believed_pose_correct",
];

/// One row of `picks.csv`.
#[derive(Serialize)]
struct PickRow<'a> {
    pick: usize,
    outcome: &'a str,
    detail: String,
    capture_s: Fixed<6>,
    ready_s: Fixed<6>,
    release_s: Fixed<6>,
    takt_s: Fixed<6>,
    spans_refill: bool,
    interval_cause: &'static str,
    pick_s: Fixed<6>,
    place_s: Fixed<6>,
    stall_sensor_s: Fixed<6>,
    stall_compute_s: Fixed<6>,
    grasp_compute_s: Fixed<6>,
    pick_compute_s: Fixed<6>,
    place_compute_s: Fixed<6>,
    placement_error_mm: Fixed<6>,
    rotation_error_deg: Fixed<6>,
    max_tracking_error_deg: Fixed<6>,
    peak_demand_ratio: Fixed<6>,
    peak_demand_joint: usize,
    saturated_s: Fixed<6>,
    suction_speed_factor: Fixed<4>,
    lift_overlap_s: Fixed<6>,
    pick_descent_overlap_s: Fixed<6>,
    place_descent_overlap_s: Fixed<6>,
    retreat_overlap_s: Fixed<6>,
    release_lead_s: Fixed<6>,
    blind: bool,
    from_result: usize,
    picks_since_capture: usize,
    sealed: Option<bool>,
    detections: Option<usize>,
    correct_detections: Option<usize>,
    believed_pose_error_mm: Fixed<6>,
    believed_pose_error_deg: Fixed<6>,
    believed_pose_correct: Option<bool>,
}

/// `picks.csv`: one row per pick (and per capture that found nothing to pick), SI units in
/// the column names; the outcome's reason in full (quoted where it holds commas or quotes).
pub fn picks_csv(records: &[PickRecord]) -> String {
    to_csv(
        &PICKS_CSV_HEADER,
        records.iter().map(|r| PickRow {
            pick: r.index,
            outcome: r.outcome.name(),
            detail: r.outcome.detail(),
            capture_s: Fixed::of(r.capture_s),
            ready_s: Fixed::of(r.ready_s),
            release_s: Fixed(r.release_s),
            takt_s: Fixed(r.takt_s),
            spans_refill: r.spans_refill,
            interval_cause: r.interval_cause.map_or("", IntervalCause::name),
            pick_s: Fixed::of(r.pick_s),
            place_s: Fixed::of(r.place_s),
            stall_sensor_s: Fixed::of(r.stall_sensor_s),
            stall_compute_s: Fixed::of(r.stall_compute_s),
            grasp_compute_s: Fixed::of(r.compute.grasp_s),
            pick_compute_s: Fixed::of(r.compute.pick_s),
            place_compute_s: Fixed::of(r.compute.place_s),
            placement_error_mm: Fixed(r.placement_error_mm),
            rotation_error_deg: Fixed(r.rotation_error_deg),
            max_tracking_error_deg: Fixed::of(r.max_tracking_error_deg),
            peak_demand_ratio: Fixed::of(r.peak_demand_ratio),
            peak_demand_joint: r.peak_demand_joint,
            saturated_s: Fixed::of(r.saturated_s),
            suction_speed_factor: Fixed::of(r.suction_speed_factor),
            lift_overlap_s: Fixed::of(r.overlaps.lift_s),
            pick_descent_overlap_s: Fixed::of(r.overlaps.pick_descent_s),
            place_descent_overlap_s: Fixed::of(r.overlaps.place_descent_s),
            retreat_overlap_s: Fixed::of(r.overlaps.retreat_s),
            release_lead_s: Fixed::of(r.release_lead_s),
            blind: r.blind,
            from_result: r.from_result,
            picks_since_capture: r.picks_since_capture,
            sealed: r.sealed,
            detections: r.recognition.map(|x| x.0),
            correct_detections: r.recognition.map(|x| x.1),
            believed_pose_error_mm: Fixed(r.aimed_at.map(|m| m.position_error_m * 1e3)),
            believed_pose_error_deg: Fixed(r.aimed_at.map(|m| m.rotation_error_rad.to_degrees())),
            believed_pose_correct: r.aimed_at.map(|m| m.correct),
        }),
    )
}

/// The widest line [`picks_table`] prints (columns).
pub const PICKS_TABLE_WIDTH: usize = 110;

/// The per-pick table printed by `binpick run` (a takt in brackets spans a pick-tray refill), at
/// most [`PICKS_TABLE_WIDTH`] columns: a pick's detail follows its row where it fits, else on
/// lines of its own under the row, whole.
pub fn picks_table(records: &[PickRecord]) -> String {
    let mut out = String::from(
        "pick  outcome              takt_s  pick_s  place_s  waits_s s/c  err_mm    torque  detail\n\
         (waits: for the sensor / for compute; err: placement error; torque: peak demand / limit, joint)\n",
    );
    for r in records {
        let takt = r.takt_s.map_or("-".to_string(), |t| {
            if r.spans_refill {
                format!("({t:.3})")
            } else {
                format!("{t:.3}")
            }
        });
        let err = r.placement_error_mm.map_or("-".to_string(), |e| format!("{e:.2}"));
        // Joint 0 is no joint: no motion was played (a pick whose motions could not be generated).
        let torque = if r.outcome.set_out() && r.peak_demand_joint > 0 {
            format!("{:.0} % J{}", 100.0 * r.peak_demand_ratio, r.peak_demand_joint)
        } else {
            "-".into()
        };
        let waits = format!("{:.3}/{:.3}", r.stall_sensor_s, r.stall_compute_s);
        let row = format!(
            "{:>4}  {:<17}  {:>8}  {:>6.3}  {:>7.3}  {:>11}  {:>6}  {:>8}",
            r.index,
            r.outcome.name(),
            takt,
            r.pick_s,
            r.place_s,
            waits,
            err,
            torque,
        );
        let detail = r.outcome.detail();
        if detail.is_empty() {
            out += row.trim_end();
            out.push('\n');
        } else if row.chars().count() + 2 + detail.chars().count() <= PICKS_TABLE_WIDTH {
            out += &format!("{row}  {detail}\n");
        } else {
            out += &row;
            out.push('\n');
            for line in wrap(&detail, PICKS_TABLE_WIDTH - 6).lines() {
                out += &format!("      {line}\n");
            }
        }
    }
    out
}

/// Units a figure keeps on its line ([`wrap`]).
const UNITS: [&str; 15] = [
    "%", "mm", "mm^2", "mm^3", "m", "s", "ms", "deg", "g", "kg", "N", "Nm", "px", "Hz", "kg/m^3",
];

/// Whether `word` (after `previous`) is a figure's unit: a unit of [`UNITS`], perhaps followed
/// by punctuation, after a word ending in a digit or a bracket; a `%` after anything.
fn is_unit_of(previous: &str, word: &str) -> bool {
    let bare = word.trim_end_matches([',', ';', ':', '.', ')']);
    bare == "%" || (UNITS.contains(&bare) && previous.ends_with(|c: char| c.is_ascii_digit() || c == ']'))
}

/// Comparison signs that stay on the line of the figure after them ("<= 5 ms").
const COMPARISONS: [&str; 6] = ["<=", ">=", "<", ">", "=", "~"];

/// `text` in lines of at most `width` characters, broken at spaces but never between a figure
/// and its unit (`%` always; `mm`, `s`, `deg` and the like after a digit or a bracket), nor
/// between a comparison sign and the figure after it; a word longer than the width (a path)
/// stands whole on a line of its own, longer than the width: cut, it could not be copied.
pub fn wrap(text: &str, width: usize) -> String {
    let width = width.max(1);
    // Words, each with the unit that follows it glued on.
    let mut words: Vec<String> = Vec::new();
    for word in text.split(' ') {
        match words.last_mut() {
            Some(last)
                if !last.is_empty()
                    && (is_unit_of(last, word)
                        || (COMPARISONS.contains(&last.as_str())
                            && word.starts_with(|c: char| c.is_ascii_digit()))) =>
            {
                last.push(' ');
                last.push_str(word);
            }
            _ => words.push(word.to_string()),
        }
    }
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in words {
        let len = word.chars().count();
        if !line.is_empty() && line.chars().count() + 1 + len > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&word);
        // A word longer than a line ends its line: what follows starts the next.
        if len > width {
            lines.push(std::mem::take(&mut line));
        }
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines.join("\n")
}

/// `text` wrapped within `width` characters from column `indent`: its first line after `head`
/// (padded to `indent`), the others under it, each line ending in a newline (a table row's
/// label and its text, a note under a row, "variant 2: " and the values that run on).
pub fn wrap_under(head: &str, indent: usize, text: &str, width: usize) -> String {
    let mut out = String::new();
    for (i, line) in wrap(text, width.saturating_sub(indent)).lines().enumerate() {
        let head = if i == 0 { head } else { "" };
        out += &format!("{head:<indent$}{line}\n");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cycle::Outcome;

    /// A `%` or a unit stays on the line of its figure, where breaking at every space would leave
    /// it alone on the next (the control: the text's 18th column is the space before the unit);
    /// a unit's name after a word is a word.
    #[test]
    fn wrap_keeps_a_unit_with_its_figure() {
        let text = "cup face up: 75.4 % of poses";
        assert_eq!(text.find(" %"), Some(17));
        assert_eq!(wrap(text, 17), "cup face up:\n75.4 % of poses");
        assert_eq!(wrap(text, 20), "cup face up: 75.4 %\nof poses");
        assert_eq!(wrap("% alone", 3), "%\nalone");
        // A word longer than the width (a path) is never cut: it stands alone on its line, and
        // a word that fits is wrapped as any.
        assert_eq!(
            wrap("in runs/tune-a-b-c/x.jsonl), then", 10),
            "in\nruns/tune-a-b-c/x.jsonl),\nthen"
        );
        assert_eq!(wrap("a runs/abcd, b", 11), "a\nruns/abcd,\nb");
        assert_eq!(wrap("centre [0.0 5.6] mm, mass", 16), "centre [0.0\n5.6] mm, mass");
        assert_eq!(wrap("tray 12.5 s) then", 9), "tray\n12.5 s)\nthen");
        assert_eq!(wrap("of s and m", 4), "of s\nand\nm");
        // A comparison sign goes with its figure (and that figure's unit): the control, a sign
        // before a word, breaks as any word does.
        assert_eq!(wrap("selection <= 5 ms", 12), "selection\n<= 5 ms");
        assert_eq!(wrap("recall >= 90 %, x", 10), "recall\n>= 90 %, x");
        assert_eq!(wrap("a <= b", 4), "a <=\nb");
        // Under a head: the text's lines start at the indent.
        assert_eq!(wrap_under("v1: ", 4, "a = 1, b = 2", 10), "v1: a = 1,\n    b = 2\n");
        assert_eq!(wrap_under("", 2, "x y", 3), "  x\n  y\n");
    }

    /// A pick whose motions could not be generated played none: its torque column is "-", not a
    /// "joint 0" (control: a pick that moved shows its joint).
    #[test]
    fn a_pick_with_no_motion_played_shows_no_torque() {
        let mut a = PickRecord::new(1, 1.0, 2.1);
        a.outcome = Outcome::NoMotion(crate::cycle::MotionFailure::PlaceDescent);
        let mut b = a.clone();
        (b.peak_demand_ratio, b.peak_demand_joint) = (0.83, 3);
        let text = picks_table(&[a, b]);
        assert!(!text.contains("J0"), "{text}");
        assert!(text.contains("83 % J3"), "{text}");
    }

    /// Every line of the printed table fits its width but one holding a word longer than a line
    /// (uncut), and a long detail is printed whole under its row (negative control: the same
    /// detail in one line would not fit).
    #[test]
    fn picks_table_fits_its_width_and_keeps_long_details_whole() {
        const LONG: &str = "part 47 left the pick tray while part 12 was on the cup; xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx";
        let mut a = PickRecord::new(1, 1.0, 2.1);
        a.outcome = Outcome::NothingGraspable(crate::pipeline::NoGrasp::NoneFeasible(
            [("crowded", 2), ("face tilted", 1), ("tray wall", 3)]
                .into_iter()
                .collect(),
        ));
        let mut b = PickRecord::new(2, 3.0, 4.1);
        b.outcome = Outcome::NothingGraspable(crate::pipeline::NoGrasp::NoneFeasible(
            [(LONG, 1)].into_iter().collect(),
        ));
        let c = PickRecord::new(3, 5.0, 6.1);
        let text = picks_table(&[a, b, c]);
        // Every line fits but the one that holds the word longer than a line, whole.
        for line in text.lines() {
            assert!(
                line.chars().count() <= PICKS_TABLE_WIDTH || line.trim() == LONG.rsplit(' ').next().unwrap(),
                "{} columns: {line}",
                line.chars().count()
            );
        }
        let words: Vec<&str> = text.split_whitespace().collect();
        let joined = words.join(" ");
        assert!(
            joined.contains("part 47 left the pick tray while part 12 was on the cup;"),
            "{text}"
        );
        assert!(
            text.contains(LONG.rsplit(' ').next().unwrap()),
            "the long word was cut\n{text}"
        );
        assert!(
            joined.contains("no feasible grasp (crowded 2, face tilted 1, tray wall 3)"),
            "{text}"
        );
        let row = text
            .lines()
            .find(|l| l.trim_start().starts_with("2 "))
            .unwrap_or_default();
        assert!(
            row.chars().count() + 2 + LONG.len() > PICKS_TABLE_WIDTH,
            "the control fits in one line"
        );
    }

    #[test]
    fn picks_csv_quotes_reasons_and_keeps_them_whole() {
        let mut r = PickRecord::new(3, 1.0, 2.1);
        r.outcome = Outcome::NothingGraspable(crate::pipeline::NoGrasp::NoneFeasible(
            [("crowded", 3), ("face \"tilted\"", 2)].into_iter().collect(),
        ));
        let text = picks_csv(&[r]);
        let mut rd = csv::Reader::from_reader(text.as_bytes());
        let header: Vec<String> = rd.headers().unwrap().iter().map(String::from).collect();
        assert_eq!(header, PICKS_CSV_HEADER);
        let rows: Vec<csv::StringRecord> = rd.records().map(Result::unwrap).collect();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].len(), PICKS_CSV_HEADER.len());
        assert_eq!(&rows[0][2], "no feasible grasp (crowded 3, face \"tilted\" 2)");
        assert_eq!(&rows[0][3], "1.000000");
        assert_eq!(&rows[0][5], "");
        let col = |name: &str| PICKS_CSV_HEADER.iter().position(|h| *h == name).unwrap();
        assert_eq!(&rows[0][col("suction_speed_factor")], "1.0000");
        // No takt, so no interval to put down to a cause.
        assert_eq!(&rows[0][col("interval_cause")], "");
    }
}
