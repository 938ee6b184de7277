//! Command-line arguments and environment overrides shared by the benchmark examples.

use std::error::Error;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use structid::io::write_atomic;
use structid::plot::{Chart, render_chart_svg};

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

/// Replaces `value` by the environment variable `name`, parsed, when it is set: a run varies a
/// setting without a command-line parser for every field.
// Each example compiles this module on its own, and not every one reads the environment.
#[allow(dead_code)]
pub fn env_override<T: FromStr>(name: &str, value: &mut T) -> Result<(), Box<dyn Error>>
where
    T::Err: Error + 'static,
{
    if let Ok(v) = std::env::var(name) {
        *value = v.parse()?;
    }
    Ok(())
}

/// [`env_override`] for a list, given as comma-separated values.
#[allow(dead_code)]
pub fn env_override_list<T: FromStr>(name: &str, value: &mut Vec<T>) -> Result<(), Box<dyn Error>>
where
    T::Err: Error + 'static,
{
    if let Ok(v) = std::env::var(name) {
        *value = v.split(',').map(str::parse).collect::<Result<_, _>>()?;
    }
    Ok(())
}

/// Writes `chart` as the figure `out/name`, atomically and never over the benchmark's `data`.
#[allow(dead_code)]
pub fn write_chart(
    out: &Path,
    name: &str,
    chart: &Chart<'_>,
    data: &Path,
) -> Result<(), Box<dyn Error>> {
    write_atomic(
        &out.join(name),
        render_chart_svg(chart)?.as_bytes(),
        &[data],
    )?;
    Ok(())
}

/// Writes `json` as `out/results.json`, atomically and never over the benchmark's `data`.
#[allow(dead_code)]
pub fn write_results(
    out: &Path,
    json: &serde_json::Value,
    data: &Path,
) -> Result<(), Box<dyn Error>> {
    let text = serde_json::to_string_pretty(json)?;
    write_atomic(&out.join("results.json"), text.as_bytes(), &[data])?;
    Ok(())
}

/// Prints each stage of a joint fit on a line of its own after `prefix`: its name, segments,
/// accepted steps and how it ended.
#[allow(dead_code)]
pub fn print_stages(prefix: &str, stages: &[structid_joint::Stage]) {
    for s in stages {
        println!(
            "{prefix}{} ({} segments): {} steps, {:?}",
            s.name,
            s.segments,
            s.costs.len() - 1,
            s.status
        );
    }
}
