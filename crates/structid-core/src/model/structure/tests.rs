use super::*;
use crate::MapBinding;
use nalgebra::dmatrix;
use serde::Deserialize;
use serde::de::IntoDeserializer;
use structid_lti::Signal;

/// A nominal model with a coloured noise path: y = 0.4q⁻¹/(1 − 0.7q⁻¹)·u + (1 + 0.5q⁻¹)/(1 − 0.7q⁻¹)·e
/// in one state (innovations form: B_e = 0.5 + 0.7 = 1.2).
fn nominal() -> Lft {
    Lft::new(LftMatrices {
        a: dmatrix![0.7],
        bu: dmatrix![0.4],
        be: dmatrix![1.2],
        bw: DMatrix::zeros(1, 0),
        cy: dmatrix![1.0],
        dyu: dmatrix![0.0],
        dye: dmatrix![1.0],
        dyw: DMatrix::zeros(1, 0),
        cz: DMatrix::zeros(0, 1),
        dzu: DMatrix::zeros(0, 1),
        dze: DMatrix::zeros(0, 1),
        dzw: DMatrix::zeros(0, 0),
    })
    .unwrap()
    .with_sample_time(0.1)
    .unwrap()
}

/// Reference simulation of each structure by direct recursion of the transfer functions.
fn reference(site: Site, f: fn(f64) -> f64, u: &[f64], e: &[f64]) -> Vec<f64> {
    let n = u.len();
    let (mut xg, mut xh) = (0.0, 0.0); // G's and H's states (separate realisations)
    let mut y = vec![0.0; n];
    let mut prev_y = 0.0;
    for k in 0..n {
        let yh = xh + e[k];
        let yk = match site {
            Site::Output => f(xg) + yh,
            _ => xg + yh,
        };
        y[k] = yk;
        let drive = match site {
            Site::Input => f(u[k]),
            Site::Output => u[k],
            Site::OutputFeedback => u[k] - f(yk),
            _ => u[k] - f((yk - prev_y) / 0.1),
        };
        prev_y = yk;
        xg = 0.7 * xg + 0.4 * drive;
        xh = 0.7 * xh + 1.2 * e[k];
    }
    y
}

fn excitation() -> (Vec<f64>, Vec<f64>) {
    let u: Vec<f64> = (0..200).map(|k| (0.13 * k as f64).sin() * 1.5).collect();
    let e: Vec<f64> = (0..200)
        .map(|k| 0.05 * ((k * 37 % 11) as f64 - 5.0))
        .collect();
    (u, e)
}

/// Simulates `lft` with `f` in its block and returns y, after checking that z is computable
/// from u and y alone.
fn simulate(lft: &Lft, f: fn(f64) -> f64, u: &[f64], e: &[f64], what: &str) -> Vec<f64> {
    let us = Signal::from_fn(u.len(), 1, |k, _| u[k]);
    let es = Signal::from_fn(e.len(), 1, |k, _| e[k]);
    let map = |z: &[f64]| f(z[0]);
    let sim = lft
        .simulate(
            &[MapBinding {
                inputs: &[0],
                output: 0,
                map: &map,
            }],
            &us,
            Some(&es),
            None,
        )
        .unwrap();
    let (z, _) = lft.compute_z(&us, &sim.y).unwrap();
    let dz = (0..u.len())
        .map(|k| (z.get(k, 0) - sim.z.get(k, 0)).abs())
        .fold(0.0, f64::max);
    assert!(dz < 1e-9, "{what}: measured z differs by {dz}");
    sim.y.channel(0)
}

