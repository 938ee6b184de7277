//! The discover workflow: a nominal model file and records in; the search for what the model
//! is missing ([`structid_discover`]) for one effect or several in turn out, with the model
//! file and nominal model of the step it reports. `structid discover` and Python's
//! `structid.discover` both run it.

use std::sync::Arc;

use structid_core::validation::{Scoring, Windows};
use structid_core::{Data, Site};
use structid_discover::discover::{
    DiscoverSettings, Discovery, Effects, EffectsSettings, discover, discover_effects,
};
use structid_discover::hypotheses::Nominal;
use structid_io::ModelFile;

use crate::error::{Result, WorkflowError};

/// The nominal model of a model file: `[linear] structure = "lti"` or an `[lft]`, one input,
/// one output, no measured z, with the locations and states its `[discover]` section
/// declares. A file with `[[nonlinearity]]` blocks (the `augmented.toml` of an earlier run)
/// is a nominal model that carries maps: every block needs a `truth` (the known map, kept
/// fixed) and one z input. `label` names the file in messages.
///
/// # Errors
/// [`WorkflowError::Request`] for a model that cannot be a nominal model, saying why.
pub fn nominal_model(mf: &ModelFile, label: &str) -> Result<Nominal> {
    let request = |m: String| WorkflowError::Request(m);
    for b in &mf.blocks {
        if b.truth.is_none() {
            return Err(request(format!(
                "`{label}`: block `{}` has no `truth`: a nominal model's maps must be known (give \
                 the map as `truth = \"expression in z0\"` or a table, as discovery writes \
                 augmented.toml), or remove the block",
                b.name
            )));
        }
        if b.inputs.len() != 1 {
            return Err(request(format!(
                "`{label}`: block `{}` reads {} z signals; a map of a nominal model reads one",
                b.name,
                b.inputs.len()
            )));
        }
    }
    if mf.signals.u.len() != 1 || mf.signals.y.len() != 1 {
        return Err(request(format!(
            "`{label}` has {} input(s) and {} output(s) in [signals]; discovery needs a nominal \
             model with one input and one output",
            mf.signals.u.len(),
            mf.signals.y.len()
        )));
    }
    if mf.signals.z.is_some() {
        return Err(request(format!(
            "`{label}` lists measured z columns ([signals].z); discovery computes z for each \
             candidate location itself: remove [signals].z"
        )));
    }
    let mut nominal = match &mf.linear {
        _ if !mf.blocks.is_empty() => known_maps_nominal(mf, label)?,
        Some(spec) if spec.structure.is_none() => Nominal::from_polynomial(&spec.model)?,
        Some(spec) => {
            return Err(WorkflowError::NotNominal(format!(
                "`{label}` has [linear] structure = \"{}\"; discovery needs structure = \"lti\" \
                 (a linear model, or an [lft] without [[nonlinearity]])",
                spec.structure_name()
            )));
        }
        None => Nominal::new(mf.lft.clone())?,
    };
    if let Some(d) = &mf.discover {
        for l in &d.locations {
            nominal = nominal.with_location(&l.name, l.z, l.w)?;
        }
        for st in &d.states {
            nominal = nominal.with_state(&st.name, st.state)?;
        }
    }
    Ok(nominal)
}

/// The nominal model of a file with `[[nonlinearity]]` blocks: its LFT with every block's
/// truth as a fixed map.
fn known_maps_nominal(mf: &ModelFile, label: &str) -> Result<Nominal> {
    let context = |e: String| {
        WorkflowError::Request(format!(
            "`{label}` cannot be a nominal model with maps: {e}"
        ))
    };
    let maps = mf
        .truth_maps()
        .map_err(|e| context(e.to_string()))?
        .ok_or_else(|| context("a block has no truth".into()))?;
    // The maps are fixed, so the model of the file's structure serves: its dispersions play
    // no part.
    let model = mf.structure_model().map_err(|e| context(e.to_string()))?;
    Nominal::from_model(&model, maps.into_iter().map(Arc::from).collect())
        .map_err(|e| context(e.to_string()))
}

