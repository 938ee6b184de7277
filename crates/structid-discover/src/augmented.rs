//! The augmented model of a [`Finding`] as files: the model file (`augmented.toml`, with the
//! table of an unnamed map next to it) and the stored estimate (`estimate.json`).
//!
//! The model file carries the map found as its block's `truth` and the dispersion discovery
//! identified it with ([`quadratic_dispersion_spec`], or total variation), so that `structid
//! validate --model` simulates what the report says and `structid identify` re-estimates the
//! map as discovery did. The estimate carries the augmented LFT and map exactly as discovery
//! simulated them, so that `structid validate --estimate` needs neither the model file nor
//! the records.

use std::path::Path;

use structid_core::InitialState;
use structid_core::estimate::{DataFingerprint, Provenance};
use structid_core::{Data, Estimate, Lft, LookupTable, Result};
use structid_io::{
    BlockSpec, DispersionSpec, IoError, LinearSpec, ModelFile, SignalNames, TruthSpec,
};

use crate::discover::{
    AugmentedMap, Classification, Discovery, Finding, initial_state, quadratic_dispersion_spec,
};
use crate::hypotheses::{Nominal, Site};

/// The name of the block added to the nominal model.
pub const BLOCK: &str = "N";
/// The file of an unnamed (or dynamic) map's table, next to the model file.
pub const TABLE_FILE: &str = "N_table.csv";
/// The file of the augmented model as a stored estimate ([`Finding::estimate`]).
pub const ESTIMATE_FILE: &str = "estimate.json";

/// The table of a map kept as a table: its file name and columns `z`, `value`.
#[derive(Clone, Debug, PartialEq)]
pub struct TableFile {
    /// File name, relative to the model file ([`TABLE_FILE`]).
    pub name: String,
    /// Breakpoints.
    pub z: Vec<f64>,
    /// Values.
    pub w: Vec<f64>,
}

/// The file of the table of block `block`'s map, next to the model file: [`TABLE_FILE`] for
/// the block [`BLOCK`], `N2_table.csv` for a second effect's block `N2`, ….
pub fn table_file_name(block: &str) -> String {
    format!("{block}_table.csv")
}

/// The augmented model file of a finding ([`Finding::augmented_file`]).
#[derive(Clone, Debug)]
pub struct AugmentedFile {
    /// The model file (its table, if any, is [`AugmentedFile::table`]).
    pub model: ModelFile,
    /// Its form: `[linear] structure = "…"`, or `[lft]`.
    pub form: String,
    /// The table to write next to it when the new block's map is a table.
    pub table: Option<TableFile>,
    /// The tables of the nominal model's known maps that are tables, to write next to it too
    /// (each renamed [`table_file_name`] of its block).
    pub known_tables: Vec<TableFile>,
    /// The initial state under which it reproduces the report's validation RMS.
    pub initial_state: InitialState,
}

impl AugmentedFile {
    /// The file's text: `header` (comment lines) followed by the model.
    pub fn text(&self, header: &str) -> String {
        let mut text = String::from(header);
        text.push_str(&self.model.to_toml_string());
        text
    }
}

/// The name of an initial-state treatment as `structid validate --initial-state` takes it.
pub fn initial_state_name(s: InitialState) -> &'static str {
    match s {
        InitialState::Zero => "zero",
        InitialState::Estimate => "estimate",
    }
}

