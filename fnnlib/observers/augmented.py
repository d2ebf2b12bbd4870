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

**Uneven sample times.** Every observer takes the record's sample times ``t`` (..., T) instead of its
nominal step ``Ts`` (:func:`~fnnlib.feedback.sampling.check_times`). The augmented plant is then
discretised per interval :math:`\Delta_k = t_{k+1} - t_k`. Its continuous form
:math:`\dot z = A_c z + B_c u`, :math:`A_c = \begin{bmatrix} 0 & I\\ 0 & 0\end{bmatrix}`,
:math:`B_c = \begin{bmatrix} I\\ 0\end{bmatrix}`, with :math:`u` held over the step (zero-order hold), has
the exact discretisation :math:`A(\Delta) = e^{A_c\Delta} = I + \Delta A_c`,
:math:`B(\Delta) = \int_0^\Delta e^{A_c s}ds\,B_c = \Delta B_c` (:math:`A_c^2 = 0`): the Euler matrices above
with :math:`T_s` replaced by :math:`\Delta_k` *are* the zero-order-hold discretisation of this plant
(:func:`augmented_step`).

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

from fnnlib._scan import linear_recurrence, varying_recurrence
from fnnlib._validation import as_trajectory, check_positive
from fnnlib.feedback.decay import check_N
from fnnlib.feedback.layer import eval_field, shift_inputs
from fnnlib.feedback.sampling import Steps, check_times, row_steps
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


def augmented_step(A: Tensor, B: Tensor, Ts: float, h: Tensor) -> tuple[Tensor, Tensor]:
    r"""The augmented plant ``A``, ``B`` of step ``Ts`` rediscretised at the steps ``h`` (...,).

    Returns :math:`A(\Delta)` (..., m, m) and :math:`B(\Delta)` (..., m, p).

    The plant is :math:`A(\Delta) = I + \Delta A_c`, :math:`B(\Delta) = \Delta B_c` (module docstring: the exact
    zero-order hold, :math:`A_c` nilpotent), so :math:`A_c = (A - I)/T_s`, :math:`B_c = B/T_s`.
    """
    eye = torch.eye(A.shape[0], dtype=F64)
    h = h.to(F64)[..., None, None]
    return eye + h * ((A - eye) / Ts), h * (B / Ts)


def steps_per_record(dt: Tensor, lead: tuple[int, ...]) -> Tensor:
    """The intervals ``dt`` (..., T-1) of :func:`~fnnlib.feedback.sampling.check_times` expanded to the records'
    leading axes."""
    try:
        return dt.to(F64).expand(*lead, dt.shape[-1])
    except RuntimeError:
        raise ValueError(f"the sample times t have leading axes {tuple(dt.shape[:-1])} but the records have "
                         f"{tuple(lead)}: give one grid (T,) or one per record") from None


def observer_steps(t: Tensor | None, Ts: float, y: Tensor, *, name: str = "y") -> Steps:
    """The observer's nominal ``Ts`` without ``t``; with it, the checked intervals (..., T-1) of ``y``'s sample
    times."""
    if t is None:
        return Ts
    dt = check_times(t, None, y, name=name)
    steps_per_record(dt, tuple(y.shape[:-2]))  # no more time grids than records
    return dt


def check_x0(x0, n: int, lead: tuple[int, ...], dtype: torch.dtype) -> Tensor | None:
    """A first state estimate ``x0``: (n,) or (..., n) broadcasting against the records' leading axes ``lead``,
    finite."""
    if x0 is None:
        return None
    try:
        x0 = torch.as_tensor(x0, dtype=dtype)
    except (TypeError, ValueError, RuntimeError):
        raise TypeError(f"x0 must be a tensor of numbers of shape (n,) = ({n},), got {type(x0).__name__}") from None
    want = f"(n,) = ({n},) or (..., n) matching the records' leading axes {tuple(lead)}"
    if x0.ndim < 1 or x0.shape[-1] != n:
        raise ValueError(f"x0 must have shape {want}, got {tuple(x0.shape)}")
    try:
        x0 = x0.expand(*lead, n) if x0.ndim - 1 <= len(lead) else None
    except RuntimeError:
        x0 = None
    if x0 is None:
        raise ValueError(f"x0 must have shape {want}; its leading axes do not broadcast against them")
    if not bool(torch.isfinite(x0).all()):
        raise ValueError(f"x0 holds a NaN or infinite value: {x0.tolist()}; the first estimate must be finite")
    return x0


