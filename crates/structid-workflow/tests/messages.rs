//! The library's messages name options the way Python names keyword arguments, never as
//! command-line flags: the errors carry the option, the value and the rule, and each front
//! end words them.

use std::path::{Path, PathBuf};

use structid_core::InitialState;
use structid_core::validation::Scoring;
use structid_workflow::WorkflowError;
use structid_workflow::compare::cases::Shard;
use structid_workflow::demo::spray_model_file;
use structid_workflow::refine_files::{RefineData, split_records};
use structid_workflow::validate::{
    Maps, ValidateRequest, ValidationOptions, open_estimate_dir, validate_model_file,
};

/// The message of `e` and its causes, checked to name no flag.
fn flagless(e: &WorkflowError) -> String {
    let mut m = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        m.push_str(&format!(": {s}"));
        source = s.source();
    }
    assert!(!m.contains("--"), "a flag in: {m}");
    m
}

fn refine_data<'a>(
    data: &'a [PathBuf],
    validation_fraction: Option<f64>,
    out: &'a Path,
) -> RefineData<'a> {
    RefineData {
        data,
        validation_data: &[],
        validation_fraction,
        settle: 0,
        out,
        vars: None,
    }
}

#[test]
fn a_validation_fraction_with_several_records_names_the_options() {
    let mf = spray_model_file(0.5);
    let data = vec![PathBuf::from("a.csv"), PathBuf::from("b.csv")];
    let e = split_records(&mf, &refine_data(&data, Some(0.2), Path::new("out")))
        .err()
        .unwrap();
    match &e {
        WorkflowError::UseInstead {
            options, instead, ..
        } => {
            assert_eq!(options, &["validation_fraction", "data"]);
            assert_eq!(*instead, "validation_data");
        }
        other => panic!("not a UseInstead: {other:?}"),
    }
    let m = flagless(&e);
    assert!(m.contains("2 data records"), "{m}");
}

#[test]
fn a_validation_fraction_out_of_range_names_the_option_and_value() {
    let mf = spray_model_file(0.5);
    let data = vec![PathBuf::from("a.csv")];
    let e = split_records(&mf, &refine_data(&data, Some(1.5), Path::new("out")))
        .err()
        .unwrap();
    assert!(
        matches!(&e, WorkflowError::InvalidOption { option: "validation_fraction", value, .. } if value == "1.5"),
        "{e:?}"
    );
    flagless(&e);
}

#[test]
fn a_validation_fraction_that_leaves_too_few_samples_names_the_option() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("d.csv");
    let rows: String = (0..40).map(|k| format!("{k},{}\n", 2 * k)).collect();
    std::fs::write(&data, format!("u,y\n{rows}")).unwrap();
    let mf = spray_model_file(0.5);
    let files = [data];
    let e = split_records(&mf, &refine_data(&files, Some(0.9), dir.path()))
        .err()
        .unwrap();
    assert!(
        matches!(&e, WorkflowError::InvalidOption { option: "validation_fraction", value, .. } if value == "0.9"),
        "{e:?}"
    );
    let m = flagless(&e);
    assert!(m.contains("4 estimation and 36 validation samples"), "{m}");
}

#[test]
fn a_missing_estimate_directory_names_the_input_and_its_path() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope");
    let e = open_estimate_dir(&missing, &dir.path().join("m.toml"))
        .err()
        .unwrap();
    match &e {
        WorkflowError::InvalidInput { input, path, .. } => {
            assert_eq!(*input, "estimate");
            assert_eq!(path, &missing);
        }
        other => panic!("not an InvalidInput: {other:?}"),
    }
    let m = flagless(&e);
    assert!(m.contains("does not exist"), "{m}");
}

fn options(dir: &Path, initial_state: InitialState) -> ValidationOptions {
    ValidationOptions {
        data: dir.join("d.csv"),
        out: dir.join("out"),
        initial_state,
        max_lag: 20,
        settle: 0,
        scoring: Scoring::Free,
    }
}

#[test]
fn true_maps_without_a_truth_ask_for_an_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let mut mf = spray_model_file(0.5);
    mf.blocks[1].truth = None;
    let model = dir.path().join("m.toml");
    std::fs::write(&model, mf.to_toml_string()).unwrap();
    let o = options(dir.path(), InitialState::Zero);
    let e = validate_model_file(ValidateRequest {
        model_path: &model,
        maps: Maps::Truth,
        options: &o,
        vars: None,
    })
    .err()
    .unwrap();
    assert!(
        matches!(
            &e,
            WorkflowError::MissingOption {
                option: "estimate",
                ..
            }
        ),
        "{e:?}"
    );
    let m = flagless(&e);
    assert!(m.contains("`g`") && !m.contains("`f`"), "{m}");
}

#[test]
fn shard_usage_names_no_flag() {
    for bad in ["3", "a/2", "0/0", "3/2"] {
        let m = bad.parse::<Shard>().err().unwrap();
        assert!(!m.contains("--"), "{m}");
        assert!(m.contains("shard"), "{m}");
    }
}

/// A non-finite simulated column blames the noise level only when there is noise; without
/// it, the model alone overflows and the error names no option.
#[test]
fn a_non_finite_simulation_blames_the_noise_only_when_there_is_noise() {
    use structid_workflow::simulate::finite_columns;
    let columns = vec![vec![1.0, f64::INFINITY]];
    match finite_columns(&["y"], &columns, 0.5).unwrap_err() {
        WorkflowError::InvalidOption { option, rule, .. } => {
            assert_eq!(option, "noise_std");
            assert!(rule.contains("`y`") && rule.contains("sample 1"), "{rule}");
        }
        other => panic!("{other:?}"),
    }
    let e = finite_columns(&["y"], &columns, 0.0).unwrap_err();
    assert!(matches!(e, WorkflowError::Failed(_)), "{e:?}");
    assert!(!e.to_string().contains("noise"), "{e}");
    assert!(finite_columns(&["y"], &[vec![1.0, 2.0]], 0.0).is_ok());
}
