"""Neural ODE vector fields f_neural(x, theta), Eq. (3)."""

from __future__ import annotations

import math

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor, nn

#: activation name (as a recipe or checkpoint writes it) -> its torch module
ACTIVATIONS: dict[str, type[nn.Module]] = {
    "relu": nn.ReLU,
    "tanh": nn.Tanh,
    "softplus": nn.Softplus,
    "elu": nn.ELU,
    "gelu": nn.GELU,
}


def mlp(n_in: int, n_out: int, hidden: Sequence[int], activation: str) -> nn.Sequential:
    """A multilayer perceptron ``n_in -> *hidden -> n_out`` with the named activation.

    ``hidden=(50, 50)`` gives three linear layers 2-50-50-2 for the spiral.
    """
    if activation not in ACTIVATIONS:
        raise ValueError(f"unknown activation {activation!r}; choose one of {sorted(ACTIVATIONS)}")
    if int(n_in) < 1 or int(n_out) < 1 or any(int(h) < 1 for h in hidden):
        raise ValueError(f"layer sizes must be >= 1, got n_in={n_in}, hidden={list(hidden)}, n_out={n_out}")
    sizes = [int(n_in), *[int(h) for h in hidden], int(n_out)]
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(ACTIVATIONS[activation]())
    return nn.Sequential(*layers)


def init_parameters(module: nn.Module, generator: torch.Generator) -> nn.Module:
    r"""Initialise every ``nn.Linear`` of ``module`` from ``generator`` (torch's default law, uniform in
    :math:`\pm 1/\sqrt{fan_{in}}` for weights and biases), leaving torch's global random state untouched.
    Returns ``module``."""
    with torch.no_grad():
        for m in module.modules():
            if isinstance(m, nn.Linear):
                bound = 1.0 / math.sqrt(m.in_features)
                m.weight.copy_((torch.rand(m.weight.shape, generator=generator, dtype=m.weight.dtype) * 2 - 1) * bound)
                if m.bias is not None:
                    m.bias.copy_((torch.rand(m.bias.shape, generator=generator, dtype=m.bias.dtype) * 2 - 1) * bound)
    return module


class NeuralODE(nn.Module):
    r"""A learned vector field :math:`f_{neural}(x, I, \theta)`, Eqs. (1) and (3).

    Called as ``f(t, x)`` (the torchdiffeq convention; autonomous, ``t`` is
    ignored) with ``x`` of shape ``(batch, n)``; returns ``dx/dt`` of the same
    shape. With ``n_input > 0`` the external input ``I`` is concatenated to
    the state: call :meth:`vector_field` with ``u`` of shape ``(batch, m)``.

    Parameters
    ----------
    n_state : int
        State dimension n.
    hidden : sequence of int
        Hidden widths; the paper's spiral model is ``(50, 50)``.
    activation : str
        One of ``ACTIVATIONS``.
    n_input : int
        External input dimension m (0 for autonomous systems).
    """

    def __init__(self, n_state: int, hidden: Sequence[int], activation: str, n_input: int = 0) -> None:
        super().__init__()
        self.n_state = int(n_state)
        self.n_input = int(n_input)
        self.hidden = tuple(int(h) for h in hidden)
        self.activation = str(activation)
        self.net = mlp(self.n_state + self.n_input, self.n_state, self.hidden, self.activation)

    @property
    def config(self) -> dict[str, Any]:
        """Constructor arguments, enough to rebuild the model (used by checkpoints)."""
        return {"n_state": self.n_state, "hidden": list(self.hidden), "activation": self.activation,
                "n_input": self.n_input}

    def vector_field(self, x: Tensor, u: Tensor | None = None) -> Tensor:
        """f_neural(x, u): ``x`` (batch, n), ``u`` (batch, m) or None -> (batch, n)."""
        if x.shape[-1] != self.n_state:
            raise ValueError(f"x has state dimension {x.shape[-1]}, model expects {self.n_state}")
        if self.n_input:
            if u is None or u.shape[-1] != self.n_input:
                got = None if u is None else tuple(u.shape)
                raise ValueError(f"model expects an input u with {self.n_input} columns, got {got}")
            x = torch.cat([x, u], dim=-1)
        elif u is not None:
            raise ValueError("model was built with n_input=0 but an input u was given")
        return self.net(x)

    @property
    def n(self) -> int:
        """The state dimension (the same number as ``n_state``; ``n`` is the name the observers use)."""
        return self.n_state

    def forward(self, t: Tensor | float, x: Tensor, u: Tensor | None = None) -> Tensor:
        """``f(t, x)`` for torchdiffeq, or ``f(t, x, u)`` for a model with inputs (``n_input > 0``)."""
        return self.vector_field(x, u)
