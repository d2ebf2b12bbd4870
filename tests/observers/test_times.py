"""Uneven sample times through every observer: uniform times equal the Ts path, random intervals match the
closed-form discretisation, the poles hold per sample, and bad times are refused before the model runs."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import torch

import fnnlib as F
from fnnlib.feedback import Measurement
from fnnlib.observers import evaluate_observer
from fnnlib.systems import LinearSystem
from fnnlib.models import NeuralFeedback, NeuralODE
from fnnlib.observers import NeuralFeedbackObserver, augmented_matrices, rollout_corrected
from fnnlib.observers.augmented import augmented_step

from tests.feedback.test_inputs import A, B, F64, TS
from tests.feedback.test_inputs import _euler_data as _euler

C = torch.tensor([[1.0, 0.0]], dtype=F64)
PLANT = LinearSystem(A, B)
T = 60
TOL = dict(rtol=0, atol=1e-12)
TS2 = 2.0 ** -4  # a step whose grid k * TS2 and intervals are exact in binary: the uniform-times comparisons


def _records(R=2):
    """R records (R, T, 2) of the controlled linear plant, their inputs (R, T, 1), a little noise."""
    u = torch.stack([torch.sin((0.7 + 0.3 * r) * torch.arange(T, dtype=F64) * TS) for r in range(R)])[..., None]
    x = torch.stack([_euler(torch.tensor([1.0 - r, -0.5], dtype=F64), u[r] + 0.2) for r in range(R)])
    return x + 1e-3 * torch.randn(x.shape, dtype=F64, generator=torch.Generator().manual_seed(4)), u


def _uniform_times(R=2, Ts=TS2):
    return torch.arange(T, dtype=F64).expand(R, T) * Ts


def _random_times(R=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    dt = TS * (0.3 + 1.4 * torch.rand(R, T - 1, dtype=F64, generator=g))
    return torch.cat([torch.zeros(R, 1, dtype=F64), dt.cumsum(-1)], -1)


def _observers(Ts=TS):
    """Every augmented observer: full state (measured y = x) and with C (y = position)."""
    kw = dict(C=C, disturbance=[1], A=A)
    return {
        "kf": (F.KalmanObserver(PLANT, Ts, n=2, cov=F.Covariances(1e-6, 1e-4)), False),
        "kf_steady": (F.KalmanObserver(PLANT, Ts, n=2, cov=F.Covariances(1e-6, 1e-4), steady_state=True), False),
        "kf_C": (F.KalmanObserver(PLANT, Ts, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), steady_state=True,
                                  **kw), True),
        "ekf": (F.ExtendedKalmanObserver(PLANT, Ts, n=2, cov=F.Covariances(1e-6, 1e-4)), False),
        "ekf_C": (F.ExtendedKalmanObserver(PLANT, Ts, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), **kw), True),
        "ukf_C": (F.UnscentedKalmanObserver(PLANT, Ts, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), **kw), True),
        "luenberger": (F.LuenbergerObserver(PLANT, Ts, n=2, poles=[0.5, 0.6, 0.7, 0.8]), False),
        "luenberger_C": (F.LuenbergerObserver(PLANT, Ts, n=2, poles=[0.7, 0.75, 0.8], **kw), True),
    }


@pytest.mark.parametrize("name", list(_observers()))
def test_uniform_times_equal_the_Ts_path(name):
    """On a grid stored exactly (k / 16) the times reproduce the step path to 1e-12. On a grid like k * 0.05
    the intervals t_{k+1} - t_k carry the rounding of t itself (~1e-15 relative), which a filter with a
    disturbance state amplifies to ~1e-11: the same path, checked to 1e-9."""
    obs, partial = _observers(TS2)[name]
    x, u = _records()
    y = x @ C.T if partial else x
    ref, got = obs.estimate(y, u), obs.estimate(y, u, t=_uniform_times())
    for a, b in zip(ref, got):
        torch.testing.assert_close(b, a, **TOL)
    torch.testing.assert_close(obs.predict(y, 5, u, t=_uniform_times()), obs.predict(y, 5, u), **TOL)
    # one grid (T,) for every record is the same as one per record
    torch.testing.assert_close(obs.observe(y, u, t=_uniform_times()[0]).x_hat, got.x_hat, rtol=0, atol=0)
    obs, _ = _observers(TS)[name]
    torch.testing.assert_close(obs.estimate(y, u, t=_uniform_times(Ts=TS)).x_hat, obs.estimate(y, u).x_hat,
                               rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", list(_observers()))
def test_each_record_steps_by_its_own_times(name):
    """A batch with a time grid per record equals each record filtered alone (one call, no loop over records)."""
    obs, partial = _observers()[name]
    x, u = _records()
    y = x @ C.T if partial else x
    t = _random_times()
    both = obs.estimate(y, u, t=t)
    for r in range(2):
        alone = obs.estimate(y[r], u[r], t=t[r])
        torch.testing.assert_close(both.x_hat[r], alone.x_hat, **TOL)
    assert bool(torch.isfinite(both.x_hat).all())


def test_the_plant_per_interval_is_the_exact_zero_order_hold():
    """A(Delta), B(Delta) equal expm([[A_c, B_c], [0, 0]] Delta) (Van Loan) at random intervals."""
    n = 2
    A_, B_, _ = augmented_matrices(n, TS)
    Ac = np.block([[np.zeros((n, n)), np.eye(n)], [np.zeros((n, 2 * n))]])
    Bc = np.vstack([np.eye(n), np.zeros((n, n))])
    h = torch.tensor([0.003, 0.05, 0.17, 1.3], dtype=F64)
    Ak, Bk = augmented_step(A_, B_, TS, h)
    for j, d in enumerate(h.tolist()):
        M = scipy.linalg.expm(np.block([[Ac, Bc], [np.zeros((n, 3 * n))]]) * d)
        np.testing.assert_allclose(Ak[j].numpy(), M[:2 * n, :2 * n], rtol=0, atol=1e-14)
        np.testing.assert_allclose(Bk[j].numpy(), M[:2 * n, 2 * n:], rtol=0, atol=1e-14)


def test_open_loop_prediction_at_random_intervals_is_the_closed_form():
    """With zero gain the filter only predicts: z_{k+1} = expm(M Delta_k) [z_k; f(y_k)], random Delta_k."""
    x, u = _records(1)
    t = _random_times(1)[0]
    obs = F.LuenbergerObserver.with_gain(PLANT, TS, n=2, L=torch.zeros(4, 2), allow_unstable=True)  # poles at 1: no correction
    est = obs.estimate(x[0], u[0], t=t)
    n = 2
    Mc = np.zeros((3 * n, 3 * n))
    Mc[:n, n:2 * n] = np.eye(n)  # x' = d + f
    Mc[:n, 2 * n:] = np.eye(n)
    fy = PLANT.rate(0.0, x[0], u[0]).numpy()
    z = np.concatenate([x[0, 0].numpy(), np.zeros(n)])
    for k in range(T - 1):
        z = (scipy.linalg.expm(Mc * float(t[k + 1] - t[k])) @ np.concatenate([z, fy[k]]))[:2 * n]
        np.testing.assert_allclose(est.x_hat[k + 1].numpy(), z[:n], rtol=0, atol=1e-12)


@pytest.mark.parametrize("steady", [False, True])
def test_a_ramp_sampled_at_random_times_is_tracked_exactly(steady):
    """x(t) = x0 + d t (the augmented plant with f = 0) sampled at random times is in the KF's model for any
    intervals: its disturbance estimate finds d, which an Ts-stepped filter of the same samples does not."""

    def zero(_t, x):
        return torch.zeros_like(x)

    t = _random_times(1, seed=3)[0] * 2
    d = torch.tensor([0.4, -1.5], dtype=F64)
    y = torch.tensor([1.0, 2.0], dtype=F64) + t[:, None] * d
    kf = F.KalmanObserver(zero, TS, n=2, cov=F.Covariances([1e-10, 1e-10, 1e-4, 1e-4], 1e-8), steady_state=steady)
    est = kf.estimate(y, t=t)
    torch.testing.assert_close(est.d_hat[-1], d, rtol=0, atol=1e-6)
    torch.testing.assert_close(est.x_hat[-1], y[-1], rtol=0, atol=1e-8)
    assert float((kf.estimate(y).d_hat[-1] - d).abs().max()) > 0.1  # the nominal step misreads the ramp


def test_process_noise_scales_with_the_interval():
    """Q is given per nominal step: a filter at intervals 2 Ts equals one at Ts with 2 Q and twice the step."""
    y, u = _records(1)
    t = torch.arange(T, dtype=F64) * 2 * TS2
    a = F.ExtendedKalmanObserver(PLANT, TS2, n=2, cov=F.Covariances(1e-6, 1e-4)).estimate(y[0], u[0], t=t)
    b = F.ExtendedKalmanObserver(PLANT, 2 * TS2, n=2, cov=F.Covariances(2e-6, 1e-4)).estimate(y[0], u[0])
    torch.testing.assert_close(a.x_hat, b.x_hat, rtol=0, atol=1e-12)


def test_luenberger_poles_hold_per_sample():
    """Full state: L_Delta = diag(I, Ts/Delta I) L has the poles of L for every Delta (closed form); with C the
    poles are placed for each distinct interval."""
    poles = [0.5, 0.6, 0.7, 0.8]
    obs = F.LuenbergerObserver(PLANT, TS, n=2, poles=poles)
    A_, B_, C_ = augmented_matrices(2, TS)
    for h in (0.01, 0.13, 0.4):
        Ah = augmented_step(A_, B_, TS, torch.tensor(h, dtype=F64))[0]
        L_h = torch.diag(torch.tensor([1.0, 1.0, TS / h, TS / h], dtype=F64)) @ obs.L
        np.testing.assert_allclose(np.sort(np.linalg.eigvals((Ah - L_h @ C_).numpy()).real), poles, atol=1e-9)
    obs_C = F.LuenbergerObserver(PLANT, TS, n=2, poles=[0.7, 0.75, 0.8], C=C, disturbance=[1], A=A)
    hs = np.array([[0.02, 0.11, 0.02]])
    K = obs_C.interval_gains(hs)
    assert K.shape == (1, 4, 3, 1)
    for k, h in enumerate([0.02, 0.11, 0.02, 0.02]):
        Phi = obs_C._linearised(A, h).numpy()
        L = Phi @ K[0, k]  # the predictor gain of that interval
        # single-output placement leaves a non-normal Phi - L C whose poles move ~1e-7 under a 1e-16 change of Phi
        np.testing.assert_allclose(np.sort(np.linalg.eigvals(Phi - L @ obs_C.C.numpy()).real), [0.7, 0.75, 0.8],
                                   atol=1e-6)


def test_rollout_and_prediction_step_along_the_record_times():
    x, u = _records(1)
    t = _random_times(1)[0]
    d = torch.full_like(x[0], 0.1)
    z = rollout_corrected(PLANT, x[0], d, None, 3, u[0], t=t)
    k = 10
    ref = x[0, k]
    for j in range(3):
        ref = ref + float(t[k + j + 1] - t[k + j]) * (PLANT.rate(0.0, ref[None], u[0, k + j][None])[0] + 0.1)
    torch.testing.assert_close(z[k], ref, **TOL)
    # past the record's end the last interval is repeated
    last = x[0, -1] + float(t[-1] - t[-2]) * (PLANT.rate(0.0, x[0, -1][None], u[0, -1][None])[0] + 0.1)
    torch.testing.assert_close(rollout_corrected(PLANT, x[0], d, None, 1, u[0], t=t)[-1], last, **TOL)
    torch.testing.assert_close(rollout_corrected(PLANT, x[0], d, TS2, 4, u[0]),
                               rollout_corrected(PLANT, x[0], d, None, 4, u[0], t=_uniform_times(1)[0]), **TOL)


def _neural(seed=0):
    torch.manual_seed(seed)
    return NeuralFeedbackObserver(NeuralODE(2, (16,), "tanh").double(), TS,
                                  h=NeuralFeedback(2, (16,), "tanh").double(), n=2, beta=0.2)


def test_neural_feedback_with_times():
    obs = _neural()
    obs.Ts = TS2
    x, _ = _records(3)
    tu = _uniform_times(3)
    for a, b in zip(obs.observe(x), obs.observe(x, t=tu)):
        torch.testing.assert_close(b, a, **TOL)
    torch.testing.assert_close(obs.predict(x, 4, t=tu), obs.predict(x, 4), **TOL)
    t = _random_times(3)
    got = obs.predict(x, 4, t=t)
    for r in range(3):  # the wavefront equals the plain loop over starts and depths
        torch.testing.assert_close(got[r], obs.predict_loop(x[r], 4, t=t[r]), **TOL)
    est = obs.observe(x, t=t)  # x_hat_{k+1} = x_hat_k + Delta_k f_hat_k
    torch.testing.assert_close(est.x_hat[:, 1:], est.x_hat[:, :-1] + t.diff(dim=-1)[..., None] * est.f_hat[:, :-1],
                               **TOL)


def test_evaluate_observer_takes_times():
    x, u = _records(1)
    t = _random_times(1)[0]
    obs = F.ExtendedKalmanObserver(PLANT, TS, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), C=C, disturbance=[1],
                                   A=A)
    f_true = PLANT.rate(0.0, x[0], u[0])
    rep = evaluate_observer(obs, x[0] @ C.T, (x[0], f_true), 3, repeats=1, u=u[0], measurement=Measurement(t=t))
    torch.testing.assert_close(rep.estimate.x_hat, obs.observe(x[0] @ C.T, u[0], t=t).x_hat, rtol=0, atol=0)
    with pytest.raises(ValueError, match="strictly increasing"):
        evaluate_observer(obs, x[0] @ C.T, (x[0], f_true), 3, repeats=1, u=u[0], measurement=Measurement(t=t.flip(0)))


class _Counting(torch.nn.Module):
    """The plant's field, counting its calls: a check that refuses before any work leaves the count at 0."""

    def __init__(self):
        super().__init__()
        self.calls = 0

    def forward(self, t, x, u=None):
        self.calls += 1
        return PLANT.rate(t, x, u)


