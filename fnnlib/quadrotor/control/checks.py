"""Checks on the plain-number inputs of the reference trajectories (NumPy, float64).

Shared by :mod:`fnnlib.quadrotor.control.min_snap` and :mod:`fnnlib.quadrotor.control.lissajous`; each refuses bad input
with a message that names the argument.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FloatArray", "as_float_array", "check_finite_real", "check_int", "check_positive"]

FloatArray = NDArray[np.float64]


def check_int(value: object, *, name: str, minimum: int) -> int:
    """``value`` as an int, refusing non-integers and values below ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def check_positive(value: object, *, name: str) -> float:
    """``value`` as a float, refusing non-reals, NaN/inf and values <= 0."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not (v > 0.0 and math.isfinite(v)):
        raise ValueError(f"{name} must be a finite positive number, got {value!r}")
    return v


def check_finite_real(value: object, *, name: str) -> float:
    """``value`` as a float, refusing non-reals and NaN/inf."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def as_float_array(x: ArrayLike, *, name: str, ndim: int) -> FloatArray:
    """``x`` as a float64 array with ``ndim`` axes, refusing non-real, ragged or non-finite input."""
    try:
        arr = np.asarray(x)
    except Exception as exc:  # ragged lists and the like
        raise TypeError(f"{name} must be array-like of real numbers: {exc}") from exc
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if np.iscomplexobj(arr):
        raise TypeError(f"{name} must be real, got dtype {arr.dtype}")
    if arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} axes, got shape {arr.shape}")
    arr = arr.astype(np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        kind = "NaN" if np.isnan(arr).any() else "infinite"
        raise ValueError(f"{name} holds a {kind} value (first at index {idx})")
    return arr

