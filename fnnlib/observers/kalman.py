r"""Kalman filters with a constant-disturbance state: filterpy's KF on the augmented model, its EKF on the learned one.

Both estimate :math:`z = [x; d]` of :mod:`fnnlib.observers.augmented` with
process noise :math:`w_k \sim \mathcal N(0, Q)` on :math:`z_{k+1}` (on
:math:`x`: model error within a step; on :math:`d`: a random walk, how fast
the disturbance drifts) and measurement noise :math:`v_k \sim \mathcal N(0, R)`
on :math:`y_k = C z_k + v_k`.

* :class:`KalmanObserver`: ``filterpy.kalman.KalmanFilter`` on the linear plant
  :math:`z_{k+1} = A z_k + B f_{neural}(y_k)` (the learned field evaluated at
  the measurement, as in Eq. (7)); exact, no linearisation. With
  ``steady_state=True`` it uses the stationary gain of the Riccati equation
  instead (:func:`steady_state_gain`, equal to ``control.dlqe``), which runs
  as one scan over time.
* :class:`ExtendedKalmanObserver`: ``filterpy.kalman.ExtendedKalmanFilter``
  propagating the estimate through the learned model itself,
  :math:`\hat x_{k+1|k} = \hat x_{k|k} + T_s(f_{neural}(\hat x_{k|k}) + \hat d_{k|k})`,
  with the Jacobian of :math:`f_{neural}` by autograd. filterpy steps one
  sample at a time, so this one loops over time (and over batch) in Python.

**Uneven sample times** ``t`` (..., T) (every ``estimate``/``observe``/``predict`` takes ``t=`` instead of the
nominal ``Ts`` given at construction): each interval :math:`\Delta_k = t_{k+1} - t_k` has its own transition.

* The plant evaluated at the measurement (the full-state :class:`KalmanObserver`) is linear, and its
  transition :math:`A(\Delta_k) = I + \Delta_k A_c`, :math:`B(\Delta_k) = \Delta_k B_c` is its exact
  zero-order-hold discretisation (:func:`~fnnlib.observers.augmented.augmented_step`).
* The model evaluated at the estimate (the EKF, the UKF, the filters with ``C``) steps by Euler with
  :math:`\Delta_k`: :math:`\Phi_{\Delta}(x, d) = (x + \Delta(f(x, u) + E d),\; d)`.
* **Process noise convention**: ``Q`` is the covariance of one *nominal* step ``Ts`` and is scaled with the
  interval, :math:`Q_k = Q\,\Delta_k / T_s` (a random walk's variance grows linearly with the time elapsed;
  for the model error on :math:`x` this is the first-order value of the continuous-time integral).
* ``steady_state=True``: a stationary gain belongs to one step, so with ``t`` the filter gain :math:`K` of the
  nominal ``Ts`` (:func:`steady_state_gain`) is held at every sample while the prediction steps by
  :math:`\Delta_k`; the time-varying filter (``steady_state=False``) is the optimal one per interval.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import torch
from torch import Tensor

from fnnlib._validation import as_trajectory
from fnnlib.feedback.gains import gain_matrix
from fnnlib.feedback.layer import eval_field
from fnnlib.feedback.measurement import check_detectable, check_measurements, check_output_matrix, model_jacobian
from fnnlib.feedback.types import VectorField
from fnnlib.observers.augmented import (
    AugmentedObserver,
    DisturbanceEstimate,
    augmented_step,
    check_x0,
    observer_steps,
    split_estimate,
    steps_per_record,
)
from fnnlib.observers.options import Covariances

if TYPE_CHECKING:
    from filterpy.kalman import KalmanFilter

#: Beyond this magnitude the squared deviations a filter forms overflow float64 (its largest value is ~1.8e308).
SQUARE_LIMIT = 1e150


class SteadyState(NamedTuple):
    """Stationary Kalman filter of :func:`steady_state_gain` (numpy float64 arrays)."""

    K: np.ndarray  # filter gain (m, q):    z_{k|k} = z_{k|k-1} + K (y_k - C z_{k|k-1})
    L: np.ndarray  # predictor gain (m, q): L = A K, the gain control.dlqe returns
    P: np.ndarray  # a-priori error covariance (m, m), the Riccati solution control.dlqe returns


def as_covariance(M: float | Tensor | list, m: int, *, name: str, definite: bool = False) -> Tensor:
    """A covariance (m, m) float64 from a scalar (times I), a vector (diagonal) or a matrix; checked PSD (or PD)."""
    try:
        M = gain_matrix(M, m)
    except TypeError:
        raise TypeError(f"{name} must be a number, a vector or a matrix of numbers, got {M!r}") from None
    except ValueError:
        raise ValueError(f"{name} must be a scalar, a vector of length {m} or an ({m}, {m}) matrix; "
                         f"got shape {tuple(torch.as_tensor(M).shape)}") from None
    if not bool(torch.isfinite(M).all()) or not torch.allclose(M, M.T):
        raise ValueError(f"{name} must be a finite symmetric matrix, got {M.tolist()}")
    low = float(torch.linalg.eigvalsh(M).min())
    if low < 0 or (definite and low <= 0):
        need = "positive definite" if definite else "positive semi-definite"
        raise ValueError(f"{name} must be {need} (smallest eigenvalue {low:.3g})")
    return M


def steady_state_gain(A, C, Q, R) -> SteadyState:
    r"""Stationary Kalman gain from the discrete algebraic Riccati equation (``scipy.linalg.solve_discrete_are``).

    .. math::
        P = A P A^T + Q - A P C^T (C P C^T + R)^{-1} C P A^T,
        \qquad K = P C^T (C P C^T + R)^{-1}, \qquad L = A K.

    :math:`P` is the a-priori covariance, the one ``control.dlqe(A, I, C, Q, R)``
    returns with its gain :math:`L` (predictor form); filterpy's
    ``KalmanFilter.K`` converges to :math:`K` (filter form).

    Parameters
    ----------
    A : array, shape (m, m)
    C : array, shape (q, m)
    Q : array, shape (m, m)
        Process noise covariance (on the state directly, G = I).
    R : array, shape (q, q)
        Measurement noise covariance, positive definite.

    Raises
    ------
    RuntimeError
        If the equation has no stabilising solution ((A, C) not detectable, or Q not positive definite on the
        unstable modes).
    """
    from scipy.linalg import solve_discrete_are  # noqa: PLC0415 (scipy.linalg loads only where it is used)

    A, C, Q, R = (np.asarray(M, dtype=float) for M in (A, C, Q, R))
    try:
        P = solve_discrete_are(A.T, C.T, Q, R)  # the filter's DARE is the control DARE of (A^T, C^T)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise RuntimeError(f"the Riccati equation has no stabilising solution ({exc}): is (A, C) detectable and "
                           "Q positive definite on the unstable modes?") from exc
    P = 0.5 * (P + P.T)
    K = np.linalg.solve(C @ P @ C.T + R, C @ P).T  # K = P C' (C P C' + R)^-1
    return SteadyState(K=K, L=A @ K, P=P)


class _OutputModel(AugmentedObserver):
    r"""The augmented model with a measurement ``C`` and a disturbance layout ``E``, and its detectability check.

    ``disturbance`` ``E`` (n, q) (or a list of the q states it acts on): :math:`\dot x = f(x, u) + E d`,
    default every state (E = I). With a ``C`` or an ``E``, the augmented pair is checked for detectability
    at the model's Jacobian ``A`` (default: at the origin) and refused with the PBH reason. Without either the
    full-state plant needs no Jacobian, and an ``A`` is refused rather than ignored.
    """

    def __init__(self, f: VectorField, Ts: float, n: int, *, C=None, disturbance=None, A=None):
        if A is not None and C is None and disturbance is None:
            raise ValueError("the model Jacobian A is where the output form (C or disturbance) is linearised and "
                             "checked; the full-state observer needs none: give C or disturbance, or no A")
        super().__init__(f, Ts, n)
        self.C_x = None if C is None else check_output_matrix(C, self.n)  # partial measurements y = C x
        self.E = None if disturbance is None else disturbance_matrix(disturbance, self.n)
        q = self.n if self.E is None else self.E.shape[1]
        if self.E is not None:
            eye = torch.eye(self.n, dtype=torch.float64)
            self.A = torch.block_diag(eye, torch.eye(q, dtype=torch.float64))
            self.A[: self.n, self.n:] = self.Ts * self.E  # x += Ts E d; d = d
            self.B = torch.cat([self.Ts * eye, torch.zeros(q, self.n, dtype=torch.float64)], 0)
        if self.C_x is not None or self.E is not None:
            Cx = torch.eye(self.n, dtype=torch.float64) if self.C_x is None else self.C_x
            self.C = torch.cat([Cx, torch.zeros(Cx.shape[0], q, dtype=torch.float64)], 1)
            check_detectable(self._linearised(A), self.C, labels=[f"x{i}" for i in range(self.n)] +
                             [f"d{j}" for j in range(q)], what="the augmented [x; d] model")
        self.q, self.p = q, self.C.shape[0]

    def _linearised(self, A, h: float | None = None) -> Tensor:
        """The augmented transition of step ``h`` (default ``Ts``) at the model's Jacobian ``A`` (default: at the
        origin, by autograd)."""
        h = self.Ts if h is None else float(h)
        A = self._jacobian(A)
        Phi = self.A.clone() if h == self.Ts else augmented_step(self.A, self.B, self.Ts, torch.tensor(h))[0]
        Phi[: self.n, : self.n] += h * A
        return Phi

    def _jacobian(self, A) -> Tensor:
        """The model Jacobian ``A`` (n, n) float64, checked; by autograd at the origin if None."""
        if A is None:
            dtype = next((p.dtype for p in getattr(self.f, "parameters", lambda: iter(()))() if p.is_floating_point()),
                         torch.float64)
            m = getattr(self.f, "m", 0) or 0
            u0 = torch.zeros(m, dtype=dtype) if m else None
            A = model_jacobian(self.f, torch.zeros(self.n, dtype=dtype), u0)
        A = torch.as_tensor(A, dtype=torch.float64)
        if A.shape != (self.n, self.n):
            raise ValueError(f"the model Jacobian A must have shape ({self.n}, {self.n}), got {tuple(A.shape)}")
        return A

    def _new(self, cls, *args, **kwargs):
        """A filterpy filter with this plant's matrices (numpy), started at P0."""
        kf = cls(*args, dim_x=self.n + self.q, dim_z=self.p, **kwargs)
        kf.F, kf.H = self.A.numpy().copy(), self.C.numpy().copy()
        kf.Q, kf.R, kf.P = self.Q.numpy().copy(), self.R.numpy().copy(), self.P0.numpy().copy()
        return kf

    def measurements(self, y: Tensor, u: Tensor | None, mask: Tensor | None, *, t: Tensor | None = None, x0=None,
                     limit: float | None = None):
        """The one check of ``y`` (..., T, p), ``u``, ``mask``, the times ``t`` and a first estimate ``x0``, before
        any work.

        Returns the checked measurements and numpy arrays per trajectory: ``ys`` (B, T, p), ``us`` (B, T, m)
        or None, ``ms`` (B, T, p) or None, ``hs`` (B, T-1) the step of each interval (``Ts`` everywhere
        without ``t``), ``x0s`` (B, n) or None. ``limit``: refuse measurements larger in magnitude.
        """
        meas = check_measurements(y, self.n, C=self.C_x, u=u, mask=mask, f=self.f)  # refuses a record with no sample
        lead, T = meas.y.shape[:-2], meas.y.shape[-2]
        if limit is not None:
            big = float(meas.y.abs().max()) if meas.y.numel() else 0.0
            if big > limit:
                raise ValueError(f"y reaches {big:.3g}: beyond {limit:.0e} the squared deviations the filter forms "
                                 "overflow float64; rescale the measurements (and the model) first")
        dt = observer_steps(t, self.Ts, meas.y)
        B = int(np.prod(lead)) if lead else 1
        hs = (np.full((B, max(T - 1, 0)), self.Ts) if not isinstance(dt, Tensor)
              else steps_per_record(dt, tuple(lead)).reshape(B, -1).numpy())
        x0s = check_x0(x0, self.n, tuple(lead), torch.float64)
        if x0s is not None:
            x0s = x0s.reshape(B, self.n).numpy()
            if limit is not None and float(np.abs(x0s).max()) > limit:
                raise ValueError(f"x0 reaches {float(np.abs(x0s).max()):.3g}: beyond {limit:.0e} the filter's squares "
                                 "overflow float64; rescale first")
        self.check_model(meas)
        ys = meas.y.reshape(-1, *meas.y.shape[-2:]).double().numpy()
        us = None if meas.u is None else meas.u.expand(*lead, *meas.u.shape[-2:]).reshape(-1, *meas.u.shape[-2:])
        ms = None if meas.mask is None else meas.mask.reshape(-1, *meas.mask.shape[-2:]).numpy()
        return meas, ys, us, ms, hs, x0s

    def check_model(self, meas) -> None:
        """One call of the model on a zero state (and the first input): it must return (1, n), else a clear error."""
        x = torch.zeros(1, self.n, dtype=meas.y.dtype)
        with torch.no_grad():
            if meas.u is None:
                out = self.f(0.0, x)
            else:
                out = self.f(0.0, x, meas.u.reshape(-1, meas.u.shape[-1])[:1])
        if not isinstance(out, Tensor) or tuple(out.shape) != (1, self.n):
            raise ValueError(f"the model f(t, x{'' if meas.u is None else ', u'}) must return the rate of every state, "
                             f"shape (batch, n) = (1, {self.n}) for x of shape (1, {self.n}); got "
                             f"{tuple(getattr(out, 'shape', ())) or type(out).__name__}")

    def start(self, y0: np.ndarray, m0: np.ndarray | None, x0: np.ndarray | None = None) -> np.ndarray:
        """The prior :math:`z_{0|-1} = [C^+ y_0; 0]` (column, n + q), over the present outputs only; ``[x0; 0]`` if
        given."""
        if x0 is not None:
            return np.concatenate([x0, np.zeros(self.q)])[:, None]
        Cx = self.C.numpy()[:, : self.n] if m0 is None else self.C.numpy()[:, : self.n] * m0[:, None]
        return np.concatenate([np.linalg.pinv(Cx) @ y0, np.zeros(self.q)])[:, None]

    def noise(self, h: float) -> np.ndarray:
        """The process noise of a step ``h``: :math:`Q\\,h/T_s` (``Q`` is given per nominal step; module docstring)."""
        Q = self.Q.numpy()
        return Q.copy() if h == self.Ts else Q * (h / self.Ts)

    def update(self, kf, y: np.ndarray, m: np.ndarray | None, *, extended: bool) -> None:
        """filterpy's measurement update on the present outputs (none: no update, the estimate runs open loop).

        ``extended``: the EKF's ``update(z, HJacobian, Hx)`` (column ``z``); else the UKF's ``update(z, R, hx)``.
        """
        C = self.C.numpy()
        if m is not None and not m.any():
            return None
        R = None if m is None else self.R.numpy()[np.ix_(m, m)]
        if m is not None:
            C, y = C[m], y[m]
        if extended:
            return kf.update(y[:, None], HJacobian=lambda _: C, Hx=lambda s: C @ s, R=R)
        return kf.update(y, R=R, hx=lambda s: C @ s)

    def _phi(self, z: np.ndarray, dtype: torch.dtype, u: Tensor | None, h: float | None = None) -> np.ndarray:
        r"""The model step :math:`\Phi(x, d) = (x + h(f(x, u) + E d),\; d)` of a filtered ``z`` (n + q,), ``h``
        default ``Ts``."""
        h = self.Ts if h is None else h
        n = self.n
        x, d = z[:n], z[n:]
        with torch.no_grad():
            xt = torch.as_tensor(x, dtype=dtype)[None]
            rate = (self.f(0.0, xt) if u is None else self.f(0.0, xt, u[None]))[0].double().numpy()
        Ed = d if self.E is None else self.E.numpy() @ d
        return np.concatenate([x + h * (rate + Ed), d])

    def constant_gain_loop(self, K, y: Tensor, u: Tensor | None, mask: Tensor | None, *, t: Tensor | None = None,
                           x0=None) -> DisturbanceEstimate:
        r"""A filter gain ``K`` (n + q, p) with the model evaluated at the estimate (partial outputs, gaps).

        :math:`\hat z_{k|k} = \hat z_{k|k-1} + K_k\,\mathrm{diag}(m_k)(y_k - C\hat z_{k|k-1})` (``m_k`` the
        present outputs: a missing one adds no correction, none at all moves the estimate open loop), then
        :math:`\hat z_{k+1|k} = \Phi_{\Delta_k}(\hat z_{k|k}, u_k)`, from :math:`\hat z_{0|-1} = [C^+ y_0; 0]`
        (or ``[x0; 0]``). ``K`` is one gain, or a callable ``K(hs)`` giving the gain of each sample (B, T, n + q, p)
        from the intervals ``hs`` (B, T-1) (the gain of sample k pairs with the interval after it).
        """
        meas, ys, us, ms, hs, x0s = self.measurements(y, u, mask, t=t, x0=x0)
        Ks = K(hs) if callable(K) else None
        dtype, C = meas.y.dtype, self.C.numpy()
        z = np.empty((*ys.shape[:2], self.n + self.q))
        for i, yi in enumerate(ys):
            prior = self.start(yi[0], None if ms is None else ms[i, 0], None if x0s is None else x0s[i])[:, 0]
            for k in range(yi.shape[0]):
                innov = yi[k] - C @ prior
                if ms is not None:
                    innov = innov * ms[i, k]
                z[i, k] = prior + (K if Ks is None else Ks[i, k]) @ innov
                if k < yi.shape[0] - 1:
                    prior = self._phi(z[i, k], dtype, None if us is None else us[i, k], hs[i, k])
        return self.split(z, meas)

    def split(self, z: np.ndarray, meas) -> DisturbanceEstimate:
        """Augmented estimates (B, T, n + q) -> ``x_hat``, ``d_hat`` (the disturbance on the rate, ``E d``), ``f_hat``."""
        y = meas.y
        z = torch.as_tensor(z).reshape(*y.shape[:-1], self.n + self.q)
        n = self.n
        x_hat, d = z[..., :n].to(y.dtype), z[..., n:]
        d_hat = (d if self.E is None else d @ self.E.T).to(y.dtype)
        with torch.no_grad():
            f_hat = eval_field(self.f, x_hat, meas.u) + d_hat  # the filter's own model: f(x_hat, u) + E d_hat
        return DisturbanceEstimate(x_hat, d_hat, f_hat)


