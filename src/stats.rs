//! Statistics over samples, defined once: mean, median, nearest-rank percentiles, min and max,
//! for the takt tables, the run summaries and the benchmarks.
//!
//! Units: whatever the samples carry. Empty input gives NaN (a table shows it as "-"). Sums run
//! in the order given, so a caller that needs a fixed result order passes a fixed sample order.

use serde::{Deserialize, Serialize};

/// Arithmetic mean, summed in the order given (NaN when empty).
pub fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        f64::NAN
    } else {
        values.iter().sum::<f64>() / values.len() as f64
    }
}

/// Arithmetic mean of an iterator, summed in its order (NaN when empty).
pub fn mean_of(values: impl IntoIterator<Item = f64>) -> f64 {
    let (sum, n) = values.into_iter().fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

/// The values sorted ascending (total order: NaNs last).
pub fn sorted(values: &[f64]) -> Vec<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v
}

/// Nearest-rank percentile `p` (0 < p <= 1) of ascending `sorted` values: the smallest value with
/// at least a fraction `p` of the samples at or below it (NaN when empty).
pub fn percentile_sorted(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() as f64 * p).ceil() as usize).saturating_sub(1)]
}

/// Median of ascending `sorted` values: the upper middle one for an even count (NaN when empty).
pub fn median_sorted(sorted: &[f64]) -> f64 {
    sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Median, minimum and maximum (NaN when empty).
pub fn median_min_max(values: &[f64]) -> (f64, f64, f64) {
    let v = sorted(values);
    match (v.first(), v.last()) {
        (Some(lo), Some(hi)) => (median_sorted(&v), *lo, *hi),
        _ => (f64::NAN, f64::NAN, f64::NAN),
    }
}

/// Count, mean, 95th percentile (nearest rank), minimum and maximum of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// How many values.
    pub count: usize,
    /// Mean (of the values in ascending order).
    pub mean_s: f64,
    /// 95th percentile (nearest rank).
    pub p95_s: f64,
    /// Minimum.
    pub min_s: f64,
    /// Maximum.
    pub max_s: f64,
}

impl Summary {
    /// From a sample of durations (s) (NaN statistics when empty).
    pub fn of(values: &[f64]) -> Self {
        let v = sorted(values);
        Summary {
            count: v.len(),
            mean_s: mean(&v),
            p95_s: percentile_sorted(&v, 0.95),
            min_s: v.first().copied().unwrap_or(f64::NAN),
            max_s: v.last().copied().unwrap_or(f64::NAN),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_of_small_samples() {
        assert!(mean(&[]).is_nan());
        assert_eq!(mean(&[1.0, 2.0, 6.0]), 3.0);
        assert_eq!(mean_of([1.0, 2.0, 6.0]), 3.0);
        let s = Summary::of(&[5.0, 1.0, 3.0, 2.0, 4.0]);
        assert_eq!((s.count, s.mean_s, s.min_s, s.max_s), (5, 3.0, 1.0, 5.0));
        // Nearest rank: ceil(0.95 * 5) = 5th value.
        assert_eq!(s.p95_s, 5.0);
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile_sorted(&v, 0.95), 95.0);
        assert_eq!(median_min_max(&[3.0, 1.0, 2.0, 4.0]), (3.0, 1.0, 4.0));
        assert!(Summary::of(&[]).mean_s.is_nan());
    }
}
