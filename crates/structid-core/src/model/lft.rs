//! The known linear block of the LFT, partitioned as in the paper's eq. (7).
//!
//! ```text
//!  x⁺ = A x + B_u u + B_e e + B_w w
//!  y  = C_y x + D_yu u + D_ye e + D_yw w
//!  z  = C_z x + D_zu u + D_ze e + D_zw w
//! ```
//! u is the known input, e the unknown noise, w = N(z) the outputs of the static maps, y the
//! measured output and z the inputs of the static maps.

use nalgebra::DMatrix;
use structid_lti::{LinearSystem, Signal, StateSpace};

use crate::error::{Error, Result};

/// The twelve matrices of the partitioned realisation, by name. Used to build an [`Lft`].
#[derive(Clone, Debug, PartialEq)]
#[allow(missing_docs)]
pub struct LftMatrices {
    pub a: DMatrix<f64>,
    pub bu: DMatrix<f64>,
    pub be: DMatrix<f64>,
    pub bw: DMatrix<f64>,
    pub cy: DMatrix<f64>,
    pub dyu: DMatrix<f64>,
    pub dye: DMatrix<f64>,
    pub dyw: DMatrix<f64>,
    pub cz: DMatrix<f64>,
    pub dzu: DMatrix<f64>,
    pub dze: DMatrix<f64>,
    pub dzw: DMatrix<f64>,
}

/// Signal dimensions of an [`Lft`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct LftDims {
    /// Number of states n.
    pub states: usize,
    /// Known inputs n_u.
    pub u: usize,
    /// Noise channels n_e.
    pub e: usize,
    /// Nonlinearity outputs n_w.
    pub w: usize,
    /// Measured outputs n_y.
    pub y: usize,
    /// Nonlinearity inputs n_z.
    pub z: usize,
}

/// The known linear block L of the structured model, validated on construction.
///
/// ```
/// use nalgebra::dmatrix;
/// use structid_core::{Lft, LftMatrices};
/// // y = w + e with w = N(u): a static map observed in white noise.
/// let lft = Lft::new(LftMatrices {
///     a: dmatrix![0.5], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![0.0],
///     cy: dmatrix![0.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![1.0],
///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
/// }).unwrap();
/// assert_eq!(lft.dims().w, 1);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Lft {
    m: LftMatrices,
    dims: LftDims,
    sample_time: Option<f64>,
}

fn check_shape(name: &str, m: &DMatrix<f64>, rows: usize, cols: usize) -> Result<()> {
    if m.nrows() != rows || m.ncols() != cols {
        return Err(Error::DimensionMismatch {
            what: format!("LFT matrix {name}"),
            expected: format!("{rows}×{cols}"),
            found: format!("{}×{}", m.nrows(), m.ncols()),
        });
    }
    for j in 0..cols {
        for i in 0..rows {
            let v = m[(i, j)];
            if !v.is_finite() {
                return Err(Error::InvalidParameter {
                    name: format!("{name}[{i}][{j}]"),
                    value: v,
                    reason: "matrix entries must be finite".into(),
                });
            }
        }
    }
    Ok(())
}

impl Lft {
    /// Validates the dimensions (taken from A, the B's columns and the C's rows) and finiteness.
    pub fn new(m: LftMatrices) -> Result<Self> {
        let dims = LftDims {
            states: m.a.nrows(),
            u: m.bu.ncols(),
            e: m.be.ncols(),
            w: m.bw.ncols(),
            y: m.cy.nrows(),
            z: m.cz.nrows(),
        };
        let n = dims.states;
        check_shape("A", &m.a, n, n)?;
        check_shape("Bu", &m.bu, n, dims.u)?;
        check_shape("Be", &m.be, n, dims.e)?;
        check_shape("Bw", &m.bw, n, dims.w)?;
        check_shape("Cy", &m.cy, dims.y, n)?;
        check_shape("Dyu", &m.dyu, dims.y, dims.u)?;
        check_shape("Dye", &m.dye, dims.y, dims.e)?;
        check_shape("Dyw", &m.dyw, dims.y, dims.w)?;
        check_shape("Cz", &m.cz, dims.z, n)?;
        check_shape("Dzu", &m.dzu, dims.z, dims.u)?;
        check_shape("Dze", &m.dze, dims.z, dims.e)?;
        check_shape("Dzw", &m.dzw, dims.z, dims.w)?;
        if dims.y == 0 {
            return Err(Error::InvalidStructure(
                "the LFT has no measured output y".into(),
            ));
        }
        Ok(Self {
            m,
            dims,
            sample_time: None,
        })
    }

