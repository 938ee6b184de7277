//! `structid`: structured nonlinear system identification from the command line.
//!
//! ```text
//! structid identify --model M.toml --data D.csv --out DIR [--beta B] [--sigma S] [--memory-limit-mib N]
//! structid simulate --model M.toml --input U.csv --out D.csv [--noise-std S] [--seed N]
//! structid validate [--model M.toml] [--estimate FILE.json|DIR] --data V.csv --out DIR2 [--initial-state zero|estimate] [--max-lag 25]
//! structid demo spray [--out DIR] [--samples L] [--seed N]
//! structid demo multi-input [--out DIR] [--samples L] [--seed N] [--noise-std S]
//! structid data silverbox|tanks --file PATH --split NAME|all --out OUT
//! structid data csv --file PATH [--columns C1,C2] [--names u,y] [--delimiter ';'] [--no-header]
//!                   [--skip-rows N] [--range A..B] [--remove-mean] --out OUT.csv
//! structid input prbs|multisine|noise|chirp|steps --length L [--sample-time TS] [--amplitude A]
//!                   [--offset U0] [--band LOW,HIGH] [--seed N] [--name u] [--time] --out U.csv
//! structid discover --model NOMINAL.toml --data EST.csv… --validation-data VAL.csv… --out DIR [--locations L1,L2]
//!                   [--no-tv] [--settle N] [--sigma-fraction F] [--trend D] [--tune-sigma]
//!                   [--significance ALPHA] [--hysteresis-threshold T]
//! structid static --data D.csv --z COL --w COL [--noise-std S] [--out DIR]
//! ```
//!
//!
//! Every command that reads data files (--data, --validation-data, --validate, --input) reads
//! CSV files, MATLAB MAT-files (v5 to v7) and NumPy .npy/.npz files; `--vars u=vir,y=qm`
//! picks and names the signals.
//!
//! Exit codes: 0 success, 2 invalid usage or input (bad arguments, malformed model or data
//! files, a model that cannot be identified as posed, an output location that cannot be used,
//! a data file longer than [`structid_io::data_file::MAX_ROWS`]), 1 failure while running
//! (writing files, numerical breakdown, not enough memory).

mod compare;
mod data;
mod demo;
mod discover;
mod error;
mod identify;
mod input;
mod linear;
mod progress;
mod refine;
mod simulate;
mod staticness;
mod stored;
mod validate;
mod wiener_hammerstein;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};

use crate::error::CliError;

/// Structured nonlinear system identification: known LTI blocks, unknown static maps.
///
/// A model file (TOML) describes the known linear part as an LFT and lists the unknown static
/// maps with their dispersions; a data file (CSV with a header row, a MATLAB MAT-file or a
/// NumPy .npy/.npz file, see --vars) holds the measured signals.
/// `structid identify` estimates the maps, `structid simulate` generates data from known maps,
/// and `structid demo` runs the examples of Hsu et al. (2006) without any files.
///
/// Data files may hold up to 1 000 000 rows (`structid data csv`, which cuts longer files, is
/// limited by the memory only). Outputs are checked before any work: an output that is an
/// input, a file where a directory is expected (or the reverse) and a place that cannot be
/// written are input errors (exit code 2). Every file is written atomically; a result
/// directory's `.complete` lists the files of the sets written in full, and commands that read
/// an estimate refuse one whose set was left unfinished by an interrupted run.
#[derive(Debug, Parser)]
#[command(name = "structid", version, about, long_about, max_term_width = 100)]
struct Cli {
    #[command(subcommand)]
    command: Command,