def _bad_times():
    t = _uniform_times(1)[0]
    back = t.clone()
    back[7] = back[5]
    nan = t.clone()
    nan[3] = float("nan")
    return {"strictly increasing": back, "NaN": nan, "one time per sample": t[:-1]}


@pytest.mark.parametrize("what", list(_bad_times()))
@pytest.mark.parametrize("kind", ["kf", "kf_steady", "ekf", "ukf_C", "luenberger", "luenberger_C", "neural"])
def test_bad_times_are_refused_before_the_model_runs(kind, what):
    f = _Counting()
    kw = dict(C=C, disturbance=[1], A=A)
    obs = {"kf": lambda: F.KalmanObserver(f, TS, n=2, cov=F.Covariances(1e-6, 1e-4)),
           "kf_steady": lambda: F.KalmanObserver(f, TS, n=2, cov=F.Covariances(1e-6, 1e-4), steady_state=True),
           "ekf": lambda: F.ExtendedKalmanObserver(f, TS, n=2, cov=F.Covariances(1e-6, 1e-4)),
           "ukf_C": lambda: F.UnscentedKalmanObserver(f, TS, n=2, cov=F.Covariances([1e-6, 1e-6, 1e-3], 1e-4), **kw),
           "luenberger": lambda: F.LuenbergerObserver(f, TS, n=2, poles=[0.5, 0.6, 0.7, 0.8]),
           "luenberger_C": lambda: F.LuenbergerObserver(f, TS, n=2, poles=[0.7, 0.75, 0.8], **kw),
           "neural": lambda: NeuralFeedbackObserver(lambda t, x: f(t, x), TS,
                                                    h=NeuralFeedback(2, (4,), "tanh").double(), n=2)}[kind]()
    x, u = _records(1)
    y = x[0] @ C.T if kind.endswith("_C") else x[0]
    f.calls = 0
    with pytest.raises(ValueError, match=what):
        if kind == "neural":
            obs.observe(y, t=_bad_times()[what])
        else:
            obs.observe(y, u[0], t=_bad_times()[what])
    assert f.calls == 0


