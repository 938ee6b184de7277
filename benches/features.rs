//! The feature-space solver against record length: SISO Hammerstein, 4th-order IIR L_yw,
//! coloured noise (Kalman-whitened), Fourier dispersion with m = 63 features.
//! Run: `cargo bench --bench features`. Figures go in BENCHMARKS.md.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use structid::{
    FourierDispersion, FourierWeights, IdentifySettings, SolverChoice, identify, scenarios,
};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("features");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10))
        .warm_up_time(Duration::from_secs(1));
    let disp = Arc::new(
        FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.2 })
            .unwrap()
            .with_harmonics(31),
    );
    let settings = IdentifySettings::builder()
        .beta(1e-4)
        .solver(SolverChoice::Features)
        .build()
        .unwrap();
    for len in [10_000usize, 100_000, 1_000_000] {
        let exp = scenarios::hammerstein_coloured(len, 4, 0.3, disp.clone(), 11).unwrap();
        group.bench_with_input(BenchmarkId::new("identify", len), &len, |b, _| {
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
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
