"""Training from outputs with a free initial state per segment: a linear plant's hidden state is learned."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from fnnlib.training.segments import train_free_initial_states

C = torch.tensor([[0.0, 1.0]], dtype=torch.float64)


class Linear(nn.Module):
    def __init__(self, a: float) -> None:
        super().__init__()
        self.a = nn.Parameter(torch.tensor(a, dtype=torch.float64))

    def forward(self, t, x, u):  # upper tank drains into the lower one; the pump fills the upper one
        return torch.stack([-self.a * x[:, 0] + u[:, 0], self.a * x[:, 0] - 0.2 * x[:, 1]], -1)


def _record(T: int = 120, Ts: float = 0.5) -> tuple[torch.Tensor, torch.Tensor]:
    truth = Linear(0.3)
    u = (1 + torch.sin(0.2 * torch.arange(T, dtype=torch.float64)))[:, None]
    x = torch.zeros(T, 2, dtype=torch.float64)
    x[0] = torch.tensor([1.0, 0.5])
    with torch.no_grad():
        for k in range(T - 1):
            x[k + 1] = x[k] + Ts * truth(0.0, x[k:k + 1], u[k:k + 1])[0]
    return x @ C.T, u


def test_the_rate_and_the_hidden_initial_states_are_learned() -> None:
    y, u = _record()
    model = Linear(0.1)
    fit = train_free_initial_states(model, y, u, 0.5, C, horizon=20, iterations=400, lr=0.05)
    assert fit.loss[-1] < 1e-3 * fit.loss[0] and abs(float(model.a) - 0.3) < 0.02
    assert fit.starts == list(range(0, 101, 20)) and fit.x0.shape == (6, 2)
    torch.testing.assert_close(fit.x0[:, 1:], y[fit.starts], atol=0.1, rtol=0)  # loose: 400 Adam steps
    assert abs(float(fit.x0[0, 0]) - 1.0) < 0.3  # the hidden upper level of the first segment (truth 1.0)


@pytest.mark.parametrize(("kwargs", "match"), [({"horizon": 1}, "horizon"), ({"stride": 0}, "stride"),
                                               ({"iterations": 0}, "iterations"), ({"lr": 0.0}, "lr > 0")])
def test_bad_settings_are_refused(kwargs, match) -> None:
    y, u = _record(30)
    with pytest.raises(ValueError, match=match):
        train_free_initial_states(Linear(0.1), y, u, 0.5, C, **{"horizon": 5, **kwargs})
    y[3] = float("nan")
    with pytest.raises(ValueError, match="finite"):
        train_free_initial_states(Linear(0.1), y, u, 0.5, C, horizon=5)
