//! Batches: the takt-time table of many cell runs of the cell as given, one row per workpiece
//! beside the reference's takt. A batch is a study of one variant ([`crate::study`] runs it,
//! shards and merges it); this front end writes its files: `takt.json` (the study's file and the
//! table), `takt.csv` and `takt.md` (the table, [`crate::results::table`]) and `takt.svg`
//! ([`takt_chart`]).
//!
//! Units: s, counts. Rows are in workpiece order as given.

pub mod takt_chart;

use serde_json::json;

use crate::results::Summary;
use crate::study::{Outputs, StudyFile};

/// The table: one summary per workpiece (in the spec's order), over all its runs.
pub fn table(file: &StudyFile) -> Vec<Summary> {
    crate::results::per_workpiece(&file.spec.workpieces, file.runs.iter().map(|r| &r.tally))
}

/// The batch's files (`takt.json`, `takt.csv`, `takt.md`, `takt.svg`) and its table.
pub fn outputs(file: &StudyFile) -> Outputs {
    let rows = table(file);
    let table = json!(rows);
    let markdown = crate::results::table::markdown(&rows);
    let doc = json!({"batch": file.to_json(), "table": table});
    let files = vec![
        ("takt.json", crate::report::pretty_json(&doc)),
        ("takt.csv", crate::results::table::csv(&rows)),
        ("takt.md", markdown.clone()),
        (
            "takt.svg",
            takt_chart::takt_svg(
                &format!("takt per workpiece: {}", file.spec.name()),
                &takt_chart::takt_bars(&rows),
            ),
        ),
    ];
    Outputs { files, markdown, table }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::{StudyRun, StudySpec, merge};

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

    fn entry(w: &str, seed: u64, takts: &[f64]) -> crate::cycle::Tally {
        let n = takts.len() + 1;
        crate::cycle::Tally {
            workpiece: w.into(),
            seed,
            runs: 1,
            attempts: n,
            placed: n,
            set_out: n,
            takts_s: takts.to_vec(),
            // The last interval spans a tray refill.
            takts_excl_refills_s: takts[..takts.len() - 1].to_vec(),
            pick_s: vec![1.0; n],
            place_s: vec![1.0; n],
            compute_sum: crate::cycle::StageCompute {
                grasp_s: 0.05 * n as f64,
                ..Default::default()
            },
            result_to_motion_s: vec![0.05; n],
            sensor_waits: crate::cycle::Waits { count: 1, total_s: 0.2 },
            agitations: 1,
            results_used: n,
            grasps: (n, n),
            recognition: recognition_fixture(),
            peak_demand_ratio: [0.9, 0.5, 0.5, 0.5, 0.5, 0.5],
            max_tracking_error_deg: 0.1,
            sim_time_s: 10.0,
            wall_s: Some(0.5),
            ..Default::default()
        }
    }

    #[test]
    fn seeds_and_shards_parse_and_shards_partition_the_batch() {
        use crate::study::{parse_seeds, parse_shard, shard};
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
        let spec = StudySpec::batch(vec!["A".into(), "B".into()], vec![1, 2, 3], 5, true);
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
        let spec = StudySpec::batch(vec!["A".into(), "B".into()], vec![1, 2], 3, false);
        let runs: Vec<StudyRun> = spec
            .jobs()
            .iter()
            .map(|j| StudyRun {
                variant: 0,
                tally: entry(&j.workpiece, j.seed, &[2.0 + j.seed as f64 * 0.1, 2.5]),
            })
            .collect();
        let whole_file = StudyFile::new(spec.clone(), (1, 1), runs.clone());
        let whole = table(&whole_file);
        let file = |k: usize| StudyFile::new(spec.clone(), (k, 2), crate::study::shard(&runs, k, 2));
        let merged = merge(&[("s2".into(), file(2)), ("s1".into(), file(1))]).unwrap();
        // Debug text, not `==`: a column with no values (the first-20 takt here) is NaN on both sides.
        assert_eq!(format!("{:?}", table(&merged)), format!("{whole:?}"));
        assert_eq!(whole[0].takt.count, 4);
        assert_eq!(whole[0].tally.runs, 2);
        assert!((whole[0].takt.mean_s - (2.1 + 2.5 + 2.2 + 2.5) / 4.0).abs() < 1e-12);
        let e = merge(&[("s1".into(), file(1))]).unwrap_err().to_string();
        assert!(
            e.contains("is in none of the shards given"),
            "a missing shard must be refused: {e}"
        );
        let e = merge(&[("s1".into(), file(1)), ("s1b".into(), file(1)), ("s2".into(), file(2))])
            .unwrap_err()
            .to_string();
        assert!(e.contains("is in 2 of the shards given"), "{e}");
        let md = crate::results::table::markdown(&whole);
        assert!(md.contains("| A | 2 | 6/6 | 100.0 % | 2.325 |"), "{md}");
        // Excluding the intervals that span a refill: 2.1 and 2.2.
        assert!((whole[0].takt_excl_refills.mean_s - 2.15).abs() < 1e-12);
        let csv = crate::results::table::csv(&whole);
        assert!(csv.lines().next().unwrap().contains("takt_excl_refills_mean_s"));
        // Written and read back, a file is the same.
        let doc = json!({"batch": whole_file.to_json()});
        assert_eq!(StudyFile::from_json(&doc).unwrap(), whole_file);
    }
}
