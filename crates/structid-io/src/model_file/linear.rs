//! The `[linear]` section: a polynomial linear block G in a named structure ([`LinearSpec`]).

use std::sync::Arc;

use serde::Deserialize;
use structid_core::refine::LinearStructure;
use structid_core::{Dispersion, Lft, PolynomialDispersion, Site};
use structid_linear::PolynomialModel;
use toml::Spanned;

use super::lft::Dim;
use super::source::{Source, err_at, plural};
use crate::error::IoError;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawLinear {
    structure: Spanned<String>,
    sample_time: Option<Spanned<f64>>,
    den: Spanned<Vec<f64>>,
    num: Spanned<Vec<Vec<f64>>>,
    num_w: Option<Spanned<Vec<f64>>>,
}

/// The `[linear] structure` names in the order of the documentation: the sites of
/// [`Site::name`] and `lti`, a linear model without a map.
pub const LINEAR_STRUCTURES: [&str; 5] =
    ["output-feedback", "input", "output", "rate-feedback", "lti"];

/// The site a `[linear] structure` name places the block at: `Some(None)` for `lti` (no
/// block), `None` for an unknown name.
pub fn parse_linear_structure(name: &str) -> Option<Option<Site>> {
    if name == "lti" {
        Some(None)
    } else {
        Site::parse(name).map(Some)
    }
}

/// A `[linear]` section: a polynomial linear block G (one output) in a named structure.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearSpec {
    /// Where the block sits (`None`: `structure = "lti"`, no block).
    pub structure: Option<Site>,
    /// G in the structure's form: for output feedback its inputs are [u…, w] (the last
    /// numerator is the effect of w on y, −B_u unless `num_w` was given); for an input map its
    /// one input is w; for an output (sensor) map and rate feedback its one input is u; for
    /// `lti` its inputs are u.
    pub model: PolynomialModel,
    /// Whether the feedback path has its own numerator (`num_w` given).
    pub separate_numerator: bool,
}

impl LinearSpec {
    /// The linear model `g` (its inputs are u) in the structure of `site` (`None`: `lti`):
    /// for output feedback the feedback path starts as the input path, y = G·(u − w), i.e.
    /// num = [B, −B] with a shared numerator.
    ///
    /// ```
    /// use structid_core::Site;
    /// use structid_io::LinearSpec;
    /// use structid_linear::PolynomialModel;
    /// let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: None };
    /// let spec = LinearSpec::from_linear(&g, Some(Site::OutputFeedback));
    /// assert_eq!(spec.model.num, vec![vec![0.0, 1.0], vec![-0.0, -1.0]]);
    /// assert_eq!(spec.structure_name(), "output-feedback");
    /// ```
    pub fn from_linear(g: &PolynomialModel, site: Option<Site>) -> Self {
        let mut model = g.clone();
        if site == Some(Site::OutputFeedback)
            && let Some(b) = g.num.first()
        {
            model.num.push(b.iter().map(|x| -x).collect());
        }
        Self {
            structure: site,
            model,
            separate_numerator: false,
        }
    }

