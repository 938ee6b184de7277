//! The figures of a sweep, drawn from the case records alone (so that a merge draws the same
//! figures as an unsharded run).
//!
//! * `overlay_<experiment>.svg`: one panel per one-input block: the truth and, for every
//!   dispersion, the estimate of the first seed (the `auto` case when it succeeded, otherwise
//!   the middle fixed β), with its 95 % band (±1.96 posterior standard deviations) when the
//!   estimate has one.
//! * `beta_sweep_<experiment>.svg`, like Fig. 4 of Hsu et al. (2006): one row of panels per
//!   dispersion (one panel per one-input block), the estimates for every fixed β of the first
//!   seed overlaid with the truth.
//!
//! Maps that share an output with another map are identifiable only up to a constant; they are
//! drawn centred (each curve minus its mean over the data points), like `structid demo spray`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use structid_io::OutputGuard;
use structid_plot::{Chart, Series, render_grid_svg};

use crate::error::CliError;
use structid_workflow::compare::results::{BlockRecord, CaseRecord};

/// Pixel size of one panel.
const PANEL: (u32, u32) = (640, 460);

/// z-scores of the 95 % band.
const BAND_Z: f64 = 1.96;

/// A curve ready to draw.
struct Curve {
    label: String,
    x: Vec<f64>,
    y: Vec<f64>,
    band: Option<(Vec<f64>, Vec<f64>)>,
}

/// A panel ready to draw.
struct Panel {
    title: String,
    x_label: String,
    y_label: String,
    curves: Vec<Curve>,
}

fn shift(v: &[f64], by: f64) -> Vec<f64> {
    v.iter().map(|x| x - by).collect()
}

/// The estimate of `block` in `r` as a curve (centred when the block is), or `None` without a grid.
fn estimate_curve(b: &BlockRecord, label: String) -> Option<Curve> {
    let g = b.grid.as_ref()?;
    let c = if b.centred { g.estimate_mean } else { 0.0 };
    let y = shift(&g.estimate.0, c);
    let band = g.std.as_ref().map(|s| {
        let lo = y.iter().zip(&s.0).map(|(m, s)| m - BAND_Z * s).collect();
        let hi = y.iter().zip(&s.0).map(|(m, s)| m + BAND_Z * s).collect();
        (lo, hi)
    });
    Some(Curve {
        label,
        x: g.z.0.clone(),
        y,
        band,
    })
}

/// The truth of `block` in `r` as a curve, when known.
fn truth_curve(b: &BlockRecord) -> Option<Curve> {
    let g = b.grid.as_ref()?;
    let t = g.truth.as_ref()?;
    let c = if b.centred {
        g.truth_mean.unwrap_or(0.0)
    } else {
        0.0
    };
    Some(Curve {
        label: "truth".into(),
        x: g.z.0.clone(),
        y: shift(&t.0, c),
        band: None,
    })
}

fn y_label(block: &str, centred: bool) -> String {
    if centred {
        format!("{block}(z), centred")
    } else {
        format!("{block}(z)")
    }
}

fn beta_label(r: &CaseRecord) -> String {
    match (r.beta_setting.as_str(), r.beta) {
        ("auto", Some(b)) => format!(
            "auto {}: β = {}",
            r.selection,
            structid_workflow::text::short(b)
        ),
        (_, Some(b)) => format!("β = {}", structid_workflow::text::short(b)),
        (s, None) => format!("β = {s}"),
    }
}

fn render(panels: &[Panel], cols: usize) -> Result<Option<String>, CliError> {
    let charts: Vec<Chart<'_>> = panels
        .iter()
        .filter(|p| !p.curves.is_empty())
        .map(|p| {
            let mut c = Chart::new(&p.title, &p.x_label, &p.y_label);
            for k in &p.curves {
                c = c.with(match &k.band {
                    Some((lo, hi)) => Series::band(&k.label, &k.x, &k.y, lo, hi),
                    None => Series::line(&k.label, &k.x, &k.y),
                });
            }
            c
        })
        .collect();
    if charts.is_empty() {
        return Ok(None);
    }
    Ok(Some(render_grid_svg(&charts, cols, PANEL)?))
}

