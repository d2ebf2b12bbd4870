"""Affine models of a torch step along a plan: finite differences, the offset c_k, dtypes and input checks."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from fnnlib.quadrotor.mpc import LinearizedMPC, linearize

F64 = torch.float64
METHODS = ("reverse", "vmap")


class CartModel(nn.Module):
    """RK4 of a 4-state nonlinear system with an MLP inside, plus a per-step correction depending on k."""

    def __init__(self, Ts: float = 0.1, dtype: torch.dtype = F64) -> None:
        super().__init__()
        torch.manual_seed(3)
        self.Ts = Ts
        self.mlp = nn.Sequential(nn.Linear(4, 16), nn.Tanh(), nn.Linear(16, 2)).to(dtype)

    def f(self, x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        p, th, v, w = x.unbind(-1)
        drift = 0.3 * self.mlp(torch.stack([p, th.sin(), th.cos(), v * w], -1))
        acc = u[:, 0] - 0.2 * v * v.abs() + drift[:, 0]
        alpha = -9.81 * th.sin() + u[:, 1] * th.cos() - 0.1 * w + drift[:, 1]
        return torch.stack([v, w, acc, alpha], -1)

    def forward(self, x: torch.Tensor, u: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
        h = self.Ts
        k1 = self.f(x, u)
        k2 = self.f(x + h / 2 * k1, u)
        k3 = self.f(x + h / 2 * k2, u)
        k4 = self.f(x + h * k3, u)
        correction = 0.01 * k.to(x.dtype)[:, None] * torch.tanh(x)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4) + correction


def plan(N: int = 6, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(size=(N, 4)), rng.normal(size=(N, 2))


def central_differences(model: nn.Module, x: np.ndarray, u: np.ndarray, h: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians by central differences, column by column (independent of linearize)."""
    N, n = x.shape
    m = u.shape[1]
    k = torch.arange(N)

    def f(xx: np.ndarray, uu: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return model(torch.tensor(xx, dtype=F64), torch.tensor(uu, dtype=F64), k).numpy()

    A = np.zeros((N, n, n))
    B = np.zeros((N, n, m))
    for j in range(n):
        e = np.zeros(n)
        e[j] = h
        A[:, :, j] = (f(x + e, u) - f(x - e, u)) / (2 * h)
    for j in range(m):
        e = np.zeros(m)
        e[j] = h
        B[:, :, j] = (f(x, u + e) - f(x, u - e)) / (2 * h)
    return A, B


@pytest.mark.parametrize("method", METHODS)
def test_jacobians_match_central_differences(method: str) -> None:
    model = CartModel()
    x, u = plan()
    lin = linearize(model, x, u, method=method)
    A_fd, B_fd = central_differences(model, x, u)
    assert lin.A.shape == (6, 4, 4) and lin.B.shape == (6, 4, 2) and lin.c.shape == (6, 4)
    assert lin.A.dtype == np.float64
    for J, J_fd in ((lin.A, A_fd), (lin.B, B_fd)):
        np.testing.assert_allclose(J, J_fd, rtol=1e-6, atol=1e-6 * np.abs(J_fd).max())
    # the per-step term 0.01 k tanh(x) enters A_k: the steps differ even at equal points
    same = linearize(model, np.repeat(x[:1], 6, 0), np.repeat(u[:1], 6, 0), method=method)
    assert np.abs(same.A[5] - same.A[0]).max() > 0.01


@pytest.mark.parametrize("method", METHODS)
def test_offset_reproduces_the_model_at_the_plan(method: str) -> None:
    model = CartModel()
    x, u = plan(seed=1)
    k = torch.tensor([0, 3, 1, 7, 2, 5])
    lin = linearize(model, torch.tensor(x), torch.tensor(u), k, method=method)
    with torch.no_grad():
        f = model(torch.tensor(x), torch.tensor(u), k).numpy()
    np.testing.assert_allclose(lin.x_next, f, rtol=0, atol=1e-13)
    affine = np.einsum("kij,kj->ki", lin.A, x) + np.einsum("kij,kj->ki", lin.B, u) + lin.c
    np.testing.assert_allclose(affine, f, rtol=0, atol=1e-12)


def test_linear_model_is_recovered_exactly() -> None:
    rng = np.random.default_rng(2)
    A = torch.tensor(rng.normal(size=(3, 3)))
    B = torch.tensor(rng.normal(size=(3, 2)))
    c = torch.tensor(rng.normal(size=3))

    def step(x: torch.Tensor, u: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
        return x @ A.T + u @ B.T + c

    x, u = rng.normal(size=(5, 3)), rng.normal(size=(5, 2))
    for method in METHODS:
        lin = linearize(step, x, u, method=method)
        np.testing.assert_allclose(lin.A, np.broadcast_to(A.numpy(), (5, 3, 3)), atol=1e-14)
        np.testing.assert_allclose(lin.B, np.broadcast_to(B.numpy(), (5, 3, 2)), atol=1e-14)
        np.testing.assert_allclose(lin.c, np.broadcast_to(c.numpy(), (5, 3)), atol=1e-13)


def test_float32_module_is_evaluated_in_its_dtype() -> None:
    m32 = CartModel(dtype=torch.float32)
    m64 = CartModel(dtype=F64)  # same seed, same weights up to rounding
    x, u = plan()
    lin32 = linearize(m32, x, u)  # numpy input: dtype taken from the module's parameters
    lin64 = linearize(m64, x, u)
    assert lin32.A.dtype == np.float64
    np.testing.assert_allclose(lin32.A, lin64.A, atol=1e-4)
    np.testing.assert_allclose(lin32.B, lin64.B, atol=1e-4)


def test_input_not_used_gives_zero_jacobian() -> None:
    def step(x: torch.Tensor, u: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
        return torch.sin(x)

    x, u = plan(N=3)
    lin = linearize(step, x, u)
    assert np.all(lin.B == 0)
    np.testing.assert_allclose(lin.A, np.stack([np.diag(np.cos(r)) for r in x]), atol=1e-15)


def test_bad_inputs_raise_clear_errors() -> None:
    model = CartModel()
    x, u = plan()
    with pytest.raises(ValueError, match="u_bar has 5 rows"):
        linearize(model, x, u[:5])
    bad = x.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="x_bar .* NaN"):
        linearize(model, bad, u)
    with pytest.raises(ValueError, match="2 axes"):
        linearize(model, x[0], u)
    with pytest.raises(ValueError, match="method"):
        linearize(model, x, u, method="jvp")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="integer tensor"):
        linearize(model, x, u, k=torch.zeros(6))
    with pytest.raises(ValueError, match="must return x_next of shape"):
        linearize(lambda a, b, k: a[:, :2], x, u)
    with pytest.raises(ValueError, match="NaN or infinite"):
        linearize(lambda a, b, k: a / 0.0, x, u)


def test_sequential_qp_converges_to_a_dynamically_consistent_plan() -> None:
    """Re-linearising at the solution and re-solving converges: the plan then satisfies the nonlinear model."""
    model = CartModel(Ts=0.05)
    N = 10
    mpc = LinearizedMPC(N, [10.0, 10.0, 1.0, 1.0], [0.1, 0.1], cost="as_written", u_lb=[-3.0, -3.0],
                        u_ub=[3.0, 3.0], eps_abs=1e-9, eps_rel=1e-9, solver_options={"polishing": True})
    x0 = np.array([0.5, 0.8, 0.0, 0.0])
    x_bar, u_bar = np.tile(x0, (N, 1)), np.zeros((N, 2))
    steps = []
    for _ in range(12):
        lin = linearize(model, x_bar, u_bar)
        sol = mpc.solve(x0, lin.A, lin.B, lin.c, np.zeros(4), np.zeros(2))
        assert sol.ok
        steps.append(np.abs(sol.u - u_bar).max())
        x_bar, u_bar = sol.x[:-1], sol.u
    assert steps[-1] < 1e-7 < steps[0]
    with torch.no_grad():  # nonlinear rollout of the final inputs matches the plan
        xs = [torch.tensor(x0)[None]]
        for k in range(N):
            xs.append(model(xs[-1], torch.tensor(sol.u[k])[None], torch.tensor([k])))
    np.testing.assert_allclose(torch.cat(xs).numpy(), sol.x, atol=1e-6)
