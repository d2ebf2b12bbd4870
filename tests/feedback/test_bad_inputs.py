"""Every bad input a trial met gets a clear error before any work (the model is never called)."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.feedback import DEFAULT_TUNE_RECIPE
from fnnlib.metrics import n_step_errors
from fnnlib.systems import LinearSystem

from tests.feedback.test_inputs import A, B, F64, TS

C = torch.tensor([[1.0, 0.0]], dtype=F64)
T = 40


class CountingPlant(LinearSystem):
    """The linear plant, counting its calls: a check 'before any work' leaves the count at 0."""

    calls = 0

    def __call__(self, t, x, u):
        CountingPlant.calls += 1
        return super().__call__(t, x, u)


@pytest.fixture
def plant():
    CountingPlant.calls = 0
    return CountingPlant(A, B)


def _gain():
    return F.place_observer_gain(torch.eye(2, dtype=F64) + TS * A, TS * C, [0.6, 0.7])


def _check_no_work():
    assert CountingPlant.calls == 0


def test_inputs_rows_off_are_refused_before_the_loop(plant):
    y, u_short = torch.zeros(T, 1, dtype=F64), torch.zeros(T - 6, 1, dtype=F64)
    ekf = F.ExtendedKalmanObserver(plant, TS, n=2, cov=F.Covariances([1e-6] * 3, 1e-4), C=C, disturbance=[1], A=A)
    ukf = F.UnscentedKalmanObserver(plant, TS, n=2, cov=F.Covariances([1e-6] * 3, 1e-4), C=C, disturbance=[1], A=A)
    mf = F.MeasuredFeedback(plant, TS, L=_gain(), measurement=F.Measurement(C=C), A=A)
    CountingPlant.calls = 0
    for call in (lambda: ekf.predict(y, 5, u_short), lambda: ukf.observe(y, u_short), lambda: mf.predict(y, 5, u_short),
                 lambda: F.cascade_predict(plant, y, TS, 5, F.Gains(1.0), u=u_short, observer=mf),
                 lambda: F.rollout_predict(plant, torch.zeros(T, 2, dtype=F64), TS, 3, u=u_short),
                 lambda: F.tune_gains(plant, torch.zeros(T, 2, dtype=F64), TS, 3, u=u_short, recipe=DEFAULT_TUNE_RECIPE)):
        with pytest.raises(ValueError, match=r"inputs u have 34 rows but .* has 40 samples: give one input row per sample"):
            call()
    _check_no_work()


def test_transposed_C_is_named(plant):
    with pytest.raises(ValueError, match=r"C has shape \(2, 1\) .*looks transposed: pass C.T"):
        F.MeasuredFeedback(plant, TS, L=_gain(), measurement=F.Measurement(C=C.T), A=A)
    with pytest.raises(ValueError, match=r"looks transposed"):
        F.ExtendedKalmanObserver(plant, TS, n=2, cov=F.Covariances(1e-6, 1e-4), C=C.T)
    _check_no_work()


def test_dtype_errors_are_clear(plant):
    net = F.NeuralODE(2, (8,), "tanh")  # float32 parameters
    x64 = torch.zeros(T, 2, dtype=F64)
    with pytest.raises(TypeError, match=r"model's parameters are torch.float32 but the states are torch.float64"):
        F.rollout_predict(net, x64, TS, 3)
    ekf = F.ExtendedKalmanObserver(net, TS, n=2, cov=F.Covariances(1e-6, 1e-4))
    with pytest.raises(TypeError, match=r"model's parameters are torch.float32"):
        ekf.predict(x64, 3)
    with pytest.raises(TypeError, match=r"inputs u are torch.float32 but y is torch.float64"):
        F.MeasuredFeedback(plant, TS, L=_gain(), measurement=F.Measurement(C=C), A=A).observe(torch.zeros(T, 1, dtype=F64),
                                                                                     torch.zeros(T, 1))
    with pytest.raises(TypeError, match="must be a floating-point tensor"):
        F.cascade_predict(plant, torch.zeros(T, 2, dtype=torch.int64), TS, 3, F.Gains(1.0))


def test_nan_truth_in_n_step_errors_is_refused():
    truth = torch.zeros(T, 2, dtype=F64)
    truth[20, 0] = float("nan")
    with pytest.raises(ValueError, match="truth holds a NaN or infinite value among the scored samples"):
        n_step_errors(torch.zeros(T, 2, dtype=F64), truth, 5)


def test_a_callable_measurement_with_the_wrong_output_and_an_inf_sample(plant):
    with pytest.raises(ValueError, match=r"h\(x\) must map \(batch, n = 2\) to \(batch, p = 1\)"):
        F.check_measurements(torch.zeros(T, 1, dtype=F64), 2, C=lambda x: x)
    y = torch.zeros(T, 1, dtype=F64)
    y[3] = float("inf")
    with pytest.raises(ValueError, match=r"y holds an infinite value \(first at index \(3, 0\)\)"):
        F.MeasuredFeedback(plant, TS, L=_gain(), measurement=F.Measurement(C=C), A=A).observe(y)
    u = torch.zeros(T, 1, dtype=F64)
    u[5] = float("nan")
    with pytest.raises(ValueError, match="inputs u hold a NaN or infinite value .*cannot be missing"):
        F.MeasuredFeedback(plant, TS, L=_gain(), measurement=F.Measurement(C=C), A=A).observe(torch.zeros(T, 1, dtype=F64),
                                                                                     u)
    _check_no_work()


def test_kalman_and_luenberger_refuse_gaps_with_a_pointer():
    f = LinearSystem(A, B)
    x = torch.zeros(T, 2, dtype=F64)
    with pytest.raises(NotImplementedError, match="for gaps use ExtendedKalmanObserver, UnscentedKalmanObserver"):
        F.KalmanObserver(lambda t, z: z @ A.T, TS, n=2, cov=F.Covariances(1e-6, 1e-4)).predict(x, 3, mask=torch.ones(T, dtype=torch.bool))
    del f
