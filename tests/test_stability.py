"""Theorem 1's balls, the continuous-time observer against a closed form, settling and growth measures."""

from __future__ import annotations

import copy
import math

import pytest
import torch

from fnnlib import LinearFeedback
from fnnlib.feedback import Gains
from fnnlib.models import mlp
from fnnlib.systems import Spiral
from fnnlib.stability import (
    discrete_residual,
    divergence_transition,
    gain_eigen_bounds,
    growth_factor,
    iss_bound,
    observe_continuous,
    reconvergence,
    reconvergence_rows,
    scaled_error_norm,
    settling_time,
    theorem1_balls,
)

F64 = torch.float64


def test_balls_for_a_known_gain():
    L = torch.tensor([[5.0, 0.0], [0.0, 20.0]], dtype=F64)
    assert gain_eigen_bounds(L, 2) == pytest.approx((5.0, 20.0))
    b1, b2 = theorem1_balls(L, 2.0, 2)
    assert (b1, b2) == pytest.approx((2.0 / 5.0, 2.0 * 20.0 / 5.0 + 2.0))
    assert theorem1_balls(20.0, 3.0, 2) == pytest.approx((0.15, 6.0))  # L = 20 I: B2 radius = 2 gamma


def test_eigen_bounds_of_a_non_symmetric_gain():
    L = torch.tensor([[2.0, 3.0], [0.0, 2.0]], dtype=F64)  # symmetric part eigenvalues 0.5, 3.5
    lam_m, lam_M = gain_eigen_bounds(L, 2)
    assert lam_m == pytest.approx(0.5)
    assert lam_M == pytest.approx(float(torch.linalg.svdvals(L).max()))


@pytest.mark.parametrize("L", [0.0, -1.0, torch.tensor([[1.0, 3.0], [3.0, 1.0]])])
def test_balls_need_a_positive_definite_gain(L):
    with pytest.raises(ValueError, match="positive-definite gain"):
        theorem1_balls(L, 1.0, 2)


def test_balls_refuse_a_bad_gamma():
    with pytest.raises(ValueError, match="gamma must be finite and >= 0"):
        theorem1_balls(1.0, float("nan"), 2)


def test_discrete_residual_of_an_euler_sequence_is_its_input():
    W = torch.tensor([[0.0, 1.0], [-1.0, 0.0]], dtype=F64)
    d = torch.tensor([[0.5, -0.25]], dtype=F64).expand(9, 2)
    x = [torch.tensor([1.0, 2.0], dtype=F64)]
    for dk in d:
        x.append(x[-1] + 0.1 * (W @ x[-1] + dk))
    x = torch.stack(x)
    torch.testing.assert_close(discrete_residual(x, x @ W.T, 0.1), d, rtol=0, atol=1e-13)
    with pytest.raises(ValueError, match="shape mismatch"):
        discrete_residual(x, x[:-1], 0.1)


def test_iss_bound_closed_form_for_scalar_gain():
    Ts, lam, gamma = 0.01, 150.0, 4.0  # A = -0.5 I: ||A^k|| = 0.5^k
    b = iss_bound(lam, Ts, gamma, 6, e0=2.0)
    k = torch.arange(6, dtype=F64)
    torch.testing.assert_close(b, 0.5**k * 2.0 + Ts * gamma * (1 - 0.5**k) / 0.5, rtol=1e-14, atol=0)
    assert float(iss_bound(250.0, Ts, 1.0, 50)[-1]) > 1e6  # rho = 1.5: the bound itself diverges


def test_continuous_observer_closed_form_for_a_constant_residual():
    """f_neural = f_true + c: x_tilde' = -l x_tilde - c, so x_tilde(t) = -c (1 - e^{-l t}) / l exactly."""
    true = Spiral(3.0, 0.05, 10.0)
    c = torch.tensor([1.5, -2.0], dtype=F64)
    l = 8.0
    t = torch.linspace(0.0, 2.0, 41, dtype=F64)
    x, est = observe_continuous(true, lambda tt, z: true(tt, z) + c, l, torch.tensor([9.0, 0.0]), t)
    expected = -c * (1 - torch.exp(-l * t))[:, None] / l
    # dopri5 at rtol = atol = 1e-9 on O(10) states: 1e-7
    torch.testing.assert_close(x - est.x_hat, expected, rtol=0, atol=1e-7)
    torch.testing.assert_close(x, true.exact_solution(torch.tensor([9.0, 0.0]), t), rtol=0, atol=1e-7)
    # f_tilde = f_true - f_hat = -c - l x_tilde
    torch.testing.assert_close(true.rate(x) - est.f_hat, -c - l * expected, rtol=0, atol=1e-7)
    # the ball of Theorem 1 is reached (not exceeded) by a constant residual: sup ||x_tilde|| -> gamma / l
    assert float((x - est.x_hat).norm(dim=-1).max()) <= theorem1_balls(l, float(c.norm()), 2)[0]


