//! Where a model and the measurements disagree: in time, and in operating space.
//!
//! Given the simulation residual ε_k = y_k − ŷ_k of a model and its noise level σ:
//!
//! * [`exceedance_windows`]: the time windows where the moving RMS of ε over `window` samples
//!   exceeds `factor`·σ (merged when they touch);
//! * [`operating_regions`]: for each candidate signal s (the input, the output, their rates,
//!   internal signals of the model), the one-sided region {s > t}, {s < t}, {|s| > t} or
//!   {|s| < t} where the residual energy concentrates most: the one with the largest excess
//!   energy share − sample share (the region's share of Σε² minus its share of the samples).
//!   Its **lift** is the ratio of the two (1 means no concentration); regions must hold at
//!   least `min_share` of the samples. The candidates are ranked by the correlation ratio
//!   η² of ε² on quantile bins of s: the fraction of the variance of ε² that the bins of s
//!   explain;
//! * [`binned_residual`]: the mean and RMS of ε in quantile bins of a signal, for plots.

use std::ops::Range;

/// Time windows where the moving RMS of `residual` over `window` samples exceeds
/// `factor`·`noise_std`, merged when they overlap or touch.
///
/// ```
/// use structid_discover::localise::exceedance_windows;
/// let mut e = vec![0.01; 1000];
/// for v in &mut e[400..500] { *v = 1.0; }
/// let w = exceedance_windows(&e, 0.01, 3.0, 20);
/// assert_eq!(w.len(), 1);
/// assert!(w[0].start >= 380 && w[0].end <= 520);
/// ```
pub fn exceedance_windows(
    residual: &[f64],
    noise_std: f64,
    factor: f64,
    window: usize,
) -> Vec<Range<usize>> {
    let n = residual.len();
    let window = window.clamp(1, n.max(1));
    if n == 0 || !(noise_std.is_finite() && noise_std >= 0.0) {
        return Vec::new();
    }
    let limit = (factor * noise_std).powi(2) * window as f64;
    let mut out: Vec<Range<usize>> = Vec::new();
    let mut sum: f64 = residual[..window].iter().map(|v| v * v).sum();
    for start in 0..=(n - window) {
        if start > 0 {
            sum += residual[start + window - 1].powi(2) - residual[start - 1].powi(2);
        }
        if sum > limit {
            let r = start..start + window;
            match out.last_mut() {
                Some(last) if last.end >= r.start => last.end = r.end,
                _ => out.push(r),
            }
        }
    }
    out
}

/// Which side of a threshold a region is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Side {
    /// s > t.
    Above,
    /// s < t.
    Below,
    /// |s| > t.
    OutsideMagnitude,
    /// |s| < t.
    InsideMagnitude,
}

/// A region of one candidate signal where the residual energy concentrates.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Region {
    /// The signal's name.
    pub signal: String,
    /// The side of the threshold.
    pub side: Side,
    /// The threshold t.
    pub threshold: f64,
    /// Fraction of the samples in the region.
    pub sample_share: f64,
    /// Fraction of Σε² in the region.
    pub energy_share: f64,
    /// energy_share / sample_share.
    pub lift: f64,
    /// The correlation ratio η² of ε² on quantile bins of the signal (0…1).
    pub eta_squared: f64,
}

impl Region {
    /// The region as text, e.g. `|u| > 0.8`.
    ///
    /// ```
    /// use structid_discover::localise::{Region, Side};
    /// let r = Region { signal: "u".into(), side: Side::OutsideMagnitude, threshold: 0.8,
    ///     sample_share: 0.2, energy_share: 0.9, lift: 4.5, eta_squared: 0.6 };
    /// assert_eq!(r.describe(), "|u| > 0.8");
    /// ```
    pub fn describe(&self) -> String {
        let t = format!("{:.3}", self.threshold)
            .trim_end_matches('0')
            .trim_end_matches('.')
            .to_string();
        match self.side {
            Side::Above => format!("{} > {t}", self.signal),
            Side::Below => format!("{} < {t}", self.signal),
            Side::OutsideMagnitude => format!("|{}| > {t}", self.signal),
            Side::InsideMagnitude => format!("|{}| < {t}", self.signal),
        }
    }
}

