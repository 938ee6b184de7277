//! Units do not decide the answer: u and y recorded in other units (every signal times c, the
//! kernel width in the units of z) give the same map in those units. The paper's Gaussian
//! kernel is normalised by (2πσ²)^(−p/2), so D(cz, cw) = c^(2+p)·D(z, w) against c² for the
//! error term: the same trade-off is β·c^(−p), and automatic selection must find it there
//! (the β search widens once past a bound) with the same map. Any absolute floor, jitter or
//! tolerance in the solvers would break that.

use std::sync::Arc;

use structid_core::paper::Experiment;
use structid_core::scenarios::hammerstein;
use structid_core::selection::{Criterion, SelectionSettings, select};
use structid_core::validation::metrics::rms_difference;
use structid_core::{
    Data, Dispersion, FourierDispersion, FourierWeights, IdentifySettings, KernelDispersion,
    Signal, SolverChoice, identify,
};

fn fourier(sigma: f64) -> Arc<dyn Dispersion> {
    Arc::new(FourierDispersion::new(FourierWeights::GaussianLike { sigma }).unwrap())
}

fn gaussian(sigma: f64) -> Arc<dyn Dispersion> {
    Arc::new(KernelDispersion::gaussian(sigma).unwrap())
}

/// The record with u and y multiplied by `c`.
fn in_units(data: &Data, c: f64) -> Data {
    let (u, y) = (data.u(), data.y());
    Data::new(
        Signal::from_fn(u.len(), u.channels(), |k, i| c * u.get(k, i)),
        Signal::from_fn(y.len(), y.channels(), |k, i| c * y.get(k, i)),
    )
    .unwrap()
}

/// RMS of ŵ_c/c − ŵ relative to RMS(ŵ).
fn relative_map_difference(w: &[f64], w_c: &[f64], c: f64) -> f64 {
    let back: Vec<f64> = w_c.iter().map(|v| v / c).collect();
    let scale = (w.iter().map(|v| v * v).sum::<f64>() / w.len() as f64).sqrt();
    rms_difference(&back, w) / scale
}

fn check(exp: &Experiment, sigma: f64, make: fn(f64) -> Arc<dyn Dispersion>, solver: SolverChoice) {
    let settings = IdentifySettings::builder().solver(solver).build().unwrap();
    let how = SelectionSettings::builder()
        .criterion(Criterion::MarginalLikelihood)
        .build()
        .unwrap();
    let model = exp.model.with_dispersions(|_| make(sigma));
    let base = select(&model, &exp.data, None, &settings, &how).unwrap();
    assert!(base.beta_at_bound.is_none(), "β = {:.3e}", base.beta);
    let fixed = IdentifySettings::builder()
        .solver(solver)
        .beta(1e-2)
        .build()
        .unwrap();
    let base_fixed = identify(&model, &exp.data, &fixed).unwrap();
    for c in [1e-8, 1e8] {
        let model_c = exp.model.with_dispersions(|_| make(sigma * c));
        let data_c = in_units(&exp.data, c);
        let sel = select(&model_c, &data_c, None, &settings, &how).unwrap();
        // The paper's Gaussian kernel is normalised by (2πσ²)^(−1/2), so β carries the units
        // of z: the same trade-off is β/c.
        assert!(
            ((sel.beta * c).log10() - base.beta.log10()).abs() < 0.05,
            "{solver:?}, c = {c:e}: β·c {:.4e} against β {:.4e} in the original units",
            sel.beta * c,
            base.beta
        );
        assert!(sel.beta_at_bound.is_none(), "c = {c:e}: β on a bound");
        let d = relative_map_difference(
            &base.identification.blocks[0].w_hat,
            &sel.identification.blocks[0].w_hat,
            c,
        );
        assert!(
            d < 1e-3,
            "{solver:?}, c = {c:e}: automatic β, map differs by {d:.2e}"
        );
        // A fixed β, converted to the new units, means the same trade-off.
        let fixed_c = IdentifySettings::builder()
            .solver(solver)
            .beta(1e-2 / c)
            .build()
            .unwrap();
        let id = identify(&model_c, &data_c, &fixed_c).unwrap();
        let d = relative_map_difference(&base_fixed.blocks[0].w_hat, &id.blocks[0].w_hat, c);
        assert!(
            d < 1e-6,
            "{solver:?}, c = {c:e}: β = 0.01, map differs by {d:.2e}"
        );
    }
}

#[test]
fn the_feature_path_gives_the_same_beta_and_map_in_any_units() {
    let exp = hammerstein(2000, 2, 0.05, fourier(0.4), 3).unwrap();
    check(&exp, 0.4, fourier, SolverChoice::Features);
}

#[test]
fn the_exact_path_gives_the_same_beta_and_map_in_any_units() {
    let exp = hammerstein(400, 2, 0.05, gaussian(0.4), 5).unwrap();
    check(&exp, 0.4, gaussian, SolverChoice::Exact);
}
