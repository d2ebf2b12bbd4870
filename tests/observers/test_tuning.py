"""The Kalman filter's disturbance process noise from training trajectories (not the true test residual)."""

from __future__ import annotations

import pytest
import torch

from fnnlib.observers.tuning import disturbance_drift_variance


def test_recovers_the_random_walk_variance_of_the_filters_own_plant() -> None:
    """Data made by the filter's plant x_{k+1} = x_k + Ts (f(x_k) + d_k), d a random walk: q_d is its step variance."""
    g = torch.Generator().manual_seed(0)
    Ts, q, B, T, n = 0.01, 0.04, 4, 500, 2
    A = torch.tensor([[-0.1, 2.0], [-2.0, -0.1]], dtype=torch.float64)

    def field(t: float, x: torch.Tensor) -> torch.Tensor:
        return x @ A.T

    w = q ** 0.5 * torch.randn(B, T - 1, n, generator=g, dtype=torch.float64)
    d = torch.cumsum(w, dim=1) + 1.0
    x = torch.empty(B, T, n, dtype=torch.float64)
    x[:, 0] = torch.randn(B, n, generator=g, dtype=torch.float64)
    for k in range(T - 1):
        x[:, k + 1] = x[:, k] + Ts * (field(0.0, x[:, k]) + d[:, k])
    got = disturbance_drift_variance(x, Ts, field)
    assert got == pytest.approx(float(w[:, 1:].std() ** 2), rel=1e-6)  # exactly the drawn steps' variance
    assert got == pytest.approx(q, rel=0.05)
    # a constant disturbance does not drift
    x_const = torch.empty(T, n, dtype=torch.float64)
    x_const[0] = 1.0
    for k in range(T - 1):
        x_const[k + 1] = x_const[k] + Ts * (field(0.0, x_const[k]) + 3.0)
    assert disturbance_drift_variance(x_const, Ts, field) < 1e-16


def test_bad_input_is_refused() -> None:
    def field(t: float, x: torch.Tensor) -> torch.Tensor:
        return torch.zeros_like(x)

    with pytest.raises(ValueError, match="T >= 3"):
        disturbance_drift_variance(torch.zeros(2, 2), 0.01, field)
    with pytest.raises(ValueError, match="NaN"):
        disturbance_drift_variance(torch.full((5, 2), float("nan")), 0.01, field)
    with pytest.raises(ValueError, match="Ts"):
        disturbance_drift_variance(torch.zeros(5, 2), -0.01, field)


def test_uneven_times_give_the_variance_per_nominal_step() -> None:
    """A random walk whose step variance is q c_k / Ts over random intervals: the variance per nominal step is q;
    times on the uniform grid give the Ts answer."""
    g = torch.Generator().manual_seed(1)
    Ts, q, B, T, n = 2.0 ** -7, 0.04, 4, 600, 2
    A = torch.tensor([[-0.1, 2.0], [-2.0, -0.1]], dtype=torch.float64)

    def field(t: float, x: torch.Tensor) -> torch.Tensor:
        return x @ A.T

    dt = Ts * (0.4 + 1.2 * torch.rand(B, T - 1, generator=g, dtype=torch.float64))
    t = torch.cat([torch.zeros(B, 1, dtype=torch.float64), dt.cumsum(-1)], -1)
    c = 0.5 * (dt[:, :-1] + dt[:, 1:])
    w = (q * c / Ts).sqrt()[..., None] * torch.randn(B, T - 2, n, generator=g, dtype=torch.float64)
    d = torch.cat([torch.ones(B, 1, n, dtype=torch.float64), 1.0 + torch.cumsum(w, dim=1)], 1)
    x = torch.empty(B, T, n, dtype=torch.float64)
    x[:, 0] = torch.randn(B, n, generator=g, dtype=torch.float64)
    for k in range(T - 1):
        x[:, k + 1] = x[:, k] + dt[:, k, None] * (field(0.0, x[:, k]) + d[:, k])
    got = disturbance_drift_variance(x, Ts, field, t=t)
    assert got == pytest.approx(float((w / (c / Ts).sqrt()[..., None]).std() ** 2), rel=1e-6)
    assert got == pytest.approx(q, rel=0.05)
    grid = torch.arange(T, dtype=torch.float64) * Ts
    assert disturbance_drift_variance(x, Ts, field, t=grid) == pytest.approx(disturbance_drift_variance(x, Ts, field),
                                                                               rel=1e-12)
    with pytest.raises(ValueError, match="strictly increasing"):
        disturbance_drift_variance(x, Ts, field, t=grid.flip(0))
