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


def test_s5_point_holds_where_both_balls_are_twice_the_measured_limit() -> None:
    """Theorem 1's balls at L = 10 with gamma = 1: |x~| <= 0.1, |f~| <= 2 (gamma lam_M / lam_m + gamma). A feedback
    whose |x~| ends at 0.02 and |f~| at 0.5 leaves the balls 5x and 4x its limit (conservative); at 0.08, 1.25x."""
    import torch

    S, T = 5, 40
    L_sweep = [5.0, 10.0, 20.0]
    t = torch.arange(T, dtype=torch.float64)
    after, last = t >= 10, t >= 20
    gamma = torch.ones(S, dtype=torch.float64) + 0.01 * torch.arange(S)
    limit = 0.5 * gamma[:, None] / torch.tensor(L_sweep, dtype=torch.float64)  # (S, G): inside gamma / L, falling

    def point(x_level: float):
        x = torch.full((S, T), x_level, dtype=torch.float64)
        f = torch.full((S, T), 0.5, dtype=torch.float64)
        return why_sec3.s5_point(L=10.0, gamma=gamma, x_feedback=x, f_feedback=f, x_continuous=x, f_continuous=f,
                                 limit_x=limit, L_sweep=L_sweep, after_transient=after, last_half=last,
                                 conservative_ratio=2.0)

    r, ratio_x = point(0.02)
    assert why_sec3.holds(r)
    np.testing.assert_allclose(ratio_x, (gamma / 10.0 / 0.02).numpy())
    r, ratio_x = point(0.08)
    assert not why_sec3.holds(r) and ratio_x.max() < 2.0


def test_s10_point_reads_the_band_and_the_settling_window() -> None:
    """An error at 0.1 that jumps to 1 at the switch and is back 0.2 s later leaves the band (2 x 0.1) and is
    back within 0.5 s, not within 0.1 s; a neural ODE error of 1 after the switch loses to it."""
    import torch

    t = torch.arange(1001, dtype=torch.float64) * 0.01  # 10 s, switch at 5 s
    err = 0.1 + 0.9 * ((t >= 5.0) & (t < 5.2)).double()
    errs = err[None] * (1 + 0.01 * torch.arange(5, dtype=torch.float64))[:, None]  # (S, T): five seeds
    e = {"x": (t, errs), "f": (t, errs), "multistep": (t[:-10], errs[:, :-10])}
    kw = dict(errors=e, rate_err_neural_ode=torch.ones_like(errs), t=t, t_switch=5.0, steady_window=1.0)
    assert why_sec3.holds(why_sec3.s10_point(**kw, band_factor=2.0, settle=0.5))
    assert not why_sec3.holds(why_sec3.s10_point(**kw, band_factor=2.0, settle=0.1))
    assert not why_sec3.holds(why_sec3.s10_point(**kw, band_factor=20.0, settle=0.5))  # never leaves the band
