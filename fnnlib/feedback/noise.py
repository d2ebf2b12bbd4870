r"""How much the cascade of Sec. 3.3 (Eq. (11)) amplifies white measurement noise: the quick bound and the exact factor.

:func:`noise_amplification` is the leading coefficient of the linearised layers of Eqs. (7)-(8) in series (the
bound :func:`~fnnlib.feedback.gains.check_gain` warns with); :func:`noise_amplification_exact` the stationary
factor of their state-space form, what a Monte Carlo run of the cascade on white noise measures.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from fnnlib.feedback.gains import leading_noise_factor, gain_matrix, implied_n
from fnnlib.feedback.options import Gains


def noise_amplification(gains: Gains, Ts: float, N: int, *, n: int | None = None) -> float:
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
    return leading_noise_factor(*_noise_setup(gains, N, n), float(Ts))


def noise_amplification_exact(gains: Gains, Ts: float, N: int, *, n: int | None = None, A: Tensor | None = None,
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


def _noise_setup(gains: Gains, N: int, n: int | None) -> tuple[Tensor, list[float]]:
    """The base gain as an (n, n) matrix and the decay factors :math:`e^{-\beta i}` of Eq. (11), i < N."""
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
