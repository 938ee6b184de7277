//! The noise level of a residual, model-free: σ̂ from first differences (robust to a slow
//! model error), the coloured-noise fit of the robust semivariogram, the quantisation floor of
//! a signal, and the lattice of a quantised output. The gap test compares a model's residual
//! with these.

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// σ̂ = MAD(Δε)/(0.6745·√2).
///
/// ```
/// use structid_discover::gap::noise_level;
/// // A slow model error of amplitude 1 barely counts as noise.
/// let e: Vec<f64> = (0..1000).map(|k| (k as f64 * 0.01).sin()).collect();
/// assert!(noise_level(&e) < 0.01);
/// ```
pub fn noise_level(residual: &[f64]) -> f64 {
    noise_level_records(&[residual])
}

/// [`noise_level`] of a residual in several records (`parts`, one slice per record): the
/// first differences are taken within each record, never across a record boundary.
///
/// ```
/// use structid_discover::gap::{noise_level, noise_level_records};
/// let a: Vec<f64> = (0..500).map(|k| (k as f64 * 0.01).sin()).collect();
/// let b: Vec<f64> = a.iter().map(|v| v + 100.0).collect();
/// // The jump of 100 between the records is no difference of either.
/// let both = noise_level_records(&[&a, &b]);
/// assert!((both - noise_level(&a)).abs() < 1e-12);
/// ```
pub fn noise_level_records(parts: &[&[f64]]) -> f64 {
    let d = lag_differences(parts, 1);
    let m = median(d.clone());
    let mad = median(d.iter().map(|v| (v - m).abs()).collect());
    mad / (0.674_489_75 * std::f64::consts::SQRT_2)
}

/// A noise level that allows for coloured noise and a slow model error in a residual: see
/// [`noise_level_coloured`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct NoiseFit {
    /// σ̂: the standard deviation of the noise itself (of the coloured process, not of its
    /// innovations).
    pub std: f64,
    /// φ̂: the noise's correlation decays as φ̂^k over k samples (0 for white noise).
    pub colour: f64,
    /// ĉ: the slow part's contribution to the semivariogram grows as ĉ·k².
    pub drift: f64,
}

/// Largest lag of the semivariogram [`noise_level_coloured`] fits: short, so that the slow
/// part of a model error (a plant-filtered signal, whose variogram saturates within a few
/// tens of samples, like coloured noise's) adds little; the AR(1) shape carries σ² beyond it.
const VARIOGRAM_LAGS: usize = 10;

/// Largest φ̂ of [`noise_level_coloured`], in percent: a "noise" correlated over more than
/// twenty samples is a slow disturbance, which a model (or its windows) has to explain, and
/// a model error's variogram would otherwise be read as such a noise.
const MAX_COLOUR_PERCENT: usize = 95;

/// σ̂ of a residual r = e + m that holds noise e (white or coloured) and a slow model error m,
/// from its robust semivariogram.
///
/// γ(k) = ½·E[(r_{t+k} − r_t)²] is estimated robustly for k = 1…10 as ½·(MAD(Δ_k r)/0.6745)²
/// (a few jumps, e.g. at the seams of a windowed simulation, do not count), and fitted by
/// γ(k) = σ²·(1 − φ^k) + c·k² with σ², c ≥ 0 and φ ∈ [0, 0.95] (relative least squares, φ on
/// a grid, σ² and c linear): the noise's part saturates at σ² once its correlation φ^k has
/// died out, while a slow error (locally a ramp, m_{t+k} − m_t ≈ ṁ·k) grows as k². White
/// noise gives φ̂ = 0 and σ̂ = the first-difference estimate of [`noise_level`]; AR(1) noise
/// e_k = φ·e_{k−1} + η_k is fitted exactly, where [`noise_level`] would return σ·√(1 − φ).
/// A model error that changes as fast as the noise cannot be told from it: the residual
/// should be that of the best model at hand.
///
/// ```
/// use structid_discover::gap::noise_level_coloured;
/// // AR(1) noise with φ = 0.8 and std 1 (a deterministic pseudo-random sequence).
/// let mut state = 12345u64;
/// let mut uniform = || {
///     state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
///     (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
/// };
/// let mut e = 0.0;
/// let r: Vec<f64> = (0..20000)
///     .map(|_| {
///         // a sum of 12 uniforms is nearly Gaussian with variance 1
///         let eta: f64 = (0..12).map(|_| uniform()).sum();
///         e = 0.8 * e + 0.6 * eta;
///         e
///     })
///     .collect();
/// let fit = noise_level_coloured(&r);
/// assert!((fit.std - 1.0).abs() < 0.1, "{fit:?}");
/// assert!((fit.colour - 0.8).abs() < 0.1, "{fit:?}");
/// ```
pub fn noise_level_coloured(residual: &[f64]) -> NoiseFit {
    noise_level_coloured_records(&[residual])
}

