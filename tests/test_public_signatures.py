"""The public face takes its options as objects: no function or constructor of more than 8 parameters, one
constructor order for every observer, and option objects that refuse bad input on construction."""

from __future__ import annotations

import dataclasses
import inspect

import pytest
import torch

import fnnlib as F
from fnnlib.systems import Spiral

F64 = torch.float64
MAX_PARAMETERS = 8

#: Public callables still over the limit, each with the reason; the list only shrinks (it is empty)
OVER_THE_LIMIT: dict[str, str] = {}

OBSERVERS = ("LinearFeedback", "NeuralFeedbackObserver", "MeasuredFeedback", "LuenbergerObserver", "KalmanObserver",
             "ExtendedKalmanObserver", "UnscentedKalmanObserver")


def _public_callables():
    for name in sorted(F.__all__):
        obj = getattr(F, name)
        if inspect.isclass(obj) and dataclasses.is_dataclass(obj):
            continue  # a settings or result record: its fields are the named options, each with a default
        if inspect.isclass(obj) and issubclass(obj, BaseException):
            continue
        if inspect.isclass(obj) or inspect.isfunction(obj):
            yield name, obj


def _parameters(obj) -> list[str]:
    return [p for p in inspect.signature(obj).parameters if p != "self"]


def test_no_public_function_or_constructor_takes_more_than_eight_parameters():
    over = {name: len(_parameters(obj)) for name, obj in _public_callables()
            if len(_parameters(obj)) > MAX_PARAMETERS and name not in OVER_THE_LIMIT}
    assert not over, f"public callables with more than {MAX_PARAMETERS} parameters: {over}"
    stale = [name for name in OVER_THE_LIMIT if name in F.__all__ and len(_parameters(getattr(F, name))) <= MAX_PARAMETERS]
    assert not stale, f"no longer over the limit: drop {stale} from OVER_THE_LIMIT"


def test_every_observer_is_built_as_f_Ts_then_keywords():
    for name in OBSERVERS:
        params = list(inspect.signature(getattr(F, name)).parameters.values())
        assert [p.name for p in params[:2]] == ["f", "Ts"], name
        assert all(p.kind == p.POSITIONAL_OR_KEYWORD for p in params[:2]), name
        assert all(p.kind == p.KEYWORD_ONLY for p in params[2:]), (name, [p.name for p in params[2:]])
    with_gain = list(inspect.signature(F.LuenbergerObserver.with_gain).parameters.values())
    assert [p.name for p in with_gain[:2]] == ["f", "Ts"] and all(p.kind == p.KEYWORD_ONLY for p in with_gain[2:])


def test_tuned_gains_are_a_tensor_and_a_schedule():
    model = Spiral(2.0, 0.1, 0.0)
    x = model.simulate(torch.tensor([1.0, 0.0], dtype=F64), torch.arange(40, dtype=F64) * 0.05)
    tuned = F.tune_gains(model, x, 0.05, 3, F.TuneRecipe(L0=2.0, beta0=0.1, iterations=2, lr=0.1))
    assert isinstance(tuned.L, torch.Tensor) and tuned.L.dtype == F64 and tuned.L.shape == (2,)
    gains = tuned.schedule()
    assert isinstance(gains, F.Gains) and torch.equal(gains.L, tuned.L) and gains.beta == tuned.beta
    F.cascade_predict(model, x, 0.05, 3, gains)  # what the cascade takes, with no rewrapping


