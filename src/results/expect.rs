//! Expectations: per-workpiece limits on a batch's figures (`binpick batch --expect FILE`), the
//! check of the table's rows against them, and that check as JUnit XML (`takt.junit.xml`, the
//! format CI servers render).
//!
//! The file is TOML, one table per workpiece (its name as in the table's part column), each key
//! a limit of one figure of [`FIGURES`]:
//!
//! ```toml
//! [E]
//! takt_max_s = 1.8     # takt mean (s) at most
//! success_min = 0.95   # success rate at least (a share, 0 to 1)
//! collisions_max = 0   # collisions at most (a count)
//! ```
//!
//! Strict: an unknown workpiece, an unknown figure, a value of the wrong kind or out of range is
//! an [`ExpectError`] naming the file, the key and the value. A figure a row has no value for (a
//! takt when nothing was placed) misses its limit.
//!
//! Units: s, shares (0 to 1; printed as %), counts.

use std::fmt::Write as _;
use std::path::Path;

use super::Summary;
use super::table::{faults, wait_share};
use crate::svg::escape;

/// Which side of a limit a figure must stay on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bound {
    /// The figure is at most the limit.
    Max,
    /// The figure is at least the limit.
    Min,
}

/// What kind of number a figure is (how its limit is checked on load and printed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A time (s), above 0.
    Seconds,
    /// A share from 0 to 1 (printed as %).
    Share,
    /// A whole count, 0 or more.
    Count,
}

/// A figure a limit can be set on.
pub struct Figure {
    /// The key in the file.
    pub key: &'static str,
    /// The figure's name in messages.
    pub name: &'static str,
    /// At most or at least.
    pub bound: Bound,
    /// Its kind of number.
    pub kind: Kind,
    /// Its value in a row (NaN when the row has none).
    pub value: fn(&Summary) -> f64,
}

/// Every figure a limit can be set on.
pub const FIGURES: &[Figure] = &[
    Figure {
        key: "takt_max_s",
        name: "takt mean",
        bound: Bound::Max,
        kind: Kind::Seconds,
        value: |s| s.takt.mean_s,
    },
    Figure {
        key: "takt_p95_max_s",
        name: "takt p95",
        bound: Bound::Max,
        kind: Kind::Seconds,
        value: |s| s.takt.p95_s,
    },
    Figure {
        key: "motion_floor_max_s",
        name: "motion floor",
        bound: Bound::Max,
        kind: Kind::Seconds,
        value: |s| s.motion_floor_s,
    },
    Figure {
        key: "success_min",
        name: "success",
        bound: Bound::Min,
        kind: Kind::Share,
        value: |s| s.success_rate,
    },
    Figure {
        key: "wait_share_max",
        name: "share of the takt waiting",
        bound: Bound::Max,
        kind: Kind::Share,
        value: wait_share,
    },
    Figure {
        key: "placed_min",
        name: "placed",
        bound: Bound::Min,
        kind: Kind::Count,
        value: |s| s.tally.placed as f64,
    },
    Figure {
        key: "faults_max",
        name: "faults",
        bound: Bound::Max,
        kind: Kind::Count,
        value: |s| faults(s) as f64,
    },
    Figure {
        key: "protective_stops_max",
        name: "protective stops",
        bound: Bound::Max,
        kind: Kind::Count,
        value: |s| s.tally.faults.protective_stops as f64,
    },
    Figure {
        key: "collisions_max",
        name: "collisions",
        bound: Bound::Max,
        kind: Kind::Count,
        value: |s| s.tally.faults.collisions as f64,
    },
    Figure {
        key: "drops_max",
        name: "drops",
        bound: Bound::Max,
        kind: Kind::Count,
        value: |s| s.tally.faults.drops as f64,
    },
    Figure {
        key: "parts_lost_max",
        name: "parts lost",
        bound: Bound::Max,
        kind: Kind::Count,
        value: |s| s.tally.faults.parts_lost as f64,
    },
    Figure {
        key: "grasp_failures_max",
        name: "grasp failures",
        bound: Bound::Max,
        kind: Kind::Count,
        value: |s| s.tally.faults.grasp_failures as f64,
    },
];

