//! The joint fit against independent answers: the truth that generated the data, the start's
//! cost, and single against multiple shooting.

use nalgebra::{DMatrix, dmatrix};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;
use structid_core::{Data, Lft, LftMatrices, MapBinding, Signal};
use structid_joint::LinearInParameters;
use structid_joint::{
    BlockMap, GaussianFeatures, JointBlock, JointModel, JointSettings, LftMatrix, fit,
};

fn noise(len: usize, std: f64, seed: u64) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..len)
        .map(|_| std * rng.sample::<f64, _>(StandardNormal))
        .collect()
}

/// A band-limited random input: white noise through a first-order low-pass, scaled to `amp`.
fn input(len: usize, amp: f64, seed: u64) -> Signal {
    let e = noise(len, 1.0, seed);
    let mut v = 0.0;
    let raw: Vec<f64> = e
        .iter()
        .map(|e| {
            v = 0.7 * v + e;
            v
        })
        .collect();
    let rms = (raw.iter().map(|v| v * v).sum::<f64>() / len as f64).sqrt();
    Signal::from_fn(len, 1, |k, _| amp * raw[k] / rms)
}

/// x⁺ = A x + B w₀, v = C x, y = w₁ with w₀ = N₀(u) and w₁ = N₁(v): an input map and a sensor
/// map in series through D_zw (z₁ = C x + 0·w₀ is read through x here; the series coupling
/// of a static path is tested by a direct term below).
fn wiener_hammerstein(direct: f64) -> Lft {
    Lft::new(LftMatrices {
        a: dmatrix![1.2, -0.5; 1.0, 0.0],
        bu: dmatrix![0.0; 0.0],
        be: dmatrix![0.0; 0.0],
        bw: dmatrix![1.0, 0.0; 0.0, 0.0],
        cy: dmatrix![0.0, 0.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0, 1.0],
        cz: dmatrix![0.0, 0.0; 0.3, 0.2],
        dzu: dmatrix![1.0; 0.0],
        dze: dmatrix![0.0; 0.0],
        dzw: dmatrix![0.0, 0.0; direct, 0.0],
    })
    .unwrap()
}

fn dead_zone(z: &[f64]) -> f64 {
    let d = 0.3;
    if z[0] > d {
        z[0] - d
    } else if z[0] < -d {
        z[0] + d
    } else {
        0.0
    }
}

fn saturation(z: &[f64]) -> f64 {
    0.8 * (z[0] / 0.8).tanh()
}

/// RMS of `a − (c·b + o)` over the points, minimised over the gain c and offset o when
/// `equivalence` holds, relative to the range of `a`.
fn rms_modulo(a: &[f64], b: &[f64], equivalence: bool) -> f64 {
    let n = a.len() as f64;
    let (c, o) = if equivalence {
        let x = DMatrix::from_fn(a.len(), 2, |k, j| if j == 0 { b[k] } else { 1.0 });
        let sol = (x.transpose() * &x)
            .cholesky()
            .unwrap()
            .solve(&(x.transpose() * DMatrix::from_column_slice(a.len(), 1, a)));
        (sol[0], sol[1])
    } else {
        (1.0, 0.0)
    };
    let err = a
        .iter()
        .zip(b)
        .map(|(a, b)| (a - c * b - o).powi(2))
        .sum::<f64>()
        / n;
    let range =
        a.iter().copied().fold(f64::MIN, f64::max) - a.iter().copied().fold(f64::MAX, f64::min);
    err.sqrt() / range
}