/// Names in order of first appearance.
fn ordered<'a>(items: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for i in items {
        if !out.contains(&i) {
            out.push(i);
        }
    }
    out
}

/// Blocks with a grid (one input) in the experiment's records, in model order.
fn plotted_blocks(recs: &[&CaseRecord]) -> Vec<String> {
    ordered(
        recs.iter()
            .flat_map(|r| r.blocks.iter().filter(|b| b.grid.is_some()))
            .map(|b| b.name.as_str()),
    )
    .into_iter()
    .map(String::from)
    .collect()
}

fn overlay(exp: &str, recs: &[&CaseRecord]) -> Result<Option<String>, CliError> {
    let first_seed = recs.first().and_then(|r| r.seed);
    let blocks = plotted_blocks(recs);
    let mut panels: Vec<Panel> = Vec::new();
    for name in &blocks {
        let mut panel = Panel {
            title: format!("{exp}: {name}"),
            x_label: "z".into(),
            y_label: String::new(),
            curves: Vec::new(),
        };
        let mut truth: Option<Curve> = None;
        for disp in ordered(recs.iter().map(|r| r.dispersion.as_str())) {
            let ok: Vec<&CaseRecord> = recs
                .iter()
                .copied()
                .filter(|r| r.dispersion == disp && r.seed == first_seed && r.is_ok())
                .collect();
            let fixed: Vec<&CaseRecord> = ok
                .iter()
                .copied()
                .filter(|r| r.beta_setting != "auto")
                .collect();
            let chosen = ok
                .iter()
                .copied()
                .find(|r| r.beta_setting == "auto")
                .or_else(|| fixed.get(fixed.len().saturating_sub(1) / 2).copied());
            let Some(r) = chosen else { continue };
            let Some(b) = r.blocks.iter().find(|b| &b.name == name) else {
                continue;
            };
            if panel.y_label.is_empty() {
                panel.y_label = y_label(name, b.centred);
            }
            if truth.is_none() {
                truth = truth_curve(b);
            }
            if let Some(c) = estimate_curve(b, format!("{disp} ({})", beta_label(r))) {
                panel.curves.push(c);
            }
        }
        if let Some(t) = truth {
            panel.curves.insert(0, t);
        }
        panels.push(panel);
    }
    let cols = panels.len().clamp(1, 3);
    render(&panels, cols)
}

fn beta_sweep(exp: &str, recs: &[&CaseRecord]) -> Result<Option<String>, CliError> {
    let first_seed = recs.first().and_then(|r| r.seed);
    let blocks = plotted_blocks(recs);
    let mut panels = Vec::new();
    for disp in ordered(recs.iter().map(|r| r.dispersion.as_str())) {
        let fixed: Vec<&CaseRecord> = recs
            .iter()
            .copied()
            .filter(|r| {
                r.dispersion == disp
                    && r.seed == first_seed
                    && r.is_ok()
                    && r.beta_setting != "auto"
            })
            .collect();
        if fixed.is_empty() {
            continue;
        }
        for name in &blocks {
            let mut panel = Panel {
                title: format!("{exp}, {disp}: {name}"),
                x_label: "z".into(),
                y_label: String::new(),
                curves: Vec::new(),
            };
            for r in &fixed {
                let Some(b) = r.blocks.iter().find(|b| &b.name == name) else {
                    continue;
                };
                if panel.curves.is_empty() {
                    panel.y_label = y_label(name, b.centred);
                    if let Some(t) = truth_curve(b) {
                        panel.curves.push(t);
                    }
                }
                if let Some(c) = estimate_curve(b, beta_label(r)) {
                    panel.curves.push(c);
                }
            }
            panels.push(panel);
        }
    }
    render(&panels, blocks.len().max(1))
}

