//! A second search around a G that integrates, when the given G's zero cancels its
//! integrator.
//!
//! A G fitted directly to a closed-loop record tends to the controller's negative inverse: its
//! numerator B gets a zero within about 0.1 of z = 1 that cancels the integrator the user
//! fixed ([`structid_linear::integrators::integrator_cancellation`]). Around such a G the
//! loops of the feedback hypotheses often diverge and no refit can start. A held chain of
//! integrators has its sampling zero near z = −1 instead, so the search runs once more around
//! G with the cancelling zero moved there,
//!
//! ```text
//!   B(z) = (z − z_c)·Q(z)   →   B̃(z) = s·(z + 1)·Q(z),
//! ```
//!
//! its gain s (sign included) fitted by the workflow's own simulation error on the estimation
//! record. The finding that validates better, of the two searches, is reported, always
//! against the nominal model as given.

use structid_core::validation::ValidationSettings;
use structid_core::{Data, Result};
use structid_linear::PolynomialModel;

use crate::hypotheses::Nominal;

use super::{DiscoverSettings, Discovery, Finding, Verdict};

/// The zero of B(z) nearest z = 1 when it lies within this distance (the cancellation test
/// allows about 0.1).
const NEAR_ONE: f64 = 0.2;

/// The second search must validate at most this share of the first's RMS to replace it: a
/// search around a G the user did not give needs clear evidence.
pub(super) const RESTORED_GAIN: f64 = 0.8;

/// `g` with the numerator zero nearest z = 1 (within [`NEAR_ONE`]) moved to z = −1 and its
/// gain fitted to `est` by the simulation error of the linear model alone (scored as every
/// simulation of the workflow), or `None` when `g` has no such zero or no gain simulates.
pub(super) fn integrating_start(
    g: &PolynomialModel,
    est: &Data,
    settings: &DiscoverSettings,
) -> Option<PolynomialModel> {
    if g.num.len() != 1 {
        return None;
    }
    let b = &g.num[0];
    let delay = b.iter().take_while(|v| **v == 0.0).count();
    // c₀·z^m + c₁·z^(m−1) + … + c_m: B without its delay, as a polynomial in z.
    let c = &b[delay..];
    if c.len() < 2 {
        return None;
    }
    let zero = nearest_root(c, 1.0)?;
    if (zero - 1.0).abs() > NEAR_ONE {
        return None;
    }
    let q = deflate(c, zero);
    // (z + 1)·Q(z)
    let mut moved = vec![0.0; q.len() + 1];
    for (i, v) in q.iter().enumerate() {
        moved[i] += v;
        moved[i + 1] += v;
    }
    let mut num = vec![0.0; delay];
    num.extend_from_slice(&moved);
    let unit = PolynomialModel {
        num: vec![num],
        den: g.den.clone(),
        sample_time: g.sample_time,
    };
    let scoring = ValidationSettings::builder()
        .initial_state(settings.gap.initial_state)
        .settle(settings.settle)
        .scoring(settings.scoring.unwrap_or_default())
        .build()
        .ok()?;
    let rms = |s: f64| -> f64 {
        let model = scaled(&unit, s);
        Nominal::from_polynomial(&model)
            .and_then(|n| crate::records::simulate(&n.model()?, &n.maps(), est, &scoring))
            .map(|v| v.rms)
            .ok()
            .filter(|r| r.is_finite())
            .unwrap_or(f64::INFINITY)
    };
    // The gain of the moved zero keeps |B| about as it was; the fit searches four decades
    // either side, both signs (a closed-loop fit often has the wrong one), by golden section
    // on log |s| around the best point of a coarse grid.
    let grid: Vec<f64> = (-16..=16).map(|k| 10f64.powf(k as f64 / 4.0)).collect();
    let mut best = (f64::INFINITY, 0.0);
    for sign in [1.0, -1.0] {
        for &m in &grid {
            let r = rms(sign * m);
            if r < best.0 {
                best = (r, sign * m);
            }
        }
    }
    if !best.0.is_finite() {
        return None;
    }
    let sign = best.1.signum();
    let (mut lo, mut hi) = (best.1.abs().ln() - 0.6, best.1.abs().ln() + 0.6);
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (hi - phi * (hi - lo), lo + phi * (hi - lo));
    let (mut fa, mut fb) = (rms(sign * a.exp()), rms(sign * b.exp()));
    for _ in 0..30 {
        if fa <= fb {
            hi = b;
            b = a;
            fb = fa;
            a = hi - phi * (hi - lo);
            fa = rms(sign * a.exp());
        } else {
            lo = a;
            a = b;
            fa = fb;
            b = lo + phi * (hi - lo);
            fb = rms(sign * b.exp());
        }
    }
    let s = if fa.min(fb) < best.0 {
        sign * if fa <= fb { a.exp() } else { b.exp() }
    } else {
        best.1
    };
    Some(scaled(&unit, s))
}