#[test]
fn two_maps_in_series_are_identified_jointly_within_ten_percent() {
    let len = 3000;
    let lft = wiener_hammerstein(0.5);
    let u = input(len, 1.0, 1001);
    let truth = lft
        .simulate(
            &[
                MapBinding {
                    inputs: &[0],
                    output: 0,
                    map: &dead_zone,
                },
                MapBinding {
                    inputs: &[1],
                    output: 1,
                    map: &saturation,
                },
            ],
            &u,
            None,
            None,
        )
        .unwrap();
    let e = noise(len, 0.01, 1002);
    let y = Signal::from_fn(len, 1, |k, _| truth.y.get(k, 0) + e[k]);
    let data = Data::new(u.clone(), y).unwrap();
    // Both maps start as the identity on their ranges.
    let range = |s: &Signal, c: usize| {
        let v = s.channel(c);
        (
            v.iter().copied().fold(f64::MAX, f64::min),
            v.iter().copied().fold(f64::MIN, f64::max),
        )
    };
    let (u0, u1) = range(&u, 0);
    let (v0, v1) = range(&truth.z, 1);
    let ident = |lo: f64, hi: f64, m: usize| {
        let f = GaussianFeatures::on_interval(lo, hi, m, (hi - lo) / (m - 1) as f64, 1e-7).unwrap();
        let z: Vec<Vec<f64>> = (0..50)
            .map(|k| vec![lo + (hi - lo) * k as f64 / 49.0])
            .collect();
        let w: Vec<f64> = z.iter().map(|z| z[0]).collect();
        f.fitted_to(&z, &w).unwrap()
    };
    let start = JointModel::new(
        lft,
        vec![
            JointBlock::new("dead zone", vec![0], 0, Box::new(ident(u0, u1, 15))),
            JointBlock::new(
                "saturation",
                vec![1],
                1,
                Box::new(ident(v0 - 0.5, v1 + 0.5, 15)),
            ),
        ],
    )
    .unwrap();
    let settings = JointSettings::builder().max_iterations(60).build().unwrap();
    let out = fit(&start, &data, None, &settings).unwrap();
    assert!(out.cost <= out.initial_cost);
    // The data fix the pair only up to an affine change of the signal between the maps
    // (c·N₀ + o with N₁ read through the inverse change), so each map is compared after the
    // best gain and offset: the change is the same for both and is not a fitted freedom of
    // the comparison beyond that equivalence.
    let grid = |lo: f64, hi: f64| -> Vec<f64> {
        (0..200)
            .map(|k| lo + (hi - lo) * k as f64 / 199.0)
            .collect()
    };
    let zu = grid(u0 * 0.9, u1 * 0.9);
    let n0 = out.model.blocks()[0].map.as_ref();
    let fitted0: Vec<f64> = zu.iter().map(|z| n0.eval(&mut [], &[*z])).collect();
    let true0: Vec<f64> = zu.iter().map(|z| dead_zone(&[*z])).collect();
    let e0 = rms_modulo(&true0, &fitted0, true);
    // The sensor map on the range its input covered in the fitted model's simulation.
    let sim = out
        .model
        .simulate(&u, Some(&out.initial_states[0]))
        .unwrap();
    let (f0, f1) = range(&sim.z, 1);
    let zv = grid(f0, f1);
    let n1 = out.model.blocks()[1].map.as_ref();
    let fitted1: Vec<f64> = zv.iter().map(|z| n1.eval(&mut [], &[*z])).collect();
    // Map the fitted intermediate signal back to the true one through the simulations.
    let (zt, zf) = (truth.z.channel(1), sim.z.channel(1));
    let x = DMatrix::from_fn(len, 2, |k, j| if j == 0 { zf[k] } else { 1.0 });
    let sol = (x.transpose() * &x)
        .cholesky()
        .unwrap()
        .solve(&(x.transpose() * DMatrix::from_column_slice(len, 1, &zt)));
    let true1: Vec<f64> = zv
        .iter()
        .map(|z| saturation(&[sol[0] * z + sol[1]]))
        .collect();
    let e1 = rms_modulo(&true1, &fitted1, false);
    println!(
        "series: dead zone {e0:.4}, saturation {e1:.4} of their ranges; rms {:?}",
        out.rms
    );
    assert!(e0 < 0.10 && e1 < 0.10, "dead zone {e0}, saturation {e1}");
    assert!(out.rms[0] < 1.5 * 0.01, "{:?}", out.rms);
}

