//! # structid-joint: whole-model fitting by simulation error
//!
//! The paper's identification (Hsu, Vincent, Wemhoff and Poolla, 2006) needs the maps' inputs
//! z to be computable from u and y (its Definition 1) and D_zw = 0. This crate fits models
//! outside that class, all at once and by their simulation error:
//!
//! - **maps in series**: D_zw ≠ 0 without a cycle; the blocks are evaluated in the order of
//!   their dependencies ([`structid_core::Lft::evaluation_order`]);
//! - **latent maps**: a block may read any signal of the LFT, a state that is not measured
//!   included;
//! - **dynamic blocks**: hysteresis operators with an internal state;
//! - **G's free entries** alongside the maps (the rest of G, an integrator's entries for
//!   instance, held fixed).
//!
//! The model ([`JointModel`]) is the LFT
//!
//! ```text
//!   x⁺ = A·x + B_u·u + B_w·w,   y = C_y·x + D_yu·u + D_yw·w,   z = C_z·x + D_zu·u + D_zw·w
//!   w_b = N_b(z_b; θ_b, s_b)      (block b, with state s_b for an operator)
//! ```
//!
//! with parameters θ = [free entries of G | θ₁ | θ₂ | …]. A nonparametric map is a kernel
//! expansion on fixed centres ([`GaussianFeatures`]) whose dispersion D_b = θ_bᵀK_ccθ_b is the
//! paper's RKHS norm, so [`fit`](crate::fit()) minimises the paper's criterion with the
//! noise replaced by the simulation error:
//!
//! ```text
//!   J(θ, ξ₀) = (1/L)·Σ_k |y_k − ŷ_k(θ, ξ₀)|² + Σ_b β_b·D_b(θ_b)
//! ```
//!
//! ŷ is the simulation from u alone, from the stacked initial state ξ₀ = [x₀; s₀] of each
//! record, which is fitted too. The minimisation is Levenberg–Marquardt with multiple shooting
//! ([`shooting`]) and Jacobians by forward sensitivities ([`step`]), followed by a
//! single-shooting polish; the result never has a higher J than the start.
//!
//! ## Example: a Hammerstein model with its pole and its map fitted together
//! ```
//! use nalgebra::dmatrix;
//! use structid_core::{Data, Lft, LftMatrices, Signal};
//! use structid_joint::{fit, GaussianFeatures, JointBlock, JointModel, JointSettings, LftMatrix};
//! let lft = |a: f64| Lft::new(LftMatrices {
//!     a: dmatrix![a], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![1.0],
//!     cy: dmatrix![1.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0],
//!     cz: dmatrix![0.0], dzu: dmatrix![1.0], dze: dmatrix![0.0], dzw: dmatrix![0.0],
//! }).unwrap();
//! // The truth: x⁺ = 0.8·x + tanh(2u), y = x.
//! let u = Signal::from_fn(400, 1, |k, _| ((k as f64) * 0.37).sin() * 1.5);
//! let truth = lft(0.8).simulate(&[structid_core::MapBinding {
//!     inputs: &[0], output: 0, map: &|z: &[f64]| (2.0 * z[0]).tanh() }], &u, None, None).unwrap();
//! let data = Data::new(u, truth.y).unwrap();
//! // Start from a = 0.5 and a linear map.
//! let n = GaussianFeatures::on_interval(-1.5, 1.5, 9, 0.4, 1e-9).unwrap();
//! let start = JointModel::new(lft(0.5), vec![JointBlock::new("N", vec![0], 0, Box::new(n))])
//!     .unwrap().with_free(LftMatrix::A, 0, 0).unwrap();
//! let out = fit(&start, &data, None, &JointSettings::default()).unwrap();
//! assert!(out.cost < 1e-3 * out.initial_cost);
//! assert!((out.model.lft().matrices().a[(0, 0)] - 0.8).abs() < 1e-2);
//! ```

pub mod block;
pub mod error;
pub mod family;
pub mod features;
pub mod fit;
pub mod fixed;
pub mod fourier_features;
pub mod hammerstein_wiener;
pub mod latent;
pub mod model;
pub mod monotone;
pub mod operator;
pub mod shooting;
pub mod step;
pub mod wiener_hammerstein;
pub mod windowed;

pub use block::{BlockJacobian, BlockMap};
pub use error::{JointError, Result};
pub use family::FamilyMap;
pub use features::{GaussianFeatures, LinearInParameters};
pub use fit::{JointFit, JointSettings, JointSettingsBuilder, Stage, fit, fit_initial_state};
pub use fixed::{FixedMap, HeldMap};
pub use fourier_features::FourierFeatures;
pub use hammerstein_wiener::{hammerstein_wiener_model, hammerstein_wiener_start};
pub use latent::{SmoothedMaps, smooth_maps};
pub use model::{JointBlock, JointModel, LftEntry, LftMatrix};
pub use monotone::MonotoneFeatures;
pub use operator::OperatorBlock;
pub use wiener_hammerstein::{
    SplitScore, WienerHammersteinSettings, WienerHammersteinSettingsBuilder,
    WienerHammersteinStart, wiener_hammerstein_model, wiener_hammerstein_start,
};
