"""Dynamical systems dx/dt = f(t, x) (Eq. (1)) or, with an input, dx/dt = f(t, x, u); batched on the first axes."""

from __future__ import annotations

import torch
from torch import Tensor
from torchdiffeq import odeint

from fnnlib._validation import as_trajectory, check_finite


class DynamicalSystem:
    r"""Base class of the true systems: a vector field ``f(t, x)`` or, controlled, ``f(t, x, u)``.

    The true system of Eq. (1), :math:`\dot x = f(x, I, t)`: what a neural ODE (Eq. (2)) learns and the feedback
    of Eq. (7) corrects.

    How to write your own
    ---------------------
    Subclass it, set the class attributes ``n`` (state dimension) and, for a controlled system,
    ``m`` (input dimension, 0 by default), and implement ``__call__``:

    * autonomous: ``__call__(self, t, x)`` with ``t`` a float or a 0-d tensor and ``x`` of shape
      (batch, n), returning dx/dt of shape (batch, n) (torchdiffeq's convention);
    * controlled (``m > 0``): ``__call__(self, t, x, u)`` with ``u`` of shape (batch, m).

    Use torch operations only, so that the field runs batched, in float64, and can be differentiated.

    What you get
    ------------
    * :meth:`simulate` integrates from ``x0`` over a time grid: dopri5 at tight tolerances for an
      autonomous system; with inputs ``u`` (one row per sample, held over the step: zero-order hold)
      classical RK4 with ``substeps`` steps per sample. Both return float64; convert to your model's
      dtype (``x.float()``) before feeding a float32 network.
    * :meth:`rate` evaluates the true change rate along a trajectory, arguments in the order of
      ``__call__``: ``rate(t, x)``, ``rate(x)`` (t = 0) or ``rate(t, x, u)``.
    """

    n: int
    m: int = 0

    def __call__(self, t: Tensor | float, x: Tensor, *u: Tensor) -> Tensor:  # pragma: no cover - abstract
        raise NotImplementedError

    def simulate(self, x0: Tensor, t: Tensor, u: Tensor | None = None, *, rtol: float = 1e-10, atol: float = 1e-10,
                 substeps: int = 20) -> Tensor:
        """Integrate from ``x0`` over the time grid ``t``.

        Parameters
        ----------
        x0 : Tensor, shape (..., n)
            Initial states.
        t : Tensor, shape (T,)
            Strictly increasing output times; ``t[0]`` is the time of ``x0``.
        u : Tensor, shape (..., T, m), optional
            Inputs of a controlled system, row k held over ``[t_k, t_{k+1})``.
        rtol, atol : float
            dopri5 tolerances (autonomous systems).
        substeps : int
            RK4 steps per sample interval (controlled systems).

        Returns
        -------
        Tensor, shape (..., T, n), float64
        """
        x0 = torch.as_tensor(x0, dtype=torch.float64)
        t = torch.as_tensor(t, dtype=torch.float64)
        if x0.shape[-1] != self.n:
            raise ValueError(f"x0 has state dimension {x0.shape[-1]}, expected {self.n}")
        check_finite(x0, name="x0")
        if self.m and u is None:
            raise ValueError(f"{type(self).__name__} is controlled (m = {self.m}): give the inputs u (..., T, m)")
        if u is not None:
            return self._simulate_inputs(x0, t, u, int(substeps))
        lead = x0.shape[:-1]
        sol = odeint(self, x0.reshape(-1, self.n), t, rtol=rtol, atol=atol, method="dopri5")
        return sol.permute(1, 0, 2).reshape(*lead, t.numel(), self.n)

    def _simulate_inputs(self, x0: Tensor, t: Tensor, u: Tensor, substeps: int) -> Tensor:
        """RK4 with ``substeps`` steps per interval, the input held over each interval (zero-order hold)."""
        u = torch.as_tensor(u, dtype=torch.float64)
        if not self.m:
            raise ValueError(f"{type(self).__name__} takes no input (m = 0) but u was given")
        if u.ndim < 2 or u.shape[-2:] != (t.numel(), self.m):
            raise ValueError(f"u must have shape (..., {t.numel()}, {self.m}), got {tuple(u.shape)}")
        if substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps}")
        check_finite(u, name="u")
        lead = torch.broadcast_shapes(x0.shape[:-1], u.shape[:-2])
        x = x0.expand(*lead, self.n).reshape(-1, self.n)
        us = u.expand(*lead, *u.shape[-2:]).reshape(-1, *u.shape[-2:])
        out = [x]
        for k in range(t.numel() - 1):
            h = float(t[k + 1] - t[k]) / substeps
            uk = us[:, k]
            for s in range(substeps):
                tk = float(t[k]) + s * h
                k1 = self(tk, x, uk)
                k2 = self(tk + h / 2, x + h / 2 * k1, uk)
                k3 = self(tk + h / 2, x + h / 2 * k2, uk)
                k4 = self(tk + h, x + h * k3, uk)
                x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            out.append(x)
        return torch.stack(out, dim=1).reshape(*lead, t.numel(), self.n)

    def rate(self, *args: Tensor | float) -> Tensor:
        """The true change rate along a trajectory, in ``__call__``'s argument order.

        ``rate(x)``, ``rate(t, x)`` or, controlled, ``rate(t, x, u)``; ``x`` of shape (..., T, n),
        ``u`` (..., T, m); ``t`` one time. Returns (..., T, n).
        """
        if len(args) == 1:
            t, x, u = 0.0, args[0], None
        elif len(args) in (2, 3):
            t, x, u = args[0], args[1], args[2] if len(args) == 3 else None
            if isinstance(t, Tensor) and isinstance(x, Tensor) and t.ndim > x.ndim:
                raise TypeError("rate takes (t, x) in the order of __call__(t, x); got a trajectory as t")
        else:
            raise TypeError(f"rate takes (x), (t, x) or (t, x, u); got {len(args)} arguments")
        x = as_trajectory(x, self.n)
        if u is None:
            return self(t, x.reshape(-1, self.n)).reshape(x.shape)
        u = torch.as_tensor(u, dtype=x.dtype).expand(*x.shape[:-1], self.m)
        return self(t, x.reshape(-1, self.n), u.reshape(-1, self.m)).reshape(x.shape)


class StackedSystem(DynamicalSystem):
    """``E`` copies of an autonomous system on the stacked state (..., E n), the layout of
    :class:`fnnlib.NeuralODEEnsemble`: one integration runs a true system beside every member of an ensemble
    (e.g. Theorem 1's continuous observer for every seed's network, :func:`fnnlib.stability.observe_continuous`)."""

    def __init__(self, system: DynamicalSystem, E: int) -> None:
        if getattr(system, "m", 0):
            raise ValueError(f"StackedSystem takes an autonomous system, {type(system).__name__} has inputs")
        if int(E) != E or int(E) < 1:
            raise ValueError(f"need a number of copies E >= 1, got {E!r}")
        self.system, self.E, self.n = system, int(E), int(E) * system.n

    def __call__(self, t: Tensor | float, x: Tensor) -> Tensor:
        """dx/dt of every copy: ``x`` (batch, E n) -> (batch, E n)."""
        n = self.system.n
        return self.system(t, x.reshape(-1, n)).reshape(x.shape)
