//! The files and lines of a validation, shared by `validate` with a model file and with a
//! stored estimate: simulation.csv's columns, the simulation and residual figures, the per-output
//! part of validation.json, the summary's wording, and what a record scored for pooling over records.

use structid_core::validation::ValidationReport;
use structid_core::validation::residual_tests::CorrelationTest;
use structid_plot::{
    Chart, CorrelationChart, Series, decimate_min_max, render_correlation_svg, render_grid_svg,
};

use serde_json::Value;
use structid_core::{Data, Signal};

use crate::{Result, WorkflowError};
pub use structid_io::validation_report::outputs_json;

/// Buckets of the thinned lines of simulation.svg: about one per pixel column of its panels
/// (at most two points each).
const PLOT_BUCKETS: usize = 1000;

/// Column names of simulation.csv: `time`, then per output `<y>`, `<y>_sim`,
/// `<y>_prediction_error` (generic `y<c>` names if the model's names would collide).
pub fn simulation_names(y_names: &[String]) -> Vec<String> {
    let build = |names: &[String]| {
        let mut out = vec!["time".to_string()];
        for n in names {
            out.extend([
                n.clone(),
                format!("{n}_sim"),
                format!("{n}_prediction_error"),
            ]);
        }
        out
    };
    let names = build(y_names);
    let mut seen = std::collections::HashSet::new();
    if names.iter().all(|n| seen.insert(n.clone())) {
        names
    } else {
        let generic: Vec<String> = (0..y_names.len()).map(|c| format!("y{c}")).collect();
        build(&generic)
    }
}

/// The simulation figure: per output, the measured and simulated signals and, in a panel
/// below, the simulation error y − ŷ. Records longer than the figure is wide are thinned to
/// the minimum and maximum of each pixel column ([`decimate_min_max`]), so that peaks of the
/// error survive and the file stays small.
pub fn simulation_svg(
    report: &ValidationReport,
    measured: &structid_lti::Signal,
    time: &[f64],
    y_names: &[String],
    time_label: &str,
) -> Result<String> {
    type Xy = (Vec<f64>, Vec<f64>);
    let series: Vec<(Xy, Xy, Xy)> = (0..y_names.len())
        .map(|c| {
            let y = measured.channel(c);
            let ys = report.simulated.channel(c);
            let err: Vec<f64> = y.iter().zip(&ys).map(|(a, b)| a - b).collect();
            (
                decimate_min_max(time, &y, PLOT_BUCKETS),
                decimate_min_max(time, &ys, PLOT_BUCKETS),
                decimate_min_max(time, &err, PLOT_BUCKETS),
            )
        })
        .collect();
    let mut charts: Vec<Chart> = Vec::with_capacity(2 * y_names.len());
    for ((name, (y, ys, err)), fit) in y_names.iter().zip(&series).zip(&report.fit_percent) {
        charts.push(
            Chart::new(
                format!("{name}: measured and simulated (fit {fit:.1} %)"),
                time_label,
                name.as_str(),
            )
            .with(Series::line("measured", &y.0, &y.1))
            .with(Series::line("simulated", &ys.0, &ys.1)),
        );
        charts.push(
            Chart::new(
                format!("{name}: simulation error"),
                time_label,
                format!("{name} − simulated"),
            )
            .with(Series::line("error", &err.0, &err.1)),
        );
    }
    Ok(render_grid_svg(&charts, 1, (1000, 400))?)
}

