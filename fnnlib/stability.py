r"""Theorem 1 and App. A.2 made measurable: error balls, the ISS bound of Eq. (25), settling and growth.

Continuous time (Theorem 1): with :math:`\|\Delta f(t)\| \le \gamma`, the observer
error :math:`\tilde x = x - \hat x` enters :math:`\mathcal B_1 = \{\|\tilde x\| \le
\gamma/\lambda_m(L)\}` and :math:`\dot{\tilde x} = \tilde f` enters :math:`\mathcal B_2 =
\{\|\tilde f\| \le \gamma\lambda_M(L)/\lambda_m(L) + \gamma\}`.

Discrete time (Eq. (25)): :math:`\tilde x_k = (I - T_s L)\tilde x_{k-1} + T_s\Delta f_{k-1}`, so with
:math:`A = I - T_s L` and :math:`\|\Delta f_k\| \le \gamma`,
:math:`\|\tilde x_k\| \le \|A^k\|\|\tilde x_0\| + T_s\gamma\sum_{j<k}\|A^j\|`; for symmetric
:math:`L`, :math:`\|A^j\| = \rho(A)^j` and the bound is at most
:math:`\rho^k\|\tilde x_0\| + T_s\gamma/(1-\rho)` when :math:`\rho < 1` (ISS).
"""

from __future__ import annotations

import math
import warnings

import torch
from torch import Tensor
from torchdiffeq import odeint

from fnnlib._validation import as_trajectory, check_finite, check_positive
from fnnlib.feedback.gains import gain_matrix
from fnnlib.feedback.types import Estimate, VectorField
from fnnlib.systems.base import DynamicalSystem


def gain_eigen_bounds(L: float | Tensor, n: int) -> tuple[float, float]:
    r"""``(lambda_m, lambda_M)`` of Theorem 1 for a gain ``L`` (scalar, (n,) diagonal or (n, n)).

    ``lambda_m`` is the smallest eigenvalue of the symmetric part (what the
    Lyapunov step :math:`\tilde x^T L \tilde x \ge \lambda_m\|\tilde x\|^2` uses);
    ``lambda_M`` is the largest singular value (so :math:`\|L\tilde x\| \le \lambda_M
    \|\tilde x\|`). For a symmetric positive-definite ``L`` they are its extreme eigenvalues.
    """
    M = gain_matrix(L, n)
    lam_m = float(torch.linalg.eigvalsh(0.5 * (M + M.T)).min())
    if not lam_m > 0:
        raise ValueError(f"Theorem 1 needs a positive-definite gain; the symmetric part of L has "
                         f"smallest eigenvalue {lam_m:.4g}")
    return lam_m, float(torch.linalg.matrix_norm(M, ord=2))


def theorem1_balls(L: float | Tensor, gamma: float, n: int) -> tuple[float, float]:
    """Radii of Theorem 1's balls: ``(gamma / lambda_m, gamma * lambda_M / lambda_m + gamma)``."""
    gamma = float(gamma)
    if not (math.isfinite(gamma) and gamma >= 0):
        raise ValueError(f"residual bound gamma must be finite and >= 0, got {gamma!r}")
    lam_m, lam_M = gain_eigen_bounds(L, n)
    return gamma / lam_m, gamma * lam_M / lam_m + gamma


def discrete_residual(x: Tensor, fx: Tensor, Ts: float) -> Tensor:
    r"""The residual that drives Eq. (25): :math:`\Delta f_k = (x_{k+1} - x_k)/T_s - f_{neural}(x_k)`.

    With it, the observer error of Eqs. (7)-(8) obeys Eq. (25) exactly (the
    Euler remainder of the true motion is part of :math:`\Delta f_k`).
    ``x``, ``fx`` (..., T, n) -> (..., T-1, n).
    """
    Ts = check_positive(Ts, name="Ts")
    x = as_trajectory(x)
    if fx.shape != x.shape:
        raise ValueError(f"shape mismatch: x {tuple(x.shape)} vs f(x) {tuple(fx.shape)}")
    return torch.diff(x, dim=-2) / Ts - fx[..., :-1, :]


