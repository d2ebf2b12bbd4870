"""The Sec. 4 claims D2-D4 at every point of their why grids: Alg. 1 retrained with one setting changed, the
readings the paper leaves open, and the authors' networks (:mod:`fnnbook.why`).

Each function applies a rule of :mod:`fnnbook.rules.sec4` unchanged to the numbers of one grid point (the
evaluation of :mod:`fnnlib.paper.feedback_eval`, judged by :mod:`fnnbook.feedback_eval`) and says whether the claim holds there; none adds a criterion of its
own. The thresholds are the claims' (``d2_factor`` of D2, ``d3_ratio`` and ``d3_flat`` of D3).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fnnbook import why as W
from fnnbook.feedback_eval import d4_result, judge
from fnnlib.paper.feedback_eval import CentredFeedback, EvaluationSetup, field_errors
from fnnbook.rules import sec4
from fnnbook.results import ClaimResult

__all__ = ["AXES", "D3_READ", "FIRST", "METRIC", "READING_D3", "TITLES", "UNIT", "WINDOW", "WORDS", "Thresholds",
           "authors_checks", "counted", "curves_grid", "d2_settled", "d4_at_usage", "decay_axis", "levels_won", "measured",
           "setting_grid", "usage_grid", "window_grid"]

#: the reading of each claim the paper's words support, the one counted on the scoreboard (claims.yaml)
WORDS = {"D4": "as worded"}

#: the units of our grids: S initialisations of one ensemble, trained side by side on shared mini-batches of the
#: same randomized cases and judged on one nominal trajectory (they share data and batches, not weights)
UNIT = "seed (one ensemble)"

#: change key of a grid point -> (parameter, the recipe's value, what the paper states (None: silent or two
#: things), the silence it probes)
AXES: dict[str, tuple[str, Callable[[Mapping[str, Any]], Any], Any, str]] = {
    "optimizer": ("fb_optimizer", lambda r: r["optimizer"], None,
                  "the feedback's optimizer: Alg. 1 names Adam, App. A.3.3 (and the release) RMSprop"),
    "lr_times": ("fb_lr", lambda r: r["lr"], 0.01, "the feedback's learning rate (App. A.3.3 states 0.01)"),
    "iterations_times": ("fb_iterations", lambda r: r["iterations"], 2000,
                         "whether longer training helps (App. A.3.3 states 2000 iterations)"),
    "refresh_every": ("refresh_every", lambda r: r["refresh_every"], 1,
                      "the rollout refresh (Alg. 1 reruns the feedback at every iteration; ours every 10)"),
}
#: each setting's grid name in the summary line
TITLES = {"optimizer": "optimizer", "lr_times": "learning rate", "iterations_times": "iterations",
          "refresh_every": "rollout refresh"}

D3_READ = tuple(sec4.D3_READINGS)
WINDOW = W.Axis("window", ("whole record", "after settling"), "the window Fig. 5b's accuracy is scored over: "
                "the paper shows trajectories, no number", ours="whole record", kind="reading")
READING_D3 = W.Axis("reading", D3_READ, "what 'converges' means for a curve the release cuts at its stopping level",
                    ours="falls and ends flat", kind="reading")
METRIC = W.Axis("metric", sec4.D4_METRICS, "what 'better generalization' compares: Fig. S10 and the release's test "
                "show the change rate; the N-step cascade is not run for Sec. 4", ours="both", kind="reading")
FIRST = W.Axis("first estimate", ("h as learned", "h centred"), "each layer's first estimate at its input, where a "
               "learned h(0) need not be zero", ours="h as learned", kind="usage")


def decay_axis(betas: Sequence[float]) -> W.Axis:
    """The cascade's decay rate of Eq. (11) for the neural feedback: Sec. 4 states none (0: the paper profile's)."""
    return W.Axis("beta", tuple(float(b) for b in betas), "the cascade's decay for the neural feedback (Sec. 4 states "
                  "none)", ours=0.0, kind="usage")


@dataclass(frozen=True)
class Thresholds:
    """The claims' thresholds: D2's factor on the nominal model's relative RMSE, D3's loss ratio and flatness."""

    d2_factor: float
    d3_ratio: float
    d3_flat: float
    d1_factor: float = 1.5

    def rules(self) -> dict[str, str]:
        """Each claim's rule as its grids state it."""
        return {"D2": f"the frozen neural ODE with the feedback is within {self.d2_factor:g}x the nominal model's "
                      "relative RMSE in >= S-1 of S seeds (sec4.d2)",
                "D3": "the loss read as the point's reading says (sec4.D3_READINGS: falls and ends flat, falls, or "
                      "reaches the release's stopping level in the release's loss form) in >= S-1 of S seeds "
                      "(sec4.reading_holds_d3)",
                "D4": "the feedback beats the neural ODE in the point's metric at every S8 level with a residual and "
                      "every held-out level (sec4.d4, as-worded reading, the one counted)"}


