"""The linear feedback Eqs. (7)-(8): a hand-computed step, Theorem 1's balls, and the input checks."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fnnlib import DynamicalSystem, GainError, LinearFeedback, check_gain, decayed_gains
from fnnlib.feedback import GainWarning, spectral_radius, Gains
from fnnlib.systems import Spiral

F64 = torch.float64


# --- one step by hand ------------------------------------------------------------------------------------------

def test_observer_equations_by_hand():
    W = [[-0.5, 1.0], [-1.0, -0.5]]
    L = [[2.0, 0.5], [0.5, 1.0]]
    Ts = 0.1
    xs = [[1.0, 0.0], [0.9, -0.2], [0.7, -0.35]]

    def mv(M, v):  # matrix times vector, plain floats
        return [M[0][0] * v[0] + M[0][1] * v[1], M[1][0] * v[0] + M[1][1] * v[1]]

    def add(*vs):
        return [sum(v[i] for v in vs) for i in range(2)]

    def scale(c, v):
        return [c * v[0], c * v[1]]

    # Eq. (8) starts at x_hat_0 = x_0; Eq. (7) f_hat = f(x) + L (x - x_hat); Eq. (8) x_hat += Ts f_hat
    xh0 = xs[0]
    fh0 = add(mv(W, xs[0]), mv(L, add(xs[0], scale(-1, xh0))))  # = W x_0
    xh1 = add(xh0, scale(Ts, fh0))
    fh1 = add(mv(W, xs[1]), mv(L, add(xs[1], scale(-1, xh1))))
    xh2 = add(xh1, scale(Ts, fh1))
    fh2 = add(mv(W, xs[2]), mv(L, add(xs[2], scale(-1, xh2))))
    # the numbers themselves, worked out on paper for x_hat_1 and f_hat_0
    assert fh0 == pytest.approx([-0.5, -1.0])
    assert xh1 == pytest.approx([0.95, -0.1])

    Wt = torch.tensor(W, dtype=F64)
    est = LinearFeedback(lambda t, x: x @ Wt.T, Ts, gains=Gains(torch.tensor(L, dtype=F64)), n=2).observe(torch.tensor(xs, dtype=F64))
    torch.testing.assert_close(est.x_hat, torch.tensor([xh0, xh1, xh2], dtype=F64), rtol=0, atol=1e-14)
    torch.testing.assert_close(est.f_hat, torch.tensor([fh0, fh1, fh2], dtype=F64), rtol=0, atol=1e-14)


def test_zero_gain_is_open_loop_euler():
    f = Spiral(2.0, 0.1, 0.0)
    x = Spiral(2.0, 0.1, 0.0).simulate(torch.tensor([1.0, 0.0]), torch.linspace(0, 1, 11))
    est = LinearFeedback(f, 0.1, gains=Gains(0.0), n=2).observe(x)
    xh = [x[0]]
    for k in range(10):
        xh.append(xh[-1] + 0.1 * f(0.0, x[k][None])[0])  # x_hat_{k+1} = x_hat_k + Ts f(x_k)
    torch.testing.assert_close(est.x_hat, torch.stack(xh), rtol=0, atol=1e-13)
    torch.testing.assert_close(est.f_hat, f.rate(x), rtol=0, atol=1e-13)


def test_batched_observe_equals_per_trajectory():
    x = Spiral(2.0, 0.1, 0.0).simulate(torch.randn(2, 3, 2, dtype=F64, generator=torch.Generator().manual_seed(0)),
                          torch.linspace(0, 2, 21))
    obs = LinearFeedback(Spiral(2.0, 0.3, 0.0), 0.1, gains=Gains(torch.tensor([3.0, 5.0])), n=2)
    est = obs.observe(x)
    assert est.x_hat.shape == est.f_hat.shape == (2, 3, 21, 2)
    for i in range(2):
        for j in range(3):
            one = obs.observe(x[i, j])
            torch.testing.assert_close(est.x_hat[i, j], one.x_hat, rtol=0, atol=1e-13)
            torch.testing.assert_close(est.f_hat[i, j], one.f_hat, rtol=0, atol=1e-13)


# --- Theorem 1 on a linear system with a known bounded residual -------------------------------------------------

class Disturbed(DynamicalSystem):
    """x' = A x + d(t), d(t) = gamma [sin t, cos t], so ||d(t)|| = gamma exactly."""

    n = 2

    def __init__(self, A: torch.Tensor, gamma: float):
        self.A, self.gamma = A, float(gamma)

    def d(self, t: torch.Tensor) -> torch.Tensor:
        t = torch.as_tensor(t, dtype=F64)
        return self.gamma * torch.stack([torch.sin(t), torch.cos(t)], dim=-1)

    def __call__(self, t, x):
        return x @ self.A.T + self.d(t)

    def exact(self, x0: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """Closed form: x = x_p(t) + e^{A t}(x0 - x_p(0)), x_p = P sin t + Q cos t the periodic solution.

        Matching sin and cos terms in x_p' = A x_p + d gives P = A Q + gamma e2 and -Q = A P + gamma e1,
        so (A^2 + I) Q = -gamma (A e2 + e1).
        """
        A, g = self.A, self.gamma
        e1, e2 = torch.tensor([1.0, 0.0], dtype=F64), torch.tensor([0.0, 1.0], dtype=F64)
        Q = torch.linalg.solve(A @ A + torch.eye(2, dtype=F64), -g * (A @ e2 + e1))
        P = A @ Q + g * e2
        xp = torch.sin(t)[:, None] * P + torch.cos(t)[:, None] * Q
        expAt = torch.linalg.matrix_exp(A * t[:, None, None])
        return xp + (expAt @ (x0 - Q)[:, None]).squeeze(-1)


A_TRUE = Spiral(2.0, 0.1, 0.0).A
X0 = torch.tensor([1.0, 0.0], dtype=F64)


def _theorem1_case(gamma: float, L: torch.Tensor, Ts: float, t_end: float, x: torch.Tensor | None = None):
    """Run the observer with f = A x (so Delta f = d) and return (x_err, f_err, ball1, ball2, slack).

    The observer is an Euler discretisation, Eq. (25): with r_k the Euler remainder of the true
    trajectory over one step, x_err_{k+1} = (I - Ts L) x_err_k + Ts d_k + r_k, ||r_k|| <= Ts^2 M2 / 2,
    M2 = sup ||x''||. For symmetric L with Ts (lambda_min + lambda_max) <= 2, ||I - Ts L|| = 1 - Ts lambda_min,
    so from x_err_0 = 0 every step obeys ||x_err|| <= gamma / lambda_min + slack, slack = Ts M2 / (2 lambda_min):
    Theorem 1's ball plus the Euler discretisation slack, which vanishes as Ts -> 0.
    """
    system = Disturbed(A_TRUE, gamma)
    t = torch.arange(round(t_end / Ts) + 1, dtype=F64) * Ts
    if x is None:
        x = system.exact(X0, t)
    xdot = x @ A_TRUE.T + system.d(t)
    ddot = gamma * torch.stack([torch.cos(t), -torch.sin(t)], dim=-1)
    M2 = 1.05 * float((xdot @ A_TRUE.T + ddot).norm(dim=-1).max())  # 5 %: sup between samples vs at samples
    est = LinearFeedback(lambda _t, z: z @ A_TRUE.T, Ts, gains=Gains(L), n=2).observe(x)
    Lm = L if L.ndim == 2 else (torch.diag(L) if L.ndim == 1 else L * torch.eye(2, dtype=F64))
    eigs = torch.linalg.eigvalsh(Lm)
    lam_min, lam_max = float(eigs.min()), float(eigs.max())
    assert Ts * (lam_min + lam_max) <= 2
    slack = Ts * M2 / (2 * lam_min)
    ball1 = gamma / lam_min
    ball2 = gamma * lam_max / lam_min + gamma
    x_err = (x - est.x_hat).norm(dim=-1)
    f_err = (xdot - est.f_hat).norm(dim=-1)  # f_tilde = d - L x_tilde
    return x_err, f_err, ball1, ball2, slack, lam_max


def test_disturbed_closed_form_matches_simulation():
    system = Disturbed(A_TRUE, 0.7)
    t = torch.linspace(0.0, 10.0, 41, dtype=F64)
    # dopri5 at rtol = atol = 1e-10 on states of size ~1
    torch.testing.assert_close(system.exact(X0, t), system.simulate(X0, t), rtol=0, atol=1e-8)


@pytest.fixture(scope="module")
def accurate_trajectory():
    """x' = A x + 0.5 [sin t, cos t] from X0, sampled at Ts = 1e-3 over 10 s (closed form)."""
    Ts, t_end = 1e-3, 10.0
    t = torch.arange(round(t_end / Ts) + 1, dtype=F64) * Ts
    return Disturbed(A_TRUE, 0.5).exact(X0, t)


@pytest.mark.parametrize("L", [
    torch.tensor(5.0, dtype=F64),
    torch.tensor([2.0, 8.0], dtype=F64),
    torch.tensor([[4.0, 1.5], [1.5, 3.0]], dtype=F64),
], ids=["scalar", "diagonal", "full_spd"])
def test_theorem1_balls(L, accurate_trajectory):
    gamma, Ts = 0.5, 1e-3
    x_err, f_err, ball1, ball2, slack, lam_max = _theorem1_case(gamma, L, Ts, 10.0, accurate_trajectory)
    assert slack < 0.01 * ball1  # Ts = 1e-3: the discretisation slack is a small correction
    after = slice(round(3.0 / Ts), None)  # after the transient (3 s >> 1/lambda_min)
    assert float(x_err.max()) <= ball1 + slack  # from x_err_0 = 0 the bound holds at every step
    assert float(x_err[after].max()) <= ball1 + slack
    assert float(f_err[after].max()) <= ball2 + lam_max * slack
    # not vacuous: the observer error does reach a good part of the ball (d turns at 1 rad/s)
    assert float(x_err[after].max()) > 0.3 * ball1


def test_theorem1_ball_shrinks_with_gain(accurate_trajectory):
    errs = [float(_theorem1_case(0.5, torch.tensor(g, dtype=F64), 1e-3, 10.0, accurate_trajectory)[0][3000:].max())
            for g in (1.0, 4.0, 16.0)]
    assert errs[0] > errs[1] > errs[2]


@settings(max_examples=25, deadline=None)
@given(lam1=st.floats(0.3, 50.0), lam2=st.floats(0.3, 50.0), angle=st.floats(0.0, math.pi),
       gamma=st.floats(0.01, 5.0))
def test_property_theorem1_random_spd_gain(lam1, lam2, angle, gamma):
    Ts = 1e-2
    c, s = math.cos(angle), math.sin(angle)
    Q = torch.tensor([[c, -s], [s, c]], dtype=F64)
    L = Q @ torch.diag(torch.tensor([lam1, lam2], dtype=F64)) @ Q.T
    L = 0.5 * (L + L.T)
    assert spectral_radius(torch.eye(2, dtype=F64) - Ts * L) < 1  # lambdas <= 50 = 0.5 / Ts
    x_err, f_err, ball1, ball2, slack, lam_max = _theorem1_case(gamma, L, Ts, 8.0)
    assert float(x_err.max()) <= ball1 + slack
    assert float(f_err.max()) <= ball2 + lam_max * slack


# --- discrete stability, App. A.2 -------------------------------------------------------------------------------

@pytest.mark.parametrize("L", [2.5 / 0.01, -1.0], ids=["rho_1.5", "negative_definite"])
def test_allow_unstable_lets_bad_gains_through_and_the_error_diverges(L):
    Ts, gamma = 0.01, 0.5
    t = torch.arange(801, dtype=F64) * Ts
    x = Disturbed(A_TRUE, gamma).exact(X0, t)
    with pytest.raises(GainError):
        LinearFeedback(lambda _t, z: z @ A_TRUE.T, Ts, gains=Gains(L), n=2)
    est = LinearFeedback(lambda _t, z: z @ A_TRUE.T, Ts, gains=Gains(L, allow_unstable=True), n=2).observe(x)
    err = (x - est.x_hat).norm(dim=-1)
    # a stable gain with lambda = 1 keeps the error under gamma + slack; these blow far past it
    assert float(err[-1]) > 100 * gamma
    assert float(err[-1]) > 10 * float(err[len(err) // 2])


def test_zero_gain_is_accepted():
    M = check_gain(0.0, 2, 0.1)
    assert torch.equal(M, torch.zeros(2, 2, dtype=F64))
    LinearFeedback(Spiral(2.0, 0.1, 0.0), 0.1, gains=Gains(torch.zeros(2, 2)), n=2)


def test_check_gain_returns_matrix_forms():
    torch.testing.assert_close(check_gain(3.0, 2, 0.1), 3.0 * torch.eye(2, dtype=F64))
    torch.testing.assert_close(check_gain([1.0, 2.0], 2, 0.1), torch.diag(torch.tensor([1.0, 2.0], dtype=F64)))


def test_decayed_gains_follow_eq11():
    L = torch.tensor([[4.0, 1.0], [1.0, 3.0]], dtype=F64)
    gains = decayed_gains(L, 4, 0.05)
    assert len(gains) == 4
    for i, Li in enumerate(gains):
        torch.testing.assert_close(Li, L * math.exp(-0.05 * i), rtol=1e-15, atol=0)


# --- bad inputs -------------------------------------------------------------------------------------------------

def _obs(L=1.0, Ts=0.1, n=2, **kw):
    return LinearFeedback(Spiral(2.0, 0.1, 0.0), Ts, gains=Gains(L), n=n, **kw)


@pytest.mark.parametrize("L", [-1.0, torch.tensor([[1.0, 3.0], [3.0, 1.0]])], ids=["negative", "indefinite"])
def test_gain_not_positive_definite(L):
    with pytest.raises(GainError, match=r"not positive definite .*lambda_min\(L\) > 0"):
        _obs(L)


def test_semidefinite_gain_is_accepted_with_a_warning_naming_the_uncorrected_state():
    with pytest.warns(GainWarning, match=r"positive semidefinite: states \[1\] are not corrected"):
        obs = _obs(torch.tensor([1.0, 0.0]))
    torch.testing.assert_close(obs.L, torch.diag(torch.tensor([1.0, 0.0], dtype=torch.float64)))
    with pytest.raises(GainError, match=r"not positive definite .*lambda_min\(L\) > 0"):
        check_gain(torch.tensor([1.0, 0.0]), 2, 0.1, allow_semidefinite=False)
    with pytest.raises(GainError, match=r"rho\(I - Ts L\) = 1\.5 >= 1"):  # the corrected state is still checked
        with pytest.warns(GainWarning):
            check_gain(torch.tensor([25.0, 0.0]), 2, 0.1)


def test_gain_makes_discrete_dynamics_unstable():
    with pytest.raises(GainError, match=r"rho\(I - Ts L\) = 1\.5 >= 1"):
        _obs(25.0, Ts=0.1)
    with pytest.raises(GainError, match=r"rho\(I - Ts L\) = 1 >= 1"):
        _obs(20.0, Ts=0.1)  # exactly on the unit circle is refused too


def test_gain_error_is_a_value_error():
    assert issubclass(GainError, ValueError)


def test_gain_with_nan():
    with pytest.raises(GainError, match="NaN or infinite"):
        _obs(float("nan"))


@pytest.mark.parametrize("L, match", [(torch.ones(3), r"gain L must be a scalar, a vector of length 2 or an \(2, 2\)"),
                                      (torch.ones(2, 3), r"Gains.L must be a scalar, a vector \(n,\) or a square"),
                                      (torch.ones(2, 2, 2), r"Gains.L must be a scalar, a vector \(n,\) or a square")])
def test_wrong_gain_shape(L, match):
    with pytest.raises(ValueError, match=match):
        _obs(L)


def test_nan_in_measurements():
    x = torch.zeros(5, 2, dtype=F64)
    x[3, 1] = float("nan")
    with pytest.raises(ValueError, match=r"x holds a NaN value \(first at index \(3, 1\)\)"):
        _obs().observe(x)


def test_inf_in_measurements():
    x = torch.zeros(5, 2, dtype=F64)
    x[0, 0] = float("inf")
    with pytest.raises(ValueError, match="x holds a infinite value"):
        _obs().observe(x)


def test_wrong_state_dimension():
    with pytest.raises(ValueError, match=r"x has state dimension 3 .*expected n = 2"):
        _obs().observe(torch.zeros(5, 3, dtype=F64))


def test_too_few_axes():
    with pytest.raises(ValueError, match=r"shape \(\.\.\., T, n\) with at least 2 axes"):
        _obs().observe(torch.zeros(2, dtype=F64))


@pytest.mark.parametrize("x", [[[0.0, 0.0]], torch.zeros(3, 2, dtype=torch.int64)], ids=["list", "int_tensor"])
def test_non_tensor_or_integer_measurements(x):
    with pytest.raises(TypeError, match="must be a torch.Tensor|floating-point tensor"):
        _obs().observe(x)


@pytest.mark.parametrize("Ts", [0.0, -0.1, float("nan"), float("inf")])
def test_bad_sample_step(Ts):
    with pytest.raises(ValueError, match="Ts must be a finite positive"):
        _obs(Ts=Ts)
    with pytest.raises(ValueError, match="Ts must be a finite positive"):
        check_gain(1.0, 2, Ts)


@pytest.mark.parametrize("beta", [-0.01, float("nan")])
def test_bad_decay_rate(beta):
    with pytest.raises(ValueError, match="decay rate beta must be finite and >= 0"):
        decayed_gains(torch.eye(2), 3, beta)


def test_vector_field_with_wrong_output_shape():
    obs = LinearFeedback(lambda t, x: x[:, :1], 0.1, gains=Gains(1.0), n=2)
    with pytest.raises(ValueError, match=r"vector field returned shape \(5, 1\) for input \(5, 2\)"):
        obs.observe(torch.zeros(5, 2, dtype=F64))
