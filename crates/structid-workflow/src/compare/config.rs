//! Loading a sweep: the configuration ([`SweepFile`]) plus every file it names, checked before
//! any case runs, so that a typo fails at once instead of in every case.

use std::path::{Path, PathBuf};

use structid_core::{Data, Interpolant, Signal};
use structid_io::sweep_file::{ExperimentData, SweepExperiment, SweepPath};
use structid_io::{DataTable, ModelFile, SweepFile, TruthSpec};

use crate::compare::cases::Fnv;
use crate::error::{Result, WorkflowError};

/// A sweep ready to run: the configuration and its experiments with their files loaded.
pub struct Sweep {
    /// The parsed configuration.
    pub file: SweepFile,
    /// The experiments, in configuration order.
    pub experiments: Vec<Experiment>,
    /// Every file read (configuration, model files, data, inputs, truth tables): outputs may
    /// never overwrite them.
    pub inputs: Vec<PathBuf>,
}

/// One experiment with its model and data loaded.
pub struct Experiment {
    /// Its name.
    pub name: String,
    /// Its model file.
    pub model: ModelFile,
    /// The true map of each block (model order), when the model file gives one.
    pub truth: Vec<Option<Box<dyn Interpolant>>>,
    /// Per block: whether its error is centred, because another block feeds one of the
    /// outputs it feeds (the two are identifiable only up to a shared constant).
    pub centred: Vec<bool>,
    /// Names of the measured outputs y (validation columns).
    pub outputs: Vec<String>,
    /// Whether validation data exist.
    pub has_validation: bool,
    /// Hash of the experiment's settings and the bytes of its files, for resume checks.
    pub fingerprint: u64,
    data: Source,
}

enum Source {
    Measured {
        estimation: Data,
        validation: Option<Data>,
    },
    Simulated {
        input: Signal,
        validation_input: Option<Signal>,
        noise_std: f64,
        validation_noise_std: f64,
        maps: Vec<Box<dyn Interpolant>>,
    },
}

/// Offset between the noise streams of the estimation and validation records of one seed, so
/// that the two are independent (the estimation record uses the seed itself, like
/// `structid simulate --seed`).
const VALIDATION_SEED_OFFSET: u64 = 0x5851_f42d_4c95_7f2d;

impl Experiment {
    /// The estimation record and, when the experiment has one, the validation record. Simulated
    /// experiments are simulated here with noise seed `seed` (required for them).
    pub fn records(&self, seed: Option<u64>) -> Result<(Data, Option<Data>)> {
        match &self.data {
            Source::Measured {
                estimation,
                validation,
            } => Ok((estimation.clone(), validation.clone())),
            Source::Simulated {
                input,
                validation_input,
                noise_std,
                validation_noise_std,
                maps,
            } => {
                let seed = seed.ok_or_else(|| {
                    WorkflowError::Failed(format!(
                        "experiment `{}` is simulated and needs a seed",
                        self.name
                    ))
                })?;
                let est = simulate(&self.model, maps, input, *noise_std, seed)?;
                let val = validation_input
                    .as_ref()
                    .map(|u| {
                        simulate(
                            &self.model,
                            maps,
                            u,
                            *validation_noise_std,
                            seed.wrapping_add(VALIDATION_SEED_OFFSET),
                        )
                    })
                    .transpose()?;
                Ok((est, val))
            }
        }
    }
}

/// The record `structid simulate --seed` would write and `identify` would read: y (and the z
/// columns when z is measured) with the truth maps in the loop and white Gaussian noise.
fn simulate(
    mf: &ModelFile,
    maps: &[Box<dyn Interpolant>],
    u: &Signal,
    noise_std: f64,
    seed: u64,
) -> Result<Data> {
    let maps: Vec<&dyn Interpolant> = maps.iter().map(|m| m.as_ref()).collect();
    let sim = mf.simulate(&maps, u, noise_std, seed)?;
    let data = Data::new(u.clone(), sim.y)?;
    Ok(match mf.signals.z {
        Some(_) => data.with_z(sim.z)?,
        None => data,
    })
}

