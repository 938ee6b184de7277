//! Known integrators (poles fixed at `z = 1`) and the stability class of a denominator.
//!
//! A position driven by a force, a motor angle driven by a current or a tank level driven by
//! a flow has a pole at `s = 0`, which sampling maps exactly to `z = 1`. Estimating that pole
//! from data wastes a parameter and, for output error, starts from a denominator that is not
//! strictly stable. When the number `N` of integrators is known, the model is written
//!
//! ```text
//! A(q) = A'(q) (1 − q⁻¹)ᴺ,     A'(q) = 1 + a'_1 q⁻¹ + … + a'_na q⁻na   (free)
//! ```
//!
//! and only `A'` and the numerators are estimated: ARX regresses `(1 − q⁻¹)ᴺ y` on the input
//! (the noise model `1/A` then carries the same integrators), output error simulates
//! `ŷ = B/(A'(1 − q⁻¹)ᴺ) u` and keeps `(1 − q⁻¹)ᴺ` fixed. Standard deviations of the
//! coefficients of the full `A` follow from those of `A'` through the linear map
//! `a_j = δ_j + Σ_i a'_i δ_{j−i}` (`δ` the coefficients of `(1 − q⁻¹)ᴺ`); the fixed factor
//! itself has none.
//!
//! [`Stability`] classifies a denominator: strictly stable, marginally stable (roots on the
//! unit circle: integrators at `z = 1`, or other undamped modes), or unstable.

use crate::polynomial::{root_radius, schur_stable};

/// Largest number of integrators the estimators fix (a triple integrator is not a plant met
/// in practice, and its regression would be badly conditioned).
pub const MAX_INTEGRATORS: usize = 2;

/// Coefficients of `(1 − q⁻¹)ᴺ` in powers of `q⁻¹`.
///
/// ```
/// use structid_linear::integrators::integrator_polynomial;
/// assert_eq!(integrator_polynomial(0), vec![1.0]);
/// assert_eq!(integrator_polynomial(2), vec![1.0, -2.0, 1.0]);
/// ```
pub fn integrator_polynomial(n: usize) -> Vec<f64> {
    (0..n).fold(vec![1.0], |p, _| convolve(&p, &[1.0, -1.0]))
}

/// Product of two polynomials in `q⁻¹` (coefficient convolution).
///
/// ```
/// use structid_linear::integrators::convolve;
/// assert_eq!(convolve(&[1.0, -0.5], &[1.0, -1.0]), vec![1.0, -1.5, 0.5]);
/// ```
pub fn convolve(a: &[f64], b: &[f64]) -> Vec<f64> {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    let mut c = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            c[i + j] += x * y;
        }
    }
    c
}

/// `(1 − q⁻¹)ᴺ x`, with the samples before the record taken as unknown: the first `N`
/// entries of the result are 0 and must not be used (the estimators start their equations
/// and costs after them).
///
/// ```
/// use structid_linear::integrators::difference;
/// assert_eq!(difference(&[1.0, 3.0, 6.0, 10.0], 1), vec![0.0, 2.0, 3.0, 4.0]);
/// assert_eq!(difference(&[1.0, 3.0, 6.0, 10.0], 2), vec![0.0, 0.0, 1.0, 1.0]);
/// ```
pub fn difference(x: &[f64], n: usize) -> Vec<f64> {
    let d = integrator_polynomial(n);
    (0..x.len())
        .map(|k| {
            if k < n {
                0.0
            } else {
                d.iter().enumerate().map(|(j, c)| c * x[k - j]).sum()
            }
        })
        .collect()
}

/// Divides `den` by `(1 − q⁻¹)ᴺ` (synthetic division by the root `z = 1`, `N` times).
/// Returns `None` when a remainder is not zero relative to the coefficients (to `1e-9`):
/// `den` then does not have `N` roots at `z = 1`.
///
/// ```
/// use structid_linear::integrators::{deflate, integrator_polynomial, convolve};
/// let den = convolve(&[1.0, -0.7], &integrator_polynomial(2));
/// let free = deflate(&den, 2).unwrap();
/// assert!((free[1] + 0.7).abs() < 1e-12 && free.len() == 2);
/// assert!(deflate(&[1.0, -0.5], 1).is_none());
/// ```
pub fn deflate(den: &[f64], n: usize) -> Option<Vec<f64>> {
    deflate_within(den, n, 1e-9)
}

