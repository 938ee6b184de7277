//! The reports of a discovery: `report.md` ([`markdown`]), `report.json` ([`json()`]) and the
//! summary a run prints ([`summary`]), with the records they describe ([`Record`]).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use structid_core::Data;
use structid_io::{DataTable, IoError, ModelFile, format_number};

use structid_core::validation::Scoring;

use crate::augmented::{AugmentedFile, BLOCK, ESTIMATE_FILE, initial_state_name};
use crate::discover::{
    AugmentedMap, Classification, DiscoverSettings, Discovery, Effects, Finding, initial_state,
    rms_text,
};
use crate::effects::EffectFit;
use crate::gap::Gap;
use crate::hypotheses::{Location, Nominal};

/// Rows of the window table in report.md per record.
const MAX_WINDOW_ROWS: usize = 20;

/// The time axis of a record: a `time` (or `t`) column, the model's sample time, or the sample
/// index.
#[derive(Clone, Debug)]
pub struct TimeAxis {
    /// The time (or sample index) of each sample.
    pub values: Vec<f64>,
    /// The axis label: `time`, `time [s]` or `sample`.
    pub label: &'static str,
    /// Whether the values are times (not sample indices).
    pub is_time: bool,
}

impl TimeAxis {
    /// The time axis of a record of `len` samples read as `table`, from a model with
    /// `sample_time`.
    pub fn new(table: &DataTable, len: usize, sample_time: Option<f64>) -> Self {
        for name in ["time", "t"] {
            if let Some(c) = table.column(name)
                && c.len() == len
            {
                return Self {
                    values: c.to_vec(),
                    label: "time",
                    is_time: true,
                };
            }
        }
        match sample_time {
            Some(ts) => Self {
                values: (0..len).map(|k| k as f64 * ts).collect(),
                label: "time [s]",
                is_time: true,
            },
            None => Self {
                values: (0..len).map(|k| k as f64).collect(),
                label: "sample",
                is_time: false,
            },
        }
    }

    /// The time of sample `k` (NaN past the end).
    pub fn at(&self, k: usize) -> f64 {
        self.values.get(k).copied().unwrap_or(f64::NAN)
    }
}

/// The time axes of several records one after the other: each record's axis shifted to start
/// one of its own steps after the end of the one before, so that figures run forward.
fn continued<'a>(axes: impl Iterator<Item = &'a [f64]>) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for axis in axes {
        let step = match axis {
            [a, b, ..] => b - a,
            _ => 1.0,
        };
        let shift = match (out.last(), axis.first()) {
            (Some(end), Some(start)) => end + step - start,
            _ => 0.0,
        };
        out.extend(axis.iter().map(|t| t + shift));
    }
    out
}

/// One record as read, or several ([`Record::join`]).
#[derive(Clone, Debug)]
pub struct Record {
    /// The file as given (the first, for several records).
    pub path: PathBuf,
    /// Every file, one per record of `data`.
    pub paths: Vec<PathBuf>,
    /// Its columns.
    pub table: DataTable,
    /// The columns the model file's `[signals]` name.
    pub data: Data,
    /// Its time axis.
    pub time: TimeAxis,
}

impl Record {
    /// Reads the record at `path` with the columns `mf`'s `[signals]` name.
    ///
    /// # Errors
    /// An unreadable or malformed file, missing columns.
    pub fn read(mf: &ModelFile, path: &Path) -> Result<Self, IoError> {
        let table = DataTable::read(path)?;
        let data = mf.select_data(&table)?;
        let time = TimeAxis::new(&table, data.len(), mf.lft.sample_time());
        Ok(Self {
            path: path.to_path_buf(),
            paths: vec![path.to_path_buf()],
            table,
            data,
            time,
        })
    }

    /// Records read one per file as one [`Record`] of several records
    /// ([`Data::from_records`]): `data` and `time` stacked in the files' order (each record's
    /// time axis shifted to continue the one before, for the figures), `table` the first
    /// file's. One record is returned as it is.
    ///
    /// # Errors
    /// No record, or records whose channels differ.
    pub fn join(records: Vec<Record>) -> structid_core::Result<Self> {
        let mut records = records;
        if records.len() == 1 {
            return Ok(records.pop().expect("one record"));
        }
        let first = records.first().ok_or_else(|| {
            structid_core::Error::InvalidStructure("no data record was given".into())
        })?;
        let (path, table, time) = (first.path.clone(), first.table.clone(), &first.time);
        let (label, is_time) = (time.label, time.is_time);
        let data = Data::from_records(records.iter().map(|r| r.data.clone()).collect())?;
        Ok(Self {
            path,
            paths: records.iter().flat_map(|r| r.paths.clone()).collect(),
            table,
            data,
            time: TimeAxis {
                values: continued(records.iter().map(|r| r.time.values.as_slice())),
                label,
                is_time,
            },
        })
    }

    /// The files, as a command line gives them: `FLAG a.csv FLAG b.csv …` (without the first
    /// flag).
    pub fn files(&self, flag: &str) -> String {
        self.paths
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(&format!(" {flag} "))
    }

    /// The files for a sentence: `a.csv` or `a.csv`, `b.csv` (2 records).
    fn names(&self) -> String {
        let names: Vec<String> = self
            .paths
            .iter()
            .map(|p| format!("`{}`", p.display()))
            .collect();
        if names.len() == 1 {
            names[0].clone()
        } else {
            format!("{} ({} records)", names.join(", "), names.len())
        }
    }
}

// report.md

fn e(v: f64) -> String {
    crate::discover::rms_text(v)
}

fn pct(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.1} %")
    } else {
        "—".into()
    }
}

