//! User-defined kernels and feature maps: identification through the same traits as the
//! built-in dispersions, estimates that keep them in memory, and stored estimates read back
//! with them by name.

use std::sync::Arc;

use structid_core::dispersion::user::{FeatureDispersion, UserKernels};
use structid_core::estimate::EstimateData;
use structid_core::stored::StoredKernel;
use structid_core::{
    Error, Estimate, FeatureMap, GaussianKernel, IdentifySettings, Kernel, KernelDispersion,
    Signal, identify, scenarios,
};

/// The paper's Gaussian, written again as a user kernel stored by name.
#[derive(Clone, Debug)]
struct MyGaussian(GaussianKernel);

impl Kernel for MyGaussian {
    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        let d2: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
        let s = self.0.sigma();
        (-d2 / (2.0 * s * s)).exp() / (2.0 * std::f64::consts::PI * s * s).sqrt()
    }
    fn describe(&self) -> String {
        "my gaussian".into()
    }
    fn width(&self) -> Option<f64> {
        Some(self.0.sigma())
    }
    fn with_width(&self, width: f64) -> Option<structid_core::Result<Self>> {
        Some(GaussianKernel::new(width).map(MyGaussian))
    }
    fn stored_kernel(&self) -> Option<StoredKernel> {
        Some(StoredKernel::User {
            name: "my-gaussian".into(),
            width: Some(self.0.sigma()),
        })
    }
}

/// ψ(z) = [1, z, z², z³] with weights 1, 1, ½, ¼, stored by name.
struct Cubic;

const CUBIC_WEIGHTS: [f64; 4] = [1.0, 1.0, 0.5, 0.25];

impl FeatureMap for Cubic {
    fn dim(&self) -> usize {
        4
    }
    fn weights(&self) -> &[f64] {
        &CUBIC_WEIGHTS
    }
    fn eval_into(&self, z: &[f64], out: &mut [f64]) {
        out.copy_from_slice(&[1.0, z[0], z[0] * z[0], z[0] * z[0] * z[0]]);
    }
    fn stored_features(&self) -> Option<StoredKernel> {
        Some(StoredKernel::User {
            name: "cubic".into(),
            width: None,
        })
    }
}

/// The kernel ψ(a)ᵀΛψ(b) of [`Cubic`], evaluated entry by entry: the Gram route.
#[derive(Debug)]
struct CubicKernel;

impl Kernel for CubicKernel {
    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        let (mut pa, mut pb) = ([0.0; 4], [0.0; 4]);
        Cubic.eval_into(a, &mut pa);
        Cubic.eval_into(b, &mut pb);
        (0..4).map(|j| CUBIC_WEIGHTS[j] * pa[j] * pb[j]).sum()
    }
    fn describe(&self) -> String {
        "cubic kernel".into()
    }
}

fn settings() -> IdentifySettings {
    IdentifySettings::builder().beta(1e-3).build().unwrap()
}

fn stored(e: &Estimate) -> EstimateData {
    serde_json::from_str(&serde_json::to_string(e).unwrap()).unwrap()
}

#[test]
fn a_user_kernel_identifies_as_the_built_in_one_and_is_read_back_by_name() {
    let sigma = 0.5;
    let builtin = Arc::new(KernelDispersion::gaussian(sigma).unwrap());
    let exp = scenarios::hammerstein(300, 2, 0.05, builtin, 7).unwrap();
    let mine = KernelDispersion::new(MyGaussian(GaussianKernel::new(sigma).unwrap()));
    let user_model = exp.model.with_dispersions(|_| Arc::new(mine.clone()) as _);
    let a = identify(&exp.model, &exp.data, &settings()).unwrap();
    let b = identify(&user_model, &exp.data, &settings()).unwrap();
    let (wa, wb) = (&a.blocks[0].w_hat, &b.blocks[0].w_hat);
    let scale = wa.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (x, y) in wa.iter().zip(wb) {
        assert!((x - y).abs() < 1e-10 * scale, "{x} vs {y}");
    }

    // In memory the estimate keeps the kernel: it predicts the identification's map.
    let est = Estimate::from_identification(&user_model, &b, &exp.data, &settings()).unwrap();
    let grid = Signal::from_fn(21, 1, |k, _| -2.0 + 0.2 * k as f64);
    let direct = b.blocks[0].map.eval_many(&grid);
    assert_eq!(est.maps()[0].eval_many(&grid), direct);

    // Stored, it names the kernel and its width; read back with it, registered at another
    // width, it evaluates to the same numbers.
    let data = stored(&est);
    let other = MyGaussian(GaussianKernel::new(2.0).unwrap());
    let kernels = UserKernels::new().with_kernel("my-gaussian", Arc::new(other));
    let back = Estimate::from_data_with_kernels(data.clone(), &kernels).unwrap();
    assert_eq!(back.maps()[0].eval_many(&grid), direct);
    for k in 0..grid.len() {
        assert_eq!(back.maps()[0].eval(grid.sample(k)), direct[k]);
    }

    // Without it, the error names the kernel.
    match Estimate::try_from(data) {
        Err(Error::UserKernelMissing { name }) => assert_eq!(name, "my-gaussian"),
        other => panic!("expected a missing user kernel, got {other:?}"),
    }
}

#[test]
fn a_user_feature_map_solves_in_feature_space_as_its_gram_matrix_does() {
    let exp = scenarios::hammerstein(
        400,
        2,
        0.05,
        Arc::new(KernelDispersion::new(CubicKernel)),
        11,
    )
    .unwrap();
    let features = exp
        .model
        .with_dispersions(|_| Arc::new(FeatureDispersion::new("cubic", Cubic)) as _);
    let gram = identify(&exp.model, &exp.data, &settings()).unwrap();
    let feat = identify(&features, &exp.data, &settings()).unwrap();
    assert_ne!(gram.diagnostics.solver, feat.diagnostics.solver);
    let (wg, wf) = (&gram.blocks[0].w_hat, &feat.blocks[0].w_hat);
    let scale = wg.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (x, y) in wg.iter().zip(wf) {
        assert!((x - y).abs() < 1e-7 * scale, "{x} vs {y}");
    }

    let est = Estimate::from_identification(&features, &feat, &exp.data, &settings()).unwrap();
    let grid = Signal::from_fn(9, 1, |k, _| -2.0 + 0.5 * k as f64);
    let direct = feat.blocks[0].map.eval_many(&grid);
    let kernels = UserKernels::new().with_features("cubic", Arc::new(Cubic));
    let back = Estimate::from_data_with_kernels(stored(&est), &kernels).unwrap();
    assert_eq!(back.maps()[0].eval_many(&grid), direct);

    // A registry entry of the wrong kind is an error, not a panic.
    let wrong = UserKernels::new().with_kernel("cubic", Arc::new(CubicKernel));
    let err = Estimate::from_data_with_kernels(stored(&est), &wrong).unwrap_err();
    assert!(err.to_string().contains("registered as a kernel"), "{err}");
}
