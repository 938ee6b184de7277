//! The [`LinearSystem`] operator trait: block lower-triangular Toeplitz operators acting on
//! stacked time-major signals.

use crate::error::LtiError;
use crate::signal::Signal;
use faer::linalg::matmul::matmul;
use faer::prelude::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par};

/// A causal discrete-time LTI system seen as a linear operator `T` on stacked signals.
///
/// All slices are time-major: the value of channel `c` at time `k` is at index
/// `k * channels + c`. `T` is block lower-triangular Toeplitz with blocks `h_{i-j}`
/// (the Markov parameters), and the initial state is always zero.
///
/// # Contract of the fast paths
/// [`apply`](LinearSystem::apply), [`apply_adjoint`](LinearSystem::apply_adjoint) and the
/// `*_columns` methods are internal fast paths: they do **not** return errors and may
/// panic (via `assert!`) when the lengths are inconsistent (`u.len() = L * inputs`,
/// `y.len() = L * outputs` with the same `L`). Non-finite values simply propagate.
/// [`simulate`](LinearSystem::simulate) is the checked entry point.
pub trait LinearSystem: Send + Sync {
    /// Number of input channels `m`.
    fn inputs(&self) -> usize;
    /// Number of output channels `p`.
    fn outputs(&self) -> usize;
    /// Number of states (0 for a static gain); used by solvers to spot static operators.
    fn order(&self) -> usize;

    /// `y = T u` with zero initial state. `u.len() = L * inputs`, `y.len() = L * outputs`
    /// (same `L`). Overwrites `y`.
    fn apply(&self, u: &[f64], y: &mut [f64]);

    /// `u = T^T y` (adjoint), computed by a backward-in-time recursion. Overwrites `u`.
    fn apply_adjoint(&self, y: &[f64], u: &mut [f64]);

    /// Applies `T` to many signals at once: each **column** of `x` is one stacked input
    /// signal (`L * inputs` rows); `out` has `L * outputs` rows and as many columns.
    ///
    /// `Accum::Replace` gives `out = alpha * T x`, `Accum::Add` gives `out += alpha * T x`.
    /// `x` may be any strided view, in particular a transposed one.
    ///
    /// The default implementation loops over the columns with [`apply`](LinearSystem::apply)
    /// through a scratch vector; implementors should override it with a blocked version.
    fn apply_columns(&self, x: MatRef<'_, f64>, out: MatMut<'_, f64>, accum: Accum, alpha: f64) {
        columns_via(
            x,
            out,
            accum,
            alpha,
            self.inputs(),
            self.outputs(),
            |a, b| self.apply(a, b),
        );
    }

    /// Adjoint version of [`apply_columns`](LinearSystem::apply_columns):
    /// `out = alpha * T^T x` (`Replace`) or `out += alpha * T^T x` (`Add`), where `x` has
    /// `L * outputs` rows and `out` has `L * inputs` rows.
    fn apply_adjoint_columns(
        &self,
        x: MatRef<'_, f64>,
        out: MatMut<'_, f64>,
        accum: Accum,
        alpha: f64,
    ) {
        columns_via(
            x,
            out,
            accum,
            alpha,
            self.outputs(),
            self.inputs(),
            |a, b| self.apply_adjoint(a, b),
        );
    }

    /// The state-space realisation behind this operator, when it is one. Solvers that stream
    /// a record chunk by chunk ([`crate::ColumnStream`]) need it; others work through the
    /// methods above.
    fn as_state_space(&self) -> Option<&crate::StateSpace> {
        None
    }

    /// The record-by-record operator this is, when it is one ([`crate::Recordwise`]): solvers
    /// that stream records chunk by chunk restart the inner operator at each record.
    fn as_recordwise(&self) -> Option<&crate::Recordwise> {
        None
    }

