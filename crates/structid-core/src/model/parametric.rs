//! A named parametric family: a static map written as an expression in its inputs and named
//! parameters, w = f(z; θ), such as `k*sqrt(abs(z0))` (a tank's outflow) or
//! `c*signum(z0) + v*z0` (Coulomb and viscous friction).
//!
//! Where a kernel expansion describes a map by its values, a family describes it by a law with
//! a few physical parameters: it extrapolates as the law does, and its parameters mean
//! something. The joint fit by simulation error fits θ with the rest of the model, so it needs
//! ∂f/∂z and ∂f/∂θ. They are exact: the expression is evaluated on dual numbers
//! a + b·ε (ε² = 0), one input or parameter direction at a time, which carries the derivative
//! through every function of the parser by the chain rule. Functions with jumps (`signum`,
//! `floor`, `round`, …) have derivative zero away from their jumps, as their one-sided
//! derivatives are; `abs`, `min` and `max` take the derivative of the branch they select. Where
//! a derivative is infinite or undefined (√|z| at z = 0), it is taken as zero.

use std::str::FromStr;

use exmex::{BinOp, Express, FlatEx, MakeOperators, Operator};

use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;
use crate::model::maps::{check_functions, expression_error, function_names};

/// A dual number v + d·ε: a value and its derivative along one direction.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dual {
    v: f64,
    d: f64,
}

impl FromStr for Dual {
    type Err = std::num::ParseFloatError;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        Ok(Self {
            v: s.parse()?,
            d: 0.0,
        })
    }
}

/// f(a) with derivative f'(a)·a.d.
fn chain(a: Dual, v: f64, slope: f64) -> Dual {
    // A zero direction stays zero even where the slope is infinite (sqrt at 0).
    let d = if a.d == 0.0 { 0.0 } else { slope * a.d };
    Dual { v, d }
}

fn flat(a: Dual, v: f64) -> Dual {
    Dual { v, d: 0.0 * a.d }
}

fn pow(a: Dual, b: Dual) -> Dual {
    let v = a.v.powf(b.v);
    let da = if a.d == 0.0 {
        0.0
    } else {
        b.v * a.v.powf(b.v - 1.0) * a.d
    };
    let db = if b.d == 0.0 { 0.0 } else { v * a.v.ln() * b.d };
    Dual { v, d: da + db }
}

fn bin(
    repr: &'static str,
    apply: fn(Dual, Dual) -> Dual,
    prio: i64,
    comm: bool,
) -> Operator<'static, Dual> {
    Operator::make_bin(
        repr,
        BinOp {
            apply,
            prio,
            is_commutative: comm,
        },
    )
}

