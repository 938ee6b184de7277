//! Residual analysis: is what the model leaves unexplained white, and independent of the input?
//!
//! As in MATLAB's `resid` and the usual system-identification practice (Ljung, *System
//! Identification*, §16.6), with ε the residual and u an input over N samples:
//!
//! ```text
//! R_ε(τ)  = (1/N)·Σ_t ε(t)·ε(t−τ) / R_ε(0)                          (whiteness)
//! R_εu(τ) = (1/N)·Σ_t ε(t)·u(t−τ) / √(R_ε(0)·R_u(0))                  (independence of u)
//! ```
//!
//! with means removed first. Under the null hypothesis (ε white and independent of u) each
//! normalised correlation at a non-zero lag is approximately N(0, 1/N), so the 99 % band is
//! ±2.576/√N. A positive lag τ in R_εu pairs ε with *past* inputs; correlation at negative lags
//! points to feedback from ε to u.
//!
//! The band is drawn per lag, but the verdict is one test over all lags at the 1 % level: with
//! 25 lags in a 99 % band, one of them falls outside a fourth of the time for a white residual.
//! The portmanteau statistics are, over the m tested lags,
//!
//! ```text
//! Q_ε  = N·(N + 2)·Σ_(τ=1..m) R_ε(τ)²/(N − τ)      (Ljung–Box, whiteness)
//! ζ_εu = N·rᵀ·P⁺·r,  r = [R_εu(−m) … R_εu(m)]       (Ljung, independence of u)
//! ```
//!
//! with P the Toeplitz matrix of the input's own autocorrelation (the cross-correlations of a
//! white ε with a coloured u are correlated across lags through it). Under the null hypothesis
//! each is approximately χ² (m, and rank P, degrees of freedom); a test passes when its
//! statistic is below the χ² quantile at 0.99.

use crate::validation::distributions::chi_square_quantile;

/// Two-sided 99 % quantile of the standard normal distribution.
pub const Z_99: f64 = 2.575_829_303_548_901;

/// Normalised correlations over a range of lags with their 99 % band.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CorrelationTest {
    /// The lags τ, ascending.
    pub lags: Vec<isize>,
    /// The normalised correlation at each lag.
    pub values: Vec<f64>,
    /// The half-width of the 99 % band, 2.576/√N.
    pub bound: f64,
    /// Whether this is an autocorrelation (whose lag 0 is 1 by definition and not a test).
    pub autocorrelation: bool,
    /// The portmanteau statistic over the tested lags (Ljung–Box for an autocorrelation,
    /// Ljung's ζ with the input's autocorrelation for a cross-correlation; see the
    /// [module docs](self)).
    pub statistic: f64,
    /// The χ² quantile at 0.99 with the statistic's degrees of freedom.
    pub critical: f64,
}

impl CorrelationTest {
    /// The lags whose correlation lies outside the band (lag 0 of an autocorrelation, which is
    /// 1 by definition, is never counted).
    pub fn outside(&self) -> Vec<isize> {
        self.lags
            .iter()
            .zip(&self.values)
            .filter(|(l, v)| !(self.autocorrelation && **l == 0) && v.abs() > self.bound)
            .map(|(l, _)| *l)
            .collect()
    }

    /// Number of lags tested (an autocorrelation's positive lags; every lag of a
    /// cross-correlation).
    pub fn tested(&self) -> usize {
        if self.autocorrelation {
            self.lags.iter().filter(|&&l| l > 0).count()
        } else {
            self.lags.len()
        }
    }

    /// Whether the portmanteau statistic stays below its 1 % critical value: the residual shows
    /// no correlation over the tested lags taken together.
    pub fn passes(&self) -> bool {
        // Not "statistic ≤ critical": a statistic that could not be computed (NaN) is no
        // evidence of correlation.
        self.statistic.partial_cmp(&self.critical) != Some(std::cmp::Ordering::Greater)
    }
}

/// The Ljung–Box statistic of the autocorrelations `values` at `lags` over `n` samples, and
/// its critical value.
fn ljung_box(lags: &[isize], values: &[f64], n: usize) -> (f64, f64) {
    let nf = n as f64;
    let (mut q, mut df) = (0.0, 0usize);
    for (&l, &r) in lags.iter().zip(values) {
        if l > 0 && (l as usize) < n {
            q += r * r / (nf - l as f64);
            df += 1;
        }
    }
    (nf * (nf + 2.0) * q, chi_square_quantile(0.99, df.max(1)))
}

fn centred(x: &[f64]) -> Vec<f64> {
    let mean = x.iter().sum::<f64>() / x.len().max(1) as f64;
    x.iter().map(|v| v - mean).collect()
}

