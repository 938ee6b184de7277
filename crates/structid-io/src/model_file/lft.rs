//! The `[lft]` section: the twelve matrices of the known block, their dimensions and the time
//! base.

use nalgebra::DMatrix;
use serde::Deserialize;
use structid_core::{Lft, LftMatrices};
use structid_lti::ContinuousStateSpace;
use toml::Spanned;

use super::source::{Source, entries, err_at, plural};
use crate::error::IoError;

type RawMatrix = Spanned<Vec<Spanned<Vec<f64>>>>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLft {
    time: Option<Spanned<String>>,
    sample_time: Option<Spanned<f64>>,
    #[serde(rename = "A", alias = "a")]
    a: Option<RawMatrix>,
    #[serde(rename = "Bu", alias = "bu", alias = "B_u")]
    bu: Option<RawMatrix>,
    #[serde(rename = "Be", alias = "be", alias = "B_e")]
    be: Option<RawMatrix>,
    #[serde(rename = "Bw", alias = "bw", alias = "B_w")]
    bw: Option<RawMatrix>,
    #[serde(rename = "Cy", alias = "cy", alias = "C_y")]
    cy: Option<RawMatrix>,
    #[serde(rename = "Dyu", alias = "dyu", alias = "D_yu")]
    dyu: Option<RawMatrix>,
    #[serde(rename = "Dye", alias = "dye", alias = "D_ye")]
    dye: Option<RawMatrix>,
    #[serde(rename = "Dyw", alias = "dyw", alias = "D_yw")]
    dyw: Option<RawMatrix>,
    #[serde(rename = "Cz", alias = "cz", alias = "C_z")]
    cz: Option<RawMatrix>,
    #[serde(rename = "Dzu", alias = "dzu", alias = "D_zu")]
    dzu: Option<RawMatrix>,
    #[serde(rename = "Dze", alias = "dze", alias = "D_ze")]
    dze: Option<RawMatrix>,
    #[serde(rename = "Dzw", alias = "dzw", alias = "D_zw")]
    dzw: Option<RawMatrix>,
}

struct MatIn {
    name: &'static str,
    given: bool,
    line: usize,
    rows: Vec<Vec<f64>>,
    row_lines: Vec<usize>,
}

impl MatIn {
    fn new(
        name: &'static str,
        raw: Option<RawMatrix>,
        src: &Source<'_>,
        fallback_line: usize,
    ) -> Result<Self, IoError> {
        let Some(raw) = raw else {
            return Ok(Self {
                name,
                given: false,
                line: fallback_line,
                rows: Vec::new(),
                row_lines: Vec::new(),
            });
        };
        let line = src.line(raw.span().start);
        let mut rows = Vec::new();
        let mut row_lines = Vec::new();
        for r in raw.into_inner() {
            row_lines.push(src.line(r.span().start));
            rows.push(r.into_inner());
        }
        let m = Self {
            name,
            given: true,
            line,
            rows,
            row_lines,
        };
        if let Some(first) = m.rows.first() {
            for (i, r) in m.rows.iter().enumerate() {
                if r.len() != first.len() {
                    return Err(err_at(
                        m.row_lines[i],
                        format!(
                            "matrix {name}: row {} has {} but row 1 has {}; all rows need the same length",
                            i + 1,
                            entries(r.len()),
                            entries(first.len()),
                        ),
                    ));
                }
                if let Some(j) = r.iter().position(|v| !v.is_finite()) {
                    return Err(err_at(
                        m.row_lines[i],
                        format!(
                            "matrix {name} has the non-finite entry {} at row {}, column {}",
                            r[j],
                            i + 1,
                            j + 1
                        ),
                    ));
                }
            }
        }
        Ok(m)
    }

    /// Rows, when the matrix is given and not `[]`.
    fn known_rows(&self) -> Option<usize> {
        (self.given && !self.rows.is_empty()).then_some(self.rows.len())
    }

    /// Columns, when the matrix is given and has at least one row.
    fn known_cols(&self) -> Option<usize> {
        self.rows.first().map(Vec::len)
    }