/// The differences r_(t+k) − r_t within each of `parts` (never across two of them).
fn lag_differences(parts: &[&[f64]], k: usize) -> Vec<f64> {
    parts
        .iter()
        .flat_map(|p| p.windows(k + 1).map(move |w| w[k] - w[0]))
        .collect()
}

/// [`noise_level_coloured`] of a residual in several records (`parts`, one slice per record):
/// the semivariogram pairs samples within each record only. Its lags are limited by the
/// shortest record.
pub fn noise_level_coloured_records(parts: &[&[f64]]) -> NoiseFit {
    let n = parts.iter().map(|p| p.len()).min().unwrap_or(0);
    let lags = VARIOGRAM_LAGS.min(n / 20).max(1);
    if n < 3 {
        return NoiseFit {
            std: noise_level_records(parts),
            colour: 0.0,
            drift: 0.0,
        };
    }
    let gamma: Vec<f64> = (1..=lags)
        .map(|k| {
            let d = lag_differences(parts, k);
            let m = median(d.clone());
            let mad = median(d.iter().map(|v| (v - m).abs()).collect()) / 0.674_489_75;
            0.5 * mad * mad
        })
        .collect();
    let white = NoiseFit {
        std: gamma[0].sqrt(),
        colour: 0.0,
        drift: 0.0,
    };
    if lags < 3 || gamma.iter().any(|g| !(g.is_finite() && *g > 0.0)) {
        return white;
    }
    // Relative residuals: each γ̂(k) has about the same relative error.
    let weight: Vec<f64> = gamma.iter().map(|g| 1.0 / g).collect();
    let mut best: Option<(f64, NoiseFit)> = None;
    for step in 0..=MAX_COLOUR_PERCENT {
        let phi = step as f64 / 100.0;
        let a: Vec<f64> = (1..=lags).map(|k| 1.0 - phi.powi(k as i32)).collect();
        let b: Vec<f64> = (1..=lags).map(|k| (k * k) as f64).collect();
        // Weighted normal equations in (σ², c), then the bounds by dropping a term.
        let dot = |x: &[f64], y: &[f64]| -> f64 {
            (0..lags).map(|i| weight[i] * weight[i] * x[i] * y[i]).sum()
        };
        let (aa, ab, bb, ag, bg) = (
            dot(&a, &a),
            dot(&a, &b),
            dot(&b, &b),
            dot(&a, &gamma),
            dot(&b, &gamma),
        );
        let det = aa * bb - ab * ab;
        let mut candidates = vec![(ag / aa, 0.0), (0.0, bg / bb)];
        if det > 1e-12 * aa * bb {
            candidates.push(((ag * bb - bg * ab) / det, (aa * bg - ab * ag) / det));
        }
        for (s, c) in candidates {
            if !(s >= 0.0 && c >= 0.0) {
                continue;
            }
            let sse: f64 = (0..lags)
                .map(|i| (weight[i] * (gamma[i] - s * a[i] - c * b[i])).powi(2))
                .sum();
            if best.is_none_or(|(v, _)| sse < v) {
                best = Some((
                    sse,
                    NoiseFit {
                        std: s.sqrt(),
                        colour: phi,
                        drift: c,
                    },
                ));
            }
        }
    }
    best.map_or(white, |(_, f)| f)
}

/// The quantisation noise q/√12 of a signal with fewer distinct values than half its samples
/// (q the smallest step between them), 0 otherwise.
pub(super) fn quantisation_floor(y: &[f64]) -> f64 {
    let mut v: Vec<f64> = y.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    if v.len() < 2 || 2 * v.len() >= y.len() {
        return 0.0;
    }
    let q = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    if q.is_finite() { q / 12f64.sqrt() } else { 0.0 }
}

/// An output that sits on a lattice y ∈ {a + k·q} up to a small noise: a quantised sensor
/// (an encoder, a coarse converter), found by [`output_lattice`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Lattice {
    /// The step q.
    pub step: f64,
    /// The coherence mean cos(2π·Δy/q) over the output's steps (1 on an exact lattice, about
    /// exp(−4π²σ²/q²) with noise of std σ after the quantiser, about 0 for a continuous output).
    pub coherence: f64,
    /// How many of the output's one-sample changes it is measured on.
    pub changes: usize,
}