fn g4(v: f64) -> String {
    if !v.is_finite() {
        return e(v);
    }
    if v == 0.0 || (1e-3..1e5).contains(&v.abs()) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

/// `|`-safe text for a Markdown table cell.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// A location as reports name it: its key and what it means.
pub fn location_text(nominal: &Nominal, l: Location) -> String {
    format!("`{}` ({})", nominal.key(l), nominal.describe(l))
}

fn gap_table(s: &mut String, estimation: &Gap, validation: &Gap) {
    let _ = writeln!(s, "| | estimation record | validation record |");
    let _ = writeln!(s, "|---|---|---|");
    let _ = writeln!(
        s,
        "| simulation RMS of y − ŷ | {} | {} |",
        e(estimation.rms),
        e(validation.rms)
    );
    if estimation.records.len() > 1 || validation.records.len() > 1 {
        let each = |g: &Gap| {
            g.records
                .iter()
                .enumerate()
                .map(|(i, r)| format!("{}: {}", i + 1, e(r.rms)))
                .collect::<Vec<_>>()
                .join("; ")
        };
        let _ = writeln!(
            s,
            "| simulation RMS per record | {} | {} |",
            each(estimation),
            each(validation)
        );
    }
    let _ = writeln!(
        s,
        "| one-step prediction RMS of ε | {} | {} |",
        e(estimation.prediction_rms),
        e(validation.prediction_rms)
    );
    let _ = writeln!(
        s,
        "| fit | {} | {} |",
        pct(estimation.fit_percent),
        pct(validation.fit_percent)
    );
    let _ = writeln!(
        s,
        "| model-free noise level of ε (MAD of Δε) | {} | {} |",
        e(estimation.noise_std),
        e(validation.noise_std)
    );
    let _ = writeln!(
        s,
        "| noise level of y − ŷ (semivariogram, coloured) | {} | {} |",
        e(estimation.noise.std),
        e(validation.noise.std)
    );
    let _ = writeln!(
        s,
        "| RMS(ε) / MAD-based level | {:.2} | {:.2} |",
        estimation.prediction_rms / estimation.noise_std.max(f64::MIN_POSITIVE),
        validation.prediction_rms / validation.noise_std.max(f64::MIN_POSITIVE)
    );
    let _ = writeln!(
        s,
        "| missing effect | {} | {} |",
        if estimation.missing_effect {
            "yes"
        } else {
            "no"
        },
        if validation.missing_effect {
            "yes"
        } else {
            "no"
        }
    );
    s.push('\n');
    let _ = writeln!(
        s,
        "Portmanteau tests (the family at the 0.1 % level, Bonferroni; ε are the one-step \
         prediction errors):\n"
    );
    let _ = writeln!(
        s,
        "| test | record | statistic | critical value | lags | result |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        for t in &g.tests {
            let _ = writeln!(
                s,
                "| {} | {record} | {:.1} | {:.1} | {} | {} |",
                cell(&t.name),
                t.statistic,
                t.critical,
                t.lags,
                if t.passes() { "pass" } else { "**FAIL**" }
            );
        }
    }
    s.push('\n');
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        let _ = writeln!(s, "- {record} record: {}", g.verdict);
    }
    s.push('\n');
}

fn windows_section(s: &mut String, records: [(&str, &Gap, &TimeAxis); 2], band: f64) {
    for (record, g, time) in records {
        if g.windows.is_empty() {
            let _ = writeln!(
                s,
                "- {record} record: none; the moving RMS of the residual stays below {band}·σ̂ = {}.",
                e(band * g.noise_std)
            );
            continue;
        }
        let samples: usize = g.windows.iter().map(|w| w.len()).sum();
        let _ = writeln!(
            s,
            "- {record} record: {} window(s) above {band}·σ̂ = {}, {samples} of {} samples \
             ({:.1} %):\n",
            g.windows.len(),
            e(band * g.noise_std),
            g.residual.len(),
            100.0 * samples as f64 / g.residual.len().max(1) as f64
        );
        if time.is_time {
            let _ = writeln!(s, "  | samples | {} |", time.label);
            let _ = writeln!(s, "  |---|---|");
        } else {
            let _ = writeln!(s, "  | samples |");
            let _ = writeln!(s, "  |---|");
        }
        for w in g.windows.iter().take(MAX_WINDOW_ROWS) {
            if time.is_time {
                let _ = writeln!(
                    s,
                    "  | {}…{} | {} … {} |",
                    w.start,
                    w.end.saturating_sub(1),
                    g4(time.at(w.start)),
                    g4(time.at(w.end.saturating_sub(1)))
                );
            } else {
                let _ = writeln!(s, "  | {}…{} |", w.start, w.end.saturating_sub(1));
            }
        }
        if g.windows.len() > MAX_WINDOW_ROWS {
            let _ = writeln!(
                s,
                "\n  … and {} more (all in report.json).",
                g.windows.len() - MAX_WINDOW_ROWS
            );
        }
        s.push('\n');
    }
}

fn regions_section(s: &mut String, estimation: &Gap, validation: &Gap) {
    let _ = writeln!(
        s,
        "For each candidate signal, the region where the residual energy concentrates most \
         (candidates ranked by η², the share of the variance of ε² that quantile bins of the \
         signal explain; lift = energy share / sample share):\n"
    );
    let _ = writeln!(
        s,
        "| record | signal | region | share of samples | share of residual energy | lift | η² |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for (record, g) in [("estimation", estimation), ("validation", validation)] {
        for r in &g.regions {
            let _ = writeln!(
                s,
                "| {record} | {} | `{}` | {:.1} % | {:.1} % | {:.2} | {:.3} |",
                cell(&r.signal),
                cell(&r.describe()),
                100.0 * r.sample_share,
                100.0 * r.energy_share,
                r.lift,
                r.eta_squared
            );
        }
    }
    s.push('\n');
}

