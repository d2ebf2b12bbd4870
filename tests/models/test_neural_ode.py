"""The neural ODE vector field, Eq. (3): layer sizes, inputs, config."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from fnnlib import NeuralODE
from fnnlib.models import MODELS, mlp
from fnnlib.models import ACTIVATIONS


def _linear_sizes(net: nn.Module) -> list[tuple[int, int]]:
    return [(m.in_features, m.out_features) for m in net.modules() if isinstance(m, nn.Linear)]


def test_spiral_model_is_2_50_50_2():
    model = NeuralODE(2, hidden=(50, 50), activation="relu")
    assert _linear_sizes(model) == [(2, 50), (50, 50), (50, 2)]
    acts = [m for m in model.net if not isinstance(m, nn.Linear)]
    assert len(acts) == 2 and all(isinstance(a, nn.ReLU) for a in acts)  # no activation after the output layer
    assert isinstance(model.net[-1], nn.Linear)


def test_mlp_sizes_and_activation():
    net = mlp(6, 3, (36, 36, 36), "tanh")
    assert _linear_sizes(net) == [(6, 36), (36, 36), (36, 36), (36, 3)]
    assert sum(isinstance(m, nn.Tanh) for m in net) == 3
    assert _linear_sizes(mlp(2, 2, (), "relu")) == [(2, 2)]  # no hidden layer: one linear map


@pytest.mark.parametrize("name", sorted(ACTIVATIONS))
def test_every_activation_builds(name):
    net = mlp(2, 2, (4,), name)
    assert isinstance(net[1], ACTIVATIONS[name])


def test_unknown_activation():
    with pytest.raises(ValueError, match=r"unknown activation 'sigmoid'; choose one of \['elu', 'gelu'"):
        NeuralODE(2, (4,), activation="sigmoid")


@pytest.mark.parametrize("hidden", [(0,), (4, -1)])
def test_bad_layer_sizes(hidden):
    with pytest.raises(ValueError, match="layer sizes must be >= 1"):
        mlp(2, 2, hidden, "relu")


def test_forward_shape_and_autonomy():
    model = NeuralODE(2, (8,), "relu").double()
    x = torch.randn(5, 2, dtype=torch.float64)
    out = model(0.0, x)
    assert out.shape == (5, 2)
    assert torch.equal(out, model(torch.tensor(3.0), x))  # t is ignored


def test_wrong_state_dimension():
    with pytest.raises(ValueError, match="x has state dimension 3, model expects 2"):
        NeuralODE(2, (4,), "relu")(0.0, torch.zeros(1, 3))


def test_input_is_concatenated():
    model = NeuralODE(3, (5,), "relu", n_input=2)
    assert _linear_sizes(model)[0] == (5, 5)
    out = model.vector_field(torch.zeros(4, 3), torch.ones(4, 2))
    assert out.shape == (4, 3)


def test_missing_input():
    with pytest.raises(ValueError, match=r"model expects an input u with 2 columns, got None"):
        NeuralODE(3, (5,), "relu", n_input=2).vector_field(torch.zeros(4, 3))


def test_wrong_input_width():
    with pytest.raises(ValueError, match=r"model expects an input u with 2 columns, got \(4, 1\)"):
        NeuralODE(3, (5,), "relu", n_input=2).vector_field(torch.zeros(4, 3), torch.zeros(4, 1))


def test_forward_refuses_a_model_with_inputs():
    # forward(t, x) is for autonomous models; a model with inputs needs vector_field(x, u)
    with pytest.raises(ValueError, match="expects an input u"):
        NeuralODE(3, (5,), "relu", n_input=2)(0.0, torch.zeros(4, 3))


def test_unexpected_input():
    with pytest.raises(ValueError, match="built with n_input=0 but an input u was given"):
        NeuralODE(2, (4,), "relu").vector_field(torch.zeros(1, 2), torch.zeros(1, 1))


def test_config_round_trip():
    torch.manual_seed(1)
    model = NeuralODE(3, (7, 5), "softplus", n_input=1)
    cfg = model.config
    assert cfg == {"n_state": 3, "hidden": [7, 5], "activation": "softplus", "n_input": 1}
    clone = MODELS["NeuralODE"](**cfg)
    assert clone.config == cfg
    clone.load_state_dict(model.state_dict())
    x, u = torch.randn(4, 3), torch.randn(4, 1)
    assert torch.equal(clone.vector_field(x, u), model.vector_field(x, u))


def test_architecture_is_required():
    with pytest.raises(TypeError):
        NeuralODE(2)  # no silent paper architecture
    with pytest.raises(TypeError):
        mlp(2, 2, (4,))
