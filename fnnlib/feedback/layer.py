r"""One feedback network, Eqs. (7)-(8), run over a whole input sequence at once.

* Eq. (7) ``feedback_NN``: :math:`\hat f_k = f_{neural}(z_k) + L(z_k - \hat x_k)`
* Eq. (8) ``sys2_2``: :math:`\hat x_{k+1} = \hat x_k + T_s \hat f_k`, i.e.
  :math:`\hat x_{k+1} = (I - T_s L)\hat x_k + T_s(f_{neural}(z_k) + L z_k)`, a
  linear recursion in time solved by the scan of :func:`~fnnlib._scan.linear_recurrence`.

This is the one kernel behind :class:`~fnnlib.LinearFeedback`, the cascade of
Sec. 3.3 (:mod:`fnnlib.feedback.cascade`) and the gain sweeps.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from fnnlib._scan import linear_recurrence, varying_recurrence
from fnnlib._validation import as_trajectory, check_finite, check_positive
from fnnlib.feedback.gains import gain_batch
from fnnlib.feedback.types import Estimate, VectorField


def eval_field(f: VectorField, x: Tensor, u: Tensor | None = None) -> Tensor:
    """Evaluate ``f(t, x)`` (or a controlled ``f(t, x, u)``) on every sample of ``x`` (..., T, n) in one batch.

    ``u`` (..., T, m), when given, holds the input at each sample (broadcast against ``x``'s leading axes)
    and is passed as the third argument. A model whose parameters have another dtype than ``x`` is refused
    with a clear error (``simulate`` returns float64, models are usually float32: call ``x.float()``).
    """
    n = x.shape[-1]
    check_model_dtype(f, x)
    if u is None:
        out = f(0.0, x.reshape(-1, n))
    else:
        u = check_inputs(u, x)
        out = f(0.0, x.reshape(-1, n), u.expand(*x.shape[:-1], u.shape[-1]).reshape(-1, u.shape[-1]))
    if out.shape != (x[..., 0].numel(), n):
        raise ValueError(f"vector field returned shape {tuple(out.shape)} for input {(x[..., 0].numel(), n)}")
    return out.reshape(x.shape)


def check_model_dtype(f: VectorField, x: Tensor) -> None:
    """Raise a clear ``TypeError`` when ``f`` is a module whose floating parameters differ in dtype from ``x``."""
    params = getattr(f, "parameters", None)
    if params is None or not callable(params):
        return
    p = next((q for q in params() if q.is_floating_point()), None)
    if p is not None and p.dtype != x.dtype:
        raise TypeError(f"the model's parameters are {p.dtype} but the states are {x.dtype}; convert one of them "
                        f"(e.g. x.to({p.dtype}) for simulated data, which is float64, or model.to({x.dtype}))")


def check_inputs(u: Tensor, x: Tensor) -> Tensor:
    """Check inputs ``u`` (..., T, m) against states ``x`` (..., T, n): a finite float tensor with x's dtype and T."""
    if not isinstance(u, Tensor) or not u.is_floating_point() or u.ndim < 2:
        raise TypeError(f"inputs u must be a floating-point tensor of shape (..., T, m), got "
                        f"{type(u).__name__} {tuple(getattr(u, 'shape', ()))}")
    if u.shape[-2] != x.shape[-2]:
        raise ValueError(f"inputs u have {u.shape[-2]} samples but the states x have {x.shape[-2]}")
    if u.dtype != x.dtype:
        raise TypeError(f"inputs u are {u.dtype} but the states x are {x.dtype}")
    check_finite(u, name="u")
    return u


def shift_inputs(u: Tensor | None, i: int) -> Tensor | None:
    """``u`` advanced by ``i`` samples along time, the last input held: row k holds ``u_{min(k+i, T-1)}``.

    Layer ``i`` of the cascade steps the state from :math:`t_{k+i}` to :math:`t_{k+i+1}`, so it needs
    the input applied at :math:`t_{k+i}`.
    """
    if u is None or i == 0:
        return u
    T = u.shape[-2]
    idx = torch.clamp(torch.arange(T) + i, max=T - 1)
    return u.index_select(-2, idx)


def feedback_layer(fx: Tensor, z: Tensor, L: Tensor, Ts: float | Tensor, *, diagonal: bool | None = None) -> Estimate:
    r"""Eqs. (7)-(8) along an input sequence ``z`` (..., T, n) for every k at once; :math:`\hat x_0 = z_0`.

    Parameters
    ----------
    fx : Tensor, shape (..., T, n)
        :math:`f_{neural}(z_k)`.
    z : Tensor, shape (..., T, n)
        The layer's input sequence (the measurements for a single layer).
    L : Tensor
        The gain, already validated, in ``z``'s dtype: with ``diagonal`` its
        diagonal, of shape (n,) or (..., n) broadcasting against ``z[..., 0, :]``
        (a batch of gains); else a full (n, n) matrix.
    Ts : float or Tensor (..., T, 1)
        Sample step, or the step of each row (uneven times, :func:`~fnnlib.feedback.sampling.row_steps`):
        :math:`\hat x_{k+1} = \hat x_k + \Delta_k \hat f_k`, a recursion with a transition per step.
    diagonal : bool, optional
        Whether ``L`` holds diagonals; by default a 1-D ``L`` does.

    Returns
    -------
    Estimate
        ``x_hat`` (Eq. (8)) and ``f_hat`` (Eq. (7)), both (..., T, n).
    """
    if diagonal is None:
        diagonal = L.ndim == 1
    varying = isinstance(Ts, Tensor)
    if diagonal:
        Lz = L.unsqueeze(-2)  # the same gain at every time step
        b = Ts * (fx + Lz * z)  # x_hat_{k+1} = (I - Ts L) x_hat_k + Ts (f(z_k) + L z_k)   (Eq. 8)
        if varying:
            x_hat = varying_recurrence((1.0 - Ts * Lz)[..., :-1, :], b[..., :-1, :], z[..., 0, :], diagonal=True)
        else:
            x_hat = linear_recurrence(1.0 - Ts * L, b[..., :-1, :], z[..., 0, :], diagonal=True)
        f_hat = fx + Lz * (z - x_hat)  # f_hat = f_neural + L (z - x_hat)   (Eq. 7)
    else:
        eye = torch.eye(L.shape[0], dtype=L.dtype)
        b = Ts * (fx + z @ L.T)  # (Eq. 8), row-vector form
        if varying:
            A = eye - Ts[..., :-1, :, None] * L  # (..., T-1, n, n): I - Delta_k L
            x_hat = varying_recurrence(A, b[..., :-1, :], z[..., 0, :])
        else:
            x_hat = linear_recurrence(eye - Ts * L, b[..., :-1, :], z[..., 0, :], diagonal=False)
        f_hat = fx + (z - x_hat) @ L.T  # (Eq. 7), row-vector form
    return Estimate(x_hat, f_hat)


def lead_gains(L: Tensor, ndim: int) -> Tensor:
    """Diagonal gains (G, n) -> (G, 1, ..., 1, n) to broadcast against ``z[..., 0, :]`` of a (G, ..., T, n) batch of ``ndim`` axes."""
    return L.reshape(L.shape[0], *([1] * (ndim - 3)), L.shape[-1])


@torch.no_grad()
def observe_gains(f: VectorField, x: Tensor, Ts: float, L: float | Sequence[float] | Tensor,
                  *, allow_unstable: bool = False) -> Estimate:
    r"""The linear feedback Eqs. (7)-(8) along ``x`` for a whole batch of diagonal base gains at once.

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
    L = gain_batch(L, n, Ts, allow_unstable=allow_unstable).to(x.dtype)
    fx = eval_field(f, x)
    expand = (L.shape[0], *x.shape)
    return feedback_layer(fx.expand(expand), x.expand(expand), lead_gains(L, len(expand)), Ts, diagonal=True)
