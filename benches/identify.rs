//! Exact Gaussian identification against its floor, a faer Cholesky of the same size.
//!
//! SISO Hammerstein with a 4th-order L_yw (`structid::scenarios::gaussian_benchmark`), L = 500,
//! 1000, 2000, 4000. Run: `cargo bench --bench identify`. Figures go in BENCHMARKS.md.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use structid::scenarios;

mod common;

fn random_spd(n: usize) -> faer::Mat<f64> {
    // Deterministic pseudo-random entries; A·Aᵀ + n·I is comfortably positive definite.
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let a = faer::Mat::<f64>::from_fn(n, n, |_, _| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    });
    &a * a.transpose() + faer::Mat::<f64>::identity(n, n) * (n as f64)
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("exact_gaussian");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(8))
        .warm_up_time(Duration::from_secs(1));
    for len in [500usize, 1000, 2000, 4000] {
        let (exp, settings) = scenarios::gaussian_benchmark(len).unwrap();
        common::bench_identify(&mut group, "identify", len, &exp, &settings);
        let spd = random_spd(len);
        group.bench_with_input(BenchmarkId::new("faer_llt", len), &len, |b, _| {
            b.iter(|| black_box(spd.llt(faer::Side::Lower).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
