//! Where a latent map starts: its input and output smoothed from the data with the linear
//! part of the model.
//!
//! A latent block reads a signal that y does not reveal, so the paper's identification cannot
//! place it. The linear part can still say where that signal probably went. Each map with an
//! affine part ([`crate::BlockMap::affine_part`]) is written w = a + B·z + δ, its departure δ from that
//! part unknown; a map without one (an operator, a fixed map) is all departure, so a map that
//! reaches y only through such a block does not reach it in the closed linear model and cannot
//! be smoothed. Closing the LFT with the affine parts gives
//! a linear model driven by u, the constant 1, δ and the noise e; the disturbance smoother of
//! `structid-lti` (initial state free) finds the most likely δ and e given y:
//!
//! ```text
//!   δ̂, ê, x̂₀ = argmin  Σ_k ‖δ_k‖²_{Q_δ⁻¹} + ‖e_k‖²_{Q_e⁻¹}   subject to the closed LFT reproducing y,
//!   ŵ = a + B·ẑ + δ̂,   ẑ = C_z·x̂ + D_zu·u + D_zw·ŵ + D_ze·ê.
//! ```
//!
//! The pairs (ẑ_k, ŵ_k) of a block are a noisy picture of its map, and a kernel fit through
//! them with the block's dispersion starts the joint fit. Without the affine parts a latent
//! integrator (a tank's level) would drift: nothing would tie its outflow to its level.
//!
//! Only the ratio of the priors matters. With s² the variance of y and E_j the energy of y's
//! response to a unit impulse on δ_j over the first min(L, 500) samples of the closed model,
//! Q_δ = diag(s²/(n_w·E_j)): the departures together are expected to explain y's variance; the
//! noise is expected to carry the share `noise_share` of y's standard deviation:
//! Q_e = noise_share²·s²·I.

use nalgebra::{DMatrix, DVector};
use structid_core::{Data, Signal};
use structid_lti::{DisturbanceSmoother, SmootherInitial, StateSpace};

use crate::model::JointModel;

use crate::error::{JointError, Result, invalid};

/// The smoothed inputs and outputs of the maps, over all records (concatenated).
#[derive(Clone, Debug)]
pub struct SmoothedMaps {
    /// ẑ, the maps' inputs (L × n_z).
    pub z: Signal,
    /// ŵ, the maps' outputs (L × n_w).
    pub w: Signal,
    /// Each record's smoothed initial LFT state x̂₀: where a fit from this start begins.
    pub initial_states: Vec<Vec<f64>>,
    /// Per z channel: whether the closed linear model observes it from y (it lies in the span
    /// of the directions the observability matrix sees with at least 10⁻⁴ of its largest gain). An unobserved channel's ẑ is its prior, not a
    /// picture of the data: a latent block reading it needs an affine start that ties it to y.
    pub observable: Vec<bool>,
}

/// A direction of the state observed with a gain below this fraction of the best-observed one
/// counts as unobserved: the smoothed signal along it would be its prior plus the noise
/// magnified that many times.
const OBSERVED: f64 = 1e-4;

/// Whether each row of `cz` lies in the row space of the observability matrix of `(a, c)`
/// (its directions observed with at least [`OBSERVED`] of the largest gain).
fn observable_rows(a: &DMatrix<f64>, c: &DMatrix<f64>, cz: &DMatrix<f64>) -> Vec<bool> {
    let n = a.nrows();
    if n == 0 {
        return vec![true; cz.nrows()];
    }
    let mut o = DMatrix::zeros(c.nrows() * n, n);
    let mut ck = c.clone();
    for k in 0..n {
        o.view_mut((k * c.nrows(), 0), (c.nrows(), n))
            .copy_from(&ck);
        ck = &ck * a;
    }
    let svd = o.svd(false, true);
    let vt = svd.v_t.expect("requested");
    let smax = svd.singular_values.max();
    let rank = svd
        .singular_values
        .iter()
        .filter(|s| **s > OBSERVED * smax.max(f64::MIN_POSITIVE))
        .count();
    let basis = vt.rows(0, rank);
    (0..cz.nrows())
        .map(|i| {
            let row = cz.row(i);
            let norm = row.norm();
            let projected = (row * basis.transpose()) * basis;
            norm == 0.0 || (row - projected).norm() <= 1e-6 * norm
        })
        .collect()
}

/// The LFT closed with the maps' affine parts, as one state space with inputs
/// [u, 1, δ, e] and output y, and what recovers z and w from its state and inputs.
struct Closed {
    system: StateSpace,
    /// w = w_x·x + w_v·v.
    w_x: DMatrix<f64>,
    w_v: DMatrix<f64>,
}