    /// Checked simulation from zero initial state: verifies that `u` has
    /// [`inputs`](LinearSystem::inputs) channels and only finite values, then returns the
    /// output signal (same length, [`outputs`](LinearSystem::outputs) channels).
    fn simulate(&self, u: &Signal) -> Result<Signal, LtiError> {
        if u.channels() != self.inputs() {
            return Err(LtiError::dims(
                "input signal channels",
                self.inputs(),
                u.channels(),
            ));
        }
        u.check_finite("input signal")?;
        let mut y = Signal::zeros(u.len(), self.outputs());
        self.apply(u.as_slice(), y.as_mut_slice());
        Ok(y)
    }
}

/// Number of samples implied by an input slice of `ulen` values over `m` channels and an
/// output slice of `ylen` values over `p` channels; panics when they are inconsistent.
pub(crate) fn horizon(m: usize, p: usize, ulen: usize, ylen: usize) -> usize {
    let len = if m > 0 {
        assert!(
            ulen.is_multiple_of(m),
            "input length {ulen} is not a multiple of the {m} input channels"
        );
        ulen / m
    } else if p > 0 {
        assert!(
            ylen.is_multiple_of(p),
            "output length {ylen} is not a multiple of the {p} output channels"
        );
        ylen / p
    } else {
        0
    };
    assert!(
        ulen == len * m && ylen == len * p,
        "inconsistent lengths: {ulen} input values ({m} channels) vs {ylen} output values ({p} channels)"
    );
    len
}

/// Column-by-column fallback used by the default `*_columns` implementations.
fn columns_via(
    x: MatRef<'_, f64>,
    mut out: MatMut<'_, f64>,
    accum: Accum,
    alpha: f64,
    in_ch: usize,
    out_ch: usize,
    op: impl Fn(&[f64], &mut [f64]),
) {
    assert_eq!(
        x.ncols(),
        out.ncols(),
        "x and out must have the same number of columns"
    );
    let _ = horizon(in_ch, out_ch, x.nrows(), out.nrows());
    let mut u = vec![0.0; x.nrows()];
    let mut y = vec![0.0; out.nrows()];
    for j in 0..x.ncols() {
        for (i, ui) in u.iter_mut().enumerate() {
            *ui = x[(i, j)];
        }
        op(&u, &mut y);
        for (i, &yi) in y.iter().enumerate() {
            let o = &mut out[(i, j)];
            *o = match accum {
                Accum::Replace => alpha * yi,
                Accum::Add => *o + alpha * yi,
            };
        }
    }
}

/// Width of the column chunks processed at once by one thread. When the operand is
/// row-major (e.g. a transposed column-major matrix), wide chunks give long contiguous
/// runs per time sample; when it is column-major, narrow chunks keep the number of
/// concurrently streamed columns small. (Tuned at L = 4000, n = 4, SISO.)
fn col_chunk(row_major: bool) -> usize {
    if row_major { 1024 } else { 16 }
}

/// Do not split the columns across threads below this many columns per task.
const MIN_PAR_COLS: usize = 32;

/// A blocked recursion of a state-space operator (forward `T` or adjoint `T^T`), applied
/// to many columns at once with dense matrix products.
///
/// Time is cut into blocks of `b` samples. For each block, the packed operand
/// `W = [X_k; S]` (the `b * cin` rows of the block, then the `n x ncols` state) is
/// multiplied by `m1` to give the `b * cout` output rows of the block, and by `m2` to give
/// the next state. Forward: `m1 = [T_b, Gamma]`, `m2 = [R, A^b]`. Adjoint (blocks in
/// reverse time order): `m1 = [T_b^T, R^T]`, `m2 = [Gamma^T, (A^b)^T]`.
pub(crate) struct BlockedRecursion {
    /// samples per block
    pub b: usize,
    /// channels of the operand
    pub cin: usize,
    /// channels of the result
    pub cout: usize,
    /// state dimension
    pub n: usize,
    /// `(b cout) x (b cin + n)`
    pub m1: Mat<f64>,
    /// `n x (b cin + n)`
    pub m2: Mat<f64>,
    /// process the blocks backwards in time (adjoint)
    pub reverse: bool,
}

