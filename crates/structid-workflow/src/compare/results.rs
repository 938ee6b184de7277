//! Case files and the result tables (`results.csv`, `results.md`) built from them.
//!
//! Everything the tables and figures show is in the case files, so a directory of case files
//! (one run, or shards merged) determines its tables and figures completely.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use structid_io::{OutputGuard, format_number};

use crate::error::{Result, WorkflowError};
use crate::text::short;
use structid_core::selection::Trial;

/// Identifies case files of this version.
pub const CASE_FORMAT: &str = "structid-compare-case/1";

/// The case file folder inside an output directory.
pub const CASES_DIR: &str = "cases";

/// Numbers that may be missing: non-finite values are written as `null` and read back as NaN,
/// so that a case with a diverged estimate still has a complete (parseable) file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Values(pub Vec<f64>);

impl Serialize for Values {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_seq(self.0.iter().map(|v| v.is_finite().then_some(*v)))
    }
}

impl<'de> Deserialize<'de> for Values {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let v: Vec<Option<f64>> = Vec::deserialize(d)?;
        Ok(Values(
            v.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect(),
        ))
    }
}

/// `Some(v)` for a finite `v`.
pub fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// One finished case: every number of its table row plus what the figures need.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CaseRecord {
    /// [`CASE_FORMAT`].
    pub format: String,
    /// The case id.
    pub id: String,
    /// Position in the full case list.
    pub index: usize,
    /// Length of the full case list.
    pub case_count: usize,
    /// Fingerprint of the full case list (equal for all shards of a sweep).
    pub case_list: String,
    /// Fingerprint of the case's settings and input files (to refuse resuming a changed sweep).
    pub fingerprint: String,
    /// Experiment name.
    pub experiment: String,
    /// Dispersion name.
    pub dispersion: String,
    /// The β of the configuration: a number or `auto`.
    pub beta_setting: String,
    /// The noise seed (simulated experiments).
    pub seed: Option<u64>,
    /// `fixed`, or how β was chosen: `ml`, `gcv`, `cv`, `validation`.
    pub selection: String,
    /// The β used (chosen, for `auto`).
    pub beta: Option<f64>,
    /// One entry per block, in model order.
    pub blocks: Vec<BlockRecord>,
    /// One entry per measured output when the experiment has validation data.
    pub validation: Vec<OutputRecord>,
    /// Cost terms at the optimum.
    pub cost: Option<CostRecord>,
    /// The solver used (or requested, when the case failed before solving).
    pub solver: String,
    /// Wall-clock time of the case in seconds.
    pub seconds: f64,
    /// `ok` or `error: <message>`.
    pub status: String,
    /// The automatic selection's trials (β, σ, criterion), empty for fixed β.
    pub selection_curve: Vec<Trial>,
    /// The noise variance implied by the selection, when it gives one.
    pub noise_variance: Option<f64>,
}

/// The estimate of one block in a case.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlockRecord {
    /// Block name.
    pub name: String,
    /// Whether the error is centred (another block feeds the same output).
    pub centred: bool,
    /// Whether the model file gives the true map.
    pub has_truth: bool,
    /// RMS error of ŵ against the truth at the data points (centred when `centred`).
    pub rms_error: Option<f64>,
    /// The kernel width used, for dispersions that have one.
    pub sigma: Option<f64>,
    /// The map on a grid, for blocks with one input.
    pub grid: Option<GridRecord>,
}

/// An estimated one-input map on a plotting grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridRecord {
    /// Grid points over the range of the block's input in the estimation data.
    pub z: Values,
    /// N̂ on the grid.
    pub estimate: Values,
    /// Posterior standard deviation of N̂ on the grid, when available.
    pub std: Option<Values>,
    /// The true map on the grid, when known.
    pub truth: Option<Values>,
    /// Mean of ŵ over the data points (subtracted when the block is centred).
    pub estimate_mean: f64,
    /// Mean of the true map over the data points.
    pub truth_mean: Option<f64>,
}

/// Validation of one output.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputRecord {
    /// Output (y column) name.
    pub name: String,
    /// RMS of y − y_sim.
    pub rms: Option<f64>,
    /// Fit in percent.
    pub fit_percent: Option<f64>,
}

/// Cost terms of eq. (4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CostRecord {
    /// (1/L)·Σ|ê|².
    pub noise: f64,
    /// Σ_i D_i (without β).
    pub dispersion: f64,
    /// J = noise + β·Σ D_i.
    pub total: f64,
}

