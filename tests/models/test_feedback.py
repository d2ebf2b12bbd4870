"""The neural feedback part h_neural (Sec. 4): shape, config, checkpoint round trip."""

import pytest
import torch

from fnnlib.models import MODELS, NeuralFeedback
from fnnlib.training import load_checkpoint, save_checkpoint


def test_architecture_is_the_papers():
    h = NeuralFeedback(2, (50, 50), "relu")
    linears = [m for m in h.net if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(2, 50), (50, 50), (50, 2)]
    assert sum(isinstance(m, torch.nn.ReLU) for m in h.net) == 2
    assert h(torch.zeros(7, 2)).shape == (7, 2)


def test_checkpoint_round_trip(tmp_path):
    assert MODELS["NeuralFeedback"] is NeuralFeedback
    h = NeuralFeedback(3, hidden=(8,), activation="tanh").double()
    save_checkpoint(tmp_path / "h.pt", h, {"seed": 1})
    h2, meta = load_checkpoint(tmp_path / "h.pt", expected_kind="NeuralFeedback")
    e = torch.randn(5, 3, dtype=torch.float64)
    assert torch.equal(h(e), h2(e)) and meta == {"seed": 1} and h2.config == h.config


def test_bad_input_dimension():
    with pytest.raises(ValueError, match="feedback expects 2"):
        NeuralFeedback(2, (50, 50), "relu")(torch.zeros(4, 3))
