//! Writes the closed-loop positioning axis of `structid_testcases::physics::positioning_axis`
//! (continuous-time physics: M·q̈ + Fv·q̇ + Fc·sign(q̇) + offset = τ under a PD controller,
//! sampled at 1 kHz) as files for the command-line tool: `DIR/estimation.csv` and
//! `DIR/validation.csv` (columns `tau`, `q`) and `DIR/nominal.toml`, the physical nominal
//! M·q̈ + Fv·q̇ = τ discretised (a pole at z = 1), then runs the discovery on it.
//!
//! ```sh
//! cargo run --release -p structid-discover --example positioning_axis -- axis
//! structid discover --model axis/nominal.toml --data axis/estimation.csv \
//!     --validate axis/validation.csv --out axis/found
//! ```

use std::fmt::Write as _;

use structid_core::Data;
use structid_discover::discover::{DiscoverSettings, discover};
use structid_discover::hypotheses::Nominal;
use structid_testcases::physics::positioning_axis;

fn csv(d: &Data) -> String {
    let mut s = String::from("tau,q\n");
    for k in 0..d.len() {
        let _ = writeln!(s, "{:e},{:e}", d.u().get(k, 0), d.y().get(k, 0));
    }
    s
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::path::PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "axis".into()));
    std::fs::create_dir_all(&dir)?;
    let axis = positioning_axis(1);
    std::fs::write(dir.join("estimation.csv"), csv(&axis.estimation))?;
    std::fs::write(dir.join("validation.csv"), csv(&axis.validation))?;
    let g = &axis.nominal;
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    std::fs::write(
        dir.join("nominal.toml"),
        format!(
            "# M·q̈ + Fv·q̇ = τ with M = {}, Fv = {}, zero-order hold at T_s = {} s\n[linear]\n\
             structure = \"lti\"\nsample_time = {}\nden = [{}]\nnum = [[{}]]\n\n[signals]\n\
             u = [\"tau\"]\ny = [\"q\"]\n",
            axis.mass,
            axis.viscous,
            g.sample_time.unwrap_or(1.0),
            g.sample_time.unwrap_or(1.0),
            list(&g.den),
            list(&g.num[0])
        ),
    )?;
    let d = discover(
        &Nominal::from_polynomial(g)?,
        &axis.estimation,
        &axis.validation,
        &DiscoverSettings::default(),
    )?;
    println!("true: Fc = {}, offset = {}", axis.coulomb, axis.offset);
    println!("{}", d.verdict);
    println!("scored by {}", d.scoring.describe());
    Ok(())
}
