//! Silverbox: the alternating pipeline's model, then refined as a whole by its simulation error.
//!
//! ```text
//! cargo run --release -p structid-benchmarks --example silverbox_joint -- [PATH/SNLS80mV.csv]
//! ```
//!
//! Runs the pipeline with the settings of its test (sixth order, separate feedback numerator,
//! polynomial map), prints its test RMS, then the joint refinement's β search and test RMS.

use structid::io::Silverbox;
use structid_benchmarks::silverbox::{SilverboxSettings, run};
use structid_benchmarks::silverbox_joint::{JointSilverboxSettings, run_joint};

mod common;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (path, _) = common::benchmark_args("silverbox/SNLS80mV.csv", "silverbox");
    let sb = Silverbox::load(&path)?;
    let settings = SilverboxSettings {
        orders: vec![6],
        numerators: vec![true],
        kernel_margin: f64::INFINITY,
        ..SilverboxSettings::default()
    };
    let base = run(&sb, &settings)?;
    for t in &base.tests {
        println!("alternation: {:<28} {:.4} mV", t.split, 1e3 * t.rms);
    }
    let mut js = JointSilverboxSettings::default();
    common::env_override_list("SB_BETAS", &mut js.betas)?;
    common::env_override("SB_SECOND_MAP", &mut js.second_map)?;
    common::env_override("SB_ITERATIONS", &mut js.max_iterations)?;
    let j = run_joint(&sb, &base, &js)?;
    for (b, v) in &j.trials {
        println!("joint: β = {b:e}, validation {:.4} mV", 1e3 * v);
    }
    common::print_stages("joint: ", &j.fit.stages);
    for (split, rms) in &j.tests {
        println!("joint: {split:<28} {:.4} mV", 1e3 * rms);
    }
    println!(
        "joint refinement: {:.1} s (pipeline {:.1} s)",
        j.seconds, base.seconds
    );
    Ok(())
}