def counted(result: ClaimResult | Mapping[str, Any], cid: str) -> str:
    """The verdict of claim ``cid``'s counted reading (:data:`WORDS`) in ``result`` (a ClaimResult or its JSON)."""
    r = result if isinstance(result, Mapping) else result.to_json()
    return r["readings"][WORDS[cid]]["verdict"] if cid in WORDS and r.get("readings") else r["verdict"]


def levels_won(s8: Mapping[str, Any]) -> np.ndarray:
    """Per seed: the S8 levels where the feedback is lower than the neural ODE in both metrics, the change-rate RMSE
    and the N-step error (the per-seed count of Fig. S10). ``s8``: :func:`field_errors`' numbers, (E, levels)."""
    s8 = {k: np.asarray(v) for k, v in s8.items()}
    return ((s8["rate_neural_feedback"] < s8["rate_neural_ode"])
            & (s8["err_N_neural_feedback"] < s8["err_N_neural_ode"])).sum(-1)


def d2_settled(numbers: Mapping[str, Any], th: Thresholds) -> ClaimResult:
    """D2's rule (:func:`sec4.d2`) over the window after the feedback's estimate has settled (per seed)."""
    return sec4.d2(rel_feedback=numbers["rel_rmse_settled_neural_feedback"], frozen_unchanged=True,
                   rel_nominal=numbers["rel_rmse_settled_nominal_neural_ode"], factor=th.d2_factor)


def measured(results: Mapping[str, Any], numbers: Mapping[str, Any], th: Thresholds) -> dict[str, Any]:
    """What one grid point measured, per claim: the counted verdict of D2-D4, D2 in both windows, D3 in each of
    its readings, and the per-seed numbers the figures show (D4: the S8 levels won, :func:`levels_won`)."""
    n = {k: np.asarray(v) for k, v in numbers.items() if not isinstance(v, dict)}
    d3 = {r: sec4.reading_holds_d3(r, ratio=n["ratio"], trend=n["last_window_trend_relative"], flat=th.d3_flat,
                                   release_final=n.get("release_form_final"), ratio_max=th.d3_ratio) for r in D3_READ}
    return {"verdict": {k: counted(results[k], k) for k in ("D2", "D3", "D4")},
            "D2_window": {"whole record": counted(results["D2"], "D2") == "reproduced",
                          "after settling": d2_settled(numbers, th).verdict == "reproduced"},
            "D3_reading": d3,
            "D2": n["rel_rmse_neural_feedback"] / n["rel_rmse_nominal_neural_ode"],
            "D2_settled": n["rel_rmse_settled_neural_feedback"] / n["rel_rmse_settled_nominal_neural_ode"],
            "settle_seconds": n["settle_seconds"],
            "D3_ratio": n["ratio"], "D3_trend": n["last_window_trend_relative"],
            "D3_release": n.get("release_form_final", np.full(n["ratio"].shape, np.nan)),
            "D4": levels_won(numbers["s8"])}


def setting_grid(key: str, cid: str, *, profile_recipe: Mapping[str, Any], profile: Mapping[str, Any],
                 points: Sequence[Mapping[str, Any]], point_measured: Sequence[Mapping[str, Any]],
                 th: Thresholds) -> W.WhyGrid:
    """Claim ``cid`` along the setting ``key`` of :data:`AXES`: the profile point (``profile``: what
    :func:`measured` gave for ``profile_recipe``) and the points that change that setting (``points``, each with
    its ``recipe`` and ``change``, and what it measured), sorted by the setting's value. D2 is crossed with the
    window, D3 with its readings; n is the fewest seeds at a point."""
    name, value_of, stated, silence = AXES[key]
    at = {value_of(profile_recipe): profile} | {value_of(p["recipe"]): m for p, m in zip(points, point_measured)
                                                if key in p["change"]}
    values = sorted(at, key=lambda v: (isinstance(v, str), v))
    axis = W.Axis(name, tuple(values), silence, paper=stated, ours=value_of(profile_recipe))
    if cid == "D2":
        holds = np.array([[at[v]["D2_window"][w] for w in WINDOW.values] for v in values])
        keys, axes = ("D2", "D2_settled", "settle_seconds"), (axis, WINDOW)
    elif cid == "D3":
        holds = np.array([[at[v]["D3_reading"][r] for r in D3_READ] for v in values])
        keys, axes = ("D3_ratio", "D3_trend", "D3_release"), (axis, READING_D3)
    else:
        holds = np.array([at[v]["verdict"][cid] == "reproduced" for v in values])
        keys, axes = (cid,), (axis,)
    nums = {k: [np.nan_to_num(at[v][k], nan=-1.0).tolist() for v in values] for k in keys}
    n = min(len(at[v][keys[0]]) for v in values)
    return W.WhyGrid(axes, holds, n, th.rules()[cid], numbers=nums, title=TITLES[key], unit=UNIT)


