"""The base feedback gain ``L`` of Eq. (7): shape handling and the stability checks of Theorem 1 and App. A.2."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import torch
from torch import Tensor


class GainError(ValueError):
    """A feedback gain that is not positive definite or makes Eq. (25) unstable."""


def as_gain(L: float | Tensor | list) -> float | Tensor | list:
    """``L`` itself when it is a real number, tensor or nested list of numbers; else a clear ``TypeError``."""
    if isinstance(L, Tensor):
        if L.is_complex() or not (L.is_floating_point() or L.dtype in (torch.int32, torch.int64)):
            raise TypeError(f"gain L must hold real numbers, got a tensor of dtype {L.dtype}")
        return L
    try:
        torch.as_tensor(L, dtype=torch.float64)
    except (TypeError, ValueError, RuntimeError):
        raise TypeError(f"gain L must be a number, a vector or a matrix of numbers, got {L!r}") from None
    if isinstance(L, (str, bytes)) or (isinstance(L, (list, tuple)) and _holds_text(L)):
        raise TypeError(f"gain L must be a number, a vector or a matrix of numbers, got {L!r}")
    return L


def _holds_text(v) -> bool:
    return any(_holds_text(e) if isinstance(e, (list, tuple)) else isinstance(e, (str, bytes)) for e in v)


def gain_matrix(L: float | Tensor | list, n: int, *, dtype: torch.dtype = torch.float64) -> Tensor:
    """Return ``L`` as an (n, n) matrix from a scalar, a vector (n,) (diagonal) or a matrix."""
    L = torch.as_tensor(as_gain(L), dtype=dtype)
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


class GainWarning(UserWarning):
    """A feedback gain that is accepted but deserves a look: semidefinite, or amplifying noise strongly."""


#: :func:`check_gain` warns when white measurement noise reaches the N-step prediction more than this many
#: times larger than it enters (:func:`~fnnlib.feedback.noise.noise_amplification`); an open-loop rollout from
#: the same noisy sample passes it with factor about 1.
NOISE_AMPLIFICATION_LIMIT = 10.0


def leading_noise_factor(M: Tensor, decay: list[float], Ts: float) -> float:
    r"""The spectral norm of :math:`\prod_i (I + T_s L e^{-\beta i})` for the base gain ``M`` (n, n)."""
    P = torch.eye(M.shape[0], dtype=M.dtype)
    for d in decay:
        P = (torch.eye(M.shape[0], dtype=M.dtype) + Ts * d * M) @ P  # (I + Ts L_i) ... (I + Ts L_0)
    return float(torch.linalg.matrix_norm(P, ord=2))


def implied_n(L: float | Tensor | list, n: int | None) -> int:
    """The state dimension: ``n`` if given (checked against a vector or matrix ``L``), else the one ``L`` implies."""
    shape = tuple(torch.as_tensor(as_gain(L), dtype=torch.float64).shape)
    if n is None:
        if len(shape) == 0:
            raise ValueError("a scalar gain L does not say the state dimension: pass n (or a vector/matrix L)")
        return int(shape[0])
    return int(n)


def check_gain(L: float | Tensor | list, n: int | None, Ts: float, *, allow_unstable: bool = False,
               allow_semidefinite: bool = True, N: int | None = None, beta: float = 0.0) -> Tensor:
    r"""Validate a feedback gain for Eqs. (7)-(8); return it as an (n, n) float64 matrix.

    Theorem 1 needs :math:`L` positive definite (:math:`\lambda_m(L) > 0`,
    checked on the symmetric part); the discrete error dynamics Eq. (25),
    :math:`\tilde x_k = (I - T_s L)\tilde x_{k-1} + T_s\Delta f`, are ISS
    when :math:`\rho(I - T_s L) < 1`. A gain failing either is refused with
    :class:`GainError` unless ``allow_unstable=True`` (to show divergence,
    App. A.2). ``L = 0`` exactly (feedback switched off: the plain neural
    ODE) is always accepted.

    A symmetric positive *semidefinite* gain (e.g. ``diag(0, 5)``: only the second state is corrected) is
    not unstable: it is accepted with a :class:`GainWarning` naming the uncorrected directions (their error
    follows the model alone), and Eq. (25) is checked on the corrected directions only. Pass
    ``allow_semidefinite=False`` to refuse it.

    With ``N`` (the cascade depth) the noise amplification of the cascade,
    :func:`~fnnlib.feedback.noise.noise_amplification` for ``N`` and ``beta``, is computed, and a :class:`GainWarning` is raised when it exceeds
    :data:`NOISE_AMPLIFICATION_LIMIT`. ``n`` may be ``None`` when ``L`` is a vector or matrix.
    """
    if not (math.isfinite(float(Ts)) and float(Ts) > 0):
        raise ValueError(f"Ts must be a finite positive step, got {Ts!r}")
    n = implied_n(L, n)
    M = gain_matrix(L, n)
    if not bool(torch.isfinite(M).all()):
        raise GainError(f"gain L holds NaN or infinite entries: {M.tolist()}")
    if allow_unstable or bool((M == 0).all()):
        return M
    sym_eigs, vecs = torch.linalg.eigh(0.5 * (M + M.T))
    tol = 1e-12 * max(1.0, float(sym_eigs.abs().max()))
    null = sym_eigs.abs() <= tol
    semidefinite = bool(null.any()) and bool((sym_eigs >= -tol).all()) and torch.equal(M, M.T)
    if float(sym_eigs.min()) <= 0 and not (semidefinite and allow_semidefinite):
        raise GainError(
            f"gain L is not positive definite (smallest eigenvalue of its symmetric part is "
            f"{float(sym_eigs.min()):.4g}); Theorem 1 needs lambda_min(L) > 0. "
            "Pass allow_unstable=True to run it anyway.")
    if semidefinite:
        directions = [[round(v, 4) for v in vecs[:, j].tolist()] for j in range(n) if bool(null[j])]
        states = [j for j in range(n) if bool((M[j] == 0).all() and (M[:, j] == 0).all())]
        where = f"states {states}" if len(states) == len(directions) else f"directions {directions}"
        warnings.warn(f"gain L is positive semidefinite: {where} are not corrected by the feedback (their error "
                      "follows the model alone; Theorem 1's bound does not hold there)", GainWarning, stacklevel=2)
        eig = torch.linalg.eigvals(torch.eye(n, dtype=M.dtype) - float(Ts) * M)
        rho = float(eig.abs()[(eig - 1).abs() > 1e-9].max()) if bool(((eig - 1).abs() > 1e-9).any()) else 0.0
    else:
        rho = spectral_radius(torch.eye(n, dtype=M.dtype) - float(Ts) * M)
    if rho >= 1:
        raise GainError(
            f"gain L makes the discrete error dynamics Eq. (25) unstable: rho(I - Ts L) = {rho:.4g} >= 1 "
            f"with Ts = {Ts}; the observer error diverges. Lower L (rho < 1 needs the eigenvalues of "
            f"Ts*L inside the disc |1 - z| < 1) or pass allow_unstable=True to show the divergence.")
    if N is not None:
        factor = leading_noise_factor(M, [math.exp(-float(beta) * i) for i in range(int(N))], float(Ts))
        if factor > NOISE_AMPLIFICATION_LIMIT:
            warnings.warn(f"the {int(N)}-layer cascade with this gain and beta = {beta} amplifies white "
                          f"measurement noise about {factor:.3g}x (prod_i (1 + Ts L e^(-beta i)); limit "
                          f"{NOISE_AMPLIFICATION_LIMIT:g}); on noisy data lower L, raise beta or tune them "
                          "(fnnlib.tune_gains)", GainWarning, stacklevel=2)
    return M


def gain_batch(L: float | Sequence[float] | Tensor, n: int, Ts: float, *, allow_unstable: bool = False) -> Tensor:
    """A batch of G base gains as a (G, n) float64 tensor of diagonals; each checked by :func:`check_gain`.

    ``L`` scalar: one gain ``L I``; shape (G,): G scalar gains ``L_g I``; shape (G, n): G diagonal gains.
    """
    L = torch.as_tensor(as_gain(L), dtype=torch.float64)
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