/// The augmented model file: the nominal file's signals, the block [`BLOCK`] at `location`
/// with `map` as its truth (a table is given as `table_file`, to be written next to the model
/// file) and `dispersion`, and the linear part as `[linear]` when the nominal file has one and
/// the location is a structure `[linear]` knows, otherwise as the hypothesis' `lft`. Returns
/// the file and its form.
///
/// A nominal file with `[[nonlinearity]]` blocks (known maps) gives an `[lft]` file with the
/// hypothesis' `lft`: the new block first (named `N`, else `N2`, … so that names stay unique,
/// at z row 0 and w column 0), then the nominal file's blocks in their order at rows and
/// columns 1, 2, … with their truth and dispersion (a table truth renamed
/// [`table_file_name`] of its block).
///
/// # Errors
/// A table that is not a valid lookup table, a linear part that has no LFT, a nominal block
/// without a truth.
pub fn model_file(
    nominal_file: &ModelFile,
    location: Site,
    lft: &Lft,
    map: &AugmentedMap,
    dispersion: DispersionSpec,
    table_file: &str,
) -> std::result::Result<(ModelFile, String), IoError> {
    // Output feedback gets a shared numerator, as `structid linear --structure
    // output-feedback` writes it: y = B/F·(u − w), i.e. num = [B, −B].
    let with_maps = !nominal_file.blocks.is_empty();
    let linear = match (&nominal_file.linear, location) {
        _ if with_maps => None,
        (_, Site::Declared { .. }) | (None, _) => None,
        (Some(spec), site) => Some(LinearSpec::from_linear(&spec.model, Some(site))),
    };
    let (lft, form) = match &linear {
        Some(spec) => (
            spec.lft()?,
            format!("[linear] structure = \"{}\"", spec.structure_name()),
        ),
        None => (lft.clone(), "[lft]".to_string()),
    };
    let truth = match map {
        AugmentedMap::Expression(e) => TruthSpec::Expression(e.clone()),
        AugmentedMap::Table { z, w } => TruthSpec::Table {
            file: table_file.to_string(),
            table: LookupTable::one_d(z.clone(), w.clone())?,
        },
    };
    let mf = ModelFile {
        discover: None,
        lft,
        linear,
        signals: SignalNames {
            u: nominal_file.signals.u.clone(),
            y: nominal_file.signals.y.clone(),
            z: None,
        },
        blocks: std::iter::once(BlockSpec {
            name: next_block_name(nominal_file),
            inputs: vec![0],
            output: 0,
            dispersion,
            truth: Some(truth),
            operator: None,
            shape: None,
        })
        .chain(known_blocks(nominal_file)?)
        .collect(),
        path: None,
    };
    Ok((mf, form))
}

/// The name of the block a discovery adds to `nominal_file`: [`BLOCK`], else `N2`, `N3`, …
/// (the rule of [`Nominal::next_block_name`]).
pub fn next_block_name(nominal_file: &ModelFile) -> String {
    let used = |n: &str| nominal_file.blocks.iter().any(|b| b.name == n);
    if !used(BLOCK) {
        return BLOCK.into();
    }
    (2..)
        .map(|i| format!("{BLOCK}{i}"))
        .find(|n| !used(n))
        .unwrap_or_else(|| BLOCK.into())
}

/// The nominal file's blocks as the augmented file carries them: at rows and columns 1, 2, …
/// after the new block, a table truth renamed [`table_file_name`].
fn known_blocks(nominal_file: &ModelFile) -> std::result::Result<Vec<BlockSpec>, IoError> {
    nominal_file
        .blocks
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let truth = match &b.truth {
                Some(TruthSpec::Table { table, .. }) => TruthSpec::Table {
                    file: table_file_name(&b.name),
                    table: table.clone(),
                },
                Some(t) => t.clone(),
                None => {
                    return Err(IoError::InvalidArgument(format!(
                        "block `{}` of the nominal model has no truth: a nominal model's maps \
                         must be known",
                        b.name
                    )));
                }
            };
            Ok(BlockSpec {
                name: b.name.clone(),
                inputs: vec![i + 1],
                output: i + 1,
                dispersion: b.dispersion.clone(),
                truth: Some(truth),
                operator: b.operator.clone(),
                shape: b.shape,
            })
        })
        .collect()
}

impl Finding {
    /// The effect in words, in the physics of its site ([`Classification::describe_at`]); for
    /// a drift found in a probe gain in series with the model
    /// ([`Stationarity::site`](crate::discover::Stationarity::site)), where that gain sits.
    pub fn effect(&self) -> String {
        match (
            &self.classification,
            self.stationarity.as_ref().and_then(|s| s.site),
        ) {
            (Classification::TimeVarying(_), Some(site)) => format!(
                "time-varying: a gain at the {} that drifts over the record (beside the best \
                 static block found)",
                site.name()
            ),
            (c, _) => c.describe_at(self.location),
        }
    }

