//! The Fourier-series kernel (paper section 4): a kernel with finitely many features.
//!
//! Each input's domain Ω = [a, b] is mapped affinely into [0, 1] with a margin of ¼ on each side,
//! t = ¼ + ½·(z − a)/(b − a). The data therefore occupy [¼, ¾], and the periodic wrap-around
//! distance between the ends of the data (½) is never shorter than their direct distance, so
//! the periodic kernel does not tie N(a) to N(b) more than their separation warrants.
//!
//! In one input, K(t₁, t₂) = λ₀ + Σ_{n=1..N} 2λ_n·cos(2πn(t₁ − t₂)), with the real features
//! φ(t) = [√λ₀, √(2λ_n)·cos(2πnt), √(2λ_n)·sin(2πnt)], i.e. K = φ(t₁)ᵀφ(t₂). Several inputs use
//! the tensor product of the per-input series (guarded by a feature budget) or, optionally, the
//! additive kernel K = Σ_j K_j(t_j).
//!
//! Weight families:
//! * Gaussian-like, λ_n = s·exp(−2π²σ_t²n²) with σ_t = s·σ and s = ½/(b − a): the periodised
//!   Gaussian with the paper's normalisation, so σ and β mean what they mean for
//!   [`crate::GaussianKernel`] (away from the domain edges);
//! * Sobolev-like, λ_n = c·(1 + n²)^(−s);
//! * a user-supplied sequence λ₀, …, λ_N.

use std::f64::consts::PI;
use std::ops::Range;
use std::sync::Arc;

use rayon::prelude::*;
use structid_lti::Signal;

use crate::dispersion::kernel::Kernel;
use crate::dispersion::{
    Dispersion, FeatureMap, Penalty, QuadraticPenalty, eval_cols_by_rows, eval_rows_by_sample,
};
use crate::error::{Error, Result, positive_finite};
use crate::model::interpolant::Interpolant;

/// Margin on each side of the data inside the periodic unit interval.
pub const DOMAIN_MARGIN: f64 = 0.25;

/// Largest number of features a Fourier dispersion may create.
pub const MAX_FEATURES: usize = 8192;

/// How the weights λ_n are chosen.
#[derive(Clone, Debug, PartialEq)]
pub enum FourierWeights {
    /// The periodised Gaussian of width `sigma` (in units of z), normalised like the paper's
    /// Gaussian kernel.
    GaussianLike {
        /// Width σ in units of z.
        sigma: f64,
    },
    /// λ_n = scale·(1 + n²)^(−order).
    SobolevLike {
        /// Smoothness s (> ½).
        order: f64,
        /// Overall scale c.
        scale: f64,
    },
    /// λ₀, …, λ_N given directly (all ≥ 0, λ₀ > 0).
    Custom(Vec<f64>),
}

/// How several inputs are combined.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Combination {
    /// Tensor product of the per-input series: all interactions, (2N+1)^p features.
    #[default]
    Tensor,
    /// Additive: N(z) = Σ_j N_j(z_j), p·2N + 1 features.
    Additive,
}

/// Settings of a Fourier-series dispersion; the domain and the kernel are fixed when the data
/// are seen ([`Dispersion::penalty`]).
///
/// ```
/// use structid_core::{Dispersion, FourierDispersion, FourierWeights};
/// let d = FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.2 }).unwrap();
/// assert!(d.describe().starts_with("fourier"));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct FourierDispersion {
    weights: FourierWeights,
    harmonics: Option<usize>,
    domain: Option<Vec<(f64, f64)>>,
    combination: Combination,
}

impl FourierDispersion {
    /// A Fourier dispersion with the given weight family; harmonics chosen from the weights'
    /// decay (down to 1e-12 of λ₀, at most 512) and the domain from the data range.
    pub fn new(weights: FourierWeights) -> Result<Self> {
        match &weights {
            FourierWeights::GaussianLike { sigma } => {
                positive_finite("sigma", *sigma)?;
            }
            FourierWeights::SobolevLike { order, scale } => {
                positive_finite("scale", *scale)?;
                if !(order.is_finite() && *order > 0.5) {
                    return Err(Error::InvalidParameter {
                        name: "order".into(),
                        value: *order,
                        reason: "the Sobolev order must exceed 1/2 for a continuous kernel".into(),
                    });
                }
            }
            FourierWeights::Custom(l) => {
                if l.is_empty() || l.iter().any(|v| !v.is_finite() || *v < 0.0) || l[0] <= 0.0 {
                    return Err(Error::InvalidParameter {
                        name: "weights".into(),
                        value: l.first().copied().unwrap_or(f64::NAN),
                        reason: "custom weights need λ₀ > 0 and finite λ_n ≥ 0".into(),
                    });
                }
            }
        }
        Ok(Self {
            weights,
            harmonics: None,
            domain: None,
            combination: Combination::Tensor,
        })
    }

    /// Uses exactly `n` harmonics per input (ignored for custom weights, whose length rules).
    pub fn with_harmonics(mut self, n: usize) -> Self {
        self.harmonics = Some(n);
        self
    }

    /// Fixes the domain [a_j, b_j] of each input instead of taking the data range.
    pub fn with_domain(mut self, domain: Vec<(f64, f64)>) -> Result<Self> {
        if domain
            .iter()
            .any(|(a, b)| !(a.is_finite() && b.is_finite() && b > a))
        {
            return Err(Error::InvalidStructure(
                "a Fourier domain needs finite bounds with lower < upper for every input".into(),
            ));
        }
        self.domain = Some(domain);
        Ok(self)
    }

    /// Chooses how several inputs are combined.
    pub fn with_combination(mut self, c: Combination) -> Self {
        self.combination = c;
        self
    }

