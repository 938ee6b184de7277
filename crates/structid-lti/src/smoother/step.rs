//! The filter quantities of one time step of the [disturbance smoother](super), the step of a
//! sample with its gains and of a sample without an output, and what the free initial state
//! needs.

use crate::riccati::{Riccati, dot, mat_t_vec_add, mat_vec, row_major, sym_pinv};
use crate::state_space::StateSpace;
use nalgebra::DMatrix;

use super::PINV_TOL;

/// Filter quantities of one time step, row-major.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Step {
    /// `F^+` (`p x p`)
    pub(super) finv: Vec<f64>,
    /// `K` (`n x p`)
    pub(super) gain: Vec<f64>,
    /// null directions of `F` as rows (`nnull x p`)
    pub(super) null: Vec<f64>,
    /// forward map `[s; m_k; y_k] -> [e_k; s_{k+1}]`: `[[-C, -D, I], [A - K C, B - K D, K]]`
    /// (`(p + n) x (n + m + p)`)
    pub(super) fw: Vec<f64>,
    /// backward map `[e_k; r_k] -> [v^_k - m_k; r_{k-1}]`:
    /// `[[Q D^T F^+, Q (B - K D)^T], [C^T F^+, (A - K C)^T]]` (`(m + n) x (p + n)`)
    pub(super) bw: Vec<f64>,
}

/// Borrowed filter quantities of one time step.
#[derive(Clone, Copy)]
pub(super) struct StepRef<'a> {
    pub(super) finv: &'a [f64],
    pub(super) null: &'a [f64],
    pub(super) fw: &'a [f64],
    pub(super) bw: &'a [f64],
}

/// What the free initial state needs: the innovations of the free response and the linear
/// maps `x^_0 = R_b b + R_h h`.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct FreeInit {
    /// `E_k` (`p x n`, row-major) for `k < e_len`, concatenated
    pub(super) e: Vec<f64>,
    /// samples with stored `E_k`: later ones are negligible (see `E_CUT`)
    pub(super) e_len: usize,
    /// `R_b` (`n x n`, row-major)
    pub(super) rb: Vec<f64>,
    /// `R_h` (`n x n`, row-major)
    pub(super) rh: Vec<f64>,
    /// the base prior covariance `P_0` of the free initial state (`n x n`, row-major)
    pub(super) p0: Vec<f64>,
}

/// The contributions of one sample to `b` and `h` of the free initial state:
/// `b += E^T F^+ e`, `h += E^T N^T N e` (`ek`: `E` row-major `p x n`; `w`: scratch of `p`).
#[inline(always)]
pub(super) fn accumulate_free(
    ek: &[f64],
    g: StepRef<'_>,
    e: &[f64],
    w: &mut [f64],
    bv: &mut [f64],
    hv: &mut [f64],
) {
    mat_vec(g.finv, e, w);
    mat_t_vec_add(ek, w, bv);
    if !g.null.is_empty() {
        for nr in g.null.chunks_exact(e.len()) {
            let s = dot(nr, e);
            for (wi, &ni) in w.iter_mut().zip(nr) {
                *wi = s * ni;
            }
            mat_t_vec_add(ek, w, hv);
        }
    }
}