    /// Builds an LFT from one state-space system with inputs `[u; e; w]` and outputs `[y; z]`.
    pub fn from_state_space(
        sys: &StateSpace,
        dims_u: usize,
        dims_e: usize,
        dims_y: usize,
    ) -> Result<Self> {
        let (n_in, n_out) = (sys.inputs(), sys.outputs());
        if dims_u + dims_e > n_in || dims_y > n_out {
            return Err(Error::DimensionMismatch {
                what: "partition of the state-space system into [u; e; w] → [y; z]".into(),
                expected: format!("at least {} inputs and {} outputs", dims_u + dims_e, dims_y),
                found: format!("{n_in} inputs and {n_out} outputs"),
            });
        }
        let n = sys.order();
        let (b, c, d) = (sys.b(), sys.c(), sys.d());
        let nw = n_in - dims_u - dims_e;
        let nz = n_out - dims_y;
        let cols = |m: &DMatrix<f64>, s: usize, k: usize| m.columns(s, k).into_owned();
        let blk = |r: usize, nr: usize, s: usize, k: usize| d.view((r, s), (nr, k)).into_owned();
        let mut lft = Self::new(LftMatrices {
            a: sys.a().clone(),
            bu: cols(b, 0, dims_u),
            be: cols(b, dims_u, dims_e),
            bw: cols(b, dims_u + dims_e, nw),
            cy: c.rows(0, dims_y).into_owned(),
            dyu: blk(0, dims_y, 0, dims_u),
            dye: blk(0, dims_y, dims_u, dims_e),
            dyw: blk(0, dims_y, dims_u + dims_e, nw),
            cz: c.rows(dims_y, nz).into_owned(),
            dzu: blk(dims_y, nz, 0, dims_u),
            dze: blk(dims_y, nz, dims_u, dims_e),
            dzw: blk(dims_y, nz, dims_u + dims_e, nw),
        })?;
        debug_assert_eq!(lft.dims.states, n);
        lft.sample_time = sys.sample_time();
        Ok(lft)
    }

    /// Attaches a sample time (seconds, > 0). It is informational: all signals are sampled.
    pub fn with_sample_time(mut self, ts: f64) -> Result<Self> {
        self.sample_time = Some(crate::error::positive_finite("sample_time", ts)?);
        Ok(self)
    }

    /// The sample time, when known.
    pub fn sample_time(&self) -> Option<f64> {
        self.sample_time
    }

    /// Signal dimensions.
    pub fn dims(&self) -> LftDims {
        self.dims
    }

    /// The twelve matrices.
    pub fn matrices(&self) -> &LftMatrices {
        &self.m
    }

    fn subsystem(&self, b: &DMatrix<f64>, c: &DMatrix<f64>, d: &DMatrix<f64>) -> StateSpace {
        // A path with no input or no output coupling through the states is a static gain; giving
        // it order 0 lets solvers use the cheap static route. That includes a path whose
        // Markov parameters C·Aᵏ·B are all exactly zero (e.g. the noise of rate feedback,
        // which reaches only the stored previous output that y does not read): its states
        // are unreachable or unobservable, and keeping them would give the whitening filter
        // the plant's poles, an integrator's among them.
        let static_path = b.iter().all(|v| *v == 0.0) || c.iter().all(|v| *v == 0.0) || {
            let mut ab = b.clone();
            (0..self.m.a.nrows()).all(|_| {
                let zero = (c * &ab).iter().all(|v| *v == 0.0);
                ab = &self.m.a * &ab;
                zero
            })
        };
        let sys = if static_path {
            StateSpace::static_gain(d.clone())
        } else {
            StateSpace::new(self.m.a.clone(), b.clone(), c.clone(), d.clone())
        };
        sys.expect("sub-blocks of a validated LFT are consistent")
    }

