r"""The option objects of the Kalman baselines (S11): their covariances and the unscented filter's sigma points.

Small frozen dataclasses, checked on construction (before a model is evaluated); the dimensions are checked
where the observer knows them (:func:`~fnnlib.observers.kalman.as_covariance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor


def _covariance(M, name: str, definite: bool) -> Tensor:
    """``M`` as a float64 tensor: a scalar (times I), a vector (a diagonal) or a square symmetric matrix, finite,
    >= 0 (> 0 with ``definite``)."""
    if M is None or isinstance(M, (str, bytes, bool)):
        raise TypeError(f"Covariances.{name} must be a number, a vector or a matrix of numbers, got {M!r}")
    try:
        t = torch.as_tensor(M, dtype=torch.float64)
    except (TypeError, ValueError, RuntimeError):
        raise TypeError(f"Covariances.{name} must be a number, a vector or a matrix of numbers, got {M!r}") from None
    if t.ndim > 2 or t.numel() == 0 or (t.ndim == 2 and t.shape[0] != t.shape[1]):
        raise ValueError(f"Covariances.{name} must be a scalar, a vector (a diagonal) or a square matrix, got shape "
                         f"{tuple(t.shape)}")
    if not bool(torch.isfinite(t).all()):
        raise ValueError(f"Covariances.{name}: {name} must be a finite symmetric matrix (or a finite scalar or "
                         "vector), got NaN or infinite entries")
    if t.ndim == 2:
        if not torch.allclose(t, t.T):
            raise ValueError(f"{name} must be a finite symmetric matrix, got {t.tolist()}")
        low = float(torch.linalg.eigvalsh(t).min())
    else:
        low = float(t.min())
    if low < 0 or (definite and low <= 0):
        need = "positive definite" if definite else "positive semi-definite"
        raise ValueError(f"{name} must be {need} (smallest eigenvalue {low:.3g})")
    return t


@dataclass(frozen=True, eq=False)
class Covariances:
    r"""The covariances of a Kalman filter on the augmented model :math:`z = [x; d]`, the baseline of the feedback
    of Eqs. (7)-(8) on the same learned model (Eq. (3)).

    ``Q``: process noise of one nominal step ``Ts`` (on :math:`x`: model error within a step; on :math:`d`: a
    random walk, how fast the disturbance drifts); ``R``: measurement noise (e.g. ``std**2``), positive
    definite; ``P0``: the prior covariance at k = 0 (default: the filter's, ``blockdiag(R, 100 I)``). Each a
    scalar (times I), a vector (a diagonal) or a symmetric matrix, stored as float64 tensors.
    """

    Q: Tensor | float
    R: Tensor | float
    P0: Tensor | float | None = None

    def __post_init__(self):
        object.__setattr__(self, "Q", _covariance(self.Q, "Q", False))
        object.__setattr__(self, "R", _covariance(self.R, "R", True))
        if self.P0 is not None:
            object.__setattr__(self, "P0", _covariance(self.P0, "P0", False))


@dataclass(frozen=True)
class SigmaPoints:
    """The scaled sigma points (van der Merwe) of the unscented filter, a baseline of the feedback of Eqs. (7)-(8):
    spread ``alpha`` > 0, ``beta`` (2 is optimal for Gaussian priors) and ``kappa``; finite numbers."""

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def __post_init__(self):
        for name in ("alpha", "beta", "kappa"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
                raise ValueError(f"SigmaPoints.{name} must be a finite number, got {v!r}")
            object.__setattr__(self, name, float(v))
        if not self.alpha > 0:
            raise ValueError(f"SigmaPoints.alpha must be > 0, got {self.alpha!r}")
