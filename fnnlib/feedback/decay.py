r"""The gain decay of Eq. (11) along the cascade of Sec. 3.3, and the checks on its N and beta.

Layer ``i = 0 .. N-1`` of the cascade uses :math:`L_i = L\,e^{-\beta i}`; the
first layer gets the full gain (the authors' release counts layers from 0 too).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor


def check_N(N: int) -> int:
    """Return ``N`` as an int if it is an integer >= 1 (prediction steps = cascade layers), else raise."""
    if isinstance(N, bool) or not isinstance(N, (int, float)) and not hasattr(N, "__index__"):
        raise TypeError(f"number of prediction steps N must be an integer >= 1, got {N!r}")
    if int(N) != N or int(N) < 1:
        raise ValueError(f"number of prediction steps N must be an integer >= 1, got {N!r}")
    return int(N)


def check_betas(beta: float | Sequence[float] | Tensor) -> Tensor:
    """Decay rates as a 1-D float64 tensor (a scalar gives one); each must be finite and >= 0."""
    b = torch.as_tensor(beta, dtype=torch.float64).reshape(-1)
    if b.numel() == 0 or not bool(torch.isfinite(b).all()) or bool((b < 0).any()):
        raise ValueError(f"decay rate beta must be finite and >= 0, got {beta!r}")
    return b


def check_beta(beta: float) -> float:
    """One decay rate as a float, finite and >= 0."""
    b = check_betas(beta)
    if b.numel() != 1:
        raise ValueError(f"expected one decay rate beta, got {beta!r}")
    return float(b[0])


def decay_factors(beta: float | Sequence[float] | Tensor, N: int) -> Tensor:
    r"""Eq. (11) factors :math:`e^{-\beta i}` for ``i = 0 .. N-1``, float64 of shape (B, N) for B decay rates.

    A scalar ``beta`` gives shape (1, N). Each factor is ``math.exp(-beta * i)``
    (the C library's exp, the same value for every caller).
    """
    betas, N = check_betas(beta).tolist(), check_N(N)
    return torch.tensor([[math.exp(-b * i) for i in range(N)] for b in betas], dtype=torch.float64)


def decayed_gains(L: Tensor, N: int, beta: float) -> list[Tensor]:
    r"""The decayed stack of Eq. (11): ``L_stack[i]`` = :math:`L\,e^{-\beta i}` for layers ``i = 0 .. N-1``.

    ``L`` is the base gain (any shape); the products are taken in ``L``'s dtype.
    """
    return [L * d for d in decay_factors(check_beta(beta), N)[0].tolist()]
