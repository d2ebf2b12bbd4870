"""Comparisons shared by the claim rules: one value per seed (paired, B2) or a single run."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fnnlib.stats import paired_win

Value = float | Sequence[float]


def per_seed(value: Value) -> np.ndarray:
    """``value`` as a 1-D float array (one entry per seed; a single run gives one entry).

    Raises
    ------
    ValueError
        If it is empty, not 0-D or 1-D, or holds a non-finite value.
    """
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"expected one number or one number per seed, got shape {np.shape(value)}")
    if not np.isfinite(arr).all():
        raise ValueError(f"non-finite measured value(s): {arr.tolist()}")
    return arr


def beats(a: Value, b: Value) -> bool:
    """``a`` beats ``b`` (lower is better).

    Over seeds (two or more paired values): :func:`fnnlib.stats.paired_win`, i.e. ``a < b`` in at
    least S-1 of the S seeds and the 90 % Student-t interval of the mean paired difference below 0.
    One run: ``a < b``.
    """
    a_s, b_s = per_seed(a), per_seed(b)
    if a_s.size == 1 and b_s.size == 1:
        return bool(a_s[0] < b_s[0])
    shape = np.broadcast_shapes(a_s.shape, b_s.shape)  # a deterministic baseline pairs with every seed
    a_s, b_s = np.broadcast_to(a_s, shape), np.broadcast_to(b_s, shape)
    return paired_win(a_s, b_s)["win"]


def at_most(a: Value, bound: float) -> bool:
    """``a <= bound`` in every seed (one run: that run)."""
    return bool((per_seed(a) <= bound).all())


def seeds_note(*values: Value) -> str:
    """The words a rule adds about how many seeds it judged."""
    n = max(per_seed(v).size for v in values)
    return (f"; over {n} seeds: a wins when it is lower in >= {n - 1} of {n} seeds and the 90 % interval "
            "of the mean paired difference excludes 0" if n > 1 else "; one seed (single run)")


def most_seeds(flags: Any) -> bool:
    """A threshold check over seeds: true in at least S-1 of the S seeds (a single run: true in it)."""
    f = np.atleast_1d(np.asarray(flags, dtype=bool))
    if f.ndim != 1 or f.size == 0:
        raise ValueError(f"expected one flag per seed, got shape {np.shape(flags)}")
    return bool(f.sum() >= max(1, f.size - 1))


def every_seed(flags: Any) -> bool:
    """A guarantee over seeds: true in every seed."""
    f = np.atleast_1d(np.asarray(flags, dtype=bool))
    if f.ndim != 1 or f.size == 0:
        raise ValueError(f"expected one flag per seed, got shape {np.shape(flags)}")
    return bool(f.all())