/// The candidate table of the naming step and the rule's decision, as report.md shows them.
fn candidate_table(s: &mut String, f: &Finding, alpha: f64) {
    let sel = &f.selection;
    let _ = writeln!(
        s,
        "Candidate table at this location. The best row has the smallest validation RMS; a row \
         is as good as the best unless the paired test of the log ratio of their mean squared \
         validation errors over blocks of the record says it is worse at α = {alpha}; among \
         the rows as good as the best that may be named, the simplest is chosen (a family before the \
         nonparametric map, then fewer parameters):\n"
    );
    let _ = writeln!(
        s,
        "| row | parameters | validation RMS | p (worse than the best) | as good | chosen |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (i, row) in f.table.iter().enumerate() {
        let p = match sel.p_worse_than_best.get(i).copied().flatten() {
            _ if i == sel.best => "best".to_string(),
            Some(p) => format!("{p:.3}"),
            None => "—".into(),
        };
        let parameters = match row.form {
            crate::table::Form::Nonparametric { .. } => "—".to_string(),
            _ => row.parameters.to_string(),
        };
        let _ = writeln!(
            s,
            "| {}{} | {parameters} | {} | {p} | {} | {} |",
            cell(&row.label),
            if row.eligible {
                ""
            } else {
                " (may not be named)"
            },
            e(row.validation_rms),
            if sel.as_good.get(i).copied().unwrap_or(false) {
                "yes"
            } else {
                "no"
            },
            if sel.chosen == Some(i) { "**yes**" } else { "" }
        );
    }
    s.push('\n');
}

