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
use structid_testcases::{parallel, physics, synthetic};

/// One generated case: its name, true noise std, AR coefficient of coloured noise, nominal
/// model and records.
struct Case {
    name: String,
    truth: f64,
    colour: Option<f64>,
    nominal: PolynomialModel,
    est: Data,
    val: Data,
}

/// (σ̂/σ of the workflow, σ̂/σ of the first difference of the nominal model's residual) and
/// the case's printed line.
fn ratios(c: &Case) -> ((f64, f64), String) {
    let n = Nominal::from_polynomial(&c.nominal).unwrap();
    let d = discover(&n, &c.est, &c.val, &DiscoverSettings::default()).unwrap();
    let ratio = d.noise.std / c.truth;
    let difference = noise_level(&d.estimation_gap.residual) / c.truth;
    let line = format!(
        "{:<16} φ {:<5} │ σ̂/σ {ratio:5.2} {} φ̂ {:.2} │ Δ-nominal {difference:6.2} │ {:<16} │ {}",
        c.name,
        c.colour.map_or("white".to_string(), |p| format!("{p:.2}")),
        if close(ratio) { " " } else { "✗" },
        d.noise.colour,
        format!("{:?}", d.verdict_kind),
        d.noise.source
    );
    ((ratio, difference), line)
}

/// Whether a ratio σ̂/σ is within 30 % of 1.
fn close(r: f64) -> bool {
    (r - 1.0).abs() <= 0.3
}

/// The 60 cases, in a fixed order.
fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    let synthetic_case = |kind, tag: &str, seed| {
        let c = synthetic::generate(kind, seed);
        Case {
            name: format!("synthetic {tag} {seed}"),
            truth: c.noise_std,
            colour: None,
            nominal: c.nominal,
            est: c.estimation,
            val: c.validation,
        }
    };
    let physics_case = |kind, tag: &str, seed| {
        let c = physics::generate(kind, seed);
        Case {
            name: format!("physics {tag} {seed}"),
            truth: c.noise_std,
            colour: c.noise_ar,
            nominal: c.nominal,
            est: c.estimation,
            val: c.validation,
        }
    };
    out.extend((0..20).map(|s| synthetic_case(synthetic::CaseKind::Static, "S", s)));
    out.extend((0..10).map(|s| synthetic_case(synthetic::CaseKind::None, "N", s)));
    out.extend((0..20).map(|s| physics_case(physics::PhysicsKind::Static, "S", s)));
    out.extend((0..10).map(|s| physics_case(physics::PhysicsKind::None, "N", s)));
    out
}

#[test]
fn the_noise_level_is_within_30_percent_of_the_truth() {
    let mut all = Vec::new();
    for (r, line) in parallel::map(&cases(), ratios) {
        eprintln!("{line}");
        all.push(r);
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
