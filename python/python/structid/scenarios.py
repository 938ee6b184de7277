"""The library's benchmark scenarios (the problems of the project's criterion benches)."""

from __future__ import annotations

from . import _structid
from .paper import Experiment, _experiment


def hammerstein_coloured(samples: int, order: int = 4, noise_std: float = 0.3, seed: int = 11,
                         sigma: float = 0.2, harmonics: int = 31) -> Experiment:
    """The feature solver's benchmark problem (``cargo bench --bench features``): SISO
    Hammerstein with N = tanh, an IIR linear block of ``order``, coloured noise
    H = (1 + 0.5q⁻¹)/(1 − 0.8q⁻¹), white input; block ``N`` has the Fourier dispersion with
    Gaussian-like weights of width ``sigma`` and ``harmonics`` harmonics (m = 2·harmonics + 1
    features)."""
    return _experiment(_structid.hammerstein_coloured(int(samples), int(order), float(noise_std),
                                                      int(seed), float(sigma), int(harmonics)))
