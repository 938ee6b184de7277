//! The figures of a discovery: residual.svg, regions.svg, map.svg and before_after.svg.

use structid_discover::discover::{Classification, Finding, HypothesisResult};
use structid_discover::gap::Gap;
use structid_discover::hypotheses::{Nominal, Site};
use structid_discover::localise::binned_residual;
use structid_plot::{Chart, Series, decimate_min_max, render_chart_svg, render_grid_svg};

use super::{Record, TimeAxis};
use crate::Result;

/// Most points per line in the time-series figures (longer records are drawn decimated).
const MAX_PLOT_POINTS: usize = 4000;
/// Most points drawn as dots in map.svg.
const MAX_DOTS: usize = 2000;
/// Bins of the binned residual in regions.svg.
pub const REGION_BINS: usize = 20;

/// Buckets of the thinned lines of the figures ([`decimate_min_max`]): about one per pixel
/// column.
const PLOT_BUCKETS: usize = 1000;

/// Every `step`-th index so that at most [`MAX_PLOT_POINTS`] remain, plus the last one.
fn plot_indices(len: usize) -> Vec<usize> {
    let step = len.div_ceil(MAX_PLOT_POINTS).max(1);
    let mut idx: Vec<usize> = (0..len).step_by(step).collect();
    if len > 0 && idx.last() != Some(&(len - 1)) {
        idx.push(len - 1);
    }
    idx
}

fn pick(v: &[f64], idx: &[usize]) -> Vec<f64> {
    idx.iter().map(|&k| v[k]).collect()
}

/// residual.svg: the residual of the nominal model on the estimation record with its ±band·σ̂ lines and the
/// exceedance windows shaded.
pub fn residual_svg(g: &Gap, band: f64, time: &TimeAxis) -> Result<String> {
    let n = g.residual.len();
    // The decimated samples plus the ends of every window, so that short windows show.
    let mut idx = plot_indices(n);
    for w in &g.windows {
        idx.push(w.start.min(n.saturating_sub(1)));
        idx.push(w.end.saturating_sub(1).min(n.saturating_sub(1)));
    }
    idx.sort_unstable();
    idx.dedup();
    let t = pick(&time.values, &idx);
    // The residual itself thinned to its envelope, so that its peaks show however long the
    // record; the band and the shading need only the sampled times.
    let (tr, r) = decimate_min_max(&time.values, &g.residual, PLOT_BUCKETS);
    let limit = band * g.noise_std;
    let upper = vec![limit; t.len()];
    let lower = vec![-limit; t.len()];
    let reach = g
        .residual
        .iter()
        .fold(limit, |m, v| if v.is_finite() { m.max(v.abs()) } else { m });
    let inside = |k: usize| g.windows.iter().any(|w| w.contains(&k));
    let shade_hi: Vec<f64> = idx
        .iter()
        .map(|&k| if inside(k) { reach } else { f64::NAN })
        .collect();
    let shade_lo: Vec<f64> = shade_hi.iter().map(|v| -v).collect();
    let mut chart = Chart::new(
        format!(
            "Residual y − ŷ of the nominal model (estimation record, RMS {:.3e}, σ̂ = {:.3e})",
            g.rms, g.noise_std
        ),
        time.label,
        "y − ŷ",
    )
    .size((1000, 450));
    if !g.windows.is_empty() {
        chart = chart.with(Series::band(
            "windows above the band",
            &t,
            &[],
            &shade_lo,
            &shade_hi,
        ));
    }
    chart = chart
        .with(Series::line("residual", &tr, &r))
        .with(Series::line(format!("+{band}·σ̂"), &t, &upper))
        .with(Series::line(format!("−{band}·σ̂"), &t, &lower));
    Ok(render_chart_svg(&chart)?)
}

/// regions.svg: the binned residual (mean and RMS per quantile bin) against each candidate signal.
pub fn regions_svg(residual: &[f64], candidates: &[(String, Vec<f64>)]) -> Result<String> {
    type Binned = (String, Vec<f64>, Vec<f64>, Vec<f64>);
    let binned: Vec<Binned> = candidates
        .iter()
        .map(|(name, s)| -> Binned {
            let b = binned_residual(residual, s, REGION_BINS);
            (
                name.clone(),
                b.iter().map(|x| x.0).collect(),
                b.iter().map(|x| x.1).collect(),
                b.iter().map(|x| x.2).collect(),
            )
        })
        .filter(|(_, x, _, _)| !x.is_empty())
        .collect();
    let charts: Vec<Chart> = binned
        .iter()
        .map(|(name, x, mean, rms)| {
            Chart::new(
                format!("residual binned by {name}"),
                name.as_str(),
                "residual",
            )
            .with(Series::line("mean", x, mean))
            .with(Series::dots("mean (bins)", x, mean))
            .with(Series::line("RMS", x, rms))
        })
        .collect();
    Ok(render_grid_svg(
        &charts,
        3.min(charts.len().max(1)),
        (480, 340),
    )?)
}

