"""Bad inputs to the observers: each refused with a clear error before any work (the model never runs)."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.systems import LinearSystem
from fnnlib.models import NeuralFeedback

from tests.feedback.test_inputs import A, B, F64, TS
from tests.feedback.test_inputs import _euler_data as _euler

C = torch.tensor([[1.0, 0.0]], dtype=F64)
T = 40


class _Counting(torch.nn.Module):
    """The linear plant's field, counting its calls after ``armed`` is set."""

    def __init__(self, out_shape=None):
        super().__init__()
        self.calls, self.armed, self.out_shape = 0, False, out_shape

    def forward(self, t, x, u=None):
        self.calls += self.armed
        out = LinearSystem(A, B).rate(t, x, u)
        return out if self.out_shape is None else out.new_zeros(x.shape[0], *self.out_shape)


def _data(R=2):
    u = torch.sin(0.7 * torch.arange(T, dtype=F64) * TS)[:, None].expand(R, T, 1)
    x = torch.stack([_euler(torch.tensor([1.0, -0.5 * r], dtype=F64), u[r]) for r in range(R)])
    return x, u


def _make(kind, f):
    kw = dict(C=C, disturbance=[1], A=A)
    return {"kf": lambda: F.KalmanObserver(f, TS, n=2, cov=F.Covariances(1e-6, 1e-4)),
            "kf_C": lambda: F.KalmanObserver(f, TS, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4),
                                             steady_state=True, **kw),
            "ekf": lambda: F.ExtendedKalmanObserver(f, TS, n=2, cov=F.Covariances(1e-6, 1e-4)),
            "ekf_C": lambda: F.ExtendedKalmanObserver(f, TS, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), **kw),
            "ukf_C": lambda: F.UnscentedKalmanObserver(f, TS, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), **kw),
            "luenberger": lambda: F.LuenbergerObserver(f, TS, n=2, poles=[0.5, 0.6, 0.7, 0.8]),
            "luenberger_C": lambda: F.LuenbergerObserver(f, TS, n=2, poles=[0.7, 0.75, 0.8], **kw)}[kind]()


KINDS = ["kf", "kf_C", "ekf", "ekf_C", "ukf_C", "luenberger", "luenberger_C"]
GAPS = ["kf_C", "ekf", "ekf_C", "ukf_C", "luenberger_C"]  # the filters that take gaps


def _refused(kind, call, match, exc=ValueError, out_shape=None):
    f = _Counting(out_shape)
    obs = _make(kind, f)
    f.armed = True
    with pytest.raises(exc, match=match):
        call(obs)
    assert f.calls == 0, "the check came after the model ran"


def _y(kind, x):
    return x @ C.T if kind.endswith("_C") else x


@pytest.mark.parametrize("kind", KINDS)
def test_an_all_nan_record_is_refused(kind):
    x, u = _data()
    y = _y(kind, x).clone()
    y[1] = float("nan")
    match = "no present sample" if kind in GAPS else "NaN"
    _refused(kind, lambda obs: obs.estimate(y, u), match)


@pytest.mark.parametrize("kind", GAPS)
def test_a_mask_hiding_every_sample_is_refused(kind):
    x, u = _data()
    mask = torch.ones(2, T, dtype=torch.bool)
    mask[0] = False
    _refused(kind, lambda obs: obs.observe(_y(kind, x), u, mask=mask), r"no present sample at all \(record \(0,\)\)")
    _refused(kind, lambda obs: obs.predict(_y(kind, x), 3, u, mask=mask), "no present sample")


@pytest.mark.parametrize("kind", KINDS)
def test_a_bad_first_estimate_is_refused(kind):
    x, u = _data()
    y = _y(kind, x)
    _refused(kind, lambda obs: obs.observe(y, u, x0=torch.tensor([float("nan"), 0.0], dtype=F64)), "x0 holds a NaN")
    _refused(kind, lambda obs: obs.observe(y, u, x0=torch.zeros(3, dtype=F64)), r"x0 must have shape \(n,\) = \(2,\)")
    _refused(kind, lambda obs: obs.observe(y, u, x0=torch.zeros(5, 2, dtype=F64)), "do not broadcast")
    _refused(kind, lambda obs: obs.observe(y, u, x0="origin"), "x0 must be a tensor", exc=TypeError)


