"""Partial measurements y = C x: the output gain L (n x p), its checks, and the observer against the truth."""

from __future__ import annotations

import pytest
import torch

from fnnlib import GainError, MeasuredFeedback, place_observer_gain
from fnnlib.observers import Covariances
from fnnlib.feedback import check_output_gain, Measurement
from fnnlib.systems import LinearSystem

from tests.feedback.test_inputs import A, B, F64, TS
from tests.feedback.test_inputs import _euler_data as _euler

C = torch.tensor([[1.0, 0.0]], dtype=F64)  # position only
T = 200


def _gain(poles=(0.6, 0.7)):
    """L with eig(I + Ts (A - L C)) = poles: placed on the pair (I + Ts A, Ts C)."""
    Ad = torch.eye(2, dtype=F64) + TS * A
    return place_observer_gain(Ad, TS * C, list(poles))


def test_estimate_converges_at_the_placed_rate_and_predicts_exactly():
    L = _gain()
    u = torch.sin(0.7 * torch.arange(T, dtype=F64) * TS)[:, None]
    x = _euler(torch.tensor([1.0, -2.0], dtype=F64), u)
    obs = MeasuredFeedback(LinearSystem(A, B), TS, L=L, measurement=Measurement(C=C, x0=torch.zeros(2, dtype=F64)),
                           A=A)
    est = obs.observe(x @ C.T, u)
    err = (est.x_hat - x).norm(dim=-1)
    assert float(err[0]) > 1.0 and float(err[60]) < 1e-6 * float(err[0])  # error poles 0.6, 0.7: 0.7^60 ~ 5e-10
    z = obs.predict(x @ C.T, 5, u)
    torch.testing.assert_close(z[80:-5], x[85:], rtol=0, atol=1e-8)


def test_batched_measurements():
    L = _gain()
    u = torch.zeros(2, 50, 1, dtype=F64)
    x = torch.stack([_euler(torch.tensor([1.0, 0.0], dtype=F64), u[0]), _euler(torch.tensor([0.0, 1.0], dtype=F64), u[1])])
    obs = MeasuredFeedback(LinearSystem(A, B), TS, L=L, measurement=Measurement(C=C), A=A)
    both = obs.observe(x @ C.T, u).x_hat
    torch.testing.assert_close(both[1], obs.observe(x[1] @ C.T, u[1]).x_hat, rtol=0, atol=1e-14)


def test_checks_name_what_fails():
    L = _gain()
    with pytest.raises(GainError, match=r"rho\(I - Ts L C\) = 1 >= 1 .*L C has rank 1 < n = 2.*pass the model's Jacobian"):
        check_output_gain(L, C, TS)
    with pytest.raises(GainError, match=r"rho\(I \+ Ts \(A - L C\)\) = .* >= 1"):
        check_output_gain(-L, C, TS, A=A)
    unstable = torch.tensor([[0.5, 0.0], [0.0, -1.0]], dtype=F64)  # mode e^{0.5 t} unmeasured by C = [0, 1]
    with pytest.raises(GainError, match="not detectable: the mode with eigenvalue 1.025"):
        check_output_gain(torch.tensor([[0.0], [1.0]]), torch.tensor([[0.0, 1.0]]), TS, A=unstable)
    with pytest.raises(ValueError, match=r"output gain L must have shape \(n, p\) = \(2, 1\)"):
        check_output_gain(torch.ones(2, 2), C, TS)
    full = check_output_gain(torch.eye(2) * 3.0, torch.eye(2), TS)[0]  # every state measured: no Jacobian needed
    torch.testing.assert_close(full, 3.0 * torch.eye(2, dtype=F64))


def test_ekf_takes_the_same_C_and_refuses_an_undetectable_disturbance_layout():
    from fnnlib import ExtendedKalmanObserver
    from fnnlib.feedback import DetectabilityError

    f = LinearSystem(A, torch.zeros(2, 1, dtype=F64))
    x = _euler(torch.tensor([1.0, -2.0], dtype=F64), torch.zeros(T, 1, dtype=F64))
    field = lambda t, z: f(t, z, torch.zeros(z.shape[0], 1, dtype=z.dtype))  # noqa: E731
    # a disturbance on both states with only the position measured: a velocity offset and a position
    # disturbance are indistinguishable ([C 0] does not observe the augmented state), refused with the PBH mode
    with pytest.raises(DetectabilityError, match=r"eigenvalue 1\+0j .*direction .*x1.*d0"):
        ExtendedKalmanObserver(field, TS, n=2, cov=Covariances([1e-10] * 4, 1e-8), C=C)
    ekf = ExtendedKalmanObserver(field, TS, n=2, cov=Covariances([1e-10] * 3, 1e-8), C=C, disturbance=[1])  # on the velocity only
    est = ekf.estimate(x @ C.T)
    assert float((est.x_hat[50:] - x[50:]).abs().max()) < 1e-6  # now the whole state
    z = ekf.predict(x @ C.T, 10)
    torch.testing.assert_close(z[50:-10], x[60:], rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match=r"C has shape \(1, 3\) but must be \(p, n\) with n = 2"):
        ExtendedKalmanObserver(f, TS, n=2, cov=Covariances(1e-4, 1e-4), C=torch.ones(1, 3))