    /// The augmented model as a model file next to which its table ([`TABLE_FILE`]) is
    /// written: see [`model_file`]. The block's dispersion is the one its map was estimated
    /// with: [`quadratic_dispersion_spec`] at the hypothesis' σ with `trend_degree`
    /// ([`crate::DiscoverSettings::trend_degree`]), or total variation.
    ///
    /// # Errors
    /// As [`model_file`].
    pub fn augmented_file(
        &self,
        nominal_file: &ModelFile,
        trend_degree: usize,
    ) -> std::result::Result<AugmentedFile, IoError> {
        let sigma = self
            .augmented
            .model
            .blocks()
            .first()
            .and_then(|b| b.dispersion.width());
        let dispersion = match sigma {
            Some(_) => quadratic_dispersion_spec(sigma, trend_degree),
            // The map was estimated with total variation, which has no width.
            None => DispersionSpec::TotalVariation {
                neighbours: None,
                interpolation: None,
            },
        };
        // With G re-estimated, the file carries the new G: as `[linear]` where the structure's
        // G is the nominal form (input, output, rate feedback), else as the exact `[lft]`.
        let refined;
        let nominal_file = match &self.nominal_refinement {
            Some(r) if r.adopted => {
                let mut f = nominal_file.clone();
                match (&mut f.linear, self.location) {
                    (Some(spec), Site::Input | Site::Output | Site::RateFeedback) => {
                        spec.model = r.after.clone();
                    }
                    _ => f.linear = None,
                }
                refined = f;
                &refined
            }
            _ => nominal_file,
        };
        let table_name = table_file_name(&next_block_name(nominal_file));
        let (mut model, form) = model_file(
            nominal_file,
            self.location,
            self.augmented.model.lft(),
            &self.augmented.map,
            dispersion,
            &table_name,
        )?;
        // The known maps as the augmented model simulates them: refitted jointly with the new
        // one when they were named by an earlier step.
        for (block, known) in model.blocks.iter_mut().skip(1).zip(&self.augmented.known) {
            if let Some(fit) = &known.fit {
                block.truth = Some(TruthSpec::Expression(fit.expression.clone()));
            }
        }
        let table = match &self.augmented.map {
            AugmentedMap::Table { z, w } => Some(TableFile {
                name: table_name,
                z: z.clone(),
                w: w.clone(),
            }),
            AugmentedMap::Expression(_) => None,
        };
        let known_tables = model
            .blocks
            .iter()
            .skip(1)
            .filter_map(|b| match &b.truth {
                Some(TruthSpec::Table {
                    file,
                    table: LookupTable::OneD { x, v },
                }) => Some(TableFile {
                    name: file.clone(),
                    z: x.clone(),
                    w: v.clone(),
                }),
                _ => None,
            })
            .collect();
        Ok(AugmentedFile {
            model,
            form,
            table,
            known_tables,
            initial_state: initial_state(self.location).1,
        })
    }

    /// The augmented model as a stored estimate (workflow `discover`): the augmented LFT and
    /// its map exactly as discovery simulated them, fingerprinted with the `estimation`
    /// record. Its notes give the location, the effect and the initial state under which it
    /// reproduces the report's validation RMS. No x̂₀ is stored (the map is not fitted jointly
    /// with one).
    ///
    /// # Errors
    /// A map without a stored form (never for an expression or a table).
    pub fn estimate(&self, nominal: &Nominal, estimation: &Data) -> Result<Estimate> {
        let maps = self.augmented.maps()?;
        let map_refs: Vec<&dyn structid_core::Interpolant> =
            maps.iter().map(|m| m.as_ref()).collect();
        let kind = match &self.classification {
            Classification::Named(_) => "named",
            Classification::Unnamed => "unnamed",
            Classification::Dynamic => "dynamic",
            Classification::TimeVarying(_) => "time-varying",
        };
        let notes = vec![
            ("location".to_string(), nominal.key(self.location)),
            ("effect".to_string(), format!("{} ({kind})", self.effect())),
            (
                "initial_state".to_string(),
                initial_state_name(initial_state(self.location).1).to_string(),
            ),
        ];
        Estimate::from_maps(
            &self.augmented.model,
            &map_refs,
            None,
            Provenance {
                workflow: "discover".into(),
                fitted_on: Some(DataFingerprint::of(estimation)),
                notes,
                ..Provenance::default()
            },
        )
    }
}

