//! A static map in kernel-feature form on fixed centres, the joint fit's nonparametric map:
//!
//! ```text
//!   N(z) = Σ_j θ_j·K(z, c_j) + a₀ + aᵀz,       K(z, c) = (2πσ²)^(−p/2)·exp(−‖z − c‖²/2σ²)
//! ```
//!
//! K is the paper's Gaussian kernel, so the dispersion of the kernel part is its RKHS norm
//! D = θᵀ·K_cc·θ with K_cc the Gram matrix of the centres, and β means what it means in
//! `identify`. The affine part a₀ + aᵀz is not penalised: a map's level and slope are what a
//! linear model already has, and the kernel part describes the departure from it. Far from the
//! centres the map falls back to that affine part, which extrapolates a tank's outflow or a
//! spring better than a kernel sum decaying to zero.
//!
//! Parameter order: θ₁ … θ_m, a₀, a₁ … a_p. For a scalar input the trend may be a polynomial
//! of higher degree d ([`GaussianFeatures::with_trend_degree`]): a₀ + a₁z + … + a_d·z^d, the
//! order of the physics of a stiffness (a cubic spring carries on as a cubic where the data
//! end).

use nalgebra::{DMatrix, DVector};

use crate::block::{BlockJacobian, BlockMap};
use crate::error::{Result, invalid};

/// A Gaussian-kernel feature map on fixed centres plus an unpenalised affine part.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianFeatures {
    centres: Vec<Vec<f64>>,
    sigma: f64,
    beta: f64,
    theta: Vec<f64>,
    affine: Vec<f64>,
    degree: usize,
}

