//! The paper's spray-deposition example (section 6.1), reproduced.
//!
//! y_k = f(u_k) + g(u_{k−2}) + e_k with u_k = sin(0.1k), e ~ N(0, 1), f(z) = −|z| and
//! g(z) = 0.5·(sin((3z)²) + (2z)² − 2), identified with the Gaussian dispersion for
//! β ∈ {0.001, 0.01, 0.1}. Writes a figure like the paper's Fig. 4 (true maps as lines,
//! estimates as dots; both centred, since f and g are identifiable only up to a shared constant).
//!
//! `cargo run --release --example spray -- [L] [out_dir]` (defaults 2000, target/examples/spray)

use std::sync::Arc;

use structid::paper::{spray, spray_f, spray_g};
use structid::plot::{Chart, Series, render_grid_svg};
use structid::validation::metrics::centred_rms_difference;
use structid::{IdentifySettings, KernelDispersion, identify};

fn centred(v: &[f64]) -> Vec<f64> {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    v.iter().map(|x| x - m).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let len: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(2000);
    let out = std::path::PathBuf::from(
        args.get(2)
            .cloned()
            .unwrap_or_else(|| "target/examples/spray".into()),
    );
    std::fs::create_dir_all(&out)?;
    let sigma = 0.1;
    let exp = spray(len, 1.0, Arc::new(KernelDispersion::gaussian(sigma)?), 2006)?;
    let z: Vec<f64> = exp.data.u().channel(0);
    // Sort once so the true maps draw as lines.
    let mut order: Vec<usize> = (0..len).collect();
    order.sort_by(|&a, &b| z[a].total_cmp(&z[b]));
    let zs: Vec<f64> = order.iter().map(|&k| z[k]).collect();
    let f_true = centred(&zs.iter().map(|&v| spray_f(v)).collect::<Vec<_>>());
    let g_true = centred(&zs.iter().map(|&v| spray_g(v)).collect::<Vec<_>>());

    let betas = [0.001, 0.01, 0.1];
    let mut estimates = Vec::new();
    println!("spray example, L = {len}, σ = {sigma}");
    println!(
        "{:>8} {:>12} {:>12} {:>10} {:>9}",
        "beta", "rms(f)", "rms(g)", "J", "time[s]"
    );
    for beta in betas {
        let settings = IdentifySettings::builder().beta(beta).build()?;
        let id = identify(&exp.model, &exp.data, &settings)?;
        let f_hat = centred(
            &order
                .iter()
                .map(|&k| id.blocks[0].w_hat[k])
                .collect::<Vec<_>>(),
        );
        let g_hat = centred(
            &order
                .iter()
                .map(|&k| id.blocks[1].w_hat[k])
                .collect::<Vec<_>>(),
        );
        let ef = centred_rms_difference(&f_hat, &f_true);
        let eg = centred_rms_difference(&g_hat, &g_true);
        println!(
            "{beta:>8} {ef:>12.4} {eg:>12.4} {:>10.4} {:>9.3}",
            id.cost.total, id.diagnostics.timings.total
        );
        estimates.push((beta, f_hat, g_hat));
    }
    // Every few points are enough for the dots; the figure stays small.
    let step = (len / 500).max(1);
    let thin = |v: &[f64]| v.iter().step_by(step).copied().collect::<Vec<_>>();
    let zs_thin = thin(&zs);
    let estimates: Vec<(f64, Vec<f64>, Vec<f64>)> = estimates
        .iter()
        .map(|(b, f, g)| (*b, thin(f), thin(g)))
        .collect();
    let mut charts = Vec::new();
    for (beta, f_hat, g_hat) in &estimates {
        charts.push(
            Chart::new(format!("f, β = {beta}"), "z", "f(z) − mean")
                .with(Series::line("true f", &zs, &f_true))
                .with(Series::dots("estimate", &zs_thin, f_hat)),
        );
        charts.push(
            Chart::new(format!("g, β = {beta}"), "z", "g(z) − mean")
                .with(Series::line("true g", &zs, &g_true))
                .with(Series::dots("estimate", &zs_thin, g_hat)),
        );
    }
    let svg = render_grid_svg(&charts, 2, (520, 320))?;
    let path = out.join("fig4.svg");
    std::fs::write(&path, svg)?;
    println!("figure: {}", path.display());
    Ok(())
}