/// A Hammerstein plant with a free pole and gain: the start is perturbed at random.
fn hammerstein(a: f64, b: f64) -> Lft {
    Lft::new(LftMatrices {
        a: dmatrix![a],
        bu: dmatrix![0.0],
        be: dmatrix![0.0],
        bw: dmatrix![b],
        cy: dmatrix![1.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: dmatrix![0.0],
        cz: dmatrix![0.0],
        dzu: dmatrix![1.0],
        dze: dmatrix![0.0],
        dzw: dmatrix![0.0],
    })
    .unwrap()
}

fn hammerstein_data(len: usize, seed: u64) -> Data {
    let u = input(len, 1.0, seed);
    let sim = hammerstein(0.85, 1.0)
        .simulate(
            &[MapBinding {
                inputs: &[0],
                output: 0,
                map: &|z: &[f64]| (1.5 * z[0]).tanh(),
            }],
            &u,
            None,
            Some(&[0.4]),
        )
        .unwrap();
    let e = noise(len, 0.05, seed + 1);
    Data::new(u, Signal::from_fn(len, 1, |k, _| sim.y.get(k, 0) + e[k])).unwrap()
}

fn hammerstein_start(a: f64) -> JointModel {
    let f = GaussianFeatures::on_interval(-3.0, 3.0, 9, 0.8, 1e-6).unwrap();
    JointModel::new(
        hammerstein(a, 1.0),
        vec![JointBlock::new("N", vec![0], 0, Box::new(f))],
    )
    .unwrap()
    .with_free(LftMatrix::A, 0, 0)
    .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]
    /// Whatever the start, the fit never ends above it and each stage's accepted costs fall.
    #[test]
    fn the_cost_never_increases(a in 0.0f64..0.95, seg in prop::option::of(20usize..200), seed in 0u64..20) {
        let data = hammerstein_data(400, 2000 + seed);
        let mut b = JointSettings::builder().max_iterations(15);
        if let Some(s) = seg {
            b = b.segment_length(s);
        }
        let out = fit(&hammerstein_start(a), &data, None, &b.build().unwrap()).unwrap();
        prop_assert!(out.cost <= out.initial_cost);
        for st in &out.stages {
            prop_assert!(st.costs.windows(2).all(|w| w[1] < w[0]), "{:?}", st.costs);
        }
    }
}

#[test]
fn multiple_and_single_shooting_agree_at_the_optimum_of_a_stable_plant() {
    let data = hammerstein_data(1500, 3000);
    let single = fit(
        &hammerstein_start(0.6),
        &data,
        None,
        &JointSettings::default(),
    )
    .unwrap();
    let multiple = fit(
        &hammerstein_start(0.6),
        &data,
        None,
        &JointSettings::builder()
            .segment_length(100)
            .continuity_weight(30.0)
            .polish(false)
            .build()
            .unwrap(),
    )
    .unwrap();
    let (ps, pm) = (single.model.parameters(), multiple.model.parameters());
    assert!((ps[0] - pm[0]).abs() < 5e-3, "pole {} vs {}", ps[0], pm[0]);
    assert!((ps[0] - 0.85).abs() < 0.02, "pole {}", ps[0]);
    // The map, over the input's range.
    let (ns, nm) = (
        single.model.blocks()[0].map.as_ref(),
        multiple.model.blocks()[0].map.as_ref(),
    );
    for k in 0..41 {
        let z = -2.0 + 0.1 * k as f64;
        assert!(
            (ns.eval(&mut [], &[z]) - nm.eval(&mut [], &[z])).abs() < 0.02,
            "at {z}"
        );
    }
    assert!(
        (multiple.cost - single.cost).abs() < 0.01 * single.cost,
        "{} vs {}",
        multiple.cost,
        single.cost
    );
}

/// Independent windows (continuity weight zero, no polish): each window from its own fitted
/// state, the criterion a windowed simulation scores. The fit ends at no higher cost of that
/// criterion than its start, and on a stable plant it finds the pole and the map the single
/// shot finds.
#[test]
fn independent_windows_fit_the_windowed_criterion() {
    let data = hammerstein_data(1500, 3000);
    let windows = JointSettings::builder()
        .segment_length(150)
        .continuity_weight(0.0)
        .polish(false)
        .build()
        .unwrap();
    let out = fit(&hammerstein_start(0.6), &data, None, &windows).unwrap();
    assert!(
        out.cost < 0.1 * out.initial_cost,
        "{} → {}",
        out.initial_cost,
        out.cost
    );
    assert_eq!(out.stages.len(), 1);
    assert_eq!(out.stages[0].name, "multiple shooting");
    let pole = out.model.parameters()[0];
    assert!((pole - 0.85).abs() < 0.02, "pole {pole}");
    let n = out.model.blocks()[0].map.as_ref();
    for k in 0..21 {
        let z = -1.0 + 0.1 * k as f64;
        assert!(
            (n.eval(&mut [], &[z]) - (1.5 * z).tanh()).abs() < 0.05,
            "at {z}"
        );
    }
    // Zero weight only where the windows are the criterion.
    for b in [
        JointSettings::builder().continuity_weight(0.0),
        JointSettings::builder()
            .continuity_weight(0.0)
            .segment_length(150),
        JointSettings::builder()
            .continuity_weight(0.0)
            .polish(false),
    ] {
        assert!(b.build().is_err());
    }
}