fn constant(repr: &'static str, v: f64) -> Operator<'static, Dual> {
    Operator::make_constant(repr, Dual { v, d: 0.0 })
}

/// The parser's operators and functions on dual numbers (the same names as for f64).
#[derive(Clone, Debug)]
pub struct DualOps;

impl MakeOperators<Dual> for DualOps {
    fn make<'a>() -> Vec<Operator<'a, Dual>> {
        use std::f64::consts::{E, PI, TAU};
        vec![
            bin("^", pow, 4, false),
            bin(
                "*",
                |a, b| Dual {
                    v: a.v * b.v,
                    d: a.d * b.v + a.v * b.d,
                },
                2,
                true,
            ),
            bin(
                "/",
                |a, b| Dual {
                    v: a.v / b.v,
                    d: (a.d * b.v - a.v * b.d) / (b.v * b.v),
                },
                3,
                false,
            ),
            Operator::make_bin_unary(
                "+",
                BinOp {
                    apply: |a, b| Dual {
                        v: a.v + b.v,
                        d: a.d + b.d,
                    },
                    prio: 0,
                    is_commutative: true,
                },
                |a| a,
            ),
            Operator::make_bin_unary(
                "-",
                BinOp {
                    apply: |a, b| Dual {
                        v: a.v - b.v,
                        d: a.d - b.d,
                    },
                    prio: 1,
                    is_commutative: false,
                },
                |a| Dual { v: -a.v, d: -a.d },
            ),
            bin(
                "atan2",
                |y, x| {
                    let r = x.v * x.v + y.v * y.v;
                    Dual {
                        v: y.v.atan2(x.v),
                        d: (x.v * y.d - y.v * x.d) / r,
                    }
                },
                0,
                false,
            ),
            bin("min", |a, b| if b.v < a.v { b } else { a }, 0, false),
            bin("max", |a, b| if b.v > a.v { b } else { a }, 0, false),
            Operator::make_unary("abs", |a| {
                if a.v < 0.0 {
                    Dual { v: -a.v, d: -a.d }
                } else {
                    a
                }
            }),
            Operator::make_unary("signum", |a| flat(a, a.v.signum())),
            Operator::make_unary("sin", |a| chain(a, a.v.sin(), a.v.cos())),
            Operator::make_unary("cos", |a| chain(a, a.v.cos(), -a.v.sin())),
            Operator::make_unary("tan", |a| chain(a, a.v.tan(), 1.0 / a.v.cos().powi(2))),
            Operator::make_unary("asin", |a| {
                chain(a, a.v.asin(), 1.0 / (1.0 - a.v * a.v).sqrt())
            }),
            Operator::make_unary("acos", |a| {
                chain(a, a.v.acos(), -1.0 / (1.0 - a.v * a.v).sqrt())
            }),
            Operator::make_unary("atan", |a| chain(a, a.v.atan(), 1.0 / (1.0 + a.v * a.v))),
            Operator::make_unary("sinh", |a| chain(a, a.v.sinh(), a.v.cosh())),
            Operator::make_unary("cosh", |a| chain(a, a.v.cosh(), a.v.sinh())),
            Operator::make_unary("tanh", |a| chain(a, a.v.tanh(), 1.0 - a.v.tanh().powi(2))),
            Operator::make_unary("asinh", |a| {
                chain(a, a.v.asinh(), 1.0 / (a.v * a.v + 1.0).sqrt())
            }),
            Operator::make_unary("acosh", |a| {
                chain(a, a.v.acosh(), 1.0 / (a.v * a.v - 1.0).sqrt())
            }),
            Operator::make_unary("atanh", |a| chain(a, a.v.atanh(), 1.0 / (1.0 - a.v * a.v))),
            Operator::make_unary("floor", |a| flat(a, a.v.floor())),
            Operator::make_unary("round", |a| flat(a, a.v.round())),
            Operator::make_unary("ceil", |a| flat(a, a.v.ceil())),
            Operator::make_unary("trunc", |a| flat(a, a.v.trunc())),
            Operator::make_unary("fract", |a| Dual {
                v: a.v.fract(),
                d: a.d,
            }),
            Operator::make_unary("exp", |a| chain(a, a.v.exp(), a.v.exp())),
            Operator::make_unary("sqrt", |a| chain(a, a.v.sqrt(), 0.5 / a.v.sqrt())),
            Operator::make_unary("cbrt", |a| {
                chain(a, a.v.cbrt(), 1.0 / (3.0 * a.v.cbrt().powi(2)))
            }),
            Operator::make_unary("ln", |a| chain(a, a.v.ln(), 1.0 / a.v)),
            Operator::make_unary("log2", |a| {
                chain(a, a.v.log2(), 1.0 / (a.v * std::f64::consts::LN_2))
            }),
            Operator::make_unary("log10", |a| {
                chain(a, a.v.log10(), 1.0 / (a.v * std::f64::consts::LN_10))
            }),
            Operator::make_unary("log", |a| chain(a, a.v.ln(), 1.0 / a.v)),
            constant("PI", PI),
            constant("π", PI),
            constant("E", E),
            constant("e", E),
            constant("TAU", TAU),
            constant("τ", TAU),
        ]
    }
}

/// Where one variable of the expression comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Slot {
    Input(usize),
    Parameter(usize),
}

/// A static map w = f(z; θ) written as an expression in the inputs `z0, z1, …` (`z` for a
/// single input) and named parameters (see the [module docs](self)).
///
/// ```
/// use structid_core::{Interpolant, ParametricMap};
/// let f = ParametricMap::parse("k*sqrt(abs(z0))", 1, vec![("k".into(), 0.5)]).unwrap();
/// assert_eq!(f.eval(&[4.0]), 1.0);
/// let (mut dz, mut dp) = ([0.0], [0.0]);
/// assert_eq!(f.gradient(&[4.0], &mut dz, &mut dp), 1.0);
/// assert!((dz[0] - 0.125).abs() < 1e-15 && (dp[0] - 2.0).abs() < 1e-15);
/// assert!(ParametricMap::parse("k*z0", 1, vec![]).is_err()); // k is not declared
/// ```
#[derive(Clone, Debug)]
pub struct ParametricMap {
    text: String,
    dim: usize,
    names: Vec<String>,
    values: Vec<f64>,
    expr: FlatEx<f64>,
    dual: FlatEx<Dual, DualOps>,
    slots: Vec<Slot>,
}

