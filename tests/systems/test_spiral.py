"""The spiral Eq. (26) against its closed form, and the measurement-noise helper."""

from __future__ import annotations

import pytest
import torch

from fnnlib import add_measurement_noise
from fnnlib.seeding import make_generator
from fnnlib.systems import Spiral

PARAMS = [dict(omega=2.0, eta=0.1, eps=0.0), dict(omega=3.0, eta=0.05, eps=10.0), dict(omega=0.8, eta=0.22, eps=-24.0)]


@pytest.mark.parametrize("params", PARAMS)
def test_simulate_matches_closed_form(params):
    spiral = Spiral(**params)
    x0 = torch.tensor([[9.0, 0.0], [1.0, -2.0], [0.0, 0.0]], dtype=torch.float64)
    t = torch.linspace(0.0, 5.0, 51, dtype=torch.float64)
    sim = spiral.simulate(x0, t)
    exact = spiral.exact_solution(x0, t)
    assert sim.shape == exact.shape == (3, 51, 2)
    assert sim.dtype == torch.float64
    # dopri5 at rtol = atol = 1e-10 over 5 s; states are O(10), so 1e-7 leaves a wide margin
    torch.testing.assert_close(sim, exact, rtol=0, atol=1e-7)


def test_exact_solution_starts_at_x0_and_shifts_with_t0():
    spiral = Spiral(omega=2.0, eta=0.1, eps=1.0)
    x0 = torch.tensor([2.0, -1.0], dtype=torch.float64)
    t = torch.linspace(0.0, 3.0, 31, dtype=torch.float64)
    a = spiral.exact_solution(x0, t)
    b = spiral.exact_solution(x0, t + 7.0)  # autonomous: only t - t[0] matters
    torch.testing.assert_close(a[0], x0, rtol=0, atol=1e-14)
    torch.testing.assert_close(a, b, rtol=0, atol=1e-12)


def test_exact_solution_converges_to_equilibrium():
    spiral = Spiral(omega=2.0, eta=0.5, eps=1.0)
    x_star = -torch.linalg.solve(spiral.A, spiral.b)
    end = spiral.exact_solution(torch.tensor([5.0, 5.0]), torch.tensor([0.0, 60.0]))[-1]
    torch.testing.assert_close(end, x_star, rtol=0, atol=1e-10)  # e^{-0.5*60} ~ 1e-13
    torch.testing.assert_close(spiral(0.0, x_star[None]), torch.zeros(1, 2, dtype=torch.float64),
                               rtol=0, atol=1e-14)


def test_rate_is_A_x_plus_b():
    spiral = Spiral(omega=3.0, eta=0.05, eps=10.0)
    x = torch.randn(4, 10, 2, dtype=torch.float64, generator=make_generator(0))
    A = torch.tensor([[-0.05, 3.0], [-3.0, -0.05]], dtype=torch.float64)
    b = torch.tensor([10.0, 10.0], dtype=torch.float64)
    expected = torch.einsum("ij,...j->...i", A, x) + b
    torch.testing.assert_close(spiral.rate(x), expected, rtol=0, atol=1e-13)
    torch.testing.assert_close(spiral(0.0, x[0]), expected[0], rtol=0, atol=1e-13)


def test_rate_keeps_float32():
    x = torch.ones(5, 2, dtype=torch.float32)
    assert Spiral(2.0, 0.1, 0.0)(0.0, x).dtype == torch.float32


def test_with_params_changes_a_copy():
    base = Spiral(omega=2.0, eta=0.1, eps=0.0)
    other = base.with_params(omega=3.0, eps=10.0)
    assert (other.omega, other.eta, other.eps) == (3.0, 0.1, 10.0)
    assert (base.omega, base.eta, base.eps) == (2.0, 0.1, 0.0)


def test_with_params_rejects_unknown_names():
    with pytest.raises(TypeError, match=r"unknown spiral parameter\(s\) \['period'\]"):
        Spiral(2.0, 0.1, 0.0).with_params(period=3.0)


