//! The whole discovery workflow on a 25 000-sample record (the target: at most 30 s).
//!
//! The case is `structid_testcases::physics` static case 0 drawn at 25 000 samples per record
//! (`generate_with_length`): a non-minimum-phase second-order plant simulated in continuous
//! time and sampled, an actuator saturation at its input, the exact nominal model; the
//! workflow names the saturation and shrinks the validation gap about 8×. One iteration is `discover`
//! with its default settings: the gap of the nominal model on both records, every default
//! location identified on the estimation record and ranked on the validation record, total
//! variation where the smooth estimates call for it, the direction test, the naming and the
//! augmented model's gap. Drawing the case is not timed. A second benchmark times dynamic
//! case 0 drawn alike (a backlash at the actuator behind a nominal estimated from the record),
//! the path that also fits a hysteresis at the input with G.
//!
//! The same static case drawn at 5000 samples per record is timed too (the speed goal of
//! discovery: at most 10 s in the median).
//!
//! Run: `cargo bench -j 1 -p structid-benchmarks --bench discover_25k`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, SamplingMode, criterion_group, criterion_main};
use structid_discover::discover::{DiscoverSettings, discover};
use structid_discover::hypotheses::Nominal;
use structid_testcases::physics::{PhysicsKind, generate_with_length};

/// Samples per record.
const SAMPLES: usize = 25_000;
/// Samples per record of the case the speed goal on 5000 samples is timed on.
const SHORT: usize = 5_000;

fn bench(c: &mut Criterion) {
    let case = generate_with_length(PhysicsKind::Static, 0, SAMPLES);
    let nominal = Nominal::from_polynomial(&case.nominal).expect("the nominal model is valid");
    let settings = DiscoverSettings::default();
    let short = generate_with_length(PhysicsKind::Static, 0, SHORT);
    let short_nominal =
        Nominal::from_polynomial(&short.nominal).expect("the nominal model is valid");
    let mut group = c.benchmark_group("discover");
    // One run takes seconds: 10 samples of one iteration each (flat sampling).
    group
        .sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .measurement_time(Duration::from_secs(60))
        .warm_up_time(Duration::from_secs(1));
    group.bench_function("physics_static_0_5k_samples", |b| {
        b.iter(|| {
            let d = discover(
                &short_nominal,
                &short.estimation,
                &short.validation,
                &settings,
            )
            .expect("discovery runs");
            black_box((d.verdict_kind, d.hypotheses.len()))
        })
    });
    group.bench_function("physics_static_0_25k_samples", |b| {
        b.iter(|| {
            let d = discover(&nominal, &case.estimation, &case.validation, &settings)
                .expect("discovery runs");
            black_box((d.verdict_kind, d.hypotheses.len()))
        })
    });
    // The slowest path: a backlash at the actuator behind a nominal estimated from its own
    // record, where no static block explains the gap and the hysteresis at the input is
    // fitted with G (a threshold search with output-error fits of G at each point).
    let dynamic = generate_with_length(PhysicsKind::Dynamic, 0, SAMPLES);
    let dynamic_nominal =
        Nominal::from_polynomial(&dynamic.nominal).expect("the nominal model is valid");
    group.bench_function("physics_dynamic_0_25k_samples", |b| {
        b.iter(|| {
            let d = discover(
                &dynamic_nominal,
                &dynamic.estimation,
                &dynamic.validation,
                &settings,
            )
            .expect("discovery runs");
            black_box((d.verdict_kind, d.hypotheses.len()))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
