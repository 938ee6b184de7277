//! Measurability of z (paper, Definition 1): can the inputs of the static maps be computed from
//! the known input u and the measured output y?
//!
//! Three cases are recognised:
//! 1. z is measured and given with the data;
//! 2. z does not depend on (e, w) at all (L_ze = 0 and L_zw = 0 as systems), so z = L_zu·u;
//! 3. a constant Ψ maps the (e, w)-part of y onto that of z, i.e. L_z(e,w) = Ψ·L_y(e,w) as
//!    systems, so z = L_zu·u + Ψ·(y − L_yu·u). Output feedback z = y is the typical case.
//!
//! Cases 2 and 3 are checked on the Markov parameters D and C·A^k·B, k < n, of the (e, w) paths:
//! by Cayley–Hamilton these determine the systems, whereas C_z = 0 alone would not.

use nalgebra::DMatrix;
use structid_lti::{LinearSystem, Signal};

use crate::error::{Error, Result};
use crate::lft::Lft;

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

impl Lft {
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
        let scale = hz.norm().max(1.0);
        if hz.norm() <= 1e-12 * scale {
            return Ok(ZSource::InputOnly);
        }
        let hy = markov_stack(self, false);
        let svd = hy.clone().svd(true, true);
        let tol = 1e-12 * svd.singular_values.max().max(1.0);
        let pinv = svd
            .pseudo_inverse(tol)
            .map_err(|e| Error::Numerical(format!("pseudo-inverse in measurability check: {e}")))?;
        let psi = &hz * pinv;
        let misfit = (&psi * &hy - &hz).norm();
        if misfit <= 1e-9 * scale {
            Ok(ZSource::OutputInjection { psi })
        } else {
            Err(Error::NotMeasurable {
                explanation: format!(
                    "the part of z driven by the noise e and the map outputs w is not a fixed linear function of y \
                     (best fit z ≈ Ψ·y leaves a relative misfit of {:.3e} on the Markov parameters); \
                     provide z as measured data columns (`z = [...]` under [signals] in the model file, or Data::with_z), \
                     or restructure the model so that z depends only on u and y",
                    misfit / scale
                ),
            })
        }
    }

    /// Computes z from u and y according to [`Lft::measurability`], with a zero initial state.
    pub fn compute_z(&self, u: &Signal, y: &Signal) -> Result<(Signal, ZSource)> {
        let source = self.measurability()?;
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