impl GaussianFeatures {
    /// Centres `centres` (m points of dimension p), width σ > 0 and dispersion weight β ≥ 0;
    /// all coefficients start at zero.
    ///
    /// ```
    /// use structid_joint::GaussianFeatures;
    /// assert!(GaussianFeatures::new(vec![vec![0.0], vec![1.0]], 0.5, 1e-3).is_ok());
    /// assert!(GaussianFeatures::new(vec![vec![0.0], vec![1.0, 2.0]], 0.5, 1e-3).is_err());
    /// assert!(GaussianFeatures::new(vec![vec![0.0]], 0.0, 1e-3).is_err());
    /// ```
    pub fn new(centres: Vec<Vec<f64>>, sigma: f64, beta: f64) -> Result<Self> {
        let p = centres.first().map_or(0, Vec::len);
        if centres.is_empty() || p == 0 {
            return Err(invalid(
                "centres",
                centres.len() as f64,
                "need at least one centre of dimension ≥ 1",
            ));
        }
        if let Some(bad) = centres.iter().position(|c| c.len() != p) {
            return Err(invalid(
                "centres",
                bad as f64,
                "every centre needs the first centre's dimension",
            ));
        }
        if centres.iter().flatten().any(|v| !v.is_finite()) {
            return Err(invalid("centres", f64::NAN, "centres must be finite"));
        }
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(invalid(
                "sigma",
                sigma,
                "must be finite and greater than zero",
            ));
        }
        if !(beta.is_finite() && beta >= 0.0) {
            return Err(invalid("beta", beta, "must be finite and not negative"));
        }
        let m = centres.len();
        Ok(Self {
            centres,
            sigma,
            beta,
            theta: vec![0.0; m],
            affine: vec![0.0; p + 1],
            degree: 1,
        })
    }

    /// The same map with an unpenalised polynomial trend of degree `d` ≥ 1 (scalar input only;
    /// new coefficients start at zero).
    ///
    /// ```
    /// use structid_joint::{BlockMap, GaussianFeatures};
    /// let f = GaussianFeatures::on_interval(-1.0, 1.0, 3, 0.5, 0.0).unwrap().with_trend_degree(3).unwrap();
    /// assert_eq!(f.parameters().len(), 3 + 4);
    /// let f = f.with_parameters(&[0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 2.0]).unwrap();
    /// assert_eq!(f.eval(&mut [], &[3.0]), 3.0 + 2.0 * 27.0);
    /// ```
    pub fn with_trend_degree(mut self, d: usize) -> Result<Self> {
        if d == 0 || (d > 1 && self.centres[0].len() != 1) {
            return Err(invalid(
                "trend degree",
                d as f64,
                "must be at least 1, and 1 for a map of several inputs",
            ));
        }
        self.degree = d;
        self.affine.resize(d + 1, 0.0);
        Ok(self)
    }

    /// `count` centres spread evenly over [lo, hi] for a scalar input.
    ///
    /// ```
    /// use structid_joint::GaussianFeatures;
    /// let f = GaussianFeatures::on_interval(0.0, 2.0, 3, 0.5, 0.0).unwrap();
    /// assert_eq!(f.centres(), &[vec![0.0], vec![1.0], vec![2.0]]);
    /// ```
    pub fn on_interval(lo: f64, hi: f64, count: usize, sigma: f64, beta: f64) -> Result<Self> {
        let centres = evenly_spaced(lo, hi, count)?
            .into_iter()
            .map(|c| vec![c])
            .collect();
        Self::new(centres, sigma, beta)
    }

    /// The centres.
    pub fn centres(&self) -> &[Vec<f64>] {
        &self.centres
    }

    /// The kernel width σ.
    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// The dispersion weight β.
    pub fn beta(&self) -> f64 {
        self.beta
    }

    fn kernel(&self, z: &[f64], c: &[f64]) -> f64 {
        let p = z.len() as f64;
        let s2 = self.sigma * self.sigma;
        let d2: f64 = z.iter().zip(c).map(|(a, b)| (a - b) * (a - b)).sum();
        (2.0 * std::f64::consts::PI * s2).powf(-p / 2.0) * (-d2 / (2.0 * s2)).exp()
    }

    /// The Gram matrix K_cc of the centres.
    pub(crate) fn gram(&self) -> DMatrix<f64> {
        let m = self.centres.len();
        DMatrix::from_fn(m, m, |i, j| self.kernel(&self.centres[i], &self.centres[j]))
    }

    /// The regressors [K(z, c_1) … K(z, c_m), 1, z₁ … z_p] of the parameters at `z`.
    pub(crate) fn features(&self, z: &[f64], out: &mut [f64]) {
        let m = self.centres.len();
        for (o, c) in out.iter_mut().zip(&self.centres) {
            *o = self.kernel(z, c);
        }
        if self.degree == 1 {
            out[m] = 1.0;
            out[m + 1..].copy_from_slice(z);
        } else {
            let mut power = 1.0;
            for o in &mut out[m..] {
                *o = power;
                power *= z[0];
            }
        }
    }

    /// The trend a₀ + a₁z (+ … + a_d·z^d) and its gradient in z.
    fn trend(&self, z: &[f64], grad: &mut [f64]) -> f64 {
        if self.degree == 1 {
            grad.copy_from_slice(&self.affine[1..]);
            return self.affine[0]
                + z.iter()
                    .zip(&self.affine[1..])
                    .map(|(a, b)| a * b)
                    .sum::<f64>();
        }
        let (mut value, mut slope, mut power) = (0.0, 0.0, 1.0);
        for (k, a) in self.affine.iter().enumerate() {
            value += a * power;
            if k + 1 < self.affine.len() {
                slope += (k + 1) as f64 * self.affine[k + 1] * power;
            }
            power *= z[0];
        }
        grad[0] = slope;
        value
    }
}

/// A block map linear in its parameters, N(z) = Σ_i θ_i·φ_i(z), whose dispersion is a
/// quadratic form in its first (penalised) parameters and leaves the trend after them free:
/// such a map is fitted to values, or through a linear operator, by one regularised
/// least-squares solve. What varies between maps is their regressors and their penalty.
pub trait LinearInParameters: Sized {
    /// Number p of the map's inputs.
    fn input_count(&self) -> usize;

    /// Number of parameters, the penalised ones first.
    fn parameter_count(&self) -> usize;

    /// The regressors φ(z) at the point `z` (`parameter_count` values into `out`).
    fn regressors(&self, z: &[f64], out: &mut [f64]);

    /// n·β times the dispersion's matrix over the penalised parameters, for n points.
    fn penalty(&self, points: usize) -> DMatrix<f64>;

    /// This map with the fitted parameters: the penalised ones, then the trend.
    fn with_fit(&self, penalised: Vec<f64>, trend: Vec<f64>) -> Self;

