"""Linear recursions in time, solved for all steps at once by a doubling scan."""

from __future__ import annotations

import torch
from torch import Tensor


def linear_recurrence(A: Tensor, b: Tensor, h0: Tensor, *, diagonal: bool | None = None) -> Tensor:
    r"""Solve :math:`h_{k+1} = A h_k + b_k` for every step at once.

    Hillis-Steele doubling: after the pass with offset d, each entry holds the
    sum of the last 2d terms :math:`A^{k-j} y_j`, so :math:`\lceil\log_2 T\rceil`
    batched passes give :math:`h_k = A^k h_0 + \sum_{j<k} A^{k-1-j} b_j`
    without a Python loop over time and without the :math:`A^{-k}` factors of
    a cumulative-sum closed form (which overflow when A is contractive).

    Parameters
    ----------
    A : Tensor, shape (n, n), (n,) or (..., n)
        Constant transition: a full matrix, or with ``diagonal`` its diagonal,
        which may differ across the batch (broadcast with ``h0``).
    b : Tensor, shape (..., T-1, n)
        Inputs.
    h0 : Tensor, shape (..., n)
        Initial state.
    diagonal : bool, optional
        Whether ``A`` holds diagonals; by default a 1-D ``A`` is a diagonal
        and a 2-D one a matrix.

    Returns
    -------
    Tensor, shape (..., T, n)
        ``h_0 .. h_{T-1}``.
    """
    if diagonal is None:
        diagonal = A.ndim == 1
    y = torch.cat([h0.unsqueeze(-2), b], dim=-2)
    T = y.shape[-2]
    P = A.unsqueeze(-2) if diagonal else A  # diagonal: (..., 1, n), the same transition at every step
    d = 1
    while d < T:
        shifted = y[..., :-d, :] * P if diagonal else y[..., :-d, :] @ P.T  # A^d h_{k-d}
        y = torch.cat([y[..., :d, :], y[..., d:, :] + shifted], dim=-2)
        P = P * P if diagonal else P @ P
        d *= 2
    return y