impl BlockedRecursion {
    /// `out = alpha * Op x` (`Replace`) or `out += alpha * Op x` (`Add`) over `len` samples.
    pub(crate) fn run(
        &self,
        len: usize,
        x: MatRef<'_, f64>,
        out: MatMut<'_, f64>,
        accum: Accum,
        alpha: f64,
    ) {
        par_columns(x, out, faer::get_global_parallelism(), &|x, out| {
            self.leaf(len, x, out, accum, alpha, None, None)
        });
    }

    /// One sequential pass over the columns of `x`/`out` (no thread splitting).
    ///
    /// `init` is the state before the first processed block (`n x ncols`, the state of a
    /// forward run at time 0, or the costate after the last sample of an adjoint run);
    /// `None` means zero. `fin`, when given, receives the state after the last block; it is
    /// exact only when `len` is a multiple of the block length (a partial block is padded with
    /// zero input, which would keep the state moving).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn leaf(
        &self,
        len: usize,
        x: MatRef<'_, f64>,
        mut out: MatMut<'_, f64>,
        accum: Accum,
        alpha: f64,
        init: Option<MatRef<'_, f64>>,
        mut fin: Option<MatMut<'_, f64>>,
    ) {
        let (b, cin, n) = (self.b, self.cin, self.n);
        let k = b * cin + n;
        let nb = len.div_ceil(b);
        let nc = x.ncols();
        let (row_major, chunk, mut buf0, mut buf1) = self.scratch(x);
        let mut j0 = 0;
        while j0 < nc {
            let w = chunk.min(nc - j0);
            let xc = x.subcols(j0, w);
            let mut oc = out.rb_mut().subcols_mut(j0, w);
            let mut cur = &mut buf0[..k * w];
            let mut nxt = &mut buf1[..k * w];
            for step in 0..nb {
                let (t0, bk) = self.block_at(step, nb, len);
                self.pack_block(xc, t0, bk, cur, row_major, step == 0);
                if step == 0
                    && let Some(s0) = init
                {
                    load_state(s0.subcols(j0, w), b * cin, cur, row_major, k);
                }
                let wv = packed_view(cur, k, w, row_major);
                self.block_output(oc.rb_mut(), t0, bk, wv, accum, alpha);
                if n > 0
                    && step + 1 == nb
                    && let Some(f) = fin.as_mut()
                {
                    matmul(
                        f.rb_mut().subcols_mut(j0, w),
                        Accum::Replace,
                        self.m2.as_ref(),
                        wv,
                        1.0,
                        Par::Seq,
                    );
                }
                if n > 0 && step + 1 < nb {
                    self.carry_state(wv, nxt, w, row_major);
                    std::mem::swap(&mut cur, &mut nxt);
                }
            }
            j0 += w;
        }
    }
}

impl BlockedRecursion {
    /// `x = Op x` in place over `len` samples (`cin == cout`), columns split across faer's
    /// global thread pool. Each block is packed before its rows are overwritten, and later
    /// blocks read only rows not yet written, so no second operand-sized buffer is needed.
    pub(crate) fn run_in_place(&self, len: usize, x: MatMut<'_, f64>) {
        assert_eq!(self.cin, self.cout, "an in-place operator must be square");
        par_columns_mut(x, faer::get_global_parallelism(), &|x| {
            self.leaf_in_place(len, x)
        });
    }

    /// One sequential in-place pass over the columns of `x` (see [`Self::run_in_place`]).
    fn leaf_in_place(&self, len: usize, mut x: MatMut<'_, f64>) {
        let n = self.n;
        let k = self.b * self.cin + n;
        let nb = len.div_ceil(self.b);
        let nc = x.ncols();
        let (row_major, chunk, mut buf0, mut buf1) = self.scratch(x.rb());
        let mut j0 = 0;
        while j0 < nc {
            let w = chunk.min(nc - j0);
            let mut xc = x.rb_mut().subcols_mut(j0, w);
            let mut cur = &mut buf0[..k * w];
            let mut nxt = &mut buf1[..k * w];
            for step in 0..nb {
                let (t0, bk) = self.block_at(step, nb, len);
                self.pack_block(xc.rb(), t0, bk, cur, row_major, step == 0);
                let wv = packed_view(cur, k, w, row_major);
                self.block_output(xc.rb_mut(), t0, bk, wv, Accum::Replace, 1.0);
                if n > 0 && step + 1 < nb {
                    self.carry_state(wv, nxt, w, row_major);
                    std::mem::swap(&mut cur, &mut nxt);
                }
            }
            j0 += w;
        }
    }
}

