//! Refinement over several records: each record is simulated from rest (or from its own
//! estimated initial state) in the map step, the linear step and the validation error. The
//! checks compare with quantities computed here independently, record by record, and with
//! the truth the data were simulated from.

use std::sync::Arc;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};
use structid_core::refine::{
    LinearStructure, RefineSettings, Refinement, output_error_records_with_state, refine,
    refine_linear,
};
use structid_core::selection::{Criterion, SelectionSettings, select};
use structid_core::{
    Data, Dispersion, FourierDispersion, FourierWeights, IdentifySettings, InitialState,
    Interpolant, MapBinding, Model, PolynomialDispersion, Signal, SolverChoice, SumDispersion,
    identify,
};
use structid_linear::{OeSettings, PolynomialModel};

fn second_order(r: f64, theta: f64, b: [f64; 2]) -> PolynomialModel {
    PolynomialModel {
        num: vec![vec![0.0, b[0], b[1]]],
        den: vec![1.0, -2.0 * r * theta.cos(), r * r],
        sample_time: None,
    }
}

fn truth() -> PolynomialModel {
    second_order(0.95, std::f64::consts::PI / 8.0, [0.10, 0.05])
}

fn wrong() -> PolynomialModel {
    second_order(0.85, std::f64::consts::PI / 7.0, [0.13, 0.03])
}

fn stiffness(y: f64) -> f64 {
    0.5 * y.powi(3) + 0.05 * y * y
}

/// Low-pass filtered Gaussian noise of RMS about `amplitude`.
fn input(len: usize, amplitude: f64, seed: u64) -> Signal {
    let mut rng = StdRng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let mut s = 0.0;
    Signal::from_fn(len, 1, |_, _| {
        s = 0.7 * s + 0.3 * n.sample(&mut rng);
        amplitude * s / 0.42
    })
}

/// y = G·(u − N(y)) + e simulated from rest, plus white noise.
fn record(len: usize, amplitude: f64, seed: u64, noise: f64) -> Data {
    let u = input(len, amplitude, seed);
    let structure = LinearStructure::output_feedback("N");
    let lft = structure
        .lft(&structure.initial_from_bla(&truth()).unwrap())
        .unwrap();
    let f = |z: &[f64]| stiffness(z[0]);
    let sim = lft
        .simulate(
            &[MapBinding {
                inputs: &[0],
                output: 0,
                map: &f,
            }],
            &u,
            None,
            None,
        )
        .unwrap();
    let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed);
    let n = Normal::new(0.0, noise).unwrap();
    let y = Signal::from_fn(len, 1, |k, _| sim.y.get(k, 0) + n.sample(&mut rng));
    Data::new(u, y).unwrap()
}

/// Features only (Fourier + cubic trend): D = ‖a‖² does not depend on the samples, so a
/// record given twice is the same problem as the record once.
fn dispersion() -> Arc<dyn Dispersion> {
    Arc::new(
        SumDispersion::new(vec![
            Arc::new(FourierDispersion::new(FourierWeights::GaussianLike { sigma: 0.3 }).unwrap()),
            Arc::new(
                PolynomialDispersion::new(3)
                    .unwrap()
                    .with_scale(10.0)
                    .unwrap(),
            ),
        ])
        .unwrap(),
    )
}

fn settings(beta: f64, x0: InitialState, iterations: usize) -> RefineSettings {
    RefineSettings::builder()
        .max_iterations(iterations)
        .tolerance(0.0)
        .identify(
            IdentifySettings::builder()
                .beta(beta)
                .initial_state(x0)
                .solver(SolverChoice::Features)
                .build()
                .unwrap(),
        )
        .selection(None)
        .oe(OeSettings::builder().tolerance(1e-10).build().unwrap())
        .build()
        .unwrap()
}