/// `g` with its numerators scaled by `s`.
fn scaled(g: &PolynomialModel, s: f64) -> PolynomialModel {
    PolynomialModel {
        num: g
            .num
            .iter()
            .map(|b| b.iter().map(|v| s * v).collect())
            .collect(),
        den: g.den.clone(),
        sample_time: g.sample_time,
    }
}

/// The real root of c₀·z^m + … + c_m nearest `start`, by Newton's method from it (`None` when
/// it does not converge to a root).
fn nearest_root(c: &[f64], start: f64) -> Option<f64> {
    let eval = |z: f64| {
        c.iter()
            .fold((0.0, 0.0), |(p, dp), &ck| (p * z + ck, dp * z + p))
    };
    let scale: f64 = c.iter().map(|v| v.abs()).sum();
    let mut z = start;
    for _ in 0..50 {
        let (p, dp) = eval(z);
        if dp == 0.0 || !dp.is_finite() {
            return None;
        }
        let step = p / dp;
        z -= step;
        if step.abs() < 1e-12 * (1.0 + z.abs()) {
            break;
        }
    }
    let (p, _) = eval(z);
    (z.is_finite() && p.abs() <= 1e-9 * scale).then_some(z)
}

/// The quotient of c₀·z^m + … + c_m by (z − root) (synthetic division; the remainder, zero at
/// a root, is dropped).
fn deflate(c: &[f64], root: f64) -> Vec<f64> {
    let mut q = Vec::with_capacity(c.len() - 1);
    let mut acc = 0.0;
    for &ck in &c[..c.len() - 1] {
        acc = acc * root + ck;
        q.push(acc);
    }
    q
}

