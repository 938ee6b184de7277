//! A static map in Fourier-feature form, the joint fit's periodic-kernel counterpart of
//! [`crate::GaussianFeatures`]:
//!
//! ```text
//!   N(z) = Σ_(j≥1) c_j·ψ_j(z) + a₀ + aᵀz,     D = Σ_(j≥1) c_j²/λ_j
//! ```
//!
//! ψ are the features of the paper's Fourier-series kernel on a fixed domain
//! ([`structid_core::FourierKernel`]: the data range mapped into [¼, ¾] of the period, cosines
//! and sines of the harmonics, tensor or additive over several inputs) and λ their weights, so
//! D is the kernel's RKHS norm and β means what it means in `identify` with a `fourier`
//! dispersion. The affine part is not penalised, as for the Gaussian features: it carries the
//! map's level and slope, and its extrapolation beyond the domain. The constant feature ψ₀ ≡ 1
//! is left out, since a₀ is the same regressor.
//!
//! Parameter order: c₁ … c_(m−1), a₀, a₁ … a_p (m the kernel's features).

use nalgebra::DMatrix;
use structid_core::{Combination, FeatureMap, FourierKernel, FourierWeights};

use crate::block::{BlockJacobian, BlockMap};
use crate::error::{Result, invalid};
use crate::features::{LinearInParameters, split_parameters};

/// A Fourier-feature map plus an unpenalised affine part.
#[derive(Clone, Debug, PartialEq)]
pub struct FourierFeatures {
    kernel: FourierKernel,
    beta: f64,
    coef: Vec<f64>,
    affine: Vec<f64>,
}

impl FourierFeatures {
    /// The features of `kernel` with dispersion weight β ≥ 0; all coefficients start at zero.
    pub fn new(kernel: FourierKernel, beta: f64) -> Result<Self> {
        if !(beta.is_finite() && beta >= 0.0) {
            return Err(invalid("beta", beta, "must be finite and not negative"));
        }
        let (m, p) = (kernel.dim(), kernel.inputs());
        Ok(Self {
            kernel,
            beta,
            coef: vec![0.0; m - 1],
            affine: vec![0.0; p + 1],
        })
    }

    /// A scalar input on the domain [lo, hi], the Gaussian-like weights of width σ (in units
    /// of z) and `harmonics` (by default, as many as the weights resolve).
    ///
    /// ```
    /// use structid_joint::{BlockMap, FourierFeatures, LinearInParameters};
    /// let f = FourierFeatures::on_interval(-2.0, 2.0, 0.4, Some(6), 1e-8).unwrap();
    /// assert_eq!(f.parameters().len(), 12 + 2); // 2·6 harmonics (ψ₀ is a₀) and a₁
    /// let z: Vec<Vec<f64>> = (0..81).map(|k| vec![-2.0 + 0.05 * k as f64]).collect();
    /// let w: Vec<f64> = z.iter().map(|z| z[0].tanh()).collect();
    /// let f = f.fitted_to(&z, &w).unwrap();
    /// assert!((f.eval(&mut [], &[0.7]) - 0.7f64.tanh()).abs() < 1e-3);
    /// ```
    ///
    /// # Errors
    /// A domain that is not finite and increasing, σ not positive, β negative.
    pub fn on_interval(
        lo: f64,
        hi: f64,
        sigma: f64,
        harmonics: Option<usize>,
        beta: f64,
    ) -> Result<Self> {
        if !(lo.is_finite() && hi.is_finite() && hi > lo) {
            return Err(invalid("interval", hi - lo, "needs finite lo < hi"));
        }
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(invalid(
                "sigma",
                sigma,
                "must be finite and greater than zero",
            ));
        }
        let kernel = FourierKernel::new(
            &FourierWeights::GaussianLike { sigma },
            harmonics,
            vec![(lo, hi)],
            Combination::Tensor,
        )?;
        Self::new(kernel, beta)
    }

    /// The feature map.
    pub fn kernel(&self) -> &FourierKernel {
        &self.kernel
    }

    /// The dispersion weight β.
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// The regressors [ψ₁(z) … ψ_(m−1)(z), 1, z₁ … z_p].
    fn features(&self, z: &[f64], out: &mut [f64]) {
        let m = self.coef.len();
        let mut psi = vec![0.0; m + 1];
        self.kernel.eval_into(z, &mut psi);
        out[..m].copy_from_slice(&psi[1..]);
        out[m] = 1.0;
        out[m + 1..].copy_from_slice(z);
    }

    /// N(z) from the kernel values `psi` = [ψ₀(z) … ψ_(m−1)(z)] at `z` (ψ₀ is the constant
    /// feature, which the affine part carries).
    fn value(&self, psi: &[f64], z: &[f64]) -> f64 {
        psi[1..]
            .iter()
            .zip(&self.coef)
            .map(|(a, b)| a * b)
            .sum::<f64>()
            + self.affine_value(z)
    }

    fn affine_value(&self, z: &[f64]) -> f64 {
        self.affine[0]
            + z.iter()
                .zip(&self.affine[1..])
                .map(|(a, b)| a * b)
                .sum::<f64>()
    }
}

impl LinearInParameters for FourierFeatures {
    fn input_count(&self) -> usize {
        self.kernel.inputs()
    }

    fn parameter_count(&self) -> usize {
        self.coef.len() + self.affine.len()
    }

    fn regressors(&self, z: &[f64], out: &mut [f64]) {
        self.features(z, out);
    }

    /// n·β·diag(1/λ_j), j ≥ 1.
    fn penalty(&self, points: usize) -> DMatrix<f64> {
        let n = points as f64;
        DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
            self.coef.len(),
            self.kernel.weights()[1..].iter().map(|l| self.beta * n / l),
        ))
    }

    fn with_fit(&self, coef: Vec<f64>, affine: Vec<f64>) -> Self {
        Self {
            coef,
            affine,
            ..self.clone()
        }
    }
}