fn parameters_text(fit: &EffectFit) -> String {
    // Derived quantities (a saturation's knee) follow the fitted parameters.
    fit.parameters
        .iter()
        .chain(&fit.derived())
        .map(|p| {
            format!(
                "{} = {} [{}, {}]",
                p.name,
                g4(p.value),
                g4(p.interval.0),
                g4(p.interval.1)
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// What the reports say besides the [`Discovery`] itself: the run's inputs, settings and
/// outputs.
#[derive(Clone, Copy, Debug)]
pub struct ReportContext<'a> {
    /// The tool's version, e.g. `0.1.0`.
    pub version: &'a str,
    /// The command line that ran the discovery.
    pub command: &'a str,
    /// The nominal model file as given.
    pub model_path: &'a Path,
    /// The output directory.
    pub out: &'a Path,
    /// The nominal model file.
    pub nominal_file: &'a ModelFile,
    /// The nominal model.
    pub nominal: &'a Nominal,
    /// The settings of the discovery.
    pub settings: &'a DiscoverSettings,
    /// The estimation record.
    pub estimation: &'a Record,
    /// The validation record.
    pub validation: &'a Record,
    /// The augmented model file written (`augmented.toml`), if any.
    pub augmented: Option<&'a AugmentedFile>,
    /// The figures written: file name and what it shows.
    pub figures: &'a [(String, String)],
    /// Lags of the gap's tests.
    pub max_lag: usize,
}

fn nominal_text(mf: &ModelFile) -> String {
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format_number(*x))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let maps = if mf.blocks.is_empty() {
        String::new()
    } else {
        format!(
            ", with the known map(s) {}",
            mf.blocks
                .iter()
                .map(|b| format!("`{}`", b.name))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    match &mf.linear {
        Some(spec) => format!(
            "`[linear]` {}, den = [{}], num = [{}]{maps}",
            spec.structure_name(),
            list(&spec.model.den),
            list(&spec.model.num[0])
        ),
        None => format!("`[lft]` with {} state(s){maps}", mf.lft.dims().states),
    }
}

/// The `--scoring` argument that reproduces `scoring` (empty for a free run, the default).
fn scoring_argument(scoring: Scoring) -> String {
    match scoring {
        Scoring::Free => String::new(),
        Scoring::Windowed(w) => format!(" --scoring {}:{}", w.length(), w.init()),
    }
}

fn validate_command(r: &ReportContext<'_>, w: &AugmentedFile, scoring: Scoring) -> String {
    format!(
        "structid validate --model {} --data {} --out {} --initial-state {}{}",
        r.out.join("augmented.toml").display(),
        r.validation.files("--data"),
        r.out.join("validation").display(),
        initial_state_name(w.initial_state),
        scoring_argument(scoring)
    )
}

fn validate_estimate_command(r: &ReportContext<'_>, w: &AugmentedFile, scoring: Scoring) -> String {
    format!(
        "structid validate --estimate {} --data {} --out {} --initial-state {}{}",
        r.out.join(ESTIMATE_FILE).display(),
        r.validation.files("--data"),
        r.out.join("validation-estimate").display(),
        initial_state_name(w.initial_state),
        scoring_argument(scoring)
    )
}

fn identify_command(r: &ReportContext<'_>, f: &Finding) -> String {
    let beta = f.hypothesis.beta;
    format!(
        "structid identify --model {} --data {} --out {} --beta {} --initial-state {}",
        r.out.join("augmented.toml").display(),
        r.estimation.files("--data"),
        r.out.join("identify").display(),
        format_number(beta),
        initial_state_name(initial_state(f.location).1)
    )
}

/// report.md: the discovery `d` in Markdown, verdict first, then the gap, where it sits, the
/// hypotheses, the effect found and the gap after, the figures and how to reproduce it.
pub fn markdown(d: &Discovery, r: &ReportContext<'_>) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# structid discover\n");
    let _ = writeln!(
        s,
        "**Verdict ({}):** {}\n",
        d.verdict_kind.describe(),
        d.verdict
    );
    let _ = writeln!(
        s,
        "Every simulation is scored by {}{}.\n",
        d.scoring.describe(),
        d.input_noise
            .map(|l| format!(
                "; the nominal model's noise path has an input disturbance of {l:.4e} per unit \
                 of output noise (maximum likelihood: the plant integrates)"
            ))
            .unwrap_or_default()
    );
    let _ = writeln!(
        s,
        "Noise level σ̂ = {} ({}): the smallest semivariogram estimate over the residuals of \
         the models examined, from {}. The naming tolerance (within 1.5·σ̂) and the verdict \
         (a gap larger than the noise) use it.\n",
        e(d.noise.std),
        if d.noise.colour > 0.0 {
            format!("coloured, correlation φ̂^k with φ̂ = {:.2}", d.noise.colour)
        } else {
            "white".to_string()
        },
        d.noise.source
    );
    let _ = writeln!(
        s,
        "Nominal model `{}` ({}); estimation record {} ({} samples), validation record {} \
         ({} samples); {:.1} s.\n",
        r.model_path.display(),
        nominal_text(r.nominal_file),
        r.estimation.names(),
        r.estimation.data.len(),
        r.validation.names(),
        r.validation.data.len(),
        d.seconds
    );

    linear_rival_md(&mut s, d);
    let _ = writeln!(s, "## 1. The gap: nominal model against the records\n");
    gap_table(&mut s, &d.estimation_gap, &d.validation_gap);

    let band = r.settings.gap().band;
    let _ = writeln!(s, "## 2. Where in time\n");
    let _ = writeln!(
        s,
        "Windows where the moving RMS of the residual exceeds {band}·σ̂:\n"
    );
    windows_section(
        &mut s,
        [
            ("estimation", &d.estimation_gap, &r.estimation.time),
            ("validation", &d.validation_gap, &r.validation.time),
        ],
        band,
    );

    let _ = writeln!(s, "## 3. Where in operating space\n");
    regions_section(&mut s, &d.estimation_gap, &d.validation_gap);

    if d.hypotheses.is_empty() {
        let _ = writeln!(
            s,
            "No hypotheses were tried: the nominal model's residual is within {}× its noise \
             level and passes every test on both records.\n",
            r.settings.gap().noise_ratio
        );
    } else {
        if d.finding.is_none() {
            let _ = writeln!(
                s,
                "A test of the nominal model's gap failed (section 1), so every candidate \
                 location was tried; none reduces the validation RMS enough to confirm a \
                 missing effect (see the verdict).\n"
            );
        }
        let _ = writeln!(s, "## 4. Where in the structure: hypotheses\n");
        let _ = writeln!(
            s,
            "One unknown static block N at each candidate location, identified on the \
             estimation record (Fourier kernel plus polynomial trend, β by marginal likelihood) \
             and ranked by the simulation RMS on the validation record:\n"
        );
        let _ = writeln!(
            s,
            "| rank | location | dispersion | β | σ | estimation RMS | validation RMS | seconds | failure |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
        for (i, h) in d.hypotheses.iter().enumerate() {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} | {:.2} | {} |",
                i + 1,
                cell(&location_text(r.nominal, h.location)),
                cell(&h.dispersion),
                e(h.beta),
                h.sigma.map(g4).unwrap_or_else(|| "fixed".into()),
                e(h.estimation_rms),
                e(h.validation_rms),
                h.seconds,
                h.failure.as_deref().map(cell).unwrap_or_default()
            );
        }
        s.push('\n');
    }

    if let Some(f) = &d.finding {
        finding_md(&mut s, d, r, f);
    } else if !d.hypotheses.is_empty() && d.hypotheses.iter().all(|h| h.failure.is_some()) {
        let _ = writeln!(
            s,
            "No hypothesis could be identified and simulated, so no augmented model was written.\n"
        );
    }

    let _ = writeln!(s, "## Figures\n");
    for (file, what) in r.figures {
        let _ = writeln!(s, "- [{file}]({file}): {what}");
    }
    s.push('\n');
    let _ = writeln!(s, "## Reproduce\n");
    let _ = writeln!(s, "```sh\n{}", r.command);
    if let (Some(f), Some(w)) = (&d.finding, r.augmented) {
        let _ = writeln!(s, "{}", validate_command(r, w, d.scoring));
        let _ = writeln!(s, "{}", validate_estimate_command(r, w, d.scoring));
        let _ = writeln!(s, "{}", identify_command(r, f));
        let _ = writeln!(s, "```\n");
        let _ = writeln!(
            s,
            "The first line reruns the discovery. The second simulates `augmented.toml` with its \
             map on the validation record (initial state {}, no settling samples): its RMS is \
             that of the gap after ({}). The third validates the stored estimate \
             `{ESTIMATE_FILE}` alike, without the model file or the estimation record. The \
             fourth re-estimates N nonparametrically with the hypothesis' dispersion and β.",
            initial_state_name(w.initial_state),
            e(f.augmented.validation_gap.rms)
        );
    } else {
        let _ = writeln!(s, "```");
    }
    s
}

/// G alone with one more mode, the linear model a finding must beat, when it was fitted.
fn linear_rival_md(s: &mut String, d: &Discovery) {
    let Some(r) = &d.linear_rival else {
        return;
    };
    let test = match &r.comparison {
        Some(c) => format!(
            "the finding against it, paired over {} blocks of the validation record: mean \
             ln(MSE ratio) {:+.3}, p = {:.3} that the finding is better",
            c.blocks,
            c.mean_log_ratio,
            1.0 - c.p_worse
        ),
        None => "no paired test (no finding, or one that cannot be tested against it)".to_string(),
    };
    let _ = writeln!(
        s,
        "**G alone with one more mode** (the linear model a finding must beat): F = {:?}, \
         B = {:?}; validation RMS {}; {test} → {}.\n",
        r.g.den,
        r.g.num,
        e(r.validation_rms),
        if r.explains {
            "it closes the gap: the linear model was wrong"
        } else {
            "it does not explain the gap"
        }
    );
}

/// Sections 5 and 6 of the report: what the finding is, and the augmented model's gap.
fn finding_md(s: &mut String, d: &Discovery, r: &ReportContext<'_>, f: &Finding) {
    if let Some(n) = &f.nominal_refinement {
        let _ = writeln!(
            s,
            "**G re-estimated with the map in the loop** ({}): F = {:?}, B = {:?} → F = {:?}, \
             B = {:?}; validation RMS {} → {}.\n",
            if n.adopted {
                "kept"
            } else {
                "not kept: no better"
            },
            n.before.den,
            n.before.num,
            n.after.den,
            n.after.num,
            e(n.validation_rms_before),
            e(n.validation_rms_after)
        );
    }
    let _ = writeln!(s, "## 5. What it is\n");
    let kind = match &f.classification {
        Classification::Named(_) => "named",
        Classification::Unnamed => "unnamed",
        Classification::Dynamic => "dynamic",
        Classification::TimeVarying(_) => "time-varying",
    };
    let _ = writeln!(
        s,
        "**{}** ({kind}) {}.\n",
        f.classification.describe_at(f.location),
        r.nominal.describe(f.location)
    );
    if let Some(h) = &f.input_hysteresis {
        let _ = writeln!(
            s,
            "- {}: w = u + λ·s, s_k = clamp(s_(k−1) + u_k − u_(k−1), −c, c), y = G·w, with G \
             re-estimated behind it (F = {:?}, B = {:?}): validation RMS {}, against {} for G \
             re-estimated alone and {} for the static approximation below. The augmented \
             model files hold that static approximation; a model file cannot declare the \
             hysteresis.\n",
            h.describe(),
            h.g.den,
            h.g.num,
            e(h.validation_rms),
            e(h.without_hysteresis_rms),
            e(f.augmented.validation_gap.rms)
        );
    }
    if let Classification::Named(fit) = &f.classification {
        let _ = writeln!(s, "- map: `{}`", fit.expression);
        let _ = writeln!(s, "- parameters (95 % intervals): {}", parameters_text(fit));
    }
    let _ = writeln!(
        s,
        "- named from the {} estimate; its validation RMS {}{}",
        f.estimator,
        e(f.nonparametric_rms),
        f.total_variation_rms
            .map(|v| format!(" (total variation tried: {})", e(v)))
            .unwrap_or_default()
    );
    let _ = writeln!(
        s,
        "- equivalent locations (the same model for a linear G): {}",
        if f.equivalent_locations.len() > 1 {
            f.equivalent_locations
                .iter()
                .map(|l| format!("`{}`", r.nominal.key(*l)))
                .collect::<Vec<_>>()
                .join(", ")
        } else {
            format!("none besides `{}`", r.nominal.key(f.location))
        }
    );
    s.push('\n');
    candidate_table(s, f, r.settings.significance());
    if let Some(st) = &f.stationarity {
        let _ = writeln!(s, "Stationarity: {}.\n", st.describe());
    }
    families_md(s, f);
    let _ = writeln!(
        s,
        "Direction test (residual deconvolved to the block's output, split by the direction of \
         z within z-bins): the direction explains {:.1} % of its energy, t = {:.2}, {} samples; \
         threshold {:.0} % → {}.\n",
        100.0 * f.direction.explained,
        f.direction.t_statistic,
        f.direction.samples,
        100.0 * r.settings.hysteresis_threshold(),
        if f.direction.dynamic {
            "dynamic (hysteresis or backlash suspected)"
        } else {
            "static"
        }
    );
    if !f.remarks.is_empty() {
        let _ = writeln!(s, "Remarks:\n");
        for m in &f.remarks {
            let _ = writeln!(s, "- {m}");
        }
        s.push('\n');
    }
    gap_after_md(s, d, r, f);
}

/// The families fitted to the finding's points, best BIC first.
fn families_md(s: &mut String, f: &Finding) {
    let _ = writeln!(
        s,
        "Families fitted to the points (z_k, ŵ_k), best BIC first (validation RMS for those \
         refined and simulated):\n"
    );
    let _ = writeln!(
        s,
        "| rank | family | parameters (95 % interval) | RMS | BIC | validation RMS |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|");
    for (i, fit) in f.naming.ranked.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} | {} |",
            i + 1,
            cell(&fit.effect.name()),
            cell(&parameters_text(fit)),
            e(fit.rms),
            fit.bic,
            f.family_rms
                .get(i)
                .copied()
                .flatten()
                .map(e)
                .unwrap_or_else(|| "—".into())
        );
    }
    s.push('\n');
}