    /// The coefficients that fit the values `w` at the points `z` (one point per entry) in
    /// the least-squares sense with this map's dispersion:
    /// min Σ_k (N(z_k) − w_k)² + n·β·D, n the number of points (D = θᵀK_ccθ for
    /// [`GaussianFeatures`]). This is how an
    /// estimated map (a table, an interpolant) becomes a starting point of the joint fit.
    ///
    /// ```
    /// use structid_joint::{BlockMap, GaussianFeatures, LinearInParameters};
    /// let f = GaussianFeatures::on_interval(-2.0, 2.0, 9, 0.5, 1e-8).unwrap();
    /// let z: Vec<Vec<f64>> = (0..81).map(|k| vec![-2.0 + 0.05 * k as f64]).collect();
    /// let w: Vec<f64> = z.iter().map(|z| z[0].tanh()).collect();
    /// let f = f.fitted_to(&z, &w).unwrap();
    /// assert!((f.eval(&mut [], &[0.7]) - 0.7f64.tanh()).abs() < 1e-3);
    /// ```
    fn fitted_to(&self, z: &[Vec<f64>], w: &[f64]) -> Result<Self> {
        self.fitted_through(z, w, &mut |column| column.to_vec())
    }

    /// The coefficients for which the map's output seen through the linear operator `filter`
    /// fits `y`: min Σ_k (y_k − (H·N(z))_k)² + n·β·D, where `filter` applies H to one
    /// signal (a block G₂ behind the map, simulated from rest). N is linear in its
    /// coefficients, so H·N(z) is the sum of the filtered regressor columns and the fit is one
    /// least-squares solve; this is how a Hammerstein or Wiener–Hammerstein start gets its map.
    ///
    /// ```
    /// use structid_joint::{BlockMap, GaussianFeatures, LinearInParameters};
    /// // y = (0.5 + 0.5 q⁻¹)·tanh(z): the map is found behind the known filter.
    /// let f = GaussianFeatures::on_interval(-2.0, 2.0, 9, 0.5, 1e-10).unwrap();
    /// let z: Vec<Vec<f64>> = (0..300).map(|k| vec![2.0 * (0.37 * k as f64).sin()]).collect();
    /// let avg = |s: &[f64]| -> Vec<f64> {
    ///     (0..s.len()).map(|k| 0.5 * s[k] + if k > 0 { 0.5 * s[k - 1] } else { 0.0 }).collect()
    /// };
    /// let w: Vec<f64> = z.iter().map(|z| z[0].tanh()).collect();
    /// let f = f.fitted_through(&z, &avg(&w), &mut |s| avg(s)).unwrap();
    /// assert!((f.eval(&mut [], &[0.7]) - 0.7f64.tanh()).abs() < 1e-3);
    /// ```
    ///
    /// # Errors
    /// Mismatched lengths, non-finite values, or normal equations that are not positive
    /// definite.
    fn fitted_through(
        &self,
        z: &[Vec<f64>],
        y: &[f64],
        filter: &mut dyn FnMut(&[f64]) -> Vec<f64>,
    ) -> Result<Self> {
        let penalty = self.penalty(z.len());
        let (p, np) = (self.input_count(), self.parameter_count());
        let features = |zk: &[f64], row: &mut [f64]| self.regressors(zk, row);
        let (penalised, trend) = fit_linear_map(z, y, p, np, &features, filter, &penalty)?;
        Ok(self.with_fit(penalised, trend))
    }
}

impl LinearInParameters for GaussianFeatures {
    fn input_count(&self) -> usize {
        self.centres[0].len()
    }

    fn parameter_count(&self) -> usize {
        self.centres.len() + self.affine.len()
    }

    fn regressors(&self, z: &[f64], out: &mut [f64]) {
        self.features(z, out);
    }

    /// n·β·K_cc.
    fn penalty(&self, points: usize) -> DMatrix<f64> {
        self.gram() * (self.beta * points as f64)
    }

    fn with_fit(&self, theta: Vec<f64>, affine: Vec<f64>) -> Self {
        Self {
            theta,
            affine,
            ..self.clone()
        }
    }
}

/// `count` ≥ 2 points spread evenly over [lo, hi], both ends included: the centres of a
/// scalar feature map.
pub(crate) fn evenly_spaced(lo: f64, hi: f64, count: usize) -> Result<Vec<f64>> {
    if !(lo.is_finite() && hi.is_finite() && hi > lo) || count < 2 {
        return Err(invalid(
            "interval",
            hi - lo,
            "needs finite lo < hi and at least two centres",
        ));
    }
    let step = (hi - lo) / (count - 1) as f64;
    Ok((0..count).map(|j| lo + step * j as f64).collect())
}

