r"""The flight test's claims Q3-Q5 at every point of their why grid (Sec. 5.2.2, App. A.5.4; Eqs. (28)-(30)).

A point is a thrust bound :math:`u_{max}` of Eq. (28), a cost variant, AdapNN's gain (App. A.5.4) and AdapFNN's
:math:`\Gamma` (Eq. (30)). Each function reads the point's flight record (:func:`fnnlib.quadrotor.evaluation.at_gains`)
and applies the flight test's own rules (:func:`fnnbook.rules.quadrotor.rules_at_setting`) unchanged; none adds a
criterion of its own.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from typing import Any

import numpy as np

from fnnlib.quadrotor.evaluation import at_gains
from fnnbook.rules.quadrotor import SIX, joined_verdict, rules_at_setting
from fnnbook.why import Axis
from fnnbook.results import ClaimResult

__all__ = ["CLAIMS", "failing_checks", "gain_axis", "holds_along_gains", "joined_at", "mean_rmse", "setting"]

#: the claims the grid judges: Q3 (tracking), Q4 (first-step prediction), Q5 (AdapFNN against FNN)
CLAIMS = ("Q3", "Q4", "Q5")


def setting(record: Mapping[str, Any], cost: str, adapnn_gamma: float, Gamma: float, *,
            units: Sequence[Hashable]) -> dict[str, ClaimResult | None]:
    r"""Q3-Q5 at one setting of one record (ours or the authors'): the seven models' tracking and first-step
    RMSEs under ``cost`` with AdapNN at ``adapnn_gamma`` and AdapFNN at ``Gamma``, judged by
    :func:`rules_at_setting` (Q3 and Q4 see AdapNN at its gain, Q5 sees AdapFNN at :math:`\Gamma`)."""
    numbers = {n: at_gains(record[cost], n, adapnn_gamma, Gamma) for n in (*SIX, "AdapFNN")}
    return rules_at_setting({n: v["rmse"] for n, v in numbers.items()}, {n: v["acc"] for n, v in numbers.items()},
                            numbers["AdapFNN"]["theorem2_inside"], units=units, label=cost)


def holds_along_gains(results: Mapping[tuple, Mapping[str, ClaimResult | None]], claim: str, cost: str, *,
                      bounds: Sequence[float], adapnn_grid: Sequence[float], Gamma_grid: Sequence[float],
                      adapnn_gamma: float, Gamma: float) -> np.ndarray:
    r"""Where ``claim`` reads *reproduced* under ``cost``, bool (bounds, gains): along AdapNN's gain (AdapFNN at the
    profile's ``Gamma``) for Q3 and Q4, along :math:`\Gamma` (AdapNN at its chosen ``adapnn_gamma``) for Q5.

    ``results``: :func:`setting`'s results keyed by ``(u_max, cost, adapnn gain, Gamma)``. A point whose result is
    missing (Q5's Theorem 2 guarantee failed) does not hold.
    """
    pairs = [(adapnn_gamma, G) for G in Gamma_grid] if claim == "Q5" else [(g, Gamma) for g in adapnn_grid]
    return np.array([[(r := results[(u, cost, g, G)][claim]) is not None and r.verdict == "reproduced"
                      for g, G in pairs] for u in bounds], dtype=bool)


def failing_checks(result: ClaimResult | None) -> list[str]:
    """The checks of a claim's result that fail, named without their setting label (``"as_written: X"`` -> X);
    a missing result (its Theorem 2 guarantee failed) fails on Theorem 2."""
    if result is None:
        return ["Theorem 2"]
    return [k.split(": ", 1)[1] for k, v in result.checks.items() if not v]


def gain_axis(claim: str, *, adapnn_grid: Sequence[float], Gamma_grid: Sequence[float], adapnn_gamma: float,
              Gamma: float) -> Axis:
    r"""The gain axis of ``claim``'s grid: AdapFNN's :math:`\Gamma` of Eq. (30) for Q5, AdapNN's gain for Q3 and Q4
    (neither is stated: App. A.5.4 says AdapNN's is "adjusted for optimal performance"); the profile's value is
    ``ours``."""
    if claim == "Q5":
        return Axis("Gamma", tuple(Gamma_grid), "AdapFNN's adaptation gain of Eq. (30) is not stated", ours=Gamma)
    return Axis("Gamma_adapnn", tuple(adapnn_grid), "AdapNN's gain: 'adjusted for optimal performance', no value",
                ours=adapnn_gamma)


def joined_at(record: Mapping[str, Any], claim: str, *, costs: Sequence[str], adapnn_gamma: Mapping[str, float],
              Gamma: float, units: Sequence[Hashable]) -> tuple[str, dict[str, bool]]:
    """``claim``'s verdict and checks over every cost at the profile's gains (AdapNN at each cost's
    ``adapnn_gamma[cost]``), joined as the flight test joins them (:func:`joined_verdict`)."""
    return joined_verdict([setting(record, c, adapnn_gamma[c], Gamma, units=units)[claim] for c in costs])


def mean_rmse(record: Mapping[str, Any], cost: str, name: str, adapnn_gamma: float, Gamma: float) -> float:
    """Model ``name``'s mean tracking RMSE over the units under ``cost`` (AdapNN at ``adapnn_gamma``, AdapFNN at
    ``Gamma``)."""
    return float(np.mean(at_gains(record[cost], name, adapnn_gamma, Gamma)["rmse"]))
