//! A study's result file and the merge of its shards.
//!
//! Job: hold what a study (or one shard of it) produced: the spec, which shard, every run's
//! tally in job order; write it as the `batch` or `sweep` object of `takt.json` / `sweep.json`
//! (the layouts those files have always had: a batch's runs are bare tallies, a sweep's carry
//! their variant) and read both back; join the files of a study's shards into the whole
//! study's, refusing shards of another study and runs missing or given twice.
//!
//! Units: as the tallies'.

use serde_json::{Value, json};

use super::{StudyError, StudySpec, input};
use crate::cycle::Tally;

/// What a front end writes of a study: its files, named, and the table, as Markdown (printed)
/// and as JSON (`--json`).
#[derive(Debug, Clone)]
pub struct Outputs {
    /// The files of the results folder: name and text.
    pub files: Vec<(&'static str, String)>,
    /// The table as Markdown.
    pub markdown: String,
    /// The table as JSON.
    pub table: Value,
}

/// One run of a study: its variant and its tally.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyRun {
    /// Index into [`StudySpec::variants`].
    pub variant: usize,
    /// The run's tally.
    pub tally: Tally,
}

/// What a study (or one of its shards) produced.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyFile {
    /// binpick version.
    pub version: String,
    /// The whole study.
    pub spec: StudySpec,
    /// This file's shard (K, N); (1, 1) for a whole study or a merge.
    pub shard: (usize, usize),
    /// Runs, in job order.
    pub runs: Vec<StudyRun>,
}

impl StudyFile {
    /// The file of `runs` of shard `shard` of `spec`, by this binpick. A deterministic study
    /// leaves the runs' wall times out (they are measurements, not results), so its file
    /// repeats byte for byte.
    pub fn new(spec: StudySpec, shard: (usize, usize), mut runs: Vec<StudyRun>) -> Self {
        if spec.deterministic {
            runs.iter_mut().for_each(|r| r.tally.wall_s = None);
        }
        StudyFile {
            version: env!("CARGO_PKG_VERSION").into(),
            spec,
            shard,
            runs,
        }
    }

    /// The key the file's object has in its JSON document: `batch` or `sweep`.
    pub fn key(&self) -> &'static str {
        if self.spec.is_batch() { "batch" } else { "sweep" }
    }

    /// The file's object (a batch's runs bare, a sweep's with their variant).
    pub fn to_json(&self) -> Value {
        let runs: Vec<Value> = self
            .runs
            .iter()
            .map(|r| {
                if self.spec.is_batch() {
                    json!(r.tally)
                } else {
                    json!({"variant": r.variant, "run": r.tally})
                }
            })
            .collect();
        json!({"version": self.version, "spec": self.spec, "shard": self.shard, "runs": runs})
    }

    /// Reads the `batch` or `sweep` object of a result document (`takt.json`, `sweep.json`).
    pub fn from_json(doc: &Value) -> Result<StudyFile, String> {
        let obj = doc
            .get("batch")
            .or_else(|| doc.get("sweep"))
            .ok_or("neither a batch nor a sweep result")?;
        let field = |k: &str| obj.get(k).cloned().ok_or(format!("no {k:?}"));
        let runs = match field("runs")? {
            Value::Array(runs) => runs
                .into_iter()
                .map(|r| match r.get("run") {
                    Some(t) => Ok(StudyRun {
                        variant: from(r.get("variant").cloned().unwrap_or(Value::Null))?,
                        tally: from(t.clone())?,
                    }),
                    None => Ok(StudyRun {
                        variant: 0,
                        tally: from(r)?,
                    }),
                })
                .collect::<Result<Vec<_>, String>>()?,
            _ => return Err("\"runs\" is not a list".into()),
        };
        Ok(StudyFile {
            version: from(field("version")?)?,
            spec: from(field("spec")?)?,
            shard: from(field("shard")?)?,
            runs,
        })
    }
}

/// A value read from JSON, or why it is not one.
fn from<T: serde::de::DeserializeOwned>(v: Value) -> Result<T, String> {
    serde_json::from_value(v).map_err(|e| e.to_string())
}

/// Joins the files of every shard of one study: the specs must agree, and together the shards
/// must cover each run of the study exactly once. The runs come back in job order.
pub fn merge(files: &[(String, StudyFile)]) -> Result<StudyFile, StudyError> {
    let Some((first_path, first)) = files.first() else {
        return Err(input("merge: no shard results given"));
    };
    let spec = &first.spec;
    let kind = first.key();
    let mut runs: Vec<&StudyRun> = Vec::new();
    for (path, f) in files {
        if &f.spec != spec {
            return Err(input(format!(
                "merge: {path} is from another {kind} than {first_path} ({} vs {})",
                f.spec.name(),
                spec.name()
            )));
        }
        runs.extend(&f.runs);
    }
    let mut ordered = Vec::with_capacity(runs.len());
    for job in spec.jobs() {
        let found: Vec<&&StudyRun> = runs
            .iter()
            .filter(|r| r.variant == job.variant && r.tally.workpiece == job.workpiece && r.tally.seed == job.seed)
            .collect();
        if let [one] = found[..] {
            ordered.push((*one).clone());
            continue;
        }
        let of = if spec.is_batch() {
            format!("of {}", spec.name())
        } else {
            format!("of variant {} ({})", job.variant + 1, spec.describe(job.variant))
        };
        let n = match found.len() {
            0 => "none".to_string(),
            n => n.to_string(),
        };
        return Err(input(format!(
            "merge: run {} seed {} {of} is in {n} of the shards given",
            job.workpiece, job.seed
        )));
    }
    Ok(StudyFile {
        version: first.version.clone(),
        spec: spec.clone(),
        shard: (1, 1),
        runs: ordered,
    })
}