    fn to_matrix(&self, rows: &Dim, cols: &Dim) -> Result<DMatrix<f64>, IoError> {
        let (r, c) = (rows.value, cols.value);
        if !self.given {
            return Ok(DMatrix::zeros(r, c));
        }
        if self.rows.is_empty() {
            if r == 0 || c == 0 {
                return Ok(DMatrix::zeros(r, c));
            }
            return Err(err_at(
                self.line,
                format!(
                    "matrix {} is empty but must be {r}×{c}: {}, and {}",
                    self.name, rows.source, cols.source
                ),
            ));
        }
        if self.rows.len() != r {
            return Err(err_at(
                self.line,
                format!(
                    "matrix {} has {} but {}",
                    self.name,
                    plural(self.rows.len(), "row"),
                    rows.source
                ),
            ));
        }
        let nc = self.rows[0].len();
        if nc != c {
            return Err(err_at(
                self.line,
                format!(
                    "matrix {} has {} but {}",
                    self.name,
                    plural(nc, "column"),
                    cols.source
                ),
            ));
        }
        Ok(DMatrix::from_fn(r, c, |i, j| self.rows[i][j]))
    }
}

/// A dimension and a phrase saying where it comes from, for error messages.
pub(super) struct Dim {
    pub(super) value: usize,
    pub(super) source: String,
    pub(super) line: Option<usize>,
}

impl Dim {
    /// The error at `line` for `what` (e.g. "block `b` writes w[3]") reaching past this
    /// dimension, counted in `unit`s.
    pub(super) fn out_of_range(&self, line: usize, what: &str, unit: &str) -> IoError {
        err_at(
            line,
            format!(
                "{what} but the model has {} (indices 0…): {}",
                plural(self.value, unit),
                self.source
            ),
        )
    }
}

fn infer_cols(mats: &[&MatIn], what: &str, sym: &str) -> Dim {
    for m in mats {
        if let Some(c) = m.known_cols() {
            return Dim {
                value: c,
                source: format!(
                    "{} has {} ({sym} = {})",
                    m.name,
                    plural(c, "column"),
                    plural(c, what)
                ),
                line: Some(m.line),
            };
        }
    }
    let names: Vec<&str> = mats.iter().map(|m| m.name).collect();
    Dim {
        value: 0,
        source: format!("none of {} has a column, so {sym} = 0", names.join(", ")),
        line: None,
    }
}

