//! A Wiener–Hammerstein system simulated in continuous time, identified with both LTI blocks
//! unknown: the best linear approximation divided between the blocks, then the joint fit.
//!
//! The plant ([`Plant`]) is `y(t) = G₂(s)·N(G₁(s)·u(t))`, each block a second-order system
//!
//! ```text
//!   G₁(s) = ω₁² / (s² + 2ζ₁ω₁s + ω₁²),     G₂(s) = ω₂²·(1 + s/ω₀) / (s² + 2ζ₂ω₂s + ω₂²),
//!   N(z)  = tanh(1.2·z) + 0.15·z²,
//! ```
//!
//! driven by a zero-order-held random-phase multisine and integrated by RK4 with substeps, so
//! the signal between the blocks is continuous and no discrete model of order 2 + 2 is exact.
//! Gaussian noise is added to the sampled output.
//!
//! Pipeline ([`run`]):
//! 1. the best linear approximation: an output-error model of orders (n_b, n_f, n_k) =
//!    (4, 4, 1) on the estimation record;
//! 2. [`structid_joint::wiener_hammerstein_start`]: every division of its poles and zeros,
//!    scored by a map fitted behind it, the best one as the start;
//! 3. the joint fit of both blocks' coefficients, the map and the initial state by simulation
//!    error on the estimation record;
//! 4. the validation record checks the fitted model against the start (the fit is kept only
//!    if it simulates the validation record better), and the test record is scored once.

use std::f64::consts::PI;

use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;
use structid_core::{Data, Signal};
use structid_joint::{
    BlockMap, JointError, JointModel, JointSettings, WienerHammersteinSettings, fit,
    wiener_hammerstein_start,
};
use structid_linear::{OeSettings, Orders, oe};

/// The continuous-time truth.
#[derive(Clone, Debug)]
pub struct Plant {
    /// Front block: natural frequency (rad per sample) and damping.
    pub front: (f64, f64),
    /// Back block: natural frequency, damping and zero (rad per sample).
    pub back: (f64, f64, f64),
    /// RK4 substeps per sample.
    pub substeps: usize,
}

impl Default for Plant {
    fn default() -> Self {
        Self {
            front: (2.0 * PI * 0.04, 0.3),
            back: (2.0 * PI * 0.07, 0.5, 2.0 * PI * 0.12),
            substeps: 10,
        }
    }
}

/// The static map between the blocks.
pub fn map(z: f64) -> f64 {
    (1.2 * z).tanh() + 0.15 * z * z
}

impl Plant {
    /// dx/dt for state [z, ż, v, v̇] (v the back block's second-order state) and input u.
    fn derivative(&self, x: &[f64; 4], u: f64) -> [f64; 4] {
        let (w1, z1) = self.front;
        let (w2, z2, _) = self.back;
        let w = map(x[0]);
        [
            x[1],
            w1 * w1 * (u - x[0]) - 2.0 * z1 * w1 * x[1],
            x[3],
            w2 * w2 * (w - x[2]) - 2.0 * z2 * w2 * x[3],
        ]
    }

