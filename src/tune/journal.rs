//! A tune's journal: every finished evaluation, appended as it finishes, so an interrupted tune
//! (or one re-run with a larger budget) resumes without running them again.
//!
//! Job: a JSON-lines file, its first line the tune's identity ([`Header`]: what decides the
//! candidates and their figures: the cell, the workpiece, the keys and ranges, the training
//! seeds, picks, mode, seed, population and optimizer), each further line one candidate's values (as the
//! files write them) and its training figures. Opening a journal of another tune is refused; a
//! last line cut short by an interruption is ignored. The optimizer, re-run with the same seed,
//! asks for the same candidates; the journal answers those it has (figures read back exactly:
//! serde_json's `float_roundtrip`), so the search continues where it stopped. The best's and the
//! untuned cell's test figures are kept too (a line `{"test": ...}`), so an interruption during
//! the test runs resumes as well.
//!
//! Shards (`tune --shard K/N`) each append to their own journal in the one shared `--out` folder
//! and read their peers' ([`read_peers`]): every shard replays the same optimizer on the same
//! figures, runs its share of each round and takes the rest from its peers' journals.
//!
//! Units: as [`super::Figures`].

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use super::{Dim, Figures};
use crate::study::StudyError;

/// What decides a tune's candidates and their figures (not its budget or its constraints: the
/// figures do not depend on them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// binpick version.
    pub version: String,
    /// The cell file's label.
    pub scene: String,
    /// The workpiece's label.
    pub workpiece: String,
    /// The keys and ranges.
    pub keys: Vec<Dim>,
    /// Training seeds.
    pub train_seeds: Vec<u64>,
    /// Picks per run.
    pub picks: usize,
    /// Fixed compute budgets.
    pub deterministic: bool,
    /// The optimizer's seed.
    pub seed: u64,
    /// Candidates per round.
    pub population: usize,
    /// The takt optimised (journals written before it was kept optimised every interval:
    /// sustained).
    #[serde(default)]
    pub objective: super::Objective,
    /// Who asks for the candidates (journals written before the grid: the swarm).
    #[serde(default)]
    pub optimizer: super::Optimizer,
}

#[derive(Serialize, Deserialize)]
struct Entry {
    values: Vec<String>,
    train: Figures,
}

/// A candidate's (or the untuned cell's) figures on the test seeds.
#[derive(Serialize, Deserialize)]
struct TestEntry {
    values: Vec<String>,
    seeds: Vec<u64>,
    figures: Figures,
}

/// A line after the header: a training evaluation, or a test measurement.
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum Line {
    Train(Entry),
    Test { test: TestEntry },
}

/// A test measurement's key: the values (as the files write them) and the test seeds.
pub type TestKey = (Vec<String>, Vec<u64>);

/// What journals hold: training figures by values, test figures by values and seeds.
#[derive(Debug, Clone, Default)]
pub struct Entries {
    /// Training figures by values.
    pub train: HashMap<Vec<String>, Figures>,
    /// Test figures by values and test seeds.
    pub test: HashMap<TestKey, Figures>,
}

/// The entries of the journal text `text` if its header is `header` (`None` if not): its lines
/// up to the first that does not parse (a line cut short by an interruption, or being written).
fn entries_of(text: &str, header: &Header) -> Option<Entries> {
    let mut lines = text.lines();
    let first: Option<Header> = lines
        .next()
        .and_then(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .and_then(|v| serde_json::from_value(v.get("tune")?.clone()).ok());
    if first.as_ref() != Some(header) {
        return None;
    }
    let mut out = Entries::default();
    for line in lines.map_while(|l| serde_json::from_str::<Line>(l).ok()) {
        match line {
            Line::Train(e) => {
                out.train.insert(e.values, e.train);
            }
            Line::Test { test } => {
                out.test.insert((test.values, test.seeds), test.figures);
            }
        }
    }
    Some(out)
}

/// The entries of every other journal of the tune `header` in `dir`: the files named
/// `<stem>.*journal.jsonl` (the tune's own journal and its shards' journals) but `own`, whose
/// header is `header`. A shard reads its peers' figures from them (a shared folder).
pub fn read_peers(dir: &Path, stem: &str, header: &Header, own: &Path) -> Result<Entries, StudyError> {
    let mut out = Entries::default();
    let prefix = format!("{stem}.");
    let list = std::fs::read_dir(dir).map_err(|e| io(dir, e))?;
    let mut paths: Vec<PathBuf> = list
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with(&prefix) && n.ends_with("journal.jsonl"))
                && p.as_path() != own
        })
        .collect();
    paths.sort();
    for p in paths {
        // A peer's journal being rewritten as it opens reads short now and whole at the next look.
        let Ok(text) = std::fs::read_to_string(&p) else {
            continue;
        };
        if let Some(e) = entries_of(&text, header) {
            out.train.extend(e.train);
            out.test.extend(e.test);
        }
    }
    Ok(out)
}

