"""Seeding: the same seed gives the same numbers."""

from __future__ import annotations

import contextlib
import random
from collections.abc import Iterator

import numpy as np
import torch


def seed_everything(seed: int) -> torch.Generator:
    """Seed Python, NumPy and torch's global generators; return a fresh torch generator.

    Network initialisation uses torch's global generator, so call this before
    building a model. Functions that draw random numbers themselves (noise,
    mini-batches) take the returned generator or their own ``seed``.
    """
    seed = int(seed)
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    return make_generator(seed)


def make_generator(seed: int) -> torch.Generator:
    """A CPU ``torch.Generator`` seeded with ``seed``."""
    g = torch.Generator()
    g.manual_seed(int(seed))
    return g


@contextlib.contextmanager
def seeded(seed: int) -> Iterator[None]:
    """Within the block, Python's, NumPy's and torch's global generators start from ``seed``; after it, each is
    back where it was. The library builds its networks from a given seed this way (torch's layers draw their
    initial weights from the global generator), so that building one leaves the caller's random state alone."""
    py, nps, ts = random.getstate(), np.random.get_state(), torch.random.get_rng_state()
    try:
        seed_everything(seed)
        yield
    finally:
        random.setstate(py)
        np.random.set_state(nps)
        torch.random.set_rng_state(ts)
