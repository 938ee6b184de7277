//! The designed inputs have the spectra, periods, balance and levels they promise.

use rustfft::FftPlanner;
use rustfft::num_complex::Complex;
use structid_input::{Design, InputError, Kind, Lines, Sweep, crest_factor, generate, prbs_bits};

/// |DFT| of x, bins 0..=n/2.
fn spectrum(x: &[f64]) -> Vec<f64> {
    let mut s: Vec<Complex<f64>> = x.iter().map(|&v| Complex::new(v, 0.0)).collect();
    FftPlanner::new().plan_fft_forward(x.len()).process(&mut s);
    s[..=x.len() / 2].iter().map(|c| c.norm()).collect()
}

fn design(length: usize, ts: f64, band: Option<(f64, f64)>) -> Design {
    Design {
        length,
        sample_time: ts,
        band,
        ..Design::default()
    }
}

#[test]
fn prbs_period_and_balance_for_every_order() {
    for n in 2..=24u32 {
        let bits = prbs_bits(n, 1).unwrap();
        let period = (1usize << n) - 1;
        assert_eq!(bits.len(), period);
        let ones = bits.iter().filter(|&&b| b).count();
        assert_eq!(ones, period / 2 + 1, "order {n}: one more 1 than 0");
        // Maximum length: the register returns to its start only after the full period, so
        // no shorter shift of the sequence equals it (checked on the orders where it is cheap).
        if n <= 12 {
            for shift in 1..period {
                assert!(
                    (0..period).any(|k| bits[k] != bits[(k + shift) % period]),
                    "order {n} repeats after {shift}"
                );
            }
        }
    }
}

