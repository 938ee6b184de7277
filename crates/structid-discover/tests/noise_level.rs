//! The workflow's noise level σ̂ ([`Discovery::noise`]) against the true noise std of the
//! generators, white and coloured: 20 static and 10 effect-free cases of
//! `structid_testcases::synthetic` (white output noise) and of `structid_testcases::physics`
//! (white or AR(1) noise, continuous-time plants, half the nominals estimated). σ̂ must be
//! within 30 % of the true std (of the coloured process itself) in at least 85 % of them
//! (measured: 53 of 60).
//!
//! The table printed with `--nocapture` also shows the first-difference estimate
//! MAD(Δr)/(0.6745·√2) of the nominal model's residual, the noise level a model-free
//! estimate on the nominal's gap would give: it holds the missing effect (too high) and
//! reads coloured noise as white (too low by √(1 − φ)).

use structid_core::Data;
use structid_discover::discover::{DiscoverSettings, discover};
use structid_discover::gap::noise_level;
use structid_discover::hypotheses::Nominal;
use structid_linear::PolynomialModel;
use structid_testcases::{physics, synthetic};

/// (σ̂/σ of the workflow, σ̂/σ of the first difference of the nominal model's residual).
fn ratios(
    name: &str,
    truth: f64,
    colour: Option<f64>,
    nominal: &PolynomialModel,
    est: &Data,
    val: &Data,
) -> (f64, f64) {
    let n = Nominal::from_polynomial(nominal).unwrap();
    let d = discover(&n, est, val, &DiscoverSettings::default()).unwrap();
    let ratio = d.noise.std / truth;
    let difference = noise_level(&d.estimation_gap.residual) / truth;
    eprintln!(
        "{name:<16} φ {:<5} │ σ̂/σ {ratio:5.2} {} φ̂ {:.2} │ Δ-nominal {difference:6.2} │ {:<16} │ {}",
        colour.map_or("white".to_string(), |p| format!("{p:.2}")),
        if (ratio - 1.0).abs() <= 0.3 {
            " "
        } else {
            "✗"
        },
        d.noise.colour,
        format!("{:?}", d.verdict_kind),
        d.noise.source
    );
    (ratio, difference)
}

/// Whether a ratio σ̂/σ is within 30 % of 1.
fn close(r: f64) -> bool {
    (r - 1.0).abs() <= 0.3
}

#[test]
fn the_noise_level_is_within_30_percent_of_the_truth() {
    let mut all = Vec::new();
    for seed in 0..20 {
        let c = synthetic::generate(synthetic::CaseKind::Static, seed);
        let name = format!("synthetic S {seed}");
        all.push(ratios(
            &name,
            c.noise_std,
            None,
            &c.nominal,
            &c.estimation,
            &c.validation,
        ));
    }
    for seed in 0..10 {
        let c = synthetic::generate(synthetic::CaseKind::None, seed);
        let name = format!("synthetic N {seed}");
        all.push(ratios(
            &name,
            c.noise_std,
            None,
            &c.nominal,
            &c.estimation,
            &c.validation,
        ));
    }
    for seed in 0..20 {
        let c = physics::generate(physics::PhysicsKind::Static, seed);
        let name = format!("physics S {seed}");
        all.push(ratios(
            &name,
            c.noise_std,
            c.noise_ar,
            &c.nominal,
            &c.estimation,
            &c.validation,
        ));
    }
    for seed in 0..10 {
        let c = physics::generate(physics::PhysicsKind::None, seed);
        let name = format!("physics N {seed}");
        all.push(ratios(
            &name,
            c.noise_std,
            c.noise_ar,
            &c.nominal,
            &c.estimation,
            &c.validation,
        ));
    }
    let within = all.iter().filter(|(r, _)| close(*r)).count();
    let difference = all.iter().filter(|(_, r)| close(*r)).count();
    let lowest = all.iter().map(|(r, _)| *r).fold(f64::INFINITY, f64::min);
    eprintln!(
        "σ̂ within 30 % of σ in {within}/{} (the first difference of the nominal's residual: \
         {difference}/{}); lowest σ̂/σ {lowest:.2}",
        all.len(),
        all.len()
    );
    // Measured: 53 of 60 (88 %). The misses are too high where no model examined explains
    // the data, and too low (0.63) where windows fitted to a strongly coloured record take up
    // its slow part.
    assert!(
        within as f64 >= 0.85 * all.len() as f64,
        "σ̂ within 30 % of σ in only {within}/{}",
        all.len()
    );
    // Each candidate residual holds nearly the whole noise, so their smallest noise level is
    // not far below it.
    assert!(lowest >= 0.6, "σ̂ is {lowest:.2} σ in one case");
    assert!(within > difference, "{within} against {difference}");
}