impl BlockMap for FourierFeatures {
    fn kind(&self) -> &'static str {
        "fourier features"
    }

    fn input_len(&self) -> usize {
        self.kernel.inputs()
    }

    fn parameters(&self) -> Vec<f64> {
        self.coef.iter().chain(&self.affine).copied().collect()
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn BlockMap>> {
        let (coef, affine) = split_parameters(p, self.coef.len(), self.affine.len())?;
        Ok(Box::new(self.with_fit(coef, affine)))
    }

    fn eval(&self, _state: &mut [f64], z: &[f64]) -> f64 {
        let mut psi = vec![0.0; self.coef.len() + 1];
        self.kernel.eval_into(z, &mut psi);
        self.value(&psi, z)
    }

    fn eval_jacobian(&self, _state: &mut [f64], z: &[f64], jac: &mut BlockJacobian) -> f64 {
        let (m, p) = (self.coef.len(), z.len());
        let (mut psi, mut grad) = (vec![0.0; m + 1], vec![0.0; (m + 1) * p]);
        self.kernel.gradient_into(z, &mut psi, &mut grad);
        jac.dw_dp[..m].copy_from_slice(&psi[1..]);
        jac.dw_dp[m] = 1.0;
        jac.dw_dp[m + 1..].copy_from_slice(z);
        for (i, d) in jac.dw_dz.iter_mut().enumerate() {
            *d = self.affine[1 + i]
                + (0..m)
                    .map(|j| self.coef[j] * grad[(j + 1) * p + i])
                    .sum::<f64>();
        }
        self.value(&psi, z)
    }

    fn regulariser(&self) -> Option<DMatrix<f64>> {
        if self.beta == 0.0 {
            return None;
        }
        let m = self.coef.len();
        let mut r = DMatrix::zeros(m, m + self.affine.len());
        for (j, l) in self.kernel.weights()[1..].iter().enumerate() {
            r[(j, j)] = (self.beta / l).sqrt();
        }
        Some(r)
    }

    fn affine_part(&self) -> Option<(f64, Vec<f64>)> {
        Some((self.affine[0], self.affine[1..].to_vec()))
    }

    fn boxed(&self) -> Box<dyn BlockMap> {
        Box::new(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(combination: Combination) -> FourierFeatures {
        let k = FourierKernel::new(
            &FourierWeights::GaussianLike { sigma: 0.5 },
            Some(3),
            vec![(-1.0, 1.0), (0.0, 2.0)],
            combination,
        )
        .unwrap();
        let f = FourierFeatures::new(k, 0.2).unwrap();
        let n = f.parameters().len();
        let p: Vec<f64> = (0..n).map(|i| (1.3 * i as f64).sin()).collect();
        let b = f.with_parameters(&p).unwrap();
        FourierFeatures {
            coef: b.parameters()[..n - 3].to_vec(),
            affine: b.parameters()[n - 3..].to_vec(),
            ..f
        }
    }

    #[test]
    fn derivatives_match_finite_differences_for_tensor_and_additive_features() {
        for c in [Combination::Tensor, Combination::Additive] {
            let f = map(c);
            let z = [0.3, 1.4];
            let mut jac = BlockJacobian::for_map(&f);
            let v = f.eval_jacobian(&mut [], &z, &mut jac);
            assert!((v - f.eval(&mut [], &z)).abs() < 1e-14);
            let h = 1e-6;
            for i in 0..2 {
                let (mut a, mut b) = (z, z);
                a[i] += h;
                b[i] -= h;
                let fd = (f.eval(&mut [], &a) - f.eval(&mut [], &b)) / (2.0 * h);
                assert!(
                    (fd - jac.dw_dz[i]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{c:?} z{i}: {fd} vs {}",
                    jac.dw_dz[i]
                );
            }
            let p = f.parameters();
            for i in 0..p.len() {
                let (mut a, mut b) = (p.clone(), p.clone());
                a[i] += h;
                b[i] -= h;
                let fa = f.with_parameters(&a).unwrap().eval(&mut [], &z);
                let fb = f.with_parameters(&b).unwrap().eval(&mut [], &z);
                assert!(
                    ((fa - fb) / (2.0 * h) - jac.dw_dp[i]).abs() < 1e-7,
                    "{c:?} θ{i}"
                );
            }
        }
    }

    #[test]
    fn the_regulariser_squares_to_beta_times_the_kernel_norm_of_the_expansion() {
        // For f = Σ c_j ψ_j, ‖f‖² = Σ c_j²/λ_j; with c = Λ·ψ(z₀), f = K(·, z₀) and
        // ‖f‖² = K(z₀, z₀). The constant part λ₀ψ₀(z₀)ψ₀ is a₀'s, unpenalised.
        let f = FourierFeatures::on_interval(-1.0, 1.0, 0.3, Some(8), 0.7).unwrap();
        let z0 = [0.25];
        let mut psi = vec![0.0; f.kernel().dim()];
        f.kernel().eval_into(&z0, &mut psi);
        let w = f.kernel().weights();
        let mut theta: Vec<f64> = psi[1..].iter().zip(&w[1..]).map(|(p, l)| p * l).collect();
        theta.extend([0.0, 0.0]);
        let r = f.regulariser().unwrap();
        let norm = (&r * nalgebra::DVector::from_vec(theta)).norm_squared();
        let k = structid_core::Kernel::eval(f.kernel(), &z0, &z0) - w[0] * psi[0] * psi[0];
        assert!((norm - 0.7 * k).abs() < 1e-10 * k, "{norm} vs {}", 0.7 * k);
    }
}