def test_times_with_a_step_are_refused():
    x, u = _records(1)
    with pytest.raises(TypeError, match="not both"):
        rollout_corrected(PLANT, x[0], x[0], TS, 2, u[0], t=_uniform_times(1)[0])
    with pytest.raises(ValueError, match="one grid"):  # more time grids than records
        F.ExtendedKalmanObserver(PLANT, TS, n=2, cov=F.Covariances(1e-6, 1e-4)).observe(x[0], u[0], t=_uniform_times(3))
    with pytest.raises(ValueError, match="one grid"):
        F.LuenbergerObserver(PLANT, TS, n=2, poles=[0.5, 0.6, 0.7, 0.8]).observe(x[0], u[0], t=_uniform_times(3))
    with pytest.raises(ValueError, match="one grid"):
        _neural().observe(x[0], t=_uniform_times(3))
    with pytest.raises(ValueError, match="one grid"):
        F.LinearFeedback(PLANT, TS, gains=F.Gains(3.0), n=2).observe(x[0], u[0], t=_uniform_times(3))
    with pytest.raises(TypeError, match="floating-point"):
        F.ExtendedKalmanObserver(PLANT, TS, n=2, cov=F.Covariances(1e-6, 1e-4)).observe(x[0], u[0], t=torch.arange(T))


