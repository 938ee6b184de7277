//! The exact dual (representer) solver for quadratic dispersions.
//!
//! With K the block-diagonal Gram matrix over the blocks, the optimum of eq. (4) is
//!
//! ```text
//! M = L·β·T_ye·T_yeᵀ + Σ_i T_i·K_i·T_iᵀ          (L·n_y × L·n_y, symmetric PSD)
//! λ = M⁻¹ r,   α_i = T_iᵀ λ,   ŵ_i = K_i α_i,   ê = L·β·T_yeᵀ λ,   N̂_i(z) = Σ_k α_{i,k} K_i(z, z_k)
//! ```
//!
//! which needs no K⁻¹ (Gaussian Gram matrices are numerically singular). M is assembled by
//! applying the operators to Gram columns, Q_i = T_i·K_i, then M += T_i·Q_iᵀ (valid because
//! K_i and M are symmetric). Q_i is never stored whole: the first SISO block is transformed in
//! M's own buffer and the others stream Q_i in time blocks through a stateful Toeplitz pass
//! (see `assemble`), so the peak memory is M plus a few panels (one L×L matrix for SISO).
//! ŵ_i = K_i·α_i is recomputed panel by panel from the Gram columns.
//!
//! Output samples that depend on neither e nor w (a strictly proper path from a zero initial
//! state) make M singular: their rows of M are zero. They are detected on M's diagonal,
//! checked for consistency (r ≈ 0 there) and left out.

use std::sync::Arc;
use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{
    LltParams, LltRegularization, cholesky_in_place, cholesky_in_place_scratch,
};
use faer::linalg::cholesky::llt::solve::{solve_in_place_scratch, solve_in_place_with_conj};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Conj, Mat, MatMut, MatRef};
use structid_lti::{LinearSystem, Signal};

use crate::dispersion::QuadraticPenalty;
use crate::error::{Error, Result};
use crate::identify::posterior::{DenseBlock as DensePosteriorBlock, Posterior};
use crate::identify::problem::Problem;
use crate::identify::result::{Diagnostics, Identification, Timings};
use crate::identify::settings::IdentifySettings;
use crate::solver::square_buffer::SquareBuffer;
use crate::solver::{BlockPart, assemble_blocks, cost_terms};

/// Gram columns are generated and pushed through T_i in panels of this many columns.
const PANEL: usize = 256;

/// Relative diagonal jitters tried, in order, when M is numerically singular.
const JITTER_LADDER: [f64; 3] = [1e-13, 1e-10, 1e-7];

/// Block size of the Cholesky factorisation of M. faer's default (128) makes one rank-128
/// update of the trailing matrix per block, each a pass over up to L×L memory; 256 halves
/// those passes and factored a 4000² SPD matrix 5–8 % faster on the project machine.
const CHOLESKY_BLOCK: usize = 256;

/// Estimated peak memory of the exact solver in bytes.
pub fn peak_memory_bytes(
    len: usize,
    outputs: usize,
    noise_inputs: usize,
    noise_dynamic: bool,
    free_cols: usize,
) -> u64 {
    let n = (len * outputs) as u64;
    let l = len as u64;
    let p = PANEL.min(len.max(1)) as u64;
    // M, a Gram panel and a panel of Q = T·K (see `assemble`)
    let mut words = n * n + l * p + n * p + 8 * n + 2 * n * free_cols as u64;
    if noise_dynamic {
        words += (n + (len * noise_inputs) as u64) * p;
    }
    8 * words
}

/// Extra memory of the exact solver when it keeps the posterior
/// ([`IdentifySettings::posterior`]), 0 otherwise. The n×n Cholesky factor itself is M's buffer,
/// already counted in [`peak_memory_bytes`], but it then stays allocated inside
/// [`crate::Posterior`] for as long as the [`Identification`] lives (8·n² bytes, n = L·n_y);
/// this adds the basis of the initial-state directions (n·n_x) and the workspace of one batch
/// of [`crate::identify::posterior::BATCH`] points (BATCH·(L + 2n)).
pub fn posterior_memory_bytes(
    settings: &IdentifySettings,
    len: usize,
    outputs: usize,
    free_cols: usize,
) -> u64 {
    if !settings.posterior() {
        return 0;
    }
    let n = (len * outputs) as u64;
    let batch = crate::identify::posterior::BATCH.min(len.max(1)) as u64;
    8 * (n * free_cols as u64 + batch * (len as u64 + 2 * n) + n)
}

