"""Shaping numpy inputs for the native module: every signal is L × channels, float64."""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from ._structid import StructidError


def as_signal(x: object, what: str, channels: Optional[int] = None) -> np.ndarray:
    """``x`` as a C-contiguous float64 array of shape (L, channels); a 1-D array is one channel."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise StructidError(f"{what} is not an array of numbers: {e}") from None
    if a.ndim == 0:
        raise StructidError(f"{what} is a scalar; give one value per sample")
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2:
        raise StructidError(f"{what} has {a.ndim} dimensions; give L samples × channels")
    if channels is not None and a.shape[1] != channels:
        raise StructidError(f"{what} has {a.shape[1]} channel(s) but the model has {channels}")
    return np.ascontiguousarray(a)


def named_columns(names: Sequence[str], x: object, what: str) -> list:
    """One (name, column) pair per channel of ``x``, named as the model's signals."""
    a = as_signal(x, what, len(names))
    return [(n, np.ascontiguousarray(a[:, i])) for i, n in enumerate(names)]


def is_records(x: object) -> bool:
    """A list or tuple of numpy arrays: several records (a list of numbers, or of lists, is
    one signal)."""
    return isinstance(x, (list, tuple)) and len(x) > 0 and all(
        isinstance(r, np.ndarray) for r in x)


def records_of(u: object, y: object, what: str = "") -> Optional[list]:
    """``[(u1, y1), (u2, y2), …]`` when u and y are lists of arrays (several records), None
    when they are one record each; a mix is refused."""
    if not (is_records(u) or is_records(y)):
        return None
    if not (is_records(u) and is_records(y) and len(u) == len(y)):
        raise StructidError(
            f"several {what}records are lists of arrays of the same length for u and y")
    return list(zip(u, y))
