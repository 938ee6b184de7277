//! Deterministic helpers for tests and benchmarks (random stable systems and signals),
//! driven by a tiny internal SplitMix64 generator so that no `rand` dependency is needed.

use crate::signal::Signal;
use crate::state_space::StateSpace;
use nalgebra::DMatrix;

/// SplitMix64 pseudo-random generator (deterministic, not cryptographic).
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// Next raw 64-bit value.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform value in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform value in `[lo, hi)`.
    pub fn uniform_in(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
}

/// A random discrete-time system with `n` states whose spectral radius is at most
/// `max_radius` (it lies in `[max_radius / 2, max_radius]` unless `A` happens to be
/// nilpotent). Entries of `B`, `C`, `D` are uniform in `[-1, 1]`. Deterministic in `seed`.
///
/// Panics if `max_radius` is negative or not finite.
///
/// ```
/// use structid_lti::testing::random_stable_system;
/// let sys = random_stable_system(7, 4, 2, 3, 0.9);
/// assert_eq!((sys.order(), sys.inputs(), sys.outputs()), (4, 2, 3));
/// assert!(sys.spectral_radius() <= 0.9 + 1e-12);
/// ```
pub fn random_stable_system(
    seed: u64,
    n: usize,
    inputs: usize,
    outputs: usize,
    max_radius: f64,
) -> StateSpace {
    assert!(
        max_radius.is_finite() && max_radius >= 0.0,
        "max_radius must be finite and non-negative, got {max_radius}"
    );
    let mut rng = SplitMix64::new(seed);
    let mut gen_mat = |r: usize, c: usize| DMatrix::from_fn(r, c, |_, _| rng.uniform_in(-1.0, 1.0));
    let mut a = gen_mat(n, n);
    let b = gen_mat(n, inputs);
    let c = gen_mat(outputs, n);
    let d = gen_mat(outputs, inputs);
    let target = max_radius * rng.uniform_in(0.5, 1.0);
    if n > 0 {
        let rho = StateSpace::new(a.clone(), b.clone(), c.clone(), d.clone())
            .expect("finite random matrices")
            .spectral_radius();
        if rho > 1e-12 {
            // slightly below the target to absorb eigenvalue round-off
            a *= target / rho * (1.0 - 1e-12);
        } else {
            a *= 0.0;
        }
    }
    StateSpace::new(a, b, c, d).expect("finite random matrices")
}

/// A random signal with entries uniform in `[-1, 1]`, deterministic in `seed`.
pub fn random_signal(seed: u64, len: usize, channels: usize) -> Signal {
    let mut rng = SplitMix64::new(seed);
    Signal::from_fn(len, channels, |_, _| rng.uniform_in(-1.0, 1.0))
}
