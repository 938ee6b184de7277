//! Discovery: what a nominal linear model is missing, where, and which static effect (as
//! `structid discover`), and the workflow on the Silverbox benchmark.

use std::path::PathBuf;

use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use structid_core::Data;
use structid_core::estimate::SignalNames;
use structid_discover::discover::{DiscoverSettings, Discovery};
use structid_discover::hypotheses::Nominal;
use structid_io::ModelFile;
use structid_workflow::discover::check_settle;
use structid_workflow::{DiscoverOptions, DiscoverRequest, discover_model_file, nominal_model};

use crate::convert::{self, error};
use crate::estimate::Fitted;
use crate::identify::{Columns, named_columns};
use crate::model::Model;

/// A discovery as Python objects: the verdict, every hypothesis, and the finding with its
/// augmented model and estimate.
fn discovery_dict<'py>(
    py: Python<'py>,
    d: &Discovery,
    nominal: &Nominal,
    file: Option<&ModelFile>,
    settings: &DiscoverSettings,
    estimation: &Data,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("verdict", &d.verdict)?;
    out.set_item("verdict_kind", d.verdict_kind.key())?;
    out.set_item("missing_effect", d.missing_effect)?;
    let rival = match &d.linear_rival {
        None => None,
        Some(r) => {
            let x = PyDict::new(py);
            x.set_item("num", r.g.num.clone())?;
            x.set_item("den", r.g.den.clone())?;
            x.set_item("validation_rms", r.validation_rms)?;
            x.set_item("p_worse", r.comparison.as_ref().map(|c| c.p_worse))?;
            x.set_item("explains", r.explains)?;
            Some(x)
        }
    };
    out.set_item("linear_rival", rival)?;
    out.set_item("nominal_validation_rms", d.validation_gap.rms)?;
    out.set_item("nominal_estimation_rms", d.estimation_gap.rms)?;
    let per_record =
        |g: &structid_discover::gap::Gap| -> Vec<f64> { g.records.iter().map(|r| r.rms).collect() };
    out.set_item(
        "nominal_estimation_rms_records",
        per_record(&d.estimation_gap),
    )?;
    out.set_item(
        "nominal_validation_rms_records",
        per_record(&d.validation_gap),
    )?;
    out.set_item(
        "validation_rms_records",
        d.finding
            .as_ref()
            .map(|f| per_record(&f.augmented.validation_gap)),
    )?;
    out.set_item("seconds", d.seconds)?;
    let hypotheses = d
        .hypotheses
        .iter()
        .map(|h| {
            let x = PyDict::new(py);
            x.set_item("location", nominal.key(h.location))?;
            x.set_item("description", nominal.describe(h.location))?;
            x.set_item("dispersion", &h.dispersion)?;
            x.set_item("beta", h.beta)?;
            x.set_item("sigma", h.sigma)?;
            x.set_item("estimation_rms", h.estimation_rms)?;
            x.set_item("validation_rms", h.validation_rms)?;
            x.set_item("failure", &h.failure)?;
            x.set_item("z", convert::vector(py, h.curve.z.clone()))?;
            x.set_item("w", convert::vector(py, h.curve.w.clone()))?;
            Ok(x)
        })
        .collect::<PyResult<Vec<_>>>()?;
    out.set_item("hypotheses", hypotheses)?;
    let finding = match &d.finding {
        None => None,
        Some(f) => {
            let x = PyDict::new(py);
            x.set_item("location", nominal.key(f.location))?;
            x.set_item("description", nominal.describe(f.location))?;
            x.set_item("effect", f.effect())?;
            x.set_item("estimator", &f.estimator)?;
            x.set_item("nonparametric_rms", f.nonparametric_rms)?;
            x.set_item("validation_rms", f.augmented.validation_gap.rms)?;
            x.set_item("remarks", f.remarks.clone())?;
            x.set_item("shrink", f.shrink)?;
            x.set_item(
                "time_varying",
                matches!(
                    f.classification,
                    structid_discover::discover::Classification::TimeVarying(_)
                ),
            )?;
            x.set_item(
                "stationarity",
                f.stationarity.as_ref().map(|s| s.describe()),
            )?;
            x.set_item("poor_model", f.poor_model)?;
            let table = f
                .table
                .iter()
                .enumerate()
                .map(|(i, row)| {
                    let r = PyDict::new(py);
                    r.set_item("label", &row.label)?;
                    r.set_item("parameters", row.parameters)?;
                    r.set_item("validation_rms", row.validation_rms)?;
                    r.set_item("eligible", row.eligible)?;
                    r.set_item(
                        "p_worse_than_best",
                        f.selection.p_worse_than_best.get(i).copied().flatten(),
                    )?;
                    r.set_item("as_good", f.selection.as_good.get(i).copied())?;
                    r.set_item("chosen", f.selection.chosen == Some(i))?;
                    Ok(r)
                })
                .collect::<PyResult<Vec<_>>>()?;
            x.set_item("table", table)?;
            let hysteresis = match &f.input_hysteresis {
                None => None,
                Some(h) => {
                    let d = PyDict::new(py);
                    d.set_item("description", h.describe())?;
                    d.set_item("threshold", h.threshold)?;
                    d.set_item("weight", h.weight)?;
                    d.set_item("play", h.is_play())?;
                    d.set_item("validation_rms", h.validation_rms)?;
                    d.set_item("without_hysteresis_rms", h.without_hysteresis_rms)?;
                    Some(d)
                }
            };
            x.set_item("input_hysteresis", hysteresis)?;
            x.set_item("z", convert::vector(py, f.hypothesis.curve.z.clone()))?;
            x.set_item("w", convert::vector(py, f.hypothesis.curve.w.clone()))?;
            let estimate = f.estimate(nominal, estimation).map_err(error)?;
            let estimate = match file {
                Some(mf) => estimate
                    .with_signal_names(SignalNames {
                        u: mf.signals.u.clone(),
                        y: mf.signals.y.clone(),
                    })
                    .map_err(error)?,
                None => estimate,
            };
            x.set_item("estimate", Fitted::new(estimate, None))?;
            // The augmented model as a Model when it stands alone (a named map is an
            // expression; an unnamed one is a table file, written by the tool only).
            let augmented = match file {
                Some(mf) => {
                    let a = f
                        .augmented_file(mf, settings.trend_degree())
                        .map_err(error)?;
                    if a.table.is_none() && a.known_tables.is_empty() {
                        Some(Model { file: a.model })
                    } else {
                        None
                    }
                }
                None => None,
            };
            x.set_item("augmented", augmented)?;
            Some(x)
        }
    };
    out.set_item("finding", finding)?;
    Ok(out)
}

