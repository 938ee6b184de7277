//! The cascaded tanks from their physical structure, with unknown maps, fitted as a whole by
//! simulation error (`structid-joint`).
//!
//! Two level states, sampled at T_s = 4 s (forward Euler: the levels move by a small fraction
//! of their range per sample), in the LFT
//!
//! ```text
//!   x₁⁺ = x₁ + u − w₁                 w₁ = N₁(x₁)   outflow of the upper tank (x₁ latent)
//!   x₂⁺ = x₂ + g·w₁ − w₂              w₂ = N₂(x₂)   outflow of the lower tank
//!   y   = w₃                          w₃ = N₃(x₂)   the sensor, with the lower tank's overflow
//! ```
//!
//! x₁ is not measured: its scale is fixed by the unit gain from u, and g (free) carries the
//! upper outflow into the lower tank. A fourth map N₄(x₁) removes what the upper tank spills
//! when it overflows; a share h of it (free) reaches the lower tank:
//! x₁⁺ gains −w₄ and x₂⁺ gains h·w₄. The integrators (A = I) are held fixed.
//!
//! Every map is increasing ([`MonotoneFeatures`], the default): an outflow, a spill and a level
//! sensor all grow with the level, and a map that may not turn back cannot extrapolate an
//! outflow negative beyond the levels the data reached.
//!
//! Pipeline ([`run`]):
//! 1. The estimation record is split into a fitting part (the first 75 %) and a validation part.
//! 2. A linear start: every map affine (their kernel parts held near zero by a large β),
//!    fitted jointly with g, h and the initial state by single shooting on the fitting part.
//! 3. The maps' centres are placed over the ranges their inputs cover in that linear
//!    simulation (latent x₁ included), and the whole model is fitted by multiple shooting
//!    then single shooting, for each structure (which maps are free,
//!    [`PhysicalSettings::structures`]) and each β of a grid.
//! 4. The structure and β are chosen by the simulation RMS on the validation part (simulated
//!    on from the end of the fitting part); the chosen model is refitted on the whole
//!    estimation record.
//! 5. The test record is simulated once, from u alone, from the initial state estimated on the
//!    estimation record (the benchmark's description says both records start from the same
//!    state).

use std::time::Instant;

use nalgebra::DMatrix;
use structid_core::Monotonicity;
use structid_core::{Data, Lft, LftMatrices, Signal};
use structid_io::CascadedTanks;
use structid_joint::LinearInParameters;
use structid_joint::{
    BlockMap, GaussianFeatures, JointBlock, JointError, JointFit, JointModel, JointSettings,
    LftMatrix, MonotoneFeatures, fit,
};

/// Settings of the physical pipeline.
///
/// ```
/// let s = structid_benchmarks::tanks_physical::PhysicalSettings::default();
/// assert!(s.betas.len() > 1 && s.centres >= 5);
/// ```
#[derive(Clone, Debug)]
pub struct PhysicalSettings {
    /// Candidate dispersion weights β (the same for every map).
    pub betas: Vec<f64>,
    /// Centres per map.
    pub centres: usize,
    /// Samples per shooting segment.
    pub segment_length: usize,
    /// Fraction of the estimation record held out for validation.
    pub validation_fraction: f64,
    /// The structures tried, each a choice per map (upper outflow, lower outflow, sensor,
    /// upper overflow) of whether its kernel part is fitted (otherwise it stays affine). By
    /// default the upper overflow is tried both ways: it reads the same latent level as the
    /// upper outflow, and two free maps of one signal are told apart only by the share h that
    /// reaches the lower tank. The validation part decides, with β.
    pub structures: Vec<[bool; 4]>,
    /// Whether every map is increasing ([`MonotoneFeatures`]): an outflow, a spill and a level
    /// sensor all grow with the level, beyond the data too.
    pub monotone: bool,
}

impl Default for PhysicalSettings {
    fn default() -> Self {
        Self {
            betas: vec![1e-9, 1e-8, 1e-7, 1e-6],
            centres: 10,
            segment_length: 128,
            validation_fraction: 0.25,
            structures: vec![[true, true, true, true], [true, true, true, false]],
            monotone: true,
        }
    }
}

/// One structure and β tried.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BetaTrial {
    /// Which maps were free ([`PhysicalSettings::structures`]).
    pub nonlinear: [bool; 4],
    /// β.
    pub beta: f64,
    /// Simulation RMS on the fitting part, volts.
    pub fit_rms: f64,
    /// Simulation RMS on the validation part, volts.
    pub validation_rms: f64,
}