    /// The signals to read from the data files, as NAME=VARIABLE items: `u=vir,y=qm` reads the
    /// variables `vir` and `qm` of a MAT-file (.mat, saved by MATLAB with -v6 or -v7, by Octave
    /// or SciPy) or of a NumPy .npz archive as the signals `u` and `y` that the model file's
    /// [signals] name; `y=data#1` is column 1 (zero-based) of a matrix variable; `u=#0` is
    /// column 0 of a .npy array or of a CSV file, whose columns may also be named by their
    /// header (`u=V1`). Applies to every data file of the command (--data,
    /// --validation-data, --validate, --input). Without it a MAT-file's or .npz archive's
    /// numeric variables are columns named by the variables (matrix columns `data#0`, …) and
    /// a .npy array's columns are c0, c1, …. MATLAB v7.3 files (HDF5) are not read: save
    /// with `save(..., '-v7')` or export CSV.
    #[arg(long, global = true, value_name = "NAME=VAR,...", value_parser = data::parse_vars)]
    vars: Option<structid_io::Vars>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Identify the static maps of a model from measured data.
    ///
    /// Writes DIR/estimate.csv (the estimated map outputs ŵ, one column per block, and the
    /// estimated noise ê), DIR/map_<block>.csv (each estimated map on a grid over the data
    /// range: 201 points for one input, 41×41 for two, the data points for more),
    /// DIR/map_<block>.svg (figures) and DIR/report.json (settings, cost terms, diagnostics,
    /// errors against the `truth` maps of the model file). Input files are never overwritten.
    Identify(IdentifyArgs),
    /// Simulate a model with the `truth` map of every block in the loop.
    ///
    /// Reads the input columns named in `[signals].u` from the input CSV and writes the u, y and
    /// z columns plus one `w_<block>` column per block. Needs D_zw = 0 (no algebraic loop).
    Simulate(SimulateArgs),
    /// Validate an estimate (or the true maps) on a record: simulation, one-step prediction
    /// and residual tests.
    ///
    /// With --estimate FILE.json (or a directory holding estimate.json), validates the stored
    /// estimate; with the directory of an older `structid identify` without estimate.json,
    /// rebuilds the estimate by re-running the identification recorded in DIR/report.json and
    /// checks it against DIR/estimate.csv; without --estimate, uses the `truth` map of every
    /// block of --model.
    /// Then simulates the model with these maps in the loop on the validation data and
    /// computes the one-step-ahead prediction errors and their whiteness and input
    /// cross-correlation tests (99 % bands). Writes DIR2/validation.json, DIR2/simulation.csv,
    /// DIR2/simulation.svg and DIR2/residuals.svg.
    Validate(ValidateArgs),
    /// k-step-ahead prediction of a stored estimate on a record.
    ///
    /// ŷ(t|t−k) uses u up to t and y up to t−k: the state is predicted by the Kalman predictor
    /// of the noise model with the maps evaluated at the measured z, then the model runs k − 1
    /// steps with the maps in the loop. k = 1 is `validate`'s one-step predictor; k ≥ the
    /// record length is the simulation. Writes DIR/prediction.csv (time, y, ŷ per output) and
    /// DIR/prediction.json (RMS and fit per output).
    Predict(PredictArgs),
    /// Run the examples of the paper end to end, with no files to prepare.
    #[command(subcommand)]
    Demo(DemoCommand),
    /// Compare dispersions and β values over experiments and noise seeds (research sweeps).
    ///
    /// `structid compare --config SWEEP.toml --out DIR` runs every case of the sweep (experiment ×
    /// dispersion × β × seed) in parallel and writes one JSON file per case, DIR/results.csv,
    /// DIR/results.md and figures. `structid compare merge DIR... --out DIR` combines shard
    /// directories (see --shard).
    Compare(compare::CompareArgs),
    /// Estimate a linear block from data (ARX, then output error) and write it as a model file.
    ///
    /// Orders are given (--orders NA,NB,NK) or selected by an information criterion or on
    /// validation data. The model file has a `[linear]` section placing the block in a
    /// structure: `lti` (a nominal linear model), `output-feedback` (y = G·(u − N(y)) + e, with
    /// an unknown map N) or `input` (y = G·N(u) + e), ready for `structid refine`.
    Linear(linear::LinearArgs),
    /// Refine an uncertain linear part: alternate between identifying the map with G fixed and
    /// re-estimating G (output error) with the map fixed.
    ///
    /// Needs a model file with a `[linear]` section with a map (structure output-feedback,
    /// rate-feedback, input or output; see `structid linear`), or an `[lft]` whose one map
    /// sits at the input or output of a linear block G or in feedback from its output or its
    /// rate, which is then written back as `[linear]`. Poles of G at z = 1 (integrators) stay there. β (and σ) are
    /// chosen on the first pass; the alternation stops when the validation simulation error
    /// stops improving. Writes DIR/model.toml (the refined linear part; `structid validate
    /// --estimate DIR` validates the stored estimate DIR/estimate.json), DIR/refine.csv and
    /// DIR/refine.svg (costs and errors per iteration) and the files of `structid identify`.
    Refine(refine::RefineArgs),
    /// Identify a Wiener–Hammerstein model y = G₂·N(G₁·u) + e with both LTI blocks unknown.
    ///
    /// Estimates the best linear approximation (output error, --orders NA,NB,NK for both
    /// blocks together), scores every division of its poles and zeros between G₁ and G₂ by a
    /// map fitted behind it, and fits both blocks, the map and the initial states from the best
    /// one by simulation error. Writes DIR/model.toml (both blocks in one LFT, the map as the
    /// table DIR/map_N.csv), DIR/joint.json and DIR/divisions.json.
    WienerHammerstein(wiener_hammerstein::WienerHammersteinArgs),
    /// Identify a Hammerstein–Wiener model y = N₂(G·N₁(u)) + e with G and both maps unknown.
    ///
    /// Estimates the best linear approximation (output error, --orders NA,NB,NK), starts both
    /// maps as the identity, and fits G's coefficients (its gain held), both maps and the
    /// initial states by simulation error. Writes DIR/model.toml (the maps `input` and
    /// `output` as the tables DIR/map_input.csv and DIR/map_output.csv), DIR/joint.json and
    /// DIR/divisions.json (the linear approximation). Same options as `wiener-hammerstein`.
    HammersteinWiener(wiener_hammerstein::WienerHammersteinArgs),
    /// Prepare data files: benchmark splits and column selection from any delimited file.
    ///
    /// `structid data silverbox|tanks --file PATH --split NAME --out OUT.csv` extracts one split
    /// of a benchmark record (nonlinearbenchmark.org) as a CSV file with columns u,y, ready for
    /// `identify`, `validate` and `simulate`; `--split all` writes OUT/<split>.csv for every
    /// split. `structid data csv` selects, reorders, renames and cuts the columns of any
    /// delimited text file.
    #[command(subcommand)]
    Data(data::DataCommand),
    /// Find what a nominal linear model is missing: where, and which static effect.
    ///
    /// Starts from a nominal model that almost fits (one input, one output, no maps: `[linear]`
    /// with structure = "lti", e.g. from `structid linear --structure lti`, or `[lft]`). Tests
    /// whether its residual on the two records is only noise (size against a model-free noise
    /// level, whiteness and (non)linear input-correlation tests) and where it is not, in time
    /// and in operating space. If something is missing, inserts one unknown static block at each
    /// candidate location (input, output, output feedback, rate feedback), identifies it on
    /// --data, ranks the locations by the simulation error on --validation-data (each repeated
    /// for several records, every record simulated from its own initial state), and names the best
    /// map from a library of effects (saturation, dead zone, friction, polynomial stiffness,
    /// quantisation, offset, gain) when its parametric form validates as well, or reports it as
    /// unnamed or dynamic (hysteresis or backlash suspected).
    ///
    /// Writes DIR/report.md (readable on its own), DIR/report.json, the figures
    /// DIR/residual.svg, regions.svg, map.svg and before_after.svg, and, when an effect was
    /// found, DIR/augmented.toml: the nominal model plus the block `N` with the map found as
    /// its `truth` (DIR/N_table.csv for an unnamed map), checked to reproduce the report's
    /// validation RMS when read back. Input files are never overwritten.
    Discover(discover::DiscoverArgs),
    /// Design an input signal for an experiment and write it as a CSV file (column `u`, or
    /// --name), atomically.
    ///
    /// `structid input prbs|multisine|noise|chirp|steps --length L [--sample-time TS]
    /// [--amplitude A] [--offset U0] [--band LOW,HIGH] [--seed N] --out U.csv`: a
    /// maximum-length binary sequence (--order, --clock), a random-phase multisine on the
    /// harmonics in the band (--period, --odd, --lines, --min-crest), band-limited Gaussian
    /// noise, a linear or logarithmic chirp (--sweep), or random steps with hold times in
    /// --hold MIN,MAX samples. The file is ready for `structid simulate --input`.
    #[command(subcommand)]
    Input(input::InputCommand),
    /// Rate how well a static map explains a (z, w) scatter (the paper's Example 1).
    ///
    /// Fits the best static map w = N(z) (a Gaussian kernel, β by marginal likelihood), and
    /// reports the variance it leaves unexplained against the noise variance (--noise-std, or
    /// estimated from the residual) and whether the residual depends on the direction of
    /// motion of z (hysteresis, backlash), with a verdict: static, direction dependent, or
    /// unexplained (dynamics or another input). With --out DIR, writes DIR/report.json and
    /// DIR/static.svg (the scatter and the fitted map).
    Static(staticness::StaticArgs),
}

