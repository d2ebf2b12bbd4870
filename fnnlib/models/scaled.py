r"""Neural fields with an input, in the units of a plant's log, trained side by side as one stacked field.

A log in physical units (levels of 0-10 V, rates of a few mV/s) does not suit an MLP whose weights start near
1: :class:`ScaledField` evaluates

.. math::

    f_e(x, u) = r \, \mathrm{MLP}_e\!\left(\frac{x - x_c}{x_s}, \frac{u - u_c}{u_s}\right)

for each member ``e`` of an ensemble, on the stacked state :math:`(x_1, \dots, x_E)` (shape (batch, E n))
with one shared input ``u`` (batch, m). The centres and scales are fixed numbers (from the training record),
the rate scale ``r`` sets the size of :math:`T_s f` at the start of training. Everything elementwise in the
state -- Euler steps, the linear feedback of Eqs. (7)-(8) with a block-diagonal gain, the cascade of
Sec. 3.3 with a diagonal gain -- runs every member at once and gives each what it would give alone, so a
record tiled ``E`` times trains the ``E`` seeds in one run (their losses add, their gradients never mix).
:meth:`ScaledField.member` returns one member as a field of its own (for a Kalman filter, say).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from fnnlib.models.neural_ode import ACTIVATIONS, mlp
from fnnlib.seeding import seeded

__all__ = ["ScaledField"]


class ScaledField(nn.Module):
    """``E`` MLP fields ``f_e(t, x, u)`` in a log's units on the stacked state (module docstring).

    Parameters
    ----------
    n_state, n_input : int
        State and input dimension of one member.
    hidden : sequence of int
        Hidden widths of every member.
    activation : str
        One of ``ACTIVATIONS``.
    seeds : sequence of int
        One seed per member: member ``e`` starts from the weights ``mlp(n + m, n, hidden, activation)`` gets
        after ``seed_everything(seeds[e])``.
    x_center, x_scale : float or sequence of n floats
        The state's centre and scale (:math:`x_c`, :math:`x_s > 0`).
    u_center, u_scale : float or sequence of m floats
        The input's centre and scale (:math:`u_c`, :math:`u_s > 0`).
    rate : float
        The rate scale :math:`r > 0` (state units per time unit).

    Attributes
    ----------
    n_members : int
        E.
    """

    def __init__(self, n_state: int, n_input: int, hidden: Sequence[int], activation: str, seeds: Sequence[int], *,
                 x_center: float | Sequence[float] = 0.0, x_scale: float | Sequence[float] = 1.0,
                 u_center: float | Sequence[float] = 0.0, u_scale: float | Sequence[float] = 1.0,
                 rate: float = 1.0) -> None:
        super().__init__()
        seeds = [int(s) for s in seeds]
        if not seeds or len(set(seeds)) != len(seeds):
            raise ValueError(f"need at least one seed and no repeats, got {seeds}")
        if activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {activation!r}; choose one of {sorted(ACTIVATIONS)}")
        if int(n_state) < 1 or int(n_input) < 1:
            raise ValueError(f"n_state and n_input must be >= 1, got {n_state}, {n_input}")
        if not float(rate) > 0:
            raise ValueError(f"rate must be > 0, got {rate}")
        n, m = int(n_state), int(n_input)
        self.n_state, self.n_input, self.hidden, self.activation = n, m, tuple(int(h) for h in hidden), activation
        self.seeds, self.n_members, self.rate = seeds, len(seeds), float(rate)
        for name, v, k in (("x_center", x_center, n), ("x_scale", x_scale, n), ("u_center", u_center, m),
                           ("u_scale", u_scale, m)):
            t = torch.as_tensor(v, dtype=torch.float64).reshape(-1).expand(k).clone()
            if not torch.isfinite(t).all() or (name.endswith("scale") and not (t > 0).all()):
                raise ValueError(f"{name} must be finite{' and > 0' if name.endswith('scale') else ''}, got {v!r}")
            self.register_buffer(name, t)
        nets = []
        for s in seeds:
            with seeded(s):
                nets.append(mlp(n + m, n, self.hidden, activation).double())
        linears = [[mod for mod in net if isinstance(mod, nn.Linear)] for net in nets]
        self.weights = nn.ParameterList([nn.Parameter(torch.stack([ls[i].weight.detach().T for ls in linears]))
                                         for i in range(len(linears[0]))])  # (E, in, out)
        self.biases = nn.ParameterList([nn.Parameter(torch.stack([ls[i].bias.detach() for ls in linears])[:, None])
                                        for i in range(len(linears[0]))])  # (E, 1, out)
        self.act = ACTIVATIONS[activation]()

    def forward(self, t: Tensor | float, x: Tensor, u: Tensor) -> Tensor:
        """dx/dt of every member: ``x`` (batch, E n), ``u`` (batch, m) -> (batch, E n)."""
        E, n = self.n_members, self.n_state
        if x.shape[-1] != E * n or u.shape[-1] != self.n_input:
            raise ValueError(f"x must be (batch, {E * n}) and u (batch, {self.n_input}), got {tuple(x.shape)} "
                             f"and {tuple(u.shape)}")
        xs = ((x.reshape(-1, E, n) - self.x_center) / self.x_scale).transpose(0, 1)  # (E, batch, n)
        us = ((u.reshape(-1, self.n_input) - self.u_center) / self.u_scale).expand(E, -1, -1)  # (E, batch, m)
        h = torch.cat([xs, us], dim=-1)
        last = len(self.weights) - 1
        for i, (W, b) in enumerate(zip(self.weights, self.biases)):
            h = torch.baddbmm(b, h, W)  # (E, batch, out)
            if i < last:
                h = self.act(h)
        return (self.rate * h).transpose(0, 1).reshape(x.shape)

    def member(self, e: int) -> ScaledField:
        """Member ``e`` alone, as a one-member field (its weights copied)."""
        if not 0 <= e < self.n_members:
            raise IndexError(f"member {e} of {self.n_members}")
        one = ScaledField(self.n_state, self.n_input, self.hidden, self.activation, [self.seeds[e]],
                          x_center=self.x_center.tolist(), x_scale=self.x_scale.tolist(),
                          u_center=self.u_center.tolist(), u_scale=self.u_scale.tolist(), rate=self.rate)
        with torch.no_grad():
            for dst, src in zip([*one.weights, *one.biases], [*self.weights, *self.biases]):
                dst.copy_(src[e:e + 1])
        return one
