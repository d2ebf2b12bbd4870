"""choose_gain: a gain is kept only where its improvement over the reference beats the spread over windows."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import fnnlib as F


def _errors(shift: float, noise: float, T: int = 400, seed: int = 0) -> torch.Tensor:
    """Two candidates: the reference (row 0) and one better by ``shift`` on average, both with window-level noise."""
    gen = torch.Generator().manual_seed(seed)
    base = 1.0 + 0.05 * torch.randn(T, generator=gen, dtype=torch.float64)
    other = base - shift + noise * torch.randn(T, generator=gen, dtype=torch.float64).cumsum(0) / math.sqrt(T)
    return torch.stack([base, other])


def test_a_clear_improvement_is_kept() -> None:
    c = F.choose_gain(_errors(shift=0.2, noise=0.01))
    assert (c.index, c.best, c.windows) == (1, 1, 8) and c.improvement > 2 * c.se
    assert c.improvement == pytest.approx(0.2, abs=0.02)


def test_an_improvement_within_the_spread_falls_back_to_the_reference() -> None:
    e = _errors(shift=0.0, noise=0.0)
    e[1, :200] -= 0.3   # better on the first half, worse on the second: a lower mean, no consistent win
    e[1, 200:] += 0.28
    c = F.choose_gain(e)
    assert c.best == 1 and c.index == 0 and 0 < c.improvement < 2 * c.se


def test_the_reference_is_kept_when_it_is_best_and_z_zero_is_the_plain_argmin() -> None:
    e = _errors(shift=-0.1, noise=0.0)   # the other candidate is worse everywhere
    assert F.choose_gain(e).index == 0 and F.choose_gain(e, z=0.0).index == 0
    e = _errors(shift=0.0, noise=0.0)
    e[1, :200] -= 0.3
    e[1, 200:] += 0.28    # a lower mean, not beyond the spread: the argmin with z = 0 only
    assert F.choose_gain(e, z=0.0).index == 1 and F.choose_gain(e).index == 0


def test_missing_targets_are_left_out_and_records_pool_their_windows() -> None:
    e = _errors(shift=0.2, noise=0.01)
    e[:, ::3] = float("nan")
    c = F.choose_gain(torch.stack([e, e], 1))   # (K, B, T): two records, 8 windows each
    assert c.index == 1 and c.windows == 16


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.floats(-0.3, 0.3), st.floats(0.0, 0.5), st.floats(0.0, 3.0))
def test_what_is_kept_is_the_best_beyond_z_spreads_or_the_reference(seed: int, shift: float, noise: float,
                                                                   z: float) -> None:
    e = _errors(shift=shift, noise=noise, seed=seed)
    c = F.choose_gain(e, z=z)
    assert c.best == min(range(len(c.means)), key=c.means.__getitem__)  # at float64: means may differ by 1e-13
    assert c.index == (c.best if c.improvement > z * c.se and c.best != 0 else 0)
    worse = e[:1] + abs(shift) + 1e-3    # worse than the reference at every start time
    assert F.choose_gain(torch.cat([e[:1], worse]), z=z).index == 0


@pytest.mark.parametrize("kwargs, match", [
    (dict(errors=torch.ones(2, 5), windows=8), "windows"),
    (dict(errors=torch.ones(2, 50), reference=2), "reference"),
    (dict(errors=torch.ones(2, 50), z=-1.0), "z must be"),
    (dict(errors=torch.ones(2, 2, 3, 4)), "shape"),
    (dict(errors=torch.full((2, 50), float("nan"))), "finite"),
    (dict(errors=torch.tensor([[1.0] * 49 + [math.inf]] * 2)), "finite"),
])
def test_bad_inputs_are_refused(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        F.choose_gain(**kwargs)
