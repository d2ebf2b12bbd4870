"""KalmanObserver with C, a disturbance layout and gaps: against the linear recursion it must equal."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import fnnlib as F
from fnnlib.systems import LinearSystem
from fnnlib.feedback.measurement import DetectabilityError

from tests.feedback.test_inputs import A, B, F64, TS
from tests.feedback.test_inputs import _euler_data as _euler

C = torch.tensor([[1.0, 0.0]], dtype=F64)  # position only
PLANT = LinearSystem(A, B)
T = 120


def _data(d=0.3):
    u = torch.sin(0.7 * torch.arange(T, dtype=F64) * TS)[:, None]
    return _euler(torch.tensor([1.0, -0.5], dtype=F64), u + d), u  # a constant disturbance d on the velocity


def _kf():
    return F.KalmanObserver(PLANT, TS, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), C=C, disturbance=[1], A=A,
                            steady_state=True)


def _linear_recursion(kf, y, u, present):
    """z_{k|k} = z_{k|k-1} + K m_k (y_k - C z_{k|k-1}); z_{k+1|k} = Phi z_{k|k} + [Ts B u_k; 0] (the linear plant)."""
    Phi, K, Cz = kf._linearised(A).numpy(), np.asarray(kf.stationary.K), kf.C.numpy()
    Bz = np.vstack([TS * B.numpy(), np.zeros((1, 1))])
    prior = np.concatenate([np.linalg.pinv(Cz[:, :2]) @ y[0].numpy(), [0.0]])
    out = []
    for k in range(T):
        z = prior + K @ ((y[k].numpy() - Cz @ prior) * present[k])
        out.append(z)
        prior = Phi @ z + Bz @ u[k].numpy()
    return np.array(out)


def test_output_kalman_equals_the_linear_recursion_and_finds_the_disturbance():
    x, u = _data()
    y = x @ C.T
    kf = _kf()
    est = kf.estimate(y, u)
    ref = _linear_recursion(kf, y, u, np.ones((T, 1)))
    np.testing.assert_allclose(est.x_hat.numpy(), ref[:, :2], rtol=0, atol=1e-10)
    assert abs(float(est.d_hat[-1, 1]) - 0.3) < 1e-2 and float(est.d_hat[-1, 0]) == 0.0  # E d on the velocity only
    assert float((est.x_hat[-20:] - x[-20:]).abs().max()) < 1e-2


def test_a_gap_moves_the_estimate_open_loop_and_no_nan_reaches_it():
    x, u = _data()
    y = x @ C.T
    y[40:60] = float("nan")
    kf = _kf()
    est = kf.estimate(y, u)
    present = np.ones((T, 1))
    present[40:60] = 0.0
    assert bool(torch.isfinite(est.x_hat).all())
    ref = _linear_recursion(kf, torch.nan_to_num(y), u, present)
    np.testing.assert_allclose(est.x_hat.numpy(), ref[:, :2], rtol=0, atol=1e-10)
    mask = torch.ones(T, dtype=torch.bool)
    mask[40:60] = False
    torch.testing.assert_close(kf.observe(torch.nan_to_num(y), u, mask=mask).x_hat, est.x_hat, rtol=0, atol=0)
    assert kf.predict(y, 5, u).shape == (T, 2)


def test_undetectable_layouts_and_bad_settings_are_refused():
    with pytest.raises(DetectabilityError):  # a disturbance on both states, only the position measured
        F.KalmanObserver(PLANT, TS, n=2, cov=F.Covariances(1e-4, 1e-4), C=C, A=A, steady_state=True)
    with pytest.raises(ValueError, match="steady_state=True"):
        F.KalmanObserver(PLANT, TS, n=2, cov=F.Covariances(1e-4, 1e-4), C=C, disturbance=[1], A=A)
    with pytest.raises(ValueError, match="C has 1 rows"):
        _kf().estimate(torch.zeros(T, 2, dtype=F64), _data()[1])


def test_the_full_state_filter_is_unchanged():
    """No C, no layout: the Eq. (7) filter of before (evaluated at the measurement), gaps refused."""
    x, u = _data()
    kf = F.KalmanObserver(PLANT, TS, n=2, cov=F.Covariances(1e-4, 1e-4), steady_state=True)
    assert not kf.output_form and np.allclose(kf.stationary.K, F.observers.kalman.steady_state_gain(
        kf.A, kf.C, kf.Q, kf.R).K)
    with pytest.raises(NotImplementedError, match="needs every sample"):
        kf.observe(x, u, mask=torch.ones(T, dtype=torch.bool))


def test_output_luenberger_places_the_poles_of_the_linearised_model_and_tracks():
    poles = [0.7, 0.75, 0.8]
    obs = F.LuenbergerObserver(PLANT, TS, n=2, poles=poles, C=C, disturbance=[1], A=A)
    np.testing.assert_allclose(np.sort(obs.error_poles().real), poles, atol=1e-9)
    assert obs.L.shape == (3, 1)
    x, u = _data()
    y = x @ C.T
    est = obs.estimate(y, u)
    # the prior error e_{k+1|k} = (Phi - L C) e_{k|k-1} on the linear plant: gone after 120 steps (0.8^120 ~ 2e-12)
    assert float((est.x_hat[-1] - x[-1]).abs().max()) < 1e-8 and abs(float(est.d_hat[-1, 1]) - 0.3) < 1e-8
    y[50:70] = float("nan")
    assert bool(torch.isfinite(obs.estimate(y, u).x_hat).all())
    with pytest.raises(DetectabilityError):
        F.LuenbergerObserver(PLANT, TS, n=2, poles=[0.7, 0.75, 0.8, 0.85], C=C, A=A)
    with pytest.raises(ValueError, match=r"observer gain L must have shape \(3, 1\)"):
        F.LuenbergerObserver.with_gain(PLANT, TS, n=2, L=torch.zeros(4, 2), C=C, disturbance=[1], A=A)
