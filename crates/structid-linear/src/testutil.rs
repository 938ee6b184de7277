//! Helpers shared by the unit tests.

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_lti::Signal;

/// Gaussian white noise of standard deviation `std`, `channels` channels, deterministic in `seed`.
pub(crate) fn white(seed: u64, len: usize, std: f64, channels: usize) -> Signal {
    let mut rng = StdRng::seed_from_u64(seed);
    let normal = Normal::new(0.0, std).expect("valid std");
    Signal::from_fn(len, channels, |_, _| normal.sample(&mut rng))
}

/// Asserts `|a_i − b_i| ≤ tol` for every entry.
pub(crate) fn assert_close(a: &[f64], b: &[f64], tol: f64) {
    assert_eq!(a.len(), b.len(), "lengths differ: {a:?} vs {b:?}");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol,
            "entry {i}: {x} vs {y} (tol {tol}); {a:?} vs {b:?}"
        );
    }
}
