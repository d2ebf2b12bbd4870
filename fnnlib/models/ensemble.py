"""Several neural ODEs trained side by side as one vector field on the stacked state (claim B2)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from fnnlib.models.neural_ode import ACTIVATIONS, NeuralODE
from fnnlib.seeding import seeded


class NeuralODEEnsemble(nn.Module):
    r"""``E`` independent MLP vector fields :math:`f_e` (Eq. (3)) acting on the stacked state.

    The ensemble is one autonomous field on :math:`\mathbb{R}^{E n}`,
    :math:`f(x_1, \dots, x_E) = (f_1(x_1), \dots, f_E(x_E))`: called as ``f(t, x)`` with ``x`` of shape
    (batch, E n), it evaluates every member with batched matrix products (an ensemble axis on the
    weights).  Anything elementwise in the state -- the Euler rollout, the linear feedback of Eqs.
    (7)-(8) with a scalar or diagonal gain, the cascade of Sec. 3.3 -- therefore runs every member at
    once and gives for each exactly what it gives for that member alone.  Training the stacked field on
    data tiled ``E`` times trains the members side by side (their losses add up; their gradients never
    mix).

    Parameters
    ----------
    n_state : int
        State dimension n of one member.
    hidden : sequence of int
        Hidden widths of every member.
    activation : str
        One of ``ACTIVATIONS``.
    seeds : sequence of int
        One seed per member: member ``e`` starts from the weights ``NeuralODE(n_state, hidden,
        activation)`` gets after ``seed_everything(seeds[e])`` (inside :func:`~fnnlib.seeding.seeded`: the
        caller's random state is left alone).
    """

    #: batches up to this size take the batched-matmul path, larger ones a loop over the members
    BMM_MAX_BATCH = 256

    def __init__(self, n_state: int, hidden: Sequence[int], activation: str, seeds: Sequence[int]) -> None:
        super().__init__()
        seeds = [int(s) for s in seeds]
        if not seeds or len(set(seeds)) != len(seeds):
            raise ValueError(f"need at least one seed and no repeats, got {seeds}")
        if activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {activation!r}; choose one of {sorted(ACTIVATIONS)}")
        self.n_state, self.hidden, self.activation, self.seeds = int(n_state), tuple(hidden), activation, seeds
        members = []
        for s in seeds:
            with seeded(s):
                members.append(NeuralODE(n_state, hidden, activation))
        self._stack(members)

    @classmethod
    def from_members(cls, members: Sequence[NeuralODE], seeds: Sequence[int]) -> NeuralODEEnsemble:
        """The ensemble of trained networks (weights copied), e.g. one per seed loaded by
        :func:`fnnlib.training.load_seed_checkpoints`: member ``e`` is ``members[e]``, trained from ``seeds[e]``.

        Every member must be an autonomous :class:`NeuralODE` of one architecture and dtype.
        """
        seeds = [int(s) for s in seeds]
        if not members or len(members) != len(seeds) or len(set(seeds)) != len(seeds):
            raise ValueError(f"need one member per seed and no repeated seed, got {len(members)} members "
                             f"for seeds {seeds}")
        first = members[0]
        if not all(isinstance(m, NeuralODE) for m in members):
            raise TypeError("every member must be a NeuralODE")
        dtypes = {next(m.parameters()).dtype for m in members}
        if any(m.config != first.config for m in members) or first.n_input or len(dtypes) > 1:
            raise ValueError("the members must share one architecture and dtype, without inputs; got "
                             f"{[m.config for m in members]}, dtypes {sorted(map(str, dtypes))}")
        ens = cls.__new__(cls)
        nn.Module.__init__(ens)
        ens.n_state, ens.hidden, ens.activation, ens.seeds = first.n_state, first.hidden, first.activation, seeds
        ens._stack(members)
        return ens

    def _stack(self, members: Sequence[NeuralODE]) -> None:
        """Stack the members' layers on an ensemble axis of the weights."""
        linears = [[m for m in member.net if isinstance(m, nn.Linear)] for member in members]
        # weight l: (E, in, out), bias l: (E, 1, out) -- y = x W + b per member
        self.weights = nn.ParameterList(
            nn.Parameter(torch.stack([ls[i].weight.detach().T.clone() for ls in linears])) for i in range(len(linears[0])))
        self.biases = nn.ParameterList(
            nn.Parameter(torch.stack([ls[i].bias.detach()[None].clone() for ls in linears])) for i in range(len(linears[0])))
        self.act = ACTIVATIONS[self.activation]()

    @property
    def size(self) -> int:
        """Number of members E."""
        return len(self.seeds)

    def forward(self, t: Tensor | float, x: Tensor) -> Tensor:
        """``f(t, x)`` for torchdiffeq: ``x`` (batch, E n) -> (batch, E n)."""
        E, n = self.size, self.n_state
        if x.ndim != 2 or x.shape[-1] != E * n:
            raise ValueError(f"the ensemble expects x of shape (batch, {E * n}), got {tuple(x.shape)}")
        last = len(self.weights) - 1
        if x.shape[0] <= self.BMM_MAX_BATCH:  # small (training) batches: one batched product per layer
            h = x.reshape(-1, E, n).transpose(0, 1)  # (E, batch, n)
            for i, (W, b) in enumerate(zip(self.weights, self.biases)):
                h = torch.baddbmm(b, h, W)
                if i < last:
                    h = self.act(h)
            return h.transpose(0, 1).reshape(x.shape)
        out = []  # large (rollout) batches: one contiguous product per member, several times faster than a
        for e in range(E):  # bmm over the strided members
            h = x[:, e * n:(e + 1) * n]
            for i, (W, b) in enumerate(zip(self.weights, self.biases)):
                h = torch.addmm(b[e, 0], h, W[e])
                if i < last:
                    h = self.act(h)
            out.append(h)
        return torch.cat(out, dim=-1)

    def split(self, z: Tensor) -> Tensor:
        """This ensemble's stacked states or rates (..., E n) -> (E, ..., n), member (seed) first: each member's
        own trajectory of Eq. (2), as :func:`split_members` with E = :attr:`size`."""
        return split_members(z, self.size)

    def member(self, e: int) -> NeuralODE:
        """Member ``e`` as a stand-alone :class:`NeuralODE` (weights copied)."""
        model = NeuralODE(self.n_state, self.hidden, self.activation).to(self.weights[0].dtype)
        linears = [m for m in model.net if isinstance(m, nn.Linear)]
        with torch.no_grad():
            for lin, W, b in zip(linears, self.weights, self.biases):
                lin.weight.copy_(W[e].T)
                lin.bias.copy_(b[e, 0])
        return model


def stack_members(x: Tensor, E: int) -> Tensor:
    """Tile states (..., n) to the ensemble's stacked state (..., E n)."""
    return x.repeat(*([1] * (x.ndim - 1)), E)


def split_members(x: Tensor, E: int) -> Tensor:
    """Stacked states (..., E n) -> (E, ..., n), member first."""
    return x.reshape(*x.shape[:-1], E, x.shape[-1] // E).movedim(-2, 0)
