//! Batches: many cell runs, one takt-time table.
//!
//! Job: a batch is every (workpiece, seed) pair of a specification, each one
//! [`crate::cycle::run`] of the same number of picks; parse its seeds and its shard
//! (`--shard K/N`: runs i with i mod N = K - 1, so shards of a batch run on different machines
//! and merge into the same table as the whole batch would give). The runs go through the
//! [`runner`] (parallel, recorded if asked, with a progress callback); their results become the
//! [`table`] (one row per workpiece, beside the reference's takt).
//!
//! Units: s, counts. Rows are in workpiece order as given.

pub mod chart;
pub mod runner;
pub mod table;

use serde::{Deserialize, Serialize};

pub use runner::{BatchInputs, BatchRuns, RecordTo, run_batch};
pub use table::{BatchFile, Row, RunEntry, csv, markdown, merge, table};

/// Why a batch specification, a shard or a merge is invalid.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// A bad argument.
    #[error("{0}")]
    Input(String),
    /// A run failed (or its recording could not be written).
    #[error("cell run failed: {0}")]
    Run(String),
    /// A shard's results could not be read.
    #[error("{path}: {reason}")]
    Read {
        /// The file.
        path: String,
        /// What went wrong.
        reason: String,
    },
}

/// What a batch runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchSpec {
    /// Workpieces, in table order.
    pub workpieces: Vec<String>,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Picks per run.
    pub picks: usize,
    /// Deterministic compute budgets.
    pub deterministic: bool,
}

impl BatchSpec {
    /// Every (workpiece, seed) run, workpiece-major.
    pub fn jobs(&self) -> Vec<(String, u64)> {
        self.workpieces
            .iter()
            .flat_map(|w| self.seeds.iter().map(move |s| (w.clone(), *s)))
            .collect()
    }

    /// A name for the batch's folder.
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
        format!(
            "batch-{}-seeds{seeds}-picks{}{}",
            self.workpieces.join(""),
            self.picks,
            if self.deterministic { "-det" } else { "" }
        )
    }
}