def test_discrete_observer_converges_to_the_continuous_one_at_first_order():
    """Eq. (8) is an Euler step of x_hat' = f_hat: halving Ts ten times shrinks the gap about tenfold."""
    torch.manual_seed(0)
    net = mlp(2, 2, (16,), "tanh").double()
    true = Spiral(3.0, 0.05, 1.0)

    def f(_t, z):
        return net(z)

    gaps = []
    for Ts in (1e-2, 1e-3):
        t = torch.arange(round(1.0 / Ts) + 1, dtype=F64) * Ts
        x, cont = observe_continuous(true, f, 5.0, torch.tensor([2.0, 0.0]), t)
        disc = LinearFeedback(f, Ts, gains=Gains(5.0), n=2).observe(x)
        gaps.append(float((disc.x_hat - cont.x_hat).norm(dim=-1).max()))
    assert 6.0 < gaps[0] / gaps[1] < 14.0  # first order: ratio ~10


def test_continuous_observer_accepts_a_float64_model_copy():
    torch.manual_seed(1)
    net = mlp(2, 2, (4,), "relu")
    x, est = observe_continuous(Spiral(2.0, 0.1, 0.0), lambda t, z: copy.deepcopy(net).double()(z), 3.0,
                                torch.tensor([[1.0, 0.0], [0.0, 1.0]]), torch.linspace(0, 0.5, 6))
    assert x.shape == est.x_hat.shape == est.f_hat.shape == (2, 6, 2)


def test_settling_time():
    t = torch.arange(11, dtype=F64) * 0.1
    err = torch.tensor([0.1, 0.1, 0.1, 5.0, 3.0, 1.5, 0.5, 0.8, 0.2, 0.1, 0.1], dtype=F64)
    assert settling_time(t, err, 0.3, 1.0) == pytest.approx(0.3)  # inside from t = 0.6 on
    assert settling_time(t, err, 0.3, 10.0) == pytest.approx(0.0)  # never left the band
    assert settling_time(t, err, 0.3, 0.05) == math.inf  # ends outside the band
    with pytest.raises(ValueError, match="no sample at or after"):
        settling_time(t, err, 2.0, 1.0)
    with pytest.raises(ValueError, match="same length"):
        settling_time(t, err[:-1], 0.0, 1.0)


def test_growth_factor_tells_exponential_from_bounded_and_linear():
    k = torch.arange(1000, dtype=F64)
    g = growth_factor(torch.stack([1.01**k, 1 + 0.1 * torch.sin(k), k * 0.01, 0.99**k]))
    assert float(g[0]) == pytest.approx(1.01 ** (999 - 499), rel=1e-9)  # window maxima at k = 999 and 499
    assert 0.9 < float(g[1]) < 1.2
    assert 1.9 < float(g[2]) < 2.1
    assert float(g[3]) < 0.1


def test_reconvergence_after_a_step():
    t = torch.arange(1001, dtype=F64) * 0.01  # 0 .. 10 s
    err = torch.where(t < 7.0, 0.5 + 0.1 * torch.sin(5 * t), 0.3 + 8.0 * torch.exp(-20 * (t - 7.0)))
    r = reconvergence(t, err, 7.0, window=1.0, band_factor=2.0)
    assert r["steady_pre"] == pytest.approx(0.6, abs=1e-3) and r["steady_post"] == pytest.approx(0.3, abs=1e-6)
    assert r["band"] == pytest.approx(1.2, abs=2e-3)
    # 0.3 + 8 e^{-20 s} <= 1.2  <=>  s >= ln(8 / 0.9) / 20 = 0.109 s; the next sample is at 0.11 s
    assert r["time"] == pytest.approx(0.11, abs=1e-9)
    assert r["time"] == r["time_pre_band"]
    with pytest.raises(ValueError, match="need a 4 s window"):
        reconvergence(t, err, 7.0, window=4.0, band_factor=2.0)
    slow = torch.where(t < 7.0, err, 0.3 + 8.0 * torch.exp(-2 * (t - 7.0)))  # ten times slower: 1.09 s
    rows = reconvergence_rows(t, torch.stack([err, slow]), 7.0, window=1.0, band_factor=2.0)
    assert rows["time"] == [r["time"], pytest.approx(1.1, abs=1e-9)] and rows["band"][0] == r["band"]
    assert set(rows) == set(r)


def test_scaled_error_norm_survives_huge_errors():
    x = torch.tensor([[3e200, 4e200], [3.0, 4.0]], dtype=torch.float64)
    norms = scaled_error_norm(x, torch.zeros_like(x))
    assert torch.isfinite(norms).all()
    torch.testing.assert_close(norms, torch.tensor([5e200, 5.0], dtype=torch.float64))
    assert torch.linalg.vector_norm(x[0]).isinf()  # what the scaling avoids


def test_divergence_transition_finds_the_switch():
    rho = torch.tensor([1.2, 0.5, 0.99, 1.01, 0.8])
    assert divergence_transition(rho, rho > 1) == (1, pytest.approx(0.99), pytest.approx(1.01))
    switches, lo, hi = divergence_transition(rho, torch.tensor([True, False, True, False, False]))
    assert switches == 3 and lo == pytest.approx(1.01) and hi == pytest.approx(0.99)
    switches, lo, hi = divergence_transition(rho, torch.zeros(5, dtype=torch.bool))
    assert switches == 0 and lo == pytest.approx(1.2) and math.isnan(hi)
    with pytest.raises(ValueError, match="1-D of one length"):
        divergence_transition(rho, torch.zeros(4, dtype=torch.bool))
