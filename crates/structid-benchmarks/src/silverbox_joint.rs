//! Silverbox refined as a whole by its simulation error (`structid-joint`), from the model of
//! the alternating pipeline ([`crate::silverbox::run`]).
//!
//! The start is that pipeline's G (its LFT, every non-zero entry of A, B_u and B_w free) and
//! its map, re-expressed as a Gaussian kernel expansion with an unpenalised cubic trend (the
//! physics' stiffness, which carries the map beyond the estimation amplitudes the arrow test
//! reaches). Beside it, in the same feedback path, sits a second map N₂(y_k, c·(y_k − y_(k−1)))
//! of the output and its increment (c scales the increment to the output's range): a Gaussian
//! expansion on a [`JointSilverboxSettings::second_map`]² grid, whose dependence on the rate is
//! what a damping that varies with the motion needs, and what one map of y cannot give. Its
//! kernel part decays beyond its centres, so it does not carry the model past the estimation
//! amplitudes; the cubic stiffness does. β is chosen from a grid by the simulation RMS on the last 20 % of the estimation
//! split (simulated on from the fitted part's start): the largest β whose validation RMS is
//! within [`JointSilverboxSettings::tie`] of the best, since a smaller difference does not
//! tell the maps apart and the smoother one extrapolates more safely (the validation part has
//! the estimation amplitudes and cannot judge extrapolation). The model is then refitted on
//! the whole estimation split with that β. Each test split is simulated once from u, from
//! the initial state that its first samples set (the samples the benchmark leaves unscored
//! for that purpose, [`structid_io::Record::settle`], fitted with the model held,
//! [`fit_initial_state`]): the multisine window opens in the middle of a multisine.

use std::time::Instant;

use structid_core::{Data, Interpolant, Result, Signal};
use structid_io::{Silverbox, SilverboxSplit};
use structid_joint::LinearInParameters;
use structid_joint::{
    GaussianFeatures, JointBlock, JointError, JointFit, JointModel, JointSettings, LftMatrix, fit,
    fit_initial_state,
};

use crate::pipeline::io;
use crate::silverbox::SilverboxResult;

/// Settings of the joint refinement of Silverbox.
///
/// ```
/// let s = structid_benchmarks::silverbox_joint::JointSilverboxSettings::default();
/// assert_eq!((s.trend_degree, s.second_map), (3, 7));
/// ```
#[derive(Clone, Debug)]
pub struct JointSilverboxSettings {
    /// Candidate β.
    pub betas: Vec<f64>,
    /// Kernel centres of the map.
    pub centres: usize,
    /// Degree of the map's unpenalised polynomial trend.
    pub trend_degree: usize,
    /// Fraction of the estimation split held out to choose β.
    pub validation_fraction: f64,
    /// Levenberg–Marquardt iterations per stage.
    pub max_iterations: usize,
    /// Relative difference of validation RMS below which two β are a tie (then the larger,
    /// smoother one is chosen).
    pub tie: f64,
    /// Centres per axis of the second map N₂(y_k, c·(y_k − y_(k−1))) entering beside the first
    /// (0: none). Seven is the coarser of {7, 9}, whose validation RMS differ by less than the
    /// [`JointSilverboxSettings::tie`] (0.2511 against 0.2501 mV): the data do not tell them
    /// apart, and the coarser map is the smoother one.
    pub second_map: usize,
}

impl Default for JointSilverboxSettings {
    fn default() -> Self {
        Self {
            betas: vec![1e-6, 1e-2, 1.0],
            centres: 15,
            trend_degree: 3,
            validation_fraction: 0.2,
            max_iterations: 30,
            tie: 0.01,
            second_map: 7,
        }
    }
}

/// The result.
#[derive(Clone, Debug)]
pub struct JointSilverbox {
    /// (β, validation RMS in volts) for each β tried.
    pub trials: Vec<(f64, f64)>,
    /// The chosen β.
    pub beta: f64,
    /// The fit on the whole estimation split.
    pub fit: JointFit,
    /// (split, RMS in volts) for each test split, simulated from the initial state its
    /// unscored first samples set.
    pub tests: Vec<(String, f64)>,
    /// Seconds of the joint refinement (the alternating pipeline not included).
    pub seconds: f64,
}

