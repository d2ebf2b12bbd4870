r"""The unscented Kalman filter (filterpy's ``UnscentedKalmanFilter``) on the learned model with a disturbance state.

The same plant as :class:`~fnnlib.observers.ExtendedKalmanObserver`,
:math:`\Phi(x, d) = (x + T_s(f_{neural}(x, u) + E d),\; d)` and :math:`y = C x + v`, but the mean and
covariance are carried through :math:`\Phi` by sigma points (van der Merwe's scaled set) instead of a
Jacobian; all sigma points of a step go through the model in one batched call.

Uneven sample times ``t`` are taken as by the EKF (:mod:`fnnlib.observers.kalman`): Euler with each interval
:math:`\Delta_k`, process noise :math:`Q\,\Delta_k/T_s`. The sigma points' squared deviations overflow float64
for states near :math:`10^{154}`: measurements or a first estimate beyond
:data:`~fnnlib.observers.kalman.SQUARE_LIMIT` are refused before any work, and a covariance that still turns
non-finite or indefinite (a diverging model) stops the filter with the sample where it happened.
"""

from __future__ import annotations

import functools

import numpy as np
import torch
from torch import Tensor

from fnnlib.feedback.types import VectorField
from fnnlib.observers.augmented import DisturbanceEstimate
from fnnlib.observers.kalman import SQUARE_LIMIT, _KalmanBase
from fnnlib.observers.options import Covariances, SigmaPoints


@functools.cache
def _batched_ukf() -> type:
    """The UKF class, made on first use (filterpy is imported where a filter is made, as in
    :mod:`fnnlib.observers.kalman`)."""
    from filterpy.kalman import UnscentedKalmanFilter  # noqa: PLC0415

    class _BatchedUKF(UnscentedKalmanFilter):
        """filterpy's UKF with every sigma point propagated in one call of ``fx_batch`` (S, n + q) -> (S, n + q)."""

        def __init__(self, fx_batch, **kw):
            super().__init__(fx=None, hx=None, **kw)
            self.fx_batch = fx_batch

        def compute_process_sigmas(self, dt, fx=None, **fx_args):
            self.sigmas_f = self.fx_batch(self.points_fn.sigma_points(self.x, self.P), **fx_args)

    return _BatchedUKF


class UnscentedKalmanObserver(_KalmanBase):
    r"""Unscented Kalman filter on the learned model with a constant-disturbance state (filterpy).

    A classical baseline for the feedback observer of Eqs. (7)-(8), on the same learned model (Eq. (3)).

    Parameters are those of :class:`~fnnlib.observers.ExtendedKalmanObserver` (``f``, ``Ts``, then by name ``n``,
    ``cov``, ``C``, ``disturbance``, ``A``), and ``sigma``, the :class:`~fnnlib.observers.options.SigmaPoints`
    (``alpha``, ``beta``, ``kappa`` of the scaled sigma points).
    :meth:`estimate` takes inputs ``u`` (..., T, m) and gaps (NaN or ``mask``) like the EKF.
    """

    takes_gaps = True

    def __init__(self, f: VectorField, Ts: float, *, n: int | None = None, cov: Covariances, C=None,
                 disturbance=None, A=None, sigma: SigmaPoints = SigmaPoints()):
        if not isinstance(sigma, SigmaPoints):
            raise TypeError(f"sigma must be a fnnlib.SigmaPoints(alpha, beta, kappa), got {type(sigma).__name__}")
        super().__init__(f, Ts, n=n, cov=cov, C=C, disturbance=disturbance, A=A)
        self.alpha, self.beta, self.kappa = sigma.alpha, sigma.beta, sigma.kappa

    def _fx(self, sigmas: np.ndarray, dtype: torch.dtype, u: Tensor | None, h: float | None = None) -> np.ndarray:
        """:math:`\\Phi_h` of every sigma point (S, n + q) in one model call (step ``h``, default ``Ts``)."""
        h = self.Ts if h is None else h
        n = self.n
        X = torch.as_tensor(sigmas[:, :n], dtype=dtype)
        with torch.no_grad():
            fx = self.f(0.0, X) if u is None else self.f(0.0, X, u.expand(X.shape[0], -1))
        d = sigmas[:, n:]
        Ed = d if self.E is None else d @ self.E.numpy().T
        return np.concatenate([sigmas[:, :n] + h * (fx.double().numpy() + Ed), d], 1)

    def estimate(self, x: Tensor, u: Tensor | None = None, *, mask: Tensor | None = None, t: Tensor | None = None,
                 x0=None) -> DisturbanceEstimate:
        """Filtered state, disturbance and change rate along measurements ``x`` (..., T, p); see the EKF's (``t``,
        ``x0``)."""
        from filterpy.kalman import MerweScaledSigmaPoints  # noqa: PLC0415 (imported on use, see _batched_ukf)

        meas, ys, us, ms, hs, x0s = self.measurements(x, u, mask, t=t, x0=x0, limit=SQUARE_LIMIT)
        dtype = meas.y.dtype
        dim = self.n + self.q
        z = np.empty((*ys.shape[:2], dim))
        for i, y in enumerate(ys):
            ui, hi = (None if us is None else us[i]), hs[i]
            points = MerweScaledSigmaPoints(dim, alpha=self.alpha, beta=self.beta, kappa=self.kappa)
            ukf = self._new(_batched_ukf(), lambda s, k: self._fx(s, dtype, None if ui is None else ui[k], float(hi[k])),
                            dt=self.Ts, points=points)
            ukf.x = self.start(y[0], None if ms is None else ms[i, 0], None if x0s is None else x0s[i])[:, 0]
            ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)  # the first update has no prediction before it
            for k in range(y.shape[0]):
                try:
                    with np.errstate(over="raise", invalid="raise"):
                        if k:
                            ukf.Q = self.noise(float(hi[k - 1]))
                            ukf.predict(k=k - 1)  # sigma points through Phi(., u_{k-1})
                        self.update(ukf, y[k], None if ms is None else ms[i, k], extended=False)
                except (FloatingPointError, np.linalg.LinAlgError, ValueError) as exc:
                    raise RuntimeError(f"the UKF failed at sample {k} of record {i} ({exc}): its covariance "
                                       "overflowed or lost definiteness, e.g. a model that diverges from the estimate "
                                       "or states of a magnitude near 1e154; rescale the data or check the model"
                                       ) from None
                if not np.all(np.isfinite(ukf.x)):
                    raise RuntimeError(f"the UKF's estimate became non-finite at sample {k} of record {i}: the model "
                                       "diverges from it, or the states overflow float64; rescale or check the model")
                z[i, k] = ukf.x
        return self.split(z, meas)

    def __repr__(self) -> str:
        return f"UnscentedKalmanObserver(n={self.n}, Ts={self.Ts})"