fn records<'py>(
    mf: &ModelFile,
    first: &[(String, PyReadonlyArray1<'py, f64>)],
    more: Option<&[Columns<'py>]>,
    settle: usize,
    what: &str,
) -> PyResult<Data> {
    let mut all = vec![convert::record(mf, named_columns(first))?];
    for r in more.into_iter().flatten() {
        all.push(convert::record(mf, named_columns(r))?);
    }
    let several = all.len() > 1;
    let lengths: Vec<(usize, String)> = all
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let which = if several {
                format!("{what} record {}", i + 1)
            } else {
                format!("the {what} record")
            };
            (r.len(), which)
        })
        .collect();
    check_settle(settle, &lengths).map_err(error)?;
    Data::from_records(all).map_err(error)
}

/// Runs the discovery workflow from a nominal model on an estimation and a validation record,
/// or on several of each (`more_records`, `more_validation`: the records after the first);
/// with `effects` > 1, up to that many effects one at a time.
#[pyfunction]
#[pyo3(signature = (model, columns, validation, total_variation=true, settle=0, tune_sigma=false, more_records=None, more_validation=None, significance=0.05, effects=1, locations=None, scoring="auto", keep_nominal=false, sigma_fraction=None, trend=None, hysteresis_threshold=None))]
#[allow(clippy::too_many_arguments)]
pub fn discover_columns<'py>(
    py: Python<'py>,
    model: &Model,
    columns: Vec<(String, PyReadonlyArray1<'py, f64>)>,
    validation: Vec<(String, PyReadonlyArray1<'py, f64>)>,
    total_variation: bool,
    settle: usize,
    tune_sigma: bool,
    more_records: Option<Vec<Columns<'py>>>,
    more_validation: Option<Vec<Columns<'py>>>,
    significance: f64,
    effects: usize,
    locations: Option<Vec<String>>,
    scoring: &str,
    keep_nominal: bool,
    sigma_fraction: Option<f64>,
    trend: Option<usize>,
    hysteresis_threshold: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let mf = model.file.clone();
    let nominal = nominal_model(&mf, "the model").map_err(error)?;
    let defaults = DiscoverOptions::default();
    let settings = DiscoverOptions {
        total_variation,
        settle,
        scoring: scoring.into(),
        keep_nominal,
        sigma_fraction: sigma_fraction.unwrap_or(defaults.sigma_fraction),
        trend: trend.unwrap_or(defaults.trend),
        tune_sigma,
        significance,
        hysteresis_threshold: hysteresis_threshold.unwrap_or(defaults.hysteresis_threshold),
        locations,
    }
    .settings(&nominal)
    .map_err(error)?;
    let est = records(&mf, &columns, more_records.as_deref(), settle, "estimation")?;
    let val = records(
        &mf,
        &validation,
        more_validation.as_deref(),
        settle,
        "validation",
    )?;
    let (s, e) = (settings.clone(), est.clone());
    let out = py
        .detach(move || {
            discover_model_file(&DiscoverRequest {
                model: &mf,
                nominal: &nominal,
                estimation: &e,
                validation: &val,
                settings: &s,
                effects,
            })
        })
        .map_err(error)?;
    let d = discovery_dict(
        py,
        &out.discovery,
        &out.nominal,
        Some(&out.model),
        &settings,
        &est,
    )?;
    let steps = match &out.effects {
        None => None,
        Some((all, _)) => Some(
            all.steps
                .iter()
                .map(|step| {
                    let x = PyDict::new(py);
                    x.set_item("adopted", step.adopted)?;
                    let row = match &step.second_block {
                        Some(row) => {
                            let r = PyDict::new(py);
                            r.set_item("site", step.nominal.key(row.site))?;
                            r.set_item("estimation_rms", row.estimation_rms)?;
                            r.set_item("validation_rms", row.validation_rms)?;
                            Some(r)
                        }
                        None => None,
                    };
                    x.set_item("second_block", row)?;
                    x.set_item(
                        "dynamic_verdict",
                        step.dynamic.as_ref().map(|d| d.verdict.clone()),
                    )?;
                    x.set_item("verdict", &step.discovery.verdict)?;
                    x.set_item(
                        "effect",
                        step.discovery
                            .finding
                            .as_ref()
                            .map(|f| f.classification.describe()),
                    )?;
                    Ok(x)
                })
                .collect::<PyResult<Vec<_>>>()?,
        ),
    };
    d.set_item("steps", steps)?;
    d.set_item(
        "stop",
        out.effects
            .as_ref()
            .map(|(all, _)| all.stop.describe(&all.settings)),
    )?;
    Ok(d)
}

/// The discovery workflow on the Silverbox benchmark file `SNLS80mV.csv`: the BLA of
/// `order` on the first part of the estimation split, discovery with the rest as validation,
/// and the test splits simulated with the BLA and the augmented model
/// ([`structid_workflow::discover_from_linear_start`]).
#[pyfunction]
#[pyo3(signature = (path, order=2, validation_fraction=0.2))]
pub fn silverbox_discovery<'py>(
    py: Python<'py>,
    path: PathBuf,
    order: usize,
    validation_fraction: f64,
) -> PyResult<Bound<'py, PyDict>> {
    use structid_io::{Silverbox, SilverboxSplit};
    use structid_workflow::{LinearStartRequest, discover_from_linear_start};
    let request = LinearStartRequest {
        order,
        validation_fraction,
        ..LinearStartRequest::default()
    };
    request.check().map_err(error)?;
    let r = py.detach(move || {
        let sb = Silverbox::load(&path).map_err(error)?;
        let est = sb.split(SilverboxSplit::Estimation).data().map_err(error)?;
        let tests = SilverboxSplit::TESTS.map(|s| sb.split(s));
        let request = LinearStartRequest {
            sample_time: sb.sample_time,
            ..request
        };
        discover_from_linear_start(&est, &tests, &request).map_err(error)
    })?;
    let settings = LinearStartRequest::default().discover;
    let out = discovery_dict(py, &r.discovery, &r.nominal, None, &settings, &r.fit)?;
    out.set_item("bla_num", r.bla.num.clone())?;
    out.set_item("bla_den", r.bla.den.clone())?;
    let tests = r
        .tests
        .iter()
        .map(|t| {
            let x = PyDict::new(py);
            x.set_item("split", &t.record)?;
            x.set_item("bla_rms", t.bla_rms)?;
            x.set_item("augmented_rms", t.augmented_rms)?;
            x.set_item("measured", convert::vector(py, t.measured.clone()))?;
            x.set_item("simulated", convert::vector(py, t.simulated.clone()))?;
            x.set_item(
                "bla_simulated",
                convert::vector(py, t.bla_simulated.clone()),
            )?;
            Ok(x)
        })
        .collect::<PyResult<Vec<_>>>()?;
    out.set_item("tests", tests)?;
    Ok(out)
}
