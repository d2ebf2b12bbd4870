"""The Sec. 3 rules at one why-grid point: the claim's own rule, unchanged, on one point's numbers."""

from __future__ import annotations

import numpy as np
import pytest

from fnnbook.rules import why_sec3

WIN = [0.10, 0.11, 0.09, 0.10, 0.12]
LOSE = [0.20, 0.21, 0.19, 0.22, 0.20]
BIG = [5.0, 5.1, 4.9, 5.2, 5.0]


def test_s3_holds_where_decay_beats_both_and_fails_where_the_plain_ode_wins() -> None:
    clean = dict(decay=[WIN, LOSE], no_decay=[WIN, BIG], neural_ode=[LOSE, BIG])  # decay helps under noise
    assert why_sec3.holds(why_sec3.s3_point(noise_std=0.003, **clean))
    lost = clean | {"neural_ode": [LOSE, WIN]}  # the open-loop ODE beats the decayed cascade at this level
    r = why_sec3.s3_point(noise_std=0.01, **lost)
    assert not why_sec3.holds(r)
    assert not r.checks["decay_better_than_neural_ode_at_std_0.01"]
    assert why_sec3.holds(r, "decay_better_at_std_0.01")
    with pytest.raises(ValueError, match="> 0"):
        why_sec3.s3_point(noise_std=0.0, **clean)
    with pytest.raises(KeyError, match="no check"):
        why_sec3.holds(r, "made_up")


def test_s8_marks_the_level_where_the_feedback_loses() -> None:
    nn, fb = np.array([LOSE, LOSE, LOSE]), np.array([WIN, LOSE[::-1], WIN])  # level 1: no paired win
    got = why_sec3.s8_levels(rate_neural_ode=nn, rate_feedback=np.array([WIN] * 3), err_N_neural_ode=nn,
                             err_N_feedback=fb, offsets=[[-1, 0, 0], [0, 0, 0], [1, 0, 0]])
    assert got.tolist() == [True, False, True]
    with pytest.raises(ValueError, match="one row per residual level"):
        why_sec3.s8_levels(rate_neural_ode=nn, rate_feedback=nn, err_N_neural_ode=nn, err_N_feedback=fb,
                           offsets=[[0, 0, 0]])
