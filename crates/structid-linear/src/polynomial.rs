//! MISO polynomial models with a common denominator, their simulation, stability test and
//! state-space realisation.

use nalgebra::DMatrix;
use structid_lti::{Signal, StateSpace, filter_row};

use crate::error::{LinearError, check_finite, check_sample_time};
use crate::orders::Orders;

/// A fitted polynomial model `y = Σ_i B_i(q)/A(q) u_i (+ noise)`, MISO, common denominator.
///
/// Coefficients are those of `1, q⁻¹, q⁻², …`. For an ARX model `den` is `A`, for an
/// output-error model it is `F`. `num[i]` includes the `nk[i]` leading zeros of the input
/// delay, so `num[i][j]` multiplies `u_{i,k−j}`.
///
/// The parameter vector used by [`parameters`](Self::parameters) and by the reported
/// standard deviations is `θ = (b_{0,0} … b_{0,nb₀−1}, b_{1,0} …, …, a_1 … a_na)`: the
/// numerator coefficients of every input without the delay zeros, then the denominator
/// without its leading 1.
///
/// ```
/// use structid_linear::PolynomialModel;
/// use structid_lti::Signal;
/// // y_k = 0.5 y_{k-1} + u_{k-1}
/// let m = PolynomialModel::new(vec![vec![0.0, 1.0]], vec![1.0, -0.5], None).unwrap();
/// let y = m.simulate(&Signal::new(1, vec![1.0, 0.0, 0.0, 0.0]).unwrap()).unwrap();
/// assert_eq!(y, vec![0.0, 1.0, 0.5, 0.25]);
/// assert_eq!(m.orders(), structid_linear::Orders::siso(1, 1, 1));
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PolynomialModel {
    /// Per input: numerator coefficients of `1, q⁻¹, …`, including the `nk` leading zeros.
    pub num: Vec<Vec<f64>>,
    /// Denominator `1, a_1, …, a_na` (for OE this is `F`).
    pub den: Vec<f64>,
    /// Sample time in seconds, if known.
    pub sample_time: Option<f64>,
}

impl PolynomialModel {
    /// A validated model (see [`validate`](Self::validate)): numerators first, then the
    /// common denominator, as [`TransferFunction::siso`](structid_lti::TransferFunction::siso)
    /// (and MATLAB's `tf(num, den)`).
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// assert!(PolynomialModel::new(vec![vec![1.0]], vec![1.0, -0.9], Some(0.01)).is_ok());
    /// assert!(PolynomialModel::new(vec![vec![1.0]], vec![0.0, 1.0], None).is_err());
    /// ```
    pub fn new(
        num: Vec<Vec<f64>>,
        den: Vec<f64>,
        sample_time: Option<f64>,
    ) -> Result<Self, LinearError> {
        let m = PolynomialModel {
            num,
            den,
            sample_time,
        };
        m.validate()?;
        Ok(m)
    }

    /// Builds a model of the given orders from the parameter vector
    /// `θ = (b…, a…)` (the order documented on [`PolynomialModel`]); the denominator gets its
    /// leading 1 and each numerator its `nk` leading zeros.
    ///
    /// ```
    /// use structid_linear::{Orders, PolynomialModel};
    /// let m = PolynomialModel::from_parameters(&Orders::siso(2, 2, 1), &[1.0, 0.5, -1.5, 0.7], None)
    ///     .unwrap();
    /// assert_eq!(m.den, vec![1.0, -1.5, 0.7]);
    /// assert_eq!(m.num, vec![vec![0.0, 1.0, 0.5]]);
    /// assert_eq!(m.parameters(), vec![1.0, 0.5, -1.5, 0.7]);
    /// ```
    pub fn from_parameters(
        orders: &Orders,
        theta: &[f64],
        sample_time: Option<f64>,
    ) -> Result<Self, LinearError> {
        orders.validate()?;
        if theta.len() != orders.parameters() {
            return Err(LinearError::dims(
                format!("parameter vector for orders {orders}"),
                orders.parameters(),
                theta.len(),
            ));
        }
        let (den, num) = split_parameters(orders, theta);
        Self::new(num, den, sample_time)
    }

