//! Simulation on an input record, written as a CSV file (`structid simulate`): of a model
//! file with the `truth` map of every block in the loop (u, y, z and w columns), or of a stored
//! estimate (u and y columns).

use std::path::Path;

use structid_core::paper::gaussian_noise;

use structid_io::{ModelFile, OutputGuard, Vars};

use crate::paths::protect_inputs;
use crate::{Result, WorkflowError};

/// What is simulated.
#[derive(Clone, Copy, Debug)]
pub enum SimulationSource<'a> {
    /// A model file; every block needs a `truth` (or an operator).
    ModelFile(&'a Path),
    /// A stored estimate (`estimate.json`).
    Estimate(&'a Path),
}

/// A simulation of a model file or of a stored estimate on an input record.
pub struct SimulateRequest<'a> {
    /// The model simulated.
    pub source: SimulationSource<'a>,
    /// The file of the input columns (the model's `[signals].u`, or the estimate's input
    /// names).
    pub input: &'a Path,
    /// The CSV file to write.
    pub out: &'a Path,
    /// Standard deviation of the white Gaussian noise on every noise channel (checked by the
    /// caller).
    pub noise_std: f64,
    /// Seed of the noise generator.
    pub seed: u64,
    /// The signals picked from the input file.
    pub vars: Option<&'a Vars>,
}

/// Simulates the request's model and writes the CSV file; returns the line to print.
pub fn simulate(r: &SimulateRequest<'_>) -> Result<String> {
    match r.source {
        SimulationSource::ModelFile(path) => simulate_model_file(path, r),
        SimulationSource::Estimate(path) => simulate_estimate(path, r),
    }
}

/// Simulates the model file with its true maps on the inputs and writes the u, y and z
/// columns plus one `w_<block>` column per block; returns the line to print.
fn simulate_model_file(model_path: &Path, r: &SimulateRequest<'_>) -> Result<String> {
    let noise_std = r.noise_std;
    let mf = ModelFile::from_path(model_path)?;
    let mut guard = OutputGuard::new();
    protect_inputs(&mut guard, &mf, model_path, &[r.input]);
    guard.check_out_file(r.out)?;
    // A nominal model's declared w columns carry w = 0.
    let lft = mf.model_lft()?;
    mf.evaluation_order().map_err(|e| {
        WorkflowError::from(e).context(format!("cannot simulate `{}`", model_path.display()))
    })?;
    let missing: Vec<String> = mf
        .blocks
        .iter()
        .filter(|b| b.truth.is_none() && b.operator.is_none())
        .map(|b| format!("`{}`", b.name))
        .collect();
    if !missing.is_empty() {
        return Err(WorkflowError::Request(format!(
            "cannot simulate `{}`: block(s) {} have no `truth`; simulation needs the true map of every block \
             (truth = \"expression in z0, z1, …\" or truth = {{ table = \"file.csv\" }})",
            model_path.display(),
            missing.join(", ")
        )));
    }
    // Output column names: u, y, z, w_<block>; they must be distinct.
    let z_names = mf.z_names();
    let mut names: Vec<String> = Vec::new();
    names.extend(mf.signals.u.iter().cloned());
    names.extend(mf.signals.y.iter().cloned());
    names.extend(z_names.iter().cloned());
    names.extend(mf.blocks.iter().map(|b| format!("w_{}", b.name)));
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            return Err(WorkflowError::Request(format!(
                "cannot simulate `{}`: the output column `{n}` would appear twice; the u, y and z names in \
                 [signals] and the `w_<block>` columns must all differ (z columns are named z0, z1, … unless \
                 [signals].z names them)",
                model_path.display()
            )));
        }
    }

    let table = crate::records::read_table(r.input, r.vars)?;
    let u = table
        .select(&mf.signals.u)
        .map_err(|e| WorkflowError::from(e).context("reading the inputs named in [signals].u"))?;
    let len = u.len();
    let dims = lft.dims();
    let sim = crate::simulate_model_file_noisy(&mf, &u, noise_std, r.seed)?;

    let mut columns: Vec<Vec<f64>> = Vec::with_capacity(names.len());
    columns.extend((0..dims.u).map(|c| u.channel(c)));
    columns.extend((0..dims.y).map(|c| sim.y.channel(c)));
    columns.extend((0..dims.z).map(|c| sim.z.channel(c)));
    columns.extend(mf.blocks.iter().map(|b| sim.w.channel(b.output)));
    finite_columns(&names, &columns, noise_std)?;
    guard.write_csv(r.out, &names, &columns)?;
    Ok(format!(
        "simulated {len} samples ({} noise, std {noise_std}, seed {}); wrote {} with columns {}\n",
        if noise_std > 0.0 { "Gaussian" } else { "no" },
        r.seed,
        r.out.display(),
        names.join(", ")
    ))
}

