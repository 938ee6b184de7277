//! `structid input`: excitation signals for experiments, written as CSV files.

use std::path::PathBuf;

use clap::{Args, Subcommand};
use structid_input::{Design, Kind, Lines, Sweep, crest_factor, generate};
use structid_io::OutputGuard;

use crate::error::CliError;

/// Subcommands of `structid input`.
#[derive(Debug, Subcommand)]
pub enum InputCommand {
    /// A maximum-length pseudo-random binary sequence: levels offset ± amplitude, period
    /// 2^n − 1 bits with one more high bit than low, each bit held for --clock samples.
    Prbs(PrbsArgs),
    /// A periodic sum of sines of equal amplitude on the harmonics of the period inside
    /// --band (or --odd ones, or --lines), random phases or --min-crest; peak = amplitude.
    Multisine(MultisineArgs),
    /// Gaussian noise whose spectrum is cut to --band (zero outside it); RMS = amplitude.
    Noise(NoiseArgs),
    /// A sine sweep across --band, linear or logarithmic in frequency; peak = amplitude.
    Chirp(ChirpArgs),
    /// Random levels in offset ± amplitude held for random times between --hold MIN,MAX
    /// samples (the amplitude-rich input of static nonlinearities).
    Steps(StepsArgs),
}

/// What every input takes.
#[derive(Debug, Args)]
pub struct CommonArgs {
    /// Number of samples.
    #[arg(long, short = 'n', value_name = "L")]
    length: usize,
    /// Sample time in seconds; frequencies are in Hz up to the Nyquist frequency 1/(2·TS).
    #[arg(
        long,
        value_name = "TS",
        default_value_t = 1.0,
        allow_negative_numbers = true
    )]
    sample_time: f64,
    /// Amplitude: the level ± A of prbs and steps, the peak of multisine and chirp, the RMS of
    /// noise.
    #[arg(
        long,
        short = 'a',
        value_name = "A",
        default_value_t = 1.0,
        allow_negative_numbers = true
    )]
    amplitude: f64,
    /// The level the signal varies around.
    #[arg(
        long,
        value_name = "U0",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    offset: f64,
    /// The band LOW,HIGH in Hz (0 ≤ LOW < HIGH ≤ Nyquist) [default: 0 to Nyquist].
    #[arg(long, value_name = "LOW,HIGH", allow_negative_numbers = true)]
    band: Option<String>,
    /// Seed of the random choices; the same seed gives the same signal.
    #[arg(long, value_name = "N", default_value_t = 1)]
    seed: u64,
    /// Name of the signal's column (the name the model file's [signals].u uses).
    #[arg(long, value_name = "NAME", default_value = "u")]
    name: String,
    /// Also write a first column `time` (k·TS, in seconds).
    #[arg(long)]
    time: bool,
    /// The CSV file to write (atomically).
    #[arg(long, short = 'o', value_name = "OUT.csv")]
    out: PathBuf,
}

/// Arguments of `structid input prbs`.
#[derive(Debug, Args)]
pub struct PrbsArgs {
    #[command(flatten)]
    common: CommonArgs,
    /// Order n of the shift register (2 to 24): the period is 2^n − 1 bits [default: the
    /// smallest order whose period covers the length].
    #[arg(long, value_name = "N")]
    order: Option<u32>,
    /// Samples per bit [default: from the band's upper edge, ⌊Nyquist / HIGH⌋].
    #[arg(long, value_name = "SAMPLES")]
    clock: Option<usize>,
}

/// Arguments of `structid input multisine`.
#[derive(Debug, Args)]
pub struct MultisineArgs {
    #[command(flatten)]
    common: CommonArgs,
    /// The period in samples [default: the length]; lines are every 1/(PERIOD·TS) Hz.
    #[arg(long, value_name = "SAMPLES")]
    period: Option<usize>,
    /// Excite only the odd harmonics in the band.
    #[arg(long, conflicts_with = "lines")]
    odd: bool,
    /// Excite these harmonics of the period, comma-separated (1 ≤ k < PERIOD/2), instead of
    /// the band's.
    #[arg(long, value_name = "K1,K2,...")]
    lines: Option<String>,
    /// Phases that minimise the crest factor (iterative clipping) instead of random ones.
    #[arg(long)]
    min_crest: bool,
}

/// Arguments of `structid input noise`.
#[derive(Debug, Args)]
pub struct NoiseArgs {
    #[command(flatten)]
    common: CommonArgs,
}

