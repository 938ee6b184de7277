"""Input design (``structid input``): PRBS, multisines, band-limited noise, chirps, steps."""

from __future__ import annotations

from typing import Optional, Sequence, Tuple

import numpy as np

from . import _structid


def _design(kind: str, length: int, sample_time: float, amplitude: float, offset: float,
            band: Optional[Tuple[float, float]], seed: int, **options: object) -> np.ndarray:
    return _structid.design_input(
        kind, int(length), float(sample_time), float(amplitude), float(offset),
        None if band is None else (float(band[0]), float(band[1])), int(seed), **options)


def prbs(length: int, *, sample_time: float = 1.0, amplitude: float = 1.0, offset: float = 0.0,
         band: Optional[Tuple[float, float]] = None, seed: int = 1, order: Optional[int] = None,
         clock: Optional[int] = None) -> np.ndarray:
    """A maximum-length binary sequence, levels ``offset ± amplitude``: period 2ⁿ − 1 bits
    (``order`` n, default the smallest whose period covers the length), each bit held for
    ``clock`` samples (default from the band's upper edge)."""
    return _design("prbs", length, sample_time, amplitude, offset, band, seed,
                   order=order, clock=clock)


def multisine(length: int, *, sample_time: float = 1.0, amplitude: float = 1.0,
              offset: float = 0.0, band: Optional[Tuple[float, float]] = None, seed: int = 1,
              period: Optional[int] = None, odd: bool = False,
              lines: Optional[Sequence[int]] = None, minimise_crest: bool = False) -> np.ndarray:
    """A random-phase multisine of equal line amplitudes, peak ``amplitude``: every harmonic
    of ``period`` (default the length) in the band, only the ``odd`` ones, or the chosen
    ``lines``; ``minimise_crest`` chooses phases that lower the crest factor."""
    return _design("multisine", length, sample_time, amplitude, offset, band, seed,
                   period=period, lines=None if lines is None else [int(k) for k in lines],
                   odd=bool(odd), minimise_crest=bool(minimise_crest))


def noise(length: int, *, sample_time: float = 1.0, amplitude: float = 1.0, offset: float = 0.0,
          band: Optional[Tuple[float, float]] = None, seed: int = 1) -> np.ndarray:
    """Gaussian noise with its spectrum cut to the band, RMS ``amplitude``."""
    return _design("noise", length, sample_time, amplitude, offset, band, seed)


def chirp(length: int, *, sample_time: float = 1.0, amplitude: float = 1.0, offset: float = 0.0,
          band: Optional[Tuple[float, float]] = None, seed: int = 1,
          sweep: str = "linear") -> np.ndarray:
    """A sine sweep across the band, ``linear`` or ``logarithmic`` in frequency."""
    return _design("chirp", length, sample_time, amplitude, offset, band, seed, sweep=sweep)


def steps(length: int, *, sample_time: float = 1.0, amplitude: float = 1.0, offset: float = 0.0,
          band: Optional[Tuple[float, float]] = None, seed: int = 1,
          hold: Tuple[int, int] = (1, 10)) -> np.ndarray:
    """Random levels in ``offset ± amplitude`` held between ``hold[0]`` and ``hold[1]``
    samples: the amplitude-rich input of static nonlinearities."""
    return _design("steps", length, sample_time, amplitude, offset, band, seed,
                   hold=(int(hold[0]), int(hold[1])))


def crest_factor(x: object) -> float:
    """max |x − x̄| / RMS(x − x̄): 1 for a binary signal, √2 for a sine."""
    return _structid.crest_factor(np.asarray(x, dtype=float).ravel().tolist())
