//! # structid-workflow: the workflows under the command-line tool and Python
//!
//! Each workflow is a typed request in, a typed result out, and a writer of its output files,
//! so that `structid` (the CLI) only parses arguments and prints, and the Python package only
//! converts arrays: both run the same code and get the same numbers.
//!
//! | module | workflow |
//! |---|---|
//! | [`identify`](mod@identify) | a model file's maps identified from records, with β and σ given or selected (`structid identify`) |
//! | [`refine`](mod@refine) | the linear part G of a one-map model refined by alternation with the map (`structid refine`) |
//! | [`refine_files`] | the records of a refinement (validation files or a held-out fraction), its files (refine.csv, refine.svg, linear.svg, model.toml and the estimate's) and the summaries of `structid refine` and `structid refine --joint` |
//! | [`options`] | an identification's options (β, solver, tolerance, iterations, memory budget) checked the same way for every front end |
//! | [`discover`](mod@discover) | what a nominal model file is missing, for one effect or several in turn (`structid discover`), with its options checked once |
//! | [`joint`] | a model file fitted as a whole by its simulation error (`structid refine --joint`), and the simulation of model files with hysteresis operators |
//! | [`wiener_hammerstein`](mod@wiener_hammerstein) | block-structured models with every block unknown, from data: Wiener–Hammerstein (`structid wiener-hammerstein`) and Hammerstein–Wiener (`structid hammerstein-wiener`) |
//! | [`validate`](mod@validate) | validation on records of a model file's true maps or of an estimate rebuilt from an older identify directory, one record or several pooled (`structid validate`) |
//! | [`stored`] | the workflows of a stored estimate (estimate.json): validation, simulation and k-step-ahead prediction (`structid validate --estimate FILE.json`, `structid simulate --estimate`, `structid predict`) |
//! | [`validation_files`] | the files and lines of a validation: simulation.csv's columns, the simulation and residual figures, the per-output part of validation.json and the summary's wording |
//! | [`simulate`](mod@simulate) | a model file simulated with its true maps, written as u, y, z and w columns (`structid simulate --model`) |
//! | [`simulation_score`] | validation by simulation alone of a model with a latent block or an operator (`structid validate` of such a model) |
//! | [`linear`](mod@linear) | the linear part G from records, orders given or selected, ARX or output error, written as a model file with a map at a site (`structid linear`) |
//! | [`linear_start`] | discovery from a record alone: the best linear approximation as the nominal model, [`structid_discover`]'s search for what it is missing, and test records scored with both (the Silverbox discovery in Python) |
//! | [`discover_report`] | the reports of a discovery: report.md, report.json and the summary `structid discover` prints (the presentation of [`structid_discover`]'s results, which carry data only) |
//! | [`free`] | the free entries of G, as the CLI and Python name them (`A`, `Bw[1][0]`) |
//! | [`compare`] | comparison sweeps of dispersions, β values and noise seeds: the cases, each case's identification and scores, and the tables of their results (`structid compare`) |
//! | [`estimate_files`] | the files of an estimate (estimate.json, estimate.csv, a table and a figure per block, report.json) and the summary `structid identify` prints |
//! | [`demo`] | the paper's examples end to end: data, model file, identification and figures (`structid demo spray`, `structid demo multi-input`) |
//! | [`figures`] | the SVG figures of estimated maps (`map_<block>.svg`) and of linear parts (linear.svg) |
//! | [`paths`] | paths as reports name them, file-name-safe block names, and the inputs a command must not overwrite |
//! | [`records`] | data files read as records, with the signals a `--vars` selection picks |
//! | [`grid`] | grids over a signal's range, on which maps are evaluated for tables and figures |
//! | [`text`] | numbers as the reports and summaries print them (β with four significant digits) |

pub mod compare;
pub mod demo;
pub mod discover;
pub mod discover_report;
pub mod error;
pub mod estimate_files;
pub mod figures;
pub mod free;
pub mod grid;
pub mod identify;
pub mod joint;
pub mod linear;
pub mod linear_start;
pub mod options;
pub mod paths;
pub mod records;
pub mod refine;
pub mod refine_files;
pub mod remedy;
pub mod simulate;
pub mod simulation_score;
pub mod stored;
pub mod text;
pub mod validate;
pub mod validation_files;
pub mod wiener_hammerstein;

pub use discover::{
    DiscoverOptions, DiscoverOutcome, DiscoverRequest, discover_model_file, nominal_model,
};
pub use error::{Result, WorkflowError};
pub use free::parse_free;
pub use identify::{
    IdentifyOutcome, IdentifyRequest, core_model, default_criterion, identify_model_file,
};
pub use joint::{
    BetaChoice, BetaTrial, FitOptions, JointOutcome, JointRequest, JointWorkflowSettings, MapTable,
    refine_joint, simulate_model_file, simulate_model_file_noisy, write_joint_outputs,
};
pub use linear::{
    LinearMethod, LinearOutcome, LinearRequest, MapKind, MapRequest, OrderChoice, fit_linear,
};
pub use linear_start::{
    LinearStartDiscovery, LinearStartRequest, TestScore, discover_from_linear_start,
    split_for_validation,
};
pub use options::SolveOptions;
pub use refine::{RefineOutcome, RefineRequest, as_linear, refine_model_file};
pub use remedy::{Remedy, remedy};
pub use simulation_score::{SimulationScore, score_simulation, why_simulation_only};
pub use wiener_hammerstein::{
    BlockStructure, WienerHammersteinOutcome, WienerHammersteinRequest, wiener_hammerstein,
    write_wiener_hammerstein_outputs,
};
