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


def varying_recurrence(A: Tensor, b: Tensor, h0: Tensor, *, diagonal: bool = False) -> Tensor:
    r"""Solve :math:`h_{k+1} = A_k h_k + b_k` for every step at once, with a transition per step.

    The doubling scan of :func:`linear_recurrence` with time-varying transitions: each pass composes the
    affine maps of adjacent windows, :math:`(A'', b'') \circ (A', b') = (A'' A', A'' b' + b'')`.

    Parameters
    ----------
    A : Tensor, shape (..., T-1, n, n), or with ``diagonal`` (..., T-1, n)
        The transition of each step (broadcast with ``b``).
    b : Tensor, shape (..., T-1, n)
        Inputs.
    h0 : Tensor, shape (..., n)
        Initial state.

    Returns
    -------
    Tensor, shape (..., T, n)
        ``h_0 .. h_{T-1}``.
    """
    lead = torch.broadcast_shapes(A.shape[:-1] if diagonal else A.shape[:-2], b.shape[:-1])
    b = b.expand(*lead, b.shape[-1])
    P = A.expand(*lead, A.shape[-1]) if diagonal else A.expand(*lead, *A.shape[-2:])
    y = torch.cat([h0.expand(*lead[:-1], h0.shape[-1]).unsqueeze(-2), b], dim=-2)
    # P[k] is the transition of the window ending at step k (applied to y[k-d]); pad with identity at the start
    one = torch.ones_like(P[..., :1, :]) if diagonal else torch.eye(P.shape[-1], dtype=P.dtype).expand_as(P[..., :1, :, :])
    P = torch.cat([one, P], dim=-2 if diagonal else -3)  # (..., T, n[, n]): row k maps y[k-1] -> y[k]
    T = y.shape[-2]
    d = 1
    while d < T:
        if diagonal:
            y = torch.cat([y[..., :d, :], y[..., d:, :] + P[..., d:, :] * y[..., :-d, :]], dim=-2)
            P = torch.cat([P[..., :d, :], P[..., d:, :] * P[..., :-d, :]], dim=-2)
        else:
            y = torch.cat([y[..., :d, :], y[..., d:, :] + (P[..., d:, :, :] @ y[..., :-d, :, None])[..., 0]], dim=-2)
            P = torch.cat([P[..., :d, :, :], P[..., d:, :, :] @ P[..., :-d, :, :]], dim=-3)
        d *= 2
    return y
