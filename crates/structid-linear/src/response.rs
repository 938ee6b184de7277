//! What a linear model looks like: frequency response with its uncertainty, step response,
//! poles and zeros (the figures of `structid linear` and `structid refine`).

use nalgebra::DMatrix;
use structid_lti::Signal;

use crate::error::LinearError;
use crate::polynomial::PolynomialModel;

/// One frequency of [`bode`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodePoint {
    /// Normalised frequency in cycles per sample (0 … 0.5).
    pub frequency: f64,
    /// |G(e^{jω})|.
    pub magnitude: f64,
    /// arg G(e^{jω}) in radians, unwrapped along the frequencies given.
    pub phase: f64,
    /// The standard deviation of the magnitude from the parameter covariance (first-order
    /// propagation), when a covariance was given.
    pub magnitude_std: Option<f64>,
}

/// The frequency response of input `input` of `model` at the normalised `frequencies`
/// (cycles per sample), with the standard deviation of the magnitude when the covariance of
/// the parameters [`PolynomialModel::parameters`] is given: σ_|G|² = J·Σ·Jᵀ, J the gradient of
/// |G| in the parameters by central differences (the delta method, as MATLAB's `bode` of an
/// `idpoly` draws its confidence region).
///
/// ```
/// use nalgebra::DMatrix;
/// use structid_linear::PolynomialModel;
/// use structid_linear::response::bode;
/// // G = 0.5 q⁻¹ / (1 − 0.5 q⁻¹): unit gain at f = 0.
/// let m = PolynomialModel::new(vec![vec![0.0, 0.5]], vec![1.0, -0.5], None).unwrap();
/// let cov = DMatrix::from_diagonal_element(2, 2, 1e-4);
/// let p = bode(&m, 0, &[0.0, 0.25], Some(&cov)).unwrap();
/// assert!((p[0].magnitude - 1.0).abs() < 1e-12);
/// assert!(p[0].magnitude_std.unwrap() > 0.0);
/// ```
///
/// # Errors
/// [`LinearError`] when `input` is out of range or the covariance does not match the
/// parameters.
pub fn bode(
    model: &PolynomialModel,
    input: usize,
    frequencies: &[f64],
    covariance: Option<&DMatrix<f64>>,
) -> Result<Vec<BodePoint>, LinearError> {
    check_input(model, input)?;
    let orders = model.orders();
    let theta = model.parameters();
    if let Some(c) = covariance
        && (c.nrows() != theta.len() || c.ncols() != theta.len())
    {
        return Err(LinearError::dims(
            "parameter covariance",
            theta.len(),
            c.nrows(),
        ));
    }
    let magnitude_at = |m: &PolynomialModel, f: f64| {
        m.frequency_response(input, f)
            .map_or(f64::NAN, |(re, im)| re.hypot(im))
    };
    // The models a small step away in each parameter, both ways, for the gradient.
    let perturbed: Vec<(PolynomialModel, PolynomialModel, f64)> = match covariance {
        Some(_) => (0..theta.len())
            .map(|i| {
                let h = 1e-6 * theta[i].abs().max(1.0);
                let at = |s: f64| {
                    let mut t = theta.clone();
                    t[i] += s * h;
                    PolynomialModel::from_parameters(&orders, &t, model.sample_time)
                };
                Ok((at(1.0)?, at(-1.0)?, h))
            })
            .collect::<Result<_, LinearError>>()?,
        None => Vec::new(),
    };
    let mut out = Vec::with_capacity(frequencies.len());
    let mut last_phase: Option<f64> = None;
    for &f in frequencies {
        let (re, im) = model
            .frequency_response(input, f)
            .unwrap_or((f64::NAN, f64::NAN));
        let mut phase = im.atan2(re);
        if let Some(prev) = last_phase {
            let turns = ((prev - phase) / std::f64::consts::TAU).round();
            phase += turns * std::f64::consts::TAU;
        }
        if phase.is_finite() {
            last_phase = Some(phase);
        }
        let magnitude_std = covariance.map(|c| {
            let j: Vec<f64> = perturbed
                .iter()
                .map(|(up, down, h)| (magnitude_at(up, f) - magnitude_at(down, f)) / (2.0 * h))
                .collect();
            let mut v = 0.0;
            for (a, ja) in j.iter().enumerate() {
                for (b, jb) in j.iter().enumerate() {
                    v += ja * c[(a, b)] * jb;
                }
            }
            v.max(0.0).sqrt()
        });
        out.push(BodePoint {
            frequency: f,
            magnitude: re.hypot(im),
            phase,
            magnitude_std,
        });
    }
    Ok(out)
}

