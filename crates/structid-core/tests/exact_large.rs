//! The exact Gaussian path on a record past the size that used to overflow the stack.
//!
//! The parallel Gram fill split its columns at a fixed share of the whole range, so a range far
//! from column 0 was peeled one column at a time: about 24 000 frames deep at L = 12 000, which
//! overflowed the (default-sized) stack of a rayon worker from about 11 000 samples. This test
//! runs at L = 12 000 with the default stack, in release mode, and checks the estimate too.

use std::sync::Arc;

use nalgebra::dmatrix;
use structid_core::*;

#[test]
fn exact_gaussian_identification_runs_at_twelve_thousand_samples() {
    // y = x + e, x⁺ = 0.5·x + w, w = tanh(u): a first-order Hammerstein system.
    let lft = Lft::new(LftMatrices {
        a: dmatrix![0.5],
        bu: dmatrix![0.0],
        be: dmatrix![0.0],
        bw: dmatrix![1.0],
        cy: dmatrix![1.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0],
        cz: dmatrix![0.0],
        dzu: dmatrix![1.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    })
    .unwrap();
    let model = Model::new(
        lft,
        vec![NonlinearBlock::new(
            "f",
            vec![0],
            0,
            Arc::new(KernelDispersion::new(GaussianKernel::new(0.3).unwrap())),
        )],
    )
    .unwrap();
    let len = 12_000;
    // A deterministic, well-spread input in [−2, 2] and small deterministic "noise".
    let u = Signal::from_fn(len, 1, |k, _| {
        2.0 * ((k as f64 * 0.618_033_988_75).fract() * 2.0 - 1.0)
    });
    let e = Signal::from_fn(len, 1, |k, _| {
        1e-3 * ((k as f64 * 0.414_213_562_37).fract() - 0.5)
    });
    let f = |z: &[f64]| z[0].tanh();
    let sim = model.simulate(&[&f], &u, Some(&e), None).unwrap();
    let data = Data::new(u.clone(), sim.y).unwrap();
    let settings = IdentifySettings::builder()
        .beta(1e-6)
        .solver(SolverChoice::Exact)
        .build()
        .unwrap();
    let id = identify(&model, &data, &settings).unwrap();
    assert_eq!(id.diagnostics.system_size, len);
    // ŵ recovers tanh(u) to well within the map's range (the noise is 1e-3).
    let w = &id.blocks[0].w_hat;
    let worst = (0..len)
        .map(|k| (w[k] - u.get(k, 0).tanh()).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.05, "largest error of ŵ {worst}");
}