/// The least coherence of a lattice that [`output_lattice`] reports: noise after the quantiser
/// below about q/8.
pub const LATTICE_COHERENCE: f64 = 0.6;

/// The lattice the measured output `y` sits on, if any: the largest step q (at most a
/// twentieth of the range of y) at which the one-sample changes Δy that move by half a step
/// or more are whole multiples of q, as measured by mean cos(2π·Δy/q) ≥ [`LATTICE_COHERENCE`]
/// over at least 100 changes.
///
/// Why the changes and not the values: an output that dwells at a few set points clusters at
/// them, and some step puts any few clusters near a lattice; the changes between samples of a
/// moving continuous output take every size, those of a quantised output only multiples of q.
/// The largest coherent step is the lattice's own: q/2, q/3, … fit its changes too, and 2q
/// does not (a change of ±q is half of it, cos π = −1). The gap tests cannot see a
/// quantiser: its error is white and uncorrelated with the input, so it passes as noise.
pub fn output_lattice(y: &[f64]) -> Option<Lattice> {
    output_lattice_records(&[y])
}

/// [`output_lattice`] of an output in several records (`parts`, one slice per record): the
/// one-sample changes are taken within each record, never across a record boundary.
pub fn output_lattice_records(parts: &[&[f64]]) -> Option<Lattice> {
    const MAX_CHANGES: usize = 4000;
    let (lo, hi) = parts
        .iter()
        .flat_map(|p| p.iter())
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let range = hi - lo;
    if !(range > 0.0 && range.is_finite()) {
        return None;
    }
    let mut changes: Vec<f64> = lag_differences(parts, 1)
        .into_iter()
        .filter(|d| d.is_finite() && *d != 0.0)
        .collect();
    if changes.len() > MAX_CHANGES {
        let step = changes.len().div_ceil(MAX_CHANGES);
        changes = changes.into_iter().step_by(step).collect();
    }
    let largest = changes.iter().fold(0.0_f64, |m, d| m.max(d.abs()));
    let coherence = |q: f64| -> (f64, usize) {
        let moved: Vec<f64> = changes
            .iter()
            .copied()
            .filter(|d| d.abs() >= 0.5 * q)
            .collect();
        let c = moved
            .iter()
            .map(|d| (std::f64::consts::TAU * d / q).cos())
            .sum::<f64>()
            / moved.len().max(1) as f64;
        (c, moved.len())
    };
    // From the largest step down: a relative spacing of q/(8·|Δy|max) keeps the phase of the
    // largest change within π/4 of a grid point.
    let mut q = range / 20.0;
    let floor = range / 20_000.0;
    while q > floor {
        let (c, n) = coherence(q);
        if n >= 100 && c >= LATTICE_COHERENCE {
            // The coherence first reaches the bound above the step (cos 2π·q/q' falls off
            // slowly); its peak is the step, below q' and above q'/1.5 (where q'/2, a
            // sub-lattice, would peak too).
            let (mut best, mut best_c, mut p) = (q, c, q);
            while p > q / 1.5 {
                let (cp, np) = coherence(p);
                if np >= 100 && cp > best_c {
                    (best, best_c) = (p, cp);
                }
                p -= p * p / (8.0 * largest.max(p));
            }
            // polish by a golden-section search of the coherence within one grid cell
            let cell = best * best / (8.0 * largest.max(best));
            let (mut a, mut b) = (best - cell, best + cell);
            let g = 0.5 * (5f64.sqrt() - 1.0);
            let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
            let (mut c1, mut c2) = (coherence(x1).0, coherence(x2).0);
            // each step keeps one interior point and its value
            for _ in 0..40 {
                if c1 >= c2 {
                    (b, x2, c2) = (x2, x1, c1);
                    x1 = b - g * (b - a);
                    c1 = coherence(x1).0;
                } else {
                    (a, x1, c1) = (x1, x2, c2);
                    x2 = a + g * (b - a);
                    c2 = coherence(x2).0;
                }
            }
            let step = 0.5 * (a + b);
            let (coherence, changes) = coherence(step);
            return Some(Lattice {
                step,
                coherence,
                changes,
            });
        }
        q -= q * q / (8.0 * largest.max(q));
    }
    None
}
