//! A latent map: two tanks in cascade simulated in continuous time (RK4, sampled), only the
//! lower level measured; the upper tank's outflow √-law acts on a level nobody measures.

use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;
use structid_core::{Data, Lft, LftMatrices, Signal};
use structid_joint::LinearInParameters;
use structid_joint::{GaussianFeatures, JointBlock, JointModel, JointSettings, fit};

const TS: f64 = 0.1;
const K1: f64 = 0.5;
const K2: f64 = 0.4;

/// ẋ₁ = u − K1·√x₁, ẋ₂ = K1·√x₁ − K2·√x₂, by RK4 with 10 substeps per sample, u held.
fn tanks(u: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let f = |x: [f64; 2], u: f64| {
        let q1 = K1 * x[0].max(0.0).sqrt();
        [u - q1, q1 - K2 * x[1].max(0.0).sqrt()]
    };
    let mut x = [1.0, 1.5];
    let (mut x1, mut x2) = (Vec::new(), Vec::new());
    let h = TS / 10.0;
    for &uk in u {
        x1.push(x[0]);
        x2.push(x[1]);
        for _ in 0..10 {
            let add = |a: [f64; 2], b: [f64; 2], s: f64| [a[0] + s * b[0], a[1] + s * b[1]];
            let k1 = f(x, uk);
            let k2 = f(add(x, k1, h / 2.0), uk);
            let k3 = f(add(x, k2, h / 2.0), uk);
            let k4 = f(add(x, k3, h), uk);
            for i in 0..2 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }
    (x1, x2)
}

/// The sampled structure: x⁺ = x + T_s·(u − w₁, w₁ − w₂), y = x₂, w₁ = N₁(x₁) latent.
fn lft() -> Lft {
    let m = |r: usize, c: usize, v: &[f64]| DMatrix::from_row_slice(r, c, v);
    Lft::new(LftMatrices {
        a: DMatrix::identity(2, 2),
        bu: m(2, 1, &[TS, 0.0]),
        be: m(2, 1, &[0.0, 0.0]),
        bw: m(2, 2, &[-TS, 0.0, TS, -TS]),
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

#[test]
fn the_outflow_maps_of_two_tanks_are_recovered_within_ten_percent_with_the_upper_level_latent() {
    let len = 6000;
    let mut rng = StdRng::seed_from_u64(1031);
    let mut u = Vec::with_capacity(len);
    let mut level = 0.7;
    for k in 0..len {
        if k % 150 == 0 {
            level = 0.35 + 0.7 * rng.random::<f64>();
        }
        u.push(level);
    }
    let (x1, x2) = tanks(&u);
    let y: Vec<f64> = x2
        .iter()
        .map(|v| v + 0.005 * rng.sample::<f64, _>(StandardNormal))
        .collect();
    let data = Data::new(Signal::new(1, u).unwrap(), Signal::new(1, y).unwrap()).unwrap();
    // Start: both outflows linear, the tangent of a √-law at level 2.
    let start_map = || {
        let f = GaussianFeatures::on_interval(0.0, 6.0, 13, 0.75, 1e-8).unwrap();
        let z: Vec<Vec<f64>> = (0..30).map(|k| vec![0.2 * k as f64]).collect();
        let w: Vec<f64> = z.iter().map(|z| 0.35 + 0.18 * z[0]).collect();
        f.fitted_to(&z, &w).unwrap()
    };
    let model = JointModel::new(
        lft(),
        vec![
            JointBlock::new("upper outflow", vec![0], 0, Box::new(start_map())),
            JointBlock::new("lower outflow", vec![1], 1, Box::new(start_map())),
        ],
    )
    .unwrap();
    let settings = JointSettings::builder()
        .segment_length(500)
        .max_iterations(300)
        .build()
        .unwrap();
    let out = fit(&model, &data, Some(&[vec![1.0, 1.5]]), &settings).unwrap();
    for s in &out.stages {
        println!(
            "{} {} {:?} {:?}",
            s.name,
            s.costs.len(),
            s.status,
            s.costs.last()
        );
    }
    println!("rms {:?}", out.rms);
    // Each map over the central 90 % of the levels its input visited, relative to its range there.
    for (b, (levels, k)) in [(&x1, K1), (&x2, K2)].into_iter().enumerate() {
        let mut sorted = levels.clone();
        sorted.sort_by(f64::total_cmp);
        let (lo, hi) = (sorted[len / 20], sorted[len - len / 20]);
        let map = out.model.blocks()[b].map.as_ref();
        let grid: Vec<f64> = (0..100).map(|i| lo + (hi - lo) * i as f64 / 99.0).collect();
        let err = (grid
            .iter()
            .map(|z| (map.eval(&mut [], &[*z]) - k * z.sqrt()).powi(2))
            .sum::<f64>()
            / 100.0)
            .sqrt();
        let range = k * (hi.sqrt() - lo.sqrt());
        println!(
            "outflow {b}: RMS error {:.4} over [{lo:.2}, {hi:.2}], {:.1} % of its range",
            err,
            100.0 * err / range
        );
        assert!(err < 0.10 * range, "map {b}: {err} vs range {range}");
    }
    assert!(out.rms[0] < 0.01, "{:?}", out.rms);
}