    /// Builds the concrete kernel for inputs with the given sample range per input.
    pub fn kernel_for(&self, z: &Signal) -> Result<FourierKernel> {
        let p = z.channels();
        let domain: Vec<(f64, f64)> = match &self.domain {
            Some(d) if d.len() == p => d.clone(),
            Some(d) => {
                return Err(Error::DimensionMismatch {
                    what: "Fourier domain".into(),
                    expected: format!("{p} interval(s)"),
                    found: d.len().to_string(),
                });
            }
            None => (0..p)
                .map(|c| {
                    let (lo, hi) =
                        (0..z.len()).fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), k| {
                            let v = z.get(k, c);
                            (l.min(v), h.max(v))
                        });
                    if hi > lo {
                        (lo, hi)
                    } else {
                        (lo - 0.5, lo + 0.5)
                    }
                })
                .collect(),
        };
        FourierKernel::new(&self.weights, self.harmonics, domain, self.combination)
    }
}

impl Dispersion for FourierDispersion {
    fn describe(&self) -> String {
        let w = match &self.weights {
            FourierWeights::GaussianLike { sigma } => format!("gaussian-like, sigma={sigma}"),
            FourierWeights::SobolevLike { order, scale } => {
                format!("sobolev-like, order={order}, scale={scale}")
            }
            FourierWeights::Custom(l) => format!("custom, {} weights", l.len()),
        };
        format!("fourier({w})")
    }

    fn parameters(&self) -> Vec<(String, f64)> {
        match &self.weights {
            FourierWeights::GaussianLike { sigma } => vec![("sigma".into(), *sigma)],
            FourierWeights::SobolevLike { order, scale } => {
                vec![("order".into(), *order), ("scale".into(), *scale)]
            }
            FourierWeights::Custom(_) => Vec::new(),
        }
    }

    fn width(&self) -> Option<f64> {
        match self.weights {
            FourierWeights::GaussianLike { sigma } => Some(sigma),
            _ => None,
        }
    }

    fn with_width(&self, width: f64) -> Option<Result<Arc<dyn Dispersion>>> {
        match self.weights {
            FourierWeights::GaussianLike { .. } => {
                Some(positive_finite("sigma", width).map(|sigma| {
                    Arc::new(Self {
                        weights: FourierWeights::GaussianLike { sigma },
                        ..self.clone()
                    }) as Arc<dyn Dispersion>
                }))
            }
            _ => None,
        }
    }

    fn penalty(&self, z: &Signal) -> Result<Penalty> {
        Ok(FeaturePenalty::of(self.kernel_for(z)?, z))
    }
}

/// The Fourier-series kernel on a fixed domain: a [`Kernel`] with an explicit [`FeatureMap`].
#[derive(Clone, Debug, PartialEq)]
pub struct FourierKernel {
    /// Per input: (offset, scale) with t = offset + scale·z.
    affine: Vec<(f64, f64)>,
    /// Per input: λ₀..λ_N.
    lambda: Vec<Vec<f64>>,
    combination: Combination,
    /// Feature weights (diagonal of Λ) in feature order.
    weights: Vec<f64>,
    /// For tensor features: the multi-index (harmonic, cos/sin) per input of each feature.
    index: Vec<Vec<(usize, u8)>>,
    /// Whether λ is the Gaussian-like family (so another width only changes the weights).
    gaussian_like: bool,
}

/// The Gaussian-like weights λ_n = s·exp(−2π²(s·σ)²n²), n = 0..=harmonics.
fn gaussian_like_lambda(s: f64, sigma: f64, harmonics: usize) -> Vec<f64> {
    let st = s * sigma;
    (0..=harmonics)
        .map(|k| s * (-2.0 * PI * PI * st * st * (k * k) as f64).exp())
        .collect()
}

/// The diagonal of Λ in feature order from the per-input weights.
fn feature_weights(
    lambda: &[Vec<f64>],
    combination: Combination,
    index: &[Vec<(usize, u8)>],
) -> Vec<f64> {
    match combination {
        Combination::Tensor => index
            .iter()
            .map(|mi| {
                mi.iter()
                    .zip(lambda)
                    .map(|(&(h, _), l)| if h == 0 { l[0] } else { 2.0 * l[h] })
                    .product()
            })
            .collect(),
        Combination::Additive => {
            let mut w = vec![lambda.iter().map(|l| l[0]).sum()];
            for l in lambda {
                for &lh in &l[1..] {
                    w.push(2.0 * lh);
                    w.push(2.0 * lh);
                }
            }
            w
        }
    }
}

fn harmonic_count(weights: &FourierWeights, harmonics: Option<usize>, s: f64) -> usize {
    match (weights, harmonics) {
        (FourierWeights::Custom(l), _) => l.len() - 1,
        (_, Some(n)) => n,
        (FourierWeights::GaussianLike { sigma }, None) => {
            let st = s * sigma;
            // exp(−2π²σ_t²N²) < 1e-12
            ((27.64 / (2.0 * PI * PI * st * st)).sqrt().ceil() as usize).clamp(1, 512)
        }
        (FourierWeights::SobolevLike { order, .. }, None) => {
            // (1 + N²)^(−s) < 1e-12
            (1e12f64.powf(1.0 / order).sqrt().ceil() as usize).clamp(1, 512)
        }
    }
}