/// (1/N)·Σ_t a(t)·b(t−τ) over the overlap, for centred a and b.
fn covariance(a: &[f64], b: &[f64], tau: isize) -> f64 {
    let n = a.len();
    let s: f64 = if tau >= 0 {
        let t0 = tau as usize;
        (t0..n).map(|t| a[t] * b[t - t0]).sum()
    } else {
        let t0 = (-tau) as usize;
        (0..n.saturating_sub(t0)).map(|t| a[t] * b[t + t0]).sum()
    };
    s / n as f64
}

/// The autocorrelation test of `residual` at lags −max_lag…max_lag.
///
/// ```
/// use structid_core::validation::residual_tests::autocorrelation;
/// let e: Vec<f64> = (0..400).map(|k| if k % 2 == 0 { 1.0 } else { -1.0 }).collect();
/// let t = autocorrelation(&e, 3);
/// assert!((t.values[4] + 1.0).abs() < 0.01); // lag 1 of an alternating sign: about −1
/// assert!(!t.passes());
/// ```
pub fn autocorrelation(residual: &[f64], max_lag: usize) -> CorrelationTest {
    let e = centred(residual);
    let r0 = covariance(&e, &e, 0);
    let lags: Vec<isize> = (-(max_lag as isize)..=max_lag as isize).collect();
    let values: Vec<f64> = lags
        .iter()
        .map(|&l| {
            if l == 0 {
                1.0
            } else if r0 > 0.0 {
                covariance(&e, &e, l) / r0
            } else {
                0.0
            }
        })
        .collect();
    let (statistic, critical) = ljung_box(&lags, &values, e.len());
    CorrelationTest {
        lags,
        values,
        bound: Z_99 / (e.len().max(1) as f64).sqrt(),
        autocorrelation: true,
        statistic,
        critical,
    }
}

/// The cross-correlation test of `residual` with `input` at lags −max_lag…max_lag
/// (`residual` and `input` of equal length).
pub fn cross_correlation(residual: &[f64], input: &[f64], max_lag: usize) -> CorrelationTest {
    let n = residual.len().min(input.len());
    let (e, u) = (centred(&residual[..n]), centred(&input[..n]));
    let scale = (covariance(&e, &e, 0) * covariance(&u, &u, 0)).sqrt();
    let lags: Vec<isize> = (-(max_lag as isize)..=max_lag as isize).collect();
    let values: Vec<f64> = lags
        .iter()
        .map(|&l| {
            if scale > 0.0 {
                covariance(&e, &u, l) / scale
            } else {
                0.0
            }
        })
        .collect();
    let (statistic, critical) = input_portmanteau(&values, &u, max_lag);
    CorrelationTest {
        lags,
        values,
        bound: Z_99 / (n.max(1) as f64).sqrt(),
        autocorrelation: false,
        statistic,
        critical,
    }
}