    /// The parameter vector `θ = (b…, a…)` of this model for its [`orders`](Self::orders)
    /// (coefficients normalised by `den[0]`).
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// let m = PolynomialModel::new(vec![vec![0.0, 4.0]], vec![2.0, 1.0], None).unwrap();
    /// assert_eq!(m.parameters(), vec![2.0, 0.5]);
    /// ```
    pub fn parameters(&self) -> Vec<f64> {
        let orders = self.orders();
        let a0 = self.den.first().copied().unwrap_or(1.0);
        let mut theta = Vec::with_capacity(orders.parameters());
        for (b, &nb) in self.num.iter().zip(&orders.nb) {
            theta.extend(b[b.len() - nb..].iter().map(|v| v / a0));
        }
        theta.extend(self.den.iter().skip(1).map(|v| v / a0));
        theta
    }

    /// Checks the model: a non-empty denominator with nonzero leading coefficient, at least
    /// one input, finite coefficients and a positive finite sample time (if any).
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// let m = PolynomialModel { num: vec![vec![f64::NAN]], den: vec![1.0], sample_time: None };
    /// assert!(m.validate().is_err());
    /// ```
    pub fn validate(&self) -> Result<(), LinearError> {
        let Some(&a0) = self.den.first() else {
            return Err(LinearError::InvalidModel("the denominator is empty".into()));
        };
        if a0 == 0.0 {
            return Err(LinearError::InvalidModel(
                "the leading denominator coefficient is zero".into(),
            ));
        }
        if self.num.is_empty() {
            return Err(LinearError::InvalidModel(
                "the model has no input (num is empty)".into(),
            ));
        }
        if let Some(j) = self.den.iter().position(|v| !v.is_finite()) {
            return Err(LinearError::InvalidModel(format!(
                "denominator coefficient {j} is not finite ({})",
                self.den[j]
            )));
        }
        for (i, b) in self.num.iter().enumerate() {
            if let Some(j) = b.iter().position(|v| !v.is_finite()) {
                return Err(LinearError::InvalidModel(format!(
                    "numerator coefficient {j} of input {i} is not finite ({})",
                    b[j]
                )));
            }
        }
        check_sample_time(self.sample_time)
    }

    /// Number of inputs (`num.len()`).
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// let m = PolynomialModel::new(vec![vec![1.0], vec![0.0, 2.0]], vec![1.0], None).unwrap();
    /// assert_eq!(m.inputs(), 2);
    /// ```
    pub fn inputs(&self) -> usize {
        self.num.len()
    }

    /// The orders of this model: `na = den.len() − 1`, `nk[i]` = number of leading exact
    /// zeros of `num[i]`, `nb[i] = num[i].len() − nk[i]` (an all-zero numerator gives
    /// `nb = 0`).
    ///
    /// ```
    /// use structid_linear::{Orders, PolynomialModel};
    /// let m = PolynomialModel::new(vec![vec![0.0, 0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], None).unwrap();
    /// assert_eq!(m.orders(), Orders::siso(2, 2, 2));
    /// ```
    pub fn orders(&self) -> Orders {
        let mut nb = Vec::with_capacity(self.num.len());
        let mut nk = Vec::with_capacity(self.num.len());
        for b in &self.num {
            let k = b.iter().position(|&v| v != 0.0).unwrap_or(b.len());
            nk.push(if k == b.len() { 0 } else { k });
            nb.push(b.len() - k);
        }
        Orders {
            na: self.den.len().saturating_sub(1),
            nb,
            nk,
        }
    }

