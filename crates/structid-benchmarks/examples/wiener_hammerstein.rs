//! A Wiener–Hammerstein system simulated in continuous time, identified with both LTI blocks
//! unknown: the best linear approximation divided between the blocks, then the joint fit.
//!
//! ```text
//! cargo run --release -p structid-benchmarks --example wiener_hammerstein -- [SEED] [NOISE]
//! ```
//!
//! SEED (default 1) draws the three records (estimation, validation, test) from seeds SEED,
//! SEED + 10 and SEED + 20; NOISE (default 0.02) is the output noise's standard deviation.
//! Prints the RMS errors of the linear approximation, the start and the joint fit on the test
//! record, against the noise, and the map's error.

use structid_benchmarks::wiener_hammerstein::{Plant, record, run};
use structid_joint::JointSettings;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seed: u64 = args.first().map_or(Ok(1), |s| s.parse())?;
    let noise: f64 = args.get(1).map_or(Ok(0.02), |s| s.parse())?;
    let plant = Plant::default();
    let est = record(&plant, 4000, noise, seed);
    let val = record(&plant, 2000, noise, seed + 10);
    let test = record(&plant, 4000, noise, seed + 20);
    let y_rms = (test.y.iter().map(|v| v * v).sum::<f64>() / test.y.len() as f64).sqrt();
    let t = std::time::Instant::now();
    let out = run(&est, &val, &test, &JointSettings::default())?;
    println!("Wiener–Hammerstein, both blocks unknown (output RMS {y_rms:.3}, noise {noise}):");
    println!(
        "  divisions of the linear approximation scored: {}",
        out.divisions
    );
    println!(
        "  test RMS: linear {:.4}  start {:.4}  joint {:.4}  ({:.2}× the noise)",
        out.bla_test_rms,
        out.start_test_rms,
        out.test_rms,
        out.test_rms / noise
    );
    println!(
        "  estimation RMS {:.4}, validation RMS {:.4}, joint fit kept: {}",
        out.fit_rms, out.validation_rms, out.joint_kept
    );
    println!(
        "  map error: {:.2} % of its range as a function, {:.2} % along the test record",
        100.0 * out.map_error,
        100.0 * out.w_error
    );
    println!("  time {:.1} s", t.elapsed().as_secs_f64());
    Ok(())
}
