//! # structid-io: files in and out of structid
//!
//! * [`ModelFile`]: the model file (TOML) — the known linear block of the LFT, the names of
//!   the data columns and the unknown static maps with their dispersions and, optionally,
//!   their true maps. Every error names the line of the offending key. See [`model_file`] for
//!   the format.
//! * [`DataTable`]: data files (CSV with a header row); errors name the line and the column.
//!   [`DataTable::read_with`] with [`CsvOptions`] reads other layouts (delimiter, no header,
//!   leading lines to skip) and selects, orders and renames columns ([`ColumnRef`]).
//! * [`array_file`]: MATLAB MAT-files (v5, compressed or not) and NumPy `.npy` / `.npz`
//!   files; [`DataTable::read`] recognises them by their first bytes, and
//!   [`DataTable::read_vars`] picks and names the signals ([`Vars`], e.g. `u=vir,y=qm`).
//! * [`benchmarks`]: loaders of the Silverbox ([`Silverbox`]) and cascaded-tanks
//!   ([`CascadedTanks`]) benchmark files with their official splits as [`Record`]s.
//! * [`OutputGuard`] / [`write_atomic`]: atomic writes that refuse to overwrite an input file,
//!   output locations checked before any work, stale temporary files of killed runs removed,
//!   and result sets marked complete only once written in full ([`output::COMPLETE_MARKER`]).
//! * [`Report`]: the `report.json` of an identification; [`ReportRecord`] reads one back.
//! * [`SweepFile`]: the sweep configuration of `structid compare` (experiments × dispersions ×
//!   β values × seeds); errors name the line. See [`sweep_file`] for the format.
//!
//! ```
//! use structid_core::{identify, IdentifySettings};
//! use structid_io::{DataTable, ModelFile};
//! let model = ModelFile::parse(r#"
//!     [lft]
//!     A = []
//!     Dye = [[1.0]]
//!     Dyw = [[1.0]]
//!     Dzu = [[1.0]]
//!     [signals]
//!     u = ["u"]
//!     y = ["y"]
//!     [[nonlinearity]]
//!     name = "N"
//!     inputs = [0]
//!     output = 0
//!     dispersion = { kind = "gaussian", sigma = 0.5 }
//!     truth = "z0^2"
//! "#, None).unwrap();
//! let mut csv = String::from("u,y\n");
//! for k in 0..50 {
//!     let u = -2.0 + 4.0 * k as f64 / 49.0;
//!     csv.push_str(&format!("{u},{}\n", u * u));
//! }
//! let data = model.select_data(&DataTable::parse(&csv, None).unwrap()).unwrap();
//! let settings = IdentifySettings::builder().beta(1e-4).build().unwrap();
//! let id = identify(&model.to_model(None, None).unwrap(), &data, &settings).unwrap();
//! assert!((id.blocks[0].predict(&[1.0]) - 1.0).abs() < 0.05, "{}", id.blocks[0].predict(&[1.0]));
//! ```

pub mod array_file;
pub mod benchmarks;
pub mod data_file;
pub mod echo;
pub mod error;
pub mod estimate_file;
pub mod model_file;
pub mod output;
pub mod report;
pub mod sweep_file;
pub mod validation_report;

pub use array_file::{ArrayFile, ArrayFileError, Vars};
pub use benchmarks::{CascadedTanks, Record, Silverbox, SilverboxSplit, TanksSplit};
pub use data_file::{
    ColumnRef, CsvOptions, DataFile, DataTable, csv_bytes, format_number, write_csv,
};
pub use error::{ErrorChain, IoError, core_is_input_error};
pub use estimate_file::{estimate_json, read_estimate};
pub use model_file::{
    BUILT_IN_LOCATIONS, BlockSpec, DeclaredLocationSpec, DiscoverSpec, DispersionSpec,
    LINEAR_STRUCTURES, LinearSpec, ModelFile, NamedStateSpec, OperatorSpec, SIGMA_SPAN,
    SUPPORTED_DISPERSIONS, SignalNames, SiteBlock, TruthSpec, default_sigma,
    parse_linear_structure,
};
pub use output::{OutputGuard, write_atomic};
pub use report::{
    BlockReport, BlockSettings, DiagnosticsReport, RecordBlock, RefinementReport, Report,
    ReportRecord, Reproduction, SelectionReport, SettingsReport,
};
pub use sweep_file::SweepFile;
