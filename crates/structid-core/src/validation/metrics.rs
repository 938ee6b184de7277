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

#[cfg(test)]
mod tests {
    use super::*;

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
