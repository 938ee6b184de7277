//! The case list of a sweep, case ids and file names, and sharding.
//!
//! A case is one experiment × dispersion × β value × seed (seeds only for simulated
//! experiments). The list is in configuration order, nested in that order: every case of the
//! first experiment, for it every case of the first dispersion, for it every β in the order
//! written, for each β every seed. Case `k` of the list has index `k`; `--shard i/n` runs the
//! cases with `k mod n = i`, so that shards of similar cost interleave and the shards of one
//! sweep partition its list.

use std::fmt;
use std::str::FromStr;

use structid_io::SweepFile;
use structid_io::sweep_file::BetaChoice;

/// One case of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Case {
    /// Position in the full case list.
    pub index: usize,
    /// Its id, e.g. `spray/gaussian/beta=0.01/seed=3`.
    pub id: String,
    /// Index of the experiment in the configuration.
    pub experiment: usize,
    /// Index of the dispersion in the configuration.
    pub dispersion: usize,
    /// The β value.
    pub beta: BetaChoice,
    /// The noise seed (simulated experiments only).
    pub seed: Option<u64>,
}

/// The id of a case: `experiment/dispersion/beta=B[/seed=S]`, with B the shortest decimal form
/// of β or `auto`.
pub fn case_id(experiment: &str, dispersion: &str, beta: &BetaChoice, seed: Option<u64>) -> String {
    let mut id = format!("{experiment}/{dispersion}/beta={}", beta.label());
    if let Some(s) = seed {
        id.push_str(&format!("/seed={s}"));
    }
    id
}

/// The file stem of a case's JSON file: the id with `/` replaced by `+`. Names cannot contain
/// `/` or `+` (the configuration allows letters, digits, `_`, `-`, `.`) and β labels and seeds
/// contain neither, so distinct ids give distinct stems.
pub fn file_stem(id: &str) -> String {
    id.replace('/', "+")
}

/// Every case of `sweep`, in order.
pub fn case_list(sweep: &SweepFile) -> Vec<Case> {
    let mut out = Vec::new();
    for (ei, e) in sweep.experiments.iter().enumerate() {
        let seeds: Vec<Option<u64>> = match e.seeds() {
            Some(s) => s.iter().map(|&s| Some(s)).collect(),
            None => vec![None],
        };
        for (di, d) in sweep.dispersions.iter().enumerate() {
            for beta in &d.betas {
                for &seed in &seeds {
                    out.push(Case {
                        index: out.len(),
                        id: case_id(&e.name, &d.name, beta, seed),
                        experiment: ei,
                        dispersion: di,
                        beta: *beta,
                        seed,
                    });
                }
            }
        }
    }
    out
}

/// `--shard i/n`: the i-th of n shards (0 ≤ i < n).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// i.
    pub index: usize,
    /// n ≥ 1.
    pub count: usize,
}

impl Shard {
    /// Whether the case with list index `case_index` belongs to this shard.
    pub fn contains(&self, case_index: usize) -> bool {
        case_index % self.count == self.index
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let usage = "write it as i/n with 0 ≤ i < n, e.g. 0/4 for the first of four shards";
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("`{s}` is not of the form i/n; {usage}"))?;
        let parse = |what: &str, v: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| format!("the {what} `{v}` is not a whole number ≥ 0; {usage}"))
        };
        let (index, count) = (parse("shard index", i)?, parse("number of shards", n)?);
        if count == 0 {
            return Err(format!("the number of shards must be at least 1; {usage}"));
        }
        if index >= count {
            return Err(format!(
                "shard index {index} is not less than the number of shards {count} (shards are numbered 0 to {})",
                count - 1
            ));
        }
        Ok(Shard { index, count })
    }
}

/// 64-bit FNV-1a: a stable hash (unlike `DefaultHasher`, fixed across Rust versions) for
/// fingerprints written into case files.
#[derive(Clone, Debug)]
pub struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Self::new()
    }
}