    /// L_yu: u → y.
    pub fn t_yu(&self) -> StateSpace {
        self.subsystem(&self.m.bu, &self.m.cy, &self.m.dyu)
    }
    /// L_ye: e → y.
    pub fn t_ye(&self) -> StateSpace {
        self.subsystem(&self.m.be, &self.m.cy, &self.m.dye)
    }
    /// L_yw: w → y.
    pub fn t_yw(&self) -> StateSpace {
        self.subsystem(&self.m.bw, &self.m.cy, &self.m.dyw)
    }
    /// The column of L_yw that carries w channel `c` (n_y outputs, one input).
    pub fn t_yw_channel(&self, c: usize) -> StateSpace {
        self.subsystem(
            &self.m.bw.columns(c, 1).into_owned(),
            &self.m.cy,
            &self.m.dyw.columns(c, 1).into_owned(),
        )
    }
    /// L_zu: u → z.
    pub fn t_zu(&self) -> StateSpace {
        self.subsystem(&self.m.bu, &self.m.cz, &self.m.dzu)
    }

    /// The whole block as one system with inputs `[u; e; w]` and outputs `[y; z]`.
    pub fn state_space(&self) -> StateSpace {
        let d = &self.dims;
        let b = hcat(&[&self.m.bu, &self.m.be, &self.m.bw], d.states);
        let c = vcat(&[&self.m.cy, &self.m.cz], d.states);
        let top = hcat(&[&self.m.dyu, &self.m.dye, &self.m.dyw], d.y);
        let bottom = hcat(&[&self.m.dzu, &self.m.dze, &self.m.dzw], d.z);
        let dd = vcat(&[&top, &bottom], d.u + d.e + d.w);
        let sys = StateSpace::new(self.m.a.clone(), b, c, dd).expect("validated LFT");
        match self.sample_time {
            Some(ts) => sys.with_sample_time(ts).expect("validated sample time"),
            None => sys,
        }
    }

    /// Checks D_zw = 0, which computing z from u and y requires (the paper's identification
    /// and the one-step predictor): with D_zw ≠ 0, z_k depends on maps' outputs w_k.
    ///
    /// Simulation does not need it: maps in series are evaluated in order
    /// ([`Lft::evaluation_order`]), and only a cycle is refused there.
    ///
    /// # Errors
    /// [`Error::SeriesMaps`] naming the first non-zero entry of D_zw.
    pub fn check_no_algebraic_loop(&self) -> Result<()> {
        let dzw = &self.m.dzw;
        for j in 0..dzw.ncols() {
            for i in 0..dzw.nrows() {
                if dzw[(i, j)] != 0.0 {
                    return Err(Error::SeriesMaps {
                        row: i,
                        col: j,
                        value: dzw[(i, j)],
                    });
                }
            }
        }
        Ok(())
    }

