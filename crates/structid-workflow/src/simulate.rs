//! Simulation of a model file with the `truth` map of every block in the loop, written as a
//! CSV file of u, y, z and w columns (`structid simulate --model`).

use std::path::Path;

use structid_io::{ModelFile, OutputGuard, Vars};

use crate::paths::protect_inputs;
use crate::stored::finite_columns;
use crate::{Result, WorkflowError};

/// A simulation of a model file.
pub struct SimulateRequest<'a> {
    /// The model file; every block needs a `truth` (or an operator).
    pub model: &'a Path,
    /// The file of the input columns named in `[signals].u`.
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

/// Simulates the model file with its true maps on the inputs and writes the u, y and z
/// columns plus one `w_<block>` column per block; returns the line to print.
pub fn simulate_to_csv(r: &SimulateRequest<'_>) -> Result<String> {
    let noise_std = r.noise_std;
    let model_path = r.model;
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
