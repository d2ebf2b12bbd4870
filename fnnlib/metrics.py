"""Error metrics. Shapes: trajectories are ``(..., T, n)``."""

from __future__ import annotations

import torch
from torch import Tensor


def error_norm(pred: Tensor, true: Tensor) -> Tensor:
    """Euclidean norm of the error per time step, shape ``(..., T)``."""
    if pred.shape != true.shape:
        raise ValueError(f"shape mismatch: pred {tuple(pred.shape)} vs true {tuple(true.shape)}")
    return torch.linalg.vector_norm(pred - true, dim=-1)


def rmse_over_time(pred: Tensor, true: Tensor) -> Tensor:
    """Root mean squared 2-norm error over time only, one per leading index: shape ``(...)``."""
    return error_norm(pred, true).pow(2).mean(-1).sqrt()


def mean_error_norm(pred: Tensor, true: Tensor) -> float:
    """Mean over time (and batch) of the 2-norm error, the paper's "mean 2-norm error"."""
    return float(error_norm(pred, true).mean())


def rmse(pred: Tensor, true: Tensor) -> float:
    """Root mean squared 2-norm error over time (and batch)."""
    return float(error_norm(pred, true).pow(2).mean().sqrt())


def relative_rmse(pred: Tensor, true: Tensor) -> float:
    """RMSE divided by the RMS norm of ``true``: a scale-free fit measure."""
    scale = float(torch.linalg.vector_norm(true, dim=-1).pow(2).mean().sqrt())
    if scale == 0.0:
        raise ValueError("relative_rmse is undefined for an all-zero reference")
    return rmse(pred, true) / scale


def ahead_position_errors(pred: Tensor, x: Tensor, N: int) -> Tensor:
    """O1's error (Sec. 5.1): each trajectory's mean position error ``N`` samples ahead.

    ``pred`` (..., K, T - N, n): the predictions from the first T - N starts of the trajectories ``x`` (K, T, n)
    (row k predicts ``x[:, k + N]``), whose first three states are the position. Returns (..., K).
    """
    return error_norm(pred[..., :3], x[:, N:, :3].expand_as(pred[..., :3])).mean(-1)


def ahead_position_loss(x: Tensor, z: Tensor, N: int) -> Tensor:
    """The mean of :func:`ahead_position_errors` over every start of every trajectory, as one differentiable
    number: the objective that tunes the gains on O1's error. ``z`` (..., K, T', n) holds predictions from at least
    the first T - N starts of ``x`` (..., K, T, n)."""
    return error_norm(z[..., : x.shape[-2] - N, :3], x[..., N:, :3]).mean()


def n_step_errors(pred: Tensor, truth: Tensor, N: int) -> Tensor:
    """2-norm errors of N-step predictions from every start that has a truth sample N steps later.

    ``pred`` (..., T, n): row ``k`` predicts ``truth[..., k + N, :]`` (the
    layout of :func:`fnnlib.feedback.cascade_sweep` and :func:`fnnlib.cascade_predict`);
    ``truth`` (T, n) or broadcastable. Returns shape (..., T - N).
    """
    N = int(N)
    T = truth.shape[-2]
    if not 1 <= N < T or pred.shape[-2] != T:
        raise ValueError(f"need 1 <= N < T and predictions of length T; got N={N}, T={T}, "
                         f"prediction length {pred.shape[-2]}")
    for name, v in (("truth", truth[..., N:, :]), ("pred", pred[..., : T - N, :])):
        if not bool(torch.isfinite(v).all()):
            idx = tuple(int(i) for i in (~torch.isfinite(v)).nonzero()[0])
            raise ValueError(f"{name} holds a NaN or infinite value among the scored samples (first at index {idx} "
                             "of the scored part); score only samples that were measured")
    return torch.linalg.vector_norm(pred[..., : T - N, :] - truth[..., N:, :], dim=-1)
