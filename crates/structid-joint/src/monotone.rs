//! A scalar map that is monotone by construction: its slope is the square of a kernel
//! expansion on fixed centres,
//!
//! ```text
//!   N(z) = a₀ + s·∫_r^z h(t)² dt,     h(t) = b + Σ_j θ_j·K(t, c_j),     s = ±1
//! ```
//!
//! with K the paper's Gaussian kernel, r the mean of the centres and s the declared direction
//! ([`Monotonicity`]). N′ = s·h² never changes sign, whatever the parameters, so the joint fit
//! needs no constraint to keep the map monotone. Far from the centres h falls back to b, and
//! N to the line a₀ + s·b²·(z − r): a map that extrapolates with its tail slope and the right
//! sign, which is what an outflow, a spring or a sensor does beyond the data.
//!
//! The dispersion is the RKHS norm of the root of the slope, D = θᵀK_ccθ: h is a kernel
//! expansion like any map of `identify`, and β weighs how far the slope departs from a
//! constant. (β therefore does not mean the same as for [`GaussianFeatures`], where D measures
//! the map itself.)
//!
//! The integral is closed form. With Φ the standard normal distribution function,
//! ∫K(t, c_j) dt = Φ((t − c_j)/σ), and K(t, c_i)·K(t, c_j) is a Gaussian around the midpoint
//! m_ij = (c_i + c_j)/2 of width σ/√2, so
//!
//! ```text
//!   ∫_r^z h² = b²·(z − r) + 2b·Σ_j θ_j·E_j(z) + Σ_ij θ_iθ_j·M_ij(z)
//!   E_j  = Φ((z − c_j)/σ) − Φ((r − c_j)/σ)
//!   M_ij = exp(−(c_i − c_j)²/4σ²)/(2σ√π) · [Φ(√2(z − m_ij)/σ) − Φ(√2(r − m_ij)/σ)]
//! ```
//!
//! which is quadratic in (θ, b): every derivative is exact. Parameter order: θ₁ … θ_m, b, a₀.

use nalgebra::{DMatrix, DVector};
use structid_core::Monotonicity;

use crate::block::{BlockJacobian, BlockMap};
use crate::error::Result;
use crate::features::LinearInParameters;
use crate::features::{GaussianFeatures, evenly_spaced, regularised_fit, split_parameters};

/// One product K(t, c_i)·K(t, c_j), i ≤ j: its weight exp(−(c_i − c_j)²/4σ²)/(2σ√π) (doubled
/// when i < j, since θ_iθ_j appears twice in the sum) and its midpoint.
#[derive(Clone, Debug, PartialEq)]
struct Pair {
    i: usize,
    j: usize,
    weight: f64,
    /// Index into [`MonotoneFeatures::midpoints`].
    mid: usize,
}

/// A midpoint m shared by one or more pairs (evenly spaced centres have only 2m − 1 of them
/// for m(m + 1)/2 pairs), with Φ at √2(r − m)/σ.
#[derive(Clone, Debug, PartialEq)]
struct Midpoint {
    at: f64,
    at_reference: NormalAt,
}

/// Φ(a) and 1 − Φ(a) at a fixed argument, both kept so that a difference Φ(x) − Φ(a) is
/// accurate in either tail.
#[derive(Clone, Copy, Debug, PartialEq)]
struct NormalAt {
    arg: f64,
    lower: f64,
    upper: f64,
}

impl NormalAt {
    fn new(arg: f64) -> Self {
        Self {
            arg,
            lower: lower_tail(arg),
            upper: upper_tail(arg),
        }
    }

    /// Φ(x) − Φ(arg), computed from the tail in which both lie.
    fn diff_from(&self, x: f64) -> f64 {
        if x >= 0.0 && self.arg >= 0.0 {
            self.upper - upper_tail(x)
        } else {
            lower_tail(x) - self.lower
        }
    }
}