class _KalmanBase(_OutputModel):
    """Shared set-up of the Kalman filters: :class:`_OutputModel` (``C``, ``E``, detectability) and their
    :class:`~fnnlib.observers.options.Covariances` ``cov`` (Q, R, P0)."""

    def __init__(self, f: VectorField, Ts: float, *, n: int | None = None, cov: Covariances, C=None,
                 disturbance=None, A=None):
        if not isinstance(cov, Covariances):
            raise TypeError(f"cov must be a fnnlib.Covariances(Q=..., R=..., P0=...), got {type(cov).__name__}")
        super().__init__(f, Ts, _state_dimension(f, n), C=C, disturbance=disturbance, A=A)
        q, m = self.q, self.n + self.q
        Q, R, P0 = cov.Q, cov.R, cov.P0
        self.Q = as_covariance(Q, m, name="Q")
        self.R = as_covariance(R, self.p, name="R", definite=True)
        if P0 is None:  # first measurement's noise on x (unit variance on unmeasured states); d of order 10
            x_part = self.R if C is None else torch.eye(self.n, dtype=torch.float64)
            P0 = torch.block_diag(x_part, 100.0 * torch.eye(q, dtype=torch.float64))
        self.P0 = as_covariance(P0, m, name="P0")


def _state_dimension(f: VectorField, n: int | None) -> int:
    """``n``, or the model's own ``f.n`` (a :class:`~fnnlib.models.NeuralODE` or a system has it)."""
    n = n if n is not None else getattr(f, "n", None)
    if n is None:
        raise ValueError("pass the state dimension n (f has no `n` attribute to take it from)")
    return int(n)


