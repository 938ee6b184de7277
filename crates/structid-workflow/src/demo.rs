//! The paper's examples end to end (`structid demo`): data generated, written with a model
//! file, identified, and drawn against the true maps.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde_json::json;
use structid_core::validation::metrics::{centred_rms_difference, rms_difference};
use structid_core::{IdentifySettings, Interpolant, identify, paper};
use structid_io::{BlockSpec, DispersionSpec, ModelFile, OutputGuard, SignalNames, TruthSpec};
use structid_plot::{Chart, HeatMap, Series, render_grid_svg, render_heatmaps_svg};

use crate::figures::grid_values;
use crate::grid::{GRID_1D, GRID_2D, linspace, mean, span, subsample};
use crate::{Result, WorkflowError};

/// f of the spray example as a model-file expression.
pub const SPRAY_F: &str = "-abs(z0)";
/// g of the spray example as a model-file expression.
pub const SPRAY_G: &str = "0.5*(sin((3*z0)^2) + (2*z0)^2 - 2)";
/// The two-input map of the multi-input example as a model-file expression.
pub const MULTI_INPUT_MAP: &str = "sin(z0)*exp(-0.3*z1^2) + 0.2*z1";

/// Kernel width of the spray demo.
const SPRAY_SIGMA: f64 = 0.1;
/// Noise standard deviation of the spray demo.
const SPRAY_NOISE: f64 = 1.0;
/// The β values of the spray demo (the paper's Fig. 4).
const SPRAY_BETAS: [f64; 3] = [0.001, 0.01, 0.1];
/// Kernel width of the multi-input demo.
const MULTI_SIGMA: f64 = 0.5;
/// β of the multi-input demo.
const MULTI_BETA: f64 = 0.01;
/// Most dots per series in the demo figures.
const DEMO_DOTS: usize = 500;

/// The files of `demo spray`.
const SPRAY_OUTPUTS: [&str; 4] = ["data.csv", "model.toml", "fig4.svg", "summary.json"];
/// The files of `demo multi-input`.
const MULTI_OUTPUTS: [&str; 4] = ["data.csv", "model.toml", "surfaces.svg", "summary.json"];

/// Checks `--samples` before anything is generated: at least 10, and few enough for the
/// demos' exact solver (one output, white noise), whose L×L matrix must fit in the memory
/// budget `limit` (bytes).
fn check_samples(samples: usize, limit: u64) -> Result<()> {
    if samples < 10 {
        return Err(WorkflowError::InvalidOption {
            option: "samples",
            value: samples.to_string(),
            rule: "the demo needs at least 10 samples".into(),
        });
    }
    let need = |l: usize| structid_core::solver::exact::peak_memory_bytes(l, 1, 1, false, 0);
    if need(samples) > limit {
        // The largest length that fits: `need` grows with L.
        let (mut lo, mut hi) = (10usize, samples);
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if need(mid) <= limit {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        return Err(WorkflowError::InvalidOption {
            option: "samples",
            value: samples.to_string(),
            rule: format!(
                "the demo's exact solver would need about {} MiB, more than the memory budget \
                 of {} MiB; use at most {lo} samples",
                need(samples) >> 20,
                limit >> 20
            ),
        });
    }
    Ok(())
}

/// Checks the arguments shared by the demos and the output directory, before any work.
fn check_args(samples: usize, out: &std::path::Path, files: &[&str]) -> Result<()> {
    check_samples(
        samples,
        IdentifySettings::default().effective_memory_limit(),
    )?;
    OutputGuard::new().check_out_dir(out, files)?;
    Ok(())
}

fn gaussian_block(
    name: &str,
    inputs: Vec<usize>,
    output: usize,
    sigma: f64,
    truth: &str,
) -> BlockSpec {
    BlockSpec {
        name: name.into(),
        inputs,
        output,
        dispersion: DispersionSpec::Gaussian { sigma: Some(sigma) },
        truth: Some(TruthSpec::Expression(truth.into())),
        operator: None,
        shape: None,
    }
}

/// The spray model in model-file form, with the true maps as expressions.
pub fn spray_model_file(sigma: f64) -> ModelFile {
    ModelFile {
        linear: None,
        lft: paper::spray_lft(),
        signals: SignalNames {
            u: vec!["u".into()],
            y: vec!["y".into()],
            z: None,
        },
        blocks: vec![
            gaussian_block("f", vec![0], 0, sigma, SPRAY_F),
            gaussian_block("g", vec![0], 1, sigma, SPRAY_G),
        ],
        discover: None,
        path: None,
    }
}

fn write_text(
    guard: &OutputGuard,
    path: &Path,
    text: &str,
    written: &mut Vec<PathBuf>,
) -> Result<()> {
    guard.write(path, text.as_bytes())?;
    written.push(path.to_path_buf());
    Ok(())
}

/// One β of the spray demo.
struct SprayRun {
    beta: f64,
    rms_f: f64,
    rms_g: f64,
    cost_total: f64,
    cost_noise: f64,
    seconds: f64,
    /// Centred estimates at the data points.
    f_hat: Vec<f64>,
    g_hat: Vec<f64>,
}

/// The spray demo's arguments.
pub struct DemoRequest<'a> {
    /// The output directory.
    pub out: &'a Path,
    /// The number of samples L.
    pub samples: usize,
    /// The seed of the generators.
    pub seed: u64,
}

