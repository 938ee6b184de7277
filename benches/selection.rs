//! Automatic β against one fixed-β fit (the targets: feature path at L = 10⁶ with
//! m = 63 features within 2×, dense path at L = 2000 within 5×). Both are measured in the same
//! run, so their ratio is meaningful on a shared machine. The last group is the paper's spray
//! example (L = 2000, two Gaussian blocks) with β and σ automatic, as
//! `structid demo spray && structid identify … --beta auto --sigma auto` runs it.
//! Run: `cargo bench --bench selection`. Figures go in BENCHMARKS.md.

use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use structid::selection::{SelectionSettings, select};
use structid::{
    FourierDispersion, FourierWeights, IdentifySettings, KernelDispersion, SolverChoice, identify,
    paper, scenarios,
};

fn bench(c: &mut Criterion) {
    let how = SelectionSettings::default();

    let mut group = c.benchmark_group("selection_features");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20))
        .warm_up_time(Duration::from_secs(1));
    let disp = Arc::new(
        FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.2 })
            .unwrap()
            .with_harmonics(31),
    );
    let features = IdentifySettings::builder()
        .beta(1e-4)
        .solver(SolverChoice::Features)
        .build()
        .unwrap();
    let exp = scenarios::hammerstein(1_000_000, 4, 0.3, disp, 11).unwrap();
    group.bench_function("fixed_beta/1000000", |b| {
        b.iter(|| {
            black_box(
                identify(&exp.model, &exp.data, &features)
                    .unwrap()
                    .cost
                    .total,
            )
        })
    });
    group.bench_function("auto_beta/1000000", |b| {
        b.iter(|| {
            black_box(
                select(&exp.model, &exp.data, None, &features, &how)
                    .unwrap()
                    .beta,
            )
        })
    });
    group.finish();

    let mut group = c.benchmark_group("selection_dense");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20))
        .warm_up_time(Duration::from_secs(1));
    let exact = IdentifySettings::builder()
        .beta(1e-2)
        .solver(SolverChoice::Exact)
        .build()
        .unwrap();
    let exp = scenarios::hammerstein(
        2000,
        4,
        0.3,
        Arc::new(KernelDispersion::gaussian(0.3).unwrap()),
        11,
    )
    .unwrap();
    group.bench_function("fixed_beta/2000", |b| {
        b.iter(|| black_box(identify(&exp.model, &exp.data, &exact).unwrap().cost.total))
    });
    group.bench_function("auto_beta/2000", |b| {
        b.iter(|| {
            black_box(
                select(&exp.model, &exp.data, None, &exact, &how)
                    .unwrap()
                    .beta,
            )
        })
    });
    group.finish();
}

fn spray(c: &mut Criterion) {
    let mut group = c.benchmark_group("selection_spray");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20))
        .warm_up_time(Duration::from_secs(1));
    // the data of `structid demo spray` (L = 2000, noise std 1, σ = 0.1, seed 1)
    let exp = paper::spray(2000, 1.0, paper::gaussian(0.1).unwrap(), 1).unwrap();
    let settings = IdentifySettings::default();
    let how = SelectionSettings::builder()
        .tune_sigma(true)
        .build()
        .unwrap();
    group.bench_function("fixed_beta/2000", |b| {
        let fixed = settings.with_beta(1e-2).unwrap();
        b.iter(|| black_box(identify(&exp.model, &exp.data, &fixed).unwrap().cost.total))
    });
    group.bench_function("auto_beta_sigma/2000", |b| {
        b.iter(|| {
            let sel = select(&exp.model, &exp.data, None, &settings, &how).unwrap();
            black_box((sel.beta, sel.sigma))
        })
    });
    group.finish();
}

criterion_group!(benches, bench, spray);
criterion_main!(benches);
