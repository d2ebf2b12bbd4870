"""Parameter sweeps in one tensor pass: batches of gains, decay rates and uncertainty levels.

The ablations of Sec. 3.4 and App. A.3 run the linear feedback (Eqs. (7)-(8))
and the cascade with gain decay (Eq. (11)) for many gains and many test
systems. Here a sweep is a leading batch axis ``G``: every gain (and decay
rate) of the sweep runs on every trajectory at once, with one batched network
call and one linear scan per cascade layer. The paper writes its grids in
MATLAB colon form ``{start: +step: stop}``; :func:`colon_range` reads them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from fnnlib._scan import linear_recurrence
from fnnlib._validation import as_trajectory, check_positive
from fnnlib.observers.gains import check_gain
from fnnlib.observers.linear import Estimate, VectorField, eval_field
from fnnlib.systems.base import DynamicalSystem


def colon_range(start: float, step: float, stop: float) -> Tensor:
    """The paper's grid ``{start: +step: stop}`` (MATLAB ``start:step:stop``), stop included.

    Returns a float64 tensor ``start + step * i`` for ``i = 0 .. floor((stop - start) / step)``
    (with a 1e-9 relative tolerance, so ``{0.04: 0.02: 0.22}`` has 10 values, not 9).

    Examples
    --------
    >>> colon_range(0, 5, 45).tolist()[-1]
    45.0
    """
    start, step, stop = float(start), float(step), float(stop)
    if not all(math.isfinite(v) for v in (start, step, stop)):
        raise ValueError(f"grid {{{start}: {step}: {stop}}} holds a non-finite value")
    if step == 0 or (stop - start) * step < 0:
        raise ValueError(f"grid {{{start}: {step}: {stop}}} is empty: step must be non-zero and point from "
                         "start towards stop")
    count = math.floor((stop - start) / step * (1 + 1e-9) + 1e-9) + 1
    return start + step * torch.arange(count, dtype=torch.float64)


def paired_levels(*grids: Sequence[float] | Tensor) -> Tensor:
    """Stack grids of equal length column-wise: level ``i`` takes the ``i``-th value of every grid.

    The paper's uncertainty levels pair their parameters this way (App. A.3.4:
    level ``i`` is ``(omega_i, eta_i, eps_i)``). Returns shape (levels, len(grids)).
    """
    cols = [torch.as_tensor(g, dtype=torch.float64).reshape(-1) for g in grids]
    if not cols:
        raise ValueError("paired_levels needs at least one grid")
    counts = [c.numel() for c in cols]
    if len(set(counts)) != 1:
        raise ValueError(f"grids paired into levels must have the same length, got lengths {counts}")
    return torch.stack(cols, dim=-1)


def simulate_levels(systems: Sequence[DynamicalSystem], x0: Tensor, t: Tensor) -> Tensor:
    """Simulate each system from ``x0`` on the grid ``t``; stack on a leading axis.

    Returns float64 of shape (len(systems), ..., T, n) for ``x0`` of shape (..., n).
    """
    if len(systems) == 0:
        raise ValueError("simulate_levels needs at least one system")
    return torch.stack([s.simulate(x0, t) for s in systems])


def _gain_batch(L: float | Sequence[float] | Tensor, n: int, Ts: float, *, allow_unstable: bool) -> Tensor:
    """Gains as a (G, n) float64 tensor of diagonals; each checked by :func:`check_gain`.

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


def _decay_batch(beta: float | Sequence[float] | Tensor, G: int) -> tuple[Tensor, int]:
    """Decay rates as a float64 tensor broadcastable against G gains; returns (beta, batch size)."""
    beta = torch.as_tensor(beta, dtype=torch.float64).reshape(-1)
    if beta.numel() == 0 or not bool(torch.isfinite(beta).all()) or bool((beta < 0).any()):
        raise ValueError(f"decay rates beta must be finite and >= 0, got {beta.tolist()}")
    if beta.numel() != 1 and G != 1 and beta.numel() != G:
        raise ValueError(f"{G} gains and {beta.numel()} decay rates do not pair up (give one of either, or as many)")
    return beta, max(G, beta.numel())


def _lead(v: Tensor, ndim: int) -> Tensor:
    """(G, n) -> (G, 1, ..., 1, n) to broadcast against a (G, ..., T, n) trajectory batch of ``ndim`` axes."""
    return v.reshape(v.shape[0], *([1] * (ndim - 2)), v.shape[-1])


def _feedback_batch(fz: Tensor, z: Tensor, L: Tensor, Ts: float) -> Estimate:
    """Eqs. (7)-(8) for a batch of diagonal gains: ``z``, ``fz`` (G, ..., T, n), ``L`` (G, n)."""
    Lb = _lead(L, z.ndim)
    b = Ts * (fz + Lb * z)  # x_hat_{k+1} = (1 - Ts L) x_hat_k + Ts (f(z_k) + L z_k)   (Eq. 8)
    x_hat = linear_recurrence((1.0 - Ts * Lb).squeeze(-2), b[..., :-1, :], z[..., 0, :], diagonal=True)
    f_hat = fz + Lb * (z - x_hat)  # f_hat = f_neural + L (z - x_hat)   (Eq. 7)
    return Estimate(x_hat, f_hat)


