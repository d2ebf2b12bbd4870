"""Controlled systems: inputs u in the simulation, the cascade and the augmented observers, against closed forms."""

from __future__ import annotations

import pytest
import torch

from fnnlib import KalmanObserver, LinearFeedback, NeuralODE, cascade_predict
from fnnlib.observers import Covariances
from fnnlib.feedback import eval_field, Gains
from fnnlib.systems import LinearSystem, Pendulum
from fnnlib.feedback.layer import shift_inputs

F64 = torch.float64
A = torch.tensor([[0.0, 1.0], [-4.0, -0.4]], dtype=F64)
B = torch.tensor([[0.0], [1.0]], dtype=F64)
TS, T = 0.05, 120


def _inputs(T=T):
    t = torch.arange(T, dtype=F64) * TS
    return torch.stack([torch.sin(1.3 * t) + 0.5 * torch.cos(3.1 * t)], -1)


def _euler_data(x0, u):
    """x_{k+1} = x_k + Ts (A x_k + B u_k): data the cascade's own discretisation reproduces exactly."""
    xs = [x0]
    for k in range(u.shape[0] - 1):
        xs.append(xs[-1] + TS * (A @ xs[-1] + B @ u[k]))
    return torch.stack(xs)


def test_simulate_with_inputs_matches_the_zero_order_hold_closed_form():
    plant, u = LinearSystem(A, B), _inputs()
    x0 = torch.tensor([1.0, -0.5], dtype=F64)
    x = plant.simulate(x0, torch.arange(T, dtype=F64) * TS, u, substeps=10)
    Ad, Bd = plant.discretize(TS)
    exact = [x0]
    for k in range(T - 1):
        exact.append(Ad @ exact[-1] + Bd @ u[k])  # x_{k+1} = e^{A Ts} x_k + int e^{A s} ds B u_k
    torch.testing.assert_close(x, torch.stack(exact), rtol=0, atol=1e-9)  # RK4 at Ts/10: error ~ 1e-10


def test_simulate_batches_inputs_and_refuses_missing_ones():
    plant, u = LinearSystem(A, B), _inputs()
    t = torch.arange(T, dtype=F64) * TS
    x0 = torch.tensor([[1.0, 0.0], [0.0, 1.0]], dtype=F64)
    both = plant.simulate(x0, t, torch.stack([u, 2 * u]))
    torch.testing.assert_close(both[1], plant.simulate(x0[1], t, 2 * u), rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="is controlled .* give the inputs u"):
        plant.simulate(x0, t)
    with pytest.raises(ValueError, match=r"u must have shape \(\.\.\., 120, 1\)"):
        plant.simulate(x0, t, u[:-1])


@pytest.mark.parametrize("L", [0.0, 5.0, torch.tensor([[4.0, 1.0], [1.0, 6.0]])], ids=["open", "scalar", "full"])
def test_cascade_with_inputs_and_an_exact_model_equals_the_euler_closed_form(L):
    u = _inputs()
    x = _euler_data(torch.tensor([1.0, -0.5], dtype=F64), u)
    plant, N = LinearSystem(A, B), 7
    z = cascade_predict(plant, x, TS, N, Gains(L, 0.05), u=u)
    Ad = torch.eye(2, dtype=F64) + TS * A
    for k in (0, 13, T - N - 1):  # x_{k+N} = Ad^N x_k + sum_j Ad^{N-1-j} Ts B u_{k+j}
        ref = torch.linalg.matrix_power(Ad, N) @ x[k]
        for j in range(N):
            ref = ref + torch.linalg.matrix_power(Ad, N - 1 - j) @ (TS * B @ u[k + j])
        torch.testing.assert_close(z[k], ref, rtol=0, atol=1e-11)


def test_layer_i_uses_the_input_i_samples_ahead():
    u = _inputs()
    x = _euler_data(torch.tensor([1.0, -0.5], dtype=F64), u)
    z = cascade_predict(LinearSystem(A, B), x, TS, 5, Gains(2.0), u=u)
    torch.testing.assert_close(z[:-5], x[5:], rtol=0, atol=1e-11)  # every start, exact
    unshifted = cascade_predict(LinearSystem(A, B), x, TS, 1, Gains(2.0), u=u)  # one layer: u_k itself
    torch.testing.assert_close(unshifted[:-1], x[1:], rtol=0, atol=1e-12)
    assert torch.equal(shift_inputs(u, 3)[0], u[3]) and torch.equal(shift_inputs(u, 3)[-1], u[-1])


def test_kalman_with_inputs_predicts_exact_euler_data():
    u = _inputs()
    x = _euler_data(torch.tensor([1.0, -0.5], dtype=F64), u)
    kf = KalmanObserver(LinearSystem(A, B), TS, n=2, cov=Covariances([1e-8] * 2 + [1e-4] * 2, 1e-6),
                        steady_state=True)
    z = kf.predict(x, 6, u=u)
    torch.testing.assert_close(z[:-6], x[6:], rtol=0, atol=1e-6)  # d_hat stays ~0 on exact data


def test_neural_ode_with_inputs_and_the_pendulum_share_the_convention():
    model = NeuralODE(2, [8], "tanh", n_input=1).double()
    x, u = torch.randn(4, 10, 2, dtype=F64), torch.randn(4, 10, 1, dtype=F64)
    assert eval_field(model, x, u).shape == (4, 10, 2)
    assert model.n == model.n_state == 2
    pend = Pendulum(9.81, 0.1, 1.0, 0.5)
    rate = pend.rate(0.0, x, u)
    torch.testing.assert_close(rate[..., 1], -9.81 * torch.sin(x[..., 0]) - 0.1 * x[..., 1] + u[..., 0] + 0.5)


def test_bad_inputs_get_clear_errors():
    model = NeuralODE(2, [8], "tanh", n_input=1)
    x = torch.randn(10, 2)
    with pytest.raises(ValueError, match="inputs u have 9 samples but the states x have 10"):
        eval_field(model, x, torch.randn(9, 1))
    with pytest.raises(TypeError, match="inputs u are torch.float64 but the states x are torch.float32"):
        eval_field(model, x, torch.randn(10, 1, dtype=F64))
    with pytest.raises(TypeError, match=r"model's parameters are torch.float32 but the states are torch.float64.*x.to"):
        eval_field(model, x.double(), torch.randn(10, 1, dtype=F64))


def test_linear_feedback_takes_inputs():
    u = _inputs()
    x = _euler_data(torch.tensor([1.0, -0.5], dtype=F64), u)
    fb = LinearFeedback(LinearSystem(A, B), TS, gains=Gains(3.0, 0.1))
    est = fb.observe(x, u)
    torch.testing.assert_close(est.x_hat, x, rtol=0, atol=1e-12)  # exact model on its own Euler data: no error
    torch.testing.assert_close(fb.predict(x, 4, u), cascade_predict(LinearSystem(A, B), x, TS, 4, Gains(3.0, 0.1),
                                                                    u=u))
