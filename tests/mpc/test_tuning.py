"""Issue 16: baseline gains chosen on validation flights from the training distribution, never on the test flight."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fnnlib.mpc.flight import FlightResult, lissajous_reference
from fnnlib.mpc.tuning import select_gain_on_validation, validation_references
from fnnlib.quadrotor_presets import PAPER_FLIGHT_DATA, PAPER_LISSAJOUS, PAPER_TS
from fnnlib.systems.quadrotor import NOMINAL

N, STEPS = 10, 30
DATA = {k: PAPER_FLIGHT_DATA[k] for k in ("n_waypoints", "box", "max_speed")}


def refs_for(n: int, seed: int) -> list:
    return validation_references(n, STEPS, N, seed=seed, Ts=PAPER_TS, params=NOMINAL, **DATA)


def fake_flight(offset: float, x_r: torch.Tensor, n_fallbacks: int = 0) -> FlightResult:
    """A flight that tracks x_r with a constant position error ``offset`` on every axis."""
    T = STEPS
    x_ref = x_r[:T + 1].numpy()
    x = x_ref.copy()
    x[:, :3] += offset
    z12, z4 = np.zeros((T, 12)), np.zeros((T, 4))
    return FlightResult(name="fake", x=x, u=z4, x_ref=x_ref, xdot_true=z12, xdot_pred=z12, x_tilde=z12, delta=z12,
                        t_linearize=np.zeros(T), t_solve=np.zeros(T), Ts=PAPER_TS, n_fallbacks=n_fallbacks,
                        fallback_reasons={"not_optimal": n_fallbacks} if n_fallbacks else {})


@pytest.fixture(scope="module")
def refs() -> list:
    return refs_for(3, 1234)


def test_validation_references_come_from_the_training_distribution(refs) -> None:
    assert len(refs) == 3
    x_lissajous, _ = lissajous_reference(STEPS, N, Ts=PAPER_TS, params=NOMINAL, curve=PAPER_LISSAJOUS)
    for x_r, u_r in refs:
        assert x_r.shape == (STEPS + N + 1, 12) and u_r.shape == (STEPS + N, 4) and x_r.dtype == torch.float64
        # rest to rest through waypoints in the training box ((-3, 3), (-3, 3), (-2, 2)), speed <= 10 m/s
        assert torch.abs(x_r[0, 3:6]).max() < 1e-9 and torch.abs(x_r[-1, 3:6]).max() < 1e-9
        assert (torch.abs(x_r[:, :2]) <= 3.0 + 1e-9).all() and (torch.abs(x_r[:, 2]) <= 2.0 + 1e-9).all()
        assert torch.linalg.norm(x_r[:, 3:6], dim=1).max() <= 10.0
        assert torch.isfinite(u_r).all()
        assert not torch.allclose(x_r, x_lissajous)
    again = refs_for(3, 1234)
    assert all(torch.equal(a[0], b[0]) for a, b in zip(refs, again))
    assert not torch.equal(refs_for(1, 99)[0][0], refs[0][0])


def test_the_gain_with_the_lowest_validation_rmse_is_chosen_and_diverged_gains_never(refs) -> None:
    seen = []
    error = {0.04: 0.3, 0.16: 0.1, 0.64: 0.2, 2.56: 0.01}  # 2.56 tracks best but diverges (fallbacks)

    def fly_fn(gain: float, x_r: torch.Tensor, u_r: torch.Tensor) -> FlightResult:
        seen.append((gain, x_r))
        return fake_flight(error[gain], x_r, n_fallbacks=STEPS // 2 if gain == 2.56 else 0)

    sel = select_gain_on_validation(fly_fn, list(error), refs)
    assert sel.value == 0.16
    assert len(seen) == len(error) * len(refs)  # every gain on every validation flight
    assert all(any(torch.equal(x, r[0]) for r in refs) for _, x in seen)
    assert sel.table[0.16]["rmse"] == pytest.approx(0.1) and sel.table[0.04]["rmse"] == pytest.approx(0.3)
    assert sel.table[2.56]["diverged"] and math.isinf(sel.table[2.56]["rmse"])
    assert sel.table[2.56]["fallback_share"] == 0.5
    assert sel.table[2.56]["fallback_reasons"] == {"not_optimal": STEPS // 2 * len(refs)}
    assert sel.table[0.16]["fallback_reasons"] == {}
    # parsimony: the smallest gain within (1 + rtol) of the best 0.1 (0.04 at 0.3 is within 3.5x, not 2.5x)
    assert select_gain_on_validation(fly_fn, list(error), refs, rtol=1.5).value == 0.16
    assert select_gain_on_validation(fly_fn, list(error), refs, rtol=2.5).value == 0.04
    with pytest.raises(ValueError, match="rtol"):
        select_gain_on_validation(fly_fn, list(error), refs, rtol=-0.1)


def test_a_flight_that_fly_refuses_counts_as_diverged(refs) -> None:
    def fly_fn(gain: float, x_r: torch.Tensor, u_r: torch.Tensor) -> FlightResult:
        if gain > 1:
            raise ValueError("the flight has left the model's domain")
        return fake_flight(0.2, x_r)

    sel = select_gain_on_validation(fly_fn, [0.5, 8.0], refs)
    assert sel.value == 0.5 and sel.table[8.0]["diverged"] and "left the model's domain" in sel.table[8.0]["error"]
    with pytest.raises(ValueError, match="every gain diverged"):
        select_gain_on_validation(fly_fn, [8.0], refs)


@pytest.mark.parametrize(("grid", "match"), [([], "empty"), ([0.1, -1.0], "finite and > 0"),
                                             ([0.1, math.nan], "finite and > 0"), ([0.1, 0.1], "repeats")])
def test_bad_grid_is_refused_before_any_flight(grid: list, match: str, refs) -> None:
    def fly_fn(*args: object) -> FlightResult:
        raise AssertionError("no flight may start")

    with pytest.raises(ValueError, match=match):
        select_gain_on_validation(fly_fn, grid, refs)
    with pytest.raises(ValueError, match="validation"):
        select_gain_on_validation(fly_fn, [0.1], [])