def test_simulate_rejects_wrong_state_dimension():
    with pytest.raises(ValueError, match="x0 has state dimension 3, expected 2"):
        Spiral(2.0, 0.1, 0.0).simulate(torch.zeros(3), torch.linspace(0, 1, 5))


def test_simulate_rejects_nan():
    with pytest.raises(ValueError, match="x0 holds a NaN value"):
        Spiral(2.0, 0.1, 0.0).simulate(torch.tensor([float("nan"), 0.0]), torch.linspace(0, 1, 5))


def test_rate_rejects_bad_trajectory():
    with pytest.raises(ValueError, match="state dimension 3"):
        Spiral(2.0, 0.1, 0.0).rate(torch.zeros(4, 3))
    with pytest.raises(TypeError, match="must be a torch.Tensor"):
        Spiral(2.0, 0.1, 0.0).rate([[0.0, 0.0]])


# --- measurement noise -----------------------------------------------------------------------------------------

def test_noise_is_reproducible_with_a_seeded_generator():
    x = torch.zeros(3, 50, 2, dtype=torch.float64)
    a = add_measurement_noise(x, 0.1, make_generator(7))
    b = add_measurement_noise(x, 0.1, make_generator(7))
    c = add_measurement_noise(x, 0.1, make_generator(8))
    assert torch.equal(a, b)
    assert not torch.equal(a, c)
    assert a.shape == x.shape and a.dtype == x.dtype


def test_noise_std_zero_returns_a_clone():
    x = torch.randn(10, 2, generator=make_generator(0))
    y = add_measurement_noise(x, 0.0)
    assert torch.equal(x, y)
    y[0, 0] += 1.0
    assert not torch.equal(x, y)  # a copy, not a view


@pytest.mark.parametrize("std", [-0.1, float("inf"), float("nan")])
def test_noise_rejects_bad_std(std):
    with pytest.raises(ValueError, match="noise std must be finite and >= 0"):
        add_measurement_noise(torch.zeros(4, 2), std)


def test_noise_has_the_requested_std():
    x = torch.full((100_000, 2), 3.0, dtype=torch.float64)
    noise = add_measurement_noise(x, 0.3, make_generator(1)) - x
    # 2e5 samples: the std estimate's relative error is ~1/sqrt(4e5) = 0.16 %, the mean's ~0.3/450
    assert abs(float(noise.std()) / 0.3 - 1.0) < 0.01
    assert abs(float(noise.mean())) < 0.005


def test_parameters_are_required():
    with pytest.raises(TypeError):
        Spiral()  # no silent nominal spiral


def test_batched_spirals_run_spiral_p_on_row_p_for_every_copy():
    """Row p, copy e of the batched field is Eq. (26) of spiral p at that copy's state; a run of the batch is
    each spiral's own run (its closed form)."""
    from fnnlib.systems import BatchedSpirals

    spirals = [Spiral(**p) for p in PARAMS]
    batch = BatchedSpirals(spirals, 2)
    x = torch.randn(3, 4, dtype=torch.float64)
    dx = batch(0.0, x)
    for p, s in enumerate(spirals):
        for e in range(2):
            torch.testing.assert_close(dx[p, 2 * e:2 * e + 2], s(0.0, x[p:p + 1, 2 * e:2 * e + 2])[0])
    t = torch.linspace(0.0, 2.0, 21, dtype=torch.float64)
    x0 = torch.tensor([[9.0, 0.0, 1.0, -2.0]] * 3, dtype=torch.float64)
    run = batch.simulate(x0, t)  # (P, T, 4)
    for p, s in enumerate(spirals):
        torch.testing.assert_close(run[p, :, 2:], s.exact_solution(x0[p, 2:], t), rtol=0, atol=1e-7)
    with pytest.raises(ValueError, match="one batch row per spiral"):
        batch(0.0, x[:2])
