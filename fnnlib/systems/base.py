"""Autonomous dynamical systems dx/dt = f(t, x), Eq. (1), batched on the first axes."""

from __future__ import annotations

import torch
from torch import Tensor
from torchdiffeq import odeint

from fnnlib._validation import as_trajectory, check_finite


class DynamicalSystem:
    """Base class: a vector field ``f(t, x)`` with ``x`` of shape ``(batch, n)``.

    Subclasses set ``n`` and implement :meth:`__call__`. :meth:`simulate`
    integrates accurately (dopri5, tight tolerances, float64).
    """

    n: int

    def __call__(self, t: Tensor | float, x: Tensor) -> Tensor:  # pragma: no cover - abstract
        raise NotImplementedError

    def simulate(self, x0: Tensor, t: Tensor, *, rtol: float = 1e-10, atol: float = 1e-10) -> Tensor:
        """Integrate from ``x0`` over the time grid ``t``.

        Parameters
        ----------
        x0 : Tensor, shape (..., n)
            Initial states.
        t : Tensor, shape (T,)
            Strictly increasing output times; ``t[0]`` is the time of ``x0``.

        Returns
        -------
        Tensor, shape (..., T, n), float64
        """
        x0 = torch.as_tensor(x0, dtype=torch.float64)
        t = torch.as_tensor(t, dtype=torch.float64)
        if x0.shape[-1] != self.n:
            raise ValueError(f"x0 has state dimension {x0.shape[-1]}, expected {self.n}")
        check_finite(x0, name="x0")
        lead = x0.shape[:-1]
        sol = odeint(self, x0.reshape(-1, self.n), t, rtol=rtol, atol=atol, method="dopri5")
        return sol.permute(1, 0, 2).reshape(*lead, t.numel(), self.n)

    def rate(self, x: Tensor, t: Tensor | float = 0.0) -> Tensor:
        """The true change rate f(t, x) along a trajectory ``x`` of shape ``(..., T, n)``."""
        x = as_trajectory(x, self.n)
        return self(t, x.reshape(-1, self.n)).reshape(x.shape)
