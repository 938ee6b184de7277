//! A small cascade identified jointly against a brute-force dense solution: a play (backlash)
//! whose output feeds a static map through D_zw, then a first-order plant. For a fixed
//! half-width c the criterion is quadratic in the map's coefficients, so its minimum over them
//! is one dense regularised least-squares solve written out here; the minimum over c is then
//! found by a dense grid and a golden-section search. The joint fit (Levenberg–Marquardt over
//! c and the coefficients at once) must land on the same c and the same criterion.

use nalgebra::{DMatrix, DVector, dmatrix};
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;
use structid_core::{Data, Lft, LftMatrices, Play, Signal};
use structid_joint::{GaussianFeatures, JointBlock, JointModel, JointSettings, OperatorBlock, fit};

const LEN: usize = 400;
const POLE: f64 = 0.7;
const GAIN: f64 = 0.3;
const CENTRES: usize = 9;
const LO: f64 = -1.6;
const HI: f64 = 1.6;
const BETA: f64 = 1e-4;

fn lft() -> Lft {
    Lft::new(LftMatrices {
        a: dmatrix![POLE],
        bu: dmatrix![0.0],
        be: dmatrix![0.0],
        bw: dmatrix![0.0, GAIN],
        cy: dmatrix![1.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0, 0.0],
        cz: dmatrix![0.0; 0.0],
        dzu: dmatrix![1.0; 0.0],
        dze: dmatrix![0.0; 0.0],
        dzw: dmatrix![0.0, 0.0; 1.0, 0.0],
    })
    .unwrap()
}

/// The play from rest at u₀, written out.
fn play(u: &[f64], c: f64) -> Vec<f64> {
    let mut b = u[0];
    u.iter()
        .map(|&v| {
            b = b.max(v - c).min(v + c);
            b
        })
        .collect()
}

/// x⁺ = POLE·x + GAIN·s, y = x, from x = 0.
fn plant(s: &[f64]) -> Vec<f64> {
    let mut x = 0.0;
    s.iter()
        .map(|v| {
            let y = x;
            x = POLE * x + GAIN * v;
            y
        })
        .collect()
}

fn centres() -> Vec<f64> {
    (0..CENTRES)
        .map(|j| LO + (HI - LO) * j as f64 / (CENTRES - 1) as f64)
        .collect()
}

fn sigma() -> f64 {
    (HI - LO) / (CENTRES - 1) as f64
}

fn kernel(a: f64, b: f64) -> f64 {
    let s2 = sigma() * sigma();
    (2.0 * std::f64::consts::PI * s2).powf(-0.5) * (-(a - b) * (a - b) / (2.0 * s2)).exp()
}

/// min over the coefficients θ = [kernel weights, a₀, a₁] of
/// Σ(y − G·N(play_c(u)))² + L·β·θ_kᵀK_ccθ_k, by one dense solve.
fn profile(u: &[f64], y: &[f64], c: f64) -> f64 {
    let s = play(u, c);
    let cs = centres();
    let np = CENTRES + 2;
    let mut f = DMatrix::zeros(LEN, np);
    for j in 0..np {
        let col: Vec<f64> = s
            .iter()
            .map(|v| match j {
                j if j < CENTRES => kernel(*v, cs[j]),
                j if j == CENTRES => 1.0,
                _ => *v,
            })
            .collect();
        for (k, v) in plant(&col).into_iter().enumerate() {
            f[(k, j)] = v;
        }
    }
    let yv = DVector::from_column_slice(y);
    let mut h = f.transpose() * &f;
    for i in 0..CENTRES {
        for j in 0..CENTRES {
            h[(i, j)] += LEN as f64 * BETA * kernel(cs[i], cs[j]);
        }
    }
    let theta = h.clone().cholesky().unwrap().solve(&(f.transpose() * &yv));
    let r = &yv - &f * &theta;
    let kk = DMatrix::from_fn(CENTRES, CENTRES, |i, j| kernel(cs[i], cs[j]));
    let tk = theta.rows(0, CENTRES).into_owned();
    r.norm_squared() + LEN as f64 * BETA * (tk.transpose() * kk * &tk)[(0, 0)]
}

#[test]
fn a_play_and_a_map_in_series_reach_the_brute_force_optimum() {
    let mut rng = StdRng::seed_from_u64(2024);
    let mut v = 0.0;
    let u: Vec<f64> = (0..LEN)
        .map(|_| {
            v = 0.8 * v + 0.45 * rng.sample::<f64, _>(StandardNormal);
            v
        })
        .collect();
    let truth: Vec<f64> = play(&u, 0.25)
        .iter()
        .map(|s| 0.8 * (s / 0.8).tanh())
        .collect();
    let y: Vec<f64> = plant(&truth)
        .iter()
        .map(|v| v + 0.01 * rng.sample::<f64, _>(StandardNormal))
        .collect();
    // Brute force: a grid over c, then golden section around the best point.
    let grid: Vec<f64> = (0..=200).map(|i| 0.02 + 0.4 * i as f64 / 200.0).collect();
    let best = grid
        .iter()
        .copied()
        .min_by(|a, b| profile(&u, &y, *a).total_cmp(&profile(&u, &y, *b)))
        .unwrap();
    let (mut a, mut b) = (best - 0.002, best + 0.002);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..60 {
        let (x1, x2) = (b - g * (b - a), a + g * (b - a));
        if profile(&u, &y, x1) < profile(&u, &y, x2) {
            b = x2;
        } else {
            a = x1;
        }
    }
    let c_bf = 0.5 * (a + b);
    let j_bf = profile(&u, &y, c_bf);
    // The joint fit from c = 0.15 and a zero map.
    let map = GaussianFeatures::on_interval(LO, HI, CENTRES, sigma(), BETA).unwrap();
    let start = JointModel::new(
        lft(),
        vec![
            JointBlock::new(
                "play",
                vec![0],
                0,
                Box::new(OperatorBlock::new(Box::new(Play::new(0.15).unwrap()))),
            ),
            JointBlock::new("map", vec![1], 1, Box::new(map)),
        ],
    )
    .unwrap();
    let data = Data::new(
        Signal::from_fn(LEN, 1, |k, _| u[k]),
        Signal::from_fn(LEN, 1, |k, _| y[k]),
    )
    .unwrap();
    let settings = JointSettings::builder()
        .max_iterations(300)
        .tolerance(1e-14)
        .estimate_initial_state(false)
        .build()
        .unwrap();
    let out = fit(&start, &data, None, &settings).unwrap();
    let c = out.model.blocks()[0].map.parameters()[0];
    println!(
        "brute force c = {c_bf:.6}, J = {j_bf:.8e}; joint fit c = {c:.6}, J = {:.8e}",
        out.cost
    );
    assert!((c - c_bf).abs() < 2e-4, "c {c} vs {c_bf}");
    assert!(
        (out.cost - j_bf).abs() <= 1e-7 * j_bf,
        "J {} vs {j_bf}",
        out.cost
    );
}
