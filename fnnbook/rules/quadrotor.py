r"""The rules of Sec. 5 (claims Q1-Q6): measured numbers in, checks and guarantees out.

Each rule returns a :class:`~fnnbook.results.ClaimResult`: ``checks`` decide the verdict and each can fail on a
plausible run;
``guarantees`` hold by construction or by a theorem whose constants are measured on the same run, and never
count. Comparisons over trained networks (and disturbances) are paired over independent units and decided by
:func:`fnnlib.stats.paired_win` (lower is better: a win holds in at least S - 1 of S units and the 90 %
t-interval of the mean paired difference excludes 0); Q2-Q4 take each entry's unit id, so S is the true
number of independent units and copies of one flight count once. Q3-Q5 are judged per setting (``label``, e.g. the cost
variant); the notebook joins the settings into one claim. A rule without guarantees leaves them ``None``.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from torch import Tensor

from fnnlib.quadrotor.mpc.experiment import SIX
from fnnbook.results import ClaimResult, GuaranteeFailed, Reading, verdict_from_checks
from fnnlib.stats import paired_win
from fnnlib.quadrotor.training import convergence_checks

__all__ = ["AUTHORS_SECONDS_50_EPOCHS", "unjudged_bound_note", "GROUPS", "SIX", "count_trainable", "join_costs", "join_readings", "joined_verdict",
           "q1_convergence", "q2_prediction", "q3_tracking", "q4_prediction", "q5_adaptive", "q6_training_cost",
           "rules_at_setting"]


def _paired(values: Mapping[str, Sequence[float]], names: Iterable[str]) -> dict[str, np.ndarray]:
    """The named models' paired values (one per unit), checked to pair."""
    out = {n: np.asarray(values[n], dtype=float) for n in names}
    lengths = {v.shape for v in out.values()}
    if len(lengths) != 1 or next(iter(lengths))[0] < 2 or len(next(iter(lengths))) != 1:
        raise ValueError(f"need one 1-D series of >= 2 paired values per model, got shapes "
                         f"{ {n: v.shape for n, v in out.items()} }")
    return out


def _units(units: Sequence[Hashable], S: int) -> list[Hashable]:
    """The unit id of each of the ``S`` paired entries, checked: one per entry, at least 2 distinct."""
    ids = list(units)
    if len(ids) != S or len(set(ids)) < 2:
        raise ValueError(f"need one unit id per paired entry ({S}) and at least 2 distinct units, got {ids}")
    return ids


def _wins(v: Mapping[str, np.ndarray], pairs: Iterable[tuple[str, str]], label: str,
          units: Sequence[Hashable]) -> tuple[dict[str, bool], dict, int]:
    """``a beats b`` by :func:`paired_win` over ``units`` for each pair, with its statistics, and the number of
    independent units (entries with the same id count once)."""
    checks, stats, n = {}, {}, 0
    for a, b in pairs:
        w = paired_win(v[a], v[b], units=units)
        n = w["seeds"]
        checks[f"{label}: {a} beats {b} (paired over {n} units, >= {n - 1} of {n})"] = w["win"]
        stats[f"{a} < {b}"] = w
    return checks, stats, n


def q1_convergence(member_loss: np.ndarray, *, min_members: int = 5) -> ClaimResult:
    """Q1: training converges for every one of at least ``min_members`` random initialisations (Fig. A).

    ``member_loss`` (epochs + 1, E): row 0 before training. Checks: every final loss <= 10 % of its initial
    one; the last 10 % of epochs change every loss by < 20 %; the largest final loss at most 2x the smallest.
    How many initialisations were trained is a parameter of the run, not a finding: it is the claim's ``n``
    and is stated in the rule (below ``min_members`` the rule says so), never a check.
    """
    loss = np.asarray(member_loss, dtype=float)
    if loss.ndim != 2 or loss.shape[0] < 2 or not np.isfinite(loss).all():
        raise ValueError(f"member_loss must be a finite (epochs + 1, members) array, got shape {loss.shape}")
    E = loss.shape[1]
    count = (f"{E} initialisations (the paper's {min_members} or more)" if E >= min_members
             else f"only {E} initialisations, fewer than the paper's {min_members}")
    return ClaimResult("Q1", checks=convergence_checks(loss, loss.shape[0] - 1),
                       numbers={"final_over_initial": (loss[-1] / loss[0]).tolist(), "final_loss": loss[-1].tolist(),
                                "initialisations": E},
                       n=E,
                       reading="'training converges for 5-6 random initialisations' (Fig. A) read as every trained "
                               "initialisation's loss falling to a tenth, ending flat, and the finals close together",
                       rule=f"{count}; final <= 10 % of initial and flat over the last 10 % of epochs for each; "
                            "max/min final <= 2")


