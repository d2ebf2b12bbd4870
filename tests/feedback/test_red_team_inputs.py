"""Inputs a red team gave the cascade, the feedback observer and the tuner: each refused with a clear message
before any work (the model is never called)."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.feedback import DEFAULT_TUNE_RECIPE
from fnnlib.systems import LinearSystem

from tests.feedback.test_inputs import A, B, F64, TS

T = 40
C = torch.tensor([[1.0, 0.0]], dtype=F64)


class Counting(LinearSystem):
    calls = 0

    def __call__(self, t, x, u=None):
        Counting.calls += 1
        return super().__call__(t, x, torch.zeros(*x.shape[:-1], 1, dtype=x.dtype) if u is None else u)


@pytest.fixture
def plant():
    Counting.calls = 0
    return Counting(A, B)


def _gain():
    return F.place_observer_gain(torch.eye(2, dtype=F64) + TS * A, TS * C, [0.6, 0.7])


def test_a_record_with_no_present_sample_is_refused(plant):
    x = torch.full((2, T, 2), float("nan"), dtype=F64)
    x[0] = 0.1  # the first record is fine, the second has nothing
    y = x[..., :1]
    mf = F.MeasuredFeedback(plant, TS, L=_gain(), measurement=F.Measurement(C=C), A=A)
    hide = torch.zeros(T, dtype=torch.bool)
    for call in (lambda: F.cascade_predict(plant, x, TS, 3, F.Gains(1.0)),
                 lambda: F.cascade_predict(plant, y, TS, 3, F.Gains(1.0), observer=mf),
                 lambda: mf.observe(y),
                 lambda: mf.predict(y, 3),
                 lambda: F.tune_gains(plant, x, TS, 3, recipe=DEFAULT_TUNE_RECIPE),
                 lambda: F.cascade_predict(plant, torch.zeros(T, 2, dtype=F64), TS, 3, F.Gains(1.0),
                                           measurement=F.Measurement(mask=hide)),
                 lambda: mf.observe(torch.zeros(T, 1, dtype=F64), mask=hide)):
        with pytest.raises(ValueError, match="no present sample at all"):
            call()
    assert Counting.calls == 0


@pytest.mark.parametrize("x0, match", [
    (torch.tensor([float("nan"), 0.0], dtype=F64), "x0 holds NaN"),
    (torch.zeros(3, dtype=F64), r"x0 must be a real vector of shape \(2,\)"),
    (torch.zeros(1, 2, dtype=F64), r"x0 must be a real vector of shape \(2,\)"),
])
def test_a_bad_first_estimate_is_refused(plant, x0, match):
    with pytest.raises(ValueError, match=match):
        F.MeasuredFeedback(plant, TS, L=_gain(), measurement=F.Measurement(C=C, x0=x0), A=A)


@pytest.mark.parametrize("beta", [float("nan"), float("inf"), -0.1])
def test_a_bad_decay_rate_is_refused(plant, beta):
    with pytest.raises(ValueError, match="decay rate beta must be finite and >= 0"):
        F.cascade_predict(plant, torch.zeros(T, 2, dtype=F64), TS, 3, F.Gains(1.0, beta))
    assert Counting.calls == 0


@pytest.mark.parametrize("L", ["2.0", ["1", "2"], [[1.0, "a"], [0.0, 1.0]]])
def test_gains_given_as_text_are_refused(plant, L):
    with pytest.raises(TypeError, match="gain L must be a number, a vector or a matrix of numbers"):
        F.cascade_predict(plant, torch.zeros(T, 2, dtype=F64), TS, 3, F.Gains(L))
    with pytest.raises(TypeError, match="gain L must be a number"):
        F.MeasuredFeedback(plant, TS, L=L, measurement=F.Measurement(C=C))
    assert Counting.calls == 0


@pytest.mark.parametrize("N", [True, False, 2.5, 0, "3"])
def test_N_must_be_an_integer(plant, N):
    with pytest.raises((TypeError, ValueError), match="N must be an integer >= 1"):
        F.cascade_predict(plant, torch.zeros(T, 2, dtype=F64), TS, N, F.Gains(1.0))
    assert Counting.calls == 0