fn close(model: &JointModel) -> Result<Closed> {
    let lft = model.lft();
    let (m, d) = (lft.matrices(), lft.dims());
    let mut a0 = DMatrix::zeros(d.w, 1);
    let mut slope = DMatrix::zeros(d.w, d.z);
    for b in model.blocks() {
        if let Some((level, grad)) = b.map.affine_part() {
            a0[(b.output, 0)] = level;
            for (i, g) in b.inputs.iter().zip(grad) {
                slope[(b.output, *i)] = g;
            }
        }
    }
    // (I − B·D_zw)·w = a + B·(C_z·x + D_zu·u + D_ze·e) + δ; the maps have no cycle, so the
    // matrix on the left is invertible (unit triangular in the evaluation order).
    let lhs = DMatrix::identity(d.w, d.w) - &slope * &m.dzw;
    let lu = lhs.lu();
    let solve = |rhs: DMatrix<f64>| {
        lu.solve(&rhs).ok_or_else(|| {
            JointError::InvalidModel("the maps' affine parts form a singular loop".into())
        })
    };
    let w_x = solve(&slope * &m.cz)?;
    let w_v = solve(hstack(&[
        &(&slope * &m.dzu),
        &a0,
        &DMatrix::identity(d.w, d.w),
        &(&slope * &m.dze),
    ]))?;
    let bv = hstack(&[
        &m.bu,
        &DMatrix::zeros(d.states, 1),
        &DMatrix::zeros(d.states, d.w),
        &m.be,
    ]);
    let dv = hstack(&[
        &m.dyu,
        &DMatrix::zeros(d.y, 1),
        &DMatrix::zeros(d.y, d.w),
        &m.dye,
    ]);
    let system = StateSpace::new(
        &m.a + &m.bw * &w_x,
        bv + &m.bw * &w_v,
        &m.cy + &m.dyw * &w_x,
        dv + &m.dyw * &w_v,
    )?;
    Ok(Closed { system, w_x, w_v })
}

/// Energy of y's response to a unit impulse on each δ channel over `horizon` samples.
fn impulse_energy(sys: &StateSpace, first: usize, count: usize, horizon: usize) -> Vec<f64> {
    (first..first + count)
        .map(|j| {
            let mut energy: f64 = sys.d().column(j).norm_squared();
            let mut x = sys.b().column(j).into_owned();
            for _ in 1..horizon {
                energy += (sys.c() * &x).norm_squared();
                x = sys.a() * x;
                if !energy.is_finite() {
                    return f64::INFINITY;
                }
            }
            energy
        })
        .collect()
}

/// Smooths the maps' inputs and outputs from `data` with the linear part of `model` closed by
/// its maps' affine parts (see the [module docs](self)); `noise_share` in (0, 1) is the share
/// of y's standard deviation expected to be noise.
///
/// # Errors
/// A `noise_share` outside (0, 1), a model without maps, a map output that does not reach y,
/// and the smoother's errors.
pub fn smooth_maps(model: &JointModel, data: &Data, noise_share: f64) -> Result<SmoothedMaps> {
    if !(noise_share > 0.0 && noise_share < 1.0) {
        return Err(invalid("noise share", noise_share, "must lie in (0, 1)"));
    }
    let lft = model.lft();
    let (m, d) = (lft.matrices(), lft.dims());
    if d.w == 0 {
        return Err(JointError::InvalidModel(
            "the model has no maps to smooth".into(),
        ));
    }
    let closed = close(model)?;
    let y = data.y().as_slice();
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let s2 = y.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / y.len() as f64;
    let energy = impulse_energy(&closed.system, d.u + 1, d.w, data.len().min(500));
    if let Some(j) = energy.iter().position(|e| !(e.is_finite() && *e > 0.0)) {
        return Err(JointError::InvalidModel(format!(
            "w[{j}] does not reach y with a finite, non-zero response, so it cannot be smoothed from y"
        )));
    }
    let floor = f64::MIN_POSITIVE;
    let mut variances = vec![0.0; d.u + 1];
    variances.extend(energy.iter().map(|e| (s2 / (d.w as f64 * e)).max(floor)));
    variances.extend(std::iter::repeat_n(
        (noise_share * noise_share * s2).max(floor),
        d.e,
    ));
    let nv = variances.len();
    let (mut z, mut w) = (Vec::with_capacity(data.len() * d.z), Vec::new());
    let mut initial_states = Vec::new();
    for rec in data.records() {
        let len = rec.len();
        let smoother =
            DisturbanceSmoother::new(&closed.system, &variances, len, SmootherInitial::Free)?;
        let mean = Signal::from_fn(len, nv, |k, c| match c {
            c if c < d.u => rec.u().get(k, c),
            c if c == d.u => 1.0,
            _ => 0.0,
        });
        let mut v = Signal::zeros(len, nv);
        let report = smoother.smooth(rec.y(), &mean, &mut v)?;
        let x0 = report.initial_state.unwrap_or_else(|| vec![0.0; d.states]);
        initial_states.push(x0.clone());
        let mut x = DVector::from_vec(x0);
        for k in 0..len {
            let vk = DVector::from_column_slice(v.sample(k));
            let wk = &closed.w_x * &x + &closed.w_v * &vk;
            let uk = vk.rows(0, d.u);
            let ek = vk.rows(d.u + 1 + d.w, d.e);
            let zk = &m.cz * &x + &m.dzu * uk + &m.dze * ek + &m.dzw * &wk;
            z.extend(zk.iter());
            w.extend(wk.iter());
            x = closed.system.a() * x + closed.system.b() * vk;
        }
    }
    // z's state part in the closed model: C_z·x + D_zw·w with w = w_x·x + ….
    let cz_closed = &m.cz + &m.dzw * &closed.w_x;
    Ok(SmoothedMaps {
        z: Signal::new(d.z, z)?,
        w: Signal::new(d.w, w)?,
        initial_states,
        observable: observable_rows(closed.system.a(), closed.system.c(), &cz_closed),
    })
}
fn hstack(parts: &[&DMatrix<f64>]) -> DMatrix<f64> {
    let rows = parts[0].nrows();
    let cols = parts.iter().map(|p| p.ncols()).sum();
    let mut out = DMatrix::zeros(rows, cols);
    let mut c = 0;
    for p in parts {
        out.view_mut((0, c), (rows, p.ncols())).copy_from(p);
        c += p.ncols();
    }
    out
}
