//! The linear-operator kernels behind the solvers.
//!
//! * `apply_columns`: the blocked Toeplitz recursion on an L × L operand (L = 4000, order 4,
//!   SISO), as the exact solver uses it (a transposed, i.e. row-major, operand).
//! * `whiten_columns`: Kalman whitening of L = 10⁶ samples × 64 columns (order 4, two noise
//!   channels), as the feature-space solver will use it.
//!
//! Run: `cargo bench --bench operators`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use faer::{Accum, Mat};
use structid::lti::testing::random_stable_system;
use structid::lti::{KalmanWhitener, LinearSystem, WhiteningOptions};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("operators");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(6))
        .warm_up_time(Duration::from_secs(1));

    let len = 4000;
    let sys = random_stable_system(1, 4, 1, 1, 0.95);
    let q = Mat::<f64>::from_fn(len, len, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
    let mut out = Mat::<f64>::zeros(len, len);
    group.bench_function("apply_columns/4000x4000_transposed", |b| {
        b.iter(|| {
            sys.apply_columns(
                black_box(q.as_ref().transpose()),
                out.as_mut(),
                Accum::Replace,
                1.0,
            )
        })
    });
    drop((q, out));

    let (len, m) = (1_000_000usize, 64usize);
    let noise = random_stable_system(7, 4, 2, 1, 0.9);
    let whitener = KalmanWhitener::new(&noise, len, &WhiteningOptions::default()).unwrap();
    let x = Mat::<f64>::from_fn(len, m, |i, j| ((i * 7 + j * 13) % 17) as f64 - 8.0);
    let mut out = Mat::<f64>::zeros(len, m);
    group.bench_function("whiten_columns/1e6x64", |b| {
        b.iter(|| whitener.whiten_columns(black_box(x.as_ref()), out.as_mut()))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
