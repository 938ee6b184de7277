//! Nonparametric best linear approximation (BLA) from periodic data.

use nalgebra::Complex;

use crate::error::{LinearError, check_finite, check_sample_time};

type C64 = Complex<f64>;

/// A measured frequency response at the excited DFT bins.
///
/// ```
/// use structid_linear::FrequencyResponse;
/// let f = FrequencyResponse { frequencies: vec![0.1], g: vec![(1.0, 0.0)], std: vec![0.01], periods: 4 };
/// assert_eq!(f.magnitude(), vec![1.0]);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct FrequencyResponse {
    /// Frequencies of the bins: Hz if the sample time is known, else cycles per sample.
    pub frequencies: Vec<f64>,
    /// `G(e^{jω})` as `(re, im)`.
    pub g: Vec<(f64, f64)>,
    /// Standard deviation of each `G` (circular complex: `E|Ĝ − G|²` = std²), estimated
    /// from the spread over the periods; `NaN` when only one period is used.
    pub std: Vec<f64>,
    /// Number of periods averaged.
    pub periods: usize,
}

impl FrequencyResponse {
    /// `|G|` at every bin.
    ///
    /// ```
    /// use structid_linear::FrequencyResponse;
    /// let f = FrequencyResponse { frequencies: vec![0.1], g: vec![(3.0, 4.0)], std: vec![f64::NAN], periods: 1 };
    /// assert_eq!(f.magnitude(), vec![5.0]);
    /// ```
    pub fn magnitude(&self) -> Vec<f64> {
        self.g.iter().map(|(r, i)| r.hypot(*i)).collect()
    }
}

/// Nonparametric BLA `G = Ȳ/Ū` from a periodic excitation (e.g. a multisine).
///
/// The record (`u`, `y` of equal length) is cut into periods of `period` samples; the first
/// `skip_periods` are dropped (transient), the DFTs `U_m(k)`, `Y_m(k)` of the remaining `P`
/// periods are averaged, and `G(k) = Ȳ(k)/Ū(k)` is returned at the excited bins
/// `k = 0 … period/2` (those with `|Ū(k)| > 1e-6 max_k |Ū(k)|`). The standard deviation
/// comes from the sample (co)variances of `Y_m`, `U_m` over the periods:
/// `var Ĝ = (σ²_Ȳ + |G|² σ²_Ū − 2 Re(Ḡ σ²_ȲŪ)) / |Ū|²`, which shrinks as `1/√P`.
///
/// ```
/// use structid_linear::bla_periodic;
/// // y_k = 0.5 u_{k-1} on a periodic input: G = 0.5 e^{-jω}
/// let period = 16;
/// let u: Vec<f64> = (0..4 * period).map(|k| (2.0 * std::f64::consts::PI * 3.0 * k as f64 / period as f64).cos()).collect();
/// let y: Vec<f64> = (0..u.len()).map(|k| 0.5 * u[(k + u.len() - 1) % u.len()]).collect();
/// let f = bla_periodic(&u, &y, period, 1, None).unwrap();
/// assert_eq!(f.frequencies, vec![3.0 / 16.0]);
/// let w = 2.0 * std::f64::consts::PI * 3.0 / 16.0;
/// assert!((f.g[0].0 - 0.5 * w.cos()).abs() < 1e-12 && (f.g[0].1 + 0.5 * w.sin()).abs() < 1e-12);
/// assert_eq!(f.periods, 3);
/// ```
pub fn bla_periodic(
    u: &[f64],
    y: &[f64],
    period: usize,
    skip_periods: usize,
    sample_time: Option<f64>,
) -> Result<FrequencyResponse, LinearError> {
    check_sample_time(sample_time)?;
    if u.len() != y.len() {
        return Err(LinearError::LengthMismatch {
            input: u.len(),
            output: y.len(),
        });
    }
    check_finite("input", u, 1)?;
    check_finite("output", y, 1)?;
    if period < 2 {
        return Err(LinearError::param(
            "period",
            format!("must be at least 2 samples, got {period}"),
        ));
    }
    if u.is_empty() || !u.len().is_multiple_of(period) {
        return Err(LinearError::PeriodMismatch {
            len: u.len(),
            period,
        });
    }
    let total = u.len() / period;
    if total <= skip_periods {
        return Err(LinearError::TooFewSamples {
            what: format!("a BLA that skips {skip_periods} periods of {period} samples"),
            needed: (skip_periods + 1) * period,
            available: u.len(),
        });
    }
    let p = total - skip_periods;
    let dft = Dft::new(period);
    let bins = period / 2 + 1;
    let (mut us, mut ys) = (Vec::with_capacity(p), Vec::with_capacity(p));
    for m in skip_periods..total {
        let r = m * period..(m + 1) * period;
        us.push(dft.half_spectrum(&u[r.clone()]));
        ys.push(dft.half_spectrum(&y[r]));
    }
    let mean = |s: &[Vec<C64>], k: usize| s.iter().map(|v| v[k]).sum::<C64>() / p as f64;
    let ubar: Vec<C64> = (0..bins).map(|k| mean(&us, k)).collect();
    let umax = ubar.iter().map(|z| z.norm()).fold(0.0, f64::max);
    let mut out = FrequencyResponse {
        frequencies: Vec::new(),
        g: Vec::new(),
        std: Vec::new(),
        periods: p,
    };
    if umax == 0.0 {
        return Err(LinearError::param(
            "u",
            "the input is zero after the skipped periods: no bin is excited",
        ));
    }
    let unit = match sample_time {
        Some(ts) => 1.0 / (period as f64 * ts),
        None => 1.0 / period as f64,
    };
    for k in 0..bins {
        let ub = ubar[k];
        if ub.norm() <= 1e-6 * umax {
            continue;
        }
        let yb = mean(&ys, k);
        let g = yb / ub;
        let std = if p < 2 {
            f64::NAN
        } else {
            let (mut vy, mut vu, mut vyu) = (0.0, 0.0, C64::new(0.0, 0.0));
            for m in 0..p {
                let dy = ys[m][k] - yb;
                let du = us[m][k] - ub;
                vy += dy.norm_sqr();
                vu += du.norm_sqr();
                vyu += dy * du.conj();
            }
            let c = 1.0 / (p * (p - 1)) as f64;
            let var = c * (vy + g.norm_sqr() * vu - 2.0 * (g.conj() * vyu).re) / ub.norm_sqr();
            var.max(0.0).sqrt()
        };
        out.frequencies.push(k as f64 * unit);
        out.g.push((g.re, g.im));
        out.std.push(std);
    }
    Ok(out)
}

