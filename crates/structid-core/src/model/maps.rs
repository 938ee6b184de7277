//! Known static maps for simulation and model files: expressions in z and lookup tables.

use exmex::{Express, FlatEx};

use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;

/// A static map given as an expression in `z0, z1, …` (or `z` for a single input), e.g.
/// `tanh(z0)`, `0.5*(sin((3*z)^2) + (2*z)^2 - 2)`, `min(max(z0, -1), 1)`.
///
/// Parsing is done by the `exmex` crate; its functions (sin, cos, tanh, exp, ln, sqrt, abs,
/// signum, min, max, atan2, floor, …) and constants (PI, E) are available.
///
/// ```
/// use structid_core::{ExprMap, Interpolant};
/// let f = ExprMap::parse("-abs(z0) + 2*z1", 2).unwrap();
/// assert_eq!(f.eval(&[-1.5, 1.0]), 0.5);
/// assert!(ExprMap::parse("tanh(x)", 1).is_err()); // unknown variable
/// ```
#[derive(Clone, Debug)]
pub struct ExprMap {
    text: String,
    expr: FlatEx<f64>,
    /// For each variable of `expr` (in exmex's order), the index into z.
    slots: Vec<usize>,
    dim: usize,
}

impl ExprMap {
    /// Parses `text` as a map of `dim` inputs.
    pub fn parse(text: &str, dim: usize) -> Result<Self> {
        let err = |reason: String| expression_error(text, reason);
        check_functions(text)?;
        let expr = exmex::parse::<f64>(text).map_err(|e| err(e.to_string()))?;
        let mut slots = Vec::new();
        for name in expr.var_names() {
            let idx = if name == "z" && dim == 1 {
                0
            } else if let Some(i) = name.strip_prefix('z').and_then(|s| s.parse::<usize>().ok()) {
                if i >= dim {
                    return Err(err(format!(
                        "variable `{name}` refers to input {i}, but the map has {dim} input(s) (z0…z{})",
                        dim.saturating_sub(1)
                    )));
                }
                i
            } else {
                return Err(err(format!(
                    "unknown variable `{name}`; use z0…z{} (or z for a single input)",
                    dim.saturating_sub(1)
                )));
            };
            slots.push(idx);
        }
        Ok(Self {
            text: text.to_string(),
            expr,
            slots,
            dim,
        })
    }

    /// The expression text.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// Number of inputs.
    pub fn dim(&self) -> usize {
        self.dim
    }
}

/// An [`Error::Expression`] about `text`.
pub(crate) fn expression_error(text: &str, reason: String) -> Error {
    Error::Expression {
        expression: text.to_string(),
        reason,
    }
}

/// Rejects a call to a function the parser does not know, naming it and the known ones,
/// before the parser would report it in terms of its own grammar.
pub(crate) fn check_functions(text: &str) -> Result<()> {
    match unknown_function(text) {
        Some(name) => Err(expression_error(
            text,
            format!(
                "unknown function `{name}`; the functions are {}",
                function_names().join(", ")
            ),
        )),
        None => Ok(()),
    }
}

/// The names the expression parser knows as functions: the unary ones (`sin`, `tanh`, …) and
/// the binary ones written as calls (`min`, `max`, `atan2`).
pub(crate) fn function_names() -> Vec<&'static str> {
    <exmex::FloatOpsFactory<f64> as exmex::MakeOperators<f64>>::make()
        .iter()
        .filter(|op| op.constant().is_none())
        .map(|op| op.repr())
        .filter(|r| r.starts_with(|c: char| c.is_ascii_alphabetic()))
        .collect()
}

