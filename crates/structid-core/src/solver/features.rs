//! The feature-space solver: cost linear in L for penalties with finitely many features.
//!
//! When each block's map is w_i = Ψ_i·a_i with D_i = a_iᵀΛ_i⁻¹a_i, write a_i = Λ_i^½·b_i and
//! Φ_i = Ψ_iΛ_i^½. With F = [T_1Φ_1 … T_BΦ_B] and the whitening W (WᵀW = (T_ye·T_yeᵀ)⁻¹),
//! eq. (4) becomes the ridge regression
//!
//! ```text
//! min_b (1/L)·‖W(r − F b − O x₀)‖² + β·‖b‖²
//! ```
//!
//! whose normal equations need only G = [F O r]ᵀWᵀW[F O r], an (m+n_x+1)² matrix. One pass over
//! time accumulates G chunk by chunk: the features of a chunk go through the block paths as a
//! [`ColumnStream`] (state carried between chunks), are whitened, and G += XᵀX is accumulated
//! from them; the L×m matrix F is never stored. When the Kalman whitening has no time-varying
//! transient it is folded into the paths: the features go through the series connection
//! W·T_i in one blocked recursion, and only [O r] through W alone. The feature columns and
//! the rows of each chunk's Gram update are split into two parts that run in parallel (the
//! split does not depend on the thread count, so neither do the results); what both column
//! parts of a map need per sample (a Fourier map's cos and sin of 2πt,
//! [`FeatureMap::prepare_rows`]) is computed once, a chunk ahead. The Gram update is a few
//! rectangular matrix products over row panels of G. A second pass
//! recovers ŵ (batched feature combinations) and ê, whose single long signals go through
//! blocked recursions ([`structid_lti::StateSpace::apply_long`]).
//!
//! The scaling by Λ^½ keeps the system well conditioned (its matrix is ≥ L·β·I on b) even when
//! λ_n decays to 1e-300. Coloured noise is whitened by the Kalman filter of the noise path,
//! streamed with the same chunks; a non-minimum-phase noise model, whose whitening filter is
//! unstable (the whitened record would grow geometrically), is refused in favour of the exact
//! solver. (A TSQR update instead of G was tried: no more accurate on minimum-phase models,
//! three times slower.)

use std::sync::Arc;
use std::time::Instant;

use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Mat, MatMut};
use rayon::prelude::*;
use structid_lti::{ColumnStream, KalmanWhitener, LinearSystem, Signal, WhiteningOptions};

use crate::dispersion::fourier::FeatureExpansion;
use crate::dispersion::{FeatureMap, QuadraticPenalty};
use crate::error::{Error, Result};
use crate::identify::posterior::{FeatureBlock as FeaturePosteriorBlock, Posterior};
use crate::identify::problem::Problem;
use crate::identify::result::{Diagnostics, Identification, Timings};
use crate::identify::settings::IdentifySettings;
use crate::solver::{BlockPart, cost_terms};

/// Samples per chunk of the time pass (rounded to the streams' block length): the chunk of
/// features and of X (m + n_x + 1 columns) stays within a core's L2 cache.
const CHUNK: usize = 2048;

/// Parts the pass is split into (run in parallel when rayon has the threads).
const PARTS: usize = 2;

/// The recursion of one part of a block's feature columns through its path (or through W·T_i
/// when the whitening is folded in), with the state carried from chunk to chunk.
struct PathJob {
    /// The block.
    block: usize,
    /// First of the block's feature columns this part carries.
    first: usize,
    /// The stream (its column count is the part's width).
    stream: ColumnStream,
    /// This part's features of a chunk (row-major, chunk × width), evaluated on the thread
    /// that pushes them: a buffer shared between threads would move between the cores'
    /// caches every chunk.
    phi: Vec<f64>,
}

/// Height of the row panels of the Gram update ([`gram_lower`]).
const GRAM_PANEL: usize = 8;

/// G += XᵀX on the lower triangle (diagonal included) of `g`, on the calling thread, by row
/// panels: G[r₀..r₁, ..r₁] += X[:, r₀..r₁]ᵀ·X[:, ..r₁] for panels of [`GRAM_PANEL`] rows (the
/// last one takes a remainder below half a panel), each one rectangular matrix product. The
/// diagonal blocks are computed whole (their upper entries are overwritten when G is
/// symmetrised), about 9 % more flops than the triangle with 65 columns, but faer's
/// triangular product splits the triangle into small blocks recursively and ran about 25 %
/// slower on the pass's shape (2048 × 65, one thread).
fn gram_lower(mut g: MatMut<'_, f64>, x: faer::MatRef<'_, f64>) {
    let cols = x.ncols();
    let mut r0 = 0;
    while r0 < cols {
        let mut r1 = (r0 + GRAM_PANEL).min(cols);
        if cols - r1 < GRAM_PANEL / 2 {
            r1 = cols;
        }
        faer::linalg::matmul::matmul(
            g.rb_mut().submatrix_mut(r0, 0, r1 - r0, r1),
            faer::Accum::Add,
            x.subcols(r0, r1 - r0).transpose(),
            x.subcols(0, r1),
            1.0,
            faer::Par::Seq,
        );
        r0 = r1;
    }
}