GROUPS = ("p", "v", "Theta", "omega")
"""The state groups of Q2 (:data:`~fnnlib.quadrotor.system.STATE_GROUPS`): all 12 states."""


def q2_prediction(neural: Sequence[Mapping[str, float]], nominal: Mapping[str, float], *, units: Sequence[Hashable],
                  tol: float = 0.10) -> ClaimResult:
    """Q2: the learned model predicts all 12 states of the long validation flights (Figs. S4-S7).

    ``neural[k][group]``: relative RMSE per state group (p, v, Theta, omega) of trained network ``k`` (unit
    ``units[k]``, one per network) on held-out flights that chose nothing (not the network kept, not a
    setting); ``nominal[group]`` the nominal model's on the same flights (no network: one value, the same
    for every unit). Checks: (a) every group at most ``tol`` in at least S - 1 of the S networks; (b) the
    neural ODE beats the nominal model for p and for v, paired over the networks (:func:`paired_win`).
    """
    S = len(neural)
    ids = _units(units, S)
    if any(set(r) != set(GROUPS) for r in (*neural, nominal)):
        raise ValueError(f"need the groups {', '.join(GROUPS)} for every network and the nominal model")
    per = {g: np.array([float(r[g]) for r in neural]) for g in GROUPS}
    within = int(np.all([per[g] <= tol for g in GROUPS], axis=0).sum())
    beats = {g: paired_win(per[g], np.full(S, float(nominal[g])), units=ids) for g in ("p", "v")}
    n = beats["p"]["seeds"]
    checks = {f"neural ODE: relative RMSE <= {100 * tol:g} % for p, v, Theta and omega in >= {n - 1} of {n} networks":
              within >= n - 1,
              f"neural ODE beats nominal for p and v (paired over {n} networks, >= {n - 1} of {n})":
              all(w["win"] for w in beats.values())}
    numbers = {"neural ODE": {g: v.tolist() for g, v in per.items()}, "nominal": {g: float(nominal[g]) for g in GROUPS},
               "networks_within": within, "paired": {f"neural ODE < nominal, {g}": w for g, w in beats.items()}}
    return ClaimResult("Q2", checks=checks, numbers=numbers, n=n,
                       rule=f"on held-out flights: relative RMSE per state group <= {100 * tol:g} % in >= S - 1 of S "
                            "networks; the neural ODE paired-beats the nominal model for p and v",
                       reading="'predicts all 12 states' is read as every state group within "
                               f"{100 * tol:g} % relative RMSE for all trained networks but at most one, on "
                               "flights used for nothing else, and better than the nominal model in p and v")


def q3_tracking(rmse: Mapping[str, Sequence[float]], *, units: Sequence[Hashable], label: str) -> ClaimResult:
    """Q3 (Fig. 7): FNN tracks best of the six; Neural < Nomi; MLP worse than Neural. Paired over units.

    ``rmse[model]``: mean per-axis tracking RMSE, one value per entry of ``units`` (the independent unit
    each flight belongs to, e.g. a trained network with one drawn disturbance), in the same order for every
    model; entries with the same unit id count as one unit (:func:`paired_win`). ``label`` names the setting
    in each check (e.g. the cost variant).
    """
    v = _paired(rmse, SIX)
    pairs = [("FNN", m) for m in SIX if m != "FNN"] + [("Neural", "Nomi"), ("Neural", "MLP")]
    checks, stats, n = _wins(v, pairs, label, _units(units, len(v["FNN"])))
    mean = {k: float(x.mean()) for k, x in v.items()}
    return ClaimResult("Q3", checks=checks, numbers={"paired": stats, "mean": mean}, n=n,
                       rule=f"{label}: FNN paired-beats each of the other five; Neural beats Nomi and MLP "
                            f"(over {n} independent units)",
                       reading="'tracks best' is read as a paired win of FNN over each other model, and of Neural "
                               "over Nomi and MLP, across independent units (network and disturbance), beyond "
                               "the spread")