/// The `[lft]` section: the twelve matrices, their dimensions and the time base.
pub(super) fn parse_lft(
    raw_lft: RawLft,
    lft_line: usize,
    u: &[String],
    y: &[String],
    z_names: &Option<(Vec<String>, usize)>,
    src: &Source<'_>,
) -> Result<(Lft, Dim, Dim), IoError> {
    // Matrices.
    let mat = |name, raw| MatIn::new(name, raw, src, lft_line);
    let a = mat("A", raw_lft.a)?;
    let bu = mat("Bu", raw_lft.bu)?;
    let be = mat("Be", raw_lft.be)?;
    let bw = mat("Bw", raw_lft.bw)?;
    let cy = mat("Cy", raw_lft.cy)?;
    let dyu = mat("Dyu", raw_lft.dyu)?;
    let dye = mat("Dye", raw_lft.dye)?;
    let dyw = mat("Dyw", raw_lft.dyw)?;
    let cz = mat("Cz", raw_lft.cz)?;
    let dzu = mat("Dzu", raw_lft.dzu)?;
    let dze = mat("Dze", raw_lft.dze)?;
    let dzw = mat("Dzw", raw_lft.dzw)?;

    let n = a.known_rows().unwrap_or(0);
    if let Some(c) = a.known_cols()
        && c != n
    {
        return Err(err_at(
            a.line,
            format!(
                "matrix A has {} and {}; it must be square (n×n)",
                plural(n, "row"),
                plural(c, "column")
            ),
        ));
    }
    let dn = Dim {
        value: n,
        source: if n > 0 {
            format!("A is {n}×{n} (n = {})", plural(n, "state"))
        } else if a.given {
            "A is empty (n = 0 states)".into()
        } else {
            "A is not given (n = 0 states)".into()
        },
        line: Some(a.line),
    };
    let du = Dim {
        value: u.len(),
        source: format!("[signals].u names {}", plural(u.len(), "input")),
        line: None,
    };
    let dy = Dim {
        value: y.len(),
        source: format!("[signals].y names {}", plural(y.len(), "output")),
        line: None,
    };
    let de = infer_cols(&[&be, &dye, &dze], "noise channel", "n_e");
    let dw = infer_cols(&[&bw, &dyw, &dzw], "map output", "n_w");
    let dz = {
        let from_mat = [&cz, &dzu, &dze, &dzw]
            .into_iter()
            .find_map(|m| m.known_rows().map(|r| (m, r)));
        match (from_mat, z_names) {
            (Some((m, r)), _) => Dim {
                value: r,
                source: format!(
                    "{} has {} (n_z = {})",
                    m.name,
                    plural(r, "row"),
                    plural(r, "map input")
                ),
                line: Some(m.line),
            },
            (None, Some((names, _))) => Dim {
                value: names.len(),
                source: format!("[signals].z names {}", plural(names.len(), "column")),
                line: None,
            },
            (None, None) => Dim {
                value: 0,
                source: "none of Cz, Dzu, Dze, Dzw has a row, so n_z = 0".into(),
                line: None,
            },
        }
    };
    let mut m = LftMatrices {
        a: a.to_matrix(&dn, &dn)?,
        bu: bu.to_matrix(&dn, &du)?,
        be: be.to_matrix(&dn, &de)?,
        bw: bw.to_matrix(&dn, &dw)?,
        cy: cy.to_matrix(&dy, &dn)?,
        dyu: dyu.to_matrix(&dy, &du)?,
        dye: dye.to_matrix(&dy, &de)?,
        dyw: dyw.to_matrix(&dy, &dw)?,
        cz: cz.to_matrix(&dz, &dn)?,
        dzu: dzu.to_matrix(&dz, &du)?,
        dze: dze.to_matrix(&dz, &de)?,
        dzw: dzw.to_matrix(&dz, &dw)?,
    };
    if let Some((names, line)) = z_names
        && names.len() != dz.value
    {
        return Err(err_at(
            *line,
            format!(
                "[signals].z names {} but {}",
                plural(names.len(), "column"),
                dz.source
            ),
        ));
    }

    // Time base.
    let sample_time = match &raw_lft.sample_time {
        Some(ts) => {
            let v = *ts.get_ref();
            if !(v.is_finite() && v > 0.0) {
                return Err(err_at(
                    src.line(ts.span().start),
                    format!(
                        "sample_time = {v} is invalid; it must be a finite number of seconds greater than zero"
                    ),
                ));
            }
            Some(v)
        }
        None => None,
    };
    match raw_lft
        .time
        .as_ref()
        .map(|t| (t.get_ref().as_str(), src.line(t.span().start)))
    {
        None | Some(("discrete", _)) => {}
        Some(("continuous", line)) => {
            let Some(ts) = sample_time else {
                return Err(err_at(
                    line,
                    "time = \"continuous\" needs a sample_time (seconds) for the zero-order-hold discretisation",
                ));
            };
            let (ne, nw, nu) = (de.value, dw.value, du.value);
            let mut b = DMatrix::zeros(n, nu + ne + nw);
            b.columns_mut(0, nu).copy_from(&m.bu);
            b.columns_mut(nu, ne).copy_from(&m.be);
            b.columns_mut(nu + ne, nw).copy_from(&m.bw);
            let sys = ContinuousStateSpace::new(
                m.a.clone(),
                b,
                DMatrix::zeros(0, n),
                DMatrix::zeros(0, nu + ne + nw),
            )
            .and_then(|s| s.discretize_zoh(ts))
            .map_err(|e| {
                err_at(
                    line,
                    format!("cannot discretise the continuous-time block: {e}"),
                )
            })?;
            m.a = sys.a().clone();
            m.bu = sys.b().columns(0, nu).into_owned();
            m.be = sys.b().columns(nu, ne).into_owned();
            m.bw = sys.b().columns(nu + ne, nw).into_owned();
        }
        Some((other, line)) => {
            return Err(err_at(
                line,
                format!(
                    "time = \"{other}\" is not supported; use \"discrete\" (default) or \"continuous\""
                ),
            ));
        }
    }
    let mut lft = Lft::new(m).map_err(|e| err_at(lft_line, e.to_string()))?;
    if let Some(ts) = sample_time {
        lft = lft
            .with_sample_time(ts)
            .map_err(|e| err_at(lft_line, e.to_string()))?;
    }

    Ok((lft, dz, dw))
}