/// Values of `--sweep`.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum SweepArg {
    /// Frequency linear in time.
    Linear,
    /// Frequency exponential in time (the band must start above 0 Hz).
    Log,
}

/// Arguments of `structid input chirp`.
#[derive(Debug, Args)]
pub struct ChirpArgs {
    #[command(flatten)]
    common: CommonArgs,
    /// The frequency law.
    #[arg(long, value_name = "linear|log", default_value = "linear")]
    sweep: SweepArg,
}

/// Arguments of `structid input steps`.
#[derive(Debug, Args)]
pub struct StepsArgs {
    #[command(flatten)]
    common: CommonArgs,
    /// Shortest and longest hold time, in samples.
    #[arg(long, value_name = "MIN,MAX", default_value = "10,50")]
    hold: String,
}

/// Runs `structid input …`.
pub fn run(cmd: InputCommand) -> Result<(), CliError> {
    let (common, kind, what) = match cmd {
        InputCommand::Prbs(a) => (
            a.common,
            Kind::Prbs {
                order: a.order,
                clock: a.clock,
            },
            "PRBS",
        ),
        InputCommand::Multisine(a) => {
            let lines = match (&a.lines, a.odd) {
                (Some(l), _) => Lines::Chosen(parse_list(l, "--lines")?),
                (None, true) => Lines::Odd,
                (None, false) => Lines::All,
            };
            (
                a.common,
                Kind::Multisine {
                    period: a.period,
                    lines,
                    minimise_crest: a.min_crest,
                },
                "multisine",
            )
        }
        InputCommand::Noise(a) => (a.common, Kind::Noise, "band-limited noise"),
        InputCommand::Chirp(a) => (
            a.common,
            Kind::Chirp {
                sweep: match a.sweep {
                    SweepArg::Linear => Sweep::Linear,
                    SweepArg::Log => Sweep::Logarithmic,
                },
            },
            "chirp",
        ),
        InputCommand::Steps(a) => {
            let hold = parse_list(&a.hold, "--hold")?;
            let [min_hold, max_hold] = hold[..] else {
                return Err(CliError::input(format!(
                    "invalid value `{}` for --hold: expected MIN,MAX in samples, e.g. 10,50",
                    a.hold
                )));
            };
            (a.common, Kind::Steps { min_hold, max_hold }, "random steps")
        }
    };
    let band = common.band.as_deref().map(parse_band).transpose()?;
    let name = common.name.trim().to_string();
    if name.is_empty() || (common.time && name == "time") {
        return Err(CliError::input(format!(
            "invalid value `{}` for --name: give a non-empty column name other than `time`",
            common.name
        )));
    }
    let design = Design {
        length: common.length,
        sample_time: common.sample_time,
        amplitude: common.amplitude,
        offset: common.offset,
        band,
        seed: common.seed,
    };
    let guard = OutputGuard::new();
    guard.check_out_file(&common.out)?;
    let u = generate(&design, &kind).map_err(|e| CliError::input(e.to_string()))?;
    let (lo, hi) = design.band().map_err(|e| CliError::input(e.to_string()))?;
    let cf = crest_factor(&u);
    let mut names = Vec::new();
    let mut columns = Vec::new();
    if common.time {
        names.push("time".to_string());
        columns.push(
            (0..u.len())
                .map(|k| k as f64 * design.sample_time)
                .collect::<Vec<f64>>(),
        );
    }
    names.push(name);
    columns.push(u);
    guard.write_csv(&common.out, &names, &columns)?;
    println!(
        "{what}: {} samples, sample time {} s, band {lo}..{hi} Hz, crest factor {cf:.3}, seed {}; wrote {}",
        design.length,
        design.sample_time,
        design.seed,
        common.out.display()
    );
    Ok(())
}

/// `--band LOW,HIGH` in Hz.
fn parse_band(s: &str) -> Result<(f64, f64), CliError> {
    let bad = || {
        CliError::input(format!(
            "invalid value `{s}` for --band: expected LOW,HIGH in Hz, e.g. 0,0.25"
        ))
    };
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    let lo: f64 = a.trim().parse().map_err(|_| bad())?;
    let hi: f64 = b.trim().parse().map_err(|_| bad())?;
    Ok((lo, hi))
}

/// A comma-separated list of whole numbers.
fn parse_list(s: &str, flag: &str) -> Result<Vec<usize>, CliError> {
    s.split(',')
        .map(|x| {
            x.trim().parse::<usize>().map_err(|_| {
                CliError::input(format!(
                    "invalid value `{s}` for {flag}: expected whole numbers separated by commas"
                ))
            })
        })
        .collect()
}
