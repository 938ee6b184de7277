//! Linear time-invariant (LTI) systems for `structid`.
//!
//! # Model
//! A discrete-time state-space system ([`StateSpace`]) is
//!
//! ```text
//! x_{k+1} = A x_k + B u_k,      y_k = C x_k + D u_k,      x_0 = 0,
//! ```
//!
//! with `n` states, `m` inputs and `p` outputs. Over a horizon of `L` samples it is the
//! linear map `y = T u` where `u` and `y` are *stacked* signals in time-major order
//! (index `k * channels + c`, see [`Signal`]) and `T` is the `(L p) x (L m)` block
//! lower-triangular Toeplitz matrix of the Markov parameters
//!
//! ```text
//! h_0 = D,   h_j = C A^{j-1} B  (j >= 1),     T[i, j] = h_{i-j}  for i >= j, 0 otherwise.
//! ```
//!
//! The adjoint `T^T` is block *upper* triangular; it corresponds to running the
//! transposed system backwards in time: with the costate `s_L = 0`,
//! `u_k = D^T y_k + B^T s_{k+1}`, `s_k = A^T s_{k+1} + C^T y_k`.
//!
//! # Why recursion
//! Forming `T` costs `O(L^2 p m)` memory and every product `O(L^2 p m)` flops. The
//! recursion above costs `O(L n (n + m + p))` per signal and no memory beyond the state, so
//! [`LinearSystem::apply`] and [`LinearSystem::apply_adjoint`] never form `T`
//! ([`StateSpace::toeplitz_dense`] exists only as a test reference). When many signals are
//! processed at once ([`LinearSystem::apply_columns`]), a *blocked* recursion groups `b`
//! time steps into small dense matrix products so that SIMD matrix multiplication does the
//! work.
//!
//! # Contents
//! - [`Signal`]: multichannel sampled signals (time-major);
//! - [`StateSpace`], [`ContinuousStateSpace`] (with zero-order-hold discretisation);
//! - [`TransferFunction`] / [`Siso`]: transfer matrices in `q^-1`, their realisation and
//!   simulation; [`realise_row`] / [`filter_row`]: the same for a common-denominator row
//!   (the polynomial models of `structid-linear`);
//! - [`LinearSystem`]: the operator trait used by the solvers; [`Recordwise`]: one operator
//!   applied to several records, restarted from rest at each record;
//! - [`DisturbanceSmoother`] (module [`smoother`]): the posterior mean of the inputs of a
//!   system given exact outputs (disturbance smoother, zero or free initial state);
//! - [`KalmanWhitener`] (module [`kalman`]): the whitening operator `W` of a noise path,
//!   `W^T W = (T T^T)^{-1}`, applied by a time-varying Kalman filter;
//! - [`LtiError`]: the error type;
//! - [`testing`]: deterministic random systems and signals for tests and benchmarks.

pub mod error;
pub mod kalman;
mod long;
mod minimal;
pub mod operator;
pub mod records;
mod riccati;
pub mod signal;
pub mod smoother;
pub mod state_space;
pub mod stream;
pub mod testing;
pub mod transfer_function;

pub use error::LtiError;
pub use kalman::{
    KalmanWhitener, WhiteningOptions, WhiteningStream, steady_state_whitening_filter,
};
pub use operator::LinearSystem;
pub use records::Recordwise;
pub use signal::Signal;
pub use smoother::{DisturbanceSmoother, SmoothReport, SmootherInitial};
pub use state_space::{ContinuousStateSpace, StateSpace};
pub use stream::ColumnStream;
pub use transfer_function::{Siso, TransferFunction, filter_row, realise_row};

#[cfg(test)]
mod tests;