/// `F`, its pseudo-inverse and null directions, and `K` for the error covariance `pm` of
/// the recursion `eq`, with `q` the scaling of the backward map (`Q`, with 1 on adjoint
/// channels, see [`DisturbanceSmoother::with_adjoint`]); `scale` is the running scale of the
/// threshold (updated).
pub(super) fn sample_step(
    eq: &Riccati<'_>,
    q: &DMatrix<f64>,
    pm: &DMatrix<f64>,
    scale: &mut f64,
) -> (Step, DMatrix<f64>) {
    let (f, mm) = eq.innovation(pm);
    *scale = scale.max(f.trace());
    let (finv, null) = sym_pinv(&f, PINV_TOL * *scale);
    let k = mm * &finv;
    let mut null_rows = Vec::with_capacity(null.len() * f.nrows());
    for v in &null {
        null_rows.extend(v.iter());
    }
    // the packed per-sample maps of `smooth`
    let sys = eq.sys;
    let (n, m, p) = (sys.order(), sys.inputs(), sys.outputs());
    let c = sys.c();
    let phi = sys.a() - &k * c;
    let gam = sys.b() - &k * sys.d();
    let mut fw = DMatrix::<f64>::zeros(p + n, n + m + p);
    fw.view_mut((0, 0), (p, n)).copy_from(&(-c));
    fw.view_mut((0, n), (p, m)).copy_from(&(-sys.d()));
    fw.view_mut((0, n + m), (p, p))
        .copy_from(&DMatrix::<f64>::identity(p, p));
    fw.view_mut((p, 0), (n, n)).copy_from(&phi);
    fw.view_mut((p, n), (n, m)).copy_from(&gam);
    fw.view_mut((p, n + m), (n, p)).copy_from(&k);
    let mut bw = DMatrix::<f64>::zeros(m + n, p + n);
    bw.view_mut((0, 0), (m, p))
        .copy_from(&(q * sys.d().transpose() * &finv));
    bw.view_mut((0, p), (m, n))
        .copy_from(&(q * gam.transpose()));
    bw.view_mut((m, 0), (n, p))
        .copy_from(&(c.transpose() * &finv));
    bw.view_mut((m, p), (n, n)).copy_from(&phi.transpose());
    (
        Step {
            finv: row_major(&finv),
            gain: row_major(&k),
            null: null_rows,
            fw: row_major(&fw),
            bw: row_major(&bw),
        },
        k,
    )
}

/// The step of a sample whose outputs are missing: no measurement update (`F^+ = 0`,
/// `K = 0`), so the forward map is `[s; m; y] -> [0; A s + B m]` and the backward map
/// `[e; r] -> [Q B^T r; A^T r]` (`q`: the backward scaling, see [`sample_step`]).
pub(super) fn skip_step(sys: &StateSpace, q: &DMatrix<f64>) -> (Step, DMatrix<f64>) {
    let (n, m, p) = (sys.order(), sys.inputs(), sys.outputs());
    let mut fw = DMatrix::<f64>::zeros(p + n, n + m + p);
    fw.view_mut((p, 0), (n, n)).copy_from(sys.a());
    fw.view_mut((p, n), (n, m)).copy_from(sys.b());
    let mut bw = DMatrix::<f64>::zeros(m + n, p + n);
    bw.view_mut((0, p), (m, n))
        .copy_from(&(q * sys.b().transpose()));
    bw.view_mut((m, p), (n, n)).copy_from(&sys.a().transpose());
    (
        Step {
            finv: vec![0.0; p * p],
            gain: vec![0.0; n * p],
            null: Vec::new(),
            fw: row_major(&fw),
            bw: row_major(&bw),
        },
        DMatrix::zeros(n, p),
    )
}

/// The base prior covariance of a free initial state: `s I` with `s` the mean
/// eigenvalue of the `n`-step reachability Gramian `sum_{j<n} A^j B Q B^T (A^j)^T` (the
/// state's scale under the input prior) plus `trace(D Q D^T) / |C|_F^2`; 0 when the
/// inputs move no state.
pub(super) fn free_base_prior(eq: &Riccati<'_>) -> DMatrix<f64> {
    let sys = eq.sys;
    let a = sys.a();
    let n = a.nrows();
    let mut trace = 0.0;
    let mut term = eq.q.clone();
    for _ in 0..n {
        trace += term.trace();
        term = a * term * a.transpose();
    }
    let mut s = if n > 0 { trace / n as f64 } else { 0.0 };
    // When the direct feedthrough dominates, a prior scaled by the Gramian alone makes
    // `C P_0 C^T` tiny next to `D Q D^T`, so `F_0` is needlessly ill-conditioned when
    // the columns of `C` and `D` are nearly parallel; scaling `x_0` to move the
    // outputs as much as the inputs do keeps both parts of `F_0` comparable.
    let c2 = sys.c().norm_squared();
    if c2 > 0.0 && s > 0.0 {
        s += eq.r.trace() / c2;
    }
    DMatrix::<f64>::identity(n, n) * s
}