def q4_prediction(acc_rmse: Mapping[str, Sequence[float]], *, units: Sequence[Hashable], label: str) -> ClaimResult:
    """Q4 (Fig. S8): the first-step acceleration prediction is best with FNN, among the six. Paired over units
    (``units`` as in :func:`q3_tracking`)."""
    v = _paired(acc_rmse, SIX)
    checks, stats, n = _wins(v, [("FNN", m) for m in SIX if m != "FNN"], label, _units(units, len(v["FNN"])))
    mean = {k: float(x.mean()) for k, x in v.items()}
    return ClaimResult("Q4", checks=checks, numbers={"paired": stats, "mean": mean}, n=n,
                       rule=f"{label}: FNN's first-step acceleration error paired-beats each of the other five "
                            f"(over {n} independent units)",
                       reading="'best prediction' is read as a paired win of FNN's first-step acceleration error "
                               "over each other model across independent units, beyond the spread")


def q5_adaptive(rmse: Mapping[str, Sequence[float]], theorem2_inside: Sequence[float], *, label: str,
                rel_tol: float = 0.25, min_inside: float = 0.95) -> ClaimResult:
    r"""Q5 (Fig. S14): AdapFNN is comparable to FNN with a slightly larger RMSE; Theorem 2's ball holds.

    Strict reading, paired over runs: AdapFNN within ``rel_tol`` of FNN in at least S - 1 of S runs,
    and AdapFNN's mean RMSE >= FNN's. As worded ("comparable"): the first check alone. A check that fails
    because AdapFNN tracks *better* than FNN (a lower mean RMSE; within the tolerance failing only on runs where
    AdapFNN is lower) is marked ``better``: the claim's verdict is then "better than claimed". Guarantee: on every
    run, the layer-0 error stays in the ball :math:`\gamma/\lambda_m(L)` for at least ``min_inside`` of the
    steps after the transient, :math:`\gamma` measured on the same run (Theorem 2).
    """
    v = _paired(rmse, ("FNN", "AdapFNN"))
    inside = np.asarray(theorem2_inside, dtype=float)
    within = np.abs(v["AdapFNN"] - v["FNN"]) <= rel_tol * v["FNN"]
    S = len(within)
    within_name = f"{label}: AdapFNN within {100 * rel_tol:g} % of FNN (>= {S - 1} of {S})"
    larger_name = f"{label}: AdapFNN mean RMSE >= FNN's (slightly larger)"
    comparable = {within_name: int(within.sum()) >= S - 1}
    checks = comparable | {larger_name: float(v["AdapFNN"].mean()) >= float(v["FNN"].mean())}
    lower = v["AdapFNN"] < v["FNN"]
    better = {within_name: not checks[within_name] and int((within | lower).sum()) >= S - 1,
              larger_name: not checks[larger_name]}
    guarantees = {f"{label}: Theorem 2 ball holds >= {100 * min_inside:g} % after the transient, every run":
                  bool(inside.size > 0 and (inside >= min_inside).all())}
    numbers = {"within_fraction": float(within.mean()), "mean": {n: float(x.mean()) for n, x in v.items()},
               "theorem2_inside_min": float(inside.min()) if inside.size else None}
    return ClaimResult("Q5", checks=checks, guarantees=guarantees, numbers=numbers, better=better,
                       reading_name="strict",
                       reading="'performance comparable to the previous feedback neural network, with a slightly "
                               f"larger RMSE' (App. A.9) read as: within {100 * rel_tol:g} % of FNN and a mean RMSE "
                               "not below FNN's",
                       readings={"as worded": Reading(
                           f"the same words read as 'comparable' alone (within {100 * rel_tol:g} % of FNN), the "
                           "'slightly larger' a description of the authors' run rather than a requirement",
                           comparable)},
                       rule=f"{label}: AdapFNN within {100 * rel_tol:g} % of FNN in >= S - 1 of S runs and its mean "
                            "RMSE >= FNN's; Theorem 2's ball is a guarantee")