/// The first name of `text` written as a call, `name(`, that is not a function of the parser
/// (which would otherwise report it in terms of its own grammar).
pub(crate) fn unknown_function(text: &str) -> Option<&str> {
    let known = function_names();
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        let starts_name = (bytes[i].is_ascii_alphabetic() || bytes[i] == b'_')
            && (i == 0
                || !(bytes[i - 1].is_ascii_alphanumeric() || matches!(bytes[i - 1], b'_' | b'.')));
        if !starts_name {
            i += 1;
            continue;
        }
        let start = i;
        while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
            i += 1;
        }
        let name = &text[start..i];
        let next = text[i..].trim_start().chars().next();
        if next == Some('(') && !known.contains(&name) {
            return Some(name);
        }
    }
    None
}

impl Interpolant for ExprMap {
    fn eval(&self, z: &[f64]) -> f64 {
        let vars: Vec<f64> = self
            .slots
            .iter()
            .map(|&i| z.get(i).copied().unwrap_or(f64::NAN))
            .collect();
        self.expr.eval(&vars).unwrap_or(f64::NAN)
    }

    fn stored(&self) -> Option<crate::stored::StoredMap> {
        Some(crate::stored::StoredMap::Expression {
            expression: self.text.clone(),
            inputs: self.dim,
        })
    }
}

/// A static map given by a table: piecewise-linear in one input, bilinear on a rectangular grid
/// in two inputs. Outside the table the value of the nearest edge is held.
///
/// ```
/// use structid_core::{Interpolant, LookupTable};
/// let t = LookupTable::one_d(vec![0.0, 1.0, 2.0], vec![0.0, 10.0, 0.0]).unwrap();
/// assert_eq!(t.eval(&[0.5]), 5.0);
/// assert_eq!(t.eval(&[5.0]), 0.0);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub enum LookupTable {
    /// Breakpoints (strictly increasing) and values.
    OneD {
        /// Breakpoints.
        x: Vec<f64>,
        /// Values at the breakpoints.
        v: Vec<f64>,
    },
    /// A rectangular grid: `values[i + j·nx]` at `(x[i], y[j])`.
    Grid2D {
        /// First-input breakpoints.
        x: Vec<f64>,
        /// Second-input breakpoints.
        y: Vec<f64>,
        /// Values, x fastest.
        values: Vec<f64>,
    },
}

fn check_axis(name: &str, x: &[f64]) -> Result<()> {
    if x.is_empty() {
        return Err(Error::InvalidStructure(format!(
            "lookup table axis {name} is empty"
        )));
    }
    if x.iter().any(|v| !v.is_finite()) || x.windows(2).any(|w| w[1] <= w[0]) {
        return Err(Error::InvalidStructure(format!(
            "lookup table axis {name} must be finite and strictly increasing"
        )));
    }
    Ok(())
}

/// Index i and weight t with x = (1−t)·xs[i] + t·xs[i+1], clamped to the ends. A NaN x
/// gives the weight NaN, so the table's value there is NaN (as for too few inputs).
fn locate(xs: &[f64], x: f64) -> (usize, f64) {
    if x.is_nan() {
        return (0, f64::NAN);
    }
    if xs.len() == 1 || x <= xs[0] {
        return (0, 0.0);
    }
    let last = xs.len() - 1;
    if x >= xs[last] {
        return (last - 1, 1.0);
    }
    let i = xs.partition_point(|&b| b <= x) - 1;
    (i, (x - xs[i]) / (xs[i + 1] - xs[i]))
}

impl LookupTable {
    /// A one-input table.
    pub fn one_d(x: Vec<f64>, v: Vec<f64>) -> Result<Self> {
        check_axis("x", &x)?;
        if v.len() != x.len() || v.iter().any(|a| !a.is_finite()) {
            return Err(Error::InvalidStructure(format!(
                "lookup table needs {} finite values, got {}",
                x.len(),
                v.len()
            )));
        }
        Ok(Self::OneD { x, v })
    }