/// Runs the spray-deposition example (`structid demo spray`) into `a.out`; returns the
/// summary to print.
pub fn spray(a: &DemoRequest<'_>) -> Result<String> {
    check_args(a.samples, a.out, &SPRAY_OUTPUTS)?;
    let exp = paper::spray(
        a.samples,
        SPRAY_NOISE,
        paper::gaussian(SPRAY_SIGMA)?,
        a.seed,
    )?;
    let guard = OutputGuard::new();
    guard.begin_set(a.out, Some(&SPRAY_OUTPUTS))?;
    let mut written = Vec::new();

    let u = exp.data.u().channel(0);
    let y = exp.data.y().channel(0);
    let f_true = exp.w_true.channel(0);
    let g_true = exp.w_true.channel(1);
    let path = a.out.join("data.csv");
    guard.write_csv(
        &path,
        &["u", "y", "f_true", "g_true", "e"],
        &[
            u.clone(),
            y,
            f_true.clone(),
            g_true.clone(),
            exp.noise.channel(0),
        ],
    )?;
    written.push(path);
    let mf = spray_model_file(SPRAY_SIGMA);
    let model_text = format!(
        "# The spray-deposition example of Hsu, Vincent, Wemhoff & Poolla (2006), section 6.1:\n\
         # y_k = f(u_k) + g(u_(k-2)) + e_k, z = u. Generated by `structid demo spray`; identify with\n\
         # structid identify --model model.toml --data data.csv --out result\n{}",
        mf.to_toml_string()
    );
    write_text(&guard, &a.out.join("model.toml"), &model_text, &mut written)?;

    let mut runs = Vec::new();
    for beta in SPRAY_BETAS {
        let t = Instant::now();
        let settings = IdentifySettings::builder().beta(beta).build()?;
        let id = identify(&exp.model, &exp.data, &settings)?;
        let (Some(f), Some(g)) = (id.block("f"), id.block("g")) else {
            return Err(WorkflowError::Failed(
                "the identification did not return blocks f and g".into(),
            ));
        };
        let centre = |x: &[f64]| {
            let m = mean(x);
            x.iter().map(|v| v - m).collect::<Vec<_>>()
        };
        runs.push(SprayRun {
            beta,
            rms_f: centred_rms_difference(&f.w_hat, &f_true),
            rms_g: centred_rms_difference(&g.w_hat, &g_true),
            cost_total: id.cost.total,
            cost_noise: id.cost.noise,
            seconds: t.elapsed().as_secs_f64(),
            f_hat: centre(&f.w_hat),
            g_hat: centre(&g.w_hat),
        });
    }

    // Fig. 4: one panel per β; true maps as lines, estimates as dots, all centred.
    let (lo, hi) = span(&u);
    let xs = linspace(lo, hi, GRID_1D);
    let (mf_true, mg_true) = (mean(&f_true), mean(&g_true));
    let f_line: Vec<f64> = xs.iter().map(|&x| paper::spray_f(x) - mf_true).collect();
    let g_line: Vec<f64> = xs.iter().map(|&x| paper::spray_g(x) - mg_true).collect();
    let idx = subsample(u.len(), DEMO_DOTS);
    let du: Vec<f64> = idx.iter().map(|&k| u[k]).collect();
    let dots: Vec<(Vec<f64>, Vec<f64>)> = runs
        .iter()
        .map(|r| {
            (
                idx.iter().map(|&k| r.f_hat[k]).collect(),
                idx.iter().map(|&k| r.g_hat[k]).collect(),
            )
        })
        .collect();
    let charts: Vec<Chart<'_>> = runs
        .iter()
        .zip(&dots)
        .map(|(r, (fd, gd))| {
            Chart::new(
                format!(
                    "β = {} (RMS f {:.3}, g {:.3})",
                    crate::text::short(r.beta),
                    r.rms_f,
                    r.rms_g
                ),
                "z = u",
                "map value (centred)",
            )
            .with(Series::line("f true", &xs, &f_line))
            .with(Series::line("g true", &xs, &g_line))
            .with(Series::dots("f estimate", &du, fd))
            .with(Series::dots("g estimate", &du, gd))
        })
        .collect();
    let svg = render_grid_svg(&charts, charts.len(), (560, 440))?;
    write_text(&guard, &a.out.join("fig4.svg"), &svg, &mut written)?;

    let summary = json!({
        "example": "spray deposition (Hsu et al. 2006, section 6.1)",
        "samples": a.samples,
        "seed": a.seed,
        "noise_std": SPRAY_NOISE,
        "dispersion": format!("gaussian(sigma={SPRAY_SIGMA})"),
        "note": "f and g are identifiable only up to a shared constant: errors are centred RMS over the data points",
        "results": runs.iter().map(|r| json!({
            "beta": r.beta,
            "centred_rms_error_f": r.rms_f,
            "centred_rms_error_g": r.rms_g,
            "cost_total": r.cost_total,
            "cost_noise": r.cost_noise,
            "seconds": r.seconds,
        })).collect::<Vec<_>>(),
    });
    let text = serde_json::to_string_pretty(&summary)
        .map_err(|e| WorkflowError::Failed(e.to_string()))?
        + "\n";
    write_text(&guard, &a.out.join("summary.json"), &text, &mut written)?;
    guard.finish_set(a.out, &SPRAY_OUTPUTS)?;

    let mut s = String::new();
    let _ = writeln!(
        s,
        "spray-deposition example: L = {}, noise std {SPRAY_NOISE}, gaussian σ = {SPRAY_SIGMA}, seed {}",
        a.samples, a.seed
    );
    let _ = writeln!(
        s,
        "centred RMS error of the estimated maps at the data points:"
    );
    let _ = writeln!(
        s,
        "  {:>8}  {:>10}  {:>10}  {:>8}",
        "beta", "f", "g", "time [s]"
    );
    for r in &runs {
        let _ = writeln!(
            s,
            "  {:>8}  {:>10.4}  {:>10.4}  {:>8.2}",
            r.beta, r.rms_f, r.rms_g, r.seconds
        );
    }
    let _ = writeln!(s, "wrote:");
    for p in &written {
        let _ = writeln!(s, "  {}", p.display());
    }
    Ok(s)
}

