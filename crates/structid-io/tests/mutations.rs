//! Stable-toolchain robustness harness for the loaders: the repository's example model files,
//! CSV files and sweep configurations (`examples/`) and the fuzz seeds (`fuzz/seeds/`) are
//! mutated by a seeded generator (bit flips, byte and token insertions, deletions,
//! duplications, line swaps, splices) and run through the same entry points as the fuzz
//! targets `model_file`, `data_file` and `sweep_file` (see FUZZING.md). Errors are fine; a
//! panic is not, and every error must say something.

mod fuzz_entry;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use structid_lti::testing::SplitMix64;

/// Mutated inputs per loader (fewer in debug builds); the environment variable
/// `STRUCTID_HARNESS_CASES` overrides it.
const CASES: usize = if cfg!(debug_assertions) {
    1_500
} else {
    20_000
};
/// Wall-clock budget per loader: the loop stops early past it, so the test stays bounded on a
/// busy machine.
const BUDGET: Duration = Duration::from_secs(6);

/// Tokens that loaders must treat with care: non-finite and out-of-range numbers, empty and
/// nested arrays, quotes, comments, keys and table headers of the formats.
const TOKENS: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "+inf",
    "1e309",
    "-1e309",
    "5e-324",
    "-0",
    "0",
    "-1",
    "1.7976931348623157e308",
    "18446744073709551616",
    "9223372036854775807",
    "-9223372036854775808",
    "1_000",
    "0x10",
    "[]",
    "[[]]",
    "[[",
    "]]",
    "{}",
    "\"\"",
    "\"",
    "'",
    ",",
    ",,",
    "=",
    "#",
    "\n",
    "\r\n",
    "\t",
    " ",
    "true",
    "2024-01-01",
    "\u{feff}",
    "é",
    "[lft]",
    "[linear]",
    "[signals]",
    "[[nonlinearity]]",
    "[discover]",
    "[[experiment]]",
    "[[dispersion]]",
    "[experiment.simulate]",
    "A = [[1.0]]",
    "Dzw = [[1.0]]",
    "inputs = [0, 1]",
    "output = 1",
    "sigma = \"auto\"",
    "beta = [\"auto\"]",
    "seeds = 100000",
    "seeds = []",
    "den = [0.0]",
    "num = [[]]",
    "time = \"continuous\"",
    "sample_time = 0",
    "structure = \"lti\"",
    "kind = \"tv\"",
    "kind = \"polynomial\"",
    "degree = 40",
    "harmonics = 100000",
    "neighbours = 0",
    "truth = \"z9\"",
    "truth = \"((((z0))))\"",
    "table = \"table.csv\"",
    "table = \"grid.csv\"",
    "z = [\"y\"]",
    "u = []",
    "y = [\"u\"]",
];

