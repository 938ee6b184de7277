//! The total-variation blocks' view of the realisation: the samples each block sees, and the
//! smoother of each record.

use super::*;

/// A total-variation block as ADMM iterates it.
///
/// The samples are sorted by node (a counting sort, stable in time): `order` holds the sample
/// of each sorted position and `sorted_node` its node. When samples are held out at the end of
/// the record (or, with several records, at the end of every record), their w reaches no
/// output that is kept, and a node with only such samples is
/// set by the total variation alone: its value is not unique (any value between its chain
/// neighbours costs the same) and ADMM would creep along it at a sublinear rate. A chain then
/// leaves those nodes out: a run of them between kept nodes a and b becomes one edge of weight
/// min c over the run (the least total variation that joins a to b through it), and after the
/// iteration [`TvView::expand`] fills the run with an exact minimiser: linear in z from a's
/// value to b's when the run's weights are equal (every monotone fill is then optimal, and this
/// one is the map's own piecewise-linear interpolation between a and b), else a's and b's
/// values with the jump at the cheapest edge; runs at an end of the chain take the value of
/// their one neighbour. Graphs (p > 1) keep every node.
pub(super) struct TvView {
    pub(super) order: Vec<usize>,
    pub(super) sorted_node: Vec<usize>,
    /// Nodes iterated.
    pub(super) nodes: usize,
    /// Samples per node iterated.
    pub(super) counts: Vec<f64>,
    /// Chain edge weights between consecutive nodes iterated.
    pub(super) weights: Vec<f64>,
    /// For a reduced chain: the iterated node of each chain node (`None`: left out), the
    /// chain's own weights and the first coordinate of z at each chain node.
    pub(super) reduced: Option<ReducedChain>,
}

/// See [`TvView::reduced`].
type ReducedChain = (Vec<Option<usize>>, Vec<f64>, Vec<f64>);

impl TvView {
    pub(super) fn new(p: &TvPenalty, z: &Signal, visible: Option<Vec<bool>>) -> Self {
        let full_weights: Vec<f64> = p.edges().iter().map(|e| e.2).collect();
        let nodes_of = p.node_of_sample();
        let mut seen = vec![false; p.nodes()];
        if let Some(vis) = &visible {
            for (k, &g) in nodes_of.iter().enumerate() {
                seen[g] |= vis[k];
            }
        }
        let reduce = p.is_chain() && visible.is_some() && seen.iter().any(|&s| !s);
        let (map, nodes, weights) = if reduce {
            let mut map = vec![None; p.nodes()];
            let mut weights = Vec::new();
            let mut next = 0usize;
            let mut run_min = f64::INFINITY;
            for g in 0..p.nodes() {
                if seen[g] {
                    if next > 0 {
                        weights.push(run_min);
                    }
                    map[g] = Some(next);
                    next += 1;
                    run_min = f64::INFINITY;
                }
                if g + 1 < p.nodes() {
                    run_min = run_min.min(full_weights[g]);
                }
            }
            (Some(map), next, weights)
        } else {
            (None, p.nodes(), full_weights.clone())
        };
        let node = |k: usize| match &map {
            Some(m) => m[nodes_of[k]],
            None => Some(nodes_of[k]),
        };
        let mut start = vec![0usize; nodes + 1];
        for k in 0..nodes_of.len() {
            if let Some(g) = node(k) {
                start[g + 1] += 1;
            }
        }
        let counts: Vec<f64> = start[1..].iter().map(|&c| c as f64).collect();
        for g in 0..nodes {
            start[g + 1] += start[g];
        }
        let mut order = vec![0usize; start[nodes]];
        let mut sorted_node = vec![0usize; start[nodes]];
        for k in 0..nodes_of.len() {
            if let Some(g) = node(k) {
                order[start[g]] = k;
                sorted_node[start[g]] = g;
                start[g] += 1;
            }
        }
        Self {
            order,
            sorted_node,
            nodes,
            counts,
            weights,
            reduced: map.map(|m| {
                let mut knots = vec![0.0; p.nodes()];
                for (k, &g) in nodes_of.iter().enumerate() {
                    knots[g] = z.sample(k).first().copied().unwrap_or(0.0);
                }
                (m, full_weights, knots)
            }),
        }
    }

    /// The values of every chain node from those iterated (see the type's documentation).
    pub(super) fn expand(&self, d: Vec<f64>) -> Vec<f64> {
        let Some((map, weights, knots)) = &self.reduced else {
            return d;
        };
        let full = map.len();
        let mut out = vec![0.0; full];
        let kept: Vec<usize> = (0..full).filter(|&g| map[g].is_some()).collect();
        let value = |g: usize| map[g].map_or(0.0, |r| d[r]);
        let (Some(&first), Some(&last)) = (kept.first(), kept.last()) else {
            return out;
        };
        for g in 0..=first {
            out[g] = value(first);
        }
        for g in last..full {
            out[g] = value(last);
        }
        for pair in kept.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let (va, vb) = (value(a), value(b));
            let (lo, hi) = weights[a..b]
                .iter()
                .fold((f64::INFINITY, 0.0f64), |(l, h), &w| (l.min(w), h.max(w)));
            let span = knots[b] - knots[a];
            if hi <= lo * (1.0 + 1e-12) && span.is_finite() && span != 0.0 {
                for g in a..=b {
                    out[g] = va + (vb - va) * (knots[g] - knots[a]) / span;
                }
            } else {
                // The cheapest edge (g, g + 1) of the run: a's value up to g, b's after.
                let cut = (a..b)
                    .min_by(|&x, &y| weights[x].total_cmp(&weights[y]))
                    .unwrap_or(a);
                for g in a..=cut {
                    out[g] = va;
                }
                for g in cut + 1..=b {
                    out[g] = vb;
                }
            }
        }
        out
    }
}