impl CaseRecord {
    /// Whether the case succeeded.
    pub fn is_ok(&self) -> bool {
        self.status == "ok"
    }

    /// The JSON of the case file.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self)
            .map(|s| s + "\n")
            .map_err(|e| WorkflowError::Failed(format!("cannot serialise a case: {e}")))
    }

    /// The JSON without the run time, for comparing two runs of the same case.
    pub fn content_without_time(&self) -> String {
        let mut r = self.clone();
        r.seconds = 0.0;
        serde_json::to_string(&r).unwrap_or_default()
    }
}

/// Reads a case file; `None` when it is missing, incomplete or not a case file of this version.
pub fn read_case(path: &Path) -> Option<CaseRecord> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str::<CaseRecord>(&text)
        .ok()
        .filter(|r| r.format == CASE_FORMAT)
}

/// The `*.json` files of `dir/cases`, sorted by name.
pub fn case_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let cases = dir.join(CASES_DIR);
    if !cases.is_dir() {
        return Ok(Vec::new());
    }
    let entries = std::fs::read_dir(&cases)
        .map_err(|e| WorkflowError::Failed(format!("cannot list `{}`: {e}", cases.display())))?;
    let mut out: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|x| x == "json")
                && p.file_name()
                    .is_some_and(|n| !n.to_string_lossy().starts_with('.'))
        })
        .collect();
    out.sort();
    Ok(out)
}

// ---------------------------------------------------------------------------------------------
// Tables

/// A table cell.
#[derive(Clone, Debug, PartialEq)]
enum Cell {
    Text(String),
    Number(Option<f64>),
    /// Run time: 3 decimals in both tables.
    Seconds(f64),
}

impl Cell {
    fn csv(&self) -> String {
        match self {
            Cell::Text(s) => s.clone(),
            Cell::Number(Some(v)) => format_number(*v),
            Cell::Number(None) => String::new(),
            Cell::Seconds(s) => format!("{s:.3}"),
        }
    }

    fn markdown(&self) -> String {
        match self {
            Cell::Text(s) => s.replace('|', "\\|").replace(['\n', '\r'], " "),
            Cell::Number(Some(v)) => short(*v),
            Cell::Number(None) => String::new(),
            Cell::Seconds(s) => format!("{s:.3}"),
        }
    }
}

/// A column: its CSV name, its Markdown heading and how to read it from a record.
struct Column {
    csv: String,
    markdown: String,
    cell: Box<dyn Fn(&CaseRecord) -> Cell>,
}

fn column(
    csv: impl Into<String>,
    markdown: impl Into<String>,
    cell: impl Fn(&CaseRecord) -> Cell + 'static,
) -> Column {
    Column {
        csv: csv.into(),
        markdown: markdown.into(),
        cell: Box::new(cell),
    }
}

/// σ of a case: one value when the blocks share it, otherwise the per-block values joined by `;`.
fn sigma_text(r: &CaseRecord) -> String {
    let s: Vec<f64> = r.blocks.iter().filter_map(|b| b.sigma).collect();
    match s.first() {
        None => String::new(),
        Some(first) if s.iter().all(|v| v == first) => format_number(*first),
        Some(_) => s
            .iter()
            .map(|v| format_number(*v))
            .collect::<Vec<_>>()
            .join(";"),
    }
}