/// A number, or `auto`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum AutoOr {
    /// A given value.
    Value(f64),
    /// Chosen from the data.
    Auto,
}

impl std::str::FromStr for AutoOr {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(AutoOr::Auto);
        }
        s.parse::<f64>()
            .map(AutoOr::Value)
            .map_err(|_| format!("expected a number or `auto`, found `{s}`"))
    }
}

/// Criterion of automatic hyperparameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum SelectionArg {
    /// Maximum marginal likelihood.
    Ml,
    /// Generalised cross-validation.
    Gcv,
    /// Blocked K-fold cross-validation.
    Cv,
    /// Simulation error on a validation record.
    Validation,
}

/// Arguments of `structid identify`.
#[derive(Debug, Args)]
struct IdentifyArgs {
    /// The model file (TOML).
    #[arg(long, short = 'm', value_name = "MODEL.toml")]
    model: PathBuf,
    /// The data file (CSV with a header row naming the columns of `[signals]` in the model file).
    /// Repeat it for several records (experiments) of the same system: each record starts from
    /// its own initial state, and the maps are fitted to all of them at once.
    #[arg(long, short = 'd', value_name = "DATA.csv", required = true)]
    data: Vec<PathBuf>,
    /// Output directory (created if needed).
    #[arg(long, short = 'o', value_name = "DIR")]
    out: PathBuf,
    /// Weight β > 0 of the dispersion against the noise energy in J = (1/L)·Σ|e_k|² + β·Σ D_i.
    /// Larger β gives smoother maps and larger residuals. `auto` selects β from the data by
    /// the criterion of --selection.
    #[arg(
        long,
        value_name = "B|auto",
        allow_negative_numbers = true,
        default_value = "0.01"
    )]
    beta: AutoOr,
    /// Kernel width σ > 0 for every block, overriding the model file. Without it each block
    /// uses its own `sigma`, or, when the model file gives none, 0.1 × the largest range of
    /// the block's inputs z over the data. `auto` scales every block's width by one common
    /// factor chosen from the data (within two decades), with β optimised for each.
    #[arg(long, value_name = "S|auto", allow_negative_numbers = true)]
    sigma: Option<AutoOr>,
    /// Criterion of automatic β/σ: `ml` (maximum marginal likelihood) or `gcv` (generalised
    /// cross-validation) for quadratic dispersions, `cv` (blocked K-fold cross-validation) for
    /// any dispersion, `validation` (simulation error on --validation-data) for any
    /// [default: ml for quadratic dispersions, cv otherwise].
    #[arg(long, value_name = "ml|gcv|cv|validation")]
    selection: Option<SelectionArg>,
    /// Number of contiguous folds of `--selection cv`.
    #[arg(long, value_name = "K", default_value_t = 5)]
    folds: usize,
    /// Validation record (CSV like --data) for `--selection validation`.
    #[arg(long, value_name = "V.csv")]
    validation_data: Option<PathBuf>,
    /// Memory budget of the solver in MiB, at most the machine's memory (checked on Linux)
    /// [default: 3/4 of the available memory].
    #[arg(long, value_name = "N")]
    memory_limit_mib: Option<u64>,
    /// How the initial state of the linear block is treated: `zero` (the system starts at
    /// rest, the paper's assumption) or `estimate` (x₀ is estimated as unpenalised parameters;
    /// use it for records that do not start at rest).
    #[arg(long, value_name = "zero|estimate", default_value = "zero")]
    initial_state: InitialStateArg,
    /// Solver: `auto` chooses by dispersion and size — for quadratic dispersions the exact
    /// solve unless its L·n_y × L·n_y matrix would not fit in memory, then the feature solver
    /// when every dispersion has finitely many features; for total variation `clarabel` up to
    /// L·n_y = 1000 samples, `admm` beyond; for models that mix the two kinds `clarabel` up to
    /// L·n_y = 500, `admm` beyond. `exact`, `features` (linear in L; fourier and
    /// gaussian-lowrank dispersions, minimum-phase noise models), `clarabel` (exact conic
    /// program for tv, dense in quadratic blocks) and `admm` (linear in L, for tv alone or
    /// mixed with quadratic dispersions) force a solver.
    #[arg(
        long,
        value_name = "auto|exact|features|clarabel|admm",
        default_value = "auto"
    )]
    solver: SolverArg,
    /// Use this dispersion for every block, overriding the model file: `gaussian`,
    /// `gaussian-lowrank`, `fourier` or `tv` (total variation; see --neighbours).
    #[arg(long, value_name = "KIND")]
    dispersion: Option<DispersionArg>,
    /// k of the nearest-neighbour graph of total variation for blocks with several inputs
    /// (with --dispersion tv; default 8).
    #[arg(long, value_name = "K")]
    neighbours: Option<usize>,
    /// Tolerance of the iterative solvers (clarabel: duality gap and feasibility, default 1e-8;
    /// admm: relative primal and dual residuals, default 1e-7).
    #[arg(long, value_name = "TOL")]
    tolerance: Option<f64>,
    /// Iteration limit of the iterative solvers (clarabel default 200, admm default 20000).
    #[arg(long, value_name = "N")]
    max_iterations: Option<usize>,
    /// Skip the posterior uncertainty bands of quadratic dispersions (the `std` column of
    /// map_<block>.csv, the shaded 95 % band of 1-D map figures, `noise_variance` in report.json).
    #[arg(long)]
    no_bands: bool,
}

