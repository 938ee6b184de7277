//! The discovery workflow on the Silverbox: from the project's own BLA to a named cubic
//! stiffness in feedback from y.
//!
//! ```sh
//! cargo run --release --example silverbox_discovery -- [PATH/SNLS80mV.csv] [OUT_DIR]
//! ```

mod common;

use structid::io::Silverbox;
use structid_benchmarks::silverbox_discovery::{SilverboxDiscoverySettings, run};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (path, _out) = common::benchmark_args("silverbox/SNLS80mV.csv", "silverbox_discovery");
    let sb = Silverbox::load(&path)?;
    let r = run(&sb, &SilverboxDiscoverySettings::default())?;
    println!("BLA ({:.1} s): {:?}", r.bla_seconds, r.bla);
    println!("discover: {:.1} s", r.discover_seconds);
    println!("{}", r.discovery.verdict);
    for h in &r.discovery.hypotheses {
        println!(
            "  {:<16} validation RMS {:.4e}  estimation RMS {:.4e}  β {:.2e}  {:.2} s {}",
            h.location.name(),
            h.validation_rms,
            h.estimation_rms,
            h.beta,
            h.seconds,
            h.failure.clone().unwrap_or_default()
        );
    }
    if let Some(f) = &r.discovery.finding {
        println!("classification: {}", f.classification.describe());
        for (fit, rms) in f.naming.ranked.iter().zip(&f.family_rms).take(5) {
            println!(
                "  {:<40} bic {:.1} rms {:.3e} validation {:?}",
                fit.effect.name(),
                fit.bic,
                fit.rms,
                rms
            );
        }
        println!("remarks: {:?}", f.remarks);
    }
    for t in &r.tests {
        println!(
            "{:<40} BLA {:.3} mV  augmented {:.3} mV  ({:.1}×)",
            t.record,
            1e3 * t.bla_rms,
            1e3 * t.augmented_rms,
            t.bla_rms / t.augmented_rms
        );
    }
    Ok(())
}