@pytest.mark.parametrize("make, err, match", [
    (lambda: F.Gains("5"), TypeError, "gain L must be a number"),
    (lambda: F.Gains(float("nan")), F.GainError, "Gains.L holds NaN"),
    (lambda: F.Gains(torch.ones(2, 3)), ValueError, r"a square matrix \(n, n\)"),
    (lambda: F.Gains(torch.ones(2, 2, 2)), ValueError, r"a square matrix \(n, n\)"),
    (lambda: F.Gains(1.0, -0.1), ValueError, "decay rate beta must be finite and >= 0"),
    (lambda: F.Gains(1.0, float("inf")), ValueError, "decay rate beta must be finite and >= 0"),
    (lambda: F.Gains(1.0, [0.1, 0.2]), TypeError, "Gains.beta must be one number"),
    (lambda: F.Gains(1.0, allow_unstable="yes"), TypeError, "allow_unstable must be a bool"),
    (lambda: F.Gains.sweep(torch.ones(3), torch.ones(2)), ValueError, "3 gains and 2 decay rates do not pair up"),
    (lambda: F.Measurement(C=torch.ones(3)), ValueError, r"Measurement.C must be a \(p, n\) matrix"),
    (lambda: F.Measurement(C=torch.tensor([[1.0, float("nan")]])), ValueError, "Measurement.C holds NaN"),
    (lambda: F.Measurement(C=torch.ones(1, 2, dtype=torch.complex128)), TypeError, "real"),
    (lambda: F.Measurement(C=lambda x: x[:, :1]), ValueError, "with a measurement function h give the first"),
    (lambda: F.Measurement(mask=torch.ones(5)), TypeError, "Measurement.mask must be a boolean tensor"),
    (lambda: F.Measurement(C=torch.ones(1, 2), x0=torch.zeros(3)), ValueError, r"x0 must be a real vector of shape \(2,\)"),
    (lambda: F.Measurement(x0=torch.tensor([0.0, float("nan")])), ValueError, "x0 holds NaN"),
    (lambda: F.Measurement(t=torch.tensor([0.0, 0.2, 0.1])), ValueError, "strictly increasing"),
    (lambda: F.Measurement(t=torch.tensor([0.0, float("nan")])), ValueError, "hold a NaN"),
    (lambda: F.Measurement(t=torch.arange(3)), TypeError, "floating-point tensor"),
    (lambda: F.Solver("leapfrog"), ValueError, "Solver.method must be one of"),
    (lambda: F.Solver("euler", rtol=1e-6), ValueError, "takes no tolerance"),
    (lambda: F.Solver("dopri5", atol=-1.0), ValueError, "Solver.atol must be a finite number > 0"),
    (lambda: F.Covariances(Q=[-1.0, 1.0], R=1.0), ValueError, "Q must be positive semi-definite"),
    (lambda: F.Covariances(Q=1.0, R=0.0), ValueError, "R must be positive definite"),
    (lambda: F.Covariances(Q=torch.ones(2, 3), R=1.0), ValueError, "a square matrix"),
    (lambda: F.Covariances(Q="big", R=1.0), TypeError, "Covariances.Q must be a number"),
    (lambda: F.SigmaPoints(alpha=0.0), ValueError, "SigmaPoints.alpha must be > 0"),
    (lambda: F.TuneRecipe(objective="loss"), TypeError, "TuneRecipe.objective must be a callable"),
    (lambda: F.TuneRecipe(iterations=0), ValueError, "TuneRecipe.iterations must be an integer >= 1"),
])
def test_option_objects_refuse_bad_input_on_construction(make, err, match):
    with pytest.raises(err, match=match):
        make()


def test_options_are_frozen():
    for obj in (F.Gains(1.0), F.Measurement(), F.Solver(), F.Covariances(1.0, 1.0), F.SigmaPoints(), F.TuneRecipe()):
        field = dataclasses.fields(obj)[0].name
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, field, None)


def test_a_misplaced_option_is_refused_before_the_model_runs():
    calls = []

    def model(t, x):
        calls.append(1)
        return -x

    x = torch.zeros(20, 2, dtype=F64)
    with pytest.raises(TypeError, match="gains must be a fnnlib.Gains"):
        F.cascade_predict(model, x, 0.1, 3, 5.0)
    with pytest.raises(ValueError, match="C and x0 belong to the first layer's observer"):
        F.cascade_predict(model, x, 0.1, 3, F.Gains(5.0), measurement=F.Measurement(C=torch.eye(2)))
    with pytest.raises(ValueError, match="takes no gaps"):
        F.rollout_predict(model, x, 0.1, 3, measurement=F.Measurement(mask=torch.ones(20, dtype=torch.bool)))
    with pytest.raises(ValueError, match="go to observe / predict"):
        F.MeasuredFeedback(model, 0.1, L=torch.ones(2, 1), measurement=F.Measurement(C=torch.ones(1, 2),
                                                                                     t=torch.arange(20.0)))
    with pytest.raises(TypeError, match="recipe must be a TuneRecipe"):
        F.tune_gains(model, x, 0.1, 3, {"lr": 0.1})
    with pytest.raises(TypeError, match="cov must be a fnnlib.Covariances"):
        F.KalmanObserver(model, 0.1, n=2, cov=(1e-6, 1e-4))
    assert not calls


def test_a_jacobian_without_an_output_form_is_refused():
    A = torch.zeros(2, 2, dtype=F64)
    with pytest.raises(ValueError, match="the full-state observer needs none"):
        F.ExtendedKalmanObserver(Spiral(2.0, 0.1, 0.0), 0.1, n=2, cov=F.Covariances(1e-6, 1e-4), A=A)
    with pytest.raises(ValueError, match="the full-state observer needs none"):
        F.LuenbergerObserver(Spiral(2.0, 0.1, 0.0), 0.1, n=2, poles=[0.5, 0.6, 0.7, 0.8], A=A)