/// Section 6 of the report: the augmented model's gap and the shrink.
fn gap_after_md(s: &mut String, d: &Discovery, r: &ReportContext<'_>, f: &Finding) {
    let _ = writeln!(s, "## 6. The gap after: augmented model\n");
    let _ = writeln!(
        s,
        "The nominal model with N {} ({}).\n",
        r.nominal.describe(f.location),
        match &f.augmented.map {
            AugmentedMap::Expression(x) => format!("N(z) = `{x}`"),
            AugmentedMap::Table { z, .. } => format!(
                "N as a table of {} points in `{}`",
                z.len(),
                table_name(r, f)
            ),
        }
    );
    gap_table(s, &f.augmented.estimation_gap, &f.augmented.validation_gap);
    let _ = writeln!(
        s,
        "**Shrink factor:** validation RMS {} → {} ({}); fit {} → {}.\n",
        e(d.validation_gap.rms),
        e(f.augmented.validation_gap.rms),
        crate::gap::shrink_text(f.shrink, 2),
        pct(d.validation_gap.fit_percent),
        pct(f.augmented.validation_gap.fit_percent)
    );
    if d.validation_gap.records.len() > 1 {
        let per: Vec<String> = d
            .validation_gap
            .records
            .iter()
            .zip(&f.augmented.validation_gap.records)
            .enumerate()
            .map(|(i, (a, b))| {
                format!(
                    "record {} ({}): {} → {} ({:.2}×)",
                    i + 1,
                    r.validation
                        .paths
                        .get(i)
                        .map(|p| format!("`{}`", p.display()))
                        .unwrap_or_default(),
                    e(a.rms),
                    e(b.rms),
                    a.rms / b.rms
                )
            })
            .collect();
        let _ = writeln!(
            s,
            "Per validation record (the shrink above pools their scored samples): {}.\n",
            per.join("; ")
        );
    }
    if let Some(w) = r.augmented {
        let _ = writeln!(
            s,
            "The augmented model is `augmented.toml` ({}{}; block `{}` with the map as its \
             `truth` and the hypothesis' dispersion, so that `structid identify` can re-estimate \
             it).\n",
            w.form,
            w.table
                .as_ref()
                .map(|t| format!(", table `{}`", t.name))
                .unwrap_or_default(),
            block_name(f)
        );
    }
}