/// How simulations are scored, as the front ends write it: `free` or windows `LENGTH:INIT`.
///
/// ```
/// use structid_core::validation::Scoring;
/// use structid_workflow::discover::parse_scoring;
/// assert_eq!(parse_scoring("free").unwrap(), Scoring::Free);
/// assert!(parse_scoring("500:25").is_ok());
/// assert!(parse_scoring("often").is_err());
/// ```
///
/// # Errors
/// A message saying what is wrong with `s`.
pub fn parse_scoring(s: &str) -> std::result::Result<Scoring, String> {
    if s == "free" {
        return Ok(Scoring::Free);
    }
    let (length, init) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}` is neither `free` nor LENGTH:INIT (e.g. 500:25)"))?;
    let parse = |v: &str, what: &str| {
        v.trim()
            .parse::<usize>()
            .map_err(|_| format!("{what} `{v}` in `{s}` is not a whole number of samples"))
    };
    Windows::new(parse(length, "LENGTH")?, parse(init, "INIT")?)
        .map(Scoring::Windowed)
        .map_err(|e| e.to_string())
}

/// Candidate locations by name: the keys of the built-in locations (`input`, `output`,
/// `output-feedback`, `rate-feedback`), `declared-i`, or names of declared ones; `None` for
/// every location.
///
/// # Errors
/// [`WorkflowError::InvalidOption`] for a name that is no location of `nominal` (the message
/// lists them) and for an empty list.
pub fn parse_locations(given: Option<&[String]>, nominal: &Nominal) -> Result<Option<Vec<Site>>> {
    let Some(given) = given else {
        return Ok(None);
    };
    let mut out: Vec<Site> = Vec::new();
    for raw in given {
        let s = raw.trim();
        let found = nominal
            .locations()
            .into_iter()
            .find(|l| nominal.key(*l) == s)
            .or_else(|| {
                nominal
                    .declared()
                    .iter()
                    .find(|d| d.name == s)
                    .map(|d| Site::Declared { z: d.z, w: d.w })
            });
        let Some(location) = found else {
            let mut known: Vec<String> = nominal
                .locations()
                .iter()
                .map(|l| format!("`{}`", nominal.key(*l)))
                .collect();
            known.extend(nominal.declared().iter().map(|d| format!("`{}`", d.name)));
            return Err(WorkflowError::InvalidOption {
                option: "locations",
                value: format!("`{s}`"),
                rule: format!(
                    "the candidate locations of this nominal model are {}",
                    known.join(", ")
                ),
            });
        };
        if !out.contains(&location) {
            out.push(location);
        }
    }
    if out.is_empty() {
        return Err(WorkflowError::InvalidOption {
            option: "locations",
            value: "(none)".into(),
            rule: "it names no location; omit it to try every one".into(),
        });
    }
    Ok(Some(out))
}

/// The options of a discovery as the front ends take them.
#[derive(Clone, Debug, PartialEq)]
pub struct DiscoverOptions {
    /// Try a total-variation estimate when the best family has a kink or a jump.
    pub total_variation: bool,
    /// Leading samples of each record left out of the scores.
    pub settle: usize,
    /// `auto`, `free` or `LENGTH:INIT` (see [`parse_scoring`]).
    pub scoring: String,
    /// Keep G exactly as given (no joint re-estimation with the map).
    pub keep_nominal: bool,
    /// Width of each hypothesis' Fourier kernel as a fraction of the range of its z.
    pub sigma_fraction: f64,
    /// Degree of the polynomial trend added to the kernel.
    pub trend: usize,
    /// Tune σ with β by marginal likelihood.
    pub tune_sigma: bool,
    /// Significance level of the candidate table's selection rule.
    pub significance: f64,
    /// Share of the deconvolved residual energy the direction of z must explain for a
    /// dynamic verdict.
    pub hysteresis_threshold: f64,
    /// Candidate locations by name (see [`parse_locations`]); `None`: every one.
    pub locations: Option<Vec<String>>,
}

impl Default for DiscoverOptions {
    fn default() -> Self {
        let d = DiscoverSettings::default();
        Self {
            total_variation: true,
            settle: 0,
            scoring: "auto".into(),
            keep_nominal: false,
            sigma_fraction: d.sigma_fraction(),
            trend: d.trend_degree(),
            tune_sigma: false,
            significance: d.significance(),
            hysteresis_threshold: d.hysteresis_threshold(),
            locations: None,
        }
    }
}

impl DiscoverOptions {
    /// The discovery settings of these options on `nominal`.
    ///
    /// # Errors
    /// [`WorkflowError::InvalidOption`] for a σ fraction that is not finite and positive, a
    /// trend degree above 64, a hysteresis threshold outside (0, 1), a scoring that does not
    /// parse and unknown locations; the settings' own errors.
    pub fn settings(&self, nominal: &Nominal) -> Result<DiscoverSettings> {
        let invalid = |option: &'static str, value: String, rule: &str| {
            Err(WorkflowError::InvalidOption {
                option,
                value,
                rule: rule.into(),
            })
        };
        if !(self.sigma_fraction.is_finite() && self.sigma_fraction > 0.0) {
            return invalid(
                "sigma_fraction",
                self.sigma_fraction.to_string(),
                "it must be a finite fraction of the range of z greater than zero",
            );
        }
        if self.trend > 64 {
            return invalid(
                "trend",
                self.trend.to_string(),
                "the polynomial degree must be at most 64",
            );
        }
        if !(self.hysteresis_threshold > 0.0 && self.hysteresis_threshold < 1.0) {
            return invalid(
                "hysteresis_threshold",
                self.hysteresis_threshold.to_string(),
                "it is a share of the residual energy and must lie strictly between 0 and 1",
            );
        }
        let mut b = DiscoverSettings::builder()
            .total_variation(self.total_variation)
            .settle(self.settle)
            .sigma_fraction(self.sigma_fraction)
            .trend_degree(self.trend)
            .tune_sigma(self.tune_sigma)
            .significance(self.significance)
            .hysteresis_threshold(self.hysteresis_threshold)
            .refine_nominal(!self.keep_nominal);
        if let Some(l) = parse_locations(self.locations.as_deref(), nominal)? {
            b = b.locations(l);
        }
        if self.scoring != "auto" {
            b = b.scoring(parse_scoring(&self.scoring).map_err(|rule| {
                WorkflowError::InvalidOption {
                    option: "scoring",
                    value: format!("`{}`", self.scoring),
                    rule,
                }
            })?);
        }
        Ok(b.build()?)
    }
}

/// Refuses a `settle` that is not less than the length of every record: `records` gives each
/// record's length and how it is named in messages.
///
/// # Errors
/// [`WorkflowError::InvalidOption`] naming the first record that is too short.
pub fn check_settle(settle: usize, records: &[(usize, String)]) -> Result<()> {
    match records.iter().find(|(len, _)| settle >= *len) {
        Some((len, label)) => Err(WorkflowError::InvalidOption {
            option: "settle",
            value: settle.to_string(),
            rule: format!("it must be less than the {len} samples of {label}"),
        }),
        None => Ok(()),
    }
}

/// A discovery to run.
#[derive(Clone, Copy)]
pub struct DiscoverRequest<'a> {
    /// The nominal model's file (the augmented files of the steps build on it).
    pub model: &'a ModelFile,
    /// The nominal model ([`nominal_model`]).
    pub nominal: &'a Nominal,
    /// The estimation records.
    pub estimation: &'a Data,
    /// The validation records.
    pub validation: &'a Data,
    /// The discovery settings ([`DiscoverOptions::settings`]).
    pub settings: &'a DiscoverSettings,
    /// How many effects to look for, one at a time (≥ 1).
    pub effects: usize,
}

/// What a discovery found.
pub struct DiscoverOutcome {
    /// The discovery reported: the only one, or the last adopted step's.
    pub discovery: Discovery,
    /// With several effects: every step, and the index of the one reported.
    pub effects: Option<(Effects, usize)>,
    /// The model file of the reported step: the given one, or the augmented file of the step
    /// before it.
    pub model: ModelFile,
    /// The nominal model of the reported step.
    pub nominal: Nominal,
}

/// Runs the discover workflow: one discovery, or with `effects` > 1 the iteration in which
/// each step adopts the augmented model of the one before as its nominal model.
///
/// # Errors
/// [`WorkflowError::InvalidOption`] for `effects` = 0, and the errors of discovery.
pub fn discover_model_file(req: &DiscoverRequest<'_>) -> Result<DiscoverOutcome> {
    if req.effects == 0 {
        return Err(WorkflowError::InvalidOption {
            option: "effects",
            value: "0".into(),
            rule: "at least one effect must be looked for".into(),
        });
    }
    if req.effects == 1 {
        return Ok(DiscoverOutcome {
            discovery: discover(req.nominal, req.estimation, req.validation, req.settings)?,
            effects: None,
            model: req.model.clone(),
            nominal: req.nominal.clone(),
        });
    }
    let effects = discover_effects(
        req.nominal,
        req.estimation,
        req.validation,
        req.settings,
        &EffectsSettings::default().with_max_effects(req.effects)?,
    )?;
    let at = effects.steps.iter().rposition(|s| s.adopted).unwrap_or(0);
    let mut model = req.model.clone();
    // Each adopted step's map as the next step built on it (re-estimated with a second
    // block, when one was).
    for step in effects.steps[..at].iter().filter(|s| s.adopted) {
        if let Some(f) = step.adopted_finding() {
            model = f.augmented_file(&model, req.settings.trend_degree())?.model;
        }
    }
    Ok(DiscoverOutcome {
        discovery: effects.steps[at].discovery.clone(),
        nominal: effects.steps[at].nominal.clone(),
        model,
        effects: Some((effects, at)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_linear::PolynomialModel;

    fn nominal() -> Nominal {
        Nominal::from_polynomial(&PolynomialModel {
            den: vec![1.0, -1.5, 0.7],
            num: vec![vec![0.0, 0.1, 0.1]],
            sample_time: Some(0.05),
        })
        .unwrap()
    }

    #[test]
    fn locations_parse_by_key_and_reject_unknown_names() {
        let nominal = nominal();
        let given = vec![
            "input".to_string(),
            " output-feedback".into(),
            "input".into(),
        ];
        assert_eq!(
            parse_locations(Some(&given), &nominal).unwrap(),
            Some(vec![Site::Input, Site::OutputFeedback])
        );
        let e = parse_locations(Some(&["friction".to_string()]), &nominal)
            .unwrap_err()
            .to_string();
        assert!(e.contains("friction") && e.contains("rate-feedback"), "{e}");
        assert_eq!(parse_locations(None, &nominal).unwrap(), None);
        assert!(parse_locations(Some(&[]), &nominal).is_err());
    }

    #[test]
    fn options_out_of_range_are_named() {
        let nominal = nominal();
        for (o, name) in [
            (
                DiscoverOptions {
                    sigma_fraction: 0.0,
                    ..Default::default()
                },
                "sigma_fraction",
            ),
            (
                DiscoverOptions {
                    trend: 65,
                    ..Default::default()
                },
                "trend",
            ),
            (
                DiscoverOptions {
                    hysteresis_threshold: 1.5,
                    ..Default::default()
                },
                "hysteresis_threshold",
            ),
            (
                DiscoverOptions {
                    scoring: "sometimes".into(),
                    ..Default::default()
                },
                "scoring",
            ),
        ] {
            let e = o.settings(&nominal).unwrap_err();
            assert!(
                matches!(&e, WorkflowError::InvalidOption { option, .. } if *option == name),
                "{e}"
            );
        }
        assert!(DiscoverOptions::default().settings(&nominal).is_ok());
        assert!(
            check_settle(10, &[(20, "a".into()), (10, "b".into())])
                .unwrap_err()
                .to_string()
                .contains("10 samples of b")
        );
    }
}