/// Values of `--dispersion`.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum DispersionArg {
    /// The Gaussian RKHS norm.
    Gaussian,
    /// The Gaussian through Nyström features.
    GaussianLowrank,
    /// The Fourier-series kernel.
    Fourier,
    /// Total variation.
    Tv,
}

/// Values of `--solver`.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum SolverArg {
    /// Choose by size.
    Auto,
    /// The exact dense solve.
    Exact,
    /// The feature-space solve.
    Features,
    /// The conic program (total variation).
    Clarabel,
    /// ADMM (total variation).
    Admm,
}

/// Values of `--initial-state`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum InitialStateArg {
    /// x₀ = 0.
    Zero,
    /// x₀ estimated.
    Estimate,
}

impl From<InitialStateArg> for structid_core::InitialState {
    fn from(a: InitialStateArg) -> Self {
        match a {
            InitialStateArg::Zero => Self::Zero,
            InitialStateArg::Estimate => Self::Estimate,
        }
    }
}

/// Arguments of `structid simulate`.
#[derive(Debug, Args)]
struct SimulateArgs {
    /// The model file (TOML); every block needs a `truth`. Give this or --estimate.
    #[arg(
        long,
        short = 'm',
        value_name = "MODEL.toml",
        required_unless_present = "estimate",
        conflicts_with = "estimate"
    )]
    model: Option<PathBuf>,
    /// A stored estimate (estimate.json of `identify`, `refine` or `discover`) to simulate
    /// instead of a model file's true maps; the input columns are the estimate's input names.
    #[arg(long, short = 'e', value_name = "FILE.json")]
    estimate: Option<PathBuf>,
    /// CSV file holding the input columns named in [signals].u.
    #[arg(long, short = 'i', value_name = "U.csv")]
    input: PathBuf,
    /// The CSV file to write (never one of the inputs).
    #[arg(long, short = 'o', value_name = "D.csv")]
    out: PathBuf,
    /// Standard deviation of the white Gaussian noise e on every noise channel.
    #[arg(
        long,
        value_name = "S",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    noise_std: f64,
    /// Seed of the noise generator.
    #[arg(long, value_name = "N", default_value_t = 1)]
    seed: u64,
}

