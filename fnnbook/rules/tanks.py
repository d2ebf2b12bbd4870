r"""The rules of claims B4-B6 (the cascaded tanks benchmark: a real plant, learned from its measured level),
fixed before any of their numbers exist.

Every number is measured on the benchmark's *validation* record, on which nothing is tuned; one value per
seed of the ensemble (the seeds are the paired units, at least 2; the chapter runs 5). Lower is better.
A *win* of A over B is :func:`fnnlib.stats.paired_win`: A is lower in at least S - 1 of S seeds **and**
the 90 % t-interval of the mean paired difference lies below 0.

B4 (feedback at prediction time): the model learned through its observer, predicting ``N`` samples ahead
with the linear feedback cascade (the tuned gains), beats the same model rolled out open loop from the
same observer's estimate. One check per horizon ``N > 1``: ``"N=<N>: feedback beats open loop"``. At
``N = 1`` the cascade is its first layer, the observer, alone, so both predictions are the same by
construction: a guarantee (they agree to :data:`SAME` volts), never a check.

B5 (feedback at training time): the model trained through its observer beats the same architecture
trained without feedback (the initial state of each training segment a free parameter, or an encoder of
past outputs) in the benchmark's metric, the free-run simulation RMSE. One check:
``"trained through the observer beats trained without feedback"``.

B6 (gains learned from data): the gains tuned by gradient descent on the estimation record beat the hand
gains (the best of a small sweep on the estimation record) at N-step prediction. One check per horizon
``N > 1``; at ``N = 1`` both are the observer alone (a guarantee, as in B4).

All checks true: *reproduced*; some: *partly*; none: *not reproduced* (:class:`fnnbook.results.ClaimResult`).
No guarantees: each check can fail on a plausible run.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from fnnbook.results import ClaimResult, headline_number
from fnnlib.stats import paired_win

__all__ = ["SAME", "b4", "b4_at", "b5", "b6", "b6_at"]

PerSeed = Sequence[float]


def _seeds(claim: str, name: str, value: PerSeed) -> np.ndarray:
    """One finite error per seed, at least 2 seeds."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1 or arr.size < 2:
        raise ValueError(f"{claim}: {name} needs one error per seed (at least 2 seeds), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{claim}: {name} holds non-finite errors {arr.tolist()}")
    return arr


