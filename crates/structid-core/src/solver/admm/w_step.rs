//! The w-step of ADMM: the quadratic subproblem in w, solved through the realisation's
//! channels and the quadratic blocks' factors.

use super::*;

/// The realisation channels of the blocks and the quadratic blocks' factors.
pub(super) struct Channels<'a> {
    /// The w channels of the total-variation blocks.
    pub(super) tv: &'a [usize],
    /// The w channels of the quadratic blocks.
    pub(super) quadratic: &'a [usize],
    /// The quadratic blocks' factors Ψ̃ (w = Ψ̃·η, D = ‖η‖²).
    pub(super) factors: &'a [QuadraticFactor],
    /// The samples whose outputs are held out (cross-validation), when any.
    pub(super) missing: Option<&'a [bool]>,
    /// Where each record starts, then L ([`Problem::record_bounds`]).
    pub(super) bounds: &'a [usize],
}

/// The quadratic blocks' factors, with a rank limit from the memory budget.
pub(super) fn quadratic_factors(
    problem: &Problem,
    quadratic: &[(Box<dyn QuadraticPenalty>, usize)],
    nb: usize,
    settings: &IdentifySettings,
) -> Result<Vec<QuadraticFactor>> {
    if quadratic.is_empty() {
        return Ok(Vec::new());
    }
    let len = problem.len().max(1);
    // Per column of a factor: Ψ̃ itself and the responses of the n_b total-variation channels
    // (8 bytes each, per sample), for every quadratic block.
    let per_column = 8 * (len as u64) * (1 + nb as u64) * quadratic.len() as u64;
    let budget = settings.effective_memory_limit() / 2;
    let max_rank = ((budget / per_column.max(1)) as usize).min(MAX_RANK);
    let mut factors = Vec::with_capacity(quadratic.len());
    for (pen, bi) in quadratic {
        let block = &problem.blocks()[*bi];
        if max_rank == 0 {
            return Err(Error::TooLarge {
                solver: NAME.into(),
                needed_mib: per_column >> 20,
                limit_mib: settings.effective_memory_limit() >> 20,
                size: problem.len() * problem.outputs(),
                suggestion: format!(
                    "even one column of the factor of quadratic block `{}` does not fit; raise the memory \
                     limit or shorten the record",
                    block.name
                ),
            });
        }
        factors.push(QuadraticFactor::new(
            pen.as_ref(),
            &block.z,
            max_rank,
            &block.name,
        )?);
    }
    Ok(factors)
}

/// Largest rank of a quadratic block's factor (each column costs one smoother pass per value
/// of ρ and O(L) per iteration).
pub(super) const MAX_RANK: usize = 2048;

/// The w-step with its linear parameters solved exactly: the total-variation blocks' constant
/// offsets and the quadratic blocks' coefficients.
///
/// Total variation does not see constants, so the problem is unchanged when w = S·d + E·c with
/// free offsets c ∈ ℝ^(n_b) (E: c_i on every sample of block i) and the ADMM constraint applies
/// to w − E·c only. A quadratic block is w_q = Ψ̃·η with the penalty β·‖η‖²
/// ([`QuadraticFactor`]). Both kinds of parameter p = (c, η) enter the smoother through its prior
/// mean: the offsets on the total-variation channels, Ψ̃·η on the quadratic channels, which have
/// variance 0 (fixed at their mean) and are *adjoint channels* of the smoother
/// ([`DisturbanceSmoother::with_adjoint`]): their output is the sensitivity g = T_qᵀS⁺δ of the
/// w-step's cost to them (δ = r − T·mean, S = T·Q·Tᵀ). The smoother being linear in its mean,
/// with M_j the mean of the unit parameter j, the cost ½δᵀS⁺δ + β‖η‖² is quadratic in p and
/// stationary where H·p = b with b_j = M_jᵀ·Tᵀ S⁺ δ₀ (from the smoother's output for p = 0:
/// ρ·(w − m) on the total-variation channels, g on the quadratic ones) and
/// H_ij = M_iᵀTᵀS⁺T·M_j + 2β·[i = j ∈ η] (from one smoother pass per parameter, once per ρ).
/// The smoother's output for p is that for 0 minus Σ_j p_j·R_j, with R_j = Q·TᵀS⁺T·M_j on the
/// total-variation channels (stored, L·n_b per parameter).
///
/// H is solved by eliminating η (its block is at least 2β·I, positive definite) and taking
/// the pseudo-inverse of the offsets' Schur complement: constants the data do not see at all
/// (e.g. with a free initial state) get the minimum-norm c.
///
/// Without the offsets, a constant combination that the data see only weakly — (f + c, g − c)
/// when two blocks read the same z into one output, seen only through the first samples from
/// rest — has a curvature of order 1/L² against ρ ~ 1/L, and ADMM drifts along it by a fraction
/// ~ 1/L per iteration.
pub(super) struct WStep {
    pub(super) smoother: RecordSmoother,
    /// R per sample: entry (k·n_b + i)·P + j is the response on total-variation channel i to
    /// the unit parameter j.
    pub(super) resp: Vec<f64>,
    /// The solution map p = G·b (P × P, row-major).
    pub(super) g: Vec<f64>,
    /// n_b.
    pub(super) nb: usize,
    /// P = n_b + Σ rank.
    pub(super) np: usize,
    pub(super) rho: f64,
}

