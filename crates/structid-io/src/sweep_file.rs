//! Sweep configuration files of `structid compare`: experiments × dispersions × β × seeds.
//!
//! # Format
//!
//! ```toml
//! [[experiment]]
//! name = "spray"
//! model = "spray/model.toml"          # a structid model file
//! estimation = "spray/estimation.csv" # measured data, or a [experiment.simulate] table
//! validation = "spray/validation.csv" # optional
//!
//! [[experiment]]
//! name = "spray-sim"
//! model = "spray/model.toml"
//! [experiment.simulate]               # data generated from the model's truth maps
//! input = "spray/input.csv"           # estimation input u (as for `structid simulate --input`)
//! validation_input = "spray/input_val.csv"  # optional
//! noise_std = 0.1                     # default 0
//! validation_noise_std = 0.0          # default 0: validation data without noise
//! seeds = 5                           # seeds 0..5 (0, 1, 2, 3, 4), or a list [1, 7, 9]; default 1
//!
//! [[dispersion]]
//! name = "gaussian"                   # label in tables and legends
//! kind = "gaussian"                   # gaussian | gaussian-lowrank | fourier | tv, with their keys
//! sigma = 0.1                         # or "auto" (quadratic kinds; needs every beta to be "auto")
//! beta = [0.001, 0.01, 0.1, "auto"]   # each value is a case; "auto" = automatic selection
//! selection = "ml"                    # ml | gcv | cv | validation (default ml, cv for tv)
//! folds = 5                           # folds of selection = "cv" (default 5)
//! solver = "auto"                     # auto | exact | features | clarabel | admm
//! ```
//!
//! Paths are relative to the configuration file's directory. Names (of experiments and
//! dispersions) are made of letters, digits, `_`, `-` and `.`, so that they can appear in case
//! ids and file names; they must be unique (ignoring case). Every error names the line of the
//! offending key.
//!
//! ```
//! use structid_io::sweep_file::{BetaChoice, SweepFile};
//! let text = r#"
//! [[experiment]]
//! name = "spray"
//! model = "model.toml"
//! estimation = "data.csv"
//!
//! [[dispersion]]
//! name = "gauss"
//! kind = "gaussian"
//! sigma = 0.1
//! beta = [0.01, "auto"]
//! "#;
//! let sweep = SweepFile::parse(text, None).unwrap();
//! assert_eq!(sweep.dispersions[0].betas, [BetaChoice::Fixed(0.01), BetaChoice::Auto]);
//! let bad = text.replace("0.01,", "-1,");
//! let e = SweepFile::parse(&bad, None).unwrap_err().to_string();
//! assert!(e.ends_with("(line 11)"), "{e}");
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;
use structid_core::SolverChoice;
use toml::Spanned;

use crate::error::IoError;
use crate::model_file::{
    DispersionSpec, Source, dispersion_from_table, dispersion_keys, err_at, toml_error, value_kind,
};

/// Folds of `selection = "cv"` when `folds` is not given.
pub const DEFAULT_FOLDS: usize = 5;

/// Most seeds `seeds = n` may ask for.
pub const MAX_SEEDS: u64 = 100_000;

/// A parsed and validated sweep configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepFile {
    /// The experiments, in file order.
    pub experiments: Vec<SweepExperiment>,
    /// The dispersions, in file order.
    pub dispersions: Vec<SweepDispersion>,
    /// The file it was read from.
    pub path: Option<PathBuf>,
    /// The directory relative paths are resolved against.
    pub base_dir: PathBuf,
}

/// A path as written in the configuration, with the line of its key.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SweepPath {
    /// The path as written (relative to the configuration's directory unless absolute).
    pub path: PathBuf,
    /// One-based line of the key.
    pub line: usize,
}

/// One `[[experiment]]`.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepExperiment {
    /// Its name (letters, digits, `_`, `-`, `.`).
    pub name: String,
    /// One-based line of its `name`.
    pub line: usize,
    /// The model file.
    pub model: SweepPath,
    /// Where its data come from.
    pub data: ExperimentData,
}