    /// The `[linear] structure` name: the site's name, or `lti`.
    pub fn structure_name(&self) -> &'static str {
        self.structure.map_or("lti", Site::name)
    }

    /// Whether `structid refine` (a [`LinearStructure`]) supports the structure: every
    /// structure with a map (output feedback, rate feedback, an input and an output map);
    /// not `lti`, which has none.
    pub fn refinable(&self) -> bool {
        self.structure.is_some()
    }

    /// The structure as a [`LinearStructure`] for [`structid_core::refine::refine`]; `block`
    /// names the map. `None` for `lti` (no map).
    pub fn structure(&self, block: &str) -> Option<LinearStructure> {
        let site = self.structure?;
        LinearStructure::new(block, site)
            .ok()
            .map(|s| s.with_separate_numerator(self.separate_numerator))
    }

    /// The LFT of this linear block in its structure.
    pub fn lft(&self) -> Result<Lft, IoError> {
        Ok(match self.structure {
            Some(Site::OutputFeedback | Site::Input) => self
                .structure(BLOCK_PLACEHOLDER)
                .expect("output feedback and input maps are refinable structures")
                .lft(&self.model)?,
            // The LFT does not depend on the block's dispersion.
            _ => self
                .to_structure(BLOCK_PLACEHOLDER, Arc::new(PolynomialDispersion::new(1)?))
                .lft()?,
        })
    }

    /// The [`Structure`](structid_core::Structure) of this block: G in its structure's form,
    /// the block called `block` at its site with `dispersion`.
    pub fn to_structure(&self, block: &str, d: Arc<dyn Dispersion>) -> structid_core::Structure {
        use structid_core::Structure;
        match self.structure {
            None => Structure::linear(&self.model),
            Some(Site::OutputFeedback) => Structure::output_feedback_with_path(&self.model, d),
            Some(site) => Structure::new(&self.model, site, d),
        }
        .named(block)
    }
}

const BLOCK_PLACEHOLDER: &str = "N";

