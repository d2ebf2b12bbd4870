"""The Sec. 3 claims' own rules at one point of a why grid (:mod:`fnnbook.why`).

Each function applies a rule of :mod:`fnnbook.rules.sec3` unchanged to the numbers of one grid point (one
noise level, one residual level) and says whether the claim holds there; none adds a criterion of its own.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fnnbook.rules import sec3
from fnnlib.results import ClaimResult

__all__ = ["holds", "s3_point", "s8_levels"]


def holds(result: ClaimResult, check: str | None = None) -> bool:
    """Whether the claim holds: its verdict is *reproduced* (or, given ``check``, that one check is true)."""
    if check is None:
        return result.verdict == "reproduced"
    if check not in result.checks:
        raise KeyError(f"{result.id} has no check {check!r}; its checks: {', '.join(result.checks)}")
    return bool(result.checks[check])


def s3_point(*, noise_std: float, decay: Any, no_decay: Any, neural_ode: Any) -> ClaimResult:
    """S3 (Fig. 4g) judged at one noise level: :func:`sec3.s3` over ``[0, noise_std]``, ``judged_std = noise_std``.

    ``decay``, ``no_decay``, ``neural_ode``: mean ``N``-step errors, shape (2, S): the noise-free row, then the
    row at ``noise_std`` (one column per seed).
    """
    if not noise_std > 0:
        raise ValueError(f"S3 at a grid point: the noise level must be > 0, got {noise_std}")
    return sec3.s3(noise_std=[0.0, float(noise_std)], decay=decay, no_decay=no_decay, neural_ode=neural_ode,
                   judged_std=float(noise_std))


def s8_levels(*, rate_neural_ode: Any, rate_feedback: Any, err_N_neural_ode: Any, err_N_feedback: Any,
              offsets: Any) -> np.ndarray:
    """S8 (Fig. S9) level by level: :func:`sec3.s8` on each residual level alone, bool (levels,).

    Arguments as :func:`sec3.s8` (one row per level, one column per seed). Level ``j`` holds when the
    strict reading's two checks (change rate and ``N``-step error) hold on that level's row alone.
    """
    rows = [np.asarray(v, dtype=float) for v in (rate_neural_ode, rate_feedback, err_N_neural_ode, err_N_feedback)]
    off = np.asarray(offsets, dtype=float)
    if len({r.shape[0] for r in rows} | {off.shape[0]}) != 1:
        raise ValueError("S8 per level: one row per residual level for every metric and the offsets")
    out = []
    for j in range(off.shape[0]):
        r = sec3.s8(rate_neural_ode=rows[0][j:j + 1], rate_feedback=rows[1][j:j + 1],
                    err_N_neural_ode=rows[2][j:j + 1], err_N_feedback=rows[3][j:j + 1], offsets=off[j:j + 1])
        out.append(holds(r, "rate_better_at_all_1_levels") and holds(r, "multistep_better_at_all_1_levels"))
    return np.asarray(out, dtype=bool)