/// The largest length in 0..=`len` that `fits` (which must hold up to some length and fail
/// beyond it), by bisection: the suggestion of a window that fits the memory.
fn longest_fitting(len: usize, fits: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0usize, len);
    while lo < hi {
        let mid = lo + (hi - lo).div_ceil(2);
        if fits(mid) {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    lo
}

fn solver_name() -> &'static str {
    "exact"
}

/// Solves the problem exactly; see the module documentation.
pub fn solve(problem: &Problem, settings: &IdentifySettings) -> Result<Identification> {
    let t_start = Instant::now();
    let beta = settings.beta();
    let len = problem.len();
    let ny = problem.outputs();
    let n = len * ny;
    let noise = problem.noise();
    let ne = noise.inputs();
    let noise_dynamic = noise.order() > 0;

    let free = problem.free_response();
    let nx = free.map_or(0, |o| o.ncols());
    let need = peak_memory_bytes(len, ny, ne, noise_dynamic, nx)
        + posterior_memory_bytes(settings, len, ny, nx);
    let limit = settings.effective_memory_limit();
    if need > limit {
        let max_len = longest_fitting(len, |l| {
            peak_memory_bytes(l, ny, ne, noise_dynamic, nx)
                + posterior_memory_bytes(settings, l, ny, nx)
                <= limit
        });
        return Err(Error::TooLarge {
            solver: solver_name().into(),
            needed_mib: need >> 20,
            limit_mib: limit >> 20,
            size: n,
            suggestion: format!(
                "The exact solver stores the dense {n}×{n} matrix M. For the whole record use a \
                 dispersion with finitely many features, which the feature solver handles in memory \
                 linear in L (the dispersion `gaussian-lowrank` for the Gaussian kernel by a \
                 low-rank approximation, or `fourier`), or total variation by ADMM; otherwise \
                 identify on a window of at most about {max_len} samples, or raise the memory limit \
                 if the machine has the memory."
            ),
        });
    }

    let penalties: Vec<Box<dyn QuadraticPenalty>> = problem
        .blocks()
        .iter()
        .map(|b| {
            let q = super::quadratic_penalty(b, "exact")?;
            if q.len() != len {
                return Err(Error::DimensionMismatch {
                    what: format!("Gram matrix of block `{}`", b.name),
                    expected: len.to_string(),
                    found: q.len().to_string(),
                });
            }
            Ok(q)
        })
        .collect::<Result<_>>()?;
    let t_prepared = Instant::now();

    // --- assemble M, leave out samples that depend on neither e nor w, factor -------------
    let lb = len as f64 * beta;
    // M is factorised in place. Q = T·K is never stored whole: see `assemble`.
    let mut m = SquareBuffer::zeros(n);
    let nblocks = problem.blocks().len();
    let r_data = problem.residual().as_slice();
    let mut t_assembled;
    let par = faer::get_global_parallelism();
    let mut llt_params: LltParams = faer::Auto::<f64>::auto();
    llt_params.block_size = CHOLESKY_BLOCK;
    let mut buf = MemBuffer::new(
        cholesky_in_place_scratch::<f64>(n, par, llt_params.into())
            .or(solve_in_place_scratch::<f64>(n, 1 + nx, par)),
    );
    let stack = MemStack::new(&mut buf);
    // A failed factorisation (M numerically singular) is repaired by re-assembling M and adding
    // a small diagonal jitter, equivalent to a little extra white noise on y; it is reported.
    let mut jitter = 0.0;
    let mut attempt = 0;
    let (kept, dropped, max_diag) = loop {
        assemble(problem, &penalties, lb, m.as_mut());
        let (kept, dropped, max_diag) = compact_live_rows(m.as_mut(), problem.held_out())?;
        let nk = kept.len();
        let mut mk = m.as_mut().submatrix_mut(0, 0, nk, nk);
        if jitter > 0.0 {
            for i in 0..nk {
                mk[(i, i)] += jitter;
            }
        }
        t_assembled = Instant::now();
        match cholesky_in_place(
            mk,
            LltRegularization::default(),
            par,
            stack,
            llt_params.into(),
        ) {
            Ok(_) => break (kept, dropped, max_diag),
            Err(e) => {
                attempt += 1;
                jitter = JITTER_LADDER
                    .get(attempt - 1)
                    .copied()
                    .unwrap_or(f64::INFINITY)
                    * max_diag;
                if !jitter.is_finite() {
                    return Err(Error::Numerical(format!(
                        "Cholesky factorisation of M failed even with a diagonal jitter of 1e-7·max(diag M): {e}"
                    )));
                }
            }
        }
    };
    let nk = kept.len();
    let mk = m.as_mut().submatrix_mut(0, 0, nk, nk);
    let t_factored = Instant::now();

    // --- solve and recover ------------------------------------------------------------------
    // Right-hand sides [r | O]: the free-response columns give the generalised least-squares
    // estimate of an unknown initial state, x₀ = (OᵀM⁻¹O)⁻¹OᵀM⁻¹r, then λ = M⁻¹(r − O·x₀).
    let mut rhs = Mat::<f64>::from_fn(nk, 1 + nx, |i, j| match (j, free) {
        (0, _) => r_data[kept[i]],
        (_, Some(o)) => o[(kept[i], j - 1)],
        _ => 0.0,
    });
    solve_in_place_with_conj(mk.as_ref(), Conj::No, rhs.as_mut(), par, stack);
    let (dmin, dmax) = (0..nk).fold((f64::INFINITY, 0.0f64), |(lo, hi), i| {
        let d = mk[(i, i)];
        (lo.min(d), hi.max(d))
    });
    let x0 = match free {
        Some(o) if nx > 0 => {
            let h = nalgebra::DMatrix::<f64>::from_fn(nx, nx, |a, b| {
                (0..nk).map(|i| o[(kept[i], a)] * rhs[(i, 1 + b)]).sum()
            });
            let g = nalgebra::DVector::from_fn(nx, |a, _| {
                (0..nk).map(|i| o[(kept[i], a)] * rhs[(i, 0)]).sum()
            });
            // Directions of x₀ that do not reach y get their minimum-norm value 0 (SVD at
            // 10⁻¹² of the largest singular value): they change neither y nor the fit. A
            // non-finite OᵀM⁻¹O (overflow on huge data or free responses) is refused before
            // the SVD, which panics on NaN singular values.
            let not_finite = || {
                Error::Numerical(
                    "the initial state is not identifiable from this record (OᵀM⁻¹O is not finite)"
                        .into(),
                )
            };
            if h.iter().any(|v| !v.is_finite()) {
                return Err(not_finite());
            }
            let svd = h.svd(true, true);
            let smax = svd.singular_values.max();
            if !smax.is_finite() {
                return Err(not_finite());
            }
            let x0 = if smax == 0.0 {
                nalgebra::DVector::zeros(nx)
            } else {
                svd.solve(&g, 1e-12 * smax).map_err(|e| {
                    Error::Numerical(format!("the initial state's least squares failed: {e}"))
                })?
            };
            for i in 0..nk {
                let corr: f64 = (0..nx).map(|j| rhs[(i, 1 + j)] * x0[j]).sum();
                rhs[(i, 0)] -= corr;
            }
            Some(x0.iter().copied().collect::<Vec<f64>>())
        }
        _ => None,
    };
    // The residual the maps and the noise must explain: r − O·x₀.
    let r_owned: Vec<f64> = match (&x0, free) {
        (Some(x0), Some(o)) => (0..n)
            .map(|i| r_data[i] - (0..nx).map(|j| o[(i, j)] * x0[j]).sum::<f64>())
            .collect(),
        _ => r_data.to_vec(),
    };
    let r = &r_owned[..];
    let dropped_max = dropped.iter().map(|&i| r[i].abs()).fold(0.0, f64::max);
    let mut lambda = vec![0.0; n];
    for (i, &row) in kept.iter().enumerate() {
        lambda[row] = rhs[(i, 0)];
    }
    if lambda.iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical(
            "the solve of M·λ = r produced non-finite values".into(),
        ));
    }

    let mut parts = Vec::with_capacity(nblocks);
    let mut kept_penalties = Vec::with_capacity(nblocks);
    for (block, pen) in problem.blocks().iter().zip(penalties) {
        let mut alpha = vec![0.0; len];
        block.path.apply_adjoint(&lambda, &mut alpha);
        let w_hat = pen.gram_times(&alpha);
        // D_i = ŵᵀK⁻¹ŵ = αᵀKα = αᵀŵ.
        let dispersion_value: f64 = alpha.iter().zip(&w_hat).map(|(a, w)| a * w).sum();
        parts.push(BlockPart {
            w_hat,
            dispersion_value,
            map: pen.interpolant(alpha),
        });
        kept_penalties.push(Arc::<dyn QuadraticPenalty>::from(pen));
    }
    let assembled = assemble_blocks(problem, parts);
    let fitted = &assembled.fitted;
    let mut e_hat = vec![0.0; len * ne];
    noise.apply_adjoint(&lambda, &mut e_hat);
    e_hat.iter_mut().for_each(|v| *v *= lb);
    let mut te = vec![0.0; n];
    noise.apply(&e_hat, &mut te);
    let (mut res2, mut r2) = (0.0, 0.0);
    for &i in &kept {
        let d = te[i] + fitted[i] - r[i];
        res2 += d * d;
        r2 += r[i] * r[i];
    }
    let mu = e_hat.iter().map(|v| v * v).sum::<f64>() / len as f64;
    let cost = cost_terms(mu, beta, &assembled)?;
    let t_end = Instant::now();

    let mut warnings = Vec::new();
    if !dropped.is_empty() {
        let scale = r
            .iter()
            .fold(0.0f64, |a, v| a.max(v.abs()))
            .max(f64::MIN_POSITIVE);
        warnings.push(format!(
            "{} output sample(s) depend on neither e nor w (strictly proper paths from a zero initial state) \
             and were left out; max |r| there = {dropped_max:.3e}{}",
            dropped.len(),
            if dropped_max > 1e-8 * scale {
                " — the data are NOT consistent with the model at those samples"
            } else {
                ""
            }
        ));
    }
    if jitter > 0.0 {
        warnings.push(format!(
            "M is numerically singular (e.g. no noise path and a numerically singular Gram matrix): a jitter of \
             {:.1e}·max(diag M) was added to its diagonal, so the data are fitted up to that level",
            jitter / max_diag
        ));
    }
    // The posterior keeps M's buffer (the factor) and the blocks' paths and penalties.
    let posterior = if settings.posterior() {
        let quad: f64 = kept.iter().map(|&i| r[i] * lambda[i]).sum();
        let blocks = problem
            .blocks()
            .iter()
            .zip(kept_penalties)
            .map(|(b, penalty)| DensePosteriorBlock {
                path: Arc::clone(&b.path),
                penalty,
                inputs: b.z.channels(),
            })
            .collect();
        Posterior::dense(m, kept, len, blocks, free, quad, lb)
            .map_err(|why| warnings.push(format!("no uncertainty bands: {why}")))
            .ok()
    } else {
        None
    };
    Ok(Identification {
        posterior,
        w_hat: assembled.w_hat,
        e_hat: Signal::new(ne, e_hat).map_err(Error::from)?,
        blocks: assembled.blocks,
        cost,
        z_source: problem.z_source().clone(),
        initial_state: x0,
        diagnostics: Diagnostics {
            solver: crate::SolverKind::Exact,
            system_size: nk,
            dropped_samples: dropped,
            dropped_max_abs_residual: dropped_max,
            diagonal_jitter: jitter,
            condition_lower_bound: super::condition_lower_bound(dmax, dmin),
            feasibility_residual: super::relative_residual(res2, r2),
            peak_memory_bytes: need,
            timings: Timings::from_instants(t_start, t_prepared, t_assembled, t_factored, t_end),
            warnings,
            ..Diagnostics::default()
        },
    })
}