/// The roots of c₀·zⁿ + c₁·zⁿ⁻¹ + … + cₙ as (re, im), by the eigenvalues of the companion
/// matrix; leading zero coefficients are dropped (they are roots at infinity).
///
/// ```
/// use structid_linear::response::roots;
/// let mut r = roots(&[1.0, -3.0, 2.0]); // (z − 1)(z − 2)
/// r.sort_by(|a, b| a.0.total_cmp(&b.0));
/// assert!((r[0].0 - 1.0).abs() < 1e-12 && (r[1].0 - 2.0).abs() < 1e-12);
/// ```
pub fn roots(c: &[f64]) -> Vec<(f64, f64)> {
    let c: Vec<f64> = c.iter().copied().skip_while(|v| *v == 0.0).collect();
    if c.len() < 2 || c.iter().any(|v| !v.is_finite()) {
        return Vec::new();
    }
    let n = c.len() - 1;
    let mut m = DMatrix::zeros(n, n);
    for j in 0..n {
        m[(0, j)] = -c[j + 1] / c[0];
        if j + 1 < n {
            m[(j + 1, j)] = 1.0;
        }
    }
    m.complex_eigenvalues()
        .iter()
        .map(|z| (z.re, z.im))
        .collect()
}

/// The poles of `model` (roots of zⁿ·A(z⁻¹)) as (re, im).
///
/// ```
/// use structid_linear::{PolynomialModel, response::poles};
/// let m = PolynomialModel::new(vec![vec![0.0, 1.0]], vec![1.0, -0.8], None).unwrap();
/// assert!((poles(&m)[0].0 - 0.8).abs() < 1e-12);
/// ```
pub fn poles(model: &PolynomialModel) -> Vec<(f64, f64)> {
    roots(&model.den)
}

/// The finite zeros of input `input` of `model` (roots of B(z⁻¹) after its delay) as
/// (re, im); empty for an input out of range.
///
/// ```
/// use structid_linear::{PolynomialModel, response::zeros};
/// // (q⁻¹ + 0.5 q⁻²)/(1 − 0.8 q⁻¹): a zero at −0.5.
/// let m = PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -0.8], None).unwrap();
/// assert!((zeros(&m, 0)[0].0 + 0.5).abs() < 1e-12);
/// ```
pub fn zeros(model: &PolynomialModel, input: usize) -> Vec<(f64, f64)> {
    model.num.get(input).map(|b| roots(b)).unwrap_or_default()
}

/// The response of the output to a unit step on input `input` (the others held at 0), `len`
/// samples from rest.
///
/// ```
/// use structid_linear::{PolynomialModel, response::step_response};
/// let m = PolynomialModel::new(vec![vec![0.0, 0.5]], vec![1.0, -0.5], None).unwrap();
/// let s = step_response(&m, 0, 60).unwrap();
/// assert_eq!(s[0], 0.0);
/// assert!((s[59] - 1.0).abs() < 1e-9);
/// ```
///
/// # Errors
/// [`LinearError`] when `input` is out of range or the simulation fails.
pub fn step_response(
    model: &PolynomialModel,
    input: usize,
    len: usize,
) -> Result<Vec<f64>, LinearError> {
    check_input(model, input)?;
    let u = Signal::from_fn(len, model.inputs(), |_, c| f64::from(u8::from(c == input)));
    model.simulate(&u)
}

