r"""Two cascaded tanks with overflow: the synthetic twin of the cascaded tanks benchmark (tests, smoke profile).

A pump (input ``u``, volts) fills the upper tank, which drains through a small opening into the lower tank,
which drains into a reservoir (Torricelli's law, levels in the sensor's volts):

.. math::

    \dot x_1 = -k_1 \sqrt{x_1} + k_4 u, \qquad
    \dot x_2 = k_2 \sqrt{x_1} - k_3 \sqrt{x_2} + k_5\, q_{\text{over}},

with ``x_1`` the upper and ``x_2`` the lower level. A tank holds at most ``h_max`` (10 V, where the real
sensor saturates): at the rim the level stops rising, and the upper tank's surplus inflow
``q_over = max(k_4 u - k_1 sqrt(x_1), 0)`` spills, a fraction ``k_5`` of it into the lower tank (as on the
real rig, where part of the overflow falls into the lower tank). The measurement is the lower level only,
``y = C x`` with ``C = [0, 1]``, saturated at ``h_max``.

The default coefficients are ours, chosen so that the records look like the benchmark's (levels of
3-10 V for pump voltages of 0.5-6.5 V, time constants of a few minutes at Ts = 4 s, and an overflow at
the highest inputs); they are not identified from the real data.
"""

from __future__ import annotations

import torch
from torch import Tensor

from fnnlib.systems.base import DynamicalSystem

__all__ = ["CascadedTanks"]


class CascadedTanks(DynamicalSystem):
    """The two-tank plant above; state ``x = (upper level, lower level)`` in volts, input the pump voltage.

    Parameters
    ----------
    k1, k2, k3 : float
        Outflow coefficients of the upper tank (out of it, into the lower one) and of the lower tank.
    k4 : float
        Pump gain.
    k5 : float
        Fraction of the upper tank's overflow that falls into the lower tank, in [0, 1].
    h_max : float
        The tanks' rim (and the sensor's saturation), volts.
    """

    n, m = 2, 1
    C = ((0.0, 1.0),)
    """The measurement: the lower tank's level."""

    def __init__(self, k1: float = 0.035, k2: float = 0.035, k3: float = 0.033, k4: float = 0.028,
                 k5: float = 0.5, h_max: float = 10.0) -> None:
        for name, v in (("k1", k1), ("k2", k2), ("k3", k3), ("k4", k4), ("h_max", h_max)):
            if not float(v) > 0:
                raise ValueError(f"{name} must be > 0, got {v}")
        if not 0.0 <= float(k5) <= 1.0:
            raise ValueError(f"k5 (the share of the overflow that reaches the lower tank) must be in [0, 1], got {k5}")
        self.k1, self.k2, self.k3, self.k4, self.k5, self.h_max = (float(k1), float(k2), float(k3), float(k4),
                                                                  float(k5), float(h_max))

    def __call__(self, t: Tensor | float, x: Tensor, u: Tensor) -> Tensor:
        """dx/dt, shape (batch, 2), for ``x`` (batch, 2) and ``u`` (batch, 1)."""
        x1, x2 = x[:, 0].clamp(min=0.0), x[:, 1].clamp(min=0.0)
        inflow, out1, out2 = self.k4 * u[:, 0], self.k1 * x1.sqrt(), self.k3 * x2.sqrt()
        full1 = x1 >= self.h_max
        spill = torch.where(full1, (inflow - out1).clamp(min=0.0), torch.zeros_like(x1))  # q_over
        dx1 = torch.where(full1, torch.minimum(inflow - out1, torch.zeros_like(x1)), inflow - out1)
        dx2 = self.k2 * x1.sqrt() - out2 + self.k5 * spill
        dx2 = torch.where(x2 >= self.h_max, torch.minimum(dx2, torch.zeros_like(x2)), dx2)  # the lower rim
        return torch.stack([dx1, dx2], dim=-1)

    def measure(self, x: Tensor) -> Tensor:
        """The lower level as the sensor reads it: ``y = C x`` saturated to [0, h_max]; (..., T, 2) -> (..., T, 1)."""
        return x[..., 1:2].clamp(0.0, self.h_max)