/// The number of cases, the time budget and a seed offset: the defaults, or the environment
/// variables `STRUCTID_HARNESS_CASES` and `STRUCTID_HARNESS_SEED` (a longer run: the budget
/// then grows with the cases).
fn settings() -> (usize, Duration, u64) {
    let var = |name: &str| std::env::var(name).ok().and_then(|v| v.parse::<u64>().ok());
    let seed = var("STRUCTID_HARNESS_SEED").unwrap_or(0);
    match var("STRUCTID_HARNESS_CASES") {
        Some(n) => (n as usize, Duration::from_secs(3_600), seed),
        None => (CASES, BUDGET, seed),
    }
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The files of `dir` (relative to the repository root) whose names end in `ext`, sorted.
fn files(dir: &str, ext: &str) -> Vec<(String, Vec<u8>)> {
    let dir = repo_root().join(dir);
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot list the seed directory {}: {e}", dir.display()))
        .map(|entry| entry.expect("directory entry").path())
        .filter(|p| p.to_string_lossy().ends_with(ext))
        .map(|p| {
            let bytes = std::fs::read(&p).expect("read a seed file");
            (p.display().to_string(), bytes)
        })
        .collect();
    out.sort();
    out
}

fn model_seeds() -> Vec<(String, Vec<u8>)> {
    let mut s = files("examples/models", ".toml");
    s.extend(files("examples/compare/spray", ".toml"));
    s.extend(files("fuzz/seeds/model_file", ".toml"));
    s
}

fn data_seeds() -> Vec<(String, Vec<u8>)> {
    let mut s = files("examples/compare/spray", ".csv");
    s.extend(files("fuzz/seeds/data_file", ".csv"));
    // Keep the long example records short: mutations near the header matter most.
    for (_, bytes) in &mut s {
        if bytes.len() > 2_000 {
            let cut = bytes[..2_000]
                .iter()
                .rposition(|&b| b == b'\n')
                .unwrap_or(0);
            bytes.truncate(cut + 1);
        }
    }
    s
}

fn sweep_seeds() -> Vec<(String, Vec<u8>)> {
    let mut s = files("examples/compare", ".toml");
    s.extend(files("fuzz/seeds/sweep_file", ".toml"));
    s
}

fn below(rng: &mut SplitMix64, n: usize) -> usize {
    (rng.next_u64() % n.max(1) as u64) as usize
}

/// One mutation of `bytes`; `other` is another seed for splicing.
fn mutate_once(rng: &mut SplitMix64, bytes: &mut Vec<u8>, other: &[u8]) {
    let len = bytes.len();
    match below(rng, 9) {
        0 if len > 0 => {
            let i = below(rng, len);
            bytes[i] ^= 1 << below(rng, 8);
        }
        1 if len > 0 => {
            let i = below(rng, len);
            const CHARS: &[u8] = b"[]{}\",=.-+#\n0123456789eE_ x";
            bytes[i] = CHARS[below(rng, CHARS.len())];
        }
        2 if len > 0 => {
            let i = below(rng, len);
            let n = 1 + below(rng, 16.min(len - i));
            bytes.drain(i..i + n);
        }
        3 if len > 0 => {
            let i = below(rng, len);
            let n = 1 + below(rng, 32.min(len - i));
            let chunk = bytes[i..i + n].to_vec();
            let at = below(rng, len + 1);
            bytes.splice(at..at, chunk);
        }
        4 if len > 0 => {
            // Replace a number-like run (or any short run) by a token.
            let i = below(rng, len);
            let end = (i..len)
                .find(|&j| !bytes[j].is_ascii_alphanumeric() && !b".-+_".contains(&bytes[j]))
                .unwrap_or(len)
                .max(i);
            let token = TOKENS[below(rng, TOKENS.len())].as_bytes();
            bytes.splice(i..end, token.iter().copied());
        }
        5 if len > 0 => bytes.truncate(below(rng, len)),
        6 => {
            // Swap two lines.
            let text = String::from_utf8_lossy(bytes).into_owned();
            let mut lines: Vec<&str> = text.split('\n').collect();
            if lines.len() > 1 {
                let (a, b) = (below(rng, lines.len()), below(rng, lines.len()));
                lines.swap(a, b);
                *bytes = lines.join("\n").into_bytes();
            }
        }
        7 if !other.is_empty() => {
            // Splice: this input's head with the other's tail.
            let cut = below(rng, len + 1);
            let from = below(rng, other.len());
            bytes.truncate(cut);
            bytes.extend_from_slice(&other[from..]);
        }
        _ => {
            let token = TOKENS[below(rng, TOKENS.len())].as_bytes();
            let at = below(rng, len + 1);
            bytes.splice(at..at, token.iter().copied());
        }
    }
}

/// Runs `entry` on `CASES` (see [`settings`]) mutants of `seeds` (1 to 4 mutations each) under `catch_unwind`;
/// fails on the first panic or empty error message, naming the seed and the mutant.
fn never_panics(
    what: &str,
    seed: u64,
    seeds: &[(String, Vec<u8>)],
    entry: fn(&[u8]) -> fuzz_entry::Outcome,
    prefix: &[u8],
) -> (usize, usize) {
    assert!(!seeds.is_empty(), "no seed files for {what}");
    let start = Instant::now();
    let (cases, budget, offset) = settings();
    let mut rng = SplitMix64::new(seed ^ offset.rotate_left(17));
    let (mut tried, mut rejected) = (0, 0);
    for case in 0..cases {
        if start.elapsed() > budget {
            break;
        }
        let (name, base) = &seeds[case % seeds.len()];
        let other = &seeds[below(&mut rng, seeds.len())].1;
        let mut bytes = base.clone();
        if !prefix.is_empty() && rng.next_u64().is_multiple_of(4) {
            let options = [prefix[0], rng.next_u64() as u8, rng.next_u64() as u8];
            bytes.splice(0..0, options);
        }
        for _ in 0..1 + below(&mut rng, 4) {
            mutate_once(&mut rng, &mut bytes, other);
        }
        let outcome = catch_unwind(AssertUnwindSafe(|| entry(&bytes))).unwrap_or_else(|_| {
            panic!(
                "the {what} loader panicked on case {case}, a mutant of {name}:\n{}",
                String::from_utf8_lossy(&bytes)
            )
        });
        for m in &outcome.errors {
            assert!(
                !m.trim().is_empty(),
                "an error without a message from the {what} loader on case {case}, a mutant of {name}:\n{}",
                String::from_utf8_lossy(&bytes)
            );
        }
        tried += 1;
        rejected += usize::from(!outcome.accepted);
    }
    eprintln!(
        "{what}: {tried} mutants, {rejected} rejected by the loader, in {:.2} s",
        start.elapsed().as_secs_f64()
    );
    assert!(
        tried >= cases.min(200),
        "only {tried} {what} cases ran in the time budget"
    );
    (tried, rejected)
}

#[test]
fn seed_files_are_accepted() {
    for (name, bytes) in model_seeds() {
        let outcome = fuzz_entry::model_file(&bytes);
        assert!(outcome.accepted, "{name}: {:?}", outcome.errors);
    }
    for (name, bytes) in sweep_seeds() {
        let outcome = fuzz_entry::sweep_file(&bytes);
        assert!(outcome.accepted, "{name}: {:?}", outcome.errors);
    }
    for (name, bytes) in data_seeds() {
        let (options, body) = fuzz_entry::csv_options(&bytes);
        let text = std::str::from_utf8(body).expect("UTF-8 seed");
        structid_io::DataTable::parse_with(text, None, &options)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
}

#[test]
fn mutated_model_files_never_panic() {
    let (tried, rejected) =
        never_panics("model file", 1, &model_seeds(), fuzz_entry::model_file, &[]);
    assert!(
        rejected > 0 && rejected < tried,
        "{rejected} of {tried} rejected"
    );
}

#[test]
fn mutated_data_files_never_panic() {
    let (tried, rejected) = never_panics(
        "data file",
        2,
        &data_seeds(),
        fuzz_entry::data_file,
        &[0xFF],
    );
    assert!(
        rejected > 0 && rejected < tried,
        "{rejected} of {tried} rejected"
    );
}

#[test]
fn mutated_sweep_configs_never_panic() {
    let (tried, rejected) = never_panics(
        "sweep config",
        3,
        &sweep_seeds(),
        fuzz_entry::sweep_file,
        &[],
    );
    assert!(
        rejected > 0 && rejected < tried,
        "{rejected} of {tried} rejected"
    );
}