    /// `true` when every root of the denominator `z^na + a_1 z^{na−1} + … + a_na` lies
    /// strictly inside the unit circle (Schur–Cohn step-down test; `na = 0` is stable).
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// let stable = PolynomialModel::new(vec![vec![1.0]], vec![1.0, -1.5, 0.7], None).unwrap();
    /// let unstable = PolynomialModel::new(vec![vec![1.0]], vec![1.0, -2.1, 1.1], None).unwrap();
    /// assert!(stable.is_stable() && !unstable.is_stable());
    /// ```
    pub fn is_stable(&self) -> bool {
        self.validate().is_ok() && schur_stable(&self.den)
    }

    /// Largest modulus of the denominator's roots (eigenvalues of its companion matrix);
    /// 0 when `na = 0`.
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// // (1 - 0.5 q^-1)(1 - 0.8 q^-1)
    /// let m = PolynomialModel::new(vec![vec![1.0]], vec![1.0, -1.3, 0.4], None).unwrap();
    /// assert!((m.spectral_radius() - 0.8).abs() < 1e-12);
    /// ```
    pub fn spectral_radius(&self) -> f64 {
        root_radius(&self.den)
    }

    /// Frequency response `G_i(e^{jω}) = B_i(e^{−jω}) / A(e^{−jω})` of input `input` at the
    /// normalised frequency `f` in cycles per sample (`ω = 2π f`), as `(re, im)`.
    /// Returns `None` when `input` is out of range.
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// // y_k = u_{k-1}: a pure delay, G = e^{-jω}
    /// let m = PolynomialModel::new(vec![vec![0.0, 1.0]], vec![1.0], None).unwrap();
    /// let (re, im) = m.frequency_response(0, 0.25).unwrap();
    /// assert!(re.abs() < 1e-15 && (im + 1.0).abs() < 1e-15);
    /// ```
    pub fn frequency_response(&self, input: usize, f: f64) -> Option<(f64, f64)> {
        let b = self.num.get(input)?;
        let w = 2.0 * std::f64::consts::PI * f;
        let eval = |c: &[f64]| {
            c.iter().enumerate().fold((0.0, 0.0), |(re, im), (j, v)| {
                let phi = -w * j as f64;
                (re + v * phi.cos(), im + v * phi.sin())
            })
        };
        let (nr, ni) = eval(b);
        let (dr, di) = eval(&self.den);
        let d2 = dr * dr + di * di;
        Some(((nr * dr + ni * di) / d2, (ni * dr - nr * di) / d2))
    }

    /// State-space realisation with one output, `inputs()` inputs and the sample time kept.
    ///
    /// Observable canonical form of the common denominator, order
    /// `n = max(na, max_i num[i].len() − 1)`: `A` has `−a_1 … −a_n` in its first column and
    /// ones on the superdiagonal, `B[r, i] = b_{i,r+1} − b_{i,0} a_{r+1}`, `C = e_1ᵀ`,
    /// `D[0, i] = b_{i,0}` (coefficients normalised by `den[0]`, missing ones are 0).
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// use structid_lti::LinearSystem;
    /// let m = PolynomialModel::new(vec![vec![0.0, 1.0, 0.5]], vec![1.0, -1.5, 0.7], Some(0.1)).unwrap();
    /// let ss = m.to_state_space().unwrap();
    /// assert_eq!((ss.order(), ss.inputs(), ss.outputs()), (2, 1, 1));
    /// assert_eq!(ss.sample_time(), Some(0.1));
    /// let u = structid_lti::Signal::from_fn(20, 1, |k, _| (k as f64 * 0.3).sin());
    /// let y_ss = ss.simulate(&u).unwrap();
    /// let y_pm = m.simulate(&u).unwrap();
    /// assert!(y_ss.as_slice().iter().zip(&y_pm).all(|(a, b)| (a - b).abs() < 1e-12));
    /// ```
    pub fn to_state_space(&self) -> Result<StateSpace, LinearError> {
        self.validate()?;
        let ss = structid_lti::realise_row(&self.num, &self.den)?;
        Ok(match self.sample_time {
            Some(ts) => ss.with_sample_time(ts)?,
            None => ss,
        })
    }

