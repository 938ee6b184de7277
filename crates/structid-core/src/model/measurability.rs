//! Measurability of z (paper, Definition 1): can the inputs of the static maps be computed from
//! the known input u and the measured output y?
//!
//! Four cases are recognised, tried in this order (the cheaper ones first):
//! 1. z is measured and given with the data;
//! 2. z does not depend on (e, w) at all (L_ze = 0 and L_zw = 0 as systems), so z = L_zu·u;
//! 3. a constant Ψ maps the (e, w)-part of y onto that of z, i.e. L_z(e,w) = Ψ·L_y(e,w) as
//!    systems, so z = L_zu·u + Ψ·(y − L_yu·u). Output feedback z = y is the typical case;
//! 4. an LTI Ψ(q) does: z = L_zu·u + Ψ(q)·(y − L_yu·u) (the paper's Definition 1 in full), e.g.
//!    z = the measured rate (y_k − y_(k−1))/T_s. It is found by inverting the noise path: when
//!    D_ye is square and invertible, e = D_ye⁻¹·(y − C_y·x − D_yu·u − D_yw·w) turns the LFT into
//!    a system driven by (u, y, w),
//!
//!    ```text
//!      x⁺ = (A − B_e·D⁻¹·C_y)·x + (B_u − B_e·D⁻¹·D_yu)·u + B_e·D⁻¹·y + (B_w − B_e·D⁻¹·D_yw)·w
//!      z  = (C_z − D_ze·D⁻¹·C_y)·x + (D_zu − D_ze·D⁻¹·D_yu)·u + D_ze·D⁻¹·y + (D_zw − D_ze·D⁻¹·D_yw)·w
//!    ```
//!
//!    and z is measurable when its w → z transfer is zero: then z is this system's response to
//!    (u, y) with w = 0 and a zero initial state ([`ZSource::Dynamic`] keeps the part of it that
//!    z observes).
//!
//! Cases 2–4 are checked on the Markov parameters D and C·A^k·B, k < n, of the (e, w) (or w)
//! paths: by Cayley–Hamilton these determine the systems, whereas C_z = 0 alone would not.
//!
//! In case 4 the inverse system can be unstable (a noise model that is not minimum phase):
//! [`Lft::compute_z`] then stops with [`Error::Numerical`] when z diverges.

use nalgebra::DMatrix;
use structid_lti::{LinearSystem, Signal, StateSpace};

use crate::error::{Error, Result};
use crate::model::lft::Lft;

/// How z is obtained from the data.
#[derive(Clone, Debug, PartialEq)]
pub enum ZSource {
    /// z was measured and supplied with the data.
    Measured,
    /// z = L_zu·u: the maps' inputs do not depend on noise or on the maps' outputs.
    InputOnly,
    /// z = L_zu·u + Ψ·(y − L_yu·u) with the given Ψ (n_z × n_y).
    OutputInjection {
        /// The matrix Ψ.
        psi: DMatrix<f64>,
    },
    /// z = L_zu·u + Ψ(q)·(y − L_yu·u) with an LTI Ψ(q): z is the response of `system` to the
    /// stacked input `[u; y]` from a zero initial state.
    Dynamic {
        /// The noise path inverted through D_ye (inputs `[u; y]`, outputs z), reduced to the
        /// states that z observes (boxed: it is much larger than the other variants).
        system: Box<StateSpace>,
    },
}

impl ZSource {
    /// A one-line description for reports.
    pub fn describe(&self) -> String {
        match self {
            ZSource::Measured => "measured z columns".into(),
            ZSource::InputOnly => "z = L_zu·u (z does not depend on e or w)".into(),
            ZSource::OutputInjection { psi } => {
                format!("z = L_zu·u + Ψ·(y − L_yu·u), Ψ = {:?}", psi.as_slice())
            }
            ZSource::Dynamic { system } => format!(
                "z = L_zu·u + Ψ(q)·(y − L_yu·u) with an LTI Ψ of order {} (z filtered from u and y \
                 through the inverted noise path)",
                system.order()
            ),
        }
    }
}

