"""The base feedback gain ``L`` of Eq. (7): shape handling and the stability checks of Theorem 1 and App. A.2."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor


class GainError(ValueError):
    """A feedback gain that is not positive definite or makes Eq. (25) unstable."""


def gain_matrix(L: float | Tensor | list, n: int, *, dtype: torch.dtype = torch.float64) -> Tensor:
    """Return ``L`` as an (n, n) matrix from a scalar, a vector (n,) (diagonal) or a matrix."""
    L = torch.as_tensor(L, dtype=dtype)
    if L.ndim == 0:
        return L * torch.eye(n, dtype=dtype)
    if L.ndim == 1 and L.shape[0] == n:
        return torch.diag(L)
    if L.shape == (n, n):
        return L.clone()
    raise ValueError(f"gain L must be a scalar, a vector of length {n} or an ({n}, {n}) matrix; got shape {tuple(L.shape)}")


def gain_compact(L: float | Tensor | list, n: int, *, dtype: torch.dtype = torch.float64) -> Tensor:
    """``L`` as a diagonal vector (n,) when it is diagonal, else as an (n, n) matrix.

    The diagonal form lets the scan and the feedback use elementwise products.
    """
    M = gain_matrix(L, n, dtype=dtype)
    diag = torch.diagonal(M)
    return diag.clone() if torch.equal(M, torch.diag(diag)) else M


def spectral_radius(M: Tensor) -> float:
    """Largest eigenvalue modulus of a square matrix."""
    return float(torch.linalg.eigvals(M.double()).abs().max())


def check_gain(L: float | Tensor | list, n: int, Ts: float, *, allow_unstable: bool = False) -> Tensor:
    r"""Validate a feedback gain for Eqs. (7)-(8); return it as an (n, n) float64 matrix.

    Theorem 1 needs :math:`L` positive definite (:math:`\lambda_m(L) > 0`,
    checked on the symmetric part); the discrete error dynamics Eq. (25),
    :math:`\tilde x_k = (I - T_s L)\tilde x_{k-1} + T_s\Delta f`, are ISS
    when :math:`\rho(I - T_s L) < 1`. A gain failing either is refused with
    :class:`GainError` unless ``allow_unstable=True`` (to show divergence,
    App. A.2). ``L = 0`` exactly (feedback switched off: the plain neural
    ODE) is always accepted.
    """
    if not (math.isfinite(float(Ts)) and float(Ts) > 0):
        raise ValueError(f"Ts must be a finite positive step, got {Ts!r}")
    M = gain_matrix(L, n)
    if not bool(torch.isfinite(M).all()):
        raise GainError(f"gain L holds NaN or infinite entries: {M.tolist()}")
    if allow_unstable or bool((M == 0).all()):
        return M
    sym_eigs = torch.linalg.eigvalsh(0.5 * (M + M.T))
    if float(sym_eigs.min()) <= 0:
        raise GainError(
            f"gain L is not positive definite (smallest eigenvalue of its symmetric part is "
            f"{float(sym_eigs.min()):.4g}); Theorem 1 needs lambda_min(L) > 0. "
            "Pass allow_unstable=True to run it anyway.")
    rho = spectral_radius(torch.eye(n, dtype=M.dtype) - float(Ts) * M)
    if rho >= 1:
        raise GainError(
            f"gain L makes the discrete error dynamics Eq. (25) unstable: rho(I - Ts L) = {rho:.4g} >= 1 "
            f"with Ts = {Ts}; the observer error diverges. Lower L (rho < 1 needs the eigenvalues of "
            f"Ts*L inside the disc |1 - z| < 1) or pass allow_unstable=True to show the divergence.")
    return M


def gain_batch(L: float | Sequence[float] | Tensor, n: int, Ts: float, *, allow_unstable: bool = False) -> Tensor:
    """A batch of G base gains as a (G, n) float64 tensor of diagonals; each checked by :func:`check_gain`.

    ``L`` scalar: one gain ``L I``; shape (G,): G scalar gains ``L_g I``; shape (G, n): G diagonal gains.
    """
    L = torch.as_tensor(L, dtype=torch.float64)
    if L.ndim == 0:
        L = L.reshape(1)
    if L.ndim == 1:
        L = L[:, None].expand(-1, n)
    elif L.ndim != 2 or L.shape[1] != n:
        raise ValueError(f"gain batch L must be a scalar, shape (G,) (scalar gains) or (G, {n}) (diagonal gains); "
                         f"got shape {tuple(L.shape)}")
    if L.shape[0] == 0:
        raise ValueError("gain batch L is empty")
    for g in L:
        check_gain(g, n, Ts, allow_unstable=allow_unstable)
    return L.contiguous()
