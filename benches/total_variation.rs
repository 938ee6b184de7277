//! Total-variation identification: the conic solver (Clarabel) and ADMM against record length.
//! SISO Hammerstein with a 2nd-order IIR block and a relay map, noise std 0.1, β = 0.01, with a
//! white-noise input and with a sinusoidal input (3 periods).
//! Run: `cargo bench --bench total_variation`. Figures go in BENCHMARKS.md.
//! White-noise Clarabel at L = 4000 and 8000:
//! `cargo run --release --example tv_scaling -- clarabel white 4000 8000`.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use structid::scenarios::{Excitation, hammerstein_map};
use structid::{IdentifySettings, SolverChoice, TotalVariation, identify};

fn relay(z: f64) -> f64 {
    if z >= 0.3 { 1.0 } else { -0.5 }
}

fn run(
    c: &mut Criterion,
    group_name: &str,
    solver: SolverChoice,
    white_lens: &[usize],
    sine_lens: &[usize],
) {
    let mut group = c.benchmark_group(group_name);
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5))
        .warm_up_time(Duration::from_millis(500));
    let settings = IdentifySettings::builder()
        .beta(0.01)
        .solver(solver)
        .build()
        .unwrap();
    for (name, excitation, lens) in [
        ("white", Excitation::White, white_lens),
        ("sine", Excitation::Sine { periods: 3.0 }, sine_lens),
    ] {
        for &len in lens {
            let exp = hammerstein_map(
                len,
                2,
                0.1,
                &relay,
                excitation,
                Arc::new(TotalVariation::new()),
                7,
            )
            .unwrap();
            group.bench_with_input(BenchmarkId::new(name, len), &len, |b, _| {
                b.iter(|| {
                    black_box(
                        identify(&exp.model, &exp.data, &settings)
                            .unwrap()
                            .cost
                            .total,
                    )
                })
            });
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

criterion_group!(benches, bench);
criterion_main!(benches);
