//! The identification problem in operator form, independent of how the operators are realised.
//!
//! With r = y − T_yu·u, find (e, w) with T_ye·e + Σ_i T_yw^\[i\]·w^\[i\] = r minimising
//! J = (1/L)·Σ_k e_kᵀe_k + β·Σ_i D_i(z^\[i\], w^\[i\]).
//! The operators are any [`LinearSystem`], so a user can pose a problem with an FIR or
//! impulse-response model directly with [`Problem::new`]; [`Problem::from_model`] builds it from
//! an [`crate::Lft`].

use std::sync::Arc;

use structid_lti::{LinearSystem, Signal};

use crate::dispersion::Dispersion;
use crate::error::{Error, Result};
use crate::model::measurability::ZSource;
use crate::model::{Data, Model};

/// One nonlinear block as the solver sees it.
#[derive(Clone)]
pub struct ProblemBlock {
    /// Name used in reports.
    pub name: String,
    /// The w channel this block produces (orders the columns of ŵ).
    pub output: usize,
    /// T_yw^\[i\]: the path from this block's output to y (n_y outputs, one input).
    pub path: Arc<dyn LinearSystem>,
    /// The block's input samples z^\[i\] (L × p_i).
    pub z: Signal,
    /// The block's dispersion.
    pub dispersion: Arc<dyn Dispersion>,
}

/// An identification problem: residual, noise path and nonlinear blocks.
#[derive(Clone)]
pub struct Problem {
    residual: Signal,
    noise: Arc<dyn LinearSystem>,
    blocks: Vec<ProblemBlock>,
    z_source: ZSource,
    /// Columns O·e_j of the free response of y to each unit initial state (L·n_y × n), when the
    /// initial state is to be estimated.
    free_response: Option<faer::Mat<f64>>,
    /// One realisation of [T_ye, T_yw] sharing the LFT's states (inputs e, then w by channel),
    /// when the problem was built from a model; state-space solvers use it.
    realisation: Option<structid_lti::StateSpace>,
    /// Whether `free_response` is the free response of `realisation`'s initial state.
    free_response_is_state: bool,
    /// Output rows (sample-major, L·n_y) left out of the fit: cross-validation folds.
    held_out: Option<Arc<[bool]>>,
    /// Where each record starts, then L (`[0, L]` for one record).
    bounds: Vec<usize>,
}

impl Problem {
    /// A problem from explicit operators. `residual` is r = y − T_yu·u (L × n_y); `noise` is T_ye
    /// (n_e inputs, n_y outputs); each block's `path` has n_y outputs and one input.
    pub fn new(
        residual: Signal,
        noise: Arc<dyn LinearSystem>,
        blocks: Vec<ProblemBlock>,
    ) -> Result<Self> {
        let (len, ny) = (residual.len(), residual.channels());
        if len == 0 {
            return Err(Error::InvalidStructure(
                "the record is empty: identification needs at least one sample".into(),
            ));
        }
        if ny == 0 {
            return Err(Error::InvalidStructure(
                "the residual has no output channel: identification needs at least one measured output y"
                    .into(),
            ));
        }
        if noise.outputs() != ny {
            return Err(Error::DimensionMismatch {
                what: "outputs of the noise path T_ye".into(),
                expected: ny.to_string(),
                found: noise.outputs().to_string(),
            });
        }
        let mut seen = vec![false; blocks.len()];
        for b in &blocks {
            match seen.get_mut(b.output) {
                Some(s) if !*s => *s = true,
                _ => {
                    return Err(Error::InvalidStructure(format!(
                        "block outputs must be the distinct channels 0..{}; block `{}` has output {}",
                        blocks.len(),
                        b.name,
                        b.output
                    )));
                }
            }
            if b.path.outputs() != ny || b.path.inputs() != 1 {
                return Err(Error::DimensionMismatch {
                    what: format!("path T_yw of block `{}`", b.name),
                    expected: format!("{ny} outputs, 1 input"),
                    found: format!("{} outputs, {} inputs", b.path.outputs(), b.path.inputs()),
                });
            }
            if b.z.len() != len {
                return Err(Error::DimensionMismatch {
                    what: format!("samples of z for block `{}`", b.name),
                    expected: len.to_string(),
                    found: b.z.len().to_string(),
                });
            }
        }
        Ok(Self {
            residual,
            noise,
            blocks,
            z_source: ZSource::Measured,
            free_response: None,
            realisation: None,
            free_response_is_state: false,
            held_out: None,
            bounds: vec![0, len],
        })
    }

