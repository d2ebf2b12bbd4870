"""Q3-Q5 at the points of their why grid: the flight test's own rules read from one record per thrust bound."""

from __future__ import annotations

import numpy as np
import pytest

from fnnbook.rules import why_quadrotor as WQ

UNITS = [0, 1, 2, 3, 4]
SPREAD = np.array([0.0, 0.01, -0.01, 0.02, -0.02])


def flights(level: float, inside: float = 1.0) -> dict:
    """One model's numbers over the five units: tracking RMSE and first-step error around ``level``."""
    v = (level + SPREAD).tolist()
    return {"rmse": v, "acc": v, "diverged": [False] * 5, "theorem2_inside": [inside] * 5}


def record(adapnn: dict[float, float], adapfnn: dict[float, float], inside: float = 1.0) -> dict:
    """One cost's record: FNN best (0.1), Neural beats Nomi and MLP; AdapNN and AdapFNN per gain."""
    fixed = {"Nomi": flights(0.5), "Neural": flights(0.2), "MLP": flights(0.3), "FB": flights(0.4),
             "FNN": flights(0.1)}
    return fixed | {"AdapNN": {str(g): flights(v) for g, v in adapnn.items()},
                    "AdapFNN": {str(G): flights(v, inside) for G, v in adapfnn.items()}}


def test_q3_holds_along_adapnns_gain_only_where_fnn_beats_it() -> None:
    rec = {"as_written": record({1.0: 0.05, 2.0: 0.3}, {8.0: 0.11, 16.0: 0.2})}
    res = {(4.0, "as_written", g, G): WQ.setting(rec, "as_written", g, G, units=UNITS)
           for g in (1.0, 2.0) for G in (8.0, 16.0)}
    grid = dict(bounds=[4.0], adapnn_grid=[1.0, 2.0], Gamma_grid=[8.0, 16.0], adapnn_gamma=2.0, Gamma=8.0)
    # AdapNN at gain 1 tracks better than FNN: Q3 fails there, holds at gain 2
    assert WQ.holds_along_gains(res, "Q3", "as_written", **grid).tolist() == [[False, True]]
    # Q5 along Gamma (AdapNN at 2): AdapFNN at 8 is within 25 % and above FNN; at 16 twice FNN's error
    assert WQ.holds_along_gains(res, "Q5", "as_written", **grid).tolist() == [[True, False]]
    assert WQ.failing_checks(res[(4.0, "as_written", 1.0, 8.0)]["Q3"]) == [
        "FNN beats AdapNN (paired over 5 units, >= 4 of 5)"]  # the setting's label dropped
    assert WQ.failing_checks(res[(4.0, "as_written", 2.0, 8.0)]["Q3"]) == []
    assert WQ.mean_rmse(rec, "as_written", "AdapNN", 2.0, 8.0) == pytest.approx(0.3)


def test_a_failed_theorem2_guarantee_is_no_point_that_holds() -> None:
    rec = {"as_written": record({2.0: 0.3}, {8.0: 0.11}, inside=0.5)}
    r = WQ.setting(rec, "as_written", 2.0, 8.0, units=UNITS)
    assert r["Q5"] is None and WQ.failing_checks(r["Q5"]) == ["Theorem 2"]
    res = {(4.0, "as_written", 2.0, 8.0): r}
    assert not WQ.holds_along_gains(res, "Q5", "as_written", bounds=[4.0], adapnn_grid=[2.0], Gamma_grid=[8.0],
                                    adapnn_gamma=2.0, Gamma=8.0).any()


def test_joined_over_the_costs_fails_when_one_cost_fails() -> None:
    rec = {"as_written": record({2.0: 0.3}, {8.0: 0.11}), "as_flown": record({2.0: 0.05}, {8.0: 0.11})}
    at = dict(adapnn_gamma={"as_written": 2.0, "as_flown": 2.0}, Gamma=8.0, units=UNITS)
    assert WQ.joined_at(rec, "Q3", costs=["as_written"], **at)[0] == "reproduced"
    verdict, checks = WQ.joined_at(rec, "Q3", costs=["as_written", "as_flown"], **at)
    assert verdict != "reproduced" and not all(checks.values())
    with pytest.raises(KeyError, match="not flown at the gain"):
        WQ.setting(rec, "as_written", 3.0, 8.0, units=UNITS)


def test_the_gain_axis_is_gamma_for_q5_and_adapnns_gain_otherwise() -> None:
    kw = dict(adapnn_grid=[1.0, 2.0], Gamma_grid=[8.0, 16.0], adapnn_gamma=2.0, Gamma=8.0)
    q5, q3 = WQ.gain_axis("Q5", **kw), WQ.gain_axis("Q3", **kw)
    assert (q5.name, q5.values, q5.ours) == ("Gamma", (8.0, 16.0), 8.0)
    assert (q3.name, q3.values, q3.ours) == ("Gamma_adapnn", (1.0, 2.0), 2.0)
    assert q3.open and q5.open  # neither gain is stated by the paper