impl FourierKernel {
    /// Builds the kernel for the given domain (one interval per input).
    pub fn new(
        weights: &FourierWeights,
        harmonics: Option<usize>,
        domain: Vec<(f64, f64)>,
        combination: Combination,
    ) -> Result<Self> {
        let weights_family = weights;
        let p = domain.len();
        if p == 0 {
            return Err(Error::InvalidStructure(
                "a Fourier kernel needs at least one input".into(),
            ));
        }
        let mut affine = Vec::with_capacity(p);
        let mut lambda = Vec::with_capacity(p);
        for &(a, b) in &domain {
            let s = (1.0 - 2.0 * DOMAIN_MARGIN) / (b - a);
            affine.push((DOMAIN_MARGIN - s * a, s));
            let n = harmonic_count(weights, harmonics, s);
            let l: Vec<f64> = match weights {
                FourierWeights::GaussianLike { sigma } => gaussian_like_lambda(s, *sigma, n),
                FourierWeights::SobolevLike { order, scale } => (0..=n)
                    .map(|k| scale * (1.0 + (k * k) as f64).powf(-order))
                    .collect(),
                FourierWeights::Custom(l) => l.clone(),
            };
            lambda.push(l);
        }
        let index = match combination {
            Combination::Tensor => {
                let count: usize = lambda.iter().map(|l| 2 * l.len() - 1).product();
                if count > MAX_FEATURES {
                    return Err(Error::InvalidStructure(format!(
                        "the tensor-product Fourier kernel would need {count} features (more than {MAX_FEATURES}); \
                         use fewer harmonics, a wider sigma, or the additive combination"
                    )));
                }
                let mut idx: Vec<Vec<(usize, u8)>> = vec![Vec::new()];
                for l in &lambda {
                    let mut next = Vec::with_capacity(idx.len() * (2 * l.len() - 1));
                    for prefix in &idx {
                        for h in 0..l.len() {
                            for kind in if h == 0 { 0..1 } else { 0..2 } {
                                let mut v = prefix.clone();
                                v.push((h, kind));
                                next.push(v);
                            }
                        }
                    }
                    idx = next;
                }
                idx
            }
            Combination::Additive => {
                let count = 1 + lambda.iter().map(|l| 2 * (l.len() - 1)).sum::<usize>();
                if count > MAX_FEATURES {
                    return Err(Error::InvalidStructure(format!(
                        "the Fourier kernel would need {count} features (more than {MAX_FEATURES})"
                    )));
                }
                Vec::new()
            }
        };
        let weights = feature_weights(&lambda, combination, &index);
        Ok(Self {
            affine,
            lambda,
            combination,
            weights,
            index,
            gaussian_like: matches!(weights_family, FourierWeights::GaussianLike { .. }),
        })
    }

    /// Number of inputs p.
    pub fn inputs(&self) -> usize {
        self.affine.len()
    }

    pub(crate) fn to_stored(&self) -> crate::stored::FourierStored {
        crate::stored::FourierStored {
            affine: self.affine.clone(),
            lambda: self.lambda.clone(),
            additive: self.combination == Combination::Additive,
            weights: self.weights.clone(),
            index: self.index.clone(),
            gaussian_like: self.gaussian_like,
        }
    }

    /// The kernel from its stored numbers, checked to fit together (every index within the
    /// harmonics, one weight per feature), so that evaluation cannot index out of range.
    pub(crate) fn from_stored(s: &crate::stored::FourierStored) -> Result<Self> {
        let p = s.affine.len();
        let ok = p > 0
            && s.lambda.len() == p
            && s.lambda.iter().all(|l| !l.is_empty())
            && if s.additive {
                s.weights.len() == 1 + s.lambda.iter().map(|l| 2 * (l.len() - 1)).sum::<usize>()
            } else {
                s.index.len() == s.weights.len()
                    && s.index.iter().all(|mi| {
                        mi.len() == p
                            && mi
                                .iter()
                                .zip(&s.lambda)
                                .all(|(&(h, kind), l)| h < l.len() && kind < 2)
                    })
            };
        if !ok {
            return Err(Error::InconsistentStored {
                item: "Fourier kernel".into(),
                detail: "its harmonics, feature indices and weights do not fit together".into(),
            });
        }
        Ok(Self {
            affine: s.affine.clone(),
            lambda: s.lambda.clone(),
            combination: if s.additive {
                Combination::Additive
            } else {
                Combination::Tensor
            },
            weights: s.weights.clone(),
            index: s.index.clone(),
            gaussian_like: s.gaussian_like,
        })
    }

    /// Number of harmonics N per input.
    pub fn harmonics(&self) -> Vec<usize> {
        self.lambda.iter().map(|l| l.len() - 1).collect()
    }

    fn unit(&self, z: &[f64], j: usize) -> f64 {
        let (o, s) = self.affine[j];
        o + s * z[j]
    }

