//! `refine_joint` from a model file: the fit recovers what generated the data, and the model
//! file it writes simulates as the fitted model does.

use structid_core::{Data, Signal};
use structid_io::ModelFile;
use structid_workflow::{
    BetaChoice, JointRequest, JointWorkflowSettings, refine_joint, simulate_model_file,
    write_joint_outputs,
};

/// y = G·w₁ with w₁ = sat(w₀), w₀ = play(u): an operator and a static map in series through
/// D_zw, behind a first-order G whose pole is free.
const TRUTH: &str = r#"
[lft]
A = [[0.85]]
Bu = [[0.0]]
Bw = [[0.0, 0.15]]
Cy = [[1.0]]
Dye = [[1.0]]
Cz = [[0.0], [0.0]]
Dzu = [[1.0], [0.0]]
Dzw = [[0.0, 0.0], [1.0, 0.0]]
[signals]
u = ["u"]
y = ["y"]
[[nonlinearity]]
name = "backlash"
inputs = [0]
output = 0
operator = { kind = "play", half_width = 0.2 }
[[nonlinearity]]
name = "limit"
inputs = [1]
output = 1
truth = "0.8*tanh(z0/0.8)"
"#;

fn input(len: usize) -> Signal {
    Signal::from_fn(len, 1, |k, _| {
        let t = k as f64;
        1.2 * ((0.011 * t).sin() * (0.053 * t).cos() + 0.4 * (0.0071 * t + 1.0).sin())
    })
}

