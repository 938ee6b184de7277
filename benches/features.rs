//! The feature-space solver against record length: SISO Hammerstein, 4th-order IIR L_yw,
//! coloured noise (Kalman-whitened), Fourier dispersion with m = 63 features.
//! Run: `cargo bench --bench features`. Figures go in BENCHMARKS.md.
//!
//! The group `matmul` measures faer's matrix product in the same run, as the machine's
//! practical peak for the pass's GFLOP/s: `square/1024` is C = A·B with n = 1024 (2n³ flop) on
//! the global thread pool, `gram_chunk` the pass's own shape, G += XᵀX with X of 2048 × 65
//! (2·2048·65² flop, one thread).

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use structid::scenarios;

mod common;

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("features");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10))
        .warm_up_time(Duration::from_secs(1));
    for len in [10_000usize, 100_000, 1_000_000] {
        let (exp, settings) = scenarios::feature_benchmark(len).unwrap();
        common::bench_identify(&mut group, "identify", len, &exp, &settings);
    }
    group.finish();

    let mut group = c.benchmark_group("matmul");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(5))
        .warm_up_time(Duration::from_secs(1));
    let n = 1024;
    let a = Mat::<f64>::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 13) as f64 - 6.0);
    let b = Mat::<f64>::from_fn(n, n, |i, j| ((i * 5 + j * 11) % 17) as f64 - 8.0);
    let mut out = Mat::<f64>::zeros(n, n);
    group.bench_function(BenchmarkId::new("square", n), |bch| {
        bch.iter(|| {
            matmul(
                out.as_mut(),
                Accum::Replace,
                a.as_ref(),
                b.as_ref(),
                1.0,
                faer::get_global_parallelism(),
            );
            black_box(out[(0, 0)])
        })
    });
    let x = Mat::<f64>::from_fn(2048, 65, |i, j| ((i * 7 + j * 3) % 13) as f64 - 6.0);
    let mut g = Mat::<f64>::zeros(65, 65);
    group.bench_function("gram_chunk", |bch| {
        bch.iter(|| {
            matmul(
                g.as_mut(),
                Accum::Replace,
                x.transpose(),
                x.as_ref(),
                1.0,
                Par::Seq,
            );
            black_box(g[(0, 0)])
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