    /// Builds the problem from a model and a record: checks the data, computes z (measured or
    /// through [`crate::Lft::compute_z`]), r = y − L_yu·u, and splits L_yw by block.
    ///
    /// With several records ([`Data::from_records`]) z and r are computed record by record and
    /// the paths are applied record by record ([`structid_lti::Recordwise`]), each record from
    /// rest: the operators are block diagonal, not those of the concatenated record. Every
    /// record must then be at least as long as the model order ([`Error::RecordTooShort`]).
    pub fn from_model(model: &Model, data: &Data) -> Result<Self> {
        let lft = model.lft();
        data.check_against(lft)?;
        let bounds = data.record_bounds();
        let several = bounds.len() > 2;
        let (z, z_source, residual) = if several {
            let order = lft.dims().states;
            for (i, w) in bounds.windows(2).enumerate() {
                if w[1] - w[0] < order {
                    return Err(Error::RecordTooShort {
                        record: i + 1,
                        len: w[1] - w[0],
                        order,
                    });
                }
            }
            let mut z_source = ZSource::Measured;
            let (mut z_all, mut r_all) = (Vec::new(), Vec::new());
            for (i, rec) in data.records().iter().enumerate() {
                let z = match rec.z() {
                    Some(z) => z.clone(),
                    None => {
                        let (z, source) = lft.compute_z(rec.u(), rec.y())?;
                        if i == 0 {
                            z_source = source;
                        }
                        z
                    }
                };
                z_all.extend_from_slice(z.as_slice());
                r_all.extend_from_slice(lft.residual(rec.u(), rec.y())?.as_slice());
            }
            let dims = lft.dims();
            (
                Signal::new(dims.z, z_all)?,
                z_source,
                Signal::new(dims.y, r_all)?,
            )
        } else {
            let (z, z_source) = match data.z() {
                Some(z) => (z.clone(), ZSource::Measured),
                None => lft.compute_z(data.u(), data.y())?,
            };
            (z, z_source, lft.residual(data.u(), data.y())?)
        };
        // A dynamic path restarts at each record; a static one (and one record) needs no wrapper.
        let per_record = |sys: structid_lti::StateSpace| -> Result<Arc<dyn LinearSystem>> {
            Ok(if several && sys.order() > 0 {
                Arc::new(structid_lti::Recordwise::new(
                    Arc::new(sys),
                    bounds.to_vec(),
                )?)
            } else {
                Arc::new(sys)
            })
        };
        let blocks = model
            .blocks()
            .iter()
            .map(|b| {
                Ok(ProblemBlock {
                    name: b.name.clone(),
                    output: b.output,
                    path: per_record(lft.t_yw_channel(b.output))?,
                    z: z.select_channels(&b.inputs),
                    dispersion: Arc::clone(&b.dispersion),
                })
            })
            .collect::<Result<_>>()?;
        let mut p = Self::new(residual, per_record(lft.t_ye())?, blocks)?;
        p.z_source = z_source;
        p.bounds = bounds.to_vec();
        let m = lft.matrices();
        let (n, ny) = (lft.dims().states, lft.dims().y);
        let hcat = |a: &nalgebra::DMatrix<f64>, b: &nalgebra::DMatrix<f64>, rows: usize| {
            let mut out = nalgebra::DMatrix::zeros(rows, a.ncols() + b.ncols());
            out.columns_mut(0, a.ncols()).copy_from(a);
            out.columns_mut(a.ncols(), b.ncols()).copy_from(b);
            out
        };
        p.realisation = Some(structid_lti::StateSpace::new(
            m.a.clone(),
            hcat(&m.be, &m.bw, n),
            m.cy.clone(),
            hcat(&m.dye, &m.dyw, ny),
        )?);
        Ok(p)
    }

    /// Estimates an unknown initial state x₀ as unpenalised parameters: r → r − O·x₀, where the
    /// columns of `free_response` (L·n_y × n) are O's, the response of y to each unit initial
    /// state with no input.
    pub fn with_free_response(mut self, free_response: faer::Mat<f64>) -> Result<Self> {
        if free_response.nrows() != self.residual.len() * self.outputs() {
            return Err(Error::DimensionMismatch {
                what: "rows of the free-response matrix O".into(),
                expected: (self.residual.len() * self.outputs()).to_string(),
                found: free_response.nrows().to_string(),
            });
        }
        self.free_response = Some(free_response);
        self.free_response_is_state = false;
        Ok(self)
    }