fn worst(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn every_site_simulates_its_equation_with_the_noise_path_kept() {
    let (u, e) = excitation();
    let f: fn(f64) -> f64 = |z| z.tanh() + 0.1 * z;
    for site in Site::ALL {
        let lft = site.insert(&nominal()).unwrap();
        let sim = simulate(&lft, f, &u, &e, site.name());
        let d = worst(&sim, &reference(site, f, &u, &e));
        assert!(d < 1e-12, "{site:?}: differs by {d}");
    }
}

/// A second-order G = (0.3q⁻¹ + 0.2q⁻²)/(1 − 1.2q⁻¹ + 0.5q⁻²) and, for the separate feedback
/// path, B_w = −0.25q⁻¹ + 0.1q⁻².
fn polynomial() -> PolynomialModel {
    PolynomialModel {
        num: vec![vec![0.0, 0.3, 0.2]],
        den: vec![1.0, -1.2, 0.5],
        sample_time: Some(0.1),
    }
}

const BW: [f64; 3] = [0.0, -0.25, 0.1];

/// Direct recursion of F(q)·(y − e) = B(q)·v (+ B_w(q)·w) for the structure at `site`
/// (`separate`: output feedback through B_w), white output noise e.
fn polynomial_reference(
    site: Site,
    separate: bool,
    f: fn(f64) -> f64,
    u: &[f64],
    e: &[f64],
) -> Vec<f64> {
    let g = polynomial();
    let (a, b) = (&g.den, &g.num[0]);
    let n = u.len();
    // lin: the noise-free linear output; v: G's input; w: the feedback path's input.
    let (mut lin, mut v, mut w, mut y) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let past = |s: &[f64], c: &[f64], k: usize| -> f64 {
        (1..c.len())
            .filter(|j| *j <= k)
            .map(|j| c[j] * s[k - j])
            .sum()
    };
    for k in 0..n {
        // Every path has a delay (b_0 = 0), so lin_k depends on the past only.
        let mut l = past(&v, b, k) - past(&lin, a, k);
        if separate {
            l += past(&w, &BW, k);
        }
        lin[k] = l;
        y[k] = match site {
            Site::Output => f(l) + e[k],
            _ => l + e[k],
        };
        let rate = (y[k] - if k > 0 { y[k - 1] } else { 0.0 }) / 0.1;
        (v[k], w[k]) = match (site, separate) {
            (Site::Input, _) => (f(u[k]), 0.0),
            (Site::Output, _) => (u[k], 0.0),
            (Site::OutputFeedback, true) => (u[k], f(y[k])),
            (Site::OutputFeedback, false) => (u[k] - f(y[k]), 0.0),
            _ => (u[k] - f(rate), 0.0),
        };
    }
    y
}

#[test]
fn every_builder_of_a_polynomial_simulates_its_equation_with_white_noise() {
    let (u, e) = excitation();
    let f: fn(f64) -> f64 = |z| 0.5 * z.tanh() + 0.1 * z;
    let d: Arc<dyn Dispersion> = Arc::new(crate::PolynomialDispersion::new(2).unwrap());
    let g = polynomial();
    let mut with_path = g.clone();
    with_path.num.push(BW.to_vec());
    for (structure, site, separate) in [
        (
            Structure::hammerstein(&g, Arc::clone(&d)),
            Site::Input,
            false,
        ),
        (Structure::wiener(&g, Arc::clone(&d)), Site::Output, false),
        (
            Structure::output_feedback(&g, Arc::clone(&d)),
            Site::OutputFeedback,
            false,
        ),
        (
            Structure::output_feedback_with_path(&with_path, Arc::clone(&d)),
            Site::OutputFeedback,
            true,
        ),
        (
            Structure::rate_feedback(&g, Arc::clone(&d)),
            Site::RateFeedback,
            false,
        ),
    ] {
        assert_eq!(structure.site(), Some(site));
        let model = structure.model().unwrap();
        assert_eq!(model.blocks()[0].name, "N");
        let sim = simulate(model.lft(), f, &u, &e, site.name());
        let want = polynomial_reference(site, separate, f, &u, &e);
        let dd = worst(&sim, &want);
        assert!(
            dd < 1e-12,
            "{site:?} (separate: {separate}): differs by {dd}"
        );
    }
    // The shared path through the last numerator is the shared path through G.
    let mut shared = g.clone();
    shared.num.push(g.num[0].iter().map(|b| -b).collect());
    let a = simulate(
        &Structure::output_feedback_with_path(&shared, Arc::clone(&d))
            .lft()
            .unwrap(),
        f,
        &u,
        &e,
        "shared",
    );
    let b = polynomial_reference(Site::OutputFeedback, false, f, &u, &e);
    assert!(worst(&a, &b) < 1e-12);
    // Without a block: y = G·u + e.
    let lti = Structure::linear(&g).model().unwrap();
    assert!(lti.blocks().is_empty());
    assert_eq!((lti.lft().dims().w, lti.lft().dims().z), (0, 0));
}

#[test]
fn feedback_needs_a_delay_and_declared_channels_must_exist() {
    let mut m = nominal().matrices().clone();
    m.dyu = dmatrix![0.3];
    let direct = Lft::new(m).unwrap();
    assert!(
        Site::OutputFeedback
            .insert(&direct)
            .unwrap_err()
            .to_string()
            .contains("delay")
    );
    assert!(Site::RateFeedback.insert(&direct).is_err());
    assert!(Site::Input.insert(&direct).is_ok());
    assert!(Site::Declared { z: 0, w: 0 }.insert(&nominal()).is_err());
    let d: Arc<dyn Dispersion> = Arc::new(crate::PolynomialDispersion::new(2).unwrap());
    let g = PolynomialModel {
        num: vec![vec![1.0, 0.2]],
        den: vec![1.0, -0.5],
        sample_time: None,
    };
    for s in [
        Structure::output_feedback(&g, Arc::clone(&d)),
        Structure::rate_feedback(&g, Arc::clone(&d)),
    ] {
        assert!(s.lft().unwrap_err().to_string().contains("delay"));
    }
}

#[test]
fn sites_are_named_as_model_files_name_them() {
    for (site, name) in [
        (Site::Input, "input"),
        (Site::Output, "output"),
        (Site::OutputFeedback, "output-feedback"),
        (Site::RateFeedback, "rate-feedback"),
    ] {
        assert_eq!(site.name(), name);
        assert_eq!(Site::parse(name), Some(site));
        let de: std::result::Result<Site, serde::de::value::Error> =
            Site::deserialize(name.into_deserializer());
        assert_eq!(de.unwrap(), site);
    }
    assert_eq!(Site::parse("lti"), None);
}
