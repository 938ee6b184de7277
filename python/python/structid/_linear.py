"""The linear part: fitting G by ARX or output error (``structid linear``), its Bode, step and
pole–zero responses, and reading data files (CSV, MAT v5, NumPy) by variable name."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _structid
from ._arrays import as_signal
from ._identify import _is_records
from ._model import Model
from ._structid import StructidError


def read_data(path: Union[str, os.PathLike], vars: Optional[str] = None) -> Dict[str, np.ndarray]:
    """The named columns of a data file, as ``structid identify --data FILE --vars VARS``
    reads it: CSV, MAT v5 (a v7.3/HDF5 file gets an error saying what to do) or NumPy
    ``.npy``/``.npz``. ``vars`` picks and names columns, e.g. ``"u=vir,y=qm"``,
    ``"y=data#1"`` (column 1 of the matrix ``data``) or ``"u,y"``; without it every column of
    a CSV file, or every vector of an array file, is returned under its own name."""
    return dict(_structid.read_columns(os.fspath(path), vars))


@dataclass
class Response:
    """The responses of one input of G: Bode magnitude and unwrapped phase (radians) at
    ``frequency`` (cycles per sample, 0 … 0.5; multiply by 1/T_s for Hz), the magnitude's
    standard deviation from the parameter covariance (the delta method, as MATLAB's ``bode``
    of an ``idpoly``) when known, the step response, and the poles and zeros (complex)."""

    frequency: np.ndarray
    magnitude: np.ndarray
    phase: np.ndarray
    magnitude_std: Optional[np.ndarray]
    step: np.ndarray
    poles: np.ndarray
    zeros: np.ndarray


def response(num: Union[Sequence[float], Sequence[Sequence[float]]], den: Sequence[float], *,
             frequencies: Union[int, Sequence[float]] = 256, steps: int = 200, input: int = 0,
             covariance: Optional[np.ndarray] = None,
             sample_time: Optional[float] = None) -> Response:
    """The :class:`Response` of G = num(q⁻¹)/den(q⁻¹) (``num`` one numerator or one per input;
    ``frequencies`` a count, spread logarithmically up to Nyquist, or normalised frequencies
    in cycles per sample)."""
    nums = [list(map(float, num))] if np.ndim(num) == 1 else [list(map(float, b)) for b in num]
    if isinstance(frequencies, (int, np.integer)):
        if frequencies < 2:
            raise StructidError("frequencies must be at least 2 points")
        f = np.logspace(-4, np.log10(0.5), int(frequencies))
    else:
        f = np.asarray(frequencies, dtype=np.float64).ravel()
    cov = None if covariance is None else np.asarray(covariance, dtype=np.float64).tolist()
    out = _structid.linear_response(nums, list(map(float, den)), f.tolist(), int(steps),
                                    int(input), cov, sample_time)
    complex_of = lambda pairs: np.array([complex(re, im) for re, im in pairs], dtype=complex)
    return Response(frequency=f, magnitude=out["magnitude"], phase=out["phase"],
                    magnitude_std=out["magnitude_std"], step=out["step"],
                    poles=complex_of(out["poles"]), zeros=complex_of(out["zeros"]))


@dataclass
class LinearFit:
    """G = B(q)/A(q) fitted by :func:`linear`: ``num`` (one numerator per input, leading zeros
    for the delay) and ``den`` in powers of q⁻¹, the orders (and how they were selected), the
    cost, the parameters' standard deviations
    and covariance, the simulation fit (%) of every record from rest, and ``model``, an LTI
    :class:`Model` (the text of ``structid linear -o``, in ``toml``) that serves as a nominal
    model for :func:`structid.discover` or as the start of :func:`structid.refine`."""

    num: List[np.ndarray]
    den: np.ndarray
    sample_time: Optional[float]
    method: str
    cost: float
    parameter_std: np.ndarray
    covariance: Optional[np.ndarray]
    iterations: int
    converged: bool
    warning: Optional[str]
    fit_percent: List[float]
    toml: str
    model: Model = field(repr=False)
    #: (na, nb per input, nk per input) as fitted.
    orders: Optional[Tuple[int, List[int], List[int]]] = None
    #: With selected orders: (criterion, number of candidates).
    selection: Optional[Tuple[str, int]] = None

    def response(self, **kw: Any) -> Response:
        """The :class:`Response` of this G with the magnitude's standard deviation from the
        fit's covariance (see :func:`response` for the keywords)."""
        kw.setdefault("covariance", self.covariance)
        return response(self.num, self.den, sample_time=self.sample_time, **kw)