fn lower_tail(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

fn upper_tail(x: f64) -> f64 {
    0.5 * libm::erfc(x / std::f64::consts::SQRT_2)
}

/// A monotone scalar map whose slope is the square of a Gaussian kernel expansion.
///
/// ```
/// use structid_core::Monotonicity;
/// use structid_joint::{BlockMap, MonotoneFeatures};
/// // An outflow √z over [0, 4]: fitted from a few values, it stays increasing everywhere.
/// let f = MonotoneFeatures::on_interval(0.0, 4.0, 8, 0.8, 1e-8, Monotonicity::Increasing).unwrap();
/// let z: Vec<Vec<f64>> = (0..41).map(|k| vec![0.1 * k as f64]).collect();
/// let w: Vec<f64> = z.iter().map(|z| z[0].sqrt()).collect();
/// let f = f.fitted_to(&z, &w).unwrap();
/// assert!((f.eval(&mut [], &[2.0]) - 2f64.sqrt()).abs() < 0.02);
/// let tail: Vec<f64> = (0..50).map(|k| f.eval(&mut [], &[-5.0 + 0.4 * k as f64])).collect();
/// assert!(Monotonicity::Increasing.holds(&tail));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct MonotoneFeatures {
    root: GaussianFeatures,
    direction: Monotonicity,
    theta: Vec<f64>,
    tail_root: f64,
    level: f64,
    reference: f64,
    centre_at_reference: Vec<NormalAt>,
    /// The pairs, ordered by midpoint, so that one Φ serves a run of them.
    pairs: Vec<Pair>,
    midpoints: Vec<Midpoint>,
}

impl MonotoneFeatures {
    /// Centres `centres` (scalars), width σ > 0, dispersion weight β ≥ 0 and `direction`. The
    /// map starts flat (every parameter zero). A flat map is a stationary point of any fit,
    /// since every derivative of N in θ and b vanishes there: start from
    /// [`fitted_to`](Self::fitted_to) or [`BlockMap::with_parameters`].
    ///
    /// ```
    /// use structid_core::Monotonicity;
    /// use structid_joint::{BlockMap, MonotoneFeatures};
    /// let f = MonotoneFeatures::new(vec![0.0, 1.0], 0.5, 0.0, Monotonicity::Decreasing).unwrap();
    /// // θ = 0, b = 2: the line a₀ − 4·(z − 0.5).
    /// let f = f.with_parameters(&[0.0, 0.0, 2.0, 1.0]).unwrap();
    /// assert!((f.eval(&mut [], &[1.5]) - (1.0 - 4.0)).abs() < 1e-12);
    /// assert!(MonotoneFeatures::new(vec![], 0.5, 0.0, Monotonicity::Increasing).is_err());
    /// ```
    pub fn new(centres: Vec<f64>, sigma: f64, beta: f64, direction: Monotonicity) -> Result<Self> {
        let root = GaussianFeatures::new(centres.iter().map(|c| vec![*c]).collect(), sigma, beta)?;
        let m = centres.len();
        let reference = centres.iter().sum::<f64>() / m as f64;
        let centre_at_reference = centres
            .iter()
            .map(|c| NormalAt::new((reference - c) / sigma))
            .collect();
        let (pairs, midpoints) = pairs_by_midpoint(&centres, sigma, reference);
        Ok(Self {
            root,
            direction,
            theta: vec![0.0; m],
            tail_root: 0.0,
            level: 0.0,
            reference,
            centre_at_reference,
            pairs,
            midpoints,
        })
    }

    /// `count` ≥ 2 centres spread evenly over [lo, hi].
    pub fn on_interval(
        lo: f64,
        hi: f64,
        count: usize,
        sigma: f64,
        beta: f64,
        direction: Monotonicity,
    ) -> Result<Self> {
        Self::new(evenly_spaced(lo, hi, count)?, sigma, beta, direction)
    }

