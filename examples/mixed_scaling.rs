//! Mixed models at scale: y = G₁·tanh(u₁) + G₂·relay(u₂) + e with a random stable 2-input
//! 2nd-order block, white inputs, noise std 0.05, β = 0.01; the smooth block has a Gaussian
//! (σ = 0.4) or a Gaussian-like Fourier dispersion, the relay block total variation. Prints
//! time, iterations, J and the solver per record length, and with `compare` the differences
//! from Clarabel.
//!
//! `cargo run --release --example mixed_scaling -- [admm|clarabel|auto] [gaussian|fourier] [compare] [L ...]`

use std::sync::Arc;
use std::time::Instant;

use structid::scenarios::mixed_hammerstein;
use structid::{
    Dispersion, FourierDispersion, FourierWeights, IdentifySettings, KernelDispersion,
    SolverChoice, identify,
};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let has = |s: &str| args.iter().any(|a| a == s);
    let solver = if has("clarabel") {
        SolverChoice::Clarabel
    } else if has("auto") {
        SolverChoice::Auto
    } else {
        SolverChoice::Admm
    };
    let smooth: Arc<dyn Dispersion> = if has("fourier") {
        Arc::new(
            FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.4 })
                .unwrap()
                .with_harmonics(31),
        )
    } else {
        Arc::new(KernelDispersion::gaussian(0.4).unwrap())
    };
    let sizes: Vec<usize> = args.iter().filter_map(|s| s.parse().ok()).collect();
    let sizes = if sizes.is_empty() {
        vec![10_000, 100_000]
    } else {
        sizes
    };
    let settings = IdentifySettings::builder()
        .beta(0.01)
        .solver(solver)
        .build()
        .unwrap();
    for len in sizes {
        let exp = mixed_hammerstein(len, Arc::clone(&smooth), 3).unwrap();
        let t = Instant::now();
        let id = identify(&exp.model, &exp.data, &settings).unwrap();
        let total = t.elapsed().as_secs_f64();
        let d = &id.diagnostics;
        print!(
            "L={len:>8} {} {}: {total:.3} s, {} iterations, J = {:.9e}, status {}, feas {:.1e}",
            d.solver,
            smooth.describe(),
            d.iterations,
            id.cost.total,
            d.status,
            d.feasibility_residual,
        );
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        print!(
            ", RMS ŵ {:.3}/{:.3}, D {:.3e}/{:.3e}",
            rms(&id.blocks[0].w_hat),
            rms(&id.blocks[1].w_hat),
            id.cost.dispersions[0],
            id.cost.dispersions[1]
        );
        if has("compare") {
            let c = identify(
                &exp.model,
                &exp.data,
                &settings.with_solver(SolverChoice::Clarabel),
            )
            .unwrap();
            let num: f64 = id
                .w_hat
                .as_slice()
                .iter()
                .zip(c.w_hat.as_slice())
                .map(|(a, b)| (a - b).powi(2))
                .sum();
            let den: f64 = c.w_hat.as_slice().iter().map(|b| b * b).sum();
            print!(
                "; clarabel {} ({}): relative ŵ difference {:.2e}, relative J difference {:.2e}",
                c.diagnostics.status,
                c.diagnostics.timings.total,
                (num / den).sqrt(),
                (id.cost.total - c.cost.total).abs() / c.cost.total.abs()
            );
        }
        println!();
        for w in &d.warnings {
            println!("  warning: {w}");
        }
    }
}