/// The columns for `records`: fixed ones, then one error column per block with a truth and one
/// RMS and one fit column per validated output, in order of first appearance.
fn columns(records: &[&CaseRecord]) -> Vec<Column> {
    let mut cols = vec![
        column("case", "case", |r| Cell::Text(r.id.clone())),
        column("experiment", "experiment", |r| {
            Cell::Text(r.experiment.clone())
        }),
        column("dispersion", "dispersion", |r| {
            Cell::Text(r.dispersion.clone())
        }),
        column("seed", "seed", |r| {
            Cell::Text(r.seed.map(|s| s.to_string()).unwrap_or_default())
        }),
        column("beta", "β", |r| Cell::Number(r.beta)),
        column("sigma", "σ", |r| Cell::Text(sigma_text(r))),
        column("selection", "selection", |r| {
            Cell::Text(r.selection.clone())
        }),
    ];
    let mut maps: Vec<(String, bool)> = Vec::new();
    let mut outputs: Vec<String> = Vec::new();
    for r in records {
        for b in r.blocks.iter().filter(|b| b.has_truth) {
            if !maps.contains(&(b.name.clone(), b.centred)) {
                maps.push((b.name.clone(), b.centred));
            }
        }
        for o in &r.validation {
            if !outputs.contains(&o.name) {
                outputs.push(o.name.clone());
            }
        }
    }
    for (name, centred) in maps {
        let (csv, md) = if centred {
            (
                format!("map_rms_centred_{name}"),
                format!("RMS {name} (centred)"),
            )
        } else {
            (format!("map_rms_{name}"), format!("RMS {name}"))
        };
        cols.push(column(csv, md, move |r| {
            Cell::Number(
                r.blocks
                    .iter()
                    .find(|b| b.name == name && b.centred == centred && b.has_truth)
                    .and_then(|b| b.rms_error),
            )
        }));
    }
    // validation RMS, then fit %, one column per output
    type Metric = fn(&OutputRecord) -> Option<f64>;
    let metrics: [(&str, &str, Metric); 2] = [
        ("val_rms", "val. RMS", |o| o.rms),
        ("val_fit", "val. fit", |o| o.fit_percent),
    ];
    for (key, label, get) in metrics {
        for name in &outputs {
            let n = name.clone();
            let unit = if key == "val_fit" { " [%]" } else { "" };
            cols.push(column(
                format!("{key}_{name}"),
                format!("{label} {name}{unit}"),
                move |r| Cell::Number(r.validation.iter().find(|o| o.name == n).and_then(get)),
            ));
        }
    }
    cols.extend([
        column("cost_noise", "noise term", |r| {
            Cell::Number(r.cost.as_ref().map(|c| c.noise))
        }),
        column("cost_dispersion", "Σ D", |r| {
            Cell::Number(r.cost.as_ref().map(|c| c.dispersion))
        }),
        column("cost_total", "J", |r| {
            Cell::Number(r.cost.as_ref().map(|c| c.total))
        }),
        column("solver", "solver", |r| Cell::Text(r.solver.clone())),
        column("run_time_s", "time [s]", |r| Cell::Seconds(r.seconds)),
        column("status", "status", |r| Cell::Text(r.status.clone())),
    ]);
    cols
}

/// `results.csv`: one row per case in case-list order.
pub fn results_csv(records: &[&CaseRecord]) -> Result<Vec<u8>> {
    let cols = columns(records);
    let mut w = csv::Writer::from_writer(Vec::new());
    let err = |e: csv::Error| WorkflowError::Failed(format!("cannot format results.csv: {e}"));
    w.write_record(cols.iter().map(|c| c.csv.as_str()))
        .map_err(err)?;
    for r in records {
        w.write_record(cols.iter().map(|c| (c.cell)(r).csv()))
            .map_err(err)?;
    }
    w.into_inner()
        .map_err(|e| WorkflowError::Failed(format!("cannot format results.csv: {e}")))
}

fn md_row(cells: impl IntoIterator<Item = String>) -> String {
    let mut s = String::from("|");
    for c in cells {
        s.push(' ');
        s.push_str(&c);
        s.push_str(" |");
    }
    s.push('\n');
    s
}

fn md_table(header: &[String], rows: &[Vec<String>]) -> String {
    let mut s = md_row(header.iter().cloned());
    s.push_str(&md_row(header.iter().map(|_| "---".to_string())));
    for r in rows {
        s.push_str(&md_row(r.iter().cloned()));
    }
    s
}

/// Mean ± sample standard deviation (just the mean for one value, empty for none).
pub fn mean_std(values: &[f64]) -> String {
    match values.len() {
        0 => String::new(),
        1 => short(values[0]),
        n => {
            let m = values.iter().sum::<f64>() / n as f64;
            let var = values.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (n - 1) as f64;
            format!("{} ± {}", short(m), short(var.sqrt()))
        }
    }
}

