//! The discovery workflow on the Silverbox estimation split (the target: at most 60 s
//! for the 65k-sample split over all default locations).
//!
//! One iteration is `structid_benchmarks::silverbox_discovery::run` with its default settings: the
//! second-order BLA on the fitting part (52 050 samples), then `discover` over the four default
//! locations (each identified on the fitting part and ranked on the 13 012 validation
//! samples), the naming of the effect and the simulation of the three test splits. The
//! Silverbox file is found as by the tests (`$STRUCTID_DATA`, else `../shared/data` beside
//! the workspace); when it is missing the benchmark prints a message and measures nothing.
//!
//! Run: `cargo bench --bench discover`. Figures go in BENCHMARKS.md; the split of the time
//! between the BLA and `discover` comes from `cargo run --release --example
//! silverbox_discovery`.

#[path = "../../structid-io/tests/common/mod.rs"]
mod common;

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, SamplingMode, criterion_group, criterion_main};
use structid::io::Silverbox;
use structid_benchmarks::silverbox_discovery::{SilverboxDiscoverySettings, run};

fn bench(c: &mut Criterion) {
    let path = common::data_dir().join("silverbox/SNLS80mV.csv");
    if !path.is_file() {
        eprintln!(
            "skipping the discover benchmark: {} not found (set STRUCTID_DATA to the directory \
             holding silverbox/)",
            path.display()
        );
        return;
    }
    let sb = Silverbox::load(&path).expect("the Silverbox file loads");
    let settings = SilverboxDiscoverySettings::default();
    let mut group = c.benchmark_group("discover");
    // One run takes seconds: 10 samples of one iteration each (flat sampling; criterion's
    // default linear sampling would run 1 + 2 + … + 10 iterations).
    group
        .sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .measurement_time(Duration::from_secs(30))
        .warm_up_time(Duration::from_secs(1));
    group.bench_function("silverbox_estimation_split", |b| {
        b.iter(|| {
            let r = run(&sb, &settings).expect("discovery runs");
            black_box((
                r.bla_seconds,
                r.discover_seconds,
                r.discovery.missing_effect,
            ))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
