//! Report stage: takt-time tables over many cell runs (batches, shards and merges).
//!
//! Job: a batch is every (workpiece, seed) pair of a sweep, each one [`crate::cycle::run`] of
//! the same number of picks. Runs go in parallel across cores; each keeps the per-pick values the
//! table needs ([`RunEntry`]), so shards of a batch run on different machines (`--shard K/N`:
//! runs i with i mod N = K - 1) and merge into the same table as the whole batch would give.
//! The table has one row per workpiece over all its seeds: takt mean, p95, min and max over the
//! placed picks after the first of each pile, success rate, waits, faults, mean Pick and Place
//! times and compute per stage, with the reference system's takt beside it.
//!
//! Units: s (ms in the table's compute columns), counts. Rows are in workpiece order as given.

use serde::{Deserialize, Serialize};

use crate::cycle::{Outcome, RunResult, TaktStats};

/// Why a batch specification, a shard or a merge is invalid.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// A bad argument.
    #[error("{0}")]
    Input(String),
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
            (Some(a), Some(b)) if self.seeds.len() > 1 && b - a + 1 == self.seeds.len() as u64 => format!("{a}-{b}"),
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

/// The runs of shard `k` of `n`: every n-th run from the (k-1)-th.
pub fn shard(jobs: &[(String, u64)], k: usize, n: usize) -> Vec<(String, u64)> {
    jobs.iter()
        .enumerate()
        .filter(|(i, _)| i % n == k - 1)
        .map(|(_, j)| j.clone())
        .collect()
}

/// What the table keeps of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunEntry {
    /// Workpiece.
    pub workpiece: String,
    /// Seed.
    pub seed: u64,
    /// Picks attempted.
    pub attempts: usize,
    /// Picks placed.
    pub placed: usize,
    /// Takts in the statistics [s].
    pub takts_s: Vec<f64>,
    /// First to last release [s] and the releases in between (end-to-end takt = ratio).
    pub release_span: (f64, usize),
    /// Pick and Place times of the placed picks [s].
    pub pick_s: Vec<f64>,
    /// Place times of the placed picks [s].
    pub place_s: Vec<f64>,
    /// Compute charged per attempt, summed: grasp, Pick, Place [s].
    pub compute_sum_s: [f64; 3],
    /// Waits for the sensor in the takts: count and total [s].
    pub sensor_waits: (usize, f64),
    /// Waits for compute in the takts: count and total [s].
    pub compute_waits: (usize, f64),
    /// Protective stops, collisions, drops, grasp failures, parts lost.
    pub faults: [usize; 5],
    /// Refills of the pick tray.
    pub refills: usize,
    /// Largest |torque| / limit.
    pub peak_torque_ratio: f64,
    /// Simulated time [s].
    pub sim_time_s: f64,
    /// Wall time of the run [s] (not in deterministic comparisons).
    pub wall_s: f64,
    /// Why the run ended.
    pub ended: String,
}

impl RunEntry {
    /// From a finished run.
    pub fn from_run(r: &RunResult, wall_s: f64) -> Self {
        let s = &r.summary;
        let placed: Vec<_> = r.records.iter().filter(|p| p.outcome == Outcome::Placed).collect();
        let attempts: Vec<_> = r.records.iter().filter(|p| p.outcome.is_attempt()).collect();
        let sum = |f: fn(&crate::cycle::PickRecord) -> f64| attempts.iter().map(|p| f(p)).sum::<f64>();
        RunEntry {
            workpiece: s.workpiece.clone(),
            seed: s.seed,
            attempts: s.attempts,
            placed: s.placed,
            takts_s: crate::cycle::takts_in_stats(&r.records),
            release_span: crate::cycle::release_span(&r.records),
            pick_s: placed.iter().map(|p| p.pick_s).collect(),
            place_s: placed.iter().map(|p| p.place_s).collect(),
            compute_sum_s: [
                sum(|p| p.grasp_compute_s),
                sum(|p| p.pick_compute_s),
                sum(|p| p.place_compute_s),
            ],
            sensor_waits: s.sensor_stalls,
            compute_waits: s.compute_stalls,
            faults: [
                s.protective_stops,
                s.collisions,
                s.drops,
                attempts.iter().filter(|p| p.outcome.name() == "grasp_failed").count(),
                s.parts_lost,
            ],
            refills: s.refills,
            peak_torque_ratio: s.peak_torque_ratio,
            sim_time_s: s.sim_time_s,
            wall_s,
            ended: s.ended.clone(),
        }
    }
}

