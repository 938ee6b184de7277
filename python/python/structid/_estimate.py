"""The fitted model on its own: simulate, predict, validate, evaluate its maps."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

from . import _structid
from ._arrays import as_signal, records_of


@dataclass(frozen=True)
class Prediction:
    """ŷ(t|t−k), the k-step-ahead prediction on a record (``structid predict``)."""

    horizon: int
    predicted: np.ndarray
    """ŷ, L × n_y."""
    rms: List[float]
    """Per output: RMS(y − ŷ) after the settling samples."""
    fit_percent: List[float]
    """Per output: 100·(1 − ‖y − ŷ‖/‖y − mean y‖)."""
    initial_state: Optional[List[float]]


@dataclass(frozen=True)
class Validation:
    """Simulation and one-step prediction errors with residual tests (``structid validate``)."""

    simulated: np.ndarray
    """y simulated from u alone with the maps in the loop, L × n_y."""
    rms: List[float]
    fit_percent: List[float]
    prediction_error: np.ndarray
    """One-step-ahead prediction errors (innovations), L × n_y."""
    prediction_rms: List[float]
    whiteness_passes: bool
    input_correlation_passes: bool
    whiteness: List[Dict[str, Any]]
    """Per output: lags, values, the 99 % bound, and the Ljung–Box statistic with its 1 % critical
    value of the autocorrelation of the errors."""
    input_correlation: List[List[Dict[str, Any]]]
    """[output][input]: the cross-correlation of the errors with u."""
    initial_state: Optional[List[float]]


@dataclass(frozen=True)
class RecordsValidation:
    """Validation on several records (``structid validate --data a.csv --data b.csv``): each
    record validated on its own, from its own initial state, and the free-run simulation error
    pooled over the samples each record's validation scored (after its settling samples)."""

    records: List[Validation]
    """Per record, its :class:`Validation`."""
    rms: List[float]
    """Per output: RMS(y − y_sim) over the scored samples of every record."""
    fit_percent: List[float]
    """Per output: 100·(1 − ‖y − y_sim‖/‖y − mean y‖) over the same samples (NaN for a
    constant output)."""
    samples: int
    """Scored samples of all records."""


class Estimate:
    """A fitted model (what ``estimate.json`` stores): the linear block with every estimated
    map. It simulates, predicts and validates without the estimation data; pickling keeps its
    JSON document (numbers bit for bit) and the user kernels it is built on. A fresh fit also
    computes bands at any point."""

    __slots__ = ("_native",)

    def __init__(self, native: "_structid.Estimate") -> None:
        self._native = native

    @classmethod
    def from_file(cls, path: Union[str, os.PathLike],
                  kernels: Sequence[Any] = ()) -> "Estimate":
        """Reads an estimate.json (of ``structid identify``, ``refine``, ``discover``).
        An estimate made with your own :class:`Kernel` or :class:`FeatureMap` stores only
        its name: pass the same objects in ``kernels``."""
        return cls(_structid.Estimate.from_file(os.fspath(path), list(kernels)))

    @classmethod
    def from_json(cls, text: str, kernels: Sequence[Any] = ()) -> "Estimate":
        """The estimate from its JSON document (with ``kernels`` as for :meth:`from_file`)."""
        return cls(_structid.Estimate.from_json(text, list(kernels)))

    def to_json(self) -> str:
        """The JSON document (estimate.json)."""
        return self._native.to_json()

    @property
    def blocks(self) -> List[Dict[str, Any]]:
        """The blocks: name, inputs, output, dispersion."""
        return self._native.blocks

    @property
    def provenance(self) -> Dict[str, Any]:
        """Workflow, settings, cost terms, solver and data fingerprint of the fit."""
        return json.loads(self._native.provenance)

    @property
    def initial_state(self) -> Optional[List[float]]:
        """x̂₀ on the estimation record, when estimated."""
        return self._native.initial_state

    @property
    def has_posterior(self) -> bool:
        """Whether :meth:`band` can compute bands (a fresh fit of a quadratic dispersion)."""
        return self._native.has_posterior

    def _points(self, block: str, points: object) -> np.ndarray:
        p = next((len(b["inputs"]) for b in self.blocks if b["name"] == block), None)
        a = as_signal(points, "points")
        if p is not None and p > 1 and a.shape[1] == 1 and a.shape[0] == p:
            a = a.T.copy()
        return a

    def evaluate(self, block: str, points: object) -> np.ndarray:
        """N̂ of ``block`` at ``points`` (a 1-D array for one input, N × p otherwise)."""
        return self._native.evaluate(block, self._points(block, points))

    def band(self, block: str, points: object) -> Optional[np.ndarray]:
        """Posterior standard deviation of N̂ at ``points`` (95 % band: N̂ ± 1.96·std), or None
        when the estimate has no posterior (total variation, a loaded or unpickled estimate)."""
        return self._native.band(block, self._points(block, points))

    def simulate(self, u: object, x0: Optional[List[float]] = None) -> Dict[str, np.ndarray]:
        """y from u alone with the maps in the loop (e = 0): ``{"y", "z", "w"}``."""
        return self._native.simulate(as_signal(u, "u"), x0)

    def predict(self, u: object, y: object, horizon: int = 1, initial_state: str = "zero",
                settle: int = 0) -> Prediction:
        """ŷ(t|t−k) with u up to t and y up to t−k (k = ``horizon``)."""
        d = self._native.predict(as_signal(u, "u"), as_signal(y, "y"), int(horizon),
                                 initial_state, int(settle))
        return Prediction(**d)

    def validate(self, u: object, y: object, initial_state: str = "zero", max_lag: int = 25,
                 settle: int = 0) -> Union[Validation, "RecordsValidation"]:
        """Simulation RMS and fit, one-step errors and their whiteness and input tests.

        With lists of arrays for u and y (several records, ``validate([u1, u2], [y1, y2])``)
        each record is validated on its own, from its own initial state, and the result is a
        :class:`RecordsValidation` that also pools the free-run simulation error over the
        records (``structid validate --data a.csv --data b.csv``)."""
        records = records_of(u, y)
        if records is not None:
            d = self._native.validate_records([as_signal(a, "u") for a, _ in records],
                                              [as_signal(b, "y") for _, b in records],
                                              initial_state, int(max_lag), int(settle))
            d["records"] = [_validation(r) for r in d["records"]]
            return RecordsValidation(**d)
        return _validation(self._native.validate(as_signal(u, "u"), as_signal(y, "y"),
                                                 initial_state, int(max_lag), int(settle)))

    def __getstate__(self) -> "_structid.Estimate":
        # The native estimate pickles as its JSON document and the user kernels it uses.
        return self._native

    def __setstate__(self, state: Any) -> None:
        self._native = (_structid.Estimate.from_json(state, [])
                        if isinstance(state, str) else state)

    def __repr__(self) -> str:
        return repr(self._native)


def _validation(d: Dict[str, Any]) -> Validation:
    """A :class:`Validation` from the native report (its tests as JSON text)."""
    d["whiteness"] = json.loads(d["whiteness"])
    d["input_correlation"] = json.loads(d["input_correlation"])
    return Validation(**d)