/// M = Σ_i T_i·K_i·T_iᵀ + L·β·T_ye·T_yeᵀ without any n×L buffer besides M.
///
/// * A first block whose path is a SISO state-space system with n = L (one output) is built
///   in M's buffer: K is filled there (using its symmetry), Q = T·K replaces it in place
///   (the transposed view: its rows are the time samples), which leaves Qᵀ, and T·Qᵀ = M
///   replaces that in place.
/// * Every other block streams Q = T·K in time blocks: each panel of Gram columns
///   K[:, j₀..j₀+w] gives Q[:, j₀..j₀+w] = T·K[:, j₀..j₀+w], whose transpose is the time block
///   j₀..j₀+w of the operand of T·Qᵀ; a stateful Toeplitz pass ([`structid_lti::ColumnStream`])
///   adds those rows of M and carries its state to the next panel.
///
/// Paths that are not state-space systems fall back to [`assemble_with_q`] with an n×L Q.
/// The panels (L×[`PANEL`] Gram columns, n×`PANEL` of Q) are allocated only for streamed
/// blocks.
pub(crate) fn assemble(
    problem: &Problem,
    penalties: &[Box<dyn QuadraticPenalty>],
    lb: f64,
    mut m: MatMut<'_, f64>,
) {
    let len = problem.len();
    let n = m.nrows();
    if problem
        .blocks()
        .iter()
        .any(|b| b.path.as_state_space().is_none())
    {
        let mut q_buf = vec![0.0f64; n * len];
        let q = MatMut::from_column_major_slice_mut(&mut q_buf, n, len);
        let mut gram = vec![0.0; len * PANEL.min(len)];
        assemble_with_q(problem, penalties, lb, m, q, &mut gram);
        return;
    }
    let panel = PANEL.min(len);
    let mut gram = Vec::new();
    let mut qp = Mat::<f64>::new();
    for (bi, (block, pen)) in problem.blocks().iter().zip(penalties).enumerate() {
        let ss = block
            .path
            .as_state_space()
            .expect("checked above: every path is a state-space system");
        if bi == 0 && n == len && ss.inputs() == 1 && ss.outputs() == 1 {
            pen.fill(m.rb_mut());
            ss.apply_columns_in_place(m.rb_mut().transpose_mut(), false);
            ss.apply_columns_in_place(m.rb_mut(), false);
            continue;
        }
        let accum = if bi == 0 { Accum::Replace } else { Accum::Add };
        if gram.is_empty() {
            gram = vec![0.0; len * panel];
            qp = Mat::<f64>::zeros(n, panel);
        }
        // Two streams over the halves of M's columns, one per thread.
        let half = n / 2;
        let mut streams = [ss.column_stream(half), ss.column_stream(n - half)];
        for j0 in (0..len).step_by(panel) {
            let w = panel.min(len - j0);
            // Row-major panels: each time sample's w values are contiguous.
            let g = &mut gram[..len * w];
            pen.fill_columns(j0..j0 + w, MatMut::from_row_major_slice_mut(g, len, w));
            let g = MatRef::from_row_major_slice(g, len, w);
            let mut q = qp.as_mut().subcols_mut(0, w);
            block.path.apply_columns(g, q.rb_mut(), Accum::Replace, 1.0);
            // Time block j₀..j₀+w of Qᵀ (w rows, n columns) → rows of M.
            let x = q.rb().transpose();
            let out = m
                .rb_mut()
                .subrows_mut(j0 * ny_of(n, len), w * ny_of(n, len));
            let (x0, x1) = x.split_at_col(half);
            let (o0, o1) = out.split_at_col_mut(half);
            let [s0, s1] = &mut streams;
            let (r0, r1) = rayon::join(
                || s0.push_with(x0, o0, accum, 1.0),
                || s1.push_with(x1, o1, accum, 1.0),
            );
            r0.and(r1)
                .expect("the stream's shapes follow from M's and the panel's");
        }
    }
    add_noise_term(problem.noise(), len, lb, m);
}

