"""The frictions a new user met, each fixed and pinned by a test."""

from __future__ import annotations

import warnings

import pytest
import torch
from torch import nn

import fnnlib as F
from fnnlib.feedback import GainWarning, cascade_predict_loop
from fnnlib.models import MODELS
from fnnlib.stability import growth_factor
from fnnlib.systems import LinearSystem, Spiral
from fnnlib.training import QUICK_RECIPE, load_checkpoint, randomized_cases, register_model, save_checkpoint

F64 = torch.float64


def test_float64_data_into_a_float32_model_gives_a_clear_error():
    x = Spiral(2.0, 0.1, 0.0).simulate(torch.tensor([9.0, 0.0]), torch.linspace(0, 1, 20))
    model = F.NeuralODE(2, [8], "relu")
    with pytest.raises(TypeError, match=r"parameters are torch.float32 but the states are torch.float64"):
        F.cascade_predict(model, x, 0.05, 2, F.Gains(1.0))
    assert F.cascade_predict(model, x.float(), 0.05, 2, F.Gains(1.0)).dtype == torch.float32


def test_n_is_implied_by_the_gain_or_the_model():
    model = F.NeuralODE(2, [8], "relu")
    assert F.LinearFeedback(model, 0.01, gains=F.Gains(5.0)).n == 2  # from the model's n
    assert F.LinearFeedback(lambda t, x: x, 0.01, gains=F.Gains(torch.tensor([1.0, 2.0, 3.0]))).n == 3  # from L
    assert F.check_gain(torch.tensor([1.0, 2.0]), None, 0.01).shape == (2, 2)
    with pytest.raises(ValueError, match="scalar gain L does not say the state dimension"):
        F.LinearFeedback(lambda t, x: x, 0.01, gains=F.Gains(5.0))
    assert F.NeuralFeedbackObserver(model, 0.01, h=F.NeuralFeedback(2, [4], "relu")).n == 2


def test_rate_takes_the_arguments_of_call():
    spiral = Spiral(2.0, 0.1, 0.5)
    x = torch.randn(5, 2, dtype=F64)
    torch.testing.assert_close(spiral.rate(0.0, x), spiral(0.0, x))
    torch.testing.assert_close(spiral.rate(x), spiral(0.0, x))
    with pytest.raises(TypeError, match=r"rate takes \(t, x\) in the order of __call__"):
        spiral.rate(torch.randn(1, 5, 2, dtype=F64), torch.tensor(0.0))
    assert "How to write your own" in F.DynamicalSystem.__doc__


class Twice(nn.Module):
    def __init__(self, n: int):
        super().__init__()
        self.n = n
        self.lin = nn.Linear(n, n)

    @property
    def config(self):
        return {"n": self.n}

    def forward(self, t, x):
        return 2 * self.lin(x)


def test_save_checkpoint_accepts_a_registered_module(tmp_path, monkeypatch):
    monkeypatch.setattr(F.training.checkpoint, "MODELS", dict(MODELS))  # the registry is global: a copy here
    model = Twice(3)
    with pytest.raises(TypeError, match=r"cannot checkpoint a Twice: register its class first"):
        save_checkpoint(tmp_path / "twice.pt", model)
    assert register_model(Twice) is Twice
    save_checkpoint(tmp_path / "twice.pt", model, {"note": "mine"})
    back, meta = load_checkpoint(tmp_path / "twice.pt", expected_kind="Twice")
    assert isinstance(back, Twice) and meta == {"note": "mine"}
    assert all(torch.equal(a, b) for a, b in zip(model.state_dict().values(), back.state_dict().values()))
    with pytest.raises(TypeError, match="needs a `config` property"):
        register_model(nn.Linear)


def test_quick_recipe_trains_a_controlled_model_in_seconds():
    plant = LinearSystem(torch.tensor([[0.0, 1.0], [-4.0, -0.4]]), torch.tensor([[0.0], [1.0]]))
    t = torch.arange(200, dtype=F64) * 0.05
    u = torch.sin(1.3 * t)[:, None]
    x = plant.simulate(torch.tensor([1.0, 0.0]), t, u).float()
    torch.manual_seed(0)
    model = F.NeuralODE(2, [16], "tanh", n_input=1)
    hist = F.train_neural_ode(model, t.float(), x, QUICK_RECIPE.replace(iterations=60), seed=0, progress=False,
                              u=u.float())
    assert sum(hist.loss[-10:]) < 0.2 * sum(hist.loss[:10])
    assert hist.seconds < 30
    assert "QUICK_RECIPE" in F.train_neural_ode.__doc__


def test_randomized_cases_from_a_parameter_range():
    t = torch.arange(50, dtype=F64) * 0.02
    X, params = randomized_cases(Spiral, [0.8, 0.04, -24.0], [3.08, 0.135, 21.6], 20, torch.tensor([9.0, 0.0]), t)
    assert X.shape == (20, 50, 2)
    torch.testing.assert_close(params[:, 0], 0.8 + 0.12 * torch.arange(20, dtype=F64))  # {0.8:0.12:3.08}
    torch.testing.assert_close(X[3], Spiral(*params[3].tolist()).simulate(torch.tensor([9.0, 0.0]), t))
    with pytest.raises(ValueError, match="n_case must be an integer >= 2"):
        randomized_cases(Spiral, [1.0], [2.0], 1, torch.zeros(2), t)


def test_growth_factor_warns_instead_of_a_silent_nan():
    err = torch.ones(3, 100)
    err[1, 95] = float("nan")
    with pytest.warns(RuntimeWarning, match="1 of 3 ratios are not finite because err holds NaN"):
        g = growth_factor(err)
    assert torch.isnan(g[1]) and torch.isfinite(g[[0, 2]]).all()
    with pytest.raises(ValueError, match="at least 2 samples"):
        growth_factor(torch.ones(3, 1))


def test_empty_trajectory_is_a_clear_error_for_both_cascades():
    f = Spiral(2.0, 0.1, 0.0)
    for fn in (F.cascade_predict, cascade_predict_loop):
        with pytest.raises(ValueError, match="x is an empty trajectory"):
            fn(f, torch.zeros(0, 2, dtype=F64), 0.01, 3, F.Gains(1.0))


def test_semidefinite_gain_is_not_called_unstable():
    with pytest.warns(GainWarning, match="positive semidefinite"):
        M = F.check_gain(torch.tensor([0.0, 5.0]), 2, 0.01)
    assert float(M[1, 1]) == 5.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        F.check_gain(0.0, 2, 0.01)  # exactly zero: feedback off, silent