    /// The direction the map goes.
    pub fn direction(&self) -> Monotonicity {
        self.direction
    }

    /// The centres of the slope's root h.
    pub fn centres(&self) -> Vec<f64> {
        self.root.centres().iter().map(|c| c[0]).collect()
    }

    /// The kernel width σ.
    pub fn sigma(&self) -> f64 {
        self.root.sigma()
    }

    /// The dispersion weight β.
    pub fn beta(&self) -> f64 {
        self.root.beta()
    }

    /// The root of the slope, h(z) = b + Σ_j θ_j·K(z, c_j); N′(z) = s·h(z)².
    pub fn slope_root(&self, z: f64) -> f64 {
        let sigma = self.root.sigma();
        let norm = 1.0 / (sigma * (2.0 * std::f64::consts::PI).sqrt());
        self.tail_root
            + self
                .root
                .centres()
                .iter()
                .zip(&self.theta)
                .map(|(c, t)| {
                    let d = (z - c[0]) / sigma;
                    t * norm * (-0.5 * d * d).exp()
                })
                .sum::<f64>()
    }

    /// ∫_r^z h², and into `grad` (when given, length m + 1) its derivatives in θ and b.
    fn integral(&self, z: f64, mut grad: Option<&mut [f64]>) -> f64 {
        let (b, sigma, m) = (self.tail_root, self.root.sigma(), self.theta.len());
        let mut value = b * b * (z - self.reference);
        let mut cross = 0.0;
        if let Some(g) = grad.as_deref_mut() {
            g.fill(0.0);
        }
        for (j, (c, at)) in self
            .root
            .centres()
            .iter()
            .zip(&self.centre_at_reference)
            .enumerate()
        {
            let e = at.diff_from((z - c[0]) / sigma);
            cross += self.theta[j] * e;
            if let Some(g) = grad.as_deref_mut() {
                g[j] += 2.0 * b * e;
            }
        }
        value += 2.0 * b * cross;
        let scale = std::f64::consts::SQRT_2 / sigma;
        let mut current = (usize::MAX, 0.0);
        for p in &self.pairs {
            let (ti, tj) = (self.theta[p.i], self.theta[p.j]);
            if ti == 0.0 && tj == 0.0 && grad.is_none() {
                continue;
            }
            if current.0 != p.mid {
                let mp = &self.midpoints[p.mid];
                current = (p.mid, mp.at_reference.diff_from(scale * (z - mp.at)));
            }
            let q = p.weight * current.1;
            value += q * ti * tj;
            if let Some(g) = grad.as_deref_mut() {
                // The weight of an off-diagonal pair is already doubled.
                if p.i == p.j {
                    g[p.i] += 2.0 * q * ti;
                } else {
                    g[p.i] += q * tj;
                    g[p.j] += q * ti;
                }
            }
        }
        if let Some(g) = grad {
            g[m] = 2.0 * b * (z - self.reference) + 2.0 * cross;
        }
        value
    }

    /// The parameters that fit the values `w` at the scalar points `z` in the least-squares
    /// sense with this map's dispersion, min Σ_k (N(z_k) − w_k)² + n·β·θᵀK_ccθ, as far as a
    /// local search finds (the problem is not convex). The search starts from the square root
    /// of the slope of an unconstrained kernel fit, clipped below at a thousandth of the mean
    /// slope (the range of `w` over the range of `z`, or a unit rise when `w` is constant), so
    /// a flat or reversed stretch of `w` still starts the map off a stationary point. For the
    /// same reason the fit's tail slope b² is kept at least that floor. A target that is not monotone gets the monotone map closest to
    /// it.
    ///
    /// # Errors
    /// Points that are not scalar, mismatched lengths or non-finite values.
    pub fn fitted_to(&self, z: &[Vec<f64>], w: &[f64]) -> Result<Self> {
        let free = GaussianFeatures::new(self.root.centres().to_vec(), self.sigma(), self.beta())?
            .fitted_to(z, w)?;
        let zs: Vec<f64> = z.iter().map(|p| p[0]).collect();
        let (start, floor) = self.root_start(&free, &zs, w)?;
        let (zb, wb, counts) = binned(&zs, w, 40 * self.theta.len());
        let mut out = start.polished(&zb, &wb, &counts, zs.len() as f64);
        if out.tail_root * out.tail_root < floor {
            // A flat tail extrapolates flat, and near θ = 0 it sits by the flat map, a
            // stationary point of any later fit.
            let s = out.direction.sign();
            let before: f64 = zs.iter().map(|z| out.integral(*z, None)).sum();
            out.tail_root = floor.sqrt().copysign(out.tail_root);
            let after: f64 = zs.iter().map(|z| out.integral(*z, None)).sum();
            out.level -= s * (after - before) / zs.len() as f64;
        }
        Ok(out)
    }