impl BlockedRecursion {
    /// The scratch of a sequential pass over the columns of `x`: whether `x` is row-major (the
    /// packed buffers take its layout, so that packing copies contiguous runs), how many
    /// columns are packed at once, and the two packed buffers of the current and next block.
    fn scratch(&self, x: MatRef<'_, f64>) -> (bool, usize, Vec<f64>, Vec<f64>) {
        let k = self.b * self.cin + self.n;
        let row_major = x.col_stride() == 1 && x.row_stride() != 1;
        let chunk = col_chunk(row_major);
        let wmax = chunk.min(x.ncols());
        (row_major, chunk, vec![0.0; k * wmax], vec![0.0; k * wmax])
    }

    /// The first sample and the length of the block processed at `step` of `nb` over `len`
    /// samples: in time order, or from the last block back for the adjoint.
    fn block_at(&self, step: usize, nb: usize, len: usize) -> (usize, usize) {
        let blk = if self.reverse { nb - 1 - step } else { step };
        let t0 = blk * self.b;
        (t0, self.b.min(len - t0))
    }

    /// Packs the samples `t0..t0 + bk` of `x` into `cur` (see [`pack`]); the first block
    /// zeroes the state rows.
    fn pack_block(
        &self,
        x: MatRef<'_, f64>,
        t0: usize,
        bk: usize,
        cur: &mut [f64],
        row_major: bool,
        first: bool,
    ) {
        let (b, cin) = (self.b, self.cin);
        pack(
            x,
            t0 * cin,
            bk * cin,
            b * cin,
            cur,
            row_major,
            first,
            b * cin + self.n,
        );
    }

    /// The rows of the block at `t0` (`bk` samples) in `out`: `M1 wv` from the packed `wv`,
    /// written or added (`accum`), times `alpha`.
    fn block_output(
        &self,
        out: MatMut<'_, f64>,
        t0: usize,
        bk: usize,
        wv: MatRef<'_, f64>,
        accum: Accum,
        alpha: f64,
    ) {
        let cout = self.cout;
        matmul(
            out.subrows_mut(t0 * cout, bk * cout),
            accum,
            self.m1.as_ref().subrows(0, bk * cout),
            wv,
            alpha,
            Par::Seq,
        );
    }

    /// Writes the state after the block packed in `wv` (`M2 wv`) into the state rows of the
    /// packed buffer `nxt` of the next block (`w` columns, row- or column-major).
    fn carry_state(&self, wv: MatRef<'_, f64>, nxt: &mut [f64], w: usize, row_major: bool) {
        let (n, skip) = (self.n, self.b * self.cin);
        let sv = if row_major {
            MatMut::from_row_major_slice_mut(&mut nxt[skip * w..], n, w)
        } else {
            MatMut::from_column_major_slice_with_stride_mut(&mut nxt[skip..], n, w, skip + n)
        };
        matmul(sv, Accum::Replace, self.m2.as_ref(), wv, 1.0, Par::Seq);
    }
}

/// The packed buffer `buf` as a `k x w` matrix (row- or column-major).
fn packed_view(buf: &[f64], k: usize, w: usize, row_major: bool) -> MatRef<'_, f64> {
    if row_major {
        MatRef::from_row_major_slice(buf, k, w)
    } else {
        MatRef::from_column_major_slice(buf, k, w)
    }
}

