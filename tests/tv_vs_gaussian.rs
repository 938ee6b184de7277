//! The research comparison of the total-variation issue: on maps with jumps total variation
//! beats the Gaussian dispersion, on smooth maps the Gaussian wins, each at its best β (the
//! Gaussian also at its best σ).
//!
//! Setup: SISO Hammerstein y = G(q)·N(u) + e, G a random stable 2nd-order IIR block, u white
//! on (−2, 2), noise std 0.1, L = 400, two seeds. The error is the RMS of N̂ − N on 201 points
//! spanning the 5–95 % quantiles of u (no extrapolation). The table printed by
//! `cargo test --release --test tv_vs_gaussian -- --nocapture` is the one in docs/benchmarks.md.

use std::sync::Arc;

use structid::scenarios::{Excitation, hammerstein_map};
use structid::{
    Dispersion, IdentifySettings, KernelDispersion, SolverChoice, TotalVariation, identify,
};

const LEN: usize = 400;
const SEEDS: [u64; 2] = [21, 22];
const BETAS: [f64; 11] = [
    1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1, 3e-1, 1.0,
];
const SIGMAS: [f64; 4] = [0.05, 0.1, 0.2, 0.4];

struct Case {
    name: &'static str,
    map: fn(f64) -> f64,
    jumps: bool,
}

fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "relay",
            map: |z| if z >= 0.3 { 1.0 } else { -0.5 },
            jumps: true,
        },
        Case {
            name: "Coulomb + viscous friction",
            map: |z| 0.8 * z.signum() + 0.3 * z,
            jumps: true,
        },
        Case {
            name: "quantiser (step 0.5)",
            map: |z| 0.5 * (z / 0.5).round(),
            jumps: true,
        },
        Case {
            name: "tanh",
            map: f64::tanh,
            jumps: false,
        },
        Case {
            name: "cubic",
            map: |z| 0.25 * z * z * z,
            jumps: false,
        },
    ]
}

/// Map RMS error of the best β (and, for `sigmas`, best σ) over the seeds' mean.
fn best_error(case: &Case, dispersions: &[Arc<dyn Dispersion>]) -> (f64, String) {
    let mut best = (f64::INFINITY, String::new());
    for d in dispersions {
        for &beta in &BETAS {
            let settings = IdentifySettings::builder()
                .beta(beta)
                .solver(SolverChoice::Auto)
                .build()
                .unwrap();
            let mut total = 0.0;
            for &seed in &SEEDS {
                let exp = hammerstein_map(
                    LEN,
                    2,
                    0.1,
                    &case.map,
                    Excitation::White,
                    Arc::clone(d),
                    seed,
                )
                .unwrap();
                let id = identify(&exp.model, &exp.data, &settings).unwrap();
                let mut u = exp.data.u().channel(0);
                u.sort_by(f64::total_cmp);
                let (lo, hi) = (u[LEN / 20], u[LEN - 1 - LEN / 20]);
                let grid: Vec<f64> = (0..201)
                    .map(|i| lo + (hi - lo) * i as f64 / 200.0)
                    .collect();
                let err: f64 = grid
                    .iter()
                    .map(|&z| (id.blocks[0].predict(&[z]) - (case.map)(z)).powi(2))
                    .sum::<f64>()
                    / grid.len() as f64;
                total += err.sqrt() / SEEDS.len() as f64;
            }
            if total < best.0 {
                best = (total, format!("{} β={beta}", d.describe()));
            }
        }
    }
    best
}

#[test]
fn total_variation_wins_on_jumps_and_the_gaussian_on_smooth_maps() {
    let gaussians: Vec<Arc<dyn Dispersion>> = SIGMAS
        .iter()
        .map(|&s| Arc::new(KernelDispersion::gaussian(s).unwrap()) as Arc<dyn Dispersion>)
        .collect();
    let tv: Vec<Arc<dyn Dispersion>> = vec![Arc::new(TotalVariation::new())];
    println!("| map | Gaussian (best σ, β) | TV (best β) | TV / Gaussian |");
    println!("|---|---|---|---|");
    let mut failures = Vec::new();
    for case in cases() {
        let (g, g_at) = best_error(&case, &gaussians);
        let (t, t_at) = best_error(&case, &tv);
        println!(
            "| {} | {g:.4} ({g_at}) | {t:.4} ({t_at}) | {:.2} |",
            case.name,
            t / g
        );
        // Margins: the winner is at least 15 % better.
        let ok = if case.jumps {
            t < 0.85 * g
        } else {
            g < 0.85 * t
        };
        if !ok {
            failures.push(format!("{}: TV {t:.4}, Gaussian {g:.4}", case.name));
        }
    }
    assert!(failures.is_empty(), "unexpected winners: {failures:?}");
}