impl WStep {
    pub(super) fn new(
        ss: &StateSpace,
        variances: &[f64],
        ch: &Channels<'_>,
        len: usize,
        initial: SmootherInitial,
        beta: f64,
        rho: f64,
    ) -> Result<Self> {
        let smoother =
            RecordSmoother::new(ss, variances, ch.bounds, initial, ch.quadratic, ch.missing)?;
        let nb = ch.tv.len();
        let nq: usize = ch.factors.iter().map(|f| f.rank).sum();
        let np = nb + nq;
        let nin = variances.len();
        let zero = Signal::zeros(len, ss.outputs());
        let mut resp = vec![0.0; len * nb * np];
        let mut h = nalgebra::DMatrix::<f64>::zeros(np, np);
        // Parameter j: an offset (channel) or column l of a factor on its channel.
        let params: Vec<(usize, Option<(&QuadraticFactor, usize)>)> = ch
            .tv
            .iter()
            .map(|&c| (c, None))
            .chain(
                ch.factors
                    .iter()
                    .zip(ch.quadratic)
                    .flat_map(|(f, &c)| (0..f.rank).map(move |l| (c, Some((f, l))))),
            )
            .collect();
        // One smoother pass per parameter (independent: in parallel, each bit-identical to
        // a sequential run): the responses on the total-variation channels and the
        // sensitivities on the quadratic ones.
        let nqb = ch.quadratic.len();
        let passes: Vec<(Vec<f64>, Vec<f64>)> = params
            .par_iter()
            .map(|&(col, factor)| -> Result<(Vec<f64>, Vec<f64>)> {
                // The mean −M_j: the smoother's output minus it is Q·TᵀS⁺T·M_j.
                let mut unit = Signal::zeros(len, nin);
                let mut out = Signal::zeros(len, nin);
                for k in 0..len {
                    unit.sample_mut(k)[col] = match factor {
                        None => -1.0,
                        Some((f, l)) => -f.rows[k * f.rank + l],
                    };
                }
                smoother.smooth(&zero, &unit, &mut out)?;
                let diff = |k: usize, c: usize| out.get(k, c) - unit.get(k, c);
                let tv: Vec<f64> = (0..len)
                    .flat_map(|k| ch.tv.iter().map(move |&c| (k, c)))
                    .map(|(k, c)| diff(k, c))
                    .collect();
                let adj: Vec<f64> = (0..len)
                    .flat_map(|k| ch.quadratic.iter().map(move |&c| (k, c)))
                    .map(|(k, c)| diff(k, c))
                    .collect();
                Ok((tv, adj))
            })
            .collect::<Result<_>>()?;
        for (j, (tv, _)) in passes.iter().enumerate() {
            for k in 0..len {
                for i in 0..nb {
                    let v = tv[k * nb + i];
                    resp[(k * nb + i) * np + j] = v;
                    h[(i, j)] += rho * v;
                }
            }
        }
        // The quadratic blocks' rows: Ψ̃_bᵀ·A_b with A_b (L × P) the sensitivities on the
        // block's channel, one product per block (sequential: bit-identical at any thread count).
        let mut at = nb;
        for (b, f) in ch.factors.iter().enumerate() {
            if f.rank == 0 {
                continue;
            }
            let a = faer::Mat::<f64>::from_fn(len, np, |k, j| passes[j].1[k * nqb + b]);
            let psi = faer::MatRef::from_row_major_slice(&f.rows, len, f.rank);
            let mut dst = faer::Mat::<f64>::zeros(f.rank, np);
            faer::linalg::matmul::matmul(
                dst.as_mut(),
                faer::Accum::Replace,
                psi.transpose(),
                a.as_ref(),
                1.0,
                faer::Par::Seq,
            );
            for l in 0..f.rank {
                for j in 0..np {
                    h[(at + l, j)] = dst[(l, j)];
                }
            }
            at += f.rank;
        }
        for i in nb..np {
            h[(i, i)] += 2.0 * beta;
        }
        let h = (&h + h.transpose()) * 0.5;
        let g = solution_map(&h, nb, len, rho);
        Ok(Self {
            smoother,
            resp,
            g,
            nb,
            np,
            rho,
        })
    }

    /// The number of parameters P (offsets, then the quadratic blocks' coefficients).
    pub(super) fn parameters(&self) -> usize {
        self.np
    }

