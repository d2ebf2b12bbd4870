"""Linear recursions in time, solved for all steps at once by a doubling scan."""

from __future__ import annotations

import torch
from torch import Tensor


def _apply(P: Tensor, y: Tensor) -> Tensor:
    """P y for row-vector batches ``y`` (..., n); ``P`` is (n,) diagonal or (n, n)."""
    return y * P if P.ndim == 1 else y @ P.T


def linear_recurrence(A: Tensor, b: Tensor, h0: Tensor) -> Tensor:
    r"""Solve :math:`h_{k+1} = A h_k + b_k` for every step at once.

    Hillis-Steele doubling: after the pass with offset d, each entry holds the
    sum of the last 2d terms :math:`A^{k-j} y_j`, so :math:`\lceil\log_2 T\rceil`
    batched passes give :math:`h_k = A^k h_0 + \sum_{j<k} A^{k-1-j} b_j`
    without a Python loop over time and without the :math:`A^{-k}` factors of
    a cumulative-sum closed form (which overflow when A is contractive).

    Parameters
    ----------
    A : Tensor, shape (n,) or (n, n)
        Constant transition; a vector means a diagonal matrix.
    b : Tensor, shape (..., T-1, n)
        Inputs.
    h0 : Tensor, shape (..., n)
        Initial state.

    Returns
    -------
    Tensor, shape (..., T, n)
        ``h_0 .. h_{T-1}``.
    """
    y = torch.cat([h0.unsqueeze(-2), b], dim=-2)
    T = y.shape[-2]
    P = A
    d = 1
    while d < T:
        y = torch.cat([y[..., :d, :], y[..., d:, :] + _apply(P, y[..., :-d, :])], dim=-2)
        P = P * P if P.ndim == 1 else P @ P
        d *= 2
    return y