/// Measured or simulated data of an experiment.
#[derive(Clone, Debug, PartialEq)]
pub enum ExperimentData {
    /// Measured records.
    Measured {
        /// The estimation record (CSV).
        estimation: SweepPath,
        /// The validation record (CSV), if any.
        validation: Option<SweepPath>,
    },
    /// Records simulated from the model's truth maps, one per seed.
    Simulated(SimulatedData),
}

/// The `[experiment.simulate]` table.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedData {
    /// The estimation input u (CSV with the columns of `[signals].u`).
    pub input: SweepPath,
    /// The validation input, if any.
    pub validation_input: Option<SweepPath>,
    /// Standard deviation of the white Gaussian noise on every noise channel of the
    /// estimation record.
    pub noise_std: f64,
    /// The same for the validation record (0: validation data without noise).
    pub validation_noise_std: f64,
    /// The noise seeds, one repetition each.
    pub seeds: Vec<u64>,
    /// One-based line of the table header.
    pub line: usize,
}

impl SweepExperiment {
    /// Whether the experiment has validation data.
    pub fn has_validation(&self) -> bool {
        match &self.data {
            ExperimentData::Measured { validation, .. } => validation.is_some(),
            ExperimentData::Simulated(s) => s.validation_input.is_some(),
        }
    }

    /// The seeds of a simulated experiment; `None` for measured data.
    pub fn seeds(&self) -> Option<&[u64]> {
        match &self.data {
            ExperimentData::Measured { .. } => None,
            ExperimentData::Simulated(s) => Some(&s.seeds),
        }
    }
}

/// One β value of a dispersion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BetaChoice {
    /// A fixed β > 0.
    Fixed(f64),
    /// β chosen automatically (by the dispersion's `selection`).
    Auto,
}

impl BetaChoice {
    /// `"auto"` or the shortest decimal form of β that reads back exactly.
    pub fn label(&self) -> String {
        match self {
            BetaChoice::Fixed(b) => crate::data_file::format_number(*b),
            BetaChoice::Auto => "auto".into(),
        }
    }
}

/// How an automatic β (and σ) is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SelectionMethod {
    /// Maximum marginal likelihood (quadratic dispersions).
    MarginalLikelihood,
    /// Generalised cross-validation (quadratic dispersions).
    Gcv,
    /// K-fold cross-validation.
    CrossValidation {
        /// Number of folds (≥ 2).
        folds: usize,
    },
    /// Simulation error on the validation record.
    Validation,
}

impl SelectionMethod {
    /// The name used in the configuration and in tables: `ml`, `gcv`, `cv` or `validation`.
    pub fn name(&self) -> &'static str {
        match self {
            SelectionMethod::MarginalLikelihood => "ml",
            SelectionMethod::Gcv => "gcv",
            SelectionMethod::CrossValidation { .. } => "cv",
            SelectionMethod::Validation => "validation",
        }
    }
}

/// One `[[dispersion]]`.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepDispersion {
    /// Its name (letters, digits, `_`, `-`, `.`).
    pub name: String,
    /// One-based line of its `name`.
    pub line: usize,
    /// The dispersion given to every block of the model. Without σ each block keeps the σ of
    /// its model file, or gets the default from the data.
    pub spec: DispersionSpec,
    /// `sigma = "auto"`: σ is chosen together with β.
    pub tune_sigma: bool,
    /// The β values, one case each, in file order.
    pub betas: Vec<BetaChoice>,
    /// How `"auto"` values are chosen.
    pub selection: SelectionMethod,
    /// The solver.
    pub solver: SolverChoice,
}

impl SweepDispersion {
    /// Whether the kind is total variation (not quadratic).
    pub fn is_total_variation(&self) -> bool {
        matches!(self.spec, DispersionSpec::TotalVariation { .. })
    }
}

