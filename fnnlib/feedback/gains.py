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
#: times larger than it enters (:func:`noise_amplification`); an open-loop rollout from the same noisy sample
#: passes it with factor about 1.
NOISE_AMPLIFICATION_LIMIT = 10.0


def noise_amplification(gains, Ts: float, N: int, *, n: int | None = None) -> float:
    r"""How much the N-layer cascade (Sec. 3.3, Eq. (11)) amplifies white measurement noise: a quick lower bound.

    Derivation. Linearise layer ``i`` (gain :math:`L_i = L e^{-\beta i}`) around the noise-free run; with
    the model's Jacobian :math:`A` (neglected here: :math:`T_s\|\partial f/\partial x\| \ll T_s L_i`)
    a perturbation :math:`v` of its input :math:`z^{(i)}` reaches its estimate :math:`s` and its output by

    .. math:: s_{k+1} = (I - T_s L_i)\,s_k + T_s(A + L_i)\,v_k, \qquad
              w_k = (I + T_s(A + L_i))\,v_k - T_s L_i\,s_k

    (Eqs. (7)-(8)). Per eigen-direction of :math:`L` and with :math:`A = 0`, :math:`c = T_s\lambda(L_i)`, the
    layer is the filter :math:`H_i(z) = (1 + c - z^{-1})/(1 - (1 - c)z^{-1})`: DC gain 1 (slow signals pass
    unchanged), leading coefficient :math:`1 + c`. The N layers are in series. This returns the leading
    coefficient of the cascade, the spectral norm of :math:`\prod_{i=0}^{N-1} (I + T_s L e^{-\beta i})`, a lower
    bound of the worst direction's factor (the tail of each filter adds :math:`O(c^3)`);
    :func:`noise_amplification_exact` gives the stationary factor itself.

    Parameters
    ----------
    gains : Gains
        The base gain ``L`` (scalar, (n,) or (n, n)) and decay rate ``beta`` of Eq. (11).
    Ts, N
        Sample step and cascade depth.
    n : int, optional
        State dimension; implied by a vector or matrix ``L``.
    """
    return _leading_factor(*_noise_setup(gains, N, n), float(Ts))


def _leading_factor(M: Tensor, decay: list[float], Ts: float) -> float:
    """The spectral norm of :math:`\prod_i (I + T_s L e^{-\beta i})` for the base gain ``M`` (n, n)."""
    P = torch.eye(M.shape[0], dtype=M.dtype)
    for d in decay:
        P = (torch.eye(M.shape[0], dtype=M.dtype) + Ts * d * M) @ P  # (I + Ts L_i) ... (I + Ts L_0)
    return float(torch.linalg.matrix_norm(P, ord=2))


def noise_amplification_exact(gains, Ts: float, N: int, *, n: int | None = None, A: Tensor | None = None,
                              reduce: str = "rms") -> float:
    r"""The stationary noise factor of the N-layer cascade (Sec. 3.3, Eq. (11)) on white measurement noise.

    The linearised layers of :func:`noise_amplification` in series, in state-space form (the N estimates
    stacked): the root mean square over the n components of the cascade's stationary output for unit white
    noise on every component, :math:`\sqrt{\operatorname{tr}\Sigma / n}` with
    :math:`\Sigma = D D^T + C_s P C_s^T`, :math:`P = A_s P A_s^T + B_s B_s^T` the discrete Lyapunov equation,
    solved by doubling (batched over eigen-directions for a symmetric ``L`` without ``A``; one
    (nN)-dimensional system otherwise). This is what a Monte Carlo run of the cascade on white noise
    measures (the RMS of the output noise over all components, divided by the input's). An open-loop
    rollout (``L = 0``, ``A = 0``) has factor 1.

    Parameters
    ----------
    gains : Gains
        The base gain ``L`` and decay rate ``beta`` of Eq. (11).
    Ts, N
        Sample step and cascade depth.
    n : int, optional
        State dimension; implied by a vector or matrix ``L``.
    A : Tensor (n, n), optional
        The model's Jacobian along the run (default: neglected, 0).
    reduce : {"rms", "max"}
        Summarise the components by their root mean square, or take the worst eigen-direction ("max": a
        symmetric ``L`` and no ``A``).
    """
    M, decay = _noise_setup(gains, N, n)
    if reduce not in ("rms", "max"):
        raise ValueError(f"reduce must be 'rms' or 'max', got {reduce!r}")
    n_ = M.shape[0]
    symmetric = A is None and torch.equal(M, M.T)
    if symmetric:  # independent eigen-directions: a batch of scalar cascades
        lam, count = torch.unique(torch.linalg.eigvalsh(M), return_counts=True)  # a scalar L: one direction
        var = _lyapunov_output_variance(*_scalar_cascades(lam, float(Ts), decay))
        if reduce == "max":
            return float(var.max().sqrt())
        return float(((var * count).sum() / n_).sqrt())
    if reduce == "max":
        raise ValueError("reduce='max' needs a symmetric L and no Jacobian A")
    Ls = M[None]
    Jac = (torch.zeros_like(M) if A is None else torch.as_tensor(A, dtype=torch.float64))[None]
    if Jac.shape[1:] != M.shape:
        raise ValueError(f"the Jacobian A must have shape {tuple(M.shape)}, got {tuple(Jac.shape[1:])}")
    var = _lyapunov_output_variance(*_cascade_matrices(Ls, Jac, float(Ts), decay))  # (1,): tr of the output's
    return float((var.sum() / n_).sqrt())


