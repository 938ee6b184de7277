//! The Rust code blocks of the README and of `docs/`, compiled and run as doc tests
//! (`cargo test --doc -p structid`). Only `rust` (and untagged) blocks are Rust to rustdoc;
//! the `sh`, `text`, `toml` and `python` blocks are run by
//! `crates/structid-cli/tests/docs_blocks.rs` and `python/tests/test_readme.py`, which also
//! check that every page is listed here.

#[doc = include_str!("../README.md")]
pub struct Readme;

#[doc = include_str!("../docs/benchmarks.md")]
pub struct DocsBenchmarks;

#[doc = include_str!("../docs/cli.md")]
pub struct DocsCli;

#[doc = include_str!("../docs/concepts.md")]
pub struct DocsConcepts;

#[doc = include_str!("../docs/files.md")]
pub struct DocsFiles;

#[doc = include_str!("../docs/python.md")]
pub struct DocsPython;
