"""Uneven sample times: uniform times equal the ``Ts`` path to 1e-12, a linear plant at random intervals matches
its closed-form discretisation, and bad times are refused before any work."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.feedback import DEFAULT_TUNE_RECIPE, cascade_sweep, Gains, Measurement, cascade_depths
from fnnlib.systems import LinearSystem
from fnnlib.feedback.sampling import check_times

from tests.feedback.test_inputs import A, B, F64, TS

T = 80
C = torch.tensor([[1.0, 0.0]], dtype=F64)
PLANT = LinearSystem(A, B)


def _gain():
    return F.place_observer_gain(torch.eye(2, dtype=F64) + TS * A, TS * C, [0.6, 0.7])


def _data(B_=2):
    g = torch.Generator().manual_seed(0)
    x = torch.randn(B_, T, 2, generator=g, dtype=F64).cumsum(-2) * 0.1
    u = torch.randn(B_, T, 1, generator=g, dtype=F64)
    return x, u


def test_uniform_times_equal_the_step_path():
    x, u = _data()
    t = torch.arange(T, dtype=F64) * TS
    for N, L, beta in [(1, 2.0, 0.0), (6, 3.0, 0.1)]:
        a = cascade_depths(PLANT, x, TS, N, F.Gains(L, beta), u=u)
        b = cascade_depths(PLANT, x, None, N, F.Gains(L, beta), u=u, measurement=F.Measurement(t=t))
        torch.testing.assert_close(a, b, rtol=0, atol=1e-12)
    gap = x.clone()
    gap[:, 20:30] = float("nan")
    torch.testing.assert_close(F.cascade_predict(PLANT, gap, TS, 5, F.Gains(3.0, 0.1), u=u),
                               F.cascade_predict(PLANT, gap, None, 5, F.Gains(3.0, 0.1), u=u,
                                                 measurement=F.Measurement(t=t)), rtol=0, atol=1e-12)
    obs_ts = F.MeasuredFeedback(PLANT, TS, L=_gain(), measurement=F.Measurement(C=C), A=A)
    obs_t = F.MeasuredFeedback(PLANT, None, L=_gain(), measurement=F.Measurement(C=C), A=A)
    y = x @ C.T
    torch.testing.assert_close(obs_ts.observe(y, u).x_hat, obs_t.observe(y, u, t=t).x_hat, rtol=0, atol=1e-12)
    torch.testing.assert_close(F.cascade_predict(PLANT, y, TS, 5, F.Gains(2.0, 0.1), u=u, observer=obs_ts),
                               F.cascade_predict(PLANT, y, None, 5, F.Gains(2.0, 0.1), u=u,
                                                 measurement=F.Measurement(t=t), observer=obs_t),
                               rtol=0, atol=1e-12)
    torch.testing.assert_close(cascade_sweep(PLANT, x, TS, 4, Gains.sweep(torch.tensor([1.0, 2.0]), 0.1), u=u),
                               cascade_sweep(PLANT, x, None, 4, Gains.sweep(torch.tensor([1.0, 2.0]), 0.1), u=u,
                                             measurement=Measurement(t=t)),
                               rtol=0, atol=1e-12)
    for method in ("euler", "rk4"):
        torch.testing.assert_close(F.rollout_predict(PLANT, x, TS, 4, solver=F.Solver(method), u=u),
                                   F.rollout_predict(PLANT, x, None, 4, solver=F.Solver(method), u=u,
                                                     measurement=F.Measurement(t=t)), rtol=0, atol=1e-12)
    recipe = F.TuneRecipe(L0=2.0, beta0=0.1, iterations=3, lr=0.1)
    a = F.tune_gains(PLANT, x, TS, 5, u=u, recipe=recipe)
    b = F.tune_gains(PLANT, x, None, 5, u=u, recipe=recipe, measurement=F.Measurement(t=t))
    torch.testing.assert_close(a.L, b.L, rtol=0, atol=1e-12)


def test_a_linear_plant_at_random_intervals_matches_its_closed_form():
    g = torch.Generator().manual_seed(1)
    t = torch.cumsum(0.02 + 0.08 * torch.rand(3, T, generator=g, dtype=F64), -1)  # one grid per record
    x0 = torch.randn(3, 2, generator=g, dtype=F64)
    steps = torch.diff(t, dim=-1)
    xs = [x0]
    for k in range(T - 1):  # the exact (zero-input) discretisation, interval by interval
        Phi = torch.linalg.matrix_exp(A * steps[:, k, None, None])
        xs.append((Phi @ xs[-1][..., None])[..., 0])
    x = torch.stack(xs, -2)
    N = 3
    u = torch.zeros(3, T, 1, dtype=F64)
    exact = F.rollout_predict(PLANT, x, None, N, solver=F.Solver("dopri5", rtol=1e-11, atol=1e-12), u=u,
                              measurement=F.Measurement(t=t))
    torch.testing.assert_close(exact[:, : T - N], x[:, N:], rtol=0, atol=1e-8)
    # the cascade with L = 0 is the Euler discretisation at the record's own steps: prod (I + Delta_k A)
    euler = F.cascade_predict(PLANT, x, None, N, F.Gains(0.0), u=u, measurement=F.Measurement(t=t))
    ref = x.clone()
    for j in range(N):
        idx = torch.clamp(torch.arange(T) + j, max=T - 2)  # the last interval repeated past the end
        ref = ref + steps[:, idx, None] * (ref @ A.T)
    torch.testing.assert_close(euler, ref, rtol=0, atol=1e-12)


def test_one_batched_call_for_records_with_their_own_times():
    x, u = _data(3)
    g = torch.Generator().manual_seed(2)
    t = torch.cumsum(TS * (0.5 + torch.rand(3, T, generator=g, dtype=F64)), -1)
    both = F.cascade_predict(PLANT, x, None, 5, F.Gains(2.0, 0.1), u=u, measurement=F.Measurement(t=t))
    for b in range(3):
        torch.testing.assert_close(both[b], F.cascade_predict(PLANT, x[b], None, 5, F.Gains(2.0, 0.1), u=u[b],
                                                              measurement=F.Measurement(t=t[b])),
                                   rtol=0, atol=1e-12)


@pytest.mark.parametrize("bad, match", [
    (lambda t: t.flip(-1), "strictly increasing"),
    (lambda t: torch.cat([t[:5], t[4:5], t[6:]]), "strictly increasing"),
    (lambda t: torch.where(torch.arange(T) == 7, float("nan"), t), "hold a NaN"),
    (lambda t: t[:-1], "one time per sample"),
    (lambda t: t.long(), "floating-point tensor"),
])
def test_bad_times_are_refused_before_any_work(bad, match):
    x, u = _data(1)
    t = torch.arange(T, dtype=F64) * TS
    calls = []

    def counting(tt, xx, uu=None):
        calls.append(1)
        return PLANT(tt, xx, uu)

    obs = F.MeasuredFeedback(counting, None, L=_gain(), measurement=F.Measurement(C=C), A=A)
    for call in (lambda: F.cascade_predict(counting, x[0], None, 3, F.Gains(1.0), u=u[0],
                                           measurement=F.Measurement(t=bad(t))),
                 lambda: obs.observe(x[0] @ C.T, u[0], t=bad(t)),
                 lambda: F.rollout_predict(counting, x[0], None, 3, u=u[0], measurement=F.Measurement(t=bad(t))),
                 lambda: F.tune_gains(counting, x[0], None, 3, u=u[0], recipe=DEFAULT_TUNE_RECIPE,
                                      measurement=F.Measurement(t=bad(t)))):
        with pytest.raises((ValueError, TypeError), match=match):
            call()
    assert not calls


def test_t_together_with_Ts_is_refused():
    x, _ = _data(1)
    with pytest.raises(TypeError, match="either the sample step Ts or the sample times t, not both"):
        F.cascade_predict(PLANT, x[0], TS, 3, F.Gains(1.0),
                          measurement=F.Measurement(t=torch.arange(T, dtype=F64) * TS))
    with pytest.raises(TypeError, match="give the sample step Ts or the sample times t"):
        F.cascade_predict(PLANT, x[0], None, 3, F.Gains(1.0))
    with pytest.raises(ValueError, match="at least 2 samples"):
        check_times(torch.zeros(1, dtype=F64), None, torch.zeros(1, 2, dtype=F64))