def varying_gain_filter(A: Tensor, B: Tensor, C: Tensor, M: Tensor, u: Tensor, y: Tensor,
                        z0: Tensor | None = None) -> Tensor:
    r"""Filtered states of an observer whose plant and filter gain change at every sample (uneven times).

    :math:`\hat z_{k|k} = \hat z_{k|k-1} + M_k(y_k - C\hat z_{k|k-1})`,
    :math:`\hat z_{k+1|k} = A_k \hat z_{k|k} + B_k u_k`, from :math:`\hat z_{0|-1} = [y_0; 0]` (or ``z0``): the
    recursion of :func:`constant_gain_filter` with a plant per interval, solved by the doubling scan of
    :func:`~fnnlib._scan.varying_recurrence` (log2 T batched passes, every leading axis at once).

    Parameters
    ----------
    A, B : Tensor, shapes (..., T-1, m, m), (..., T-1, m, p)
        The plant of each interval (:func:`augmented_step`).
    C : Tensor, shape (q, m)
    M : Tensor, shape (..., T, m, q) or (m, q)
        Filter gains.
    u, y : Tensor, shapes (..., T, p), (..., T, q)
    z0 : Tensor, shape (..., m), optional

    Returns
    -------
    Tensor, shape (..., T, m), float64
    """
    u, y = u.to(F64), y.to(F64)
    T, m = y.shape[-2], A.shape[-1]
    if z0 is None:
        z0 = torch.cat([y[..., 0, :], torch.zeros(*y.shape[:-2], m - y.shape[-1], dtype=F64)], -1)
    lead = torch.broadcast_shapes(y.shape[:-2], A.shape[:-3], z0.shape[:-1], M.shape[:-3] if M.ndim > 2 else ())
    M = M.expand(*lead, T, *M.shape[-2:]) if M.ndim > 2 else M.expand(*lead, T, *M.shape)
    y, u = y.expand(*lead, *y.shape[-2:]), u.expand(*lead, *u.shape[-2:])
    eye = torch.eye(m, dtype=F64)
    # z_{k+1|k} = A_k (I - M_k C) z_{k|k-1} + A_k M_k y_k + B_k u_k: one scan with a transition per step
    Mk = M[..., :-1, :, :]
    trans = A @ (eye - Mk @ C)
    b = (A @ (Mk @ y[..., :-1, :, None]))[..., 0] + (B @ u[..., :-1, :, None])[..., 0]
    prior = varying_recurrence(trans, b, z0.expand(*lead, m))
    return prior + ((y - prior @ C.T)[..., None, :] @ M.mT)[..., 0, :]  # z_{k|k} = z_{k|k-1} + M_k (y_k - C z_{k|k-1})


