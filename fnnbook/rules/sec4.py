"""Rules of the Sec. 4 claims D1-D4 (the neural feedback of Eq. (12), Alg. 1, Fig. 5, S10).

Every function takes measured numbers (one value, or one value per seed) and returns the claim's
:class:`~fnnbook.results.ClaimResult` (checks, guarantees, rule); the notebook adds its numbers.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fnnbook.rules._compare import Value, beats, most_seeds, per_seed, seeds_note
from fnnbook.rules.sec3 import AS_WORDED_LEVELS, residual_levels
from fnnbook.results import ClaimResult, Reading



def _in_most(value: Value) -> str:
    n = per_seed(value).size
    return f"in >= {max(1, n - 1)} of {n} seeds" if n > 1 else "in the run"


def d1(*, rel_dr: Value, rel_nominal: Value, factor: float = 1.5) -> ClaimResult:
    """D1 (Fig. 5a): the domain-randomized neural ODE's relative change-rate RMSE on the nominal task exceeds
    ``factor`` x the nominal model's.

    Win-type, paired per seed (seed s: the spiral task's network s against the domain-randomized model of
    initialisation s): ``factor`` x nominal beats the domain-randomized model by :func:`fnnlib.stats.paired_win`.
    """
    return ClaimResult(
        "D1",
        checks={"dr_worse_than_nominal_by_factor": beats(factor * per_seed(rel_nominal), rel_dr)},
        guarantees={},
        reading="Fig. 5a's 'domain randomization ... compromises accuracy on the nominal task' read as a "
                f"domain-randomized error above {factor:g}x the nominal model's",
        rule=f"domain-randomized relative change-rate RMSE on the nominal task > {factor:g}x the nominal "
             "neural ODE's" + seeds_note(rel_dr))


def d2(*, rel_feedback: Value, rel_nominal: Value, frozen_unchanged: bool | Sequence[bool],
       factor: float = 1.5) -> ClaimResult:
    """D2 (Fig. 5b): the frozen neural ODE + neural feedback keeps the nominal accuracy.

    Threshold-type, per seed (fixed before the multi-seed run): the relative RMSE of seed s's frozen
    network with seed s's feedback is at most ``factor`` x that network's alone, in at least S-1 of the S seeds.
    Guarantee: every frozen model (``frozen_unchanged``: one flag, or one per seed) bitwise unchanged by the
    training of its feedback (it is frozen by construction).
    """
    flags = [frozen_unchanged] if isinstance(frozen_unchanged, bool) else list(frozen_unchanged)
    if not flags or not all(isinstance(f, bool) for f in flags):
        raise ValueError(f"D2: frozen_unchanged must be a bool or one bool per seed, got {frozen_unchanged!r}")
    ok = most_seeds(per_seed(rel_feedback) <= factor * per_seed(rel_nominal))
    return ClaimResult(
        "D2",
        checks={"feedback_within_factor_of_nominal": ok},
        guarantees={"frozen_neural_ode_unchanged": all(flags)},
        reading="'maintaining accuracy on previous tasks' (Fig. 5b) read as the frozen model with its feedback "
                f"within {factor:g}x the nominal model's error",
        rule=f"frozen neural ODE + neural feedback relative RMSE <= {factor:g}x the nominal neural ODE's "
             f"{_in_most(rel_feedback)}; every frozen model bitwise unchanged is a guarantee"
             + seeds_note(rel_feedback))


def loss_convergence(loss: Any) -> tuple[np.ndarray, np.ndarray]:
    """The two numbers D3's rule reads from a training-loss curve ``loss`` (iterations,) or (iterations, E).

    With ``m`` = 10 % of the iterations (at least 2): ``ratio`` = mean of the last ``m`` / mean of the first
    ``m``; ``trend`` = the least-squares line's change over the last ``m``, over their mean. One value per seed
    (shape (E,), or (1,) for one curve).
    """
    loss = np.asarray(loss, dtype=float)
    loss = loss[:, None] if loss.ndim == 1 else loss
    if loss.ndim != 2 or len(loss) < 4 or not np.isfinite(loss).all():
        raise ValueError(f"D3: a finite loss curve of at least 4 iterations, got shape {loss.shape}")
    m = max(2, len(loss) // 10)
    first, last = loss[:m].mean(0), loss[-m:].mean(0)
    slope = np.polyfit(np.arange(m), loss[-m:], 1)[0]
    return last / first, slope * m / last


def d3(*, ratio: Value, trend: Value, ratio_max: float = 0.5, flat: float = 0.1) -> ClaimResult:
    """D3 (Fig. 5c): the feedback's training loss converges.

    Threshold-type, per seed (fixed before the multi-seed run): each in at least S-1 of the S seeds, the mean
    Eq. (12) loss of the last 10 % of the iterations < ``ratio_max`` x that of the first 10 %, and the last 10 %
    flat (the least-squares trend over them < ``flat`` of their mean).
    """
    return ClaimResult(
        "D3",
        checks={"last_below_ratio_of_first": most_seeds(per_seed(ratio) < ratio_max),
                "last_window_flat": most_seeds(np.abs(per_seed(trend)) < flat)},
        guarantees={},
        reading="Fig. 5c's training curve read as a loss that falls by a factor and ends flat",
        rule=f"mean loss of the last 10 % < {ratio_max:g}x that of the first 10 %, and the last 10 % change "
             f"by < {flat:.0%} of their mean, each {_in_most(ratio)}" + seeds_note(ratio))


#: the metrics D4 can be read in: the change rate Fig. S10 and the release's test compare, the N-step error of
#: the cascade, or both (the paper profile's strict rule)
D4_METRICS = ("both", "rate", "err_N")


def _both_better(rate_nf: Any, rate_nn: Any, ms_nf: Any, ms_nn: Any, metric: str = "both") -> list[bool]:
    """Per level: the neural feedback beats the neural ODE in change rate and in N-step error (``metric``: both,
    or only one of them)."""
    if metric not in D4_METRICS:
        raise ValueError(f"D4: metric {metric!r} is not one of {D4_METRICS}")
    arrs = [np.asarray(v, dtype=float) for v in (rate_nf, rate_nn, ms_nf, ms_nn)]
    if len({a.shape for a in arrs}) != 1 or arrs[0].ndim not in (1, 2) or arrs[0].size == 0:
        raise ValueError("D4: one value per level (and per seed) for every metric")
    rows = [a if a.ndim == 2 else a[:, None] for a in arrs]
    rate = [beats(rows[0][j], rows[1][j]) for j in range(rows[0].shape[0])]
    multi = [beats(rows[2][j], rows[3][j]) for j in range(rows[0].shape[0])]
    return {"both": [a and b for a, b in zip(rate, multi)], "rate": rate, "err_N": multi}[metric]


_METRIC_WORDS = {"both": "change-rate RMSE and mean {N}-step error", "rate": "change-rate RMSE",
                 "err_N": "mean {N}-step error"}


def d4(*, rate_neural_feedback: Any, rate_neural_ode: Any, err_N_neural_feedback: Any, err_N_neural_ode: Any,
       heldout_rate_neural_feedback: Any, heldout_rate_neural_ode: Any, heldout_err_N_neural_feedback: Any,
       heldout_err_N_neural_ode: Any, N: int, offsets: Any, metric: str = "both") -> ClaimResult:
    """D4 (Fig. S10): the neural feedback beats the neural ODE at the 12 residual levels of S8 -- which sit next
    to the domain-randomized training cases -- and at held-out levels away from them.

    Arrays: one row per level (one column per seed).  Win-type, paired per seed: a level is won when the neural
    feedback beats the neural ODE (:func:`fnnlib.stats.paired_win` over the seeds; one seed: lower) in both the
    change-rate RMSE and the mean ``N``-step error.  ``offsets``: the S8 levels' parameter offsets (one row
    per level).  Strict reading: every S8 level.  As worded (the one the scoreboard counts, ``claims.yaml``):
    every S8 level with a residual to correct (:func:`fnnbook.rules.sec3.residual_levels`); the held-out levels
    as in the strict reading.  ``metric`` (:data:`D4_METRICS`): "both" (the paper profile's rule), or the why's
    readings "rate" (the change rate Fig. S10 and the release's test compare) and "err_N" (the cascade alone).
    """
    s8 = _both_better(rate_neural_feedback, rate_neural_ode, err_N_neural_feedback, err_N_neural_ode, metric)
    held = _both_better(heldout_rate_neural_feedback, heldout_rate_neural_ode, heldout_err_N_neural_feedback,
                        heldout_err_N_neural_ode, metric)
    live = residual_levels(offsets, len(s8), "D4")
    held_check = {f"all_{len(held)}_heldout_levels": all(held)}
    return ClaimResult(
        "D4",
        checks={f"all_{len(s8)}_S8_levels": all(s8)} | held_check,
        guarantees={},
        reading_name="strict",
        reading="'better generalization performance' over the 12 levels (Fig. S10) read as wins at every one of "
                "the 12 S8 levels, the zero-residual level included, and at every held-out level",
        readings={"as worded": Reading(AS_WORDED_LEVELS + "; held-out levels all won",
                                       {f"the_{len(live)}_S8_levels_with_a_residual": all(s8[j] for j in live)}
                                       | held_check)},
        rule=f"neural feedback below the neural ODE in {_METRIC_WORDS[metric].format(N=N)} at every S8 "
             f"level ({sum(s8)} of {len(s8)}) and at every held-out level ({sum(held)} of {len(held)})"
             + seeds_note(np.asarray(rate_neural_feedback, dtype=float).reshape(len(s8), -1)[0]))


# ---------------------------------------------------------------- the why's readings of D2 and D3
#: the band that defines a settled estimate: within 2x its steady level (as S10's band)
SETTLE_BAND = 2.0


def settling_index(err: Any, band: float = SETTLE_BAND) -> np.ndarray:
    """Where an estimate has settled, read from its per-time error curve ``err`` (T,) or (E, T): the first sample
    after which the error stays within ``band`` x its steady level (the median over the last half of the record),
    and at the latest the start of that last half (where the steady level is measured: an error that keeps
    leaving its band settles nowhere earlier). One index per curve (shape (E,), or (1,) for one curve). A rule on
    the data, fixed before any why run."""
    err = np.asarray(err, dtype=float)
    err = err[None] if err.ndim == 1 else err
    if err.ndim != 2 or err.shape[1] < 4 or not np.isfinite(err).all() or band <= 1:
        raise ValueError(f"settling_index: finite (E, T) error curves with T >= 4 and band > 1, got {err.shape}")
    steady = np.median(err[:, err.shape[1] // 2:], axis=1)
    above = err > band * steady[:, None]
    last = np.where(above.any(1), err.shape[1] - 1 - np.argmax(above[:, ::-1], axis=1), -1)
    return np.minimum(last + 1, err.shape[1] // 2)


#: D3's readings: the paper profile's (ratio and a flat end), the same without the flat end (a curve cut at a
#: stopping level is never flat at its end), and the release's own stopping rule (its logged loss below 0.5)
D3_READINGS = {
    "falls and ends flat": "the last 10 % of the loss < {ratio_max:g}x the first 10 % and flat (< {flat:.0%} change)",
    "falls": "the last 10 % of the loss < {ratio_max:g}x the first 10 % (no flat end: a curve cut at a stopping "
             "level never ends flat)",
    "reaches the release's stop": "the loss in the release's form (mean absolute change-rate error over the "
                                  "randomized cases) ends below its stopping level {stop:g}",
}
#: the release's stopping level of the feedback training (its logged loss; spiral_curve/d_FeedbackNN_converge.py)
RELEASE_STOP = 0.5


def reading_holds_d3(reading: str, *, ratio: Value, trend: Value, release_final: Value | None,
                     ratio_max: float = 0.5, flat: float = 0.1, stop: float = RELEASE_STOP) -> bool:
    """Whether D3 holds under one of :data:`D3_READINGS` (each in >= S-1 of S curves): ``ratio`` and ``trend``
    from :func:`loss_convergence`; ``release_final``: the last loss in the release's form, per curve (None:
    that reading cannot be judged, ValueError)."""
    if reading == "falls and ends flat":
        return most_seeds(per_seed(ratio) < ratio_max) and most_seeds(np.abs(per_seed(trend)) < flat)
    if reading == "falls":
        return most_seeds(per_seed(ratio) < ratio_max)
    if reading == "reaches the release's stop":
        if release_final is None:
            raise ValueError("D3: the release's stopping rule needs the loss in the release's form")
        return most_seeds(per_seed(release_final) < stop)
    raise ValueError(f"D3: unknown reading {reading!r}; readings: {list(D3_READINGS)}")
