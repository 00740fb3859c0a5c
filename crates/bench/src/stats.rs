//! Order statistics of measured samples, one definition for every table: nearest-rank
//! quantiles, NaN where there is no sample (a table shows that no value was measured rather
//! than a made-up zero or a panic).

/// The `q` quantile of `v` by nearest rank (the smallest sample with at least `q` of the
/// samples at or below it); NaN for an empty list.
pub fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    of_sorted(&v, q)
}

/// The `q` quantile by nearest rank of samples already in order; NaN for none.
fn of_sorted(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1]
}

/// The median of `v` (its 0.5 quantile by nearest rank); NaN for an empty list.
pub fn median(v: Vec<f64>) -> f64 {
    percentile(v, 0.5)
}

/// Where a set of timings lies: median, tail and worst, and how many there were.
#[derive(Debug, Clone, Copy)]
pub struct Spread {
    pub p50: f64,
    pub p90: f64,
    pub p99: f64,
    pub max: f64,
    pub count: usize,
}

/// The spread of `v`; every quantile NaN (and `count` 0) for an empty list.
pub fn spread(mut v: Vec<f64>) -> Spread {
    v.sort_by(f64::total_cmp);
    Spread {
        p50: of_sorted(&v, 0.5),
        p90: of_sorted(&v, 0.9),
        p99: of_sorted(&v, 0.99),
        max: of_sorted(&v, 1.0),
        count: v.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_quantiles() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(v.clone(), 0.99), 99.0);
        assert_eq!(percentile(v.clone(), 1.0), 100.0);
        assert_eq!(percentile(v.clone(), 0.0), 1.0);
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), 2.0);
        let s = spread(v);
        assert_eq!(
            (s.p50, s.p90, s.p99, s.max, s.count),
            (50.0, 90.0, 99.0, 100.0, 100)
        );
    }

    #[test]
    fn no_samples_is_nan_everywhere() {
        assert!(median(Vec::new()).is_nan());
        assert!(percentile(Vec::new(), 0.9).is_nan());
        let s = spread(Vec::new());
        assert!(s.p50.is_nan() && s.p99.is_nan() && s.max.is_nan());
        assert_eq!(s.count, 0);
    }
}
