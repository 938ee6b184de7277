//! Synthetic identification problems used by benchmarks, timing examples and tests.

use std::sync::Arc;

use nalgebra::DMatrix;
use structid_lti::Signal;

use crate::dispersion::Dispersion;
use crate::error::Result;
use crate::lft::{Lft, LftMatrices};
use crate::model::{Model, NonlinearBlock};
use crate::paper::{Experiment, gaussian_noise};

/// A SISO Hammerstein system y = G(q)·N(u) + e with a random stable G of the given order
/// (spectral radius 0.9, reproducible from `seed`), N = tanh, u uniform on [−2, 2] and white
/// noise of standard deviation `noise_std`.
pub fn hammerstein(
    len: usize,
    order: usize,
    noise_std: f64,
    dispersion: Arc<dyn Dispersion>,
    seed: u64,
) -> Result<Experiment> {
    let g = structid_lti::testing::random_stable_system(seed, order, 1, 1, 0.9);
    let n = g.order();
    let lft = Lft::new(LftMatrices {
        a: g.a().clone(),
        bu: DMatrix::zeros(n, 1),
        be: DMatrix::zeros(n, 1),
        bw: g.b().clone(),
        cy: g.c().clone(),
        dyu: DMatrix::zeros(1, 1),
        dye: DMatrix::from_element(1, 1, 1.0),
        dyw: g.d().clone(),
        cz: DMatrix::zeros(1, n),
        dzu: DMatrix::from_element(1, 1, 1.0),
        dze: DMatrix::zeros(1, 1),
        dzw: DMatrix::zeros(1, 1),
    })?;
    let model = Model::new(lft, vec![NonlinearBlock::new("N", vec![0], 0, dispersion)])?;
    let noise = gaussian_noise(len, 1, noise_std, seed.wrapping_add(1));
    let u = {
        let white = gaussian_noise(len, 1, 1.0, seed.wrapping_add(2));
        Signal::from_fn(len, 1, |k, _| 2.0 * (white.get(k, 0) * 0.8).tanh())
    };
    let map = |z: &[f64]| z[0].tanh();
    Experiment::simulate(model, &[&map], u, noise)
}
