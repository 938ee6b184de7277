//! Is an effect static at all? A test for dependence on the direction of motion.
//!
//! A static map w = N(z) gives the same w whether z rises or falls. Hysteresis and backlash
//! do not: the paper's Example 1 shows the best static dispersion staying high. Given the
//! points (z_k, w_k) in time order and a static fit f, [`direction_dependence`] splits the
//! residual r_k = w_k − f(z_k) by the direction of z (sign of z_(k+1) − z_(k−1), held through
//! flat stretches as a play remembers it) inside
//! quantile bins of z, so that a map that merely differs across z is not mistaken for
//! hysteresis, and measures
//!
//! ```text
//!   explained = Σ_b Σ_(d ∈ {rising, falling}) n_bd·(m_bd − m_b)²  /  Σ_k r_k²
//! ```
//!
//! (m_bd the mean residual of bin b's samples moving in direction d, m_b the bin's mean: the
//! share of the residual energy that the direction explains beyond z itself)
//!
//! together with the standardised difference of the rising and falling means, its variance
//! allowing for the serial correlation of the residual (a direction is held over runs of many
//! samples, and a residual is correlated over as many). The effect is
//! reported as dynamic ("hysteresis or backlash suspected") when direction explains more than
//! `threshold` (0.1 is a good default) of the residual energy and the difference is significant
//! (|t| > [`DIRECTION_T`]).

/// The bar on |t| of the rising-minus-falling difference: the two-sided standard normal
/// quantile at 1 − α/(2·m) with α = 0.05 and m = 10 tests. The statistic's variance allows for
/// the serial correlation of the residual (a Newey–West long-run variance), so that under a
/// static map it is about standard normal; a run of the workflow tests up to about ten fits
/// (each site, each estimator), and the chance that the residual of any static fit among them
/// passes the bar by chance is then at most 5 % (Bonferroni).
pub const DIRECTION_T: f64 = 2.807;

use structid_core::validation::comparison::{default_bandwidth, long_run_variance};

/// The outcome of [`direction_dependence`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DirectionTest {
    /// Share of the residual energy explained by the direction of z within z-bins (0…1).
    pub explained: f64,
    /// The t statistic of (mean rising − mean falling residual) within bins, its variance the
    /// Newey–West long-run variance of the residual's contributions (the pooled variance when
    /// that long-run variance is not positive).
    pub t_statistic: f64,
    /// Samples used (those with a nonzero direction).
    pub samples: usize,
    /// Whether the effect looks dynamic (direction-dependent).
    pub dynamic: bool,
    /// The residual energy the direction explains, Σ_b Σ_d n_bd·(m_bd − m_b)² (the numerator
    /// of `explained`, in the squared units of the residual).
    pub direction_energy: f64,
    /// The same energy of the direction dependence that sampling alone leaves after a static
    /// fit of a map acting in continuous time (see `discover`'s direction test), 0 when not
    /// assessed. A direction effect no larger than a few times this is not called dynamic.
    pub sampling_energy: f64,
}

impl DirectionTest {
    /// The test of a record too short or flat to say anything: not dynamic.
    pub fn none() -> Self {
        DirectionTest {
            explained: 0.0,
            t_statistic: 0.0,
            samples: 0,
            dynamic: false,
            direction_energy: 0.0,
            sampling_energy: 0.0,
        }
    }
}

/// Tests whether the residual `r` of a static fit depends on the direction of `z` (both in
/// time order); see the [module documentation](self). `threshold` is the share of residual
/// energy direction must explain to call the effect dynamic.
///
/// ```
/// use structid_discover::hysteresis::direction_dependence;
/// // Backlash of half-width 0.3 driven by a sine, against the static fit w = z.
/// let z: Vec<f64> = (0..2000).map(|k| (k as f64 * 0.02).sin()).collect();
/// let mut w = vec![0.0; z.len()];
/// for k in 1..z.len() {
///     w[k] = if z[k] - w[k - 1] > 0.3 { z[k] - 0.3 } else if z[k] - w[k - 1] < -0.3 { z[k] + 0.3 } else { w[k - 1] };
/// }
/// let r: Vec<f64> = w.iter().zip(&z).map(|(w, z)| w - z).collect();
/// assert!(direction_dependence(&z, &r, 0.1).dynamic);
/// ```
pub fn direction_dependence(z: &[f64], r: &[f64], threshold: f64) -> DirectionTest {
    let n = z.len().min(r.len());
    direction_dependence_records(z, r, &[0, n], threshold)
}

