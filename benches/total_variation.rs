//! Total-variation identification: the conic solver (Clarabel) and ADMM against record length.
//! SISO Hammerstein with a 2nd-order IIR block and a relay map, noise std 0.1, β = 0.01, with a
//! white-noise input and with a sinusoidal input (3 periods).
//! Run: `cargo bench --bench total_variation`. Figures go in BENCHMARKS.md.
//! White-noise Clarabel at L = 4000 and 8000:
//! `cargo run --release --example tv_scaling -- clarabel white 4000 8000`.
//!
//! Further groups (select one with `cargo bench --bench total_variation -- <group>`):
//! * `tv_admm_million`: ADMM at L = 10⁶, white input;
//! * `mixed_admm`: a Gaussian (or Gaussian-like Fourier) block and a total-variation block
//!   behind a random 2-input block ([`structid::scenarios::mixed_hammerstein`]), ADMM at
//!   L = 10⁴ and 10⁵ (single runs: `cargo run --release --example mixed_scaling`);
//! * `tv_cv`: β by blocked 5-fold cross-validation at L = 2000, white input, solver auto
//!   (ADMM with held-out samples);
//! * `graph_tv_admm`: graph total variation (p = 2, k = 8), one block h(z) = 1[z₁ + z₂ > 0]
//!   behind a 2nd-order block ([`structid::scenarios::graph_hammerstein`]), white inputs, ADMM
//!   at L = 2000 and 2·10⁴.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use structid::scenarios::{Excitation, graph_hammerstein, mixed_hammerstein, relay_hammerstein};
use structid::selection::{Criterion as Cv, SelectionSettings, select};
use structid::{
    Dispersion, FourierDispersion, FourierWeights, IdentifySettings, KernelDispersion, SolverChoice,
};

mod common;

fn run(
    c: &mut Criterion,
    group_name: &str,
    solver: SolverChoice,
    white_lens: &[usize],
    sine_lens: &[usize],
) {
    let mut group = group(c, group_name);
    let settings = settings(solver);
    for (name, excitation, lens) in [
        ("white", Excitation::White, white_lens),
        ("sine", Excitation::Sine { periods: 3.0 }, sine_lens),
    ] {
        for &len in lens {
            let exp = relay_hammerstein(len, excitation).unwrap();
            common::bench_identify(&mut group, name, len, &exp, &settings);
        }
    }
    group.finish();
}

fn bench(c: &mut Criterion) {
    // Clarabel with a white-noise input takes ~30 s at L = 4000 and minutes at 8000, too long for
    // criterion's ten samples: those two are single runs of `examples/tv_scaling.rs`.
    run(
        c,
        "tv_clarabel",
        SolverChoice::Clarabel,
        &[1000, 2000],
        &[1000, 2000, 4000, 8000],
    );
    let admm_lens = [2000, 10_000, 100_000];
    run(c, "tv_admm", SolverChoice::Admm, &admm_lens, &admm_lens);
}

fn group<'a>(
    c: &'a mut Criterion,
    name: &str,
) -> criterion::BenchmarkGroup<'a, criterion::measurement::WallTime> {
    let mut g = c.benchmark_group(name);
    g.sample_size(10)
        .measurement_time(Duration::from_secs(5))
        .warm_up_time(Duration::from_millis(500));
    g
}

fn settings(solver: SolverChoice) -> IdentifySettings {
    IdentifySettings::builder()
        .beta(0.01)
        .solver(solver)
        .build()
        .unwrap()
}

/// TV by ADMM at L = 10⁶, white input.
fn bench_million(c: &mut Criterion) {
    let mut g = group(c, "tv_admm_million");
    let len = 1_000_000;
    let exp = relay_hammerstein(len, Excitation::White).unwrap();
    common::bench_identify(&mut g, "white", len, &exp, &settings(SolverChoice::Admm));
    g.finish();
}

/// Mixed models (quadratic + total variation) by ADMM.
fn bench_mixed(c: &mut Criterion) {
    let mut g = group(c, "mixed_admm");
    let s = settings(SolverChoice::Admm);
    let kinds: [(&str, Arc<dyn Dispersion>); 2] = [
        (
            "gaussian",
            Arc::new(KernelDispersion::gaussian(0.4).unwrap()),
        ),
        (
            "fourier",
            Arc::new(
                FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.4 })
                    .unwrap()
                    .with_harmonics(31),
            ),
        ),
    ];
    for (name, smooth) in kinds {
        for len in [10_000, 100_000] {
            let exp = mixed_hammerstein(len, Arc::clone(&smooth), 3).unwrap();
            common::bench_identify(&mut g, name, len, &exp, &s);
        }
    }
    g.finish();
}

/// β by blocked 5-fold cross-validation for total variation.
fn bench_cv(c: &mut Criterion) {
    let mut g = group(c, "tv_cv");
    let len = 2000;
    let exp = relay_hammerstein(len, Excitation::White).unwrap();
    let how = SelectionSettings::builder()
        .criterion(Cv::CrossValidation { folds: 5 })
        .build()
        .unwrap();
    let s = settings(SolverChoice::Auto);
    g.bench_with_input(BenchmarkId::new("white_5_folds", len), &len, |b, _| {
        b.iter(|| black_box(select(&exp.model, &exp.data, None, &s, &how).unwrap().beta))
    });
    g.finish();
}

/// Graph total variation (p = 2) by ADMM.
fn bench_graph(c: &mut Criterion) {
    let mut g = group(c, "graph_tv_admm");
    let s = settings(SolverChoice::Admm);
    for len in [2000, 20_000] {
        let exp = graph_hammerstein(len, 5).unwrap();
        common::bench_identify(&mut g, "white", len, &exp, &s);
    }
    g.finish();
}

criterion_group!(
    benches,
    bench,
    bench_million,
    bench_mixed,
    bench_cv,
    bench_graph
);
criterion_main!(benches);