    /// The w-step for prior mean `mean` (on the total-variation channels: d − u; zero on the
    /// quadratic ones): writes w − E·c into the total-variation channels of `out` (the other
    /// channels keep the smoother's output for p = 0, unused) and the parameters into `p`.
    pub(super) fn solve(
        &self,
        r: &Signal,
        mean: &Signal,
        out: &mut Signal,
        p: &mut [f64],
        ch: &Channels<'_>,
    ) -> Result<()> {
        self.smoother.smooth(r, mean, out)?;
        let (nb, np) = (self.nb, self.np);
        let mut b = vec![0.0; np];
        gather(out, mean, ch, self.rho, &mut b);
        for (i, pi) in p.iter_mut().enumerate() {
            *pi = self.g[i * np..(i + 1) * np]
                .iter()
                .zip(&b)
                .map(|(g, b)| g * b)
                .sum();
        }
        for k in 0..out.len() {
            let o = out.sample_mut(k);
            let rows = &self.resp[k * nb * np..(k + 1) * nb * np];
            for (i, &col) in ch.tv.iter().enumerate() {
                let row = &rows[i * np..(i + 1) * np];
                o[col] -= row.iter().zip(p.iter()).map(|(a, b)| a * b).sum::<f64>();
            }
        }
        Ok(())
    }
}

/// b_j = M_jᵀ·TᵀS⁺δ from a smoother output `out` for the mean `mean`: ρ times the block sums
/// of out − mean on the total-variation channels, Ψ̃ᵀ(out − mean) on the quadratic (adjoint)
/// channels.
pub(super) fn gather(out: &Signal, mean: &Signal, ch: &Channels<'_>, rho: f64, b: &mut [f64]) {
    let nb = ch.tv.len();
    b.iter_mut().for_each(|v| *v = 0.0);
    let len = out.len();
    for k in 0..len {
        let (o, m) = (out.sample(k), mean.sample(k));
        for (bi, &col) in b[..nb].iter_mut().zip(ch.tv) {
            *bi += o[col] - m[col];
        }
        let mut at = nb;
        for (f, &col) in ch.factors.iter().zip(ch.quadratic) {
            let g = o[col] - m[col];
            let row = &f.rows[k * f.rank..(k + 1) * f.rank];
            for (bj, psi) in b[at..at + f.rank].iter_mut().zip(row) {
                *bj += psi * g;
            }
            at += f.rank;
        }
    }
    b[..nb].iter_mut().for_each(|v| *v *= rho);
}

/// The map p = G·b solving H·p = b: η eliminated through the Cholesky factor of its block
/// (≥ 2β·I), the offsets through the pseudo-inverse of their Schur complement, whose
/// eigenvalues below a relative 1e-10 (of max(L, λ_max) after dividing by ρ: the entries of the
/// offsets' block are at most ρ·L) count as directions the data do not see.
pub(super) fn solution_map(
    h: &nalgebra::DMatrix<f64>,
    nb: usize,
    len: usize,
    rho: f64,
) -> Vec<f64> {
    use nalgebra::DMatrix;
    let np = h.nrows();
    let nq = np - nb;
    let hcc = h.view((0, 0), (nb, nb)).into_owned();
    let hcq = h.view((0, nb), (nb, nq)).into_owned();
    let hqq = h.view((nb, nb), (nq, nq)).into_owned();
    // H_ηη⁻¹ (symmetric positive definite; eigen-decomposition as a fallback).
    let hqq_inv = match hqq.clone().cholesky() {
        Some(c) => c.inverse(),
        None => pinv_sym(&hqq, 0.0),
    };
    // X = H_ηη⁻¹·H_ηc, Schur complement S = H_cc − H_cη·X.
    let x = &hqq_inv * hcq.transpose();
    let schur = &hcc - &hcq * &x;
    let schur = (&schur + schur.transpose()) * 0.5;
    let k = &schur / rho;
    let eig_max = k.clone().symmetric_eigen().eigenvalues.amax();
    let s_inv = pinv_sym(&k, 1e-10 * (len as f64).max(eig_max)) / rho;
    let mut g = DMatrix::<f64>::zeros(np, np);
    g.view_mut((0, 0), (nb, nb)).copy_from(&s_inv);
    let sx = &s_inv * x.transpose();
    g.view_mut((0, nb), (nb, nq)).copy_from(&(-&sx));
    g.view_mut((nb, 0), (nq, nb)).copy_from(&(-sx.transpose()));
    g.view_mut((nb, nb), (nq, nq))
        .copy_from(&(&hqq_inv + &x * &sx));
    g.transpose().as_slice().to_vec()
}

/// The pseudo-inverse of a symmetric matrix, eigenvalues at or below `cut` left out.
pub(super) fn pinv_sym(a: &nalgebra::DMatrix<f64>, cut: f64) -> nalgebra::DMatrix<f64> {
    let n = a.nrows();
    let eig = a.clone().symmetric_eigen();
    let mut out = nalgebra::DMatrix::<f64>::zeros(n, n);
    for (l, &lam) in eig.eigenvalues.iter().enumerate() {
        if lam > cut {
            let v = eig.eigenvectors.column(l);
            out += (v * v.transpose()) / lam;
        }
    }
    out
}
