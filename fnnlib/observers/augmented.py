r"""The learned model with a constant-disturbance state: the plant every observer of S11 estimates.

The true change rate is the learned one plus an unknown disturbance,
:math:`\dot x = f_{neural}(x) + d` with :math:`d = \Delta f` (the residual of
Assumption 1), modelled as constant, :math:`\dot d = 0`. Discretised by Euler
at the sample step :math:`T_s` (the discretisation of Eq. (8)) and measured
in full with noise, the augmented state :math:`z = [x; d]` (2n) obeys

.. math::
    z_{k+1} = A z_k + B f_{neural}(x_k), \qquad y_k = C z_k + v_k,
    \qquad A = \begin{bmatrix} I & T_s I\\ 0 & I\end{bmatrix},\;
    B = \begin{bmatrix} T_s I\\ 0\end{bmatrix},\; C = [I\;\; 0].

An observer that evaluates the learned field at the *measurement*,
:math:`u_k = f_{neural}(y_k)`, as the linear feedback of Eqs. (7)-(8) does,
sees a linear plant with a known input, so its error dynamics are exactly
:math:`A - LC` (up to :math:`f_{neural}(x_k) - f_{neural}(y_k)`, of the
order of the noise): no linearisation is needed, and the estimate along a
whole trajectory is one linear recursion solved by a scan.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from fnnlib._scan import linear_recurrence
from fnnlib._validation import as_trajectory, check_positive
from fnnlib.feedback.decay import check_N
from fnnlib.feedback.layer import eval_field, shift_inputs
from fnnlib.feedback.types import Estimate, VectorField

F64 = torch.float64


class DisturbanceEstimate(NamedTuple):
    """An augmented-state observer's output, each of shape (..., T, n).

    ``x_hat`` and ``d_hat`` are the filtered estimates :math:`\\hat x_{k|k}`,
    :math:`\\hat d_{k|k}` (measurements up to k); ``f_hat`` is the corrected
    change rate :math:`f_{neural} + \\hat d_{k|k}`.
    """

    x_hat: Tensor
    d_hat: Tensor
    f_hat: Tensor

    def as_estimate(self) -> Estimate:
        """The ``(x_hat, f_hat)`` pair every observer returns."""
        return Estimate(self.x_hat, self.f_hat)


def augmented_matrices(n: int, Ts: float) -> tuple[Tensor, Tensor, Tensor]:
    """``A`` (2n, 2n), ``B`` (2n, n), ``C`` (n, 2n) of the Euler model with a constant disturbance, float64."""
    n = int(n)
    if n < 1:
        raise ValueError(f"state dimension n must be >= 1, got {n}")
    eye, zero = torch.eye(n, dtype=F64), torch.zeros(n, n, dtype=F64)
    A = torch.cat([torch.cat([eye, Ts * eye], 1), torch.cat([zero, eye], 1)], 0)  # x += Ts d; d = d
    B = torch.cat([Ts * eye, zero], 0)  # x += Ts u, u = f_neural
    C = torch.cat([eye, zero], 1)  # y = x
    return A, B, C


def constant_gain_filter(A: Tensor, B: Tensor, C: Tensor, L: Tensor, u: Tensor, y: Tensor) -> Tensor:
    r"""Filtered states of a constant-gain observer in predictor form, all steps at once.

    The prior :math:`\hat z_{k|k-1}` follows
    :math:`\hat z_{k+1|k} = (A - LC)\hat z_{k|k-1} + B u_k + L y_k` from
    :math:`\hat z_{0|-1} = [y_0; 0]` (a linear recursion, solved by the
    scan of :func:`~fnnlib._scan.linear_recurrence`), and the filtered state is
    :math:`\hat z_{k|k} = \hat z_{k|k-1} + M(y_k - C\hat z_{k|k-1})` with
    :math:`M = A^{-1}L`, so that :math:`\hat z_{k+1|k} = A\hat z_{k|k} + B u_k`.
    For the Kalman filter :math:`M` is the filter gain :math:`K` and
    :math:`L = AK` the gain of ``control.dlqe``.

    Parameters
    ----------
    A, B, C : Tensor, shapes (m, m), (m, p), (q, m)
        Plant; ``A`` invertible.
    L : Tensor, shape (m, q)
        Predictor-form observer gain.
    u : Tensor, shape (..., T, p)
        Known inputs.
    y : Tensor, shape (..., T, q)
        Measurements.

    Returns
    -------
    Tensor, shape (..., T, m), float64
        :math:`\hat z_{k|k}`.
    """
    u, y = u.to(F64), y.to(F64)
    z0 = torch.cat([y[..., 0, :], torch.zeros(*y.shape[:-2], A.shape[0] - y.shape[-1], dtype=F64)], -1)
    b = u @ B.T + y @ L.T  # z_{k+1|k} = (A - L C) z_{k|k-1} + B u_k + L y_k
    prior = linear_recurrence(A - L @ C, b[..., :-1, :], z0)
    M = torch.linalg.solve(A, L)
    return prior + (y - prior @ C.T) @ M.T  # z_{k|k} = z_{k|k-1} + M (y_k - C z_{k|k-1})


def split_estimate(f: VectorField, z: Tensor, y: Tensor, u: Tensor | None = None) -> DisturbanceEstimate:
    """Split filtered augmented states ``z`` (..., T, 2n) into the estimate, in ``y``'s dtype.

    The change rate is the observer's own model, :math:`\\hat f_k = f_{neural}(y_k) + \\hat d_{k|k}`.
    """
    n = y.shape[-1]
    x_hat, d_hat = z[..., :n].to(y.dtype), z[..., n:].to(y.dtype)
    with torch.no_grad():
        f_hat = eval_field(f, y, u) + d_hat
    return DisturbanceEstimate(x_hat, d_hat, f_hat)


@torch.no_grad()
def rollout_corrected(f: VectorField, x_start: Tensor, d_hat: Tensor, Ts: float, N: int,
                      u: Tensor | None = None) -> Tensor:
    r"""N Euler steps of the corrected model from every start, the disturbance held frozen.

    :math:`z_{j+1} = z_j + T_s\,(f_{neural}(z_j) + \hat d_k)`, :math:`z_0 = \hat x_k`,
    for all start times k at once (the loop runs over the N steps, not over time).

    Parameters
    ----------
    x_start, d_hat : Tensor, shape (..., T, n)
        Start states and the disturbance estimate at each start.
    u : Tensor, shape (..., T, m), optional
        Inputs of a controlled model; step ``j`` from start ``k`` uses ``u_{k+j}`` (the last one held).

    Returns
    -------
    Tensor, shape (..., T, n)
        Row k predicts the state at :math:`t_{k+N}`.
    """
    if x_start.shape != d_hat.shape:
        raise ValueError(f"x_start {tuple(x_start.shape)} and d_hat {tuple(d_hat.shape)} differ in shape")
    z = x_start
    for j in range(check_N(N)):
        z = z + Ts * (eval_field(f, z, shift_inputs(u, j)) + d_hat)  # x_{j+1} = x_j + Ts (f(x_j, u_j) + d_hat)
    return z


class AugmentedObserver:
    """What the Luenberger and Kalman observers share: the augmented plant, :meth:`observe` and :meth:`predict`.

    Subclasses implement :meth:`estimate`, the filtered state, disturbance and change rate.

    Parameters
    ----------
    f : callable
        The learned vector field ``f(t, x)``, ``x`` of shape (batch, n).
    Ts : float
        Sampling step.
    n : int
        State dimension.

    Attributes
    ----------
    A, B, C : Tensor
        Augmented plant of :func:`augmented_matrices`, (2n, 2n), (2n, n), (n, 2n).
    """

    def __init__(self, f: VectorField, Ts: float, n: int):
        self.f = f
        self.Ts = check_positive(Ts, name="Ts")
        self.n = int(n)
        self.A, self.B, self.C = augmented_matrices(self.n, self.Ts)

    def estimate(self, x: Tensor, u: Tensor | None = None, **kw) -> DisturbanceEstimate:  # pragma: no cover
        raise NotImplementedError

    def _estimate(self, x: Tensor, u: Tensor | None, mask: Tensor | None) -> DisturbanceEstimate:
        """:meth:`estimate`, with ``mask`` only for the filters that take gaps."""
        if mask is None:
            return self.estimate(x, u)
        if not getattr(self, "takes_gaps", False):
            raise NotImplementedError(f"{type(self).__name__} evaluates the learned field at the measurement "
                                      "(Eq. (7)), so it needs every sample; for gaps use ExtendedKalmanObserver, "
                                      "UnscentedKalmanObserver or MeasuredFeedback")
        return self.estimate(x, u, mask=mask)

    def inputs(self, x: Tensor, u_ext: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """The checked measurements ``y`` (..., T, n) and the known input :math:`u_k = f_{neural}(y_k)`, as in Eq. (7).

        For a controlled model, ``u_ext`` (..., T, m) are its inputs: :math:`u_k = f_{neural}(y_k, u^{ext}_k)`.
        """
        x = as_trajectory(x, self.n)
        with torch.no_grad():
            u = eval_field(self.f, x, u_ext)
        return x, u

    def constant_gain_estimate(self, x: Tensor, u: Tensor, L: Tensor,
                               u_ext: Tensor | None = None) -> DisturbanceEstimate:
        """:func:`constant_gain_filter` with the predictor-form gain ``L`` (2n, n), split into the estimate."""
        return split_estimate(self.f, constant_gain_filter(self.A, self.B, self.C, L, u, x), x, u_ext)

    def observe(self, x: Tensor, u: Tensor | None = None, *, mask: Tensor | None = None) -> Estimate:
        """``x_hat`` (filtered, :math:`\\hat x_{k|k}`), ``f_hat`` (model rate + :math:`\\hat d_{k|k}`), (..., T, n).

        ``u`` (..., T, m): inputs of a controlled model; ``mask``: missing samples (the filters that take gaps).
        """
        return self._estimate(x, u, mask).as_estimate()

    def predict(self, x: Tensor, N: int, u: Tensor | None = None, *, mask: Tensor | None = None) -> Tensor:
        """N-step predictions from every sample: :func:`rollout_corrected` from :math:`\\hat x_{k|k}, \\hat d_{k|k}`."""
        N = check_N(N)
        est = self._estimate(x, u, mask)
        return rollout_corrected(self.f, est.x_hat, est.d_hat, self.Ts, N, u)
