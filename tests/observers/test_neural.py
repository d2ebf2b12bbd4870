"""The neural feedback observer: interface, the recursion of Eqs. (7)-(8), the wavefront cascade."""

import pytest
import torch

from fnnlib.models import NeuralFeedback, NeuralODE
from fnnlib.observers import Observer, NeuralFeedbackObserver
from fnnlib.feedback import rollout_predict

TS = 0.05


def _nets(seed=0):
    torch.manual_seed(seed)
    return NeuralODE(2, (16,), "tanh").double(), NeuralFeedback(2, (16,), "tanh").double()


def _traj(B=(), T=30):
    t = torch.arange(T, dtype=torch.float64) * TS
    x = torch.stack([torch.cos(2 * t), -torch.sin(2 * t)], -1)
    return x + 0.1 * torch.randn(*B, T, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(1))


class Zero(torch.nn.Module):
    def forward(self, e):
        return torch.zeros_like(e)


def test_interface_and_shapes():
    f, h = _nets()
    obs = NeuralFeedbackObserver(f, TS, h=h, n=2)
    assert isinstance(obs, Observer)
    x = _traj((3, 2))
    est = obs.observe(x)
    assert est.x_hat.shape == est.f_hat.shape == x.shape
    assert obs.predict(x, 4).shape == x.shape


def test_observe_is_the_recursion():
    f, h = _nets()
    x = _traj()
    est = NeuralFeedbackObserver(f, TS, h=h, n=2).observe(x)
    x_hat = x[0].clone()
    with torch.no_grad():
        for k in range(x.shape[0]):
            f_hat = f(0.0, x[k:k + 1])[0] + h((x[k] - x_hat)[None])[0]  # Eq. (7), neural form
            torch.testing.assert_close(est.x_hat[k], x_hat, rtol=0, atol=1e-12)
            torch.testing.assert_close(est.f_hat[k], f_hat, rtol=0, atol=1e-12)
            x_hat = x_hat + TS * f_hat  # Eq. (8)


@pytest.mark.parametrize("T,N,beta", [(30, 5, 0.0), (6, 9, 0.1), (12, 1, 0.0), (1, 3, 0.0)])
def test_wavefront_cascade_equals_double_loop(T, N, beta):
    f, h = _nets()
    obs = NeuralFeedbackObserver(f, TS, h=h, n=2, beta=beta)
    x = _traj(T=T)
    torch.testing.assert_close(obs.predict(x, N), obs.predict_loop(x, N), rtol=0, atol=1e-6)


def test_batched_cascade_equals_per_trajectory():
    f, h = _nets()
    obs = NeuralFeedbackObserver(f, TS, h=h, n=2)
    x = _traj((2, 3))
    z = obs.predict(x, 6)
    for a in range(2):
        for b in range(3):
            torch.testing.assert_close(z[a, b], obs.predict_loop(x[a, b], 6), rtol=0, atol=1e-6)


def test_zero_feedback_is_the_euler_rollout():
    f, _ = _nets()
    x = _traj((2,))
    obs = NeuralFeedbackObserver(f, TS, h=Zero(), n=2)
    torch.testing.assert_close(obs.predict(x, 7), rollout_predict(f, x, TS, 7), rtol=0, atol=1e-10)
    with torch.no_grad():
        torch.testing.assert_close(obs.observe(x).f_hat, f(0.0, x.reshape(-1, 2)).reshape(x.shape))


def test_bad_inputs():
    f, h = _nets()
    with pytest.raises(ValueError, match="Ts"):
        NeuralFeedbackObserver(f, 0.0, h=h, n=2)
    with pytest.raises(ValueError, match="beta"):
        NeuralFeedbackObserver(f, TS, h=h, n=2, beta=-1.0)
    with pytest.raises(ValueError, match="N must be"):
        NeuralFeedbackObserver(f, TS, h=h, n=2).predict(_traj(), 0)