    /// The sampled output (noise-free) and the map's input and output at the samples, from
    /// rest, for the held input `u`.
    pub fn simulate(&self, u: &[f64]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let h = 1.0 / self.substeps as f64;
        let w0 = self.back.2;
        let mut x = [0.0; 4];
        let (mut y, mut z, mut w) = (Vec::new(), Vec::new(), Vec::new());
        for &uk in u {
            z.push(x[0]);
            w.push(map(x[0]));
            // y = v + v̇/ω₀: the zero of G₂.
            y.push(x[2] + x[3] / w0);
            for _ in 0..self.substeps {
                let step = |x: &[f64; 4], k: &[f64; 4], a: f64| {
                    std::array::from_fn::<f64, 4, _>(|i| x[i] + a * k[i])
                };
                let k1 = self.derivative(&x, uk);
                let k2 = self.derivative(&step(&x, &k1, h / 2.0), uk);
                let k3 = self.derivative(&step(&x, &k2, h / 2.0), uk);
                let k4 = self.derivative(&step(&x, &k3, h), uk);
                for i in 0..4 {
                    x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
            }
        }
        (y, z, w)
    }
}

/// A random-phase multisine of `len` samples exciting every bin up to `band` (a fraction of
/// the sampling frequency), with RMS `rms`.
pub fn multisine(len: usize, band: f64, rms: f64, seed: u64) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    let bins = ((band * len as f64) as usize).max(1);
    let phases: Vec<f64> = (0..bins).map(|_| 2.0 * PI * rng.random::<f64>()).collect();
    let raw: Vec<f64> = (0..len)
        .map(|k| {
            phases
                .iter()
                .enumerate()
                .map(|(b, p)| (2.0 * PI * (b + 1) as f64 * k as f64 / len as f64 + p).cos())
                .sum()
        })
        .collect();
    let r = (raw.iter().map(|v| v * v).sum::<f64>() / len as f64).sqrt();
    raw.iter().map(|v| rms * v / r).collect()
}

/// One measured record: input, noisy output, and the map's true input and output.
#[derive(Clone, Debug)]
pub struct Record {
    /// The input.
    pub u: Vec<f64>,
    /// The measured output.
    pub y: Vec<f64>,
    /// The map's input at the samples.
    pub z: Vec<f64>,
    /// The map's output at the samples.
    pub w: Vec<f64>,
}

/// A record of `len` samples: multisine input with seed `seed`, output noise of standard
/// deviation `noise` with seed `seed + 1`.
pub fn record(plant: &Plant, len: usize, noise: f64, seed: u64) -> Record {
    let u = multisine(len, 0.15, 1.0, seed);
    let (y, z, w) = plant.simulate(&u);
    let mut rng = StdRng::seed_from_u64(seed.wrapping_add(1));
    let y = y
        .iter()
        .map(|v| v + noise * rng.sample::<f64, _>(StandardNormal))
        .collect();
    Record { u, y, z, w }
}

/// What the pipeline found.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Divisions of the poles and zeros scored.
    pub divisions: usize,
    /// RMS output error of the best linear approximation on the test record.
    pub bla_test_rms: f64,
    /// RMS output error of the start (best division, map fitted behind it) on the test record.
    pub start_test_rms: f64,
    /// RMS output error of the joint fit on the estimation record.
    pub fit_rms: f64,
    /// RMS output error of the chosen model on the validation record.
    pub validation_rms: f64,
    /// RMS output error of the chosen model on the test record (against the noisy output).
    pub test_rms: f64,
    /// The fitted map against the true one as functions over the test record's range, up to
    /// an affine change of input and output, relative to the map's range ([`map_error`]).
    pub map_error: f64,
    /// The map's output along the test record against the true one, up to an affine change,
    /// relative to its range: this also carries G₁'s error (through z).
    pub w_error: f64,
    /// Whether the joint fit was kept (it simulated the validation record better).
    pub joint_kept: bool,
}

fn rms(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / a.len() as f64).sqrt()
}

fn data(r: &Record) -> Result<Data, JointError> {
    let n = r.u.len();
    Ok(Data::new(
        Signal::from_fn(n, 1, |k, _| r.u[k]),
        Signal::from_fn(n, 1, |k, _| r.y[k]),
    )?)
}

/// The output of `model` from rest on `r` (channel 0), its map's input and output.
struct Run {
    y: Vec<f64>,
    z: Vec<f64>,
    w: Vec<f64>,
}

fn simulate(model: &JointModel, r: &Record) -> Result<Run, JointError> {
    let n = r.u.len();
    let sim = model.simulate(&Signal::from_fn(n, 1, |k, _| r.u[k]), None)?;
    Ok(Run {
        y: sim.y.channel(0),
        z: sim.z.channel(0),
        w: sim.w.channel(0),
    })
}