/// [`deflate`] accepting a remainder F(1) up to `tolerance` times Σ|f_i| at each step (a
/// denominator computed in floating point, e.g. a discretised plant, has its roots at 1 only
/// to rounding).
///
/// ```
/// use structid_linear::integrators::deflate_within;
/// assert_eq!(deflate_within(&[1.0, -1.5, 0.5 + 1e-8], 1, 1e-6).map(|p| p.len()), Some(2));
/// assert!(deflate_within(&[1.0, -1.5, 0.5 + 1e-8], 1, 1e-12).is_none());
/// ```
pub fn deflate_within(den: &[f64], n: usize, tolerance: f64) -> Option<Vec<f64>> {
    let mut p = den.to_vec();
    for _ in 0..n {
        if p.len() < 2 {
            return None;
        }
        let scale: f64 = p.iter().map(|v| v.abs()).sum();
        // p(q⁻¹) = (1 − q⁻¹) r(q⁻¹) + c: r_j = Σ_{i ≤ j} p_i, remainder = Σ p_i.
        let mut r = Vec::with_capacity(p.len() - 1);
        let mut acc = 0.0;
        for v in &p[..p.len() - 1] {
            acc += v;
            r.push(acc);
        }
        let rem = acc + p[p.len() - 1];
        if rem.is_nan() || rem.abs() > tolerance * scale.max(f64::MIN_POSITIVE) {
            return None;
        }
        p = r;
    }
    Some(p)
}

/// Number of roots of `den` at `z = 1` (exact deflations, see [`deflate`]).
///
/// ```
/// use structid_linear::integrators::{count_integrators, convolve};
/// assert_eq!(count_integrators(&convolve(&[1.0, -0.9], &[1.0, -1.0])), 1);
/// assert_eq!(count_integrators(&[1.0, -0.9]), 0);
/// ```
pub fn count_integrators(den: &[f64]) -> usize {
    let mut n = 0;
    let mut p = den.to_vec();
    while let Some(r) = deflate(&p, 1) {
        n += 1;
        p = r;
    }
    n
}

/// A numerator `B(1)` below this share of `Σ|bᵢ|` puts a zero within about 0.1 of z = 1,
/// where it cancels an integrator ([`integrator_cancellation`]).
pub const CANCELLATION: f64 = 0.05;

/// How nearly the numerators of a model with an integrator cancel it: the smallest
/// `|B_i(1)| / Σ_k |b_ik|` over the inputs, or `None` when the denominator has no root at
/// z = 1 or no numerator has a nonzero coefficient.
///
/// A zero at z₀ makes `B(1)` proportional to `1 − z₀` (for `B = b₁q⁻¹ + b₂q⁻²` the ratio is
/// `|1 − z₀| / (1 + |z₀|)`), so a ratio under [`CANCELLATION`] means a zero within about 0.1
/// of z = 1: with it, G does not integrate at the frequencies the record resolves. That is what an
/// output-error or ARX fit with a fixed integrator returns when the data do not show the
/// integration, most often because the record was taken in closed loop with the controller's
/// action dominating (the direct fit of u → y then approaches the controller's negative
/// inverse), or because friction holds the output still at low force.
///
/// ```
/// use structid_linear::PolynomialModel;
/// use structid_linear::integrators::integrator_cancellation;
/// // (1 − q⁻¹)(1 − 0.9 q⁻¹) with B = q⁻¹ − 0.999 q⁻²: the zero at 0.999 cancels the integrator
/// let m = PolynomialModel::new(vec![vec![0.0, 1.0, -0.999]], vec![1.0, -1.9, 0.9], None).unwrap();
/// assert!(integrator_cancellation(&m).unwrap() < 1e-3);
/// let ok = PolynomialModel::new(vec![vec![0.0, 1.0, 1.0]], vec![1.0, -1.9, 0.9], None).unwrap();
/// assert_eq!(integrator_cancellation(&ok), Some(1.0));
/// ```
pub fn integrator_cancellation(model: &crate::PolynomialModel) -> Option<f64> {
    if count_integrators(&model.den) == 0 {
        return None;
    }
    model
        .num
        .iter()
        .filter_map(|b| {
            let size: f64 = b.iter().map(|v| v.abs()).sum();
            (size > 0.0).then(|| b.iter().sum::<f64>().abs() / size)
        })
        .min_by(f64::total_cmp)
}

