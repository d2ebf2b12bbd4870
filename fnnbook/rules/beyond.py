r"""The rules of claims B1 (gains tuned from data), B2 (seeds) and B3 (the scoreboard), fixed before any of their
numbers exist.

B1: the base gain :math:`L` and the decay rate :math:`\beta` of Eq. (11), learned from training data by
gradient descent through the differentiable cascade (``fnnlib.tune_gains``), predict (or fly) better than
gains set by hand (a small documented sweep on training data, per setting) on data the tuning never saw.
It is judged per *setting* -- the pendulum and the noisy spiral of ``own_system`` (the S3 setting), the real
bottle throws (the O1 setting), the quadrotor FNN-MPC flight at the judged thrust bound (the Q3 setting, one setting per cost variant) -- on *units* that
pair the predictors: seeds, test throws, or trained networks x disturbances, as the notebook says.

Per setting, with ``errors[setting][predictor]`` one error per unit (lower is better):

1. ``tuned_beats_hand``: the tuned gains win over the hand-tuned ones;
2. ``tuned_beats_open_loop`` (where an open-loop prediction is given): the tuned gains win over the
   model without feedback;
3. ``tuned_within_2x_kalman`` (where a Kalman filter is given): tuned <= 2 x Kalman in all units but one.

A *win* of A over B is :func:`fnnlib.stats.paired_win`: A is lower in at least S - 1 of S units **and**
the 90 % t-interval of the mean paired difference lies below 0. All checks true: *reproduced*; some:
*partly*; none: *not reproduced* (:class:`fnnbook.results.ClaimResult`). B1 has no guarantee.

A fair comparison (the premises, enforced or shown, never checks): per setting the tuned and the hand gains
get the same *budget* -- the same number of evaluations of their cost on the same training data, one
evaluation being one pass of the cascade (or one flight) over that data (:func:`b1_budget` refuses unequal
budgets; the tuner's pass also returns a gradient, which the grid does not get) -- and the hand grid spans
the region the tuned gains reach (:func:`b1_coverage` says, per unit, whether every tuned entry of ``L`` and
``beta`` lies within the span of the hand grid).

B2 (every comparison over seeds) and B3 (the scoreboard is computed from the runs) are judged by the
scoreboard over every task's results (:func:`b2`, :func:`b3`).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

import numpy as np

from fnnbook.results import ClaimResult, GuaranteeFailed, Headline, headline_number
from fnnlib.stats import paired_win

__all__ = ["KALMAN_FACTOR", "MIN_SEEDS", "PREDICTORS", "b1", "b1_budget", "b1_coverage", "b1_paired", "b1_summary",
           "b2", "b3"]

KALMAN_FACTOR = 2.0
"""How much worse than the Kalman filter the tuned gains may be, unit by unit (check 3)."""

PREDICTORS = ("tuned", "hand", "open_loop", "kalman")
"""The predictors a setting may give: ``tuned`` and ``hand`` always, the other two where measured."""

Errors = Mapping[str, Mapping[str, Sequence[float]]]


def _checked(errors: Errors) -> dict[str, dict[str, np.ndarray]]:
    """Every setting's errors as float arrays, all checked before any statistic."""
    if not errors:
        raise ValueError("B1 needs at least one setting")
    out = {}
    for setting, e in errors.items():
        for need in ("tuned", "hand"):
            if need not in e:
                raise ValueError(f"B1 setting {setting!r} has no {need!r} errors (it has {sorted(e)})")
        unknown = set(e) - set(PREDICTORS)
        if unknown:
            raise ValueError(f"B1 setting {setting!r}: unknown predictors {sorted(unknown)}; expected {PREDICTORS}")
        arr = {k: np.asarray(v, dtype=float) for k, v in e.items()}
        S = arr["tuned"].shape
        for k, v in arr.items():
            if v.ndim != 1 or v.shape != S or v.size < 2:
                raise ValueError(f"B1 setting {setting!r}: every predictor needs one error per unit, at least 2 "
                                 f"units and as many as 'tuned' ({S}); {k!r} has shape {v.shape}")
            if not np.isfinite(v).all():
                raise ValueError(f"B1 setting {setting!r}: {k!r} has non-finite errors {v.tolist()}")
        out[setting] = arr
    return out


