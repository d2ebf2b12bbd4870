"""The neural feedback part h_neural(x - x_hat, xi) of Sec. 4."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor, nn

from fnnlib.models.ensemble import NeuralODEEnsemble
from fnnlib.models.neural_ode import NeuralODE, mlp


class NeuralFeedback(nn.Module):
    r"""A learned feedback :math:`h_{neural}(x - \hat x, \xi)` (Sec. 4, Eq. (12) `learn_feedback_part`).

    It replaces the linear term :math:`L(x - \hat x)` of Eq. (7): the corrected change rate is
    :math:`\hat f = f_{neural}(x) + h_{neural}(x - \hat x)`. Called as ``h(e)`` with the observation
    error ``e`` of shape (batch, n); returns the correction, shape (batch, n).

    Parameters
    ----------
    n_state : int
        State dimension n.
    hidden : sequence of int
        Hidden widths; the paper's spiral feedback is ``(50, 50)`` (App. A.3.3).
    activation : str
        One of :data:`fnnlib.models.ACTIVATIONS`.
    """

    def __init__(self, n_state: int, hidden: Sequence[int], activation: str) -> None:
        super().__init__()
        self.n_state = int(n_state)
        self.hidden = tuple(int(h) for h in hidden)
        self.activation = str(activation)
        self.net = mlp(self.n_state, self.n_state, self.hidden, self.activation)

    @property
    def config(self) -> dict[str, Any]:
        """Constructor arguments, enough to rebuild the model (used by checkpoints)."""
        return {"n_state": self.n_state, "hidden": list(self.hidden), "activation": self.activation}

    def forward(self, e: Tensor) -> Tensor:
        """h_neural(e): ``e`` (batch, n) -> (batch, n)."""
        if e.shape[-1] != self.n_state:
            raise ValueError(f"error e has dimension {e.shape[-1]}, feedback expects {self.n_state}")
        return self.net(e)


class _MemberMajorGrad(torch.autograd.Function):
    """Identity whose gradient is made contiguous: the (E, batch, n) gradient of the last layer then sums each
    member's bias gradient in one contiguous pass, so a member's gradient does not depend on E (bitwise)."""

    @staticmethod
    def forward(ctx, z: Tensor) -> Tensor:
        return z.view_as(z)

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        return grad.contiguous()


class NeuralFeedbackEnsemble(nn.Module):
    r"""``E`` independent feedbacks :math:`h_e` (Sec. 4) acting on the stacked observation error.

    The feedback analogue of :class:`~fnnlib.models.NeuralODEEnsemble`: called as ``h(e)`` with ``e`` of
    shape (batch, E n), it returns :math:`(h_1(e_1), \dots, h_E(e_E))`, every member by one batched product
    per layer. Member ``e`` starts from the weights ``NeuralFeedback(n_state, hidden, activation)`` gets after
    ``seed_everything(seeds[e])``, and evaluates and back-propagates bitwise as a one-member ensemble of its
    seed would (equal to that ``NeuralFeedback`` up to float32 rounding: batched products); with the
    stacked field of a :class:`~fnnlib.models.NeuralODEEnsemble`, the neural feedback network of Eqs. (7)-(8)
    (:func:`~fnnlib.observers.feedback_rollout`, the cascade) runs every seed at once.

    The parameters (``n_state`` of one member, ``hidden``, ``activation``, one distinct seed per member) are
    those of :class:`~fnnlib.models.NeuralODEEnsemble`.
    """

    def __init__(self, n_state: int, hidden: Sequence[int], activation: str, seeds: Sequence[int]) -> None:
        super().__init__()
        # NeuralFeedback and an input-free NeuralODE build the same MLP (`mlp(n, n, hidden, activation)`), so the
        # stacked MLP of a NeuralODEEnsemble starts every member from its seed's NeuralFeedback weights
        self.stacked = NeuralODEEnsemble(n_state, hidden, activation, seeds)

    @classmethod
    def from_members(cls, members: Sequence[NeuralFeedback], seeds: Sequence[int]) -> NeuralFeedbackEnsemble:
        """The ensemble of trained neural feedbacks (Eq. (12); weights copied), e.g. one per seed loaded by
        :func:`fnnlib.training.load_seed_checkpoints`: member ``e`` is ``members[e]``, trained from ``seeds[e]``.

        Its stacked MLP is a :meth:`NeuralODEEnsemble.from_members` of input-free neural ODEs holding the
        feedbacks' MLPs (the layout of the constructor).
        """
        if not all(isinstance(m, NeuralFeedback) for m in members):
            raise TypeError("every member must be a NeuralFeedback")
        as_odes = []
        for m in members:
            ode = NeuralODE(m.n_state, m.hidden, m.activation).to(next(m.parameters()).dtype)
            ode.net.load_state_dict(m.net.state_dict())
            as_odes.append(ode)
        ens = cls.__new__(cls)
        nn.Module.__init__(ens)
        ens.stacked = NeuralODEEnsemble.from_members(as_odes, seeds)
        return ens

    @property
    def size(self) -> int:
        """Number of members E."""
        return self.stacked.size

    @property
    def seeds(self) -> list[int]:
        """The members' seeds."""
        return self.stacked.seeds

    @property
    def n_state(self) -> int:
        """State dimension n of one member."""
        return self.stacked.n_state

    def forward(self, e: Tensor) -> Tensor:
        """h(e): ``e`` (batch, E n) -> (batch, E n), one batched product per layer."""
        s = self.stacked
        E, n = s.size, s.n_state
        if e.ndim != 2 or e.shape[-1] != E * n:
            raise ValueError(f"the feedback ensemble expects e of shape (batch, {E * n}), got {tuple(e.shape)}")
        z = e.reshape(-1, E, n).transpose(0, 1)  # (E, batch, n)
        last = len(s.weights) - 1
        for i, (W, b) in enumerate(zip(s.weights, s.biases)):
            z = torch.baddbmm(b, z, W)
            if i < last:
                z = s.act(z)
        return _MemberMajorGrad.apply(z).transpose(0, 1).reshape(e.shape)

    def member(self, e: int) -> NeuralFeedback:
        """Member ``e`` as a stand-alone :class:`NeuralFeedback` (weights copied)."""
        s = self.stacked
        h = NeuralFeedback(s.n_state, s.hidden, s.activation).to(s.weights[0].dtype)
        h.net.load_state_dict(s.member(e).net.state_dict())
        return h