impl Figure {
    /// `v` as this figure prints it (with its unit).
    pub fn text(&self, v: f64) -> String {
        match self.kind {
            Kind::Seconds => format!("{v:.3} s"),
            Kind::Share => format!("{:.1} %", 100.0 * v),
            Kind::Count => format!("{v:.0}"),
        }
    }
}

/// A limits file that cannot be used: the file, the key and the bad value in the message.
#[derive(Debug, thiserror::Error)]
pub enum ExpectError {
    /// The file cannot be read.
    #[error("{file}: cannot read: {message}")]
    Read { file: String, message: String },
    /// The file is not TOML.
    #[error("{file}: not a TOML file: {message}")]
    Syntax { file: String, message: String },
    /// A key or a value the file must not hold.
    #[error("{file}: {key} = {value}: {message}")]
    Bad {
        file: String,
        key: String,
        value: String,
        message: String,
    },
    /// No limit at all.
    #[error("{file}: holds no limits (a table per workpiece, e.g. [E] with takt_max_s = 1.8)")]
    Empty { file: String },
}

/// One limit of the file.
#[derive(Debug, Clone)]
pub struct Limit {
    /// The workpiece it holds for.
    pub workpiece: String,
    /// The figure (an entry of [`FIGURES`]).
    pub figure: &'static Figure,
    /// The limit, in the figure's unit.
    pub limit: f64,
}

/// A limits file, loaded and checked against the batch's workpieces.
#[derive(Debug, Clone)]
pub struct Expectations {
    /// The file, as given.
    pub file: String,
    /// Its limits, in file order of workpieces (sorted) and figures (as [`FIGURES`] lists them).
    pub limits: Vec<Limit>,
}

impl std::fmt::Debug for Figure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.key)
    }
}

impl Expectations {
    /// Reads and checks `path` for a batch of `workpieces`.
    pub fn load(path: &Path, workpieces: &[String]) -> Result<Self, ExpectError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ExpectError::Read {
            file: file.clone(),
            message: e.to_string(),
        })?;
        Self::parse(&file, &text, workpieces)
    }

    /// Parses and checks the limits file `file` holding `text`, for a batch of `workpieces`.
    pub fn parse(file: &str, text: &str, workpieces: &[String]) -> Result<Self, ExpectError> {
        let table: toml::Table = toml::from_str(text).map_err(|e| ExpectError::Syntax {
            file: file.into(),
            message: e.message().to_string(),
        })?;
        let bad = |key: String, value: &dyn std::fmt::Display, message: String| ExpectError::Bad {
            file: file.into(),
            key,
            value: value.to_string(),
            message,
        };
        let mut limits = Vec::new();
        for (workpiece, entry) in &table {
            if !workpieces.contains(workpiece) {
                return Err(bad(
                    format!("[{workpiece}]"),
                    entry,
                    format!("unknown workpiece: this batch runs {}", workpieces.join(", ")),
                ));
            }
            let Some(entry) = entry.as_table() else {
                return Err(bad(
                    workpiece.clone(),
                    entry,
                    "expected a table of limits, e.g. [E] with takt_max_s = 1.8".into(),
                ));
            };
            let keys: Vec<&str> = FIGURES.iter().map(|f| f.key).collect();
            for key in entry.keys() {
                if !keys.contains(&key.as_str()) {
                    return Err(bad(
                        format!("[{workpiece}] {key}"),
                        &entry[key],
                        format!("unknown figure; the figures are {}", keys.join(", ")),
                    ));
                }
            }
            for figure in FIGURES {
                let Some(v) = entry.get(figure.key) else { continue };
                let key = format!("[{workpiece}] {}", figure.key);
                let limit = match (figure.kind, v) {
                    (Kind::Count, toml::Value::Integer(n)) if *n >= 0 => *n as f64,
                    (Kind::Count, _) => return Err(bad(key, v, "expected a whole count, 0 or more".into())),
                    (_, toml::Value::Integer(n)) => *n as f64,
                    (_, toml::Value::Float(x)) => *x,
                    _ => return Err(bad(key, v, "expected a number".into())),
                };
                let ok = match figure.kind {
                    Kind::Seconds => limit.is_finite() && limit > 0.0,
                    Kind::Share => (0.0..=1.0).contains(&limit),
                    Kind::Count => true,
                };
                if !ok {
                    let want = match figure.kind {
                        Kind::Seconds => "a time in s, above 0",
                        _ => "a share from 0 to 1 (0.95 for 95 %)",
                    };
                    return Err(bad(key, v, format!("expected {want}")));
                }
                limits.push(Limit {
                    workpiece: workpiece.clone(),
                    figure,
                    limit,
                });
            }
        }
        if limits.is_empty() {
            return Err(ExpectError::Empty { file: file.into() });
        }
        Ok(Expectations {
            file: file.into(),
            limits,
        })
    }

    /// Each limit checked against its workpiece's row of `rows` (a workpiece without a row has no
    /// value, and misses).
    pub fn check(&self, rows: &[Summary]) -> Vec<Check> {
        self.limits
            .iter()
            .map(|l| {
                let row = rows.iter().find(|r| r.tally.workpiece == l.workpiece);
                let value = row.map_or(f64::NAN, |r| (l.figure.value)(r));
                let met = match l.figure.bound {
                    Bound::Max => value <= l.limit,
                    Bound::Min => value >= l.limit,
                };
                let why_none = match row {
                    None => "no runs",
                    Some(r) if r.tally.placed == 0 => "nothing placed",
                    Some(_) => "too few placed",
                };
                Check {
                    limit: l.clone(),
                    value,
                    met,
                    why_none,
                }
            })
            .collect()
    }
}

