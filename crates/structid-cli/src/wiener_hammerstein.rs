//! `structid wiener-hammerstein` and `structid hammerstein-wiener`: block-structured models with
//! every block unknown, from data. Arguments are parsed here; the workflow is
//! `structid_workflow::wiener_hammerstein`.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use structid_core::Data;
use structid_io::{OutputGuard, SignalNames};
use structid_joint::WienerHammersteinSettings;
use structid_workflow::{BetaChoice, BlockStructure, WienerHammersteinRequest};

use crate::InitialStateArg;
use crate::error::CliError;

/// Arguments of `structid wiener-hammerstein` and `structid hammerstein-wiener`.
#[derive(Debug, Args)]
pub struct WienerHammersteinArgs {
    /// The estimation data (CSV with a header row); repeat it for several records.
    #[arg(long, short = 'd', value_name = "DATA.csv", required = true)]
    data: Vec<PathBuf>,
    /// The input column.
    #[arg(long, value_name = "COL", default_value = "u")]
    input: String,
    /// The output column.
    #[arg(long, value_name = "COL", default_value = "y")]
    output: String,
    /// Orders `NA,NB,NK` of the best linear approximation (MATLAB's convention): the poles of
    /// the LTI block(s), the numerator's coefficients, the delay.
    #[arg(long, value_name = "NA,NB,NK", value_parser = crate::linear::parse_orders, required = true)]
    orders: [usize; 3],
    /// Validation records: β is then chosen on them from 10⁻¹⁰ … 10⁻² unless --beta is given.
    #[arg(long, value_name = "V.csv")]
    validation_data: Vec<PathBuf>,
    /// The map's dispersion weight β (default 1e-8 without validation records).
    #[arg(long, value_name = "B")]
    beta: Option<f64>,
    /// Kernel centres of each map, over the range of its input plus 10 % on each side.
    #[arg(long, value_name = "N", default_value_t = 15)]
    centres: usize,
    /// Levenberg–Marquardt iterations per stage.
    #[arg(long, value_name = "N", default_value_t = 100)]
    iterations: usize,
    /// Samples per multiple-shooting segment (default: single shooting).
    #[arg(long, value_name = "N")]
    segment_length: Option<usize>,
    /// Fit by the score of a simulation in windows of LENGTH samples, each from a state
    /// fitted to its first half and scored after its first INIT samples.
    #[arg(long, value_name = "LENGTH:INIT", value_parser = crate::refine::parse_windows)]
    windows: Option<structid_core::validation::Windows>,
    /// `zero` (each record starts at rest) or `estimate` (each record's initial state fitted).
    #[arg(long, value_name = "zero|estimate", default_value = "zero")]
    initial_state: InitialStateArg,
    /// Output directory: model.toml, the maps' tables, joint.json, divisions.json.
    #[arg(long, short = 'o', value_name = "DIR")]
    out: PathBuf,
}

fn records(paths: &[PathBuf], a: &WienerHammersteinArgs) -> Result<Data, CliError> {
    let records = paths
        .iter()
        .map(|p| {
            let table = crate::data::read_table(p)?;
            let u = table.select(std::slice::from_ref(&a.input))?;
            let y = table.select(std::slice::from_ref(&a.output))?;
            Ok(Data::new(u, y)?)
        })
        .collect::<Result<Vec<_>, CliError>>()?;
    Ok(Data::from_records(records)?)
}

/// Runs `structid wiener-hammerstein` or `structid hammerstein-wiener`.
pub fn run(a: WienerHammersteinArgs, structure: BlockStructure) -> Result<(), CliError> {
    let t0 = Instant::now();
    let mut guard = OutputGuard::new();
    for d in a.data.iter().chain(&a.validation_data) {
        guard.protect(d);
    }
    let data = records(&a.data, &a)?;
    let validation = match a.validation_data.is_empty() {
        true => None,
        false => Some(records(&a.validation_data, &a)?),
    };
    let start = WienerHammersteinSettings::builder()
        .centres(a.centres)
        .build()
        .map_err(|e| CliError::input(format!("--centres: {e}")))?;
    let fit = structid_workflow::FitOptions {
        iterations: a.iterations,
        estimate_initial_state: matches!(a.initial_state, InitialStateArg::Estimate),
        segment_length: a.segment_length,
        windows: a.windows,
    };
    let req = WienerHammersteinRequest {
        structure,
        data: &data,
        names: SignalNames {
            u: vec![a.input.clone()],
            y: vec![a.output.clone()],
            z: None,
        },
        orders: a.orders,
        beta: BetaChoice::from_options_or(a.beta, validation, start.beta()),
        start,
        fit: fit.settings().map_err(|e| CliError::input(e.to_string()))?,
    };
    let out = structid_workflow::wiener_hammerstein(&req)
        .map_err(|e| CliError::from(e).context("cannot identify the block-structured model"))?;
    structid_workflow::write_wiener_hammerstein_outputs(&out, &a.out, &guard)?;
    if let Some(best) = out.divisions.first() {
        println!(
            "Wiener–Hammerstein model: {} divisions of the linear approximation scored, best start RMS {:.4e}",
            out.divisions.len(),
            best.rms
        );
    }
    println!(
        "joint fit: cost {:.4e} → {:.4e}, simulation RMS {:.4e} (β = {:.1e}, {:.2} s)",
        out.joint.fit.initial_cost,
        out.joint.fit.cost,
        out.joint.fit.rms[0],
        out.joint.beta,
        t0.elapsed().as_secs_f64()
    );
    for t in &out.joint.trials {
        println!(
            "  β = {:.1e}: validation RMS {:?}",
            t.beta, t.validation_rms
        );
    }
    println!(
        "wrote {}/model.toml, the map tables, joint.json and divisions.json",
        a.out.display()
    );
    Ok(())
}
