"""Error metrics on hand-checkable values."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib import error_norm, mean_error_norm, relative_rmse, rmse, rmse_over_time


def test_error_norm_per_step():
    true = torch.zeros(2, 3, 2)
    pred = torch.tensor([[[3.0, 4.0], [0.0, 1.0], [0.0, 0.0]], [[6.0, 8.0], [1.0, 0.0], [0.0, 2.0]]])
    torch.testing.assert_close(error_norm(pred, true), torch.tensor([[5.0, 1.0, 0.0], [10.0, 1.0, 2.0]]))
    assert mean_error_norm(pred, true) == pytest.approx(19.0 / 6)
    assert rmse(pred, true) == pytest.approx(math.sqrt((25 + 1 + 0 + 100 + 1 + 4) / 6))


def test_constant_error():
    true = torch.randn(10, 2, dtype=torch.float64)
    pred = true + torch.tensor([3.0, 4.0], dtype=torch.float64)
    assert rmse(pred, true) == pytest.approx(5.0)
    assert mean_error_norm(pred, true) == pytest.approx(5.0)
    assert rmse(true, true) == 0.0


def test_relative_rmse():
    true = torch.tensor([[3.0, 4.0], [0.0, 5.0]])  # RMS norm 5
    pred = true + torch.tensor([1.0, 0.0])  # rmse 1
    assert relative_rmse(pred, true) == pytest.approx(0.2)


def test_relative_rmse_zero_reference():
    with pytest.raises(ValueError, match="undefined for an all-zero reference"):
        relative_rmse(torch.ones(3, 2), torch.zeros(3, 2))


@pytest.mark.parametrize("fn", [error_norm, mean_error_norm, rmse, relative_rmse])
def test_shape_mismatch(fn):
    with pytest.raises(ValueError, match=r"shape mismatch: pred \(4, 2\) vs true \(5, 2\)"):
        fn(torch.ones(4, 2), torch.ones(5, 2))


def test_rmse_over_time_per_series():
    true = torch.zeros(2, 2, 2)
    pred = torch.tensor([[[3.0, 4.0], [0.0, 0.0]], [[1.0, 0.0], [0.0, 1.0]]])
    torch.testing.assert_close(rmse_over_time(pred, true), torch.tensor([math.sqrt(25 / 2), 1.0]))