    /// The features ψ(z) into `psi` (m) and their derivatives ∂ψ/∂z into `grad` (m × p,
    /// row-major), in closed form: d/dz cos(2πn·t) = −2πn·s·sin(2πn·t) with t = o + s·z, and
    /// the product rule across the inputs of a tensor feature.
    ///
    /// ```
    /// use structid_core::{Combination, FeatureMap, FourierKernel, FourierWeights};
    /// let k = FourierKernel::new(&FourierWeights::GaussianLike { sigma: 0.3 }, Some(3),
    ///     vec![(-1.0, 1.0)], Combination::Tensor).unwrap();
    /// let (mut psi, mut grad) = (vec![0.0; 7], vec![0.0; 7]);
    /// k.gradient_into(&[0.2], &mut psi, &mut grad);
    /// let (mut up, mut down) = (vec![0.0; 7], vec![0.0; 7]);
    /// k.eval_into(&[0.2 + 1e-6], &mut up);
    /// k.eval_into(&[0.2 - 1e-6], &mut down);
    /// for j in 0..7 {
    ///     assert!((grad[j] - (up[j] - down[j]) / 2e-6).abs() < 1e-6);
    /// }
    /// ```
    pub fn gradient_into(&self, z: &[f64], psi: &mut [f64], grad: &mut [f64]) {
        let p = self.affine.len();
        // (value, derivative) of cos and sin of every harmonic of every input.
        let trig: Vec<Vec<[(f64, f64); 2]>> = (0..p)
            .map(|j| {
                let scale = self.affine[j].1;
                let t = self.unit(z, j);
                (0..self.lambda[j].len())
                    .map(|h| {
                        let omega = 2.0 * PI * h as f64;
                        let (sn, cs) = (omega * t).sin_cos();
                        [(cs, -omega * scale * sn), (sn, omega * scale * cs)]
                    })
                    .collect()
            })
            .collect();
        grad.fill(0.0);
        match self.combination {
            Combination::Tensor if p > 1 => {
                for (f, mi) in self.index.iter().enumerate() {
                    let factors: Vec<(f64, f64)> = mi
                        .iter()
                        .enumerate()
                        .map(|(j, &(h, kind))| trig[j][h][kind as usize])
                        .collect();
                    psi[f] = factors.iter().map(|v| v.0).product();
                    for i in 0..p {
                        grad[f * p + i] = factors
                            .iter()
                            .enumerate()
                            .map(|(j, v)| if j == i { v.1 } else { v.0 })
                            .product();
                    }
                }
            }
            _ => {
                // One input, or the additive order: [1, then (cos, sin) of each harmonic of
                // each input in turn].
                psi[0] = 1.0;
                let mut at = 1;
                for (j, tj) in trig.iter().enumerate() {
                    for pair in &tj[1..] {
                        for (kind, &(v, d)) in pair.iter().enumerate() {
                            psi[at + kind] = v;
                            grad[(at + kind) * p + j] = d;
                        }
                        at += 2;
                    }
                }
            }
        }
    }
}

impl Kernel for FourierKernel {
    fn stored_kernel(&self) -> Option<crate::stored::StoredKernel> {
        Some(crate::stored::StoredKernel::Fourier(self.to_stored()))
    }

    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        let series = |j: usize| -> f64 {
            let d = self.unit(a, j) - self.unit(b, j);
            let l = &self.lambda[j];
            l[0] + (1..l.len())
                .map(|n| 2.0 * l[n] * (2.0 * PI * n as f64 * d).cos())
                .sum::<f64>()
        };
        match self.combination {
            Combination::Tensor => (0..self.affine.len()).map(series).product(),
            Combination::Additive => (0..self.affine.len()).map(series).sum(),
        }
    }

    fn describe(&self) -> String {
        format!(
            "fourier(harmonics={:?}, features={})",
            self.harmonics(),
            self.weights.len()
        )
    }
}

impl FeatureMap for FourierKernel {
    fn stored_features(&self) -> Option<crate::stored::StoredKernel> {
        Some(crate::stored::StoredKernel::Fourier(self.to_stored()))
    }

    fn dim(&self) -> usize {
        self.weights.len()
    }

    fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Gaussian-like weights at another σ on the same harmonics: the features do not change.
    fn weights_at_width(&self, width: f64) -> Option<Vec<f64>> {
        if !(self.gaussian_like && width.is_finite() && width > 0.0) {
            return None;
        }
        let lambda: Vec<Vec<f64>> = self
            .affine
            .iter()
            .zip(&self.lambda)
            .map(|(&(_, s), l)| gaussian_like_lambda(s, width, l.len() - 1))
            .collect();
        Some(feature_weights(&lambda, self.combination, &self.index))
    }

    /// One input: the harmonics of 8 samples at a time (independent recurrences side
    /// by side, which the compiler vectorises); the same operations as
    /// [`eval_into`](FeatureMap::eval_into), hence the same values.
    fn eval_rows(&self, z: &Signal, t0: usize, scale: &[f64], rows: &mut [f64]) {
        if !self.one_input_fast(z) {
            return eval_rows_by_sample(self, z, t0, scale, rows);
        }
        let m = self.dim();
        let zs = &z.as_slice()[t0..t0 + rows.len() / m];
        for (zl, block) in zs.chunks(LANES).zip(rows.chunks_mut(LANES * m)) {
            let (c1, s1) = self.unit_angles(zl);
            let (mut c, mut s) = ([1.0; LANES], [0.0; LANES]);
            for row in block.chunks_exact_mut(m) {
                row[0] = scale[0];
            }
            for h in 0..(m - 1) / 2 {
                rotate(&mut c, &mut s, &c1, &s1);
                let (sc, ss) = (scale[1 + 2 * h], scale[2 + 2 * h]);
                for (l, row) in block.chunks_exact_mut(m).enumerate() {
                    row[1 + 2 * h] = c[l] * sc;
                    row[2 + 2 * h] = s[l] * ss;
                }
            }
        }
    }

    /// One input: the harmonics up to the last column asked for, 8 samples at a time, by the
    /// operations of [`eval_rows`](FeatureMap::eval_rows), hence the same values.
    fn eval_cols(
        &self,
        z: &Signal,
        t0: usize,
        cols: std::ops::Range<usize>,
        scale: &[f64],
        rows: &mut [f64],
    ) {
        if !self.one_input_fast(z) {
            return eval_cols_by_rows(self, z, t0, cols, scale, rows);
        }
        let w = cols.len();
        if w == 0 {
            return;
        }
        let zs = &z.as_slice()[t0..t0 + rows.len() / w];
        self.harmonic_cols(cols, scale, rows, |i| {
            self.unit_angles(&zs[i..zs.len().min(i + LANES)])
        });
    }

