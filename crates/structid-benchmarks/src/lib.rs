//! The benchmark protocols of structid: the Silverbox and Cascaded Tanks pipelines end to end,
//! with the constants tuned for those records. They are examples of how to use the library on
//! real data, kept in this unpublished crate with their integration tests (which need the
//! benchmark files; see `shared/data` or `STRUCTID_DATA`) and examples
//! (`cargo run --release -p structid-benchmarks --example silverbox`).

mod pipeline;
pub mod silverbox;
pub mod silverbox_discovery;
pub mod silverbox_joint;
pub mod tanks;
pub mod tanks_physical;
pub mod wiener_hammerstein;
