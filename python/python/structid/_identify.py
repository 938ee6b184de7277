"""Identification and its results: ŵ, ê, the maps on a grid with bands, the report."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _structid
from ._arrays import is_records, named_columns
from ._estimate import Estimate, Prediction, RecordsValidation, Validation
from ._model import Dispersion, Model, _dispersion


@dataclass(frozen=True)
class MapEstimate:
    """One block's estimated map N̂: its data points and its values on a grid over the data
    range (201 points for one input, 41 × 41 for two, the data points for more)."""

    name: str
    dispersion: str
    z: np.ndarray
    """The block's input at each sample, L × p."""
    w_hat: np.ndarray
    """ŵ at each sample, length L."""
    grid: np.ndarray
    """Evaluation points, G × p."""
    value: np.ndarray
    """N̂ on the grid."""
    std: Optional[np.ndarray]
    """Posterior standard deviation on the grid (None without bands)."""
    dispersion_value: float
    """D_i(z, ŵ)."""

    @property
    def lower(self) -> Optional[np.ndarray]:
        """Lower edge of the 95 % band, N̂ − 1.96·std."""
        return None if self.std is None else self.value - 1.96 * self.std

    @property
    def upper(self) -> Optional[np.ndarray]:
        """Upper edge of the 95 % band, N̂ + 1.96·std."""
        return None if self.std is None else self.value + 1.96 * self.std


@dataclass
class Fit:
    """The result of :func:`identify`: the fitted model and everything the command-line tool
    writes for it. Pickles (the estimate through its JSON document) and saves to the tool's
    result directory (:meth:`save`, :func:`load`)."""

    estimate: Estimate
    model: Model
    w_hat: np.ndarray
    """ŵ, L × n_w (one column per w channel, named by ``w_names``)."""
    e_hat: np.ndarray
    """ê, L × n_e."""
    w_names: List[str]
    beta: float
    """β used (the chosen one after selection)."""
    sigma: Optional[float]
    """σ given or chosen for every block, when one was."""
    maps: Dict[str, MapEstimate]
    report: Dict[str, Any]
    """report.json of ``structid identify``: settings, cost terms, diagnostics, blocks, selection."""
    widths: List[Optional[float]] = field(default_factory=list)
    """Per block: the σ chosen by selection, when σ was selected."""
    noise_variance: Optional[float] = None

    @property
    def cost(self) -> Dict[str, Any]:
        """Cost terms: ``total`` J, ``noise`` (1/L)·Σ|ê|², ``dispersions`` D_i, ``beta``."""
        return self.report["cost"]

    @property
    def diagnostics(self) -> Dict[str, Any]:
        """Solver, reason, status, residuals, timings and warnings."""
        return self.report["diagnostics"]

    def evaluate(self, block: str, points: object) -> np.ndarray:
        """N̂ of ``block`` at ``points``."""
        return self.estimate.evaluate(block, points)

    def band(self, block: str, points: object) -> Optional[np.ndarray]:
        """Posterior standard deviation of N̂ at ``points``, or None (see :meth:`Estimate.band`)."""
        return self.estimate.band(block, points)

    def simulate(self, u: object, x0: Optional[List[float]] = None) -> Dict[str, np.ndarray]:
        """y from u with the estimated maps in the loop (see :meth:`Estimate.simulate`)."""
        return self.estimate.simulate(u, x0)

    def predict(self, u: object, y: object, horizon: int = 1, **kw: Any) -> Prediction:
        """k-step-ahead prediction (see :meth:`Estimate.predict`)."""
        return self.estimate.predict(u, y, horizon, **kw)

    def validate(self, u: object, y: object, **kw: Any) -> Union[Validation, RecordsValidation]:
        """Validation on a record, or on several given as lists of arrays (see
        :meth:`Estimate.validate`)."""
        return self.estimate.validate(u, y, **kw)

    def save(self, directory: Union[str, os.PathLike]) -> None:
        """Writes the tool's result files into ``directory``: estimate.json, estimate.csv (ŵ by
        block, then ê), report.json and model.toml; ``structid validate --estimate
        DIR/estimate.json`` and ``structid predict`` read them, :func:`load` reads them back."""
        names = list(self.w_names)
        prefix = "e_hat" if any(f"e{i}" in names for i in range(self.e_hat.shape[1])) else "e"
        names += [f"{prefix}{i}" for i in range(self.e_hat.shape[1])]
        columns = [np.ascontiguousarray(c) for c in np.hstack([self.w_hat, self.e_hat]).T]
        _structid.write_result(os.fspath(directory), self.estimate._native,
                               json.dumps(self.report, indent=2) + "\n", names, columns,
                               self.model.to_toml())

    def __repr__(self) -> str:
        c = self.cost
        return (f"Fit(blocks={list(self.maps)}, beta={self.beta:.4g}, J={c['total']:.6g}, "
                f"noise={c['noise']:.6g}, solver={self.diagnostics.get('solver')!r})")


