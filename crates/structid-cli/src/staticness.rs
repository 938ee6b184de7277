//! `structid static`: how well a static map explains a (z, w) scatter (the paper's Example 1).

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Args;
use structid_discover::staticness::{Staticness, StaticnessError, StaticnessSettings, staticness};
use structid_io::OutputGuard;
use structid_plot::{Chart, Series, render_chart_svg};

use crate::error::CliError;
use structid_workflow::grid::{MAX_DOTS, subsample};

/// Arguments of `structid static`.
#[derive(Debug, Args)]
pub struct StaticArgs {
    /// The record (CSV with a header row, MAT-file or NumPy file; see --vars), in time order.
    #[arg(long, short = 'd', value_name = "DATA.csv")]
    data: PathBuf,
    /// The column of the map's input z.
    #[arg(long, value_name = "COL")]
    z: String,
    /// The column of the map's output w.
    #[arg(long, value_name = "COL")]
    w: String,
    /// The noise standard deviation of w, if known (default: estimated from the first
    /// differences of the static fit's residual).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    noise_std: Option<f64>,
    /// The kernel width σ of the static fit, in the units of z (default: 0.1 × the range of z).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    sigma: Option<f64>,
    /// The largest unexplained variance of a static relation, in noise variances.
    #[arg(long, value_name = "R", default_value_t = 2.0)]
    ratio_limit: f64,
    /// The share of the residual energy the direction of motion must explain to call the
    /// relation direction dependent (hysteresis or backlash).
    #[arg(long, value_name = "T", default_value_t = 0.1)]
    direction_threshold: f64,
    /// Where to write report.json and static.svg (nothing is written without it).
    #[arg(long, short = 'o', value_name = "DIR")]
    out: Option<PathBuf>,
}

/// The report written as report.json.
#[derive(serde::Serialize)]
struct StaticReport<'a> {
    data_file: String,
    z: &'a str,
    w: &'a str,
    settings: &'a StaticnessSettings,
    result: &'a Staticness,
    verdict_text: &'static str,
    files: Vec<String>,
}

fn settings(a: &StaticArgs) -> Result<StaticnessSettings, CliError> {
    let mut b = StaticnessSettings::builder()
        .ratio_limit(a.ratio_limit)
        .direction_threshold(a.direction_threshold);
    if let Some(s) = a.noise_std {
        b = b.noise_std(s);
    }
    if let Some(s) = a.sigma {
        b = b.sigma(s);
    }
    b.build().map_err(|e| CliError::input(e.to_string()))
}

/// Runs `structid static`.
pub fn run(a: StaticArgs) -> Result<(), CliError> {
    let settings = settings(&a)?;
    let mut guard = OutputGuard::new();
    guard.protect(&a.data);
    let planned = ["report.json", "static.svg"];
    if let Some(out) = &a.out {
        guard.check_out_dir(out, planned)?;
    }
    let table = crate::data::read_table(&a.data)?;
    let column =
        |name: &str| -> Result<Vec<f64>, CliError> { Ok(table.select(&[name])?.channel(0)) };
    let (z, w) = (column(&a.z)?, column(&a.w)?);
    let s = staticness(&z, &w, &settings).map_err(|e| match e {
        StaticnessError::Fit(e) => {
            CliError::from(e).context("cannot fit a static map to the scatter")
        }
        other => CliError::input(format!("`{}`: {other}", a.data.display())),
    })?;
    let mut written = Vec::new();
    if let Some(out) = &a.out {
        guard.begin_set(out, Some(&planned))?;
        let svg_path = out.join("static.svg");
        guard.write(&svg_path, figure(&s, &z, &w, &a.z, &a.w)?.as_bytes())?;
        let report_path = out.join("report.json");
        let report = StaticReport {
            data_file: a.data.display().to_string(),
            z: &a.z,
            w: &a.w,
            settings: &settings,
            result: &s,
            verdict_text: s.verdict.describe(),
            files: planned.iter().map(|f| f.to_string()).collect(),
        };
        let json = serde_json::to_string_pretty(&report)
            .map_err(|e| CliError::runtime(format!("internal error: the report: {e}")))?;
        guard.write(&report_path, json.as_bytes())?;
        written = vec![svg_path, report_path];
        guard.finish_set(out, &structid_io::output::file_names(&written))?;
    }
    print!("{}", summary(&s, &a, &written));
    Ok(())
}

/// The scatter (z_k, w_k) behind the best static map.
fn figure(s: &Staticness, z: &[f64], w: &[f64], zn: &str, wn: &str) -> Result<String, CliError> {
    let idx = subsample(z.len(), MAX_DOTS);
    let dz: Vec<f64> = idx.iter().map(|&k| z[k]).collect();
    let dw: Vec<f64> = idx.iter().map(|&k| w[k]).collect();
    let chart = Chart::new(
        format!(
            "{wn} against {zn}: unexplained variance {:.2} × the noise",
            s.unexplained_ratio
        ),
        zn,
        wn,
    )
    .with(Series::dots("data (z, w)", &dz, &dw))
    .with(Series::line("best static map", &s.grid_z, &s.grid_w));
    Ok(render_chart_svg(&chart)?)
}

fn summary(s: &Staticness, a: &StaticArgs, written: &[PathBuf]) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "best static map {} = N({}) from {} samples: Gaussian kernel σ = {:.4e}, β = {:.4e} (marginal likelihood{})",
        a.w,
        a.z,
        s.samples,
        s.sigma,
        s.beta,
        if s.beta_at_bound { ", at a bound" } else { "" }
    );
    let _ = writeln!(
        t,
        "unexplained variance {:.4e} = {:.2} × the noise variance {:.4e} ({}); the map explains {:.1} % of the variance of {}",
        s.unexplained_variance,
        s.unexplained_ratio,
        s.noise_variance,
        if s.noise_given { "given" } else { "estimated" },
        100.0 * s.explained_share,
        a.w
    );
    let d = &s.direction;
    let _ = writeln!(
        t,
        "direction test: rising and falling {} explain {:.1} % of the residual energy (t = {:.1}, {} samples){}",
        a.z,
        100.0 * d.explained,
        d.t_statistic,
        d.samples,
        if d.dynamic {
            ": direction dependent"
        } else {
            ""
        }
    );
    for w in &s.warnings {
        let _ = writeln!(t, "warning: {w}");
    }
    let _ = writeln!(t, "verdict: {}", s.verdict.describe());
    if !written.is_empty() {
        let _ = writeln!(t, "wrote:");
        for p in written {
            let _ = writeln!(t, "  {}", p.display());
        }
    }
    t
}