/// Comment lines at the top of the augmented model file of `d`'s finding `f`: where it comes
/// from (`model_path`, the nominal model file) and where its report is (`report_path`).
pub fn header(
    model_path: &Path,
    report_path: &Path,
    nominal: &Nominal,
    d: &Discovery,
    f: &Finding,
) -> String {
    let what = match &f.classification {
        Classification::Named(fit) => format!("{} (named)", fit.effect.name()),
        other => other.describe(),
    };
    let block = f
        .augmented
        .model
        .blocks()
        .first()
        .map_or(BLOCK, |b| b.name.as_str());
    format!(
        "# Written by discovery: the nominal model `{}` with the block `{block}` {}.\n\
         # Missing effect: {what}; validation RMS {:.6e} (nominal {:.6e}).\n\
         # `{block}`'s truth is the map found; its dispersion is the one discovery identified it with.\n\
         # See {} for the report and how to reproduce it.\n",
        model_path.display(),
        nominal.describe(f.location),
        f.augmented.validation_gap.rms,
        d.validation_gap.rms,
        report_path.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_core::validation::{ValidationSettings, validate};
    use structid_core::{Interpolant, KernelDispersion, Signal};
    use structid_io::DataTable;
    use structid_linear::PolynomialModel;

    fn g() -> PolynomialModel {
        PolynomialModel {
            den: vec![1.0, -1.5, 0.7],
            num: vec![vec![0.0, 0.1, 0.1]],
            sample_time: Some(0.05),
        }
    }

    fn nominal_file() -> ModelFile {
        ModelFile::parse(
            "[linear]\nstructure = \"lti\"\nsample_time = 0.05\nden = [1.0, -1.5, 0.7]\n\
             num = [[0.0, 0.1, 0.1]]\n[signals]\nu = [\"u\"]\ny = [\"y\"]\n",
            None,
        )
        .unwrap()
    }

    /// Reads `path` back and simulates it with its truth map on `val` (columns by the file's
    /// own `[signals]`) as `structid validate --model path` does: the simulation RMS.
    fn simulate_file(
        path: &Path,
        val: &DataTable,
        initial_state: InitialState,
        max_lag: usize,
    ) -> f64 {
        let mf = ModelFile::from_path(path).unwrap();
        let maps = mf.truth_maps().unwrap().unwrap();
        let model = mf.to_model(None, None).unwrap();
        let data = mf.select_data(val).unwrap();
        let refs: Vec<&dyn Interpolant> = maps.iter().map(|m| m.as_ref()).collect();
        let settings = ValidationSettings::builder()
            .initial_state(initial_state)
            .max_lag(max_lag)
            .build()
            .unwrap();
        validate(&model, &refs, &data, &settings).unwrap().rms[0]
    }

    /// A nominal file with a map gives an `[lft]` file with the new block `N2` first and the
    /// nominal block after it, its table truth renamed for its block.
    #[test]
    fn a_nominal_file_with_a_map_keeps_it_after_the_new_block() {
        let mut nominal_mf = ModelFile::parse(
            "[linear]\nstructure = \"input\"\nsample_time = 0.05\nden = [1.0, -1.5, 0.7]\n\
             num = [[0.0, 0.1, 0.1]]\n[signals]\nu = [\"u\"]\ny = [\"y\"]\n\
             [[nonlinearity]]\nname = \"N\"\ninputs = [0]\noutput = 0\n\
             dispersion = { kind = \"polynomial\", degree = 1 }\ntruth = \"z0\"\n",
            None,
        )
        .unwrap();
        let table = LookupTable::one_d(vec![-1.0, 0.0, 1.0], vec![-0.5, 0.0, 0.5]).unwrap();
        nominal_mf.blocks[0].truth = Some(TruthSpec::Table {
            file: "../elsewhere/old.csv".into(),
            table: table.clone(),
        });
        let lft = nominal_mf.lft.clone();
        let (mf, form) = model_file(
            &nominal_mf,
            Site::OutputFeedback,
            &lft,
            &AugmentedMap::Expression("0.2*z0^3".into()),
            quadratic_dispersion_spec(Some(0.3), 3),
            "N2_table.csv",
        )
        .unwrap();
        assert_eq!(form, "[lft]");
        assert!(mf.linear.is_none());
        let names: Vec<&str> = mf.blocks.iter().map(|b| b.name.as_str()).collect();
        assert_eq!(names, ["N2", "N"]);
        assert_eq!(
            (mf.blocks[1].inputs.clone(), mf.blocks[1].output),
            (vec![1], 1)
        );
        assert_eq!(
            mf.blocks[1].truth,
            Some(TruthSpec::Table {
                file: table_file_name("N"),
                table
            })
        );
        assert_eq!(next_block_name(&mf), "N3");
    }

    /// Every location's augmented file, read back, simulates like the hypothesis' LFT it was
    /// written from.
    #[test]
    fn augmented_files_reproduce_the_hypothesis_at_every_location() {
        let nominal_mf = nominal_file();
        let nominal = Nominal::from_polynomial(&g()).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let n = 600;
        let mut s = 0.0;
        let u: Vec<f64> = (0..n)
            .map(|k| {
                s = 0.8 * s + 0.5 * ((k as f64 * 0.37).sin() + (k as f64 * 0.11).cos());
                s
            })
            .collect();
        let truth = |z: f64| 0.3 * z + 0.05 * z * z * z;
        for (location, map) in [
            (
                Site::Input,
                AugmentedMap::Expression("min(max(1.5*z0, -0.8), 0.8)".into()),
            ),
            (
                Site::Output,
                AugmentedMap::Expression("z0 + 0.2*z0^3".into()),
            ),
            (
                Site::OutputFeedback,
                AugmentedMap::Table {
                    z: (0..41).map(|i| -4.0 + 0.2 * i as f64).collect(),
                    w: (0..41).map(|i| truth(-4.0 + 0.2 * i as f64)).collect(),
                },
            ),
            (
                Site::RateFeedback,
                AugmentedMap::Expression("0.01*z0".into()),
            ),
        ] {
            let h = nominal
                .hypothesis(
                    location,
                    std::sync::Arc::new(KernelDispersion::gaussian(0.3).unwrap()),
                )
                .unwrap();
            let interp = map.interpolant().unwrap();
            let us = Signal::from_fn(n, 1, |k, _| u[k]);
            let sim = h.simulate(interp.as_ref(), &us, None).unwrap();
            let y: Vec<f64> = (0..n)
                .map(|k| sim.y.get(k, 0) + 0.01 * ((k * 7919 % 101) as f64 / 50.0 - 1.0))
                .collect();
            let table = DataTable::new(vec!["u".into(), "y".into()], vec![u.clone(), y]).unwrap();
            let data = nominal_mf.select_data(&table).unwrap();
            let data_h = h.data(&data).unwrap();
            let init = initial_state(location).1;
            let expected = validate(
                &h.model,
                &[interp.as_ref()],
                &data_h,
                &ValidationSettings::builder()
                    .initial_state(init)
                    .build()
                    .unwrap(),
            )
            .unwrap()
            .rms[0];
            let (mf, form) = model_file(
                &nominal_mf,
                location,
                h.model.lft(),
                &map,
                quadratic_dispersion_spec(Some(0.3), 3),
                TABLE_FILE,
            )
            .unwrap();
            let expect_linear = !matches!(location, Site::Declared { .. });
            assert_eq!(form.starts_with("[linear]"), expect_linear, "{form}");
            let sub = dir.path().join(nominal.key(location));
            std::fs::create_dir_all(&sub).unwrap();
            if let AugmentedMap::Table { z, w } = &map {
                structid_io::write_csv(
                    &sub.join(TABLE_FILE),
                    &["z", "value"],
                    &[z.clone(), w.clone()],
                )
                .unwrap();
            }
            let path = sub.join("augmented.toml");
            std::fs::write(&path, mf.to_toml_string()).unwrap();
            let rms = simulate_file(&path, &table, init, 25);
            // The file's rate at sample 0 is computed with Ψ at rest (y₋₁ = 0), the
            // hypothesis takes it as 0 (a record rarely starts at y = 0); with x₀ estimated
            // that one sample moves the least-squares x̂₀ by O(1/L). Every other location
            // reproduces to rounding.
            let tolerance = if location == Site::RateFeedback {
                1e-3
            } else {
                1e-9
            };
            assert!(
                (rms - expected).abs() <= tolerance * expected,
                "{location:?}: {rms} vs {expected}"
            );
            let back = ModelFile::from_path(&path).unwrap();
            assert_eq!(back.blocks[0].dispersion.sigma(), Some(0.3));
            assert_eq!(back.blocks[0].dispersion.kind(), "fourier");
        }
    }
}
