//! Fuzz target: `Lft::new` and `Problem::new` from arbitrary small dimensions and f64 entries
//! (NaN, ±∞, huge, subnormal), and what follows construction (sub-systems, measurability, z,
//! simulation, `Problem::from_model`, a tiny identification).
//! Only a panic or a hang is a finding; errors are expected.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../../crates/structid-core/tests/fuzz_entry/mod.rs"]
mod fuzz_entry;

fuzz_target!(|data: &[u8]| {
    let _ = fuzz_entry::lft_and_problem(data);
});