/// An open journal: its entries, and the file new ones are appended to.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: Mutex<std::fs::File>,
    /// Figures by values, as read when opened.
    pub entries: HashMap<Vec<String>, Figures>,
    /// Test figures by values and test seeds, as read when opened.
    pub tests: HashMap<TestKey, Figures>,
}

fn io(path: &Path, e: std::io::Error) -> StudyError {
    StudyError::Run(format!("{}: {e}", path.display()))
}

impl Journal {
    /// Opens the journal at `path` (created with `header` if it does not exist). A journal of
    /// another tune is refused.
    pub fn open(path: &Path, header: &Header) -> Result<Journal, StudyError> {
        let mut entries = HashMap::new();
        let mut tests = HashMap::new();
        if path.exists() {
            let text = std::fs::read_to_string(path).map_err(|e| io(path, e))?;
            // A line cut short by an interruption does not parse: it and anything after it
            // (nothing, as lines are appended whole) are run again.
            let Some(e) = entries_of(&text, header) else {
                return Err(StudyError::Input(format!(
                    "{}: a journal of another tune (another cell, workpiece, keys, ranges, training seeds, picks, mode, seed, population or optimizer); remove it or write to another --out",
                    path.display()
                )));
            };
            entries = e.train;
            tests = e.test;
        } else {
            let line = serde_json::json!({ "tune": header }).to_string() + "\n";
            std::fs::write(path, line).map_err(|e| io(path, e))?;
        }
        // Rewrite what was read, so an append never follows a partial line.
        let mut text = serde_json::json!({ "tune": header }).to_string() + "\n";
        let mut sorted: Vec<_> = entries.iter().collect();
        sorted.sort_by(|a, b| a.0.cmp(b.0));
        for (values, train) in sorted {
            text += &(serde_json::to_string(&Entry {
                values: values.clone(),
                train: train.clone(),
            })
            .map_err(|e| StudyError::Run(e.to_string()))?
                + "\n");
        }
        let mut sorted: Vec<_> = tests.iter().collect();
        sorted.sort_by(|a, b| a.0.cmp(b.0));
        for ((values, seeds), figures) in sorted {
            text += &(serde_json::to_string(&Line::Test {
                test: TestEntry {
                    values: values.clone(),
                    seeds: seeds.clone(),
                    figures: figures.clone(),
                },
            })
            .map_err(|e| StudyError::Run(e.to_string()))?
                + "\n");
        }
        std::fs::write(path, text).map_err(|e| io(path, e))?;
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| io(path, e))?;
        Ok(Journal {
            path: path.to_path_buf(),
            file: Mutex::new(file),
            entries,
            tests,
        })
    }

    /// Appends one finished evaluation (written and flushed at once).
    pub fn append(&self, values: &[String], train: &Figures) -> Result<(), StudyError> {
        self.append_line(&Line::Train(Entry {
            values: values.to_vec(),
            train: train.clone(),
        }))
    }

    /// Appends one finished test measurement: `values` (or the untuned cell's row) on `seeds`.
    pub fn append_test(&self, values: &[String], seeds: &[u64], figures: &Figures) -> Result<(), StudyError> {
        self.append_line(&Line::Test {
            test: TestEntry {
                values: values.to_vec(),
                seeds: seeds.to_vec(),
                figures: figures.clone(),
            },
        })
    }

    fn append_line(&self, line: &Line) -> Result<(), StudyError> {
        let line = serde_json::to_string(line).map_err(|e| StudyError::Run(e.to_string()))? + "\n";
        let mut f = self
            .file
            .lock()
            .map_err(|_| StudyError::Run("the journal's lock is poisoned".into()))?;
        f.write_all(line.as_bytes())
            .and_then(|_| f.flush())
            .map_err(|e| io(&self.path, e))
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}
