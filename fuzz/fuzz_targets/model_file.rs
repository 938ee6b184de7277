//! Fuzz target: the model-file parser and the model builder (`ModelFile::parse`, `to_model`, truth maps, simulation, `to_toml_string`).
//! Only a panic or a hang is a finding; errors are expected.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../../crates/structid-io/tests/fuzz_entry/mod.rs"]
mod fuzz_entry;

fuzz_target!(|data: &[u8]| {
    let _ = fuzz_entry::model_file(data);
});