/// Parses `1-3` or `1,2,5` (or a mix, `1-3,7`) into seeds: any u64 (a range may end at
/// `u64::MAX`), ranges ascending, no seed twice, at most 10,000 in all.
pub fn parse_seeds(text: &str) -> Result<Vec<u64>, BatchError> {
    // Most seeds in one batch. Every seed is a cell run of each workpiece (seconds to a minute of
    // wall time each), and the expanded list and every run's entry are held in memory and in
    // `takt.json`: 10,000 seeds are 60,000 runs of the six workpieces, hours to days of compute,
    // so more is a typo (`1-1000000`) rather than a plan; a larger sweep is several batches.
    const MAX_SEEDS: usize = 10_000;
    let input = |m: String| BatchError::Input(format!("--seeds: {m}"));
    let bad = || input(format!("expected e.g. 1-3 or 1,2,5, got {text:?}"));
    let seed = |s: &str| -> Result<u64, BatchError> {
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
pub fn parse_shard(text: &str) -> Result<(usize, usize), BatchError> {
    let bad = || BatchError::Input(format!("--shard: expected K/N with 1 <= K <= N, got {text:?}"));
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

/// The runs of shard `k` of `n`: every n-th run from the (k-1)-th (batches and sweeps).
pub fn shard<T: Clone>(jobs: &[T], k: usize, n: usize) -> Vec<T> {
    jobs.iter()
        .enumerate()
        .filter(|(i, _)| i % n == k - 1)
        .map(|(_, j)| j.clone())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two captures' worth of recognition figures (all finite, so rows compare equal).
    fn recognition_fixture() -> crate::sensor::RecognitionTotals {
        crate::sensor::RecognitionTotals {
            captures: 2,
            top_layer: 10,
            top_layer_found: 9,
            detected: 11,
            correct: 11,
            position_errors_m: vec![0.0002, 0.0004],
            rotation_errors_rad: vec![0.01, 0.02],
        }
    }

    fn entry(w: &str, seed: u64, takts: &[f64]) -> RunEntry {
        RunEntry {
            workpiece: w.into(),
            seed,
            attempts: takts.len() + 1,
            placed: takts.len() + 1,
            set_out: takts.len() + 1,
            takts_s: takts.to_vec(),
            // The last interval spans a tray refill.
            takts_excl_refills_s: takts[..takts.len() - 1].to_vec(),
            pick_s: vec![1.0; takts.len() + 1],
            place_s: vec![1.0; takts.len() + 1],
            compute_sum_s: [0.05 * (takts.len() + 1) as f64, 0.0, 0.0],
            result_to_motion_s: vec![0.05; takts.len() + 1],
            sensor_waits: (1, 0.2),
            compute_waits: (0, 0.0),
            faults: [0, 0, 0, 0, 0],
            refills: 0,
            agitations: 1,
            blind_picks: (0, 0),
            results_used: takts.len() + 1,
            grasps: (takts.len() + 1, takts.len() + 1),
            misrecognised: 0,
            recognition: recognition_fixture(),
            peak_demand_ratio: [0.9, 0.5, 0.5, 0.5, 0.5, 0.5],
            saturated_s: 0.0,
            max_tracking_error_deg: 0.1,
            sim_time_s: 10.0,
            wall_s: Some(0.5),
            ended: "picks done".into(),
        }
    }

    #[test]
    fn seeds_and_shards_parse_and_shards_partition_the_batch() {
        assert_eq!(parse_seeds("1-3").unwrap(), vec![1, 2, 3]);
        assert_eq!(parse_seeds("4,1-2").unwrap(), vec![4, 1, 2]);
        assert!(
            parse_seeds("3-1")
                .unwrap_err()
                .to_string()
                .contains("range 3-1 is reversed")
        );
        assert!(parse_seeds("1,1").is_err());
        for bad in ["x", "", "1,", "-3", "1-", "1-2-3", "1 2", "-1"] {
            assert!(parse_seeds(bad).is_err(), "{bad:?}");
        }
        // Up to u64::MAX, and not one past it.
        let max = u64::MAX;
        assert_eq!(parse_seeds(&format!("{}-{max}", max - 1)).unwrap(), vec![max - 1, max]);
        assert_eq!(parse_seeds(&format!("{max},0")).unwrap(), vec![max, 0]);
        let past = parse_seeds(&format!("{max}-18446744073709551616"))
            .unwrap_err()
            .to_string();
        assert!(past.contains("seed 18446744073709551616 is out of range"), "{past}");
        // At most MAX_SEEDS, however written; a range over the whole u64 does not overflow.
        assert_eq!(parse_seeds("1-10000").unwrap().len(), 10_000);
        for many in [
            "1-10001".to_string(),
            "0-18446744073709551615".to_string(),
            "1-5000,6001-11001".to_string(),
            format!("1-10000,{max}"),
        ] {
            assert!(
                parse_seeds(&many)
                    .unwrap_err()
                    .to_string()
                    .contains("more than 10000 seeds"),
                "{many}"
            );
        }
        assert_eq!(parse_shard("2/3").unwrap(), (2, 3));
        for bad in ["0/3", "4/3", "1", "a/b", "1/0"] {
            assert!(parse_shard(bad).is_err(), "{bad}");
        }
        let spec = BatchSpec {
            workpieces: vec!["A".into(), "B".into()],
            seeds: vec![1, 2, 3],
            picks: 5,
            deterministic: true,
        };
        let jobs = spec.jobs();
        assert_eq!(jobs.len(), 6);
        let mut all: Vec<_> = (1..=4).flat_map(|k| shard(&jobs, k, 4)).collect();
        all.sort();
        let mut want = jobs.clone();
        want.sort();
        assert_eq!(all, want);
        assert_eq!(spec.name(), "batch-AB-seeds1-3-picks5-det");
    }

    #[test]
    fn merged_shards_give_the_whole_batch_table_and_gaps_are_refused() {
        let spec = BatchSpec {
            workpieces: vec!["A".into(), "B".into()],
            seeds: vec![1, 2],
            picks: 3,
            deterministic: true,
        };
        let entries: Vec<RunEntry> = spec
            .jobs()
            .iter()
            .map(|(w, s)| entry(w, *s, &[2.0 + *s as f64 * 0.1, 2.5]))
            .collect();
        let whole = table(&spec.workpieces, &entries);
        let file = |k: usize| BatchFile {
            version: "t".into(),
            spec: spec.clone(),
            shard: (k, 2),
            runs: entries
                .iter()
                .enumerate()
                .filter(|(i, _)| i % 2 == k - 1)
                .map(|(_, e)| e.clone())
                .collect(),
        };
        let merged = merge(&[("s2".into(), file(2)), ("s1".into(), file(1))]).unwrap();
        assert_eq!(table(&spec.workpieces, &merged.runs), whole);
        assert_eq!(whole[0].takt.count, 4);
        assert!((whole[0].takt.mean_s - (2.1 + 2.5 + 2.2 + 2.5) / 4.0).abs() < 1e-12);
        assert!(
            merge(&[("s1".into(), file(1))]).is_err(),
            "a missing shard must be refused"
        );
        assert!(merge(&[("s1".into(), file(1)), ("s1b".into(), file(1)), ("s2".into(), file(2))]).is_err());
        assert!(
            markdown(&whole).contains("| A | 2 | 6/6 | 100.0 % | 2.325 |"),
            "{}",
            markdown(&whole)
        );
        // Excluding the intervals that span a refill: 2.1 and 2.2.
        assert!((whole[0].takt_excl_refills.mean_s - 2.15).abs() < 1e-12);
        assert!(csv(&whole).lines().next().unwrap().contains("takt_excl_refills_mean_s"));
    }
}