/// The `[linear]` section: a polynomial G in a named structure, realised as an LFT.
pub(super) fn parse_linear(
    raw: RawLinear,
    line: usize,
    u: &[String],
    y: &[String],
    z_names: &Option<(Vec<String>, usize)>,
    src: &Source<'_>,
) -> Result<(LinearSpec, Lft, Dim, Dim), IoError> {
    let structure_line = src.line(raw.structure.span().start);
    let Some(structure) = parse_linear_structure(raw.structure.get_ref()) else {
        return Err(err_at(
            structure_line,
            format!(
                "[linear] structure = \"{}\" is unknown; supported: {}",
                raw.structure.get_ref(),
                LINEAR_STRUCTURES
                    .iter()
                    .map(|k| format!("\"{k}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    };
    let structure_name = structure.map_or("lti", Site::name);
    if y.len() != 1 {
        return Err(err_at(
            line,
            format!(
                "[linear] describes a block with one output, but [signals].y names {}",
                plural(y.len(), "output")
            ),
        ));
    }
    if let Some((_, zl)) = z_names {
        return Err(err_at(
            *zl,
            "[signals].z is not used with [linear]: the structure fixes z (y for output feedback, u for an input map, \
             G·u for an output map, Δy/T_s for rate feedback)",
        ));
    }
    let sample_time = match &raw.sample_time {
        Some(ts) if !(ts.get_ref().is_finite() && *ts.get_ref() > 0.0) => {
            return Err(err_at(
                src.line(ts.span().start),
                format!(
                    "sample_time = {} is invalid; it must be a finite number of seconds greater than zero",
                    ts.get_ref()
                ),
            ));
        }
        Some(ts) => Some(*ts.get_ref()),
        None => None,
    };
    let den_line = src.line(raw.den.span().start);
    let den = raw.den.get_ref().clone();
    if den.is_empty() || den[0] == 0.0 || den.iter().any(|v| !v.is_finite()) {
        return Err(err_at(
            den_line,
            "[linear] den must list finite coefficients of 1, q⁻¹, q⁻², … with a nonzero first one",
        ));
    }
    let num_line = src.line(raw.num.span().start);
    let mut num = raw.num.get_ref().clone();
    if num.iter().flatten().any(|v| !v.is_finite()) {
        return Err(err_at(
            num_line,
            "[linear] num has a coefficient that is not finite",
        ));
    }
    let single_input = matches!(
        structure,
        Some(Site::Input | Site::Output | Site::RateFeedback)
    );
    let expected = if single_input { 1 } else { u.len() };
    if single_input && u.len() != 1 {
        return Err(err_at(
            line,
            format!(
                "structure = \"{}\" has one input u, but [signals].u names {}",
                structure_name,
                plural(u.len(), "input")
            ),
        ));
    }
    if num.len() != expected {
        return Err(err_at(
            num_line,
            format!(
                "[linear] num has {} but the structure needs {expected} (one per input u)",
                plural(num.len(), "numerator")
            ),
        ));
    }
    // An all-zero numerator would be read as "no path at all" (the delay is read from the
    // leading zeros), so refinement could never move it.
    if structure.is_some()
        && let Some(i) = num.iter().position(|b| b.iter().all(|v| *v == 0.0))
    {
        return Err(err_at(
            num_line,
            format!(
                "[linear] num[{i}] is all zeros: start from small nonzero coefficients after the \
                 delay (e.g. [0.0, 0.01]) so that the path can be estimated"
            ),
        ));
    }
    if let Some(nw) = &raw.num_w
        && nw.get_ref().iter().all(|v| *v == 0.0)
    {
        return Err(err_at(
            src.line(nw.span().start),
            "[linear] num_w is all zeros: start from small nonzero coefficients after the delay \
             (e.g. [0.0, -0.01]) so that the feedback path can be estimated",
        ));
    }
    let mut separate = false;
    match (&raw.num_w, structure) {
        (Some(nw), Some(Site::OutputFeedback)) => {
            let l = src.line(nw.span().start);
            let nw = nw.get_ref();
            if nw.iter().any(|v| !v.is_finite()) {
                return Err(err_at(
                    l,
                    "[linear] num_w has a coefficient that is not finite",
                ));
            }
            if nw.first().is_some_and(|b| *b != 0.0) {
                return Err(err_at(
                    l,
                    "[linear] num_w starts with a direct term; the feedback path needs a delay \
                     (num_w = [0.0, …]), otherwise y_k depends on N(y_k)",
                ));
            }
            separate = true;
            num.push(nw.clone());
        }
        (Some(nw), _) => {
            return Err(err_at(
                src.line(nw.span().start),
                format!(
                    "num_w (a separate feedback numerator) only applies to structure = \"output-feedback\", not \"{}\"",
                    structure_name
                ),
            ));
        }
        (None, Some(Site::OutputFeedback)) => {
            if u.len() != 1 {
                return Err(err_at(
                    line,
                    "an output-feedback structure with several inputs u needs its feedback numerator num_w",
                ));
            }
            if num[0].first().is_some_and(|b| *b != 0.0) {
                return Err(err_at(
                    num_line,
                    "[linear] num starts with a direct term; the feedback path shares it and needs \
                     a delay (num = [[0.0, …]]), otherwise y_k depends on N(y_k)",
                ));
            }
            let bw: Vec<f64> = num[0].iter().map(|x| -x).collect();
            num.push(if bw.is_empty() { vec![0.0] } else { bw });
        }
        (None, Some(Site::RateFeedback)) => {
            if num[0].first().is_some_and(|b| *b != 0.0) {
                return Err(err_at(
                    num_line,
                    "[linear] num starts with a direct term; rate feedback needs a delay \
                     (num = [[0.0, …]]), otherwise y_k depends on N(ẏ_k)",
                ));
            }
        }
        (None, _) => {}
    }
    let spec = LinearSpec {
        structure,
        model: PolynomialModel {
            num,
            den,
            sample_time,
        },
        separate_numerator: separate,
    };
    let lft = spec.lft().map_err(|e| err_at(line, e.to_string()))?;
    let (nz, nw) = (lft.dims().z, lft.dims().w);
    let what = match structure {
        Some(Site::OutputFeedback) => "one map in feedback from y (z = y)",
        Some(Site::Input) => "one map at the input (z = u)",
        Some(Site::Output) => "one map at the output (z = G·u)",
        Some(Site::RateFeedback) => "one map in feedback from the rate of y (z = Δy/T_s)",
        Some(Site::Declared { .. }) | None => "no map",
    };
    let dim = |value: usize| Dim {
        value,
        source: format!("[linear] structure = \"{structure_name}\" has {what}"),
        line: Some(structure_line),
    };
    Ok((spec, lft, dim(nz), dim(nw)))
}
