r"""Switched systems: the vector field jumps between given systems at given times (Fig. S12's step change)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from fnnlib._validation import as_trajectory, check_finite
from fnnlib.systems.base import DynamicalSystem


class SwitchedSystem(DynamicalSystem):
    r"""Piecewise dynamics :math:`\dot x = f_j(t, x)` for :math:`\tau_j \le t < \tau_{j+1}`.

    With switch times :math:`\tau_1 < \dots < \tau_m` (and :math:`\tau_0 = -\infty`,
    :math:`\tau_{m+1} = \infty`), system ``j`` is active on :math:`[\tau_j, \tau_{j+1})`: the
    field is right-continuous, the state continuous. :meth:`simulate`
    integrates each piece separately from the state reached at its switch
    time, so no solver step straddles a jump.

    Parameters
    ----------
    systems : sequence of DynamicalSystem
        ``m + 1`` systems of the same state dimension.
    switch_times : sequence of float
        ``m`` strictly increasing finite times.

    Examples
    --------
    The step change of Fig. S12: ``SwitchedSystem([Spiral(3, 0.05, 10), Spiral(1, 0.12, 5)], [7.0])``.
    """

    def __init__(self, systems: Sequence[DynamicalSystem], switch_times: Sequence[float]):
        systems = tuple(systems)
        times = [float(s) for s in switch_times]
        if len(systems) != len(times) + 1:
            raise ValueError(f"a switched system needs one more system than switch times; got {len(systems)} "
                             f"systems and {len(times)} switch times")
        if not all(math.isfinite(s) for s in times):
            raise ValueError(f"switch times must be finite, got {times}")
        if any(b <= a for a, b in zip(times[:-1], times[1:])):
            raise ValueError(f"switch times must be strictly increasing, got {times}")
        dims = {s.n for s in systems}
        if len(dims) != 1:
            raise ValueError(f"all systems of a switched system must share the state dimension, got {sorted(dims)}")
        self.systems = systems
        self.switch_times = torch.tensor(times, dtype=torch.float64)
        self.n = dims.pop()

    def index(self, t: Tensor | float) -> Tensor:
        """Index of the active system at time(s) ``t`` (right-continuous at a switch)."""
        t = torch.as_tensor(t, dtype=torch.float64)
        return torch.searchsorted(self.switch_times, t.contiguous(), right=True)

    def __call__(self, t: Tensor | float, x: Tensor) -> Tensor:
        """dx/dt for ``x`` (batch, n) at a scalar ``t`` or per-row times ``t`` of shape (batch,)."""
        t = torch.as_tensor(t, dtype=torch.float64)
        if t.ndim == 0:
            return self.systems[int(self.index(t))](t, x)
        if t.shape != x.shape[:1]:
            raise ValueError(f"per-row times must have shape ({x.shape[0]},), got {tuple(t.shape)}")
        idx = self.index(t)
        out = torch.stack([s(t, x) for s in self.systems])  # (systems, batch, n)
        return out.gather(0, idx.view(1, -1, 1).expand(1, *x.shape)).squeeze(0)

    def rate(self, *args: Tensor | float) -> Tensor:
        """The true change rate along a trajectory ``x`` (..., T, n) sampled at times ``t`` (T,) (or one time).

        ``rate(t, x)`` (the order of ``__call__``) or ``rate(x)`` (t = 0).
        """
        if len(args) not in (1, 2):
            raise TypeError(f"rate takes (x) or (t, x); got {len(args)} arguments")
        t, x = (0.0, args[0]) if len(args) == 1 else args
        if isinstance(t, Tensor) and isinstance(x, Tensor) and t.ndim > x.ndim:
            raise TypeError("rate takes (t, x) in the order of __call__(t, x); got a trajectory as t")
        x = as_trajectory(x, self.n)
        t = torch.as_tensor(t, dtype=torch.float64)
        if t.ndim == 0:
            return super().rate(t, x)
        if t.shape != x.shape[-2:-1]:
            raise ValueError(f"times t must have shape ({x.shape[-2]},) to match x {tuple(x.shape)}, "
                             f"got {tuple(t.shape)}")
        rows = t.expand(x.shape[:-1]).reshape(-1)
        return self(rows, x.reshape(-1, self.n)).reshape(x.shape)

    def simulate(self, x0: Tensor, t: Tensor, *, rtol: float = 1e-10, atol: float = 1e-10) -> Tensor:
        """Integrate piece by piece over the grid ``t``; shapes and precision as :meth:`DynamicalSystem.simulate`."""
        x0 = torch.as_tensor(x0, dtype=torch.float64)
        t = torch.as_tensor(t, dtype=torch.float64)
        if x0.shape[-1] != self.n:
            raise ValueError(f"x0 has state dimension {x0.shape[-1]}, expected {self.n}")
        check_finite(x0, name="x0")
        if t.ndim != 1 or t.numel() < 1 or not bool((torch.diff(t) > 0).all()):
            raise ValueError("t must be a strictly increasing 1-D time grid")
        t_start, t_end = float(t[0]), float(t[-1])
        ends = [float(s) for s in self.switch_times if t_start < float(s) < t_end] + [t_end]
        pieces, x, t_cur, k = [x0.unsqueeze(-2)], x0, t_start, 1
        for end in ends:
            if end <= t_cur:  # a single-sample grid: nothing to integrate
                break
            k_end = k + int(((t[k:] > t_cur) & (t[k:] <= end)).sum())  # grid samples in (t_cur, end]
            tt = torch.cat([t.new_tensor([t_cur]), t[k:k_end]])
            if float(tt[-1]) < end:
                tt = torch.cat([tt, t.new_tensor([end])])  # stop at the switch itself
            sol = self.systems[int(self.index(t_cur))].simulate(x, tt, rtol=rtol, atol=atol)
            pieces.append(sol[..., 1:1 + k_end - k, :])
            x, t_cur, k = sol[..., -1, :], end, k_end
        return torch.cat(pieces, dim=-2)
