//! Studies: many cell runs, one table. A study is every (variant, workpiece, seed) run of a
//! [`StudySpec`], each one [`crate::cycle::run`] of the same number of picks in the same mode.
//! A batch is a study of one variant (the cell as given); a sweep's variants are the cell and
//! workpiece files with `--set` values applied ([`crate::sweep`]). Both are front ends of this
//! one pipeline: the same spec, the same [`runner`], the same shards and merge ([`file`](mod@file)), the
//! same error type.
//!
//! Job: describe a study's runs (variant-major, then workpiece, then seed), parse its seeds and
//! its shard (`--shard K/N`: runs i with i mod N = K - 1, so shards of a study run on different
//! machines and merge into the same table as the whole study would give), name its folder.
//!
//! Units: s, counts.

pub mod file;
pub mod page;
pub mod runner;

use serde::{Deserialize, Serialize};

pub use file::{Outputs, StudyFile, StudyRun, merge};
pub use page::report_html;
pub use runner::{RecordTo, Resolved, RunSettings, Variant, run_stem, run_study};

/// Why a study's specification, a variant, a shard or a merge is invalid, or a run failed.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// A bad argument (seeds, shard, `--set`, a merge's files).
    #[error("{0}")]
    Input(String),
    /// A variant's cell or workpiece file is refused by the checks a cell file goes through.
    #[error("{0}")]
    Config(#[from] crate::config::ConfigError),
    /// A run failed (or its recording could not be written).
    #[error("cell run failed: {0}")]
    Run(String),
}

fn input(m: impl Into<String>) -> StudyError {
    StudyError::Input(m.into())
}

fn one_plain_variant() -> Vec<Vec<String>> {
    vec![Vec::new()]
}

fn is_one_plain_variant(v: &[Vec<String>]) -> bool {
    v.len() == 1 && v[0].is_empty()
}

/// What a study runs: recorded in its result file, compared when shards merge. A batch has no
/// keys and one variant without values (and writes neither, nor the scene: its files keep the
/// layout batches have always had).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StudySpec {
    /// The cell file the variants start from (its label; empty for a batch).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub scene: String,
    /// The varied keys, in `--set` order (none for a batch).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keys: Vec<String>,
    /// Each variant's values, as [`crate::sweep::value_text`] writes them, in `keys` order.
    #[serde(default = "one_plain_variant", skip_serializing_if = "is_one_plain_variant")]
    pub variants: Vec<Vec<String>>,
    /// Workpieces, in table order.
    pub workpieces: Vec<String>,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Picks per run.
    pub picks: usize,
    /// Fixed compute budgets instead of measured wall time: the same seed gives byte-identical
    /// results.
    pub deterministic: bool,
}

/// One run of a study: which variant, workpiece and seed.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Job {
    /// Index into [`StudySpec::variants`].
    pub variant: usize,
    /// Workpiece name.
    pub workpiece: String,
    /// Seed.
    pub seed: u64,
}

impl StudySpec {
    /// A batch: one variant, the cell as given.
    pub fn batch(workpieces: Vec<String>, seeds: Vec<u64>, picks: usize, deterministic: bool) -> Self {
        StudySpec {
            scene: String::new(),
            keys: Vec::new(),
            variants: one_plain_variant(),
            workpieces,
            seeds,
            picks,
            deterministic,
        }
    }

    /// Whether the study is a batch (no varied key).
    pub fn is_batch(&self) -> bool {
        self.keys.is_empty()
    }

    /// Every run: variant-major, then workpiece, then seed.
    pub fn jobs(&self) -> Vec<Job> {
        (0..self.variants.len())
            .flat_map(|variant| {
                self.workpieces.iter().flat_map(move |w| {
                    self.seeds.iter().map(move |s| Job {
                        variant,
                        workpiece: w.clone(),
                        seed: *s,
                    })
                })
            })
            .collect()
    }

    /// A name for the study's folder: `batch-<workpieces>-seeds<seeds>-picks<n>[-det]`, a
    /// sweep's with `sweep-<keys>-` in place of `batch-`. One-letter workpieces run together
    /// (`ABCDEF`); longer names are joined by `+` (`hex-standoff+to220`), as a sweep's keys are.
    pub fn name(&self) -> String {
        let seeds = match (self.seeds.first(), self.seeds.last()) {
            // A run of consecutive seeds reads as a range (no overflow for seeds near u64::MAX).
            (Some(a), Some(b))
                if self.seeds.len() > 1
                    && b.checked_sub(*a).and_then(|d| d.checked_add(1)) == Some(self.seeds.len() as u64)
                    && self.seeds.windows(2).all(|w| w[0].checked_add(1) == Some(w[1])) =>
            {
                format!("{a}-{b}")
            }
            _ => self.seeds.iter().map(u64::to_string).collect::<Vec<_>>().join("_"),
        };
        let joint = if self.workpieces.iter().all(|w| w.chars().count() == 1) {
            ""
        } else {
            "+"
        };
        let runs = format!(
            "{}-seeds{seeds}-picks{}{}",
            self.workpieces.join(joint),
            self.picks,
            if self.deterministic { "-det" } else { "" }
        );
        if self.is_batch() {
            return format!("batch-{runs}");
        }
        let keys: String = self
            .keys
            .iter()
            .map(|k| k.replace(|c: char| !c.is_ascii_alphanumeric() && c != '_' && c != '.', "_"))
            .collect::<Vec<_>>()
            .join("+");
        format!("sweep-{keys}-{runs}")
    }

