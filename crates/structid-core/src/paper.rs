//! The examples of Hsu, Vincent, Wemhoff & Poolla (2006), section 6, as data generators.
//!
//! They are used by `examples/`, by `structid demo` and by the integration tests, so the three
//! always run the same experiment.

use std::sync::Arc;

use nalgebra::{DMatrix, dmatrix};
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};
use structid_lti::Signal;

use crate::dispersion::{Dispersion, KernelDispersion};
use crate::error::Result;
use crate::model::lft::{Lft, LftMatrices};
use crate::model::{Data, Model, NonlinearBlock};

/// f(z) = −|z|, the first map of the spray-deposition example.
pub fn spray_f(z: f64) -> f64 {
    -z.abs()
}

/// g(z) = 0.5·(sin((3z)²) + (2z)² − 2), the second map of the spray-deposition example.
pub fn spray_g(z: f64) -> f64 {
    0.5 * ((3.0 * z).powi(2).sin() + (2.0 * z).powi(2) - 2.0)
}

/// A generated experiment: the model (with the dispersions it was built with), the data and
/// the noise-free map outputs.
#[derive(Clone, Debug)]
pub struct Experiment {
    /// The structured model.
    pub model: Model,
    /// The simulated record.
    pub data: Data,
    /// The true w (L × n_w).
    pub w_true: Signal,
    /// The noise that was added (L × n_e).
    pub noise: Signal,
}

impl Experiment {
    /// Simulates `model` with the true `maps` in the loop, input `u` and noise `noise`.
    pub fn simulate(
        model: Model,
        maps: &[&dyn crate::Interpolant],
        u: Signal,
        noise: Signal,
    ) -> Result<Self> {
        let sim = model.simulate(maps, &u, Some(&noise), None)?;
        Ok(Self {
            data: Data::new(u, sim.y)?,
            w_true: sim.w,
            noise,
            model,
        })
    }
}

/// The LFT of the spray example (section 6.1): y_k = f(u_k) + g(u_{k−2}) + e_k, z = u,
/// L_yw = [1, q⁻²].
pub fn spray_lft() -> Lft {
    Lft::new(LftMatrices {
        a: dmatrix![0.0, 0.0; 1.0, 0.0],
        bu: DMatrix::zeros(2, 1),
        be: DMatrix::zeros(2, 1),
        bw: dmatrix![0.0, 1.0; 0.0, 0.0],
        cy: dmatrix![0.0, 1.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![1.0, 0.0],
        cz: DMatrix::zeros(1, 2),
        dzu: dmatrix![1.0],
        dze: dmatrix![0.0],
        dzw: DMatrix::zeros(1, 2),
    })
    .expect("the spray LFT is consistent")
}

/// The spray-deposition experiment: u_k = sin(0.1k), e ~ N(0, noise_std²), blocks `f` and `g`
/// with the given dispersion.
pub fn spray(
    len: usize,
    noise_std: f64,
    dispersion: Arc<dyn Dispersion>,
    seed: u64,
) -> Result<Experiment> {
    let lft = spray_lft();
    let model = Model::new(
        lft,
        vec![
            NonlinearBlock::new("f", vec![0], 0, Arc::clone(&dispersion)),
            NonlinearBlock::new("g", vec![0], 1, dispersion),
        ],
    )?;
    let u = Signal::from_fn(len, 1, |k, _| (0.1 * k as f64).sin());
    let noise = gaussian_noise(len, 1, noise_std, seed);
    let f = |z: &[f64]| spray_f(z[0]);
    let g = |z: &[f64]| spray_g(z[0]);
    Experiment::simulate(model, &[&f, &g], u, noise)
}

/// The smooth two-input map used for the multi-input example (the paper does not give one):
/// N(z₁, z₂) = sin(z₁)·exp(−0.3·z₂²) + 0.2·z₂.
pub fn multi_input_map(z: &[f64]) -> f64 {
    z[0].sin() * (-0.3 * z[1] * z[1]).exp() + 0.2 * z[1]
}

/// The multi-input experiment of section 6.2: a random stable L_yu with three states and two
/// inputs, i.i.d. uniform inputs with mean 0 and variance 1.5, a two-input static map of z = u
/// feeding y through L_yw = 1 + 0.5q⁻¹/(1 − 0.5q⁻¹), and e ~ N(0, noise_std²).
pub fn multi_input(
    len: usize,
    noise_std: f64,
    dispersion: Arc<dyn Dispersion>,
    seed: u64,
) -> Result<Experiment> {
    let g = structid_lti::testing::random_stable_system(seed, 3, 2, 1, 0.8);
    let n = g.order() + 1;
    let mut a = DMatrix::zeros(n, n);
    a.view_mut((0, 0), (3, 3)).copy_from(g.a());
    a[(3, 3)] = 0.5;
    let mut bu = DMatrix::zeros(n, 2);
    bu.view_mut((0, 0), (3, 2)).copy_from(g.b());
    let mut bw = DMatrix::zeros(n, 1);
    bw[(3, 0)] = 1.0;
    let mut cy = DMatrix::zeros(1, n);
    cy.view_mut((0, 0), (1, 3)).copy_from(g.c());
    cy[(0, 3)] = 0.5;
    let lft = Lft::new(LftMatrices {
        a,
        bu,
        be: DMatrix::zeros(n, 1),
        bw,
        cy,
        dyu: g.d().clone(),
        dye: dmatrix![1.0],
        dyw: dmatrix![1.0],
        cz: DMatrix::zeros(2, n),
        dzu: DMatrix::identity(2, 2),
        dze: DMatrix::zeros(2, 1),
        dzw: DMatrix::zeros(2, 1),
    })?;
    let model = Model::new(
        lft,
        vec![NonlinearBlock::new("N", vec![0, 1], 0, dispersion)],
    )?;
    let half_width = (3.0f64 * 1.5).sqrt();
    let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed_1234);
    let u = Signal::from_fn(len, 2, |_, _| rng.random_range(-half_width..half_width));
    let noise = gaussian_noise(len, 1, noise_std, seed.wrapping_add(17));
    let map = |z: &[f64]| multi_input_map(z);
    Experiment::simulate(model, &[&map], u, noise)
}

/// Gaussian white noise N(0, std²), reproducible from `seed`.
pub fn gaussian_noise(len: usize, channels: usize, std: f64, seed: u64) -> Signal {
    let mut rng = StdRng::seed_from_u64(seed);
    let normal =
        Normal::new(0.0, std.max(0.0)).unwrap_or_else(|_| Normal::new(0.0, 0.0).expect("valid"));
    Signal::from_fn(len, channels, |_, _| normal.sample(&mut rng))
}

/// A Gaussian dispersion as a trait object (convenience for the examples).
pub fn gaussian(sigma: f64) -> Result<Arc<dyn Dispersion>> {
    Ok(Arc::new(KernelDispersion::gaussian(sigma)?))
}