/// The summary of one experiment: per dispersion and β setting, mean ± std over seeds of each
/// map's RMS error and each output's validation fit.
fn summary(experiment: &str, records: &[&CaseRecord]) -> String {
    let recs: Vec<&CaseRecord> = records
        .iter()
        .copied()
        .filter(|r| r.experiment == experiment)
        .collect();
    let mut maps: Vec<(String, bool)> = Vec::new();
    let mut outputs: Vec<String> = Vec::new();
    let mut groups: Vec<(String, String)> = Vec::new();
    for r in &recs {
        for b in r.blocks.iter().filter(|b| b.has_truth) {
            if !maps.contains(&(b.name.clone(), b.centred)) {
                maps.push((b.name.clone(), b.centred));
            }
        }
        for o in &r.validation {
            if !outputs.contains(&o.name) {
                outputs.push(o.name.clone());
            }
        }
        let g = (r.dispersion.clone(), r.beta_setting.clone());
        if !groups.contains(&g) {
            groups.push(g);
        }
    }
    let mut header: Vec<String> = ["dispersion", "β", "ok / cases", "β chosen"]
        .into_iter()
        .map(String::from)
        .collect();
    for (name, centred) in &maps {
        header.push(if *centred {
            format!("RMS {name} (centred)")
        } else {
            format!("RMS {name}")
        });
    }
    for o in &outputs {
        header.push(format!("val. fit {o} [%]"));
    }
    let mut rows = Vec::new();
    for (disp, beta) in &groups {
        let g: Vec<&CaseRecord> = recs
            .iter()
            .copied()
            .filter(|r| &r.dispersion == disp && &r.beta_setting == beta)
            .collect();
        let ok: Vec<&CaseRecord> = g.iter().copied().filter(|r| r.is_ok()).collect();
        let mut row = vec![
            disp.clone(),
            match g.first() {
                Some(r) if beta == "auto" => format!("auto ({})", r.selection),
                _ => beta.clone(),
            },
            format!("{} / {}", ok.len(), g.len()),
            if beta == "auto" {
                mean_std(&ok.iter().filter_map(|r| r.beta).collect::<Vec<_>>())
            } else {
                String::new()
            },
        ];
        for (name, centred) in &maps {
            let v: Vec<f64> = ok
                .iter()
                .filter_map(|r| {
                    r.blocks
                        .iter()
                        .find(|b| &b.name == name && b.centred == *centred)
                        .and_then(|b| b.rms_error)
                })
                .collect();
            row.push(mean_std(&v));
        }
        for o in &outputs {
            let v: Vec<f64> = ok
                .iter()
                .filter_map(|r| {
                    r.validation
                        .iter()
                        .find(|x| &x.name == o)
                        .and_then(|x| x.fit_percent)
                })
                .collect();
            row.push(mean_std(&v));
        }
        rows.push(row);
    }
    md_table(&header, &rows)
}

/// `results.md`: the full table and a summary per experiment.
pub fn results_md(records: &[&CaseRecord], total_cases: usize) -> String {
    let cols = columns(records);
    let mut s = String::from("# structid compare: results\n\n");
    let ok = records.iter().filter(|r| r.is_ok()).count();
    let _ = writeln!(
        s,
        "{} of {total_cases} cases in this directory, {ok} succeeded. RMS: error of the estimated map \
         against the truth at the data points (centred: each side's mean removed, for maps that share \
         an output with another map); val.: simulation of the validation record from rest.\n",
        records.len()
    );
    s.push_str("## Summary (mean ± standard deviation over seeds, successful cases)\n\n");
    let mut experiments: Vec<&str> = Vec::new();
    for r in records {
        if !experiments.contains(&r.experiment.as_str()) {
            experiments.push(&r.experiment);
        }
    }
    for e in experiments {
        let _ = writeln!(s, "### {e}\n");
        s.push_str(&summary(e, records));
        s.push('\n');
    }
    s.push_str("## All cases\n\n");
    let header: Vec<String> = cols.iter().map(|c| c.markdown.clone()).collect();
    let rows: Vec<Vec<String>> = records
        .iter()
        .map(|r| cols.iter().map(|c| (c.cell)(r).markdown()).collect())
        .collect();
    s.push_str(&md_table(&header, &rows));
    s
}

