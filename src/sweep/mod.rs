//! What-if sweeps: the same batch over variants of the cell and workpiece files.
//!
//! Job: parse `--set KEY=V1,V2,...` (a key path into the cell file, or into every workpiece file
//! with the prefix `workpiece.`; values in the file's own TOML types, arrays allowed; numeric
//! ranges `start:stop:step`), form the variants (the product of the lists, the first key
//! slowest), and describe the sweep's runs: every (variant, workpiece, seed), variant-major, each a
//! run like `batch`'s. The variants are resolved and checked in [`resolve`](mod@resolve) (before anything
//! runs); the runs, shards and merges are the study's ([`crate::study`]: a sweep is a study of
//! several variants); the table, its files and the chart are [`table`](mod@table)'s and
//! [`sweep_chart`]'s.
//!
//! Units: the file's own (the key names carry them); s and counts in the results.

pub mod resolve;
pub mod sweep_chart;
pub mod table;

pub use resolve::resolve;
pub use table::{SweepRow, csv, markdown, outputs, table};

use crate::study::StudyError;

/// Most values one `--set` list gives (a range included): a typo guard (`0:1:0.0001`).
pub const MAX_VALUES: usize = 1000;
/// Most variants one sweep forms (the product of its lists).
pub const MAX_VARIANTS: usize = 10_000;

/// Which file a key path goes into.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// The cell (scene) file.
    Cell,
    /// Every workpiece file of the sweep (keys written `workpiece.KEY`).
    Workpiece,
}

/// One step of a key path: a table key or an array index (`center_m[2]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Segment {
    /// A key of a table.
    Key(String),
    /// An element of an array.
    Index(usize),
}

/// One `--set KEY=V1,V2,...`: the key and its values, in order.
#[derive(Debug, Clone, PartialEq)]
pub struct SetArg {
    /// The key as written (`gripper.cup_diameter_m`, `workpiece.grasp.face_margin_m`).
    pub key: String,
    /// The file it goes into.
    pub target: Target,
    /// The path inside that file.
    pub path: Vec<Segment>,
    /// The values, parsed as TOML (a bare word is a string).
    pub values: Vec<toml::Value>,
}

fn input(m: impl Into<String>) -> StudyError {
    StudyError::Input(m.into())
}

/// A value as the tables and folder names show it: TOML's inline form, a string bare.
pub fn value_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// Parses a key path: dotted keys, each optionally followed by `[i]` indices.
pub fn parse_key(key: &str) -> Result<(Target, Vec<Segment>), String> {
    let mut path = Vec::new();
    for part in key.split('.') {
        let (name, mut rest) = part.split_once('[').map_or((part, ""), |(n, r)| (n, r));
        let valid = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
        if !valid(name) {
            return Err(format!(
                "{key:?} is not a key path (e.g. gripper.cup_diameter_m or obstacles[0].size_m)"
            ));
        }
        path.push(Segment::Key(name.to_string()));
        while !rest.is_empty() {
            let (i, after) = rest
                .split_once(']')
                .ok_or_else(|| format!("{key:?}: unclosed [ in the key path"))?;
            let i: usize = i.parse().map_err(|_| format!("{key:?}: [{i}] is not an array index"))?;
            path.push(Segment::Index(i));
            rest = match after.strip_prefix('[') {
                Some(r) => r,
                None if after.is_empty() => "",
                None => return Err(format!("{key:?}: unexpected {after:?} after an index")),
            };
        }
    }
    match path.first() {
        Some(Segment::Key(k)) if k == "workpiece" => {
            if path.len() < 2 {
                return Err(format!(
                    "{key:?}: workpiece. needs a key of the workpiece files after it"
                ));
            }
            Ok((Target::Workpiece, path.split_off(1)))
        }
        _ => Ok((Target::Cell, path)),
    }
}

/// Splits `text` at commas outside brackets and quotes.
fn split_top_level(text: &str) -> Vec<&str> {
    let (mut depth, mut quote, mut start) = (0i32, None::<char>, 0);
    let mut parts = Vec::new();
    for (i, c) in text.char_indices() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, '[' | '{') => depth += 1,
            (None, ']' | '}') => depth -= 1,
            (None, ',') if depth == 0 => {
                parts.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&text[start..]);
    parts
}

/// One value: a TOML value (`0.006`, `3`, `true`, `"x"`, `[0.4, -0.2, 0.006]`), else a bare word
/// as a string (`oracle`).
fn parse_value(key: &str, text: &str) -> Result<toml::Value, StudyError> {
    let t = text.trim();
    if t.is_empty() {
        return Err(input(format!("--set {key}: an empty value in the list")));
    }
    if let Ok(mut table) = toml::from_str::<toml::Table>(&format!("v = {t}"))
        && let Some(v) = table.remove("v")
    {
        return Ok(v);
    }
    if t.bytes().all(|b| b.is_ascii_alphanumeric() || b"_-./+".contains(&b)) {
        return Ok(toml::Value::String(t.to_string()));
    }
    Err(input(format!(
        "--set {key}: {t:?} is not a value (a number, true/false, a \"string\" or [an, array])"
    )))
}

