"""Every observer fits the one interface, and a comparison is a loop over them on a tiny problem."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib import LinearFeedback, add_measurement_noise, cascade_predict, rollout_predict
from fnnlib.seeding import make_generator
from fnnlib.systems import Spiral
from fnnlib.feedback import Estimate, Gains
from fnnlib.observers import (
    Covariances,
    ExtendedKalmanObserver,
    KalmanObserver,
    LuenbergerObserver,
    Observer,
    evaluate_observer,
    metrics_table,
    rollout_corrected,
)

F64 = torch.float64
TS, T, N = 0.01, 60, 5
MODEL = Spiral(2.0, 0.1, 0.0)  # stands in for the learned field
Q, R = [1e-8, 1e-8, 1e-2, 1e-2], 1e-4
#: the observers of :func:`_observers`, by name: written out, so that collecting the tests makes none (a Luenberger
#: observer imports python-control, ~1 s in every pytest-xdist worker)
NAMES = ("linear feedback", "luenberger", "kalman", "kalman_ss", "ekf")


def _observers() -> dict[str, Observer]:
    return {
        "linear feedback": LinearFeedback(MODEL, TS, gains=Gains(20.0, 0.02), n=2),
        "luenberger": LuenbergerObserver(MODEL, TS, n=2, poles=[0.5, 0.5, 0.8, 0.8]),
        "kalman": KalmanObserver(MODEL, TS, n=2, cov=Covariances(Q, R)),
        "kalman_ss": KalmanObserver(MODEL, TS, n=2, cov=Covariances(Q, R), steady_state=True),
        "ekf": ExtendedKalmanObserver(MODEL, TS, n=2, cov=Covariances(Q, R)),
    }


@pytest.fixture(scope="module")
def problem():
    t = torch.arange(T, dtype=F64) * TS
    system = Spiral(3.0, 0.05, 10.0)
    x = system.simulate(torch.tensor([9.0, 0.0]), t)
    return x, add_measurement_noise(x, 0.01, make_generator(0)), system.rate(x)


def test_the_names_are_the_observers() -> None:
    assert tuple(_observers()) == NAMES


@pytest.mark.parametrize("name", NAMES)
def test_observer_satisfies_the_interface(name, problem):
    obs = _observers()[name]
    assert isinstance(obs, Observer)
    _, y, _ = problem
    est = obs.observe(y)
    assert isinstance(est, Estimate)
    assert est.x_hat.shape == est.f_hat.shape == y.shape and est.x_hat.dtype == y.dtype
    z = obs.predict(y, N)
    assert z.shape == y.shape and bool(torch.isfinite(z).all())


def test_comparison_is_a_loop(problem):
    x, y, f = problem
    reports = {name: evaluate_observer(obs, y, (x, f), N, settle=10, repeats=1) for name, obs in _observers().items()}
    keys = {"state_rmse", "rate_rmse", "state_rmse_settled", "rate_rmse_settled", "err_N_mean", "us_per_step",
            "us_per_start"}
    for name, rep in reports.items():
        assert set(rep.metrics) == keys, name
        assert all(math.isfinite(v) and v >= 0 for v in rep.metrics.values()), (name, rep.metrics)
        assert rep.z_N.shape == y.shape
    # every observer corrects the model: its change-rate error is far below the open-loop one
    open_loop = float((MODEL.rate(y) - f).norm(dim=-1).pow(2).mean().sqrt())
    assert all(r.metrics["rate_rmse_settled"] < 0.2 * open_loop for r in reports.values())
    table = metrics_table({name: r.metrics for name, r in reports.items()})
    assert table.count("\n") == len(reports) + 1 and "| ekf |" in table


def test_linear_feedback_predicts_by_the_cascade(problem):
    _, y, _ = problem
    fb = LinearFeedback(MODEL, TS, gains=Gains(20.0, 0.02), n=2)
    torch.testing.assert_close(fb.predict(y, N), cascade_predict(MODEL, y, TS, N, Gains(20.0, 0.02)), rtol=0, atol=0)


def test_rollout_with_no_disturbance_is_the_euler_rollout(problem):
    x, _, _ = problem
    torch.testing.assert_close(rollout_corrected(MODEL, x, torch.zeros_like(x), TS, N),
                               rollout_predict(MODEL, x, TS, N), rtol=0, atol=1e-12)


def test_bad_calls_are_refused(problem):
    x, y, f = problem
    with pytest.raises(TypeError, match="Observer interface"):
        evaluate_observer(object(), y, (x, f), N)
    with pytest.raises(ValueError, match=r"need y \(T, p\) and x_true, f_true \(T, n\)"):
        evaluate_observer(_observers()["luenberger"], y, (x[:-1], f), N)
    with pytest.raises(ValueError, match="1 <= N < T"):
        evaluate_observer(_observers()["luenberger"], y, (x, f), T)
    with pytest.raises(ValueError, match="settle"):
        evaluate_observer(_observers()["luenberger"], y, (x, f), N, settle=T)
    with pytest.raises(ValueError, match="same shape|differ in shape"):
        rollout_corrected(MODEL, x, torch.zeros(2), TS, N)
    with pytest.raises(ValueError, match="beta"):
        LinearFeedback(MODEL, TS, gains=Gains(20.0, -0.1), n=2)
