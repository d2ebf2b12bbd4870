"""Luenberger observer: placed poles are the eigenvalues of A - LC, the linear feedback is one, and bad inputs."""

from __future__ import annotations

import cmath

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fnnlib import LinearFeedback, add_measurement_noise
from fnnlib.feedback import Gains
from fnnlib.seeding import make_generator
from fnnlib.systems import Spiral
from fnnlib.observers import LuenbergerObserver, augmented_matrices, linear_feedback_gain, place_observer_gain

F64 = torch.float64
TS = 0.01


def _eig_error(A, L, C, poles) -> float:
    eig = np.linalg.eigvals(np.asarray(A) - np.asarray(L) @ np.asarray(C))
    return float(np.abs(np.sort_complex(eig) - np.sort_complex(np.asarray(poles, dtype=complex))).max())


# --- pole placement -----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("poles", [
    [0.5, 0.5, 0.8, 0.8],
    [0.0, 0.0, 0.8, 0.8],
    [0.1, 0.3, 0.6, 0.9],
    [0.7 * cmath.exp(0.4j), 0.7 * cmath.exp(-0.4j), 0.2, -0.5],
], ids=["repeated", "deadbeat_state", "distinct", "complex_pair"])
def test_augmented_poles_equal_the_requested_ones(poles):
    A, _, C = augmented_matrices(2, TS)
    obs = LuenbergerObserver(Spiral(2.0, 0.1, 0.0), TS, n=2, poles=poles)
    assert obs.L.shape == (4, 2)
    assert _eig_error(A, obs.L, C, poles) < 1e-9
    assert _eig_error(A, obs.L, C, obs.error_poles()) < 1e-12


def test_scalar_plant_gain_matches_the_characteristic_polynomial():
    # n = 1: A - LC = [[1 - l1, Ts], [-l2, 1]], char. poly z^2 - (2 - l1) z + (1 - l1 + Ts l2)
    p1, p2 = 0.3, 0.75
    l1 = 2 - (p1 + p2)
    l2 = (p1 * p2 - 1 + l1) / TS
    A, _, C = augmented_matrices(1, TS)
    L = place_observer_gain(A, C, [p1, p2])  # SISO: the gain is unique
    torch.testing.assert_close(L, torch.tensor([[l1], [l2]], dtype=F64), rtol=1e-10, atol=1e-10)


@settings(max_examples=25, deadline=None)
@given(r1=st.floats(-0.95, 0.95), r2=st.floats(-0.95, 0.95), mod=st.floats(0.05, 0.95),
       arg=st.floats(0.05, 3.0))
def test_property_random_stable_poles_are_placed(r1, r2, mod, arg):
    poles = [r1, r2, mod * cmath.exp(1j * arg), mod * cmath.exp(-1j * arg)]
    if min(abs(a - b) for i, a in enumerate(poles) for b in poles[i + 1:]) < 1e-3:
        return  # near-coincident poles: placement is ill-conditioned, not what this property is about
    A, _, C = augmented_matrices(2, TS)
    L = place_observer_gain(A, C, poles)
    assert _eig_error(A, L, C, poles) < 1e-7


def test_generic_observable_pair():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3))
    C = rng.normal(size=(1, 3))
    poles = [0.1, -0.2, 0.4]
    assert _eig_error(A, place_observer_gain(A, C, poles), C, poles) < 1e-9


# --- the linear feedback is a Luenberger observer ------------------------------------------------------------------

@pytest.mark.parametrize("L", [20.0, torch.tensor([[15.0, 4.0], [4.0, 30.0]], dtype=F64)], ids=["scalar", "full_spd"])
def test_linear_feedback_is_the_luenberger_observer_with_its_gain(L):
    t = torch.arange(200, dtype=F64) * TS
    x = Spiral(3.0, 0.05, 10.0).simulate(torch.tensor([9.0, 0.0]), t)
    y = add_measurement_noise(x, 0.01, make_generator(0))
    model = Spiral(2.0, 0.1, 0.0)  # a "learned" model with a large residual
    fb = LinearFeedback(model, TS, gains=Gains(L), n=2).observe(y)
    lu = LuenbergerObserver.with_gain(model, TS, n=2, L=linear_feedback_gain(L, TS, 2))
    est = lu.estimate(y)
    torch.testing.assert_close(est.f_hat, fb.f_hat, rtol=0, atol=1e-9)  # Eq. (7)'s f_hat
    torch.testing.assert_close(est.x_hat, y, rtol=0, atol=1e-9)  # deadbeat state part: x_hat_{k|k} = y_k
    torch.testing.assert_close(est.d_hat, fb.f_hat - model.rate(y), rtol=0, atol=1e-9)  # d_hat = L (y - x_hat)
    # error poles {0} and eig(I - Ts L), the matrix of Eq. (25)
    Lm = L * torch.eye(2, dtype=F64) if not isinstance(L, torch.Tensor) else L
    expected = np.concatenate([[0.0, 0.0], np.linalg.eigvals((torch.eye(2, dtype=F64) - TS * Lm).numpy())])
    assert float(np.abs(np.sort_complex(lu.error_poles()) - np.sort_complex(expected)).max()) < 1e-6