/// Arguments of `structid validate`.
#[derive(Clone, Debug, Args)]
struct ValidateArgs {
    /// The model file (TOML) of an estimate rebuilt from an older directory (same blocks as in
    /// DIR/report.json); without --estimate, the model whose true maps are validated. Not
    /// needed, and not read, with a stored estimate (FILE.json, or a directory holding
    /// estimate.json), which carries its model.
    #[arg(long, short = 'm', value_name = "MODEL.toml")]
    model: Option<PathBuf>,
    /// The estimate: a stored estimate file (DIR/estimate.json, written by `identify`,
    /// `refine` and `discover`; it needs neither --model nor the estimation data), or an
    /// output directory: its estimate.json when it has one, otherwise (a directory of an older
    /// `structid identify`) the estimate rebuilt by re-running the identification it records. Without it, the model is validated with its true maps:
    /// every block of --model needs a `truth`.
    #[arg(long, short = 'e', value_name = "FILE.json|DIR")]
    estimate: Option<PathBuf>,
    /// The validation data (CSV with the columns named in the model's `[signals]`). Repeat it
    /// for several records: each is validated on its own (from its own initial state) into
    /// DIR2/record_<i>/, and DIR2/validation.json adds the simulation error over all records.
    #[arg(long, short = 'd', value_name = "V.csv", required = true)]
    data: Vec<PathBuf>,
    /// Output directory (created if needed).
    #[arg(long, short = 'o', value_name = "DIR2")]
    out: PathBuf,
    /// Initial state of the validation record: `zero` (at rest) or `estimate` (x₀ estimated
    /// by least squares from the one-step residual, then used for simulation and prediction).
    #[arg(long, value_name = "zero|estimate", default_value = "zero")]
    initial_state: InitialStateArg,
    /// Largest lag of the correlation tests (less than the number of samples).
    #[arg(long, value_name = "N", default_value_t = 25)]
    max_lag: usize,
    /// Leading samples that only settle the state: the simulation RMS and fit leave them out
    /// (the Silverbox benchmark allows 50).
    #[arg(long, value_name = "N", default_value_t = 0)]
    settle: usize,
    /// How the simulation is scored: `free` (one run from x₀, the default) or `LENGTH:INIT`,
    /// windows of LENGTH samples, each simulated from a state fitted to its first half
    /// and scored after its first INIT samples (for plants with integrators, whose free run drifts; `discover`
    /// reports the windows it used).
    #[arg(long, value_name = "free|LENGTH:INIT", value_parser = structid_workflow::discover::parse_scoring, default_value = "free")]
    scoring: structid_core::validation::Scoring,
}

