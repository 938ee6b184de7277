//! Times the exact Gaussian solver on the benchmark Hammerstein problem (SISO, 4th-order L_yw)
//! and a faer Cholesky of the same size, and prints the solver's own phase timings.
//!
//! `cargo run --release --example identify_timing -- 4000`
//! Peak memory: `/usr/bin/time -v target/release/examples/identify_timing 4000`.

use std::time::Instant;

use structid::{identify, scenarios};

fn main() {
    let len: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(2000);
    let only_identify = std::env::args().any(|a| a == "--identify-only");
    let (exp, settings) = scenarios::gaussian_benchmark(len).unwrap();
    for _ in 0..3 {
        let t = Instant::now();
        let id = identify(&exp.model, &exp.data, &settings).unwrap();
        let total = t.elapsed().as_secs_f64();
        let d = &id.diagnostics;
        println!(
            "L={len} identify {:.3}s (prepare {:.3} assemble {:.3} factor {:.3} solve {:.3}) feas {:.1e} J {:.5}",
            total,
            d.timings.prepare,
            d.timings.assemble,
            d.timings.factor,
            d.timings.solve,
            d.feasibility_residual,
            id.cost.total
        );
    }
    if only_identify {
        return;
    }
    let a = faer::Mat::<f64>::from_fn(len, len, |i, j| ((i * 7 + j * 13) % 17) as f64 / 17.0 - 0.5);
    let spd = &a * a.transpose() + faer::Mat::<f64>::identity(len, len) * (len as f64);
    for _ in 0..3 {
        let t = Instant::now();
        let llt = spd.llt(faer::Side::Lower).unwrap();
        std::hint::black_box(&llt);
        println!("L={len} faer llt {:.3}s", t.elapsed().as_secs_f64());
    }
}
