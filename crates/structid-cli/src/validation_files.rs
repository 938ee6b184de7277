//! The files and lines of a validation, shared by `validate` with a model file and with a
//! stored estimate: simulation.csv's columns, the simulation and residual figures, the per-output
//! part of validation.json and the summary's wording.

use structid_core::residual_tests::CorrelationTest;
use structid_core::validation::ValidationReport;
use structid_plot::{Chart, CorrelationChart, Series, render_correlation_svg, render_grid_svg};

use structid_core::Data;

use crate::ValidateArgs;
use crate::error::CliError;
pub(crate) use structid_io::validation_report::outputs_json;

/// Most points per line in simulation.svg (longer records are drawn decimated).
const MAX_PLOT_POINTS: usize = 5000;

/// Column names of simulation.csv: `time`, then per output `<y>`, `<y>_sim`,
/// `<y>_prediction_error` (generic `y<c>` names if the model's names would collide).
pub(crate) fn simulation_names(y_names: &[String]) -> Vec<String> {
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

/// Every `step`-th index so that at most [`MAX_PLOT_POINTS`] remain, plus the last one.
pub(crate) fn plot_indices(len: usize) -> Vec<usize> {
    let step = len.div_ceil(MAX_PLOT_POINTS).max(1);
    let mut idx: Vec<usize> = (0..len).step_by(step).collect();
    if len > 0 && idx.last() != Some(&(len - 1)) {
        idx.push(len - 1);
    }
    idx
}

pub(crate) fn simulation_svg(
    report: &ValidationReport,
    measured: &structid_lti::Signal,
    time: &[f64],
    y_names: &[String],
    time_label: &str,
) -> Result<String, CliError> {
    let idx = plot_indices(time.len());
    let t: Vec<f64> = idx.iter().map(|&k| time[k]).collect();
    let series: Vec<(Vec<f64>, Vec<f64>)> = (0..y_names.len())
        .map(|c| {
            (
                idx.iter().map(|&k| measured.get(k, c)).collect(),
                idx.iter().map(|&k| report.simulated.get(k, c)).collect(),
            )
        })
        .collect();
    let charts: Vec<Chart> = y_names
        .iter()
        .zip(&series)
        .zip(&report.fit_percent)
        .map(|((name, (y, ys)), fit)| {
            Chart::new(
                format!("{name}: measured and simulated (fit {fit:.1} %)"),
                time_label,
                name.as_str(),
            )
            .with(Series::line("measured", &t, y))
            .with(Series::line("simulated", &t, ys))
        })
        .collect();
    Ok(render_grid_svg(&charts, 1, (1000, 400))?)
}

pub(crate) fn residuals_svg(
    report: &ValidationReport,
    y_names: &[String],
    u_names: &[String],
) -> Result<String, CliError> {
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

pub(crate) fn fmt_pct(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2} %")
    } else {
        "undefined (constant output)".into()
    }
}

pub(crate) fn pass(t: &CorrelationTest) -> String {
    let n = t.outside().len();
    let tested = if t.autocorrelation {
        t.lags.iter().filter(|&&l| l != 0).count()
    } else {
        t.lags.len()
    };
    format!(
        "{} ({n} of {tested} lags outside the 99 % band)",
        if n == 0 { "pass" } else { "FAIL" }
    )
}

/// The files a validation writes, in order.
pub(crate) const OUTPUTS: [&str; 4] = [
    "validation.json",
    "simulation.csv",
    "simulation.svg",
    "residuals.svg",
];

/// Checks `--settle` and `--max-lag` against the length of the validation record.
pub(crate) fn check_lengths(a: &ValidateArgs, vdata: &Data) -> Result<(), CliError> {
    if a.settle >= vdata.len() {
        return Err(CliError::input(format!(
            "invalid value {} for --settle: it must be less than the number of samples of `{}` ({})",
            a.settle,
            a.data.display(),
            vdata.len()
        )));
    }
    if a.max_lag >= vdata.len() {
        return Err(CliError::input(format!(
            "invalid value {} for --max-lag: it must be less than the number of samples of `{}` ({})",
            a.max_lag,
            a.data.display(),
            vdata.len()
        )));
    }
    Ok(())
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

    #[test]
    fn plot_indices_keep_the_ends_and_at_most_the_limit() {
        assert_eq!(plot_indices(3), [0, 1, 2]);
        let idx = plot_indices(12_345);
        assert!(idx.len() <= MAX_PLOT_POINTS + 1);
        assert_eq!((idx[0], *idx.last().unwrap()), (0, 12_344));
        assert!(plot_indices(0).is_empty());
    }
}