#[test]
fn a_cycle_of_maps_and_bad_settings_are_clear_errors() {
    let f = GaussianFeatures::on_interval(-1.0, 1.0, 3, 0.5, 0.0).unwrap();
    let mut lft = wiener_hammerstein(0.5).matrices().clone();
    lft.dzw = dmatrix![0.0, 0.7; 0.5, 0.0];
    let e = JointModel::new(
        Lft::new(lft).unwrap(),
        vec![
            JointBlock::new("input", vec![0], 0, Box::new(f.clone())),
            JointBlock::new("sensor", vec![1], 1, Box::new(f)),
        ],
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("algebraic loop") && e.contains("`input`") && e.contains("`sensor`"),
        "{e}"
    );
    assert!(
        JointSettings::builder()
            .continuity_weight(f64::NAN)
            .build()
            .is_err()
    );
    assert!(JointSettings::builder().tolerance(0.0).build().is_err());
}

/// A backlash (play) in front of a first-order plant: its half-width is fitted with the pole,
/// from a start a third of the truth, and the play's memory is a fitted initial state.
#[test]
fn a_play_at_the_input_is_fitted_with_the_plant() {
    use structid_core::Play;
    use structid_joint::OperatorBlock;
    let plant = |a: f64| {
        let mut m = hammerstein(a, 1.0 - a).matrices().clone();
        m.bw = dmatrix![1.0 - a];
        Lft::new(m).unwrap()
    };
    let len = 2000;
    let u = input(len, 1.0, 4001);
    let truth = JointModel::new(
        plant(0.9),
        vec![JointBlock::new(
            "backlash",
            vec![0],
            0,
            Box::new(OperatorBlock::new(Box::new(Play::new(0.3).unwrap()))),
        )],
    )
    .unwrap();
    let sim = truth.simulate(&u, None).unwrap();
    let e = noise(len, 0.01, 4002);
    let data = Data::new(u, Signal::from_fn(len, 1, |k, _| sim.y.get(k, 0) + e[k])).unwrap();
    let start = JointModel::new(
        plant(0.8),
        vec![JointBlock::new(
            "backlash",
            vec![0],
            0,
            Box::new(OperatorBlock::new(Box::new(Play::new(0.1).unwrap()))),
        )],
    )
    .unwrap()
    .with_free(LftMatrix::A, 0, 0)
    .unwrap()
    .with_free(LftMatrix::Bw, 0, 0)
    .unwrap();
    let out = fit(
        &start,
        &data,
        None,
        &JointSettings::builder()
            .segment_length(200)
            .build()
            .unwrap(),
    )
    .unwrap();
    let p = out.model.parameters();
    println!(
        "play: pole {:.4}, gain {:.4}, half-width {:.4}; rms {:?}",
        p[0], p[1], p[2], out.rms
    );
    assert!((p[2] - 0.3).abs() < 0.03, "half-width {}", p[2]);
    assert!((p[0] - 0.9).abs() < 0.01, "pole {}", p[0]);
    assert!(out.rms[0] < 0.0125, "{:?}", out.rms);
}

