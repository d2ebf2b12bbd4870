"""The quadrotor's learned aerodynamic residual (App. A.5.2) and its adaptive last layer (Eqs. (29)-(30))."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor, nn

from fnnlib.models.neural_ode import mlp
from fnnlib.training.checkpoint import register_model

#: Slice of the 12-dimensional quadrotor state that feeds the residual: (v, Theta).
RESIDUAL_INPUTS = slice(3, 9)


def _run(layers: nn.Sequential, h: Tensor) -> Tensor:
    """``layers(h)`` calling each module's ``forward`` directly.

    Skips ``nn.Module.__call__`` (hook dispatch, ~5-10 us a layer): the residual runs at
    every RK4 stage of every MPC step, where per-call overhead is the cost. No hooks are
    used on these networks.
    """
    for layer in layers:
        h = layer.forward(h)
    return h


@register_model  # checkpointable: save_checkpoint / load_checkpoint know it once this module is imported
class AeroResidual(nn.Module):
    r"""An acceleration residual :math:`f_{neural}(v, \Theta, \theta)` added to Eq. (27) (App. A.5.2).

    The augmented model is :math:`\dot v = -\tfrac{1}{m} Z_B T + g Z_E + f_{neural}(v, \Theta)`.
    The paper uses an MLP with 2 hidden layers of 36 units (the authors'
    release: 3 hidden layers, tanh).

    Called as ``net(x)`` with the full quadrotor state ``x`` of shape (..., 12);
    returns the residual acceleration, shape (..., 3). The last linear layer is
    :math:`\chi` of Eq. (29): ``net(x) == features(x) @ W.T + b``.

    Parameters
    ----------
    hidden : sequence of int
        Hidden widths (the paper's: ``(36, 36)``, in
        :data:`~fnnlib.quadrotor.presets.PAPER_RESIDUAL_RECIPE`).
    activation : str
        One of :data:`fnnlib.models.ACTIVATIONS` (the paper's: ``"tanh"``).
    """

    n_in = 6
    n_out = 3

    def __init__(self, hidden: Sequence[int], activation: str) -> None:
        super().__init__()
        self.hidden = tuple(int(h) for h in hidden)
        self.activation = str(activation)
        if not self.hidden:
            raise ValueError("the residual network needs at least one hidden layer (its last layer is adapted)")
        self.net = mlp(self.n_in, self.n_out, self.hidden, self.activation)

    @property
    def config(self) -> dict[str, Any]:
        """Constructor arguments, enough to rebuild the model (used by checkpoints)."""
        return {"hidden": list(self.hidden), "activation": self.activation}

    @property
    def last(self) -> nn.Linear:
        """The last linear layer (weights :math:`\\chi` of Eq. (29) and a bias)."""
        layer = self.net[-1]
        assert isinstance(layer, nn.Linear)
        return layer

    def _check(self, x: Tensor) -> Tensor:
        if x.shape[-1] != 12:
            raise ValueError(f"the residual takes the 12-dimensional quadrotor state, got shape {tuple(x.shape)}")
        return x[..., RESIDUAL_INPUTS]

    def features(self, x: Tensor) -> Tensor:
        r"""The front layers :math:`\Xi` of Eq. (29): (..., 12) -> (..., hidden[-1])."""
        return _run(self.net[:-1], self._check(x))

    def forward(self, x: Tensor) -> Tensor:
        return _run(self.net, self._check(x))


class AdaptiveResidual(nn.Module):
    r"""A residual whose last layer adapts online: Eqs. (29)-(30) `feedback_NN2` / `adaptive_law`.

    :math:`f_{neural}(x) = \Xi(x)\hat\chi` with the front layers of a trained
    :class:`AeroResidual` frozen and :math:`\hat\chi` (the last 3 x h weight
    matrix; the bias stays fixed) updated by Eq. (30)

    .. math:: \dot{\hat\chi} = \Gamma\,\Xi^\top(t)\,\tilde x(t),

    integrated with an explicit Euler step of length ``Ts`` by :meth:`adapt`.
    Only the velocity rows of :math:`\Xi` are nonzero (the residual enters
    :math:`\dot v`), so only the velocity part of :math:`\tilde x` matters:
    :math:`\Xi^\top\tilde x = \mathrm{vec}(\tilde x_v\,\phi^\top)`.

    Parameters
    ----------
    base : AeroResidual
        The offline-trained network; copied, never modified.
    Gamma : float
        Adaptation gain (a positive multiple of the identity); the authors'
        release uses :data:`~fnnlib.quadrotor.presets.PAPER_GAMMA` = 8.0.
    """

    def __init__(self, base: AeroResidual, Gamma: float) -> None:
        super().__init__()
        Gamma = float(Gamma)
        if not (Gamma > 0 and torch.isfinite(torch.tensor(Gamma))):
            raise ValueError(f"adaptation gain Gamma must be finite and > 0 (positive definite), got {Gamma}")
        self.Gamma = Gamma
        self.front = copy.deepcopy(base.net[:-1])  # a copy: freezing it must not touch the base
        for p in self.front.parameters():
            p.requires_grad_(False)
        last = base.last
        self.register_buffer("chi_hat", last.weight.detach().clone())  # (3, h)
        self.register_buffer("chi_0", last.weight.detach().clone())
        self.register_buffer("b", last.bias.detach().clone())

    def features(self, x: Tensor) -> Tensor:
        r""":math:`\phi(x)`, the output of the front layers: (..., 12) -> (..., h)."""
        if x.shape[-1] != 12:
            raise ValueError(f"the residual takes the 12-dimensional quadrotor state, got shape {tuple(x.shape)}")
        return _run(self.front, x[..., RESIDUAL_INPUTS])

    def forward(self, x: Tensor) -> Tensor:
        # f_neural = Xi(x) chi_hat   (Eq. 29)
        return self.features(x) @ self.chi_hat.T + self.b

    def adapt(self, x: Tensor, x_tilde_v: Tensor, Ts: float) -> None:
        r"""One Euler step of Eq. (30): :math:`\hat\chi \mathrel{+}= T_s\,\Gamma\,\tilde x_v\phi(x)^\top`.

        ``x`` (12,) is the state where :math:`\Xi` is evaluated, ``x_tilde_v``
        (3,) the velocity part of the observation error.
        """
        if x_tilde_v.shape != (3,) or x.shape != (12,):
            raise ValueError(f"adapt takes x (12,) and x_tilde_v (3,), got {tuple(x.shape)} and {tuple(x_tilde_v.shape)}")
        if not bool(torch.isfinite(x_tilde_v).all()):
            raise ValueError("observation error holds NaN or inf; refusing to adapt")
        with torch.no_grad():
            phi = self.features(x.to(self.chi_hat.dtype))
            # chi_hat' = Gamma Xi^T x_tilde   (Eq. 30)
            self.chi_hat.add_(torch.outer(x_tilde_v.to(self.chi_hat.dtype), phi), alpha=float(Ts) * self.Gamma)

    def reset(self) -> None:
        """Back to the offline weights."""
        with torch.no_grad():
            self.chi_hat.copy_(self.chi_0)


class EnsembleResidual(nn.Module):
    r"""``E`` independently initialised :class:`AeroResidual` networks evaluated as one batch.

    Used to train several random initialisations at once (Q1): the closed
    loops of all members are stacked along the state axis, so the training
    loss is a sum of independent per-member losses and, Adam being
    element-wise, each member follows exactly the updates it would get alone
    on the same mini-batches. Call with ``x`` (..., E, 12) -> (..., E, 3).
    """

    def __init__(self, members: Sequence[AeroResidual]) -> None:
        super().__init__()
        if not members:
            raise ValueError("an ensemble needs at least one member")
        cfg = members[0].config
        if any(m.config != cfg for m in members):
            raise ValueError("all ensemble members must share hidden sizes and activation")
        self.config_member = dict(cfg)
        self.E = len(members)
        self.activation = members[0].net[1]  # the shared activation module
        linears = [[layer for layer in m.net if isinstance(layer, nn.Linear)] for m in members]
        self.weights = nn.ParameterList(
            [nn.Parameter(torch.stack([ls[i].weight.detach() for ls in linears])) for i in range(len(linears[0]))])
        self.biases = nn.ParameterList(
            [nn.Parameter(torch.stack([ls[i].bias.detach() for ls in linears])) for i in range(len(linears[0]))])

    def forward(self, x: Tensor) -> Tensor:
        if x.shape[-2:] != (self.E, 12):
            raise ValueError(f"ensemble input must have shape (..., {self.E}, 12), got {tuple(x.shape)}")
        h = x[..., RESIDUAL_INPUTS]
        last = len(self.weights) - 1
        for i, (W, b) in enumerate(zip(self.weights, self.biases)):
            h = torch.einsum("eoi,...ei->...eo", W, h) + b  # member e's layer on member e's input
            if i < last:
                h = self.activation(h)
        return h

    def member(self, e: int) -> AeroResidual:
        """Member ``e`` as a stand-alone :class:`AeroResidual` (a copy)."""
        net = AeroResidual(**self.config_member).to(self.weights[0].dtype)
        linears = [layer for layer in net.net if isinstance(layer, nn.Linear)]
        with torch.no_grad():
            for layer, W, b in zip(linears, self.weights, self.biases):
                layer.weight.copy_(W[e])
                layer.bias.copy_(b[e])
        return net
