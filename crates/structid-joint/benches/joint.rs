//! One Levenberg–Marquardt iteration of the joint fit (the sensitivity pass that accumulates
//! the normal equations, and the trial simulations) on a Silverbox-like model: a second-order
//! G with a cubic-trend kernel map in output feedback, at L = 10⁴ and 10⁵ samples. The cost per
//! iteration is O(L), so the ratio of the two should be near 10. Beside them, the same model
//! with the map an increasing one ([`structid_joint::MonotoneFeatures`], 15 centres, its slope
//! the square of a kernel expansion) at L = 10⁴: what the closed-form integral costs against
//! the kernel sum.
//!
//! `cargo bench -p structid-joint --bench joint`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::dmatrix;
use structid_core::{Data, Lft, LftMatrices, Monotonicity, Signal};
use structid_joint::{
    BlockMap, GaussianFeatures, JointBlock, JointModel, JointSettings, LftMatrix, MonotoneFeatures,
    fit,
};

fn model() -> JointModel {
    model_with(Box::new(
        GaussianFeatures::on_interval(-0.3, 0.3, 15, 0.06, 1e-8)
            .unwrap()
            .with_trend_degree(3)
            .unwrap(),
    ))
}

fn monotone_model() -> JointModel {
    let z: Vec<Vec<f64>> = (0..61).map(|k| vec![-0.3 + 0.01 * k as f64]).collect();
    let w: Vec<f64> = z.iter().map(|z| z[0] + 10.0 * z[0].powi(3)).collect();
    let f = MonotoneFeatures::on_interval(-0.3, 0.3, 15, 0.06, 1e-8, Monotonicity::Increasing)
        .unwrap()
        .fitted_to(&z, &w)
        .unwrap();
    model_with(Box::new(f))
}

fn model_with(map: Box<dyn BlockMap>) -> JointModel {
    // y = G·(u − N(y)), G with poles 0.99·e^{±0.1j}.
    let lft = Lft::new(LftMatrices {
        a: dmatrix![1.97, -0.98; 1.0, 0.0],
        bu: dmatrix![0.01; 0.0],
        be: dmatrix![0.0; 0.0],
        bw: dmatrix![-0.01; 0.0],
        cy: dmatrix![1.0, 0.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0],
        cz: dmatrix![1.0, 0.0],
        dzu: dmatrix![0.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    })
    .unwrap();
    JointModel::new(lft, vec![JointBlock::new("N", vec![0], 0, map)])
        .unwrap()
        .with_free_nonzero(LftMatrix::A)
        .unwrap()
        .with_free_nonzero(LftMatrix::Bu)
        .unwrap()
        .with_free_nonzero(LftMatrix::Bw)
        .unwrap()
}

fn data(len: usize) -> Data {
    let u = Signal::from_fn(len, 1, |k, _| {
        0.1 * ((k as f64 * 0.031).sin() + (k as f64 * 0.0071).cos())
    });
    let y = Signal::from_fn(len, 1, |k, _| 0.05 * (k as f64 * 0.013).sin());
    Data::new(u, y).unwrap()
}

fn bench(c: &mut Criterion) {
    let m = model();
    let settings = JointSettings::builder()
        .max_iterations(1)
        .polish(true)
        .build()
        .unwrap();
    let mut g = c.benchmark_group("joint/one_iteration");
    g.sample_size(10);
    for len in [10_000usize, 100_000] {
        let d = data(len);
        g.bench_function(format!("{len}"), |b| {
            b.iter(|| black_box(fit(&m, &d, None, &settings).unwrap()))
        });
    }
    let (m, d) = (monotone_model(), data(10_000));
    g.bench_function("10000 increasing map", |b| {
        b.iter(|| black_box(fit(&m, &d, None, &settings).unwrap()))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