def b1(errors: Errors) -> ClaimResult:
    """B1's checks (see the module docstring); the notebook adds its numbers (``b1(errors).replace(numbers=...)``).

    Parameters
    ----------
    errors : mapping
        ``errors[setting][predictor]``: one error per unit, paired by position across predictors;
        ``predictor`` in :data:`PREDICTORS` (``tuned`` and ``hand`` required).

    Returns
    -------
    ClaimResult
        ``checks`` (``"<setting>: tuned beats hand"``, ``"<setting>: tuned beats open loop"``,
        ``"<setting>: tuned within 2x Kalman"``, the last two where that predictor is given),
        ``guarantees`` (none) and ``rule`` (the rule in words).
    """
    checks = {}
    for setting, e in _checked(errors).items():
        checks[f"{setting}: tuned beats hand"] = paired_win(e["tuned"], e["hand"])["win"]
        if "open_loop" in e:
            checks[f"{setting}: tuned beats open loop"] = paired_win(e["tuned"], e["open_loop"])["win"]
        if "kalman" in e:
            S = e["tuned"].size
            checks[f"{setting}: tuned within {KALMAN_FACTOR:g}x Kalman"] = (
                int((e["tuned"] <= KALMAN_FACTOR * e["kalman"]).sum()) >= S - 1)
    return ClaimResult(
        "B1",
        checks=checks,
        guarantees={},
        rule=("per setting: the tuned (L, beta) win (lower in >= S-1 of S paired units and the 90 % interval "
              "of the mean paired difference below 0) over the hand-tuned gains and, where given, over the "
              f"open-loop model; where a Kalman filter is given, tuned <= {KALMAN_FACTOR:g}x its error in all "
              "units but one"))


def b1_paired(errors: Errors) -> dict[str, dict]:
    """The paired statistics behind :func:`b1`: ``"<setting>: tuned vs <other>"`` -> :func:`~fnnlib.stats.paired_win`."""
    return {f"{setting}: tuned vs {other}": paired_win(e["tuned"], e[other])
            for setting, e in _checked(errors).items() for other in PREDICTORS[1:] if other in e}


def b1_summary(errors: Errors) -> dict[str, dict]:
    """Per setting, what the chapter reports beside the checks: the true number of paired units ``n``, each
    predictor's mean error, and ``kalman_beats_tuned`` (where a Kalman filter is given: the filter wins over
    the tuned gains by :func:`~fnnlib.stats.paired_win`, so the chapter must say the filter is better there;
    ``None`` where no filter is given). Not a check: the verdict is :func:`b1`'s."""
    return {setting: {"n": int(e["tuned"].size), "mean": {k: float(v.mean()) for k, v in e.items()},
                      "kalman_beats_tuned": (paired_win(e["kalman"], e["tuned"])["win"] if "kalman" in e else None)}
            for setting, e in _checked(errors).items()}


def b1_budget(budgets: Mapping[str, Mapping[str, int]]) -> dict[str, int]:
    """Each setting's budget of cost evaluations, the same for the tuned and the hand gains.

    ``budgets[setting]`` gives ``tuned`` (the tuner's evaluations: Adam steps, or grid points where the tuner
    is a grid) and ``hand`` (the points of the hand grid), both on the same training data. Returns
    ``{setting: budget}``; raises ``ValueError`` where a setting's two budgets differ (the comparison would
    measure the budget, not the method) or one is below 1.
    """
    out = {}
    for setting, b in budgets.items():
        for need in ("tuned", "hand"):
            if need not in b:
                raise ValueError(f"B1 setting {setting!r}: no {need!r} budget (it has {sorted(b)})")
        tuned, hand = int(b["tuned"]), int(b["hand"])
        if min(tuned, hand) < 1:
            raise ValueError(f"B1 setting {setting!r}: a budget is at least 1 evaluation, got tuned {tuned}, hand {hand}")
        if tuned != hand:
            raise ValueError(f"B1 setting {setting!r}: the tuned gains get {tuned} evaluations and the hand gains "
                             f"{hand}; a fair comparison gives both the same budget")
        out[setting] = tuned
    return out


def b1_coverage(tuned: Mapping[str, Sequence[Mapping]], hand: Mapping[str, Sequence[Mapping]]) -> dict[str, dict]:
    """Per setting, whether the hand grid spans the region the tuned gains reach (a premise, shown, not judged).

    ``tuned[setting]``: per unit ``{"L": scalar or diagonal, "beta": float}``; ``hand[setting]``: per unit the
    hand sweep (``L_grid``, ``beta_grid``). A unit is covered when every entry of its tuned ``L`` lies within
    [min, max] of its ``L_grid`` and its ``beta`` within [min, max] of its ``beta_grid``. Returns per setting
    ``units``, ``covered`` (how many), ``outside`` (the indices of the others) and the spans of the first
    unit's grids.
    """
    out = {}
    for setting, units in tuned.items():
        grids = hand.get(setting, ())
        if len(grids) != len(units):
            raise ValueError(f"B1 setting {setting!r}: one hand grid per unit needed, got {len(grids)} for "
                             f"{len(units)} tuned units")
        outside = []
        for k, (t, g) in enumerate(zip(units, grids)):
            L, beta = np.atleast_1d(np.asarray(t["L"], float)), float(t["beta"])
            Lg, bg = np.asarray(g["L_grid"], float), np.asarray(g["beta_grid"], float)
            tol = 1e-9
            if not ((L >= Lg.min() * (1 - tol)).all() and (L <= Lg.max() * (1 + tol)).all()
                    and bg.min() - tol <= beta <= bg.max() * (1 + tol) + tol):
                outside.append(k)
        first = grids[0]
        out[setting] = {"units": len(units), "covered": len(units) - len(outside), "outside": outside,
                        "L_span": [float(min(first["L_grid"])), float(max(first["L_grid"]))],
                        "beta_span": [float(min(first["beta_grid"])), float(max(first["beta_grid"]))]}
    return out