/// Whether every block of `problem` can use the feature solver, and if not, why.
pub fn unsupported_reason(problem: &Problem) -> Option<String> {
    if problem.noise().order() > 0 && record_state_space(problem.noise()).is_none() {
        return Some(
            "the feature solver whitens a dynamic noise path as a state-space system".into(),
        );
    }
    for b in problem.blocks() {
        if record_state_space(b.path.as_ref()).is_none() {
            return Some(format!(
                "block `{}`: the feature solver streams its path as a state-space system",
                b.name
            ));
        }
    }
    None
}

/// The state-space system of a path, or of each record of a record-by-record path (the pass
/// restarts it at every record).
fn record_state_space(sys: &dyn LinearSystem) -> Option<&structid_lti::StateSpace> {
    sys.as_state_space()
        .or_else(|| sys.as_recordwise()?.inner().as_state_space())
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// The one pass over time: the feature maps of the blocks and the Gram matrix
/// G = [F O r]ᵀWᵀW[F O r] (see the module documentation).
pub(crate) struct FeatureGram {
    pub maps: Vec<(Arc<dyn FeatureMap>, Signal)>,
    pub dims: Vec<usize>,
    pub offsets: Vec<usize>,
    /// Total number of features m.
    pub m: usize,
    /// Number of free initial-state columns.
    pub nx: usize,
    /// (m + n_x + 1)², columns in the order [features, x₀, r].
    pub g: Mat<f64>,
    whitening: Whitening,
    chunk: usize,
    t_prepared: Instant,
    t_assembled: Instant,
}

/// Accumulates [`FeatureGram`]. With `scaled`, the features are Φ = ΨΛ^½ (what the solver
/// needs); without, the bare Ψ (what hyperparameter selection needs, as it varies Λ).
/// Output rows with `held_out[row]` set contribute nothing (cross-validation; static noise only,
/// whose whitening acts sample by sample).
impl FeatureGram {
    /// ln det(T_ye·T_yeᵀ) of the whitening (for marginal likelihoods).
    pub fn noise_log_det(&self, len: usize) -> f64 {
        match &self.whitening {
            Whitening::Static { ls, .. } => {
                len as f64 * 2.0 * ls.l().diagonal().iter().map(|v| v.ln()).sum::<f64>()
            }
            Whitening::Kalman(k) => k.log_det(),
        }
    }
}

pub(crate) fn gram(
    problem: &Problem,
    scaled: bool,
    held_out: Option<&[bool]>,
) -> Result<FeatureGram> {
    if let Some(reason) = unsupported_reason(problem) {
        return Err(Error::Unsupported(reason));
    }
    let len = problem.len();
    let ny = problem.outputs();
    let noise = problem.noise();
    let ne = noise.inputs();
    let penalties: Vec<Box<dyn QuadraticPenalty>> = problem
        .blocks()
        .iter()
        .map(|b| super::quadratic_penalty(b, "feature"))
        .collect::<Result<_>>()?;
    let mut maps: Vec<(Arc<dyn FeatureMap>, Signal)> = Vec::new();
    for (b, p) in problem.blocks().iter().zip(&penalties) {
        maps.push(p.features().map(|(f, z)| (f, z.clone())).ok_or_else(|| {
            Error::Unsupported(format!(
                "block `{}` ({}) has no finite feature map; use the exact solver or a Fourier dispersion",
                b.name,
                b.dispersion.describe()
            ))
        })?);
    }
    let dims: Vec<usize> = maps.iter().map(|(f, _)| f.dim()).collect();
    let offsets: Vec<usize> = dims
        .iter()
        .scan(0, |acc, d| {
            let o = *acc;
            *acc += d;
            Some(o)
        })
        .collect();
    let m: usize = dims.iter().sum();
    let free = problem.free_response();
    let nx = free.map_or(0, |o| o.ncols());
    let cols = m + nx + 1;

    // Whitening: ω_t = L_S⁻¹·ν_t with S = D_ye·D_yeᵀ for a static noise path, the Kalman
    // filter of the noise path otherwise (paper Fig. 3).
    // With several records, each is whitened from its own start (its own Kalman filter from
    // rest), as the noise path restarts there.
    let bounds = problem.record_bounds();
    let whitening = match record_state_space(noise).filter(|_| noise.order() > 0) {
        Some(ss) => {
            let k = RecordWhiteners::new(ss, bounds)?;
            // A noise model whose zeros lie on or outside the unit circle has an unstable
            // whitening filter (e.g. W = T_ye⁻¹ for square D_ye): the whitened record grows
            // geometrically. The exact (dual) solver does not whiten and is unaffected.
            // Only the modes the measurements drive through the gain can grow; a plant's
            // integrator that the noise does not reach stays at its zero state. The longest
            // record's whitener is the one nearest its steady state.
            let radius = k
                .longest()
                .steady_state_filter()
                .reachable_spectral_radius();
            if radius.is_nan() {
                return Err(Error::Numerical(
                    "the whitening filter of the noise model overflows (its entries are too large to \
                     compute its spectral radius); use the exact solver, or rescale the model"
                        .into(),
                ));
            }
            if radius >= 1.0 - 1e-9 {
                return Err(Error::Unsupported(format!(
                    "the noise model is not minimum phase: its whitening filter has spectral radius {radius:.4} ≥ 1, \
                     so the feature solver would whiten with an unstable recursion; use the exact solver, or a \
                     minimum-phase noise model with the same spectrum"
                )));
            }
            Whitening::Kalman(Box::new(k))
        }
        None => {
            let d = static_gain(noise, ny, ne);
            let ls = (&d * d.transpose()).cholesky().ok_or_else(|| {
                Error::Numerical(
                    "D_ye·D_yeᵀ is singular: some output carries no noise, so the noise-weighted fit is undefined; \
                     add noise to every output or use the exact solver"
                        .into(),
                )
            })?;
            Whitening::Static { d, ls }
        }
    };

    if let Some(mask) = held_out {
        if matches!(whitening, Whitening::Kalman(_)) {
            return Err(Error::Unsupported(
                "held-out samples with a dynamic noise path in the feature solver (its whitening runs across samples); use the exact solver"
                    .into(),
            ));
        }
        if mask.len() != len * ny || mask.chunks(ny).any(|s| s.iter().any(|&v| v != s[0])) {
            return Err(Error::InvalidStructure(
                "held-out rows must cover whole samples (all outputs of a sample)".into(),
            ));
        }
    }
    // Parts of the pass that can run in parallel: the feature columns are split between them
    // for the recursions, the rows of each chunk for the Gram update. The split does not
    // depend on the thread count, so neither do the results (bit for bit).
    let parts = PARTS;
    // A whitening without a time-varying transient is an LTI filter W from the first sample
    // on; then the features go through the series connection W·T_i in one recursion (folded)
    // and only the few columns [O r] through W alone.
    let folded = match &whitening {
        Whitening::Kalman(k) => k.without_transient(),
        Whitening::Static { .. } => false,
    };
    let mut jobs: Vec<PathJob> = Vec::new();
    let mut systems = Vec::with_capacity(problem.blocks().len());
    for (bi, b) in problem.blocks().iter().enumerate() {
        let path = record_state_space(b.path.as_ref()).expect("checked above");
        // The series connection carries the noise model's states in the path and the plant's in
        // the filter when both come from one model (order 10 where 5 is minimal): the blocked
        // recursion's cost grows with the order, so the hidden states are removed.
        let sys = match &whitening {
            Whitening::Kalman(k) if folded => k
                .longest()
                .steady_state_filter()
                .series(path)?
                .minimal_realisation(),
            _ => path.minimal_realisation(),
        };
        let mi = dims[bi];
        let per = mi.div_ceil(parts);
        let mut j0 = 0;
        while j0 < mi {
            let w = per.min(mi - j0);
            jobs.push(PathJob {
                block: bi,
                first: j0,
                stream: sys.column_stream(w),
                phi: Vec::new(),
            });
            j0 += w;
        }
        systems.push(sys);
    }
    let unit = jobs.iter().fold(1, |a, j| {
        a / gcd(a, j.stream.block_len()) * j.stream.block_len()
    });
    let chunk = CHUNK.div_ceil(unit) * unit;
    let t_prepared = Instant::now();

    // --- one pass over time: G = XᵀX with X = W·[F O r] ----------------------------------------
    let r = problem.residual().as_slice();
    let tail_cols = nx + 1;
    // the lower triangle of G, one accumulator per thread (summed after the pass)
    let mut g_parts: Vec<Mat<f64>> = (0..parts).map(|_| Mat::zeros(cols, cols)).collect();
    // Two buffers of X (and of the whitening's operand): the Gram update of one chunk runs
    // in the same parallel step as the recursions of the next, one synchronisation per chunk
    // and four tasks to balance instead of two steps of two. Each accumulator still takes
    // its rows of every chunk in time order, so the results do not depend on the scheduling.
    let mut xs: [Mat<f64>; 2] = std::array::from_fn(|_| Mat::<f64>::zeros(chunk * ny, cols));
    // folded: [O r] before whitening; otherwise the whole whitened chunk
    let mut wxs: [Mat<f64>; 2] = std::array::from_fn(|_| {
        Mat::<f64>::zeros(
            match &whitening {
                Whitening::Kalman(_) => chunk * ny,
                Whitening::Static { .. } => 0,
            },
            if folded { tail_cols } else { cols },
        )
    });
    // the Gram operand is X itself, or the whitened copy when the whitening is not folded
    let white_in_wx = matches!(whitening, Whitening::Kalman(_)) && !folded;
    let mut wstream = match &whitening {
        Whitening::Kalman(k) => Some(k.of(0).column_stream(if folded { tail_cols } else { cols })),
        Whitening::Static { .. } => None,
    };
    for job in jobs.iter_mut() {
        job.phi = vec![0.0; chunk * job.stream.state().ncols()];
    }
    let sqrt_w: Vec<Vec<f64>> = maps
        .iter()
        .map(|(f, _)| {
            if scaled {
                f.weights().iter().map(|l| l.sqrt()).collect()
            } else {
                vec![1.0; f.dim()]
            }
        })
        .collect();
    // G += XᵀX (lower triangle) for the first `rows` rows of a chunk, split between the parts
    let gram_update = |g_parts: &mut [Mat<f64>], white: faer::MatRef<'_, f64>, rows: usize| {
        let per = rows.div_ceil(parts);
        g_parts.par_iter_mut().enumerate().for_each(|(k, gk)| {
            let r0 = (k * per).min(rows);
            gram_lower(gk.as_mut(), white.subrows(r0, per.min(rows - r0)));
        });
    };
    // The chunks (first sample, length); they end at record boundaries.
    let mut schedule = Vec::new();
    {
        let (mut t, mut rec) = (0, 1);
        while t < len {
            if t == bounds[rec] {
                rec += 1;
            }
            let c = chunk.min(bounds[rec] - t);
            schedule.push((t, c));
            t += c;
        }
    }
    // What the column parts of a map share per sample (a Fourier map's cos and sin of 2πt),
    // computed once for both, a chunk ahead and split by samples, in two buffers like X.
    let plen: Vec<usize> = maps.iter().map(|(f, _)| f.prepared_len()).collect();
    let mut preps: [Vec<Vec<f64>>; 2] =
        std::array::from_fn(|_| plen.iter().map(|&p| vec![0.0; chunk * p]).collect());
    let prepare = |bufs: &mut [Vec<f64>], (t0, c): (usize, usize)| {
        for ((buf, &p), (map, z)) in bufs.iter_mut().zip(&plen).zip(&maps) {
            if p == 0 {
                continue;
            }
            let half = c.div_ceil(parts);
            buf[..c * p]
                .par_chunks_mut(half * p)
                .enumerate()
                .for_each(|(k, out)| map.prepare_rows(z, t0 + k * half, out));
        }
    };
    if let Some(&first) = schedule.first() {
        prepare(&mut preps[0], first);
    }
    // rows of the previous chunk whose Gram update is pending, and its buffer
    let mut pending: Option<(usize, usize)> = None;
    // Chunks end at record boundaries, where the paths and the whitening restart from rest.
    let mut next_record = 1;
    let mut t0 = 0;
    let mut buf = 0;
    let mut ci = 0;
    while t0 < len {
        if t0 == bounds[next_record] {
            next_record += 1;
            for job in jobs.iter_mut() {
                job.stream = systems[job.block].column_stream(job.stream.state().ncols());
            }
            if let Whitening::Kalman(k) = &whitening {
                wstream = Some(k.of(next_record - 1).column_stream(if folded {
                    tail_cols
                } else {
                    cols
                }));
            }
        }
        let c = chunk.min(bounds[next_record] - t0);
        debug_assert_eq!(schedule[ci], (t0, c));
        let (p0, p1) = preps.split_at_mut(1);
        let (prep, prep_next) = if buf == 0 {
            (&p0[0], &mut p1[0])
        } else {
            (&p1[0], &mut p0[0])
        };
        let ([x0, x1], [w0, w1]) = (&mut xs, &mut wxs);
        let ((x, wx), (x_prev, wx_prev)) = if buf == 0 {
            ((x0, w0), (&*x1, &*w1))
        } else {
            ((x1, w1), (&*x0, &*w0))
        };
        let xc = x.as_mut().subrows_mut(0, c * ny);
        let (mut feat, mut tail) = xc.split_at_col_mut(m);
        // [O r] of the chunk: into the whitening input when folded, else into X
        {
            let mut dst = if folded {
                wx.as_mut().subrows_mut(0, c * ny)
            } else {
                tail.rb_mut()
            };
            for i in 0..c * ny {
                if let Some(o) = free {
                    for j in 0..nx {
                        dst[(i, j)] = o[(t0 * ny + i, j)];
                    }
                }
                dst[(i, nx)] = r[t0 * ny + i];
            }
        }
        // the feature columns (evaluated, row-major and scaled) through the paths (W·T_i when
        // folded), the column parts in parallel, beside the previous chunk's Gram update
        let mut work = Vec::with_capacity(jobs.len());
        for job in jobs.iter_mut() {
            let w = job.stream.state().ncols();
            let (part, rest) = feat.split_at_col_mut(w);
            feat = rest;
            work.push((job, part));
        }
        let (maps_ref, sqrt_w_ref) = (&maps, &sqrt_w);
        let (pushed, ((), ())) = rayon::join(
            || {
                work.into_par_iter().try_for_each(|(job, out)| {
                    let w = out.ncols();
                    let (map, z) = &maps_ref[job.block];
                    let phi = &mut job.phi[..c * w];
                    map.eval_cols_prepared(
                        z,
                        t0,
                        job.first..job.first + w,
                        &sqrt_w_ref[job.block],
                        &prep[job.block][..c * plen[job.block]],
                        phi,
                    );
                    let rows = faer::MatRef::from_row_major_slice(phi, c, w);
                    job.stream.push(rows, out)
                })
            },
            || {
                rayon::join(
                    || {
                        if let Some((_, rows)) = pending {
                            let white = if white_in_wx { wx_prev } else { x_prev };
                            gram_update(&mut g_parts, white.as_ref(), rows);
                        }
                    },
                    || {
                        if let Some(&next) = schedule.get(ci + 1) {
                            prepare(prep_next, next);
                        }
                    },
                )
            },
        );
        pushed?;
        if let Some(mask) = held_out {
            // whole samples only (checked above), so zeroing before the per-sample static
            // whitening equals leaving the samples out
            let mut xc = x.as_mut().subrows_mut(0, c * ny);
            for i in 0..c * ny {
                if mask[t0 * ny + i] {
                    xc.rb_mut().row_mut(i).fill(0.0);
                }
            }
        }
        let mut xc = x.as_mut().subrows_mut(0, c * ny);
        match (&whitening, wstream.as_mut()) {
            (Whitening::Static { ls, .. }, _) => whiten_static(xc.rb_mut(), &ls.l(), ny),
            (Whitening::Kalman(_), Some(ws)) if folded => ws.push(
                wx.as_ref().subrows(0, c * ny),
                xc.rb_mut().subcols_mut(m, tail_cols),
            )?,
            (Whitening::Kalman(_), Some(ws)) => {
                ws.push(xc.rb(), wx.as_mut().subrows_mut(0, c * ny))?
            }
            (Whitening::Kalman(_), None) => unreachable!("a Kalman whitening has a stream"),
        }
        pending = Some((buf, c * ny));
        buf = 1 - buf;
        t0 += c;
        ci += 1;
    }
    if let Some((b, rows)) = pending {
        let white = if white_in_wx { &wxs[b] } else { &xs[b] };
        gram_update(&mut g_parts, white.as_ref(), rows);
    }
    let mut g = g_parts.pop().expect("at least one part");
    for gk in &g_parts {
        g += gk;
    }
    for j in 0..cols {
        for i in 0..j {
            g[(i, j)] = g[(j, i)];
        }
    }
    let t_assembled = Instant::now();
    Ok(FeatureGram {
        maps,
        dims,
        offsets,
        m,
        nx,
        g,
        whitening,
        chunk,
        t_prepared,
        t_assembled,
    })
}

