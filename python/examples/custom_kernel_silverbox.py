"""A kernel written in numpy on a real record: the Silverbox's restoring force.

    python python/examples/custom_kernel_silverbox.py [--silverbox PATH/SNLS80mV.csv]

A window of the Silverbox estimation data (samples 50 000–53 999, offsets removed) gives the
best linear approximation G of orders (2, 3, 1) by output error; the missing force is a map in
feedback from the output, y = G·(u − N(y)). N is identified twice, with β chosen by the
marginal likelihood: with the built-in Gaussian (σ = 0.05 V) and with the same Gaussian
written in numpy and passed as ``structid.Kernel``. Both are validated on samples
60 000–61 999 by simulation. The script prints the β chosen, the validation RMS of G alone
and of each model, and how far apart the two ŵ are: the numpy kernel must give the built-in
one's numbers on measured data too. G stays the linear approximation (nothing is refined), so
the RMS is far from the benchmark's best models (``cargo run --release -p
structid-benchmarks --example silverbox``); the point here is the equality.

The data file is ``--silverbox``, else ``$STRUCTID_DATA/silverbox/SNLS80mV.csv``, else
``../shared/data/silverbox/SNLS80mV.csv`` beside the repository.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import structid

SIGMA = 0.05


def np_gaussian(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The paper's Gaussian (2πσ²)^(−p/2)·exp(−‖a − b‖²/(2σ²)), vectorised over rows."""
    d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2)
    return np.exp(-d2 / (2 * SIGMA**2)) / (2 * np.pi * SIGMA**2) ** (a.shape[1] / 2)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--silverbox", help="path of SNLS80mV.csv")
    a = p.parse_args()
    raw = np.genfromtxt(structid.silverbox_data(a.silverbox), delimiter=",", skip_header=1)
    u_all, y_all = raw[:, 0] - raw[:, 0].mean(), raw[:, 1] - raw[:, 1].mean()
    est, val = slice(50_000, 54_000), slice(60_000, 62_000)
    u, y, uv, yv = u_all[est], y_all[est], u_all[val], y_all[val]

    lin = structid.linear(u, y, (2, 3, 1), method="oe")
    num, den = list(lin.num[0]), list(lin.den)
    linear_rms = np.sqrt(np.mean((lin.model.simulate(uv)["y"][:, 0] - yv) ** 2))
    model = structid.Model.output_feedback(num, den, structid.gaussian(sigma=SIGMA))
    print(f"G alone: validation RMS {1e3 * linear_rms:.3f} mV")
    fits = {}
    for name, dispersion in [("built-in", None),
                             ("numpy", structid.Kernel(np_gaussian, name="np-gaussian"))]:
        t = time.perf_counter()
        fit = structid.identify(model, u, y, beta="auto", dispersion=dispersion)
        seconds = time.perf_counter() - t
        rms = fit.validate(uv, yv).rms[0]
        print(f"{name:8s}: β = {fit.beta:.3e}, validation RMS {1e3 * rms:.3f} mV, {seconds:.2f} s")
        fits[name] = fit
    ref, mine = fits["built-in"].w_hat, fits["numpy"].w_hat
    print(f"max relative difference of ŵ: {np.abs(mine - ref).max() / np.abs(ref).max():.1e}")


if __name__ == "__main__":
    main()