/// The better of the discovery `first` around the given nominal `given` and `second` around
/// the integrating start `start`: `second` when it names a missing effect whose augmented model
/// validates below [`RESTORED_GAIN`] of what `first` leaves (its finding's augmented model,
/// or the nominal model's gap when it found none). `second` is restated against the given
/// nominal: its gaps are `first`'s, its shrink over them, and G as given and as kept.
pub(super) fn better(
    first: Discovery,
    second: Discovery,
    given: &Nominal,
    start: &PolynomialModel,
    val: &Data,
    settings: &DiscoverSettings,
) -> Result<Discovery> {
    let first_rms = match (&first.finding, first.verdict_kind, &first.linear_rival) {
        (Some(f), Verdict::MissingEffect, _) => f.augmented.validation_gap.rms,
        // G with one more mode closed the gap: that is what a second search must beat.
        (None, Verdict::LinearModel, Some(r)) => r.validation_rms,
        _ => first.validation_gap.rms,
    };
    let Some(f) = second
        .finding
        .as_ref()
        .filter(|_| second.verdict_kind == Verdict::MissingEffect)
    else {
        return Ok(first);
    };
    // A NaN RMS (nothing simulated) never replaces the first search.
    let clearly_better = f.augmented.validation_gap.rms < RESTORED_GAIN * first_rms;
    if !clearly_better {
        return Ok(first);
    }
    let mut second = second;
    let mut f: Finding = second.finding.take().expect("checked above");
    f.remarks.push(format!(
        "the search ran again around G with the zero that cancelled its integrator moved to \
         z = −1 (where a held chain of integrators has it) and its gain fitted to the \
         estimation record (nominal validation RMS {} as given, {} so), and this effect \
         validates better there than the first pass's result around G as given ({}: \
         validation RMS {})",
        super::rms_text(first.validation_gap.rms),
        super::rms_text(second.validation_gap.rms),
        first
            .finding
            .as_ref()
            .map_or_else(|| first.verdict_kind.describe().to_string(), |f| f.effect()),
        super::rms_text(first_rms)
    ));
    super::against_given(&mut f, given, start, &first.validation_gap, val, settings)?;
    let verdict = super::naming::verdict_text(given, &first.validation_gap, &f);
    Ok(Discovery {
        estimation_gap: first.estimation_gap,
        validation_gap: first.validation_gap,
        missing_effect: true,
        verdict_kind: Verdict::MissingEffect,
        finding: Some(f),
        verdict,
        seconds: first.seconds + second.seconds,
        ..second
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Moving the zero: (z − 0.999)·(z − 0.3) becomes (z + 1)·(z − 0.3) up to the gain.
    #[test]
    fn the_cancelling_zero_is_found_and_deflated() {
        // (z − 0.999)(z − 0.3) = z² − 1.299 z + 0.2997
        let c = [1.0, -1.299, 0.2997];
        let root = nearest_root(&c, 1.0).unwrap();
        assert!((root - 0.999).abs() < 1e-12, "{root}");
        let q = deflate(&c, root);
        assert_eq!(q.len(), 2);
        assert!(
            (q[0] - 1.0).abs() < 1e-12 && (q[1] + 0.3).abs() < 1e-9,
            "{q:?}"
        );
        // No real root near 1: z² + 1.
        assert!(nearest_root(&[1.0, 0.0, 1.0], 1.0).is_none());
    }

    /// On a record of a double integrator G = b·(q⁻¹ + q⁻²)/(1 − q⁻¹)² (the hold's zero at
    /// −1), a G with the same denominator whose zero cancels an integrator and whose gain is
    /// wrong in size and sign is restored to the true G: the zero moved to −1 and the gain
    /// fitted by the windowed simulation error, to a few per cent.
    #[test]
    fn a_cancelled_double_integrator_is_restored_to_the_true_one() {
        use structid_core::Signal;
        use structid_core::validation::{Scoring, Windows};
        let b = 2e-3;
        let n = 3000;
        let u: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64;
                (0.013 * t).sin() + 0.5 * (0.041 * t + 1.0).sin() - 0.3 * (0.0071 * t).cos()
            })
            .collect();
        let mut y = vec![0.0; n];
        for k in 0..n {
            let at = |v: &[f64], j: usize| if k >= j { v[k - j] } else { 0.0 };
            y[k] = 2.0 * at(&y, 1) - at(&y, 2) + b * (at(&u, 1) + at(&u, 2));
        }
        let est = Data::new(
            Signal::from_fn(n, 1, |k, _| u[k]),
            Signal::from_fn(n, 1, |k, _| y[k]),
        )
        .unwrap();
        // A zero at 0.999 (B(1) is 0.05 % of Σ|bᵢ|) and the wrong sign and size.
        let cancelled = PolynomialModel {
            num: vec![vec![0.0, -0.05, 0.04995]],
            den: vec![1.0, -2.0, 1.0],
            sample_time: None,
        };
        let settings = DiscoverSettings {
            scoring: Some(Scoring::Windowed(Windows::new(200, 25).unwrap())),
            ..DiscoverSettings::default()
        };
        let g = integrating_start(&cancelled, &est, &settings).expect("a restored G");
        assert_eq!(g.den, cancelled.den);
        let num = &g.num[0];
        assert_eq!(num[0], 0.0);
        assert!((num[1] - b).abs() < 0.03 * b, "{num:?}");
        assert!((num[2] - b).abs() < 0.03 * b, "{num:?}");
        // A G without a zero near 1 has nothing to restore.
        let ok = PolynomialModel {
            num: vec![vec![0.0, b, b]],
            ..cancelled
        };
        assert!(integrating_start(&ok, &est, &settings).is_none());
    }
}