def _record_arrays(u: object, y: object, label: str = "") -> Tuple[List[np.ndarray], List[np.ndarray]]:
    """One record or several as the lists of 2-D u and 1-D y arrays the bindings take."""
    us = list(u) if _is_records(u) else [u]
    ys = list(y) if _is_records(y) else [y]
    if len(us) != len(ys):
        raise StructidError(f"{len(us)} input records and {len(ys)} output records")
    name = lambda s, i: f"{label}{s}" if len(us) == 1 else f"{label}{s} of record {i}"
    ua = [as_signal(r, name("u", i)) for i, r in enumerate(us)]
    ya = []
    for i, r in enumerate(ys):
        a = as_signal(r, name("y", i))
        if a.shape[1] != 1:
            raise StructidError(f"y has {a.shape[1]} channels; a linear fit takes one output")
        ya.append(np.ascontiguousarray(a[:, 0]))
    return ua, ya


def linear(u: object, y: object, orders: Optional[Tuple[int, int, int]] = None, *,
           method: str = "oe", initial_state: str = "zero", integrators: int = 0,
           sample_time: Optional[float] = None, transient: int = 0,
           inputs: Optional[Sequence[str]] = None, output: str = "y", select: str = "bic",
           max_order: int = 6, delays: Tuple[int, int] = (1, 3),
           validation: Optional[Tuple[object, object]] = None, structure: str = "lti",
           map: str = "N", dispersion: str = "fourier", trend: Optional[int] = None,
           separate_numerator: bool = False) -> LinearFit:
    """Fits G = B(q)/A(q), as ``structid linear`` does (the same workflow and numbers).

    ``orders = (na, nb, nk)`` (denominator order, numerator length, input delay, as
    ``--orders NA,NB,NK``), or ``None`` to select them by ``select`` (``"aic"``, ``"bic"``,
    ``"fpe"``, or ``"validation"`` with ``validation=(u, y)``) over NA, NB ≤ ``max_order``
    and NK in ``delays``. ``method="oe"`` (output error, each record from rest, or from its
    estimated state with ``initial_state="estimate"``) or ``"arx"``; ``integrators`` poles
    held at z = 1 (0, 1 or 2; for a position driven by a force, say). ``structure``
    (``"lti"``, ``"output-feedback"``, ``"input"``) places a map named ``map`` with
    ``dispersion`` (and a polynomial ``trend``) in the model file, ready for
    :func:`structid.refine`. ``u`` and ``y`` are one record (arrays) or several (lists of
    arrays), as in :func:`structid.identify`."""
    ua, ya = _record_arrays(u, y)
    val = None
    if validation is not None:
        vu, vy = _record_arrays(validation[0], validation[1], "validation ")
        if len(vu) != 1:
            raise StructidError("validation takes one record (u, y)")
        val = (vu[0], vy[0])
    o = None if orders is None else [int(v) for v in orders]
    if o is not None and len(o) != 3:
        raise StructidError(f"orders has {len(o)} numbers; give three: (na, nb, nk)")
    out = _structid.linear_fit(ua, ya, o, method, initial_state, int(integrators), sample_time,
                               int(transient), None if inputs is None else list(inputs), output,
                               select, int(max_order), (int(delays[0]), int(delays[1])), val,
                               structure, map, dispersion,
                               None if trend is None else int(trend), bool(separate_numerator))
    cov = out["covariance"]
    na, nb, nk = out["orders"]
    return LinearFit(num=[np.asarray(b) for b in out["num"]], den=out["den"],
                     sample_time=out["sample_time"], method=method.lower(), cost=out["cost"],
                     parameter_std=out["parameter_std"],
                     covariance=None if cov is None else np.asarray(cov),
                     iterations=out["iterations"], converged=out["converged"],
                     warning=out["warning"], fit_percent=list(out["fit_percent"]),
                     toml=out["toml"], model=Model.from_toml(out["toml"]),
                     orders=(na, list(nb), list(nk)),
                     selection=None if out["selection"] is None else tuple(out["selection"]))