    /// A variant's values as `key=value, ...` (empty for a batch's).
    pub fn describe(&self, variant: usize) -> String {
        self.keys
            .iter()
            .zip(&self.variants[variant])
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Parses `1-3` or `1,2,5` (or a mix, `1-3,7`) into seeds: any u64 (a range may end at
/// `u64::MAX`), ranges ascending, no seed twice, at most 10,000 in all.
pub fn parse_seeds(text: &str) -> Result<Vec<u64>, StudyError> {
    // Most seeds in one study. Every seed is a cell run of each workpiece (seconds to a minute of
    // wall time each), and the expanded list and every run's tally are held in memory and in
    // the result file: 10,000 seeds are 60,000 runs of the six workpieces, hours to days of
    // compute, so more is a typo (`1-1000000`) rather than a plan; a larger one is several.
    const MAX_SEEDS: usize = 10_000;
    let input = |m: String| input(format!("--seeds: {m}"));
    let bad = || input(format!("expected e.g. 1-3 or 1,2,5, got {text:?}"));
    let seed = |s: &str| -> Result<u64, StudyError> {
        let s = s.trim();
        match s.parse::<u64>() {
            Ok(v) => Ok(v),
            Err(_) if !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()) => {
                Err(input(format!("seed {s} is out of range: seeds are 0 to {}", u64::MAX)))
            }
            Err(_) => Err(bad()),
        }
    };
    let too_many = || {
        input(format!(
            "{text:?} gives more than {MAX_SEEDS} seeds, the most one batch runs"
        ))
    };
    let mut seeds = Vec::new();
    for part in text.split(',') {
        if let Some((a, b)) = part.split_once('-') {
            let (a, b) = (seed(a)?, seed(b)?);
            if b < a {
                return Err(input(format!(
                    "range {a}-{b} is reversed (it ends below its start); write {b}-{a}"
                )));
            }
            // `b - a` cannot overflow (b >= a); the count `b - a + 1` could, so compare first.
            if b - a >= (MAX_SEEDS - seeds.len()) as u64 {
                return Err(too_many());
            }
            seeds.extend(a..=b);
        } else {
            seeds.push(seed(part)?);
            if seeds.len() > MAX_SEEDS {
                return Err(too_many());
            }
        }
    }
    let mut seen = std::collections::BTreeSet::new();
    if let Some(d) = seeds.iter().find(|s| !seen.insert(**s)) {
        return Err(input(format!("seed {d} appears twice in {text:?}")));
    }
    Ok(seeds)
}

/// Parses `K/N` (1 <= K <= N).
pub fn parse_shard(text: &str) -> Result<(usize, usize), StudyError> {
    let bad = || input(format!("--shard: expected K/N with 1 <= K <= N, got {text:?}"));
    let (k, n) = text.split_once('/').ok_or_else(bad)?;
    let (k, n): (usize, usize) = (
        k.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if k == 0 || n == 0 || k > n {
        return Err(bad());
    }
    Ok((k, n))
}

/// The runs of shard `k` of `n`: every n-th run from the (k-1)-th.
pub fn shard<T: Clone>(jobs: &[T], k: usize, n: usize) -> Vec<T> {
    jobs.iter()
        .enumerate()
        .filter(|(i, _)| i % n == k - 1)
        .map(|(_, j)| j.clone())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::StudySpec;

    #[test]
    fn a_folder_name_keeps_long_workpiece_names_apart() {
        let spec = |w: &[&str]| StudySpec::batch(w.iter().map(|s| s.to_string()).collect(), vec![1, 2, 3], 21, true);
        assert_eq!(spec(&["A", "B", "F"]).name(), "batch-ABF-seeds1-3-picks21-det");
        assert_eq!(
            spec(&["hex-standoff", "to220", "D"]).name(),
            "batch-hex-standoff+to220+D-seeds1-3-picks21-det"
        );
    }
}