/// Output channels per sample of M (n = L·n_y rows).
fn ny_of(n: usize, len: usize) -> usize {
    n / len.max(1)
}

/// M = Σ_i T_i·K_i·T_iᵀ + L·β·T_ye·T_yeᵀ through whole Q_i = T_i·K_i (n×L each) built from
/// panels of Gram columns; on return `q` holds Q of the last block. The fallback of
/// [`assemble`] for paths that are not state-space systems, and its reference in tests.
pub(crate) fn assemble_with_q(
    problem: &Problem,
    penalties: &[Box<dyn QuadraticPenalty>],
    lb: f64,
    mut m: MatMut<'_, f64>,
    mut q: MatMut<'_, f64>,
    gram: &mut [f64],
) {
    let len = problem.len();
    let panel = PANEL.min(len);
    for (bi, (block, pen)) in problem.blocks().iter().zip(penalties).enumerate() {
        if bi == 0 && m.nrows() >= len {
            // M's buffer is free before the first block: hold the whole K there (filled using
            // its symmetry), so Q = T·K is one pass; K's transpose view is row-major, the
            // layout the blocked recursion streams fastest, and equals K.
            let mut k = m.rb_mut().submatrix_mut(0, 0, len, len);
            pen.fill(k.rb_mut());
            block
                .path
                .apply_columns(k.rb().transpose(), q.rb_mut(), Accum::Replace, 1.0);
        } else {
            for j0 in (0..len).step_by(panel) {
                let w = panel.min(len - j0);
                // Row-major panels: each time sample's w values are contiguous.
                let g = &mut gram[..len * w];
                pen.fill_columns(j0..j0 + w, MatMut::from_row_major_slice_mut(g, len, w));
                let g = MatRef::from_row_major_slice(g, len, w);
                block
                    .path
                    .apply_columns(g, q.rb_mut().subcols_mut(j0, w), Accum::Replace, 1.0);
            }
        }
        let accum = if bi == 0 { Accum::Replace } else { Accum::Add };
        block
            .path
            .apply_columns(q.rb().transpose(), m.rb_mut(), accum, 1.0);
    }
    add_noise_term(problem.noise(), len, lb, m);
}