/// The residual figure: per output, the autocorrelation of the one-step prediction error ε
/// and its cross-correlation with each input, with their 99 % bands.
pub fn residuals_svg(
    report: &ValidationReport,
    y_names: &[String],
    u_names: &[String],
) -> Result<String> {
    let as_f64 = |t: &CorrelationTest| t.lags.iter().map(|&l| l as f64).collect::<Vec<f64>>();
    let lags: Vec<(Vec<f64>, Vec<Vec<f64>>)> = report
        .whiteness
        .iter()
        .zip(&report.input_correlation)
        .map(|(w, cross)| (as_f64(w), cross.iter().map(as_f64).collect()))
        .collect();
    let mut charts = Vec::new();
    for (c, name) in y_names.iter().enumerate() {
        let w = &report.whiteness[c];
        charts.push(
            CorrelationChart::new(
                format!("autocorrelation of ε ({name})"),
                "lag τ",
                "R_ε(τ)",
                &lags[c].0,
                &w.values,
                w.bound,
            )
            .exempt_zero(),
        );
        for (j, u) in u_names.iter().enumerate() {
            let t = &report.input_correlation[c][j];
            charts.push(CorrelationChart::new(
                format!("ε ({name}) against {u}"),
                "lag τ",
                "R_εu(τ)",
                &lags[c].1[j],
                &t.values,
                t.bound,
            ));
        }
    }
    Ok(render_correlation_svg(
        &charts,
        1 + u_names.len(),
        (600, 380),
    )?)
}

/// A fit in percent as the summaries print it (`undefined` for a constant output).
pub fn fmt_pct(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2} %")
    } else {
        "undefined (constant output)".into()
    }
}

/// A correlation test as the summaries print it: pass or FAIL, its statistic, critical value
/// and the lags outside the band.
pub fn pass(t: &CorrelationTest) -> String {
    format!(
        "{} ({} = {:.1}, 1 % critical value {:.1}; {} of {} lags outside the 99 % band)",
        if t.passes() { "pass" } else { "FAIL" },
        if t.autocorrelation {
            "Ljung–Box Q"
        } else {
            "Ljung ζ"
        },
        t.statistic,
        t.critical,
        t.outside().len(),
        t.tested()
    )
}

/// The files a validation writes, in order.
pub const OUTPUTS: [&str; 4] = [
    "validation.json",
    "simulation.csv",
    "simulation.svg",
    "residuals.svg",
];

/// Checks `--settle` and `--max-lag` against the length of the validation record.
pub fn check_lengths(
    settle: usize,
    max_lag: usize,
    path: &std::path::Path,
    vdata: &Data,
) -> Result<()> {
    if settle >= vdata.len() {
        return Err(WorkflowError::InvalidOption {
            option: "settle",
            value: settle.to_string(),
            rule: format!(
                "it must be less than the number of samples of `{}` ({})",
                path.display(),
                vdata.len()
            ),
        });
    }
    if max_lag >= vdata.len() {
        return Err(WorkflowError::InvalidOption {
            option: "max_lag",
            value: max_lag.to_string(),
            rule: format!(
                "it must be less than the number of samples of `{}` ({})",
                path.display(),
                vdata.len()
            ),
        });
    }
    Ok(())
}

/// The samples a report scored, as `[start, end)` pairs (one for a free run after the
/// settling samples, one per window otherwise).
pub fn scored_json(report: &ValidationReport) -> serde_json::Value {
    serde_json::json!(
        report
            .scored
            .iter()
            .map(|r| [r.start, r.end])
            .collect::<Vec<_>>()
    )
}

/// What one record's validation scored, for pooling over records, with its validation.json.
pub struct RecordScore {
    /// The measured outputs.
    pub y: Signal,
    /// The simulated outputs.
    pub simulated: Signal,
    /// The samples the simulation error is over.
    pub scored: Vec<std::ops::Range<usize>>,
    /// The record's validation.json document.
    pub doc: Value,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simulation_column_names_fall_back_when_they_collide() {
        let n = simulation_names(&["y".into(), "p".into()]);
        assert_eq!(
            n,
            [
                "time",
                "y",
                "y_sim",
                "y_prediction_error",
                "p",
                "p_sim",
                "p_prediction_error"
            ]
        );
        let n = simulation_names(&["time".into()]);
        assert_eq!(n, ["time", "y0", "y0_sim", "y0_prediction_error"]);
        let n = simulation_names(&["a".into(), "a_sim".into()]);
        assert_eq!(n[1], "y0");
    }
}
