//! Error measures used in reports, examples and tests.

/// Root mean square of a slice (0 for an empty slice).
pub fn rms(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// RMS of a − b.
pub fn rms_difference(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    rms(&d)
}

/// RMS of (a − mean a) − (b − mean b): the error of a map that is identifiable only up to an
/// additive constant (e.g. two blocks feeding the same output).
pub fn centred_rms_difference(a: &[f64], b: &[f64]) -> f64 {
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len().max(1) as f64;
    let (ma, mb) = (mean(a), mean(b));
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| (x - ma) - (y - mb)).collect();
    rms(&d)
}

/// MATLAB-style fit in percent: 100·(1 − ‖y − ŷ‖ / ‖y − mean y‖).
pub fn fit_percent(measured: &[f64], simulated: &[f64]) -> f64 {
    let mean = measured.iter().sum::<f64>() / measured.len().max(1) as f64;
    let num: f64 = measured
        .iter()
        .zip(simulated)
        .map(|(a, b)| (a - b) * (a - b))
        .sum();
    let den: f64 = measured.iter().map(|a| (a - mean) * (a - mean)).sum();
    100.0 * (1.0 - (num / den).sqrt())
}

/// The simulation RMS and fit pooled over the scored samples of several records (or
/// several stretches of one): y and ŷ are added stretch by stretch and the measures are
/// those of all the added samples taken together, as if the stretches were one record.
///
/// The fit is about the mean of the pooled samples, 100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖), not an
/// average of the records' fits: a record with little spread does not swing it.
///
/// ```
/// use structid_core::validation::metrics::{PooledFit, fit_percent, rms_difference};
/// let (y1, s1) = ([1.0, 2.0, 4.0], [1.5, 2.0, 3.0]);
/// let (y2, s2) = ([0.0, -1.0], [0.5, -1.0]);
/// let mut pooled = PooledFit::default();
/// pooled.add(&y1, &s1);
/// pooled.add(&y2, &s2);
/// let (y, s) = ([1.0, 2.0, 4.0, 0.0, -1.0], [1.5, 2.0, 3.0, 0.5, -1.0]);
/// assert!((pooled.rms() - rms_difference(&y, &s)).abs() < 1e-15);
/// assert!((pooled.fit_percent() - fit_percent(&y, &s)).abs() < 1e-12);
/// assert_eq!(pooled.samples(), 5);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PooledFit {
    sse: f64,
    /// The first measured sample: the sums are of y − shift, so that an output far from zero
    /// keeps its spread's precision.
    shift: Option<f64>,
    sum: f64,
    sum_squares: f64,
    samples: usize,
}

impl PooledFit {
    /// Adds the samples of one stretch: measured `y` and simulated `simulated` (pairs up
    /// to the shorter of the two).
    pub fn add(&mut self, y: &[f64], simulated: &[f64]) {
        for (a, b) in y.iter().zip(simulated) {
            let shift = *self.shift.get_or_insert(*a);
            self.sse += (a - b) * (a - b);
            self.sum += a - shift;
            self.sum_squares += (a - shift) * (a - shift);
            self.samples += 1;
        }
    }

    /// Adds the samples of `y` and `simulated` at the index ranges `scored`.
    pub fn add_ranges(&mut self, y: &[f64], simulated: &[f64], scored: &[std::ops::Range<usize>]) {
        for r in scored {
            let end = r.end.min(y.len()).min(simulated.len());
            let start = r.start.min(end);
            self.add(&y[start..end], &simulated[start..end]);
        }
    }

    /// The number of samples added.
    pub fn samples(&self) -> usize {
        self.samples
    }

    /// Σ(y − ŷ)² over the samples added.
    pub fn sum_squared_error(&self) -> f64 {
        self.sse
    }

    /// The RMS of y − ŷ over the samples added (NaN when none were).
    pub fn rms(&self) -> f64 {
        if self.samples == 0 {
            return f64::NAN;
        }
        (self.sse / self.samples as f64).sqrt()
    }