#[test]
fn an_operator_and_a_map_in_series_are_fitted_from_a_model_file_and_written_back() {
    let truth = ModelFile::parse(TRUTH, None).unwrap();
    let u = input(3000);
    let sim = simulate_model_file(&truth, &u, None).unwrap();
    let data = Data::new(u.clone(), sim.y.clone()).unwrap();
    // The start: the pole off by 0.1, the play a quarter of its width, the map unknown
    // (no truth: it starts at zero).
    let start_text = TRUTH
        .replace("A = [[0.85]]", "A = [[0.75]]")
        .replace("half_width = 0.2", "half_width = 0.05")
        .replace("truth = \"0.8*tanh(z0/0.8)\"\n", "");
    let start = ModelFile::parse(&start_text, None).unwrap();
    let settings = JointWorkflowSettings {
        beta: BetaChoice::Fixed(1e-8),
        free: vec!["A".into()],
        ..JointWorkflowSettings::default()
    };
    let out = refine_joint(&JointRequest {
        model: &start,
        data: &data,
        settings,
    })
    .unwrap();
    let p = out.fit.model.parameters();
    println!(
        "pole {:.4}, half-width {:.4}, rms {:?}",
        p[0], p[1], out.fit.rms
    );
    assert!((p[0] - 0.85).abs() < 0.01, "pole {}", p[0]);
    assert!((p[1] - 0.2).abs() < 0.02, "half-width {}", p[1]);
    assert!(out.fit.rms[0] < 0.01 * 0.8, "{:?}", out.fit.rms);
    // The written model file, read back, simulates as the fitted model (its map as a table).
    let dir = tempfile::tempdir().unwrap();
    write_joint_outputs(&out, dir.path(), &structid_io::OutputGuard::new()).unwrap();
    let back = ModelFile::from_path(&dir.path().join("model.toml")).unwrap();
    assert_eq!(back.blocks[0].operator, out.model_file.blocks[0].operator);
    let x0 = &out.fit.initial_states[0][..1];
    let from_file = simulate_model_file(&back, &u, Some(x0)).unwrap();
    let fitted = out
        .fit
        .model
        .simulate(&u, Some(&out.fit.initial_states[0]))
        .unwrap();
    let diff = from_file
        .y
        .channel(0)
        .iter()
        .zip(fitted.y.channel(0))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(diff < 1e-3, "written model differs by {diff}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("joint.json")).unwrap())
            .unwrap();
    assert!(json["cost"].as_f64().unwrap() <= json["initial_cost"].as_f64().unwrap());
}

#[test]
fn beta_is_chosen_on_the_validation_record_and_bad_requests_are_clear() {
    let truth = ModelFile::parse(TRUTH, None).unwrap();
    let (u, v) = (
        input(1500),
        Signal::from_fn(800, 1, |k, _| 0.9 * (0.02 * k as f64).sin()),
    );
    let est = Data::new(u.clone(), simulate_model_file(&truth, &u, None).unwrap().y).unwrap();
    let val = Data::new(v.clone(), simulate_model_file(&truth, &v, None).unwrap().y).unwrap();
    let start =
        ModelFile::parse(&TRUTH.replace("truth = \"0.8*tanh(z0/0.8)\"\n", ""), None).unwrap();
    let settings = JointWorkflowSettings {
        beta: BetaChoice::Validated {
            grid: vec![1e-8, 1e2],
            validation: val,
        },
        ..JointWorkflowSettings::default()
    };
    let out = refine_joint(&JointRequest {
        model: &start,
        data: &est,
        settings,
    })
    .unwrap();
    assert_eq!(out.trials.len(), 2);
    let best = out
        .trials
        .iter()
        .min_by(|a, b| a.validation_rms[0].total_cmp(&b.validation_rms[0]))
        .unwrap();
    assert_eq!(best.beta, out.beta);
    // A huge β flattens the map: it must validate worse than the small one.
    assert_eq!(out.beta, 1e-8, "{:?}", out.trials);
    // A free entry that does not exist, and a static block without truth in simulation.
    let e = refine_joint(&JointRequest {
        model: &start,
        data: &est,
        settings: JointWorkflowSettings {
            free: vec!["Bq".into()],
            ..JointWorkflowSettings::default()
        },
    })
    .unwrap_err()
    .to_string();
    assert!(e.contains("free entry `Bq`"), "{e}");
    let e = simulate_model_file(&start, &u, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("block `limit` has no `truth`"), "{e}");
}

/// Two tanks sampled by forward Euler, only the lower level measured; both outflows √-laws.
const TANKS: &str = r#"
[lft]
A = [[1.0, 0.0], [0.0, 1.0]]
Bu = [[0.1], [0.0]]
Bw = [[-0.1, 0.0], [0.1, -0.1]]
Cy = [[0.0, 1.0]]
Dye = [[1.0]]
Cz = [[1.0, 0.0], [0.0, 1.0]]
Dze = [[0.0], [1.0]]
[signals]
u = ["u"]
y = ["y"]
[[nonlinearity]]
name = "upper"
inputs = [0]
output = 0
truth = "0.5*sqrt(abs(z0))"
[[nonlinearity]]
name = "lower"
inputs = [1]
output = 1
truth = "0.4*sqrt(abs(z0))"
"#;

/// The latent upper outflow, started from a linear guess only, and the lower outflow, started
/// from nothing: the linear start, the smoothed latent level and the joint fit recover the
/// upper outflow within 10 % of its range over the central 90 % of the levels it visited (the
/// true latent level from the simulation). With no start at all for the latent block, the
/// error says what to give.
#[test]
fn a_latent_map_is_recovered_from_the_smoothed_latent_signal() {
    let truth = ModelFile::parse(TANKS, None).unwrap();
    let len = 6000;
    let u = Signal::from_fn(len, 1, |k, _| {
        let step = (k / 150) as f64;
        0.7 + 0.35 * ((1.7 * step).sin() + 0.6 * (0.37 * step * step).cos()) / 1.6
    });
    let sim = structid_workflow::simulate_model_file_noisy(&truth, &u, 0.005, 7).unwrap();
    let clean = simulate_model_file(&truth, &u, None).unwrap();
    let data = Data::new(u, sim.y.clone()).unwrap();
    let start_text = TANKS
        .replace("truth = \"0.5*sqrt(abs(z0))\"", "truth = \"0.2*z0\"")
        .replace("truth = \"0.4*sqrt(abs(z0))\"\n", "");
    let start = ModelFile::parse(&start_text, None).unwrap();
    assert_eq!(
        start.block_access().unwrap()[0],
        structid_core::BlockAccess::Latent
    );
    let settings = JointWorkflowSettings {
        beta: BetaChoice::Fixed(1e-8),
        fit: structid_joint::JointSettings::builder()
            .estimate_initial_state(true)
            .max_iterations(100)
            .build()
            .unwrap(),
        ..JointWorkflowSettings::default()
    };
    let out = refine_joint(&JointRequest {
        model: &start,
        data: &data,
        settings: settings.clone(),
    })
    .unwrap();
    let flat = ModelFile::parse(&start_text.replace("truth = \"0.2*z0\"\n", ""), None).unwrap();
    let e = match refine_joint(&JointRequest {
        model: &flat,
        data: &data,
        settings,
    }) {
        Ok(_) => panic!("a latent block with a flat start was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("block `upper` is latent") && e.contains("give it a start"),
        "{e}"
    );
    // The latent level's origin is not in the data (x₁ + c with N₁(· − c) gives the same y):
    // the fitted level is compared after the mean shift between its simulation and the truth.
    let true_level = clean.z.channel(0);
    let fitted = out
        .fit
        .model
        .simulate(data.u(), Some(&out.fit.initial_states[0]))
        .unwrap();
    let shift = fitted
        .z
        .channel(0)
        .iter()
        .zip(&true_level)
        .map(|(a, b)| a - b)
        .sum::<f64>()
        / len as f64;
    let mut levels = true_level.clone();
    levels.sort_by(f64::total_cmp);
    let (lo, hi) = (levels[len / 20], levels[len - len / 20]);
    let map = out.fit.model.blocks()[0].map.as_ref();
    let grid: Vec<f64> = (0..100).map(|i| lo + (hi - lo) * i as f64 / 99.0).collect();
    let err = (grid
        .iter()
        .map(|z| (map.eval(&mut [], &[z + shift]) - 0.5 * z.sqrt()).powi(2))
        .sum::<f64>()
        / 100.0)
        .sqrt();
    let range = 0.5 * (hi.sqrt() - lo.sqrt());
    println!(
        "upper outflow: {:.3} % of its range ({err:.3e} of {range:.3}); shift {shift:.3}; rms {:?}",
        100.0 * err / range,
        out.fit.rms
    );
    assert!(err < 0.10 * range, "upper outflow {err} vs range {range}");
    assert!(out.fit.rms[0] < 1.5 * 0.005, "{:?}", out.fit.rms);
}

/// A map whose input the data never move cannot be placed: the error names the block and says
/// what to check.
#[test]
fn a_map_without_excitation_is_a_clear_error() {
    let start =
        ModelFile::parse(&TRUTH.replace("truth = \"0.8*tanh(z0/0.8)\"\n", ""), None).unwrap();
    let u = Signal::from_fn(500, 1, |_, _| 0.0);
    let y = Signal::from_fn(500, 1, |k, _| 1e-3 * (k as f64).sin());
    let data = Data::new(u, y).unwrap();
    let e = match refine_joint(&JointRequest {
        model: &start,
        data: &data,
        settings: JointWorkflowSettings::default(),
    }) {
        Ok(_) => panic!("a map that the data never excite was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("block `limit`") && e.contains("does not move") && e.contains("excite"),
        "{e}"
    );
}

/// y = G·N(u) with a saturating N whose slope falls to a tenth over the data: a Hammerstein
/// model declared `shape = "increasing"` and started from nothing (no `truth`).
const SHAPED: &str = r#"
[lft]
A = [[0.8]]
Bu = [[0.0]]
Bw = [[0.2]]
Cy = [[1.0]]
Dye = [[1.0]]
Cz = [[0.0]]
Dzu = [[1.0]]
Dzw = [[0.0]]
[signals]
u = ["u"]
y = ["y"]
[[nonlinearity]]
name = "limit"
inputs = [0]
output = 0
truth = "tanh(z0) + 0.1*z0"
"#;

#[test]
fn a_declared_shape_holds_beyond_the_data_and_is_written_back() {
    let truth = ModelFile::parse(SHAPED, None).unwrap();
    let u = input(2000);
    let y = simulate_model_file(&truth, &u, None).unwrap().y;
    let data = Data::new(u.clone(), y).unwrap();
    for (direction, sign) in [("increasing", 1.0), ("decreasing", -1.0)] {
        // The decreasing case fits −N through −G: the same data, the map mirrored.
        let text = SHAPED
            .replace(
                "truth = \"tanh(z0) + 0.1*z0\"",
                &format!("shape = \"{direction}\""),
            )
            .replace("Bw = [[0.2]]", &format!("Bw = [[{}]]", 0.2 * sign));
        let start = ModelFile::parse(&text, None).unwrap();
        let out = refine_joint(&JointRequest {
            model: &start,
            data: &data,
            settings: JointWorkflowSettings {
                beta: BetaChoice::Fixed(1e-10),
                ..JointWorkflowSettings::default()
            },
        })
        .unwrap();
        let map = &out.fit.model.blocks()[0].map;
        let (lo, hi) = u
            .channel(0)
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        // Within the data the map is the truth (up to the level the LFT cannot see: none
        // here, y = G·N(u) has no other path).
        let err = (0..=50)
            .map(|k| {
                let z = lo + (hi - lo) * k as f64 / 50.0;
                (map.eval(&mut [], &[z]) - sign * (z.tanh() + 0.1 * z)).abs()
            })
            .fold(0.0, f64::max);
        assert!(err < 0.02 * (hi - lo), "{direction}: map error {err}");
        // Beyond the data, three ranges either side, it still goes the declared way.
        let wide: Vec<f64> = (0..=600)
            .map(|k| {
                map.eval(
                    &mut [],
                    &[lo - 3.0 * (hi - lo) + 7.0 * (hi - lo) * k as f64 / 600.0],
                )
            })
            .collect();
        let d: structid_core::Monotonicity = direction.parse().unwrap();
        assert!(d.holds(&wide), "{direction}: not monotone beyond the data");
        assert_eq!(out.model_file.blocks[0].shape, Some(d));
        // The written file follows the fitted map beyond the data as well: on an input half
        // as large again, its simulation is the fitted model's (up to the table's linear
        // interpolation).
        let dir = tempfile::tempdir().unwrap();
        write_joint_outputs(&out, dir.path(), &structid_io::OutputGuard::new()).unwrap();
        let back = ModelFile::from_path(&dir.path().join("model.toml")).unwrap();
        let wide = Signal::from_fn(u.len(), 1, |k, _| 1.5 * u.get(k, 0));
        let from_file = simulate_model_file(&back, &wide, None)
            .unwrap()
            .y
            .channel(0);
        let fitted = out.fit.model.simulate(&wide, None).unwrap().y.channel(0);
        let diff = from_file
            .iter()
            .zip(&fitted)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            diff < 1e-3,
            "{direction}: written model differs by {diff} beyond the data"
        );
    }
}
