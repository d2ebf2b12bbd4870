"""train_neural_ode on uneven sample times: each segment along its own intervals."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.training import QUICK_RECIPE

F64 = torch.float64
A = torch.tensor([[0.0, 1.0], [-1.0, -0.2]], dtype=F64)


class Linear(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.W = torch.nn.Parameter(torch.zeros(2, 2, dtype=F64))

    def forward(self, t, x):
        return x @ self.W.T


def _records(seed=0, B=3, T=60):
    g = torch.Generator().manual_seed(seed)
    t = torch.cumsum(0.05 + 0.15 * torch.rand(B, T, generator=g, dtype=F64), -1)
    x0 = torch.randn(B, 2, generator=g, dtype=F64)
    xs = [x0]
    for k in range(T - 1):
        Phi = torch.linalg.matrix_exp(A * (t[:, k + 1] - t[:, k])[:, None, None])
        xs.append((Phi @ xs[-1][..., None])[..., 0])
    return t, torch.stack(xs, 1)


def test_a_linear_field_is_learned_from_uneven_times():
    t, x = _records()
    model = Linear()
    recipe = QUICK_RECIPE.replace(iterations=300, batch_size=16, batch_time=6, lr=0.05, optimizer="adam")
    F.train_neural_ode(model, t, x, recipe, seed=0, progress=False)
    torch.testing.assert_close(model.W.detach(), A, rtol=0, atol=0.05)


def test_uneven_times_are_checked():
    t, x = _records()
    with pytest.raises(ValueError, match="strictly increasing"):
        F.train_neural_ode(Linear(), t.flip(-1), x, QUICK_RECIPE, seed=0, progress=False)
    with pytest.raises(ValueError, match="points but x has"):
        F.train_neural_ode(Linear(), t[:, :-1], x, QUICK_RECIPE, seed=0, progress=False)