/// Finds the rows of M that are (numerically) zero — samples that depend on neither e nor w —
/// and compacts the others, except held-out rows (cross-validation), into the leading block.
/// Returns (kept, dropped, max diag); held-out rows are in neither list.
fn compact_live_rows(
    mut m: MatMut<'_, f64>,
    held_out: Option<&[bool]>,
) -> Result<(Vec<usize>, Vec<usize>, f64)> {
    let n = m.nrows();
    let max_diag = (0..n).map(|i| m[(i, i)]).fold(0.0f64, f64::max);
    if (0..n).any(|i| !m[(i, i)].is_finite()) {
        // M = T·K·Tᵀ + L·β·A depends on the data only through z (where K is bounded): its
        // overflow is the model's.
        return Err(Error::Unstable(
            "the paths w → y overflow over the record (the system matrix M is not finite): the \
             linear block is unstable or badly scaled; rescale it"
                .into(),
        ));
    }
    if max_diag <= 0.0 {
        return Err(Error::Numerical(format!(
            "the system matrix M has no positive diagonal entry (max {max_diag}): no output depends on e or w"
        )));
    }
    let dead_tol = 1e-14 * max_diag;
    let held = |i: usize| held_out.is_some_and(|h| h[i]);
    let (kept, dropped): (Vec<usize>, Vec<usize>) = (0..n)
        .filter(|&i| !held(i))
        .partition(|&i| m[(i, i)] > dead_tol);
    if kept.len() < n {
        // In place: destinations never overtake their sources in column-major order.
        for (jj, &j) in kept.iter().enumerate() {
            for (ii, &i) in kept.iter().enumerate() {
                m[(ii, jj)] = m[(i, j)];
            }
        }
    }
    Ok((kept, dropped, max_diag))
}