/// Writes the figures of every experiment in `records` into `dir`; returns the files written.
/// Experiments without a successful case of a one-input block get no figure.
pub fn write_figures(
    guard: &OutputGuard,
    dir: &Path,
    records: &BTreeMap<usize, CaseRecord>,
) -> Result<Vec<PathBuf>, CliError> {
    let recs: Vec<&CaseRecord> = records.values().collect();
    let mut written = Vec::new();
    for exp in ordered(recs.iter().map(|r| r.experiment.as_str())) {
        let mine: Vec<&CaseRecord> = recs
            .iter()
            .copied()
            .filter(|r| r.experiment == exp)
            .collect();
        for (stem, svg) in [
            (format!("overlay_{exp}.svg"), overlay(exp, &mine)?),
            (format!("beta_sweep_{exp}.svg"), beta_sweep(exp, &mine)?),
        ] {
            if let Some(svg) = svg {
                let path = dir.join(stem);
                guard.write(&path, svg.as_bytes())?;
                written.push(path);
            }
        }
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use structid_workflow::compare::results::{CASE_FORMAT, GridRecord, Values};

    fn rec(index: usize, disp: &str, beta: &str, seed: u64, level: f64, ok: bool) -> CaseRecord {
        let z: Vec<f64> = (0..21).map(|i| -1.0 + 0.1 * i as f64).collect();
        CaseRecord {
            format: CASE_FORMAT.into(),
            id: format!("e/{disp}/beta={beta}/seed={seed}"),
            index,
            case_count: 10,
            case_list: "0".into(),
            fingerprint: "0".into(),
            experiment: "e".into(),
            dispersion: disp.into(),
            beta_setting: beta.into(),
            seed: Some(seed),
            selection: "fixed".into(),
            beta: beta.parse().ok(),
            blocks: vec![BlockRecord {
                name: "f".into(),
                centred: false,
                has_truth: true,
                rms_error: Some(0.1),
                sigma: None,
                grid: Some(GridRecord {
                    estimate: Values(z.iter().map(|v| v * v + level).collect()),
                    std: (beta == "auto").then(|| Values(vec![0.05; z.len()])),
                    truth: Some(Values(z.iter().map(|v| v * v).collect())),
                    z: Values(z),
                    estimate_mean: 0.0,
                    truth_mean: Some(0.0),
                }),
            }],
            validation: Vec::new(),
            cost: None,
            solver: "exact".into(),
            seconds: 0.0,
            status: if ok { "ok".into() } else { "error: x".into() },
            selection_curve: Vec::new(),
            noise_variance: None,
        }
    }

    #[test]
    fn overlay_takes_auto_or_the_middle_beta_of_the_first_seed() {
        let recs = [
            rec(0, "gauss", "0.001", 0, 0.11, true),
            rec(1, "gauss", "0.001", 1, 0.12, true),
            rec(2, "gauss", "0.01", 0, 0.21, true),
            rec(3, "gauss", "0.1", 0, 0.31, true),
            rec(4, "tv", "0.01", 0, 0.41, true),
            rec(5, "tv", "auto", 0, 0.51, true),
            rec(6, "bad", "auto", 0, 0.61, false),
        ];
        let refs: Vec<&CaseRecord> = recs.iter().collect();
        let svg = overlay("e", &refs).unwrap().unwrap();
        assert!(svg.contains("gauss (β = 0.01)"), "middle β of gauss");
        // Its β is unknown in this hand-made record.
        assert!(svg.contains("tv (β = auto)"));
        assert!(!svg.contains("bad ("), "failed cases are not drawn");
        // The auto case has a band: a filled polygon.
        assert!(svg.contains("<polygon"));
        let sweep = beta_sweep("e", &refs).unwrap().unwrap();
        for l in [
            "β = 0.001",
            "β = 0.01",
            "β = 0.1",
            "e, gauss: f",
            "e, tv: f",
        ] {
            assert!(sweep.contains(l), "{l}");
        }
        assert!(!sweep.contains("e, bad: f"));
        // Nothing to draw: no figure.
        let failed = [rec(0, "bad", "0.1", 0, 0.0, false)];
        let refs: Vec<&CaseRecord> = failed.iter().collect();
        assert!(overlay("e", &refs).unwrap().is_none());
        assert!(beta_sweep("e", &refs).unwrap().is_none());
    }
}
