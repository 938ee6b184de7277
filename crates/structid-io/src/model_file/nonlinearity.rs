//! A `[[nonlinearity]]` block ([`BlockSpec`]): the z channels it reads, the w channel it writes
//! and its true map ([`TruthSpec`]). Its dispersion has a module of its own.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use structid_core::{ExprMap, Interpolant, LookupTable, ParametricMap};
use toml::Spanned;

use super::dispersion::DispersionSpec;
use super::source::{Source, err_at, plural, value_kind};
use crate::data_file::DataTable;
use crate::error::IoError;

/// The true map of a block, when the model file gives one.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum TruthSpec {
    /// An expression in `z0, z1, …` (see [`structid_core::ExprMap`]).
    Expression(String),
    /// A parametric family: an expression in `z0, z1, …` and named parameters with their
    /// values (`parameters = { k = 0.3 }` beside `truth`; see
    /// [`structid_core::ParametricMap`]). `refine --joint` fits the parameters.
    Family {
        /// The expression.
        expression: String,
        /// (name, value) of each parameter, sorted by name.
        parameters: Vec<(String, f64)>,
    },
    /// A lookup table read from a CSV file.
    Table {
        /// The file name as written in the model file (relative to its directory).
        file: String,
        /// The table.
        table: LookupTable,
    },
}

impl TruthSpec {
    /// The map as an interpolant of `dim` inputs.
    pub fn to_interpolant(&self, dim: usize) -> Result<Box<dyn Interpolant>, IoError> {
        match self {
            TruthSpec::Expression(text) => Ok(Box::new(ExprMap::parse(text, dim)?)),
            TruthSpec::Family { .. } => Ok(Box::new(self.family(dim)?.expect("a family"))),
            TruthSpec::Table { table, file } => {
                if table.dim() != dim {
                    return Err(IoError::InvalidArgument(format!(
                        "truth table `{file}` has {} input column(s) but the block has {dim} input(s)",
                        table.dim()
                    )));
                }
                Ok(Box::new(table.clone()))
            }
        }
    }

    /// The parametric family of `dim` inputs, when this truth is one.
    pub fn family(&self, dim: usize) -> Result<Option<ParametricMap>, IoError> {
        match self {
            TruthSpec::Family {
                expression,
                parameters,
            } => Ok(Some(ParametricMap::parse(
                expression,
                dim,
                parameters.clone(),
            )?)),
            _ => Ok(None),
        }
    }

