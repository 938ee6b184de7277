//! `structid validate`: the arguments as the validations of [`structid_workflow::validate`]
//! and [`structid_workflow::stored`], and their summaries printed.

use std::path::Path;

use clap::Parser;
use structid_io::Reproduction;
use structid_workflow::validate::{
    self as workflow, Maps, Recorded, ValidateRequest, ValidationOptions,
};
use structid_workflow::validation_files::RecordScore;

use crate::error::CliError;
use crate::identify::load;
use crate::{Cli, Command, IdentifyArgs, ValidateArgs};

/// The arguments of the identification recorded in a report, parsed like a command line so
/// that options added later take their defaults.
fn identify_args(rep: &Reproduction, dir: &Path, report: &Path) -> Result<IdentifyArgs, CliError> {
    // `flag=value`, so that no value is taken for a flag; `{:?}` is the shortest form that
    // parses back to the same f64.
    let mut argv: Vec<String> = vec![
        "structid".into(),
        "identify".into(),
        format!("--model={}", rep.model_file_absolute),
        format!("--out={}", dir.display()),
        format!("--beta={:?}", rep.beta),
        // The solver that ran, not `auto`: the automatic choice depends on the free memory.
        format!("--solver={}", rep.solver),
        format!("--initial-state={}", rep.initial_state),
    ];
    if rep.data_files_absolute.is_empty() {
        argv.push(format!("--data={}", rep.data_file_absolute));
    }
    argv.extend(
        rep.data_files_absolute
            .iter()
            .map(|f| format!("--data={f}")),
    );
    let mut opt = |flag: &str, v: Option<String>| {
        if let Some(v) = v {
            argv.push(format!("{flag}={v}"));
        }
    };
    opt("--sigma", rep.sigma.map(|v| format!("{v:?}")));
    opt(
        "--memory-limit-mib",
        rep.memory_limit_mib.map(|v| v.to_string()),
    );
    opt("--dispersion", rep.dispersion.clone());
    opt("--neighbours", rep.neighbours.map(|v| v.to_string()));
    opt("--tolerance", rep.tolerance.map(|v| format!("{v:?}")));
    opt(
        "--max-iterations",
        rep.max_iterations.map(|v| v.to_string()),
    );
    let invalid = |detail: String| {
        CliError::input(format!(
            "`{}` records identification settings that this version of structid does not accept: {detail}",
            report.display()
        ))
    };
    match Cli::try_parse_from(&argv) {
        Ok(Cli {
            command: Command::Identify(a),
            ..
        }) => Ok(a),
        Ok(_) => Err(invalid("not an identify command".into())),
        Err(e) => Err(invalid(
            e.to_string()
                .lines()
                .next()
                .unwrap_or_default()
                .trim_start_matches("error: ")
                .to_string(),
        )),
    }
}

/// Runs `structid validate`.
pub fn run(mut a: ValidateArgs) -> Result<(), CliError> {
    // An output directory of this version carries its estimate as a file: that file is the
    // estimate, and the estimation data need not exist any more.
    if let Some(dir) = &a.estimate
        && dir.is_dir()
        && dir.join("estimate.json").is_file()
    {
        a.estimate = Some(dir.join("estimate.json"));
    }
    if a.data.len() > 1 {
        let text = workflow::validate_records(&a.data, &a.out, a.settle, |i, file, out| {
            let one = ValidateArgs {
                data: vec![file.to_path_buf()],
                out,
                ..a.clone()
            };
            println!("record {} (`{}`):", i + 1, file.display());
            validate_record(one)
                .map_err(|e| e.context(format!("record {} (`{}`)", i + 1, file.display())))
        })?;
        print!("{text}");
        return Ok(());
    }
    validate_record(a).map(|_| ())
}

/// `structid validate` on one record (the files of `a.out`).
fn validate_record(a: ValidateArgs) -> Result<RecordScore, CliError> {
    let o = ValidationOptions {
        data: a.data[0].clone(),
        out: a.out.clone(),
        initial_state: a.initial_state.into(),
        max_lag: a.max_lag,
        settle: a.settle,
        scoring: a.scoring,
    };
    let vars = crate::data::vars();
    let done = match &a.estimate {
        Some(p) if p.is_file() => {
            structid_workflow::stored::validate_stored(p, a.model.as_deref(), &o, vars)?
        }
        _ => {
            let model_path = a.model.as_deref().ok_or_else(|| {
                CliError::input(
                    "--model is required, except with --estimate FILE.json (a stored estimate, which carries its model)",
                )
            })?;
            workflow::check_max_lag(a.max_lag)?;
            let maps = match &a.estimate {
                Some(dir) => Maps::Rebuilt(Box::new(recorded(dir, model_path)?)),
                None => Maps::Truth,
            };
            workflow::validate_model_file(ValidateRequest {
                model_path,
                maps,
                options: &o,
                vars,
            })?
        }
    };
    print!("{}", done.summary);
    Ok(done.score)
}

/// The identification recorded in the estimate directory `dir`, loaded (not run yet), after
/// `model_path` is checked against it.
fn recorded(dir: &Path, model_path: &Path) -> Result<Recorded, CliError> {
    let opened = workflow::open_estimate_dir(dir, model_path)?;
    let args = identify_args(&opened.reproduction, dir, &opened.report_path)?;
    opened.check_files(&args.model, &args.data)?;
    let (settings, sigma, model) = load(&args).map_err(|e| e.context(opened.context()))?;
    Ok(opened.recorded(args.model, args.data, settings, sigma, model)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reproduction() -> Reproduction {
        Reproduction {
            model_file_absolute: "/m.toml".into(),
            data_file_absolute: "/d.csv".into(),
            data_files_absolute: Vec::new(),
            beta: 0.1 + 0.2,
            sigma: Some(1e-7),
            solver_requested: "auto".into(),
            solver: "admm".into(),
            initial_state: "estimate".into(),
            memory_limit_mib: Some(64),
            dispersion: Some("tv".into()),
            neighbours: Some(5),
            tolerance: Some(1e-9),
            max_iterations: Some(300),
            block_sigmas: Vec::new(),
        }
    }

    #[test]
    fn recorded_settings_parse_back_exactly() {
        let rep = reproduction();
        let a = identify_args(&rep, Path::new("-odd dir"), Path::new("r.json")).unwrap();
        assert_eq!(a.beta, crate::AutoOr::Value(0.1 + 0.2));
        assert_eq!(a.sigma, Some(crate::AutoOr::Value(1e-7)));
        assert_eq!(a.out, Path::new("-odd dir"));
        assert_eq!(a.model, Path::new("/m.toml"));
        assert!(matches!(a.solver, crate::SolverArg::Admm));
        assert!(matches!(a.initial_state, crate::InitialStateArg::Estimate));
        assert!(matches!(a.dispersion, Some(crate::DispersionArg::Tv)));
        assert_eq!(
            (
                a.memory_limit_mib,
                a.neighbours,
                a.tolerance,
                a.max_iterations
            ),
            (Some(64), Some(5), Some(1e-9), Some(300))
        );
        let bad = Reproduction {
            solver: "magic".into(),
            ..rep
        };
        let e = identify_args(&bad, Path::new("d"), Path::new("r.json"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("r.json") && e.contains("magic"), "{e}");
        assert!(!e.contains('\n'), "{e}");
    }
}