/// A discrete Wiener–Hammerstein plant x₁⁺ = 0.8x₁ + u, w = tanh(0.7x₁), x₂⁺ = 0.3x₂ + w, y = x₂:
/// its best linear approximation has the poles 0.8 and 0.3, and of the four divisions the
/// one that puts 0.8 in front must explain the data best (the other three cannot, with any
/// map).
#[test]
fn the_wiener_hammerstein_start_puts_each_pole_in_its_block() {
    use structid_joint::{WienerHammersteinSettings, wiener_hammerstein_start};
    use structid_linear::{OeSettings, Orders, oe};
    let len = 3000;
    let u = input(len, 0.5, 77);
    let (mut x1, mut x2) = (0.0f64, 0.0f64);
    let y: Vec<f64> = (0..len)
        .map(|k| {
            let y = x2;
            let w = (0.7 * x1).tanh();
            x1 = 0.8 * x1 + u.get(k, 0);
            x2 = 0.3 * x2 + w;
            y
        })
        .collect();
    let data = Data::new(u.clone(), Signal::from_fn(len, 1, |k, _| y[k])).unwrap();
    let bla = oe(
        data.u(),
        data.y(),
        &Orders::siso(2, 1, 2),
        &OeSettings::default(),
    )
    .unwrap()
    .model;
    let start =
        wiener_hammerstein_start(&bla, &data, &WienerHammersteinSettings::default()).unwrap();
    assert_eq!(start.splits.len(), 4);
    let best = &start.splits[0];
    // The front block's single pole is near 0.8, the back block's near 0.3.
    assert_eq!(best.split.front.den.len(), 2, "{best:?}");
    assert!((best.split.front.den[1] + 0.8).abs() < 0.05, "{best:?}");
    assert!((best.split.back.den[1] + 0.3).abs() < 0.1, "{best:?}");
    // Scores are sorted and the best is clearly better than the swapped division.
    assert!(start.splits.windows(2).all(|p| p[0].rms <= p[1].rms));
    let swapped = start
        .splits
        .iter()
        .find(|s| s.split.front.den.len() == 2 && (s.split.front.den[1] + 0.3).abs() < 0.1)
        .unwrap();
    assert!(
        best.rms < 0.5 * swapped.rms,
        "{} vs {}",
        best.rms,
        swapped.rms
    );
    // The joint fit from it ends near the noise-free truth.
    let out = fit(&start.model, &data, None, &JointSettings::default()).unwrap();
    let y_rms = (y.iter().map(|v| v * v).sum::<f64>() / len as f64).sqrt();
    assert!(
        out.rms[0] < 0.01 * y_rms,
        "{:?} vs output RMS {y_rms}",
        out.rms
    );
}

/// Hammerstein–Wiener from data alone: an input dead zone, a second-order G and a sensor
/// saturation, all unknown. The start is the best linear approximation with identity maps; the
/// joint fit must reach the noise, and both maps must match the truth up to the affine changes
/// of the signals between the blocks (within 10 % of their ranges).
#[test]
fn a_hammerstein_wiener_model_is_fitted_from_its_best_linear_approximation() {
    use structid_joint::{WienerHammersteinSettings, hammerstein_wiener_start};
    use structid_linear::{OeSettings, Orders, oe};
    let len = 4000;
    let lft = wiener_hammerstein(0.0);
    let u = input(len, 1.0, 2001);
    let truth = lft
        .simulate(
            &[
                MapBinding {
                    inputs: &[0],
                    output: 0,
                    map: &dead_zone,
                },
                MapBinding {
                    inputs: &[1],
                    output: 1,
                    map: &saturation,
                },
            ],
            &u,
            None,
            None,
        )
        .unwrap();
    let e = noise(len, 0.01, 2002);
    let y = Signal::from_fn(len, 1, |k, _| truth.y.get(k, 0) + e[k]);
    let data = Data::new(u.clone(), y).unwrap();
    let bla = oe(
        data.u(),
        data.y(),
        &Orders::siso(2, 2, 1),
        &OeSettings::default(),
    )
    .unwrap()
    .model;
    let start =
        hammerstein_wiener_start(&bla, &data, &WienerHammersteinSettings::default()).unwrap();
    let out = fit(
        &start,
        &data,
        None,
        &JointSettings::builder()
            .max_iterations(200)
            .build()
            .unwrap(),
    )
    .unwrap();
    println!(
        "Hammerstein–Wiener: rms {:?}, stages {:?}",
        out.rms,
        out.stages.iter().map(|s| s.costs.len()).collect::<Vec<_>>()
    );
    assert!(out.rms[0] < 1.5 * 0.01, "{:?}", out.rms);
    // Each map along the data against the truth, up to a gain and an offset.
    let sim = out
        .model
        .simulate(&u, Some(&out.initial_states[0]))
        .unwrap();
    for (c, name) in [(0, "dead zone"), (1, "saturation")] {
        let err = rms_modulo(&truth.w.channel(c), &sim.w.channel(c), true);
        println!("{name}: {:.2} % of its range", 100.0 * err);
        assert!(err < 0.10, "{name}: {err}");
    }
}