/// Solves the problem in feature space; see the module documentation.
pub fn solve(problem: &Problem, settings: &IdentifySettings) -> Result<Identification> {
    let t_start = Instant::now();
    let beta = settings.beta();
    let len = problem.len();
    let ny = problem.outputs();
    let noise = problem.noise();
    let ne = noise.inputs();
    let r = problem.residual().as_slice();
    let free = problem.free_response();
    let gram = gram(problem, true, problem.held_out())?;
    let (maps, dims, offsets) = (&gram.maps, &gram.dims, &gram.offsets);
    let (m, nx, g, whitening) = (gram.m, gram.nx, &gram.g, &gram.whitening);
    let (chunk, t_prepared, t_assembled) = (gram.chunk, gram.t_prepared, gram.t_assembled);
    let cols = m + nx + 1;

    // --- ridge least squares in (b, x₀): (G_XX + L·β·[I 0; 0 0])·v = G_Xr --------------------
    let lb = len as f64 * beta;
    let k = m + nx;
    let mut h = nalgebra::DMatrix::<f64>::from_fn(k, k, |i, j| g[(i, j)]);
    for i in 0..m {
        h[(i, i)] += lb;
    }
    let rhs = nalgebra::DVector::<f64>::from_fn(k, |i, _| g[(i, k)]);
    // Directions of x₀ that do not reach y (a rate's memory of the previous output, with the
    // maps' outputs as parameters) make the x₀ block singular; a ridge of 10⁻¹⁰ of its largest
    // diagonal gives them their minimum-norm value 0 and leaves resolved directions as they are.
    let chol = match h.clone().cholesky() {
        Some(c) => c,
        None => {
            let scale = (m..k).map(|i| h[(i, i)]).fold(0.0f64, f64::max);
            let mut ridged = h.clone();
            for i in m..k {
                ridged[(i, i)] += 1e-10 * scale.max(f64::MIN_POSITIVE);
            }
            ridged.cholesky().ok_or_else(|| {
                Error::Numerical(
                    "the feature-space normal equations are singular: the initial state is not identifiable from this record"
                        .into(),
                )
            })?
        }
    };
    let v = chol.solve(&rhs);
    let t_factored = Instant::now();
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for i in 0..k {
        let dii = chol.l()[(i, i)];
        lo = lo.min(dii);
        hi = hi.max(dii);
    }

    // --- recover ŵ, ê, the maps and the cost terms -----------------------------------------
    // ‖W(r − X v)‖² = r'r − 2vᵀg + vᵀG_XX v, with G_XX without the ridge.
    let hv = &h * &v;
    let vgv = v.dot(&hv) - lb * (0..m).map(|i| v[i] * v[i]).sum::<f64>();
    let weighted_sse = (g[(k, k)] - 2.0 * v.dot(&rhs) + vgv).max(0.0);
    let mu = weighted_sse / len as f64;
    let x0: Option<Vec<f64>> = (nx > 0).then(|| (0..nx).map(|j| v[m + j]).collect());

    let mut parts = Vec::with_capacity(maps.len());
    for (bi, (map, z)) in maps.iter().enumerate() {
        let mi = dims[bi];
        let b_i: Vec<f64> = (0..mi).map(|j| v[offsets[bi] + j]).collect();
        let coef: Vec<f64> = b_i
            .iter()
            .zip(map.weights())
            .map(|(b, l)| b * l.sqrt())
            .collect();
        let mut w_hat = vec![0.0; len];
        w_hat
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(ci, out)| map.combine_rows(z, ci * CHUNK, &coef, out));
        parts.push(BlockPart {
            w_hat,
            // D_i = a_iᵀΛ⁻¹a_i = ‖b_i‖².
            dispersion_value: b_i.iter().map(|b| b * b).sum(),
            map: Box::new(FeatureExpansion::new(Arc::clone(map), coef)),
        });
    }
    // the single long signals by blocked recursions (the per-sample ones for other operators)
    let assembled = crate::solver::assemble_blocks_with(problem, parts, apply_long);
    let fitted = &assembled.fitted;
    // ρ = r − T_yw·ŵ − O·x₀; ê is the least-norm noise explaining it, ê = T_yeᵀ(T_ye·T_yeᵀ)⁻¹ρ.
    // Held-out samples have no equation, so their noise estimate is its prior mean, 0 (the
    // static whitening acts sample by sample): zero residual there.
    let held = problem.held_out();
    let rho: Vec<f64> = (0..len * ny)
        .map(|idx| {
            if held.is_some_and(|h| h[idx]) {
                return 0.0;
            }
            let ox: f64 = match (&x0, free) {
                (Some(x0), Some(o)) => (0..nx).map(|j| o[(idx, j)] * x0[j]).sum(),
                _ => 0.0,
            };
            r[idx] - fitted[idx] - ox
        })
        .collect();
    let mut e_hat = vec![0.0; len * ne];
    match &whitening {
        Whitening::Static { d, ls } => {
            let p_mat = d.transpose() * ls.inverse();
            for t in 0..len {
                let rt = &rho[t * ny..(t + 1) * ny];
                for c in 0..ne {
                    e_hat[t * ne + c] = (0..ny).map(|i| p_mat[(c, i)] * rt[i]).sum();
                }
            }
        }
        Whitening::Kalman(k) => {
            // Record by record: ê = T_yeᵀ·WᵀW·ρ with each record's own whitening.
            // Without a transient, W is its steady-state filter from rest, so the filter and the
            // noise path go through the recursions in minimal realisations (they carry each
            // other's states when both come from one model: order 5 where 1 is minimal).
            let mut w1 = vec![0.0; len * ny];
            let mut w2 = vec![0.0; len * ny];
            let ss = record_state_space(noise).map(|s| s.minimal_realisation());
            let filters: Vec<Option<structid_lti::StateSpace>> = k
                .whiteners
                .iter()
                .map(|kw| {
                    (kw.transient_len() == 0)
                        .then(|| kw.steady_state_filter().minimal_realisation())
                })
                .collect();
            for (i, w) in problem.record_bounds().windows(2).enumerate() {
                let (rows, ins) = (w[0] * ny..w[1] * ny, w[0] * ne..w[1] * ne);
                match &filters[k.of_record[i]] {
                    Some(f) => {
                        f.apply_long(&rho[rows.clone()], &mut w1[rows.clone()]);
                        f.apply_adjoint_long(&w1[rows.clone()], &mut w2[rows.clone()]);
                    }
                    None => {
                        let kr = k.of(i);
                        kr.whiten_long(&rho[rows.clone()], &mut w1[rows.clone()]);
                        kr.whiten_adjoint_long(&w1[rows.clone()], &mut w2[rows.clone()]);
                    }
                }
                match &ss {
                    Some(ss) => ss.apply_adjoint_long(&w2[rows], &mut e_hat[ins]),
                    None => noise.apply_adjoint(&w2[rows], &mut e_hat[ins]),
                }
            }
        }
    }
    let mut te = vec![0.0; len * ny];
    apply_long(noise, &e_hat, &mut te);
    let res2: f64 = rho.iter().zip(&te).map(|(a, b)| (a - b) * (a - b)).sum();
    let r2: f64 = r
        .iter()
        .enumerate()
        .filter(|(i, _)| !held.is_some_and(|h| h[*i]))
        .map(|(_, v)| v * v)
        .sum();
    let cost = cost_terms(mu, beta, &assembled)?;
    let mut warnings = Vec::new();
    let sqrt_w: Vec<Vec<f64>> = maps
        .iter()
        .map(|(f, _)| f.weights().iter().map(|l| l.sqrt()).collect())
        .collect();
    let observations = problem
        .held_out()
        .map_or(len * ny, |h| h.iter().filter(|&&x| !x).count());
    let posterior = settings
        .posterior()
        .then(|| {
            feature_posterior(
                &chol,
                maps,
                offsets,
                &sqrt_w,
                weighted_sse,
                lb,
                &v,
                m,
                observations,
                nx,
            )
        })
        .and_then(|p| {
            p.map_err(|why| warnings.push(format!("no uncertainty bands: {why}")))
                .ok()
        });
    let t_end = Instant::now();
    Ok(Identification {
        posterior,
        w_hat: assembled.w_hat,
        e_hat: Signal::new(ne, e_hat)?,
        blocks: assembled.blocks,
        cost,
        z_source: problem.z_source().clone(),
        initial_state: x0,
        diagnostics: Diagnostics {
            solver: crate::SolverKind::Features { features: m },
            system_size: k,
            dropped_samples: Vec::new(),
            dropped_max_abs_residual: 0.0,
            diagonal_jitter: 0.0,
            condition_lower_bound: super::condition_lower_bound(hi, lo),
            feasibility_residual: super::relative_residual(res2, r2),
            peak_memory_bytes: 8 * (cols * cols + 4 * chunk * ny * cols + chunk * m) as u64,
            timings: Timings::from_instants(t_start, t_prepared, t_assembled, t_factored, t_end),
            warnings,
            ..Diagnostics::default()
        },
    })
}

