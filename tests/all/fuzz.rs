//! Fuzz: seeded mutations of copies of the shipped URDF, cell file and workpiece files (numbers
//! replaced by NaN, inf, -1, 0, 1e30 or integers too large; names changed; an element, key or
//! section removed or doubled; an attribute removed; the file truncated; one mutant in four
//! carries two of these). `binpick check` must
//! answer every mutant with exit 0 or exit 2 and a problem line naming the file: never a panic
//! (exit 101) or a signal.
//!
//! Deterministic: every draw comes from `binpick::rng::stream(FUZZ_SEED, "fuzz")`, so a failing
//! case is the same case on every machine; its message names the mutation. The mutants are
//! checked in batches (`binpick check f1 f2 ...`, one process per batch, batches on parallel
//! threads), and each file's verdict is read from the batch's output: an `ok: FILE` line on
//! stdout, or at least one `FILE: ...` line on stderr, never both. A batch that does not exit 0 or
//! 2 is run again one file at a time to name the files that crash.

use std::ops::Range;
use std::path::Path;

use rand::RngExt;

use crate::support::{Workspace, binpick_in, stderr, stdout};

/// The seed of the fuzz stream.
const FUZZ_SEED: u64 = 13;
/// Mutants of the URDF, of the cell file and of the workpiece files.
const URDF_CASES: usize = 1000;
const SCENE_CASES: usize = 800;
const WORKPIECE_CASES: usize = 600;
/// Files per `binpick check` call.
const BATCH: usize = 40;
/// Batches checked at once.
const THREADS: usize = 4;

/// Numbers put in place of a number: non-finite, negative, zero, huge, and integers out of the
/// range of every integer type the formats use.
const NUMBERS: [&str; 9] = [
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e30",
    "18446744073709551616",
    "-9223372036854775809",
    "4294967296",
];

/// Names put in place of a name: empty, unknown, and names the files already use elsewhere.
const NAMES: [&str; 8] = ["", "nope", "link_9", "link_1", "joint_2", "base_link", "box", "X Y"];

/// The two syntaxes mutated.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Syntax {
    Urdf,
    Toml,
}

/// Byte mask of comments: TOML `#` to the end of the line (outside strings), XML `<!-- -->`.
fn comments(text: &str, syntax: Syntax) -> Vec<bool> {
    let b = text.as_bytes();
    let mut mask = vec![false; b.len()];
    match syntax {
        Syntax::Toml => {
            let (mut in_string, mut in_comment) = (false, false);
            for (i, &c) in b.iter().enumerate() {
                if c == b'\n' {
                    in_comment = false;
                    in_string = false;
                } else if !in_comment && c == b'"' {
                    in_string = !in_string;
                } else if !in_string && c == b'#' {
                    in_comment = true;
                }
                mask[i] = in_comment;
            }
        }
        Syntax::Urdf => {
            let mut from = 0;
            while let Some(s) = text[from..].find("<!--") {
                let s = from + s;
                let e = text[s..].find("-->").map_or(b.len(), |e| s + e + 3);
                mask[s..e].iter_mut().for_each(|m| *m = true);
                from = e;
            }
        }
    }
    mask
}

/// Spans of the numbers outside comments (not digits inside names such as `link_6`).
fn number_spans(text: &str, comment: &[bool]) -> Vec<Range<usize>> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts = b[i].is_ascii_digit() || (b[i] == b'-' && b.get(i + 1).is_some_and(u8::is_ascii_digit));
        let after_name = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_' || b[i - 1] == b'.');
        if !starts || after_name || comment[i] {
            i += 1;
            continue;
        }
        let mut j = i + 1;
        while j < b.len()
            && (b[j].is_ascii_digit()
                || b[j] == b'.'
                || b[j] == b'e'
                || b[j] == b'E'
                || ((b[j] == b'-' || b[j] == b'+') && matches!(b[j - 1], b'e' | b'E')))
        {
            j += 1;
        }
        if text[i..j].parse::<f64>().is_ok() {
            out.push(i..j);
        }
        i = j;
    }
    out
}

/// Spans of the contents of quoted strings outside comments (TOML strings, XML attribute
/// values); `names_only` keeps the URDF's `name` and `link` attributes.
fn string_spans(text: &str, comment: &[bool], names_only: bool) -> Vec<Range<usize>> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'"' || comment[i] {
            i += 1;
            continue;
        }
        let Some(len) = text[i + 1..].find(['"', '\n']) else {
            break;
        };
        let end = i + 1 + len;
        if b[end] == b'"' {
            let before = &text[..i];
            if !names_only || before.ends_with("name=") || before.ends_with("link=") {
                out.push(i + 1..end);
            }
        }
        i = end + 1;
    }
    out
}