    /// The start of [`fitted_to`](Self::fitted_to): h fitted to the root of the free fit's
    /// clipped slope on a grid over the points and centres, then a₀ by least squares; and the
    /// floor of the slope.
    fn root_start(&self, free: &GaussianFeatures, z: &[f64], w: &[f64]) -> Result<(Self, f64)> {
        let cs = self.centres();
        let lo = z.iter().chain(&cs).copied().fold(f64::INFINITY, f64::min);
        let hi = z
            .iter()
            .chain(&cs)
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        let m = cs.len();
        let grid: Vec<f64> = (0..=4 * m)
            .map(|k| lo + (hi - lo) * k as f64 / (4 * m) as f64)
            .collect();
        let s = self.direction.sign();
        let mut jac = BlockJacobian::for_map(free);
        let slopes: Vec<f64> = grid
            .iter()
            .map(|t| {
                free.eval_jacobian(&mut [], &[*t], &mut jac);
                s * jac.dw_dz[0]
            })
            .collect();
        let span = (hi - lo).max(f64::MIN_POSITIVE);
        let w_range = w.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - w.iter().copied().fold(f64::INFINITY, f64::min);
        // A thousandth of the mean slope of a monotone map through the values (of a unit
        // rise when they are all equal).
        let floor = 1e-3 * if w_range > 0.0 { w_range } else { 1.0 } / span;
        let roots: Vec<f64> = slopes.iter().map(|v| v.max(floor).sqrt()).collect();
        let mut row = vec![0.0; m + 2];
        let mut columns = vec![vec![0.0; grid.len()]; m + 1];
        for (k, t) in grid.iter().enumerate() {
            self.root.features(&[*t], &mut row);
            for (c, r) in columns.iter_mut().zip(&row) {
                c[k] = *r;
            }
        }
        let penalty = self.root.gram() * (self.beta() * grid.len() as f64);
        let sol = regularised_fit(columns, &roots, &mut |c| c.to_vec(), &penalty)?;
        let mut out = self.clone();
        out.theta = sol.rows(0, m).iter().copied().collect();
        out.tail_root = sol[m];
        out.level = z
            .iter()
            .zip(w)
            .map(|(zk, wk)| wk - s * out.integral(*zk, None))
            .sum::<f64>()
            / z.len() as f64;
        Ok((out, floor))
    }