fn z_label(location: Site) -> &'static str {
    match location {
        Site::Input => "z = u",
        Site::Output => "z = G·u",
        Site::OutputFeedback => "z = y",
        Site::RateFeedback => "z = ẏ",
        Site::Declared { .. } => "z",
    }
}

/// map.svg: the best hypothesis' map with its ±2σ band and points, and the map of the augmented model.
pub fn map_svg(nominal: &Nominal, h: &HypothesisResult, f: &Finding) -> Result<String> {
    let c = &h.curve;
    let band = c.std.as_ref().map(|s| {
        (
            c.w.iter()
                .zip(s)
                .map(|(w, s)| w - 2.0 * s)
                .collect::<Vec<f64>>(),
            c.w.iter()
                .zip(s)
                .map(|(w, s)| w + 2.0 * s)
                .collect::<Vec<f64>>(),
        )
    });
    let n = h.points.0.len();
    let idx: Vec<usize> = if n <= MAX_DOTS {
        (0..n).collect()
    } else {
        (0..MAX_DOTS).map(|i| i * n / MAX_DOTS).collect()
    };
    let pz = pick(&h.points.0, &idx);
    let pw = pick(&h.points.1, &idx);
    let map = f.augmented.map.interpolant()?;
    let aw: Vec<f64> = c.z.iter().map(|z| map.eval(&[*z])).collect();
    let label = match &f.classification {
        Classification::Named(fit) => format!("{} (named, in augmented.toml)", fit.effect.name()),
        _ => format!("table in augmented.toml ({} estimate)", f.estimator),
    };
    let mut chart = Chart::new(
        format!(
            "Map N {}: {}",
            nominal.key(f.location),
            f.classification.describe_at(f.location)
        ),
        z_label(f.location),
        "w = N(z)",
    )
    .size((900, 560));
    if let Some((lo, hi)) = &band {
        chart = chart.with(Series::band("±2σ", &c.z, &[], lo, hi));
    }
    if !pz.is_empty() {
        chart = chart.with(Series::dots("points (z_k, ŵ_k)", &pz, &pw));
    }
    chart = chart
        .with(Series::line("nonparametric estimate", &c.z, &c.w))
        .with(Series::line(label, &c.z, &aw));
    Ok(render_chart_svg(&chart)?)
}

/// before_after.svg: measured y, the nominal and the augmented simulation on the validation record, and the two
/// residuals.
pub fn before_after_svg(val: &Record, before: &Gap, after: &Gap, shrink: f64) -> Result<String> {
    let n = before.simulated.len();
    let time = &val.time.values[..n.min(val.time.values.len())];
    let thin = |v: &[f64]| decimate_min_max(time, v, PLOT_BUCKETS);
    let y = thin(&val.data.y().channel(0));
    let nominal = thin(&before.simulated);
    let augmented = thin(&after.simulated);
    let r0 = thin(&before.residual);
    let r1 = thin(&after.residual);
    let charts = [
        Chart::new(
            format!(
                "Validation record: measured and simulated (fit {:.1} % → {:.1} %)",
                before.fit_percent, after.fit_percent
            ),
            val.time.label,
            "y",
        )
        .with(Series::line("measured y", &y.0, &y.1))
        .with(Series::line("nominal model", &nominal.0, &nominal.1))
        .with(Series::line("augmented model", &augmented.0, &augmented.1)),
        Chart::new(
            format!(
                "Residuals y − ŷ (RMS {:.3e} → {:.3e}, {})",
                before.rms,
                after.rms,
                structid_discover::gap::shrink_text(shrink, 1)
            ),
            val.time.label,
            "y − ŷ",
        )
        .with(Series::line("nominal model", &r0.0, &r0.1))
        .with(Series::line("augmented model", &r1.0, &r1.1)),
    ];
    Ok(render_grid_svg(&charts, 1, (1000, 400))?)
}