    /// Checks that an identification residual stays bounded: when e reaches y only directly
    /// (B_e = 0, an output-error noise model) the residual is y minus the simulated paths
    /// u → y and w → y, and a reachable pole of either outside the unit circle makes it grow
    /// geometrically with the record ([`Error::Unstable`]). Poles on the unit circle
    /// (integrators) and noise models with dynamics, whose predictor filters the paths, are
    /// accepted.
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_core::{Lft, LftMatrices};
    /// let m = |a: f64| LftMatrices {
    ///     a: dmatrix![a], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
    ///     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
    ///     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
    /// };
    /// assert!(Lft::new(m(0.9)).unwrap().check_residual_stable().is_ok());
    /// assert!(Lft::new(m(1.0)).unwrap().check_residual_stable().is_ok());
    /// let e = Lft::new(m(1.5)).unwrap().check_residual_stable().unwrap_err();
    /// assert!(e.to_string().contains("pole of modulus 1.5"), "{e}");
    /// ```
    pub fn check_residual_stable(&self) -> Result<()> {
        if self.m.be.iter().any(|v| *v != 0.0) {
            return Ok(());
        }
        for (name, sys) in [("u → y", self.t_yu()), ("w → y", self.t_yw())] {
            let rho = sys.reachable_spectral_radius();
            // The tolerance admits repeated poles at 1 (integrators), whose computed moduli
            // are off by about ε^(1/m) for multiplicity m (6·10⁻⁶ for three).
            if rho.is_nan() || rho > 1.0 + 1e-5 {
                return Err(Error::Unstable(format!(
                    "the path {name} of the linear block has a pole of modulus {rho:.4} > 1, and with \
                     an output-error noise model (B_e = 0) the identification residual grows without \
                     bound over the record; identify needs that path stable (poles on the unit circle, \
                     integrators, are accepted) or a noise model whose predictor is stable"
                )));
            }
        }
        Ok(())
    }

    /// Residual r = y − L_yu·u with a zero initial state.
    pub fn residual(&self, u: &Signal, y: &Signal) -> Result<Signal> {
        let yu = self.t_yu().simulate(u)?;
        let mut r = y.clone();
        for (ri, yi) in r.as_mut_slice().iter_mut().zip(yu.as_slice()) {
            *ri -= yi;
        }
        Ok(r)
    }
}

fn hcat(parts: &[&DMatrix<f64>], rows: usize) -> DMatrix<f64> {
    let cols: usize = parts.iter().map(|p| p.ncols()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut at = 0;
    for p in parts {
        out.view_mut((0, at), (rows, p.ncols())).copy_from(*p);
        at += p.ncols();
    }
    out
}

fn vcat(parts: &[&DMatrix<f64>], cols: usize) -> DMatrix<f64> {
    let rows: usize = parts.iter().map(|p| p.nrows()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut at = 0;
    for p in parts {
        out.view_mut((at, 0), (p.nrows(), cols)).copy_from(*p);
        at += p.nrows();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::dmatrix;

    fn output_error(a: f64, be: f64) -> Lft {
        Lft::new(LftMatrices {
            a: dmatrix![a],
            bu: dmatrix![1.0],
            be: dmatrix![be],
            bw: dmatrix![1.0],
            cy: dmatrix![1.0],
            dyu: dmatrix![0.0],
            dye: dmatrix![1.0],
            dyw: dmatrix![0.0],
            cz: dmatrix![0.0],
            dzu: dmatrix![1.0],
            dze: dmatrix![0.0],
            dzw: dmatrix![0.0],
        })
        .unwrap()
    }

    #[test]
    fn an_unstable_output_error_path_is_refused_an_integrator_is_not() {
        assert!(output_error(0.5, 0.0).check_residual_stable().is_ok());
        // A double integrator (a Jordan block at 1).
        let mut m = output_error(1.0, 0.0).matrices().clone();
        m.a = dmatrix![1.0, 1.0; 0.0, 1.0];
        m.bu = dmatrix![0.0; 1.0];
        m.be = dmatrix![0.0; 0.0];
        m.bw = dmatrix![0.0; 1.0];
        m.cy = dmatrix![1.0, 0.0];
        m.cz = dmatrix![0.0, 0.0];
        assert!(Lft::new(m).unwrap().check_residual_stable().is_ok());
        assert!(output_error(-1.0, 0.0).check_residual_stable().is_ok());
        let e = output_error(1.2, 0.0).check_residual_stable().unwrap_err();
        assert!(matches!(e, Error::Unstable(_)), "{e}");
        assert!(
            e.to_string().starts_with("unstable model: the path u → y"),
            "{e}"
        );
        // A noise model with dynamics (innovations form): its predictor filters the paths.
        assert!(output_error(1.2, 1.0).check_residual_stable().is_ok());
    }
}
