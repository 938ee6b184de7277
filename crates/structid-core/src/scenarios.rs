//! Synthetic identification problems used by benchmarks, timing examples and tests.

use std::sync::Arc;

use nalgebra::DMatrix;
use structid_lti::Signal;

use crate::dispersion::fourier::{FourierDispersion, FourierWeights};
use crate::dispersion::{Dispersion, KernelDispersion};
use crate::error::Result;
use crate::identify::{IdentifySettings, SolverChoice};
use crate::model::lft::{Lft, LftMatrices};
use crate::model::structure::Structure;
use crate::paper::{Experiment, gaussian_noise};

/// The model y = N₂(G·N₁(u)) + e with G = (b₀q² + b₁q + b₂)/(q² + a₁q + a₂) in
/// controllable form: z₁ = u, z₂ = C·x + b₀·w₁ (maps in series through D_zw = b₀ when
/// b₀ ≠ 0), y = w₂ + e, and the noise reaching the state (B_e ≠ 0), so that no z is computed
/// from the record: a model beyond measurability, scored by simulation. Blocks `actuator`
/// (w₁ = N₁(z₁)) and `sensor` (w₂ = N₂(z₂)), with a Gaussian kernel dispersion of width 0.5.
///
/// ```
/// use structid_core::scenarios::actuator_sensor_series;
/// let m = actuator_sensor_series([-1.8, 0.8], [0.01, 0.015, 0.005]).unwrap();
/// assert_eq!(m.lft().matrices().dzw[(1, 0)], 0.01);
/// assert_eq!(m.evaluation_order().unwrap(), vec![0, 1]);
/// ```
pub fn actuator_sensor_series(a: [f64; 2], b: [f64; 3]) -> Result<crate::Model> {
    use nalgebra::dmatrix;
    let lft = Lft::new(LftMatrices {
        a: dmatrix![-a[0], -a[1]; 1.0, 0.0],
        bu: DMatrix::zeros(2, 1),
        be: dmatrix![0.1; 0.0],
        bw: dmatrix![1.0, 0.0; 0.0, 0.0],
        cy: DMatrix::zeros(1, 2),
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0, 1.0],
        cz: dmatrix![0.0, 0.0; b[1] - a[0] * b[0], b[2] - a[1] * b[0]],
        dzu: dmatrix![1.0; 0.0],
        dze: dmatrix![0.0; 0.0],
        dzw: dmatrix![0.0, 0.0; b[0], 0.0],
    })?;
    let d: Arc<dyn Dispersion> = Arc::new(KernelDispersion::gaussian(0.5)?);
    crate::Model::new(
        lft,
        vec![
            crate::NonlinearBlock::new("actuator", vec![0], 0, Arc::clone(&d)),
            crate::NonlinearBlock::new("sensor", vec![1], 1, d),
        ],
    )
}

/// A SISO Hammerstein system y = G(q)·N(u) + e with a random stable G of the given order
/// (spectral radius 0.9, reproducible from `seed`), N = tanh, u white noise squashed to
/// (−2, 2) ([`Excitation::White`]) and white noise of standard deviation `noise_std`.
pub fn hammerstein(
    len: usize,
    order: usize,
    noise_std: f64,
    dispersion: Arc<dyn Dispersion>,
    seed: u64,
) -> Result<Experiment> {
    hammerstein_map(
        len,
        order,
        noise_std,
        &f64::tanh,
        Excitation::White,
        dispersion,
        seed,
    )
}

/// The input of a synthetic Hammerstein experiment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Excitation {
    /// White noise squashed to (−2, 2): u_k = 2·tanh(0.8·n_k), n_k ~ N(0, 1) independent.
    White,
    /// A sinusoid 2·sin(2π·periods·k/L): z sweeps its range slowly and in order.
    Sine {
        /// Periods over the record.
        periods: f64,
    },
}

/// A SISO Hammerstein system y = G(q)·N(u) + e with a random stable G of the given order
/// (reproducible from `seed`), any static map N, white noise of standard deviation
/// `noise_std`, and the chosen excitation. The test problem of the total-variation issue.
pub fn hammerstein_map(
    len: usize,
    order: usize,
    noise_std: f64,
    map: &(dyn Fn(f64) -> f64 + Sync),
    excitation: Excitation,
    dispersion: Arc<dyn Dispersion>,
    seed: u64,
) -> Result<Experiment> {
    build_hammerstein(
        len, order, noise_std, false, map, excitation, dispersion, seed,
    )
}

/// [`hammerstein`] with coloured noise: e reaches y through the minimum-phase filter
/// H(q) = (1 + 0.5q⁻¹)/(1 − 0.8q⁻¹), one more state in the LFT (B_e ≠ 0).
pub fn hammerstein_coloured(
    len: usize,
    order: usize,
    noise_std: f64,
    dispersion: Arc<dyn Dispersion>,
    seed: u64,
) -> Result<Experiment> {
    build_hammerstein(
        len,
        order,
        noise_std,
        true,
        &f64::tanh,
        Excitation::White,
        dispersion,
        seed,
    )
}