/// The name of the finding's block in the augmented model (`N`, or `N2`, … when the nominal
/// model already had maps).
fn block_name(f: &Finding) -> &str {
    f.augmented
        .model
        .blocks()
        .first()
        .map_or(BLOCK, |b| b.name.as_str())
}

/// The file of the finding's table as the augmented file names it.
fn table_name(r: &ReportContext<'_>, f: &Finding) -> String {
    r.augmented
        .and_then(|w| w.table.as_ref())
        .map(|t| t.name.clone())
        .unwrap_or_else(|| crate::augmented::table_file_name(block_name(f)))
}

// ---------------------------------------------------------------------------------------------
// report.json

fn json_value<T: serde::Serialize>(v: &T) -> Result<Value, serde_json::Error> {
    serde_json::to_value(v)
}

fn gap_json(g: &Gap, time: &TimeAxis) -> Result<Value, serde_json::Error> {
    let regions = g
        .regions
        .iter()
        .map(|r| {
            let mut v = json_value(r)?;
            if let Value::Object(m) = &mut v {
                m.insert("description".into(), json!(r.describe()));
            }
            Ok(v)
        })
        .collect::<Result<Vec<Value>, serde_json::Error>>()?;
    Ok(json!({
        "rms": g.rms,
        "prediction_rms": g.prediction_rms,
        "fit_percent": g.fit_percent,
        "noise_std": g.noise_std,
        "noise": json_value(&g.noise)?,
        "tests": g.tests.iter().map(|t| json!({
            "name": t.name,
            "statistic": t.statistic,
            "critical": t.critical,
            "lags": t.lags,
            "passes": t.passes(),
        })).collect::<Vec<_>>(),
        "windows": g.windows.iter().map(|w| json!({
            "start": w.start,
            "end": w.end,
            "time_start": time.is_time.then(|| time.at(w.start)),
            "time_end": time.is_time.then(|| time.at(w.end.saturating_sub(1))),
        })).collect::<Vec<_>>(),
        "regions": regions,
        "lattice": json_value(&g.lattice)?,
        "missing_effect": g.missing_effect,
        "verdict": g.verdict,
        "records": json_value(&g.records)?,
    }))
}

fn parameter_json(p: &crate::effects::Parameter) -> Value {
    json!({
        "name": p.name,
        "value": p.value,
        "interval": [p.interval.0, p.interval.1],
    })
}

fn fit_json(fit: &EffectFit, validation_rms: Option<f64>) -> Result<Value, serde_json::Error> {
    Ok(json!({
        "name": fit.effect.name(),
        "family": json_value(&fit.effect)?,
        "expression": fit.expression,
        "parameters": fit.parameters.iter().map(parameter_json).collect::<Vec<_>>(),
        "derived": fit.derived().iter().map(parameter_json).collect::<Vec<_>>(),
        "rms": fit.rms,
        "bic": fit.bic,
        "validation_rms": validation_rms,
    }))
}

