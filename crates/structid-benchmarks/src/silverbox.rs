//! The Silverbox benchmark end to end: an electronic Duffing oscillator, m·ÿ + d·ẏ + a·y +
//! b·y³ = u (Wigren and Schoukens, 2013).
//!
//! Structure: y = G·(u − w) + e with w = N(y), G a discrete linear block estimated from the
//! data and N a static map of the measured output
//! ([`LinearStructure::output_feedback`]).
//!
//! Pipeline ([`run`]):
//! 1. The estimation split is divided into a fitting part (the first 80 %) and a validation
//!    part (the rest). Nothing below looks at the test splits.
//! 2. For each candidate order n (na = nb = n, nk = 1): the best linear approximation (BLA) by
//!    ARX and then output error with a free initial state on the fitting part; then
//!    [`refine`]: the map by [`identify()`](structid_core::identify()) (β and σ by marginal likelihood on the
//!    first pass), G by output error, in turn, with the initial state estimated in both steps,
//!    until the validation error stops improving. The validation error is the simulation
//!    error on the validation part, simulated from the start of the estimation split so that
//!    no transient is scored.
//! 3. The order (and whether the feedback path gets its own numerator) with the lowest
//!    validation error wins; then the map with a kernel is tried for that structure. The final
//!    model is refined again on the whole estimation split with the chosen structure and the
//!    same number of alternations.
//! 4. Each test split is simulated open loop from u alone, from rest; the first 50 samples
//!    settle the state and are not scored.
//!
//! The map's dispersion is a cubic polynomial (ridge regression on 1, y, y², y³, the physics'
//! stiffness with an even term) or that polynomial plus a Gaussian-like Fourier kernel
//! ([`SumDispersion`](structid_core::SumDispersion)). The validation part has the estimation amplitudes, so it cannot judge
//! extrapolation (the last part of the arrow test reaches 40 % beyond them): the kernel is kept
//! only when it lowers the validation error by more than `kernel_margin` (5 %), and otherwise
//! the simpler map wins. Outside the data, the kernel part of a sum reverts towards zero with
//! a growing band (see the figure of `examples/silverbox.rs`), while the polynomial carries on.

use std::sync::Arc;
use std::time::Instant;

use structid_core::refine::{LinearStructure, Refinement, refine};
use structid_core::{Data, Dispersion, Interpolant, MapBinding, Model, Result, Signal};
use structid_io::{Silverbox, SilverboxSplit};
use structid_linear::PolynomialModel;

use crate::pipeline::{io, map_dispersion, range, refine_settings, rms_from};

/// Settings of the Silverbox pipeline.
#[derive(Clone, Debug)]
pub struct SilverboxSettings {
    /// Candidate orders n of G (na = nb = n, nk = 1).
    pub orders: Vec<usize>,
    /// Candidate feedback numerators: `false` shares G's numerator (y = G·(u − N(y))),
    /// `true` fits its own.
    pub numerators: Vec<bool>,
    /// The kernel-plus-trend dispersion replaces the plain polynomial only when it lowers the
    /// validation error by more than this fraction (the simpler map wins ties).
    pub kernel_margin: f64,
    /// Fraction of the estimation split held out for validation.
    pub validation_fraction: f64,
    /// Largest number of alternations.
    pub max_iterations: usize,
    /// Degree of the map's polynomial trend.
    pub trend_degree: usize,
    /// Weight of each normalised monomial of the trend.
    pub trend_scale: f64,
    /// Tune σ with β (marginal likelihood); otherwise σ = `sigma_fraction` × the range of y.
    pub tune_sigma: bool,
    /// σ (or the start of its search) as a fraction of the range of y.
    pub sigma_fraction: f64,
}

impl Default for SilverboxSettings {
    fn default() -> Self {
        Self {
            orders: vec![2, 3, 4, 5, 6],
            numerators: vec![false, true],
            kernel_margin: 0.05,
            validation_fraction: 0.2,
            max_iterations: 6,
            trend_degree: 3,
            trend_scale: 10.0,
            tune_sigma: false,
            sigma_fraction: 0.2,
        }
    }
}