@torch.no_grad()
def observe_gains(f: VectorField, x: Tensor, Ts: float, L: float | Sequence[float] | Tensor,
                  *, allow_unstable: bool = False) -> Estimate:
    r"""The linear feedback Eqs. (7)-(8) along ``x`` for a whole batch of diagonal gains at once.

    Equals :meth:`fnnlib.LinearFeedback.observe` run once per gain.

    Parameters
    ----------
    f : callable
        Learned vector field ``f(t, x)``, evaluated once on ``x``.
    x : Tensor, shape (..., T, n)
        Measurements.
    Ts : float
        Sample step.
    L : float, Tensor (G,) or Tensor (G, n)
        G scalar gains (``L_g I``) or G diagonal gains.
    allow_unstable : bool
        Accept gains with :math:`\rho(I - T_s L) \ge 1` (to show divergence, App. A.2).

    Returns
    -------
    Estimate
        ``x_hat`` and ``f_hat`` of shape (G, ..., T, n).
    """
    Ts = check_positive(Ts, name="Ts")
    x = as_trajectory(x, x.shape[-1] if isinstance(x, Tensor) else None)
    n = x.shape[-1]
    gains = _gain_batch(L, n, Ts, allow_unstable=allow_unstable).to(x.dtype)
    G = gains.shape[0]
    fx = eval_field(f, x)
    expand = (G, *x.shape)
    return _feedback_batch(fx.expand(expand), x.expand(expand), gains, Ts)


@torch.no_grad()
def cascade_sweep(f: VectorField, x: Tensor, Ts: float, N: int, L: float | Sequence[float] | Tensor,
                  beta: float | Sequence[float] | Tensor = 0.0, *, allow_unstable: bool = False) -> Tensor:
    r"""The N-step cascade (Sec. 3.3, Eq. (11)) for a batch of (gain, decay rate) pairs in one pass.

    Batch element ``g`` runs :func:`fnnlib.cascade_predict` with gain ``L_g`` and
    decay rate ``beta_g``: layer ``i`` uses :math:`L_g e^{-\beta_g i}`. Gains and
    decay rates pair up by broadcasting (one of either, or as many of each).

    Parameters
    ----------
    f : callable
        Learned vector field ``f(t, x)``.
    x : Tensor, shape (..., T, n)
        Measurements (any leading axes: levels, noise draws).
    Ts : float
        Sample step (also the prediction step).
    N : int
        Prediction steps (layers).
    L : float, Tensor (G,) or Tensor (G, n)
        Scalar or diagonal base gains.
    beta : float or Tensor (G,)
        Decay rates of Eq. (11).

    Returns
    -------
    Tensor, shape (G, ..., T, n)
        Row ``k`` predicts the state at ``t_{k+N}``.
    """
    if int(N) != N or int(N) < 1:
        raise ValueError(f"number of prediction steps N must be an integer >= 1, got {N!r}")
    Ts = check_positive(Ts, name="Ts")
    x = as_trajectory(x, x.shape[-1] if isinstance(x, Tensor) else None)
    n = x.shape[-1]
    gains = _gain_batch(L, n, Ts, allow_unstable=allow_unstable).to(x.dtype)
    betas, G = _decay_batch(beta, gains.shape[0])
    gains = gains.expand(G, n)
    z = x.expand(G, *x.shape)
    for i in range(int(N)):
        L_i = gains * torch.exp(-betas * i).to(x.dtype)[:, None]  # L_i = L e^{-beta i}   (Eq. 11)
        _, f_hat = _feedback_batch(eval_field(f, z), z, L_i, Ts)
        z = z + Ts * f_hat  # z^{(i+1)} = z^{(i)} + Ts f_hat^{(i)}
    return z


def n_step_errors(pred: Tensor, truth: Tensor, N: int) -> Tensor:
    """2-norm errors of N-step predictions from every start that has a truth sample N steps later.

    ``pred`` (..., T, n): row ``k`` predicts ``truth[..., k + N, :]`` (the
    layout of :func:`cascade_sweep` and :func:`fnnlib.cascade_predict`);
    ``truth`` (T, n) or broadcastable. Returns shape (..., T - N).
    """
    N = int(N)
    T = truth.shape[-2]
    if not 1 <= N < T or pred.shape[-2] != T:
        raise ValueError(f"need 1 <= N < T and predictions of length T; got N={N}, T={T}, "
                         f"prediction length {pred.shape[-2]}")
    return torch.linalg.vector_norm(pred[..., : T - N, :] - truth[..., N:, :], dim=-1)


def outward_increase_fraction(err: Tensor, center: int) -> Tensor:
    """Fraction of steps away from level ``center`` along the last axis where ``err`` increases.

    For levels ordered by a parameter that is nominal at index ``center``
    (uncertainty grows both left and right of it), each adjacent pair
    ``(j, j+1)`` right of the centre counts as increasing if
    ``err[j+1] > err[j]``, and each pair left of it if ``err[j-1] > err[j]``.
    Returns the fraction per leading index, shape ``err.shape[:-1]``.
    """
    m = err.shape[-1]
    if not 0 <= int(center) < m or m < 2:
        raise ValueError(f"centre level {center} must index one of {m} >= 2 levels")
    c = int(center)
    right = err[..., c + 1:] > err[..., c:-1]
    left = err[..., :c] > err[..., 1:c + 1]
    steps = torch.cat([left, right], dim=-1)
    return steps.double().mean(dim=-1)
