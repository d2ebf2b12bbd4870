"""Thrown object with quadratic drag, and the least-squares drag fit."""

from __future__ import annotations

import pytest
import torch

from fnnlib.data import synthetic_throws
from fnnlib.systems.projectile import ThrownObject, fit_drag


def test_without_drag_the_throw_is_a_parabola() -> None:
    obj = ThrownObject(k=(0.0, 0.0, 0.0), g=9.81)
    x0 = torch.tensor([0.0, 0.0, 1.0, 2.0, 1.0, 4.0], dtype=torch.float64)
    t = torch.linspace(0.0, 0.6, 61, dtype=torch.float64)
    x = obj.simulate(x0, t)
    p = x0[:3] + t[:, None] * x0[3:] + 0.5 * t[:, None] ** 2 * torch.tensor([0.0, 0.0, -9.81], dtype=torch.float64)
    assert torch.allclose(x[:, :3], p, atol=1e-8)


def test_drag_decelerates_along_the_velocity() -> None:
    obj = ThrownObject(k=(-0.1, -0.1, -0.1), g=0.0)
    x = torch.tensor([[0.0, 0.0, 0.0, 3.0, 4.0, 0.0]], dtype=torch.float64)
    a = obj(0.0, x)[0, 3:]
    assert torch.allclose(a, -0.1 * 5.0 * torch.tensor([3.0, 4.0, 0.0], dtype=torch.float64))


def test_fit_recovers_the_coefficients_of_synthetic_throws() -> None:
    throws = synthetic_throws(4, 300, k=(-0.08, -0.05, -0.02), seed=1)
    fitted = fit_drag(throws.data[..., 6:9], throws.acc)
    assert torch.allclose(fitted.k, torch.tensor([-0.08, -0.05, -0.02], dtype=torch.float64), atol=1e-6)


def test_fit_refuses_bad_input() -> None:
    v = torch.ones(10, 3, dtype=torch.float64)
    with pytest.raises(ValueError, match="same shape"):
        fit_drag(v, torch.ones(9, 3, dtype=torch.float64))
    with pytest.raises(ValueError, match="NaN"):
        fit_drag(v, torch.full((10, 3), float("nan"), dtype=torch.float64))
