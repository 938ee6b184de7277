//! The latent signals smoothed with the linear part: on two tanks whose outflows are exactly
//! affine, the smoothed upper level (never measured) is the simulated one, and a flat upper
//! outflow leaves it unobserved.

use nalgebra::DMatrix;
use structid_core::{Data, Lft, LftMatrices, MapBinding, Signal};
use structid_joint::LinearInParameters;
use structid_joint::{GaussianFeatures, JointBlock, JointModel, smooth_maps};

fn lft() -> Lft {
    let m = |r: usize, c: usize, v: &[f64]| DMatrix::from_row_slice(r, c, v);
    Lft::new(LftMatrices {
        a: DMatrix::identity(2, 2),
        bu: m(2, 1, &[0.1, 0.0]),
        be: m(2, 1, &[0.0, 0.0]),
        bw: m(2, 2, &[-0.1, 0.0, 0.1, -0.1]),
        cy: m(1, 2, &[0.0, 1.0]),
        dyu: m(1, 1, &[0.0]),
        dye: m(1, 1, &[1.0]),
        dyw: m(1, 2, &[0.0, 0.0]),
        cz: m(2, 2, &[1.0, 0.0, 0.0, 1.0]),
        dzu: m(2, 1, &[0.0, 0.0]),
        dze: m(2, 1, &[0.0, 0.0]),
        dzw: DMatrix::zeros(2, 2),
    })
    .unwrap()
}

/// A kernel expansion whose affine part is `a₀ + a₁z` and whose kernel part is zero.
fn affine(a0: f64, a1: f64) -> GaussianFeatures {
    let f = GaussianFeatures::on_interval(0.0, 10.0, 5, 2.5, 1e-6).unwrap();
    let z: Vec<Vec<f64>> = (0..41).map(|k| vec![0.25 * k as f64]).collect();
    let w: Vec<f64> = z.iter().map(|z| a0 + a1 * z[0]).collect();
    f.fitted_to(&z, &w).unwrap()
}

#[test]
fn the_smoothed_latent_level_is_the_simulated_one_and_a_flat_outflow_is_unobserved() {
    let len = 2000;
    let u = Signal::from_fn(len, 1, |k, _| {
        1.0 + 0.5 * (0.013 * k as f64).sin() + 0.3 * (0.07 * k as f64).cos()
    });
    let (f0, f1) = (|z: &[f64]| 0.1 + 0.3 * z[0], |z: &[f64]| 0.05 + 0.25 * z[0]);
    let sim = lft()
        .simulate(
            &[
                MapBinding {
                    inputs: &[0],
                    output: 0,
                    map: &f0,
                },
                MapBinding {
                    inputs: &[1],
                    output: 1,
                    map: &f1,
                },
            ],
            &u,
            None,
            None,
        )
        .unwrap();
    // A small deterministic disturbance stands in for the noise.
    let y = Signal::from_fn(len, 1, |k, _| {
        sim.y.get(k, 0) + 1e-4 * (1.7 * k as f64).sin()
    });
    let data = Data::new(u, y).unwrap();
    let model = |upper: GaussianFeatures| {
        JointModel::new(
            lft(),
            vec![
                JointBlock::new("upper", vec![0], 0, Box::new(upper)),
                JointBlock::new("lower", vec![1], 1, Box::new(affine(0.05, 0.25))),
            ],
        )
        .unwrap()
    };
    let exact = model(affine(0.1, 0.3));
    assert!(exact.blocks()[0].map.affine_part().is_some());
    let s = smooth_maps(&exact, &data, 0.1).unwrap();
    assert_eq!(s.observable, vec![true, true]);
    let (z0, t0) = (s.z.channel(0), sim.z.channel(0));
    let rms = (z0
        .iter()
        .zip(&t0)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / len as f64)
        .sqrt();
    let spread =
        t0.iter().copied().fold(f64::MIN, f64::max) - t0.iter().copied().fold(f64::MAX, f64::min);
    println!("smoothed latent level: RMS error {rms:.2e} over a spread of {spread:.3}");
    assert!(rms < 1e-2 * spread, "{rms} vs {spread}");
    // The smoothed outflow follows the affine map of the smoothed level.
    let w0 = s.w.channel(0);
    let dev = (0..len)
        .map(|k| (w0[k] - 0.1 - 0.3 * z0[k]).powi(2))
        .sum::<f64>()
        / len as f64;
    assert!(dev.sqrt() < 1e-2 * 0.3 * spread, "{}", dev.sqrt());
    let flat = smooth_maps(&model(affine(0.5, 0.0)), &data, 0.1).unwrap();
    assert_eq!(flat.observable, vec![false, true]);
    assert!(smooth_maps(&exact, &data, 1.5).is_err());
}
