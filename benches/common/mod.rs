//! What the identification benchmarks share.

use std::hint::black_box;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, BenchmarkId};
use structid::paper::Experiment;
use structid::{IdentifySettings, identify};

/// Times one identification of `exp` with `settings` as `name/len` in `group` (the cost is
/// kept so that the optimiser cannot drop the work).
pub fn bench_identify(
    group: &mut BenchmarkGroup<'_, WallTime>,
    name: &str,
    len: usize,
    exp: &Experiment,
    settings: &IdentifySettings,
) {
    group.bench_with_input(BenchmarkId::new(name, len), &len, |b, _| {
        b.iter(|| {
            black_box(
                identify(&exp.model, &exp.data, settings)
                    .unwrap()
                    .cost
                    .total,
            )
        })
    });
}