    /// Levenberg–Marquardt on Σ_k c_k·(N(z_k) − w_k)² + n·‖Rθ‖² from `self` (c_k the points
    /// each of `z`, `w` stands for, n their total): a dense solve in the m + 2 parameters,
    /// never ending above where it started.
    fn polished(self, z: &[f64], w: &[f64], counts: &[f64], n: f64) -> Self {
        let np = self.theta.len() + 2;
        let reg = self
            .regulariser()
            .map(|r| r * n.sqrt())
            .unwrap_or_else(|| DMatrix::zeros(0, np));
        let cost = |f: &Self, p: &DVector<f64>| -> f64 {
            let fit: f64 = z
                .iter()
                .zip(w)
                .zip(counts)
                .map(|((zk, wk), c)| c * (f.eval(&mut [], &[*zk]) - wk).powi(2))
                .sum();
            fit + (&reg * p).norm_squared()
        };
        let mut cur = self;
        let mut p = DVector::from_vec(cur.parameters());
        let mut c = cost(&cur, &p);
        let mut lambda = 1e-3;
        let mut jac = BlockJacobian::for_map(&cur);
        for _ in 0..200 {
            let mut jtj = reg.transpose() * &reg;
            let mut jtr = &jtj * &p;
            for ((zk, wk), c) in z.iter().zip(w).zip(counts) {
                let r = cur.eval_jacobian(&mut [], &[*zk], &mut jac) - wk;
                for a in 0..np {
                    jtr[a] += c * jac.dw_dp[a] * r;
                    for b in 0..np {
                        jtj[(a, b)] += c * jac.dw_dp[a] * jac.dw_dp[b];
                    }
                }
            }
            let accepted = loop {
                let mut lhs = jtj.clone();
                for a in 0..np {
                    lhs[(a, a)] += lambda * jtj[(a, a)].max(1e-12);
                }
                let trial = lhs.cholesky().map(|ch| &p - ch.solve(&jtr));
                let next = trial.and_then(|t| {
                    let f = cur.with_values(t.as_slice())?;
                    let cost = cost(&f, &t);
                    (cost < c).then_some((f, t, cost))
                });
                if let Some(found) = next {
                    lambda = (lambda / 3.0).max(1e-12);
                    break Some(found);
                }
                lambda *= 4.0;
                if lambda > 1e12 {
                    break None;
                }
            };
            let Some((f, t, cost)) = accepted else { break };
            let gain = c - cost;
            (cur, p, c) = (f, t, cost);
            if gain <= 1e-12 * c.max(f64::MIN_POSITIVE) {
                break;
            }
        }
        cur
    }

    /// The map with parameters `p` (θ, b, a₀), `None` when they do not fit.
    fn with_values(&self, p: &[f64]) -> Option<Self> {
        let (theta, rest) = split_parameters(p, self.theta.len(), 2).ok()?;
        Some(Self {
            theta,
            tail_root: rest[0],
            level: rest[1],
            ..self.clone()
        })
    }
}

/// Every pair i ≤ j of `centres` with its weight exp(−(c_i − c_j)²/4σ²)/(2σ√π) (doubled when
/// i < j), ordered by midpoint; midpoints that agree to rounding are one.
fn pairs_by_midpoint(centres: &[f64], sigma: f64, reference: f64) -> (Vec<Pair>, Vec<Midpoint>) {
    let m = centres.len();
    let mut raw: Vec<(f64, usize, usize)> = (0..m)
        .flat_map(|i| (i..m).map(move |j| (i, j)))
        .map(|(i, j)| (0.5 * (centres[i] + centres[j]), i, j))
        .collect();
    raw.sort_by(|a, b| a.0.total_cmp(&b.0));
    let span = centres.iter().fold(0.0f64, |a, c| a.max(c.abs()));
    let scale = std::f64::consts::SQRT_2 / sigma;
    let (mut pairs, mut midpoints): (Vec<Pair>, Vec<Midpoint>) = (Vec::new(), Vec::new());
    for (mid, i, j) in raw {
        if midpoints
            .last()
            .is_none_or(|last| (mid - last.at).abs() > 1e-12 * span.max(f64::MIN_POSITIVE))
        {
            midpoints.push(Midpoint {
                at: mid,
                at_reference: NormalAt::new(scale * (reference - mid)),
            });
        }
        let d = centres[i] - centres[j];
        let once =
            (-d * d / (4.0 * sigma * sigma)).exp() / (2.0 * sigma * std::f64::consts::PI.sqrt());
        pairs.push(Pair {
            i,
            j,
            weight: if i == j { once } else { 2.0 * once },
            mid: midpoints.len() - 1,
        });
    }
    (pairs, midpoints)
}