/// A feature map's parameters `p` split into its m kernel coefficients and its `trend`
/// coefficients, after checking their count and that they are finite.
pub(crate) fn split_parameters(p: &[f64], m: usize, trend: usize) -> Result<(Vec<f64>, Vec<f64>)> {
    if p.len() != m + trend {
        return Err(invalid(
            "parameters",
            p.len() as f64,
            "wrong number of parameters for this feature map",
        ));
    }
    if let Some(v) = p.iter().find(|v| !v.is_finite()) {
        return Err(invalid("parameters", *v, "must be finite"));
    }
    Ok((p[..m].to_vec(), p[m..].to_vec()))
}

/// The columns φ_i(z_k) of the `np` regressors `features` writes at each point, after
/// checking the points (p inputs each, finite, one value each).
/// The fit of a map linear in its `np` parameters: the regressor columns of `features` at the
/// points `z`, seen through `filter`, fitted to `y` with `penalty` on the first
/// `penalty.nrows()` (the map's own) parameters; returns those and the affine rest apart.
pub(crate) fn fit_linear_map(
    z: &[Vec<f64>],
    y: &[f64],
    p: usize,
    np: usize,
    features: &dyn Fn(&[f64], &mut [f64]),
    filter: &mut dyn FnMut(&[f64]) -> Vec<f64>,
    penalty: &DMatrix<f64>,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let columns = regressor_columns(z, y, p, np, features)?;
    let sol = regularised_fit(columns, y, filter, penalty)?;
    let m = penalty.nrows();
    Ok((
        sol.rows(0, m).iter().copied().collect(),
        sol.rows(m, np - m).iter().copied().collect(),
    ))
}

pub(crate) fn regressor_columns(
    z: &[Vec<f64>],
    y: &[f64],
    p: usize,
    np: usize,
    features: &dyn Fn(&[f64], &mut [f64]),
) -> Result<Vec<Vec<f64>>> {
    if z.len() != y.len() || z.is_empty() {
        return Err(invalid(
            "points",
            z.len() as f64,
            "need as many values as points, and at least one",
        ));
    }
    let mut columns = vec![vec![0.0; z.len()]; np];
    let mut row = vec![0.0; np];
    for (k, (zk, &yk)) in z.iter().zip(y).enumerate() {
        if zk.len() != p || !yk.is_finite() || zk.iter().any(|v| !v.is_finite()) {
            return Err(invalid(
                "points",
                yk,
                "points need the map's input dimension and finite values",
            ));
        }
        features(zk, &mut row);
        for (c, r) in columns.iter_mut().zip(&row) {
            c[k] = *r;
        }
    }
    Ok(columns)
}

/// The coefficients of a map linear in them, w = Σ_i θ_i·φ_i(z), whose output seen through
/// `filter` fits `y`: the regressor `columns` φ_i(z_k) are filtered, and the normal equations
/// get `penalty` (m × m, already scaled) on the first m coefficients (the kernel part; the
/// trend is not penalised), plus a relative ridge of 10⁻¹⁰ that keeps the solve defined when
/// the points do not reach every feature.
pub(crate) fn regularised_fit(
    columns: Vec<Vec<f64>>,
    y: &[f64],
    filter: &mut dyn FnMut(&[f64]) -> Vec<f64>,
    penalty: &DMatrix<f64>,
) -> Result<DVector<f64>> {
    let (n, np, m) = (y.len(), columns.len(), penalty.nrows());
    let columns: Vec<Vec<f64>> = columns.iter().map(|c| filter(c)).collect();
    if columns.iter().any(|c| c.len() != n) {
        return Err(invalid(
            "filter",
            n as f64,
            "the filter must return a signal as long as its input",
        ));
    }
    let mut gram = DMatrix::from_fn(np, np, |i, j| {
        columns[i].iter().zip(&columns[j]).map(|(a, b)| a * b).sum()
    });
    let rhs = DVector::from_fn(np, |i, _| {
        columns[i].iter().zip(y).map(|(a, b)| a * b).sum()
    });
    let mut kk = gram.view_mut((0, 0), (m, m));
    kk += penalty;
    let ridge = 1e-10 * (0..np).map(|i| gram[(i, i)]).fold(1e-300, f64::max);
    for i in 0..np {
        gram[(i, i)] += ridge;
    }
    Ok(gram
        .cholesky()
        .ok_or_else(|| {
            invalid(
                "points",
                n as f64,
                "the fit's normal equations are not positive definite",
            )
        })?
        .solve(&rhs))
}

