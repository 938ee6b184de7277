//! The discovery workflow on the real Silverbox file: starting from the project's own
//! second-order BLA, `discover` must name a hardening stiffness acting in feedback from y (a
//! cubic, or a power law with a linear term whose exponent is near 3: the candidate table
//! chooses between them by their validation errors), and adding it must shrink the full
//! arrow test's RMS at least 5× from the BLA's.

#[path = "../../structid-io/tests/common/mod.rs"]
mod common;

use structid::io::Silverbox;
use structid_benchmarks::silverbox_discovery::{SilverboxDiscoverySettings, run};
use structid_discover::Effect;
use structid_discover::discover::Classification;
use structid_discover::hypotheses::Site;

#[test]
fn discover_names_a_cubic_stiffness_in_feedback_from_y_and_shrinks_the_arrow_error_fivefold() {
    let Some(path) = common::silverbox_file() else {
        return;
    };
    let sb = Silverbox::load(&path).unwrap();
    let r = run(&sb, &SilverboxDiscoverySettings::default()).unwrap();
    eprintln!("{}", r.discovery.verdict);
    assert!(r.discovery.missing_effect, "the BLA's gap must be detected");
    let f = r.discovery.finding.as_ref().expect("an effect is found");
    assert_eq!(f.location, Site::OutputFeedback);
    match &f.classification {
        Classification::Named(fit) if fit.effect == Effect::OddPolynomial { degree: 3 } => {
            // A hardening spring: the cubic coefficient is positive and its interval excludes 0.
            let a3 = fit.parameter("a3").unwrap();
            assert!(a3.value > 0.0 && a3.interval.0 > 0.0, "a3 = {a3:?}");
        }
        Classification::Named(fit) if fit.effect == Effect::PowerLaw { linear: true } => {
            // A hardening spring: a positive stiffness growing with an exponent near the cubic's.
            let k = fit.parameter("stiffness").unwrap();
            let p = fit.parameter("exponent").unwrap();
            assert!(k.value > 0.0 && k.interval.0 > 0.0, "stiffness = {k:?}");
            assert!((2.5..=3.5).contains(&p.value), "exponent = {p:?}");
        }
        other => panic!("expected a hardening stiffness, got {}", other.describe()),
    }
    let arrow = r
        .tests
        .iter()
        .find(|t| t.record == "silverbox-test-arrow-full")
        .unwrap();
    eprintln!(
        "arrow: BLA {:.3} mV, augmented {:.3} mV; discover {:.1} s",
        1e3 * arrow.bla_rms,
        1e3 * arrow.augmented_rms,
        r.discover_seconds
    );
    assert!(
        arrow.bla_rms >= 5.0 * arrow.augmented_rms,
        "arrow RMS shrank only {:.2}×",
        arrow.bla_rms / arrow.augmented_rms
    );
}