    /// Like [`Problem::from_model`], and also sets up the estimation of the LFT's unknown initial
    /// state. z must stay computable with x₀ ≠ 0: measured, or the x₀-part of z must be Ψ times
    /// that of y ([`Error::NotMeasurable`] otherwise, in particular for a dynamic Ψ(q) with
    /// states of its own, [`ZSource::Dynamic`]).
    pub fn from_model_with_initial_state(model: &Model, data: &Data) -> Result<Self> {
        let problem = Self::from_model(model, data)?;
        let lft = model.lft();
        let m = lft.matrices();
        let n = lft.dims().states;
        if data.z().is_none() && lft.dims().z > 0 {
            // The x₀-part of z is C_z·A^k·x₀; it must equal Ψ·C_y·A^k·x₀ (Ψ = 0 for z = L_zu·u).
            let psi = match problem.z_source() {
                ZSource::OutputInjection { psi } => psi.clone(),
                // z = Ψ(q)·y also depends on Ψ's own initial state, which is part of x₀.
                ZSource::Dynamic { system } if system.order() > 0 => {
                    return Err(Error::NotMeasurable {
                        explanation: format!(
                            "with an unknown initial state, z is no longer computable from u and y: it is \
                             filtered from y through a dynamic Ψ(q) with {} state(s) (e.g. the previous \
                             output of a measured rate), whose initial value is part of the unknown x₀; \
                             provide z as measured data columns, or identify with a zero initial state",
                            system.order()
                        ),
                    });
                }
                ZSource::Dynamic { system } => {
                    system.d().columns(lft.dims().u, lft.dims().y).into_owned()
                }
                _ => nalgebra::DMatrix::zeros(lft.dims().z, lft.dims().y),
            };
            let mut ak = nalgebra::DMatrix::<f64>::identity(n, n);
            let scale = m.cz.norm().max(1.0);
            for _ in 0..n.max(1) {
                let misfit = (&m.cz * &ak - &psi * &m.cy * &ak).norm();
                if misfit > 1e-9 * scale * ak.norm().max(1.0) {
                    return Err(Error::NotMeasurable {
                        explanation: "with an unknown initial state, z is no longer computable from u and y \
                                      (the initial condition reaches z and y differently); provide z as measured \
                                      data columns, or identify with a zero initial state"
                            .into(),
                    });
                }
                ak = &m.a * ak;
            }
        }
        // One initial state per record: O is block diagonal, each record's block the first
        // L_r·n_y rows of the free response over the longest record.
        let bounds = data.record_bounds();
        let longest = bounds.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
        let ny = lft.dims().y;
        let free = structid_lti::StateSpace::new(
            m.a.clone(),
            nalgebra::DMatrix::zeros(n, 0),
            m.cy.clone(),
            nalgebra::DMatrix::zeros(ny, 0),
        )?;
        let records = bounds.len() - 1;
        let mut o = faer::Mat::<f64>::zeros(data.len() * ny, n * records);
        let none = Signal::zeros(longest, 0);
        for j in 0..n {
            let mut x0 = vec![0.0; n];
            x0[j] = 1.0;
            let (y, _) = free.simulate_from(&x0, &none)?;
            for (r, w) in bounds.windows(2).enumerate() {
                let rows = (w[1] - w[0]) * ny;
                for (i, v) in y.as_slice()[..rows].iter().enumerate() {
                    o[(w[0] * ny + i, r * n + j)] = *v;
                }
            }
        }
        let mut problem = problem.with_free_response(o)?;
        problem.free_response_is_state = true;
        Ok(problem)
    }

    /// The realisation of [T_ye, T_yw] (inputs e, then w by channel) shared with the LFT, and
    /// whether the free response (if any) is that of its initial state. `None` for problems
    /// posed with [`Problem::new`].
    pub(crate) fn shared_realisation(&self) -> Option<(&structid_lti::StateSpace, bool)> {
        self.realisation
            .as_ref()
            .map(|ss| (ss, self.free_response_is_state))
    }

