"""Eq. (11): the decay factors, the decayed stack, and the checks on N and beta."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib.feedback import check_beta, check_betas, check_N, decay_factors, decayed_gains


def test_decay_factors_are_exp_minus_beta_i_per_rate():
    d = decay_factors([0.0, 0.1, 2.0], 4)
    assert d.shape == (3, 4) and d.dtype == torch.float64
    for row, beta in zip(d.tolist(), [0.0, 0.1, 2.0]):
        assert row == [math.exp(-beta * i) for i in range(4)]
    assert d[:, 0].tolist() == [1.0, 1.0, 1.0]  # layer 0 keeps the full gain


def test_decayed_stack_multiplies_the_base_gain():
    L = torch.tensor([[20.0, 1.0], [0.0, 10.0]], dtype=torch.float64)
    L_stack = decayed_gains(L, 3, 0.5)
    assert len(L_stack) == 3
    torch.testing.assert_close(L_stack[2], L * math.exp(-1.0), rtol=0, atol=0)


@pytest.mark.parametrize("N", [0, -1, 2.5])
def test_bad_N_is_refused(N):
    with pytest.raises(ValueError, match="number of prediction steps N must be an integer >= 1"):
        check_N(N)


@pytest.mark.parametrize("beta", [-0.1, float("nan"), float("inf"), []])
def test_bad_beta_is_refused(beta):
    with pytest.raises(ValueError, match="decay rate beta must be finite and >= 0"):
        check_betas(beta)


def test_one_rate_expected_where_one_is_used():
    assert check_beta(0.02) == 0.02
    with pytest.raises(ValueError, match="expected one decay rate"):
        check_beta([0.1, 0.2])
    with pytest.raises(ValueError, match="expected one decay rate"):
        decayed_gains(torch.eye(2), 3, [0.1, 0.2])
