//! Comparison sweeps of dispersions, β values and noise seeds (`structid compare`).
//!
//! The configuration ([`structid_io::sweep_file`]) lists experiments (a model file with
//! measured or simulated data, [`config`]) and dispersions (a kind, its parameters and β
//! values); every combination, with every seed of a simulated experiment, is a case
//! ([`cases`]). Each case is identified, its β selected when asked, and scored against the
//! truth and on the validation record ([`case`]); its record ([`results`]) holds every number
//! of its table row and of its figures, so that a directory of case files determines the
//! tables completely. The front end runs the cases (in parallel, resuming, in shards) and
//! draws the figures.

pub mod case;
pub mod cases;
pub mod config;
pub mod results;