def disturbance_matrix(E, n: int) -> Tensor:
    """The disturbance layout ``E`` (n, q) float64 from a matrix or a list of state indices."""
    E = torch.as_tensor(E)
    if E.ndim == 1 and not E.is_floating_point():
        idx = [int(i) for i in E.tolist()]
        if not idx or any(not 0 <= i < n for i in idx) or len(set(idx)) != len(idx):
            raise ValueError(f"disturbance states must be distinct indices in 0..{n - 1}, got {idx}")
        return torch.eye(n, dtype=torch.float64)[:, idx]
    E = E.to(torch.float64)
    if E.ndim != 2 or E.shape[0] != n or E.shape[1] < 1 or not bool(torch.isfinite(E).all()):
        raise ValueError(f"disturbance must be a finite (n, q) = ({n}, q) matrix or a list of state indices, "
                         f"got shape {tuple(E.shape)}")
    return E


class KalmanObserver(_KalmanBase):
    r"""Kalman filter on the augmented learned model (filterpy ``KalmanFilter``).

    A classical baseline for the feedback observer of Eqs. (7)-(8), on the same learned model (Eq. (3)).

    Every observer is built as ``(f, Ts, *, ...)``: the model and the nominal sample step by position, the rest
    by name.

    Parameters
    ----------
    f, Ts
        Learned field and sampling step, as :class:`~fnnlib.observers.augmented.AugmentedObserver`.
    n : int, optional
        State dimension; by default ``f.n``.
    cov : Covariances
        ``Q`` (float, (2n,) or (2n, 2n)): process noise covariance of :math:`z = [x; d]`; ``R`` (float, (n,) or
        (n, n)): measurement noise covariance (the noise variance, e.g. ``std**2``); ``P0`` (float, (2n,) or
        (2n, 2n), optional): prior covariance at k = 0 (around :math:`[y_0; 0]`), default ``blockdiag(R, 100 I)``.
    steady_state : bool
        Use the stationary gain (:func:`steady_state_gain`) in one scan over
        time instead of filterpy's time-varying filter (a Python loop inside
        ``KalmanFilter.batch_filter``).
    C, disturbance, A : optional
        Partial measurements ``y = C x`` (p, n), the disturbance layout and the model Jacobian, as
        :class:`_KalmanBase` takes them (detectability checked there). With any of them the filter is the
        stationary Kalman gain of the augmented model linearised at ``A`` (default: at the origin), run with
        the model evaluated at the *estimate* (:meth:`_OutputModel.constant_gain_loop`; ``steady_state`` must
        then be True), and it takes gaps (``mask`` or NaN). Without them the full-state filter above is unchanged.
    """

    def __init__(self, f: VectorField, Ts: float, *, n: int | None = None, cov: Covariances,
                 steady_state: bool = False, C=None, disturbance=None, A=None):
        super().__init__(f, Ts, n=n, cov=cov, C=C, disturbance=disturbance, A=A)
        self.steady_state = bool(steady_state)
        self.output_form = C is not None or disturbance is not None
        if self.output_form:
            if not self.steady_state:
                raise ValueError("KalmanObserver with C or disturbance runs the stationary gain: pass steady_state=True "
                                 "(for a time-varying filter with C use ExtendedKalmanObserver)")
            self.takes_gaps = True
            self.stationary = steady_state_gain(self._linearised(A).numpy(), self.C.numpy(), self.Q.numpy(),
                                                self.R.numpy())
        else:  # full-state measurements: f is evaluated at y (Eq. (7))
            self.stationary = steady_state_gain(self.A, self.C, self.Q, self.R)

    def make_filter(self) -> KalmanFilter:
        """A filterpy ``KalmanFilter`` with F = A, B, H = C, Q, R and P = P0 (state left at zero)."""
        from filterpy.kalman import KalmanFilter  # noqa: PLC0415 (imported on use, see _learned_model_ekf)

        kf = self._new(KalmanFilter)
        kf.B = self.B.numpy().copy()
        return kf

    def gain_history(self, T: int) -> np.ndarray:
        """filterpy's gains ``K_k`` for k = 0..T-1, shape (T, 2n, n); they do not depend on the data."""
        kf = self.make_filter()
        K = np.empty((int(T), 2 * self.n, self.n))
        for k in range(int(T)):
            kf.update(np.zeros(self.n))  # K = P C' (C P C' + R)^-1, then P = (I - K C) P ...
            K[k] = kf.K
            kf.predict(u=np.zeros(self.n))  # P = A P A' + Q
        return K

    def estimate(self, x: Tensor, u_ext: Tensor | None = None, *, mask: Tensor | None = None,
                 t: Tensor | None = None, x0=None) -> DisturbanceEstimate:
        """Filtered state, disturbance and change rate along measurements ``x`` (..., T, n) (inputs ``u_ext``);
        with ``C``, ``x`` is ``y`` (..., T, p) and ``mask`` marks missing outputs.

        ``t`` (..., T): the sample times instead of ``Ts`` (module docstring: exact zero-order hold per interval,
        ``Q`` scaled by :math:`\\Delta_k/T_s`, the stationary gain held); ``x0`` (n,) or (..., n): the first
        estimate instead of the first measurement's."""
        if self.output_form:
            return self.constant_gain_loop(np.asarray(self.stationary.K), x, u_ext, mask, t=t, x0=x0)
        if mask is not None:
            raise ValueError("mask needs the output form of KalmanObserver (give C, e.g. the identity)")
        x = as_trajectory(x, self.n)
        dt = observer_steps(t, self.Ts, x)
        z0 = self.start_prior(x, x0)
        x, u = self.inputs(x, u_ext)  # u_k = f_neural(y_k), as in Eq. (7)
        if self.steady_state:
            K = torch.as_tensor(self.stationary.K)
            return self.constant_gain_estimate(x, u, torch.as_tensor(self.stationary.L), u_ext, dt=dt, x0=x0,
                                               M=None if not isinstance(dt, Tensor) else K)
        ys, us = x.reshape(-1, *x.shape[-2:]).double().numpy(), u.reshape(-1, *u.shape[-2:]).double().numpy()
        T, m = x.shape[-2], 2 * self.n
        if isinstance(dt, Tensor):  # one exact zero-order-hold plant per interval; the last prediction is unused
            Ak, Bk = augmented_step(self.A, self.B, self.Ts, steps_per_record(dt, tuple(x.shape[:-2])))
            Ak, Bk = Ak.reshape(-1, T - 1, m, m).numpy(), Bk.reshape(-1, T - 1, m, self.n).numpy()
            hs = steps_per_record(dt, tuple(x.shape[:-2])).reshape(-1, T - 1).numpy()
        z0s = None if z0 is None else z0.reshape(-1, m).numpy()
        z = np.empty((*ys.shape[:2], m))
        for i, (y, ui) in enumerate(zip(ys, us)):  # filterpy filters one trajectory at a time
            kf = self.make_filter()
            kf.x = np.concatenate([y[0], np.zeros(self.n)]) if z0s is None else z0s[i].copy()  # prior z_{0|-1}
            if isinstance(dt, Tensor):
                last = T - 2
                Fs = [Ak[i, min(k, last)] for k in range(T)]
                Bs = [Bk[i, min(k, last)] for k in range(T)]
                Qs = [self.noise(float(hs[i, min(k, last)])) for k in range(T)]
                means, *_ = kf.batch_filter(list(y), Fs=Fs, Qs=Qs, Bs=Bs, us=list(ui), update_first=True)
            else:
                means, *_ = kf.batch_filter(list(y), us=list(ui), update_first=True)  # update(y_k), predict(u_k)
            z[i] = means
        z = torch.as_tensor(z).reshape(*x.shape[:-1], m)
        return split_estimate(self.f, z, x, u_ext)

    def __repr__(self) -> str:
        return f"KalmanObserver(n={self.n}, Ts={self.Ts}, steady_state={self.steady_state})"