/// M += L·β·T_ye·T_yeᵀ: a block-diagonal D_ye·D_yeᵀ for a static noise path, otherwise built
/// panel by panel from T_yeᵀ applied to identity columns.
pub(crate) fn add_noise_term(
    noise: &dyn LinearSystem,
    len: usize,
    lb: f64,
    mut m: MatMut<'_, f64>,
) {
    if lb == 0.0 {
        return;
    }
    let ny = noise.outputs();
    let ne = noise.inputs();
    let n = len * ny;
    if ne == 0 {
        return;
    }
    if noise.order() == 0 {
        let mut d = vec![0.0; ny * ne]; // column-major D_ye
        let mut unit = vec![0.0; ne];
        for c in 0..ne {
            unit.iter_mut().for_each(|v| *v = 0.0);
            unit[c] = 1.0;
            noise.apply(&unit, &mut d[c * ny..(c + 1) * ny]);
        }
        for k in 0..len {
            for i in 0..ny {
                for j in 0..ny {
                    let ddt: f64 = (0..ne).map(|c| d[c * ny + i] * d[c * ny + j]).sum();
                    m[(k * ny + i, k * ny + j)] += lb * ddt;
                }
            }
        }
        return;
    }
    let panel = PANEL.min(n);
    let mut x = Mat::<f64>::zeros(len * ne, panel);
    let mut ident = Mat::<f64>::zeros(n, panel);
    for j0 in (0..n).step_by(panel) {
        let w = panel.min(n - j0);
        ident.fill(0.0);
        for jj in 0..w {
            ident[(j0 + jj, jj)] = 1.0;
        }
        noise.apply_adjoint_columns(
            ident.as_ref().subcols(0, w),
            x.as_mut().subcols_mut(0, w),
            Accum::Replace,
            1.0,
        );
        noise.apply_columns(
            x.as_ref().subcols(0, w),
            m.rb_mut().subcols_mut(j0, w),
            Accum::Add,
            lb,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{KernelDispersion, ProblemBlock};
    use structid_lti::StateSpace;

    /// A problem with `blocks` Gaussian blocks behind random stable paths (`ny` outputs, one
    /// input each) and a dynamic noise path.
    fn random_problem(seed: u64, len: usize, ny: usize, blocks: usize) -> Problem {
        use structid_lti::testing::random_stable_system;
        let bl = (0..blocks)
            .map(|i| ProblemBlock {
                name: format!("b{i}"),
                output: i,
                path: Arc::new(random_stable_system(seed + i as u64, 3 + i, 1, ny, 0.9)),
                z: Signal::from_fn(len, 1, |k, _| ((k * (7 + i) + 3) % 23) as f64 / 11.0 - 1.0),
                dispersion: Arc::new(KernelDispersion::gaussian(0.4).unwrap()),
            })
            .collect();
        let residual = Signal::from_fn(len, ny, |k, c| ((k * 5 + c * 3) % 7) as f64 - 3.0);
        let noise = Arc::new(random_stable_system(seed ^ 99, 2, ny, ny, 0.8));
        Problem::new(residual, noise, bl).unwrap()
    }

    /// The streamed assembly (in-place first block, stateful Toeplitz pass for the others)
    /// equals the reference that stores Q = T·K whole, to 1e-12 relative: SISO one and two
    /// blocks, two outputs, and lengths that are and are not multiples of the panel width.
    #[test]
    fn the_streamed_assembly_equals_the_whole_q_assembly() {
        for (len, ny, blocks) in [
            (300, 1, 1),
            (300, 1, 2),
            (257, 1, 3),
            (130, 2, 2),
            (600, 1, 2),
            (40, 2, 1),
        ] {
            let problem = random_problem(len as u64, len, ny, blocks);
            let penalties: Vec<Box<dyn QuadraticPenalty>> = problem
                .blocks()
                .iter()
                .map(|b| super::super::quadratic_penalty(b, "exact").unwrap())
                .collect();
            let n = len * ny;
            let mut gram = vec![0.0; len * PANEL.min(len)];
            let mut want = Mat::<f64>::zeros(n, n);
            let mut q = vec![0.0; n * len];
            assemble_with_q(
                &problem,
                &penalties,
                0.3,
                want.as_mut(),
                MatMut::from_column_major_slice_mut(&mut q, n, len),
                &mut gram,
            );
            // a dirty buffer, as on a re-assembly after a failed factorisation
            let mut got = Mat::<f64>::from_fn(n, n, |i, j| (i + 2 * j) as f64);
            assemble(&problem, &penalties, 0.3, got.as_mut());
            let err = (&want - &got).norm_max() / want.norm_max();
            assert!(
                err <= 1e-12,
                "L = {len}, n_y = {ny}, {blocks} blocks: {err:e}"
            );
        }
    }

    /// K·α by the Gaussian penalty's symmetric panels equals the product with the whole K to
    /// 1e-12 relative, for one and two input channels and lengths that are and are not
    /// multiples of the panel width.
    #[test]
    fn the_symmetric_gram_product_equals_the_dense_one() {
        use crate::dispersion::{Dispersion, Penalty};
        for (len, p) in [(1, 1), (63, 1), (64, 1), (200, 1), (129, 2)] {
            let z = Signal::from_fn(len, p, |k, c| ((k * (5 + c) + 3) % 17) as f64 / 8.0 - 1.0);
            let Penalty::Quadratic(pen) = KernelDispersion::gaussian(0.4)
                .unwrap()
                .penalty(&z)
                .unwrap()
            else {
                panic!("a kernel penalty is quadratic");
            };
            let alpha: Vec<f64> = (0..len).map(|k| ((k * 7) % 13) as f64 - 6.0).collect();
            let mut k = Mat::<f64>::zeros(len, len);
            pen.fill_columns(0..len, k.as_mut());
            let want: Vec<f64> = (0..len)
                .map(|i| (0..len).map(|j| k[(i, j)] * alpha[j]).sum())
                .collect();
            let got = pen.gram_times(&alpha);
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let err = want
                .iter()
                .zip(&got)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(err <= 1e-12 * scale, "L = {len}, p = {p}: {err:e}");
        }
    }

    /// Found by the `lft_problem` fuzz target: free responses so large that OᵀM⁻¹O overflows
    /// made the SVD of the initial-state step panic (NaN singular values).
    #[test]
    fn an_overflowing_initial_state_step_is_an_error_not_a_panic() {
        let len = 4;
        let gain = |v: f64| Arc::new(StateSpace::static_gain(nalgebra::dmatrix![v]).unwrap());
        let block = ProblemBlock {
            name: "b0".into(),
            output: 0,
            path: gain(1.0),
            z: Signal::from_fn(len, 1, |k, _| k as f64),
            dispersion: Arc::new(KernelDispersion::gaussian(0.5).unwrap()),
        };
        let residual = Signal::from_fn(len, 1, |k, _| 1.0 - k as f64);
        let problem = Problem::new(residual, gain(1.0), vec![block])
            .unwrap()
            .with_free_response(Mat::from_fn(len, 1, |_, _| 1e300))
            .unwrap();
        let settings = IdentifySettings::builder()
            .solver(crate::SolverChoice::Exact)
            .build()
            .unwrap();
        let e = solve(&problem, &settings).unwrap_err();
        assert!(matches!(e, Error::Numerical(_)), "{e:?}");
        assert!(e.to_string().contains("initial state"), "{e}");
    }

    /// The suggested window was 0 samples for long records (a coarse scan from the top).
    #[test]
    fn the_suggested_window_is_the_longest_that_fits() {
        let limit = 16u64 << 30;
        let fits = |l: usize| peak_memory_bytes(l, 1, 1, false, 0) <= limit;
        let l = longest_fitting(10_000_000, fits);
        assert!(l > 30_000 && fits(l) && !fits(l + 1), "{l}");
        assert_eq!(longest_fitting(100, fits), 100);
        assert_eq!(longest_fitting(100, |_| false), 0);
    }

    /// A path whose gain overflows M (a model with A = 1e308) is the model's instability,
    /// not a numerical accident.
    #[test]
    fn an_overflowing_system_matrix_is_an_unstable_model() {
        let len = 4;
        let gain = |v: f64| Arc::new(StateSpace::static_gain(nalgebra::dmatrix![v]).unwrap());
        let block = ProblemBlock {
            name: "b0".into(),
            output: 0,
            path: gain(1e200),
            z: Signal::from_fn(len, 1, |k, _| k as f64),
            dispersion: Arc::new(KernelDispersion::gaussian(0.5).unwrap()),
        };
        let residual = Signal::from_fn(len, 1, |k, _| 1.0 - k as f64);
        let problem = Problem::new(residual, gain(1.0), vec![block]).unwrap();
        let settings = IdentifySettings::builder()
            .solver(crate::SolverChoice::Exact)
            .build()
            .unwrap();
        let e = solve(&problem, &settings).unwrap_err();
        assert!(matches!(e, Error::Unstable(_)), "{e:?}");
        assert!(e.to_string().contains("overflow"), "{e}");
    }
}