/// URDF: spans of whole elements (`<x .../>` or `<x ...>...</x>`), outside comments.
fn element_spans(text: &str, comment: &[bool]) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    for (i, _) in text.match_indices('<') {
        let rest = &text[i + 1..];
        if comment[i] || rest.starts_with(['/', '!', '?']) {
            continue;
        }
        let name: String = rest
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        let Some(gt) = rest.find('>') else { continue };
        if rest[..gt].ends_with('/') {
            out.push(i..i + 1 + gt + 1);
            continue;
        }
        // The matching close tag, counting nested elements of the same name.
        let (open, close) = (format!("<{name}"), format!("</{name}>"));
        let mut depth = 0usize;
        let mut at = i + 1 + gt + 1;
        while let Some(n) = text[at..].find(&close) {
            let inner = &text[at..at + n];
            depth += inner
                .match_indices(&open)
                .filter(|(k, _)| {
                    let after = &inner[k + open.len()..];
                    after.starts_with([' ', '>', '\n', '\t']) && !after[..after.find('>').unwrap_or(0)].ends_with('/')
                })
                .count();
            at += n + close.len();
            if depth == 0 {
                out.push(i..at);
                break;
            }
            depth -= 1;
        }
    }
    out
}

/// URDF: spans of attributes (` name="value"`), outside comments.
fn attribute_spans(text: &str, comment: &[bool]) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    for (eq, _) in text.match_indices("=\"") {
        if comment[eq] {
            continue;
        }
        let start = text[..eq].rfind(|c: char| c.is_whitespace()).unwrap_or(eq);
        let Some(len) = text[eq + 2..].find('"') else { continue };
        out.push(start..eq + 2 + len + 1);
    }
    out
}

/// TOML: spans of `key = value` lines (with their newline) and of key names.
fn key_spans(text: &str, comment: &[bool]) -> (Vec<Range<usize>>, Vec<Range<usize>>) {
    let (mut lines, mut keys) = (Vec::new(), Vec::new());
    let mut start = 0;
    for line in text.split_inclusive('\n') {
        let t = line.trim_start();
        let indent = line.len() - t.len();
        if !t.is_empty()
            && !comment[start + indent]
            && !t.starts_with('[')
            && let Some(eq) = t.find('=')
        {
            lines.push(start..start + line.len());
            let key = t[..eq].trim_end();
            keys.push(start + indent..start + indent + key.len());
        }
        start += line.len();
    }
    (lines, keys)
}

/// TOML: spans of sections, header to the next header.
fn section_spans(text: &str) -> Vec<Range<usize>> {
    let mut headers = Vec::new();
    let mut start = 0;
    for line in text.split_inclusive('\n') {
        if line.starts_with('[') {
            headers.push(start);
        }
        start += line.len();
    }
    headers
        .iter()
        .enumerate()
        .map(|(k, &s)| s..headers.get(k + 1).copied().unwrap_or(text.len()))
        .collect()
}

/// `list[k]`, or the next one if that is `old` (a mutation must change the file).
fn different<'a>(list: &[&'a str], k: usize, old: &str) -> &'a str {
    if list[k] == old {
        list[(k + 1) % list.len()]
    } else {
        list[k]
    }
}