/// One candidate of the order search.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Candidate {
    /// Order n of G.
    pub order: usize,
    /// Whether the feedback path had its own numerator.
    pub separate_numerator: bool,
    /// Whether the map had the Fourier kernel besides its polynomial.
    pub kernel: bool,
    /// Validation RMS of the best alternation, volts.
    pub validation_rms: f64,
    /// Alternations run.
    pub iterations: usize,
    /// Validation RMS of the BLA (no map), volts.
    pub bla_validation_rms: f64,
    /// Seconds of the refinement.
    pub seconds: f64,
}

/// The test error on one split.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TestScore {
    /// Split name.
    pub split: String,
    /// RMS simulation error of the structured model, volts.
    pub rms: f64,
    /// RMS simulation error of the project's second-order BLA, volts.
    pub bla2_rms: f64,
    /// RMS simulation error of the BLA of the chosen order, volts.
    pub bla_rms: f64,
    /// The structured model's simulated output over the split.
    #[serde(skip)]
    pub simulated: Vec<f64>,
    /// The measured output over the split.
    #[serde(skip)]
    pub measured: Vec<f64>,
}

/// Everything the pipeline produced.
pub struct SilverboxResult {
    /// Every candidate tried, in order.
    pub candidates: Vec<Candidate>,
    /// The chosen candidate (index into `candidates`).
    pub chosen: usize,
    /// The final refinement on the whole estimation split.
    pub refinement: Refinement,
    /// The test scores, one per test split.
    pub tests: Vec<TestScore>,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// The map's dispersion: the polynomial of the trend degree alone, or with a Gaussian-like
/// Fourier kernel added.
fn dispersion(
    settings: &SilverboxSettings,
    y: &Signal,
    with_kernel: bool,
) -> Result<Arc<dyn Dispersion>> {
    let sigma = with_kernel.then(|| settings.sigma_fraction * range(&y.channel(0)));
    map_dispersion(settings.trend_degree, settings.trend_scale, sigma)
}

/// The BLA of order n (na = nb = n, nk = 1): ARX, then output error with a free initial
/// state.
pub fn bla(data: &Data, order: usize, sample_time: f64) -> Result<PolynomialModel> {
    crate::pipeline::bla(data, order, sample_time)
}

/// Simulates `model` with `map` in the loop from rest over `u`.
pub fn simulate(model: &Model, map: &dyn Interpolant, u: &Signal) -> Result<Vec<f64>> {
    let b = &model.blocks()[0];
    let sim = model.lft().simulate(
        &[MapBinding {
            inputs: &b.inputs,
            output: b.output,
            map,
        }],
        u,
        None,
        None,
    )?;
    Ok(sim.y.channel(0))
}

/// Refines one candidate on the fitting part and scores it on the validation part.
fn try_candidate(
    settings: &SilverboxSettings,
    g: &PolynomialModel,
    bla_validation_rms: f64,
    separate: bool,
    with_kernel: bool,
    fit: &Data,
    est: &Data,
) -> Result<Candidate> {
    let ts = g.sample_time.unwrap_or(1.0);
    let structure = LinearStructure::output_feedback("N").with_separate_numerator(separate);
    let g0 = structure.initial_from_bla(g)?;
    let rs = refine_settings(
        settings.max_iterations,
        1e-3,
        fit.len(),
        ts,
        settings.tune_sigma,
        true,
    )?;
    let disp = dispersion(settings, est.y(), with_kernel)?;
    // Validation: the whole estimation split, scored after the fitting part, so that the
    // transient of the initial state is not scored.
    let r = refine(&structure, &g0, disp, fit, Some(est), &rs)?;
    let validation_rms = r.iterations[r.best].validation_rms.unwrap_or(f64::INFINITY);
    Ok(Candidate {
        order: g.den.len() - 1,
        separate_numerator: separate,
        kernel: with_kernel,
        validation_rms,
        iterations: r.best + 1,
        bla_validation_rms,
        seconds: r.seconds,
    })
}

/// Runs the pipeline of the [module documentation](self) on the loaded benchmark.
pub fn run(sb: &Silverbox, settings: &SilverboxSettings) -> Result<SilverboxResult> {
    let t0 = Instant::now();
    let ts = sb.sample_time;
    let est = sb.split(SilverboxSplit::Estimation).data().map_err(io)?;
    let cut = ((1.0 - settings.validation_fraction) * est.len() as f64).round() as usize;
    let fit = Data::new(est.u().slice(0..cut), est.y().slice(0..cut))?;

    // Stage 1: orders and numerators with the polynomial map.
    let mut candidates = Vec::new();
    let mut blas = Vec::new();
    for &n in &settings.orders {
        let g = bla(&fit, n, ts)?;
        let bla_val = {
            let lft = structid_core::refine::lti_lft(&g)?;
            let sim = lft.simulate(&[], est.u(), None, None)?;
            rms_from(&sim.y.channel(0), &est.y().channel(0), cut)
        };
        for &separate in &settings.numerators {
            candidates.push(try_candidate(
                settings, &g, bla_val, separate, false, &fit, &est,
            )?);
        }
        blas.push(g);
    }
    let lowest = |c: &[Candidate]| {
        (0..c.len()).min_by(|&a, &b| c[a].validation_rms.total_cmp(&c[b].validation_rms))
    };
    let mut chosen = lowest(&candidates).ok_or_else(|| {
        structid_core::Error::InvalidStructure(
            "no candidate orders or numerators were given".into(),
        )
    })?;
    // Stage 2: the kernel-plus-trend map for the chosen structure, kept only if clearly better.
    if settings.kernel_margin.is_finite() {
        let c = candidates[chosen].clone();
        let k = settings
            .orders
            .iter()
            .position(|&n| n == c.order)
            .unwrap_or(0);
        let with_kernel = try_candidate(
            settings,
            &blas[k],
            c.bla_validation_rms,
            c.separate_numerator,
            true,
            &fit,
            &est,
        )?;
        candidates.push(with_kernel);
        if candidates[candidates.len() - 1].validation_rms
            < (1.0 - settings.kernel_margin) * c.validation_rms
        {
            chosen = candidates.len() - 1;
        }
    }
    let c = candidates[chosen].clone();

    // Final model on the whole estimation split.
    let structure =
        LinearStructure::output_feedback("N").with_separate_numerator(c.separate_numerator);
    let g = bla(&est, c.order, ts)?;
    let g0 = structure.initial_from_bla(&g)?;
    let rs = refine_settings(c.iterations, 0.0, 0, ts, settings.tune_sigma, true)?;
    let refinement = refine(
        &structure,
        &g0,
        dispersion(settings, est.y(), c.kernel)?,
        &est,
        None,
        &rs,
    )?;
    let bla2 = bla(&est, 2, ts)?;

    let mut tests = Vec::new();
    let map = refinement.identification.blocks[0].map.as_ref();
    for split in SilverboxSplit::TESTS {
        let rec = sb.split(split);
        let data = rec.data().map_err(io)?;
        let y_sim = simulate(&refinement.model, map, data.u())?;
        let linear = |g: &PolynomialModel| -> Result<f64> {
            let lft = structid_core::refine::lti_lft(g)?;
            let sim = lft.simulate(&[], data.u(), None, None)?;
            rec.scored_rms(&sim.y.channel(0)).map_err(io)
        };
        tests.push(TestScore {
            split: split.name().into(),
            rms: rec.scored_rms(&y_sim).map_err(io)?,
            bla2_rms: linear(&bla2)?,
            bla_rms: linear(&g)?,
            simulated: y_sim,
            measured: rec.y.clone(),
        });
    }
    Ok(SilverboxResult {
        candidates,
        chosen,
        refinement,
        tests,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
