//! The files of a discovery (`structid discover`): augmented.toml with the table of an unnamed
//! map and estimate.json, the figures, report.md and report.json; outputs of an earlier run that
//! this one did not write are removed.

use std::path::{Path, PathBuf};

use structid_core::estimate::SignalNames;
use structid_discover::augmented::{self, AugmentedFile, ESTIMATE_FILE, TABLE_FILE};
use structid_discover::discover::{
    DiscoverSettings, Discovery, Effects, Finding, candidate_signals,
};
use structid_discover::hypotheses::Nominal;
use structid_io::{ModelFile, OutputGuard, estimate_json};

use super::figures::{REGION_BINS, before_after_svg, map_svg, regions_svg, residual_svg};
use super::{Record, ReportContext};
use crate::paths::{file_names, json_text};
use crate::{Result, WorkflowError};

/// The tables of blocks `N2` … `N{MAX_TABLE_BLOCKS}` (second and later effects) that an
/// earlier run may have left are removed like the other outputs.
const MAX_TABLE_BLOCKS: usize = 9;

/// Every file a discovery may write, in the order of the summary (and the tables of later
/// effects' blocks, `N2_table.csv`, …).
pub const OUTPUTS: [&str; 9] = [
    "augmented.toml",
    TABLE_FILE,
    ESTIMATE_FILE,
    "report.md",
    "report.json",
    "residual.svg",
    "regions.svg",
    "map.svg",
    "before_after.svg",
];

/// Every file a discovery may write, earlier runs' extra tables included.
pub fn planned_outputs() -> Vec<String> {
    OUTPUTS
        .iter()
        .map(|f| f.to_string())
        .chain(
            (2..=MAX_TABLE_BLOCKS)
                .map(|i| augmented::table_file_name(&format!("{}{i}", augmented::BLOCK))),
        )
        .collect()
}

/// Removes the outputs of an earlier run in `out` that this one did not write (they would
/// contradict the report); returns them.
fn remove_stale(out: &Path, written: &[PathBuf]) -> Vec<PathBuf> {
    let mut removed = Vec::new();
    for f in planned_outputs() {
        let p = out.join(f);
        if p.is_file() && !written.contains(&p) && std::fs::remove_file(&p).is_ok() {
            removed.push(p);
        }
    }
    removed
}

/// The discovery to write and what its files are written from.
#[derive(Clone, Copy, Debug)]
pub struct DiscoveryFiles<'a> {
    /// The nominal model file as given.
    pub model_path: &'a Path,
    /// The output directory.
    pub out: &'a Path,
    /// The command line, for the reports.
    pub command: &'a str,
    /// The model file of the reported step.
    pub model: &'a ModelFile,
    /// The nominal model of the reported step.
    pub nominal: &'a Nominal,
    /// The settings of the discovery.
    pub settings: &'a DiscoverSettings,
    /// The estimation records.
    pub estimation: &'a Record,
    /// The validation records.
    pub validation: &'a Record,
}

/// Writes augmented.toml (and the table of an unnamed map) and estimate.json for the finding
/// `f`.
fn write_augmented(
    r: &DiscoveryFiles<'_>,
    header: &str,
    f: &Finding,
    guard: &OutputGuard,
    written: &mut Vec<PathBuf>,
) -> Result<AugmentedFile> {
    let file = f.augmented_file(r.model, r.settings.trend_degree())?;
    for t in file.table.iter().chain(&file.known_tables) {
        let path = r.out.join(&t.name);
        guard.write_csv(&path, &["z", "value"], &[t.z.clone(), t.w.clone()])?;
        written.push(path);
    }
    let path = r.out.join("augmented.toml");
    guard.write(&path, file.text(header).as_bytes())?;
    written.push(path);
    let stored = f
        .estimate(r.nominal, &r.estimation.data)?
        .with_signal_names(SignalNames {
            u: r.model.signals.u.clone(),
            y: r.model.signals.y.clone(),
        })?;
    let path = r.out.join(ESTIMATE_FILE);
    guard.write(&path, &estimate_json(&stored)?)?;
    written.push(path);
    Ok(file)
}