/// Stacks [D, C·B, C·A·B, …, C·A^(n−1)·B] for the (e, w) inputs and the given output rows.
fn markov_stack(lft: &Lft, output_z: bool) -> DMatrix<f64> {
    let m = lft.matrices();
    let dims = lft.dims();
    let n = dims.states;
    let (c, de, dw, rows) = if output_z {
        (&m.cz, &m.dze, &m.dzw, dims.z)
    } else {
        (&m.cy, &m.dye, &m.dyw, dims.y)
    };
    let k = dims.e + dims.w;
    let mut b = DMatrix::zeros(n, k);
    b.columns_mut(0, dims.e).copy_from(&m.be);
    b.columns_mut(dims.e, dims.w).copy_from(&m.bw);
    let mut out = DMatrix::zeros(rows, k * (n + 1));
    out.view_mut((0, 0), (rows, dims.e)).copy_from(de);
    out.view_mut((0, dims.e), (rows, dims.w)).copy_from(dw);
    let mut ak_b = b;
    for j in 0..n {
        let h = c * &ak_b;
        out.view_mut((0, k * (j + 1)), (rows, k)).copy_from(&h);
        ak_b = &m.a * ak_b;
    }
    out
}

/// The Markov parameters of finite but huge LFT matrices can overflow, or their norm can: the
/// SVD of a non-finite stack panics (NaN singular values) and an infinite norm makes every
/// tolerance infinite (z would pass as input-only), so both are an input error.
fn check_markov_finite(h: &DMatrix<f64>, output: &str) -> Result<()> {
    if h.iter().all(|v| v.is_finite()) && h.norm().is_finite() {
        return Ok(());
    }
    Err(Error::InvalidStructure(format!(
        "the Markov parameters of the paths from (e, w) to {output} (D and C·Aᵏ·B) overflow \
         the range of f64: the LFT matrices are too large; rescale the signals or the model"
    )))
}

impl Lft {
    /// Whether the noise reaches neither the state nor z (B_e = 0 and D_ze = 0): an
    /// output-error model, whose z is a function of u alone (the simulation's) and whose
    /// one-step predictor is the simulation, whatever the maps' places.
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_core::{Lft, LftMatrices};
    /// let m = |be: f64| LftMatrices {
    ///     a: dmatrix![0.5], bu: dmatrix![1.0], be: dmatrix![be], bw: dmatrix![1.0],
    ///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
    ///     cz: dmatrix![1.0], dzu: dmatrix![0.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
    /// };
    /// assert!(Lft::new(m(0.0)).unwrap().noise_free_z());
    /// assert!(!Lft::new(m(0.3)).unwrap().noise_free_z());
    /// ```
    pub fn noise_free_z(&self) -> bool {
        let m = self.matrices();
        m.be.iter().chain(m.dze.iter()).all(|v| *v == 0.0)
    }

