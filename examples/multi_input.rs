//! The paper's multi-input example (section 6.2), reproduced.
//!
//! A random stable L_yu with three states and two inputs, i.i.d. uniform inputs with mean 0 and
//! variance 1.5, unit Gaussian noise, and a smooth two-input map N(z₁, z₂) =
//! sin(z₁)·exp(−0.3·z₂²) + 0.2·z₂ of z = u (the paper does not give its map). Writes the true
//! and estimated surfaces as SVG heat maps on a shared colour scale.
//!
//! `cargo run --release --example multi_input -- [L] [out_dir]` (defaults 1500, target/examples/multi_input)

use std::sync::Arc;

use structid::paper::{multi_input, multi_input_map};
use structid::plot::{HeatMap, render_heatmaps_svg};
use structid::validation::metrics::rms_difference;
use structid::{IdentifySettings, KernelDispersion, identify};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let len: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1500);
    let out = std::path::PathBuf::from(
        args.get(2)
            .cloned()
            .unwrap_or_else(|| "target/examples/multi_input".into()),
    );
    std::fs::create_dir_all(&out)?;
    let exp = multi_input(len, 1.0, Arc::new(KernelDispersion::gaussian(0.5)?), 62)?;
    let settings = IdentifySettings::builder().beta(0.01).build()?;
    let id = identify(&exp.model, &exp.data, &settings)?;
    let block = &id.blocks[0];
    let truth: Vec<f64> = (0..len)
        .map(|k| multi_input_map(block.z.sample(k)))
        .collect();
    println!(
        "multi-input example, L = {len}: RMS map error at the data {:.4} (map RMS {:.4}), J = {:.4}, {:.2} s",
        rms_difference(&block.w_hat, &truth),
        structid::validation::metrics::rms(&truth),
        id.cost.total,
        id.diagnostics.timings.total
    );
    let h = 2.0f64 * 1.5f64.sqrt() * 3.0f64.sqrt() / 2.0; // half-width of the uniform inputs
    let n = 41;
    let axis: Vec<f64> = (0..n)
        .map(|i| -h + 2.0 * h * i as f64 / (n - 1) as f64)
        .collect();
    let mut est = Vec::with_capacity(n * n);
    let mut tru = Vec::with_capacity(n * n);
    for &b in &axis {
        for &a in &axis {
            est.push(block.predict(&[a, b]));
            tru.push(multi_input_map(&[a, b]));
        }
    }
    let (lo, hi) = tru
        .iter()
        .chain(&est)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), v| {
            (l.min(*v), u.max(*v))
        });
    let maps = [
        HeatMap::new("true N(z1, z2)", "z1", "z2", &axis, &axis, &tru).with_range(lo, hi),
        HeatMap::new("estimated N(z1, z2)", "z1", "z2", &axis, &axis, &est).with_range(lo, hi),
    ];
    let path = out.join("surfaces.svg");
    std::fs::write(&path, render_heatmaps_svg(&maps, 2, (480, 420))?)?;
    println!("figure: {}", path.display());
    Ok(())
}
