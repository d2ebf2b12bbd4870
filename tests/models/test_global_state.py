"""Building a model from seeds leaves the caller's random state where it was (randomness from what is passed in)."""

from __future__ import annotations

import random

import numpy as np
import pytest
import torch

import fnnlib as F
from fnnlib.models import NeuralFeedbackEnsemble
from fnnlib.seeding import seed_everything
from fnnlib.models.scaled import ScaledField
from fnnlib.seeding import seeded


def _states():
    return random.getstate(), np.random.get_state()[1].copy(), torch.random.get_rng_state().clone()


def _same(a, b) -> bool:
    return a[0] == b[0] and np.array_equal(a[1], b[1]) and torch.equal(a[2], b[2])


@pytest.mark.parametrize("build", [
    lambda: F.NeuralODEEnsemble(2, (8, 8), "tanh", [0, 1, 2]),
    lambda: NeuralFeedbackEnsemble(2, (8,), "tanh", [3, 4]),
    lambda: ScaledField(2, 1, (8,), "tanh", [0, 1]),
])
def test_building_an_ensemble_leaves_the_global_generators_untouched(build) -> None:
    torch.manual_seed(123)
    np.random.seed(7)
    random.seed(9)
    before = _states()
    build()
    assert _same(before, _states())


def test_seeded_members_are_what_their_seed_gives_and_the_block_restores_state() -> None:
    torch.manual_seed(5)
    before = _states()
    with seeded(1):
        inside = torch.rand(3)
    assert _same(before, _states())
    seed_everything(1)
    assert torch.equal(inside, torch.rand(3))
    ens = F.NeuralODEEnsemble(2, (8,), "tanh", [1, 2])
    seed_everything(2)
    member = F.NeuralODE(2, (8,), "tanh")
    assert torch.equal(ens.member(1).net[0].weight, member.net[0].weight)
