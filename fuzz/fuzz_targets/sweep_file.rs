//! Fuzz target: the sweep configuration of `structid compare` (`SweepFile::parse`) and the dispersions it builds.
//! Only a panic or a hang is a finding; errors are expected.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../../crates/structid-io/tests/fuzz_entry/mod.rs"]
mod fuzz_entry;

fuzz_target!(|data: &[u8]| {
    let _ = fuzz_entry::sweep_file(data);
});
