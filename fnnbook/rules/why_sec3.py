"""The Sec. 3 claims' own rules at one point of a why grid (:mod:`fnnbook.why`).

Each function applies a rule of :mod:`fnnbook.rules.sec3` unchanged to the numbers of one grid point (one
noise level, one residual level) and says whether the claim holds there; none adds a criterion of its own.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from fnnbook.rules import sec3
from fnnbook.results import ClaimResult
from fnnlib.stability import reconvergence_rows, theorem1_balls

__all__ = ["holds", "s3_point", "s5_point", "s8_levels", "s10_point"]


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


def s5_point(*, L: float, gamma: Any, x_feedback: Any, f_feedback: Any, x_continuous: Any, f_continuous: Any,
             limit_x: Any, L_sweep: Sequence[float], after_transient: Any, last_half: Any,
             conservative_ratio: float) -> tuple[ClaimResult, np.ndarray]:
    r"""S5 (Theorem 1, Fig. S1) on one test spiral: :func:`sec3.s5` unchanged, and the ratio ball / limit of
    :math:`\|\tilde x\|` per seed.

    Tensors, one row per seed: ``gamma`` (S,) Assumption 1's bound along the run; ``x_feedback``, ``f_feedback``,
    ``x_continuous``, ``f_continuous`` (S, T) the norms of :math:`\tilde x` and :math:`\tilde f` of the feedback
    network (Eqs. (7)-(8)) and of Theorem 1's continuous observer; ``limit_x`` (S, G) the largest
    :math:`\|\tilde x\|` over the last half at each gain of ``L_sweep``. ``after_transient`` and ``last_half``:
    (T,) masks of the times the balls and the measured limit are read over. The balls are Theorem 1's at the
    gain ``L`` (:func:`fnnlib.stability.theorem1_balls`) with each seed's ``gamma``.
    """
    bx, bf = (np.array(v) for v in zip(*(theorem1_balls(L, float(g), 2) for g in gamma)))
    rx, rf = bx / x_feedback[:, last_half].amax(-1).numpy(), bf / f_feedback[:, last_half].amax(-1).numpy()
    r = sec3.s5(ball_x=bx, ball_f=bf, feedback_x=x_feedback[:, after_transient].amax(-1),
                feedback_f=f_feedback[:, after_transient].amax(-1), continuous_x=x_continuous[:, after_transient].amax(-1),
                continuous_f=f_continuous[:, after_transient].amax(-1), ratio_x=rx, ratio_f=rf, L_sweep=L_sweep,
                limit_x=limit_x.T, ball_x_sweep=gamma[None, :] / gamma.new_tensor(L_sweep)[:, None],
                conservative_ratio=conservative_ratio)
    return r, rx


def s10_point(*, errors: Mapping[str, tuple[Any, Any]], rate_err_neural_ode: Any, t: Any, t_switch: float,
              steady_window: float, band_factor: float, settle: float) -> ClaimResult:
    """S10 (Fig. S12) with the band ``band_factor`` x the steady level and the window ``settle`` s:
    :func:`sec3.s10` unchanged (strict reading) on the errors of one run of the switched spiral.

    ``errors``: ``"x"``, ``"f"``, ``"multistep"`` -> (times (T',), per-seed errors (S, T') as tensors): the
    observer error, the feedback's change-rate error (on ``t``) and the ``N``-step error indexed by the
    prediction's start. ``rate_err_neural_ode`` (S, T): the neural ODE's change-rate error on ``t``. Each error's
    band and re-convergence time are :func:`fnnlib.stability.reconvergence`'s over ``steady_window`` s.
    """
    parts = {}
    for k, (tt, err) in errors.items():
        rows = reconvergence_rows(tt, err, t_switch, window=steady_window, band_factor=band_factor)
        parts[k] = {"band": rows["band"], "peak": err[:, tt >= t_switch].amax(-1).tolist(), "time": rows["time"]}
    late = t >= t_switch + settle
    return sec3.s10(state=parts["x"], rate=parts["f"], multistep=parts["multistep"],
                    rate_err_after_feedback=errors["f"][1][:, late].mean(-1).tolist(),
                    rate_err_after_neural_ode=rate_err_neural_ode[:, late].mean(-1).tolist(), settle_threshold=settle)