    /// Simulates `y_k = Σ_i Σ_j b_{i,j} u_{i,k−j} − Σ_{j≥1} a_j y_{k−j}` from zero initial
    /// conditions (by recursion, `O(L·(na + Σ nb))`). `u` needs `inputs()` channels and
    /// finite values; an unstable model may overflow to infinities.
    ///
    /// ```
    /// use structid_linear::PolynomialModel;
    /// use structid_lti::Signal;
    /// let m = PolynomialModel::new(vec![vec![1.0], vec![0.0, 2.0]], vec![1.0], None).unwrap();
    /// let u = Signal::new(2, vec![1.0, 1.0, 0.0, 0.0]).unwrap();
    /// assert_eq!(m.simulate(&u).unwrap(), vec![1.0, 2.0]);
    /// ```
    pub fn simulate(&self, u: &Signal) -> Result<Vec<f64>, LinearError> {
        self.validate()?;
        if u.channels() != self.inputs() {
            return Err(LinearError::dims(
                "input channels of the simulated signal",
                self.inputs(),
                u.channels(),
            ));
        }
        check_finite("input", u.as_slice(), u.channels())?;
        let cols: Vec<Vec<f64>> = (0..u.channels()).map(|c| u.channel(c)).collect();
        let a0 = self.den[0];
        let den: Vec<f64> = self.den.iter().map(|v| v / a0).collect();
        let num: Vec<Vec<f64>> = self
            .num
            .iter()
            .map(|b| b.iter().map(|v| v / a0).collect())
            .collect();
        let mut y = vec![0.0; u.len()];
        filter_row(&num, &den, &cols, &mut y);
        Ok(y)
    }
}

/// Schur–Cohn (step-down) stability test of `den[0] + den[1] z^{-1} + …`: `true` iff every
/// root of `den[0] z^n + … + den[n]` lies strictly inside the unit circle.
pub(crate) fn schur_stable(den: &[f64]) -> bool {
    let Some(&a0) = den.first() else {
        return false;
    };
    if a0 == 0.0 || den.iter().any(|v| !v.is_finite()) {
        return false;
    }
    let mut p: Vec<f64> = den.iter().map(|v| v / a0).collect();
    // trailing zeros are roots at the origin
    while p.len() > 1 && p[p.len() - 1] == 0.0 {
        p.pop();
    }
    let mut q = vec![0.0; p.len()];
    for m in (1..p.len()).rev() {
        let k = p[m];
        if k.is_nan() || k.abs() >= 1.0 {
            return false;
        }
        let s = 1.0 - k * k;
        for i in 0..m {
            q[i] = (p[i] - k * p[m - i]) / s;
        }
        p[..m].copy_from_slice(&q[..m]);
        p.truncate(m);
    }
    true
}

/// Largest root modulus of `den[0] z^n + … + den[n]` via companion-matrix eigenvalues.
pub(crate) fn root_radius(den: &[f64]) -> f64 {
    let Some(&a0) = den.first() else {
        return f64::NAN;
    };
    let n = den.len() - 1;
    if n == 0 {
        return 0.0;
    }
    if a0 == 0.0 || den.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    let mut c = DMatrix::zeros(n, n);
    for j in 0..n {
        c[(0, j)] = -den[j + 1] / a0;
        if j + 1 < n {
            c[(j + 1, j)] = 1.0;
        }
    }
    c.complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}