/// One row of the takt-time table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// Workpiece.
    pub workpiece: String,
    /// Runs.
    pub runs: usize,
    /// Picks attempted.
    pub attempts: usize,
    /// Picks placed.
    pub placed: usize,
    /// placed / attempts.
    pub success_rate: f64,
    /// Takt statistics over all runs' takts.
    pub takt: TaktStats,
    /// The reference system's takt [s].
    pub reference_takt_s: Option<f64>,
    /// End-to-end takt over all runs: refills, re-captures and failures included [s].
    pub effective_takt_s: f64,
    /// Mean Pick time [s].
    pub mean_pick_s: f64,
    /// Mean Place time [s].
    pub mean_place_s: f64,
    /// Mean compute per attempt: grasp, Pick, Place [s].
    pub mean_compute_s: [f64; 3],
    /// Waits for the sensor: count, mean [s].
    pub sensor_waits: (usize, f64),
    /// Waits for compute: count, mean [s].
    pub compute_waits: (usize, f64),
    /// Protective stops.
    pub protective_stops: usize,
    /// Collisions.
    pub collisions: usize,
    /// Drops.
    pub drops: usize,
    /// Grasp failures.
    pub grasp_failures: usize,
    /// Parts lost.
    pub parts_lost: usize,
    /// Refills.
    pub refills: usize,
    /// Largest |torque| / limit.
    pub peak_torque_ratio: f64,
    /// Simulated time, all runs [s].
    pub sim_time_s: f64,
    /// Wall time, all runs [s].
    pub wall_s: f64,
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// The table: one row per workpiece (in `order`), over every entry of that workpiece.
pub fn table(order: &[String], entries: &[RunEntry]) -> Vec<Row> {
    order
        .iter()
        .filter_map(|w| {
            let es: Vec<&RunEntry> = entries.iter().filter(|e| &e.workpiece == w).collect();
            if es.is_empty() {
                return None;
            }
            let cat = |f: fn(&RunEntry) -> &Vec<f64>| es.iter().flat_map(|e| f(e).iter().copied()).collect::<Vec<_>>();
            let attempts: usize = es.iter().map(|e| e.attempts).sum();
            let placed: usize = es.iter().map(|e| e.placed).sum();
            let waits = |f: fn(&RunEntry) -> (usize, f64)| {
                let (n, t) = es.iter().map(|e| f(e)).fold((0, 0.0), |(n, t), (a, b)| (n + a, t + b));
                (n, if n == 0 { 0.0 } else { t / n as f64 })
            };
            let fault = |i: usize| es.iter().map(|e| e.faults[i]).sum();
            let compute = |i: usize| {
                if attempts == 0 {
                    f64::NAN
                } else {
                    es.iter().map(|e| e.compute_sum_s[i]).sum::<f64>() / attempts as f64
                }
            };
            Some(Row {
                workpiece: w.clone(),
                runs: es.len(),
                attempts,
                placed,
                success_rate: if attempts == 0 {
                    f64::NAN
                } else {
                    placed as f64 / attempts as f64
                },
                takt: TaktStats::of(&cat(|e| &e.takts_s)),
                reference_takt_s: crate::cycle::reference_takt(w),
                effective_takt_s: {
                    let (t, n) = es
                        .iter()
                        .fold((0.0, 0), |(t, n), e| (t + e.release_span.0, n + e.release_span.1));
                    if n == 0 { f64::NAN } else { t / n as f64 }
                },
                mean_pick_s: mean(&cat(|e| &e.pick_s)),
                mean_place_s: mean(&cat(|e| &e.place_s)),
                mean_compute_s: [compute(0), compute(1), compute(2)],
                sensor_waits: waits(|e| e.sensor_waits),
                compute_waits: waits(|e| e.compute_waits),
                protective_stops: fault(0),
                collisions: fault(1),
                drops: fault(2),
                grasp_failures: fault(3),
                parts_lost: fault(4),
                refills: es.iter().map(|e| e.refills).sum(),
                peak_torque_ratio: es.iter().map(|e| e.peak_torque_ratio).fold(0.0, f64::max),
                sim_time_s: es.iter().map(|e| e.sim_time_s).sum(),
                wall_s: es.iter().map(|e| e.wall_s).sum(),
            })
        })
        .collect()
}

fn num(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "-".into()
    }
}

/// The table as Markdown.
pub fn markdown(rows: &[Row]) -> String {
    let mut md = String::from(
        "| part | runs | placed | success | takt mean [s] | p95 | min | max | reference [s] | end-to-end [s] | Pick [s] | Place [s] \
         | compute grasp/Pick/Place [ms] | sensor waits (mean s) | compute waits (mean s) | stops | collisions \
         | drops | grasp fails | lost | refills |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        md += &format!(
            "| {} | {} | {}/{} | {} % | {} | {} | {} | {} | {} | {} | {} | {} | {}/{}/{} | {} ({}) | {} ({}) | {} | {} | {} | {} | {} | {} |\n",
            r.workpiece,
            r.runs,
            r.placed,
            r.attempts,
            num(100.0 * r.success_rate, 1),
            num(r.takt.mean_s, 3),
            num(r.takt.p95_s, 3),
            num(r.takt.min_s, 3),
            num(r.takt.max_s, 3),
            r.reference_takt_s.map_or("-".into(), |t| num(t, 1)),
            num(r.effective_takt_s, 3),
            num(r.mean_pick_s, 3),
            num(r.mean_place_s, 3),
            num(r.mean_compute_s[0] * 1e3, 1),
            num(r.mean_compute_s[1] * 1e3, 1),
            num(r.mean_compute_s[2] * 1e3, 1),
            r.sensor_waits.0,
            num(r.sensor_waits.1, 3),
            r.compute_waits.0,
            num(r.compute_waits.1, 3),
            r.protective_stops,
            r.collisions,
            r.drops,
            r.grasp_failures,
            r.parts_lost,
            r.refills,
        );
    }
    md
}