/// One limit checked.
#[derive(Debug, Clone)]
pub struct Check {
    /// The limit.
    pub limit: Limit,
    /// The figure's value (NaN: none).
    pub value: f64,
    /// Whether the value keeps the limit (a missing value does not).
    pub met: bool,
    /// Why there is no value, when there is none.
    pub why_none: &'static str,
}

impl Check {
    /// The test's name: the key and the limit as the file writes them.
    pub fn name(&self) -> String {
        format!("{} = {}", self.limit.figure.key, self.limit.limit)
    }

    /// The outcome in one line: the part, the figure, its value and the limit.
    pub fn message(&self) -> String {
        let l = &self.limit;
        let f = l.figure;
        let value = if self.value.is_finite() {
            f.text(self.value)
        } else {
            format!("none ({})", self.why_none)
        };
        let (word, side) = match (f.bound, self.met) {
            (Bound::Max, true) => ("met", "at most"),
            (Bound::Min, true) => ("met", "at least"),
            (Bound::Max, false) => ("MISSED", "at most"),
            (Bound::Min, false) => ("MISSED", "at least"),
        };
        format!(
            "{word}: {} {} {value}, limit {side} {} ({})",
            l.workpiece,
            f.name,
            f.text(l.limit),
            self.name()
        )
    }
}