/// Splits `θ = (b…, a…)` of the given orders into the denominator (with its leading 1) and
/// the numerators (each with its `nk` leading zeros); `theta` has `orders.parameters()`
/// entries.
pub(crate) fn split_parameters(orders: &Orders, theta: &[f64]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut off = 0;
    let mut num = Vec::with_capacity(orders.inputs());
    for (&nb, &nk) in orders.nb.iter().zip(&orders.nk) {
        let mut b = vec![0.0; nk];
        b.extend_from_slice(&theta[off..off + nb]);
        off += nb;
        num.push(b);
    }
    let mut den = vec![1.0];
    den.extend_from_slice(&theta[off..]);
    (den, num)
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_lti::LinearSystem;

    fn poly_from_roots(roots: &[f64]) -> Vec<f64> {
        let mut p = vec![1.0];
        for r in roots {
            let mut q = p.clone();
            q.push(0.0);
            for j in 1..q.len() {
                q[j] -= r * p[j - 1];
            }
            p = q;
        }
        p
    }

    #[test]
    fn schur_cohn_agrees_with_eigenvalues() {
        for roots in [
            vec![0.5, -0.3, 0.99],
            vec![1.01, 0.2],
            vec![-1.0],
            vec![0.0, 0.0, 0.9],
            vec![0.95, 0.95, 0.95],
        ] {
            let den = poly_from_roots(&roots);
            let rmax = roots.iter().fold(0.0f64, |a, r| a.max(r.abs()));
            assert_eq!(schur_stable(&den), rmax < 1.0, "{roots:?}");
            assert!((root_radius(&den) - rmax).abs() < 1e-4, "{roots:?}");
        }
        // complex pair of modulus sqrt(0.7)
        assert!(schur_stable(&[1.0, -1.5, 0.7]));
        assert!((root_radius(&[1.0, -1.5, 0.7]) - 0.7f64.sqrt()).abs() < 1e-12);
        assert!(!schur_stable(&[1.0, -1.5, 1.0]));
        assert!(schur_stable(&[2.0]));
        assert!(!schur_stable(&[]));
    }

    #[test]
    fn state_space_matches_simulation_miso_with_feedthrough() {
        let m = PolynomialModel::new(
            vec![vec![1.0, 0.5], vec![0.0, 0.0, 0.0, 1.0, -0.4]],
            vec![2.0, -1.0, 0.3],
            None,
        )
        .unwrap();
        let u = Signal::from_fn(50, 2, |k, c| ((k * (c + 2)) as f64 * 0.37).sin());
        let y = m.simulate(&u).unwrap();
        let ss = m.to_state_space().unwrap();
        assert_eq!(ss.order(), 4);
        let y2 = ss.simulate(&u).unwrap();
        for (a, b) in y.iter().zip(y2.as_slice()) {
            assert!((a - b).abs() < 1e-12);
        }
        assert_eq!(m.orders(), Orders::new(2, vec![2, 2], vec![0, 3]).unwrap());
        // static model
        let g = PolynomialModel::new(vec![vec![3.0]], vec![1.0], None).unwrap();
        assert_eq!(g.to_state_space().unwrap().order(), 0);
    }

    #[test]
    fn parameters_round_trip_and_serde() {
        let o = Orders::new(2, vec![2, 1], vec![1, 0]).unwrap();
        let theta = [1.0, 0.5, -2.0, -1.5, 0.7];
        let m = PolynomialModel::from_parameters(&o, &theta, Some(0.5)).unwrap();
        assert_eq!(m.orders(), o);
        assert_eq!(m.parameters(), theta.to_vec());
        let json = serde_json::to_string(&m).unwrap();
        let back: PolynomialModel = serde_json::from_str(&json).unwrap();
        assert_eq!(back, m);
        assert!(PolynomialModel::from_parameters(&o, &theta[..4], None).is_err());
    }

    #[test]
    fn simulate_checks_inputs() {
        let m = PolynomialModel::new(vec![vec![1.0]], vec![1.0, -0.5], None).unwrap();
        assert!(matches!(
            m.simulate(&Signal::zeros(5, 2)),
            Err(LinearError::DimensionMismatch { .. })
        ));
        let u = Signal::new(1, vec![0.0, f64::NAN]).unwrap();
        assert!(matches!(
            m.simulate(&u),
            Err(LinearError::NonFinite { sample: 1, .. })
        ));
        let bad = PolynomialModel {
            num: vec![vec![1.0]],
            den: vec![],
            sample_time: None,
        };
        assert!(!bad.is_stable());
        assert!(bad.to_state_space().is_err());
    }
}