/// x⁺ = A x + B_u u + B_w w, y = x₁, w = N(x₁) in feedback: a lightly damped second-order plant
/// whose stiffness is a kernel expansion.
fn resonant_model(damping: f64, map_scale: f64) -> JointModel {
    let lft = Lft::new(LftMatrices {
        a: dmatrix![1.0, 0.1; -0.3, 1.0 - damping],
        bu: dmatrix![0.0; 0.1],
        be: dmatrix![0.0; 0.0],
        bw: dmatrix![0.0; -0.1],
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
    let f = GaussianFeatures::on_interval(-2.0, 2.0, 7, 0.8, 0.0).unwrap();
    let n = f.parameters().len();
    let p: Vec<f64> = (0..n)
        .map(|i| map_scale * ((i as f64) * 1.3).sin())
        .collect();
    let f = f.with_parameters(&p).unwrap();
    JointModel::new(lft, vec![JointBlock::new("N", vec![0], 0, f)])
        .unwrap()
        .with_free(LftMatrix::A, 1, 1)
        .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(8))]
    /// A window that opens in the middle of the motion: the initial state fitted with the
    /// model held is the one it was simulated from, and the model's parameters do not move.
    #[test]
    fn the_initial_state_of_a_window_is_recovered_with_the_model_held(
        damping in 0.02f64..0.2,
        scale in 0.0f64..0.3,
        x1 in -1.5f64..1.5,
        x2 in -1.5f64..1.5,
        seed in 0u64..50,
    ) {
        use structid_joint::fit_initial_state;
        let model = resonant_model(damping, scale);
        let u = input(60, 0.5, 3000 + seed);
        let y = model.simulate(&u, Some(&[x1, x2])).unwrap().y;
        let data = Data::new(u, y).unwrap();
        let x0 = fit_initial_state(&model, &data, &JointSettings::default()).unwrap();
        prop_assert_eq!(x0.len(), 1);
        prop_assert!((x0[0][0] - x1).abs() < 1e-6 && (x0[0][1] - x2).abs() < 1e-6, "{:?}", x0);
        // The held model has nothing free and simulates as the model does.
        let held = model.held();
        prop_assert!(held.parameters().is_empty());
        let (a, b) = (
            model.simulate(data.u(), Some(&x0[0])).unwrap().y,
            held.simulate(data.u(), Some(&x0[0])).unwrap().y,
        );
        prop_assert_eq!(a.channel(0), b.channel(0));
    }
}

/// A held operator passes on every derivative with respect to its input and its memory, as
/// the free operator computes them, sample after sample.
#[test]
fn a_held_operator_keeps_its_state_derivatives() {
    use structid_core::BoucWen;
    use structid_joint::{BlockJacobian, HeldMap, OperatorBlock};
    let free = OperatorBlock::new(Box::new(BoucWen::new(0.3, 1.0, 0.5, 0.5).unwrap()));
    let held = HeldMap::new(free.boxed());
    assert!(held.parameters().is_empty() && !free.parameters().is_empty());
    assert_eq!(held.state_len(), free.state_len());
    let n = free.state_len();
    let (mut sf, mut sh) = (vec![0.0; n], vec![0.0; n]);
    for k in 0..40 {
        let z = [1.5 * (0.3 * k as f64).sin()];
        let (mut jf, mut jh) = (BlockJacobian::for_map(&free), BlockJacobian::for_map(&held));
        let wf = free.eval_jacobian(&mut sf, &z, &mut jf);
        let wh = held.eval_jacobian(&mut sh, &z, &mut jh);
        assert_eq!(wf, wh);
        assert_eq!(sf, sh);
        assert_eq!(
            (&jf.dw_dz, &jf.dw_ds, &jf.ds_ds, &jf.ds_dz),
            (&jh.dw_dz, &jh.dw_ds, &jh.ds_ds, &jh.ds_dz)
        );
        assert!(jh.dw_dp.is_empty() && jh.ds_dp.is_empty());
    }
    // Derivatives that do not vanish: the test would see a dropped copy.
    let mut j = BlockJacobian::for_map(&held);
    held.eval_jacobian(&mut sh, &[0.7], &mut j);
    assert!(j.dw_ds.iter().chain(&j.ds_ds).any(|v| *v != 0.0));
}