/// `y = T u` for one long signal: the blocked recursion of a minimal realisation for a
/// state-space operator (a path or noise model that shares one model's state vector carries
/// the other's states), the per-sample recursion otherwise.
fn apply_long(sys: &dyn LinearSystem, u: &[f64], y: &mut [f64]) {
    match sys.as_state_space() {
        Some(ss) => ss.minimal_realisation().apply_long(u, y),
        None => sys.apply(u, y),
    }
}

/// The posterior of the maps from the m-space factor the solve computed: s² from
/// min L·J = weighted SSE + L·β·|b|² (see [`crate::identify::posterior`]).
fn feature_posterior(
    chol: &nalgebra::Cholesky<f64, nalgebra::Dyn>,
    maps: &[(Arc<dyn FeatureMap>, Signal)],
    offsets: &[usize],
    sqrt_w: &[Vec<f64>],
    weighted_sse: f64,
    lb: f64,
    v: &nalgebra::DVector<f64>,
    m: usize,
    observations: usize,
    nx: usize,
) -> std::result::Result<Posterior, String> {
    let l = chol.l();
    let factor = Mat::<f64>::from_fn(l.nrows(), l.ncols(), |i, j| l[(i, j)]);
    let blocks = maps
        .iter()
        .zip(offsets)
        .zip(sqrt_w)
        .map(|(((map, z), &offset), sw)| FeaturePosteriorBlock {
            map: Arc::clone(map),
            offset,
            sqrt_weights: sw.clone(),
            inputs: z.channels(),
        })
        .collect();
    let b2: f64 = (0..m).map(|i| v[i] * v[i]).sum();
    Posterior::features(factor, blocks, weighted_sse + lb * b2, observations, nx)
}