/// The samples whose map value (w channel `col`) reaches an output that is kept, when samples
/// are held out or there are several records: sample k of a record is seen unless k + l₀ is
/// past the last kept sample of its record (each record restarts from its own state, so
/// nothing carries over into the next), l₀ the first non-zero Markov parameter of the
/// channel. With several records the last l₀ samples of every record are unseen even without
/// held-out samples. `None` for one record without held-out samples (every sample but the
/// last l₀ is seen, and those few are left to the iteration as before).
pub(super) fn visible_samples(
    real: &Realisation,
    col: usize,
    missing: Option<&[bool]>,
    bounds: &[usize],
) -> Option<Vec<bool>> {
    if missing.is_none() && bounds.len() <= 2 {
        return None;
    }
    if let Some(m) = missing {
        m.iter().rposition(|&m| !m)?;
    }
    let held = |k: usize| missing.is_some_and(|m| m[k]);
    let ss = &real.ss;
    let n = ss.order();
    let tol = 1e-14 * (1.0 + ss.a().amax() + ss.b().amax() + ss.c().amax() + ss.d().amax());
    let markov = ss.markov_parameters(n + 1);
    let lead = (0..=n)
        .find(|&l| markov[l].column(col).amax() > tol)
        .unwrap_or(usize::MAX);
    let mut visible = Vec::with_capacity(*bounds.last().unwrap_or(&0));
    for w in bounds.windows(2) {
        let last_kept = (w[0]..w[1]).rposition(|k| !held(k));
        visible.extend(
            (0..w[1] - w[0]).map(|k| last_kept.is_some_and(|last| k.saturating_add(lead) <= last)),
        );
    }
    Some(visible)
}

/// The disturbance smoother over every record, each from its own initial state (zero, or
/// free with one x₀ per record): one [`DisturbanceSmoother`] per record, over its own
/// samples and held-out mask. With one record it is that smoother on the whole signals, with
/// no copies.
pub(super) struct RecordSmoother {
    /// The record bounds `[0, L₁, …, L]`.
    pub(super) bounds: Vec<usize>,
    /// The smoother of each record.
    pub(super) parts: Vec<DisturbanceSmoother>,
}

impl RecordSmoother {
    pub(super) fn new(
        ss: &StateSpace,
        variances: &[f64],
        bounds: &[usize],
        initial: SmootherInitial,
        adjoint: &[usize],
        missing: Option<&[bool]>,
    ) -> Result<Self> {
        let parts = bounds
            .windows(2)
            .map(|w| {
                let len = w[1] - w[0];
                Ok(match missing {
                    Some(m) => DisturbanceSmoother::with_missing(
                        ss,
                        variances,
                        len,
                        initial,
                        adjoint,
                        &m[w[0]..w[1]],
                    )?,
                    None => {
                        DisturbanceSmoother::with_adjoint(ss, variances, len, initial, adjoint)?
                    }
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            bounds: bounds.to_vec(),
            parts,
        })
    }

    /// Smooths every record ([`DisturbanceSmoother::smooth`] on its samples of `y`, `mean`
    /// and `out`) and returns the estimated initial states, record after record, for a free
    /// initial state.
    pub(super) fn smooth(
        &self,
        y: &Signal,
        mean: &Signal,
        out: &mut Signal,
    ) -> Result<Option<Vec<f64>>> {
        if let [one] = &self.parts[..] {
            return Ok(one.smooth(y, mean, out)?.initial_state);
        }
        let (ny, nin) = (y.channels(), mean.channels());
        let slice = |s: &Signal, ch: usize, w: &[usize]| {
            Signal::new(ch, s.as_slice()[w[0] * ch..w[1] * ch].to_vec())
        };
        // The records are independent: smoothed in parallel, each bit-identical to a
        // sequential run.
        let results: Vec<(Signal, Option<Vec<f64>>)> = self
            .parts
            .par_iter()
            .zip(self.bounds.par_windows(2))
            .map(|(sm, w)| -> Result<(Signal, Option<Vec<f64>>)> {
                let (yr, mr) = (slice(y, ny, w)?, slice(mean, nin, w)?);
                let mut o = Signal::zeros(w[1] - w[0], nin);
                let report = sm.smooth(&yr, &mr, &mut o)?;
                Ok((o, report.initial_state))
            })
            .collect::<Result<_>>()?;
        let mut x0: Option<Vec<f64>> = None;
        let dst = out.as_mut_slice();
        for ((o, x), w) in results.into_iter().zip(self.bounds.windows(2)) {
            dst[w[0] * nin..w[1] * nin].copy_from_slice(o.as_slice());
            if let Some(x) = x {
                x0.get_or_insert_with(Vec::new).extend(x);
            }
        }
        Ok(x0)
    }

    /// The samples with stored gains, over every record.
    pub(super) fn transient_len(&self) -> usize {
        self.parts.iter().map(|s| s.transient_len()).sum()
    }
}