/// Decimal places written in a number's text (`0.0025` has 4, `1e-3` is counted as 3).
fn decimals(text: &str) -> i32 {
    let t = text.trim().to_ascii_lowercase();
    let (mant, exp) = t
        .split_once('e')
        .map_or((t.as_str(), 0), |(m, e)| (m, e.parse::<i32>().unwrap_or(0)));
    let frac = mant.split_once('.').map_or(0, |(_, f)| f.len() as i32);
    (frac - exp).max(0)
}

/// A range `start:stop:step`: start, start + step, ... up to stop (included when a whole number of
/// steps away). Integers if all three are; otherwise floats rounded to the decimals written.
fn parse_range(key: &str, text: &str) -> Result<Vec<toml::Value>, StudyError> {
    let parts: Vec<&str> = text.split(':').map(str::trim).collect();
    let bad = |why: &str| input(format!("--set {key}: range {text:?} {why}"));
    if parts.len() != 3 {
        return Err(bad("must be start:stop:step"));
    }
    if let (Ok(a), Ok(b), Ok(s)) = (
        parts[0].parse::<i64>(),
        parts[1].parse::<i64>(),
        parts[2].parse::<i64>(),
    ) {
        if s == 0 {
            return Err(bad("has a zero step"));
        }
        if (b - a).signum() * s.signum() < 0 {
            return Err(bad("never reaches its stop: the step goes the other way"));
        }
        let n = (b - a) / s + 1;
        if n as usize > MAX_VALUES {
            return Err(bad(&format!("gives {n} values, more than {MAX_VALUES}")));
        }
        return Ok((0..n).map(|i| toml::Value::Integer(a + i * s)).collect());
    }
    let num = |t: &str| t.parse::<f64>().ok().filter(|v| v.is_finite());
    let (Some(a), Some(b), Some(s)) = (num(parts[0]), num(parts[1]), num(parts[2])) else {
        return Err(bad("needs three finite numbers, start:stop:step"));
    };
    if s == 0.0 {
        return Err(bad("has a zero step"));
    }
    if (b - a) * s < 0.0 {
        return Err(bad("never reaches its stop: the step goes the other way"));
    }
    let steps = ((b - a) / s * (1.0 + 1e-9) + 1e-9).floor();
    if steps + 1.0 > MAX_VALUES as f64 {
        return Err(bad(&format!("gives {} values, more than {MAX_VALUES}", steps + 1.0)));
    }
    // Whole multiples of the written resolution: 0.004 + 2 x 0.002 is 0.008, not 0.008000000000000002.
    let d = parts.iter().map(|p| decimals(p)).max().unwrap_or(0).min(15);
    let scale = 10f64.powi(d);
    let (a_k, s_k) = ((a * scale).round(), (s * scale).round());
    Ok((0..=steps as usize)
        .map(|i| toml::Value::Float((a_k + i as f64 * s_k) / scale))
        .collect())
}

/// Parses one `--set KEY=V1,V2,...`.
pub fn parse_set(text: &str) -> Result<SetArg, StudyError> {
    let (key, list) = text
        .split_once('=')
        .ok_or_else(|| input(format!("--set: expected KEY=V1,V2,..., got {text:?}")))?;
    let key = key.trim();
    let (target, path) = parse_key(key).map_err(|m| input(format!("--set: {m}")))?;
    if list.trim().is_empty() {
        return Err(input(format!("--set {key}: the list of values is empty")));
    }
    let mut values = Vec::new();
    for part in split_top_level(list) {
        let t = part.trim();
        let plain = !t.starts_with(['[', '{', '"', '\'']);
        if plain && t.contains(':') {
            values.extend(parse_range(key, t)?);
        } else {
            values.push(parse_value(key, t)?);
        }
        if values.len() > MAX_VALUES {
            return Err(input(format!("--set {key}: more than {MAX_VALUES} values")));
        }
    }
    Ok(SetArg {
        key: key.to_string(),
        target,
        path,
        values,
    })
}

/// Parses every `--set`; a key given twice is refused (its lists would multiply, not combine).
pub fn parse_sets(texts: &[String]) -> Result<Vec<SetArg>, StudyError> {
    if texts.is_empty() {
        return Err(input("sweep: give at least one --set KEY=V1,V2,..."));
    }
    let mut sets: Vec<SetArg> = Vec::new();
    for t in texts {
        let s = parse_set(t)?;
        if s.target == Target::Workpiece && s.path == [Segment::Key("name".into())] {
            return Err(input(format!(
                "--set {}: a workpiece's name labels its rows and runs; sweep its other keys",
                s.key
            )));
        }
        if let Some(first) = sets.iter().find(|x| x.target == s.target && x.path == s.path) {
            return Err(input(format!(
                "--set {}: the same key is set twice (also as {}); give all its values in one list",
                s.key, first.key
            )));
        }
        sets.push(s);
    }
    let count = sets.iter().try_fold(1usize, |n, s| n.checked_mul(s.values.len()));
    if count.is_none_or(|n| n > MAX_VARIANTS) {
        return Err(input(format!(
            "sweep: the --set lists give more than {MAX_VARIANTS} variants"
        )));
    }
    Ok(sets)
}

