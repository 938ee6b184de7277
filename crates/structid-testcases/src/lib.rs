//! # structid-testcases: the generators of structid's discovery tests
//!
//! Not published: the crates' tests, examples and benches use it as a dev-dependency, so that
//! the published library carries no test generator.
//!
//! * [`synthetic`]: a random nominal model plus records of a system with one hidden effect (a
//!   static effect at a location, none, or hysteresis), deterministic in a seed, simulated with
//!   the very LFT the workflow hypothesises;
//! * [`physics`]: plants from continuous-time physics (integrators in closed loop, two-mass
//!   plants, delays, coloured noise, estimated nominals) integrated by RK4 and sampled, and the
//!   closed-loop positioning axis;
//! * [`parallel`]: independent cases on every core.

pub mod parallel;
pub mod physics;
pub mod synthetic;
