"""Feedback gains: shape handling and the stability checks of Theorem 1 and App. A.2."""

from __future__ import annotations

import math

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


def decayed_gains(L: Tensor, N: int, beta: float) -> list[Tensor]:
    r"""Gain decay Eq. (11): :math:`L_i = L\,e^{-\beta i}` for layers ``i = 0 .. N-1``.

    The first layer gets the full gain (the authors' release counts layers
    from 0 too).
    """
    beta = float(beta)
    if not (math.isfinite(beta) and beta >= 0):
        raise ValueError(f"decay rate beta must be finite and >= 0, got {beta!r}")
    if int(N) < 1:
        raise ValueError(f"number of prediction steps N must be >= 1, got {N}")
    return [L * math.exp(-beta * i) for i in range(int(N))]