/// Writes `results.csv` and `results.md` for `records` (any order) atomically into `dir`.
pub fn write_tables(
    guard: &OutputGuard,
    dir: &Path,
    records: &BTreeMap<usize, CaseRecord>,
    total_cases: usize,
) -> Result<()> {
    let recs: Vec<&CaseRecord> = records.values().collect();
    guard.write(&dir.join("results.csv"), &results_csv(&recs)?)?;
    guard.write(
        &dir.join("results.md"),
        results_md(&recs, total_cases).as_bytes(),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(index: usize, exp: &str, disp: &str, beta: &str, seed: Option<u64>) -> CaseRecord {
        CaseRecord {
            format: CASE_FORMAT.into(),
            id: format!("{exp}/{disp}/beta={beta}"),
            index,
            case_count: 4,
            case_list: "0".into(),
            fingerprint: "0".into(),
            experiment: exp.into(),
            dispersion: disp.into(),
            beta_setting: beta.into(),
            seed,
            selection: if beta == "auto" { "ml" } else { "fixed" }.into(),
            beta: Some(if beta == "auto" {
                0.0123
            } else {
                beta.parse().unwrap()
            }),
            blocks: vec![
                BlockRecord {
                    name: "f".into(),
                    centred: true,
                    has_truth: true,
                    rms_error: Some(0.1 + index as f64 * 0.01),
                    sigma: Some(0.1),
                    grid: None,
                },
                BlockRecord {
                    name: "g".into(),
                    centred: true,
                    has_truth: false,
                    rms_error: None,
                    sigma: Some(0.2),
                    grid: None,
                },
            ],
            validation: vec![OutputRecord {
                name: "y".into(),
                rms: Some(0.5),
                fit_percent: Some(90.0 + index as f64),
            }],
            cost: Some(CostRecord {
                noise: 1.0,
                dispersion: 2.0,
                total: 1.02,
            }),
            solver: "exact".into(),
            seconds: 0.25,
            status: "ok".into(),
            selection_curve: Vec::new(),
            noise_variance: None,
        }
    }

    #[test]
    fn csv_has_one_row_per_case_and_the_expected_columns() {
        let mut a = record(0, "spray", "gauss", "0.01", Some(3));
        let b = record(1, "spray", "gauss", "auto", Some(3));
        a.status = "error: M is not \"positive\", definite".into();
        a.cost = None;
        let csv = String::from_utf8(results_csv(&[&a, &b]).unwrap()).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(
            lines[0],
            "case,experiment,dispersion,seed,beta,sigma,selection,map_rms_centred_f,val_rms_y,val_fit_y,\
             cost_noise,cost_dispersion,cost_total,solver,run_time_s,status"
        );
        assert_eq!(lines.len(), 3);
        // σ differs between blocks; the error message is quoted, costs are empty.
        assert_eq!(
            lines[1],
            "spray/gauss/beta=0.01,spray,gauss,3,0.01,0.1;0.2,fixed,0.1,0.5,90.0,,,,exact,0.250,\
             \"error: M is not \"\"positive\"\", definite\""
        );
        assert!(lines[2].starts_with("spray/gauss/beta=auto,spray,gauss,3,0.0123,"));
    }

    #[test]
    fn markdown_escapes_and_summarises() {
        let mut a = record(0, "spray", "gauss", "0.01", Some(1));
        a.status = "error: a | b".into();
        let b = record(1, "spray", "gauss", "auto", Some(1));
        let c = record(2, "spray", "gauss", "auto", Some(2));
        let md = results_md(&[&a, &b, &c], 4);
        assert!(
            md.contains("3 of 4 cases in this directory, 2 succeeded"),
            "{md}"
        );
        assert!(md.contains("error: a \\| b"), "{md}");
        // Summary: the auto group over seeds 1 and 2 (fit 91 and 92), the failed fixed case.
        assert!(
            md.contains(
                "| gauss | auto (ml) | 2 / 2 | 0.0123 ± 0 | 0.115 ± 0.007071 | 91.5 ± 0.7071 |"
            ),
            "{md}"
        );
        assert!(md.contains("| gauss | 0.01 | 0 / 1 |  |  |  |"), "{md}");
        // Every markdown row has as many cells as the header.
        let all = md.split("## All cases").nth(1).unwrap();
        let counts: Vec<usize> = all
            .lines()
            .filter(|l| l.starts_with('|'))
            .map(|l| l.matches(" |").count())
            .collect();
        assert!(counts.iter().all(|&n| n == counts[0]), "{counts:?}");
    }

    #[test]
    fn short_numbers() {
        assert_eq!(short(0.0), "0");
        assert_eq!(short(0.012345), "0.01235");
        assert_eq!(short(123.0), "123");
        assert_eq!(short(1.5e-7), "1.5e-7");
        assert_eq!(short(-2.0e6), "-2e6");
        assert_eq!(mean_std(&[]), "");
        assert_eq!(mean_std(&[2.0]), "2");
        assert_eq!(mean_std(&[1.0, 3.0]), "2 ± 1.414");
    }

    #[test]
    fn values_survive_non_finite_numbers() {
        let v = Values(vec![1.0, f64::NAN, f64::INFINITY]);
        let s = serde_json::to_string(&v).unwrap();
        assert_eq!(s, "[1.0,null,null]");
        let back: Values = serde_json::from_str(&s).unwrap();
        assert_eq!(back.0[0], 1.0);
        assert!(back.0[1].is_nan() && back.0[2].is_nan());
    }
}