/// One seeded mutation of `text`: the mutated text and what was done.
fn mutate(text: &str, syntax: Syntax, rng: &mut impl RngExt) -> (String, String) {
    let comment = comments(text, syntax);
    let pick = |spans: &[Range<usize>], rng: &mut dyn FnMut(usize) -> usize| -> Option<Range<usize>> {
        (!spans.is_empty()).then(|| spans[rng(spans.len())].clone())
    };
    let mut draw = |n: usize| rng.random_range(0..n);
    let replace = |r: &Range<usize>, with: &str| format!("{}{with}{}", &text[..r.start], &text[r.end..]);
    loop {
        let kind = draw(8);
        let done = match (kind, syntax) {
            // A number replaced (three times as likely as the rest: most values are numbers).
            (0..=2, _) => pick(&number_spans(text, &comment), &mut draw).map(|r| {
                let with = different(&NUMBERS, draw(NUMBERS.len()), &text[r.clone()]);
                (
                    replace(&r, with),
                    format!("number {:?} at byte {} -> {with}", &text[r.clone()], r.start),
                )
            }),
            // A name changed: a URDF name or link reference, a TOML string value or key.
            (3, _) => {
                let key_names = syntax == Syntax::Toml && draw(3) == 0;
                let spans = if key_names {
                    key_spans(text, &comment).1
                } else {
                    string_spans(text, &comment, syntax == Syntax::Urdf && draw(4) > 0)
                };
                pick(&spans, &mut draw).map(|r| {
                    let with = if key_names {
                        format!("{}_x", &text[r.clone()])
                    } else {
                        different(&NAMES, draw(NAMES.len()), &text[r.clone()]).to_string()
                    };
                    (
                        replace(&r, &with),
                        format!("name {:?} at byte {} -> {with:?}", &text[r.clone()], r.start),
                    )
                })
            }
            // An element removed / a section removed.
            (4, Syntax::Urdf) => pick(&element_spans(text, &comment), &mut draw)
                .map(|r| (replace(&r, ""), format!("element at bytes {r:?} removed"))),
            (4, Syntax::Toml) => pick(&section_spans(text), &mut draw)
                .map(|r| (replace(&r, ""), format!("section at bytes {r:?} removed"))),
            // An attribute removed / a key removed.
            (5, Syntax::Urdf) => pick(&attribute_spans(text, &comment), &mut draw)
                .map(|r| (replace(&r, ""), format!("attribute {:?} removed", &text[r.clone()]))),
            (5, Syntax::Toml) => pick(&key_spans(text, &comment).0, &mut draw).map(|r| {
                (
                    replace(&r, ""),
                    format!("key line {:?} removed", text[r.clone()].trim()),
                )
            }),
            // An element or a key line doubled.
            (6, _) => {
                let spans = match syntax {
                    Syntax::Urdf => element_spans(text, &comment),
                    Syntax::Toml => key_spans(text, &comment).0,
                };
                pick(&spans, &mut draw).map(|r| {
                    let twice = format!("{0}{0}", &text[r.clone()]);
                    (replace(&r, &twice), format!("bytes {r:?} doubled"))
                })
            }
            // Truncated.
            _ => {
                let mut at = draw(text.len());
                while !text.is_char_boundary(at) {
                    at -= 1;
                }
                Some((text[..at].to_string(), format!("truncated at byte {at}")))
            }
        };
        if let Some(d) = done {
            return d;
        }
    }
}

/// One mutant: its path relative to the workspace and what was mutated.
struct Case {
    rel: String,
    what: String,
}

/// Checks a batch of mutants with one `binpick check` call. Per mutant: `Ok(true)` accepted,
/// `Ok(false)` refused with a line naming it, `Err` what went wrong.
fn check_batch(ws: &Workspace, cases: &[Case]) -> Vec<Result<bool, String>> {
    let args: Vec<&str> = std::iter::once("check")
        .chain(cases.iter().map(|c| c.rel.as_str()))
        .collect();
    let out = binpick_in(ws.dir.path(), &args);
    let (so, se) = (stdout(&out), stderr(&out));
    let code = out.status.code();
    if !matches!(code, Some(0) | Some(2)) {
        // A crash (exit 101) or a signal (no code): each file on its own names the culprits.
        if let [c] = cases {
            let first = se.lines().find(|l| l.contains("panicked")).unwrap_or("");
            return vec![Err(format!("{} ({}): exit {code:?}: {first}", c.rel, c.what))];
        }
        return cases
            .iter()
            .flat_map(|c| check_batch(ws, std::slice::from_ref(c)))
            .collect();
    }
    let mut verdicts: Vec<Result<bool, String>> = cases
        .iter()
        .map(|c| {
            let ok = so.lines().any(|l| l.starts_with(&format!("ok: {} (", c.rel)));
            let named = se.lines().any(|l| l.starts_with(&format!("{}: ", c.rel)));
            if ok == named {
                Err(format!(
                    "{} ({}): ok on stdout {ok}, named on stderr {named}; stderr:\n{se}",
                    c.rel, c.what
                ))
            } else {
                Ok(ok)
            }
        })
        .collect();
    if (code == Some(0)) != se.trim().is_empty() {
        verdicts.push(Err(format!("batch exit {code:?} with stderr:\n{se}")));
    }
    verdicts
}