fn read_bytes(path: &Path, fp: &mut Fnv) -> Result<()> {
    let bytes = std::fs::read(path).map_err(|source| structid_io::IoError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    fp.write(&bytes);
    Ok(())
}

/// Which y outputs each block's w channel reaches (through the Markov parameters of T_yw).
fn centred_blocks(mf: &ModelFile) -> Vec<bool> {
    let lft = &mf.lft;
    let n = lft.dims().states;
    let reach: Vec<Vec<bool>> = mf
        .blocks
        .iter()
        .map(|b| {
            let path = lft.t_yw_channel(b.output);
            let markov = path.markov_parameters(n + 1);
            (0..lft.dims().y)
                .map(|j| markov.iter().any(|h| h[(j, 0)] != 0.0))
                .collect()
        })
        .collect();
    (0..reach.len())
        .map(|i| {
            (0..reach.len())
                .any(|k| k != i && reach[i].iter().zip(&reach[k]).any(|(a, b)| *a && *b))
        })
        .collect()
}

fn context(exp: &SweepExperiment, what: &str, p: &SweepPath) -> String {
    format!(
        "experiment `{}`: {what} `{}` (line {})",
        exp.name,
        p.path.display(),
        p.line
    )
}

/// Reads the sweep configuration at `path` and every file it names.
pub fn load(path: &Path) -> Result<Sweep> {
    let file = SweepFile::from_path(path)?;
    let mut inputs = vec![path.to_path_buf()];
    let mut experiments = Vec::with_capacity(file.experiments.len());
    for exp in &file.experiments {
        // The fingerprint covers what the results depend on: the kind of data, the noise levels
        // and the bytes of every file (in a fixed order), not paths or line numbers, so that
        // moving files or editing comments does not invalidate finished cases.
        let mut fp = Fnv::new();
        match &exp.data {
            ExperimentData::Measured { validation, .. } => {
                fp.write(format!("measured|{}", validation.is_some()).as_bytes());
            }
            ExperimentData::Simulated(sim) => fp.write(
                format!(
                    "simulated|{:?}|{:?}|{}",
                    sim.noise_std,
                    sim.validation_noise_std,
                    sim.validation_input.is_some()
                )
                .as_bytes(),
            ),
        }
        let model_path = file.resolve(&exp.model);
        let mf = ModelFile::from_path(&model_path)
            .map_err(|e| WorkflowError::from(e).context(context(exp, "model", &exp.model)))?;
        read_bytes(&model_path, &mut fp)?;
        inputs.push(model_path.clone());
        let base = model_path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        for b in &mf.blocks {
            if let Some(TruthSpec::Table { file: t, .. }) = &b.truth {
                let p = base.join(t);
                read_bytes(&p, &mut fp)?;
                inputs.push(p);
            }
        }
        let truth = mf
            .blocks
            .iter()
            .map(|b| b.truth_map())
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let mut read_table = |what: &str, p: &SweepPath| -> Result<DataTable> {
            let full = file.resolve(p);
            let t = DataTable::read(&full)
                .map_err(|e| WorkflowError::from(e).context(context(exp, what, p)))?;
            read_bytes(&full, &mut fp)?;
            inputs.push(full);
            Ok(t)
        };
        let data = match &exp.data {
            ExperimentData::Measured {
                estimation,
                validation,
            } => {
                let est = read_table("estimation data", estimation)?;
                let est = mf.select_data(&est).map_err(|e| {
                    WorkflowError::from(e).context(context(exp, "estimation data", estimation))
                })?;
                let val = match validation {
                    Some(v) => {
                        let t = read_table("validation data", v)?;
                        Some(mf.select_data(&t).map_err(|e| {
                            WorkflowError::from(e).context(context(exp, "validation data", v))
                        })?)
                    }
                    None => None,
                };
                Source::Measured {
                    estimation: est,
                    validation: val,
                }
            }
            ExperimentData::Simulated(sim) => {
                mf.evaluation_order().map_err(|e| {
                    WorkflowError::from(e).context(format!(
                        "experiment `{}` (line {}): cannot simulate `{}`",
                        exp.name,
                        sim.line,
                        model_path.display()
                    ))
                })?;
                let missing: Vec<String> = mf
                    .blocks
                    .iter()
                    .zip(&truth)
                    .filter(|(_, t)| t.is_none())
                    .map(|(b, _)| format!("`{}`", b.name))
                    .collect();
                if !missing.is_empty() {
                    return Err(WorkflowError::Request(format!(
                        "experiment `{}` (line {}) is simulated, but block(s) {} of `{}` have no `truth`; \
                         simulation needs the true map of every block",
                        exp.name,
                        sim.line,
                        missing.join(", "),
                        model_path.display()
                    )));
                }
                let select_u = |t: DataTable, what: &str, p: &SweepPath| {
                    t.select(&mf.signals.u).map_err(|e| {
                        WorkflowError::from(e).context(format!(
                            "{}: reading the inputs named in [signals].u",
                            context(exp, what, p)
                        ))
                    })
                };
                let t = read_table("input", &sim.input)?;
                let input = select_u(t, "input", &sim.input)?;
                let validation_input = match &sim.validation_input {
                    Some(p) => {
                        let t = read_table("validation input", p)?;
                        Some(select_u(t, "validation input", p)?)
                    }
                    None => None,
                };
                let maps = mf
                    .truth_maps()?
                    .ok_or_else(|| WorkflowError::Failed("a block has no truth map".into()))?;
                Source::Simulated {
                    input,
                    validation_input,
                    noise_std: sim.noise_std,
                    validation_noise_std: sim.validation_noise_std,
                    maps,
                }
            }
        };
        let exp_loaded = Experiment {
            name: exp.name.clone(),
            centred: centred_blocks(&mf),
            outputs: mf.signals.y.clone(),
            has_validation: exp.has_validation(),
            fingerprint: fp.finish(),
            truth,
            model: mf,
            data,
        };
        // A simulated experiment that cannot be simulated fails here, once, not in every case.
        if let Some(seed) = exp.seeds().and_then(|s| s.first()) {
            exp_loaded.records(Some(*seed)).map_err(|e| {
                e.context(format!(
                    "experiment `{}` (line {}): simulating seed {seed}",
                    exp.name, exp.line
                ))
            })?;
        }
        experiments.push(exp_loaded);
    }
    Ok(Sweep {
        file,
        experiments,
        inputs,
    })
}