def iss_bound(L: float | Tensor, Ts: float, gamma: float, steps: int, *, e0: float = 0.0, n: int = 2) -> Tensor:
    r"""The ISS bound of Eq. (25), for ``k = 0 .. steps-1``:

    .. math:: \|\tilde x_k\| \le \|A^k\|\,e_0 + T_s\gamma\sum_{j<k}\|A^j\|, \quad A = I - T_s L,

    spectral norms, any ``L`` (stable or not). Returns float64 (steps,).
    """
    Ts = check_positive(Ts, name="Ts")
    if int(steps) < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    A = torch.eye(n, dtype=torch.float64) - Ts * gain_matrix(L, n)
    norms = torch.empty(int(steps), dtype=torch.float64)
    P = torch.eye(n, dtype=torch.float64)
    for k in range(int(steps)):
        norms[k] = torch.linalg.matrix_norm(P, ord=2)  # ||A^k||
        P = A @ P
    partial = torch.cat([torch.zeros(1, dtype=torch.float64), torch.cumsum(norms, 0)[:-1]])  # sum_{j<k} ||A^j||
    return norms * float(e0) + Ts * float(gamma) * partial


@torch.no_grad()
def observe_continuous(system: DynamicalSystem, f: VectorField, L: float | Tensor, x0: Tensor, t: Tensor,
                       *, rtol: float = 1e-9, atol: float = 1e-9) -> tuple[Tensor, Estimate]:
    r"""Theorem 1's continuous-time observer, integrated accurately alongside the true system.

    Integrates :math:`\dot x = f(x)` (the true ``system``) together with
    :math:`\dot{\hat x} = f_{neural}(x) + L(x - \hat x)` (Eq. (7) with
    :math:`\dot{\hat x} = \hat f`, the limit :math:`T_s \to 0` of Eq. (8)) by dopri5
    in float64, from :math:`\hat x(0) = x(0)`.

    Parameters
    ----------
    system : DynamicalSystem
        The true dynamics.
    f : callable
        The learned field ``f(t, x)`` in float64 (cast a model with ``.double()``).
    L : float or Tensor
        Gain (scalar, (n,) diagonal or (n, n)).
    x0 : Tensor, shape (..., n)
    t : Tensor, shape (T,)

    Returns
    -------
    x : Tensor, shape (..., T, n)
        The true states at ``t``.
    Estimate
        ``x_hat`` and ``f_hat`` (..., T, n).
    """
    n = system.n
    x0 = torch.as_tensor(x0, dtype=torch.float64)
    t = torch.as_tensor(t, dtype=torch.float64)
    check_finite(x0, name="x0")
    Lm = gain_matrix(L, n)
    lead = x0.shape[:-1]

    def rhs(tt: Tensor, s: Tensor) -> Tensor:
        x, x_hat = s[:, :n], s[:, n:]
        return torch.cat([system(tt, x), f(tt, x) + (x - x_hat) @ Lm.T], dim=-1)  # x_hat' = f_hat   (Eq. 7)

    s0 = torch.cat([x0, x0], dim=-1).reshape(-1, 2 * n)
    sol = odeint(rhs, s0, t, method="dopri5", rtol=rtol, atol=atol).permute(1, 0, 2)
    sol = sol.reshape(*lead, t.numel(), 2 * n)
    x, x_hat = sol[..., :n], sol[..., n:]
    f_hat = f(0.0, x.reshape(-1, n)).reshape(x.shape) + (x - x_hat) @ Lm.T
    return x, Estimate(x_hat, f_hat)


def settling_time(t: Tensor, err: Tensor, t0: float, band: float) -> float:
    """Time after ``t0`` from which ``err`` stays within ``band`` up to the end of the record.

    Returns ``t[k*] - t0`` for the first sample ``k* >= t0`` with ``err[k] <= band``
    for every ``k >= k*``; ``inf`` if the last sample is outside the band.
    ``t`` (T,), ``err`` (T,).
    """
    t, err = torch.as_tensor(t, dtype=torch.float64), torch.as_tensor(err, dtype=torch.float64)
    if t.ndim != 1 or err.shape != t.shape:
        raise ValueError(f"t and err must be 1-D of the same length, got {tuple(t.shape)} and {tuple(err.shape)}")
    after = torch.nonzero(t >= float(t0)).flatten()
    if after.numel() == 0:
        raise ValueError(f"no sample at or after t0 = {t0}")
    outside = torch.nonzero(err[after] > float(band)).flatten()
    if outside.numel() == 0:
        return float(t[after[0]] - t0)
    last = int(after[outside[-1]])
    if last == t.numel() - 1:
        return math.inf
    return float(t[last + 1] - t0)