def test_linear_feedback_with_times():
    """LinearFeedback: uniform times equal Ts; random times follow x_hat_{k+1} = x_hat_k + Delta_k f_hat_k and the
    cascade's own times; a gain stable at Ts but not at the longest interval is refused (Eq. (25))."""
    x, u = _records(2)
    obs = F.LinearFeedback(PLANT, TS2, gains=F.Gains(3.0), n=2)
    tu = _uniform_times(2)
    for a, b in zip(obs.observe(x, u), obs.observe(x, u, t=tu)):
        torch.testing.assert_close(b, a, **TOL)
    torch.testing.assert_close(obs.predict(x, 4, u, t=tu), obs.predict(x, 4, u), **TOL)
    t = _random_times(2)
    est = obs.observe(x, u, t=t)
    torch.testing.assert_close(est.x_hat[:, 1:], est.x_hat[:, :-1] + t.diff(dim=-1)[..., None] * est.f_hat[:, :-1],
                               **TOL)
    torch.testing.assert_close(obs.predict(x, 3, u, t=t), F.cascade_predict(PLANT, x, None, 3, F.Gains(3.0), u=u,
                                                                            measurement=F.Measurement(t=t)), **TOL)
    with pytest.raises(F.feedback.gains.GainError):
        F.LinearFeedback(PLANT, TS, gains=F.Gains(25.0), n=2).observe(x, u, t=t * 2)  # rho(I - Delta L) > 1 at the longest interval