@pytest.mark.parametrize("kind", KINDS)
def test_a_first_estimate_starts_the_filter(kind):
    x, u = _data()
    y = _y(kind, x)
    obs = _make(kind, LinearSystem(A, B))
    x0 = torch.tensor([[0.3, 0.1], [-0.2, 0.4]], dtype=F64)
    a = obs.observe(y, u, x0=x0).x_hat
    b = obs.observe(y, u).x_hat
    assert bool(torch.isfinite(a).all()) and float((a[:, 0] - b[:, 0]).abs().max()) > 1e-3
    torch.testing.assert_close(obs.observe(y[1], u[1], x0=x0[1]).x_hat, a[1], rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind", ["ekf", "ekf_C", "ukf_C", "kf", "luenberger"])
@pytest.mark.parametrize("out_shape", [(3,), (2, 1)])
def test_a_model_of_the_wrong_shape_is_refused(kind, out_shape):
    x, u = _data()
    match = "must return the rate of every state" if kind in GAPS else "vector field returned shape"
    f = _Counting(out_shape)
    obs = _make(kind, f) if kind in ("kf", "luenberger", "ekf") else None
    if obs is None:  # the C forms linearise the model at construction: give them the Jacobian, then swap the model
        obs = _make(kind, _Counting())
        obs.f = f
    with pytest.raises(ValueError, match=match):
        obs.estimate(_y(kind, x), u)


@pytest.mark.parametrize("scale", [1e200, 1e160])
def test_the_ukf_at_1e200_is_refused_before_it_overflows(scale):
    x, u = _data(1)
    _refused("ukf_C", lambda obs: obs.estimate(x[0] @ C.T * scale, u[0]), "overflow float64")
    _refused("ukf_C", lambda obs: obs.estimate(x[0] @ C.T, u[0], x0=torch.tensor([scale, 0.0], dtype=F64)),
             "x0 reaches")


def test_a_diverging_ukf_stops_with_the_sample():
    """A model that explodes from the estimate: a clear RuntimeError naming the sample, not scipy's Cholesky error."""

    def wild(_t, x, u=None):
        return 1e80 * x ** 3

    x, u = _data(1)
    ukf = F.UnscentedKalmanObserver(wild, TS, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), C=C, disturbance=[1],
                                    A=A)
    with pytest.raises(RuntimeError, match="the UKF"):
        ukf.estimate(x[0] @ C.T, u[0])


def test_the_neural_feedback_refuses_bad_measurements():
    obs = F.NeuralFeedbackObserver(LinearSystem(A, torch.zeros(2, 0, dtype=F64)), TS,
                                   h=NeuralFeedback(2, (4,), "tanh").double(), n=2)
    x, _ = _data(1)
    y = x[0].clone()
    y[3, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        obs.observe(y)


def test_settings_given_as_text_are_refused():
    plant = LinearSystem(A, B)
    with pytest.raises(TypeError, match="observer gain L must be a matrix of numbers"):
        F.LuenbergerObserver.with_gain(plant, TS, n=2, L="abc")
    with pytest.raises(TypeError, match="poles must be numbers"):
        F.LuenbergerObserver(plant, TS, n=2, poles=["a", "b", "c", "d"])
    with pytest.raises(TypeError, match="Q must be a number"):
        F.KalmanObserver(plant, TS, n=2, cov=F.Covariances("abc", 1e-4))
    with pytest.raises(TypeError, match="R must be a number"):
        F.ExtendedKalmanObserver(plant, TS, n=2, cov=F.Covariances(1e-6, ["x", "y"]))
