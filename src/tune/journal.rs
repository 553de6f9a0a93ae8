//! A tune's journal: every finished evaluation, appended as it finishes, so an interrupted tune
//! (or one re-run with a larger budget) resumes without running them again.
//!
//! Job: a JSON-lines file, its first line the tune's identity ([`Header`]: what decides the
//! candidates and their figures: the cell, the workpiece, the keys and ranges, the training
//! seeds, picks, mode, seed and population), each further line one candidate's values (as the
//! files write them) and its training figures. Opening a journal of another tune is refused; a
//! last line cut short by an interruption is ignored. The optimizer, re-run with the same seed,
//! asks for the same candidates; the journal answers those it has (figures read back exactly:
//! serde_json's `float_roundtrip`), so the search continues where it stopped.
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
}

#[derive(Serialize, Deserialize)]
struct Entry {
    values: Vec<String>,
    train: Figures,
}

/// An open journal: its entries, and the file new ones are appended to.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: Mutex<std::fs::File>,
    /// Figures by values, as read when opened.
    pub entries: HashMap<Vec<String>, Figures>,
}

fn io(path: &Path, e: std::io::Error) -> StudyError {
    StudyError::Run(format!("{}: {e}", path.display()))
}

impl Journal {
    /// Opens the journal at `path` (created with `header` if it does not exist). A journal of
    /// another tune is refused.
    pub fn open(path: &Path, header: &Header) -> Result<Journal, StudyError> {
        let mut entries = HashMap::new();
        if path.exists() {
            let text = std::fs::read_to_string(path).map_err(|e| io(path, e))?;
            let mut lines = text.lines();
            let first: Option<Header> = lines
                .next()
                .and_then(|l| serde_json::from_str::<serde_json::Value>(l).ok())
                .and_then(|v| serde_json::from_value(v.get("tune")?.clone()).ok());
            if first.as_ref() != Some(header) {
                return Err(StudyError::Input(format!(
                    "{}: a journal of another tune (another cell, workpiece, keys, ranges, training seeds, picks, mode, seed or population); remove it or write to another --out",
                    path.display()
                )));
            }
            // A line cut short by an interruption does not parse: it and anything after it
            // (nothing, as lines are appended whole) are run again.
            for e in lines.map_while(|l| serde_json::from_str::<Entry>(l).ok()) {
                entries.insert(e.values, e.train);
            }
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
        std::fs::write(path, text).map_err(|e| io(path, e))?;
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| io(path, e))?;
        Ok(Journal {
            path: path.to_path_buf(),
            file: Mutex::new(file),
            entries,
        })
    }

    /// Appends one finished evaluation (written and flushed at once).
    pub fn append(&self, values: &[String], train: &Figures) -> Result<(), StudyError> {
        let line = serde_json::to_string(&Entry {
            values: values.to_vec(),
            train: train.clone(),
        })
        .map_err(|e| StudyError::Run(e.to_string()))?
            + "\n";
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