impl ParametricMap {
    /// Parses `text` as a map of `dim` inputs with the named `parameters` (name, value).
    ///
    /// # Errors
    /// [`Error::Expression`] for a parse error, an unknown function or variable, or a
    /// parameter name that is an input's or a constant's; [`Error::InvalidParameter`] for a
    /// value that is not finite.
    pub fn parse(text: &str, dim: usize, parameters: Vec<(String, f64)>) -> Result<Self> {
        let err = |reason: String| expression_error(text, reason);
        check_functions(text)?;
        let constants = ["PI", "π", "E", "e", "TAU", "τ"];
        for (i, (name, v)) in parameters.iter().enumerate() {
            let input_like = name == "z"
                || name
                    .strip_prefix('z')
                    .is_some_and(|s| s.parse::<usize>().is_ok());
            let ident = name.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
                && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            if !ident
                || input_like
                || constants.contains(&name.as_str())
                || function_names().contains(&name.as_str())
            {
                return Err(err(format!(
                    "`{name}` cannot name a parameter: a parameter is an ASCII identifier other \
                     than the inputs z, z0, z1, …, the constants and the functions"
                )));
            }
            if parameters[..i].iter().any(|(n, _)| n == name) {
                return Err(err(format!("parameter `{name}` is declared twice")));
            }
            if !v.is_finite() {
                return Err(Error::InvalidParameter {
                    name: name.clone(),
                    value: *v,
                    reason: "a parameter's value must be finite".into(),
                });
            }
        }
        let expr = exmex::parse::<f64>(text).map_err(|e| err(e.to_string()))?;
        let dual = FlatEx::<Dual, DualOps>::parse(text).map_err(|e| err(e.to_string()))?;
        let mut slots = Vec::new();
        for name in expr.var_names() {
            let slot = if let Some(p) = parameters.iter().position(|(n, _)| n == name) {
                Slot::Parameter(p)
            } else if name == "z" && dim == 1 {
                Slot::Input(0)
            } else if let Some(i) = name.strip_prefix('z').and_then(|s| s.parse::<usize>().ok()) {
                if i >= dim {
                    return Err(err(format!(
                        "variable `{name}` refers to input {i}, but the map has {dim} input(s)"
                    )));
                }
                Slot::Input(i)
            } else {
                let declared: Vec<&str> = parameters.iter().map(|(n, _)| n.as_str()).collect();
                return Err(err(format!(
                    "unknown variable `{name}`: neither an input (z0…z{}) nor a declared parameter ({})",
                    dim.saturating_sub(1),
                    if declared.is_empty() {
                        "none declared".to_string()
                    } else {
                        declared.join(", ")
                    }
                )));
            };
            slots.push(slot);
        }
        let (names, values) = parameters.into_iter().unzip();
        Ok(Self {
            text: text.to_string(),
            dim,
            names,
            values,
            expr,
            dual,
            slots,
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

    /// The parameters' names, in declaration order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The parameters' values, in declaration order.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The same family with parameter values `values`.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] for a wrong count, [`Error::InvalidParameter`] for a
    /// value that is not finite.
    pub fn with_values(&self, values: &[f64]) -> Result<Self> {
        if values.len() != self.values.len() {
            return Err(Error::DimensionMismatch {
                what: format!("parameters of `{}`", self.text),
                expected: self.values.len().to_string(),
                found: values.len().to_string(),
            });
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(Error::InvalidParameter {
                name: self.names[i].clone(),
                value: values[i],
                reason: "a parameter's value must be finite".into(),
            });
        }
        Ok(Self {
            values: values.to_vec(),
            ..self.clone()
        })
    }

    fn value_of(&self, slot: Slot, z: &[f64]) -> f64 {
        match slot {
            Slot::Input(i) => z.get(i).copied().unwrap_or(f64::NAN),
            Slot::Parameter(p) => self.values[p],
        }
    }

    /// f(z; θ), writing ∂f/∂z into `dw_dz` (p) and ∂f/∂θ into `dw_dp` (n_θ).
    pub fn gradient(&self, z: &[f64], dw_dz: &mut [f64], dw_dp: &mut [f64]) -> f64 {
        dw_dz.fill(0.0);
        dw_dp.fill(0.0);
        let mut vars: Vec<Dual> = self
            .slots
            .iter()
            .map(|&s| Dual {
                v: self.value_of(s, z),
                d: 0.0,
            })
            .collect();
        for (k, slot) in self.slots.iter().enumerate() {
            vars[k].d = 1.0;
            let d = self.dual.eval(&vars).map_or(f64::NAN, |r| r.d);
            vars[k].d = 0.0;
            // Where the law has no finite derivative (√|z| at 0), its one-sided slopes are
            // infinite; a zero keeps the sensitivities finite, as for a jump.
            let d = if d.is_finite() { d } else { 0.0 };
            match *slot {
                Slot::Input(i) if i < dw_dz.len() => dw_dz[i] += d,
                Slot::Parameter(p) if p < dw_dp.len() => dw_dp[p] += d,
                _ => {}
            }
        }
        self.eval(z)
    }
}

impl Interpolant for ParametricMap {
    fn eval(&self, z: &[f64]) -> f64 {
        let vars: Vec<f64> = self.slots.iter().map(|&s| self.value_of(s, z)).collect();
        self.expr.eval(&vars).unwrap_or(f64::NAN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of f along one variable.
    fn central(f: &ParametricMap, z: &[f64], input: Option<usize>, param: Option<usize>) -> f64 {
        let h = 1e-6;
        let (mut zp, mut zm) = (z.to_vec(), z.to_vec());
        let (mut vp, mut vm) = (f.values().to_vec(), f.values().to_vec());
        if let Some(i) = input {
            zp[i] += h;
            zm[i] -= h;
        }
        if let Some(p) = param {
            vp[p] += h;
            vm[p] -= h;
        }
        let (fp, fm) = (f.with_values(&vp).unwrap(), f.with_values(&vm).unwrap());
        (fp.eval(&zp) - fm.eval(&zm)) / (2.0 * h)
    }

    #[test]
    fn dual_derivatives_match_central_differences_through_every_smooth_function() {
        let exprs = [
            "a*sin(z0)^2 + b*cos(z1) - tan(0.3*z0)",
            "a*exp(-z0^2/b) + ln(2 + z1) + log10(3 + z0) + log2(4 + z1) + log(5 + a)",
            "sqrt(1 + z0^2)*b + cbrt(2 + z1) + atan2(z1, 1 + a) + atan(z0)",
            "asin(0.3*z0) + acos(0.2*z1) + sinh(a*z0) + cosh(z1) + tanh(b*z1)",
            "asinh(z0) + acosh(2 + z1^2) + atanh(0.4*z0) + a^z1 + z0^b",
            "abs(z0 - 0.1)*a + min(z0, z1)*b + max(a*z0, z1) + signum(z1)*a + floor(z0)*b",
            "a/(1 + z0^2) - b*z1/(a + 3) + PI*z0 + E*a",
        ];
        let z = [0.7, 0.45];
        for text in exprs {
            let f =
                ParametricMap::parse(text, 2, vec![("a".into(), 1.3), ("b".into(), 2.1)]).unwrap();
            let (mut dz, mut dp) = ([0.0; 2], [0.0; 2]);
            let v = f.gradient(&z, &mut dz, &mut dp);
            assert_eq!(v, f.eval(&z), "{text}");
            for i in 0..2 {
                let fd = central(&f, &z, Some(i), None);
                assert!(
                    (dz[i] - fd).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{text}: ∂/∂z{i} {} vs {fd}",
                    dz[i]
                );
                let fd = central(&f, &z, None, Some(i));
                assert!(
                    (dp[i] - fd).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{text}: ∂/∂θ{i} {} vs {fd}",
                    dp[i]
                );
            }
        }
    }

    #[test]
    fn an_infinite_slope_is_taken_as_zero() {
        let f = ParametricMap::parse("k*sqrt(abs(z0))", 1, vec![("k".into(), 0.5)]).unwrap();
        let (mut dz, mut dp) = ([1.0], [1.0]);
        assert_eq!(f.gradient(&[0.0], &mut dz, &mut dp), 0.0);
        assert_eq!((dz[0], dp[0]), (0.0, 0.0));
    }

    #[test]
    fn a_parameter_used_twice_and_the_single_input_z_sum_their_derivatives() {
        let f = ParametricMap::parse("k*z + k^2", 1, vec![("k".into(), 3.0)]).unwrap();
        let (mut dz, mut dp) = ([0.0], [0.0]);
        assert_eq!(f.gradient(&[2.0], &mut dz, &mut dp), 15.0);
        assert_eq!((dz[0], dp[0]), (3.0, 2.0 + 6.0));
    }

    #[test]
    fn bad_declarations_are_named() {
        let p = |n: &str| vec![(n.to_string(), 1.0)];
        for (text, params, needle) in [
            ("k*z0", vec![], "`k`"),
            ("z0", p("z1"), "`z1`"),
            ("z0", p("e"), "`e`"),
            ("z0", p("sin"), "`sin`"),
            ("z0", p("2k"), "`2k`"),
            ("z0", p("ω"), "`ω`"),
            ("z2*k", p("k"), "z2"),
            ("k*z0", vec![("k".into(), 1.0), ("k".into(), 2.0)], "twice"),
            ("frob(z0)*k", p("k"), "frob"),
        ] {
            let e = ParametricMap::parse(text, 1, params)
                .unwrap_err()
                .to_string();
            assert!(e.contains(needle), "{text}: {e}");
        }
        let e = ParametricMap::parse("k*z0", 1, p("k"))
            .unwrap()
            .with_values(&[f64::NAN]);
        assert!(e.is_err());
    }
}
