"""paired_win: the rule every over-seeds comparison uses (>= S-1 of S seeds and a 90 % interval below 0)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from fnnlib.stats import paired_win


def test_clear_win():
    r = paired_win([1.0, 1.1, 0.9, 1.0, 1.2], [2.0, 2.2, 1.8, 2.1, 2.0])
    assert r["win"] and r["wins"] == 5 and r["ci_high"] < 0


def test_interval_matches_scipy_t_interval():
    a, b = np.array([1.0, 2.0, 1.5, 1.2, 0.8]), np.array([1.4, 2.1, 2.5, 1.3, 1.0])
    r = paired_win(a, b)
    lo, hi = stats.t.interval(0.90, 4, loc=np.mean(a - b), scale=stats.sem(a - b))
    assert r["ci_low"] == pytest.approx(lo) and r["ci_high"] == pytest.approx(hi)


def test_three_of_five_is_not_a_win_even_with_a_large_mean():
    r = paired_win([1.0, 1.0, 1.0, 5.1, 5.1], [10.0, 10.0, 10.0, 5.0, 5.0])
    assert r["wins"] == 3 and not r["win"]


def test_four_of_five_but_an_interval_across_zero_is_not_a_win():
    r = paired_win([1.0, 1.0, 1.0, 1.0, 9.0], [1.1, 1.1, 1.1, 1.1, 1.0])
    assert r["wins"] == 4 and r["ci_high"] > 0 and not r["win"]


def test_bad_input():
    with pytest.raises(ValueError, match="paired"):
        paired_win([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="at least 2 seeds"):
        paired_win([1.0], [2.0])
    with pytest.raises(ValueError, match="finite"):
        paired_win([1.0, float("nan")], [2.0, 3.0])
    with pytest.raises(ValueError, match="min_wins"):
        paired_win([1.0, 2.0], [2.0, 3.0], min_wins=3)


def test_copies_of_one_unit_count_once():
    """A flight copied for every trained network is one unit, not many: with unit ids it counts once."""
    a, b = [1.0, 1.0, 1.0, 2.0, 2.1], [1.5, 1.5, 1.5, 2.6, 2.5]
    # without ids, the three copies of unit 0 would make 5 "seeds" and a win
    assert paired_win(a, b)["seeds"] == 5 and paired_win(a, b)["win"]
    r = paired_win(a, b, units=[0, 0, 0, 1, 2])
    assert r["seeds"] == 3 and r["pairs"] == 5 and r["wins"] == 3
    assert r == {**paired_win([1.0, 2.0, 2.1], [1.5, 2.6, 2.5]), "pairs": 5}
    with pytest.raises(ValueError, match="at least 2 seeds"):  # copies of one unit alone compare nothing
        paired_win([1.0] * 5, [2.0] * 5, units=["F0"] * 5)


def test_replicates_within_a_unit_are_averaged():
    """Networks flown on one disturbance against a model without a network: the unit is the disturbance."""
    trained = [1.0, 3.0, 2.0, 2.0]  # two networks on each of two disturbances
    r = paired_win(trained, [2.5, 2.5, 2.5, 2.5], units=["F0", "F0", "F1", "F1"], min_wins=2)
    assert r["seeds"] == 2 and r["mean_diff"] == pytest.approx(-0.5) and r["wins"] == 2
    with pytest.raises(ValueError, match="one id per pair"):
        paired_win([1.0, 2.0], [2.0, 3.0], units=[0])