def constant_gain_filter(A: Tensor, B: Tensor, C: Tensor, L: Tensor, u: Tensor, y: Tensor,
                         z0: Tensor | None = None) -> Tensor:
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
    z0 : Tensor, shape (..., m), optional
        The prior :math:`\hat z_{0|-1}` instead of :math:`[y_0; 0]`.

    Returns
    -------
    Tensor, shape (..., T, m), float64
        :math:`\hat z_{k|k}`.
    """
    u, y = u.to(F64), y.to(F64)
    if z0 is None:
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
def rollout_corrected(f: VectorField, x_start: Tensor, d_hat: Tensor, Ts: float | None, N: int,
                      u: Tensor | None = None, *, t: Tensor | None = None) -> Tensor:
    r"""N Euler steps of the corrected model from every start, the disturbance held frozen.

    :math:`z_{j+1} = z_j + T_s\,(f_{neural}(z_j) + \hat d_k)`, :math:`z_0 = \hat x_k`,
    for all start times k at once (the loop runs over the N steps, not over time).

    Parameters
    ----------
    x_start, d_hat : Tensor, shape (..., T, n)
        Start states and the disturbance estimate at each start.
    Ts : float or None
        The step; ``None`` with ``t``.
    u : Tensor, shape (..., T, m), optional
        Inputs of a controlled model; step ``j`` from start ``k`` uses ``u_{k+j}`` (the last one held).
    t : Tensor, shape (..., T), optional
        The sample times instead of ``Ts``: step ``j`` from start ``k`` is :math:`\Delta_{k+j}`, so row k
        predicts the state at the record's own :math:`t_{k+N}` (past the record's end the last interval
        is repeated, :func:`~fnnlib.feedback.sampling.row_steps`).

    Returns
    -------
    Tensor, shape (..., T, n)
        Row k predicts the state at :math:`t_{k+N}`.
    """
    if x_start.shape != d_hat.shape:
        raise ValueError(f"x_start {tuple(x_start.shape)} and d_hat {tuple(d_hat.shape)} differ in shape")
    N = check_N(N)
    dt = check_times(t, Ts, x_start, name="x_start")
    T = x_start.shape[-2]
    z = x_start
    for j in range(N):
        h = row_steps(dt, j, T) if T > 1 else dt
        if isinstance(h, Tensor):
            h = h.to(z.dtype)
        z = z + h * (eval_field(f, z, shift_inputs(u, j)) + d_hat)  # x_{j+1} = x_j + Delta (f(x_j, u_j) + d_hat)
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

    def _estimate(self, x: Tensor, u: Tensor | None, mask: Tensor | None, **kw) -> DisturbanceEstimate:
        """:meth:`estimate`, with ``mask`` only for the filters that take gaps (``kw``: ``t``, ``x0``)."""
        kw = {k: v for k, v in kw.items() if v is not None}
        if mask is None:
            return self.estimate(x, u, **kw)
        if not getattr(self, "takes_gaps", False):
            raise NotImplementedError(f"{type(self).__name__} evaluates the learned field at the measurement "
                                      "(Eq. (7)), so it needs every sample; for gaps use ExtendedKalmanObserver, "
                                      "UnscentedKalmanObserver or MeasuredFeedback")
        return self.estimate(x, u, mask=mask, **kw)

    def inputs(self, x: Tensor, u_ext: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """The checked measurements ``y`` (..., T, n) and the known input :math:`u_k = f_{neural}(y_k)`, as in Eq. (7).

        For a controlled model, ``u_ext`` (..., T, m) are its inputs: :math:`u_k = f_{neural}(y_k, u^{ext}_k)`.
        """
        x = as_trajectory(x, self.n)
        with torch.no_grad():
            u = eval_field(self.f, x, u_ext)
        return x, u

    def start_prior(self, x: Tensor, x0) -> Tensor | None:
        """The prior :math:`\\hat z_{0|-1} = [x_0; 0]` (..., 2n) from a checked first estimate ``x0``, or None (then
        :math:`[y_0; 0]`)."""
        x0 = check_x0(x0, self.n, tuple(x.shape[:-2]), F64)
        return None if x0 is None else torch.cat([x0, torch.zeros_like(x0)], -1)

    def constant_gain_estimate(self, x: Tensor, u: Tensor, L: Tensor, u_ext: Tensor | None = None, *,
                               dt: Steps | None = None, x0=None, M: Tensor | None = None) -> DisturbanceEstimate:
        """:func:`constant_gain_filter` with the predictor-form gain ``L`` (2n, n), split into the estimate.

        With intervals ``dt`` (..., T-1) (uneven times) the plant is :func:`augmented_step` per interval and the
        filter gain ``M`` (..., T, 2n, n) (default :math:`A_k^{-1}L`, ``L`` then (..., T, 2n, n)):
        :func:`varying_gain_filter`. ``x0``: the first estimate instead of :math:`y_0`.
        """
        z0 = self.start_prior(x, x0)
        if dt is None or not isinstance(dt, Tensor):
            z = constant_gain_filter(self.A, self.B, self.C, L, u, x, z0)
        else:
            Ak, Bk = augmented_step(self.A, self.B, self.Ts, steps_per_record(dt, tuple(x.shape[:-2])))
            if M is None:  # the filter gain of sample k pairs with the step after it (the last one repeats)
                A_after = torch.cat([Ak, Ak[..., -1:, :, :]], -3)
                M = torch.linalg.solve(A_after, L)
            z = varying_gain_filter(Ak, Bk, self.C, M, u, x, z0)
        return split_estimate(self.f, z, x, u_ext)

    def observe(self, x: Tensor, u: Tensor | None = None, *, mask: Tensor | None = None, t: Tensor | None = None,
                x0=None) -> Estimate:
        """``x_hat`` (filtered, :math:`\\hat x_{k|k}`), ``f_hat`` (model rate + :math:`\\hat d_{k|k}`), (..., T, n).

        ``u`` (..., T, m): inputs of a controlled model; ``mask``: missing samples (the filters that take gaps);
        ``t`` (..., T): the sample times instead of the nominal ``Ts`` (module docstring); ``x0`` (n,) or
        (..., n): the first state estimate instead of the one from the first measurement.
        """
        return self._estimate(x, u, mask, t=t, x0=x0).as_estimate()

    def predict(self, x: Tensor, N: int, u: Tensor | None = None, *, mask: Tensor | None = None,
                t: Tensor | None = None, x0=None) -> Tensor:
        """N-step predictions from every sample: :func:`rollout_corrected` from :math:`\\hat x_{k|k}, \\hat d_{k|k}`.

        With ``t`` the rollout steps along the record's own times (row k predicts the state at :math:`t_{k+N}`).
        """
        N = check_N(N)
        est = self._estimate(x, u, mask, t=t, x0=x0)
        return rollout_corrected(self.f, est.x_hat, est.d_hat, None if t is not None else self.Ts, N, u, t=t)