def _columns(model: Model, u: object, y: object, z: object, what: str) -> List[Tuple[str, np.ndarray]]:
    s = model.signals
    cols = named_columns(s["u"], u, f"{what}u") + named_columns(s["y"], y, f"{what}y")
    if s.get("z"):
        if z is None:
            raise _structid.StructidError(f"the model measures z ({s['z']}); give z")
        cols += named_columns(s["z"], z, f"{what}z")
    elif z is not None:
        raise _structid.StructidError("the model computes z from u and y; do not give z")
    return cols


def identify(model: Model, u: object, y: object, z: object = None, *,
             beta: Union[float, str] = 0.01, sigma: Union[None, float, str] = None,
             dispersion: Union[None, Dispersion, str, "_structid.Kernel", "_structid.FeatureMap",
                               Dict[str, Any]] = None,
             selection: Optional[str] = None,
             folds: int = 5, validation: Optional[Tuple[object, ...]] = None,
             solver: str = "auto", initial_state: str = "zero", bands: bool = True,
             tolerance: Optional[float] = None, max_iterations: Optional[int] = None,
             memory_limit_mib: Optional[int] = None) -> Fit:
    """Identifies the unknown maps of ``model`` from a record (``structid identify``).

    u, y (and z when the model measures it) are arrays with one row per sample (1-D for one
    channel), or lists of such arrays for several records (experiments), each with its own
    initial state and length: ``identify(model, [u1, u2], [y1, y2])``. ``beta`` is β or ``"auto"``; ``sigma`` is a kernel width for every block,
    ``"auto"`` or None (the model's). ``dispersion`` replaces every block's dispersion (e.g.
    ``"fourier"``, ``structid.total_variation()``), or is your own :class:`Kernel` or
    :class:`FeatureMap` (for every block, or ``{block name: kernel}`` for some). ``selection`` is ``"ml"``, ``"gcv"``,
    ``"cv"`` (``folds``) or ``"validation"`` (with ``validation=(u_val, y_val)``); by default
    marginal likelihood for quadratic dispersions, cross-validation for total variation.
    ``solver`` is ``auto``, ``exact``, ``features``, ``clarabel`` or ``admm``. Raises
    :class:`StructidError` with the library's message on bad input or failure.
    """
    kernels = _user_kernels(dispersion)
    if dispersion is not None and not kernels:
        model = model.with_dispersion(_dispersion(dispersion))
    beta_value = None if isinstance(beta, str) and beta == "auto" else beta
    if isinstance(beta, str) and beta != "auto":
        raise _structid.StructidError(f"beta `{beta}` is neither a number nor \"auto\"")
    sigma_auto = isinstance(sigma, str)
    if sigma_auto and sigma != "auto":
        raise _structid.StructidError(f"sigma `{sigma}` is neither a number nor \"auto\"")
    more = None
    if _is_records(u) or _is_records(y):
        # several records (MATLAB's multi-experiment data): each restarts from its own state
        zs = z if z is not None else [None] * len(u)
        if not (_is_records(u) and _is_records(y) and len(u) == len(y) == len(zs)):
            raise _structid.StructidError(
                "several records are lists of arrays of the same length for u, y (and z)")
        cols = _columns(model, u[0], y[0], zs[0], "record 1 ")
        more = [_columns(model, a, b, c, f"record {i + 2} ")
                for i, (a, b, c) in enumerate(zip(u[1:], y[1:], zs[1:]))]
    else:
        cols = _columns(model, u, y, z, "")
    val = None
    if validation is not None:
        val = _columns(model, *(list(validation) + [None] * (3 - len(validation))), "validation ")
    out = _structid.identify_columns(
        model._native, cols, None if beta_value is None else float(beta_value),
        None if sigma is None or sigma_auto else float(sigma), sigma_auto, selection, int(folds),
        val, solver, initial_state, bool(bands), tolerance, max_iterations, memory_limit_mib,
        more, kernels)
    return _fit(model, out)