fn joint(e: JointError) -> structid_core::Error {
    match e {
        JointError::Core(c) => c,
        other => structid_core::Error::Numerical(other.to_string()),
    }
}

/// The start: the pipeline's LFT and its map as kernel features with a polynomial trend.
fn start(
    base: &SilverboxResult,
    y: &Signal,
    s: &JointSilverboxSettings,
    beta: f64,
) -> Result<JointModel> {
    let map: &dyn Interpolant = base.refinement.identification.blocks[0].map.as_ref();
    let v = y.channel(0);
    let (lo, hi) = v
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(*x), b.max(*x))
        });
    let spacing = (hi - lo) / (s.centres - 1) as f64;
    let f = GaussianFeatures::on_interval(lo, hi, s.centres, 1.5 * spacing, beta)
        .and_then(|f| f.with_trend_degree(s.trend_degree))
        .map_err(joint)?;
    let z: Vec<Vec<f64>> = (0..400)
        .map(|k| vec![lo + (hi - lo) * k as f64 / 399.0])
        .collect();
    let w: Vec<f64> = z.iter().map(|z| map.eval(z)).collect();
    let f = f.fitted_to(&z, &w).map_err(joint)?;
    let b = &base.refinement.model.blocks()[0];
    let lft = base.refinement.model.lft();
    let n = lft.dims().states;
    let mut blocks = vec![JointBlock::new(
        "N",
        b.inputs.clone(),
        b.output,
        Box::new(f),
    )];
    let lft = if s.second_map > 0 {
        let g2 = GaussianFeatures::new(
            grid(lo, hi, s.second_map),
            1.5 * (hi - lo) / (s.second_map - 1) as f64,
            beta,
        )
        .map_err(joint)?;
        blocks.push(JointBlock::new("N2", vec![1, 2], 1, Box::new(g2)));
        // The second input is the output's increment, scaled to the output's range.
        let dy = v
            .windows(2)
            .map(|p| (p[1] - p[0]).abs())
            .fold(0.0, f64::max);
        with_previous_output(lft, (hi - lo) / (2.0 * dy.max(1e-12)))?
    } else {
        lft.clone()
    };
    let mut model = JointModel::new(lft.clone(), blocks).map_err(joint)?;
    let m = lft.matrices();
    for (matrix, mat, cols) in [
        (LftMatrix::A, &m.a, n),
        (LftMatrix::Bu, &m.bu, m.bu.ncols()),
        (LftMatrix::Bw, &m.bw, m.bw.ncols()),
    ] {
        for i in 0..n {
            for j in 0..cols {
                if mat[(i, j)] != 0.0 {
                    model = model.with_free(matrix, i, j).map_err(joint)?;
                }
            }
        }
    }
    Ok(model)
}

/// `m`² points on the square [lo, hi]².
fn grid(lo: f64, hi: f64, m: usize) -> Vec<Vec<f64>> {
    let axis: Vec<f64> = (0..m)
        .map(|j| lo + (hi - lo) * j as f64 / (m - 1) as f64)
        .collect();
    axis.iter()
        .flat_map(|a| axis.iter().map(move |b| vec![*a, *b]))
        .collect()
}

