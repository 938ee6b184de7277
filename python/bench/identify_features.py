"""Times identification with the feature (Fourier) solver through the Python bindings against
the same problem in Rust.

    python python/bench/identify_features.py [--samples 1000000] [--repeats 5]
        [--rust target/release/examples/feature_scaling]

The problem is the one of ``cargo bench --bench features`` and ``examples/feature_scaling.rs``:
SISO Hammerstein (N = tanh), a 4th-order IIR linear block, coloured noise (Kalman-whitened),
Fourier dispersion with 31 harmonics (m = 63 features), β = 1e-4, the feature solver. The
Python call is ``structid.identify(..., solver="features", bands=False)`` (the example keeps
no posterior either); its time includes copying the record out of numpy, the checks of the
record, the report and the stored estimate.

With ``--rust`` (build it with ``cargo build --release --example feature_scaling``) the Rust
example runs between the Python repeats, so that both see the same load on the machine, and
the script prints both medians and their ratio.
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import time

import structid


def rust_seconds(binary: str, samples: int) -> float:
    out = subprocess.run([binary, str(samples)], capture_output=True, text=True, check=True).stdout
    m = re.search(r"features \(m = \d+\): ([0-9.]+) s", out)
    if not m:
        raise RuntimeError(f"unexpected output of {binary}: {out}")
    return float(m.group(1))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--samples", type=int, default=1_000_000)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--rust", help="path of the feature_scaling example binary")
    a = p.parse_args()

    t = time.perf_counter()
    exp = structid.scenarios.hammerstein_coloured(a.samples)
    print(f"scenario: L = {a.samples}, generated in {time.perf_counter() - t:.2f} s")

    py_times, rust_times = [], []
    for i in range(a.repeats):
        t = time.perf_counter()
        fit = structid.identify(exp.model, exp.u, exp.y, beta=1e-4, solver="features", bands=False)
        py_times.append(time.perf_counter() - t)
        line = f"repeat {i + 1}: python {py_times[-1]:.3f} s ({fit.diagnostics['solver']}, " \
               f"solver's own total {fit.diagnostics['timings']['total']:.3f} s)"
        if a.rust:
            rust_times.append(rust_seconds(a.rust, a.samples))
            line += f", rust {rust_times[-1]:.3f} s"
        print(line)
    py = statistics.median(py_times)
    print(f"python median {py:.3f} s (min {min(py_times):.3f} s)")
    if rust_times:
        rust = statistics.median(rust_times)
        print(f"rust   median {rust:.3f} s (min {min(rust_times):.3f} s)")
        print(f"python / rust = {py / rust:.3f} (goal ≤ 1.10)")


if __name__ == "__main__":
    main()
