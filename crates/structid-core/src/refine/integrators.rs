//! Poles at z = 1 held fixed in the linear step: G = B/(F′·(1 − q⁻¹)ⁿ).

use structid_lti::Signal;

use crate::error::{Error, Result};

use structid_linear::integrators::{convolve, count_integrators, integrator_polynomial};

/// How many factors (1 − q⁻¹) divide `den` ([`structid_linear::integrators`]).
pub(super) fn count(den: &[f64]) -> usize {
    count_integrators(den)
}

/// F′ = F/(1 − q⁻¹)ⁿ, or an error when F has fewer than n poles at 1.
pub(super) fn deflate(den: &[f64], n: usize) -> Result<Vec<f64>> {
    structid_linear::integrators::deflate(den, n).ok_or_else(|| {
        Error::InvalidStructure(format!(
            "the linear part has {} pole(s) at z = 1 (denominator of degree {}), not the {n} \
             integrator(s) to hold fixed",
            count(den),
            den.len().saturating_sub(1)
        ))
    })
}

/// F′·(1 − q⁻¹)ⁿ.
pub(super) fn inflate(den: &[f64], n: usize) -> Vec<f64> {
    convolve(den, &integrator_polynomial(n))
}

/// Every channel of `s` summed n times from zero: s/(1 − q⁻¹)ⁿ.
pub(super) fn sum(s: &Signal, n: usize) -> Result<Signal> {
    let (len, m) = (s.len(), s.channels());
    let mut out = vec![0.0; len * m];
    for c in 0..m {
        let mut col: Vec<f64> = (0..len).map(|k| s.get(k, c)).collect();
        for _ in 0..n {
            let mut acc = 0.0;
            for v in &mut col {
                acc += *v;
                *v = acc;
            }
        }
        for (k, v) in col.into_iter().enumerate() {
            out[k * m + c] = v;
        }
    }
    Ok(Signal::new(m, out)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Property: inflating by n and counting gives n back, and deflating restores F′.
    #[test]
    fn inflate_count_and_deflate_are_inverse() {
        let f = [1.0, -1.2, 0.5];
        for n in 0..3 {
            let d = inflate(&f, n);
            assert_eq!(count(&d), n, "{d:?}");
            let back = deflate(&d, n).unwrap();
            for (a, b) in back.iter().zip(&f) {
                assert!((a - b).abs() < 1e-12);
            }
        }
        // A pole at 0.999 is not an integrator.
        assert_eq!(count(&[1.0, -0.999]), 0);
        assert!(deflate(&[1.0, -0.999], 1).is_err());
    }

    /// Summing once is the response of 1/(1 − q⁻¹): a step for an impulse, a ramp twice.
    #[test]
    fn summing_is_the_integrator_response() {
        let impulse = Signal::from_fn(5, 1, |k, _| if k == 0 { 1.0 } else { 0.0 });
        assert_eq!(sum(&impulse, 1).unwrap().channel(0), vec![1.0; 5]);
        assert_eq!(
            sum(&impulse, 2).unwrap().channel(0),
            vec![1.0, 2.0, 3.0, 4.0, 5.0]
        );
    }
}
