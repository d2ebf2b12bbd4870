r"""Observer settings from training data only: the Kalman filter's process noise on the disturbance.

The Kalman baselines (:mod:`fnnlib.observers.kalman`) model the residual :math:`\Delta f = \dot x - f_{neural}(x)`
as a disturbance state with a random walk, :math:`d_{k+1} = d_k + w_k`, :math:`w_k \sim \mathcal N(0, q_d I)`.
Reading :math:`q_d` off the true residual along the *test* trajectory tells the baseline what it is about to
see. :func:`disturbance_drift_variance` estimates it from the training trajectories instead, through the
filter's own plant (:mod:`fnnlib.observers.augmented`, Euler at :math:`T_s`):
:math:`x_{k+1} = x_k + T_s (f_{neural}(x_k) + d_k)` gives :math:`d_k` from two samples, no true rate needed.
"""

from __future__ import annotations

import torch
from torch import Tensor

from fnnlib._validation import check_positive
from fnnlib.feedback import VectorField, eval_field
from fnnlib.feedback.measurement import check_measurements
from fnnlib.feedback.sampling import check_times

__all__ = ["disturbance_drift_variance"]


def disturbance_drift_variance(x: Tensor, Ts: float, field: VectorField, u: Tensor | None = None, *,
                               t: Tensor | None = None) -> float:
    r""":math:`q_d`: the variance of the per-step change of :math:`\Delta f` on training trajectories.

    Parameters
    ----------
    x : Tensor, shape (T, n) or (B, T, n)
        Training trajectories sampled every ``Ts`` (T >= 3), never the test trajectory.
    Ts : float
        Sampling step.
    field : callable
        The learned field ``f(t, x)``, e.g. the trained neural ODE, or ``f(t, x, u)`` with inputs.
    u : Tensor, shape (T, m) or (B, T, m), optional
        The inputs of the training trajectories, one row per sample.
    t : Tensor, shape (T,) or (B, T), optional
        Uneven sample times. ``Ts`` is then the *nominal* step the variance refers to (the step the
        observers' ``Q`` is given per, :mod:`fnnlib.observers.kalman`): :math:`d_k` uses
        :math:`\Delta_k = t_{k+1} - t_k`, and each change :math:`d_{k+1} - d_k`, spanning
        :math:`c_k = (\Delta_k + \Delta_{k+1})/2`, is scaled by :math:`\sqrt{T_s / c_k}` (a random walk's
        variance grows with the time elapsed).

    Returns
    -------
    float
        The sample variance (``torch.std(...) ** 2``, unbiased) of :math:`d_{k+1} - d_k`
        pooled over trajectories and coordinates, with
        :math:`d_k = (x_{k+1} - x_k) / T_s - f_{neural}(x_k)` (the filter's Euler plant solved for
        :math:`d_k`); the observers notebook's ``kf_q_d``.
    """
    Ts = check_positive(Ts, name="Ts")
    if isinstance(x, Tensor) and (x.ndim not in (2, 3) or x.shape[-2] < 3):
        raise ValueError(f"x must be (T, n) or (B, T, n) with T >= 3, got shape {tuple(x.shape)}")
    meas = check_measurements(x, x.shape[-1] if isinstance(x, Tensor) else 0, u=u, f=field, missing=False,
                              name="x")  # T >= 3 checked above
    dt = None if t is None else check_times(t, None, x, name="x")[..., None]  # (..., T-1, 1)
    u_k = None if meas.u is None else meas.u[..., :-1, :]
    with torch.no_grad():
        # d_k = (x_{k+1} - x_k) / Delta_k - f_neural(x_k, u_k)   (the augmented plant's Euler step)
        d = x.diff(dim=-2) / (Ts if dt is None else dt) - eval_field(field, x[..., :-1, :], u_k)
    change = d.diff(dim=-2)
    if dt is not None:  # per nominal step: scaled by sqrt(Ts / c_k), c_k = (Delta_k + Delta_{k+1}) / 2
        change = change * torch.sqrt(Ts / (0.5 * (dt[..., :-1, :] + dt[..., 1:, :])))
    return float(change.std() ** 2)