    /// A two-input grid table, values x-fastest.
    pub fn grid_2d(x: Vec<f64>, y: Vec<f64>, values: Vec<f64>) -> Result<Self> {
        check_axis("x", &x)?;
        check_axis("y", &y)?;
        if values.len() != x.len() * y.len() || values.iter().any(|a| !a.is_finite()) {
            return Err(Error::InvalidStructure(format!(
                "grid table needs {}×{} finite values, got {}",
                x.len(),
                y.len(),
                values.len()
            )));
        }
        Ok(Self::Grid2D { x, y, values })
    }

    /// Builds a table from rows `[z…, value]` (p = row length − 1): p = 1 rows in any order,
    /// p = 2 rows forming a complete rectangular grid in any order.
    pub fn from_rows(rows: &[Vec<f64>]) -> Result<Self> {
        let p = rows.first().map_or(0, |r| r.len().saturating_sub(1));
        if rows.iter().any(|r| r.len() != p + 1) {
            return Err(Error::InvalidStructure(
                "lookup table rows have different lengths".into(),
            ));
        }
        match p {
            1 => {
                let mut pts: Vec<(f64, f64)> = rows.iter().map(|r| (r[0], r[1])).collect();
                pts.sort_by(|a, b| a.0.total_cmp(&b.0));
                Self::one_d(
                    pts.iter().map(|p| p.0).collect(),
                    pts.iter().map(|p| p.1).collect(),
                )
            }
            2 => {
                let axis = |c: usize| {
                    let mut v: Vec<f64> = rows.iter().map(|r| r[c]).collect();
                    v.sort_by(f64::total_cmp);
                    v.dedup();
                    v
                };
                let (x, y) = (axis(0), axis(1));
                let mut values = vec![f64::NAN; x.len() * y.len()];
                for r in rows {
                    let i = x.partition_point(|&b| b < r[0]);
                    let j = y.partition_point(|&b| b < r[1]);
                    values[i + j * x.len()] = r[2];
                }
                if values.iter().any(|v| v.is_nan()) || rows.len() != values.len() {
                    return Err(Error::InvalidStructure(format!(
                        "a two-input lookup table must be a complete {}×{} grid without duplicates; got {} rows",
                        x.len(),
                        y.len(),
                        rows.len()
                    )));
                }
                Self::grid_2d(x, y, values)
            }
            _ => Err(Error::InvalidStructure(format!(
                "lookup tables support one or two inputs, not {p}"
            ))),
        }
    }

    /// Number of inputs.
    pub fn dim(&self) -> usize {
        match self {
            Self::OneD { .. } => 1,
            Self::Grid2D { .. } => 2,
        }
    }
}

impl LookupTable {
    /// The table as rows `[z…, value]`, the form [`LookupTable::from_rows`] reads.
    pub fn rows(&self) -> Vec<Vec<f64>> {
        match self {
            Self::OneD { x, v } => x.iter().zip(v).map(|(a, b)| vec![*a, *b]).collect(),
            Self::Grid2D { x, y, values } => {
                let mut rows = Vec::with_capacity(values.len());
                for (j, b) in y.iter().enumerate() {
                    for (i, a) in x.iter().enumerate() {
                        rows.push(vec![*a, *b, values[i + j * x.len()]]);
                    }
                }
                rows
            }
        }
    }
}

impl Interpolant for LookupTable {
    fn stored(&self) -> Option<crate::stored::StoredMap> {
        Some(crate::stored::StoredMap::Table { rows: self.rows() })
    }

