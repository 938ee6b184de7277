//! `structid simulate`.

use structid_io::{ModelFile, OutputGuard};

use crate::SimulateArgs;
use crate::error::{CliError, finite_columns};
use crate::identify::protect_inputs;

/// Runs `structid simulate`.
pub fn run(a: SimulateArgs) -> Result<(), CliError> {
    let noise_std = crate::error::noise_std("--noise-std", a.noise_std)?;
    let model_path = match (&a.model, &a.estimate) {
        (_, Some(e)) => return crate::stored::simulate(&a, e, noise_std),
        (Some(m), None) => m.clone(),
        (None, None) => {
            return Err(CliError::input(
                "give --model MODEL.toml or --estimate FILE.json",
            ));
        }
    };
    let model_path = model_path.as_path();
    let mf = ModelFile::from_path(model_path)?;
    let mut guard = OutputGuard::new();
    protect_inputs(&mut guard, &mf, model_path, &[&a.input]);
    guard.check_out_file(&a.out)?;
    // A nominal model's declared w columns carry w = 0.
    let lft = mf.model_lft()?;
    mf.evaluation_order().map_err(|e| {
        CliError::from(e).context(format!("cannot simulate `{}`", model_path.display()))
    })?;
    let missing: Vec<String> = mf
        .blocks
        .iter()
        .filter(|b| b.truth.is_none() && b.operator.is_none())
        .map(|b| format!("`{}`", b.name))
        .collect();
    if !missing.is_empty() {
        return Err(CliError::input(format!(
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
            return Err(CliError::input(format!(
                "cannot simulate `{}`: the output column `{n}` would appear twice; the u, y and z names in \
                 [signals] and the `w_<block>` columns must all differ (z columns are named z0, z1, … unless \
                 [signals].z names them)",
                model_path.display()
            )));
        }
    }

    let table = crate::data::read_table(&a.input)?;
    let u = table
        .select(&mf.signals.u)
        .map_err(|e| CliError::from(e).context("reading the inputs named in [signals].u"))?;
    let len = u.len();
    let dims = lft.dims();
    let sim = structid_workflow::simulate_model_file_noisy(&mf, &u, noise_std, a.seed)?;

    let mut columns: Vec<Vec<f64>> = Vec::with_capacity(names.len());
    columns.extend((0..dims.u).map(|c| u.channel(c)));
    columns.extend((0..dims.y).map(|c| sim.y.channel(c)));
    columns.extend((0..dims.z).map(|c| sim.z.channel(c)));
    columns.extend(mf.blocks.iter().map(|b| sim.w.channel(b.output)));
    finite_columns(&names, &columns, noise_std)?;
    guard.write_csv(&a.out, &names, &columns)?;
    println!(
        "simulated {len} samples ({} noise, std {noise_std}, seed {}); wrote {} with columns {}",
        if noise_std > 0.0 { "Gaussian" } else { "no" },
        a.seed,
        a.out.display(),
        names.join(", ")
    );
    Ok(())
}