/// A planned DFT of length `n`: radix-2 FFT when `n` is a power of two, Bluestein's chirp-z
/// algorithm (on a power-of-two FFT) otherwise.
struct Dft {
    n: usize,
    fft: Fft,
    /// Bluestein: chirp `w_j = e^{−iπ j²/n}` and the FFT of the conjugate chirp filter.
    chirp: Option<(Vec<C64>, Vec<C64>)>,
}

impl Dft {
    fn new(n: usize) -> Self {
        if n.is_power_of_two() {
            return Dft {
                n,
                fft: Fft::new(n),
                chirp: None,
            };
        }
        let m = (2 * n - 1).next_power_of_two();
        let fft = Fft::new(m);
        let w: Vec<C64> = (0..n)
            .map(|j| {
                let r = ((j as u128 * j as u128) % (2 * n as u128)) as f64;
                C64::from_polar(1.0, -std::f64::consts::PI * r / n as f64)
            })
            .collect();
        let mut b = vec![C64::new(0.0, 0.0); m];
        b[0] = w[0].conj();
        for j in 1..n {
            b[j] = w[j].conj();
            b[m - j] = w[j].conj();
        }
        fft.forward(&mut b);
        Dft {
            n,
            fft,
            chirp: Some((w, b)),
        }
    }

    /// DFT bins `0 … n/2` of a real sequence of length `n`.
    fn half_spectrum(&self, x: &[f64]) -> Vec<C64> {
        let bins = self.n / 2 + 1;
        match &self.chirp {
            None => {
                let mut a: Vec<C64> = x.iter().map(|&v| C64::new(v, 0.0)).collect();
                self.fft.forward(&mut a);
                a.truncate(bins);
                a
            }
            Some((w, fb)) => {
                let m = fb.len();
                let mut a = vec![C64::new(0.0, 0.0); m];
                for j in 0..self.n {
                    a[j] = w[j] * x[j];
                }
                self.fft.forward(&mut a);
                for (aj, bj) in a.iter_mut().zip(fb) {
                    *aj = (*aj * bj).conj();
                }
                self.fft.forward(&mut a); // conj(FFT(conj(·))) / m is the inverse
                (0..bins).map(|k| w[k] * a[k].conj() / m as f64).collect()
            }
        }
    }
}

/// Iterative radix-2 FFT of a fixed power-of-two length.
struct Fft {
    n: usize,
    twiddles: Vec<C64>,
}

impl Fft {
    fn new(n: usize) -> Self {
        debug_assert!(n.is_power_of_two());
        let twiddles = (0..n / 2)
            .map(|k| C64::from_polar(1.0, -2.0 * std::f64::consts::PI * k as f64 / n as f64))
            .collect();
        Fft { n, twiddles }
    }