    /// Decides whether z can be computed from u and y, and how.
    ///
    /// Returns [`Error::NotMeasurable`] with an explanation otherwise.
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_core::{Lft, LftMatrices, ZSource};
    /// // Output feedback: y = x, x⁺ = 0.9x + u − w, z = y.
    /// let lft = Lft::new(LftMatrices {
    ///     a: dmatrix![0.9], bu: dmatrix![1.0], be: dmatrix![0.0], bw: dmatrix![-1.0],
    ///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
    ///     cz: dmatrix![1.0], dzu: dmatrix![0.0], dze: dmatrix![1.0], dzw: dmatrix![0.0],
    /// }).unwrap();
    /// assert!(matches!(lft.measurability().unwrap(), ZSource::OutputInjection { .. }));
    /// ```
    pub fn measurability(&self) -> Result<ZSource> {
        let dims = self.dims();
        if dims.z == 0 {
            return Ok(ZSource::InputOnly);
        }
        let hz = markov_stack(self, true);
        check_markov_finite(&hz, "z")?;
        let scale = hz.norm().max(1.0);
        if hz.norm() <= 1e-12 * scale {
            return Ok(ZSource::InputOnly);
        }
        let hy = markov_stack(self, false);
        check_markov_finite(&hy, "y")?;
        let svd = hy.clone().svd(true, true);
        let tol = 1e-12 * svd.singular_values.max().max(1.0);
        let pinv = svd
            .pseudo_inverse(tol)
            .map_err(|e| Error::Numerical(format!("pseudo-inverse in measurability check: {e}")))?;
        let psi = &hz * pinv;
        let misfit = (&psi * &hy - &hz).norm();
        if misfit <= 1e-9 * scale {
            return Ok(ZSource::OutputInjection { psi });
        }
        match dynamic_inverse(self) {
            Ok(system) => Ok(ZSource::Dynamic {
                system: Box::new(system),
            }),
            Err(why_not_dynamic) => Err(Error::NotMeasurable {
                explanation: format!(
                    "the part of z driven by the noise e and the map outputs w is not a fixed linear function of y \
                     (best fit z ≈ Ψ·y leaves a relative misfit of {:.3e} on the Markov parameters), nor a causal \
                     LTI filter Ψ(q) of y ({why_not_dynamic}); \
                     provide z as measured data columns (`z = [...]` under [signals] in the model file, or Data::with_z), \
                     or restructure the model so that z depends only on u and y",
                    misfit / scale
                ),
            }),
        }
    }

    /// Computes z from u and y according to [`Lft::measurability`], with a zero initial state.
    ///
    /// For [`ZSource::Dynamic`], z is the response of the inverted noise path to (u, y); if that
    /// path is unstable and z diverges (non-finite, or beyond 10¹²× the size of u and y),
    /// the result is [`Error::Numerical`].
    pub fn compute_z(&self, u: &Signal, y: &Signal) -> Result<(Signal, ZSource)> {
        let source = self.measurability()?;
        if let ZSource::Dynamic { system } = &source {
            let z = dynamic_z(self, system, u, y)?;
            return Ok((z, source));
        }
        let mut z = self.t_zu().simulate(u)?;
        if let ZSource::OutputInjection { psi } = &source {
            let r = self.residual(u, y)?;
            let (nz, ny) = (psi.nrows(), psi.ncols());
            for k in 0..z.len() {
                let rk = r.sample(k).to_vec();
                let zk = z.sample_mut(k);
                for i in 0..nz {
                    zk[i] += (0..ny).map(|j| psi[(i, j)] * rk[j]).sum::<f64>();
                }
            }
        }
        Ok((z, source))
    }
}

/// Simulates the inverted noise path `system` (inputs `[u; y]`) from rest and checks that z
/// stays bounded.
fn dynamic_z(lft: &Lft, system: &StateSpace, u: &Signal, y: &Signal) -> Result<Signal> {
    let dims = lft.dims();
    let len = u.len();
    for (what, s, channels) in [("u", u, dims.u), ("y", y, dims.y)] {
        if s.channels() != channels || s.len() != len {
            return Err(Error::DimensionMismatch {
                what: format!("signal {what} for computing z"),
                expected: format!("{len} samples × {channels} channels"),
                found: format!("{} samples × {} channels", s.len(), s.channels()),
            });
        }
    }
    let nu = dims.u;
    let uy = Signal::from_fn(len, nu + dims.y, |k, c| {
        if c < nu {
            u.get(k, c)
        } else {
            y.get(k, c - nu)
        }
    });
    let size = uy.as_slice().iter().fold(
        1.0f64,
        |m, v| if v.is_finite() { m.max(v.abs()) } else { m },
    );
    let z = system.simulate(&uy)?;
    let nz = z.channels().max(1);
    if let Some(i) = z
        .as_slice()
        .iter()
        .position(|v| !v.is_finite() || v.abs() > 1e12 * size)
    {
        return Err(Error::Numerical(format!(
            "z computed from y through the dynamic Ψ(q) (the inverted noise path) diverges: \
             z = {:.3e} at sample {}, channel {}, while u and y stay below {:.3e}. The inverse of the \
             noise path has spectral radius {:.4} (≥ 1: the noise model is not minimum phase), so z \
             cannot be recovered from y stably; provide z as measured data columns, or give the \
             model a minimum-phase noise path",
            z.as_slice()[i],
            i / nz,
            i % nz,
            size,
            system.spectral_radius()
        )));
    }
    Ok(z)
}

