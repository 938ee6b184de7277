//! The facade's Cargo features: without the default `plot` and `workflow` features, nothing
//! of the plotting stack is built.

use std::process::Command;

/// The normal dependencies of the facade, as `cargo tree` prints them.
fn tree(extra: &[&str]) -> String {
    let out = Command::new(env!("CARGO"))
        .args(["tree", "-p", "structid", "-e", "normal", "--prefix", "none"])
        .args(extra)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo tree failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8")
}

#[test]
fn plotting_is_optional() {
    let full = tree(&[]);
    assert!(
        full.contains("plotters"),
        "the default build has the figures"
    );
    let lean = tree(&["--no-default-features"]);
    assert!(!lean.contains("plotters"), "{lean}");
    assert!(!lean.contains("structid-plot"), "{lean}");
    assert!(!lean.contains("structid-workflow"), "{lean}");
    // The workflows write figures: asking for them brings the plotting stack.
    let workflows = tree(&["--no-default-features", "--features", "workflow"]);
    assert!(workflows.contains("plotters"), "{workflows}");
    assert!(lean.contains("structid-core"), "{lean}");
}
