// scratch (not committed)
use structid_discover::discover::{DiscoverSettings, EffectsSettings, discover_effects};
use structid_discover::hypotheses::Nominal;
use structid_testcases::physics::{PhysicsKind, generate};
fn main() {
    let seed: u64 = std::env::args().nth(1).unwrap().parse().unwrap();
    let case = generate(PhysicsKind::TwoEffects, seed);
    let nominal = Nominal::from_polynomial(&case.nominal).unwrap();
    let effects = match discover_effects(
        &nominal,
        &case.estimation,
        &case.validation,
        &DiscoverSettings::default(),
        &EffectsSettings::default().with_max_effects(2).unwrap(),
    ) {
        Ok(e) => e,
        Err(e) => {
            println!("ERR {e:?}");
            return;
        }
    };
    println!(
        "truth: {:?} / {:?}",
        case.expected.as_ref().map(|e| (&e.family, e.site)),
        case.second.as_ref().map(|s| (&s.1.family, s.1.site))
    );
    for (i, s) in effects.steps.iter().enumerate() {
        let d = &s.discovery;
        println!("=== step {i}: {:?}\n{}", d.verdict_kind, d.verdict);
        println!(
            "gap val rms {:.4e} noise {:?}",
            d.validation_gap.rms, d.noise
        );
        if let Some(r) = &s.second_block {
            println!(
                "  ROW {:?}+{:?} est {:.4e} val {:.4e}",
                r.first_location, r.site, r.estimation_rms, r.validation_rms
            );
        }
        if i == 0 {
            if let Some(f) = &d.finding {
                let st = DiscoverSettings::builder()
                    .scoring(d.scoring)
                    .build()
                    .unwrap();
                println!("  first finding val {:.4e}", f.augmented.validation_gap.rms);
                for r in structid_discover::discover::second_blocks(
                    &s.nominal,
                    f,
                    &case.estimation,
                    &case.validation,
                    &st,
                ) {
                    println!(
                        "  row {:?}+{:?} est {:.4e} val {:.4e} ({:.1}s)",
                        r.first_location, r.site, r.estimation_rms, r.validation_rms, r.seconds
                    );
                }
            }
        }
        for h in d.hypotheses.iter().take(8) {
            println!(
                "  {:?} {}: val {:.4e} est {:.4e} {:?}",
                h.location,
                h.dispersion,
                h.validation_rms,
                h.estimation_rms,
                h.failure.as_deref().map(|f| &f[..f.len()])
            );
        }
    }
    println!("stop {:?}", effects.stop);
}
