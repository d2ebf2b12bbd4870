"""Measurement noise: scale, reproducibility, stacked draws, bad settings."""

from __future__ import annotations

import pytest
import torch

from fnnlib import add_measurement_noise
from fnnlib.models import split_members
from fnnlib.seeding import make_generator
from fnnlib.systems import add_member_noise


def test_draws_stack_independent_copies():
    x = torch.zeros(50, 2, dtype=torch.float64)
    y = add_measurement_noise(x, 0.5, make_generator(0), draws=3)
    assert y.shape == (3, 50, 2)
    assert not torch.equal(y[0], y[1])
    assert 0.3 < float(y.std()) < 0.7
    again = add_measurement_noise(x, 0.5, make_generator(0), draws=3)
    assert torch.equal(y, again)
    w = torch.randn((3, 50, 2), generator=make_generator(0), dtype=torch.float64)
    assert torch.equal(y, x + 0.5 * w)  # one draw of shape (draws, ...): the order of the random numbers


def test_zero_std_copies_and_bad_settings():
    x = torch.ones(4, 2)
    assert torch.equal(add_measurement_noise(x, 0.0, draws=2), x.expand(2, 4, 2))
    with pytest.raises(ValueError, match="noise std"):
        add_measurement_noise(x, -1.0)
    with pytest.raises(ValueError, match="noise draws"):
        add_measurement_noise(x, 0.1, draws=0)


def test_add_member_noise_gives_each_member_its_own_seeded_draw() -> None:
    import fnnlib as F
    x = torch.randn(50, 2)
    z = add_member_noise(x, 0.1, [make_generator(1), make_generator(2)], draws=3)
    assert z.shape == (3, 50, 4)
    parts = split_members(z, 2)
    for e, s in enumerate([1, 2]):
        assert torch.equal(parts[e], F.add_measurement_noise(x, 0.1, make_generator(s), draws=3))
    assert not torch.equal(parts[0], parts[1])
    with pytest.raises(ValueError, match="one generator per ensemble member"):
        add_member_noise(x, 0.1, [])