fn build_hammerstein(
    len: usize,
    order: usize,
    noise_std: f64,
    coloured: bool,
    nonlinearity: &(dyn Fn(f64) -> f64 + Sync),
    excitation: Excitation,
    dispersion: Arc<dyn Dispersion>,
    seed: u64,
) -> Result<Experiment> {
    let g = structid_lti::testing::random_stable_system(seed, order, 1, 1, 0.9);
    let ng = g.order();
    let n = ng + usize::from(coloured);
    let mut a = DMatrix::zeros(n, n);
    a.view_mut((0, 0), (ng, ng)).copy_from(g.a());
    let mut bu = DMatrix::zeros(n, 1);
    bu.view_mut((0, 0), (ng, 1)).copy_from(g.b());
    let mut be = DMatrix::zeros(n, 1);
    let mut cy = DMatrix::zeros(1, n);
    cy.view_mut((0, 0), (1, ng)).copy_from(g.c());
    if coloured {
        // x_e⁺ = 0.8·x_e + e, y += 1.3·x_e + e: H = 1 + 1.3q⁻¹/(1 − 0.8q⁻¹).
        a[(ng, ng)] = 0.8;
        be[(ng, 0)] = 1.0;
        cy[(0, ng)] = 1.3;
    }
    // The nominal y = G·u + H·e; the map goes ahead of G.
    let nominal = Lft::new(LftMatrices {
        a,
        bu,
        be,
        bw: DMatrix::zeros(n, 0),
        cy,
        dyu: g.d().clone(),
        dye: DMatrix::from_element(1, 1, 1.0),
        dyw: DMatrix::zeros(1, 0),
        cz: DMatrix::zeros(0, n),
        dzu: DMatrix::zeros(0, 1),
        dze: DMatrix::zeros(0, 1),
        dzw: DMatrix::zeros(0, 0),
    })?;
    let model = Structure::hammerstein(nominal, dispersion).model()?;
    let noise = gaussian_noise(len, 1, noise_std, seed.wrapping_add(1));
    let u = match excitation {
        Excitation::White => {
            let white = gaussian_noise(len, 1, 1.0, seed.wrapping_add(2));
            Signal::from_fn(len, 1, |k, _| 2.0 * (white.get(k, 0) * 0.8).tanh())
        }
        Excitation::Sine { periods } => Signal::from_fn(len, 1, |k, _| {
            2.0 * (2.0 * std::f64::consts::PI * periods * k as f64 / len as f64).sin()
        }),
    };
    let map = |z: &[f64]| nonlinearity(z[0]);
    Experiment::simulate(model, &[&map], u, noise)
}

/// A mixed model: y = G₁·tanh(u₁) + G₂·relay(u₂) + e, where [G₁ G₂] is a random stable 2-input
/// block of order 2 (spectral radius 0.8, reproducible from `seed`), relay(z) = 1 for z ≥ 0.3
/// and −0.5 otherwise, u₁ and u₂ white Gaussian of unit variance, and e white of standard
/// deviation 0.05. The block `smooth` (on u₁) has the dispersion `smooth`, the block `relay`
/// (on u₂) total variation: the problem of a smooth spring next to a friction with a jump.
///
/// ```
/// use std::sync::Arc;
/// use structid_core::{KernelDispersion, scenarios::mixed_hammerstein};
/// let exp = mixed_hammerstein(100, Arc::new(KernelDispersion::gaussian(0.4).unwrap()), 1).unwrap();
/// assert_eq!(exp.model.blocks().len(), 2);
/// ```
pub fn mixed_hammerstein(len: usize, smooth: Arc<dyn Dispersion>, seed: u64) -> Result<Experiment> {
    mixed_hammerstein_with_radius(len, smooth, 0.8, seed)
}

/// [`mixed_hammerstein`] with the spectral radius of the random LTI block.
///
/// ```
/// use std::sync::Arc;
/// use structid_core::{PolynomialDispersion, scenarios::mixed_hammerstein_with_radius};
/// let exp = mixed_hammerstein_with_radius(60, Arc::new(PolynomialDispersion::new(3).unwrap()), 0.4, 2).unwrap();
/// assert_eq!(exp.data.len(), 60);
/// ```
pub fn mixed_hammerstein_with_radius(
    len: usize,
    smooth: Arc<dyn Dispersion>,
    radius: f64,
    seed: u64,
) -> Result<Experiment> {
    let g = structid_lti::testing::random_stable_system(seed, 2, 2, 1, radius);
    let lft = maps_of_the_inputs(&g, 2)?;
    let blocks = vec![
        crate::model::NonlinearBlock::new("smooth", vec![0], 0, smooth),
        crate::model::NonlinearBlock::new(
            "relay",
            vec![1],
            1,
            Arc::new(crate::dispersion::total_variation::TotalVariation::new()),
        ),
    ];
    let model = crate::model::Model::new(lft, blocks)?;
    let u = gaussian_noise(len, 2, 1.0, seed + 1);
    let noise = gaussian_noise(len, 1, 0.05, seed + 2);
    let f = |z: &[f64]| z[0].tanh();
    let h = |z: &[f64]| relay(z[0]);
    Experiment::simulate(model, &[&f, &h], u, noise)
}