def test_the_varying_gain_scan_equals_its_loop():
    """varying_gain_filter (a doubling scan) against the plain recursion, random plants, gains and inputs."""
    from fnnlib.observers.augmented import varying_gain_filter

    g = torch.Generator().manual_seed(7)
    R, m, p, q = 3, 4, 2, 2
    h = 0.02 + 0.1 * torch.rand(R, T - 1, dtype=F64, generator=g)
    A_, B_, C_ = augmented_matrices(2, TS)
    Ak, Bk = augmented_step(A_, B_, TS, h)
    M = 0.3 * torch.rand(R, T, m, q, dtype=F64, generator=g)
    u, y = torch.randn(R, T, p, dtype=F64, generator=g), torch.randn(R, T, q, dtype=F64, generator=g)
    got = varying_gain_filter(Ak, Bk, C_, M, u, y)
    prior = torch.cat([y[:, 0], torch.zeros(R, 2, dtype=F64)], -1)
    for k in range(T):
        z = prior + ((y[:, k] - prior @ C_.T)[:, None, :] @ M[:, k].mT)[:, 0]
        torch.testing.assert_close(got[:, k], z, rtol=0, atol=1e-12)
        if k < T - 1:
            prior = (Ak[:, k] @ z[..., None])[..., 0] + (Bk[:, k] @ u[:, k, :, None])[..., 0]


def test_ackermann_per_interval_equals_pole_placement():
    """With one output the gain placing given poles is unique: the batched Ackermann gains equal control.place's."""
    from fnnlib.observers.luenberger import _ackermann, place_observer_gain

    obs = F.LuenbergerObserver(PLANT, TS, n=2, poles=[0.7, 0.75, 0.8], C=C, disturbance=[1], A=A)
    hs = [0.01, 0.03, 0.2]
    Phis = np.stack([obs._linearised(A, h).numpy() for h in hs])
    L = _ackermann(Phis, C.numpy() @ np.eye(2, 3), [0.7, 0.75, 0.8])
    for j in range(len(hs)):
        ref = place_observer_gain(Phis[j], obs.C, [0.7, 0.75, 0.8]).numpy()
        np.testing.assert_allclose(L[j], ref, rtol=1e-8, atol=1e-10)