def test_place_finds_the_linear_feedback_gain():
    A, _, C = augmented_matrices(2, TS)
    torch.testing.assert_close(place_observer_gain(A, C, [0.0, 0.0, 0.8, 0.8]), linear_feedback_gain(20.0, TS, 2),
                               rtol=0, atol=1e-9)


def test_observer_converges_on_its_own_model():
    # data from the observer's own plant: x_{k+1} = x_k + Ts (f(x_k) + d), d constant, no noise
    model, d = Spiral(2.0, 0.1, 0.0), torch.tensor([3.0, -1.5], dtype=F64)
    xs = [torch.tensor([9.0, 0.0], dtype=F64)]
    for _ in range(299):
        xs.append(xs[-1] + TS * (model(0.0, xs[-1][None])[0] + d))
    est = LuenbergerObserver(model, TS, n=2, poles=[0.5, 0.5, 0.8, 0.8]).estimate(torch.stack(xs))
    err = (est.d_hat - d).norm(dim=-1)
    assert float(err[-1]) < 1e-9 * float(d.norm())  # 0.8^300 ~ 1e-29, up to a polynomial factor
    assert float(err[0]) > 0.5 * float(d.norm())  # it did start from d_hat = 0
    torch.testing.assert_close(est.f_hat[-50:], (model.rate(torch.stack(xs)) + d)[-50:], rtol=0, atol=1e-8)


def test_batched_estimate_equals_per_trajectory():
    x = Spiral(2.0, 0.1, 0.0).simulate(torch.randn(3, 2, dtype=F64, generator=torch.Generator().manual_seed(1)),
                          torch.arange(40, dtype=F64) * TS)
    obs = LuenbergerObserver(Spiral(2.0, 0.3, 0.0), TS, n=2, poles=[0.2, 0.2, 0.7, 0.7])
    est = obs.estimate(x)
    for i in range(3):
        one = obs.estimate(x[i])
        torch.testing.assert_close(est.d_hat[i], one.d_hat, rtol=0, atol=1e-12)
        torch.testing.assert_close(est.x_hat[i], one.x_hat, rtol=0, atol=1e-12)


# --- bad inputs ---------------------------------------------------------------------------------------------------

def test_unobservable_pair_is_refused():
    A = np.diag([0.5, 0.9])
    C = np.array([[1.0, 0.0]])  # the second mode is never seen
    with pytest.raises(ValueError, match="not observable"):
        place_observer_gain(A, C, [0.1, 0.2])


@pytest.mark.parametrize("poles, match", [
    ([0.5, 0.5, 0.8, 1.2], "unit disc"),
    ([0.5, 0.5, 0.8, -1.0], "unit disc"),
    ([0.5, 0.8, 0.8], "need 4 poles"),
    ([0.5, 0.5, 0.3 + 0.2j, 0.3 + 0.1j], "conjugate pairs"),
    ([0.5, 0.5, 0.5, 0.8], "at most rank"),
    ([0.5, 0.5, float("nan"), 0.8], "finite"),
], ids=["outside", "on_circle", "count", "not_conjugate", "repeated_3x", "nan"])
def test_bad_poles_are_refused(poles, match):
    with pytest.raises(ValueError, match=match):
        LuenbergerObserver(Spiral(2.0, 0.1, 0.0), TS, n=2, poles=poles)


def test_allow_unstable_places_poles_outside_the_disc():
    obs = LuenbergerObserver(Spiral(2.0, 0.1, 0.0), TS, n=2, poles=[0.5, 0.5, 0.8, 1.2], allow_unstable=True)
    assert float(np.abs(obs.error_poles()).max()) == pytest.approx(1.2)


def test_poles_or_a_ready_gain_each_by_its_own_constructor():
    with pytest.raises(TypeError, match="poles"):
        LuenbergerObserver(Spiral(2.0, 0.1, 0.0), TS, n=2)
    with pytest.raises(TypeError, match="unexpected keyword argument 'L'"):
        LuenbergerObserver(Spiral(2.0, 0.1, 0.0), TS, n=2, poles=[0.5, 0.5, 0.8, 0.8], L=linear_feedback_gain(20.0, TS, 2))


def test_bad_ready_gains_are_refused():
    with pytest.raises(ValueError, match="shape"):
        LuenbergerObserver.with_gain(Spiral(2.0, 0.1, 0.0), TS, n=2, L=torch.zeros(2, 2))
    with pytest.raises(ValueError, match="unstable"):
        LuenbergerObserver.with_gain(Spiral(2.0, 0.1, 0.0), TS, n=2, L=linear_feedback_gain(250.0, TS, 2))  # pole 1 - Ts L = -1.5