def growth_factor(err: Tensor, *, early: tuple[float, float] = (0.4, 0.5),
                  late: tuple[float, float] = (0.9, 1.0)) -> Tensor:
    r"""Ratio of the largest ``err`` in a late window to that in an early window (last axis = time).

    Windows are fractions of the record; the defaults compare the last tenth
    with the tenth before the middle, so an error growing like
    :math:`\rho^k` over ``T`` samples gives about :math:`\rho^{T/2}`, a bounded
    one about 1 or less, a linear drift from zero about 2. Shape ``err.shape[:-1]``.
    """
    T = err.shape[-1]

    def window(lo: float, hi: float) -> Tensor:
        a, b = int(round(lo * T)), max(int(round(hi * T)), int(round(lo * T)) + 1)
        return err[..., a:b].amax(dim=-1)

    if T < 2:
        raise ValueError(f"growth_factor needs a record of at least 2 samples along the last axis, got shape "
                         f"{tuple(err.shape)}")
    ratio = window(*late) / window(*early).clamp_min(torch.finfo(err.dtype).tiny)
    bad = ~torch.isfinite(ratio)
    if bool(bad.any()):
        what = "NaN" if bool(torch.isnan(err).any()) else "infinite"
        warnings.warn(f"growth_factor: {int(bad.sum())} of {ratio.numel()} ratios are not finite because err holds "
                      f"{what} values (an overflowed error? use scaled_error_norm); they are returned as NaN/inf",
                      RuntimeWarning, stacklevel=2)
    return ratio


def scaled_error_norm(x: Tensor, x_hat: Tensor) -> Tensor:
    """The 2-norm of ``x - x_hat`` over the last axis without overflow: each row is scaled by its largest entry first.

    A diverging observer (App. A.2) reaches errors of 1e176, whose squares are inf in float64.
    """
    diff = x - x_hat
    scale = diff.abs().amax(-1, keepdim=True).clamp_min(1e-300)
    return (diff / scale).norm(dim=-1) * scale[..., 0]


def divergence_transition(rho: Tensor, diverges: Tensor) -> tuple[int, float, float]:
    """Where runs sorted by spectral radius ``rho`` switch from bounded to diverging (App. A.2).

    Returns the number of class switches along the sorted ``rho``, the largest
    bounded ``rho`` and the smallest diverging one (NaN where there is none).
    """
    if rho.shape != diverges.shape or rho.ndim != 1:
        raise ValueError(f"rho and diverges must be 1-D of one length, got {tuple(rho.shape)}, {tuple(diverges.shape)}")
    cls = diverges[torch.argsort(rho)]
    switches = int((cls[1:] != cls[:-1]).sum())
    rho_lo = float(rho[~diverges].max()) if bool((~diverges).any()) else float("nan")
    rho_hi = float(rho[diverges].min()) if bool(diverges.any()) else float("nan")
    return switches, rho_lo, rho_hi


def reconvergence(t: Tensor, err: Tensor, t_switch: float, *, window: float,
                  band_factor: float) -> dict[str, float]:
    """How fast an error returns to its steady level after a step change at ``t_switch``.

    Steady levels: the largest ``err`` over the ``window`` seconds before the
    switch (``steady_pre``) and over the last ``window`` seconds of the record
    (``steady_post``; the residual, hence the steady error, may differ after
    the switch). ``band = band_factor * max(steady_pre, steady_post)``;
    ``time`` is :func:`settling_time` into that band, ``time_pre_band`` the
    same with the band set by ``steady_pre`` alone. ``t``, ``err``: (T,).
    """
    t, err = torch.as_tensor(t, dtype=torch.float64), torch.as_tensor(err, dtype=torch.float64)
    pre = (t >= t_switch - window) & (t < t_switch)
    post = t >= t[-1] - window
    if not bool(pre.any()) or not bool(post.any()) or float(t[-1]) - window < t_switch:
        raise ValueError(f"need a {window:g} s window before the switch at {t_switch:g} s and after it, within "
                         f"[{float(t[0]):g}, {float(t[-1]):g}] s")
    steady_pre, steady_post = float(err[pre].max()), float(err[post].max())
    band = band_factor * max(steady_pre, steady_post)
    return {"steady_pre": steady_pre, "steady_post": steady_post, "band": band,
            "time": settling_time(t, err, t_switch, band),
            "time_pre_band": settling_time(t, err, t_switch, band_factor * steady_pre)}


def reconvergence_rows(t: Tensor, err: Tensor, t_switch: float, *, window: float,
                       band_factor: float) -> dict[str, list[float]]:
    """:func:`reconvergence` of each row of ``err`` (rows, T) (one seed a row), as one list per key: how fast each
    seed's error returns after the step change of S10 (Fig. S12)."""
    rows = [reconvergence(t, e, t_switch, window=window, band_factor=band_factor) for e in err]
    return {k: [r[k] for r in rows] for k in rows[0]}