    /// A one-line description: the expression (with its parameters' values), or
    /// `table <file>`.
    pub fn describe(&self) -> String {
        match self {
            TruthSpec::Expression(t) => t.clone(),
            TruthSpec::Family {
                expression,
                parameters,
            } => format!(
                "{expression} with {}",
                parameters
                    .iter()
                    .map(|(n, v)| format!("{n} = {v}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            TruthSpec::Table { file, .. } => format!("table {file}"),
        }
    }
}

/// One `[[nonlinearity]]` entry.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockSpec {
    /// Unique name, used in reports and output file names.
    pub name: String,
    /// Indices into z of the block's inputs.
    pub inputs: Vec<usize>,
    /// Index into w of the block's output.
    pub output: usize,
    /// Its dispersion.
    pub dispersion: DispersionSpec,
    /// Its true map, if known.
    pub truth: Option<TruthSpec>,
    /// A hysteresis operator instead of a static map (`operator = { kind = … }`).
    pub operator: Option<super::operator::OperatorSpec>,
    /// A declared direction of a scalar map (`shape = "increasing"`), which the joint fit
    /// keeps by construction.
    pub shape: Option<structid_core::Monotonicity>,
}

impl BlockSpec {
    /// The true map as an interpolant, if the block has one.
    pub fn truth_map(&self) -> Result<Option<Box<dyn Interpolant>>, IoError> {
        self.truth
            .as_ref()
            .map(|t| t.to_interpolant(self.inputs.len()))
            .transpose()
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawBlock {
    pub(super) name: Spanned<String>,
    pub(super) inputs: Spanned<toml::Value>,
    pub(super) output: Spanned<i64>,
    pub(super) dispersion: Option<Spanned<toml::Value>>,
    truth: Option<Spanned<toml::Value>>,
    table: Option<Spanned<String>>,
    parameters: Option<Spanned<toml::Value>>,
    pub(super) operator: Option<Spanned<toml::Value>>,
    pub(super) shape: Option<Spanned<String>>,
}

/// The block's `shape`: a direction, for a static map of one input that is not a named family.
pub(super) fn parse_shape(
    raw: &RawBlock,
    block: &str,
    dim: usize,
    truth: Option<&TruthSpec>,
    src: &Source<'_>,
) -> Result<Option<structid_core::Monotonicity>, IoError> {
    let Some(shape) = &raw.shape else {
        return Ok(None);
    };
    let line = src.line(shape.span().start);
    let direction: structid_core::Monotonicity = shape.get_ref().parse().map_err(|_| {
        err_at(
            line,
            format!(
                "block `{block}`: unknown shape `{}`; a map's shape is \"increasing\" or \"decreasing\"",
                shape.get_ref()
            ),
        )
    })?;
    let why = if raw.operator.is_some() {
        Some("a hysteresis operator has no static shape")
    } else if matches!(truth, Some(TruthSpec::Family { .. })) {
        Some("a named family keeps the form of its law")
    } else if dim != 1 {
        Some("a map of several inputs has no single direction")
    } else {
        None
    };
    match why {
        Some(why) => Err(err_at(
            line,
            format!("block `{block}` declares `shape`, but {why}; remove `shape`"),
        )),
        None => Ok(Some(direction)),
    }
}

fn load_table_truth(
    file: &str,
    dim: usize,
    block: &str,
    base_dir: Option<&Path>,
    line: usize,
) -> Result<TruthSpec, IoError> {
    let path = match base_dir {
        Some(d) => d.join(file),
        None => PathBuf::from(file),
    };
    let table = DataTable::read(&path).map_err(|e| {
        let cause = match &e {
            IoError::Read { source, .. } => format!("cannot read `{}`: {source}", path.display()),
            other => other.to_string(),
        };
        err_at(line, format!("truth table of block `{block}`: {cause}"))
    })?;
    let mut table = table;
    // The map files of `structid identify` may end with the posterior standard deviation.
    if table.names.len() == dim + 2 && table.names.last().is_some_and(|n| n == "std") {
        table.names.pop();
        table.columns.pop();
    }
    if table.names.len() != dim + 1 {
        return Err(err_at(
            line,
            format!(
                "truth table `{}` of block `{block}` has {} but the block has {} (expected columns z…, value)",
                path.display(),
                plural(table.names.len(), "column"),
                plural(dim, "input"),
            ),
        ));
    }
    if let Some((c, _)) = table
        .columns
        .iter()
        .enumerate()
        .find(|(_, col)| col.iter().any(|v| v.is_nan()))
    {
        return Err(err_at(
            line,
            format!(
                "truth table `{}` of block `{block}` has an empty field in column `{}`",
                path.display(),
                table.names[c]
            ),
        ));
    }
    let rows: Vec<Vec<f64>> = (0..table.len())
        .map(|k| table.columns.iter().map(|c| c[k]).collect())
        .collect();
    let lookup = LookupTable::from_rows(&rows).map_err(|e| {
        err_at(
            line,
            format!("truth table `{}` of block `{block}`: {e}", path.display()),
        )
    })?;
    Ok(TruthSpec::Table {
        file: file.to_string(),
        table: lookup,
    })
}

pub(super) fn parse_truth(
    raw: &RawBlock,
    block: &str,
    dim: usize,
    base_dir: Option<&Path>,
    src: &Source<'_>,
) -> Result<Option<TruthSpec>, IoError> {
    let table = raw.table.as_ref();
    let truth = raw.truth.as_ref();
    if let (Some(_), Some(t)) = (truth, table) {
        return Err(err_at(
            src.line(t.span().start),
            format!("block `{block}` gives both `truth` and `table`; keep one"),
        ));
    }
    if let Some(t) = table {
        if let Some(p) = &raw.parameters {
            return Err(err_at(
                src.line(p.span().start),
                format!("block `{block}`: `parameters` go with a truth expression, not a table"),
            ));
        }
        return load_table_truth(t.get_ref(), dim, block, base_dir, src.line(t.span().start))
            .map(Some);
    }
    let parameters = raw
        .parameters
        .as_ref()
        .map(|p| parse_parameters(p, block, src))
        .transpose()?;
    let Some(truth) = truth else {
        if let Some(p) = &raw.parameters {
            return Err(err_at(
                src.line(p.span().start),
                format!(
                    "block `{block}` declares `parameters` without a `truth` expression that uses them"
                ),
            ));
        }
        return Ok(None);
    };
    let line = src.line(truth.span().start);
    match (truth.get_ref(), parameters) {
        (toml::Value::String(expr), Some(parameters)) => {
            ParametricMap::parse(expr, dim, parameters.clone())
                .map_err(|e| err_at(line, format!("truth of block `{block}`: {e}")))?;
            Ok(Some(TruthSpec::Family {
                expression: expr.clone(),
                parameters,
            }))
        }
        (_, Some(_)) => Err(err_at(
            line,
            format!("block `{block}`: `parameters` go with a truth expression, not a table"),
        )),
        (toml::Value::String(expr), None) => {
            ExprMap::parse(expr, dim)
                .map_err(|e| err_at(line, format!("truth of block `{block}`: {e}")))?;
            Ok(Some(TruthSpec::Expression(expr.clone())))
        }
        (toml::Value::Table(t), None) => {
            if let Some(key) = t.keys().find(|k| k.as_str() != "table") {
                return Err(err_at(
                    line,
                    format!(
                        "block `{block}`: unknown key `{key}` in truth; use truth = \"expression\" or truth = {{ table = \"file.csv\" }}"
                    ),
                ));
            }
            match t.get("table") {
                Some(toml::Value::String(file)) => {
                    load_table_truth(file, dim, block, base_dir, line).map(Some)
                }
                _ => Err(err_at(
                    line,
                    format!(
                        "block `{block}`: truth = {{ table = \"file.csv\" }} needs a file name string"
                    ),
                )),
            }
        }
        (other, None) => Err(err_at(
            line,
            format!(
                "block `{block}`: truth must be an expression string or {{ table = \"file.csv\" }}, not {}",
                value_kind(other)
            ),
        )),
    }
}

pub(super) fn parse_index_list(
    v: &Spanned<toml::Value>,
    block: &str,
    src: &Source<'_>,
) -> Result<Vec<usize>, IoError> {
    let line = src.line(v.span().start);
    let bad = |what: String| {
        err_at(
            line,
            format!("block `{block}`: inputs {what}; write e.g. inputs = [0]"),
        )
    };
    let items: Vec<&toml::Value> = match v.get_ref() {
        toml::Value::Array(a) => a.iter().collect(),
        single @ toml::Value::Integer(_) => vec![single],
        other => {
            return Err(bad(format!(
                "must be a list of z indices, not {}",
                value_kind(other)
            )));
        }
    };
    let mut out = Vec::with_capacity(items.len());
    for item in items {
        match item {
            toml::Value::Integer(i) if *i >= 0 => {
                let i = usize::try_from(*i).map_err(|_| bad(format!("index {i} is too large")))?;
                if out.contains(&i) {
                    return Err(bad(format!("lists z[{i}] twice")));
                }
                out.push(i);
            }
            toml::Value::Integer(i) => return Err(bad(format!("contains the negative index {i}"))),
            other => {
                return Err(bad(format!(
                    "must contain integers, not {}",
                    value_kind(other)
                )));
            }
        }
    }
    if out.is_empty() {
        return Err(bad("is empty; a block reads at least one z channel".into()));
    }
    Ok(out)
}

/// `parameters = { name = value, … }`: finite numbers, sorted by name.
fn parse_parameters(
    p: &Spanned<toml::Value>,
    block: &str,
    src: &Source<'_>,
) -> Result<Vec<(String, f64)>, IoError> {
    let line = src.line(p.span().start);
    let toml::Value::Table(t) = p.get_ref() else {
        return Err(err_at(
            line,
            format!("block `{block}`: parameters must be a table such as {{ k = 0.3, c = 1.0 }}"),
        ));
    };
    if t.is_empty() {
        return Err(err_at(
            line,
            format!("block `{block}`: `parameters` is empty; drop it for a fixed expression"),
        ));
    }
    t.iter()
        .map(|(name, v)| {
            let value = match v {
                toml::Value::Float(f) => *f,
                toml::Value::Integer(i) => *i as f64,
                other => {
                    return Err(err_at(
                        line,
                        format!(
                            "block `{block}`: parameter `{name}` must be a number, not {}",
                            value_kind(other)
                        ),
                    ));
                }
            };
            if !value.is_finite() {
                return Err(err_at(
                    line,
                    format!("block `{block}`: parameter `{name}` = {value} is not finite"),
                ));
            }
            Ok((name.clone(), value))
        })
        .collect()
}