MIN_SEEDS = 5
"""B2's least number of independent seeds (or paired units) behind a claim's headline (at least 5)."""


def b2(headlines: Mapping[str, Headline | None], *, min_seeds: int = MIN_SEEDS) -> ClaimResult:
    """B2 (every comparison over several seeds, with spread shown), computed by the scoreboard from the runs.

    ``headlines`` maps each judged claim ID (B2 and B3 aside) to its headline
    (:func:`fnnbook.results.headline_number`: ``n`` values when it is per seed, with their ``spread``), or None.

    Checks, each of which a plausible run fails (a profile with fewer seeds, a claim judged on one run):

    1. ``per_seed_headlines_over_>=5_seeds``: every per-seed headline has ``n >= min_seeds``;
    2. ``every_claim_shows_a_spread``: every judged claim's headline is per seed (``n >= 2``).

    Guarantee (by construction of ``headline_number``): a per-seed headline carries its spread.
    Headline: the fraction of judged claims whose headline has a seed count ``n``.
    """
    if not headlines:
        raise ValueError("B2 needs the judged claims' headlines")
    n = {cid: None if h is None else h.n for cid, h in headlines.items()}
    seeded = {cid: k for cid, k in n.items() if k is not None and k >= 2}
    single = sorted(cid for cid in n if cid not in seeded)
    few = sorted(cid for cid, k in seeded.items() if k < min_seeds)
    return ClaimResult(
        "B2",
        checks={f"per_seed_headlines_over_>={min_seeds}_seeds": bool(seeded) and not few,
                "every_claim_shows_a_spread": not single},
        guarantees={"spread_with_every_per_seed_headline":
                    all(headlines[cid].spread is not None for cid in seeded)},
        numbers={"seeds_per_claim": n, "claims_with_fewer_seeds": few, "claims_without_spread": single},
        rule=f"every judged claim's headline is per seed (n >= 2, with its spread) and every per-seed "
             f"headline rests on >= {min_seeds} seeds or paired units (computed by the scoreboard)",
        headline=headline_number("judged claims with a per-seed headline",
                                 sum(bool(k) for k in n.values()) / len(headlines)),
        paper="the paper shows single runs",
        title="every comparison over seeds, spread shown")


def b3(listed: Collection[str], reported: Sequence[ClaimResult], *, tasks_with_results: int,
       expected: Collection[str]) -> ClaimResult:
    """B3 (the scoreboard page is computed from the runs), judged by the scoreboard.

    ``listed``: the claim IDs of the claims file; ``reported``: every claim a task reported (B2 included);
    ``tasks_with_results``: how many result sets there are; ``expected``: the IDs the tasks declare.

    The claim is bookkeeping, so it has no check (it is "verified by construction", never counted as
    reproduced): a task that failed or was skipped leaves its claims "not run" on a page that is still computed
    from the runs, so completeness says nothing on the claim; it is shown as a number
    (``claims_not_reported``, ``tasks_with_results``). Guarantees: every reported ID is listed; every verdict
    is the one its checks imply (by construction: a :class:`ClaimResult` derives its verdict, and reading a
    results file refuses a stored verdict that differs).

    Raises
    ------
    GuaranteeFailed
        Naming the reported IDs that the claims file does not list.
    """
    ids = {c.id for c in reported}
    unknown = sorted(ids - set(listed))
    if unknown:
        raise GuaranteeFailed(f"claim B3: IDs not in the claims file {unknown}")
    missing = sorted(set(expected) - ids)
    return ClaimResult(
        "B3",
        checks={},
        guarantees={"ids_known": not unknown, "verdicts_follow_checks": True},
        numbers={"tasks_with_results": tasks_with_results, "claims_reported": len(reported),
                 "claims_listed": len(set(listed)), "claims_not_reported": missing},
        rule="bookkeeping, no check: every reported ID is in the claims file and every verdict equals the one its "
             "checks imply (guarantees); the claims a task declares but did not report are shown, not judged")
