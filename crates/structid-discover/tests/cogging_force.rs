//! A case outside the physics generator and outside the effect library: a motor's cogging
//! force, periodic in position, on a mass–spring–damper simulated in continuous time.
//!
//! M·ÿ + c·ẏ + k·y + A·sin(2π·y/p) = u with M = 1, c = 4, k = 100, A = 15, p = 0.25, so the
//! force repeats about sixteen times over the range of y. RK4 at 20 steps per sample with the
//! input held (T_s = 0.01 s), output noise of std 0.005, and a nominal estimated by output
//! error from the effect-laden estimation record (as `structid linear --method oe` would). No
//! family names a periodic force. The workflow must still place it in feedback from y, and
//! its table must carry the periodic force: at the default kernel width (a tenth of the range
//! of z) the map is a smooth curve that explains nothing, so the workflow tries a narrower
//! kernel, and the table is written fine enough to keep what that kernel resolved.

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_core::{Data, Signal};
use structid_discover::discover::{AugmentedMap, DiscoverSettings, Verdict, discover};
use structid_discover::hypotheses::{Nominal, Site};
use structid_linear::{OeSettings, Orders, oe};

const PERIOD: f64 = 0.25;
const COGGING: f64 = 15.0;

/// One record: input amplitude `amp`, seed for the input and the noise.
fn record(seed: u64, len: usize, amp: f64) -> Data {
    let (m, c, k) = (1.0, 4.0, 100.0);
    let ts = 0.01;
    let mut rng = StdRng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let mut s = 0.0;
    let u: Vec<f64> = (0..len)
        .map(|_| {
            s = 0.9 * s + 0.436 * n.sample(&mut rng);
            amp * s
        })
        .collect();
    let f = |x: [f64; 2], u: f64| {
        let cog = COGGING * (std::f64::consts::TAU * x[0] / PERIOD).sin();
        [x[1], (u - c * x[1] - k * x[0] - cog) / m]
    };
    let mut x = [0.0, 0.0];
    let h = ts / 20.0;
    let mut y = Vec::with_capacity(len);
    for &uk in &u {
        y.push(x[0] + 0.005 * n.sample(&mut rng));
        for _ in 0..20 {
            let k1 = f(x, uk);
            let k2 = f([x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1]], uk);
            let k3 = f([x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1]], uk);
            let k4 = f([x[0] + h * k3[0], x[1] + h * k3[1]], uk);
            x[0] += h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]);
            x[1] += h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]);
        }
    }
    let sig = |v: &[f64]| Signal::from_fn(v.len(), 1, |k, _| v[k]);
    Data::new(sig(&u), sig(&y)).unwrap()
}

#[test]
fn a_cogging_force_is_placed_in_feedback_from_y_and_its_period_kept() {
    let est = record(1, 4000, 60.0);
    let val = record(2, 4000, 66.0);
    let nominal = oe(
        est.u(),
        est.y(),
        &Orders::siso(2, 2, 1),
        &OeSettings::builder().sample_time(0.01).build().unwrap(),
    )
    .unwrap()
    .model;
    let d = discover(
        &Nominal::from_polynomial(&nominal).unwrap(),
        &est,
        &val,
        &DiscoverSettings::default(),
    )
    .unwrap();
    assert_eq!(d.verdict_kind, Verdict::MissingEffect, "{}", d.verdict);
    let f = d.finding.as_ref().unwrap();
    assert!(
        f.location == Site::OutputFeedback
            || f.equivalent_locations.contains(&Site::OutputFeedback),
        "found at {}",
        f.location.name()
    );
    assert!(f.shrink >= 2.0, "shrink {:.2}", f.shrink);
    // The written model validates as well as the hypothesis it came from.
    assert!(
        f.augmented.validation_gap.rms <= 1.05 * f.hypothesis.validation_rms,
        "augmented {} against the hypothesis' {}",
        f.augmented.validation_gap.rms,
        f.hypothesis.validation_rms
    );
    // The table, with its straight-line trend removed over the estimation range of y,
    // follows the cogging force.
    let AugmentedMap::Table { z, w } = &f.augmented.map else {
        panic!(
            "a periodic force has no family, yet it was named: {:?}",
            f.augmented.map
        );
    };
    let y = est.y().channel(0);
    let (lo, hi) = y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let inside: Vec<(f64, f64)> = z
        .iter()
        .zip(w)
        .filter(|(z, _)| **z >= lo && **z <= hi)
        .map(|(z, w)| (*z, *w))
        .collect();
    let n = inside.len() as f64;
    assert!(n >= 50.0, "{n} table points inside the range");
    let (mz, mw) = inside
        .iter()
        .fold((0.0, 0.0), |(a, b), (z, w)| (a + z / n, b + w / n));
    let slope = inside.iter().map(|(z, w)| (z - mz) * (w - mw)).sum::<f64>()
        / inside.iter().map(|(z, _)| (z - mz).powi(2)).sum::<f64>();
    let detrended: Vec<f64> = inside
        .iter()
        .map(|(z, w)| w - mw - slope * (z - mz))
        .collect();
    let truth: Vec<f64> = inside
        .iter()
        .map(|(z, _)| COGGING * (std::f64::consts::TAU * z / PERIOD).sin())
        .collect();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let correlation =
        dot(&detrended, &truth) / (dot(&detrended, &detrended) * dot(&truth, &truth)).sqrt();
    eprintln!(
        "cogging force: {} at {}, validation RMS {:.4e} → {:.4e} ({:.1}× smaller), table \
         correlation with the force {correlation:.3}",
        f.classification.describe(),
        f.location.name(),
        d.validation_gap.rms,
        f.augmented.validation_gap.rms,
        f.shrink
    );
    assert!(
        correlation > 0.7,
        "correlation with the cogging force {correlation:.3}"
    );
}