    /// One input: cos and sin of 2πt per sample (what [`eval_cols`](FeatureMap::eval_cols)
    /// starts every sample from); otherwise nothing.
    fn prepared_len(&self) -> usize {
        if self.affine.len() == 1 && !self.dim().is_multiple_of(2) {
            2
        } else {
            0
        }
    }

    fn prepare_rows(&self, z: &Signal, t0: usize, out: &mut [f64]) {
        if !self.one_input_fast(z) {
            return;
        }
        let zs = &z.as_slice()[t0..t0 + out.len() / 2];
        for (zv, cs) in zs.iter().zip(out.chunks_exact_mut(2)) {
            let (s1, c1) = self.unit_angle(*zv);
            cs[0] = c1;
            cs[1] = s1;
        }
    }

    /// [`eval_cols`](FeatureMap::eval_cols) with cos and sin of 2πt read from `prepared`
    /// (computed by the same expression, so the values are the same bit for bit).
    fn eval_cols_prepared(
        &self,
        z: &Signal,
        t0: usize,
        cols: std::ops::Range<usize>,
        scale: &[f64],
        prepared: &[f64],
        rows: &mut [f64],
    ) {
        let w = cols.len();
        if w == 0 {
            return;
        }
        let count = rows.len() / w;
        if !self.one_input_fast(z) || prepared.len() < 2 * count {
            return self.eval_cols(z, t0, cols, scale, rows);
        }
        self.harmonic_cols(cols, scale, rows, |i| {
            let (mut c1, mut s1) = ([1.0; LANES], [0.0; LANES]);
            for (l, cs) in prepared[2 * i..2 * count.min(i + LANES)]
                .chunks_exact(2)
                .enumerate()
            {
                c1[l] = cs[0];
                s1[l] = cs[1];
            }
            (c1, s1)
        });
    }

    /// One input: Σ coef_j·ψ_j for 8 samples at a time, summed in feature order as
    /// the default does.
    fn combine_rows(&self, z: &Signal, t0: usize, coef: &[f64], out: &mut [f64]) {
        let m = self.dim();
        if self.affine.len() != 1 || z.channels() != 1 || m.is_multiple_of(2) {
            let mut psi = vec![0.0; m];
            for (k, o) in out.iter_mut().enumerate() {
                self.eval_into(z.sample(t0 + k), &mut psi);
                *o = psi.iter().zip(coef).map(|(p, c)| p * c).sum();
            }
            return;
        }
        let zs = &z.as_slice()[t0..t0 + out.len()];
        for (zl, ol) in zs.chunks(LANES).zip(out.chunks_mut(LANES)) {
            let (c1, s1) = self.unit_angles(zl);
            let (mut c, mut s) = ([1.0; LANES], [0.0; LANES]);
            // 0.0 + 1.0·coef₀, as a sum over the features starting from zero
            let mut acc = [0.0 + coef[0]; LANES];
            for h in 0..(m - 1) / 2 {
                rotate(&mut c, &mut s, &c1, &s1);
                let (cc, cs) = (coef[1 + 2 * h], coef[2 + 2 * h]);
                for l in 0..LANES {
                    acc[l] += c[l] * cc;
                    acc[l] += s[l] * cs;
                }
            }
            ol.copy_from_slice(&acc[..ol.len()]);
        }
    }

    /// Unscaled features ψ with K = ψᵀΛψ: ψ = 1, cos(2πnt), sin(2πnt) (products for tensors).
    fn eval_into(&self, z: &[f64], out: &mut [f64]) {
        let p = self.affine.len();
        if p == 1 {
            // [1, cos 2πt, sin 2πt, cos 4πt, …] by the angle-addition recurrence; the tensor
            // and additive orders coincide for one input.
            let (s1, c1) = (2.0 * PI * self.unit(z, 0)).sin_cos();
            out[0] = 1.0;
            let (mut c, mut s) = (1.0, 0.0);
            for pair in out[1..].chunks_exact_mut(2) {
                (c, s) = (c * c1 - s * s1, s * c1 + c * s1);
                pair[0] = c;
                pair[1] = s;
            }
            return;
        }
        // cos/sin of every harmonic of every input, by the angle-addition recurrence.
        let mut trig: Vec<Vec<(f64, f64)>> = Vec::with_capacity(p);
        for j in 0..p {
            let t = self.unit(z, j);
            let (s1, c1) = (2.0 * PI * t).sin_cos();
            let n = self.lambda[j].len();
            let mut v = Vec::with_capacity(n);
            let (mut c, mut s) = (1.0, 0.0);
            for _ in 0..n {
                v.push((c, s));
                (c, s) = (c * c1 - s * s1, s * c1 + c * s1);
            }
            trig.push(v);
        }
        match self.combination {
            Combination::Tensor => {
                for (o, mi) in out.iter_mut().zip(&self.index) {
                    *o = mi
                        .iter()
                        .enumerate()
                        .map(|(j, &(h, kind))| {
                            if kind == 0 {
                                trig[j][h].0
                            } else {
                                trig[j][h].1
                            }
                        })
                        .product();
                }
            }
            Combination::Additive => {
                out[0] = 1.0;
                let mut at = 1;
                for tj in &trig {
                    for &(c, s) in &tj[1..] {
                        out[at] = c;
                        out[at + 1] = s;
                        at += 2;
                    }
                }
            }
        }
    }
}

/// Samples evaluated side by side by the batched feature evaluations.
const LANES: usize = 8;

/// (c, s) ← (c·c₁ − s·s₁, s·c₁ + c·s₁) in every lane: the next harmonic, with the operations
/// of [`FourierKernel`]'s single-sample recurrence.
#[inline(always)]
fn rotate(c: &mut [f64; LANES], s: &mut [f64; LANES], c1: &[f64; LANES], s1: &[f64; LANES]) {
    for l in 0..LANES {
        (c[l], s[l]) = (c[l] * c1[l] - s[l] * s1[l], s[l] * c1[l] + c[l] * s1[l]);
    }
}