/// The LFT with a state m_k = y_(k−1) and two more z rows [y; c·(y − m)] for a second map,
/// whose output enters as the first map's does.
fn with_previous_output(lft: &structid_core::Lft, c: f64) -> Result<structid_core::Lft> {
    use nalgebra::DMatrix;
    let m = lft.matrices();
    let d = lft.dims();
    let n = d.states;
    let mut a = DMatrix::zeros(n + 1, n + 1);
    a.view_mut((0, 0), (n, n)).copy_from(&m.a);
    a.view_mut((n, 0), (1, n)).copy_from(&m.cy);
    let stack = |top: &DMatrix<f64>, bottom: &DMatrix<f64>| {
        let mut out = DMatrix::zeros(top.nrows() + bottom.nrows(), top.ncols());
        out.view_mut((0, 0), top.shape()).copy_from(top);
        out.view_mut((top.nrows(), 0), bottom.shape())
            .copy_from(bottom);
        out
    };
    let twice = |c: &DMatrix<f64>| {
        let mut out = DMatrix::zeros(c.nrows(), 2);
        out.set_column(0, &c.column(0));
        out.set_column(1, &c.column(0));
        out
    };
    let mut cz = DMatrix::zeros(3, n + 1);
    cz.view_mut((0, 0), (1, n)).copy_from(&m.cz);
    cz.view_mut((1, 0), (1, n)).copy_from(&m.cz);
    cz.view_mut((2, 0), (1, n)).copy_from(&(&m.cz * c));
    cz[(2, n)] = -c;
    let lft2 = structid_core::Lft::new(structid_core::LftMatrices {
        a,
        bu: stack(&m.bu, &m.dyu),
        be: stack(&m.be, &m.dye),
        bw: stack(&twice(&m.bw), &twice(&m.dyw)),
        cy: stack(&m.cy.transpose(), &DMatrix::zeros(1, 1)).transpose(),
        dyu: m.dyu.clone(),
        dye: m.dye.clone(),
        dyw: twice(&m.dyw),
        cz,
        dzu: stack(&stack(&m.dzu, &m.dzu), &DMatrix::zeros(1, d.u)),
        dze: stack(&stack(&m.dze, &m.dze), &(&m.dze * c)),
        dzw: DMatrix::zeros(3, 2),
    })?;
    match lft.sample_time() {
        Some(ts) => lft2.with_sample_time(ts),
        None => Ok(lft2),
    }
}

fn rms_after(a: &[f64], b: &[f64], from: usize) -> f64 {
    let n = (a.len() - from) as f64;
    (a[from..]
        .iter()
        .zip(&b[from..])
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

/// Runs the joint refinement from the pipeline's result `base`.
pub fn run_joint(
    sb: &Silverbox,
    base: &SilverboxResult,
    s: &JointSilverboxSettings,
) -> Result<JointSilverbox> {
    let t0 = Instant::now();
    let est = sb.split(SilverboxSplit::Estimation).data().map_err(io)?;
    let cut = ((1.0 - s.validation_fraction) * est.len() as f64).round() as usize;
    let part = Data::new(est.u().slice(0..cut), est.y().slice(0..cut))?;
    let settings = JointSettings::builder()
        .max_iterations(s.max_iterations)
        .build()
        .map_err(joint)?;
    let mut trials = Vec::new();
    for &beta in &s.betas {
        let f = fit(&start(base, est.y(), s, beta)?, &part, None, &settings).map_err(joint)?;
        let sim = f
            .model
            .simulate(est.u(), Some(&f.initial_states[0]))
            .map_err(joint)?;
        trials.push((beta, rms_after(&sim.y.channel(0), &est.y().channel(0), cut)));
    }
    let best = trials.iter().map(|t| t.1).fold(f64::INFINITY, f64::min);
    let beta = trials
        .iter()
        .filter(|t| t.1 <= (1.0 + s.tie) * best)
        .map(|t| t.0)
        .fold(f64::NAN, f64::max);
    if !beta.is_finite() {
        return Err(structid_core::Error::InvalidStructure(
            "no β validated".into(),
        ));
    }
    let f = fit(&start(base, est.y(), s, beta)?, &est, None, &settings).map_err(joint)?;
    let mut tests = Vec::new();
    for split in SilverboxSplit::TESTS {
        let rec = sb.split(split);
        let data = rec.data().map_err(io)?;
        // The window's unscored first samples set its initial state (a window may open in the
        // middle of an excitation).
        let x0 = if rec.settle > 0 {
            let settle = Data::new(data.u().slice(0..rec.settle), data.y().slice(0..rec.settle))?;
            fit_initial_state(&f.model, &settle, &settings)
                .map_err(joint)?
                .pop()
        } else {
            None
        };
        let sim = f.model.simulate(data.u(), x0.as_deref()).map_err(joint)?;
        tests.push((
            split.name().to_string(),
            rec.scored_rms(&sim.y.channel(0)).map_err(io)?,
        ));
    }
    Ok(JointSilverbox {
        trials,
        beta,
        fit: f,
        tests,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