def _noise_setup(gains, N: int, n: int | None) -> tuple[Tensor, list[float]]:
    """The base gain as an (n, n) matrix and the decay factors :math:`e^{-\beta i}` of Eq. (11), i < N."""
    from fnnlib.feedback.options import Gains  # noqa: PLC0415 (options imports this module)

    if not isinstance(gains, Gains):
        raise TypeError(f"gains must be a fnnlib.Gains(L, beta), got {type(gains).__name__}")
    N = int(N)
    if N < 1:
        raise ValueError(f"number of prediction steps N must be an integer >= 1, got {N!r}")
    M = gain_matrix(gains.L, implied_n(gains.L, n))
    return M, [math.exp(-float(gains.beta) * i) for i in range(N)]


def _scalar_cascades(lam: Tensor, Ts: float, decay: list[float]) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    r"""The state-space form of :func:`_cascade_matrices` for scalar layers (one per eigenvalue ``lam`` (b,) of L,
    no Jacobian), built in closed form: with :math:`c_i = T_s\lambda e^{-\beta i}` and
    :math:`\pi_i = \prod_{l<i}(1 + c_l)`, the input of layer i is :math:`\pi_i v - \sum_{j<i} c_j (\pi_i/\pi_{j+1}) s_j`."""
    c = Ts * lam[:, None] * torch.tensor(decay, dtype=torch.float64)  # (b, N)
    b, N = c.shape
    pi = torch.cat([torch.ones(b, 1, dtype=torch.float64), torch.cumprod(1.0 + c, -1)], -1)  # (b, N+1)
    Q = -c[:, None, :] * pi[:, :, None] / pi[:, None, 1:]  # Q[i, j] = -c_j pi_i / pi_{j+1}  (j < i), (b, N+1, N)
    Q = Q * torch.tril(torch.ones(N + 1, N, dtype=torch.float64), -1)
    As = c[:, :, None] * Q[:, :N] + torch.diag_embed(1.0 - c)  # s_i' = (1 - c_i) s_i + c_i z_i
    Bs = (c * pi[:, :N])[..., None]  # (b, N, 1)
    return As, Bs, Q[:, N:N + 1], pi[:, N:N + 1, None]


def _cascade_matrices(L: Tensor, A: Tensor, Ts: float, decay: list[float]) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """The linearised cascade of :func:`noise_amplification` in state-space form, state = the N layers' estimates:
    ``(As, Bs, Cs, Ds)`` of shapes (b, Nq, Nq), (b, Nq, q), (b, q, Nq), (b, q, q) for ``L``, ``A`` (b, q, q)."""
    b, q = L.shape[0], L.shape[-1]
    N = len(decay)
    eye = torch.eye(q, dtype=torch.float64).expand(b, q, q)
    As = torch.zeros(b, N * q, N * q, dtype=torch.float64)
    Bs = torch.zeros(b, N * q, q, dtype=torch.float64)
    P_in = eye  # z_i = P_in v + sum_j Q[j] s_j
    Q = [torch.zeros(b, q, q, dtype=torch.float64) for _ in range(N)]
    for i, d in enumerate(decay):
        Li = d * L
        G = Ts * (A + Li)  # s_i' = (I - Ts L_i) s_i + Ts (A + L_i) z_i
        rows = slice(i * q, (i + 1) * q)
        for j in range(i):
            As[:, rows, j * q:(j + 1) * q] = G @ Q[j]
        As[:, rows, rows] = eye - Ts * Li
        Bs[:, rows] = G @ P_in
        D = eye + Ts * (A + Li)  # w_i = (I + Ts (A + L_i)) z_i - Ts L_i s_i
        Q = [D @ Q[j] for j in range(i)] + [-Ts * Li] + Q[i + 1:]
        P_in = D @ P_in
    return As, Bs, torch.cat(Q, -1), P_in


def _lyapunov_output_variance(As: Tensor, Bs: Tensor, Cs: Tensor, Ds: Tensor) -> Tensor:
    """tr of the stationary output covariance :math:`D D^T + C P C^T`, :math:`P = A P A^T + B B^T`, per system (b,);
    ``inf`` for an unstable one (As is block lower triangular: its eigenvalues are its diagonal blocks')."""
    b, q = As.shape[0], Bs.shape[-1]
    blocks = torch.stack([As[:, i:i + q, i:i + q] for i in range(0, As.shape[-1], q)], 1)  # (b, N, q, q)
    if float(torch.linalg.eigvals(blocks).abs().max()) >= 1:
        return torch.full((b,), float("inf"), dtype=torch.float64)
    X, Ak = Bs @ Bs.mT, As  # doubling: X = sum_k A^k B B' A'^k
    for _ in range(64):
        X_next = X + Ak @ X @ Ak.mT
        Ak = Ak @ Ak
        done = float((X_next - X).abs().max()) <= 1e-15 * max(1.0, float(X_next.abs().max()))
        X = X_next
        if done:
            break
    S = Ds @ Ds.mT + Cs @ X @ Cs.mT
    return torch.diagonal(S, dim1=-2, dim2=-1).sum(-1)


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
        factor = _leading_factor(M, [math.exp(-float(beta) * i) for i in range(int(N))], float(Ts))
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