impl Fnv {
    /// The empty hash.
    pub fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }

    /// Adds bytes, followed by a separator so that ("ab", "c") and ("a", "bc") differ.
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes.iter().chain(&[0xff]) {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// The hash.
    pub fn finish(&self) -> u64 {
        self.0
    }
}

/// A fingerprint of the whole case list (ids in order): shard directories of one sweep share it.
pub fn case_list_hash(cases: &[Case]) -> String {
    let mut h = Fnv::new();
    for c in cases {
        h.write(c.id.as_bytes());
    }
    format!("{:016x}", h.finish())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sweep(seeds: &str) -> SweepFile {
        SweepFile::parse(
            &format!(
                r#"
[[experiment]]
name = "meas"
model = "m.toml"
estimation = "d.csv"
[[experiment]]
name = "sim"
model = "m.toml"
[experiment.simulate]
input = "u.csv"
seeds = {seeds}
[[dispersion]]
name = "gaussian"
kind = "gaussian"
beta = [0.01, "auto"]
[[dispersion]]
name = "tv"
kind = "tv"
beta = 1e-5
"#
            ),
            None,
        )
        .unwrap()
    }

    #[test]
    fn ids_follow_the_configuration_order() {
        let cases = case_list(&sweep("[4, 2]"));
        let ids: Vec<&str> = cases.iter().map(|c| c.id.as_str()).collect();
        assert_eq!(
            ids,
            [
                "meas/gaussian/beta=0.01",
                "meas/gaussian/beta=auto",
                "meas/tv/beta=1e-5",
                "sim/gaussian/beta=0.01/seed=4",
                "sim/gaussian/beta=0.01/seed=2",
                "sim/gaussian/beta=auto/seed=4",
                "sim/gaussian/beta=auto/seed=2",
                "sim/tv/beta=1e-5/seed=4",
                "sim/tv/beta=1e-5/seed=2",
            ]
        );
        assert!(cases.iter().enumerate().all(|(i, c)| c.index == i));
        assert_eq!(file_stem(ids[3]), "sim+gaussian+beta=0.01+seed=4");
        // The hash depends on the ids and their order.
        let mut swapped = cases.clone();
        swapped.swap(0, 1);
        assert_ne!(case_list_hash(&cases), case_list_hash(&swapped));
        assert_eq!(
            case_list_hash(&cases),
            case_list_hash(&case_list(&sweep("[4, 2]")))
        );
    }

    #[test]
    fn shard_parsing() {
        assert_eq!("1/3".parse::<Shard>(), Ok(Shard { index: 1, count: 3 }));
        assert_eq!("0/1".parse::<Shard>().unwrap().to_string(), "0/1");
        for (bad, needle) in [
            ("3/3", "not less than the number of shards 3"),
            ("1/0", "at least 1"),
            ("-1/2", "not a whole number"),
            ("a/2", "not a whole number"),
            ("2", "not of the form i/n"),
            ("", "not of the form i/n"),
        ] {
            let e = bad.parse::<Shard>().unwrap_err();
            assert!(e.contains(needle), "{bad}: {e}");
        }
    }

    proptest! {
        /// Property `shards_partition_the_case_list`: for any number of seeds and shards, every
        /// case belongs to exactly one shard, and the shards together hold every case once.
        #[test]
        fn shards_partition_the_case_list(seeds in 1u64..6, count in 1usize..12) {
            let cases = case_list(&sweep(&seeds.to_string()));
            let mut owner = vec![None; cases.len()];
            for i in 0..count {
                let shard = Shard { index: i, count };
                for c in cases.iter().filter(|c| shard.contains(c.index)) {
                    prop_assert!(owner[c.index].is_none(), "case {} in two shards", c.id);
                    owner[c.index] = Some(i);
                }
            }
            prop_assert!(owner.iter().all(Option::is_some));
            // Sizes differ by at most one: shards interleave.
            let sizes: Vec<usize> = (0..count)
                .map(|i| owner.iter().filter(|o| **o == Some(i)).count())
                .collect();
            prop_assert!(sizes.iter().max().unwrap() - sizes.iter().min().unwrap() <= 1);
        }
    }
}
