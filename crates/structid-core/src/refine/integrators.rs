//! Poles at z = 1 held fixed in the linear step: G = B/(F′·(1 − q⁻¹)ⁿ).

use structid_lti::Signal;

use crate::error::{Error, Result};

/// Relative size of F(1) below which (1 − q⁻¹) is taken to divide F.
const TOLERANCE: f64 = 1e-8;

/// F divided by (1 − q⁻¹) once: the quotient and the remainder F(1).
fn divide(den: &[f64]) -> (Vec<f64>, f64) {
    // F(q⁻¹) = (1 − q⁻¹)·Q(q⁻¹) + r: q_0 = f_0, q_k = f_k + q_(k−1), r = f_n + q_(n−1).
    let n = den.len() - 1;
    let mut q = Vec::with_capacity(n);
    let mut acc = 0.0;
    for &f in &den[..n] {
        acc += f;
        q.push(acc);
    }
    (q, acc + den[n])
}

fn scale(den: &[f64]) -> f64 {
    den.iter().map(|v| v.abs()).sum::<f64>()
}

/// How many factors (1 − q⁻¹) divide `den` (to a relative 1e-8).
pub(super) fn count(den: &[f64]) -> usize {
    let mut d = den.to_vec();
    let mut n = 0;
    while d.len() > 1 {
        let (q, r) = divide(&d);
        if r.abs() > TOLERANCE * scale(&d) {
            break;
        }
        d = q;
        n += 1;
    }
    n
}

/// F′ = F/(1 − q⁻¹)ⁿ, or an error when F has fewer than n poles at 1.
pub(super) fn deflate(den: &[f64], n: usize) -> Result<Vec<f64>> {
    let mut d = den.to_vec();
    for i in 0..n {
        if d.len() < 2 {
            return Err(Error::InvalidStructure(format!(
                "the linear part's denominator has degree {}, too low to hold {n} \
                 integrator(s) fixed",
                den.len() - 1
            )));
        }
        let (q, r) = divide(&d);
        if r.abs() > TOLERANCE * scale(&d) {
            return Err(Error::InvalidStructure(format!(
                "the linear part has {i} pole(s) at z = 1, not the {n} integrator(s) to hold \
                 fixed (its denominator at z = 1 is {r:e} after removing {i})"
            )));
        }
        d = q;
    }
    Ok(d)
}

/// F′·(1 − q⁻¹)ⁿ.
pub(super) fn inflate(den: &[f64], n: usize) -> Vec<f64> {
    let mut d = den.to_vec();
    for _ in 0..n {
        let mut next = vec![0.0; d.len() + 1];
        for (k, &v) in d.iter().enumerate() {
            next[k] += v;
            next[k + 1] -= v;
        }
        d = next;
    }
    d
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
