"""paired_win: the rule every over-seeds comparison uses (>= S-1 of S seeds and a 90 % interval below 0)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from fnnlib import paired_win


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