/// An input index out of range is a parameter error naming how many inputs the model has.
fn check_input(model: &PolynomialModel, input: usize) -> Result<(), LinearError> {
    if input >= model.inputs() {
        return Err(LinearError::param(
            "input",
            format!(
                "the model has {} input(s), not {}",
                model.inputs(),
                input + 1
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The delta-method band of a first-order model against Monte Carlo over its parameter
    /// distribution: the spread of |G| at each frequency agrees within 10 %.
    #[test]
    fn the_magnitude_band_matches_sampled_parameters() {
        let m = PolynomialModel::new(vec![vec![0.0, 0.3]], vec![1.0, -0.7], None).unwrap();
        let cov = DMatrix::from_row_slice(2, 2, &[4e-6, 1e-6, 1e-6, 2e-6]);
        let freqs = [0.0, 0.01, 0.05, 0.2, 0.5];
        let p = bode(&m, 0, &freqs, Some(&cov)).unwrap();
        let chol = cov.clone().cholesky().unwrap().l();
        let mut state = 99u64;
        let mut normal = || {
            let mut u = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (u(), u());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let draws = 20_000;
        let mut samples = vec![Vec::with_capacity(draws); freqs.len()];
        for _ in 0..draws {
            let e = nalgebra::DVector::from_fn(2, |_, _| normal());
            let d = &chol * e;
            let t = [0.3 + d[0], -0.7 + d[1]];
            let mm = PolynomialModel::from_parameters(&m.orders(), &t, None).unwrap();
            for (i, f) in freqs.iter().enumerate() {
                let (re, im) = mm.frequency_response(0, *f).unwrap();
                samples[i].push(re.hypot(im));
            }
        }
        for (i, s) in samples.iter().enumerate() {
            let mean = s.iter().sum::<f64>() / s.len() as f64;
            let std = (s.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / s.len() as f64).sqrt();
            let band = p[i].magnitude_std.unwrap();
            assert!(
                (band / std - 1.0).abs() < 0.1,
                "f = {}: {band} vs {std}",
                freqs[i]
            );
        }
        // Without a covariance, no band.
        assert!(
            bode(&m, 0, &freqs, None).unwrap()[0]
                .magnitude_std
                .is_none()
        );
        assert!(bode(&m, 1, &freqs, None).is_err());
        assert!(bode(&m, 0, &freqs, Some(&DMatrix::zeros(3, 3))).is_err());
    }

    /// The phase of a pure delay of 3 samples falls linearly through −3·2π·f, unwrapped.
    #[test]
    fn the_phase_is_unwrapped() {
        let m = PolynomialModel::new(vec![vec![0.0, 0.0, 0.0, 1.0]], vec![1.0], None).unwrap();
        let freqs: Vec<f64> = (0..=100).map(|i| 0.5 * i as f64 / 100.0).collect();
        let p = bode(&m, 0, &freqs, None).unwrap();
        for q in &p {
            let expected = -3.0 * std::f64::consts::TAU * q.frequency;
            assert!((q.phase - expected).abs() < 1e-9, "{q:?}");
            assert!((q.magnitude - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn poles_and_zeros_of_a_second_order_model() {
        // A = (1 − 0.5 q⁻¹)(1 − 0.9 q⁻¹), B = q⁻¹·(1 + 0.4 q⁻¹).
        let m =
            PolynomialModel::new(vec![vec![0.0, 1.0, 0.4]], vec![1.0, -1.4, 0.45], None).unwrap();
        let mut p: Vec<f64> = poles(&m).iter().map(|z| z.0).collect();
        p.sort_by(f64::total_cmp);
        assert!((p[0] - 0.5).abs() < 1e-12 && (p[1] - 0.9).abs() < 1e-12);
        let z = zeros(&m, 0);
        assert_eq!(z.len(), 1);
        assert!((z[0].0 + 0.4).abs() < 1e-12 && z[0].1 == 0.0);
        assert!(zeros(&m, 3).is_empty());
        // Complex poles 0.6 ± 0.6j.
        let c = roots(&[1.0, -1.2, 0.72]);
        assert!(
            c.iter()
                .all(|z| (z.0 - 0.6).abs() < 1e-12 && (z.1.abs() - 0.6).abs() < 1e-12)
        );
    }
}
