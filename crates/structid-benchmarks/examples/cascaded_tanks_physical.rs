//! The cascaded tanks from their physical structure: two level states, the outflows as unknown
//! maps (the upper one of the unmeasured level), the overflows as unknown maps, all fitted with
//! G's free entries by simulation error.
//!
//! ```text
//! cargo run --release -p structid-benchmarks --example cascaded_tanks_physical -- [PATH/dataBenchmark.csv]
//! ```
//!
//! Prints the search over structures and β (validation RMS on the last 25 % of the estimation
//! record), then the estimation and test RMS of the chosen model next to the published figures.

use structid::io::CascadedTanks;
use structid_benchmarks::tanks::PUBLISHED;
use structid_benchmarks::tanks_physical::{PhysicalSettings, run};

mod common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (path, _) = common::benchmark_args("cascaded_tanks/dataBenchmark.csv", "cascaded_tanks");
    let tanks = CascadedTanks::load(&path)?;
    let mut settings = PhysicalSettings::default();
    common::env_override_list("TANKS_BETAS", &mut settings.betas)?;
    common::env_override("TANKS_CENTRES", &mut settings.centres)?;
    common::env_override("TANKS_SEGMENT", &mut settings.segment_length)?;
    // Structures as comma-separated masks of the free maps, e.g. TANKS_STRUCTURES=1111,1110.
    if let Ok(v) = std::env::var("TANKS_STRUCTURES") {
        settings.structures = v
            .split(',')
            .map(|mask| std::array::from_fn(|i| mask.as_bytes().get(i) == Some(&b'1')))
            .collect();
    }
    if let Ok(v) = std::env::var("TANKS_MONOTONE") {
        settings.monotone = v != "0";
    }
    let r = run(&tanks, &settings)?;
    let mask = |m: &[bool; 4]| {
        m.iter()
            .map(|f| if *f { '1' } else { '0' })
            .collect::<String>()
    };
    println!(
        "structure and β search (simulation RMS [V]; free maps: upper outflow, lower outflow, sensor, upper overflow):"
    );
    for t in &r.trials {
        println!(
            "  {} β = {:<8e} fitting part {:.4}  validation part {:.4}",
            mask(&t.nonlinear),
            t.beta,
            t.fit_rms,
            t.validation_rms
        );
    }
    println!(
        "chosen {} β = {:e}; cost {:.4e} from {:.4e}",
        mask(&r.nonlinear),
        r.beta,
        r.fit.cost,
        r.fit.initial_cost
    );
    common::print_stages("  ", &r.fit.stages);
    println!(
        "estimation RMS {:.4} V; test RMS {:.4} V ({:.1} s)",
        r.estimation_rms, r.test_rms, r.seconds
    );
    println!("published (test RMS [V]):");
    for (m, v) in PUBLISHED {
        println!("  {m:<34} {v}");
    }
    Ok(())
}
