//! Synthetic identification problems used by benchmarks, timing examples and tests.

use std::sync::Arc;

use nalgebra::DMatrix;
use structid_lti::Signal;

use crate::dispersion::Dispersion;
use crate::error::Result;
use crate::lft::{Lft, LftMatrices};
use crate::paper::{Experiment, gaussian_noise};
use crate::structure::Structure;

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
    hammerstein_with_noise(len, order, noise_std, false, dispersion, seed)
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
    hammerstein_with_noise(len, order, noise_std, true, dispersion, seed)
}

fn hammerstein_with_noise(
    len: usize,
    order: usize,
    noise_std: f64,
    coloured: bool,
    dispersion: Arc<dyn Dispersion>,
    seed: u64,
) -> Result<Experiment> {
    build_hammerstein(
        len,
        order,
        noise_std,
        coloured,
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
