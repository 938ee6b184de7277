"""The examples of Hsu, Vincent, Wemhoff & Poolla (2006), as ``structid demo`` generates them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _structid
from ._model import Model


@dataclass
class Experiment:
    """A generated record with its model and the true map outputs."""

    model: Model
    """The structured model (Gaussian dispersions of the experiment's σ)."""
    u: np.ndarray
    y: np.ndarray
    w_true: np.ndarray
    """The true map outputs, L × n_w."""
    noise: np.ndarray


def _experiment(d: dict) -> Experiment:
    d["model"] = Model(d["model"])
    return Experiment(**d)


def spray(samples: int = 2000, noise_std: float = 1.0, sigma: float = 0.1, seed: int = 1) -> Experiment:
    """The spray-deposition example (section 6.1, ``structid demo spray``):
    y_k = f(u_k) + g(u_(k−2)) + e_k, u_k = sin(0.1k), f(z) = −|z|,
    g(z) = 0.5·(sin((3z)²) + (2z)² − 2), blocks ``f`` and ``g``."""
    return _experiment(_structid.spray(int(samples), float(noise_std), float(sigma), int(seed)))


def multi_input(samples: int = 1500, noise_std: float = 0.1, sigma: float = 0.5, seed: int = 1) -> Experiment:
    """The two-input example (section 6.2, ``structid demo multi-input``)."""
    return _experiment(_structid.multi_input(int(samples), float(noise_std), float(sigma), int(seed)))