/// Arguments of `structid predict`.
#[derive(Debug, Args)]
struct PredictArgs {
    /// The stored estimate (estimate.json of `identify`, `refine` or `discover`).
    #[arg(long, short = 'e', value_name = "FILE.json")]
    estimate: PathBuf,
    /// The record (CSV with the estimate's input and output columns).
    #[arg(long, short = 'd', value_name = "V.csv")]
    data: PathBuf,
    /// The horizon k ≥ 1.
    #[arg(long, short = 'k', value_name = "K", default_value_t = 1)]
    horizon: usize,
    /// Output directory (created if needed).
    #[arg(long, short = 'o', value_name = "DIR")]
    out: PathBuf,
    /// Initial state of the record: `zero` (at rest) or `estimate` (x₀ by least squares from
    /// the one-step residual).
    #[arg(long, value_name = "zero|estimate", default_value = "zero")]
    initial_state: InitialStateArg,
    /// Leading samples left out of the RMS and fit.
    #[arg(long, value_name = "N", default_value_t = 0)]
    settle: usize,
}

#[derive(Debug, Subcommand)]
enum DemoCommand {
    /// The spray-deposition example (paper section 6.1, Fig. 4).
    ///
    /// y_k = f(u_k) + g(u_{k−2}) + e_k with f(z) = −|z|, g(z) = 0.5·(sin((3z)²) + (2z)² − 2),
    /// u_k = sin(0.1k), e ~ N(0, 1), Gaussian dispersions with σ = 0.1, identified for
    /// β = 0.001, 0.01 and 0.1. Writes data.csv, model.toml (re-usable with `structid
    /// identify`), fig4.svg and summary.json.
    Spray(SprayArgs),
    /// The two-input example (paper section 6.2): one map N(z0, z1) behind a known LTI block.
    ///
    /// L = 1500 samples, σ = 0.5, β = 0.01. Writes data.csv, model.toml, surfaces.svg (true and
    /// estimated map as heat maps) and summary.json.
    MultiInput(MultiInputArgs),
}

