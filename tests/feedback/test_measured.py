"""Partial measurements y = C x: the output gain L (n x p), its checks, and the observer against the truth."""

from __future__ import annotations

import pytest
import torch

from fnnlib import GainError, LinearSystem, MeasuredFeedback, check_output_gain, place_observer_gain

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
    obs = MeasuredFeedback(LinearSystem(A, B), L, C, TS, A=A)
    est = obs.observe(x @ C.T, u, x0=torch.zeros(2, dtype=F64))
    err = (est.x_hat - x).norm(dim=-1)
    assert float(err[0]) > 1.0 and float(err[60]) < 1e-6 * float(err[0])  # error poles 0.6, 0.7: 0.7^60 ~ 5e-10
    z = obs.predict(x @ C.T, 5, u, x0=torch.zeros(2, dtype=F64))
    torch.testing.assert_close(z[80:-5], x[85:], rtol=0, atol=1e-8)


def test_batched_measurements():
    L = _gain()
    u = torch.zeros(2, 50, 1, dtype=F64)
    x = torch.stack([_euler(torch.tensor([1.0, 0.0], dtype=F64), u[0]), _euler(torch.tensor([0.0, 1.0], dtype=F64), u[1])])
    obs = MeasuredFeedback(LinearSystem(A, B), L, C, TS, A=A)
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


def test_ekf_takes_the_same_C_and_predicts_the_measured_output():
    from fnnlib import ExtendedKalmanObserver

    f = LinearSystem(A, torch.zeros(2, 1, dtype=F64))
    x = _euler(torch.tensor([1.0, -2.0], dtype=F64), torch.zeros(T, 1, dtype=F64))
    ekf = ExtendedKalmanObserver(lambda t, z: f(t, z, torch.zeros(z.shape[0], 1, dtype=z.dtype)), TS, 2,
                                 [1e-10] * 2 + [1e-10] * 2, 1e-8, C=C)
    est = ekf.estimate(x @ C.T)
    assert float((est.x_hat[50:, 0] - x[50:, 0]).abs().max()) < 1e-8  # the measured position
    # with a constant-disturbance state and only the position measured, a velocity offset and a disturbance
    # are indistinguishable ([C 0] does not observe the augmented state), but the predicted outputs are exact
    z = ekf.predict(x @ C.T, 10)
    torch.testing.assert_close(z[50:-10] @ C.T, x[60:] @ C.T, rtol=0, atol=1e-8)
    with pytest.raises(ValueError, match=r"C must be a finite \(p, 2\) matrix"):
        ExtendedKalmanObserver(f, TS, 2, 1e-4, 1e-4, C=torch.ones(1, 3))