/// The table as CSV.
pub fn csv(rows: &[Row]) -> String {
    let mut out = String::from(
        "workpiece,runs,attempts,placed,success_rate,takt_mean_s,takt_p95_s,takt_min_s,takt_max_s,takt_count,\
         reference_takt_s,effective_takt_s,mean_pick_s,mean_place_s,mean_grasp_compute_s,mean_pick_compute_s,mean_place_compute_s,\
         sensor_waits,sensor_wait_mean_s,compute_waits,compute_wait_mean_s,protective_stops,collisions,drops,\
         grasp_failures,parts_lost,refills,peak_torque_ratio,sim_time_s\n",
    );
    let f = |v: f64| {
        if v.is_finite() {
            format!("{v:.6}")
        } else {
            String::new()
        }
    };
    for r in rows {
        out += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            r.workpiece,
            r.runs,
            r.attempts,
            r.placed,
            f(r.success_rate),
            f(r.takt.mean_s),
            f(r.takt.p95_s),
            f(r.takt.min_s),
            f(r.takt.max_s),
            r.takt.count,
            r.reference_takt_s.map_or(String::new(), f),
            f(r.effective_takt_s),
            f(r.mean_pick_s),
            f(r.mean_place_s),
            f(r.mean_compute_s[0]),
            f(r.mean_compute_s[1]),
            f(r.mean_compute_s[2]),
            r.sensor_waits.0,
            f(r.sensor_waits.1),
            r.compute_waits.0,
            f(r.compute_waits.1),
            r.protective_stops,
            r.collisions,
            r.drops,
            r.grasp_failures,
            r.parts_lost,
            r.refills,
            f(r.peak_torque_ratio),
            f(r.sim_time_s),
        );
    }
    out
}

/// What `takt.json` holds: the batch, which shard, every run's entry, and the table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BatchFile {
    /// binpick version.
    pub version: String,
    /// The whole batch.
    pub spec: BatchSpec,
    /// This file's shard (K, N); (1, 1) for a whole batch or a merge.
    pub shard: (usize, usize),
    /// Runs.
    pub runs: Vec<RunEntry>,
}

/// Joins the `takt.json` of every shard of one batch: the specs must agree, and together the
/// shards must cover each run of the batch exactly once.
pub fn merge(files: &[(String, BatchFile)]) -> Result<BatchFile, BatchError> {
    let Some((first_path, first)) = files.first() else {
        return Err(BatchError::Input("merge: no shard results given".into()));
    };
    let mut runs: Vec<RunEntry> = Vec::new();
    for (path, f) in files {
        if f.spec != first.spec {
            return Err(BatchError::Input(format!(
                "merge: {path} is from another batch than {first_path} ({} vs {})",
                f.spec.name(),
                first.spec.name()
            )));
        }
        runs.extend(f.runs.iter().cloned());
    }
    let jobs = first.spec.jobs();
    let mut ordered = Vec::with_capacity(jobs.len());
    for (w, s) in &jobs {
        let found: Vec<&RunEntry> = runs.iter().filter(|e| &e.workpiece == w && e.seed == *s).collect();
        match found.len() {
            1 => ordered.push(found[0].clone()),
            0 => {
                return Err(BatchError::Input(format!(
                    "merge: run {w} seed {s} of {} is in none of the shards given",
                    first.spec.name()
                )));
            }
            _ => {
                return Err(BatchError::Input(format!(
                    "merge: run {w} seed {s} is in {} of the shards given",
                    found.len()
                )));
            }
        }
    }
    Ok(BatchFile {
        version: first.version.clone(),
        spec: first.spec.clone(),
        shard: (1, 1),
        runs: ordered,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(w: &str, seed: u64, takts: &[f64]) -> RunEntry {
        RunEntry {
            workpiece: w.into(),
            seed,
            attempts: takts.len() + 1,
            placed: takts.len() + 1,
            takts_s: takts.to_vec(),
            release_span: (takts.iter().sum(), takts.len()),
            pick_s: vec![1.0; takts.len() + 1],
            place_s: vec![1.0; takts.len() + 1],
            compute_sum_s: [0.05 * (takts.len() + 1) as f64, 0.0, 0.0],
            sensor_waits: (1, 0.2),
            compute_waits: (0, 0.0),
            faults: [0, 0, 0, 0, 0],
            refills: 0,
            peak_torque_ratio: 0.9,
            sim_time_s: 10.0,
            wall_s: 0.5,
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
        assert!(markdown(&whole).contains("| A | 2 | 6/6 | 100.0 % | 2.325 |"));
        assert!((whole[0].effective_takt_s - 2.325).abs() < 1e-12);
    }
}