/// report.json: the discovery `d` and its context, machine-readable; `files` are the files
/// the run wrote.
///
/// # Errors
/// A part of the discovery that does not serialise (never for finite and non-finite numbers,
/// which become numbers and `null`).
pub fn json(
    d: &Discovery,
    r: &ReportContext<'_>,
    files: &[String],
) -> Result<Value, serde_json::Error> {
    let hypotheses: Vec<Value> = d
        .hypotheses
        .iter()
        .map(|h| {
            json!({
                "location": r.nominal.key(h.location),
                "description": r.nominal.describe(h.location),
                "dispersion": h.dispersion,
                "beta": h.beta,
                "sigma": h.sigma,
                "noise_term": h.noise_term,
                "dispersion_value": h.dispersion_value,
                "estimation_rms": h.estimation_rms,
                "validation_rms": h.validation_rms,
                "seconds": h.seconds,
                "failure": h.failure,
            })
        })
        .collect();
    let finding = match &d.finding {
        None => Value::Null,
        Some(f) => {
            let (kind, named) = match &f.classification {
                Classification::Named(fit) => (
                    "named",
                    fit_json(fit, Some(f.augmented.validation_gap.rms))?,
                ),
                Classification::Unnamed => ("unnamed", Value::Null),
                Classification::Dynamic => ("dynamic", Value::Null),
                Classification::TimeVarying(fit) => ("time-varying", fit_json(fit, None)?),
            };
            let families = f
                .naming
                .ranked
                .iter()
                .enumerate()
                .map(|(i, fit)| fit_json(fit, f.family_rms.get(i).copied().flatten()))
                .collect::<Result<Vec<Value>, serde_json::Error>>()?;
            let curve = Some(json_value(&f.hypothesis.curve)?);
            let map = match &f.augmented.map {
                AugmentedMap::Expression(x) => json!({ "expression": x }),
                AugmentedMap::Table { z, .. } => {
                    json!({ "table": table_name(r, f), "points": z.len() })
                }
            };
            json!({
                "location": r.nominal.key(f.location),
                "description": r.nominal.describe(f.location),
                "equivalent_locations": f.equivalent_locations.iter().map(|l| r.nominal.key(*l)).collect::<Vec<_>>(),
                "classification": { "kind": kind, "description": f.classification.describe_at(f.location) },
                "named_effect": named,
                "estimator": f.estimator,
                "nonparametric_validation_rms": f.nonparametric_rms,
                "total_variation_validation_rms": f.total_variation_rms,
                "families": families,
                "candidate_table": json_value(&f.table)?,
                "stationarity": json_value(&f.stationarity)?,
                "selection": json_value(&f.selection)?,
                "direction": json_value(&f.direction)?,
                "input_hysteresis": json_value(&f.input_hysteresis)?,
                "remarks": f.remarks,
                "map": map,
                "curve": curve,
                "gap_after": {
                    "estimation": gap_json(&f.augmented.estimation_gap, &r.estimation.time)?,
                    "validation": gap_json(&f.augmented.validation_gap, &r.validation.time)?,
                },
                "shrink": f.shrink,
            })
        }
    };
    let augmented = match (r.augmented, &d.finding) {
        (Some(w), Some(f)) => json!({
            "model_file": "augmented.toml",
            "form": w.form,
            "table_file": w.table.as_ref().map(|t| t.name.as_str()),
            "block": block_name(f),
            "initial_state": initial_state_name(w.initial_state),
            "estimate_file": ESTIMATE_FILE,
            "validation_rms": f.augmented.validation_gap.rms,
            "nominal_refinement": f.nominal_refinement,
            "reproduce": validate_command(r, w, d.scoring),
            "reproduce_estimate": validate_estimate_command(r, w, d.scoring),
            "reestimate": identify_command(r, f),
        }),
        _ => Value::Null,
    };
    let s = r.settings;
    Ok(json!({
        "tool": format!("structid {}", r.version),
        "version": r.version,
        "command": r.command,
        "inputs": {
            "model_file": r.model_path.display().to_string(),
            "model_file_absolute": absolute(r.model_path).display().to_string(),
            "data_file": r.estimation.path.display().to_string(),
            "data_file_absolute": absolute(&r.estimation.path).display().to_string(),
            "validation_file": r.validation.path.display().to_string(),
            "validation_file_absolute": absolute(&r.validation.path).display().to_string(),
            "data_files": r.estimation.paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "validation_files": r.validation.paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "estimation_samples": r.estimation.data.len(),
            "validation_samples": r.validation.data.len(),
            "sample_time": r.nominal_file.lft.sample_time(),
        },
        "settings": {
            "locations": s.locations().map(|l| l.iter().map(|l| r.nominal.key(*l)).collect::<Vec<_>>()),
            "total_variation": s.total_variation(),
            "settle": s.settle(),
            "sigma_fraction": s.sigma_fraction(),
            "trend_degree": s.trend_degree(),
            "tune_sigma": s.tune_sigma(),
            "significance": s.significance(),
            "hysteresis_threshold": s.hysteresis_threshold(),
            "band": s.gap().band,
            "noise_ratio": s.gap().noise_ratio,
            "max_lag": r.max_lag,
        },
        "verdict": d.verdict,
        "verdict_kind": d.verdict_kind,
        "missing_effect": d.missing_effect,
        "scoring": d.scoring.describe(),
        "input_noise_ratio": d.input_noise,
        "noise": json_value(&d.noise)?,
        "linear_rival": json_value(&d.linear_rival)?,
        "seconds": d.seconds,
        "gap_before": {
            "estimation": gap_json(&d.estimation_gap, &r.estimation.time)?,
            "validation": gap_json(&d.validation_gap, &r.validation.time)?,
        },
        "hypotheses": hypotheses,
        "finding": finding,
        "augmented": augmented,
        "files": files,
    }))
}

/// The summary printed after a run: the verdict, the effect and the shrink, the files
/// `written` and those `removed` (outputs of an earlier run), and the wall-clock `seconds`.
pub fn summary(
    d: &Discovery,
    r: &ReportContext<'_>,
    written: &[PathBuf],
    removed: &[PathBuf],
    seconds: f64,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "discovery on {} ({} samples) and {} ({} samples), {:.1} s",
        r.estimation.names(),
        r.estimation.data.len(),
        r.validation.names(),
        r.validation.data.len(),
        seconds
    );
    let _ = writeln!(s, "verdict: {}", d.verdict);
    if let Some(f) = &d.finding {
        let _ = writeln!(
            s,
            "best location: {} (of {} hypotheses)",
            location_text(r.nominal, f.location),
            d.hypotheses.len()
        );
        match &f.classification {
            Classification::Named(fit) => {
                let _ = writeln!(
                    s,
                    "effect: {} ({}): N(z) = {}",
                    fit.effect.name(),
                    fit.parameters
                        .iter()
                        .chain(&fit.derived())
                        .map(|p| format!("{} = {}", p.name, g4(p.value)))
                        .collect::<Vec<_>>()
                        .join(", "),
                    fit.expression
                );
            }
            other => match &f.input_hysteresis {
                Some(h) => {
                    let _ = writeln!(
                        s,
                        "effect: {}: {}, with G re-estimated, validation RMS {} (the model files \
                         hold its static approximation)",
                        other.describe(),
                        h.describe(),
                        e(h.validation_rms)
                    );
                }
                None => {
                    let _ = writeln!(s, "effect: {} (map kept as a table)", other.describe());
                }
            },
        }
        let _ = writeln!(
            s,
            "validation RMS: {} → {} ({}), fit {} → {}",
            e(d.validation_gap.rms),
            e(f.augmented.validation_gap.rms),
            crate::gap::shrink_text(f.shrink, 2),
            pct(d.validation_gap.fit_percent),
            pct(f.augmented.validation_gap.fit_percent)
        );
        if let Some(w) = r.augmented {
            let _ = writeln!(
                s,
                "augmented model: augmented.toml ({}) and {ESTIMATE_FILE}",
                w.form
            );
        }
    } else {
        let _ = writeln!(
            s,
            "validation RMS {} (fit {}), noise level σ̂ = {}",
            e(d.validation_gap.rms),
            pct(d.validation_gap.fit_percent),
            e(d.noise.std)
        );
    }
    let _ = writeln!(s, "wrote:");
    for p in written {
        let _ = writeln!(s, "  {}", p.display());
    }
    for p in removed {
        let _ = writeln!(s, "removed (from an earlier run): {}", p.display());
    }
    s
}

