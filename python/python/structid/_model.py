"""The model: a model file (TOML) or a structure built in code, and the dispersions."""

from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _structid
from ._arrays import as_signal

Dispersion = Dict[str, Any]


def _spec(kind: str, **keys: Any) -> Dispersion:
    return {"kind": kind, **{k: v for k, v in keys.items() if v is not None}}


def gaussian(sigma: Optional[float] = None, trend: Optional[int] = None,
             trend_scale: Optional[float] = None) -> Dispersion:
    """The Gaussian RKHS dispersion D = wᵀK⁻¹w of width ``sigma`` (the paper's normalisation);
    without ``sigma``, 0.1 × the range of the block's input. ``trend=d`` adds a polynomial
    trend of degree d (followed outside the data)."""
    return _spec("gaussian", sigma=sigma, trend=trend, trend_scale=trend_scale)


def gaussian_lowrank(sigma: Optional[float] = None, tolerance: Optional[float] = None,
                     trend: Optional[int] = None) -> Dispersion:
    """The Gaussian through Nyström features (pivoted Cholesky to relative trace ``tolerance``)."""
    return _spec("gaussian-lowrank", sigma=sigma, tolerance=tolerance, trend=trend)


def fourier(sigma: Optional[float] = None, harmonics: Optional[int] = None,
            additive: bool = False, trend: Optional[int] = None) -> Dispersion:
    """The Fourier-series kernel with Gaussian-like weights (finitely many features: the
    feature solver, O(L·m²))."""
    return _spec("fourier", sigma=sigma, harmonics=harmonics, additive=additive, trend=trend)


def polynomial(degree: int, scale: Optional[float] = None) -> Dispersion:
    """Ridge regression on the monomials up to total ``degree``."""
    return _spec("polynomial", degree=degree, scale=scale)


def total_variation(neighbours: Optional[int] = None,
                    interpolation: Optional[str] = None) -> Dispersion:
    """Total variation of the piecewise-linear interpolant (keeps jumps and corners); several
    inputs use the k-nearest-neighbour graph (``neighbours``, ``interpolation`` =
    ``"nearest"`` or ``"inverse-distance"``)."""
    return _spec("tv", neighbours=neighbours, interpolation=interpolation)


def _dispersion(d: Union[Dispersion, str]) -> Dispersion:
    if isinstance(d, str):
        return {"kind": d}
    return dict(d)