impl FourierKernel {
    /// Whether the batched one-input evaluation applies (one input, odd m: a constant and
    /// cos/sin pairs).
    fn one_input_fast(&self, z: &Signal) -> bool {
        self.affine.len() == 1 && z.channels() == 1 && !self.dim().is_multiple_of(2)
    }

    /// (sin, cos) of 2πt for one sample of a one-input map.
    #[inline(always)]
    fn unit_angle(&self, zv: f64) -> (f64, f64) {
        (2.0 * PI * self.unit(std::slice::from_ref(&zv), 0)).sin_cos()
    }

    /// cos and sin of 2πt for up to [`LANES`] samples of a one-input map (unused lanes: t = 0).
    fn unit_angles(&self, z: &[f64]) -> ([f64; LANES], [f64; LANES]) {
        let (mut c1, mut s1) = ([1.0; LANES], [0.0; LANES]);
        for (l, zv) in z.iter().enumerate() {
            (s1[l], c1[l]) = self.unit_angle(*zv);
        }
        (c1, s1)
    }

    /// The columns `cols` of the scaled one-input features of `rows.len() / cols.len()`
    /// samples, [`LANES`] at a time, with `angles(i)` the cos and sin of 2πt of the lanes
    /// from sample `i` on: the harmonics by the rotations of
    /// [`eval_rows`](FeatureMap::eval_rows), up to the last column asked for.
    #[inline(always)]
    fn harmonic_cols(
        &self,
        cols: std::ops::Range<usize>,
        scale: &[f64],
        rows: &mut [f64],
        angles: impl Fn(usize) -> ([f64; LANES], [f64; LANES]),
    ) {
        let w = cols.len();
        let a = cols.start;
        for (bi, block) in rows.chunks_mut(LANES * w).enumerate() {
            let (c1, s1) = angles(bi * LANES);
            let (mut c, mut s) = ([1.0; LANES], [0.0; LANES]);
            if a == 0 {
                for row in block.chunks_exact_mut(w) {
                    row[0] = scale[0];
                }
            }
            // harmonic h fills columns 1 + 2h (cos) and 2 + 2h (sin)
            for h in 0..(cols.end.saturating_sub(1)).div_ceil(2) {
                rotate(&mut c, &mut s, &c1, &s1);
                let (jc, js) = (1 + 2 * h, 2 + 2 * h);
                if js < a {
                    continue;
                }
                let (sc, ss) = (scale[jc], scale[js]);
                let (has_c, has_s) = (cols.contains(&jc), cols.contains(&js));
                for (l, row) in block.chunks_exact_mut(w).enumerate() {
                    if has_c {
                        row[jc - a] = c[l] * sc;
                    }
                    if has_s {
                        row[js - a] = s[l] * ss;
                    }
                }
            }
        }
    }
}

/// Samples whose features are evaluated in one call where a penalty needs them all (a map
/// written in another language pays per call, not per sample).
const FEATURE_BLOCK: usize = 1024;

/// A quadratic penalty given by a feature map at fixed sample points: K = Ψ Λ Ψᵀ, whose Gram
/// columns come from `kernel`: the map itself for the built-in maps, a kernel wrapped around
/// it for a user's map (which need not be a [`Kernel`]).
pub(crate) struct FeaturePenalty<F: FeatureMap, K: Kernel> {
    pub(crate) map: Arc<F>,
    pub(crate) kernel: Arc<K>,
    pub(crate) z: Signal,
}

impl<F: FeatureMap + Kernel + 'static> FeaturePenalty<F, F> {
    /// The penalty at the points `z` of a map that is its own kernel.
    pub(crate) fn of(map: F, z: &Signal) -> Penalty {
        let map = Arc::new(map);
        Penalty::Quadratic(Box::new(Self {
            kernel: Arc::clone(&map),
            map,
            z: z.clone(),
        }))
    }
}

impl<F: FeatureMap + 'static, K: Kernel + 'static> QuadraticPenalty for FeaturePenalty<F, K> {
    fn len(&self) -> usize {
        self.z.len()
    }

    fn fill_columns(&self, cols: Range<usize>, out: faer::MatMut<'_, f64>) {
        self.kernel.fill_gram_columns(&self.z, cols, out);
    }

    fn interpolant(&self, alpha: Vec<f64>) -> Box<dyn Interpolant> {
        // N̂(z) = Σ_k α_k K(z, z_k) = ψ(z)ᵀ·(Λ Ψᵀ α): m coefficients instead of L centres.
        // The features are evaluated a block of samples at a time (one call of a batched map).
        let m = self.map.dim();
        let ones = vec![1.0; m];
        let mut coef = vec![0.0; m];
        let mut psi = vec![0.0; FEATURE_BLOCK * m];
        for t0 in (0..alpha.len()).step_by(FEATURE_BLOCK) {
            let n = FEATURE_BLOCK.min(alpha.len() - t0);
            let rows = &mut psi[..n * m];
            self.map.eval_rows(&self.z, t0, &ones, rows);
            for (a, row) in alpha[t0..t0 + n].iter().zip(rows.chunks_exact(m.max(1))) {
                if *a != 0.0 {
                    coef.iter_mut().zip(row).for_each(|(c, v)| *c += a * v);
                }
            }
        }
        coef.iter_mut()
            .zip(self.map.weights())
            .for_each(|(c, l)| *c *= l);
        Box::new(FeatureExpansion::new(
            Arc::clone(&self.map) as Arc<dyn FeatureMap>,
            coef,
        ))
    }

