//! `report.html`, the page of a batch, a sweep and a tune: read back with a strict XML reader
//! (quick-xml, not the code that writes it) and checked for what a person needs from it: a
//! title, the reading guide, the tables, the charts inline, each run's files linked, every link
//! relative and to a file that exists, nothing fetched from elsewhere, no script. Negative
//! controls: a page with an element left open, a link to a missing file, or a script is refused.

use std::collections::BTreeMap;
use std::path::Path;

use quick_xml::events::Event;

use crate::support::{binpick, stderr};

/// What the page holds: element counts by name, the links, the section ids, the inline SVGs.
#[derive(Debug, Default)]
struct PageFacts {
    elements: BTreeMap<String, usize>,
    links: Vec<String>,
    sections: Vec<String>,
    /// `<th>` texts of every table.
    headers: Vec<String>,
}

/// The page read with quick-xml: well-formed (elements nest and close, attributes quoted and
/// unique, entities XML's own), one `html` root with `head` (title, UTF-8) and `body`; no
/// script; every `href` and `src` relative and naming a file in `dir`.
fn check_page(html: &str, dir: &Path) -> Result<PageFacts, String> {
    let body = html
        .strip_prefix("<!DOCTYPE html>\n")
        .ok_or("no <!DOCTYPE html> first")?;
    let mut r = quick_xml::Reader::from_str(body);
    r.config_mut().check_end_names = true;
    let mut stack: Vec<String> = Vec::new();
    let mut facts = PageFacts::default();
    let mut roots = 0;
    let mut in_th = false;
    loop {
        let ev = r
            .read_event()
            .map_err(|e| format!("not well-formed at {}: {e}", r.buffer_position()))?;
        let (start, empty) = match &ev {
            Event::Start(e) => (Some(e.clone()), false),
            Event::Empty(e) => (Some(e.clone()), true),
            Event::End(e) => {
                let name = String::from_utf8_lossy(e.name().as_ref()).into_owned();
                if stack.pop().as_deref() != Some(name.as_str()) {
                    return Err(format!("</{name}> closes nothing open"));
                }
                in_th &= name != "th";
                continue;
            }
            Event::Text(t) => {
                let text = t.decode().map_err(|e| e.to_string())?;
                if stack.is_empty() && !text.trim().is_empty() {
                    return Err(format!("text outside the root: {text:.30}"));
                }
                if in_th {
                    facts.headers.push(text.trim().to_string());
                }
                continue;
            }
            Event::GeneralRef(g) => {
                let name = String::from_utf8_lossy(g.as_ref()).into_owned();
                if !(g.is_char_ref() || ["amp", "lt", "gt", "quot", "apos"].contains(&name.as_str())) {
                    return Err(format!("entity &{name}; is not XML's"));
                }
                continue;
            }
            Event::Eof => break,
            Event::DocType(_) => return Err("a second doctype".into()),
            _ => continue,
        };
        let e = start.expect("a start tag");
        let name = String::from_utf8_lossy(e.name().as_ref()).into_owned();
        if stack.is_empty() {
            roots += 1;
        }
        *facts.elements.entry(name.clone()).or_default() += 1;
        if name == "script" {
            return Err("a script".into());
        }
        for a in e.attributes() {
            let a = a.map_err(|e| format!("<{name}>: bad attribute: {e}"))?;
            let key = String::from_utf8_lossy(a.key.as_ref()).into_owned();
            let value = a
                .unescape_value()
                .map_err(|e| format!("<{name} {key}>: {e}"))?
                .into_owned();
            if (key == "href" || key == "src") && name != "svg" {
                if value.contains("://") || value.starts_with('/') || value.starts_with("data:") {
                    return Err(format!("<{name} {key}={value:?}> is not a relative link"));
                }
                let file = percent_decode(&value);
                if !dir.join(&file).is_file() {
                    return Err(format!("<{name} {key}={value:?}>: no file {file}"));
                }
                facts.links.push(file);
            }
            if name == "section" && key == "id" {
                facts.sections.push(value);
            }
        }
        in_th |= name == "th";
        if !empty {
            stack.push(name);
        }
    }
    if !stack.is_empty() {
        return Err(format!("elements left open: {stack:?}"));
    }
    if roots != 1 || facts.elements.get("html") != Some(&1) {
        return Err(format!("{roots} roots"));
    }
    for needed in ["head", "title", "body", "h1", "table", "style"] {
        if !facts.elements.contains_key(needed) {
            return Err(format!("no <{needed}>"));
        }
    }
    if !html.contains("<meta charset=\"utf-8\"/>") {
        return Err("no UTF-8 charset".into());
    }
    Ok(facts)
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && i + 3 <= b.len()
            && let Ok(v) = u8::from_str_radix(&s[i + 1..i + 3], 16)
        {
            out.push(v);
            i += 3;
            continue;
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn run_ok(args: &[&str]) {
    let o = binpick(args);
    assert_eq!(o.status.code(), Some(0), "{args:?}: {}", stderr(&o));
}

fn page(dir: &Path) -> (String, PageFacts) {
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    let facts = check_page(&html, dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    (html, facts)
}

#[test]
fn batch_sweep_and_tune_pages_are_well_formed_and_link_what_exists() {
    let tmp = crate::support::tempdir().unwrap();
    let out = |s: &str| tmp.path().join(s).to_str().unwrap().to_string();
    // A recorded batch of five picks: time charts (with a steady-state close-up) and recordings.
    run_ok(&[
        "batch",
        "--workpieces",
        "E,F",
        "--seeds",
        "1",
        "--picks",
        "6",
        "--deterministic",
        "--record",
        "--jobs",
        "2",
        "--out",
        &out("b"),
    ]);
    let dir = Path::new(&out("b")).join("batch-EF-seeds1-picks6-det");
    let (html, facts) = page(&dir);
    assert_eq!(facts.sections, ["guide", "tables", "charts", "runs", "files"]);
    assert_eq!(facts.elements["svg"], 1, "takt.svg inline");
    assert!(html.contains("<dt>takt</dt>") && html.contains("<dt>motion floor</dt>"));
    for h in ["part", "success", "reference"] {
        assert!(
            facts.headers.iter().any(|t| t.contains(h)),
            "no {h} column: {:?}",
            facts.headers
        );
    }
    for w in ["E", "F"] {
        for suffix in [
            ".picks.csv",
            ".events.json",
            ".timechart.svg",
            ".timechart-steady.svg",
            ".rrd",
            ".mcap",
        ] {
            let f = format!("run-{w}-seed1{suffix}");
            assert!(facts.links.contains(&f), "{f} not linked: {:?}", facts.links);
        }
    }
    for f in ["takt.svg", "takt.csv", "takt.json", "takt.md", "scene.toml"] {
        assert!(facts.links.iter().any(|l| l == f), "{f} not linked");
    }

    // Negative controls: an element left open, a link to a missing file, a script.
    let bad = [
        html.replacen("</table>", "", 1),
        html.replacen("href=\"takt.csv\"", "href=\"takt.xlsx\"", 1),
        html.replacen("</body>", "<script>alert(1)</script></body>", 1),
        html.replacen("href=\"takt.csv\"", "href=\"https://example.com/takt.csv\"", 1),
        html.replacen("<title>", "<title>&nbsp;", 1),
    ];
    for (k, b) in bad.iter().enumerate() {
        assert_ne!(b, &html, "control {k} changed nothing");
        assert!(check_page(b, &dir).is_err(), "control {k} passed");
    }

    // A sweep of two variants: its chart inline, no recordings (the page says so).
    run_ok(&[
        "sweep",
        "--set",
        "sensor.latency_s=0.3,1.1",
        "--workpieces",
        "E",
        "--picks",
        "3",
        "--deterministic",
        "--jobs",
        "2",
        "--out",
        &out("s"),
    ]);
    let dir = Path::new(&out("s")).join("sweep-sensor.latency_s-E-seeds1-picks3-det");
    let (html, facts) = page(&dir);
    assert_eq!(facts.sections, ["guide", "tables", "charts", "runs", "files"]);
    assert_eq!(facts.elements["svg"], 1, "sweep.svg inline");
    assert!(html.contains("No run of this study kept its time chart"));
    assert!(
        facts.links.iter().any(|l| l == "variant-2/scene.toml"),
        "{:?}",
        facts.links
    );

    // A tune: its tables and its convergence chart, the untuned files linked (whether or not a
    // candidate met the constraints: without one the page is written and the command fails).
    let o = binpick(&[
        "tune",
        "--workpiece",
        "E",
        "--vary",
        "workpiece.gripper.cup_diameter_m=0.004:0.02",
        "--budget",
        "2",
        "--population",
        "2",
        "--train-seeds",
        "1",
        "--test-seeds",
        "2",
        "--picks",
        "3",
        "--deterministic",
        "--out",
        &out("t"),
    ]);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", stderr(&o));
    let dir = std::fs::read_dir(out("t"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.is_dir())
        .unwrap();
    let (_, facts) = page(&dir);
    assert_eq!(facts.sections, ["guide", "tables", "charts", "files"]);
    assert_eq!(facts.elements["svg"], 1, "tune.svg inline");
    assert!(
        facts.links.iter().any(|l| l == "untuned/scene.toml"),
        "{:?}",
        facts.links
    );
}
