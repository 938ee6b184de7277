//! # structid
//!
//! Structured nonlinear system identification: a system is an interconnection of **known** LTI
//! blocks and **unknown static** maps, written as one LFT; identification finds the maps by
//! minimising J = (1/L)·Σ|e_k|² + β·Σ_i D_i(z^\[i\], w^\[i\]) over all signals consistent with the
//! data (Hsu, Vincent, Wemhoff & Poolla, IFAC SYSID 2006).
//!
//! This facade re-exports the workspace crates:
//! * [`lti`] — linear systems: state space, transfer functions, ZOH, recursive Toeplitz operators;
//! * the core (re-exported at the top level) — the LFT model, measurability, dispersions and
//!   kernels, [`identify()`], simulation with maps in the loop;
//! * [`io`] — model files (TOML), data files (CSV), reports and atomic output;
//! * `plot` — SVG figures (the default feature `plot`; leave it out with
//!   `default-features = false` to build without plotters);
//! * [`linear`] — estimating the linear part: ARX, output error, order selection, periodic BLA;
//! * [`discover`] — the discovery workflow: what a nominal model is missing, where, and which effect;
//! * [`nalgebra`] and [`faer`] — the versions the public types use, so that a program needs only
//!   `structid` in its Cargo.toml;
//! * [`prelude`] — the names a typical program uses.
//!
//! The benchmark protocols (Silverbox, Cascaded Tanks) live in the unpublished crate
//! `structid-benchmarks` of the workspace, with their tests and examples.
//!
//! A Hammerstein model y = G·N(u) + e, fitted and kept as an [`Estimate`], with nothing but
//! `structid` in Cargo.toml:
//!
//! ```
//! use std::sync::Arc;
//! use structid::prelude::*;
//! // y = G·N(u) + e with G(q) = q⁻¹/(1 − 0.5q⁻¹): one line for the structure.
//! let g = PolynomialModel { num: vec![vec![0.0, 1.0]], den: vec![1.0, -0.5], sample_time: None };
//! let model = Structure::hammerstein(&g, Arc::new(KernelDispersion::gaussian(0.3).unwrap()))
//!     .model()
//!     .unwrap();
//! let u = Signal::from_fn(400, 1, |k, _| 2.0 * (0.37 * k as f64).sin());
//! let truth = |z: &[f64]| z[0].clamp(-1.0, 1.0);
//! let y = model.simulate(&[&truth], &u, None, None).unwrap().y;
//! let data = Data::new(u, y).unwrap();
//! let estimate = model.fit(&data, &IdentifySettings::builder().beta(1e-5).build().unwrap()).unwrap();
//! let fresh = Signal::from_fn(200, 1, |k, _| 1.5 * (0.11 * k as f64).cos());
//! let y_hat = estimate.simulate(&fresh, None).unwrap().y;
//! let y_true = model.simulate(&[&truth], &fresh, None, None).unwrap().y;
//! let err = (0..200).map(|k| (y_hat.get(k, 0) - y_true.get(k, 0)).abs()).fold(0.0, f64::max);
//! assert!(err < 0.05, "max error {err}");
//! ```

pub use structid_core::*;
pub use structid_discover as discover;
pub use {faer, nalgebra};

/// The names a typical program uses: the model, the data, the dispersions, identification,
/// the fitted [`Estimate`] and its settings.
pub mod prelude {
    pub use structid_core::estimate::{Estimate, Prediction, PredictionSettings};
    pub use structid_core::validation::{ValidationSettings, validate};
    pub use structid_core::{
        Data, Dispersion, FourierDispersion, FourierWeights, GaussianKernel, IdentifySettings,
        Interpolant, KernelDispersion, Lft, LftMatrices, Model, NonlinearBlock,
        PolynomialDispersion, Signal, Site, SolverChoice, Structure, SumDispersion, TotalVariation,
        identify,
    };
    pub use structid_linear::PolynomialModel;
}
pub use structid_io as io;
/// Whole-model fitting by simulation error: maps in series, latent maps, hysteresis operators.
pub use structid_joint as joint;
pub use structid_linear as linear;
pub use structid_lti as lti;
/// SVG figures: charts, grids of charts and heat maps (feature `plot`, on by default).
#[cfg(feature = "plot")]
pub use structid_plot as plot;
/// The workflows under the command-line tool and Python, as typed requests and results
/// (feature `workflow`, on by default; it writes figures, so it brings `plot` with it).
#[cfg(feature = "workflow")]
pub use structid_workflow as workflow;

#[cfg(doctest)]
mod readme_doctests;
