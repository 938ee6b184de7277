//! Solvers for the identification problem. Each takes a [`crate::Problem`] and settings and
//! returns an [`crate::Identification`]; [`crate::identify()`] chooses between them.

pub mod exact;
pub mod features;
