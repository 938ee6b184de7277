//! The Silverbox benchmark: estimate on the estimation split, score on the three test splits.
//!
//! ```text
//! cargo run --release --example silverbox -- [PATH/SNLS80mV.csv] [OUT_DIR]
//! ```
//!
//! PATH defaults to `../shared/data/silverbox/SNLS80mV.csv` beside the workspace (or
//! `$STRUCTID_DATA/silverbox/SNLS80mV.csv`), OUT_DIR to `target/silverbox`. Prints the order
//! search, the alternations and the test RMS errors next to the published figures, and writes
//! `map.svg` (N̂(y) with its 95 % band over the arrow test's amplitude range), `error.svg` (the
//! arrow-test simulation error over time) and `results.json`.

use structid::Signal;
use structid::io::Silverbox;
use structid::plot::{Chart, Series};
use structid_benchmarks::silverbox::{SilverboxSettings, run};

mod common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (path, out) = common::benchmark_args("silverbox/SNLS80mV.csv", "silverbox");
    let sb = Silverbox::load(&path)?;
    let mut settings = SilverboxSettings::default();
    common::env_override("SB_SIGMA", &mut settings.sigma_fraction)?;
    common::env_override_list("SB_ORDERS", &mut settings.orders)?;
    common::env_override("SB_DEGREE", &mut settings.trend_degree)?;
    common::env_override("SB_SCALE", &mut settings.trend_scale)?;
    if std::env::var_os("SB_TUNE").is_some() {
        settings.tune_sigma = true;
    }
    let r = run(&sb, &settings)?;

    println!("order search (validation = last 20 % of the estimation split):");
    println!(
        "  n  separate B_w  map                BLA val. RMS [mV]  structured val. RMS [mV]  alternations"
    );
    for (i, c) in r.candidates.iter().enumerate() {
        println!(
            "  {}  {:<12}  {:<17}  {:>17.3}  {:>24.3}  {:>12}{}",
            c.order,
            c.separate_numerator,
            if c.kernel {
                "fourier + cubic"
            } else {
                "cubic polynomial"
            },
            1e3 * c.bla_validation_rms,
            1e3 * c.validation_rms,
            c.iterations,
            if i == r.chosen { "  ← chosen" } else { "" }
        );
    }
    let f = &r.refinement;
    println!(
        "final model: β = {:.3e}, σ = {:?}, {} alternation(s) on the whole estimation split",
        f.beta,
        f.model.blocks()[0].dispersion.width(),
        f.iterations.len()
    );
    println!(
        "\ntest RMS simulation error [mV] (published on the full arrow: BLA 13.5, deep encoder 1.4, PNLSS 0.3):"
    );
    println!("  split                          structid  own BLA (n = 2)  own BLA (chosen n)");
    for t in &r.tests {
        println!(
            "  {:<29}  {:>8.3}  {:>15.3}  {:>18.3}",
            t.split,
            1e3 * t.rms,
            1e3 * t.bla2_rms,
            1e3 * t.bla_rms
        );
    }
    println!("({:.1} s)", r.seconds);

    // Figures.
    std::fs::create_dir_all(&out)?;
    let id = &f.identification;
    let grid: Vec<f64> = (0..=240).map(|i| -0.3 + 0.6 * i as f64 / 240.0).collect();
    let points = Signal::from_channels(std::slice::from_ref(&grid))?;
    let nhat: Vec<f64> = grid.iter().map(|&y| id.blocks[0].predict(&[y])).collect();
    let std = id
        .posterior_std(0, &points)?
        .unwrap_or_else(|| vec![0.0; grid.len()]);
    let lower: Vec<f64> = nhat.iter().zip(&std).map(|(v, s)| v - 1.96 * s).collect();
    let upper: Vec<f64> = nhat.iter().zip(&std).map(|(v, s)| v + 1.96 * s).collect();
    // Every 30th estimation sample keeps the figure small.
    let z: Vec<f64> = id.blocks[0].z.channel(0).into_iter().step_by(30).collect();
    let w: Vec<f64> = id.w_hat.channel(0).into_iter().step_by(30).collect();
    let map = Chart::new("Silverbox: identified N̂(y)", "y [V]", "N̂(y)")
        .with(Series::dots("ŵ at estimation samples (every 30th)", &z, &w))
        .with(Series::band("95 % band", &grid, &[], &lower, &upper))
        .with(Series::line("N̂(y)", &grid, &nhat));
    common::write_chart(&out, "map.svg", &map, &path)?;
    let arrow = &r.tests[0];
    let t: Vec<f64> = (0..arrow.measured.len())
        .map(|k| k as f64 * sb.sample_time)
        .collect();
    let err: Vec<f64> = arrow
        .measured
        .iter()
        .zip(&arrow.simulated)
        .map(|(a, b)| 1e3 * (a - b))
        .collect();
    let chart = Chart::new(
        "Silverbox: simulation error on the full arrow test",
        "time [s]",
        "y − ŷ [mV]",
    )
    .with(Series::line("error", &t, &err));
    common::write_chart(&out, "error.svg", &chart, &path)?;
    let json = serde_json::json!({
        "candidates": r.candidates,
        "chosen": r.chosen,
        "beta": f.beta,
        "sigma": f.model.blocks()[0].dispersion.width(),
        "iterations": f.iterations,
        "linear": f.linear,
        "tests": r.tests,
        "seconds": r.seconds,
    });
    common::write_results(&out, &json, &path)?;
    println!(
        "wrote {}/{{map.svg, error.svg, results.json}}",
        out.display()
    );
    Ok(())
}