/// [`direction_dependence`] of points in several records: `bounds` are where each record
/// starts in `z` and `r`, then their length (`[0, L₁, …, L]`). The direction of z is taken
/// within each record (a central difference never spans two records, and a record starts
/// without a remembered direction); the bins and energies are over all records.
///
/// ```
/// use structid_discover::hysteresis::{direction_dependence, direction_dependence_records};
/// let z: Vec<f64> = (0..1000).map(|k| (k as f64 * 0.02).sin()).collect();
/// let r: Vec<f64> = z.iter().map(|v| 0.1 * v).collect();
/// let one = direction_dependence(&z, &r, 0.1);
/// assert_eq!(direction_dependence_records(&z, &r, &[0, 1000], 0.1), one);
/// // Two records lose the two samples next to their seam.
/// let two = direction_dependence_records(&z, &r, &[0, 500, 1000], 0.1);
/// assert_eq!(two.samples, one.samples - 2);
/// ```
pub fn direction_dependence_records(
    z: &[f64],
    r: &[f64],
    bounds: &[usize],
    threshold: f64,
) -> DirectionTest {
    let n = z.len().min(r.len());
    let none = DirectionTest::none();
    if n < 20 {
        return none;
    }
    // Direction by the central difference; a flat stretch keeps the direction of the last
    // change, as a play or a hysteresis remembers it (on a staircase input the moving
    // samples are only the step edges, where any error of the linear model's transient sits,
    // and the test would weigh those alone).
    let mut up: Vec<bool> = Vec::with_capacity(n);
    let mut keep: Vec<usize> = Vec::with_capacity(n);
    for w in bounds.windows(2) {
        let (start, end) = (w[0].min(n), w[1].min(n));
        let mut last: Option<bool> = None;
        for k in start + 1..end.saturating_sub(1) {
            let d = z[k + 1] - z[k - 1];
            if d != 0.0 && d.is_finite() {
                last = Some(d > 0.0);
            }
            if let Some(dir) = last
                && r[k].is_finite()
                && z[k].is_finite()
            {
                keep.push(k);
                up.push(dir);
            }
        }
    }
    let m = keep.len();
    if m < 20 {
        return none;
    }
    // Quantile bins of z over the kept samples.
    let bins = (m / 50).clamp(2, 20);
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| z[keep[a]].total_cmp(&z[keep[b]]));
    let mut bin = vec![0; m];
    for (rank, &i) in order.iter().enumerate() {
        bin[i] = rank * bins / m;
    }
    // Per bin and direction: count, sum, sum of squares.
    let mut acc = vec![[(0usize, 0.0f64, 0.0f64); 2]; bins];
    for i in 0..m {
        let v = r[keep[i]];
        let a = &mut acc[bin[i]][usize::from(up[i])];
        a.0 += 1;
        a.1 += v;
        a.2 += v * v;
    }
    let total: f64 = keep.iter().map(|&k| r[k] * r[k]).sum();
    if total <= 0.0 {
        return DirectionTest { samples: m, ..none };
    }
    let (mut between, mut diff_sum, mut var_sum, mut within) = (0.0, 0.0, 0.0, 0.0);
    let mut dof = 0usize;
    for b in &acc {
        let [(n0, s0, q0), (n1, s1, q1)] = *b;
        if n0 < 2 || n1 < 2 {
            continue;
        }
        let (m0, m1) = (s0 / n0 as f64, s1 / n1 as f64);
        let nb = (n0 + n1) as f64;
        let mb = (s0 + s1) / nb;
        // Energy explained by splitting this bin by direction (around the bin's mean).
        between += n0 as f64 * (m0 - mb).powi(2) + n1 as f64 * (m1 - mb).powi(2);
        within += (q0 - s0 * m0) + (q1 - s1 * m1);
        dof += n0 + n1 - 2;
        diff_sum += (m1 - m0) * nb;
        var_sum += nb * nb * (1.0 / n0 as f64 + 1.0 / n1 as f64);
    }
    if dof == 0 {
        return DirectionTest { samples: m, ..none };
    }
    let pooled = (within / dof as f64).max(f64::MIN_POSITIVE);
    let t = direction_t(r, &keep, &up, &bin, &acc, diff_sum)
        .unwrap_or_else(|| diff_sum / (pooled * var_sum).sqrt());
    let explained = (between / total).clamp(0.0, 1.0);
    DirectionTest {
        explained,
        t_statistic: t,
        samples: m,
        dynamic: explained > threshold && t.abs() > DIRECTION_T,
        direction_energy: between,
        sampling_energy: 0.0,
    }
}