#[test]
fn prbs_signal_levels_clock_and_band() {
    let d = Design {
        length: 3 * 127 * 4,
        amplitude: 2.0,
        offset: 1.0,
        ..Design::default()
    };
    let u = generate(
        &d,
        &Kind::Prbs {
            order: Some(7),
            clock: Some(4),
        },
    )
    .unwrap();
    assert!(u.iter().all(|&v| v == 3.0 || v == -1.0));
    // Period 127 bits × 4 samples, bits held for 4 samples.
    for k in 0..u.len() - 508 {
        assert_eq!(u[k], u[k + 508]);
    }
    for k in (0..u.len()).step_by(4) {
        assert!(u[k..k + 4].iter().all(|&v| v == u[k]));
    }
    let high = u[..508].iter().filter(|&&v| v == 3.0).count();
    assert_eq!(high, 64 * 4);
    // The clock from the band: 0..Nyquist/4 gives 4 samples per bit.
    let d = design(508, 0.1, Some((0.0, 1.25)));
    let v = generate(
        &d,
        &Kind::Prbs {
            order: Some(7),
            clock: None,
        },
    )
    .unwrap();
    for k in (0..v.len()).step_by(4) {
        assert!(v[k..k + 4].iter().all(|&x| x == v[k]));
    }
    // The order from the length: 1000 samples need 2^10 − 1 bits.
    let d = design(1000, 1.0, None);
    let w = generate(
        &d,
        &Kind::Prbs {
            order: None,
            clock: None,
        },
    )
    .unwrap();
    let high = w.iter().filter(|&&x| x > 0.0).count();
    assert!((480..=520).contains(&high), "{high}");
    // A PRBS band must start at 0.
    let e = generate(
        &design(100, 1.0, Some((0.1, 0.3))),
        &Kind::Prbs {
            order: None,
            clock: None,
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("lower edge"), "{e}");
}

#[test]
fn multisine_lines_present_and_absent() {
    let n = 1000;
    let ts = 0.01; // lines every 0.1 Hz
    let d = design(n, ts, Some((2.0, 10.0)));
    let u = generate(
        &d,
        &Kind::Multisine {
            period: None,
            lines: Lines::Odd,
            minimise_crest: false,
        },
    )
    .unwrap();
    let s = spectrum(&u);
    let top = s.iter().cloned().fold(0.0, f64::max);
    for (k, &a) in s.iter().enumerate() {
        let f = k as f64 * 0.1;
        let excited = (2.0 - 1e-9..=10.0 + 1e-9).contains(&f) && k % 2 == 1;
        if excited {
            assert!(
                (a - top).abs() < 1e-6 * top,
                "line {k} ({f} Hz): {a} vs {top}"
            );
        } else {
            assert!(a < 1e-9 * top, "bin {k} ({f} Hz) should be empty: {a}");
        }
    }
    // Chosen lines, two periods.
    let d = design(2 * 256, 1.0, None);
    let u = generate(
        &d,
        &Kind::Multisine {
            period: Some(256),
            lines: Lines::Chosen(vec![3, 7, 50]),
            minimise_crest: false,
        },
    )
    .unwrap();
    assert_eq!(u[..256], u[256..]);
    let s = spectrum(&u);
    for (k, &a) in s.iter().enumerate() {
        let excited = [6, 14, 100].contains(&k);
        assert_eq!(a > 1e-6, excited, "bin {k}: {a}");
    }
}

#[test]
fn crest_factor_minimisation() {
    let d = design(2048, 1.0, Some((0.0, 0.25)));
    let random = generate(
        &d,
        &Kind::Multisine {
            period: None,
            lines: Lines::All,
            minimise_crest: false,
        },
    )
    .unwrap();
    let low = generate(
        &d,
        &Kind::Multisine {
            period: None,
            lines: Lines::All,
            minimise_crest: true,
        },
    )
    .unwrap();
    let (cr, cl) = (crest_factor(&random), crest_factor(&low));
    assert!(cl < 1.7, "minimised crest factor {cl}");
    assert!(cl < cr, "{cl} vs random {cr}");
    // Still flat on the same lines.
    let s = spectrum(&low);
    let top = s.iter().cloned().fold(0.0, f64::max);
    for (k, &a) in s.iter().enumerate().skip(1) {
        if k <= 512 {
            assert!((a - top).abs() < 1e-6 * top, "line {k}");
        } else {
            assert!(a < 1e-9 * top, "bin {k}");
        }
    }
}

#[test]
fn noise_band_limits_and_rms() {
    let d = Design {
        amplitude: 0.5,
        ..design(4000, 0.001, Some((50.0, 120.0)))
    };
    let u = generate(&d, &Kind::Noise).unwrap();
    let rms = (u.iter().map(|v| v * v).sum::<f64>() / u.len() as f64).sqrt();
    assert!((rms - 0.5).abs() < 1e-12, "{rms}");
    let s = spectrum(&u);
    let df = 1.0 / (4000.0 * 0.001);
    let (mut inside, mut outside) = (0.0, 0.0);
    for (k, &a) in s.iter().enumerate() {
        let f = k as f64 * df;
        if (50.0..=120.0).contains(&f) {
            inside += a * a;
        } else {
            outside += a * a;
        }
    }
    assert!(outside < 1e-20 * inside, "{outside} vs {inside}");
}

#[test]
fn chirp_sweeps_the_band() {
    for sweep in [Sweep::Linear, Sweep::Logarithmic] {
        let d = design(8000, 0.001, Some((20.0, 100.0)));
        let u = generate(&d, &Kind::Chirp { sweep }).unwrap();
        assert!(u.iter().all(|v| v.abs() <= 1.0));
        let s = spectrum(&u);
        let df = 1.0 / 8.0;
        let (mut inside, mut total) = (0.0, 0.0);
        for (k, &a) in s.iter().enumerate() {
            let f = k as f64 * df;
            total += a * a;
            if (15.0..=105.0).contains(&f) {
                inside += a * a;
            }
        }
        assert!(inside > 0.97 * total, "{sweep:?}: {}", inside / total);
    }
    let e = generate(
        &design(100, 1.0, None),
        &Kind::Chirp {
            sweep: Sweep::Logarithmic,
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("above 0 Hz"), "{e}");
}

#[test]
fn steps_hold_times_and_levels() {
    let d = Design {
        amplitude: 2.0,
        offset: 5.0,
        ..design(5000, 1.0, None)
    };
    let u = generate(
        &d,
        &Kind::Steps {
            min_hold: 10,
            max_hold: 30,
        },
    )
    .unwrap();
    assert!(u.iter().all(|&v| (3.0..=7.0).contains(&v)));
    let mut runs = Vec::new();
    let mut start = 0;
    for k in 1..=u.len() {
        if k == u.len() || u[k] != u[k - 1] {
            runs.push(k - start);
            start = k;
        }
    }
    let last = runs.pop().unwrap();
    assert!(last <= 30);
    assert!(runs.iter().all(|r| (10..=30).contains(r)), "{runs:?}");
    assert!(runs.iter().any(|&r| r < 15) && runs.iter().any(|&r| r > 25));
}

#[test]
fn same_seed_same_signal_other_seed_other_signal() {
    let kinds = [
        Kind::Prbs {
            order: Some(8),
            clock: None,
        },
        Kind::Multisine {
            period: None,
            lines: Lines::All,
            minimise_crest: true,
        },
        Kind::Noise,
        Kind::Steps {
            min_hold: 2,
            max_hold: 9,
        },
    ];
    for kind in &kinds {
        let a = generate(
            &Design {
                seed: 7,
                ..design(600, 1.0, Some((0.0, 0.3)))
            },
            kind,
        );
        let a = match kind {
            Kind::Prbs { .. } => generate(
                &Design {
                    seed: 7,
                    ..design(600, 1.0, None)
                },
                kind,
            ),
            _ => a,
        }
        .unwrap();
        let b = match kind {
            Kind::Prbs { .. } => generate(
                &Design {
                    seed: 7,
                    ..design(600, 1.0, None)
                },
                kind,
            ),
            _ => generate(
                &Design {
                    seed: 7,
                    ..design(600, 1.0, Some((0.0, 0.3)))
                },
                kind,
            ),
        }
        .unwrap();
        assert_eq!(a, b, "{kind:?}");
        let c = match kind {
            Kind::Prbs { .. } => generate(
                &Design {
                    seed: 8,
                    ..design(600, 1.0, None)
                },
                kind,
            ),
            _ => generate(
                &Design {
                    seed: 8,
                    ..design(600, 1.0, Some((0.0, 0.3)))
                },
                kind,
            ),
        }
        .unwrap();
        assert_ne!(a, c, "{kind:?}");
    }
    // The chirp has no randomness.
    let d = design(100, 1.0, None);
    assert_eq!(
        generate(
            &d,
            &Kind::Chirp {
                sweep: Sweep::Linear
            }
        ),
        generate(
            &Design {
                seed: 99,
                ..d.clone()
            },
            &Kind::Chirp {
                sweep: Sweep::Linear
            }
        )
    );
}

#[test]
fn bad_arguments_are_named() {
    let ok = Kind::Noise;
    let cases: Vec<(Design, Kind, &str)> = vec![
        (design(0, 1.0, None), ok.clone(), "invalid length"),
        (design(10, 0.0, None), ok.clone(), "invalid sample time"),
        (
            design(10, f64::NAN, None),
            ok.clone(),
            "invalid sample time",
        ),
        (
            Design {
                amplitude: -1.0,
                ..design(10, 1.0, None)
            },
            ok.clone(),
            "invalid amplitude",
        ),
        (
            Design {
                offset: f64::INFINITY,
                ..design(10, 1.0, None)
            },
            ok.clone(),
            "invalid offset",
        ),
        (
            design(10, 1.0, Some((0.3, 0.2))),
            ok.clone(),
            "invalid band",
        ),
        (
            design(10, 1.0, Some((0.0, 0.6))),
            ok.clone(),
            "above the Nyquist frequency 0.5 Hz",
        ),
        (
            design(10, 1.0, Some((0.01, 0.02))),
            ok.clone(),
            "holds no frequency",
        ),
        (
            design(10, 1.0, None),
            Kind::Prbs {
                order: Some(30),
                clock: None,
            },
            "invalid order",
        ),
        (
            design(10, 1.0, None),
            Kind::Prbs {
                order: None,
                clock: Some(0),
            },
            "invalid clock",
        ),
        (
            design(10, 1.0, None),
            Kind::Multisine {
                period: Some(2),
                lines: Lines::All,
                minimise_crest: false,
            },
            "invalid period",
        ),
        (
            design(64, 1.0, None),
            Kind::Multisine {
                period: None,
                lines: Lines::Chosen(vec![32]),
                minimise_crest: false,
            },
            "harmonic 32",
        ),
        (
            design(64, 1.0, None),
            Kind::Multisine {
                period: None,
                lines: Lines::Chosen(vec![]),
                minimise_crest: false,
            },
            "no harmonic chosen",
        ),
        (
            design(64, 1.0, Some((0.001, 0.01))),
            Kind::Multisine {
                period: None,
                lines: Lines::Odd,
                minimise_crest: false,
            },
            "no odd harmonic",
        ),
        (
            design(64, 1.0, None),
            Kind::Steps {
                min_hold: 5,
                max_hold: 4,
            },
            "invalid hold",
        ),
    ];
    for (d, k, want) in cases {
        let e: InputError = generate(&d, &k).unwrap_err();
        assert!(e.to_string().contains(want), "want `{want}`: {e}");
    }
}
