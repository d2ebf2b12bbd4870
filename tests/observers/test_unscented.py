"""The UKF (filterpy) beside the EKF: equal on a linear plant, inputs, gaps, partial measurements, and
evaluate_observer on a partially measured system."""

from __future__ import annotations

import torch

import fnnlib as F
from fnnlib.observers import evaluate_observer
from fnnlib.systems import LinearSystem

from tests.feedback.test_inputs import A, B, F64, TS
from tests.feedback.test_inputs import _euler_data as _euler

C = torch.tensor([[1.0, 0.0]], dtype=F64)
T = 100
PLANT = LinearSystem(A, B)


def _data():
    u = torch.cos(1.1 * torch.arange(T, dtype=F64) * TS)[:, None]
    return _euler(torch.tensor([0.5, 1.0], dtype=F64), u), u


def _filters():
    kw = dict(C=C, disturbance=[1], A=A)
    return (F.ExtendedKalmanObserver(PLANT, TS, n=2, cov=F.Covariances([1e-8] * 3, 1e-4), **kw),
            F.UnscentedKalmanObserver(PLANT, TS, n=2, cov=F.Covariances([1e-8] * 3, 1e-4), **kw))


def test_ukf_equals_the_ekf_on_a_linear_plant_with_inputs_and_gaps():
    x, u = _data()
    y = x @ C.T
    y[30:50] = float("nan")
    ekf, ukf = _filters()
    a, b = ekf.estimate(y, u), ukf.estimate(y, u)
    assert bool(torch.isfinite(b.x_hat).all())
    torch.testing.assert_close(a.x_hat, b.x_hat, rtol=0, atol=1e-9)  # a linear plant: both are the Kalman filter
    torch.testing.assert_close(a.d_hat, b.d_hat, rtol=0, atol=1e-9)
    # through the gap the filtered estimate is the model's Euler rollout (no update)
    z = b.x_hat[29]
    for k in range(29, 49):
        z = z + TS * (A @ z + B @ u[k] + b.d_hat[29])
    torch.testing.assert_close(b.x_hat[49], z, rtol=0, atol=1e-9)


def test_evaluate_observer_scores_a_partially_measured_system():
    x, u = _data()
    y = x @ C.T + 0.001 * torch.randn(T, 1, generator=torch.Generator().manual_seed(0), dtype=F64)
    f_true = PLANT.rate(0.0, x, u)
    _, ukf = _filters()
    report = evaluate_observer(ukf, y, (x, f_true), 5, settle=40, repeats=1, u=u)
    assert report.z_N.shape == (T, 2)
    assert report.metrics["state_rmse_settled"] < 0.01 and report.metrics["err_N_mean"] < 0.05