def join_readings(per_setting: Iterable[ClaimResult]) -> dict[str, Reading] | None:
    """The other readings of one claim judged per setting (e.g. per cost variant), joined: each reading's checks
    over every setting, its sentence from the first; None when the claims have no other readings."""
    claims = list(per_setting)
    if not claims or not claims[0].readings:
        return None
    return {name: Reading(first.sentence, {k: v for c in claims for k, v in (c.readings or {})[name].checks.items()})
            for name, first in claims[0].readings.items()}


def join_costs(per_cost: Mapping[str, ClaimResult], *, numbers: Mapping[str, Any] | None = None,
               **fields: Any) -> ClaimResult:
    """One claim over the cost variants of Eq. (28), as the flight test reports it: every variant's checks,
    guarantees, readings (:func:`join_readings`) and better-than-claimed marks together, its numbers by variant
    (and ``numbers`` beside them), the other ``fields`` (figure, headline, ...) set on the first variant's result."""
    claims = list(per_cost.values())
    return claims[0].replace(
        checks={k: v for c in claims for k, v in c.checks.items()},
        guarantees={k: v for c in claims for k, v in (c.guarantees or {}).items()},
        readings=join_readings(claims),
        better={k: v for c in claims for k, v in (c.better or {}).items()} or None,
        numbers={cost: c.numbers for cost, c in per_cost.items()} | dict(numbers or {}), **fields)


def rules_at_setting(rmse: Mapping[str, Sequence[float]], acc_rmse: Mapping[str, Sequence[float]],
                     theorem2_inside: Sequence[float], *, units: Sequence[Hashable],
                     label: str) -> dict[str, ClaimResult | None]:
    """Q3, Q4 and Q5 at one setting (one cost variant at one thrust bound and gain), as the flight-test notebook
    applies them: :func:`q3_tracking` on ``rmse`` (the seven models), :func:`q4_prediction` on the six of
    ``acc_rmse``, :func:`q5_adaptive` on ``rmse`` with ``theorem2_inside``. Nothing is added to the rules: a why
    grid point holds where the claim's result reads reproduced. Q5 is ``None`` where its Theorem 2 guarantee
    fails (the rule then stops: no verdict, so the point cannot hold).
    """
    out: dict[str, ClaimResult | None] = {
        "Q3": q3_tracking(rmse, units=units, label=label),
        "Q4": q4_prediction({n: acc_rmse[n] for n in SIX}, units=units, label=label)}
    try:
        out["Q5"] = q5_adaptive(rmse, theorem2_inside, label=label)
    except GuaranteeFailed:
        out["Q5"] = None
    return out


def joined_verdict(per_setting: Iterable[ClaimResult | None]) -> tuple[str, dict[str, bool]]:
    """One claim over several settings (e.g. the two cost variants), as the flight-test notebook joins them: the
    verdict of every setting's checks together, and those checks. A missing result (a failed guarantee) makes
    the verdict "not reproduced"."""
    claims = list(per_setting)
    if not claims:
        raise ValueError("need at least one setting's result")
    if any(c is None for c in claims):
        return "not reproduced", {}
    checks = {k: v for c in claims for k, v in c.checks.items()}
    return verdict_from_checks(checks), checks


def count_trainable(tensors: Iterable[Tensor]) -> int:
    """Number of trainable entries (``requires_grad``) among ``tensors``."""
    return int(sum(t.numel() for t in tensors if t.requires_grad))


#: the authors' training time for the quadrotor's residual model: "around 30 mins to run 50 epochs on a laptop with
#: 13th Gen Intel(R) Core(TM) i9-13900H" (App. A.7), 14 cores
AUTHORS_SECONDS_50_EPOCHS = 30 * 60.0
#: "around" 30 minutes read as a band: a factor 2 either way (15 to 60 minutes)
AROUND_FACTOR = 2.0