/// What the pipeline found.
#[derive(Clone, Debug)]
pub struct PhysicalResult {
    /// Each structure and β tried, scored on the validation part.
    pub trials: Vec<BetaTrial>,
    /// The structure chosen.
    pub nonlinear: [bool; 4],
    /// The β chosen.
    pub beta: f64,
    /// The model refitted on the whole estimation record.
    pub fit: JointFit,
    /// Simulation RMS on the estimation record, volts.
    pub estimation_rms: f64,
    /// Simulation RMS on the test record, volts (scored once).
    pub test_rms: f64,
    /// The simulated test output.
    pub test_simulation: Vec<f64>,
    /// Wall-clock seconds of the whole pipeline.
    pub seconds: f64,
}

fn lft(g: f64, h: f64) -> structid_core::Result<Lft> {
    let m = |r: usize, c: usize, v: &[f64]| DMatrix::from_row_slice(r, c, v);
    Lft::new(LftMatrices {
        a: DMatrix::identity(2, 2),
        bu: m(2, 1, &[1.0, 0.0]),
        be: m(2, 1, &[0.0, 0.0]),
        bw: m(2, 4, &[-1.0, 0.0, 0.0, -1.0, g, -1.0, 0.0, h]),
        cy: m(1, 2, &[0.0, 0.0]),
        dyu: m(1, 1, &[0.0]),
        dye: m(1, 1, &[1.0]),
        dyw: m(1, 4, &[0.0, 0.0, 1.0, 0.0]),
        cz: m(2, 2, &[1.0, 0.0, 0.0, 1.0]),
        dzu: m(2, 1, &[0.0, 0.0]),
        dze: m(2, 1, &[0.0, 0.0]),
        dzw: DMatrix::zeros(2, 4),
    })
}

/// An affine map a₀ + a₁z with centres over [lo, hi].
fn affine(
    lo: f64,
    hi: f64,
    m: usize,
    beta: f64,
    a0: f64,
    a1: f64,
) -> Result<GaussianFeatures, JointError> {
    let f = GaussianFeatures::on_interval(lo, hi, m, 1.5 * (hi - lo) / (m - 1) as f64, beta)?;
    let z: Vec<Vec<f64>> = (0..20)
        .map(|k| vec![lo + (hi - lo) * k as f64 / 19.0])
        .collect();
    let w: Vec<f64> = z.iter().map(|z| a0 + a1 * z[0]).collect();
    f.fitted_to(&z, &w)
}

fn model(blocks: [Box<dyn BlockMap>; 4], g: f64, h: f64) -> Result<JointModel, JointError> {
    let [n1, n2, n3, n4] = blocks;
    JointModel::new(
        lft(g, h)?,
        vec![
            JointBlock::new("upper outflow", vec![0], 0, n1),
            JointBlock::new("lower outflow", vec![1], 1, n2),
            JointBlock::new("sensor", vec![1], 2, n3),
            JointBlock::new("upper overflow", vec![0], 3, n4),
        ],
    )?
    .with_free(LftMatrix::Bw, 1, 0)?
    .with_free(LftMatrix::Bw, 1, 3)
}

fn data(u: &[f64], y: &[f64]) -> Result<Data, JointError> {
    let s = |v: &[f64]| Signal::new(1, v.to_vec()).map_err(structid_core::Error::from);
    Ok(Data::new(s(u)?, s(y)?)?)
}

fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

/// The linear start on `d`: outflows with time constants of about 25 samples, a unit sensor,
/// no overflow; returns the fitted model.
fn linear_start(d: &Data, settings: &JointSettings) -> Result<JointFit, JointError> {
    let (ymax, umean) = {
        let y = d.y().channel(0);
        let u = d.u().channel(0);
        (
            y.iter().copied().fold(0.0, f64::max).max(1.0),
            u.iter().sum::<f64>() / u.len() as f64,
        )
    };
    let k = 0.04;
    let frozen = 1e3;
    // The upper level settles at u/k; the lower at g·u/k.
    let x1 = umean / k;
    let g = ymax * 0.5 * k / umean;
    let start = model(
        [
            Box::new(affine(0.0, 2.0 * x1, 5, frozen, 0.0, k)?),
            Box::new(affine(0.0, ymax, 5, frozen, 0.0, k)?),
            Box::new(affine(0.0, ymax, 5, frozen, 0.0, 1.0)?),
            Box::new(affine(0.0, 2.0 * x1, 5, frozen, 0.0, 0.0)?),
        ],
        g,
        0.5,
    )?;
    fit(&start, d, None, settings)
}