/// The t statistic of the rising-minus-falling difference D = Σ_b n_b·(m_b↑ − m_b↓), with
/// its variance allowing for the serial correlation of the residual. D = Σ_i c_i·r_i, with
/// c_i = n_b/n_b↑ for a rising sample of bin b and −n_b/n_b↓ for a falling one; under a static
/// map the products x_i = c_i·(r_i − m_(b,d)) have mean zero, and the variance of their sum
/// is L·V̂, V̂ their Newey–West long-run variance (Andrews' bandwidth). A direction held over
/// long runs of a slowly varying z, met by a coloured residual, thus counts as the few
/// independent runs it is, not as its many samples. `None` when fewer than three samples
/// contribute or their long-run variance is not positive.
fn direction_t(
    r: &[f64],
    keep: &[usize],
    up: &[bool],
    bin: &[usize],
    acc: &[[(usize, f64, f64); 2]],
    diff_sum: f64,
) -> Option<f64> {
    let x: Vec<f64> = (0..keep.len())
        .filter_map(|i| {
            let [(n0, s0, _), (n1, s1, _)] = acc[bin[i]];
            if n0 < 2 || n1 < 2 {
                return None;
            }
            let nb = (n0 + n1) as f64;
            let (c, mean) = if up[i] {
                (nb / n1 as f64, s1 / n1 as f64)
            } else {
                (-nb / n0 as f64, s0 / n0 as f64)
            };
            Some(c * (r[keep[i]] - mean))
        })
        .collect();
    if x.len() < 3 {
        return None;
    }
    let variance = x.len() as f64 * long_run_variance(&x, default_bandwidth(&x));
    (variance > 0.0).then(|| diff_sum / variance.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, Normal};

    fn input(len: usize, seed: u64) -> Vec<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let n = Normal::new(0.0, 1.0).unwrap();
        let mut s = 0.0;
        (0..len)
            .map(|_| {
                s = 0.95 * s + 0.3 * n.sample(&mut rng);
                s
            })
            .collect()
    }

    #[test]
    fn a_static_map_with_noise_is_not_dynamic() {
        for seed in 0..10 {
            let z = input(3000, seed);
            let mut rng = StdRng::seed_from_u64(seed + 100);
            let n = Normal::new(0.0, 0.05).unwrap();
            // The residual of a correct static fit: noise only.
            let r: Vec<f64> = z.iter().map(|_| n.sample(&mut rng)).collect();
            let t = direction_dependence(&z, &r, 0.1);
            assert!(!t.dynamic && t.explained < 0.02, "seed {seed}: {t:?}");
            // A wrong static fit (a missing z³) is still not direction-dependent.
            let r: Vec<f64> = z
                .iter()
                .map(|z| 0.3 * z.powi(3) + n.sample(&mut rng))
                .collect();
            let t = direction_dependence(&z, &r, 0.1);
            assert!(
                !t.dynamic && t.explained < 0.02,
                "seed {seed} (wrong static map): {t:?}"
            );
        }
    }

    /// A coloured residual met by a slowly varying z: each direction is held over long runs,
    /// so the pooled statistic, which counts every sample as independent, finds a
    /// "significant" difference far more often than its nominal level; the statistic with
    /// the long-run variance stays near its null distribution, and a real backlash of the
    /// same slow motion still passes it.
    #[test]
    fn a_coloured_residual_on_slow_motion_is_not_dynamic() {
        let slow = |seed: u64| -> Vec<f64> {
            let mut rng = StdRng::seed_from_u64(seed);
            let n = Normal::new(0.0, 1.0).unwrap();
            let (mut a, mut b) = (0.0, 0.0);
            (0..3000)
                .map(|_| {
                    a = 0.995 * a + 0.1 * n.sample(&mut rng);
                    b = 0.9 * b + 0.1 * a;
                    b
                })
                .collect()
        };
        let (mut pooled_large, mut flagged) = (0, 0);
        for seed in 0..40 {
            let z = slow(seed);
            let mut rng = StdRng::seed_from_u64(seed + 1000);
            let n = Normal::new(0.0, 0.05).unwrap();
            let mut c = 0.0;
            let r: Vec<f64> = (0..z.len())
                .map(|_| {
                    c = 0.98 * c + n.sample(&mut rng);
                    c
                })
                .collect();
            let t = direction_dependence(&z, &r, 0.0);
            // The pooled statistic of the same samples, computed here from its definition.
            let up: Vec<bool> = (1..z.len() - 1).map(|k| z[k + 1] > z[k - 1]).collect();
            let (r_in, z_in) = (&r[1..z.len() - 1], &z[1..z.len() - 1]);
            let mut order: Vec<usize> = (0..r_in.len()).collect();
            order.sort_by(|&a, &b| z_in[a].total_cmp(&z_in[b]));
            let bins = (r_in.len() / 50).clamp(2, 20);
            let (mut diff, mut var, mut within, mut dof) = (0.0, 0.0, 0.0, 0usize);
            for chunk in order.chunks(r_in.len().div_ceil(bins)) {
                let side = |d: bool| -> Vec<f64> {
                    chunk
                        .iter()
                        .filter(|&&i| up[i] == d)
                        .map(|&i| r_in[i])
                        .collect()
                };
                let (lo, hi) = (side(false), side(true));
                if lo.len() < 2 || hi.len() < 2 {
                    continue;
                }
                let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
                let (m0, m1) = (mean(&lo), mean(&hi));
                let nb = (lo.len() + hi.len()) as f64;
                diff += (m1 - m0) * nb;
                var += nb * nb * (1.0 / lo.len() as f64 + 1.0 / hi.len() as f64);
                within += lo.iter().map(|v| (v - m0).powi(2)).sum::<f64>()
                    + hi.iter().map(|v| (v - m1).powi(2)).sum::<f64>();
                dof += lo.len() + hi.len() - 2;
            }
            let pooled_t = diff / (within / dof as f64 * var).sqrt();
            pooled_large += usize::from(pooled_t.abs() > DIRECTION_T);
            flagged += usize::from(t.t_statistic.abs() > DIRECTION_T);
        }
        assert!(
            pooled_large >= 10,
            "pooled statistic large in {pooled_large}/40"
        );
        assert!(flagged <= 3, "flagged {flagged}/40");
        // Backlash of half-width 0.05 on the same slow motion.
        let z = slow(7);
        let mut w = z[0];
        let r: Vec<f64> = z
            .iter()
            .map(|&z| {
                w = w.clamp(z - 0.05, z + 0.05);
                w - z
            })
            .collect();
        let t = direction_dependence(&z, &r, 0.1);
        assert!(t.dynamic, "{t:?}");
    }

    #[test]
    fn backlash_and_bouc_wen_hysteresis_are_dynamic() {
        for seed in 0..10 {
            let z = input(3000, seed);
            // Backlash of half-width 0.2; the static fit is the identity.
            let mut w = vec![0.0; z.len()];
            for k in 1..z.len() {
                let d = z[k] - w[k - 1];
                w[k] = if d > 0.2 {
                    z[k] - 0.2
                } else if d < -0.2 {
                    z[k] + 0.2
                } else {
                    w[k - 1]
                };
            }
            let r: Vec<f64> = w.iter().zip(&z).map(|(w, z)| w - z).collect();
            let t = direction_dependence(&z, &r, 0.1);
            assert!(t.dynamic && t.explained > 0.15, "backlash {seed}: {t:?}");
            // Bouc–Wen: ḣ = A·ż − β|ż|·h − γ·ż·|h|, w = α·z + (1 − α)·h.
            let (a, b, g, alpha) = (1.0, 2.0, 1.0, 0.3);
            let mut h = 0.0;
            let mut r = vec![0.0; z.len()];
            for k in 1..z.len() {
                let dz = z[k] - z[k - 1];
                h += a * dz - b * dz.abs() * h - g * dz * h.abs();
                // Residual against the best linear static part α·z: the hysteretic term.
                r[k] = (1.0 - alpha) * h;
            }
            let t = direction_dependence(&z, &r, 0.1);
            assert!(t.dynamic, "Bouc–Wen {seed}: {t:?}");
        }
    }

    /// On a staircase input only the step edges move; a linear model's transient error sits
    /// there and follows the step's sign. Held through the dwell, the direction sees that
    /// the map is the same rising and falling: a static map is not called dynamic.
    #[test]
    fn a_staircase_with_transient_errors_at_its_edges_is_not_dynamic() {
        let mut seed = 12345u64;
        let mut uniform = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let levels: Vec<f64> = (0..120).map(|_| 2.0 * uniform() - 1.0).collect();
        let z: Vec<f64> = (0..3000).map(|k| levels[k / 25]).collect();
        let r: Vec<f64> = (0..3000)
            .map(|k| {
                let edge = if k > 0 { 0.3 * (z[k] - z[k - 1]) } else { 0.0 };
                edge + 0.01 * (uniform() - 0.5)
            })
            .collect();
        let t = direction_dependence(&z, &r, 0.1);
        assert!(t.samples > 2500, "{t:?}");
        assert!(!t.dynamic, "{t:?}");
    }

    #[test]
    fn short_or_flat_records_are_not_dynamic() {
        assert!(!direction_dependence(&[1.0; 10], &[1.0; 10], 0.25).dynamic);
        assert!(!direction_dependence(&[1.0; 100], &[0.5; 100], 0.25).dynamic);
    }
}
