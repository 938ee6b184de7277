//! The identify and refine workflows against the library calls they stand for: the same
//! numbers as `identify` on the model the file describes, the default criterion by dispersion,
//! and requests refused with the option named.

use std::path::Path;
use std::sync::Arc;

use structid_core::progress::Progress;
use structid_core::{Data, IdentifySettings, KernelDispersion, Signal, identify};
use structid_io::ModelFile;
use structid_workflow::{
    IdentifyRequest, RefineRequest, WorkflowError, identify_model_file, refine_model_file,
};

fn model_file() -> ModelFile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/models/hammerstein.toml");
    ModelFile::from_path(&path).unwrap()
}

/// A record of the example model: u uniform on [−2, 2] from a fixed LCG, no noise added (the
/// fits only need a record the maps can be identified from).
fn record(mf: &ModelFile, len: usize) -> Data {
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let u = Signal::from_fn(len, 1, |_, _| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0
    });
    let sim = structid_workflow::simulate_model_file(mf, &u, None).unwrap();
    Data::new(u, sim.y).unwrap()
}

fn request<'a>(mf: &'a ModelFile, data: &'a Data) -> IdentifyRequest<'a> {
    IdentifyRequest {
        model: mf,
        data,
        data_label: "the record".into(),
        validation: None,
        beta: Some(1e-3),
        sigma: Some(0.4),
        sigma_label: "sigma".into(),
        sigma_auto: false,
        selection: None,
        folds: 5,
        settings: IdentifySettings::default(),
        dispersions: Vec::new(),
        progress: Progress::none(),
    }
}

#[test]
fn identify_gives_the_numbers_of_identify_on_the_files_model() {
    let mf = model_file();
    let data = record(&mf, 300);
    let out = identify_model_file(&request(&mf, &data)).unwrap();
    let settings = IdentifySettings::builder().beta(1e-3).build().unwrap();
    let direct = identify(&mf.to_model(Some(0.4), None).unwrap(), &data, &settings).unwrap();
    assert_eq!(out.identification.w_hat, direct.w_hat);
    assert_eq!(out.settings.beta(), 1e-3);
    assert_eq!(
        out.estimate.maps()[0].eval(&[0.3]),
        direct.blocks[0].map.eval(&[0.3])
    );
    // A dispersion given in place of the file's is used, and its kind is reported.
    let mut req = request(&mf, &data);
    req.dispersions = vec![(
        None,
        Arc::new(KernelDispersion::gaussian(0.8).unwrap()) as _,
    )];
    req.sigma = None;
    let other = identify_model_file(&req).unwrap();
    assert_ne!(other.identification.w_hat, direct.w_hat);
    assert_eq!(other.report.settings.blocks[0].kind, "user");
}

#[test]
fn the_default_criterion_follows_the_dispersions() {
    let mf = model_file();
    let data = record(&mf, 200);
    let mut req = request(&mf, &data);
    req.beta = None;
    let out = identify_model_file(&req).unwrap();
    let sel = out.selection.expect("β was selected");
    assert_eq!(sel.criterion, "ml");
    // Total variation has no evidence: cross-validation, unless every block is replaced.
    let mut tv = mf.clone();
    tv.replace_dispersions(&structid_io::DispersionSpec::TotalVariation {
        neighbours: None,
        interpolation: None,
    });
    let mut req = request(&tv, &data);
    req.beta = None;
    req.sigma = None;
    assert_eq!(structid_workflow::default_criterion(&tv, 5).name(), "cv");
    req.dispersions = vec![(
        None,
        Arc::new(KernelDispersion::gaussian(0.4).unwrap()) as _,
    )];
    let out = identify_model_file(&req).unwrap();
    assert_eq!(out.selection.unwrap().criterion, "ml");
}

#[test]
fn requests_out_of_range_name_the_option() {
    let mf = model_file();
    let data = record(&mf, 200);
    let mut req = request(&mf, &data);
    req.beta = Some(1e9);
    assert!(matches!(
        identify_model_file(&req),
        Err(WorkflowError::InvalidOption { option: "beta", .. })
    ));
    let mut req = request(&mf, &data);
    req.dispersions = vec![(
        Some("nowhere".into()),
        Arc::new(KernelDispersion::gaussian(0.4).unwrap()) as _,
    )];
    let e = identify_model_file(&req).err().unwrap().to_string();
    assert!(e.contains("nowhere"), "{e}");

    let refine = RefineRequest {
        model: &mf,
        model_label: "hammerstein.toml".into(),
        data: &data,
        data_label: "the record".into(),
        validation: None,
        validation_labels: Vec::new(),
        validation_note: None,
        beta: Some(1e-3),
        sigma: Some(0.4),
        sigma_label: "sigma".into(),
        sigma_auto: false,
        criterion: structid_core::selection::Criterion::MarginalLikelihood,
        iterations: 0,
        tolerance: 1e-3,
        settle: 0,
        identify: IdentifySettings::default(),
        progress: Progress::none(),
        selection_progress: Progress::none(),
    };
    assert!(matches!(
        refine_model_file(&refine),
        Err(WorkflowError::InvalidOption {
            option: "iterations",
            ..
        })
    ));
    // The [lft] example is recognised as an input map around G and refined.
    let out = refine_model_file(&RefineRequest {
        iterations: 2,
        ..refine
    })
    .unwrap();
    assert!(out.recognised.unwrap().contains("input"));
    assert!(out.refined.linear.is_some());
}
