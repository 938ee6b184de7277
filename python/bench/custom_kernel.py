"""Times identification with a kernel written in numpy against the built-in kernel it equals.

    python python/bench/custom_kernel.py [--samples 2000] [--repeats 5]

The problem: the README's Hammerstein model (G(q) = (0.5q⁻¹ + 0.3q⁻²)/(1 − 1.2q⁻¹ + 0.5q⁻²),
N = tanh(2z)) simulated from a uniform input with noise 0.05, β = 1e-4, the exact solver,
bands kept. Two fits alternate, so that both see the same load on the machine: the built-in
Gaussian (σ = 0.3), and the same Gaussian written in numpy (``structid.Kernel``), called once
per block of Gram columns and per block of cross-Gram rows.

The script prints the medians and the ratio numpy / built-in, and checks that ŵ agree.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import structid

SIGMA = 0.3


def np_gaussian(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2)
    return np.exp(-d2 / (2 * SIGMA**2)) / (2 * np.pi * SIGMA**2) ** (a.shape[1] / 2)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--samples", type=int, default=2000)
    p.add_argument("--repeats", type=int, default=5)
    a = p.parse_args()

    model = structid.Model.hammerstein(num=[0.0, 0.5, 0.3], den=[1.0, -1.2, 0.5],
                                       dispersion=structid.gaussian(sigma=SIGMA))
    u = np.random.default_rng(1).uniform(-2, 2, a.samples)
    y = model.with_truth("N", "tanh(2*z0)").simulate(u, noise_std=0.05, seed=1)["y"]
    kernel = structid.Kernel(np_gaussian, name="np-gaussian")

    builtin, numpy_k = [], []
    for i in range(a.repeats):
        t = time.perf_counter()
        ref = structid.identify(model, u, y, beta=1e-4, solver="exact")
        builtin.append(time.perf_counter() - t)
        t = time.perf_counter()
        mine = structid.identify(model, u, y, beta=1e-4, solver="exact", dispersion=kernel)
        numpy_k.append(time.perf_counter() - t)
        diff = np.abs(mine.w_hat - ref.w_hat).max() / np.abs(ref.w_hat).max()
        print(f"repeat {i + 1}: built-in {builtin[-1]:.3f} s, numpy {numpy_k[-1]:.3f} s, "
              f"max relative difference of w_hat {diff:.1e}")
    b, n = statistics.median(builtin), statistics.median(numpy_k)
    print(f"L = {a.samples}: built-in {b:.3f} s, numpy kernel {n:.3f} s, ratio {n / b:.2f}")


if __name__ == "__main__":
    main()
