//! The Silverbox pipeline on the real benchmark file, in release mode within CI time: the
//! issue's requirement is at most 1.0 mV RMS on the full arrow test; this test asserts 0.8 mV.
//!
//! The candidate search is narrowed to the structure that the full search of
//! `examples/silverbox.rs` chooses (n = 6, separate feedback numerator, cubic map; see
//! BENCHMARKS.md), so the test runs one refinement on the fitting part and one on the whole
//! estimation split.

#[path = "../../structid-io/tests/common/mod.rs"]
mod common;

use structid::io::Silverbox;
use structid_benchmarks::silverbox::{SilverboxSettings, run};

/// The structure the full search chooses: sixth order, separate feedback numerator, cubic map.
fn narrowed() -> SilverboxSettings {
    SilverboxSettings {
        orders: vec![6],
        numerators: vec![true],
        kernel_margin: f64::INFINITY,
        ..SilverboxSettings::default()
    }
}

#[test]
fn silverbox_full_arrow_test_is_below_one_millivolt() {
    let Some(path) = common::silverbox_file() else {
        return;
    };
    let sb = Silverbox::load(&path).unwrap();
    let settings = narrowed();
    let r = run(&sb, &settings).unwrap();
    let score = |name: &str| {
        r.tests
            .iter()
            .find(|t| t.split == name)
            .map(|t| (t.rms, t.bla2_rms))
            .unwrap()
    };
    let (arrow, bla) = score("test-arrow-full");
    eprintln!(
        "silverbox: arrow {:.3} mV (own second-order BLA {:.3} mV), {:.1} s",
        1e3 * arrow,
        1e3 * bla,
        r.seconds
    );
    assert!(arrow < 0.8e-3, "full arrow test RMS {:.3} mV", 1e3 * arrow);
    // The BLA is an order of magnitude worse (published: 13.5 mV), so the map does the work.
    assert!(bla > 10.0 * arrow, "BLA {bla} vs {arrow}");
    let (no_extrapolation, _) = score("test-arrow-no-extrapolation");
    let (multisine, _) = score("test-multisine");
    assert!(no_extrapolation < 0.6e-3, "{no_extrapolation}");
    assert!(multisine < 0.6e-3, "{multisine}");
    // The chosen structure's validation error beats its BLA's by far.
    let c = &r.candidates[r.chosen];
    assert!(c.validation_rms < 0.2 * c.bla_validation_rms, "{c:?}");
}

#[test]
fn the_joint_fit_by_simulation_error_improves_every_test_split() {
    use structid_benchmarks::silverbox_joint::{JointSilverboxSettings, run_joint};
    let Some(path) = common::silverbox_file() else {
        return;
    };
    let sb = Silverbox::load(&path).unwrap();
    let settings = narrowed();
    let base = run(&sb, &settings).unwrap();
    let j = run_joint(&sb, &base, &JointSilverboxSettings::default()).unwrap();
    assert!(j.fit.cost <= j.fit.initial_cost);
    for ((split, rms), t) in j.tests.iter().zip(&base.tests) {
        eprintln!(
            "silverbox joint: {split} {:.4} mV (alternation {:.4} mV)",
            1e3 * rms,
            1e3 * t.rms
        );
        assert_eq!(split, &t.split);
        assert!(*rms < t.rms, "{split}: {rms} ≥ {}", t.rms);
    }
    // The goals are 0.30 / 0.25 / 0.30 mV; measured 0.298 / 0.248 / 0.259 mV. The
    // arrow's bounds leave room for the last bits of a parallel solve, which move a
    // 30-iteration fit.
    for (split, bound) in [
        ("test-arrow-full", 0.31e-3),
        ("test-arrow-no-extrapolation", 0.26e-3),
        ("test-multisine", 0.30e-3),
    ] {
        let rms = j.tests.iter().find(|t| t.0 == split).unwrap().1;
        assert!(rms < bound, "{split}: {:.4} mV", 1e3 * rms);
    }
    // β is the largest that validated within the tie of the best.
    let best = j.trials.iter().map(|t| t.1).fold(f64::INFINITY, f64::min);
    let chosen = j.trials.iter().find(|t| t.0 == j.beta).unwrap();
    assert!(chosen.1 <= 1.01 * best);
    assert!(j.trials.iter().all(|t| t.0 <= j.beta || t.1 > 1.01 * best));
}