/// How the solver whitens the noise.
enum Whitening {
    /// Static noise path: ω_t = L_S⁻¹·ν_t with S = D·Dᵀ = L_S·L_Sᵀ.
    Static {
        d: nalgebra::DMatrix<f64>,
        ls: nalgebra::Cholesky<f64, nalgebra::Dyn>,
    },
    /// Dynamic noise path: the Kalman filter of the noise system, restarted at every record.
    Kalman(Box<RecordWhiteners>),
}

/// The Kalman whitening of a dynamic noise path over each record from its own start: one
/// [`KalmanWhitener`] per distinct record length (their time-varying gains are the same from
/// a record's start; only the length differs).
struct RecordWhiteners {
    /// The whiteners, one per distinct record length, the longest first.
    whiteners: Vec<KalmanWhitener>,
    /// The whitener of each record (an index into `whiteners`).
    of_record: Vec<usize>,
}

impl RecordWhiteners {
    fn new(noise: &structid_lti::StateSpace, bounds: &[usize]) -> Result<Self> {
        let lens: Vec<usize> = bounds.windows(2).map(|w| w[1] - w[0]).collect();
        let mut distinct = lens.clone();
        distinct.sort_unstable_by(|a, b| b.cmp(a));
        distinct.dedup();
        let whiteners = distinct
            .iter()
            .map(|&l| KalmanWhitener::new(noise, l, &WhiteningOptions::default()))
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let of_record = lens
            .iter()
            .map(|l| distinct.iter().position(|d| d == l).unwrap_or(0))
            .collect();
        Ok(Self {
            whiteners,
            of_record,
        })
    }