/// Arguments of `structid demo spray`.
#[derive(Debug, Args)]
struct SprayArgs {
    /// Output directory.
    #[arg(
        long,
        short = 'o',
        value_name = "DIR",
        default_value = "structid-demo/spray"
    )]
    out: PathBuf,
    /// Number of samples L.
    #[arg(long, value_name = "L", default_value_t = 2000)]
    samples: usize,
    /// Seed of the noise generator.
    #[arg(long, value_name = "N", default_value_t = 1)]
    seed: u64,
}

/// Arguments of `structid demo multi-input`.
#[derive(Debug, Args)]
struct MultiInputArgs {
    /// Output directory.
    #[arg(
        long,
        short = 'o',
        value_name = "DIR",
        default_value = "structid-demo/multi-input"
    )]
    out: PathBuf,
    /// Number of samples L.
    #[arg(long, value_name = "L", default_value_t = 1500)]
    samples: usize,
    /// Seed of the input and noise generators.
    #[arg(long, value_name = "N", default_value_t = 1)]
    seed: u64,
    /// Standard deviation of the output noise e.
    #[arg(
        long,
        value_name = "S",
        default_value_t = 0.1,
        allow_negative_numbers = true
    )]
    noise_std: f64,
}

fn run(cli: Cli) -> Result<(), CliError> {
    if let Some(vars) = cli.vars {
        let reads_data = !matches!(
            cli.command,
            Command::Demo(_)
                | Command::Data(data::DataCommand::Silverbox(_) | data::DataCommand::Tanks(_))
                | Command::Compare(_)
                | Command::Input(_)
        );
        if !reads_data {
            return Err(CliError::input(
                "--vars selects the signals of the data files of identify, validate, predict, \
                 simulate, linear, refine, wiener-hammerstein, hammerstein-wiener, discover, static and data csv; this command reads none (a sweep \
                 configuration of `compare` reads a MAT-file's variables as columns named by \
                 the variables)",
            ));
        }
        data::set_vars(vars);
    }
    match cli.command {
        Command::Identify(a) => identify::run(a),
        Command::Simulate(a) => simulate::run(a),
        Command::Validate(a) => validate::run(a),
        Command::Predict(a) => stored::predict(a),
        Command::Demo(DemoCommand::Spray(a)) => demo::spray(a),
        Command::Demo(DemoCommand::MultiInput(a)) => demo::multi_input(a),
        Command::Compare(a) => compare::run(a),
        Command::Linear(a) => linear::run(a),
        Command::Refine(a) => refine::run(a),
        Command::WienerHammerstein(a) => {
            wiener_hammerstein::run(a, structid_workflow::BlockStructure::WienerHammerstein)
        }
        Command::HammersteinWiener(a) => {
            wiener_hammerstein::run(a, structid_workflow::BlockStructure::HammersteinWiener)
        }
        Command::Data(c) => data::run(c),
        Command::Discover(a) => discover::run(a),
        Command::Input(c) => input::run(c),
        Command::Static(a) => staticness::run(a),
    }
}

fn main() -> ExitCode {
    // A panic is a bug; report it as one, briefly, without a backtrace.
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown cause".into());
        let at = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!("error: internal error{at}: {msg}\nThis is a bug in structid; please report it.");
    }));
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.code())
        }
    }
}