fn parameters_distance(a: &PolynomialModel, b: &PolynomialModel) -> f64 {
    a.parameters()
        .iter()
        .zip(b.parameters())
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// The pooled RMS simulation error of a refinement's model on `data`, each record simulated
/// from rest with the returned map in the loop (computed here, record by record).
fn pooled_rms(out: &Refinement, data: &Data) -> f64 {
    let map = out.identification.blocks[0].map.as_ref();
    let (mut s, mut n) = (0.0, 0);
    for r in data.records() {
        let sim = out
            .model
            .lft()
            .simulate(
                &[MapBinding {
                    inputs: &[0],
                    output: 0,
                    map,
                }],
                r.u(),
                None,
                None,
            )
            .unwrap();
        for k in 0..r.len() {
            s += (r.y().get(k, 0) - sim.y.get(k, 0)).powi(2);
            n += 1;
        }
    }
    (s / n as f64).sqrt()
}

fn assert_monotone(out: &Refinement) {
    let tol = |j: f64| 1e-9 * j.abs() + 1e-15;
    for (k, it) in out.iterations.iter().enumerate() {
        if let Some(after) = it.cost_after_linear {
            assert!(
                after <= it.cost_after_maps + tol(it.cost_after_maps),
                "iteration {k}: linear step raised J from {} to {after}",
                it.cost_after_maps
            );
            if let Some(next) = out.iterations.get(k + 1) {
                assert!(
                    next.cost_after_maps <= after + tol(after),
                    "iteration {}: map step raised J from {after} to {}",
                    k + 1,
                    next.cost_after_maps
                );
            }
        }
    }
}

/// Two records from rest: J never increases with either initial-state treatment, G comes
/// back, the validation error over two validation records is the pooled error of each
/// record simulated from rest, and the concatenated record (which carries the first record's
/// final state into the second) gives a worse G.
#[test]
fn refinement_over_two_records_decreases_j_and_recovers_g() {
    let (a, b) = (record(1500, 0.3, 3, 0.002), record(1000, 0.3, 4, 0.002));
    let data = Data::from_records(vec![a.clone(), b.clone()]).unwrap();
    let validation =
        Data::from_records(vec![record(800, 0.3, 5, 0.0), record(600, 0.3, 6, 0.0)]).unwrap();
    let structure = LinearStructure::output_feedback("N");
    let start = structure.initial_from_bla(&wrong()).unwrap();
    let gt = structure.initial_from_bla(&truth()).unwrap();
    assert!(parameters_distance(&start, &gt) > 0.1);
    for x0 in [InitialState::Zero, InitialState::Estimate] {
        let out = refine(
            &structure,
            &start,
            dispersion(),
            &data,
            Some(&validation),
            &settings(1e-7, x0, 8),
        )
        .unwrap();
        assert_monotone(&out);
        // The numerator is pinned by the structure (u enters only through it); the
        // denominator shares a free direction with the map (F + k·B, N − k·y).
        let b = &out.linear.num[0];
        let bt = &gt.num[0];
        for j in 1..3 {
            assert!(
                (b[j] - bt[j]).abs() < 0.02 * bt[1].abs(),
                "{x0:?}: b_{j} {} vs {}",
                b[j],
                bt[j]
            );
        }
        let first = out.iterations[0].validation_rms.unwrap();
        let best = out.iterations[out.best].validation_rms.unwrap();
        let scale = (validation.y().as_slice().iter().map(|v| v * v).sum::<f64>()
            / validation.len() as f64)
            .sqrt();
        eprintln!("{x0:?}: validation RMS {first} -> {best}, output RMS {scale}");
        assert!(
            best < 0.01 * scale && best < 0.1 * first,
            "{x0:?}: {first} -> {best}"
        );
        // The reported validation error is the pooled error of each record from rest.
        let reported = out.iterations[out.best].validation_rms.unwrap();
        let here = pooled_rms(&out, &validation);
        assert!(
            (reported - here).abs() <= 1e-9 * here,
            "{x0:?}: reported {reported} vs {here}"
        );
        let est = out.iterations[out.best].estimation_rms;
        let here = pooled_rms(&out, &data);
        assert!((est - here).abs() <= 1e-9 * here, "{x0:?}: {est} vs {here}");
    }
    // The concatenated record: the seam is no restart, so the fit is of a different problem.
    let cat = |f: &dyn Fn(&Data) -> &Signal| {
        Signal::new(1, [f(&a).as_slice(), f(&b).as_slice()].concat()).unwrap()
    };
    let glued = Data::new(cat(&|d| d.u()), cat(&|d| d.y())).unwrap();
    let s = settings(1e-7, InitialState::Zero, 8);
    let two = refine(&structure, &start, dispersion(), &data, None, &s).unwrap();
    let one = refine(&structure, &start, dispersion(), &glued, None, &s).unwrap();
    let (v_two, v_one) = (pooled_rms(&two, &validation), pooled_rms(&one, &validation));
    let b_err = |g: &PolynomialModel| {
        (1..3)
            .map(|j| (g.num[0][j] - gt.num[0][j]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let (b_two, b_one) = (b_err(&two.linear), b_err(&one.linear));
    eprintln!("validation RMS: records {v_two}, concatenation {v_one}; b error {b_two} vs {b_one}");
    assert!(
        v_two < 0.5 * v_one,
        "records {v_two} vs concatenation {v_one}"
    );
    assert!(b_two < b_one, "records {b_two} vs concatenation {b_one}");
}

/// One record passed as a `Data` of one record, or the same record given twice, is the same
/// problem as the record once: with feature dispersions D = ‖a‖² and the noise term is a
/// mean, so (1/2L)·2‖e‖² = (1/L)‖e‖²; with a free x₀ each copy gets the same one.
#[test]
fn a_record_given_twice_refines_like_the_record_once() {
    let a = record(1200, 0.3, 11, 0.005);
    let structure = LinearStructure::output_feedback("N");
    let start = structure.initial_from_bla(&wrong()).unwrap();
    for x0 in [InitialState::Zero, InitialState::Estimate] {
        let s = settings(1e-6, x0, 4);
        let once = refine(&structure, &start, dispersion(), &a, None, &s).unwrap();
        let wrapped = Data::from_records(vec![a.clone()]).unwrap();
        let same = refine(&structure, &start, dispersion(), &wrapped, None, &s).unwrap();
        assert_eq!(same.linear, once.linear);
        let twice = Data::from_records(vec![a.clone(), a.clone()]).unwrap();
        let out = refine(&structure, &start, dispersion(), &twice, None, &s).unwrap();
        assert_eq!(out.iterations.len(), once.iterations.len());
        for (p, q) in out.iterations.iter().zip(&once.iterations) {
            let rel = |x: f64, y: f64| (x - y).abs() / y.abs().max(1e-300);
            assert!(
                rel(p.cost_after_maps, q.cost_after_maps) < 1e-6,
                "{x0:?}: {p:?} vs {q:?}"
            );
            assert!(rel(p.estimation_rms, q.estimation_rms) < 1e-6, "{x0:?}");
        }
        for (x, y) in out.linear.parameters().iter().zip(once.linear.parameters()) {
            assert!(
                (x - y).abs() < 1e-6 * y.abs().max(1e-3),
                "{x0:?}: {x} vs {y}"
            );
        }
    }
}

/// The linear step over two records: its cost is the mean over both records of the error of
/// each record simulated from rest (from its own initial state when x₀ is free), computed here
/// with the fitted G; and a free x₀ per record recovers G from records that do not start at
/// rest.
#[test]
fn the_linear_step_over_records_is_the_stacked_output_error() {
    let g = PolynomialModel {
        num: vec![vec![0.0, 0.3, 0.1]],
        den: vec![1.0, -1.3, 0.6],
        sample_time: None,
    };
    // Free responses of the two records: different initial states.
    let free = [(1.5, -0.4), (-2.0, 0.9)];
    let records: Vec<(Signal, Signal)> = [(700, 1u64), (500, 2)]
        .iter()
        .zip(free)
        .map(|(&(len, seed), (p, q))| {
            let u = input(len, 1.0, seed);
            let sim = g.simulate(&u).unwrap();
            // y_k of 1/F from y₋₁ = p, y₋₂ = q (zero input): the free response.
            let mut fr = vec![0.0; len];
            let (mut y1, mut y2) = (p, q);
            for v in fr.iter_mut() {
                let y0 = 1.3 * y1 - 0.6 * y2;
                *v = y0;
                y2 = y1;
                y1 = y0;
            }
            let y = Signal::from_fn(len, 1, |k, _| sim[k] + fr[k]);
            (u, y)
        })
        .collect();
    let pairs: Vec<(&Signal, &Signal)> = records.iter().map(|(u, y)| (u, y)).collect();
    let start = PolynomialModel {
        num: vec![vec![0.0, 0.25, 0.2]],
        den: vec![1.0, -1.1, 0.4],
        sample_time: None,
    };
    let s = OeSettings::builder().tolerance(1e-12).build().unwrap();
    let fit = output_error_records_with_state(&pairs, &start, &s, true, 0).unwrap();
    assert_eq!(fit.model.num.len(), 1);
    // The uncertainty is that of G's parameters (the initial states marginalised out).
    let d = g.parameters().len();
    assert_eq!(fit.parameter_std.len(), d);
    let cov = fit.parameter_covariance.as_ref().unwrap();
    assert_eq!((cov.nrows(), cov.ncols()), (d, d));
    for (i, s) in fit.parameter_std.iter().enumerate() {
        assert!((cov[(i, i)].max(0.0).sqrt() - s).abs() <= 1e-12 * s.max(1e-300));
    }
    for (x, y) in fit.model.parameters().iter().zip(g.parameters()) {
        assert!((x - y).abs() < 1e-7, "{x} vs {y}");
    }
    assert!(fit.cost < 1e-16, "{}", fit.cost);
    // From rest, the records' free responses are unexplained: the cost is the mean squared
    // error of each record simulated from rest by the fitted G, computed here.
    let rest = output_error_records_with_state(&pairs, &start, &s, false, 0).unwrap();
    let (mut sse, mut n) = (0.0, 0);
    for (u, y) in &records {
        let sim = rest.model.simulate(u).unwrap();
        sse += (0..y.len())
            .map(|k| (y.get(k, 0) - sim[k]).powi(2))
            .sum::<f64>();
        n += y.len();
    }
    assert!((rest.cost - sse / n as f64).abs() <= 1e-10 * rest.cost);
    assert!(rest.cost > 1e-4);
}

/// `refine_linear` over two records at the sensor site (output error through the map, each
/// record simulated from rest) recovers G, and its costs are those of the stacked records.
#[test]
fn refine_linear_through_a_sensor_map_over_records() {
    let truth = second_order(0.9, 0.3, [0.10, 0.06]);
    let structure = LinearStructure::output("sensor");
    let lft = structure.lft(&truth).unwrap();
    let map = |v: f64| v + 0.2 * v * v * v;
    let f = |z: &[f64]| map(z[0]);
    let rec = |len: usize, seed: u64| {
        let u = input(len, 0.3, seed);
        let sim = lft
            .simulate(
                &[MapBinding {
                    inputs: &[0],
                    output: 0,
                    map: &f,
                }],
                &u,
                None,
                None,
            )
            .unwrap();
        Data::new(u, sim.y).unwrap()
    };
    let data = Data::from_records(vec![rec(900, 41), rec(700, 42)]).unwrap();
    let start = second_order(0.85, 0.35, [0.12, 0.05]);
    let r = refine_linear(
        &structure,
        &start,
        &f,
        &data,
        &settings(1e-7, InitialState::Zero, 1),
    )
    .unwrap();
    for (x, y) in r.linear().parameters().iter().zip(truth.parameters()) {
        assert!((x - y).abs() < 1e-6, "{x} vs {y}");
    }
    assert!(r.cost_after < 1e-12 * r.cost_before.max(1.0));
    // cost_before: the mean over both records of (y − N(G₀·u))², each from rest, here.
    let (mut sse, mut n) = (0.0, 0);
    for rec in data.records() {
        let z = start.simulate(rec.u()).unwrap();
        for k in 0..rec.len() {
            sse += (rec.y().get(k, 0) - map(z[k])).powi(2);
            n += 1;
        }
    }
    assert!((r.cost_before - sse / n as f64).abs() <= 1e-10 * r.cost_before);
    assert!(r.simulation_rms_after < 1e-5 * r.simulation_rms_before);
}

/// β chosen on two validation records: the criterion at the chosen β is the pooled mean
/// squared simulation error of both records, each from rest, recomputed here from a fit at
/// that β.
#[test]
fn validation_selection_pools_several_validation_records() {
    let structure = LinearStructure::output_feedback("N");
    let model: Model = structure
        .model(&structure.initial_from_bla(&truth()).unwrap(), dispersion())
        .unwrap();
    let data = record(1000, 0.3, 21, 0.01);
    let validation =
        Data::from_records(vec![record(500, 0.3, 22, 0.0), record(400, 0.3, 23, 0.0)]).unwrap();
    let id_settings = IdentifySettings::builder()
        .solver(SolverChoice::Features)
        .build()
        .unwrap();
    let sel = SelectionSettings::builder()
        .criterion(Criterion::Validation)
        .build()
        .unwrap();
    let s = select(&model, &data, Some(&validation), &id_settings, &sel).unwrap();
    assert!(s.method.contains("2 records"), "{}", s.method);
    let id = identify(&model, &data, &id_settings.with_beta(s.beta).unwrap()).unwrap();
    let map: &dyn Interpolant = id.blocks[0].map.as_ref();
    let (mut sse, mut n) = (0.0, 0);
    for r in validation.records() {
        let sim = model
            .lft()
            .simulate(
                &[MapBinding {
                    inputs: &[0],
                    output: 0,
                    map,
                }],
                r.u(),
                None,
                None,
            )
            .unwrap();
        for k in 0..r.len() {
            sse += (r.y().get(k, 0) - sim.y.get(k, 0)).powi(2);
            n += 1;
        }
    }
    let best = s
        .curve
        .iter()
        .find(|t| t.beta == s.beta)
        .expect("the chosen β is a trial");
    let here = sse / n as f64;
    assert!(
        (best.value - here).abs() <= 1e-9 * here,
        "{} vs {here}",
        best.value
    );
}
