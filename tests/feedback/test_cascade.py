"""Multi-step prediction: the vectorised cascade (Sec. 3.3, Eq. (11)) against loops and Euler rollouts."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib import cascade_predict, rollout_predict
from fnnlib.feedback import cascade_predict_loop, Gains, cascade_depths, rollout_depths
from fnnlib.systems import Spiral

F64 = torch.float64
TS = 0.1

GAINS = {
    "scalar": torch.tensor(2.0, dtype=F64),
    "vector": torch.tensor([1.0, 3.0], dtype=F64),
    "full_spd": torch.tensor([[3.0, 1.0], [1.0, 2.0]], dtype=F64),
}


@pytest.fixture(scope="module")
def x():
    return Spiral(omega=3.0, eta=0.05, eps=1.0).exact_solution(torch.tensor([2.0, 0.0]),
                                                                torch.arange(25, dtype=F64) * TS)


def streaming_reference(f, x, Ts, N, L, beta):
    """Independent streaming form: layer i's estimate starts at its own first input z^(i)_0 (Eq. (8), x_hat_0 = x_0).

    Layer i (gain L e^{-beta i}, Eq. (11)) receives z^(i)_k, the previous layer's one-step prediction;
    f_hat = f(z) + L_i (z - x_hat^(i)) (Eq. (7)); x_hat^(i) += Ts f_hat; z^(i+1) = z^(i) + Ts f_hat.
    """
    T, n = x.shape
    Lm = L if L.ndim == 2 else (torch.diag(L) if L.ndim == 1 else L * torch.eye(n, dtype=F64))
    x_hat = [None] * N
    out = []
    for k in range(T):
        z = x[k]
        for i in range(N):
            Li = Lm * math.exp(-beta * i)
            if x_hat[i] is None:
                x_hat[i] = z.clone()
            f_hat = f(0.0, z[None])[0] + Li @ (z - x_hat[i])
            x_hat[i] = x_hat[i] + Ts * f_hat
            z = z + Ts * f_hat
        out.append(z)
    return torch.stack(out)


@pytest.mark.parametrize("N", [1, 4])
def test_zero_gain_equals_euler_rollout(f, x, N):
    torch.testing.assert_close(cascade_predict(f, x, TS, N, Gains(0.0)), rollout_predict(f, x, TS, N),
                               rtol=0, atol=1e-6)
    torch.testing.assert_close(cascade_depths(f, x, TS, N, Gains(0.0)),
                               rollout_depths(f, x, TS, N), rtol=0, atol=1e-6)


@pytest.mark.parametrize("N", [1, 3, 7])
@pytest.mark.parametrize("beta", [0.0, 0.05])
@pytest.mark.parametrize("gain", list(GAINS))
def test_vectorised_equals_loop(f, x, gain, beta, N):
    fast = cascade_predict(f, x, TS, N, Gains(GAINS[gain], beta))
    slow = cascade_predict_loop(f, x, TS, N, Gains(GAINS[gain], beta))
    torch.testing.assert_close(fast, slow, rtol=0, atol=1e-6)


@pytest.mark.parametrize("N", [1, 3, 7])
@pytest.mark.parametrize("beta", [0.0, 0.05])
@pytest.mark.parametrize("gain", list(GAINS))
def test_vectorised_equals_streaming_reference(f, x, gain, beta, N):
    fast = cascade_predict(f, x, TS, N, Gains(GAINS[gain], beta))
    torch.testing.assert_close(fast, streaming_reference(f, x, TS, N, GAINS[gain], beta), rtol=0, atol=1e-6)


def test_return_all_shapes_and_depths(f, x):
    xb = torch.stack([x, 0.5 * x, -x]).reshape(3, 1, *x.shape).expand(3, 2, *x.shape)  # (3, 2, T, n)
    N = 4
    all_depths = cascade_depths(f, xb, TS, N, Gains(GAINS["full_spd"], 0.05))
    assert all_depths.shape == (N + 1, 3, 2, *x.shape)
    assert torch.equal(all_depths[0], xb)
    torch.testing.assert_close(all_depths[-1], cascade_predict(f, xb, TS, N, Gains(GAINS["full_spd"], 0.05)),
                               rtol=0, atol=1e-14)
    # depth d of an N-deep cascade is the d-deep cascade (later layers do not feed back)
    torch.testing.assert_close(all_depths[2], cascade_predict(f, xb, TS, 2, Gains(GAINS["full_spd"], 0.05)),
                               rtol=0, atol=1e-14)


def test_batched_equals_per_trajectory(f, x):
    xb = torch.stack([x, x.flip(0), 0.3 * x])  # (3, T, n)
    out = cascade_predict(f, xb, TS, 3, Gains(GAINS["vector"], 0.05))
    roll = rollout_predict(f, xb, TS, 3)
    for i in range(3):
        torch.testing.assert_close(out[i], cascade_predict(f, xb[i], TS, 3, Gains(GAINS["vector"], 0.05)),
                                   rtol=0, atol=1e-13)
        torch.testing.assert_close(roll[i], rollout_predict(f, xb[i], TS, 3), rtol=0, atol=1e-13)


@pytest.mark.parametrize("N", [0, -2, 2.5])
def test_bad_N(f, x, N):
    for fn in (cascade_predict, cascade_predict_loop):
        with pytest.raises(ValueError, match="number of prediction steps N must be an integer >= 1"):
            fn(f, x, TS, N, Gains(1.0))
    with pytest.raises(ValueError, match="number of prediction steps N must be an integer >= 1"):
        rollout_predict(f, x, TS, N)


def test_bad_inputs(f, x):
    with pytest.raises(ValueError, match="Ts must be a finite positive"):
        cascade_predict(f, x, 0.0, 2, Gains(1.0))
    with pytest.raises(ValueError, match="decay rate beta must be finite and >= 0"):
        cascade_predict(f, x, TS, 2, Gains(1.0, -0.1))
    with pytest.raises(TypeError, match="must be a torch.Tensor"):
        cascade_predict(f, x.tolist(), TS, 2, Gains(1.0))
    bad = x.clone()
    bad[4, 0] = float("inf")  # a NaN is a missing sample (tests/feedback/test_gaps.py); inf is an error
    with pytest.raises(ValueError, match="x holds an infinite value"):
        cascade_predict(f, bad, TS, 2, Gains(1.0))
    with pytest.raises(ValueError, match="x holds a NaN value"):
        cascade_predict_loop(f, torch.where(torch.isinf(bad), float("nan"), bad), TS, 2, Gains(1.0))
    with pytest.raises(ValueError, match="not positive definite"):
        cascade_predict(f, x, TS, 2, Gains(-1.0))
    with pytest.raises(ValueError, match="one trajectory of shape"):
        cascade_predict_loop(f, x[None], TS, 2, Gains(1.0))


def test_allow_unstable_passes_through(f, x):
    out = cascade_predict(f, x, TS, 2, Gains(-1.0, allow_unstable=True))
    assert out.shape == x.shape


def test_perfect_model_on_spiral_is_at_euler_level():
    spiral = Spiral(omega=2.0, eta=0.1, eps=0.5)
    Ts, T, N = 0.02, 500, 10
    t = torch.arange(T, dtype=F64) * Ts
    x = spiral.exact_solution(torch.tensor([2.0, 0.0]), t)
    # Euler global error after N steps: e_N <= Ts M2 / (2 Lip) (e^{Lip N Ts} - 1), M2 = sup ||x''||
    A = spiral.A
    M2 = 1.05 * float(((x @ A.T + spiral.b) @ A.T).norm(dim=-1).max())  # x'' = A x'; 5 % for sup vs samples
    lip = float(torch.linalg.matrix_norm(A, 2))
    bound = Ts * M2 / (2 * lip) * (math.exp(lip * N * Ts) - 1)
    after = slice(100, None)  # past the observer transient (2 s)
    truth = x[N:]
    roll_err = (rollout_predict(spiral, x, Ts, N)[:-N] - truth).norm(dim=-1)[after]
    assert float(roll_err.max()) <= bound
    for L in (1.0, 5.0, 20.0):
        casc_err = (cascade_predict(spiral, x, Ts, N, Gains(L))[:-N] - truth).norm(dim=-1)[after]
        assert float(casc_err.max()) <= bound
        assert float(casc_err.mean()) <= float(roll_err.mean()) + 1e-12
