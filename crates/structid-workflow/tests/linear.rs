//! `fit_linear`: G from records, against least squares written out here, with its options
//! checked before any data and the model file it writes reading back.

use nalgebra::{DMatrix, DVector};
use structid_core::Site;
use structid_io::ModelFile;
use structid_lti::Signal;
use structid_workflow::WorkflowError;
use structid_workflow::linear::{
    LinearMethod, LinearRequest, MapKind, MapRequest, OrderChoice, fit_linear,
};

/// y_k = 1.5·y_(k−1) − 0.7·y_(k−2) + u_(k−1) + 0.5·u_(k−2) + e_k with white Gaussian u and e.
fn record(len: usize, noise: f64) -> (Signal, Signal) {
    let u = structid_core::paper::gaussian_noise(len, 1, 1.0, len as u64).channel(0);
    let e = structid_core::paper::gaussian_noise(len, 1, 1.0, 7 + len as u64).channel(0);
    let mut y = vec![0.0; len];
    for k in 2..len {
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + u[k - 1] + 0.5 * u[k - 2] + noise * e[k];
    }
    (Signal::new(1, u).unwrap(), Signal::new(1, y).unwrap())
}

fn request(records: Vec<(Signal, Signal)>, method: LinearMethod) -> LinearRequest {
    LinearRequest {
        records,
        inputs: vec!["u".into()],
        output: "y".into(),
        orders: OrderChoice::Given([2, 2, 1]),
        method,
        integrators: 0,
        transient: 0,
        sample_time: Some(0.5),
        map: None,
    }
}

#[test]
fn arx_is_the_least_squares_solution_over_both_records() {
    let records = vec![record(300, 0.05), record(200, 0.05)];
    let out = fit_linear(&request(records.clone(), LinearMethod::Arx), &|_, _| {}).unwrap();
    // The normal equations of the stacked regressions, each record from its own third sample.
    let mut rows = Vec::new();
    let mut rhs = Vec::new();
    for (u, y) in &records {
        let (u, y) = (u.channel(0), y.channel(0));
        for k in 2..y.len() {
            rows.extend([-y[k - 1], -y[k - 2], u[k - 1], u[k - 2]]);
            rhs.push(y[k]);
        }
    }
    let phi = DMatrix::from_row_slice(rhs.len(), 4, &rows);
    let theta = (phi.transpose() * &phi)
        .cholesky()
        .unwrap()
        .solve(&(phi.transpose() * DVector::from_vec(rhs)));
    let den = &out.model.den;
    let num = &out.model.num[0];
    for (fitted, expected) in [den[1], den[2], num[1], num[2]].iter().zip(theta.iter()) {
        assert!((fitted - expected).abs() < 1e-9, "{fitted} vs {expected}");
    }
    assert_eq!((out.iterations, out.converged), (0, true));
    assert_eq!(out.fit_percent.len(), 2);
    // The model file carries G and reads back with the same polynomials.
    let back = ModelFile::parse(&out.model_file.to_toml_string(), None).unwrap();
    assert_eq!(back.linear.as_ref().unwrap().model.den, out.model.den);
}

#[test]
fn selection_finds_the_orders_and_output_error_the_plant() {
    // Noise makes the criterion's trade-off real (without it every larger order fits exactly).
    let mut r = request(vec![record(2000, 0.05)], LinearMethod::Oe);
    r.orders = OrderChoice::Selected {
        criterion: structid_linear::OrderCriterion::Bic,
        max_order: 4,
        delays: (1, 2),
    };
    let out = fit_linear(&r, &|_, _| {}).unwrap();
    assert_eq!(
        (out.orders.na, out.orders.nb[0], out.orders.nk[0]),
        (2, 2, 1)
    );
    assert_eq!(out.selection.as_ref().unwrap().1, 4 * 4 * 2);
    assert!(out.pooled_fit_percent > 95.0, "{}", out.pooled_fit_percent);
    let den = &out.model.den;
    assert!(
        (den[1] + 1.5).abs() < 0.02 && (den[2] - 0.7).abs() < 0.02,
        "{den:?}"
    );
}

#[test]
fn a_map_at_a_site_is_written_with_its_block() {
    let mut r = request(vec![record(300, 0.01)], LinearMethod::Arx);
    r.map = Some(MapRequest {
        site: Site::OutputFeedback,
        name: "spring".into(),
        kind: MapKind::Gaussian,
        trend: Some(3),
        separate_numerator: true,
    });
    let out = fit_linear(&r, &|_, _| {}).unwrap();
    let mf = &out.model_file;
    assert_eq!(mf.blocks.len(), 1);
    assert_eq!(mf.blocks[0].name, "spring");
    assert_eq!(
        mf.linear.as_ref().unwrap().structure,
        Some(Site::OutputFeedback)
    );
    assert!(mf.to_toml_string().contains("trend"));
}

#[test]
fn options_are_checked_before_any_data() {
    let conflict = |r: &LinearRequest| match r.check() {
        Err(WorkflowError::OptionConflict { options, .. }) => options,
        other => panic!("{other:?}"),
    };
    let mut r = request(Vec::new(), LinearMethod::Arx);
    r.transient = 5;
    assert_eq!(conflict(&r), vec!["transient", "method"]);
    let mut r = request(Vec::new(), LinearMethod::OeWithInitialState);
    r.integrators = 1;
    assert_eq!(conflict(&r), vec!["integrators", "initial_state"]);
    let mut r = request(Vec::new(), LinearMethod::Oe);
    r.map = Some(MapRequest {
        site: Site::Input,
        name: "N".into(),
        kind: MapKind::Tv,
        trend: Some(2),
        separate_numerator: false,
    });
    assert_eq!(conflict(&r), vec!["trend", "dispersion"]);
    r.inputs = vec!["a".into(), "b".into()];
    assert_eq!(conflict(&r), vec!["structure"]);
    let mut r = request(Vec::new(), LinearMethod::Oe);
    r.orders = OrderChoice::Given([31, 2, 1]);
    assert!(matches!(
        r.check(),
        Err(WorkflowError::InvalidOption {
            option: "orders",
            ..
        })
    ));
    // Records that do not match the request are refused with what they hold.
    let mut r = request(vec![record(100, 0.0)], LinearMethod::Arx);
    r.inputs = vec!["a".into(), "b".into()];
    let e = fit_linear(&r, &|_, _| {}).unwrap_err().to_string();
    assert!(e.contains("1 input") && e.contains("2 input"), "{e}");
}
