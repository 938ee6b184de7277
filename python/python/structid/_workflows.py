"""Refinement of the linear part and discovery of a missing effect."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _structid
from ._arrays import as_signal, records_of
from ._estimate import Estimate
from ._identify import Fit, _columns, _fit, _is_records
from ._model import Model


@dataclass
class Refinement:
    """The result of :func:`refine`: the refined model (new linear part) and its fit."""

    model: Model
    """The model with the refined linear part (``structid refine``'s model.toml)."""
    fit: Fit
    iterations: List[Dict[str, Any]]
    """Per iteration: cost after the maps, after the linear part, estimation and validation RMS."""
    best: int
    stop_reason: str


def _checked_beta_and_validation(model: Model, beta: object,
                                 validation: Optional[Tuple[object, object]]) -> object:
    """Checks that ``beta`` is a number or ``"auto"``, and returns the validation records'
    columns (``None`` without validation)."""
    if isinstance(beta, str) and beta != "auto":
        raise _structid.StructidError(f"beta `{beta}` is neither a number nor \"auto\"")
    if validation is None:
        return None
    if len(validation) != 2:
        raise _structid.StructidError("validation is a pair (u_val, y_val)")
    return _records_columns(model, validation[0], validation[1], "validation ")


def refine(model: Model, u: object, y: object, *, validation: Optional[Tuple[object, object]] = None,
           beta: Union[float, str] = "auto", sigma: Union[None, float, str] = None,
           selection: str = "ml", iterations: int = 10, tolerance: float = 1e-3, settle: int = 0,
           initial_state: str = "zero", bands: bool = True) -> Refinement:
    """Refines an uncertain linear part (``structid refine``): alternates between identifying
    the map with G fixed and re-estimating G (output error) with the map fixed, and stops when
    the validation simulation error (``validation=(u_val, y_val)``, else the estimation one)
    stops improving. ``model`` is a one-map structure (:meth:`Model.hammerstein`, …), or an
    LFT whose one map sits where such a structure puts it (the refined model is then written
    with a ``[linear]`` section).

    u and y may be lists of arrays for several records (``refine(model, [u1, u2], [y1, y2])``,
    ``structid refine --data a.csv --data b.csv``): both steps restart at every record, each
    simulated from rest (or from its own estimated initial state with
    ``initial_state="estimate"``). ``validation`` may likewise be ``([u1, u2], [y1, y2])``:
    each validation record is simulated from rest, its first ``settle`` samples not scored,
    and the squared errors are pooled."""
    sigma_auto = isinstance(sigma, str)
    if sigma_auto and sigma != "auto":
        raise _structid.StructidError(f"sigma `{sigma}` is neither a number nor \"auto\"")
    val = _checked_beta_and_validation(model, beta, validation)
    out = _structid.refine_columns(
        model._native, _records_columns(model, u, y, ""), val,
        None if isinstance(beta, str) else float(beta),
        None if sigma is None or sigma_auto else float(sigma), sigma_auto, selection,
        int(iterations), float(tolerance), int(settle), initial_state, bool(bands))
    refined = Model(out.pop("model"))
    fit = _fit(refined, out)
    r = fit.report["refinement"]
    return Refinement(model=refined, fit=fit, iterations=r["iterations"], best=r["best"],
                      stop_reason=r["stop_reason"])


@dataclass
class JointRefinement:
    """The result of :func:`refine_joint`: the model fitted as a whole by its simulation error."""

    model: Model
    """The fitted model (``structid refine --joint``'s model.toml): G with its fitted free
    entries, each static map as a table of its values, each operator with its parameters."""
    beta: float
    trials: List[Tuple[float, List[float]]]
    """Each β tried with its validation RMS per output (empty when β was given)."""
    cost: float
    """The criterion Σ|y − ŷ|² + L·Σβ·D at the end (never above ``initial_cost``)."""
    initial_cost: float
    rms: List[float]
    """Simulation RMS per output on the estimation records."""
    initial_states: List[List[float]]
    """Each record's fitted initial state (the LFT's states, then each operator's memory)."""
    free: List[Tuple[str, int, int, float]]
    """Each free entry of G: matrix, row, column, fitted value."""
    stages: List[Tuple[str, int, List[float], str]]
    """Each stage: name, segments, its cost after each accepted step, how it ended."""


def refine_joint(model: Model, u: object, y: object, *, validation: Optional[Tuple[object, object]] = None,
                 beta: Union[float, str] = "auto", free: Sequence[str] = (), centres: int = 15,
                 segment_length: Optional[int] = None, iterations: int = 100,
                 initial_state: str = "zero",
                 out: Optional[Union[str, os.PathLike]] = None,
                 windows: Optional[Tuple[int, int]] = None) -> JointRefinement:
    """Fits the whole model at once by its simulation error (``structid refine --joint``):
    the entries of G named in ``free`` (``"A"`` for every non-zero entry of A, ``"Bw[1][0]"``
    for one), every static map as a Gaussian kernel expansion (or, when its ``truth`` declares
    ``parameters``, that parametric family's parameters), every hysteresis operator's
    parameters and each record's initial state, by Levenberg–Marquardt (multiple shooting
    with ``segment_length``). It takes maps in series, maps of unmeasured states and
    operators. ``beta`` is a number, or ``"auto"`` with ``validation=(u_val, y_val)``: the
    best of 10⁻¹⁰ … 10⁻² by the validation simulation RMS. ``initial_state`` is ``"zero"``
    (each record starts at rest) or ``"estimate"`` (fitted). ``windows=(LENGTH, INIT)`` fits by
    the score of a simulation in windows of LENGTH samples, each from a state fitted to its
    first half and scored after its first INIT samples (``--windows``; plants with
    integrators), instead of by shooting. ``out`` writes the CLI's output directory
    (model.toml, the map tables, joint.json)."""
    val = _checked_beta_and_validation(model, beta, validation)
    o = _structid.refine_joint_columns(
        model._native, _records_columns(model, u, y, ""), val,
        None if isinstance(beta, str) else float(beta), [str(f) for f in free], int(centres),
        None if segment_length is None else int(segment_length), int(iterations), initial_state,
        None if out is None else os.fspath(out), _windows(windows))
    return JointRefinement(**_joint_fields(o))


def _windows(windows: Optional[Tuple[int, int]]) -> Optional[Tuple[int, int]]:
    """``(LENGTH, INIT)`` as whole numbers, or ``None``."""
    if windows is None:
        return None
    if len(windows) != 2:
        raise _structid.StructidError("windows is a pair (LENGTH, INIT)")
    return (int(windows[0]), int(windows[1]))


def _joint_fields(o: Dict[str, Any]) -> Dict[str, Any]:
    """The fields of :class:`JointRefinement` from the native result ``o``."""
    keys = ("beta", "trials", "cost", "initial_cost", "rms", "initial_states", "free", "stages")
    return dict(model=Model(o["model"]), **{k: o[k] for k in keys})


@dataclass
class BlockStructured(JointRefinement):
    """The result of :func:`wiener_hammerstein` (y = G₂·N(G₁·u) + e) and
    :func:`hammerstein_wiener` (y = N₂(G·N₁(u)) + e), every block fitted: the fields of
    :class:`JointRefinement` (``model`` is the LTI block(s) in one LFT, each map as a table of
    its values, ``N``; or ``input`` and ``output``), and the two below."""

    bla: Tuple[List[float], List[float]] = ((), ())
    """The best linear approximation (num, den) in q⁻¹."""
    divisions: List[Dict[str, Any]] = field(default_factory=list)
    """Wiener–Hammerstein: every division of its poles and zeros, best first: ``front`` and
    ``back`` as (num, den), and ``rms``, the error left by a map fitted behind it. Empty for
    Hammerstein–Wiener."""


def _block_structured(structure: str, u: object, y: object, orders: Tuple[int, int, int],
                      validation: Optional[Tuple[object, object]], beta: Optional[float],
                      centres: int, segment_length: Optional[int], iterations: int,
                      initial_state: str, out: Optional[Union[str, os.PathLike]],
                      windows: Optional[Tuple[int, int]]) -> BlockStructured:
    def pairs(a: object, b: object, what: str) -> List[Tuple[List[float], List[float]]]:
        recs = records_of(a, b, what) or [(a, b)]
        return [(as_signal(ua, f"{what}u", 1)[:, 0].tolist(), as_signal(ya, f"{what}y", 1)[:, 0].tolist())
                for ua, ya in recs]
    val = None
    if validation is not None:
        if len(validation) != 2:
            raise _structid.StructidError("validation is a pair (u_val, y_val)")
        val = pairs(validation[0], validation[1], "validation ")
    if len(orders) != 3:
        raise _structid.StructidError("orders are three whole numbers (NA, NB, NK)")
    o = _structid.wiener_hammerstein_records(
        pairs(u, y, ""), tuple(int(v) for v in orders), val,
        None if beta is None else float(beta), int(centres),
        None if segment_length is None else int(segment_length), int(iterations), initial_state,
        None if out is None else os.fspath(out), structure, _windows(windows))
    divisions = [{"front": (fn, fd), "back": (bn, bd), "rms": r}
                 for fn, fd, bn, bd, r in o["divisions"]]
    return BlockStructured(bla=o["bla"], divisions=divisions, **_joint_fields(o))


def _block_structured_fit(structure: str, doc: str) -> Any:
    """The public function of one block structure: its options, and its docstring ``doc``."""
    def fit(u: object, y: object, orders: Tuple[int, int, int], *,
            validation: Optional[Tuple[object, object]] = None,
            beta: Optional[float] = None, centres: int = 15,
            segment_length: Optional[int] = None, iterations: int = 100,
            initial_state: str = "zero",
            out: Optional[Union[str, os.PathLike]] = None,
            windows: Optional[Tuple[int, int]] = None) -> BlockStructured:
        return _block_structured(structure, u, y, orders, validation, beta, centres,
                                 segment_length, iterations, initial_state, out, windows)
    fit.__name__ = fit.__qualname__ = structure.replace("-", "_")
    fit.__doc__ = doc
    return fit


wiener_hammerstein = _block_structured_fit("wiener-hammerstein", """A Wiener–Hammerstein
    model with both LTI blocks unknown (``structid wiener-hammerstein``): the best linear
    approximation of ``orders`` = (NA, NB, NK) (both blocks together), every division of its
    poles and zeros scored by a map fitted behind it, then both blocks, the map and the initial
    states fitted from the best by simulation error. ``beta`` defaults to 10⁻⁸, or is chosen
    from 10⁻¹⁰ … 10⁻² on ``validation=(u_val, y_val)``; ``windows`` as in
    :func:`refine_joint`. u and y are 1-D arrays, or lists of them for several records.""")

hammerstein_wiener = _block_structured_fit("hammerstein-wiener", """A Hammerstein–Wiener
    model y = N₂(G·N₁(u)) + e with G and both maps unknown (``structid hammerstein-wiener``,
    MATLAB's ``nlhw``): G starts as the best linear approximation of ``orders`` = (NA, NB,
    NK), both maps as the identity, then everything is fitted by simulation error. Options as
    :func:`wiener_hammerstein`.""")


def _records_columns(model: Model, u: object, y: object, what: str) -> List[Any]:
    """The named columns of each record: one record, or lists of arrays for several."""
    records = records_of(u, y, what)
    if records is None:
        return [_columns(model, u, y, None, what)]
    return [_columns(model, a, b, None, f"{what}record {i + 1} ")
            for i, (a, b) in enumerate(records)]


@dataclass
class Finding:
    """The effect discovery found: where, which, and the augmented model."""

    location: str
    description: str
    effect: str
    """The named family in the physics of its site (e.g. ``actuator saturation``, ``sensor
    quantisation``, ``softening spring (saturation of y)``, ``Coulomb + viscous friction``),
    ``unnamed static effect``, ``dynamic: …`` or ``time-varying: …``."""
    estimator: str
    nonparametric_rms: float
    validation_rms: float
    """Validation simulation RMS of the augmented model."""
    remarks: List[str]
    shrink: float
    z: np.ndarray
    """The estimated map's curve: its input …"""
    w: np.ndarray
    """… and its value."""
    estimate: Estimate
    """The augmented model as a fitted model (simulate, predict, validate)."""
    augmented: Optional[Model]
    """The augmented model file (None when its map is a table)."""
    input_hysteresis: Optional[Dict[str, Any]] = None
    """A dynamic finding's hysteresis at the input fitted with G (w = u + λ·s, s a stop
    operator of threshold c): ``threshold``, ``weight`` (λ), ``play`` (λ near −1, a
    backlash), ``description``, ``validation_rms`` and ``without_hysteresis_rms``; None when
    none was fitted or it did not explain the gap."""
    time_varying: bool = False
    """Whether the effect changes over the estimation record (the family's parameters, or a
    gain in series with the model, re-estimated on consecutive segments, follow a trend larger
    than their scatter allows)."""
    stationarity: Optional[str] = None
    """That test in one sentence (None when none was made)."""
    poor_model: bool = False
    """Whether the augmented model is still a poor model: on the validation record it explains
    less than half of the output's variance and misses it by more than the noise."""
    table: List[Dict[str, Any]] = field(default_factory=list)
    """The candidate table at the finding's location, one dict per row: ``label``,
    ``parameters``, ``validation_rms``, ``eligible``, ``p_worse_than_best`` (the
    p-value of the paired block test against the best row), ``as_good`` and ``chosen``."""


@dataclass
class Discovery:
    """The result of :func:`discover`."""

    verdict: str
    verdict_kind: str
    """``no-missing-effect``, ``missing-effect``, ``unexplained`` or ``linear-model`` (the
    linear model was wrong), as report.json spells it."""
    missing_effect: bool
    nominal_validation_rms: float
    nominal_estimation_rms: float
    hypotheses: List[Dict[str, Any]]
    """Per candidate location: dispersion, β, σ, estimation and validation RMS, failure."""
    finding: Optional[Finding]
    linear_rival: Optional[Dict[str, Any]]
    """G alone re-estimated with one more mode, the linear model a finding must beat (None
    when it was not fitted): ``num``, ``den``, ``validation_rms``, ``p_worse`` (from the
    paired test of the finding against it: the finding is better at α when ``1 − p_worse``
    < α; None when there was no finding or it could not be tested) and ``explains`` (it
    closes the gap: the verdict is ``linear-model``)."""
    seconds: float
    extra: Dict[str, Any]


def _discovery(out: Dict[str, Any]) -> Discovery:
    finding = out.pop("finding")
    if finding is not None:
        est = Estimate(finding.pop("estimate"))
        aug = finding.pop("augmented")
        finding = Finding(estimate=est, augmented=None if aug is None else Model(aug), **finding)
    keys = ("verdict", "verdict_kind", "missing_effect", "nominal_validation_rms",
            "nominal_estimation_rms", "hypotheses", "linear_rival", "seconds")
    core = {k: out.pop(k) for k in keys}
    return Discovery(finding=finding, extra=out, **core)


def discover(nominal: Model, u: object, y: object, u_val: object, y_val: object, *,
             total_variation: bool = True, settle: int = 0, tune_sigma: bool = False,
             significance: float = 0.05, effects: int = 1,
             locations: Optional[List[str]] = None, scoring: str = "auto",
             keep_nominal: bool = False, sigma_fraction: Optional[float] = None,
             trend: Optional[int] = None,
             hysteresis_threshold: Optional[float] = None) -> Discovery:
    """Finds what a nominal linear model (``Model.structure("lti", ...)``, an ``[lft]``
    without maps, or a model whose every map has a known ``truth``, such as an earlier
    discovery's augmented model) is missing (``structid discover``): tests its residual,
    inserts one unknown map at each candidate location, ranks them on the validation record
    and names the map.

    Each of u, y, u_val, y_val is an array, or a list of arrays for several records
    (experiments, each simulated from its own initial state):
    ``discover(nominal, [u1, u2], [y1, y2], [u3, u4], [y3, y4])``. The validation RMS is then
    pooled over the validation records; ``extra`` holds each record's
    (``nominal_validation_rms_records``, ``validation_rms_records``).

    ``significance`` is the level α of the candidate table's rule: the simplest row that a
    paired test of the validation errors over blocks does not call worse than the best at α
    is chosen (``Finding.table``). The other keywords are the options of ``structid
    discover``: ``effects`` (up to N effects, one at a time; the result is the last adopted
    step's, ``extra["steps"]`` lists every step, with the second-block row that re-estimated
    its map when one did and, in ``dynamic_verdict``, the dynamic verdict a static reading
    replaced, and ``extra["stop"]`` why it stopped),
    ``locations`` (e.g. ``["input", "output-feedback"]``), ``scoring`` (``"auto"``,
    ``"free"`` or ``"LENGTH:INIT"``), ``keep_nominal``, ``sigma_fraction``, ``trend`` and
    ``hysteresis_threshold`` (None: the defaults)."""
    est, more = _record_columns(nominal, u, y, "")
    val, more_val = _record_columns(nominal, u_val, y_val, "validation ")
    return _discovery(_structid.discover_columns(
        nominal._native, est, val, bool(total_variation), int(settle), bool(tune_sigma),
        more, more_val, float(significance), int(effects),
        None if locations is None else [str(l) for l in locations], str(scoring),
        bool(keep_nominal), sigma_fraction, trend, hysteresis_threshold))


def _record_columns(model: Model, u: object, y: object, what: str):
    """The columns of one record (u, y arrays), or of the first of several records (lists of
    arrays) and those of the others."""
    if not (_is_records(u) or _is_records(y)):
        return _columns(model, u, y, None, what), None
    if not (_is_records(u) and _is_records(y) and len(u) == len(y)):
        raise _structid.StructidError(
            f"several {what}records are lists of arrays of the same length for u and y")
    cols = [_columns(model, a, b, None, f"{what}record {i + 1} ")
            for i, (a, b) in enumerate(zip(u, y))]
    return cols[0], cols[1:]


def silverbox_data(path: Union[None, str, os.PathLike] = None) -> str:
    """The Silverbox file ``SNLS80mV.csv``: ``path`` if given, else ``$STRUCTID_DATA/silverbox/``,
    else ``../shared/data/silverbox/`` beside the repository (as the project's tests find it)."""
    if path is not None:
        return os.fspath(path)
    base = os.environ.get("STRUCTID_DATA")
    if not base:
        here = os.path.dirname(os.path.abspath(__file__))
        for up in (os.path.join(here, ".."), os.getcwd()):
            repo = os.path.abspath(up)
            while repo != os.path.dirname(repo):
                if os.path.isfile(os.path.join(repo, "Cargo.lock")) and os.path.isdir(os.path.join(repo, "crates")):
                    break
                repo = os.path.dirname(repo)
            candidate = os.path.join(repo, "..", "shared", "data")
            if os.path.isdir(candidate):
                base = candidate
                break
    if not base:
        raise _structid.StructidError(
            "the Silverbox data were not found: give the path of SNLS80mV.csv or set STRUCTID_DATA "
            "to the directory holding silverbox/")
    return os.path.normpath(os.path.join(base, "silverbox", "SNLS80mV.csv"))


def silverbox_discovery(path: Union[None, str, os.PathLike] = None, order: int = 2,
                        validation_fraction: float = 0.2) -> Discovery:
    """The discovery workflow on the Silverbox benchmark: the BLA of ``order`` on the first
    part of the estimation split, discovery with the rest as validation, the test splits
    simulated with both. ``extra`` holds ``bla_num``, ``bla_den`` and the ``tests`` (RMS per
    split, measured and simulated outputs)."""
    return _discovery(_structid.silverbox_discovery(silverbox_data(path), int(order),
                                                    float(validation_fraction)))