/// Quantile bin index of every sample of `s` (`bins` bins of about equal counts).
fn quantile_bins(s: &[f64], bins: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..s.len()).collect();
    order.sort_by(|&a, &b| s[a].total_cmp(&s[b]));
    let mut bin = vec![0; s.len()];
    for (rank, &k) in order.iter().enumerate() {
        bin[k] = rank * bins / s.len().max(1);
    }
    bin
}

/// η² of `values` grouped by `groups` (between-group variance over total variance).
fn correlation_ratio(values: &[f64], groups: &[usize], count: usize) -> f64 {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let total: f64 = values.iter().map(|v| (v - mean).powi(2)).sum();
    if total <= 0.0 {
        return 0.0;
    }
    let mut sums = vec![0.0; count];
    let mut counts = vec![0usize; count];
    for (v, &g) in values.iter().zip(groups) {
        sums[g] += v;
        counts[g] += 1;
    }
    let between: f64 = sums
        .iter()
        .zip(&counts)
        .filter(|(_, c)| **c > 0)
        .map(|(s, c)| *c as f64 * (s / *c as f64 - mean).powi(2))
        .sum();
    (between / total).clamp(0.0, 1.0)
}

/// For each candidate signal (name, samples), the region where the residual energy
/// concentrates most (see the [module documentation](self)), candidates ranked by η².
/// Signals of the wrong length or with non-finite samples are skipped.
///
/// ```
/// use structid_discover::localise::operating_regions;
/// let u: Vec<f64> = (0..2000).map(|k| ((k as f64) * 0.01).sin()).collect();
/// // The model fails only where |u| > 0.8.
/// let e: Vec<f64> = u.iter().map(|u| if u.abs() > 0.8 { 0.5 } else { 0.01 }).collect();
/// let regions = operating_regions(&e, &[("u", &u)], 0.05);
/// assert_eq!(regions[0].describe(), "|u| > 0.8");
/// ```
pub fn operating_regions(
    residual: &[f64],
    signals: &[(&str, &[f64])],
    min_share: f64,
) -> Vec<Region> {
    let n = residual.len();
    let e2: Vec<f64> = residual.iter().map(|v| v * v).collect();
    let total: f64 = e2.iter().sum();
    let mut out = Vec::new();
    if n < 10 || total <= 0.0 || !total.is_finite() {
        return out;
    }
    let min_count = ((min_share.clamp(0.0, 0.5) * n as f64).ceil() as usize).max(1);
    for (name, s) in signals {
        if s.len() != n || s.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let bins = 20.min(n / 5).max(2);
        let eta = correlation_ratio(&e2, &quantile_bins(s, bins), bins);
        let mut best: Option<Region> = None;
        for (side, key) in [
            (Side::Above, Box::new(|v: f64| v) as Box<dyn Fn(f64) -> f64>),
            (Side::Below, Box::new(|v: f64| -v)),
            (Side::OutsideMagnitude, Box::new(|v: f64| v.abs())),
            (Side::InsideMagnitude, Box::new(|v: f64| -v.abs())),
        ] {
            // Sort by the key descending; a region is a prefix {key > key_t}.
            let mut order: Vec<usize> = (0..n).collect();
            order.sort_by(|&a, &b| key(s[b]).total_cmp(&key(s[a])));
            let mut energy = 0.0;
            for (count, &k) in order.iter().enumerate() {
                energy += e2[k];
                let count = count + 1;
                if count < min_count || count > n - min_count {
                    continue;
                }
                // Only thresholds between distinct values.
                if key(s[order[count]]) == key(s[k]) {
                    continue;
                }
                let (es, ss) = (energy / total, count as f64 / n as f64);
                let lift = es / ss;
                // The excess energy share (a Kolmogorov–Smirnov-like distance) picks the whole
                // region where the residual is denser than average; the lift alone would
                // prefer the narrowest slice of it.
                if best
                    .as_ref()
                    .is_none_or(|b| es - ss > b.energy_share - b.sample_share)
                {
                    let t = 0.5 * (key(s[k]) + key(s[order[count]]));
                    let threshold = match side {
                        Side::Above | Side::OutsideMagnitude => t,
                        Side::Below | Side::InsideMagnitude => -t,
                    };
                    best = Some(Region {
                        signal: name.to_string(),
                        side,
                        threshold,
                        sample_share: ss,
                        energy_share: es,
                        lift,
                        eta_squared: eta,
                    });
                }
            }
        }
        if let Some(b) = best {
            out.push(b);
        }
    }
    out.sort_by(|a, b| b.eta_squared.total_cmp(&a.eta_squared));
    out
}