/// The points sorted by z and averaged in at most `bins` runs of equal count: what the polish
/// of [`MonotoneFeatures::fitted_to`] fits, so that its cost does not grow with the record
/// (a smoothed latent signal has a point per sample). Returns the mean z, the mean w and the
/// count of each run; with fewer points than bins, the points themselves.
fn binned(z: &[f64], w: &[f64], bins: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    if z.len() <= bins {
        return (z.to_vec(), w.to_vec(), vec![1.0; z.len()]);
    }
    let mut order: Vec<usize> = (0..z.len()).collect();
    order.sort_by(|&a, &b| z[a].total_cmp(&z[b]));
    let (mut zb, mut wb, mut counts) = (Vec::new(), Vec::new(), Vec::new());
    for run in 0..bins {
        let (a, b) = (run * z.len() / bins, (run + 1) * z.len() / bins);
        let c = (b - a) as f64;
        zb.push(order[a..b].iter().map(|&k| z[k]).sum::<f64>() / c);
        wb.push(order[a..b].iter().map(|&k| w[k]).sum::<f64>() / c);
        counts.push(c);
    }
    (zb, wb, counts)
}

impl BlockMap for MonotoneFeatures {
    fn kind(&self) -> &'static str {
        "monotone features"
    }

    fn input_len(&self) -> usize {
        1
    }

    fn parameters(&self) -> Vec<f64> {
        let mut p = self.theta.clone();
        p.extend([self.tail_root, self.level]);
        p
    }

    fn with_parameters(&self, p: &[f64]) -> Result<Box<dyn BlockMap>> {
        let (theta, rest) = split_parameters(p, self.theta.len(), 2)?;
        Ok(Box::new(Self {
            theta,
            tail_root: rest[0],
            level: rest[1],
            ..self.clone()
        }))
    }

    fn eval(&self, _state: &mut [f64], z: &[f64]) -> f64 {
        self.level + self.direction.sign() * self.integral(z[0], None)
    }

    fn eval_jacobian(&self, _state: &mut [f64], z: &[f64], jac: &mut BlockJacobian) -> f64 {
        let (m, s) = (self.theta.len(), self.direction.sign());
        let value = self.integral(z[0], Some(&mut jac.dw_dp[..=m]));
        for g in &mut jac.dw_dp[..=m] {
            *g *= s;
        }
        jac.dw_dp[m + 1] = 1.0;
        jac.dw_dz[0] = s * self.slope_root(z[0]).powi(2);
        self.level + s * value
    }

    fn regulariser(&self) -> Option<DMatrix<f64>> {
        // The root's regulariser has m + 2 columns (θ, then its own level and slope), the
        // same count as this map's θ, b, a₀, and touches θ only.
        self.root.regulariser()
    }

    /// The line a₀ + s·b²·(z − r): the slope the map takes far from its centres on both sides
    /// (it runs parallel to this line there, offset on each side by the kernel part's integral),
    /// and the whole map when θ = 0.
    fn affine_part(&self) -> Option<(f64, Vec<f64>)> {
        let slope = self.direction.sign() * self.tail_root * self.tail_root;
        Some((self.level - slope * self.reference, vec![slope]))
    }

    fn boxed(&self) -> Box<dyn BlockMap> {
        Box::new(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn map(direction: Monotonicity, p: &[f64]) -> Box<dyn BlockMap> {
        MonotoneFeatures::on_interval(-1.0, 2.0, 5, 0.6, 1e-3, direction)
            .unwrap()
            .with_parameters(p)
            .unwrap()
    }

    /// ∫_r^z h² by composite Simpson on 2000 panels, from the definition of h.
    fn quadrature(f: &MonotoneFeatures, z: f64) -> f64 {
        let (a, n) = (f.reference, 2000);
        let step = (z - a) / n as f64;
        let h2 = |t: f64| f.slope_root(t).powi(2);
        let mut sum = h2(a) + h2(z);
        for k in 1..n {
            sum += h2(a + step * k as f64) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        sum * step / 3.0
    }

    #[test]
    fn the_closed_form_matches_quadrature() {
        let p = [0.4, -1.1, 0.7, 0.2, -0.3, 0.25, 1.5];
        let f = MonotoneFeatures::on_interval(-1.0, 2.0, 5, 0.6, 0.0, Monotonicity::Increasing)
            .unwrap();
        let f = f.with_values(&p).unwrap();
        // Five evenly spaced centres: 15 pairs share 9 midpoints.
        assert_eq!((f.pairs.len(), f.midpoints.len()), (15, 9));
        for z in [-4.0, -1.0, 0.3, 0.5, 1.7, 6.0] {
            let closed = f.integral(z, None);
            let numeric = quadrature(&f, z);
            assert!(
                (closed - numeric).abs() < 1e-9 * (1.0 + numeric.abs()),
                "z = {z}: {closed} vs {numeric}"
            );
        }
    }

    #[test]
    fn the_regulariser_squares_to_beta_times_the_norm_of_the_root() {
        let p = [0.4, -1.1, 0.7, 0.2, -0.3, 9.0, 4.0];
        let f = map(Monotonicity::Increasing, &p);
        let r = f.regulariser().unwrap();
        let rt = (&r * DVector::from_column_slice(&p)).norm_squared();
        let c = [-1.0, -0.25, 0.5, 1.25, 2.0];
        let k = |a: f64, b: f64| {
            (-(a - b) * (a - b) / (2.0 * 0.36)).exp() / (0.6 * (2.0 * std::f64::consts::PI).sqrt())
        };
        let d: f64 = (0..5)
            .flat_map(|i| (0..5).map(move |j| (i, j)))
            .map(|(i, j)| p[i] * p[j] * k(c[i], c[j]))
            .sum();
        assert!((rt - 1e-3 * d).abs() < 1e-8 * d, "{rt} vs {}", 1e-3 * d);
    }

    #[test]
    fn the_tail_is_the_affine_part() {
        let f = map(
            Monotonicity::Decreasing,
            &[0.5, -0.2, 0.3, 0.1, 0.4, 0.8, -2.0],
        );
        let (a0, a) = f.affine_part().unwrap();
        // Far below the centres every kernel term and every integral beyond the tail is
        // negligible, and the map runs parallel to the tail line; far above as well.
        let gap = |z: f64| f.eval(&mut [], &[z]) - (a0 + a[0] * z);
        assert!((gap(-40.0) - gap(-60.0)).abs() < 1e-12);
        assert!((gap(40.0) - gap(60.0)).abs() < 1e-12);
        assert!(a[0] < 0.0);
    }

    #[test]
    fn a_reversed_target_gets_a_monotone_fit() {
        let f = MonotoneFeatures::on_interval(-1.0, 1.0, 7, 0.4, 1e-9, Monotonicity::Increasing)
            .unwrap();
        let z: Vec<Vec<f64>> = (0..60).map(|k| vec![-1.0 + k as f64 / 29.5]).collect();
        // Up, then down over the last third: the best increasing fit flattens there.
        let w: Vec<f64> = z.iter().map(|z| (2.0 * z[0]).sin()).collect();
        let f = f.fitted_to(&z, &w).unwrap();
        let values: Vec<f64> = z.iter().map(|z| f.eval(&mut [], z)).collect();
        assert!(Monotonicity::Increasing.holds(&values));
        // Where the target rises the fit follows it.
        assert!(
            (values[20] - w[20]).abs() < 0.05,
            "{} vs {}",
            values[20],
            w[20]
        );
    }

    #[test]
    fn a_flat_target_still_starts_off_the_stationary_point() {
        let f = MonotoneFeatures::on_interval(0.0, 1.0, 4, 0.4, 1e-6, Monotonicity::Increasing)
            .unwrap();
        let z: Vec<Vec<f64>> = (0..10).map(|k| vec![k as f64 / 9.0]).collect();
        let f = f.fitted_to(&z, &[0.0; 10]).unwrap();
        let p = f.parameters();
        assert!(p[..5].iter().any(|v| *v != 0.0), "{p:?}");
        assert!(f.eval(&mut [], &[0.5]).abs() < 1e-2);
    }

    #[test]
    fn a_long_record_is_fitted_through_its_runs() {
        // 30 000 noisy points of √z: the polish fits 40·m averaged runs, and the map is still
        // within the noise's reach of the truth.
        let n = 30_000;
        let z: Vec<Vec<f64>> = (0..n)
            .map(|k| vec![4.0 * ((k * 7919) % n) as f64 / n as f64])
            .collect();
        let w: Vec<f64> = z
            .iter()
            .enumerate()
            .map(|(k, z)| z[0].sqrt() + 0.05 * (((k * 104_729) % 1000) as f64 / 500.0 - 1.0))
            .collect();
        let f = MonotoneFeatures::on_interval(0.0, 4.0, 10, 0.65, 1e-9, Monotonicity::Increasing)
            .unwrap()
            .fitted_to(&z, &w)
            .unwrap();
        for t in [0.5, 1.0, 2.0, 3.5] {
            let e = (f.eval(&mut [], &[t]) - f64::sqrt(t)).abs();
            assert!(e < 0.02, "at {t}: {e}");
        }
        let (zb, _, counts) = binned(&[3.0, 1.0, 2.0, 0.0], &[0.0; 4], 2);
        assert_eq!((zb, counts), (vec![0.5, 2.5], vec![2.0, 2.0]));
    }

    proptest! {
        #[test]
        fn monotone_for_every_parameter(
            p in proptest::collection::vec(-3.0f64..3.0, 7),
            decreasing in any::<bool>(),
        ) {
            let d = if decreasing { Monotonicity::Decreasing } else { Monotonicity::Increasing };
            let f = map(d, &p);
            let values: Vec<f64> = (0..400).map(|k| f.eval(&mut [], &[-6.0 + 0.03 * k as f64])).collect();
            // Ties to rounding where the slope vanishes.
            let tol = 1e-12 * values.iter().map(|v| v.abs()).fold(1.0, f64::max);
            prop_assert!(values.windows(2).all(|w| d.sign() * (w[1] - w[0]) >= -tol));
        }

        #[test]
        fn derivatives_match_finite_differences(
            p in proptest::collection::vec(-2.0f64..2.0, 7),
            z in -3.0f64..4.0,
            decreasing in any::<bool>(),
        ) {
            let d = if decreasing { Monotonicity::Decreasing } else { Monotonicity::Increasing };
            let f = map(d, &p);
            let mut jac = BlockJacobian::for_map(f.as_ref());
            f.eval_jacobian(&mut [], &[z], &mut jac);
            let h = 1e-6;
            let fd = (f.eval(&mut [], &[z + h]) - f.eval(&mut [], &[z - h])) / (2.0 * h);
            prop_assert!((fd - jac.dw_dz[0]).abs() < 1e-6 * (1.0 + fd.abs()), "z: {} vs {}", fd, jac.dw_dz[0]);
            for i in 0..p.len() {
                let (mut a, mut b) = (p.clone(), p.clone());
                a[i] += h;
                b[i] -= h;
                let fa = map(d, &a).eval(&mut [], &[z]);
                let fb = map(d, &b).eval(&mut [], &[z]);
                let fd = (fa - fb) / (2.0 * h);
                prop_assert!((fd - jac.dw_dp[i]).abs() < 1e-6 * (1.0 + fd.abs()), "θ{}: {} vs {}", i, fd, jac.dw_dp[i]);
            }
        }
    }
}