/// The noise path of `lft` inverted through D_ye: a system with inputs `[u; y]` and outputs z
/// (reduced to the states z observes) when w does not reach z once e is recovered from y;
/// otherwise why not.
fn dynamic_inverse(lft: &Lft) -> std::result::Result<StateSpace, String> {
    let dims = lft.dims();
    let m = lft.matrices();
    let n = dims.states;
    if dims.e != dims.y {
        return Err(format!(
            "that needs D_ye square and invertible, but there are {} noise channels for {} outputs",
            dims.e, dims.y
        ));
    }
    let sv = m.dye.clone().singular_values();
    let (smax, smin) = (sv.max(), sv.min());
    if smax <= 0.0 || smin <= 1e-12 * smax {
        return Err(format!(
            "that needs D_ye invertible, but its singular values range from {smax:.3e} down to {smin:.3e}"
        ));
    }
    let dinv = m
        .dye
        .clone()
        .try_inverse()
        .ok_or_else(|| "that needs D_ye invertible, and it is singular".to_string())?;
    let g = &m.be * &dinv;
    let h = &m.dze * &dinv;
    let at = &m.a - &g * &m.cy;
    let btu = &m.bu - &g * &m.dyu;
    let btw = &m.bw - &g * &m.dyw;
    let ctz = &m.cz - &h * &m.cy;
    let dtu = &m.dzu - &h * &m.dyu;
    let dtw = &m.dzw - &h * &m.dyw;
    // Markov parameters of the (y, w) → z paths of the inverse system.
    let (ny, nw) = (dims.y, dims.w);
    let mut bt = DMatrix::zeros(n, ny + nw);
    bt.columns_mut(0, ny).copy_from(&g);
    bt.columns_mut(ny, nw).copy_from(&btw);
    let mut w_part = dtw.norm_squared();
    let mut all = w_part + h.norm_squared();
    let mut ak_b = bt;
    for _ in 0..n {
        let mk = &ctz * &ak_b;
        let mw = mk.columns(ny, nw).norm_squared();
        w_part += mw;
        all += mk.norm_squared();
        ak_b = &at * ak_b;
    }
    let (w_part, scale) = (w_part.sqrt(), all.sqrt().max(1.0));
    if w_part.is_nan() || w_part > 1e-9 * scale {
        return Err(format!(
            "with the noise recovered from y as e = D_ye⁻¹·(y − …), the map outputs w still reach z \
             (relative size {:.3e} of the w → z Markov parameters)",
            w_part / scale
        ));
    }
    // Keep the part of the state that z observes: an orthonormal basis T (rows) of the row
    // space of [C̃_z; C̃_z·Ã; …], which is invariant under ·Ã, so ξ = T·x follows
    // ξ⁺ = T·Ã·Tᵀ·ξ + T·B̃·v and z = C̃_z·Tᵀ·ξ + D̃·v exactly.
    let basis = observed_rows(&ctz, &at);
    let r = basis.len();
    let t = DMatrix::from_fn(r, n, |i, j| basis[i][j]);
    let mut b_uy = DMatrix::zeros(n, dims.u + ny);
    b_uy.columns_mut(0, dims.u).copy_from(&btu);
    b_uy.columns_mut(dims.u, ny).copy_from(&g);
    let mut d_uy = DMatrix::zeros(dims.z, dims.u + ny);
    d_uy.columns_mut(0, dims.u).copy_from(&dtu);
    d_uy.columns_mut(dims.u, ny).copy_from(&h);
    let system = StateSpace::new(
        &t * &at * t.transpose(),
        &t * b_uy,
        &ctz * t.transpose(),
        d_uy,
    )
    .map_err(|e| format!("the inverted noise path is not a valid system: {e}"))?;
    match lft.sample_time() {
        Some(ts) => system
            .with_sample_time(ts)
            .map_err(|e| format!("sample time of the inverted noise path: {e}")),
        None => Ok(system),
    }
}

