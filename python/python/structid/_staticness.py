"""How well a static map explains a (z, w) scatter (``structid static``, the paper's Example 1)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Dict, Optional

import numpy as np

from . import _structid


@dataclass
class Staticness:
    """The best static map w = N(z) and what it leaves: ``verdict`` is ``static``,
    ``direction_dependent`` (hysteresis or backlash suspected) or ``unexplained``."""

    verdict: str
    verdict_text: str
    unexplained_ratio: float
    """Unexplained variance over the noise variance (about 1 for a static map)."""
    explained_share: float
    """Share of the residual variance the direction of motion of z explains."""
    noise_std: float
    sigma: float
    beta: float
    fitted: np.ndarray
    """N̂(z_k) at the samples."""
    grid_z: np.ndarray
    grid_w: np.ndarray
    report: Dict[str, Any]
    """Everything ``structid static`` writes in report.json."""


def staticness(z: object, w: object, *, sigma_fraction: Optional[float] = None,
               sigma: Optional[float] = None, noise_std: Optional[float] = None,
               ratio_limit: Optional[float] = None,
               direction_threshold: Optional[float] = None) -> Staticness:
    """Fits the best static map by a Gaussian kernel with automatic β and rates the
    unexplained variance against the noise level (``noise_std``, else estimated from the
    residual's first differences) and the direction test."""
    zz = np.ascontiguousarray(np.asarray(z, dtype=float).ravel())
    ww = np.ascontiguousarray(np.asarray(w, dtype=float).ravel())
    out = _structid.staticness_columns(zz, ww, sigma_fraction, sigma, noise_std, ratio_limit,
                                       direction_threshold)
    report = json.loads(out["report"])
    return Staticness(verdict=report["verdict"], verdict_text=out["verdict_text"],
                      unexplained_ratio=report["unexplained_ratio"],
                      explained_share=report["explained_share"],
                      noise_std=float(np.sqrt(report["noise_variance"])),
                      sigma=report["sigma"], beta=report["beta"], fitted=out["fitted"],
                      grid_z=out["grid_z"], grid_w=out["grid_w"], report=report)