/// The least-squares gain and offset (c, o) of `y ≈ c·x + o`.
fn affine_fit(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let cov: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let var: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    let c = if var > 0.0 { cov / var } else { 0.0 };
    (c, my - c * mx)
}

/// The RMS of `a − (c·b + o)` with the best gain and offset, relative to the range of `a`.
pub fn relative_error_modulo_affine(a: &[f64], b: &[f64]) -> f64 {
    let (c, o) = affine_fit(b, a);
    let sse: f64 = a.iter().zip(b).map(|(a, b)| (a - c * b - o).powi(2)).sum();
    let range =
        a.iter().copied().fold(f64::MIN, f64::max) - a.iter().copied().fold(f64::MAX, f64::min);
    (sse / a.len() as f64).sqrt() / range
}

/// The fitted map against the true one as functions, up to what the LFT cannot tell apart:
/// an affine change of the map's input (absorbed by G₁; estimated by regressing the model's ẑ
/// on the true z along the record) and of its output (absorbed by G₂). The RMS difference over
/// 200 points spanning the true z's range on the record, relative to the true map's range
/// there.
pub fn map_error(true_z: &[f64], model_z: &[f64], fitted: &dyn BlockMap) -> f64 {
    let (a, b) = affine_fit(true_z, model_z);
    let lo = true_z.iter().copied().fold(f64::MAX, f64::min);
    let hi = true_z.iter().copied().fold(f64::MIN, f64::max);
    let grid: Vec<f64> = (0..200)
        .map(|k| lo + (hi - lo) * k as f64 / 199.0)
        .collect();
    let truth: Vec<f64> = grid.iter().map(|z| map(*z)).collect();
    let model: Vec<f64> = grid
        .iter()
        .map(|z| fitted.eval(&mut [], &[a * z + b]))
        .collect();
    relative_error_modulo_affine(&truth, &model)
}

/// The pipeline on three records of the same plant (see the [module docs](self)).
///
/// # Errors
/// A failed linear or joint fit.
pub fn run(
    estimation: &Record,
    validation: &Record,
    test: &Record,
    joint: &JointSettings,
) -> Result<Outcome, JointError> {
    let est = data(estimation)?;
    let bla = oe(
        est.u(),
        est.y(),
        &Orders::siso(4, 4, 1),
        &OeSettings::default(),
    )
    .map_err(|e| JointError::InvalidModel(e.to_string()))?
    .model;
    let n = test.u.len();
    let bla_test = bla
        .simulate(&Signal::from_fn(n, 1, |k, _| test.u[k]))
        .map_err(|e| JointError::InvalidModel(e.to_string()))?;
    let start = wiener_hammerstein_start(&bla, &est, &WienerHammersteinSettings::default())?;
    let fitted = fit(&start.model, &est, None, joint)?;
    let yv_start = simulate(&start.model, validation)?.y;
    let yv_fit = simulate(&fitted.model, validation)?.y;
    let joint_kept = rms(&yv_fit, &validation.y) < rms(&yv_start, &validation.y);
    let chosen = if joint_kept {
        &fitted.model
    } else {
        &start.model
    };
    let t = simulate(chosen, test)?;
    let yt_start = simulate(&start.model, test)?.y;
    Ok(Outcome {
        divisions: start.splits.len(),
        bla_test_rms: rms(&bla_test, &test.y),
        start_test_rms: rms(&yt_start, &test.y),
        fit_rms: fitted.rms[0],
        validation_rms: rms(&yv_fit, &validation.y).min(rms(&yv_start, &validation.y)),
        test_rms: rms(&t.y, &test.y),
        map_error: map_error(&test.z, &t.z, chosen.blocks()[0].map.as_ref()),
        w_error: relative_error_modulo_affine(&test.w, &t.w),
        joint_kept,
    })
}