/// Copies `rows` rows of `x` starting at `r0` into the packed buffer `w` (a `k x ncols`
/// matrix, row- or column-major), zero-fills the rows `rows..pad` and, if `zero_state`,
/// the state rows `pad..k`.
fn pack(
    x: MatRef<'_, f64>,
    r0: usize,
    rows: usize,
    pad: usize,
    w: &mut [f64],
    row_major: bool,
    zero_state: bool,
    k: usize,
) {
    let nc = x.ncols();
    if row_major {
        for i in 0..rows {
            let dst = &mut w[i * nc..(i + 1) * nc];
            let src = x.row(r0 + i);
            match src.try_as_row_major() {
                Some(s) => dst.copy_from_slice(s.as_slice()),
                None => {
                    for (j, d) in dst.iter_mut().enumerate() {
                        *d = x[(r0 + i, j)];
                    }
                }
            }
        }
        w[rows * nc..pad * nc].fill(0.0);
        if zero_state {
            w[pad * nc..k * nc].fill(0.0);
        }
    } else {
        for j in 0..nc {
            let col = &mut w[j * k..(j + 1) * k];
            let src = x.col(j).subrows(r0, rows);
            match src.try_as_col_major() {
                Some(s) => col[..rows].copy_from_slice(s.as_slice()),
                None => {
                    for (i, d) in col[..rows].iter_mut().enumerate() {
                        *d = x[(r0 + i, j)];
                    }
                }
            }
            col[rows..pad].fill(0.0);
            if zero_state {
                col[pad..].fill(0.0);
            }
        }
    }
}

/// Writes the state `s0` (`n x ncols`) into the state rows `pad..k` of the packed buffer
/// `w` (a `k x ncols` matrix, row- or column-major).
fn load_state(s0: MatRef<'_, f64>, pad: usize, w: &mut [f64], row_major: bool, k: usize) {
    let (n, nc) = (s0.nrows(), s0.ncols());
    debug_assert_eq!(pad + n, k);
    for j in 0..nc {
        for i in 0..n {
            let idx = if row_major {
                (pad + i) * nc + j
            } else {
                j * k + pad + i
            };
            w[idx] = s0[(i, j)];
        }
    }
}

/// Static operator (no state): `out_k = alpha * g x_k (+ out_k)` for every sample `k`,
/// where `g` is `cout x cin` (`D` or `D^T`).
pub(crate) fn static_columns(
    g: MatRef<'_, f64>,
    len: usize,
    x: MatRef<'_, f64>,
    out: MatMut<'_, f64>,
    accum: Accum,
    alpha: f64,
) {
    let (cout, cin) = (g.nrows(), g.ncols());
    par_columns(x, out, faer::get_global_parallelism(), &|x, mut out| {
        for t in 0..len {
            matmul(
                out.rb_mut().subrows_mut(t * cout, cout),
                accum,
                g,
                x.subrows(t * cin, cin),
                alpha,
                Par::Seq,
            );
        }
    });
}

/// Splits the columns of `x` across the threads of `par` and runs `leaf` on each part.
pub(crate) fn par_columns_mut(
    x: MatMut<'_, f64>,
    par: Par,
    leaf: &(dyn Fn(MatMut<'_, f64>) + Sync),
) {
    let nc = x.ncols();
    if par.degree() <= 1 || nc < 2 * MIN_PAR_COLS {
        leaf(x);
        return;
    }
    let mid = nc / 2;
    let (x0, x1) = x.split_at_col_mut(mid);
    faer::utils::thread::join_raw(
        move |p| par_columns_mut(x0, p, leaf),
        move |p| par_columns_mut(x1, p, leaf),
        par,
    );
}

/// Splits the columns of `x`/`out` across the threads of `par` and runs `leaf` on each part.
pub(crate) fn par_columns(
    x: MatRef<'_, f64>,
    out: MatMut<'_, f64>,
    par: Par,
    leaf: &(dyn Fn(MatRef<'_, f64>, MatMut<'_, f64>) + Sync),
) {
    let nc = x.ncols();
    if par.degree() <= 1 || nc < 2 * MIN_PAR_COLS {
        leaf(x, out);
        return;
    }
    let mid = nc / 2;
    let (x0, x1) = x.split_at_col(mid);
    let (o0, o1) = out.split_at_col_mut(mid);
    faer::utils::thread::join_raw(
        move |p| par_columns(x0, o0, p, leaf),
        move |p| par_columns(x1, o1, p, leaf),
        par,
    );
}
