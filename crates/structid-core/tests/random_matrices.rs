//! Stable-toolchain robustness harness for `Lft::new` and `Problem::new`: seeded random byte
//! strings are decoded into small matrices and records (NaN, ±∞, huge and subnormal entries,
//! shapes off by one) and driven through the same entry point as the fuzz target
//! `lft_problem` (`fuzz/`, see FUZZING.md). Errors are fine; a panic is not, and every error
//! must say something.

mod fuzz_entry;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::{Duration, Instant};

use structid_lti::testing::SplitMix64;

/// Random inputs tried (fewer in debug builds, where the solver is much slower); the
/// environment variable `STRUCTID_HARNESS_CASES` overrides it.
const CASES: usize = if cfg!(debug_assertions) {
    3_000
} else {
    30_000
};
/// Wall-clock budget: the loop stops early past it, so the test stays bounded on a busy machine.
const BUDGET: Duration = Duration::from_secs(8);

/// The seed, the number of cases and the time budget: the defaults, or the environment
/// variables `STRUCTID_HARNESS_SEED` and `STRUCTID_HARNESS_CASES` (a longer run: the budget
/// then grows with the cases).
fn settings() -> (u64, usize, Duration) {
    let var = |name: &str| std::env::var(name).ok().and_then(|v| v.parse::<u64>().ok());
    let seed = var("STRUCTID_HARNESS_SEED").unwrap_or(0x05ee_d1f7);
    match var("STRUCTID_HARNESS_CASES") {
        Some(n) => (seed, n as usize, Duration::from_secs(3_600)),
        None => (seed, CASES, BUDGET),
    }
}

fn random_bytes(rng: &mut SplitMix64) -> Vec<u8> {
    let len = (rng.next_u64() % 512) as usize;
    (0..len).map(|_| rng.next_u64() as u8).collect()
}

#[test]
fn random_lft_matrices_and_problems_never_panic() {
    let start = Instant::now();
    let (seed, cases, budget) = settings();
    let mut rng = SplitMix64::new(seed);
    let (mut tried, mut errors, mut lfts, mut problems, mut solved) = (0, 0, 0, 0, 0);
    for case in 0..cases {
        if start.elapsed() > budget {
            break;
        }
        let bytes = random_bytes(&mut rng);
        let outcome = catch_unwind(AssertUnwindSafe(|| fuzz_entry::lft_and_problem(&bytes)));
        let outcome = outcome.unwrap_or_else(|_| {
            panic!("Lft::new / Problem::new panicked on case {case}, bytes {bytes:?}")
        });
        for m in &outcome.errors {
            assert!(
                !m.trim().is_empty(),
                "an error without a message on case {case}, bytes {bytes:?}"
            );
        }
        errors += outcome.errors.len();
        lfts += usize::from(outcome.lft);
        problems += usize::from(outcome.problem);
        solved += outcome.solved;
        tried += 1;
    }
    eprintln!(
        "{tried} cases in {:.2} s: {lfts} LFTs and {problems} problems built, {solved} \
         identifications, {errors} errors",
        start.elapsed().as_secs_f64()
    );
    assert!(
        tried >= cases.min(500),
        "only {tried} cases ran in the time budget"
    );
    assert!(
        errors > 0,
        "no input was rejected: the decoder is not exercising the checks"
    );
    assert!(
        lfts > 0 && problems > 0 && solved > 0,
        "the decoder never reaches the solver: {lfts} LFTs, {problems} problems, {solved} solved"
    );
}
