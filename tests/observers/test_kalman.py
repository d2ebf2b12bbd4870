"""Kalman filters: the steady-state gain is the Riccati solution of control.dlqe, filterpy converges to it,
the scan equals filterpy's filter, the EKF's Jacobian is the model's, and bad covariances are refused."""

from __future__ import annotations

import control
import numpy as np
import pytest
import torch

from fnnlib import add_measurement_noise
from fnnlib.seeding import make_generator
from fnnlib.systems import Spiral
from fnnlib.observers import ExtendedKalmanObserver, KalmanObserver, augmented_matrices, steady_state_gain, Covariances

F64 = torch.float64
TS = 0.01
Q_AUG = [1e-8, 1e-8, 1e-2, 1e-2]
R_AUG = 1e-4


def _dlqe(A, C, Q, R):
    L, P, _ = control.dlqe(np.asarray(A), np.eye(np.asarray(A).shape[0]), np.asarray(C), np.asarray(Q), np.asarray(R))
    return L, P


def _riccati_iteration(A, C, Q, R, tol=1e-13, max_iter=200_000):
    """The test reference: the Riccati difference equation iterated from P = Q to its fixed point."""
    A, C, Q, R = (np.asarray(M, dtype=float) for M in (A, C, Q, R))
    P = Q.copy()
    for _ in range(max_iter):
        S = C @ P @ C.T + R
        AK = A @ np.linalg.solve(S, C @ P).T
        P_next = A @ P @ A.T + Q - AK @ S @ AK.T
        P_next = 0.5 * (P_next + P_next.T)
        if np.max(np.abs(P_next - P)) <= tol * max(1.0, np.max(np.abs(P_next))):
            return P_next
        P = P_next
    raise AssertionError("the reference iteration did not converge")


