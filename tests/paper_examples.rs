//! The paper's examples (section 6), end to end through the facade crate.

use std::sync::Arc;

use structid::paper::{multi_input, multi_input_map, spray, spray_f, spray_g};
use structid::validation::metrics::{centred_rms_difference, rms, rms_difference};
use structid::{IdentifySettings, KernelDispersion, identify};

/// Centred RMS errors of f̂ and ĝ at the data points (f and g share an unidentifiable constant).
fn spray_errors(len: usize, beta: f64, sigma: f64, seed: u64) -> (f64, f64) {
    let exp = spray(
        len,
        1.0,
        Arc::new(KernelDispersion::gaussian(sigma).unwrap()),
        seed,
    )
    .unwrap();
    let settings = IdentifySettings::builder().beta(beta).build().unwrap();
    let id = identify(&exp.model, &exp.data, &settings).unwrap();
    assert!(id.diagnostics.feasibility_residual < 1e-9);
    let z = exp.data.u().channel(0);
    let f: Vec<f64> = z.iter().map(|&v| spray_f(v)).collect();
    let g: Vec<f64> = z.iter().map(|&v| spray_g(v)).collect();
    (
        centred_rms_difference(&id.blocks[0].w_hat, &f),
        centred_rms_difference(&id.blocks[1].w_hat, &g),
    )
}

/// Consistency: at fixed β and σ, the map errors fall as L grows from 500 to 4000.
#[test]
fn spray_estimates_improve_with_record_length() {
    let (beta, sigma) = (0.01, 0.1);
    for seed in [2006u64, 11] {
        let errs: Vec<(f64, f64)> = [500, 1000, 2000, 4000]
            .iter()
            .map(|&l| spray_errors(l, beta, sigma, seed))
            .collect();
        eprintln!("seed {seed}: (rms f, rms g) for L = 500, 1000, 2000, 4000: {errs:?}");
        let (f500, g500) = errs[0];
        let (f4000, g4000) = errs[3];
        assert!(f4000 < 0.8 * f500, "f: {f500} → {f4000}");
        assert!(g4000 < 0.8 * g500, "g: {g500} → {g4000}");
        // The noise is N(0, 1) and the maps span about 1.5, so 4000 samples must do far better
        // than predicting zero.
        assert!(
            f4000 < 0.25 && g4000 < 0.25,
            "L = 4000 errors too large: {f4000}, {g4000}"
        );
    }
}

/// The multi-input example recovers a two-input map far below its own scale.
#[test]
fn multi_input_map_is_recovered() {
    let exp = multi_input(
        1500,
        1.0,
        Arc::new(KernelDispersion::gaussian(0.5).unwrap()),
        62,
    )
    .unwrap();
    let settings = IdentifySettings::builder().beta(0.01).build().unwrap();
    let id = identify(&exp.model, &exp.data, &settings).unwrap();
    let b = &id.blocks[0];
    let truth: Vec<f64> = (0..b.z.len())
        .map(|k| multi_input_map(b.z.sample(k)))
        .collect();
    let err = rms_difference(&b.w_hat, &truth);
    assert!(
        err < 0.3 * rms(&truth),
        "RMS error {err} vs map RMS {}",
        rms(&truth)
    );
    // Off the data too: a grid inside the input box.
    let mut worst: f64 = 0.0;
    for a in [-1.5, -0.5, 0.0, 0.7, 1.4] {
        for c in [-1.4, -0.3, 0.0, 0.9, 1.5] {
            worst = worst.max((b.predict(&[a, c]) - multi_input_map(&[a, c])).abs());
        }
    }
    assert!(worst < 0.35, "worst grid error {worst}");
}