def _user_kernels(dispersion: object) -> List[Tuple[Optional[str], Any]]:
    """(block or None for every block, kernel) for user kernels and feature maps; empty for a
    built-in dispersion."""
    user = (_structid.Kernel, _structid.FeatureMap)
    if isinstance(dispersion, user):
        return [(None, dispersion)]
    if isinstance(dispersion, dict) and "kind" not in dispersion:
        return [(str(block), k) for block, k in dispersion.items()]
    return []


def _is_records(x: object) -> bool:
    """A list or tuple of numpy arrays: several records."""
    return is_records(x)


def _fit(model: Model, out: Dict[str, Any]) -> Fit:
    report = json.loads(out["report"])
    estimate = Estimate(out["estimate"])
    blocks = {b["output"]: b["name"] for b in model.blocks}
    w_names = [blocks.get(c, f"w{c}") for c in range(out["w_hat"].shape[1])]
    maps = {}
    for m in out["maps"]:
        m["w_hat"] = out["w_hat"][:, m.pop("output")]
        maps[m["name"]] = MapEstimate(**m)
    return Fit(estimate=estimate, model=model, w_hat=out["w_hat"], e_hat=out["e_hat"],
               w_names=w_names, beta=out["beta"], sigma=out["sigma"], maps=maps, report=report,
               widths=list(out.get("widths") or []), noise_variance=out.get("noise_variance"))


def load(directory: Union[str, os.PathLike], kernels: Sequence[Any] = ()) -> Fit:
    """Reads a result directory written by :meth:`Fit.save` or by ``structid identify --out``:
    the estimate, ŵ and ê (estimate.csv), report.json and the model (model.toml, else the
    report's model file). Maps are evaluated on the grid of the report's z ranges; the
    samples' z and the bands are not kept in the files (``z`` is empty, ``std`` is None).
    A fit made with your own :class:`Kernel` or :class:`FeatureMap` stores its name only:
    pass the same objects in ``kernels``."""
    d = os.fspath(directory)
    estimate = Estimate.from_file(os.path.join(d, "estimate.json"), kernels)
    with open(os.path.join(d, "report.json"), encoding="utf-8") as f:
        report = json.load(f)
    model_path = os.path.join(d, "model.toml")
    if not os.path.exists(model_path):
        # A directory of `structid identify`: the model file it was run with.
        model_path = (report.get("reproduction") or {}).get("model_file_absolute") \
            or report.get("model_file") or model_path
    model = Model.from_file(model_path)
    cols = _structid.read_columns(os.path.join(d, "estimate.csv"))
    blocks = {b["output"]: b["name"] for b in model.blocks}
    n_w = model.dims["w"]
    w_names = [blocks.get(c, f"w{c}") for c in range(n_w)]
    names = list(cols)
    w_hat = np.column_stack([cols[n] for n in names[:n_w]]) if n_w else np.zeros((0, 0))
    e_hat = np.column_stack([cols[n] for n in names[n_w:]])
    maps = {}
    for b in report["blocks"]:
        ranges = b["z_range"]
        if len(ranges) == 1:
            grid = np.linspace(ranges[0][0], ranges[0][1], 201)[:, None]
        elif len(ranges) == 2:
            xs = np.linspace(*ranges[0], 41)
            ys = np.linspace(*ranges[1], 41)
            grid = np.column_stack([np.tile(xs, 41), np.repeat(ys, 41)])
        else:
            grid = np.zeros((0, len(ranges)))
        w = w_hat[:, b["output"]] if w_hat.size else np.zeros(0)
        maps[b["name"]] = MapEstimate(
            name=b["name"], dispersion=b["dispersion"], z=np.zeros((0, len(ranges))), w_hat=w,
            grid=grid, value=estimate.evaluate(b["name"], grid) if len(grid) else np.zeros(0),
            std=None, dispersion_value=b["dispersion_value"])
    sel = report.get("selection") or {}
    return Fit(estimate=estimate, model=model, w_hat=w_hat, e_hat=e_hat, w_names=w_names,
               beta=report["settings"]["beta"], sigma=sel.get("sigma"), maps=maps,
               report=report)
