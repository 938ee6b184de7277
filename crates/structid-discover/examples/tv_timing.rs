//! Timing of discovery, hypothesis by hypothesis, on records of a given length.
//!
//! `cargo run --release -p structid-discover --example tv_timing -- LEN SEED...`
//!
//! A seed below 1000 is a static case of `synthetic::generate` whose estimation record is
//! stretched to LEN samples (both of its inputs end to end, repeated, simulated afresh with
//! new noise); a seed of 1000 or more is a nearly integrating plant k/(s·(M·s + F)) (pole
//! 0.999) with Coulomb + viscous friction in rate feedback. Prints the total time and, per
//! hypothesis, its dispersion, β, seconds, validation RMS and failure.

use std::time::Instant;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_core::{Data, Signal};
use structid_discover::discover::{DiscoverSettings, discover};
use structid_discover::effects::Effect;
use structid_discover::hypotheses::Nominal;
use structid_discover::hypotheses::Site;
use structid_linear::PolynomialModel;
use structid_testcases::synthetic::{Case, CaseKind, Hidden, InputKind, generate};

/// A nearly integrating plant k/(s·(M·s + F)) (integrator pole at 0.999) with Coulomb +
/// viscous friction in rate feedback, driven by low-pass noise.
fn integrator(seed: u64) -> Case {
    let ts: f64 = 0.01;
    let (k, m, f): (f64, f64, f64) = (1.0, 1.0, 0.5);
    let p2 = (-f / m * ts).exp();
    // ZOH of k/(s(Ms+F)) approximately: b1 = b2 = k·T²/(2M).
    let b = k * ts * ts / (2.0 * m);
    let g = PolynomialModel {
        den: vec![1.0, -(0.999 + p2), 0.999 * p2],
        num: vec![vec![0.0, b, b]],
        sample_time: Some(ts),
    };
    let mut rng = StdRng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let mut record = |len: usize| -> Vec<f64> {
        let mut x = 0.0;
        (0..len)
            .map(|_| {
                x = 0.98 * x + 0.2 * n.sample(&mut rng);
                x
            })
            .collect()
    };
    let len = 3000;
    let (ue, uv) = (record(len), record(len));
    let hidden = Hidden::Static {
        effect: Effect::CoulombViscous,
        theta: vec![0.3, 0.05],
        location: Site::RateFeedback,
    };
    let y0 = hidden.simulate(&g, &ue, None).unwrap();
    let sd = (y0.iter().map(|v| v * v).sum::<f64>() / len as f64).sqrt();
    let noise_std = 0.01 * sd;
    let noise = Normal::new(0.0, noise_std).unwrap();
    let ee: Vec<f64> = (0..len).map(|_| noise.sample(&mut rng)).collect();
    let ev: Vec<f64> = (0..len).map(|_| noise.sample(&mut rng)).collect();
    let data = |u: &[f64], e: &[f64]| {
        let y = hidden.simulate(&g, u, Some(e)).unwrap();
        Data::new(
            Signal::from_fn(len, 1, |k, _| u[k]),
            Signal::from_fn(len, 1, |k, _| y[k]),
        )
        .unwrap()
    };
    Case {
        seed,
        nominal: g.clone(),
        hidden: hidden.clone(),
        input: InputKind::FilteredNoise,
        noise_std,
        estimation: data(&ue, &ee),
        validation: data(&uv, &ev),
        estimation_noise: ee,
        validation_noise: ev,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let len: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(5000);
    let seeds: Vec<u64> = args[2..].iter().filter_map(|s| s.parse().ok()).collect();
    for seed in seeds {
        let case = if seed >= 1000 {
            integrator(seed)
        } else {
            generate(CaseKind::Static, seed)
        };
        // The estimation record stretched to `len` samples: both inputs end to end, repeated.
        let mut u: Vec<f64> = case.estimation.u().channel(0);
        u.extend(case.validation.u().channel(0));
        let base = u.clone();
        while u.len() < len {
            u.extend(&base);
        }
        u.truncate(len);
        let mut rng = StdRng::seed_from_u64(seed + 1000);
        let normal = Normal::new(0.0, case.noise_std).unwrap();
        let e: Vec<f64> = (0..len).map(|_| normal.sample(&mut rng)).collect();
        let y = case.hidden.simulate(&case.nominal, &u, Some(&e)).unwrap();
        let est = Data::new(
            Signal::from_fn(len, 1, |k, _| u[k]),
            Signal::from_fn(len, 1, |k, _| y[k]),
        )
        .unwrap();
        let nominal = Nominal::from_polynomial(&case.nominal).unwrap();
        let t = Instant::now();
        let d = discover(
            &nominal,
            &est,
            &case.validation,
            &DiscoverSettings::default(),
        )
        .unwrap();
        println!(
            "seed {seed}: {:?} L = {len}: {:.2} s total; {}",
            case.hidden,
            t.elapsed().as_secs_f64(),
            d.finding
                .as_ref()
                .map(|f| f.classification.describe())
                .unwrap_or_else(|| "nothing".into())
        );
        for h in &d.hypotheses {
            println!(
                "   {:<16} {:<40} β {:.3e} {:6.2} s val {:.3e} {}",
                h.location.name(),
                h.dispersion,
                h.beta,
                h.seconds,
                h.validation_rms,
                h.failure.clone().unwrap_or_default()
            );
        }
    }
}