class Model:
    """A structured model: the known linear block (an LFT or a ``[linear]`` structure), the
    names of the data columns and the unknown static maps with their dispersions.

    Build one from a model file (:meth:`from_file`, :meth:`from_toml`) or from a structure
    (:meth:`hammerstein`, :meth:`wiener`, :meth:`output_feedback`, :meth:`rate_feedback`).
    It is immutable, pickles through its TOML text, and :meth:`save` writes the model file.
    """

    __slots__ = ("_native",)

    def __init__(self, native: "_structid.Model") -> None:
        self._native = native

    # --- construction ---------------------------------------------------------------------

    @classmethod
    def from_toml(cls, text: str, base_dir: Optional[Union[str, os.PathLike]] = None) -> "Model":
        """Parses model-file text; ``base_dir`` resolves relative truth-table paths."""
        return cls(_structid.Model.from_toml(text, None if base_dir is None else os.fspath(base_dir)))

    @classmethod
    def from_file(cls, path: Union[str, os.PathLike]) -> "Model":
        """Reads a model file (as ``structid identify --model``)."""
        return cls(_structid.Model.from_file(os.fspath(path)))

    @classmethod
    def structure(cls, site: Union[str, Sequence[str]], num: Union[Sequence[float], Sequence[Sequence[float]]],
                  den: Sequence[float], dispersion: Union[Dispersion, str, Sequence[Union[Dispersion, str]]] = "gaussian",
                  name: Union[str, Sequence[str], None] = None, sample_time: Optional[float] = None,
                  inputs: Optional[Sequence[str]] = None, output: str = "y") -> "Model":
        """Unknown maps at ``site`` of G(q) = num(q⁻¹)/den(q⁻¹): ``"input"`` (Hammerstein),
        ``"output"`` (Wiener), ``"output-feedback"``, ``"rate-feedback"``, or ``"lti"`` (no
        map). A list of sites places the first in G and each further one at that site of the
        model built so far: ``["input", "output"]`` is Hammerstein–Wiener, ``["output-feedback",
        "rate-feedback"]`` a stiffness and a friction in feedback. ``dispersion`` and ``name``
        may be lists with one entry per site (names default to ``N``, or ``N1, N2, …``).
        ``num`` is one numerator, or one per input; ``inputs`` and ``output`` name the data
        columns (default ``u`` or ``u0, u1, …`` and ``y``)."""
        sites = [site] if isinstance(site, str) else list(site)
        if not sites:
            raise ValueError("site: give at least one site (or \"lti\")")
        if name is None:
            names = ["N"] if len(sites) == 1 else [f"N{i + 1}" for i in range(len(sites))]
        else:
            names = [name] if isinstance(name, str) else list(name)
        ds = list(dispersion) if isinstance(dispersion, (list, tuple)) else [dispersion] * len(sites)
        if len(names) != len(sites) or len(ds) != len(sites):
            raise ValueError(f"{len(sites)} site(s) need as many names and dispersions "
                             f"(got {len(names)} and {len(ds)})")
        nested = len(num) > 0 and np.ndim(num[0]) == 1
        nums = [list(map(float, n)) for n in num] if nested else [list(map(float, num))]
        return cls(_structid.Model.structure(
            sites, nums, [float(d) for d in den], [_dispersion(d) for d in ds], names,
            sample_time, None if inputs is None else list(inputs), output))

    @classmethod
    def hammerstein(cls, num, den, dispersion: Union[Dispersion, str] = "gaussian", **kw: Any) -> "Model":
        """y = G·N(u) + e: the map ahead of the linear block (see :meth:`structure`)."""
        return cls.structure("input", num, den, dispersion, **kw)

    @classmethod
    def wiener(cls, num, den, dispersion: Union[Dispersion, str] = "gaussian", **kw: Any) -> "Model":
        """y = N(G·u) + e: the map after the linear block (a sensor map)."""
        return cls.structure("output", num, den, dispersion, **kw)

    @classmethod
    def output_feedback(cls, num, den, dispersion: Union[Dispersion, str] = "gaussian", **kw: Any) -> "Model":
        """y = G·(u − N(y)) + e: the map in feedback from the output (Silverbox-like)."""
        return cls.structure("output-feedback", num, den, dispersion, **kw)

    feedback = output_feedback

    @classmethod
    def rate_feedback(cls, num, den, dispersion: Union[Dispersion, str] = "gaussian", **kw: Any) -> "Model":
        """y = G·(u − N(ẏ)) + e with ẏ the measured rate (y_k − y_(k−1))/T_s."""
        return cls.structure("rate-feedback", num, den, dispersion, **kw)

    # --- derived models -------------------------------------------------------------------

    def with_dispersion(self, dispersion: Union[Dispersion, str]) -> "Model":
        """Every block with ``dispersion`` (keeping its σ when the new one gives none)."""
        return Model(self._native.with_dispersion(_dispersion(dispersion)))

    def with_truth(self, block: str, expression: str) -> "Model":
        """Block ``block`` with a known true map (an expression in z0, z1, …) for :meth:`simulate`."""
        return Model(self._native.with_truth(block, expression))

    def with_shape(self, block: str, shape: Optional[str]) -> "Model":
        """Block ``block`` declared monotone, ``"increasing"`` or ``"decreasing"`` (``None``
        removes the declaration): :func:`structid.refine_joint` then keeps the map going that
        way everywhere, beyond the data too (``shape = …`` in the model file)."""
        return Model(self._native.with_shape(block, shape))

    # --- views ------------------------------------------------------------------------------

    @property
    def signals(self) -> Dict[str, Optional[List[str]]]:
        """The data columns: ``{"u": [...], "y": [...], "z": [...] or None}``."""
        return self._native.signals

    @property
    def blocks(self) -> List[Dict[str, Any]]:
        """The blocks: name, inputs (z channels), output (w channel), dispersion, sigma, truth."""
        return self._native.blocks

    @property
    def dims(self) -> Dict[str, int]:
        """Sizes of the LFT: states, u, e, w, y, z."""
        return self._native.dims

    def to_toml(self) -> str:
        """The model-file text (canonical form)."""
        return self._native.to_toml()

    def save(self, path: Union[str, os.PathLike]) -> None:
        """Writes the model file (readable by ``structid identify --model``)."""
        with open(path, "w", encoding="utf-8") as f:
            f.write(self.to_toml())

    def simulate(self, u: object, noise_std: float = 0.0, seed: int = 0) -> Dict[str, np.ndarray]:
        """Simulates with every block's truth in the loop (as ``structid simulate``): returns
        ``{"y", "z", "w"}``, each L × channels."""
        return self._native.simulate(as_signal(u, "u", self.dims["u"]), float(noise_std), int(seed))

    def block_access(self) -> List[Tuple[str, str, List[str]]]:
        """How identification reaches each block: ``(name, kind, upstream)`` with kind
        ``"computable"`` (from u and y), ``"in series"`` (it reads the blocks ``upstream`` in the
        same sample) or ``"latent"`` (u and y do not reveal its input). Blocks that are not
        computable need :func:`refine_joint`."""
        return self._native.block_access()

    def why_simulation_only(self) -> Optional[str]:
        """Why ``validate`` scores the model by its simulation alone (a latent block or a
        hysteresis operator), or None when the one-step predictor applies (maps in series are
        evaluated in order)."""
        return self._native.why_simulation_only()

    def score_simulation(self, u: object, y: object, settle: int = 0) -> Dict[str, Any]:
        """The simulation from rest on (u, y) and its scores after ``settle`` samples, as
        ``structid validate`` scores a model without a one-step predictor: ``{"y_sim", "rms",
        "fit_percent"}`` (``fit_percent`` is 100·(1 − ‖y − ŷ‖/‖y − ȳ‖) per output)."""
        return self._native.score_simulation(as_signal(u, "u", self.dims["u"]),
                                             as_signal(y, "y", self.dims["y"]), int(settle))

    def __getstate__(self) -> str:
        return self.to_toml()

    def __setstate__(self, text: str) -> None:
        self._native = _structid.Model.from_toml(text)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Model) and self.to_toml() == other.to_toml()

    def __repr__(self) -> str:
        return repr(self._native)