    fn eval(&self, z: &[f64]) -> f64 {
        match self {
            Self::OneD { x, v } => {
                let Some(&z0) = z.first() else {
                    return f64::NAN;
                };
                let (i, t) = locate(x, z0);
                if x.len() == 1 {
                    v[0]
                } else {
                    (1.0 - t) * v[i] + t * v[i + 1]
                }
            }
            Self::Grid2D { x, y, values } => {
                let nx = x.len();
                let (Some(&z0), Some(&z1)) = (z.first(), z.get(1)) else {
                    return f64::NAN;
                };
                let (i, s) = locate(x, z0);
                let (j, t) = locate(y, z1);
                let at = |a: usize, b: usize| values[a.min(nx - 1) + b.min(y.len() - 1) * nx];
                (1.0 - s) * (1.0 - t) * at(i, j)
                    + s * (1.0 - t) * at(i + 1, j)
                    + (1.0 - s) * t * at(i, j + 1)
                    + s * t * at(i + 1, j + 1)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expression_variables_map_to_inputs_regardless_of_alphabetical_order() {
        // exmex sorts variable names alphabetically ("z10" < "z2"); slots must follow names.
        let f = ExprMap::parse("z2 - 10*z10", 11).unwrap();
        let mut z = vec![0.0; 11];
        z[2] = 1.0;
        z[10] = 0.5;
        assert_eq!(f.eval(&z), 1.0 - 5.0);
    }

    #[test]
    fn expression_errors_name_the_problem() {
        let e = ExprMap::parse("z3", 2).unwrap_err().to_string();
        assert!(e.contains("z3"), "{e}");
        assert!(ExprMap::parse("tanh(", 1).is_err());
    }

    #[test]
    fn unknown_functions_are_named() {
        let e = ExprMap::parse("0.5*frobnicate(2*z0) + 1", 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown function `frobnicate`"), "{e}");
        assert!(e.contains("tanh") && e.contains("min"), "{e}");
        assert!(!e.contains("wlog"), "{e}");
        // Known functions, binary ones and variables next to parentheses are fine.
        for ok in [
            "tanh (2*z0)",
            "min(max(z0, -1), 1)",
            "max(z0, 0.002)",
            "2.5*(z0)",
            "z0*(1+z0)",
        ] {
            assert!(ExprMap::parse(ok, 1).is_ok(), "{ok}");
        }
        assert_eq!(unknown_function("sinz(z)"), Some("sinz"));
        assert_eq!(unknown_function("sin(z) + cos (z)"), None);
    }

    #[test]
    fn bilinear_table_reproduces_bilinear_functions() {
        let x = vec![-1.0, 0.0, 2.0];
        let y = vec![0.0, 1.0];
        let f = |a: f64, b: f64| 1.0 + 2.0 * a - 3.0 * b + 0.5 * a * b;
        let mut rows = Vec::new();
        for &b in &y {
            for &a in &x {
                rows.push(vec![a, b, f(a, b)]);
            }
        }
        rows.reverse();
        let t = LookupTable::from_rows(&rows).unwrap();
        for (a, b) in [(-0.5, 0.3), (1.7, 0.9), (0.0, 0.0)] {
            assert!((t.eval(&[a, b]) - f(a, b)).abs() < 1e-12);
        }
        assert!(LookupTable::from_rows(&rows[1..]).is_err());
        // Too few inputs give NaN (which simulation reports), not a panic.
        assert!(t.eval(&[0.5]).is_nan());
    }

    /// Found by the `data_file` fuzz target: a NaN input made `locate` compute index −1.
    #[test]
    fn nan_inputs_give_nan_not_a_panic() {
        let one =
            LookupTable::from_rows(&[vec![-1.0, -0.5], vec![0.0, 0.0], vec![1.0, 2.0]]).unwrap();
        assert!(one.eval(&[f64::NAN]).is_nan());
        assert_eq!(one.eval(&[f64::INFINITY]), 2.0);
        assert_eq!(one.eval(&[f64::NEG_INFINITY]), -0.5);
        let grid = LookupTable::from_rows(&[
            vec![0.0, 0.0, 1.0],
            vec![0.0, 1.0, 2.0],
            vec![1.0, 0.0, 3.0],
            vec![1.0, 1.0, 4.0],
        ])
        .unwrap();
        assert!(grid.eval(&[f64::NAN, 0.5]).is_nan());
        assert!(grid.eval(&[0.5, f64::NAN]).is_nan());
        assert_eq!(grid.eval(&[f64::INFINITY, f64::NEG_INFINITY]), 3.0);
    }
}
