//! Command-line arguments shared by the benchmark examples.

use std::path::PathBuf;

/// `[PATH] [OUT_DIR]` from the command line: PATH defaults to `rel` under `$STRUCTID_DATA`, or
/// under `../shared/data` beside the workspace; OUT_DIR to `target/<out>`.
pub fn benchmark_args(rel: &str, out: &str) -> (PathBuf, PathBuf) {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().map(PathBuf::from).unwrap_or_else(|| {
        let base = std::env::var("STRUCTID_DATA")
            .map(PathBuf::from)
            .unwrap_or_else(|_| {
                // The crate sits at `crates/structid-benchmarks` of the workspace, and the
                // data beside the workspace root.
                PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data")
            });
        base.join(rel)
    });
    let out = args
        .get(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("target").join(out));
    (path, out)
}
