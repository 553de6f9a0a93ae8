//! Report stage: `report.html`, one page per study (a batch, a sweep, a tune), written beside
//! the study's other files by this one writer.
//!
//! Job: put on one page what a person reads first: what ran, a short reading guide (takt as the
//! reference defines it, success, motion floor, the reference column), the study's tables (its
//! Markdown file turned into HTML tables), its charts inline (the SVG documents the study writes,
//! each with a link to its file), each run's time charts and recordings, and the other files of
//! the folder, all as relative links to files that exist when the page is written.
//!
//! The page is self-contained and opens from disk in any browser: no script, no font, no file
//! fetched from elsewhere; its styles are inline. It is also well-formed XML (every element
//! closed, attributes quoted, only XML's entities), so a strict XML reader checks it.
//! Deterministic: the same inputs give the same bytes (no clock, no absolute path).
//!
//! Units: as the tables' and the charts' own.

use std::fmt::Write;
use std::path::Path;

use crate::svg::escape;

/// One study's page.
#[derive(Debug, Clone)]
pub struct Page<'a> {
    /// The page's title (and its heading).
    pub title: &'a str,
    /// What ran, in a sentence or two.
    pub about: &'a str,
    /// The study's tables as its Markdown file holds them (headings, lists, tables, text).
    pub markdown: &'a str,
    /// The charts: the file's name (linked) and its SVG document (inlined).
    pub charts: &'a [(&'a str, &'a str)],
    /// Each run's files, if any run kept some.
    pub runs: &'a [RunFiles],
    /// The folder's other files, relative to it.
    pub files: &'a [String],
}

/// One run's files: its label and its files (relative to the folder) that exist.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunFiles {
    /// Which run (workpiece, seed, variant).
    pub label: String,
    /// (what the file shows, relative path).
    pub files: Vec<(&'static str, String)>,
}

/// What a run may leave beside the study's results: the suffix after its stem and what it shows.
pub const RUN_FILES: [(&str, &str); 6] = [
    (".picks.csv", "picks"),
    (".events.json", "events"),
    (".timechart.svg", "time chart"),
    (".timechart-steady.svg", "steady state"),
    (".rrd", "Rerun"),
    (".mcap", "Foxglove"),
];

/// The files of [`RUN_FILES`] that a run named `stem` left in `dir`.
pub fn run_files(dir: &Path, label: String, stem: &str) -> RunFiles {
    let files = RUN_FILES
        .iter()
        .map(|(suffix, what)| (*what, format!("{stem}{suffix}")))
        .filter(|(_, f)| dir.join(f).is_file())
        .collect();
    RunFiles { label, files }
}

/// The files of `dir` and of its folders one level down, relative to it, sorted; the page
/// itself and the files of `skip` (the runs', listed with them) left out.
pub fn folder_files(dir: &Path, skip: &[RunFiles]) -> Vec<String> {
    let listed: std::collections::BTreeSet<&str> = skip
        .iter()
        .flat_map(|r| r.files.iter().map(|(_, f)| f.as_str()))
        .chain(["report.html"])
        .collect();
    let mut out = Vec::new();
    let entries = |d: &Path| -> Vec<(String, bool)> {
        std::fs::read_dir(d)
            .map(|it| {
                it.filter_map(Result::ok)
                    .map(|e| {
                        let dir = e.file_type().is_ok_and(|t| t.is_dir());
                        (e.file_name().to_string_lossy().into_owned(), dir)
                    })
                    .collect()
            })
            .unwrap_or_default()
    };
    for (name, is_dir) in entries(dir) {
        if is_dir {
            for (inner, inner_dir) in entries(&dir.join(&name)) {
                if !inner_dir {
                    out.push(format!("{name}/{inner}"));
                }
            }
        } else if !listed.contains(name.as_str()) {
            out.push(name);
        }
    }
    out.sort();
    out
}

/// The reading guide: each term and what it means.
pub const READING_GUIDE: [(&str, &str); 6] = [
    (
        "takt",
        "as the reference defines it: the mean of every release-to-release interval after a run's first release, failed picks, re-captures, waits and tray refills included (\"excl. tray refills\" leaves out the intervals that span a refill); lower is better",
    ),
    (
        "success",
        "parts placed within the place tray's tolerance / picks attempted, re-captures counted as attempts; a part placed beyond it (misplaced, listed under the table) is a failed attempt, though it counts in placed / attempts",
    ),
    (
        "motion floor",
        "mean Pick + Place: the takt the arm would reach with instantaneous sensing and compute; the gap to the takt is time spent waiting",
    ),
    (
        "reference",
        "the takt the reference system reports for the workpiece (its Table 5, the mean of 20 consecutive picks), where it has one; the table's other columns are defined in the study's Markdown and CSV files",
    ),
    (
        "p5, p95, min, max",
        "the 5th and 95th percentiles and the extremes of all intervals; a maximum far above the mean is usually an interval that spans a tray refill",
    ),
    (
        "takt by cause",
        "the takt split by what happened in each interval since the release before: a tray refill, else a failed attempt (and the agitation after it), else a hopper dose, else nothing (a clean cycle); the four shares add up to the takt",
    ),
];