/// The residual binned by a signal: per quantile bin, (centre of the signal, mean ε, RMS ε,
/// samples).
///
/// ```
/// use structid_discover::localise::binned_residual;
/// let s: Vec<f64> = (0..100).map(|k| k as f64).collect();
/// let e: Vec<f64> = s.iter().map(|v| if *v >= 50.0 { 1.0 } else { 0.0 }).collect();
/// let b = binned_residual(&e, &s, 2);
/// assert_eq!(b.len(), 2);
/// assert_eq!((b[0].1, b[1].1), (0.0, 1.0));
/// ```
pub fn binned_residual(
    residual: &[f64],
    signal: &[f64],
    bins: usize,
) -> Vec<(f64, f64, f64, usize)> {
    let n = residual.len().min(signal.len());
    if n == 0 || bins == 0 {
        return Vec::new();
    }
    let bins = bins.min(n);
    let groups = quantile_bins(&signal[..n], bins);
    let mut acc = vec![(0.0, 0.0, 0.0, 0usize); bins];
    for k in 0..n {
        let a = &mut acc[groups[k]];
        a.0 += signal[k];
        a.1 += residual[k];
        a.2 += residual[k] * residual[k];
        a.3 += 1;
    }
    acc.into_iter()
        .filter(|a| a.3 > 0)
        .map(|(s, e, e2, c)| {
            let c_f = c as f64;
            (s / c_f, e / c_f, (e2 / c_f).sqrt(), c)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_find_every_burst_and_nothing_in_pure_noise() {
        let mut e: Vec<f64> = (0..5000)
            .map(|k| 0.01 * ((k * 7919 % 1000) as f64 / 500.0 - 1.0))
            .collect();
        assert!(exceedance_windows(&e, 0.01, 3.0, 50).is_empty());
        for v in &mut e[1000..1100] {
            *v += 0.2;
        }
        for v in &mut e[3000..3050] {
            *v -= 0.3;
        }
        let w = exceedance_windows(&e, 0.01, 3.0, 50);
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(w[0].start < 1100 && w[0].end > 1000);
        assert!(w[1].start < 3050 && w[1].end > 3000);
    }

    #[test]
    fn the_signal_that_explains_the_residual_ranks_first() {
        let len = 4000;
        let u: Vec<f64> = (0..len).map(|k| (k as f64 * 0.013).sin()).collect();
        let y: Vec<f64> = (0..len).map(|k| (k as f64 * 0.0071).cos()).collect();
        // A dead-zone-like error: large only where y < −0.5.
        let e: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(k, y)| if *y < -0.5 { 0.3 } else { 0.0 } + 0.01 * ((k % 7) as f64 - 3.0))
            .collect();
        let r = operating_regions(&e, &[("u", &u), ("y", &y)], 0.05);
        assert_eq!(r[0].signal, "y");
        assert_eq!(r[0].side, Side::Below);
        assert!((r[0].threshold + 0.5).abs() < 0.05, "{:?}", r[0]);
        assert!(r[0].lift > 2.5 && r[0].eta_squared > r[1].eta_squared);
    }

    #[test]
    fn degenerate_inputs_give_empty_answers() {
        assert!(exceedance_windows(&[], 1.0, 3.0, 10).is_empty());
        assert!(operating_regions(&[0.0; 50], &[("u", &[1.0; 50])], 0.05).is_empty());
        let short = [1.0; 3];
        assert!(operating_regions(&[1.0; 50], &[("u", &short)], 0.05).is_empty());
        assert!(binned_residual(&[], &[], 5).is_empty());
    }
}