@functools.cache
def _learned_model_ekf() -> type:
    """The EKF class of :class:`ExtendedKalmanObserver`, made on first use.

    filterpy imports scipy.stats, ~0.25 s of CPU in every process that imports it; most processes that import
    fnnlib (every notebook's kernel) never run a Kalman filter, so filterpy is imported where a filter is made.
    """
    from filterpy.kalman import ExtendedKalmanFilter  # noqa: PLC0415

    class _LearnedModelEKF(ExtendedKalmanFilter):
        """filterpy's EKF predicts linearly (``F x + B u``); here ``predict_x`` runs the learned model.

        ``step(z)`` returns the next state and the Jacobian at ``z``; setting
        ``self.F`` there makes the following ``P = F P F' + Q`` of ``predict`` use it.
        """

        def __init__(self, step, dim_x: int, dim_z: int):
            super().__init__(dim_x=dim_x, dim_z=dim_z)
            self.step = step

        k: int | None = None  # the sample the next prediction steps from (its input)

        def predict_x(self, u=0):
            self.x, self.F = self.step(self.x, self.k)

    return _LearnedModelEKF


class ExtendedKalmanObserver(_KalmanBase):
    r"""Extended Kalman filter on the learned model with a constant-disturbance state (filterpy).

    A classical baseline for the feedback observer of Eqs. (7)-(8), on the same learned model (Eq. (3)).

    Prediction :math:`\hat z_{k+1|k} = \Phi(\hat z_{k|k})` with
    :math:`\Phi(x, d) = (x + T_s(f_{neural}(x) + d),\; d)` and Jacobian
    :math:`F_k = \begin{bmatrix} I + T_s J(\hat x_{k|k}) & T_s I\\ 0 & I\end{bmatrix}`,
    :math:`J = \partial f_{neural}/\partial x` by autograd; the measurement
    update is linear (:math:`H = C`). The change rate is the model's own,
    :math:`\hat f_k = f_{neural}(\hat x_{k|k}) + \hat d_{k|k}`.

    Parameters are those of :class:`KalmanObserver`, ``(f, Ts, *, n, cov, C, disturbance, A)`` (no
    ``steady_state``), and ``C`` (p, n): measure
    only :math:`y = C x` (default: every state; then ``R`` is (p, p) and the default ``P0`` puts unit
    variance on the state). The model is evaluated at the estimate, so partial measurements need no
    full state (the :class:`~fnnlib.feedback.measured.MeasuredFeedback` of the same ``C`` is its
    constant-gain counterpart).
    filterpy advances one sample per call, so :meth:`estimate` loops over
    time and over the leading batch axes in Python.

    ``disturbance`` (the states the constant disturbance acts on, or a matrix E (n, q)) and the model
    Jacobian ``A`` for the detectability check: see :class:`_KalmanBase`. Inputs ``u`` and gaps are taken.
    """

    takes_gaps = True

    def _step(self, z: np.ndarray, dtype: torch.dtype, u: Tensor | None = None, h: float | None = None):
        r"""The prediction :math:`\Phi_h(z)` and its Jacobian :math:`F`, for a column ``z`` (n + q, 1), input ``u``
        (m,), step ``h``."""
        n, Ts = self.n, (self.Ts if h is None else h)
        x, d = z[:n, 0], z[n:, 0]
        with torch.enable_grad():  # J by one batched backward pass: row i of f(X), X = n copies of x
            X = torch.as_tensor(x, dtype=dtype).expand(n, n).clone().requires_grad_(True)
            out = self.f(0.0, X) if u is None else self.f(0.0, X, u.expand(n, -1))
            (J,) = torch.autograd.grad(out.diagonal().sum(), X)  # J[i, j] = d f_i / d x_j
        if Ts == self.Ts:
            F = self.A.numpy().copy()
        else:  # A(h) = I + h A_c (the exact hold of the augmented plant, fnnlib.observers.augmented)
            if getattr(self, "_Ac", None) is None:
                self._Ac = ((self.A - torch.eye(self.A.shape[0], dtype=self.A.dtype)) / self.Ts).numpy()
            F = np.eye(self._Ac.shape[0]) + Ts * self._Ac
        F[:n, :n] += Ts * J.double().numpy()  # F = dPhi/dz = [[I + Ts J, Ts E], [0, I]]
        Ed = d if self.E is None else self.E.numpy() @ d
        x_next = x + Ts * (out[0].detach().double().numpy() + Ed)  # x_{k+1|k} = x_{k|k} + Ts (f(x_{k|k}, u_k) + E d)
        return np.concatenate([x_next, d])[:, None], F

    def estimate(self, x: Tensor, u: Tensor | None = None, *, mask: Tensor | None = None, t: Tensor | None = None,
                 x0=None) -> DisturbanceEstimate:
        """Filtered state, disturbance and change rate along measurements ``x`` (..., T, p), inputs ``u`` (..., T, m).

        A NaN in ``x`` or a ``False`` in ``mask`` ((..., T) or (..., T, p)) is a missing output: the update
        uses the present ones only, and none at all moves the estimate open loop. ``t`` (..., T): the sample
        times (Euler step and :math:`Q\\,\\Delta_k/T_s` per interval, module docstring); ``x0``: the first estimate.
        """
        meas, ys, us, ms, hs, x0s = self.measurements(x, u, mask, t=t, x0=x0)
        dtype = meas.y.dtype
        z = np.empty((*ys.shape[:2], self.n + self.q))
        for i, y in enumerate(ys):  # filterpy: one filter per trajectory, one sample per call
            ui, hi = (None if us is None else us[i]), hs[i]
            ekf = self._new(_learned_model_ekf(),
                            lambda s, k=None: self._step(s, dtype, None if ui is None else ui[k], float(hi[k])))
            ekf.x = self.start(y[0], None if ms is None else ms[i, 0], None if x0s is None else x0s[i])  # z_{0|-1}
            for k in range(y.shape[0]):
                if k:
                    ekf.k = k - 1
                    ekf.Q = self.noise(float(hi[k - 1]))
                    ekf.predict()  # z = Phi(z, u_{k-1}); P = F P F' + Q
                self.update(ekf, y[k], None if ms is None else ms[i, k], extended=True)  # K, z += K (y - C z)
                z[i, k] = ekf.x[:, 0]
        return self.split(z, meas)

    def __repr__(self) -> str:
        return f"ExtendedKalmanObserver(n={self.n}, Ts={self.Ts})"