    /// Leaves out of the fit the output rows marked in `held_out` (length L·n_y, sample-major:
    /// row `k·n_y + i` is output `i` at sample `k`): their equations y_k = … are dropped, so
    /// the estimate does not see them, while ŵ and ê are still defined at every sample. This
    /// is what cross-validation needs ([`crate::selection`]). The exact and conic
    /// solvers support it, the feature solver for a static noise path and whole samples, ADMM
    /// for whole samples (missing outputs of its smoother).
    ///
    /// ```
    /// use std::sync::Arc;
    /// use structid_core::{paper, KernelDispersion, Problem};
    /// let exp = paper::spray(50, 1.0, Arc::new(KernelDispersion::gaussian(0.1).unwrap()), 1).unwrap();
    /// let p = Problem::from_model(&exp.model, &exp.data).unwrap();
    /// let mut mask = vec![false; 50];
    /// mask[10..20].iter_mut().for_each(|v| *v = true);
    /// let p = p.with_held_out(mask).unwrap();
    /// assert_eq!(p.held_out().unwrap().iter().filter(|&&h| h).count(), 10);
    /// ```
    pub fn with_held_out(mut self, held_out: Vec<bool>) -> Result<Self> {
        let rows = self.residual.len() * self.outputs();
        if held_out.len() != rows {
            return Err(Error::DimensionMismatch {
                what: "held-out mask".into(),
                expected: format!("{rows} entries (L·n_y)"),
                found: held_out.len().to_string(),
            });
        }
        if held_out.iter().all(|&h| h) {
            return Err(Error::InvalidStructure(
                "every output row is held out: nothing is left to fit".into(),
            ));
        }
        self.held_out = held_out.iter().any(|&h| h).then(|| held_out.into());
        Ok(self)
    }

    /// The held-out output rows, if any ([`Problem::with_held_out`]).
    pub fn held_out(&self) -> Option<&[bool]> {
        self.held_out.as_deref()
    }

    /// The held-out samples, when rows are held out: `Some(Some(mask))` when every held-out
    /// sample has all its output channels held out (one entry per sample), `Some(None)` when
    /// some sample is held out in part, `None` without held-out rows. ADMM takes whole samples
    /// only, as missing outputs of its smoother.
    pub(crate) fn held_out_samples(&self) -> Option<Option<Vec<bool>>> {
        let rows = self.held_out()?;
        let ny = self.outputs().max(1);
        let mut mask = Vec::with_capacity(self.len());
        for sample in rows.chunks(ny) {
            let held = sample[0];
            if sample.iter().any(|&h| h != held) {
                return Some(None);
            }
            mask.push(held);
        }
        Some(Some(mask))
    }

    /// Where each record starts, followed by L: `[0, L₁, …, L]`, `[0, L]` for one record. With
    /// several records the operators restart at every record and an estimated initial state
    /// has one block of n entries per record (the columns of [`Problem::free_response`]).
    pub fn record_bounds(&self) -> &[usize] {
        &self.bounds
    }

    /// Number of records.
    pub fn record_count(&self) -> usize {
        self.bounds.len() - 1
    }

    /// The free-response matrix O, when the initial state is estimated.
    pub fn free_response(&self) -> Option<&faer::Mat<f64>> {
        self.free_response.as_ref()
    }

    /// Number of samples L.
    pub fn len(&self) -> usize {
        self.residual.len()
    }

    /// Whether L = 0.
    pub fn is_empty(&self) -> bool {
        self.residual.is_empty()
    }

    /// Number of outputs n_y.
    pub fn outputs(&self) -> usize {
        self.residual.channels()
    }

    /// The residual r = y − T_yu·u.
    pub fn residual(&self) -> &Signal {
        &self.residual
    }

    /// The noise path T_ye.
    pub fn noise(&self) -> &dyn LinearSystem {
        self.noise.as_ref()
    }

    /// The blocks.
    pub fn blocks(&self) -> &[ProblemBlock] {
        &self.blocks
    }

    /// How z was obtained.
    pub fn z_source(&self) -> &ZSource {
        &self.z_source
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::KernelDispersion;
    use structid_lti::StateSpace;

    /// Found by the `lft_problem` fuzz target: a residual with samples but no output channel
    /// was accepted, and the exact solver then indexed past its empty Gram buffer.
    #[test]
    fn a_residual_without_outputs_is_an_error_not_a_panic() {
        let residual = Signal::zeros(4, 0);
        assert_eq!(residual.len(), 4);
        let noise = StateSpace::static_gain(nalgebra::DMatrix::zeros(0, 1)).unwrap();
        let block = ProblemBlock {
            name: "b0".into(),
            output: 0,
            path: Arc::new(StateSpace::static_gain(nalgebra::DMatrix::zeros(0, 1)).unwrap()),
            z: Signal::zeros(4, 1),
            dispersion: Arc::new(KernelDispersion::gaussian(0.5).unwrap()),
        };
        let e = Problem::new(residual, Arc::new(noise), vec![block])
            .err()
            .expect("no output channel is an error");
        assert!(matches!(e, Error::InvalidStructure(_)), "{e:?}");
        assert!(e.to_string().contains("no output channel"), "{e}");
    }
}