/// The figures of a discovery (residual.svg, regions.svg, and with a finding map.svg and
/// before_after.svg), each added to `written`; returns each file with its caption.
fn write_figures(
    r: &DiscoveryFiles<'_>,
    guard: &OutputGuard,
    d: &Discovery,
    written: &mut Vec<PathBuf>,
) -> Result<Vec<(String, String)>> {
    let (out, nominal, est) = (r.out, r.nominal, r.estimation);
    let mut figures: Vec<(String, String)> = Vec::new();
    let band = r.settings.gap().band;
    let svg = residual_svg(&d.estimation_gap, band, &est.time)?;
    let path = out.join("residual.svg");
    guard.write(&path, svg.as_bytes())?;
    written.push(path);
    figures.push((
        "residual.svg".into(),
        format!(
            "the nominal model's residual on the estimation record with ±{band}·σ̂ and the \
             windows above it shaded"
        ),
    ));
    let linear =
        structid_discover::records::stacked(&est.data, |r| nominal.simulate_output(r.u()))?;
    let mut candidates = candidate_signals(
        &est.data,
        &linear,
        nominal.lft().sample_time().unwrap_or(1.0),
    );
    candidates.extend(nominal.state_signals(&est.data)?);
    let path = out.join("regions.svg");
    guard.write(
        &path,
        regions_svg(&d.estimation_gap.residual, &candidates)?.as_bytes(),
    )?;
    written.push(path);
    figures.push((
        "regions.svg".into(),
        format!(
            "the residual binned by each candidate signal ({REGION_BINS} quantile bins: mean and \
             RMS), estimation record"
        ),
    ));
    if let Some(f) = &d.finding {
        if let Some(h) = Some(&f.hypothesis).filter(|h| !h.curve.z.is_empty()) {
            let path = out.join("map.svg");
            guard.write(&path, map_svg(nominal, h, f)?.as_bytes())?;
            written.push(path);
            figures.push((
                "map.svg".into(),
                "the best hypothesis' nonparametric map with its ±2σ band and points, and the \
                 map of the augmented model"
                    .into(),
            ));
        }
        let path = out.join("before_after.svg");
        let svg = before_after_svg(
            r.validation,
            &d.validation_gap,
            &f.augmented.validation_gap,
            f.shrink,
        )?;
        guard.write(&path, svg.as_bytes())?;
        written.push(path);
        figures.push((
            "before_after.svg".into(),
            "validation record: measured y, the nominal and the augmented simulation, and their \
             residuals"
                .into(),
        ));
    }
    Ok(figures)
}

/// Writes the files of the discovery `d` (with several effects, `effects` lists every step)
/// as one result set in `r.out`, and removes the outputs of an earlier run that this one did
/// not write. Returns the summary to print.
pub fn write_discovery(
    r: &DiscoveryFiles<'_>,
    guard: &OutputGuard,
    d: &Discovery,
    effects: Option<&Effects>,
    started: std::time::Instant,
) -> Result<String> {
    // The gap's lags, as discovery sets them.
    let max_lag = r
        .settings
        .gap()
        .max_lag
        .min(structid_discover::records::shortest(&r.estimation.data) / 4)
        .max(1);
    guard.begin_set(r.out, Some(&planned_outputs()))?;
    let mut written_files: Vec<PathBuf> = Vec::new();
    let written = match &d.finding {
        Some(f) => {
            let header = augmented::header(r.model_path, &r.out.join("report.md"), r.nominal, d, f);
            Some(write_augmented(r, &header, f, guard, &mut written_files)?)
        }
        None => None,
    };
    let figures = write_figures(r, guard, d, &mut written_files)?;

    // Reports.
    let context = ReportContext {
        version: env!("CARGO_PKG_VERSION"),
        run: r,
        augmented: written.as_ref(),
        figures: &figures,
        max_lag,
    };
    let md_path = r.out.join("report.md");
    let mut markdown = super::markdown(d, &context);
    if let Some(effects) = effects {
        // The iteration's section right after the title and before the reported step's.
        let at = markdown.find("\n\n").map_or(0, |i| i + 2);
        markdown.insert_str(at, &super::effects_markdown(effects));
    }
    guard.write(&md_path, markdown.as_bytes())?;
    written_files.push(md_path);
    let json_path = r.out.join("report.json");
    written_files.push(json_path.clone());
    let files = file_names(&written_files);
    let serialise =
        |e: serde_json::Error| WorkflowError::Failed(format!("cannot serialise the report: {e}"));
    let mut value = super::json(d, &context, &files).map_err(serialise)?;
    if let (Some(effects), Some(object)) = (effects, value.as_object_mut()) {
        object.insert(
            "effects".into(),
            super::effects_json(effects).map_err(serialise)?,
        );
    }
    guard.write(&json_path, json_text(&value)?.as_bytes())?;

    // Outputs of an earlier run that this one did not write would contradict the report.
    let removed = remove_stale(r.out, &written_files);
    guard.finish_set(r.out, &structid_io::output::file_names(&written_files))?;

    let mut s = effects.map(super::effects_summary).unwrap_or_default();
    s.push_str(&super::summary(
        d,
        &context,
        &written_files,
        &removed,
        started.elapsed().as_secs_f64(),
    ));
    Ok(s)
}

/// The warning when a validation file is also an estimation file: ranking and naming on a
/// record the maps were estimated on favour whatever overfits.
pub fn validation_is_estimation(data: &[PathBuf], validation: &[PathBuf]) -> Option<&'static str> {
    let canonical = |p: &PathBuf| std::fs::canonicalize(p).ok();
    validation
        .iter()
        .any(|v| data.iter().any(|d| canonical(d) == canonical(v)))
        .then_some(
            "a validation data file is also an estimation data file: the hypotheses are ranked and \
             the effect is named on a record they were estimated on, which favours whatever \
             overfits; give a separate validation record",
        )
}
