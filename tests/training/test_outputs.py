"""A neural ODE learned from measured outputs only (position of an oscillator, noise, 20 % lost samples): the
hidden state is recovered up to a change of coordinates, and starting each segment at the feedback estimate
beats the same architecture trained with free start states."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.training.outputs import OutputRecipe, free_run, train_from_outputs

F64 = torch.float64
TS, T, B = 0.1, 300, 4
A = torch.tensor([[0.0, 1.0], [-1.0, -0.3]], dtype=F64)
C = torch.tensor([[1.0, 0.0]], dtype=F64)


def _plant(x, u):
    acc = x @ A[1] + u[..., 0] - 0.2 * x[..., 0] ** 3  # a stiffening spring
    return torch.stack([x[..., 1], acc], -1)


@pytest.fixture(scope="module")
def records():
    g = torch.Generator().manual_seed(0)
    w = 0.5 * TS * (1 + torch.rand(B, 1, 1, generator=g, dtype=F64))
    u = 0.8 * torch.sin(torch.arange(2 * T, dtype=F64)[None, :, None] * w)
    xs = [torch.randn(B, 2, generator=g, dtype=F64)]
    for k in range(2 * T - 1):
        xs.append(xs[-1] + TS * _plant(xs[-1], u[:, k]))
    x = torch.stack(xs, 1)
    y = x @ C.T + 0.01 * torch.randn(B, 2 * T, 1, generator=g, dtype=F64)
    y[torch.rand(B, 2 * T, generator=g) < 0.2] = float("nan")
    return (y[:, :T], u[:, :T]), (y[:, T:], u[:, T:], x[:, T:])


def _gain():
    return F.place_observer_gain(torch.eye(2, dtype=F64) + TS * A, TS * C, [0.8, 0.85])  # from a rough model


def _fit(start, train):
    torch.manual_seed(1)
    model = F.NeuralODE(2, (16, 16), "tanh", n_input=1).double()
    recipe = OutputRecipe(start=start, iterations=150, lr=0.01, burn=20, horizon=40, batch=32,
                          L=tuple(map(tuple, _gain().tolist())), seed=0)
    train_from_outputs(model, train[0], C, recipe, Ts=TS, u=train[1], progress=False)
    return model


def _scores(model, test):
    y, u, x = test
    obs = F.MeasuredFeedback(model, TS, L=_gain(), measurement=F.Measurement(C=C), allow_unstable=True)
    sim = free_run(model, y, C, burn=20, Ts=TS, u=u, observer=obs)
    rmse = float((sim - (x @ C.T)[:, 20:]).pow(2).mean().sqrt())
    est = obs.observe(y, u).x_hat[:, 50:].reshape(-1, 2)
    X = torch.cat([est, torch.ones(est.shape[0], 1, dtype=F64)], -1)
    Y = x[:, 50:].reshape(-1, 2)
    fit = X @ torch.linalg.lstsq(X, Y).solution
    r2 = 1 - (fit - Y).pow(2).sum(0) / (Y - Y.mean(0)).pow(2).sum(0)
    return rmse, r2.detach()  # a score: no graph back into the model


def test_feedback_start_recovers_the_hidden_state_and_beats_free_starts(records):
    train, test = records
    rmse_fb, r2_fb = _scores(_fit("feedback", train), test)
    rmse_free, _ = _scores(_fit("free", train), test)
    # the velocity is never measured: the learned state maps onto (position, velocity) affinely
    assert float(r2_fb.min()) > 0.95, r2_fb
    assert rmse_fb < 0.8 * rmse_free, (rmse_fb, rmse_free)


def test_encoder_start_trains(records):
    train, test = records
    torch.manual_seed(1)
    model = F.NeuralODE(2, (8,), "tanh", n_input=1).double()
    fit = train_from_outputs(model, train[0], C, OutputRecipe(start="encoder", iterations=30, burn=10, horizon=20,
                                                              seed=0), Ts=TS, u=train[1], progress=False)
    assert fit.encoder is not None and fit.loss[-1] < fit.loss[0]
    sim = free_run(model, test[0], C, burn=10, Ts=TS, u=test[1], encoder=fit.encoder)
    assert sim.shape == (B, T - 10, 1) and bool(torch.isfinite(sim).all())


def test_bad_training_inputs_are_refused_before_any_work(records):
    (y, u), _ = records
    model = F.NeuralODE(2, (8,), "tanh", n_input=1).double()
    empty = y.clone()
    empty[1] = float("nan")
    recipe = OutputRecipe(start="encoder", iterations=1)
    with pytest.raises(ValueError, match="no present sample at all"):
        train_from_outputs(model, empty, C, recipe, Ts=TS, u=u, progress=False)
    with pytest.raises(ValueError, match="needs the observer's output gain L"):
        OutputRecipe(start="feedback")
    with pytest.raises(ValueError, match="start must be one of"):
        OutputRecipe(start="magic")
    with pytest.raises(ValueError, match="burn must be an integer >= 1"):
        OutputRecipe(start="free", burn=0)
    with pytest.raises(ValueError, match="a segment needs burn \\+ horizon"):
        train_from_outputs(model, y[:, :30], C, OutputRecipe(start="free", burn=20, horizon=40), Ts=TS, u=u[:, :30],
                           progress=False)
    with pytest.raises(TypeError, match="not both"):
        train_from_outputs(model, y, C, recipe, Ts=TS, measurement=F.Measurement(t=torch.arange(T, dtype=F64)), u=u,
                           progress=False)
    with pytest.raises(ValueError, match="C and x0 belong to the first layer's observer"):
        train_from_outputs(model, y, C, recipe, Ts=TS, measurement=F.Measurement(C=C), u=u, progress=False)
    with pytest.raises(ValueError, match="seed must be an integer >= 0"):
        OutputRecipe(start="free", seed=-1)