@pytest.mark.parametrize("case", ["augmented", "augmented_slow_drift", "random_stable"])
def test_steady_state_gain_equals_dlqe(case):
    if case.startswith("augmented"):
        A, _, C = augmented_matrices(2, TS)
        Q = np.diag(Q_AUG) if case == "augmented" else np.diag([1e-6, 1e-6, 1e-5, 1e-5])
        R = R_AUG * np.eye(2)
    else:
        rng = np.random.default_rng(3)
        A = rng.normal(size=(3, 3))
        A *= 0.9 / np.max(np.abs(np.linalg.eigvals(A)))
        C, Q, R = rng.normal(size=(2, 3)), np.diag([0.1, 0.2, 0.3]), np.array([[0.5, 0.1], [0.1, 0.4]])
    ss = steady_state_gain(A, C, Q, R)
    L, P = _dlqe(A, C, Q, R)
    np.testing.assert_allclose(ss.P, _riccati_iteration(A, C, Q, R), rtol=1e-7, atol=1e-14)  # the old fixed point (its stop rule leaves ~5e-9)
    np.testing.assert_allclose(ss.L, L, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(ss.P, P, rtol=1e-7, atol=1e-12)
    A, C = np.asarray(A), np.asarray(C)
    np.testing.assert_allclose(ss.L, A @ ss.K, rtol=1e-12)  # predictor gain = A x filter gain
    # P solves the discrete algebraic Riccati equation
    S = C @ P @ C.T + R
    residual = A @ P @ A.T + Q - A @ P @ C.T @ np.linalg.solve(S, C @ P @ A.T) - P
    assert np.abs(residual).max() < 1e-9 * np.abs(P).max()


def test_filterpy_gain_converges_to_the_stationary_gain():
    kf = KalmanObserver(Spiral(2.0, 0.1, 0.0), TS, n=2, cov=Covariances(Q_AUG, R_AUG))
    K = kf.gain_history(400)
    err = np.abs(K - kf.stationary.K).max(axis=(1, 2)) / np.abs(kf.stationary.K).max()
    assert err[0] > 1e-2  # started away from it (P0 large on d)
    assert err[-1] < 1e-9  # the stationary K is itself accurate to ~1e-11 (Riccati iteration tolerance)
    assert err[60] < 1e-3 * err[5]  # geometric approach, not a drift


def _data(T=150, std=0.01):
    t = torch.arange(T, dtype=F64) * TS
    x = Spiral(3.0, 0.05, 10.0).simulate(torch.tensor([9.0, 0.0]), t)
    return x, add_measurement_noise(x, std, make_generator(0))


def test_scan_equals_filterpy_when_started_at_steady_state():
    # with P0 = the stationary prior, filterpy's time-varying filter is the stationary one from k = 0
    _, y = _data()
    model = Spiral(2.0, 0.1, 0.0)
    P_ss = KalmanObserver(model, TS, n=2, cov=Covariances(Q_AUG, R_AUG)).stationary.P
    loop = KalmanObserver(model, TS, n=2, cov=Covariances(Q_AUG, R_AUG, P0=torch.as_tensor(P_ss))).estimate(y)
    scan = KalmanObserver(model, TS, n=2, cov=Covariances(Q_AUG, R_AUG, P0=torch.as_tensor(P_ss)), steady_state=True).estimate(y)
    torch.testing.assert_close(scan.x_hat, loop.x_hat, rtol=0, atol=1e-9)
    torch.testing.assert_close(scan.d_hat, loop.d_hat, rtol=0, atol=1e-7)


def test_kalman_learns_a_constant_disturbance_of_its_own_model():
    model, d = Spiral(2.0, 0.1, 0.0), torch.tensor([3.0, -1.5], dtype=F64)
    xs = [torch.tensor([9.0, 0.0], dtype=F64)]
    for _ in range(399):
        xs.append(xs[-1] + TS * (model(0.0, xs[-1][None])[0] + d))  # x_{k+1} = x_k + Ts (f(x_k) + d)
    for obs in (KalmanObserver(model, TS, n=2, cov=Covariances(Q_AUG, R_AUG)), ExtendedKalmanObserver(model, TS, n=2,
                                                                                   cov=Covariances(Q_AUG, R_AUG))):
        est = obs.estimate(torch.stack(xs))
        assert float((est.d_hat[-1] - d).norm()) < 1e-6, type(obs).__name__


def test_ekf_jacobian_is_the_model_jacobian():
    model = Spiral(2.0, 0.1, 3.0)  # f(x) = A x + b: J = A everywhere
    ekf = ExtendedKalmanObserver(model, TS, n=2, cov=Covariances(Q_AUG, R_AUG))
    z = np.array([[1.0], [2.0], [0.5], [-0.25]])
    z_next, F = ekf._step(z, F64)
    A, _, _ = augmented_matrices(2, TS)
    expected = A.numpy().copy()
    expected[:2, :2] += TS * model.A.numpy()
    np.testing.assert_allclose(F, expected, rtol=0, atol=1e-14)
    x = torch.tensor([[1.0, 2.0]], dtype=F64)
    np.testing.assert_allclose(z_next[:2, 0], (x + TS * (model(0.0, x) + torch.tensor([0.5, -0.25]))).numpy()[0],
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(z_next[2:, 0], [0.5, -0.25])


def test_ekf_batched_equals_per_trajectory():
    x, y = _data(T=40)
    ekf = ExtendedKalmanObserver(Spiral(2.0, 0.1, 0.0), TS, n=2, cov=Covariances(Q_AUG, R_AUG))
    batch = ekf.estimate(torch.stack([y, x]))
    torch.testing.assert_close(batch.d_hat[0], ekf.estimate(y).d_hat, rtol=0, atol=1e-12)
    torch.testing.assert_close(batch.d_hat[1], ekf.estimate(x).d_hat, rtol=0, atol=1e-12)


@pytest.mark.parametrize("kwargs, match", [
    ({"Q": [1e-8, 1e-8, -1.0, 1e-2]}, "Q must be positive semi-definite"),
    ({"Q": torch.tensor([[1.0, 2, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=F64)}, "symmetric"),
    ({"R": 0.0}, "R must be positive definite"),
    ({"R": [1e-4, float("nan")]}, "finite symmetric"),
    ({"P0": [1.0, 1.0, 1.0]}, "P0 must be a scalar, a vector of length 4"),
], ids=["Q_negative", "Q_not_symmetric", "R_zero", "R_nan", "P0_shape"])
def test_bad_covariances_are_refused(kwargs, match):
    args = {"Q": Q_AUG, "R": R_AUG} | kwargs
    for cls in (KalmanObserver, ExtendedKalmanObserver):
        with pytest.raises(ValueError, match=match):  # the covariances refuse what they can see on their own
            cls(Spiral(2.0, 0.1, 0.0), TS, n=2, cov=Covariances(**args))


def test_an_undetectable_pair_has_no_stationary_gain():
    A = np.diag([1.2, 0.5])  # the unstable mode is not seen by C
    with pytest.raises(RuntimeError, match="detectable"):
        steady_state_gain(A, np.array([[0.0, 1.0]]), np.eye(2), np.eye(1))


def test_filterpy_is_imported_only_where_a_filter_is_made():
    """filterpy (with scipy.stats, ~0.25 s) is not loaded by fnnlib's face, the observers or the training code, which
    every notebook kernel imports; making a Kalman filter loads it."""
    import subprocess  # noqa: PLC0415
    import sys  # noqa: PLC0415

    code = ("import sys, torch, fnnlib as F, fnnlib.observers, fnnlib.training; F.KalmanObserver; "
            "F.UnscentedKalmanObserver; F.ExtendedKalmanObserver; print('filterpy' in sys.modules); "
            "from fnnlib.observers.kalman import _learned_model_ekf; _learned_model_ekf(); "
            "print('filterpy' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False", "True"], done.stdout
