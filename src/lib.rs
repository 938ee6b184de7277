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
//! * [`plot`] — SVG figures;
//! * [`linear`] — estimating the linear part: ARX, output error, order selection, periodic BLA;
//! * [`silverbox`] — the Silverbox benchmark pipeline end to end.
//!
//! ```
//! use std::sync::Arc;
//! use structid::{identify, paper, IdentifySettings, KernelDispersion};
//! let exp = paper::spray(500, 1.0, Arc::new(KernelDispersion::gaussian(0.1).unwrap()), 1).unwrap();
//! let id = identify(&exp.model, &exp.data, &IdentifySettings::default()).unwrap();
//! println!("J = {:.4}", id.cost.total);
//! ```

mod pipeline;
pub mod silverbox;
pub mod silverbox_discovery;
pub mod tanks;

pub use structid_core::*;
pub use structid_io as io;
pub use structid_linear as linear;
pub use structid_lti as lti;
pub use structid_plot as plot;
