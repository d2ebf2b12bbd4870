"""The linear feedback network, Eqs. (7)-(8)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import torch
from torch import Tensor

from fnnlib._scan import linear_recurrence
from fnnlib._validation import as_trajectory, check_positive
from fnnlib.observers.gains import check_gain, gain_compact

VectorField = Callable[[Tensor | float, Tensor], Tensor]


class Estimate(NamedTuple):
    """An observer's output along a trajectory, both of shape (..., T, n)."""

    x_hat: Tensor
    f_hat: Tensor


def eval_field(f: VectorField, x: Tensor) -> Tensor:
    """Evaluate an autonomous ``f(t, x)`` on every sample of ``x`` (..., T, n) in one batch."""
    n = x.shape[-1]
    out = f(0.0, x.reshape(-1, n))
    if out.shape != (x[..., 0].numel(), n):
        raise ValueError(f"vector field returned shape {tuple(out.shape)} for input {(x[..., 0].numel(), n)}")
    return out.reshape(x.shape)


def _times(L: Tensor, y: Tensor) -> Tensor:
    """L y for row-vector batches; ``L`` is (n,) diagonal or (n, n)."""
    return y * L if L.ndim == 1 else y @ L.T


def feedback_layer(fx: Tensor, z: Tensor, L: Tensor, Ts: float) -> Estimate:
    r"""One feedback network run over a whole input sequence ``z`` (..., T, n).

    With ``fx = f_neural(z)`` (same shape), for every k at once:

    * Eq. (7) ``feedback_NN``: :math:`\hat f_k = f_{neural}(z_k) + L(z_k - \hat x_k)`
    * Eq. (8) ``sys2_2``: :math:`\hat x_{k+1} = \hat x_k + T_s \hat f_k`,
      i.e. :math:`\hat x_{k+1} = (I - T_s L)\hat x_k + T_s(f_{neural}(z_k) + L z_k)`,
      a linear recursion solved by a scan; :math:`\hat x_0 = z_0`.

    ``L`` is (n,) (diagonal) or (n, n), already validated, in ``z``'s dtype.
    """
    eye = torch.ones_like(L) if L.ndim == 1 else torch.eye(L.shape[0], dtype=L.dtype)
    A = eye - Ts * L
    b = Ts * (fx + _times(L, z))  # x_hat_{k+1} = A x_hat_k + Ts*(f(z_k) + L z_k)   (Eq. 8)
    x_hat = linear_recurrence(A, b[..., :-1, :], z[..., 0, :])
    f_hat = fx + _times(L, z - x_hat)  # f_hat = f_neural + L (x - x_hat)   (Eq. 7)
    return Estimate(x_hat, f_hat)


class LinearFeedback:
    r"""Neural ODE with a linear feedback, Eqs. (7)-(8).

    Parameters
    ----------
    f : callable
        The learned vector field ``f(t, x)``, ``x`` of shape (batch, n).
    L : float, Tensor (n,) or Tensor (n, n)
        Feedback gain (scalar, diagonal or full). Checked by
        :func:`~fnnlib.observers.gains.check_gain`.
    Ts : float
        Sampling step of the measurements.
    n : int
        State dimension.
    allow_unstable : bool
        Accept a gain that is not positive definite or has
        :math:`\rho(I - T_s L) \ge 1`.
    beta : float
        Gain decay rate of Eq. (11) used by :meth:`predict`.
    """

    def __init__(self, f: VectorField, L: float | Tensor, Ts: float, n: int, *, allow_unstable: bool = False,
                 beta: float = 0.0):
        self.f = f
        self.Ts = check_positive(Ts, name="Ts")
        self.n = int(n)
        self.L = check_gain(L, self.n, self.Ts, allow_unstable=allow_unstable)  # (n, n) float64
        self.allow_unstable = bool(allow_unstable)
        self.beta = float(beta)
        if not (math.isfinite(self.beta) and self.beta >= 0):
            raise ValueError(f"decay rate beta must be finite and >= 0, got {beta!r}")

    def observe(self, x: Tensor) -> Estimate:
        """Run the feedback network along measurements ``x`` (..., T, n).

        Returns ``x_hat`` (the estimate of Eq. (8)) and ``f_hat`` (the
        corrected change rate of Eq. (7)), both (..., T, n).
        """
        x = as_trajectory(x, self.n)
        with torch.no_grad():
            fx = eval_field(self.f, x)
        L = gain_compact(self.L, self.n, dtype=x.dtype)
        return feedback_layer(fx, x, L, self.Ts)

    def predict(self, x: Tensor, N: int) -> Tensor:
        """N-step prediction from every sample of ``x`` (..., T, n) by the cascade of Sec. 3.3.

        :func:`~fnnlib.prediction.cascade_predict` with this gain and the decay
        ``beta`` of Eq. (11); row k predicts the state at ``t_{k+N}``.
        """
        from fnnlib.prediction import cascade_predict  # prediction builds on this module

        return cascade_predict(self.f, x, self.Ts, N, self.L, self.beta, allow_unstable=self.allow_unstable)