    fn features(&self) -> Option<(Arc<dyn FeatureMap>, &Signal)> {
        Some((Arc::clone(&self.map) as Arc<dyn FeatureMap>, &self.z))
    }

    /// K(z_k, p_j) = ψ(z_k)ᵀΛψ(p_j) as one L×m by m×G matrix product (the features of the
    /// samples are recomputed per call: O(L·m) evaluations, no L×m storage between calls).
    fn cross_columns(&self, points: &Signal, out: faer::MatMut<'_, f64>) -> bool {
        let (len, g, m) = (self.z.len(), points.len(), self.map.dim());
        if points.channels() != self.z.channels() || out.nrows() != len || out.ncols() != g {
            return false;
        }
        let ones = vec![1.0; m];
        let mut psi_z = vec![0.0; len * m];
        psi_z
            .par_chunks_mut((FEATURE_BLOCK * m).max(1))
            .enumerate()
            .for_each(|(b, rows)| self.map.eval_rows(&self.z, b * FEATURE_BLOCK, &ones, rows));
        let mut psi_p = vec![0.0; g * m];
        self.map
            .eval_rows(points, 0, self.map.weights(), &mut psi_p);
        faer::linalg::matmul::matmul(
            out,
            faer::Accum::Replace,
            faer::MatRef::from_row_major_slice(&psi_z, len, m),
            faer::MatRef::from_row_major_slice(&psi_p, g, m).transpose(),
            1.0,
            faer::get_global_parallelism(),
        );
        true
    }

    fn diagonal_at(&self, points: &Signal) -> Option<Vec<f64>> {
        if points.channels() != self.z.channels() {
            return None;
        }
        let m = self.map.dim();
        let mut psi = vec![0.0; points.len() * m];
        self.map.eval_rows(points, 0, &vec![1.0; m], &mut psi);
        Some(
            psi.chunks_exact(m.max(1))
                .map(|row| {
                    row.iter()
                        .zip(self.map.weights())
                        .map(|(v, l)| v * v * l)
                        .sum()
                })
                .collect(),
        )
    }
}

/// N̂(z) = ψ(z)ᵀc for a feature map ψ and coefficients c.
pub struct FeatureExpansion {
    map: Arc<dyn FeatureMap>,
    coef: Vec<f64>,
}

impl FeatureExpansion {
    /// An expansion with the given coefficients (length = number of features).
    pub fn new(map: Arc<dyn FeatureMap>, coef: Vec<f64>) -> Self {
        Self { map, coef }
    }

    /// The coefficients.
    pub fn coefficients(&self) -> &[f64] {
        &self.coef
    }
}

impl Interpolant for FeatureExpansion {
    fn eval(&self, z: &[f64]) -> f64 {
        let mut psi = vec![0.0; self.coef.len()];
        self.map.eval_into(z, &mut psi);
        psi.iter().zip(&self.coef).map(|(a, b)| a * b).sum()
    }

