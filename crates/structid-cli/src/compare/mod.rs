//! `structid compare`: research comparison sweeps of dispersions, β values and noise seeds.
//!
//! ```text
//! structid compare --config sweep.toml --out DIR [--resume] [--shard i/n] [--jobs N]
//! structid compare merge DIR... --out DIR
//! ```
//!
//! The configuration ([`structid_io::sweep_file`]) lists experiments (a model file with
//! measured or simulated data) and dispersions (a kind, its parameters and β values); every
//! combination, with every seed of a simulated experiment, is a case
//! ([`structid_workflow::compare`]). Cases run in parallel ([`mod@run`]); each writes
//! `DIR/cases/<id>.json` as soon as it finishes, and the tables `results.csv`/`results.md` are
//! rebuilt from the case files after each case.
//! The figures ([`figures`]) follow at the end. `merge` combines the case files of shard
//! directories and rebuilds the same tables and figures.

pub mod figures;
pub mod merge;
pub mod run;

use std::path::PathBuf;

use clap::{Args, Subcommand};

use crate::error::CliError;
use structid_workflow::compare::cases::Shard;

/// Arguments of `structid compare`.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct CompareArgs {
    /// `merge`: combine shard directories.
    #[command(subcommand)]
    command: Option<CompareCommand>,
    /// The sweep configuration (TOML): `[[experiment]]` and `[[dispersion]]` tables.
    #[arg(long, short = 'c', value_name = "SWEEP.toml", required = true)]
    config: Option<PathBuf>,
    /// Output directory: cases/*.json, results.csv, results.md and the figures.
    #[arg(long, short = 'o', value_name = "DIR", required = true)]
    out: Option<PathBuf>,
    /// Continue an interrupted sweep in DIR: cases whose case file is complete are skipped.
    #[arg(long)]
    resume: bool,
    /// Run only shard i of n (0 ≤ i < n): the cases whose index in the case list is i modulo n.
    /// Merge the shard directories afterwards with `structid compare merge`.
    #[arg(long, value_name = "i/n", value_parser = parse_shard)]
    shard: Option<Shard>,
    /// Number of cases run in parallel [default: all cores].
    #[arg(long, short = 'j', value_name = "N")]
    jobs: Option<usize>,
}

#[derive(Debug, Subcommand)]
enum CompareCommand {
    /// Combine the case files of shard directories (or of several runs of one sweep) into one
    /// directory, with the tables and figures an unsharded run would write.
    Merge(MergeArgs),
}

/// Arguments of `structid compare merge`.
#[derive(Debug, Args)]
struct MergeArgs {
    /// Output directories of `structid compare` runs (e.g. runs/shard-*).
    #[arg(value_name = "DIR", required = true, num_args = 1..)]
    dirs: Vec<PathBuf>,
    /// The merged output directory (new, or without case files).
    #[arg(long, short = 'o', value_name = "DIR")]
    out: PathBuf,
}

fn parse_shard(s: &str) -> Result<Shard, String> {
    s.parse()
}

/// Runs `structid compare` or `structid compare merge`.
pub fn run(a: CompareArgs) -> Result<(), CliError> {
    match a.command {
        Some(CompareCommand::Merge(m)) => merge::merge(&m.dirs, &m.out),
        None => {
            let (Some(config), Some(out)) = (a.config, a.out) else {
                return Err(CliError::input(
                    "structid compare needs --config SWEEP.toml and --out DIR",
                ));
            };
            run::run(run::RunOptions {
                config,
                out,
                resume: a.resume,
                shard: a.shard,
                jobs: a.jobs,
            })
        }
    }
}
