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
