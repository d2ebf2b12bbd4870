"""Noise amplification of the cascade: the formula against its closed form and a Monte Carlo estimate."""

from __future__ import annotations

import math
import warnings

import pytest
import torch

from fnnlib import cascade_predict, check_gain, noise_amplification
from fnnlib.feedback import GainWarning, NOISE_AMPLIFICATION_LIMIT, Gains, noise_amplification_exact

F64 = torch.float64


def _zero(t, x):
    return torch.zeros_like(x)


def test_leading_coefficient_is_the_product_formula():
    Ts, N, beta, L = 0.01, 50, 0.02, 20.0
    expected = math.prod(1 + Ts * L * math.exp(-beta * i) for i in range(N))
    assert noise_amplification(Gains(L, beta), Ts, N, n=2) == pytest.approx(expected, rel=1e-12)
    assert noise_amplification(Gains(torch.tensor([L, 1.0]), beta), Ts, N) == pytest.approx(expected, rel=1e-12)


def test_one_layer_exact_factor_matches_its_closed_form():
    Ts, L = 0.1, 5.0
    c, a = Ts * L, 1 - Ts * L
    closed = math.sqrt((1 + c) ** 2 + c ** 4 / (1 - a ** 2))  # h_0 = 1 + c, h_j = -c^2 a^(j-1)
    assert noise_amplification_exact(Gains(L), Ts, 1, n=1) == pytest.approx(closed, rel=1e-9)


@pytest.mark.parametrize("L, beta, N", [(20.0, 0.02, 30), (5.0, 0.0, 20), (40.0, 0.1, 10)])
def test_exact_factor_matches_monte_carlo_white_noise(L, beta, N):
    Ts = 0.01
    gen = torch.Generator().manual_seed(0)
    v = torch.randn(16, 5000, 1, generator=gen, dtype=F64)  # unit white noise, the only input (f = 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GainWarning)
        z = cascade_predict(_zero, v, Ts, N, Gains(torch.tensor([L]), beta))
    mc = float(z[:, 1500:].std())  # after the start-up transient of every layer
    exact = noise_amplification_exact(Gains(L, beta), Ts, N, n=1)
    assert mc == pytest.approx(exact, rel=0.03)  # 16 x 3500 samples: standard error of a std ~0.3 %, tails correlated
    assert noise_amplification(Gains(L, beta), Ts, N, n=1) <= exact  # the product formula is the leading term only


def test_check_gain_warns_above_the_limit_only():
    with pytest.warns(GainWarning, match=r"amplifies white measurement noise about .*x"):
        check_gain(20.0, 2, 0.01, N=50, beta=0.02)
    assert noise_amplification(Gains(2.0, 0.02), 0.01, 50, n=2) < NOISE_AMPLIFICATION_LIMIT
    with warnings.catch_warnings():
        warnings.simplefilter("error", GainWarning)
        check_gain(2.0, 2, 0.01, N=50, beta=0.02)
        check_gain(20.0, 2, 0.01)  # no N: no noise check


def test_bad_arguments():
    with pytest.raises(ValueError, match="scalar gain L does not say the state dimension"):
        noise_amplification(Gains(2.0), 0.01, 5)
    with pytest.raises(ValueError, match="N must be an integer >= 1"):
        noise_amplification(Gains(2.0), 0.01, 0, n=1)


@pytest.mark.parametrize("L, A", [(torch.tensor([30.0, 3.0]), None),
                                  (10.0, torch.tensor([[0.0, 1.0], [-25.0, -8.0]], dtype=F64))])
def test_exact_factor_is_the_measured_rms_for_diagonal_gains_and_a_model_jacobian(L, A):
    """The measured figure is the RMS over every component; a diagonal gain's worst direction overstates it,
    and a damping model (its Jacobian A) changes it: the exact factor takes both into account."""
    Ts, N, beta = 0.01, 20, 0.02
    Am = torch.zeros(2, 2, dtype=F64) if A is None else A
    v = torch.randn(8, 4000, 2, generator=torch.Generator().manual_seed(1), dtype=F64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GainWarning)
        z = cascade_predict(lambda t, x: x @ Am.T, v, Ts, N, Gains(L, beta))
    mc = float(z[:, 1000:].pow(2).mean().sqrt())
    exact = noise_amplification_exact(Gains(L, beta), Ts, N, n=2, A=A)
    assert mc == pytest.approx(exact, rel=0.03)
    if A is None:
        worst = noise_amplification_exact(Gains(L, beta), Ts, N, n=2, reduce="max")
        assert worst > 1.2 * mc  # the worst direction is not what is measured