// The model's class lives here, beside the classes, so that `polynomial` need not know them.
impl crate::PolynomialModel {
    /// Stability class of the denominator: strictly stable, marginally stable (integrators at
    /// `z = 1` or other poles on the unit circle) or unstable; displayed as "stable",
    /// "marginally stable (1 integrator)", "UNSTABLE (spectral radius …)".
    ///
    /// ```
    /// use structid_linear::{PolynomialModel, Stability};
    /// // (1 − q⁻¹)(1 − 0.9 q⁻¹): a position driven by a force
    /// let m = PolynomialModel::new(vec![vec![0.0, 1.0]], vec![1.0, -1.9, 0.9], None).unwrap();
    /// assert_eq!(m.stability(), Stability::MarginallyStable { integrators: 1, other_unit_circle: 0 });
    /// assert_eq!(m.stability().to_string(), "marginally stable (1 integrator)");
    /// ```
    pub fn stability(&self) -> Stability {
        Stability::of(&self.den)
    }
}

/// Stability class of a discrete-time denominator.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Stability {
    /// Every root strictly inside the unit circle.
    Stable,
    /// No root outside the unit circle, some on it: `integrators` roots at `z = 1` and
    /// `other_unit_circle` further roots of modulus 1 (undamped oscillations or `z = −1`).
    MarginallyStable {
        /// Roots at `z = 1` (integrators).
        integrators: usize,
        /// Other roots on the unit circle (to `1e-7` in modulus).
        other_unit_circle: usize,
    },
    /// A root outside the unit circle.
    Unstable {
        /// Largest root modulus.
        spectral_radius: f64,
    },
}

impl Stability {
    /// Classifies the denominator `den` (`1, a_1, …`): the integrators are deflated exactly,
    /// then the rest is tested by Schur–Cohn and, if not strictly stable, by its largest
    /// root modulus (within `1e-7` of 1 counts as on the circle).
    ///
    /// ```
    /// use structid_linear::integrators::Stability;
    /// assert_eq!(Stability::of(&[1.0, -0.5]), Stability::Stable);
    /// assert_eq!(
    ///     Stability::of(&[1.0, -1.5, 0.5]),
    ///     Stability::MarginallyStable { integrators: 1, other_unit_circle: 0 }
    /// );
    /// assert!(matches!(Stability::of(&[1.0, -1.2]), Stability::Unstable { .. }));
    /// ```
    pub fn of(den: &[f64]) -> Self {
        let integrators = count_integrators(den);
        let rest = deflate(den, integrators).unwrap_or_else(|| den.to_vec());
        if schur_stable(&rest) {
            return if integrators == 0 {
                Stability::Stable
            } else {
                Stability::MarginallyStable {
                    integrators,
                    other_unit_circle: 0,
                }
            };
        }
        let r = root_radius(&rest);
        if r <= 1.0 + 1e-7 {
            let other = unit_circle_roots(&rest);
            Stability::MarginallyStable {
                integrators,
                other_unit_circle: other.max(1),
            }
        } else {
            Stability::Unstable { spectral_radius: r }
        }
    }

    /// `true` for [`Stability::Stable`].
    ///
    /// ```
    /// use structid_linear::integrators::Stability;
    /// assert!(!Stability::of(&[1.0, -1.0]).is_stable());
    /// ```
    pub fn is_stable(&self) -> bool {
        matches!(self, Stability::Stable)
    }

    /// `true` unless [`Stability::Unstable`]: the model can be simulated without growing
    /// exponentially (integrators drift, but polynomially).
    ///
    /// ```
    /// use structid_linear::integrators::Stability;
    /// assert!(Stability::of(&[1.0, -2.0, 1.0]).is_acceptable());
    /// ```
    pub fn is_acceptable(&self) -> bool {
        !matches!(self, Stability::Unstable { .. })
    }
}

impl std::fmt::Display for Stability {
    /// "stable", "marginally stable (1 integrator)", "marginally stable (2 integrators,
    /// 2 other poles on the unit circle)", "UNSTABLE (spectral radius 1.2)".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stability::Stable => write!(f, "stable"),
            Stability::MarginallyStable {
                integrators,
                other_unit_circle,
            } => {
                let mut parts = Vec::new();
                if *integrators > 0 {
                    parts.push(format!(
                        "{integrators} integrator{}",
                        if *integrators == 1 { "" } else { "s" }
                    ));
                }
                if *other_unit_circle > 0 {
                    parts.push(format!(
                        "{other_unit_circle} other pole{} on the unit circle",
                        if *other_unit_circle == 1 { "" } else { "s" }
                    ));
                }
                write!(f, "marginally stable ({})", parts.join(", "))
            }
            Stability::Unstable { spectral_radius } => {
                write!(f, "UNSTABLE (spectral radius {spectral_radius:.6})")
            }
        }
    }
}