// ---------------------------------------------------------------------------------------------
// Raw (serde) form

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSweep {
    #[serde(default)]
    experiment: Vec<Spanned<RawExperiment>>,
    #[serde(default)]
    dispersion: Vec<Spanned<RawDispersion>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExperiment {
    name: Spanned<String>,
    model: Spanned<String>,
    estimation: Option<Spanned<String>>,
    validation: Option<Spanned<String>>,
    simulate: Option<Spanned<RawSimulate>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSimulate {
    input: Spanned<String>,
    validation_input: Option<Spanned<String>>,
    noise_std: Option<Spanned<f64>>,
    validation_noise_std: Option<Spanned<f64>>,
    seeds: Option<Spanned<toml::Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDispersion {
    name: Spanned<String>,
    kind: Spanned<String>,
    sigma: Option<Spanned<toml::Value>>,
    beta: Option<Spanned<toml::Value>>,
    selection: Option<Spanned<String>>,
    folds: Option<Spanned<i64>>,
    solver: Option<Spanned<String>>,
    harmonics: Option<Spanned<toml::Value>>,
    combine: Option<Spanned<toml::Value>>,
    tolerance: Option<Spanned<toml::Value>>,
    neighbours: Option<Spanned<toml::Value>>,
    interpolation: Option<Spanned<toml::Value>>,
}

impl RawDispersion {
    /// The kind-specific keys that are present, with their values.
    fn kind_keys(&self) -> Vec<(&'static str, &Spanned<toml::Value>)> {
        [
            ("sigma", &self.sigma),
            ("harmonics", &self.harmonics),
            ("combine", &self.combine),
            ("tolerance", &self.tolerance),
            ("neighbours", &self.neighbours),
            ("interpolation", &self.interpolation),
        ]
        .into_iter()
        .filter_map(|(k, v)| v.as_ref().map(|v| (k, v)))
        .collect()
    }
}

// ---------------------------------------------------------------------------------------------
// Parsing

/// Model-file errors from the shared helpers become sweep errors (same location and message).
fn to_sweep(e: IoError) -> IoError {
    match e {
        IoError::Model {
            path,
            line,
            column,
            message,
        } => IoError::Sweep {
            path,
            line,
            column,
            message,
        },
        other => other,
    }
}

fn err(line: usize, message: impl Into<String>) -> IoError {
    to_sweep(err_at(line, message))
}

/// Checks a name used in case ids and file names.
fn check_name(name: &str, what: &str, line: usize) -> Result<(), IoError> {
    if name.is_empty() {
        return Err(err(line, format!("{what} has an empty name")));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')))
    {
        return Err(err(
            line,
            format!(
                "{what} name `{name}` contains `{c}`; names may use letters, digits, `_`, `-` and `.` \
                 (they appear in case ids and file names)"
            ),
        ));
    }
    if name.starts_with('.') {
        return Err(err(
            line,
            format!("{what} name `{name}` starts with `.`; start it with a letter or digit"),
        ));
    }
    Ok(())
}

/// A number (float or integer) or `None` for anything else.
fn number(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

fn parse_betas(
    v: &Spanned<toml::Value>,
    owner: &str,
    src: &Source<'_>,
) -> Result<Vec<BetaChoice>, IoError> {
    let line = src.line(v.span().start);
    let one = |item: &toml::Value| -> Result<BetaChoice, IoError> {
        match item {
            toml::Value::String(s) if s == "auto" => Ok(BetaChoice::Auto),
            other => match number(other) {
                Some(b) if b.is_finite() && b > 0.0 => Ok(BetaChoice::Fixed(b)),
                Some(b) => Err(err(
                    line,
                    format!(
                        "{owner}: beta = {b} is invalid; every β must be a finite number greater than zero (or \"auto\")"
                    ),
                )),
                None => Err(err(
                    line,
                    format!(
                        "{owner}: beta values must be numbers or \"auto\", not {}",
                        describe(other)
                    ),
                )),
            },
        }
    };
    let betas: Vec<BetaChoice> = match v.get_ref() {
        toml::Value::Array(items) => items.iter().map(one).collect::<Result<_, _>>()?,
        single => vec![one(single)?],
    };
    if betas.is_empty() {
        return Err(err(
            line,
            format!(
                "{owner}: beta is an empty list; give at least one value, e.g. beta = [0.01, \"auto\"]"
            ),
        ));
    }
    for (i, b) in betas.iter().enumerate() {
        if betas[..i].iter().any(|c| c.label() == b.label()) {
            return Err(err(
                line,
                format!("{owner}: beta lists {} twice", b.label()),
            ));
        }
    }
    Ok(betas)
}

fn describe(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("the string \"{s}\""),
        other => value_kind(other).to_string(),
    }
}

fn parse_seeds(
    v: &Spanned<toml::Value>,
    owner: &str,
    src: &Source<'_>,
) -> Result<Vec<u64>, IoError> {
    let line = src.line(v.span().start);
    match v.get_ref() {
        toml::Value::Integer(n) if *n >= 1 && (*n as u64) <= MAX_SEEDS => {
            Ok((0..*n as u64).collect())
        }
        toml::Value::Integer(n) => Err(err(
            line,
            format!(
                "{owner}: seeds = {n} is invalid; give a number of repetitions from 1 to {MAX_SEEDS} or a list of seeds"
            ),
        )),
        toml::Value::Array(items) => {
            let mut seeds = Vec::with_capacity(items.len());
            for item in items {
                match item {
                    toml::Value::Integer(s) if *s >= 0 => {
                        let s = *s as u64;
                        if seeds.contains(&s) {
                            return Err(err(line, format!("{owner}: seeds lists {s} twice")));
                        }
                        seeds.push(s);
                    }
                    other => {
                        return Err(err(
                            line,
                            format!(
                                "{owner}: seeds must be whole numbers ≥ 0, not {}",
                                describe(other)
                            ),
                        ));
                    }
                }
            }
            if seeds.is_empty() {
                return Err(err(line, format!("{owner}: seeds is an empty list")));
            }
            Ok(seeds)
        }
        other => Err(err(
            line,
            format!(
                "{owner}: seeds must be a number of repetitions (seeds = 5 means 0..5) or a list such as [1, 7, 9], not {}",
                describe(other)
            ),
        )),
    }
}

fn non_negative(
    v: &Spanned<f64>,
    key: &str,
    owner: &str,
    src: &Source<'_>,
) -> Result<f64, IoError> {
    let x = *v.get_ref();
    if x.is_finite() && x >= 0.0 {
        Ok(x)
    } else {
        Err(err(
            src.line(v.span().start),
            format!("{owner}: {key} = {x} is invalid; it must be a finite number, zero or greater"),
        ))
    }
}

fn path_of(
    v: &Spanned<String>,
    key: &str,
    owner: &str,
    src: &Source<'_>,
) -> Result<SweepPath, IoError> {
    let line = src.line(v.span().start);
    if v.get_ref().trim().is_empty() {
        return Err(err(line, format!("{owner}: {key} is an empty path")));
    }
    Ok(SweepPath {
        path: PathBuf::from(v.get_ref()),
        line,
    })
}

fn parse_experiment(
    raw: &Spanned<RawExperiment>,
    src: &Source<'_>,
) -> Result<SweepExperiment, IoError> {
    let r = raw.get_ref();
    let name = r.name.get_ref().clone();
    let line = src.line(r.name.span().start);
    check_name(&name, "an [[experiment]]", line)?;
    let owner = format!("experiment `{name}`");
    let model = path_of(&r.model, "model", &owner, src)?;
    let data = match (&r.estimation, &r.simulate) {
        (Some(_), Some(s)) => {
            return Err(err(
                src.line(s.span().start),
                format!(
                    "{owner} gives both `estimation` data and an [experiment.simulate] table; keep one"
                ),
            ));
        }
        (None, None) => {
            return Err(err(
                line,
                format!(
                    "{owner} has no data: give `estimation = \"file.csv\"` (measured) or an [experiment.simulate] table"
                ),
            ));
        }
        (Some(est), None) => ExperimentData::Measured {
            estimation: path_of(est, "estimation", &owner, src)?,
            validation: r
                .validation
                .as_ref()
                .map(|v| path_of(v, "validation", &owner, src))
                .transpose()?,
        },
        (None, Some(sim)) => {
            if let Some(v) = &r.validation {
                return Err(err(
                    src.line(v.span().start),
                    format!(
                        "{owner}: a simulated experiment takes its validation data from `validation_input` in [experiment.simulate], not `validation`"
                    ),
                ));
            }
            let s = sim.get_ref();
            ExperimentData::Simulated(SimulatedData {
                input: path_of(&s.input, "input", &owner, src)?,
                validation_input: s
                    .validation_input
                    .as_ref()
                    .map(|v| path_of(v, "validation_input", &owner, src))
                    .transpose()?,
                noise_std: s
                    .noise_std
                    .as_ref()
                    .map(|v| non_negative(v, "noise_std", &owner, src))
                    .transpose()?
                    .unwrap_or(0.0),
                validation_noise_std: s
                    .validation_noise_std
                    .as_ref()
                    .map(|v| non_negative(v, "validation_noise_std", &owner, src))
                    .transpose()?
                    .unwrap_or(0.0),
                seeds: match &s.seeds {
                    Some(v) => parse_seeds(v, &owner, src)?,
                    None => vec![0],
                },
                line: src.line(sim.span().start),
            })
        }
    };
    Ok(SweepExperiment {
        name,
        line,
        model,
        data,
    })
}

fn parse_dispersion_entry(
    raw: &Spanned<RawDispersion>,
    src: &Source<'_>,
) -> Result<SweepDispersion, IoError> {
    let r = raw.get_ref();
    let name = r.name.get_ref().clone();
    let line = src.line(r.name.span().start);
    check_name(&name, "a [[dispersion]]", line)?;
    let owner = format!("dispersion `{name}`");
    let kind = r.kind.get_ref().as_str();
    let kind_line = src.line(r.kind.span().start);
    let line_of = |key: &str| -> usize {
        if key == "kind" {
            return kind_line;
        }
        r.kind_keys()
            .into_iter()
            .find(|(k, _)| *k == key)
            .map_or(kind_line, |(_, v)| src.line(v.span().start))
    };

    // sigma = "auto" is ours; everything else about the kind is the model file's syntax.
    let mut tune_sigma = false;
    let mut table = toml::Table::new();
    table.insert("kind".into(), toml::Value::String(kind.to_string()));
    for (key, v) in r.kind_keys() {
        if key == "sigma"
            && let toml::Value::String(s) = v.get_ref()
        {
            if s != "auto" {
                return Err(err(
                    line_of("sigma"),
                    format!("{owner}: sigma must be a number or \"auto\", not the string \"{s}\""),
                ));
            }
            if dispersion_keys(kind).is_some_and(|k| k.contains(&"sigma")) {
                tune_sigma = true;
                continue;
            }
        }
        table.insert(key.to_string(), v.get_ref().clone());
    }
    let spec = dispersion_from_table(&table, &owner, &line_of).map_err(to_sweep)?;

    let beta_v = r.beta.as_ref().ok_or_else(|| {
        err(
            line,
            format!("{owner} has no `beta`; give the values to compare, e.g. beta = [0.001, 0.01, 0.1, \"auto\"]"),
        )
    })?;
    let betas = parse_betas(beta_v, &owner, src)?;
    let beta_line = src.line(beta_v.span().start);
    let tv = matches!(spec, DispersionSpec::TotalVariation { .. });
    if tune_sigma && betas.iter().any(|b| matches!(b, BetaChoice::Fixed(_))) {
        return Err(err(
            beta_line,
            format!(
                "{owner}: sigma = \"auto\" is chosen together with β, so every beta value must be \"auto\"; \
                 to compare fixed β values give sigma a number (or leave it out) in another [[dispersion]]"
            ),
        ));
    }

    let folds = match &r.folds {
        None => None,
        Some(f) if *f.get_ref() >= 2 && *f.get_ref() <= 1000 => Some(*f.get_ref() as usize),
        Some(f) => {
            return Err(err(
                src.line(f.span().start),
                format!(
                    "{owner}: folds = {} is invalid; cross-validation needs 2 to 1000 folds",
                    f.get_ref()
                ),
            ));
        }
    };
    let selection = match &r.selection {
        None if tv => SelectionMethod::CrossValidation {
            folds: folds.unwrap_or(DEFAULT_FOLDS),
        },
        None => SelectionMethod::MarginalLikelihood,
        Some(s) => {
            let sl = src.line(s.span().start);
            let m = match s.get_ref().as_str() {
                "ml" => SelectionMethod::MarginalLikelihood,
                "gcv" => SelectionMethod::Gcv,
                "cv" => SelectionMethod::CrossValidation {
                    folds: folds.unwrap_or(DEFAULT_FOLDS),
                },
                "validation" => SelectionMethod::Validation,
                other => {
                    return Err(err(
                        sl,
                        format!(
                            "{owner}: unknown selection `{other}`; use ml, gcv, cv or validation"
                        ),
                    ));
                }
            };
            if tv
                && matches!(
                    m,
                    SelectionMethod::MarginalLikelihood | SelectionMethod::Gcv
                )
            {
                return Err(err(
                    sl,
                    format!(
                        "{owner}: selection = \"{}\" needs a quadratic dispersion (a Gaussian-process model); \
                         use \"cv\" or \"validation\" for tv",
                        m.name()
                    ),
                ));
            }
            m
        }
    };
    if let Some(f) = &r.folds
        && !matches!(selection, SelectionMethod::CrossValidation { .. })
    {
        return Err(err(
            src.line(f.span().start),
            format!("{owner}: folds applies to selection = \"cv\" only"),
        ));
    }
    let solver = match &r.solver {
        None => SolverChoice::Auto,
        Some(s) => SolverChoice::from_name(s.get_ref()).ok_or_else(|| {
            err(
                src.line(s.span().start),
                format!(
                    "{owner}: unknown solver `{}`; use auto, exact, features, clarabel or admm",
                    s.get_ref()
                ),
            )
        })?,
    };
    Ok(SweepDispersion {
        name,
        line,
        spec,
        tune_sigma,
        betas,
        selection,
        solver,
    })
}

impl SweepFile {
    /// Reads and validates a sweep configuration; relative paths are resolved against its
    /// directory.
    pub fn from_path(path: &Path) -> Result<Self, IoError> {
        let text = std::fs::read_to_string(path).map_err(|source| IoError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let base = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let mut s = Self::parse(&text, Some(base)).map_err(|e| e.with_path(path))?;
        s.path = Some(path.to_path_buf());
        Ok(s)
    }

    /// Parses and validates configuration text; `base_dir` resolves relative paths (the
    /// current directory when `None`). Files are not opened.
    pub fn parse(text: &str, base_dir: Option<&Path>) -> Result<Self, IoError> {
        let src = Source::new(text);
        let raw: RawSweep = toml::from_str(text).map_err(|e| to_sweep(toml_error(&e, &src)))?;
        if raw.experiment.is_empty() {
            return Err(err(
                1,
                "no [[experiment]]; add at least one with a name, a model and its data",
            ));
        }
        if raw.dispersion.is_empty() {
            return Err(err(
                1,
                "no [[dispersion]]; add at least one with a name, a kind and beta values",
            ));
        }
        let mut experiments: Vec<SweepExperiment> = Vec::new();
        for e in &raw.experiment {
            let exp = parse_experiment(e, &src)?;
            if let Some(prev) = experiments
                .iter()
                .find(|p| p.name.eq_ignore_ascii_case(&exp.name))
            {
                return Err(err(
                    exp.line,
                    format!(
                        "two experiments are named `{}` (lines {} and {}; names are compared ignoring case)",
                        exp.name, prev.line, exp.line
                    ),
                ));
            }
            experiments.push(exp);
        }
        let mut dispersions: Vec<SweepDispersion> = Vec::new();
        for (d, raw_d) in raw
            .dispersion
            .iter()
            .map(|d| (parse_dispersion_entry(d, &src), d))
        {
            let d = d?;
            if let Some(prev) = dispersions
                .iter()
                .find(|p| p.name.eq_ignore_ascii_case(&d.name))
            {
                return Err(err(
                    d.line,
                    format!(
                        "two dispersions are named `{}` (lines {} and {}; names are compared ignoring case)",
                        d.name, prev.line, d.line
                    ),
                ));
            }
            if d.selection == SelectionMethod::Validation
                && d.betas.contains(&BetaChoice::Auto)
                && let Some(e) = experiments.iter().find(|e| !e.has_validation())
            {
                let line = raw_d
                    .get_ref()
                    .selection
                    .as_ref()
                    .map_or(d.line, |s| src.line(s.span().start));
                return Err(err(
                    line,
                    format!(
                        "dispersion `{}` chooses β on validation data, but experiment `{}` (line {}) has none; \
                         add `validation = \"file.csv\"` (measured) or `validation_input` (simulated), or use another selection",
                        d.name, e.name, e.line
                    ),
                ));
            }
            dispersions.push(d);
        }
        Ok(Self {
            experiments,
            dispersions,
            path: None,
            base_dir: base_dir.map_or_else(|| PathBuf::from("."), Path::to_path_buf),
        })
    }

    /// The path of `p` on disk: relative paths are taken from the configuration's directory.
    pub fn resolve(&self, p: &SweepPath) -> PathBuf {
        if p.path.is_absolute() {
            p.path.clone()
        } else {
            self.base_dir.join(&p.path)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"# a comment
[[experiment]]
name = "measured"
model = "m.toml"
estimation = "est.csv"
validation = "val.csv"

[[experiment]]
name = "sim"
model = "m.toml"
[experiment.simulate]
input = "u.csv"
validation_input = "uv.csv"
noise_std = 1
seeds = [3, 1]

[[dispersion]]
name = "g"
kind = "gaussian"
sigma = 0.2
beta = [0.001, 1, "auto"]
selection = "gcv"
solver = "exact"

[[dispersion]]
name = "tv"
kind = "tv"
neighbours = 4
beta = "auto"

[[dispersion]]
name = "f-auto"
kind = "fourier"
sigma = "auto"
harmonics = 12
beta = ["auto"]
selection = "validation"
"#;

    fn parse_err(text: &str) -> String {
        SweepFile::parse(text, None).unwrap_err().to_string()
    }

    #[test]
    fn parses_every_key() {
        let s = SweepFile::parse(GOOD, Some(Path::new("/cfg"))).unwrap();
        assert_eq!(s.experiments.len(), 2);
        let m = &s.experiments[0];
        assert_eq!((m.name.as_str(), m.line), ("measured", 3));
        assert_eq!(s.resolve(&m.model), Path::new("/cfg/m.toml"));
        assert!(m.has_validation() && m.seeds().is_none());
        let ExperimentData::Simulated(sim) = &s.experiments[1].data else {
            panic!("simulated")
        };
        assert_eq!(sim.seeds, [3, 1]);
        assert_eq!((sim.noise_std, sim.validation_noise_std), (1.0, 0.0));
        assert_eq!(sim.line, 11);
        let g = &s.dispersions[0];
        assert_eq!(g.spec, DispersionSpec::Gaussian { sigma: Some(0.2) });
        assert_eq!(
            g.betas,
            [
                BetaChoice::Fixed(0.001),
                BetaChoice::Fixed(1.0),
                BetaChoice::Auto
            ]
        );
        assert_eq!(g.selection, SelectionMethod::Gcv);
        assert_eq!(g.solver, SolverChoice::Exact);
        assert!(!g.tune_sigma);
        let tv = &s.dispersions[1];
        assert!(tv.is_total_variation());
        assert_eq!(
            tv.selection,
            SelectionMethod::CrossValidation {
                folds: DEFAULT_FOLDS
            }
        );
        assert_eq!(tv.betas, [BetaChoice::Auto]);
        let f = &s.dispersions[2];
        assert!(f.tune_sigma);
        assert_eq!(
            f.spec,
            DispersionSpec::Fourier {
                sigma: None,
                harmonics: Some(12),
                additive: false
            }
        );
    }

    #[test]
    fn seeds_count_means_zero_to_n() {
        let text = GOOD.replace("seeds = [3, 1]", "seeds = 4");
        let s = SweepFile::parse(&text, None).unwrap();
        assert_eq!(s.experiments[1].seeds().unwrap(), [0, 1, 2, 3]);
        let text = GOOD.replace("seeds = [3, 1]\n", "");
        let s = SweepFile::parse(&text, None).unwrap();
        assert_eq!(s.experiments[1].seeds().unwrap(), [0]);
    }

    /// Each malformed variant of GOOD with the line its error must name and a piece of the
    /// message.
    #[test]
    fn errors_name_the_line() {
        let cases: &[(&str, &str, usize, &str)] = &[
            (
                "seeds = [3, 1]",
                "seeds = [3, 3]",
                15,
                "seeds lists 3 twice",
            ),
            ("seeds = [3, 1]", "seeds = 0", 15, "seeds = 0 is invalid"),
            ("seeds = [3, 1]", "seeds = [-1]", 15, "whole numbers"),
            ("noise_std = 1", "noise_std = -1", 14, "noise_std = -1"),
            ("sigma = 0.2", "sigma = -0.2", 20, "sigma = -0.2 is invalid"),
            (
                "sigma = 0.2",
                "sigma = \"wide\"",
                20,
                "a number or \"auto\"",
            ),
            (
                "beta = [0.001, 1, \"auto\"]",
                "beta = [0.001, 0]",
                21,
                "beta = 0 is invalid",
            ),
            (
                "beta = [0.001, 1, \"auto\"]",
                "beta = [0.001, 0.001]",
                21,
                "twice",
            ),
            ("beta = [0.001, 1, \"auto\"]", "beta = []", 21, "empty list"),
            (
                "beta = [0.001, 1, \"auto\"]",
                "beta = [\"best\"]",
                21,
                "numbers or \"auto\"",
            ),
            (
                "selection = \"gcv\"",
                "selection = \"aic\"",
                22,
                "unknown selection `aic`",
            ),
            (
                "solver = \"exact\"",
                "solver = \"magic\"",
                23,
                "unknown solver `magic`",
            ),
            (
                "kind = \"gaussian\"",
                "kind = \"laplace\"",
                19,
                "unknown dispersion kind `laplace`",
            ),
            ("neighbours = 4", "neighbours = 0", 28, "neighbours must be"),
            (
                "neighbours = 4",
                "harmonics = 4",
                28,
                "unknown key `harmonics` in the tv dispersion",
            ),
            (
                "beta = \"auto\"",
                "beta = \"auto\"\nselection = \"ml\"",
                30,
                "quadratic dispersion",
            ),
            (
                "harmonics = 12",
                "harmonics = 12\nfolds = 3",
                36,
                "folds applies to selection = \"cv\"",
            ),
            (
                "beta = [\"auto\"]",
                "beta = [\"auto\", 0.1]",
                36,
                "every beta value must be \"auto\"",
            ),
            ("name = \"sim\"", "name = \"a/b\"", 9, "contains `/`"),
            (
                "name = \"sim\"",
                "name = \"MEASURED\"",
                9,
                "two experiments are named",
            ),
            (
                "name = \"tv\"",
                "name = \"g\"",
                26,
                "two dispersions are named",
            ),
            (
                "validation = \"val.csv\"",
                "validation = \"val.csv\"\ncolour = 1",
                7,
                "unknown field `colour`",
            ),
            ("estimation = \"est.csv\"", "", 3, "has no data"),
            (
                "input = \"u.csv\"",
                "input = \"u.csv\"\nestimation = 1",
                13,
                "unknown field",
            ),
            ("beta = [0.001, 1, \"auto\"]\n", "", 18, "has no `beta`"),
            ("noise_std = 1", "noise_std = [1", 15, "invalid TOML"),
        ];
        for (from, to, line, needle) in cases {
            assert!(GOOD.contains(from), "{from}");
            let text = GOOD.replacen(from, to, 1);
            let e = parse_err(&text);
            assert!(e.starts_with("sweep config: "), "{e}");
            assert!(e.contains(needle), "{from} -> {to}: {e}");
            assert!(
                e.contains(&format!("(line {line}")),
                "{from} -> {to}: expected line {line}: {e}"
            );
        }
    }

    #[test]
    fn validation_selection_needs_validation_data_everywhere() {
        let text = GOOD.replace("validation_input = \"uv.csv\"\n", "");
        let e = parse_err(&text);
        assert!(
            e.contains("experiment `sim` (line 9) has none") && e.contains("(line 36)"),
            "{e}"
        );
    }

    #[test]
    fn empty_configs_are_refused() {
        assert!(parse_err("").contains("no [[experiment]]"));
        let only_exp = "[[experiment]]\nname = \"a\"\nmodel = \"m\"\nestimation = \"d\"\n";
        assert!(parse_err(only_exp).contains("no [[dispersion]]"));
    }

    #[test]
    fn errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sweep.toml");
        std::fs::write(&p, GOOD.replace("sigma = 0.2", "sigma = 0")).unwrap();
        let e = SweepFile::from_path(&p).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("sweep config `{}`", p.display())),
            "{e}"
        );
        let s = SweepFile::from_path(&dir.path().join("missing.toml")).unwrap_err();
        assert!(matches!(s, IoError::Read { .. }));
    }
}