/// y = G·h(u₁, u₂) + e with h = 1[z₁ + z₂ > 0], G a random stable 2nd-order block (spectral
/// radius 0.9, reproducible from `seed`), u₁ and u₂ white Gaussian of unit variance, noise std
/// 0.1, and graph total variation on the two-input map: the `graph_tv_admm` benchmark.
///
/// ```
/// use structid_core::scenarios::graph_hammerstein;
/// let exp = graph_hammerstein(50, 5).unwrap();
/// assert_eq!(exp.model.blocks()[0].inputs, [0, 1]);
/// ```
pub fn graph_hammerstein(len: usize, seed: u64) -> Result<Experiment> {
    let g = structid_lti::testing::random_stable_system(seed, 2, 1, 1, 0.9);
    let lft = maps_of_the_inputs(&g, 2)?;
    let block = crate::model::NonlinearBlock::new(
        "h",
        vec![0, 1],
        0,
        Arc::new(crate::dispersion::total_variation::TotalVariation::new()),
    );
    let model = crate::model::Model::new(lft, vec![block])?;
    let u = gaussian_noise(len, 2, 1.0, seed + 1);
    let noise = gaussian_noise(len, 1, 0.1, seed + 2);
    let h = |z: &[f64]| if z[0] + z[1] > 0.0 { 1.0 } else { 0.0 };
    Experiment::simulate(model, &[&h], u, noise)
}

/// The LFT of maps that read the `inputs` measured inputs directly (z = u) and drive the LTI
/// block `g` (w → y, one output), with white noise on y: y = G·N(u) + e.
fn maps_of_the_inputs(g: &structid_lti::StateSpace, inputs: usize) -> Result<Lft> {
    let (n, nw) = (g.order(), g.b().ncols());
    Lft::new(LftMatrices {
        a: g.a().clone(),
        bu: DMatrix::zeros(n, inputs),
        be: DMatrix::zeros(n, 1),
        bw: g.b().clone(),
        cy: g.c().clone(),
        dyu: DMatrix::zeros(1, inputs),
        dye: DMatrix::identity(1, 1),
        dyw: g.d().clone(),
        cz: DMatrix::zeros(inputs, n),
        dzu: DMatrix::identity(inputs, inputs),
        dze: DMatrix::zeros(inputs, 1),
        dzw: DMatrix::zeros(inputs, nw),
    })
}

/// The relay of the total-variation problems: 1 for z ≥ 0.3 and −0.5 below, a jump that no
/// smooth dispersion follows.
pub fn relay(z: f64) -> f64 {
    if z >= 0.3 { 1.0 } else { -0.5 }
}

/// The total-variation benchmark (`cargo bench --bench total_variation`, the `tv_scaling`
/// example): [`hammerstein_map`] with a 2nd-order G, the [`relay`] map, noise std 0.1, total
/// variation and seed 7.
pub fn relay_hammerstein(len: usize, excitation: Excitation) -> Result<Experiment> {
    hammerstein_map(
        len,
        2,
        0.1,
        &relay,
        excitation,
        Arc::new(crate::dispersion::total_variation::TotalVariation::new()),
        7,
    )
}

/// The feature-space solver's benchmark (`cargo bench --bench features`, the `feature_scaling`
/// example, BENCHMARKS.md): [`hammerstein_coloured`] with a 4th-order G, noise std 0.3 and seed
/// 11, a Gaussian-like Fourier dispersion (σ = 0.2, 31 harmonics: m = 63 features), and the
/// settings it is timed with (β = 10⁻⁴, the feature-space solver).
pub fn feature_benchmark(len: usize) -> Result<(Experiment, IdentifySettings)> {
    let disp =
        FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.2 })?.with_harmonics(31);
    let exp = hammerstein_coloured(len, 4, 0.3, Arc::new(disp), 11)?;
    let settings = IdentifySettings::builder()
        .beta(1e-4)
        .solver(SolverChoice::Features)
        .build()?;
    Ok((exp, settings))
}

/// The exact Gaussian solver's benchmark (`cargo bench --bench identify`, the `identify_timing`
/// example, BENCHMARKS.md): [`hammerstein`] with a 4th-order G, noise std 0.1, a Gaussian
/// dispersion of σ = 0.2 and seed 42, and the β it is timed with, 10⁻³.
pub fn gaussian_benchmark(len: usize) -> Result<(Experiment, IdentifySettings)> {
    let exp = hammerstein(len, 4, 0.1, Arc::new(KernelDispersion::gaussian(0.2)?), 42)?;
    let settings = IdentifySettings::builder().beta(1e-3).build()?;
    Ok((exp, settings))
}