/// Simulates a stored estimate on an input record and writes the inputs and the simulated
/// outputs as a CSV file; returns the line to print.
fn simulate_estimate(path: &Path, r: &SimulateRequest<'_>) -> Result<String> {
    let noise_std = r.noise_std;
    let mut guard = OutputGuard::new();
    guard.protect(path);
    guard.protect(r.input);
    guard.check_out_file(r.out)?;
    let (estimate, u_names, y_names) = crate::stored::load(path)?;
    let table = crate::records::read_table(r.input, r.vars)?;
    let u = table
        .select(&u_names)
        .map_err(|e| WorkflowError::from(e).context("reading the estimate's input columns"))?;
    let dims = estimate.lft().dims();
    let e = (noise_std > 0.0).then(|| gaussian_noise(u.len(), dims.e, noise_std, r.seed));
    let sim = estimate
        .model()
        .simulate(&estimate.maps(), &u, e.as_ref(), None)?;
    let mut names = u_names.clone();
    names.extend(y_names.iter().cloned());
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            return Err(WorkflowError::Request(format!(
                "the estimate's channel name `{n}` appears twice; cannot write distinct columns"
            )));
        }
    }
    let mut columns: Vec<Vec<f64>> = (0..dims.u).map(|c| u.channel(c)).collect();
    columns.extend((0..dims.y).map(|c| sim.y.channel(c)));
    finite_columns(&names, &columns, noise_std)?;
    guard.write_csv(r.out, &names, &columns)?;
    Ok(format!(
        "simulated the stored estimate `{}` on {} samples ({} noise, std {noise_std}); wrote {} with columns {}\n",
        path.display(),
        u.len(),
        if noise_std > 0.0 { "Gaussian" } else { "no" },
        r.out.display(),
        names.join(", ")
    ))
}

/// Refuses simulated columns that are not finite (the model's gains and the noise level
/// overflow together), naming the column and the first sample, so that no file of
/// non-finite numbers (which no command reads back) is written.
pub fn finite_columns<S: AsRef<str>>(
    names: &[S],
    columns: &[Vec<f64>],
    noise_std: f64,
) -> Result<()> {
    for (name, c) in names.iter().zip(columns) {
        if let Some(k) = c.iter().position(|v| !v.is_finite()) {
            // Without noise, the model alone overflows: no option is to blame.
            if noise_std == 0.0 {
                return Err(WorkflowError::Failed(format!(
                    "the simulated column `{}` is not finite at sample {k} ({}): the model's \
                     simulation diverges or overflows; rescale the model. Nothing was written",
                    name.as_ref(),
                    c[k]
                )));
            }
            return Err(WorkflowError::InvalidOption {
                option: "noise_std",
                value: format!("{noise_std:e}"),
                rule: format!(
                    "the simulated column `{}` is not finite at sample {k} ({}): the model's \
                     gains and the noise overflow together; give a smaller noise standard \
                     deviation, or rescale the model. Nothing was written",
                    name.as_ref(),
                    c[k]
                ),
            });
        }
    }
    Ok(())
}