/// `p` made absolute (canonical when it exists), for reports that outlive the working
/// directory.
fn absolute(p: &Path) -> PathBuf {
    std::fs::canonicalize(p)
        .or_else(|_| std::path::absolute(p))
        .unwrap_or_else(|_| p.to_path_buf())
}

// ---------------------------------------------------------------------------------------------
// Several effects

/// What one step of an iteration found, in a few words.
fn step_effect(r: &Nominal, d: &Discovery) -> String {
    match &d.finding {
        Some(f) => format!(
            "{} {}",
            f.classification.describe_at(f.location),
            location_text(r, f.location)
        ),
        None => d.verdict_kind.describe().to_string(),
    }
}

/// The section of report.md on an iteration over several effects ([`Effects`]): one row per
/// step with what it found, the validation RMS before and after and whether it was adopted,
/// then why the iteration stopped. The report that follows is the last adopted step's (or the
/// first step's when none was adopted).
pub fn effects_markdown(effects: &Effects) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Effects, one at a time
"
    );
    let _ = writeln!(
        s,
        "Each step runs discovery on the model the previous adopted step left (its maps fixed \
         in the loop), and is adopted when it cuts the validation RMS by at least {:.0} %.\n",
        100.0 * effects.settings.min_improvement()
    );
    let _ = writeln!(
        s,
        "| step | found | validation RMS before | after | ratio | adopted |\n|---|---|---|---|---|---|"
    );
    for (i, step) in effects.steps.iter().enumerate() {
        let d = &step.discovery;
        let after = d.finding.as_ref().map(|f| f.augmented.validation_gap.rms);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            i + 1,
            cell(&step_effect(&step.nominal, d)),
            rms_text(d.validation_gap.rms),
            after.map(rms_text).unwrap_or_else(|| "—".into()),
            after
                .map(|a| format!("{:.3}", a / d.validation_gap.rms))
                .unwrap_or_else(|| "—".into()),
            if step.adopted { "yes" } else { "no" }
        );
    }
    let rms = effects.validation_rms();
    let _ = writeln!(
        s,
        "\n**Stopped:** {}. {} effect(s) adopted; validation RMS {}.\n",
        effects.stop.describe(&effects.settings),
        effects.findings().len(),
        rms.iter()
            .map(|v| rms_text(*v))
            .collect::<Vec<_>>()
            .join(" → ")
    );
    let _ = writeln!(
        s,
        "The sections below are those of the last adopted step (the first step when none was \
         adopted): its nominal model is the given one with the effects of the steps before it.\n"
    );
    s
}

/// The `effects` member of report.json for an iteration: every step (location, effect,
/// verdict, validation RMS before and after, adopted) and why it stopped.
///
/// # Errors
/// A part that does not serialise.
pub fn effects_json(effects: &Effects) -> Result<Value, serde_json::Error> {
    let steps: Vec<Value> = effects
        .steps
        .iter()
        .enumerate()
        .map(|(i, step)| {
            let d = &step.discovery;
            let f = d.finding.as_ref();
            json!({
                "step": i + 1,
                "verdict_kind": d.verdict_kind,
                "verdict": d.verdict,
                "location": f.map(|f| step.nominal.key(f.location)),
                "effect": f.map(|f| f.classification.describe_at(f.location)),
                "expression": f.and_then(|f| match &f.augmented.map {
                    AugmentedMap::Expression(x) => Some(x.clone()),
                    AugmentedMap::Table { .. } => None,
                }),
                "known_maps": step.nominal.known_maps().iter().map(|k| k.name.clone()).collect::<Vec<_>>(),
                "validation_rms_before": d.validation_gap.rms,
                "validation_rms_after": f.map(|f| f.augmented.validation_gap.rms),
                "adopted": step.adopted,
                "seconds": d.seconds,
            })
        })
        .collect();
    Ok(json!({
        "max_effects": effects.settings.max_effects(),
        "min_improvement": effects.settings.min_improvement(),
        "steps": steps,
        "stop": json_value(&effects.stop)?,
        "stop_text": effects.stop.describe(&effects.settings),
        "effects_found": effects.findings().len(),
        "validation_rms": effects.validation_rms(),
        "seconds": effects.seconds,
    }))
}

/// The lines the run prints for an iteration, before the last step's summary.
pub fn effects_summary(effects: &Effects) -> String {
    let mut s = String::new();
    for (i, step) in effects.steps.iter().enumerate() {
        let d = &step.discovery;
        let _ = writeln!(
            s,
            "step {}: {}; validation RMS {} → {}{}",
            i + 1,
            step_effect(&step.nominal, d),
            rms_text(d.validation_gap.rms),
            d.finding
                .as_ref()
                .map(|f| rms_text(f.augmented.validation_gap.rms))
                .unwrap_or_else(|| "—".into()),
            if step.adopted { " (adopted)" } else { "" }
        );
    }
    let _ = writeln!(
        s,
        "stopped: {} ({} effect(s))",
        effects.stop.describe(&effects.settings),
        effects.findings().len()
    );
    s
}