/// Writes every mutant into the workspace: URDFs and cell files into `scenes/` (where the cell's
/// relative URDF path resolves), workpieces into `workpieces/`.
fn write_cases(ws: &Workspace) -> Vec<Case> {
    let mut rng = binpick::rng::stream(FUZZ_SEED, "fuzz");
    let read = |rel: &str| std::fs::read_to_string(ws.path(rel)).expect("shipped file");
    let urdf = read("scenes/viper_s650.urdf");
    let scene = read("scenes/default.toml");
    let workpieces: Vec<String> = ["A", "B", "C", "D", "E", "F"]
        .iter()
        .map(|w| read(&format!("workpieces/{w}.toml")))
        .collect();
    let mut cases = Vec::new();
    for k in 0..URDF_CASES + SCENE_CASES + WORKPIECE_CASES {
        let (rel, base, syntax) = if k < URDF_CASES {
            (format!("scenes/fuzz_{k:04}.urdf"), &urdf, Syntax::Urdf)
        } else if k < URDF_CASES + SCENE_CASES {
            (format!("scenes/fuzz_{k:04}.toml"), &scene, Syntax::Toml)
        } else {
            let w = k % workpieces.len();
            (format!("workpieces/fuzz_{k:04}.toml"), &workpieces[w], Syntax::Toml)
        };
        let (mut text, mut what) = mutate(base, syntax, &mut rng);
        // One mutant in four carries a second mutation.
        if rng.random_range(0..4) == 0 {
            let (t, w) = mutate(&text, syntax, &mut rng);
            (text, what) = (t, format!("{what}, then {w}"));
        }
        std::fs::write(ws.path(&rel), text).expect("write mutant");
        cases.push(Case { rel, what });
    }
    cases
}

#[test]
fn mutated_urdf_cell_and_workpiece_files_never_crash_check() {
    let ws = Workspace::new();
    let cases = write_cases(&ws);
    let batches: Vec<&[Case]> = cases.chunks(BATCH).collect();
    let verdicts: Vec<Result<bool, String>> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..THREADS)
            .map(|t| {
                let (ws, batches) = (&ws, &batches);
                s.spawn(move || {
                    batches
                        .iter()
                        .enumerate()
                        .filter(|(b, _)| b % THREADS == t)
                        .map(|(b, cases)| (b, check_batch(ws, cases)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        let mut done: Vec<_> = workers.into_iter().flat_map(|w| w.join().expect("worker")).collect();
        done.sort_by_key(|(b, _)| *b);
        done.into_iter().flat_map(|(_, v)| v).collect()
    });
    let failures: Vec<&String> = verdicts.iter().filter_map(|v| v.as_ref().err()).collect();
    assert!(
        failures.is_empty(),
        "{} of {} mutants failed:\n{}",
        failures.len(),
        cases.len(),
        failures.iter().map(|f| f.as_str()).collect::<Vec<_>>().join("\n")
    );
    // The mutants reach past the parser: of each kind of file, some are accepted, most refused.
    for (kind, range) in [
        ("URDF", 0..URDF_CASES),
        ("cell", URDF_CASES..URDF_CASES + SCENE_CASES),
        ("workpiece", URDF_CASES + SCENE_CASES..cases.len()),
    ] {
        let accepted = verdicts[range.clone()].iter().filter(|v| matches!(v, Ok(true))).count();
        eprintln!(
            "fuzz: {kind}: {accepted} of {} mutants accepted, the rest refused",
            range.len()
        );
        assert!(
            accepted > 0 && accepted < range.len() / 2,
            "{kind}: {accepted} of {} accepted",
            range.len()
        );
    }
}

/// The mutations are what they claim: each kind changes the file, and the same seed gives the
/// same mutants.
#[test]
fn mutations_are_deterministic_and_change_the_file() {
    let text = std::fs::read_to_string(crate::support::repo().join("scenes/viper_s650.urdf")).unwrap();
    let run = || {
        let mut rng = binpick::rng::stream(FUZZ_SEED, "fuzz");
        (0..50)
            .map(|_| mutate(&text, Syntax::Urdf, &mut rng))
            .collect::<Vec<_>>()
    };
    let (a, b) = (run(), run());
    assert_eq!(a, b);
    assert!(a.iter().all(|(t, _)| t != &text), "a mutant equals the original");
    let comment = comments(&text, Syntax::Urdf);
    let links = element_spans(&text, &comment)
        .into_iter()
        .filter(|r| text[r.clone()].starts_with("<link "))
        .count();
    assert_eq!(links, 7, "the seven links are elements");
    let scene = std::fs::read_to_string(Path::new(&crate::support::repo()).join("scenes/default.toml")).unwrap();
    assert!(!section_spans(&scene).is_empty() && !number_spans(&scene, &comments(&scene, Syntax::Toml)).is_empty());
}