    fn forward(&self, a: &mut [C64]) {
        let n = self.n;
        debug_assert_eq!(a.len(), n);
        if n <= 1 {
            return;
        }
        let bits = n.trailing_zeros();
        for i in 0..n {
            let j = i.reverse_bits() >> (usize::BITS - bits);
            if j > i {
                a.swap(i, j);
            }
        }
        let mut len = 2;
        while len <= n {
            let step = n / len;
            for start in (0..n).step_by(len) {
                for k in 0..len / 2 {
                    let t = a[start + k + len / 2] * self.twiddles[k * step];
                    let s = a[start + k];
                    a[start + k] = s + t;
                    a[start + k + len / 2] = s - t;
                }
            }
            len *= 2;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::polynomial::PolynomialModel;
    use crate::testutil::*;
    use structid_lti::Signal;

    fn naive(x: &[f64]) -> Vec<C64> {
        let n = x.len();
        (0..=n / 2)
            .map(|k| {
                x.iter()
                    .enumerate()
                    .map(|(j, &v)| {
                        v * C64::from_polar(
                            1.0,
                            -2.0 * std::f64::consts::PI * ((k * j) % n) as f64 / n as f64,
                        )
                    })
                    .sum()
            })
            .collect()
    }

    #[test]
    fn dft_matches_naive_for_any_length() {
        for n in [2usize, 3, 8, 12, 17, 64, 100, 255] {
            let x: Vec<f64> = (0..n).map(|k| ((k * k + 3) as f64 * 0.7).sin()).collect();
            let fast = Dft::new(n).half_spectrum(&x);
            let slow = naive(&x);
            for (a, b) in fast.iter().zip(&slow) {
                assert!((a - b).norm() < 1e-11 * n as f64, "n = {n}: {a} vs {b}");
            }
        }
    }

    /// Random-phase multisine exciting bins `1..=excited` of a period of `period` samples.
    fn multisine(seed: u64, period: usize, excited: usize, periods: usize) -> Vec<f64> {
        let phases = white(seed, excited, 1.0, 1);
        (0..period * periods)
            .map(|t| {
                (1..=excited)
                    .map(|k| {
                        (2.0 * std::f64::consts::PI * (k * t % period) as f64 / period as f64
                            + 3.0 * phases.get(k - 1, 0))
                        .cos()
                    })
                    .sum::<f64>()
                    / (excited as f64).sqrt()
            })
            .collect()
    }

    fn system() -> PolynomialModel {
        PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None).unwrap()
    }

    #[test]
    fn exact_frf_without_noise() {
        for period in [256usize, 200] {
            let g = system();
            let u = multisine(61, period, 60, 6);
            let y = g.simulate(&Signal::new(1, u.clone()).unwrap()).unwrap();
            let f = bla_periodic(&u, &y, period, 2, Some(0.01)).unwrap();
            assert_eq!(f.periods, 4);
            assert_eq!(f.frequencies.len(), 60);
            for ((freq, (re, im)), s) in f.frequencies.iter().zip(&f.g).zip(&f.std) {
                let (tr, ti) = g.frequency_response(0, freq * 0.01).unwrap();
                assert!((re - tr).abs() < 1e-6 && (im - ti).abs() < 1e-6, "{freq}");
                assert!(*s < 1e-9);
            }
            assert!((f.frequencies[0] - 1.0 / (period as f64 * 0.01)).abs() < 1e-12);
        }
    }

    #[test]
    fn std_shrinks_with_periods() {
        let g = system();
        let period = 128;
        let u = multisine(62, period, 40, 34);
        let y0 = g.simulate(&Signal::new(1, u.clone()).unwrap()).unwrap();
        let e = white(63, y0.len(), 0.2, 1);
        let y: Vec<f64> = y0.iter().zip(e.as_slice()).map(|(a, b)| a + b).collect();
        let mean_std = |periods: usize| {
            let len = (2 + periods) * period;
            let f = bla_periodic(&u[..len], &y[..len], period, 2, None).unwrap();
            assert_eq!(f.periods, periods);
            f.std.iter().sum::<f64>() / f.std.len() as f64
        };
        let (s4, s16) = (mean_std(4), mean_std(16));
        let ratio = s4 / s16;
        assert!(
            (1.5..2.7).contains(&ratio),
            "std ratio {ratio} (expected about 2)"
        );
        // the estimate is within a few std of the truth
        let f = bla_periodic(&u, &y, period, 2, None).unwrap();
        let mut outside = 0;
        for ((freq, (re, im)), s) in f.frequencies.iter().zip(&f.g).zip(&f.std) {
            let (tr, ti) = g.frequency_response(0, *freq).unwrap();
            if (re - tr).hypot(im - ti) > 3.0 * s {
                outside += 1;
            }
        }
        assert!(outside <= 2, "{outside} bins outside 3 std");
        // one period: no spread estimate
        let f1 = bla_periodic(&u[..3 * period], &y[..3 * period], period, 2, None).unwrap();
        assert!(f1.std.iter().all(|s| s.is_nan()));
    }

    #[test]
    fn errors() {
        let u = vec![1.0; 100];
        assert!(matches!(
            bla_periodic(&u, &u, 30, 0, None),
            Err(LinearError::PeriodMismatch {
                len: 100,
                period: 30
            })
        ));
        assert!(matches!(
            bla_periodic(&u, &u[..50], 10, 0, None),
            Err(LinearError::LengthMismatch { .. })
        ));
        assert!(matches!(
            bla_periodic(&u, &u, 10, 10, None),
            Err(LinearError::TooFewSamples { .. })
        ));
        let mut bad = u.clone();
        bad[42] = f64::NAN;
        assert!(matches!(
            bla_periodic(&u, &bad, 10, 0, None),
            Err(LinearError::NonFinite { sample: 42, .. })
        ));
        assert!(bla_periodic(&u, &u, 10, 0, Some(-1.0)).is_err());
        assert!(bla_periodic(&[0.0; 20], &u[..20], 10, 0, None).is_err());
    }
}