    fn stored(&self) -> Option<crate::stored::StoredMap> {
        Some(crate::stored::StoredMap::FeatureExpansion {
            features: self.map.stored_features()?,
            coefficients: self.coef.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signal(v: &[f64]) -> Signal {
        Signal::from_channels(&[v.to_vec()]).unwrap()
    }

    /// The batched evaluations equal the single-sample ones exactly (same operations), the
    /// harmonics by recurrence equal cos/sin of nθ evaluated directly, and the default trait
    /// methods (two inputs) agree with the overrides' contract.
    #[test]
    fn batched_features_equal_single_sample_and_direct_trig() {
        let zs: Vec<f64> = (0..203)
            .map(|k| ((k * 37) % 101) as f64 / 50.0 - 1.0)
            .collect();
        let z = signal(&zs);
        let k = FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.2 })
            .unwrap()
            .with_harmonics(31)
            .kernel_for(&z)
            .unwrap();
        let m = k.dim();
        assert_eq!(m, 63);
        let scale: Vec<f64> = k.weights().iter().map(|l| l.sqrt()).collect();
        let coef: Vec<f64> = (0..m).map(|j| ((j * 13) % 7) as f64 - 3.0).collect();
        for (t0, count) in [(0, 203), (5, 64), (200, 3), (17, 1)] {
            let mut rows = vec![0.0; count * m];
            k.eval_rows(&z, t0, &scale, &mut rows);
            let mut out = vec![0.0; count];
            k.combine_rows(&z, t0, &coef, &mut out);
            let mut psi = vec![0.0; m];
            for i in 0..count {
                k.eval_into(z.sample(t0 + i), &mut psi);
                for j in 0..m {
                    assert_eq!(rows[i * m + j], psi[j] * scale[j]);
                }
                let direct: f64 = psi.iter().zip(&coef).map(|(p, c)| p * c).sum();
                assert_eq!(out[i], direct);
                let theta = 2.0 * PI * k.unit(z.sample(t0 + i), 0);
                for h in 1..=31 {
                    let (s, c) = (h as f64 * theta).sin_cos();
                    assert!((psi[2 * h - 1] - c).abs() < 1e-13, "cos, harmonic {h}");
                    assert!((psi[2 * h] - s).abs() < 1e-13, "sin, harmonic {h}");
                }
            }
        }
        // column ranges (what the feature solver's threads evaluate): the same values as the
        // whole rows, bit for bit
        for (t0, count) in [(0, 203), (17, 9)] {
            let mut rows = vec![0.0; count * m];
            k.eval_rows(&z, t0, &scale, &mut rows);
            for cols in [0..32, 32..63, 0..63, 1..2, 2..3, 5..6, 62..63, 7..7] {
                let w = cols.len();
                let mut part = vec![0.0; count * w];
                k.eval_cols(&z, t0, cols.clone(), &scale, &mut part);
                for i in 0..count {
                    assert_eq!(
                        &part[i * w..(i + 1) * w],
                        &rows[i * m + cols.start..i * m + cols.end]
                    );
                }
            }
        }
        // from the prepared cos and sin of 2πt (what the feature solver's threads share): the
        // same values as the column ranges computed whole, bit for bit
        assert_eq!(k.prepared_len(), 2);
        for (t0, count) in [(0, 203), (17, 9), (5, 1)] {
            let mut prep = vec![0.0; 2 * count];
            // prepared in two pieces, as the solver's threads split the samples
            let half = count / 2;
            k.prepare_rows(&z, t0, &mut prep[..2 * half]);
            k.prepare_rows(&z, t0 + half, &mut prep[2 * half..]);
            for i in 0..count {
                let theta = 2.0 * PI * k.unit(z.sample(t0 + i), 0);
                assert!((prep[2 * i] - theta.cos()).abs() < 1e-15);
                assert!((prep[2 * i + 1] - theta.sin()).abs() < 1e-15);
            }
            for cols in [0..32, 32..63, 0..63, 1..2, 2..3, 5..6, 62..63, 7..7] {
                let w = cols.len();
                let mut want = vec![0.0; count * w];
                k.eval_cols(&z, t0, cols.clone(), &scale, &mut want);
                let mut got = vec![f64::NAN; count * w];
                k.eval_cols_prepared(&z, t0, cols.clone(), &scale, &prep, &mut got);
                assert_eq!(got, want, "{cols:?} from {t0}");
            }
        }
        // two inputs: the trait's per-sample defaults
        let z2 = Signal::from_channels(&[zs.clone(), zs.iter().map(|v| v * v).collect()]).unwrap();
        let k2 = FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.5 })
            .unwrap()
            .with_harmonics(2)
            .kernel_for(&z2)
            .unwrap();
        let m2 = k2.dim();
        let scale2 = vec![2.0; m2];
        let mut rows = vec![0.0; 10 * m2];
        k2.eval_rows(&z2, 3, &scale2, &mut rows);
        let mut psi = vec![0.0; m2];
        for i in 0..10 {
            k2.eval_into(z2.sample(3 + i), &mut psi);
            for j in 0..m2 {
                assert_eq!(rows[i * m2 + j], 2.0 * psi[j]);
            }
        }
        let mut part = vec![0.0; 10 * 3];
        k2.eval_cols(&z2, 3, 1..4, &scale2, &mut part);
        for i in 0..10 {
            assert_eq!(&part[i * 3..(i + 1) * 3], &rows[i * m2 + 1..i * m2 + 4]);
        }
        // nothing to prepare: the prepared evaluation is eval_cols
        assert_eq!(k2.prepared_len(), 0);
        let mut got = vec![0.0; 10 * 3];
        k2.eval_cols_prepared(&z2, 3, 1..4, &scale2, &[], &mut got);
        assert_eq!(got, part);
    }

    #[test]
    fn features_reproduce_the_kernel() {
        for comb in [Combination::Tensor, Combination::Additive] {
            for p in 1..=2 {
                let dom = vec![(-1.0, 2.0); p];
                let k = FourierKernel::new(
                    &FourierWeights::SobolevLike {
                        order: 1.5,
                        scale: 0.7,
                    },
                    Some(6),
                    dom,
                    comb,
                )
                .unwrap();
                let (a, b) = (vec![0.3, -0.8][..p].to_vec(), vec![1.7, 0.1][..p].to_vec());
                let mut pa = vec![0.0; k.dim()];
                let mut pb = vec![0.0; k.dim()];
                k.eval_into(&a, &mut pa);
                k.eval_into(&b, &mut pb);
                let via: f64 = pa
                    .iter()
                    .zip(&pb)
                    .zip(k.weights())
                    .map(|((x, y), l)| x * y * l)
                    .sum();
                assert!(
                    (via - k.eval(&a, &b)).abs() < 1e-12 * k.eval(&a, &a),
                    "{comb:?} p={p}"
                );
            }
        }
    }

    #[test]
    fn gaussian_like_matches_the_gaussian_kernel_inside_the_domain() {
        let sigma = 0.15;
        let fd = FourierDispersion::new(FourierWeights::GaussianLike { sigma }).unwrap();
        let k = fd.kernel_for(&signal(&[-1.0, 1.0])).unwrap();
        let g = crate::GaussianKernel::new(sigma).unwrap();
        for (a, b) in [(0.0, 0.0), (0.1, -0.2), (-1.0, -0.7), (0.9, 1.0)] {
            let (x, y) = (k.eval(&[a], &[b]), g.eval(&[a], &[b]));
            assert!(
                (x - y).abs() < 1e-9 * g.eval(&[0.0], &[0.0]),
                "({a},{b}): {x} vs {y}"
            );
        }
        // The ends of the data are not tied together by the periodic wrap.
        assert!(k.eval(&[-1.0], &[1.0]) < 1e-9);
    }

    #[test]
    fn tensor_feature_guard_and_bad_parameters() {
        let fd = FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.001 }).unwrap();
        let z = Signal::from_fn(10, 3, |k, c| (k + c) as f64);
        assert!(matches!(fd.penalty(&z), Err(Error::InvalidStructure(_))));
        assert!(FourierDispersion::new(FourierWeights::GaussianLike { sigma: -1.0 }).is_err());
        assert!(
            FourierDispersion::new(FourierWeights::SobolevLike {
                order: 0.3,
                scale: 1.0
            })
            .is_err()
        );
        assert!(FourierDispersion::new(FourierWeights::Custom(vec![0.0, 1.0])).is_err());
    }
}