    /// The whitener of record `r`.
    fn of(&self, r: usize) -> &KalmanWhitener {
        &self.whiteners[self.of_record[r]]
    }

    /// The whitener of the longest record.
    fn longest(&self) -> &KalmanWhitener {
        &self.whiteners[0]
    }

    /// Whether every whitener is an LTI filter from its first sample (no transient).
    fn without_transient(&self) -> bool {
        self.whiteners.iter().all(|k| k.transient_len() == 0)
    }

    /// ln det(T_ye·T_yeᵀ) of the block-diagonal noise covariance: the sum over the records.
    fn log_det(&self) -> f64 {
        self.of_record
            .iter()
            .map(|&i| self.whiteners[i].log_det())
            .sum()
    }
}

/// D of a static noise path, found by applying it to unit impulses.
pub(crate) fn static_gain(
    noise: &dyn LinearSystem,
    ny: usize,
    ne: usize,
) -> nalgebra::DMatrix<f64> {
    let mut d = nalgebra::DMatrix::zeros(ny, ne);
    let mut unit = vec![0.0; ne];
    let mut col = vec![0.0; ny];
    for c in 0..ne {
        unit.iter_mut().for_each(|v| *v = 0.0);
        unit[c] = 1.0;
        noise.apply(&unit, &mut col);
        for i in 0..ny {
            d[(i, c)] = col[i];
        }
    }
    d
}