/// The variants: every combination of the lists' values, the first key's slowest; each as the
/// values in `sets` order.
pub fn variants(sets: &[SetArg]) -> Vec<Vec<toml::Value>> {
    let mut out: Vec<Vec<toml::Value>> = vec![Vec::new()];
    for s in sets {
        out = out
            .into_iter()
            .flat_map(|prefix| {
                s.values.iter().map(move |v| {
                    let mut p = prefix.clone();
                    p.push(v.clone());
                    p
                })
            })
            .collect();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn floats(v: &[toml::Value]) -> Vec<f64> {
        v.iter().map(|x| x.as_float().unwrap()).collect()
    }

    #[test]
    fn lists_ranges_and_types_parse() {
        let s = parse_set("gripper.cup_diameter_m=0.004:0.012:0.002").unwrap();
        assert_eq!(floats(&s.values), vec![0.004, 0.006, 0.008, 0.01, 0.012]);
        assert_eq!(s.target, Target::Cell);
        let s = parse_set("cycle.max_picks_per_capture=1:3:1").unwrap();
        assert_eq!(s.values, vec![1.into(), 2.into(), 3.into()]);
        let s = parse_set("place_tray.tray.center_m=[0.4, -0.2, 0.006],[0.3,0.3,0.006]").unwrap();
        assert_eq!(s.values.len(), 2);
        assert_eq!(value_text(&s.values[0]), "[0.4, -0.2, 0.006]");
        let s = parse_set("sensor.recognition=oracle,\"cloud\"").unwrap();
        assert_eq!(s.values, vec!["oracle".into(), "cloud".into()]);
        let s = parse_set("workpiece.grasp.face_margin_m=0.0005,1e-3").unwrap();
        assert_eq!(s.target, Target::Workpiece);
        assert_eq!(
            s.path,
            vec![Segment::Key("grasp".into()), Segment::Key("face_margin_m".into())]
        );
        let (_, p) = parse_key("obstacles[1].size_m[2]").unwrap();
        assert_eq!(p.len(), 4);
        // A range down, and one whose stop is not a whole number of steps away.
        assert_eq!(
            floats(&parse_set("k=1.1:0.3:-0.4").unwrap().values),
            vec![1.1, 0.7, 0.3]
        );
        assert_eq!(
            floats(&parse_set("k=0:1:0.3").unwrap().values),
            vec![0.0, 0.3, 0.6, 0.9]
        );
        for (bad, why) in [
            ("k=", "empty"),
            ("k=1,,2", "empty value"),
            ("k=1:2:0", "zero step"),
            ("k=1:2:-1", "other way"),
            ("k=1:2", "start:stop:step"),
            ("k=a:b:c", "three finite numbers"),
            ("k=0:1:0.0001", "more than 1000"),
            ("nokey", "KEY=V1"),
            ("a..b=1", "not a key path"),
            ("k=[1,", "not a value"),
        ] {
            let e = parse_set(bad).unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
        let e = parse_sets(&["k=1,2".into(), "k=3".into()]).unwrap_err().to_string();
        assert!(e.contains("set twice"), "{e}");
        let e = parse_sets(&["workpiece.name=X".into()]).unwrap_err().to_string();
        assert!(e.contains("labels its rows"), "{e}");
    }

    #[test]
    fn variants_are_the_product_first_key_slowest_and_shards_partition_them() {
        let sets = parse_sets(&["a=1,2".into(), "b=x,y,z".into()]).unwrap();
        let v = variants(&sets);
        assert_eq!(v.len(), 6);
        assert_eq!(v[1], vec![1.into(), "y".into()]);
        assert_eq!(v[3], vec![2.into(), "x".into()]);
        let spec = crate::study::StudySpec {
            scene: "s".into(),
            keys: vec!["a".into(), "b".into()],
            variants: v.iter().map(|x| x.iter().map(value_text).collect()).collect(),
            workpieces: vec!["A".into(), "B".into()],
            seeds: vec![1, 2],
            picks: 5,
            deterministic: true,
        };
        let jobs = spec.jobs();
        assert_eq!(jobs.len(), 24);
        let j = &jobs[5];
        assert_eq!((j.variant, j.workpiece.as_str(), j.seed), (1, "A", 2));
        let mut all: Vec<_> = (1..=5).flat_map(|k| crate::study::shard(&jobs, k, 5)).collect();
        all.sort();
        let mut want = jobs.clone();
        want.sort();
        assert_eq!(all, want);
        assert_eq!(spec.name(), "sweep-a+b-AB-seeds1-2-picks5-det");
        assert_eq!(spec.describe(1), "a=1, b=y");
    }
}