def _by_horizon(claim: str, errors: Mapping[int, Mapping[str, PerSeed]], a: str, b: str
                ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """``errors[N][a]``, ``errors[N][b]`` per horizon, checked and paired."""
    if not errors:
        raise ValueError(f"{claim} needs the errors of at least one horizon N")
    out = {}
    for N, e in errors.items():
        if isinstance(N, bool) or int(N) != N or N < 1:
            raise ValueError(f"{claim}: horizons must be integers >= 1, got {N!r}")
        for need in (a, b):
            if need not in e:
                raise ValueError(f"{claim}: N={N} has no {need!r} errors (it has {sorted(e)})")
        x, y = _seeds(claim, f"N={N} {a!r}", e[a]), _seeds(claim, f"N={N} {b!r}", e[b])
        if x.shape != y.shape:
            raise ValueError(f"{claim}: N={N}: {a!r} and {b!r} must pair seed by seed, got {x.size} and {y.size}")
        out[int(N)] = (x, y)
    return dict(sorted(out.items()))


SAME = 1e-9
"""At N = 1 both predictors are the observer alone (no layer after it): equal to this (volts), by construction."""


def _per_horizon(claim: str, errors: Mapping[int, Mapping[str, PerSeed]], a: str, b: str, words: str,
                 rule: str, headline: str) -> ClaimResult:
    pairs = _by_horizon(claim, errors, a, b)
    stats = {N: paired_win(x, y) for N, (x, y) in pairs.items() if N > 1}
    longest = max(pairs)
    x, y = pairs[longest]
    return ClaimResult(
        claim,
        checks={f"N={N}: {words}": s["win"] for N, s in stats.items()},
        guarantees={f"N=1: {a} equals {b} (the observer alone, no layer after it)":
                    bool(np.all(np.abs(pairs[1][0] - pairs[1][1]) <= SAME))} if 1 in pairs else {},
        rule=rule + "; at N = 1 both are the observer alone, equal by construction (a guarantee, not a check)",
        numbers={"mean": {f"N={N}": {a: float(x.mean()), b: float(y.mean())} for N, (x, y) in pairs.items()},
                 "paired": {f"N={N}": s for N, s in stats.items()}},
        headline=headline_number(f"N={longest} RMSE ratio, {headline}", (x / y).tolist()),
        n=int(x.size))


def b4(errors: Mapping[int, Mapping[str, PerSeed]]) -> ClaimResult:
    """B4: linear feedback beats open loop at every horizon (module docstring).

    Parameters
    ----------
    errors : mapping
        ``errors[N]["feedback"]``, ``errors[N]["open_loop"]``: the N-step RMSE of ``y`` on the validation
        record, one per seed, paired by position.
    """
    return _per_horizon("B4", errors, "feedback", "open_loop", "feedback beats open loop",
                        "per horizon N: the feedback cascade's N-step RMSE wins over the open-loop rollout from "
                        "the same observer's estimate (lower in >= S-1 of S seeds and the 90 % interval of the "
                        "mean paired difference below 0), on the validation record",
                        "feedback / open loop")


def b5(*, observer_trained: PerSeed, no_feedback: PerSeed) -> ClaimResult:
    """B5: the model trained through its observer beats the same architecture trained without feedback, in
    free-run simulation RMSE on the validation record (module docstring); one RMSE per seed each."""
    a = _seeds("B5", "observer_trained", observer_trained)
    b = _seeds("B5", "no_feedback", no_feedback)
    if a.shape != b.shape:
        raise ValueError(f"B5: observer_trained and no_feedback must pair seed by seed, got {a.size} and {b.size}")
    s = paired_win(a, b)
    return ClaimResult(
        "B5",
        checks={"trained through the observer beats trained without feedback": s["win"]},
        guarantees={},
        rule="the free-run simulation RMSE on the validation record of the model trained through its observer "
             "wins over the same architecture's trained without feedback (lower in >= S-1 of S seeds and the "
             "90 % interval of the mean paired difference below 0)",
        numbers={"mean": {"observer_trained": float(a.mean()), "no_feedback": float(b.mean())}, "paired": s},
        headline=headline_number("free-run RMSE, trained through the observer", a.tolist(), unit="V"),
        n=int(a.size))


def b6(errors: Mapping[int, Mapping[str, PerSeed]]) -> ClaimResult:
    """B6: tuned gains beat hand gains at every horizon (module docstring).

    Parameters
    ----------
    errors : mapping
        ``errors[N]["tuned"]``, ``errors[N]["hand"]``: the N-step RMSE of ``y`` on the validation record
        with each gain, one per seed, paired by position.
    """
    return _per_horizon("B6", errors, "tuned", "hand", "tuned gains beat hand gains",
                        "per horizon N: the cascade with the gains tuned on the estimation record wins over the "
                        "hand gains (the best of a sweep on the estimation record) in N-step RMSE on the "
                        "validation record (lower in >= S-1 of S seeds and the 90 % interval of the mean paired "
                        "difference below 0)",
                        "tuned / hand")


def b4_at(errors: Mapping[str, Mapping[int, PerSeed]], horizons: Sequence[int], feedback: str = "tuned") -> ClaimResult:
    """B4 (:func:`b4`) at one point of a why grid: ``errors`` holds each model's N-step errors by horizon (the cascade's
    columns ``"tuned"``, ``"hand"`` or a fixed gain's, and ``"open_loop"``); the cascade ``feedback`` against the open
    loop at every horizon of ``horizons``."""
    return b4({N: {"feedback": errors[feedback][N], "open_loop": errors["open_loop"][N]} for N in horizons})


def b6_at(errors: Mapping[str, Mapping[int, PerSeed]], horizons: Sequence[int]) -> ClaimResult:
    """B6 (:func:`b6`) at one point of a why grid: the tuned gains against the hand gains at every horizon of
    ``horizons`` (``errors`` as :func:`b4_at` reads them)."""
    return b6({N: {"tuned": errors["tuned"][N], "hand": errors["hand"][N]} for N in horizons})
