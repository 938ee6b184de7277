//! The cascaded-tanks benchmark: estimate on the estimation record, score on the test record.
//!
//! ```text
//! cargo run --release --example cascaded_tanks -- [PATH/dataBenchmark.csv] [OUT_DIR]
//! ```
//!
//! PATH defaults to `../shared/data/cascaded_tanks/dataBenchmark.csv` beside the workspace (or
//! `$STRUCTID_DATA/cascaded_tanks/dataBenchmark.csv`), OUT_DIR to `target/cascaded_tanks`.
//! Prints the candidate search (scored on the last 25 % of the estimation record), the test
//! RMS of the final model of each structure next to the published figures, and writes
//! `test.svg` (measured and simulated test output) and `results.json`.
//!
//! Environment overrides: `TANKS_ORDERS=1,2,3`, `TANKS_DEGREE=3`, `TANKS_SIGMA=0.2`,
//! `TANKS_NO_KERNEL`, `TANKS_NO_OVERFLOW`, `TANKS_NO_REFIT`.

use structid::io::CascadedTanks;
use structid::plot::{Chart, Series};
use structid_benchmarks::tanks::{Candidate, PUBLISHED, TanksSettings, run};

mod common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (path, out) = common::benchmark_args("cascaded_tanks/dataBenchmark.csv", "cascaded_tanks");
    let tanks = CascadedTanks::load(&path)?;
    let mut settings = TanksSettings::default();
    common::env_override_list("TANKS_ORDERS", &mut settings.orders)?;
    common::env_override("TANKS_DEGREE", &mut settings.trend_degree)?;
    common::env_override("TANKS_SIGMA", &mut settings.sigma_fraction)?;
    if std::env::var_os("TANKS_NO_KERNEL").is_some() {
        settings.kernel = false;
    }
    if std::env::var_os("TANKS_NO_REFIT").is_some() {
        settings.refit = false;
    }
    if std::env::var_os("TANKS_NO_OVERFLOW").is_some() {
        settings.overflow = false;
    }
    let r = run(&tanks, &settings)?;

    println!(
        "offsets u₀ = {:.4} V, y₀ = {:.4} V; overflow clip at {:.3} V; fitting part {} samples, \
         validation the remaining {}",
        r.input_offset,
        r.output_offset,
        r.overflow_level,
        r.fit_samples,
        tanks.estimation.len() - r.fit_samples
    );
    println!("\ncandidates (validation RMS [V], last part of the estimation record):");
    println!(
        "  {:<26} n  map          raw val.  clipped val.  alternations  seconds",
        "structure"
    );
    for c in &r.candidates {
        print!(
            "  {} {:>8.3}  {:>12.3}  {:>12}  {:>7.1}",
            candidate_columns(c),
            c.validation_rms,
            c.validation_rms_clipped,
            c.iterations,
            c.seconds
        );
        match &c.failure {
            Some(f) => println!("  failed: {f}"),
            None => println!(),
        }
    }

    println!(
        "\nfinal models ({}) — RMS [V]:",
        if settings.refit {
            "re-estimated on the whole estimation record"
        } else {
            "as fitted on the fitting part and validated"
        }
    );
    println!(
        "  {:<26} n  map          clip  validation  estimation  test (x₀ from est.)  test (x₀ = 0)",
        "structure"
    );
    for (i, m) in r.models.iter().enumerate() {
        let c = &m.candidate;
        println!(
            "  {} {:<4}  {:>10.3}  {:>10.3}  {:>19.3}  {:>13.3}{}",
            candidate_columns(c),
            if m.clipped { "yes" } else { "no" },
            c.score(),
            m.estimation_rms,
            m.test_rms,
            m.test_rms_zero_state,
            if i == r.chosen {
                "  ← chosen on validation"
            } else {
                ""
            }
        );
    }
    println!("\npublished test RMS [V] (Forgione and Piga 2021, Table 3):");
    for (name, v) in PUBLISHED {
        println!("  {name:<34} {v}");
    }
    println!(
        "  {:<34} {:.3}",
        "structid (chosen on validation)", r.models[r.chosen].test_rms
    );
    println!("({:.1} s)", r.seconds);

    std::fs::create_dir_all(&out)?;
    let m = &r.models[r.chosen];
    let t: Vec<f64> = (0..r.measured.len())
        .map(|k| k as f64 * tanks.test.sample_time)
        .collect();
    let chart = Chart::new(
        "Cascaded tanks: test record",
        "time [s]",
        "lower tank level y [V]",
    )
    .with(Series::line("measured", &t, &r.measured))
    .with(Series::line("simulated (chosen model)", &t, &m.simulated));
    common::write_chart(&out, "test.svg", &chart, &path)?;
    let models: Vec<_> = r
        .models
        .iter()
        .map(|m| {
            serde_json::json!({
                "candidate": m.candidate,
                "clipped": m.clipped,
                "estimation_rms": m.estimation_rms,
                "test_rms": m.test_rms,
                "test_rms_zero_state": m.test_rms_zero_state,
                "initial_state": m.initial_state,
                "linear": m.linear,
                "beta": m.refinement.as_ref().map(|f| f.beta),
            })
        })
        .collect();
    let json = serde_json::json!({
        "candidates": r.candidates,
        "models": models,
        "chosen": r.chosen,
        "input_offset": r.input_offset,
        "output_offset": r.output_offset,
        "overflow_level": r.overflow_level,
        "seconds": r.seconds,
    });
    common::write_results(&out, &json, &path)?;
    println!("wrote {}/{{test.svg, results.json}}", out.display());
    Ok(())
}

/// The columns that name a candidate in both tables: structure, order, and its map (none, or
/// the expansion it was fitted with).
fn candidate_columns(c: &Candidate) -> String {
    let map = if !c.structure.has_map() {
        "-"
    } else if c.kernel {
        "fourier+poly"
    } else {
        "polynomial"
    };
    format!("{:<26} {}  {:<12}", c.structure.name(), c.order, map)
}