/// A relative link target: unreserved characters and `/` as they are, every other byte
/// percent-encoded.
fn href(path: &str) -> String {
    let mut out = String::new();
    for b in path.bytes() {
        if b.is_ascii_alphanumeric() || b"-_.~/".contains(&b) {
            out.push(b as char);
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

/// Inline Markdown of the study's files: `code` spans; everything else as text.
fn inline(text: &str) -> String {
    let mut out = String::new();
    for (i, piece) in text.split('`').enumerate() {
        if i % 2 == 1 {
            let _ = write!(out, "<code>{}</code>", escape(piece));
        } else {
            out += &escape(&piece.replace("**", ""));
        }
    }
    out
}

/// The cells of a Markdown table row.
fn cells(line: &str) -> Vec<&str> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    inner.split('|').map(str::trim).collect()
}

/// The study's Markdown (headings, lists, tables, paragraphs) as HTML.
fn markdown_html(md: &str) -> String {
    let mut out = String::new();
    let lines: Vec<&str> = md.lines().collect();
    let mut i = 0;
    let mut list = false;
    while i < lines.len() {
        let line = lines[i].trim_end();
        let is_item = line.starts_with("- ") || line.starts_with("* ");
        if list && !is_item {
            out += "</ul>\n";
            list = false;
        }
        if line.starts_with('|') {
            let mut rows = Vec::new();
            while i < lines.len() && lines[i].trim_start().starts_with('|') {
                rows.push(lines[i]);
                i += 1;
            }
            let separator = |l: &str| {
                cells(l)
                    .iter()
                    .all(|c| !c.is_empty() && c.chars().all(|ch| "-: ".contains(ch)))
            };
            let head = (rows.len() > 1 && separator(rows[1])).then(|| rows[0]);
            out += "<div class=\"scroll\"><table>\n";
            if let Some(h) = head {
                out += "<thead><tr>";
                for c in cells(h) {
                    let _ = write!(out, "<th>{}</th>", inline(c));
                }
                out += "</tr></thead>\n";
            }
            out += "<tbody>\n";
            for r in rows.iter().skip(if head.is_some() { 2 } else { 0 }) {
                out += "<tr>";
                for c in cells(r) {
                    let _ = write!(out, "<td>{}</td>", inline(c));
                }
                out += "</tr>\n";
            }
            out += "</tbody></table></div>\n";
            continue;
        }
        if let Some(h) = line.strip_prefix('#') {
            // Under the page's section headings (h2): `#` -> h3, deeper -> h4.
            let level = 3 + h.chars().take_while(|c| *c == '#').count().min(1);
            let _ = writeln!(out, "<h{level}>{}</h{level}>", inline(h.trim_start_matches('#').trim()));
        } else if is_item {
            if !list {
                out += "<ul>\n";
                list = true;
            }
            // An item's continuation lines (indented) belong to it.
            let mut item = line[2..].to_string();
            while let Some(next) = lines.get(i + 1).filter(|l| l.starts_with("  ") && !l.trim().is_empty()) {
                item.push(' ');
                item += next.trim();
                i += 1;
            }
            let _ = writeln!(out, "<li>{}</li>", inline(&item));
        } else if !line.trim().is_empty() {
            let _ = writeln!(out, "<p>{}</p>", inline(line.trim()));
        }
        i += 1;
    }
    if list {
        out += "</ul>\n";
    }
    out
}

/// An SVG document as an element of the page: its XML declaration, if any, left out.
fn inline_svg(svg: &str) -> &str {
    let s = svg.trim();
    match s.strip_prefix("<?xml") {
        Some(rest) => rest.find("?>").map_or(s, |k| rest[k + 2..].trim_start()),
        None => s,
    }
}

const STYLE: &str = "body{font-family:Helvetica,Arial,sans-serif;margin:24px auto;max-width:1280px;padding:0 16px;color:#222;line-height:1.45}\
h1{font-size:22px}h2{font-size:18px;margin-top:32px;border-bottom:1px solid #ddd}h3,h4{font-size:15px}\
table{border-collapse:collapse;font-size:13px;margin:8px 0}th,td{border:1px solid #ccc;padding:3px 7px;text-align:right;white-space:nowrap}\
th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}.scroll{overflow-x:auto}\
figure{margin:12px 0}figure svg{max-width:100%;height:auto;border:1px solid #eee}figcaption{font-size:13px;color:#555}\
dl.guide dt{font-weight:bold;float:left;clear:left;width:150px}dl.guide dd{margin:0 0 6px 160px}\
code{background:#f4f4f4;padding:0 3px}.empty{color:#777}";

/// The table of the runs' files, a link where a run has the file.
fn runs_table(out: &mut String, runs: &[RunFiles]) {
    *out += "<div class=\"scroll\"><table>\n<thead><tr><th>run</th>";
    for (_, what) in RUN_FILES {
        let _ = write!(out, "<th>{what}</th>");
    }
    *out += "</tr></thead>\n<tbody>\n";
    for r in runs {
        let _ = write!(out, "<tr><td>{}</td>", escape(&r.label));
        for (_, what) in RUN_FILES {
            match r.files.iter().find(|(w, _)| *w == what) {
                Some((_, f)) => {
                    let _ = write!(out, "<td><a href=\"{}\">{}</a></td>", href(f), escape(f));
                }
                None => *out += "<td>-</td>",
            }
        }
        *out += "</tr>\n";
    }
    *out += "</tbody></table></div>\n";
    *out += "<p>Open a <code>.rrd</code> in the Rerun viewer (0.36) and a <code>.mcap</code> in Foxglove: its 3D panel draws the arm from <code>/robot_description</code> (turn the topic on) on the frames of <code>/tf</code>.</p>\n";
}

/// `report.html`: the page.
pub fn page_html(p: &Page<'_>) -> String {
    let mut out = String::new();
    let title = escape(p.title);
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html xmlns=\"http://www.w3.org/1999/xhtml\" lang=\"en\">\n<head>\n<meta charset=\"utf-8\"/>\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"/>\n<title>{title}</title>\n\
         <style>{STYLE}</style>\n</head>\n<body>\n<h1>{title}</h1>\n<p class=\"about\">{}</p>\n",
        escape(p.about)
    );
    out += "<section id=\"guide\">\n<h2>How to read it</h2>\n<dl class=\"guide\">\n";
    for (term, meaning) in READING_GUIDE {
        let _ = writeln!(out, "<dt>{}</dt><dd>{}</dd>", escape(term), escape(meaning));
    }
    out += "</dl>\n</section>\n";
    out += "<section id=\"tables\">\n<h2>Results</h2>\n";
    out += &markdown_html(p.markdown);
    out += "</section>\n";
    if !p.charts.is_empty() {
        out += "<section id=\"charts\">\n<h2>Charts</h2>\n";
        for (name, svg) in p.charts {
            let _ = writeln!(
                out,
                "<figure>\n{}\n<figcaption><a href=\"{}\">{}</a></figcaption>\n</figure>",
                inline_svg(svg),
                href(name),
                escape(name)
            );
        }
        out += "</section>\n";
    }
    // A study without runs of its own to show (a tune's are summarised in its tables) has no
    // section of runs.
    if !p.runs.is_empty() {
        out += "<section id=\"runs\">\n<h2>Runs</h2>\n";
        if p.runs.iter().all(|r| r.files.is_empty()) {
            out += "<p class=\"empty\">No run of this study kept its time chart or recordings (<code>binpick batch --record</code> keeps them for each run; <code>binpick run</code> writes them for one run).</p>\n";
        } else {
            runs_table(&mut out, p.runs);
        }
        out += "</section>\n";
    }
    if !p.files.is_empty() {
        out += "<section id=\"files\">\n<h2>Files</h2>\n<ul>\n";
        for f in p.files {
            let _ = writeln!(out, "<li><a href=\"{}\">{}</a></li>", href(f), escape(f));
        }
        out += "</ul>\n</section>\n";
    }
    let _ = writeln!(
        out,
        "<p class=\"empty\">binpick {}</p>\n</body>\n</html>",
        env!("CARGO_PKG_VERSION")
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_tables_lists_and_headings_become_html() {
        let md = "# tune of A\n\nsome `key` text & more\n\n| a | b |\n|---|--:|\n| 1 | <2> |\n\n- one\n- two,\n  continued\n";
        let h = markdown_html(md);
        assert!(h.contains("<h3>tune of A</h3>"), "{h}");
        assert!(h.contains("<p>some <code>key</code> text &amp; more</p>"), "{h}");
        assert!(h.contains("<thead><tr><th>a</th><th>b</th></tr></thead>"), "{h}");
        assert!(h.contains("<tr><td>1</td><td>&lt;2&gt;</td></tr>"), "{h}");
        assert!(h.contains("<ul>\n<li>one</li>\n<li>two, continued</li>\n</ul>"), "{h}");
        assert_eq!(href("run-a b&c.rrd"), "run-a%20b%26c.rrd");
        let svg = "<?xml version=\"1.0\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>\n";
        assert_eq!(inline_svg(svg), "<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>");
    }
}