    /// The fit 100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖) over the samples added, ȳ their mean (NaN when
    /// y does not vary).
    pub fn fit_percent(&self) -> f64 {
        let n = self.samples.max(1) as f64;
        // Sums about the first sample keep the spread of an output far from zero; rounding
        // can still leave it a hair below zero, so it is clamped.
        let spread = (self.sum_squares - self.sum * self.sum / n).max(0.0);
        if spread > 0.0 {
            100.0 * (1.0 - (self.sse / spread).sqrt())
        } else {
            f64::NAN
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Property: pooling stretches equals the measures of their concatenation, whatever
        /// the split.
        #[test]
        fn pooling_any_split_equals_the_concatenation(
            y in proptest::collection::vec(-5.0f64..5.0, 3..60),
            noise in proptest::collection::vec(-1.0f64..1.0, 60),
            cut in 0usize..60,
        ) {
            let s: Vec<f64> = y.iter().zip(&noise).map(|(a, e)| a + e).collect();
            let cut = cut.min(y.len());
            let mut pooled = PooledFit::default();
            let (first, second) = (0..cut, cut..y.len());
            pooled.add(&y[first.clone()], &s[first]);
            pooled.add_ranges(&y, &s, std::slice::from_ref(&second));
            prop_assert_eq!(pooled.samples(), y.len());
            prop_assert!((pooled.rms() - rms_difference(&y, &s)).abs() <= 1e-12 * (1.0 + pooled.rms()));
            let fit = fit_percent(&y, &s);
            if fit.is_finite() && fit > -1e6 {
                prop_assert!((pooled.fit_percent() - fit).abs() <= 1e-8 * (1.0 + fit.abs()));
            }
        }
    }

    /// An output riding on a large offset: the pooled fit equals the two-pass fit about the
    /// mean (raw sums would lose every digit of the spread).
    #[test]
    fn a_large_offset_keeps_the_fit() {
        let y: Vec<f64> = (0..200).map(|k| 1e9 + (k as f64 * 0.1).sin()).collect();
        let s: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(k, v)| v + 0.1 * (k as f64 * 0.37).cos())
            .collect();
        let mut pooled = PooledFit::default();
        pooled.add(&y[..80], &s[..80]);
        pooled.add(&y[80..], &s[80..]);
        assert!((pooled.fit_percent() - fit_percent(&y, &s)).abs() < 1e-6);
    }

    #[test]
    fn pooled_measures_by_hand() {
        let y = [1.0, 2.0, 3.0, 4.0];
        let s = [1.0, 2.0, 3.0, 2.0];
        let mut pooled = PooledFit::default();
        pooled.add_ranges(&y, &s, &[0..2, 2..4]);
        // Σ(y − ŷ)² = 4 over 4 samples; ȳ = 2.5, Σ(y − ȳ)² = 5.
        assert!((pooled.rms() - 1.0).abs() < 1e-12);
        assert!((pooled.fit_percent() - 100.0 * (1.0 - (4.0f64 / 5.0).sqrt())).abs() < 1e-12);
    }

    #[test]
    fn an_empty_or_flat_pool_says_so() {
        let empty = PooledFit::default();
        assert!(empty.rms().is_nan() && empty.samples() == 0);
        let mut flat = PooledFit::default();
        flat.add(&[2.0, 2.0], &[1.0, 3.0]);
        assert!((flat.rms() - 1.0).abs() < 1e-15);
        assert!(flat.fit_percent().is_nan());
    }

    #[test]
    fn centred_difference_ignores_constant_offsets() {
        let a = [1.0, 2.0, 4.0];
        let b = [11.0, 12.0, 14.0];
        assert!(centred_rms_difference(&a, &b) < 1e-15);
        assert!((rms_difference(&a, &b) - 10.0).abs() < 1e-12);
    }

    #[test]
    fn fit_is_100_for_perfect_and_0_for_mean() {
        let y = [1.0, 3.0, 2.0, 6.0];
        assert!((fit_percent(&y, &y) - 100.0).abs() < 1e-12);
        assert!(fit_percent(&y, &[3.0; 4]).abs() < 1e-12);
    }
}
