"""Switched systems against piecewise closed forms, the right-continuous field, and bad inputs."""

from __future__ import annotations

import pytest
import torch
from torchdiffeq import odeint

from fnnlib.systems import Spiral
from fnnlib.systems import SwitchedSystem

F64 = torch.float64
A, B, C = Spiral(3.0, 0.05, 10.0), Spiral(1.0, 0.12, 5.0), Spiral(2.0, 0.3, -4.0)


def piecewise_exact(systems, switches, x0, t):
    """Chain the spirals' closed forms: each piece starts from the state at its switch time."""
    x0 = torch.as_tensor(x0, dtype=F64)
    bounds = [float(t[0])] + [s for s in switches if float(t[0]) < s < float(t[-1])]
    active = [int(sum(s <= b for s in switches)) for b in bounds]
    out = torch.empty(*x0.shape[:-1], t.numel(), 2, dtype=F64)
    for j, (start, sys_j) in enumerate(zip(bounds, active)):
        stop = bounds[j + 1] if j + 1 < len(bounds) else float("inf")
        mask = (t >= start) & (t < stop) if j + 1 < len(bounds) else (t >= start)
        times = torch.cat([torch.tensor([start], dtype=F64), t[mask]])
        sol = systems[sys_j].exact_solution(x0, times)
        out[..., mask, :] = sol[..., 1:, :]
        if j + 1 < len(bounds):
            x0 = systems[sys_j].exact_solution(x0, torch.tensor([start, stop], dtype=F64))[..., -1, :]
    return out


@pytest.mark.parametrize("switches", [[0.73], [0.7], [0.305, 0.307]], ids=["off_grid", "on_grid", "two_in_one_step"])
def test_simulate_matches_piecewise_closed_form(switches):
    systems = [A, B, C][: len(switches) + 1]
    sw = SwitchedSystem(systems, switches)
    t = torch.arange(121, dtype=F64) * 0.01
    x0 = torch.tensor([9.0, 0.0], dtype=F64)
    sim = sw.simulate(x0, t)
    ref = piecewise_exact(systems, switches, x0, t)
    assert sim.shape == (121, 2) and sim.dtype == F64
    # dopri5 at rtol = atol = 1e-10 over 1.2 s on O(10) states; 1e-7 leaves a wide margin
    torch.testing.assert_close(sim, ref, rtol=0, atol=1e-7)


def test_simulate_batched_initial_states():
    sw = SwitchedSystem([A, B], [0.45])
    t = torch.arange(61, dtype=F64) * 0.01
    x0 = torch.tensor([[[9.0, 0.0], [1.0, 2.0]], [[0.0, 0.0], [-3.0, 4.0]]], dtype=F64)
    sim = sw.simulate(x0, t)
    assert sim.shape == (2, 2, 61, 2)
    for i in range(2):
        for j in range(2):
            # the batch shares dopri5's step control, so single runs differ at the 1e-10 tolerance
            torch.testing.assert_close(sim[i, j], sw.simulate(x0[i, j], t), rtol=0, atol=1e-8)


def test_switch_outside_the_grid_leaves_one_system():
    t = torch.arange(51, dtype=F64) * 0.01
    x0 = torch.tensor([9.0, 0.0], dtype=F64)
    torch.testing.assert_close(SwitchedSystem([A, B], [5.0]).simulate(x0, t), A.exact_solution(x0, t),
                               rtol=0, atol=1e-8)
    torch.testing.assert_close(SwitchedSystem([A, B], [-1.0]).simulate(x0, t), B.exact_solution(x0, t),
                               rtol=0, atol=1e-8)


def test_state_is_continuous_and_rate_jumps_at_the_switch():
    sw = SwitchedSystem([A, B], [0.5])
    t = torch.arange(101, dtype=F64) * 0.01
    x = sw.simulate(torch.tensor([9.0, 0.0], dtype=F64), t)
    steps = (x[1:] - x[:-1]).norm(dim=-1)
    assert float(steps.max()) < 0.01 * 60  # |x'| <= ~60 here: no jump in the state
    rate = sw.rate(t, x)
    torch.testing.assert_close(rate[:50], A.rate(x[:50]), rtol=0, atol=1e-12)
    torch.testing.assert_close(rate[50:], B.rate(x[50:]), rtol=0, atol=1e-12)  # t = 0.5 is already B's


def test_call_with_scalar_and_per_row_times():
    sw = SwitchedSystem([A, B, C], [1.0, 2.0])
    x = torch.randn(4, 2, dtype=F64, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(sw(0.99, x), A(0.0, x))
    torch.testing.assert_close(sw(1.0, x), B(0.0, x))
    torch.testing.assert_close(sw(torch.tensor(5.0), x), C(0.0, x))
    rows = sw(torch.tensor([0.0, 1.5, 2.0, -3.0], dtype=F64), x)
    expected = torch.stack([A(0.0, x[:1])[0], B(0.0, x[1:2])[0], C(0.0, x[2:3])[0], A(0.0, x[3:])[0]])
    torch.testing.assert_close(rows, expected)
    assert sw.index(torch.tensor([0.5, 1.0, 1.7, 2.5])).tolist() == [0, 1, 1, 2]


def test_field_drives_odeint_too():
    """The field is a plain f(t, x): an adaptive solver across the jump lands near the piecewise answer."""
    sw = SwitchedSystem([A, B], [0.4])
    t = torch.tensor([0.0, 0.8], dtype=F64)
    x0 = torch.tensor([[9.0, 0.0]], dtype=F64)
    through = odeint(sw, x0, t, rtol=1e-10, atol=1e-10)[-1, 0]
    torch.testing.assert_close(through, sw.simulate(x0[0], t)[-1], rtol=0, atol=1e-6)


@pytest.mark.parametrize("systems, switches, match", [
    ([A, B], [], "one more system than switch times"),
    ([A, B, C], [2.0, 1.0], "strictly increasing"),
    ([A, B, C], [1.0, 1.0], "strictly increasing"),
    ([A, B], [float("nan")], "finite"),
])
def test_bad_construction(systems, switches, match):
    with pytest.raises(ValueError, match=match):
        SwitchedSystem(systems, switches)


def test_systems_of_different_dimension():
    class ThreeD(Spiral):
        n = 3

    with pytest.raises(ValueError, match="share the state dimension"):
        SwitchedSystem([A, ThreeD(2.0, 0.1, 0.0)], [1.0])


def test_bad_simulate_and_rate_inputs():
    sw = SwitchedSystem([A, B], [0.5])
    with pytest.raises(ValueError, match="state dimension 3"):
        sw.simulate(torch.zeros(3), torch.linspace(0, 1, 5))
    with pytest.raises(ValueError, match="strictly increasing"):
        sw.simulate(torch.zeros(2), torch.tensor([0.0, 0.2, 0.1]))
    with pytest.raises(ValueError, match="x0 holds a NaN"):
        sw.simulate(torch.tensor([float("nan"), 0.0]), torch.linspace(0, 1, 5))
    with pytest.raises(ValueError, match=r"times t must have shape \(5,\)"):
        sw.rate(torch.zeros(4), torch.zeros(5, 2, dtype=F64))
    with pytest.raises(ValueError, match=r"per-row times must have shape \(3,\)"):
        sw(torch.zeros(2), torch.zeros(3, 2, dtype=F64))
