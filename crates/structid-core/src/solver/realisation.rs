//! One state-space realisation of the (e, w) → y paths, for the solvers that work with states
//! (the conic program's sparse constraints, the Kalman smoother inside ADMM).

use nalgebra::DMatrix;
use structid_lti::StateSpace;

use crate::error::{Error, Result};
use crate::identify::problem::Problem;

/// x_{k+1} = A·x_k + B·[e_k; w_k], r_k = C·x_k + D·[e_k; w_k] (+ the free response of x₀).
pub(crate) struct Realisation {
    /// Inputs: the n_e noise channels, then one w channel per block in output order.
    pub ss: StateSpace,
    /// n_e.
    pub noise_inputs: usize,
    /// Whether x₀ is free (the problem estimates the initial state).
    pub free_initial_state: bool,
}

/// The LFT's realisation when the problem came from a model; otherwise the parallel connection
/// of the operators' own realisations.
pub(crate) fn joint_realisation(problem: &Problem, solver: &str) -> Result<Realisation> {
    let ne = problem.noise().inputs();
    if let Some((ss, is_state)) = problem.shared_realisation() {
        if problem.free_response().is_some() && !is_state {
            return Err(unsupported_free(solver));
        }
        return Ok(Realisation {
            ss: ss.clone(),
            noise_inputs: ne,
            free_initial_state: problem.free_response().is_some(),
        });
    }
    if problem.free_response().is_some() {
        return Err(unsupported_free(solver));
    }
    let mut parts: Vec<&StateSpace> = Vec::with_capacity(problem.blocks().len() + 1);
    let missing = |what: &str| {
        Error::Unsupported(format!(
            "the {solver} solver needs a state-space realisation of {what}; pose the problem from an LFT model or \
             with StateSpace operators"
        ))
    };
    parts.push(
        problem
            .noise()
            .as_state_space()
            .ok_or_else(|| missing("T_ye"))?,
    );
    let mut blocks: Vec<_> = problem.blocks().iter().collect();
    blocks.sort_by_key(|b| b.output);
    for b in blocks {
        parts.push(
            b.path
                .as_state_space()
                .ok_or_else(|| missing(&format!("the path of block `{}`", b.name)))?,
        );
    }
    let n: usize = parts.iter().map(|s| s.order()).sum();
    let m: usize = parts.iter().map(|s| s.inputs()).sum();
    let p = problem.outputs();
    let (mut a, mut b) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
    let (mut c, mut d) = (DMatrix::zeros(p, n), DMatrix::zeros(p, m));
    let (mut i, mut j) = (0, 0);
    for s in parts {
        let (ni, mi) = (s.order(), s.inputs());
        a.view_mut((i, i), (ni, ni)).copy_from(s.a());
        b.view_mut((i, j), (ni, mi)).copy_from(s.b());
        c.view_mut((0, i), (p, ni)).copy_from(s.c());
        d.view_mut((0, j), (p, mi)).copy_from(s.d());
        i += ni;
        j += mi;
    }
    Ok(Realisation {
        ss: StateSpace::new(a, b, c, d)?,
        noise_inputs: ne,
        free_initial_state: false,
    })
}

fn unsupported_free(solver: &str) -> Error {
    Error::Unsupported(format!(
        "the {solver} solver estimates the initial state as the state of the LFT; build the problem with \
         Problem::from_model_with_initial_state (or identify with InitialState::Estimate) rather than a \
         custom free-response matrix"
    ))
}

/// [`unreachable_samples`] of every record, each from its own start (`bounds` as
/// [`Problem::record_bounds`]).
pub(crate) fn unreachable_samples_of_records(
    real: &Realisation,
    bounds: &[usize],
) -> Vec<(usize, usize)> {
    let longest = bounds.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    let first = unreachable_samples(real, longest);
    bounds
        .windows(2)
        .flat_map(|w| {
            first
                .iter()
                .filter(move |&&(k, _)| k < w[1] - w[0])
                .map(move |&(k, ch)| (w[0] + k, ch))
        })
        .collect()
}

/// The output samples (k, channel) that depend on neither e, w nor (when free) x₀: their
/// equations read 0 = r_k and are left out of the solve, as in the exact solver.
pub(crate) fn unreachable_samples(real: &Realisation, len: usize) -> Vec<(usize, usize)> {
    let ss = &real.ss;
    let (n, p) = (ss.order(), ss.outputs());
    let tol = 1e-14 * (1.0 + ss.a().amax() + ss.b().amax() + ss.c().amax() + ss.d().amax());
    let markov = ss.markov_parameters(n + 1);
    // Reachability through the inputs is monotone: from the first non-zero Markov row on.
    let lead: Vec<usize> = (0..p)
        .map(|ch| {
            (0..=n)
                .find(|&k| markov[k].row(ch).amax() > tol)
                .unwrap_or(usize::MAX)
        })
        .collect();
    let horizon = lead.iter().copied().max().unwrap_or(0).min(len);
    let mut out = Vec::new();
    let mut cak = ss.c().clone();
    for k in 0..horizon {
        for ch in 0..p {
            let by_state = real.free_initial_state && n > 0 && cak.row(ch).amax() > tol;
            if k < lead[ch] && !by_state {
                out.push((k, ch));
            }
        }
        if n > 0 {
            cak = &cak * ss.a();
        }
    }
    out
}