def q6_training_cost(n_trainable_feedback: int, seconds_per_model: float, *,
                     around: float = AROUND_FACTOR) -> ClaimResult:
    """Q6: the linear feedback needs no training; the residual model trains in around the authors' time.

    "Around 30 mins" read as the band [30 / ``around``, 30 x ``around``] minutes: the text gives one rounded
    number for one laptop and no spread, so a factor 2 either way is what "around" can carry (a factor of 2 is
    the spread of one generation's laptop CPUs on one workload; beyond it the cost is another one). Two
    checks, one per edge of the band, each failing on a plausible run (a slower machine or a costlier
    implementation fails the upper edge; a faster one the lower edge). Below the band the measured cost beats
    the claim in its own direction (cheaper): that check is marked ``better``, so a run below the band reads
    "better than claimed", not "reproduced". Guarantee (construction): the feedback object has no trainable
    parameter (counted by :func:`count_trainable`).
    """
    if int(n_trainable_feedback) < 0 or not np.isfinite(seconds_per_model) or seconds_per_model < 0 or around <= 1:
        raise ValueError(f"bad inputs: {n_trainable_feedback}, {seconds_per_model}, around={around}")
    minutes = AUTHORS_SECONDS_50_EPOCHS / 60
    lo, hi = AUTHORS_SECONDS_50_EPOCHS / around, AUTHORS_SECONDS_50_EPOCHS * around
    below = f"one model's 50 epochs not below {lo / 60:g} min (around {minutes:g})"
    checks = {f"one model's 50 epochs not above {hi / 60:g} min (around {minutes:g})": float(seconds_per_model) <= hi,
              below: float(seconds_per_model) >= lo}
    return ClaimResult(
        "Q6",
        checks=checks,
        better={below: float(seconds_per_model) < lo},
        guarantees={"linear feedback has no trainable parameter (counted on the feedback object)":
                    int(n_trainable_feedback) == 0},
        numbers={"trainable_feedback_parameters": int(n_trainable_feedback),
                 "seconds_per_model_50_epochs": float(seconds_per_model),
                 "authors_seconds_50_epochs": AUTHORS_SECONDS_50_EPOCHS,
                 "band_seconds": [lo, hi],
                 "over_authors": float(seconds_per_model) / AUTHORS_SECONDS_50_EPOCHS},
        reading=f"'it takes around {minutes:g} mins to run 50 epochs on a laptop' (App. A.7) read as the band "
                f"{lo / 60:g}-{hi / 60:g} min (a factor {around:g} either way: one rounded number, one laptop); "
                "below it the cost beats the claim (better than claimed), on different hardware",
        rule=f"one model's 50 epochs (measured, scaled to 50) within {lo / 60:g}-{hi / 60:g} min (the authors' "
             f"{minutes:g} min on a 14-core laptop CPU, a factor {around:g} either way; different hardware); below "
             "the band reads better than claimed; no trainable parameter on the feedback object is a guarantee "
             "(construction)")


def unjudged_bound_note(rows: Mapping[str, Any] | None, *, metric: str, unit: str, need: Mapping[str, float],
                        u_max: float, setting: str, flown: str, compare: tuple[str, str]) -> str:
    """The outcome at a thrust bound that is not judged, and why it cannot be judged there, with the number.

    ``rows``: the table rows flown at ``u_max`` under ``setting`` (None when not flown in this run); ``metric``
    a :class:`FlightRow` field; ``need`` what :func:`thrust_needed` returns; ``flown`` says which flights they
    are; ``compare`` = (a, b) names the two models whose order is stated.
    """
    why = (f"not judged at {u_max:g} N: the test vehicle needs {need['peak']:.2f} N per motor at the reference's "
           f"peak acceleration ({need['hover']:.2f} N to hover) against the {u_max:g} N bound"
           + (", so no model can track there" if need["peak"] > u_max else ""))
    if rows is None:
        return f"{setting}, {u_max:g} N: not flown in this run; {why}."
    values = {n: getattr(r, metric) for n, r in rows.items()}
    a, b = compare
    order = "worse than" if values[a] > values[b] else "better than or equal to"
    listed = ", ".join(f"{n} {v:.2f}" for n, v in values.items())
    return (f"{setting}, {u_max:g} N ({flown}): {metric} {listed} {unit}; every model "
            f"{min(values.values()):.2f}-{max(values.values()):.2f} {unit}, {a} {order} {b}; {why}.")
