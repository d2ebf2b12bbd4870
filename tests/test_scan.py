"""The doubling scan h_{k+1} = A h_k + b_k against a plain Python loop."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fnnlib._scan import linear_recurrence


def loop_reference(A: torch.Tensor, b: torch.Tensor, h0: torch.Tensor) -> torch.Tensor:
    """h_0 = h0, h_{k+1} = A h_k + b_k, one step at a time (row vectors)."""
    h = [h0]
    for k in range(b.shape[-2]):
        Ah = h[-1] * A if A.ndim == 1 else h[-1] @ A.T
        h.append(Ah + b[..., k, :])
    return torch.stack(h, dim=-2)


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


@pytest.mark.parametrize("T", [1, 2, 3, 5, 8, 13, 16, 17, 100])
@pytest.mark.parametrize("kind", ["diagonal", "full"])
def test_matches_loop(T, kind):
    n = 3
    g = _gen(T)
    A = 0.9 * torch.rand(n, dtype=torch.float64, generator=g) if kind == "diagonal" else \
        0.3 * torch.randn(n, n, dtype=torch.float64, generator=g)
    b = torch.randn(T - 1, n, dtype=torch.float64, generator=g)
    h0 = torch.randn(n, dtype=torch.float64, generator=g)
    out = linear_recurrence(A, b, h0)
    assert out.shape == (T, n)
    torch.testing.assert_close(out, loop_reference(A, b, h0), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("kind", ["diagonal", "full"])
def test_batched_leading_dims(kind):
    n, T = 2, 11
    g = _gen(3)
    A = torch.tensor([0.5, -0.7], dtype=torch.float64) if kind == "diagonal" else \
        torch.tensor([[0.9, 0.2], [-0.3, 0.8]], dtype=torch.float64)
    b = torch.randn(2, 3, T - 1, n, dtype=torch.float64, generator=g)
    h0 = torch.randn(2, 3, n, dtype=torch.float64, generator=g)
    out = linear_recurrence(A, b, h0)
    assert out.shape == (2, 3, T, n)
    torch.testing.assert_close(out, loop_reference(A, b, h0), rtol=1e-12, atol=1e-12)
    for i in range(2):
        for j in range(3):
            torch.testing.assert_close(out[i, j], linear_recurrence(A, b[i, j], h0[i, j]), rtol=0, atol=1e-14)


def test_first_row_is_h0_and_zero_A_gives_inputs():
    b = torch.arange(12.0, dtype=torch.float64).reshape(6, 2)
    h0 = torch.tensor([5.0, -5.0], dtype=torch.float64)
    out = linear_recurrence(torch.zeros(2, dtype=torch.float64), b, h0)
    assert torch.equal(out[0], h0)
    assert torch.equal(out[1:], b)


def test_identity_A_is_cumulative_sum():
    b = torch.randn(20, 2, dtype=torch.float64, generator=_gen(5))
    h0 = torch.zeros(2, dtype=torch.float64)
    out = linear_recurrence(torch.eye(2, dtype=torch.float64), b, h0)
    torch.testing.assert_close(out[1:], torch.cumsum(b, dim=0), rtol=1e-12, atol=1e-12)


def test_long_contractive_run_does_not_overflow():
    # a closed form with A^{-k} would overflow here (0.5^-2000); the scan must not
    A = torch.tensor([0.5, 0.1], dtype=torch.float64)
    b = torch.ones(2000, 2, dtype=torch.float64)
    out = linear_recurrence(A, b, torch.zeros(2, dtype=torch.float64))
    assert bool(torch.isfinite(out).all())
    torch.testing.assert_close(out[-1], 1.0 / (1.0 - A), rtol=1e-12, atol=0)  # fixed point b/(1-a)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 4), T=st.integers(1, 70), seed=st.integers(0, 2**31 - 1),
       radius=st.floats(0.05, 0.99), full=st.booleans())
def test_property_random_contractive(n, T, seed, radius, full):
    g = _gen(seed)
    if full:
        M = torch.randn(n, n, dtype=torch.float64, generator=g)
        A = radius * M / torch.linalg.matrix_norm(M, 2)  # spectral norm = radius < 1
    else:
        A = radius * (2 * torch.rand(n, dtype=torch.float64, generator=g) - 1)
    b = torch.randn(2, T - 1, n, dtype=torch.float64, generator=g)
    h0 = torch.randn(2, n, dtype=torch.float64, generator=g)
    torch.testing.assert_close(linear_recurrence(A, b, h0), loop_reference(A, b, h0), rtol=1e-10, atol=1e-10)