impl BlockMap for GaussianFeatures {
    fn kind(&self) -> &'static str {
        "gaussian features"
    }

    /// The map of a scalar input as an expression in `z0` (the syntax of
    /// [`structid_core::ExprMap`]): the sum of its kernels and its trend, exact to the
    /// printed digits, so that a written map keeps its fit and extrapolates with its trend.
    /// `None` for a map of several inputs or with a coefficient that is not finite.
    ///
    /// ```
    /// use structid_core::{ExprMap, Interpolant};
    /// use structid_joint::{BlockMap, GaussianFeatures};
    /// let f = GaussianFeatures::on_interval(-2.0, 2.0, 5, 1.0, 0.0).unwrap().with_trend_degree(3).unwrap();
    /// let f = f.with_parameters(&[0.3, -1.2, 0.5, 2.0, -0.7, 0.1, 1.0, 0.0, -0.25]).unwrap();
    /// let g = ExprMap::parse(&f.expression().unwrap(), 1).unwrap();
    /// for z in [-3.0, -0.4, 0.0, 1.7, 2.5] {
    ///     assert!((g.eval(&[z]) - f.eval(&mut [], &[z])).abs() < 1e-12);
    /// }
    /// ```
    fn expression(&self) -> Option<String> {
        let s2 = self.sigma * self.sigma;
        let scale = (2.0 * std::f64::consts::PI * s2).powf(-0.5);
        let finite = self.theta.iter().chain(&self.affine).all(|v| v.is_finite());
        if self.centres[0].len() != 1 || !finite || !scale.is_finite() {
            return None;
        }
        let kernels = self.theta.iter().zip(&self.centres).map(|(t, c)| {
            // Plain decimals (the parser reads no exponent), and the square inside the
            // negation (a leading minus binds tighter than ^).
            format!("({})*exp(-((z0-({}))^2)/({}))", t * scale, c[0], 2.0 * s2)
        });
        let trend = self
            .affine
            .iter()
            .enumerate()
            .map(|(k, a)| format!("({a})*z0^{k}"));
        Some(kernels.chain(trend).collect::<Vec<_>>().join(" + "))
    }

    fn input_len(&self) -> usize {
        self.centres[0].len()
    }

    fn parameters(&self) -> Vec<f64> {
        self.theta.iter().chain(&self.affine).copied().collect()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn BlockMap>> {
        let (theta, affine) = split_parameters(p, self.centres.len(), self.affine.len())?;
        Ok(Box::new(self.with_fit(theta, affine)))
    }

    fn eval(&self, _state: &mut [f64], z: &[f64]) -> f64 {
        let kernel: f64 = self
            .centres
            .iter()
            .zip(&self.theta)
            .map(|(c, t)| t * self.kernel(z, c))
            .sum();
        let mut grad = [0.0; 8];
        let trend = if z.len() <= grad.len() {
            self.trend(z, &mut grad[..z.len()])
        } else {
            self.trend(z, &mut vec![0.0; z.len()])
        };
        kernel + trend
    }

    fn eval_jacobian(&self, state: &mut [f64], z: &[f64], jac: &mut BlockJacobian) -> f64 {
        let m = self.centres.len();
        self.features(z, &mut jac.dw_dp);
        let s2 = self.sigma * self.sigma;
        self.trend(z, &mut jac.dw_dz);
        for ((c, t), k) in self.centres.iter().zip(&self.theta).zip(&jac.dw_dp[..m]) {
            for (d, (zi, ci)) in jac.dw_dz.iter_mut().zip(z.iter().zip(c)) {
                *d -= t * k * (zi - ci) / s2;
            }
        }
        self.eval(state, z)
    }

    fn regulariser(&self) -> Option<DMatrix<f64>> {
        if self.beta == 0.0 {
            return None;
        }
        let m = self.centres.len();
        let mut k = self.gram();
        // Gaussian Gram matrices are numerically singular: a relative jitter makes the
        // Cholesky factor exist, and changes D by a relative 1e-10 at most.
        let jitter = 1e-10 * (0..m).map(|i| k[(i, i)]).sum::<f64>() / m as f64;
        for i in 0..m {
            k[(i, i)] += jitter;
        }
        let l = k.cholesky()?.l();
        let mut r = DMatrix::zeros(m, m + self.affine.len());
        r.view_mut((0, 0), (m, m))
            .copy_from(&(l.transpose() * self.beta.sqrt()));
        Some(r)
    }

    fn affine_part(&self) -> Option<(f64, Vec<f64>)> {
        let p = self.centres[0].len();
        Some((self.affine[0], self.affine[1..=p].to_vec()))
    }

    fn boxed(&self) -> Box<dyn BlockMap> {
        Box::new(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_regulariser_squares_to_beta_times_the_rkhs_norm() {
        let f = GaussianFeatures::on_interval(-1.0, 1.0, 6, 0.4, 0.3).unwrap();
        let theta = [0.5, -1.0, 2.0, 0.1, -0.3, 0.7, 9.0, 4.0];
        let f = f.with_parameters(&theta).unwrap();
        let r = f.regulariser().unwrap();
        let rt = &r * DVector::from_column_slice(&theta);
        // θᵀKθ summed by hand from the kernel definition.
        let g = GaussianFeatures::on_interval(-1.0, 1.0, 6, 0.4, 0.3).unwrap();
        let mut d = 0.0;
        for i in 0..6 {
            for j in 0..6 {
                d += theta[i] * theta[j] * g.kernel(&g.centres[i], &g.centres[j]);
            }
        }
        assert!(
            (rt.norm_squared() - 0.3 * d).abs() < 1e-8 * d,
            "{} {}",
            rt.norm_squared(),
            0.3 * d
        );
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let centres = vec![vec![0.0, 0.0], vec![1.0, -0.5], vec![-0.4, 0.8]];
        let f = GaussianFeatures::new(centres, 0.7, 0.0).unwrap();
        let p = [0.3, -1.2, 0.8, 0.1, 0.5, -0.25];
        let f = f.with_parameters(&p).unwrap();
        let z = [0.2, 0.4];
        let mut jac = BlockJacobian::for_map(f.as_ref());
        f.eval_jacobian(&mut [], &z, &mut jac);
        let h = 1e-6;
        for i in 0..2 {
            let (mut a, mut b) = (z, z);
            a[i] += h;
            b[i] -= h;
            let fd = (f.eval(&mut [], &a) - f.eval(&mut [], &b)) / (2.0 * h);
            assert!(
                (fd - jac.dw_dz[i]).abs() < 1e-7,
                "z{i}: {fd} vs {}",
                jac.dw_dz[i]
            );
        }
        for i in 0..p.len() {
            let (mut a, mut b) = (p, p);
            a[i] += h;
            b[i] -= h;
            let fa = f.with_parameters(&a).unwrap().eval(&mut [], &z);
            let fb = f.with_parameters(&b).unwrap().eval(&mut [], &z);
            assert!(((fa - fb) / (2.0 * h) - jac.dw_dp[i]).abs() < 1e-7, "θ{i}");
        }
    }
}

#[cfg(test)]
mod trend_tests {
    use super::*;

    #[test]
    fn a_cubic_trend_has_exact_derivatives() {
        let f = GaussianFeatures::on_interval(-1.0, 1.0, 4, 0.5, 0.0)
            .unwrap()
            .with_trend_degree(3)
            .unwrap();
        let p = [0.3, -0.2, 0.5, 0.1, 0.2, -1.0, 0.4, 2.0];
        let f = f.with_parameters(&p).unwrap();
        let mut jac = BlockJacobian::for_map(f.as_ref());
        let z = [0.7];
        f.eval_jacobian(&mut [], &z, &mut jac);
        let h = 1e-6;
        let fd = (f.eval(&mut [], &[z[0] + h]) - f.eval(&mut [], &[z[0] - h])) / (2.0 * h);
        assert!((fd - jac.dw_dz[0]).abs() < 1e-7, "{fd} vs {}", jac.dw_dz[0]);
        // The trend's regressors are 1, z, z², z³.
        assert_eq!(&jac.dw_dp[4..], &[1.0, 0.7, 0.7 * 0.7, 0.7 * 0.7 * 0.7]);
        assert!(
            GaussianFeatures::new(vec![vec![0.0, 0.0]], 0.5, 0.0)
                .unwrap()
                .with_trend_degree(2)
                .is_err()
        );
    }
}
