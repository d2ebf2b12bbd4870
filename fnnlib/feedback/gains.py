"""The base feedback gain ``L`` of Eq. (7): shape handling and the stability checks of Theorem 1 and App. A.2."""

from __future__ import annotations

import math
import warnings
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


class GainWarning(UserWarning):
    """A feedback gain that is accepted but deserves a look: semidefinite, or amplifying noise strongly."""


#: :func:`check_gain` warns when white measurement noise reaches the N-step prediction more than this many
#: times larger than it enters (:func:`noise_amplification`); an open-loop rollout from the same noisy sample
#: passes it with factor about 1.
NOISE_AMPLIFICATION_LIMIT = 10.0


def noise_amplification(L: float | Tensor | list, Ts: float, N: int, beta: float = 0.0, *,
                        n: int | None = None, exact: bool = False, horizon: int | None = None) -> float:
    r"""How much the N-layer cascade (Sec. 3.3, Eq. (11)) amplifies white measurement noise.

    Derivation. Linearise layer ``i`` (gain :math:`L_i = L e^{-\beta i}`) around the noise-free run and
    neglect the model's Jacobian against :math:`L_i` (:math:`T_s\|\partial f/\partial x\| \ll T_s L_i`).
    A perturbation :math:`v` of its input sequence then reaches its output
    :math:`z^{(i+1)}_k = z^{(i)}_k + T_s(f(z^{(i)}_k) + L_i(z^{(i)}_k - \hat x_k))` (Eqs. (7)-(8)) through
    the filter with impulse response (per eigen-direction, :math:`c = T_s\lambda(L_i)`, :math:`a = 1 - c`)

    .. math:: h_0 = 1 + c, \qquad h_j = -c^2 a^{j-1}\;(j \ge 1),

    whose DC gain is 1 (slow signals pass unchanged) but whose leading coefficient is :math:`1 + c`. The N
    layers are in series, so the cascade's filter is the product of theirs and its leading coefficient is

    .. math:: \prod_{i=0}^{N-1} (I + T_s L e^{-\beta i}).

    White noise of variance :math:`\sigma^2` on the measurements leaves the cascade with variance
    :math:`\sigma^2\sum_j h_j^2 \ge \sigma^2 h_0^2`; the tail adds :math:`O(c^3)` per layer. This
    function returns the spectral norm of the product above (the largest over components for a diagonal
    ``L``), or with ``exact`` the root of :math:`\sum_j h_j^2` of the whole cascade (impulse responses
    over ``horizon`` samples, by default enough for the slowest layer to decay), the largest over the
    eigen-directions of a symmetric ``L``. An open-loop rollout has factor 1.

    Parameters
    ----------
    L : float, Tensor (n,) or (n, n)
        Base gain.
    Ts, N, beta
        Sample step, cascade depth, decay rate of Eq. (11).
    n : int, optional
        State dimension; implied by a vector or matrix ``L``.
    """
    N = int(N)
    if N < 1:
        raise ValueError(f"number of prediction steps N must be an integer >= 1, got {N!r}")
    M = gain_matrix(L, implied_n(L, n))
    decay = [math.exp(-float(beta) * i) for i in range(N)]
    if not exact:
        P = torch.eye(M.shape[0], dtype=M.dtype)
        for d in decay:
            P = (torch.eye(M.shape[0], dtype=M.dtype) + float(Ts) * d * M) @ P  # (I + Ts L_i) ... (I + Ts L_0)
        return float(torch.linalg.matrix_norm(P, ord=2))
    lams = torch.linalg.eigvalsh(0.5 * (M + M.T)).tolist()
    worst = 0.0
    for lam in lams:
        c = [float(Ts) * lam * d for d in decay]
        slow = min((ci for ci in c if ci > 0), default=1.0)
        K = int(horizon) if horizon is not None else int(min(200_000, 40.0 / slow + 10 * N))
        h = torch.zeros(K, dtype=torch.float64)
        h[0] = 1.0
        for ci in c:  # the cascade's impulse response: one layer's filter after another
            j = torch.arange(1, K, dtype=torch.float64)
            g = torch.cat([torch.tensor([1.0 + ci], dtype=torch.float64), -ci * ci * (1.0 - ci) ** (j - 1)])
            h = _convolve(h, g)
        worst = max(worst, float(h.pow(2).sum().sqrt()))
    return worst


def _convolve(h: Tensor, g: Tensor) -> Tensor:
    """The first ``len(h)`` coefficients of the product of two causal filters (by FFT)."""
    K = h.shape[0]
    size = 2 * K
    return torch.fft.irfft(torch.fft.rfft(h, size) * torch.fft.rfft(g, size), size)[:K]


def implied_n(L: float | Tensor | list, n: int | None) -> int:
    """The state dimension: ``n`` if given (checked against a vector or matrix ``L``), else the one ``L`` implies."""
    shape = tuple(torch.as_tensor(L).shape)
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

    With ``N`` (the cascade depth) the noise amplification of the cascade, :func:`noise_amplification`
    for ``N`` and ``beta``, is computed, and a :class:`GainWarning` is raised when it exceeds
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
        factor = noise_amplification(M, Ts, N, beta)
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
