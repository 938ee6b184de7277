//! The feature-space solver at scale: SISO Hammerstein, 4th-order IIR L_yw, coloured noise
//! (H = (1 + 0.5q⁻¹)/(1 − 0.8q⁻¹), Kalman-whitened),
//! a Fourier dispersion with 31 harmonics (m = 63 features), L = 10⁴, 10⁵, 10⁶.
//!
//! `cargo run --release --example feature_scaling -- [L ...]`
//! Peak memory: `/usr/bin/time -v target/release/examples/feature_scaling 1000000`.

use std::time::Instant;

use structid::validation::metrics::rms_difference;
use structid::{identify, scenarios};

fn main() {
    let sizes: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|s| s.parse().ok())
        .collect();
    let sizes = if sizes.is_empty() {
        vec![10_000, 100_000, 1_000_000]
    } else {
        sizes
    };
    for len in sizes {
        let (exp, settings) = scenarios::feature_benchmark(len).unwrap();
        let t = Instant::now();
        let id = identify(&exp.model, &exp.data, &settings).unwrap();
        let total = t.elapsed().as_secs_f64();
        let d = &id.diagnostics;
        let err = rms_difference(&id.blocks[0].w_hat, &exp.w_true.channel(0));
        println!(
            "L={len:>8} {}: {total:.3} s (pass {:.3}, solve {:.4}, recover {:.3}); map RMS error {err:.4}; feas {:.1e}",
            d.solver, d.timings.assemble, d.timings.factor, d.timings.solve, d.feasibility_residual
        );
    }
}