/// Ljung's statistic of the cross-correlations `r` at lags −m…m with the centred input `u`:
/// ζ = N·rᵀP⁺r, P the Toeplitz matrix of u's autocorrelation ρ_u(τ_i − τ_j). For ε white and
/// independent of u, r is about N(0, P/N), so ζ is χ² with rank P degrees of freedom whatever
/// u's colour (a sum of squared r, correct for a white u only, fails coloured inputs far more
/// often than its level). P⁺ keeps the eigenvalues above 10⁻⁸ of the largest: a sinusoidal
/// input correlates only a few directions of r.
fn input_portmanteau(r: &[f64], u: &[f64], m: usize) -> (f64, f64) {
    let n = u.len();
    let r0 = covariance(u, u, 0);
    if n == 0 || r0 <= 0.0 {
        return (0.0, chi_square_quantile(0.99, 1));
    }
    let rho: Vec<f64> = (0..=2 * m)
        .map(|t| {
            if t < n {
                covariance(u, u, t as isize) / r0
            } else {
                0.0
            }
        })
        .collect();
    let k = r.len();
    let p = nalgebra::DMatrix::from_fn(k, k, |i, j| rho[i.abs_diff(j)]);
    let eig = p.symmetric_eigen();
    let largest = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let rv = nalgebra::DVector::from_column_slice(r);
    let (mut zeta, mut rank) = (0.0, 0usize);
    for (i, &l) in eig.eigenvalues.iter().enumerate() {
        if l > 1e-8 * largest {
            let proj = eig.eigenvectors.column(i).dot(&rv);
            zeta += proj * proj / l;
            rank += 1;
        }
    }
    (n as f64 * zeta, chi_square_quantile(0.99, rank.max(1)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_lti::testing::SplitMix64;

    fn white(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = SplitMix64::new(seed);
        (0..n)
            .map(|_| {
                let (a, b) = (rng.uniform().max(1e-300), rng.uniform());
                (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
            })
            .collect()
    }

    #[test]
    fn white_noise_stays_inside_the_band_about_99_percent_of_the_time() {
        // 40 records × 50 non-zero lags = 2000 tests at the 1 % level: expect about 20 outside.
        let mut outside = 0;
        for seed in 0..40 {
            outside += autocorrelation(&white(2000, seed), 25).outside().len();
        }
        assert!(
            outside <= 50,
            "{outside} of 2000 lags outside the 99 % band"
        );
    }

    #[test]
    fn the_portmanteau_tests_keep_their_one_percent_level_where_single_lags_would_not() {
        // 200 white records, 25 lags each: a lag outside the 99 % band in about a fifth of
        // them, the Ljung–Box test failing in about 1 %.
        let (mut any_lag, mut failed) = (0, 0);
        for seed in 100..300 {
            let t = autocorrelation(&white(2000, seed), 25);
            any_lag += usize::from(!t.outside().is_empty());
            failed += usize::from(!t.passes());
        }
        assert!(any_lag > 20, "{any_lag} of 200 with a lag outside");
        assert!(failed <= 8, "{failed} of 200 failed the Ljung–Box test");
        // The statistic is Ljung–Box's, summed here by hand.
        let e = white(300, 7);
        let t = autocorrelation(&e, 4);
        let q: f64 = (1..=4)
            .map(|l| {
                let r = t.values[t.lags.iter().position(|&x| x == l).unwrap()];
                r * r / (300.0 - l as f64)
            })
            .sum::<f64>()
            * 300.0
            * 302.0;
        assert!((t.statistic - q).abs() < 1e-9 * q, "{} vs {q}", t.statistic);
    }

    #[test]
    fn the_input_test_keeps_its_level_for_a_coloured_input_and_finds_a_leak() {
        // u = AR(0.95), ε white and independent: a plain sum of squared cross-correlations
        // fails this a sixth of the time; Ljung's form, about 1 %.
        let mut failed = 0;
        for seed in 0..100 {
            let v = white(2000, 500 + seed);
            let mut u = vec![0.0; 2000];
            for k in 1..2000 {
                u[k] = 0.95 * u[k - 1] + v[k];
            }
            failed += usize::from(!cross_correlation(&white(2000, 900 + seed), &u, 25).passes());
        }
        assert!(failed <= 6, "{failed} of 100 failed");
        // A leak of the input three samples back is found.
        let u = white(4000, 5);
        let v = white(4000, 6);
        let e: Vec<f64> = (0..4000)
            .map(|t| v[t] + if t >= 3 { 0.2 * u[t - 3] } else { 0.0 })
            .collect();
        assert!(!cross_correlation(&e, &u, 10).passes());
    }

    #[test]
    fn an_ar1_residual_is_detected_with_its_coefficient() {
        let v = white(5000, 3);
        let mut e = vec![0.0; 5000];
        for k in 1..5000 {
            e[k] = 0.6 * e[k - 1] + v[k];
        }
        let t = autocorrelation(&e, 5);
        let lag1 = t.values[t.lags.iter().position(|&l| l == 1).unwrap()];
        assert!((lag1 - 0.6).abs() < 0.05, "{lag1}");
        // Symmetric in the lag.
        assert_eq!(
            lag1,
            t.values[t.lags.iter().position(|&l| l == -1).unwrap()]
        );
        assert!(!t.passes());
    }

    #[test]
    fn cross_correlation_finds_the_delay_of_an_input_leak() {
        // ε(t) = 0.5·u(t − 3) + noise: correlated with the input three samples back.
        let u = white(4000, 5);
        let v = white(4000, 6);
        let e: Vec<f64> = (0..4000)
            .map(|t| v[t] + if t >= 3 { 0.5 * u[t - 3] } else { 0.0 })
            .collect();
        let t = cross_correlation(&e, &u, 10);
        assert_eq!(t.outside(), vec![3]);
        let independent = cross_correlation(&v, &u, 10);
        assert!(independent.outside().len() <= 1);
    }

    #[test]
    fn degenerate_inputs_do_not_panic() {
        assert!(autocorrelation(&[], 3).values.iter().all(|v| v.is_finite()));
        assert!(autocorrelation(&[1.0; 10], 3).passes());
        assert!(cross_correlation(&[1.0, 2.0], &[0.0, 0.0], 5).passes());
    }
}
