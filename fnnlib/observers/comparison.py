r"""The observers side by side (S11): one set per learned model, and the checks that tie them to their closed forms.

:func:`observer_set` builds the seven observers of one network on the constant-disturbance plant of
:mod:`fnnlib.observers.augmented`; :func:`lowpass_twin` checks the linear feedback of Eqs. (7)-(8) as an observer
(its correction :math:`\hat d_k = L(y_k - \hat x_k)` is a first-order low-pass of the measured model residual, and
the Luenberger observer with gain :math:`[I + T_s L;\ L]` is its twin); :func:`design_checks` holds the Luenberger
poles, the Riccati gain and each error's spectral radius (Eq. (25), App. A.2) against their closed forms.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from fnnlib.feedback import Gains, eval_field, spectral_radius
from fnnlib.observers.kalman import ExtendedKalmanObserver, KalmanObserver
from fnnlib.observers.options import Covariances
from fnnlib.observers.linear import LinearFeedback
from fnnlib.observers.luenberger import LuenbergerObserver, linear_feedback_gain

__all__ = ["design_checks", "lowpass_twin", "observer_set"]


def observer_set(model: Any, Ts: float, *, L: float, beta: float, poles: Sequence[float], noise_std: float,
                 q_x: float, q_d: float, p0_d: float) -> dict[str, Any]:
    r"""The seven observers of one network: the neural ODE alone (L = 0), the linear feedback (gain ``L``, decay
    ``beta`` of Eq. (11)), the Luenberger observer that reproduces it, the Luenberger observer with ``poles``, the
    Kalman filter (time-varying and steady state) and the EKF, the last three with
    :math:`Q = \mathrm{diag}(q_x I, q_d I)`, :math:`R` = ``noise_std``:sup:`2` and
    :math:`P_0 = \mathrm{diag}(\text{noise\_std}^2 I, p_{0,d} I)`."""
    Q, R, P0 = [q_x] * 2 + [q_d] * 2, noise_std ** 2, [noise_std ** 2] * 2 + [p0_d] * 2
    return {
        "neural ODE": LinearFeedback(model, Ts, gains=Gains(0.0), n=2),
        "linear feedback": LinearFeedback(model, Ts, gains=Gains(L, beta), n=2),
        "Luenberger (as LF)": LuenbergerObserver.with_gain(model, Ts, n=2, L=linear_feedback_gain(L, Ts, 2)),
        "Luenberger": LuenbergerObserver(model, Ts, n=2, poles=poles),
        "Kalman": KalmanObserver(model, Ts, n=2, cov=Covariances(Q, R, P0=P0)),
        "Kalman, steady state": KalmanObserver(model, Ts, n=2, cov=Covariances(Q, R, P0=P0), steady_state=True),
        "EKF": ExtendedKalmanObserver(model, Ts, n=2, cov=Covariances(Q, R, P0=P0)),
    }


def lowpass_twin(estimates: Mapping[str, Any], model: Any, y: Tensor, x: Tensor, d_true: Tensor, Ts: float,
                 L: float) -> tuple[Tensor, dict[str, float]]:
    r"""The linear feedback in observer terms, for one network: its disturbance estimate
    :math:`\hat d_k = \hat f_k - f_{neural}(y_k) = L(y_k - \hat x_k)` (Eq. (7)), and how far it is from the low-pass
    :math:`\hat d_{k+1} = (I - T_s L)\hat d_k + T_s L\, r_k` of the measured residual
    :math:`r_k = (y_{k+1} - y_k)/T_s - f_{neural}(y_k)` and from its Luenberger twin (relative to the largest
    :math:`|\hat f|`); its mean state error and :math:`|\Delta f|/L` (Theorem 1's ball) beside.

    ``estimates``: the estimates of ``"linear feedback"`` and ``"Luenberger (as LF)"`` on the measurements ``y``
    (T, 2) of the clean states ``x``; ``d_true`` (T, 2) the true residual :math:`\Delta f`.
    """
    lf, lu_lf = estimates["linear feedback"], estimates["Luenberger (as LF)"]
    with torch.no_grad():
        r_k = (y[1:] - y[:-1]) / Ts - eval_field(model, y[:-1])  # measured model residual
        d_lf = lf.f_hat - eval_field(model, y)  # = L (y - x_hat), Eq. (7)
    d_rec = [torch.zeros(2)]
    for k in range(y.shape[0] - 1):
        d_rec.append((1 - Ts * L) * d_rec[-1] + Ts * L * r_k[k])  # d_{k+1} = (1 - Ts L) d_k + Ts L r_k
    scale = float(lf.f_hat.abs().max())
    return d_lf, {"max_rel_diff_lowpass": float((torch.stack(d_rec) - d_lf).abs().max()) / scale,
                  "max_rel_diff_luenberger": float((lu_lf.f_hat - lf.f_hat).abs().max()) / scale,
                  "lf_state_err_mean": float((lf.x_hat - x).norm(dim=-1).mean()),
                  "mean_abs_delta_f_over_L": float(d_true.norm(dim=-1).mean()) / L}


def design_checks(observers: Mapping[str, Any], poles: Sequence[float], n_samples: int, Ts: float) -> dict[str, Any]:
    """One network's designs against their closed forms: the Luenberger error poles against ``poles``; the Kalman
    steady state against ``control.dlqe`` (same P; its predictor gain is A K) and filterpy's time-varying gain
    after ``n_samples`` steps against the stationary K; the spectral radius of each error's dynamics (Eq. (25))."""
    import control  # noqa: PLC0415 (python-control loads matplotlib.pyplot: only for these checks)

    lu, kf, L_fb = observers["Luenberger"], observers["Kalman"], observers["linear feedback"].L
    pole_err = float(np.abs(np.sort_complex(lu.error_poles()) - np.sort_complex(np.array(poles, complex))).max())
    L_dlqe, P_dlqe, _ = control.dlqe(kf.A.numpy(), np.eye(4), kf.C.numpy(), kf.Q.numpy(), kf.R.numpy())
    ss = kf.stationary
    K_filterpy = kf.gain_history(n_samples)[-1]
    return {"luenberger_pole_err": pole_err,
            "kf_L_rel_err_vs_dlqe": float(np.abs(ss.L - L_dlqe).max() / np.abs(L_dlqe).max()),
            "kf_P_rel_err_vs_dlqe": float(np.abs(ss.P - P_dlqe).max() / np.abs(P_dlqe).max()),
            "filterpy_K_rel_err": float(np.abs(K_filterpy - ss.K).max() / np.abs(ss.K).max()),
            "rho_linear_feedback": spectral_radius(torch.eye(2, dtype=torch.float64) - Ts * L_fb),
            "rho_luenberger": float(np.abs(lu.error_poles()).max()),
            "rho_kalman_steady": float(np.abs(np.linalg.eigvals(kf.A.numpy() - L_dlqe @ kf.C.numpy())).max()),
            "kf_stationary_poles": sorted(np.abs(np.linalg.eigvals(kf.A.numpy() - ss.L @ kf.C.numpy())).tolist())}