/// Re-centres each map over the range its input covers in `base`'s simulation of `d`,
/// keeping its values there, with dispersion weight β (increasing maps when `monotone`).
fn recentred(
    base: &JointFit,
    d: &Data,
    settings: &PhysicalSettings,
    beta: f64,
    nonlinear: [bool; 4],
) -> Result<(JointModel, Vec<Vec<f64>>), JointError> {
    let centres = settings.centres;
    let sim = base.model.simulate(d.u(), Some(&base.initial_states[0]))?;
    let range = |c: usize| {
        let v = sim.z.channel(c);
        let (lo, hi) = (
            v.iter().copied().fold(f64::MAX, f64::min),
            v.iter().copied().fold(f64::MIN, f64::max),
        );
        let pad = 0.1 * (hi - lo).max(1e-3);
        (lo - pad, hi + pad)
    };
    let blocks = base.model.blocks();
    let mut maps = Vec::new();
    for (b, &free) in blocks.iter().zip(&nonlinear) {
        let beta = if free { beta } else { 1e3 };
        let (lo, hi) = range(b.inputs[0]);
        // The old map's values over the new range, kernel part included.
        let z: Vec<Vec<f64>> = (0..40)
            .map(|k| vec![lo + (hi - lo) * k as f64 / 39.0])
            .collect();
        let w: Vec<f64> = z.iter().map(|z| b.map.eval(&mut [], z)).collect();
        let sigma = 1.5 * (hi - lo) / (centres - 1) as f64;
        let map: Box<dyn BlockMap> = if settings.monotone {
            let f = MonotoneFeatures::on_interval(
                lo,
                hi,
                centres,
                sigma,
                beta,
                Monotonicity::Increasing,
            )?;
            Box::new(f.fitted_to(&z, &w)?)
        } else {
            let f = GaussianFeatures::on_interval(lo, hi, centres, sigma, beta)?;
            Box::new(f.fitted_to(&z, &w)?)
        };
        maps.push(map);
    }
    let p = base.model.parameters();
    let maps: [Box<dyn BlockMap>; 4] = maps.try_into().expect("four maps");
    Ok((model(maps, p[0], p[1])?, base.initial_states.clone()))
}

/// Runs the pipeline (see the [module documentation](self)).
pub fn run(
    tanks: &CascadedTanks,
    settings: &PhysicalSettings,
) -> Result<PhysicalResult, JointError> {
    let t0 = Instant::now();
    let est = &tanks.estimation;
    let n_fit = ((1.0 - settings.validation_fraction) * est.len() as f64).round() as usize;
    let fit_data = data(&est.u[..n_fit], &est.y[..n_fit])?;
    let all = data(&est.u, &est.y)?;
    let single = JointSettings::builder().max_iterations(60).build()?;
    let shooting = JointSettings::builder()
        .segment_length(settings.segment_length)
        .max_iterations(60)
        .build()?;
    let linear = linear_start(&fit_data, &single)?;
    let mut trials = Vec::new();
    let mut best: Option<([bool; 4], f64, f64)> = None;
    for (&nonlinear, &beta) in settings
        .structures
        .iter()
        .flat_map(|s| settings.betas.iter().map(move |b| (s, b)))
    {
        let (start, x0) = recentred(&linear, &fit_data, settings, beta, nonlinear)?;
        let x0: Vec<Vec<f64>> = x0.iter().map(|x| x[..2].to_vec()).collect();
        let f = fit(&start, &fit_data, Some(&x0), &shooting)?;
        // Simulated through the whole estimation record from the fitted start: the validation
        // part follows on from the fitting part.
        let sim = f.model.simulate(all.u(), Some(&f.initial_states[0]))?;
        let y = sim.y.channel(0);
        let trial = BetaTrial {
            nonlinear,
            beta,
            fit_rms: rms(&est.y[..n_fit], &y[..n_fit]),
            validation_rms: rms(&est.y[n_fit..], &y[n_fit..]),
        };
        if best.is_none_or(|(_, _, v)| trial.validation_rms < v) {
            best = Some((nonlinear, beta, trial.validation_rms));
        }
        trials.push(trial);
    }
    let (nonlinear, beta, _) =
        best.ok_or_else(|| JointError::InvalidModel("no structure or no β to try".into()))?;
    let linear_all = linear_start(&all, &single)?;
    let (start, x0) = recentred(&linear_all, &all, settings, beta, nonlinear)?;
    let x0: Vec<Vec<f64>> = x0.iter().map(|x| x[..2].to_vec()).collect();
    let fitted = fit(&start, &all, Some(&x0), &shooting)?;
    let sim = fitted
        .model
        .simulate(all.u(), Some(&fitted.initial_states[0]))?;
    let estimation_rms = rms(&est.y, &sim.y.channel(0));
    let test_u = Signal::new(1, tanks.test.u.clone()).map_err(structid_core::Error::from)?;
    let test = fitted
        .model
        .simulate(&test_u, Some(&fitted.initial_states[0]))?;
    let test_simulation = test.y.channel(0);
    let test_rms = rms(&tanks.test.y, &test_simulation);
    Ok(PhysicalResult {
        trials,
        nonlinear,
        beta,
        fit: fitted,
        estimation_rms,
        test_rms,
        test_simulation,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