/// Runs the two-input example (`structid demo multi-input`) into `a.out` with output noise of
/// standard deviation `noise_std` (checked by the caller); returns the summary to print.
pub fn multi_input(a: &DemoRequest<'_>, noise_std: f64) -> Result<String> {
    check_args(a.samples, a.out, &MULTI_OUTPUTS)?;
    let t = Instant::now();
    let exp = paper::multi_input(a.samples, noise_std, paper::gaussian(MULTI_SIGMA)?, a.seed)?;
    let guard = OutputGuard::new();
    guard.begin_set(a.out, Some(&MULTI_OUTPUTS))?;
    let mut written = Vec::new();

    let u0 = exp.data.u().channel(0);
    let u1 = exp.data.u().channel(1);
    let w_true = exp.w_true.channel(0);
    let path = a.out.join("data.csv");
    guard.write_csv(
        &path,
        &["u0", "u1", "y", "w_true", "e"],
        &[
            u0.clone(),
            u1.clone(),
            exp.data.y().channel(0),
            w_true.clone(),
            exp.noise.channel(0),
        ],
    )?;
    written.push(path);
    let mf = ModelFile {
        linear: None,
        lft: exp.model.lft().clone(),
        signals: SignalNames {
            u: vec!["u0".into(), "u1".into()],
            y: vec!["y".into()],
            z: None,
        },
        blocks: vec![gaussian_block(
            "N",
            vec![0, 1],
            0,
            MULTI_SIGMA,
            MULTI_INPUT_MAP,
        )],
        discover: None,
        path: None,
    };
    let model_text = format!(
        "# The multi-input example (Hsu et al. 2006, section 6.2), generated by `structid demo multi-input`.\n{}",
        mf.to_toml_string()
    );
    write_text(&guard, &a.out.join("model.toml"), &model_text, &mut written)?;

    let settings = IdentifySettings::builder().beta(MULTI_BETA).build()?;
    let id = identify(&exp.model, &exp.data, &settings)?;
    let est = id
        .blocks
        .first()
        .ok_or_else(|| WorkflowError::Failed("the identification returned no block".into()))?;
    let rms = rms_difference(&est.w_hat, &w_true);
    let rms_centred = centred_rms_difference(&est.w_hat, &w_true);

    let (x0, x1) = span(&u0);
    let (y0, y1) = span(&u1);
    let xs = linspace(x0, x1, GRID_2D);
    let ys = linspace(y0, y1, GRID_2D);
    let truth = |z: &[f64]| paper::multi_input_map(z);
    let tv = grid_values(&truth, &xs, &ys);
    let ev = grid_values(est.map.as_ref() as &dyn Interpolant, &xs, &ys);
    let err: Vec<f64> = ev.iter().zip(&tv).map(|(e, t)| e - t).collect();
    let rms_grid = rms_difference(&ev, &tv);
    let (lo, hi) = span(&[tv.as_slice(), ev.as_slice()].concat());
    let emax = err.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    let maps = [
        HeatMap::new("true map N(z0, z1)", "z0 = u0", "z1 = u1", &xs, &ys, &tv).with_range(lo, hi),
        HeatMap::new(
            format!("estimate (β = {MULTI_BETA}, σ = {MULTI_SIGMA})"),
            "z0 = u0",
            "z1 = u1",
            &xs,
            &ys,
            &ev,
        )
        .with_range(lo, hi),
        HeatMap::new("estimate − truth", "z0 = u0", "z1 = u1", &xs, &ys, &err)
            .with_range(-emax, emax),
    ];
    let svg = render_heatmaps_svg(&maps, 3, (520, 460))?;
    write_text(&guard, &a.out.join("surfaces.svg"), &svg, &mut written)?;

    let summary = json!({
        "example": "multi-input map (Hsu et al. 2006, section 6.2)",
        "samples": a.samples,
        "seed": a.seed,
        "noise_std": noise_std,
        "beta": MULTI_BETA,
        "dispersion": format!("gaussian(sigma={MULTI_SIGMA})"),
        "rms_error_at_data_points": rms,
        "centred_rms_error_at_data_points": rms_centred,
        "rms_error_on_grid": rms_grid,
        "grid": format!("{GRID_2D}×{GRID_2D} over the data range"),
        "cost": id.cost,
        "seconds": t.elapsed().as_secs_f64(),
    });
    let text = serde_json::to_string_pretty(&summary)
        .map_err(|e| WorkflowError::Failed(e.to_string()))?
        + "\n";
    write_text(&guard, &a.out.join("summary.json"), &text, &mut written)?;
    guard.finish_set(a.out, &MULTI_OUTPUTS)?;

    let mut s = String::new();
    let _ = writeln!(
        s,
        "multi-input example: L = {}, noise std {noise_std}, gaussian σ = {MULTI_SIGMA}, β = {MULTI_BETA}, seed {}",
        a.samples, a.seed
    );
    let _ = writeln!(
        s,
        "RMS error of N̂: {rms:.4} at the data points (centred {rms_centred:.4}), {rms_grid:.4} on the {GRID_2D}×{GRID_2D} grid"
    );
    let _ = writeln!(s, "wrote:");
    for p in &written {
        let _ = writeln!(s, "  {}", p.display());
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_core::ExprMap;

    #[test]
    fn expressions_match_the_paper_maps() {
        let f = ExprMap::parse(SPRAY_F, 1).unwrap();
        let g = ExprMap::parse(SPRAY_G, 1).unwrap();
        let n = ExprMap::parse(MULTI_INPUT_MAP, 2).unwrap();
        for i in 0..41 {
            let z = -2.0 + 0.1 * i as f64;
            assert!((f.eval(&[z]) - paper::spray_f(z)).abs() < 1e-12);
            assert!((g.eval(&[z]) - paper::spray_g(z)).abs() < 1e-12, "{z}");
            let p = [z, 0.7 - 0.5 * z];
            assert!(
                (n.eval(&p) - paper::multi_input_map(&p)).abs() < 1e-12,
                "{p:?}"
            );
        }
    }

    #[test]
    fn spray_model_file_round_trips() {
        let mf = spray_model_file(0.1);
        let back = ModelFile::parse(&mf.to_toml_string(), None).unwrap();
        assert_eq!(back.lft, mf.lft);
        assert_eq!(back.blocks, mf.blocks);
    }
}