def window_grid(numbers: Mapping[str, Any], th: Thresholds, *, units: int, unit: str, networks: str,
                title: str) -> W.WhyGrid:
    """D2 over the window (:data:`WINDOW`): the whole record and after the estimate has settled."""
    whole = sec4.d2(rel_feedback=numbers["rel_rmse_neural_feedback"], rel_nominal=numbers["rel_rmse_nominal_neural_ode"],
                    frozen_unchanged=True, factor=th.d2_factor).verdict == "reproduced"
    holds = np.array([whole, d2_settled(numbers, th).verdict == "reproduced"])
    nums = {"ratio": [np.asarray(numbers["rel_rmse_neural_feedback"]) / np.asarray(numbers["rel_rmse_nominal_neural_ode"]),
                      np.asarray(numbers["rel_rmse_settled_neural_feedback"])
                      / np.asarray(numbers["rel_rmse_settled_nominal_neural_ode"])],
            "settle_seconds": np.asarray(numbers["settle_seconds"])}
    return W.WhyGrid((WINDOW,), holds, units, th.rules()["D2"], numbers=nums, title=title, unit=unit, networks=networks)


def curves_grid(curves: Mapping[str, np.ndarray], th: Thresholds) -> W.WhyGrid:
    """D3's readings (:data:`READING_D3`) over the release's own loss curves, one unit per training run, each
    curve's last value its final loss in the release's form."""
    cols = list(curves.values())
    ratio_t, trend_t = (np.concatenate(v) for v in zip(*(sec4.loss_convergence(c) for c in cols)))
    final_t = np.array([c[-1] for c in cols])
    holds = np.array([sec4.reading_holds_d3(r, ratio=ratio_t, trend=trend_t, release_final=final_t,
                                            ratio_max=th.d3_ratio, flat=th.d3_flat) for r in D3_READ])
    return W.WhyGrid((READING_D3,), holds, len(cols), th.rules()["D3"], unit="training run", networks="authors",
                     numbers={"ratio": ratio_t, "trend": trend_t, "final": final_t,
                              "iterations": [len(c) for c in cols]}, title="authors' loss curves: reading")


def d4_at_usage(f: Any, h: Any, E: int, setup: EvaluationSetup, beta: float) -> tuple[list[bool], np.ndarray]:
    """D4's counted reading in every metric of :data:`METRIC` with the feedback ``h`` used at the cascade's decay
    ``beta``; and the S8 levels won in both metrics per seed (:func:`levels_won`)."""
    s8, held = (field_errors(f, h, x, ft, setup, E, beta=beta)
                for x, ft in ((setup.x_s8, setup.f_s8), (setup.x_held, setup.f_held)))
    return [counted(d4_result(s8, held, setup, m), "D4") == "reproduced" for m in METRIC.values], levels_won(s8)


def usage_grid(f: Any, h: Any, E: int, setup: EvaluationSetup, th: Thresholds, *, betas: Sequence[float], unit: str,
               networks: str, title: str) -> W.WhyGrid:
    """D4's counted reading at every metric x decay (:func:`decay_axis`) x first estimate (:data:`FIRST`: ``h``
    as learned, or :class:`CentredFeedback` so that h(0) = 0)."""
    decay = decay_axis(betas)
    holds = np.zeros((len(METRIC.values), len(decay.values), len(FIRST.values)), bool)
    won = np.zeros((len(decay.values), len(FIRST.values), E))
    for k, first in enumerate(FIRST.values):
        for j, b in enumerate(decay.values):
            holds[:, j, k], won[j, k] = d4_at_usage(f, h if first == "h as learned" else CentredFeedback(h), E,
                                                    setup, b)
    return W.WhyGrid((METRIC, decay, FIRST), holds, E, th.rules()["D4"], numbers={"S8_levels_won_both": won},
                     title=title, unit=unit, networks=networks)


def authors_checks(f: Any, h: Any, f_dr: Any, setup: EvaluationSetup, ours: Mapping[str, ClaimResult],
                   networks: Mapping[str, str], th: Thresholds) -> tuple[dict[str, W.AuthorsCheck], dict[str, Any]]:
    """D1, D2 and D4 with the authors' nominal neural ODE ``f``, neural feedback ``h`` and domain-randomized
    ``f_dr`` (one network each: n = 1) on ``setup`` (the release's spiral), each beside our counted verdict in
    ``ours`` and naming the networks it judged (``networks``, by claim); and their numbers."""
    theirs, numbers = judge(f, h, setup, 1, loss=None, factor=th.d2_factor, ratio_max=th.d3_ratio, flat=th.d3_flat,
                            f_dr=f_dr, d1_factor=th.d1_factor)
    return {cid: W.AuthorsCheck(verdict=counted(theirs[cid], cid), ours=counted(ours[cid], cid),
                                checks=theirs[cid].checks, networks=networks[cid], n=1) for cid in networks}, numbers
