"""The two-tank plant: Torricelli's equilibrium, the rims, and the overflow into the lower tank."""

from __future__ import annotations

import pytest
import torch

from fnnlib.systems.tanks import CascadedTanks


def test_equilibrium_is_torricellis() -> None:
    p = CascadedTanks()
    u = torch.tensor([[3.0]], dtype=torch.float64)
    x1 = (p.k4 * 3.0 / p.k1) ** 2  # k1 sqrt(x1) = k4 u
    x2 = (p.k2 / p.k3) ** 2 * x1    # k3 sqrt(x2) = k2 sqrt(x1)
    x = torch.tensor([[x1, x2]], dtype=torch.float64)
    assert torch.allclose(p(0.0, x, u), torch.zeros(1, 2, dtype=torch.float64), atol=1e-12)


def test_levels_stay_below_the_rim_and_the_overflow_reaches_the_lower_tank() -> None:
    full = torch.tensor([[10.0, 5.0]], dtype=torch.float64)
    big = torch.tensor([[6.5]], dtype=torch.float64)
    for k5, more in ((0.0, False), (0.5, True)):
        p = CascadedTanks(k5=k5)
        dx = p(0.0, full, big)
        assert dx[0, 0] == 0.0  # the upper tank cannot rise past its rim
        base = p.k2 * 10 ** 0.5 - p.k3 * 5 ** 0.5
        assert (dx[0, 1] > base + 1e-6) == more
    t = torch.arange(200, dtype=torch.float64) * 4.0
    x = CascadedTanks().simulate(torch.tensor([[9.0, 9.0]], dtype=torch.float64), t, big.expand(1, 200, 1), substeps=4)
    # RK4 steps over the rim by at most a few mV before the field stops the level (the sensor clamps y)
    assert float(x.max()) <= 10.0 + 1e-2 and float(CascadedTanks().measure(x).max()) <= 10.0


@pytest.mark.parametrize(("kwargs", "match"), [({"k1": 0.0}, "k1"), ({"k5": 1.5}, "k5"), ({"h_max": -1.0}, "h_max")])
def test_bad_coefficients_are_refused(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        CascadedTanks(**kwargs)
