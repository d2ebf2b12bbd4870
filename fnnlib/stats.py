"""Comparisons over seeds (claim B2): when does one method beat another?"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import numpy as np


def _per_unit(a: np.ndarray, b: np.ndarray, units: Sequence[Hashable]) -> tuple[np.ndarray, np.ndarray]:
    """``a`` and ``b`` averaged within each unit id of ``units`` (one id per pair), in the order units first appear.

    Pairs that share an id are copies or replicates of one independent unit; each unit then counts once.
    """
    ids = list(units)
    if len(ids) != a.shape[0]:
        raise ValueError(f"units must give one id per pair: {len(ids)} ids for {a.shape[0]} pairs")
    order = list(dict.fromkeys(ids))
    index = np.array([order.index(u) for u in ids])
    count = np.bincount(index, minlength=len(order))
    return np.bincount(index, a) / count, np.bincount(index, b) / count


def paired_win(a: Sequence[float], b: Sequence[float], *, min_wins: int | None = None, level: float = 0.90,
               units: Sequence[Hashable] | None = None) -> dict:
    r"""Whether ``a`` beats ``b`` (lower is better) over paired runs, one pair per independent unit (seed).

    The rule: ``a`` wins when (i) ``a_s < b_s`` for at least ``min_wins`` of the S units (default: all
    but one, i.e. 4 of 5) and (ii) the two-sided ``level`` Student-t interval of the mean paired
    difference :math:`d_s = a_s - b_s` lies below 0 (excludes 0).

    ``units`` names the independent unit of each pair (e.g. ``(network, disturbance)``, or the disturbance
    when a model without a network flew it once). Pairs with the same id are one unit: their ``a`` and
    their ``b`` are averaged and S counts distinct ids, so copies of one flight never count as many.
    Without ``units`` every pair is its own unit.

    Returns a dict of plain values: ``win`` (bool), ``wins`` (count of units with a < b), ``seeds`` (S,
    the independent units), ``mean_diff``, ``ci_low``, ``ci_high`` (the interval of the mean difference),
    ``level``; with ``units``, also ``pairs`` (how many pairs were given).
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"a and b must be 1-D and paired (one value per seed), got shapes {a.shape}, {b.shape}")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("a and b must hold finite values")
    pairs = a.shape[0]
    if units is not None:
        a, b = _per_unit(a, b, units)
    S = a.shape[0]
    if S < 2:
        raise ValueError(f"a paired comparison needs at least 2 seeds (independent units), got {S}")
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    need = S - 1 if min_wins is None else int(min_wins)
    if not 1 <= need <= S:
        raise ValueError(f"min_wins must lie in 1..{S}, got {min_wins!r}")
    d = a - b
    mean = float(d.mean())
    sem = float(d.std(ddof=1) / np.sqrt(S))
    from scipy import stats  # noqa: PLC0415 (scipy.stats costs ~0.7 s of CPU to import; only this needs it)

    half = float(stats.t.ppf(0.5 + level / 2, S - 1)) * sem
    wins = int((d < 0).sum())
    out = {"win": bool(wins >= need and mean + half < 0), "wins": wins, "seeds": S, "mean_diff": mean,
           "ci_low": mean - half, "ci_high": mean + half, "level": level}
    return out if units is None else out | {"pairs": pairs}
