"""The paper's spray example and a Silverbox discovery, notebook style.

    python python/examples/spray_and_silverbox.py [--silverbox PATH/SNLS80mV.csv] [--out DIR]

Part 1 redoes the spray-deposition example of Hsu, Vincent, Wemhoff & Poolla (2006),
section 6.1 (``structid demo spray``): y_k = f(u_k) + g(u_(k−2)) + e_k with unit noise,
Gaussian dispersions of width 0.1, identified for β = 0.001, 0.01 and 0.1 (Fig. 4), then with
β and σ selected by the marginal likelihood.

Part 2 runs the discovery workflow on the Silverbox benchmark: the best linear approximation
of order 2 is the nominal model, and discovery finds what it is missing (a cubic stiffness in
feedback from the output) and scores the augmented model on the test splits. The data file is
``--silverbox``, else ``$STRUCTID_DATA/silverbox/SNLS80mV.csv``, else
``../shared/data/silverbox/SNLS80mV.csv`` beside the repository (as the project's tests find
it); without it part 2 is skipped with a message.

Figures are written with matplotlib when it is installed (``pip install matplotlib``).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import structid

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:  # the numbers do not need it
    plt = None


def centred_rms(a: np.ndarray, b: np.ndarray) -> float:
    """RMS of the difference after removing each one's mean (f and g are known up to a
    constant each: only f + g's offset is identifiable)."""
    return float(np.sqrt(np.mean(((a - a.mean()) - (b - b.mean())) ** 2)))


def spray(out: str) -> None:
    # %% The record: L = 2000, u_k = sin(0.1k), e ~ N(0, 1), as `structid demo spray`.
    exp = structid.paper.spray(samples=2000, noise_std=1.0, sigma=0.1, seed=1)
    print(f"spray: {exp.u.shape[0]} samples, blocks {[b['name'] for b in exp.model.blocks]}")

    # %% Fig. 4: one identification per β.
    fits = {}
    for beta in (0.001, 0.01, 0.1):
        t = time.perf_counter()
        fit = structid.identify(exp.model, exp.u, exp.y, beta=beta)
        fits[beta] = fit
        print(f"  β = {beta:<6} J = {fit.cost['total']:.4f}  "
              f"RMS(f̂ − f) = {centred_rms(fit.w_hat[:, 0], exp.w_true[:, 0]):.4f}  "
              f"RMS(ĝ − g) = {centred_rms(fit.w_hat[:, 1], exp.w_true[:, 1]):.4f}  "
              f"({time.perf_counter() - t:.2f} s, {fit.diagnostics['solver']})")

    # %% β and σ chosen by the marginal likelihood instead.
    auto = structid.identify(exp.model, exp.u, exp.y, beta="auto", sigma="auto")
    print(f"  selected β = {auto.beta:.3e}, σ = {auto.sigma:.3f}: "
          f"RMS(f̂ − f) = {centred_rms(auto.w_hat[:, 0], exp.w_true[:, 0]):.4f}, "
          f"RMS(ĝ − g) = {centred_rms(auto.w_hat[:, 1], exp.w_true[:, 1]):.4f}")

    # %% The fit is a value: save it as the tool does, pickle it, validate it on a new record.
    auto.save(os.path.join(out, "spray-fit"))
    fresh = structid.paper.spray(samples=1000, noise_std=1.0, sigma=0.1, seed=2)
    v = auto.validate(fresh.u, fresh.y)
    print(f"  on a fresh record: simulation RMS {v.rms[0]:.4f} (noise std 1), "
          f"one-step residuals white: {v.whiteness_passes}")

    if plt is not None:
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        z = exp.u[:, 0]
        order = np.argsort(z)
        for ax, name, col in ((axes[0], "f", 0), (axes[1], "g", 1)):
            truth = exp.w_true[:, col]
            ax.plot(z[order], truth[order] - truth.mean(), "k-", label="true")
            for beta, fit in fits.items():
                w = fit.w_hat[:, col]
                ax.plot(z, w - w.mean(), ".", ms=2, label=f"β = {beta}")
            m = auto.maps[name]
            shift = auto.w_hat[:, col].mean()
            ax.fill_between(m.grid[:, 0], m.lower - shift, m.upper - shift, alpha=0.3,
                            label="95 % band (auto)")
            ax.set_title(f"{name}: centred estimates")
            ax.set_xlabel("z = u")
            ax.legend(fontsize=7)
        fig.tight_layout()
        path = os.path.join(out, "spray_fig4.png")
        fig.savefig(path, dpi=120)
        print(f"  wrote {path}")


def silverbox(path: str, out: str) -> None:
    # %% Discovery from the BLA of order 2.
    t = time.perf_counter()
    d = structid.silverbox_discovery(path, order=2)
    print(f"silverbox: {d.verdict}")
    print(f"  ({time.perf_counter() - t:.1f} s)")
    for h in d.hypotheses:
        print(f"  {h['location']:<16} validation RMS {h['validation_rms']:.4e}")
    for test in d.extra["tests"]:
        print(f"  {test['split']:<40} BLA RMS {1e3 * test['bla_rms']:.3f} mV → augmented "
              f"{1e3 * test['augmented_rms']:.3f} mV")
    if plt is not None and d.finding is not None:
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        f = d.finding
        axes[0].plot(f.z, f.w, "-")
        axes[0].set_title(f"N̂ at {f.location}: {f.effect}")
        axes[0].set_xlabel("z")
        test = d.extra["tests"][0]
        k = slice(0, 4000)
        axes[1].plot(test["measured"][k] - test["simulated"][k], lw=0.5, label="augmented")
        axes[1].plot(test["measured"][k] - test["bla_simulated"][k], lw=0.5, label="BLA")
        axes[1].set_title(f"simulation error, {test['split']}")
        axes[1].legend()
        fig.tight_layout()
        path = os.path.join(out, "silverbox_discovery.png")
        fig.savefig(path, dpi=120)
        print(f"  wrote {path}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--silverbox", help="path of SNLS80mV.csv")
    p.add_argument("--out", default="structid-python-example", help="output directory")
    a = p.parse_args()
    os.makedirs(a.out, exist_ok=True)
    spray(a.out)
    try:
        path = structid.silverbox_data(a.silverbox)
    except structid.StructidError as e:
        print(f"silverbox: skipped ({e})")
        return
    if not os.path.isfile(path):
        print(f"silverbox: skipped ({path} not found; give --silverbox PATH)")
        return
    silverbox(path, a.out)


if __name__ == "__main__":
    main()