/// X_t ← L_S⁻¹·X_t for every sample t (rows t·ny..(t+1)·ny), all columns.
fn whiten_static(mut x: MatMut<'_, f64>, l: &nalgebra::DMatrix<f64>, ny: usize) {
    let rows = x.nrows();
    let cols = x.ncols();
    if ny == 1 {
        let inv = 1.0 / l[(0, 0)];
        for j in 0..cols {
            x.rb_mut().col_mut(j).iter_mut().for_each(|v| *v *= inv);
        }
        return;
    }
    for j in 0..cols {
        for t in (0..rows).step_by(ny) {
            for i in 0..ny {
                let mut acc = x[(t + i, j)];
                for kk in 0..i {
                    acc -= l[(i, kk)] * x[(t + kk, j)];
                }
                x[(t + i, j)] = acc / l[(i, i)];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{PolynomialDispersion, ProblemBlock};
    use nalgebra::DMatrix;
    use structid_lti::StateSpace;

    /// The panel Gram update equals the dense product XᵀX on the lower triangle (diagonal
    /// included), for column counts around and between the panel boundaries.
    #[test]
    fn gram_lower_equals_the_dense_product_on_the_lower_triangle() {
        for (rows, cols) in [
            (1, 1),
            (7, 3),
            (50, 8),
            (33, 11),
            (64, 12),
            (100, 17),
            (2048, 65),
        ] {
            let x = Mat::<f64>::from_fn(rows, cols, |i, j| {
                ((i * 37 + j * 11) % 29) as f64 / 7.0 - 2.0 + (i as f64 * 0.1).sin()
            });
            let g0 = Mat::<f64>::from_fn(cols, cols, |i, j| (i + 2 * j) as f64 * 0.5);
            let mut g = g0.clone();
            gram_lower(g.as_mut(), x.as_ref());
            let dense = x.transpose() * &x;
            let scale = dense.norm_max().max(1.0);
            for j in 0..cols {
                for i in j..cols {
                    let want = g0[(i, j)] + dense[(i, j)];
                    assert!(
                        (g[(i, j)] - want).abs() <= 1e-12 * scale,
                        "{rows}×{cols}: ({i}, {j}) {} against {want}",
                        g[(i, j)]
                    );
                }
            }
        }
    }

    /// Found by the `lft_problem` fuzz target: a noise path with a huge (finite) entry in A
    /// whose whitening filter overflows; its spectral radius check panicked inside the SVD.
    #[test]
    fn an_overflowing_whitening_filter_is_an_error_not_a_panic() {
        let len = 5;
        let noise = StateSpace::new(
            DMatrix::from_column_slice(2, 2, &[-4.75, 1e300, 1.9375, -6.9375]),
            DMatrix::from_column_slice(2, 3, &[-0.3125, 6.875, -0.9375, 7.6875, -1.75, -2.75]),
            DMatrix::from_column_slice(3, 2, &[0.625, 5.6875, -2.8125, 3.125, -5.3125, -2.875]),
            DMatrix::from_column_slice(
                3,
                3,
                &[0.0, -5.875, -7.3125, 2.3125, -2.875, 0.1875, 1.0, 1.25, 1.0],
            ),
        )
        .unwrap();
        let block = ProblemBlock {
            name: "b0".into(),
            output: 0,
            path: Arc::new(StateSpace::static_gain(DMatrix::from_element(3, 1, 1.0)).unwrap()),
            z: Signal::from_fn(len, 1, |k, _| k as f64),
            dispersion: Arc::new(PolynomialDispersion::new(2).unwrap()),
        };
        let residual = Signal::from_fn(len, 3, |k, c| (k + c) as f64 / 4.0);
        let problem = Problem::new(residual, Arc::new(noise), vec![block]).unwrap();
        let settings = IdentifySettings::builder()
            .solver(crate::SolverChoice::Features)
            .beta(0.1)
            .build()
            .unwrap();
        let e = crate::identify_problem(&problem, &settings).unwrap_err();
        assert!(!e.to_string().is_empty());
        assert!(e.to_string().contains("overflow"), "{e}");
    }
}