/// An orthonormal basis (as rows) of the smallest ·A-invariant row space holding the rows of
/// C: the states that the output C·x observes.
fn observed_rows(c: &DMatrix<f64>, a: &DMatrix<f64>) -> Vec<Vec<f64>> {
    let n = a.nrows();
    let mut basis: Vec<Vec<f64>> = Vec::new();
    // Adds the part of v orthogonal to the basis unless it is negligible next to `reference`.
    let add = |basis: &mut Vec<Vec<f64>>, mut v: Vec<f64>, reference: f64| -> bool {
        if basis.len() >= n || reference <= 0.0 {
            return false;
        }
        for _ in 0..2 {
            for q in basis.iter() {
                let p: f64 = q.iter().zip(&v).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(q).for_each(|(x, qi)| *x -= p * qi);
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-10 * reference {
            v.iter_mut().for_each(|x| *x /= norm);
            basis.push(v);
            true
        } else {
            false
        }
    };
    let c_ref = (0..c.nrows()).map(|i| c.row(i).norm()).fold(0.0, f64::max);
    let mut fresh = Vec::new();
    for i in 0..c.nrows() {
        if add(&mut basis, c.row(i).iter().copied().collect(), c_ref) {
            fresh.push(basis.len() - 1);
        }
    }
    let a_ref = a.norm();
    while let Some(i) = fresh.pop() {
        // v = q_i·A (a row vector).
        let v: Vec<f64> = (0..n)
            .map(|j| (0..n).map(|k| basis[i][k] * a[(k, j)]).sum())
            .collect();
        if add(&mut basis, v, a_ref) {
            fresh.push(basis.len() - 1);
        }
    }
    basis
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::problem::Problem;
    use crate::model::lft::LftMatrices;
    use crate::model::structure::{Site, polynomial_lft};
    use crate::model::{Data, Model, NonlinearBlock};

    fn rate_feedback_lft(g: &structid_linear::PolynomialModel) -> Result<Lft> {
        polynomial_lft(g, Some(Site::RateFeedback), false)
    }
    use crate::model::simulate::MapBinding;
    use nalgebra::dmatrix;
    use proptest::prelude::*;
    use std::sync::Arc;
    use structid_linear::PolynomialModel;
    use structid_lti::testing::{SplitMix64, random_stable_system};

    /// Largest |a − b| relative to max(1, max |b|).
    fn rel_diff(a: &Signal, b: &Signal) -> f64 {
        assert_eq!((a.len(), a.channels()), (b.len(), b.channels()));
        let scale = b.as_slice().iter().fold(1.0f64, |m, v| m.max(v.abs()));
        a.as_slice()
            .iter()
            .zip(b.as_slice())
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
            / scale
    }

    fn gaussian(rng: &mut SplitMix64, len: usize, channels: usize, std: f64) -> Signal {
        Signal::from_fn(len, channels, |_, _| {
            // Box–Muller from two uniforms.
            let (a, b) = (rng.uniform().max(1e-300), rng.uniform());
            std * (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        })
    }

    /// Found by the `lft_problem` fuzz target: finite LFT entries whose Markov parameters
    /// overflow made the SVD panic (NaN singular values) or, when only their norm overflowed,
    /// z look input-only.
    #[test]
    fn overflowing_markov_parameters_are_an_error_not_a_panic() {
        let lft = |cy: f64, cz: f64| {
            Lft::new(LftMatrices {
                a: dmatrix![0.5],
                bu: dmatrix![0.0],
                be: dmatrix![1e300],
                bw: dmatrix![0.0],
                cy: dmatrix![cy],
                dyu: dmatrix![0.0],
                dye: dmatrix![1.0],
                dyw: dmatrix![0.0],
                cz: dmatrix![cz],
                dzu: dmatrix![0.0],
                dze: dmatrix![0.0],
                dzw: dmatrix![0.0],
            })
            .unwrap()
        };
        for (cy, cz, output) in [
            (1e300, 1e-300, "to y"),
            (1.0, 1e300, "to z"),
            (1.0, 1e-100, "to z"),
        ] {
            let e = lft(cy, cz).measurability().unwrap_err();
            assert!(matches!(e, Error::InvalidStructure(_)), "{e:?}");
            assert!(e.to_string().contains(output), "{e}");
            let u = Signal::zeros(4, 0);
            let y = Signal::zeros(4, 1);
            assert!(lft(cy, cz).compute_z(&u, &y).is_err());
        }
    }

    #[test]
    fn rate_feedback_lft_is_dynamic_and_compute_z_matches_simulation() {
        for seed in 0..8u64 {
            let mut rng = SplitMix64::new(seed);
            // A random stable second-order G with one sample of delay.
            let (p1, p2) = (rng.uniform_in(-0.9, 0.9), rng.uniform_in(-0.9, 0.9));
            let g = PolynomialModel {
                num: vec![vec![
                    0.0,
                    rng.uniform_in(0.2, 1.0),
                    rng.uniform_in(-0.5, 0.5),
                ]],
                den: vec![1.0, -(p1 + p2), p1 * p2],
                sample_time: Some(rng.uniform_in(0.05, 1.0)),
            };
            let lft = rate_feedback_lft(&g).unwrap();
            let source = lft.measurability().unwrap();
            let ZSource::Dynamic { system } = &source else {
                panic!("seed {seed}: {source:?}");
            };
            // Ψ = (1 − q⁻¹)/T_s needs one state (the previous output).
            assert_eq!(system.order(), 1, "seed {seed}");
            assert!(source.describe().contains("Ψ(q)"));
            // A random bounded friction-like map.
            let (a, b, c) = (
                rng.uniform_in(0.05, 0.5),
                rng.uniform_in(0.2, 3.0),
                rng.uniform_in(-0.2, 0.2),
            );
            let map = move |z: &[f64]| a * (b * z[0]).tanh() + c * (z[0]).sin();
            let len = 400;
            let u = gaussian(&mut rng, len, 1, 1.0);
            let e = gaussian(&mut rng, len, 1, 0.1);
            let sim = lft
                .simulate(
                    &[MapBinding {
                        inputs: &[0],
                        output: 0,
                        map: &map,
                    }],
                    &u,
                    Some(&e),
                    None,
                )
                .unwrap();
            let (z, _) = lft.compute_z(&u, &sim.y).unwrap();
            let d = rel_diff(&z, &sim.z);
            assert!(
                d < 1e-9,
                "seed {seed}: compute_z differs from simulate's z by {d}"
            );
        }
    }

    #[test]
    fn z_driven_by_w_through_a_state_y_does_not_reveal_is_not_measurable() {
        // x⁺ = 0.5·x + w, y = e, z = x: y says nothing about x.
        let lft = Lft::new(LftMatrices {
            a: dmatrix![0.5],
            bu: dmatrix![0.0],
            be: dmatrix![0.0],
            bw: dmatrix![1.0],
            cy: dmatrix![0.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: dmatrix![0.0],
            cz: dmatrix![1.0],
            dzu: dmatrix![0.0],
            dze: dmatrix![0.0],
            dzw: dmatrix![0.0],
        })
        .unwrap();
        let err = lft.measurability().unwrap_err();
        let Error::NotMeasurable { explanation } = &err else {
            panic!("{err:?}");
        };
        assert!(explanation.contains("LTI filter"), "{explanation}");
        assert!(explanation.contains("w still reach z"), "{explanation}");
        assert!(
            explanation.contains("provide z as measured"),
            "{explanation}"
        );
        // Two outputs and one noise channel: the dynamic case cannot be tried.
        let mut m = lft.matrices().clone();
        m.cy = dmatrix![0.0; 1.0];
        m.dyu = dmatrix![0.0; 0.0];
        m.dye = dmatrix![1.0; 0.0];
        m.dyw = dmatrix![0.0; 0.0];
        m.bw = dmatrix![1.0];
        m.cz = dmatrix![1.0];
        m.a = dmatrix![0.5];
        // y₂ = x reveals x only through C_y, yet the constant Ψ = [0, 1] works: case 3.
        let lft2 = Lft::new(m.clone()).unwrap();
        assert!(matches!(
            lft2.measurability().unwrap(),
            ZSource::OutputInjection { .. }
        ));
        m.cy = dmatrix![0.0; 0.0];
        let err = Lft::new(m)
            .unwrap()
            .measurability()
            .unwrap_err()
            .to_string();
        assert!(err.contains("2 outputs"), "{err}");
    }

    #[test]
    fn unstable_inverse_noise_path_makes_compute_z_fail_clearly() {
        // Non-minimum-phase noise y = e + 2·e_(k−1) (x⁺ = e, y = 2x + e), z = x = e_(k−1):
        // recovering e from y runs x⁺ = y − 2x, which diverges.
        let lft = Lft::new(LftMatrices {
            a: dmatrix![0.0],
            bu: dmatrix![0.0],
            be: dmatrix![1.0],
            bw: DMatrix::zeros(1, 0),
            cy: dmatrix![2.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: DMatrix::zeros(1, 0),
            cz: dmatrix![1.0],
            dzu: dmatrix![0.0],
            dze: dmatrix![0.0],
            dzw: DMatrix::zeros(1, 0),
        })
        .unwrap();
        let source = lft.measurability().unwrap();
        assert!(matches!(source, ZSource::Dynamic { .. }), "{source:?}");
        let mut rng = SplitMix64::new(5);
        let u = Signal::zeros(200, 1);
        let y = gaussian(&mut rng, 200, 1, 1.0);
        let err = lft.compute_z(&u, &y).unwrap_err();
        let text = err.to_string();
        assert!(matches!(err, Error::Numerical(_)), "{text}");
        assert!(
            text.contains("diverges") && text.contains("minimum phase"),
            "{text}"
        );
    }

    #[test]
    fn dynamic_z_with_an_estimated_initial_state_is_not_measurable() {
        let g = PolynomialModel {
            num: vec![vec![0.0, 1.0]],
            den: vec![1.0, -0.5],
            sample_time: None,
        };
        let lft = rate_feedback_lft(&g).unwrap();
        let block = NonlinearBlock::new(
            "N",
            vec![0],
            0,
            Arc::new(crate::KernelDispersion::gaussian(0.3).unwrap()),
        );
        let model = Model::new(lft, vec![block]).unwrap();
        let u = Signal::from_fn(30, 1, |k, _| (0.3 * k as f64).sin());
        let y = Signal::from_fn(30, 1, |k, _| (0.2 * k as f64).cos());
        let data = Data::new(u, y).unwrap();
        assert!(Problem::from_model(&model, &data).is_ok());
        let err = Problem::from_model_with_initial_state(&model, &data)
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("dynamic Ψ(q)") && err.contains("zero initial state"),
            "{err}"
        );
    }

    /// "Random G, z = filter(y)": a random stable G from (u, e, w) to y, and z = C_f·x_f where
    /// x_f⁺ = A_f·x_f + B_f·y is a random stable filter of y carried as extra states.
    fn filtered_output_lft(
        seed: u64,
        (ng, nf, nu, ny, nz, nw): (usize, usize, usize, usize, usize, usize),
    ) -> Lft {
        let g = random_stable_system(seed, ng, nu + ny + nw, ny, 0.9);
        let f = random_stable_system(seed ^ 0x5eed, nf, ny, nz, 0.8);
        let n = ng + nf;
        let (bg, dg) = (g.b(), g.d());
        let dyu = dg.columns(0, nu).into_owned();
        // A well-conditioned noise feedthrough.
        let dye = DMatrix::identity(ny, ny) + 0.3 * dg.columns(nu, ny);
        let dyw = dg.columns(nu + ny, nw).into_owned();
        let mut a = DMatrix::zeros(n, n);
        a.view_mut((0, 0), (ng, ng)).copy_from(g.a());
        a.view_mut((ng, 0), (nf, ng)).copy_from(&(f.b() * g.c()));
        a.view_mut((ng, ng), (nf, nf)).copy_from(f.a());
        let stack = |top: DMatrix<f64>, feed: &DMatrix<f64>| {
            let mut out = DMatrix::zeros(n, top.ncols());
            out.view_mut((0, 0), (ng, top.ncols())).copy_from(&top);
            out.view_mut((ng, 0), (nf, top.ncols()))
                .copy_from(&(f.b() * feed));
            out
        };
        let mut cy = DMatrix::zeros(ny, n);
        cy.view_mut((0, 0), (ny, ng)).copy_from(g.c());
        let mut cz = DMatrix::zeros(nz, n);
        cz.view_mut((0, ng), (nz, nf)).copy_from(f.c());
        Lft::new(LftMatrices {
            a,
            bu: stack(bg.columns(0, nu).into_owned(), &dyu),
            be: stack(bg.columns(nu, ny).into_owned(), &dye),
            bw: stack(bg.columns(nu + ny, nw).into_owned(), &dyw),
            cy,
            dyu,
            dye,
            dyw,
            cz,
            dzu: DMatrix::zeros(nz, nu),
            dze: DMatrix::zeros(nz, ny),
            dzw: DMatrix::zeros(nz, nw),
        })
        .unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        #[test]
        fn prop_z_filtered_from_y_is_measurable_and_compute_z_matches_simulation(
            seed in any::<u64>(),
            ng in 1usize..4,
            nf in 1usize..3,
            nu in 1usize..3,
            ny in 1usize..3,
            nz in 1usize..3,
            nw in 1usize..3,
        ) {
            let lft = filtered_output_lft(seed, (ng, nf, nu, ny, nz, nw));
            let source = lft.measurability().unwrap();
            let ZSource::Dynamic { system } = &source else {
                return Err(TestCaseError::fail(format!("not dynamic: {source:?}")));
            };
            // Only the filter's states are observed by z.
            prop_assert!(system.order() <= nf, "order {} > {}", system.order(), nf);
            let mut rng = SplitMix64::new(seed.wrapping_add(1));
            let coef: Vec<f64> = (0..2 * nw).map(|_| rng.uniform_in(-1.0, 1.0)).collect();
            let maps: Vec<_> = (0..nw)
                .map(|i| {
                    let (a, b) = (coef[2 * i], coef[2 * i + 1]);
                    move |z: &[f64]| a * (z.iter().sum::<f64>() * b).tanh() + 0.3 * a * z[0].cos()
                })
                .collect();
            let inputs: Vec<Vec<usize>> = (0..nw).map(|i| vec![i % nz, (i + 1) % nz]).collect();
            let bindings: Vec<MapBinding<'_>> = maps
                .iter()
                .zip(&inputs)
                .enumerate()
                .map(|(i, (m, inp))| MapBinding { inputs: inp, output: i, map: m })
                .collect();
            let len = 150;
            let u = gaussian(&mut rng, len, nu, 1.0);
            let e = gaussian(&mut rng, len, ny, 0.2);
            let sim = lft.simulate(&bindings, &u, Some(&e), None).unwrap();
            let (z, _) = lft.compute_z(&u, &sim.y).unwrap();
            let d = rel_diff(&z, &sim.z);
            prop_assert!(d < 1e-9, "compute_z differs from simulate's z by {}", d);
        }
    }
}
