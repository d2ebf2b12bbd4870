"""Comparisons over seeds (claim B2): when does one method beat another?"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def paired_win(a: Sequence[float], b: Sequence[float], *, min_wins: int | None = None, level: float = 0.90) -> dict:
    r"""Whether ``a`` beats ``b`` (lower is better) over paired runs, one pair per seed.

    The rule: ``a`` wins when (i) ``a_s < b_s`` for at least ``min_wins`` of the S seeds (default: all
    but one, i.e. 4 of 5) and (ii) the two-sided ``level`` Student-t interval of the mean paired
    difference :math:`d_s = a_s - b_s` lies below 0 (excludes 0).

    Returns a dict of plain values: ``win`` (bool), ``wins`` (count of seeds with a < b), ``seeds``,
    ``mean_diff``, ``ci_low``, ``ci_high`` (the interval of the mean difference), ``level``.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"a and b must be 1-D and paired (one value per seed), got shapes {a.shape}, {b.shape}")
    S = a.shape[0]
    if S < 2:
        raise ValueError(f"a paired comparison needs at least 2 seeds, got {S}")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("a and b must hold finite values")
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
    return {"win": bool(wins >= need and mean + half < 0), "wins": wins, "seeds": S, "mean_diff": mean,
            "ci_low": mean - half, "ci_high": mean + half, "level": level}
