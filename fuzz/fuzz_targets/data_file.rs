//! Fuzz target: the data-file (CSV) reader (`DataTable::parse_with` / `read_with` with fuzzed `CsvOptions`), column selection and lookup tables.
//! Only a panic or a hang is a finding; errors are expected.

#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../../crates/structid-io/tests/fuzz_entry/mod.rs"]
mod fuzz_entry;

fuzz_target!(|data: &[u8]| {
    let _ = fuzz_entry::data_file(data);
});
