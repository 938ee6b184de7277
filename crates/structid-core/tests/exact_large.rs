//! The exact Gaussian path on a record past the size that used to overflow the stack.
//!
//! The parallel Gram fill split its columns at a fixed share of the whole range, so a range far
//! from column 0 was peeled one column at a time: about 24 000 frames deep at L = 12 000, which
//! overflowed the (default-sized) stack of a rayon worker from about 11 000 samples. This test
//! runs at L = 12 000 with the default stack, in release mode, and checks the estimate too.

use std::sync::Arc;

use structid_core::scenarios::hammerstein;
use structid_core::*;

#[test]
fn exact_gaussian_identification_runs_at_twelve_thousand_samples() {
    // y = G·tanh(u) + e with a first-order G, noise 1e-3.
    let len = 12_000;
    let exp = hammerstein(
        len,
        1,
        1e-3,
        Arc::new(KernelDispersion::new(GaussianKernel::new(0.3).unwrap())),
        5,
    )
    .unwrap();
    let settings = IdentifySettings::builder()
        .beta(1e-6)
        .solver(SolverChoice::Exact)
        .build()
        .unwrap();
    let id = identify(&exp.model, &exp.data, &settings).unwrap();
    assert_eq!(id.diagnostics.system_size, len);
    // ŵ recovers tanh(u) to well within the map's range (the noise is 1e-3).
    let w = &id.blocks[0].w_hat;
    let worst = (0..len)
        .map(|k| (w[k] - exp.w_true.get(k, 0)).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.05, "largest error of ŵ {worst}");
}
