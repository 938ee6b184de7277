"""structid: structured nonlinear system identification from Python.

A system is an interconnection of *known* linear time-invariant blocks and *unknown static*
maps, written as one linear fractional transformation (LFT). :func:`identify` finds the maps
that explain measured data with the least complexity,

    J = (1/L)·Σ|e_k|² + β·Σ_i D_i(z_i, w_i),

for a Gaussian RKHS, Fourier-series, total-variation (or other) dispersion D_i, with β and σ
given or selected automatically (Hsu, Vincent, Wemhoff & Poolla, IFAC SYSID 2006).

This package is a thin layer over the Rust library: every number comes from the same code as
the ``structid`` command-line tool, and long calls release the GIL.

>>> import numpy as np, structid
>>> model = structid.Model.hammerstein(num=[0.0, 0.5, 0.3], den=[1.0, -1.2, 0.5],
...                                    dispersion=structid.gaussian(sigma=0.3))
>>> u = np.sin(0.07 * np.arange(400)) * 2.0
>>> sim = model.with_truth("N", "tanh(2*z0)").simulate(u, noise_std=0.05, seed=1)
>>> fit = structid.identify(model, u, sim["y"], beta=1e-4)
>>> fit.maps["N"].value.shape
(201,)
"""

from __future__ import annotations

from ._structid import FeatureMap, Kernel, StructidError, __version__
from ._model import Model, gaussian, gaussian_lowrank, fourier, polynomial, total_variation
from ._identify import Fit, MapEstimate, identify, load
from ._estimate import Estimate, Prediction, RecordsValidation, Validation
from ._workflows import (BlockStructured, Discovery, Finding, JointRefinement, Refinement,
                         discover, refine, refine_joint, silverbox_data, silverbox_discovery,
                         hammerstein_wiener, wiener_hammerstein)
from ._staticness import Staticness, staticness
from ._linear import LinearFit, Response, linear, read_data, response
from . import input, paper, scenarios

__all__ = [
    "StructidError",
    "Model",
    "Estimate",
    "Fit",
    "MapEstimate",
    "Prediction",
    "RecordsValidation",
    "Validation",
    "identify",
    "load",
    "refine",
    "Refinement",
    "refine_joint",
    "JointRefinement",
    "wiener_hammerstein",
    "hammerstein_wiener",
    "BlockStructured",
    "discover",
    "Discovery",
    "Finding",
    "silverbox_data",
    "silverbox_discovery",
    "staticness",
    "linear",
    "LinearFit",
    "response",
    "Response",
    "read_data",
    "Staticness",
    "input",
    "paper",
    "scenarios",
    "gaussian",
    "gaussian_lowrank",
    "fourier",
    "polynomial",
    "total_variation",
    "Kernel",
    "FeatureMap",
    "__version__",
]
