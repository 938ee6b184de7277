// scratch (not committed)
use structid_discover::discover::{DiscoverSettings, discover};
use structid_discover::hypotheses::Nominal;
use structid_testcases::physics::{PhysicsKind, generate};
fn main() {
    let kind = std::env::args().nth(1).unwrap();
    let seed: u64 = std::env::args().nth(2).unwrap().parse().unwrap();
    let kind = match kind.as_str() {
        "static" => PhysicsKind::Static,
        "dyn" => PhysicsKind::Dynamic,
        "two" => PhysicsKind::TwoEffects,
        _ => panic!(),
    };
    let case = generate(kind, seed);
    let nominal = Nominal::from_polynomial(&case.nominal).unwrap();
    let d = discover(
        &nominal,
        &case.estimation,
        &case.validation,
        &DiscoverSettings::default(),
    )
    .unwrap();
    println!(
        "truth: {:?}",
        case.expected.as_ref().map(|e| (&e.family, e.site))
    );
    println!("{}", d.verdict);
    if let Some(f) = &d.finding {
        println!("direction: {:?}", f.direction);
        for r in &f.remarks {
            println!("  - {r}");
        }
    }
    for h in &d.hypotheses {
        println!(
            "H {:?} val {:?} {:?}",
            h.location, h.validation_rms, h.failure
        );
    }
}
