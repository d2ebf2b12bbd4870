"""The integrator of the Sec. 5 code: classical RK4 with the input held over the step (zero-order hold)."""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import Tensor

__all__ = ["check_step", "rk4"]


def rk4(fun: Callable[[Tensor], Tensor], y: Tensor, Ts: float, substeps: int = 1, k1: Tensor | None = None) -> Tensor:
    """Classical fourth-order Runge-Kutta over ``Ts`` in ``substeps`` equal sub-steps of ``y' = fun(y)``.

    Parameters
    ----------
    fun : callable, Tensor (..., n) -> Tensor (..., n)
        Right-hand side, evaluated four times per sub-step.
    y : Tensor, shape (..., n)
    Ts : float
        Step length (> 0; not checked here, see :func:`check_step`).
    substeps : int
        Number of equal RK4 sub-steps (>= 1).
    k1 : Tensor, shape (..., n), optional
        ``fun(y)`` if the caller has it already (it is the change rate at the start);
        used for the first sub-step only.

    Returns
    -------
    Tensor, shape (..., n)
    """
    h = Ts / substeps
    for i in range(substeps):
        if i > 0 or k1 is None:
            k1 = fun(y)
        k2 = fun(torch.add(y, k1, alpha=0.5 * h))
        k3 = fun(torch.add(y, k2, alpha=0.5 * h))
        k4 = fun(torch.add(y, k3, alpha=h))
        # y + h/6 (k1 + 2 k2 + 2 k3 + k4), in fused adds (the step is bound by per-op overhead)
        y = torch.add(y, torch.add(torch.add(k1, k4), torch.add(k2, k3), alpha=2.0), alpha=h / 6.0)
    return y


def check_step(Ts: float, substeps: int) -> tuple[float, int]:
    """Validate an integration step: ``Ts`` finite and > 0, ``substeps`` an int >= 1."""
    if isinstance(Ts, bool) or not isinstance(Ts, (int, float)):
        raise TypeError(f"Ts must be a float, got {type(Ts).__name__}")
    if not (math.isfinite(Ts) and Ts > 0):
        raise ValueError(f"Ts must be a finite positive number, got {Ts!r}")
    if isinstance(substeps, bool) or not isinstance(substeps, int):
        raise TypeError(f"substeps must be an int, got {type(substeps).__name__}")
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    return float(Ts), substeps