/// The checks as JUnit XML: one `testsuite` named `suite` (the batch), one `testcase` per
/// workpiece and limit (class: the workpiece; name: the limit as the file writes it), a
/// `failure` with the message for each missed limit, the measured value in `system-out`.
pub fn junit_xml(suite: &str, file: &str, checks: &[Check]) -> String {
    let failures = checks.iter().filter(|c| !c.met).count();
    let n = checks.len();
    let mut x = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        x,
        "<testsuites name=\"binpick batch --expect\" tests=\"{n}\" failures=\"{failures}\" errors=\"0\">"
    );
    let _ = writeln!(
        x,
        "  <testsuite name=\"{}\" tests=\"{n}\" failures=\"{failures}\" errors=\"0\" skipped=\"0\">",
        escape(suite)
    );
    let _ = writeln!(
        x,
        "    <properties>\n      <property name=\"expect\" value=\"{}\"/>\n    </properties>",
        escape(file)
    );
    for c in checks {
        let _ = writeln!(
            x,
            "    <testcase classname=\"{}\" name=\"{}\">",
            escape(&c.limit.workpiece),
            escape(&c.name())
        );
        let message = escape(&c.message());
        if !c.met {
            let _ = writeln!(
                x,
                "      <failure message=\"{message}\" type=\"limit missed\">{message}</failure>"
            );
        }
        let _ = writeln!(x, "      <system-out>{message}</system-out>\n    </testcase>");
    }
    x += "  </testsuite>\n</testsuites>\n";
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cycle::Tally;

    fn names() -> Vec<String> {
        vec!["E".into(), "A&<B>".into()]
    }

    #[test]
    fn a_file_is_read_strictly() {
        let e = Expectations::parse("x.toml", "[E]\ntakt_max_s = 2\nsuccess_min = 0.95\n", &names()).unwrap();
        assert_eq!(e.limits.len(), 2);
        for (text, want) in [
            ("[Z]\ntakt_max_s = 1", "x.toml: [Z] = "),
            ("[E]\ncycle_s = 1", "x.toml: [E] cycle_s = 1: unknown figure"),
            (
                "[E]\ntakt_max_s = \"fast\"",
                "x.toml: [E] takt_max_s = \"fast\": expected a number",
            ),
            (
                "[E]\nsuccess_min = 95",
                "x.toml: [E] success_min = 95: expected a share",
            ),
            (
                "[E]\ncollisions_max = 0.5",
                "x.toml: [E] collisions_max = 0.5: expected a whole",
            ),
            ("[E]\ntakt_max_s = -1", "x.toml: [E] takt_max_s = -1: expected a time"),
            ("", "x.toml: holds no limits"),
            ("[E\n", "x.toml: not a TOML file"),
        ] {
            let got = Expectations::parse("x.toml", text, &names()).unwrap_err().to_string();
            assert!(got.starts_with(want), "{text:?}: {got}");
        }
    }

    #[test]
    fn limits_are_checked_and_written_as_junit() {
        let mut t = Tally {
            workpiece: "A&<B>".into(),
            runs: 1,
            attempts: 4,
            placed: 3,
            takts_s: vec![2.0, 2.0],
            ..Tally::default()
        };
        t.faults.collisions = 1;
        let rows = [Summary::of(&t)];
        let e = Expectations::parse(
            "x.toml",
            "[\"A&<B>\"]\ntakt_max_s = 2.5\nsuccess_min = 0.8\ncollisions_max = 0\n",
            &names(),
        )
        .unwrap();
        let checks = e.check(&rows);
        let met: Vec<bool> = checks.iter().map(|c| c.met).collect();
        // takt 2.0 <= 2.5 met; success 0.75 < 0.8 missed; 1 collision > 0 missed.
        assert_eq!(met, [true, false, false]);
        assert!(
            checks[1].message().contains("success 75.0 %, limit at least 80.0 %"),
            "{}",
            checks[1].message()
        );
        let xml = junit_xml("batch", "x.toml", &checks);
        assert_eq!(xml.matches("<testcase ").count(), 3);
        assert_eq!(xml.matches("<failure ").count(), 2);
        assert!(
            xml.contains("classname=\"A&amp;&lt;B&gt;\"") && !xml.contains("A&<B>"),
            "{xml}"
        );
        // A row with nothing placed has no takt, and misses.
        let none = Summary::of(&Tally {
            workpiece: "E".into(),
            runs: 1,
            attempts: 2,
            ..Tally::default()
        });
        let e = Expectations::parse("x.toml", "[E]\ntakt_max_s = 100\n", &names()).unwrap();
        let c = &e.check(&[none])[0];
        assert!(
            !c.met && c.message().contains("none (nothing placed)"),
            "{}",
            c.message()
        );
    }
}