/// Roots of modulus within `1e-7` of 1 (companion-matrix eigenvalues).
fn unit_circle_roots(den: &[f64]) -> usize {
    let n = den.len().saturating_sub(1);
    if n == 0 || den[0] == 0.0 {
        return 0;
    }
    let mut c = nalgebra::DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        c[(0, j)] = -den[j + 1] / den[0];
        if j + 1 < n {
            c[(j + 1, j)] = 1.0;
        }
    }
    c.complex_eigenvalues()
        .iter()
        .filter(|z| (z.norm() - 1.0).abs() <= 1e-7)
        .count()
}

/// The covariance of `θ_full = (b…, a…)` of `A'(1 − q⁻¹)ᴺ` from that of `θ_free = (b…, a'…)`
/// (`nb_total` numerator parameters, `na_free` free denominator coefficients): `T Σ Tᵀ` with
/// `∂a_j/∂a'_i = δ_{j−i}`.
pub(crate) fn full_covariance(
    cov: &nalgebra::DMatrix<f64>,
    nb_total: usize,
    na_free: usize,
    n: usize,
) -> nalgebra::DMatrix<f64> {
    let delta = integrator_polynomial(n);
    let d_full = nb_total + na_free + n;
    let d_free = nb_total + na_free;
    let t = nalgebra::DMatrix::from_fn(d_full, d_free, |r, c| {
        if r < nb_total || c < nb_total {
            if r == c { 1.0 } else { 0.0 }
        } else {
            // row: a_j with j = r − nb_total + 1; column: a'_i with i = c − nb_total + 1
            let j = r - nb_total + 1;
            let i = c - nb_total + 1;
            if j >= i && j - i < delta.len() {
                delta[j - i]
            } else {
                0.0
            }
        }
    });
    &t * cov * t.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deflation_inverts_multiplication() {
        for n in 0..=2 {
            let free = [1.0, -1.3, 0.4];
            let den = convolve(&free, &integrator_polynomial(n));
            let back = deflate(&den, n).unwrap();
            assert_eq!(back.len(), free.len());
            for (a, b) in back.iter().zip(free) {
                assert!((a - b).abs() < 1e-12);
            }
            assert_eq!(count_integrators(&den), n);
        }
    }

    #[test]
    fn stability_classes_match_roots() {
        // roots 1, 1, 0.8
        let den = convolve(&[1.0, -0.8], &integrator_polynomial(2));
        assert_eq!(
            Stability::of(&den),
            Stability::MarginallyStable {
                integrators: 2,
                other_unit_circle: 0
            }
        );
        assert_eq!(
            Stability::of(&den).to_string(),
            "marginally stable (2 integrators)"
        );
        // an undamped oscillator z² − 2cos(0.3) z + 1
        let osc = [1.0, -2.0 * 0.3f64.cos(), 1.0];
        assert_eq!(
            Stability::of(&osc),
            Stability::MarginallyStable {
                integrators: 0,
                other_unit_circle: 2
            }
        );
        // an integrator times an unstable pole is unstable
        let bad = convolve(&[1.0, -1.1], &[1.0, -1.0]);
        match Stability::of(&bad) {
            Stability::Unstable { spectral_radius } => {
                assert!((spectral_radius - 1.1).abs() < 1e-9)
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn difference_annihilates_polynomials_of_degree_below_n() {
        // (1 − q⁻¹)² kills a ramp, (1 − q⁻¹) a constant
        let ramp: Vec<f64> = (0..10).map(|k| 3.0 + 2.0 * k as f64).collect();
        assert!(difference(&ramp, 2)[2..].iter().all(|v| v.abs() < 1e-12));
        assert!(difference(&[5.0; 6], 1)[1..].iter().all(|v| *v == 0.0));
    }
}

#[cfg(test)]
mod fit_tests {
    use structid_lti::Signal;

    use super::*;
    use crate::testutil::white;
    use crate::{ArxSettings, OeSettings, OeWarning, Orders, PolynomialModel, arx, oe};

    /// The exact zero-order-hold discretisation of `k/(s(Ms + F))` at sample time `ts`, in
    /// closed form: with `a = F/M`, `p = e^{−a ts}`,
    /// `G(z) = (k/M) z⁻¹ [(ts/a + (p−1)/a²) − (p ts/a + (p−1)/a²) z⁻¹] / ((1 − z⁻¹)(1 − p z⁻¹))`.
    fn integrating_axis(k: f64, m: f64, f: f64, ts: f64) -> (PolynomialModel, f64) {
        let a = f / m;
        let p = (-a * ts).exp();
        let b0 = k / m * (ts / a + (p - 1.0) / (a * a));
        let b1 = -k / m * (p * ts / a + (p - 1.0) / (a * a));
        let model =
            PolynomialModel::new(vec![vec![0.0, b0, b1]], vec![1.0, -(1.0 + p), p], Some(ts))
                .unwrap();
        (model, p)
    }

    /// A force held for 25 samples at a time (a slow random staircase), zero mean.
    fn staircase(seed: u64, len: usize) -> Signal {
        let levels = white(seed, len / 25 + 1, 1.0, 1);
        Signal::from_fn(len, 1, |k, _| levels.get(k / 25, 0))
    }

    /// Output-error settings of the axis tests: one integrator held at z = 1, 10 ms samples.
    fn one_integrator() -> OeSettings {
        OeSettings::builder()
            .integrators(1)
            .sample_time(0.01)
            .build()
            .unwrap()
    }

    /// Data of the axis with white output noise of `level` times the output's spread.
    fn axis_data(level: f64) -> (Signal, Signal, f64) {
        let (g, p) = integrating_axis(1.0, 2.0, 4.0, 0.01);
        let u = staircase(41, 4000);
        let y0 = g.simulate(&u).unwrap();
        let mean = y0.iter().sum::<f64>() / y0.len() as f64;
        let spread = (y0.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / y0.len() as f64).sqrt();
        let e = white(42, 4000, level * spread, 1);
        let y = Signal::new(1, y0.iter().zip(e.as_slice()).map(|(a, b)| a + b).collect()).unwrap();
        (u, y, p)
    }

    /// The free pole of a fitted `(1 − q⁻¹)(1 − p q⁻¹)` denominator.
    fn free_pole(den: &[f64]) -> f64 {
        let free = deflate(den, 1).expect("an exact root at 1");
        assert_eq!(free.len(), 2);
        -free[1] / free[0]
    }

    #[test]
    fn arx_with_a_fixed_integrator_keeps_it_exactly_and_finds_the_other_pole() {
        // Differencing turns white sensor noise into the MA noise (1 − q⁻¹)e, which biases
        // least squares in proportion to its size against the velocity increments: ARX
        // needs a quiet sensor (1e-5 of the spread here, an encoder), OE does not (next test, 2 %).
        let (u, y, p) = axis_data(1e-5);
        let s = ArxSettings::builder().integrators(1).build().unwrap();
        let fit = arx(&u, &y, &Orders::siso(1, 2, 1), &s).unwrap();
        assert_eq!(fit.integrators, 1);
        // the root at z = 1 is exact: the coefficients sum to zero to rounding
        assert!(fit.model.den.iter().sum::<f64>().abs() < 1e-14);
        assert_eq!(fit.model.orders(), Orders::siso(2, 2, 1));
        let ph = free_pole(&fit.model.den);
        assert!((ph - p).abs() < 0.02 * p, "pole {ph} vs {p}");
        assert_eq!(
            fit.model.stability(),
            Stability::MarginallyStable {
                integrators: 1,
                other_unit_circle: 0
            }
        );
        // one standard deviation per parameter of the full model; the fixed factor adds
        // none, so a_2 = −p̂ has the std of a'_1 and a_1 = −1 − p̂ the same
        assert_eq!(fit.parameter_std.len(), fit.model.parameters().len());
        assert!((fit.parameter_std[2] - fit.parameter_std[3]).abs() < 1e-15);
    }

    #[test]
    fn oe_with_a_fixed_integrator_fits_the_axis() {
        let (u, y, p) = axis_data(0.02);
        let s = one_integrator();
        let fit = oe(&u, &y, &Orders::siso(1, 2, 1), &s).unwrap();
        assert!(fit.fit_percent > 80.0, "fit {}", fit.fit_percent);
        assert_eq!(fit.warning, None);
        assert!(fit.model.den.iter().sum::<f64>().abs() < 1e-14);
        let ph = free_pole(&fit.model.den);
        assert!((ph - p).abs() < 0.02 * p, "pole {ph} vs {p}");
        // the reported fit is that of the returned (full) model
        let sim = fit.model.simulate(&u).unwrap();
        let (f2, _) = crate::output_error::judge_fit(y.as_slice(), &sim, 0);
        assert!((f2 - fit.fit_percent).abs() < 1e-9);
        // refining the full model again keeps the integrator and does not get worse
        let again = crate::output_error(&u, &y, &fit.model, &s).unwrap();
        assert!(again.cost <= fit.cost * (1.0 + 1e-9));
        assert_eq!(count_integrators(&again.model.den), 1);
        // a start without the root at 1 is refused in words
        let bad = PolynomialModel::new(fit.model.num.clone(), vec![1.0, -0.9], None).unwrap();
        let e = crate::output_error(&u, &y, &bad, &s).unwrap_err();
        assert!(e.to_string().contains("z = 1"), "{e}");
    }

    #[test]
    fn a_fixed_integrator_that_the_data_do_not_show_is_cancelled_and_warned_about() {
        // A stable first-order lag, no integrator: forced to carry one, the best fit puts a
        // zero on it (G = b(1 − q⁻¹)/((1 − q⁻¹)(1 − p q⁻¹)) is the lag itself).
        let lag = PolynomialModel::new(vec![vec![0.0, 0.1]], vec![1.0, -0.9], Some(0.01)).unwrap();
        let u = staircase(7, 3000);
        let y0 = lag.simulate(&u).unwrap();
        let e = white(8, 3000, 1e-3, 1);
        let y = Signal::new(1, y0.iter().zip(e.as_slice()).map(|(a, b)| a + b).collect()).unwrap();
        let s = one_integrator();
        let fit = oe(&u, &y, &Orders::siso(1, 2, 1), &s).unwrap();
        let ratio = integrator_cancellation(&fit.model).unwrap();
        assert!(ratio < CANCELLATION, "|B(1)|/Σ|b| = {ratio}");
        // the zero −b₂/b₁ sits on the integrator
        let b = &fit.model.num[0];
        assert!((-b[2] / b[1] - 1.0).abs() < 0.1, "zero {}", -b[2] / b[1]);
        match &fit.warning {
            Some(w @ OeWarning::IntegratorCancelled { .. }) => {
                assert!(
                    w.to_string().contains("cancels the fixed integrator"),
                    "{w}"
                )
            }
            other => panic!("expected a cancellation warning, got {other:?}"),
        }
        // the real axis keeps its integrator: no warning (previous test) and a ratio of 1
        let (u, y, _) = axis_data(0.02);
        let fit = oe(&u, &y, &Orders::siso(1, 2, 1), &s).unwrap();
        assert!(integrator_cancellation(&fit.model).unwrap() > 0.5);
        // no integrator, no ratio
        assert_eq!(integrator_cancellation(&lag), None);
    }

    #[test]
    fn degenerate_fits_are_named() {
        use crate::output_error::judge_fit;
        let y: Vec<f64> = (0..100).map(|k| (k as f64 * 0.1).sin() + 2.0).collect();
        let mean = y.iter().sum::<f64>() / 100.0;
        // the mean itself: 0 %, not a warning
        let (f, w) = judge_fit(&y, &vec![mean; 100], 0);
        assert!(f.abs() < 1e-9 && w.is_none(), "{f} {w:?}");
        // the mirror image about the mean: error twice the spread, −100 %
        let mirror: Vec<f64> = y.iter().map(|v| 2.0 * mean - v).collect();
        let (f, w) = judge_fit(&y, &mirror, 0);
        assert!((f + 100.0).abs() < 1e-9);
        assert!(matches!(w, Some(OeWarning::WorseThanConstant { .. })));
        // an output that stays at zero
        let (_, w) = judge_fit(&y, &[0.0; 100], 0);
        assert!(matches!(w, Some(OeWarning::OutputNearZero { ratio, .. }) if ratio == 0.0));
        assert!(w.unwrap().to_string().contains("integrator"));
    }
}
