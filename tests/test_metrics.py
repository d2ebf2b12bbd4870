"""Error metrics on hand-checkable values."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib.metrics import error_norm, mean_error_norm, relative_rmse, rmse, rmse_over_time


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


def test_ahead_position_errors_read_the_position_n_samples_ahead():
    """Row k predicts x[:, k + N]: an exact prediction scores 0; one off by (3, 4, 0) in position, and anything in
    the velocity, scores 5 at every start; the loss is their mean over starts and trajectories."""
    from fnnlib.metrics import ahead_position_errors, ahead_position_loss

    x = torch.arange(2 * 7 * 6, dtype=torch.float64).reshape(2, 7, 6)
    N = 2
    exact = x[:, N:].clone()  # (K, T - N, 6)
    assert ahead_position_errors(exact, x, N).tolist() == [0.0, 0.0]
    off = exact + torch.tensor([3.0, 4.0, 0.0, 9.0, 9.0, 9.0], dtype=torch.float64)
    assert ahead_position_errors(off, x, N).tolist() == [5.0, 5.0]
    assert ahead_position_errors(off[None].expand(3, -1, -1, -1), x, N).shape == (3, 2)
    off[1, :, 0] += 12.0  # the second trajectory: (15, 4, 0) off, norm sqrt(241)
    torch.testing.assert_close(ahead_position_loss(x, off, N), torch.tensor((5.0 + math.sqrt(241.0)) / 2,
                                                                            dtype=torch.float64))
