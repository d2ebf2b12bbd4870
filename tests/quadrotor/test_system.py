"""Eq. (27) `quadrotor_model`: equilibrium, drag, the right-hand side, RK4 steps, checks, batching."""

from __future__ import annotations

import pytest
import torch

from fnnlib.quadrotor.allocation import allocation_matrix
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, TRAINING_TRUTH, Quadrotor, QuadrotorParams
from fnnlib.quadrotor.rotations import euler_rate_matrix, rotation_matrix

F64 = torch.float64


def _state(seed: int = 0, n: int | None = None) -> torch.Tensor:
    """A non-trivial state (tilted, moving, spinning), or a batch of ``n`` of them."""
    g = torch.Generator().manual_seed(seed)
    shape = (12,) if n is None else (n, 12)
    x = torch.randn(*shape, generator=g, dtype=F64)
    x[..., 6:9] *= 0.4  # moderate Euler angles, far from gimbal lock
    return x


def test_vehicles_hold_the_paper_and_release_values() -> None:
    assert NOMINAL.mass == 0.83 and NOMINAL.drag == (0.0, 0.0, 0.0)
    assert TRAINING_TRUTH.drag == (0.7, 0.7, 0.2)
    assert TEST_TRUTH.mass == pytest.approx(NOMINAL.mass + 0.5)
    assert TEST_TRUTH.inertia[:2] == pytest.approx((5e-3, 5e-3))
    assert TEST_TRUTH.force_disturbance == (0.3, 0.3, 0.3)
    # the Sec. 5.3 percentages: 37.6 % mass (of the test vehicle), 40 % x/y inertia
    assert 0.5 / TEST_TRUTH.mass == pytest.approx(0.376, abs=1e-3)
    assert 2e-3 / TEST_TRUTH.inertia[0] == pytest.approx(0.40)
    heavier = NOMINAL.replace(mass=1.0)
    assert heavier.mass == 1.0 and heavier.inertia == NOMINAL.inertia


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"mass": -0.1}, "mass"),
        ({"mass": 0.0}, "mass"),
        ({"inertia": (3e-3, 0.0, 4e-3)}, "inertia"),
        ({"drag": (0.1, -0.1, 0.0)}, "drag"),
        ({"arm": 0.0}, "arm"),
        ({"torque_coeff": -1.0}, "torque_coeff"),
        ({"g": float("nan")}, "g"),
        ({"inertia": (1e-3, 1e-3)}, "3 entries"),
    ],
)
def test_non_physical_parameters_are_refused(changes: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        QuadrotorParams(**changes)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- Eq. (27)


def test_hover_is_an_equilibrium_of_the_nominal_model() -> None:
    quad = Quadrotor(NOMINAL)
    x = torch.zeros(12, dtype=F64)
    x[:3] = torch.tensor([1.0, -2.0, -3.0])  # anywhere
    xdot = quad.f(x, quad.hover_input())
    assert torch.allclose(xdot, torch.zeros(12, dtype=F64), atol=1e-12, rtol=0)
    assert torch.allclose(quad.hover_input().sum(), torch.tensor(0.83 * 9.81, dtype=F64))


def test_drag_breaks_the_hover_of_the_training_vehicle() -> None:
    x = torch.zeros(12, dtype=F64)
    x[3:6] = torch.tensor([1.0, -2.0, 0.5])
    u = Quadrotor(NOMINAL).hover_input()
    nominal = Quadrotor(NOMINAL).f(x, u)
    truth = Quadrotor(TRAINING_TRUTH).f(x, u)
    assert torch.allclose(nominal[3:6], torch.zeros(3, dtype=F64), atol=1e-12)
    # level attitude: R = I, so the drag is -D v exactly
    assert torch.allclose(truth[3:6], torch.tensor([-0.7, 1.4, -0.1], dtype=F64), atol=1e-12)


def test_drag_rotates_with_the_body() -> None:
    x = _state(3)
    R = rotation_matrix(x[6:9])
    D = torch.diag(torch.tensor(TRAINING_TRUTH.drag, dtype=F64))
    expected = -R @ D @ R.T @ x[3:6]
    assert torch.allclose(Quadrotor(TRAINING_TRUTH).drag_acceleration(x), expected, atol=1e-13)
    assert torch.allclose(Quadrotor(NOMINAL).drag_acceleration(x), torch.zeros(3, dtype=F64))


def test_thrust_pushes_along_minus_body_z_and_the_disturbance_adds_f_over_m() -> None:
    x = _state(4)
    x[9:] = 0.0
    u = torch.full((4,), 2.0, dtype=F64)
    R = rotation_matrix(x[6:9])
    quad = Quadrotor(NOMINAL.replace(force_disturbance=(0.3, -0.6, 0.9)))
    expected = -(8.0 / 0.83) * R[:, 2] + torch.tensor([0.3, -0.6, 0.83 * 9.81 + 0.9], dtype=F64) / 0.83
    assert torch.allclose(quad.f(x, u)[3:6], expected, atol=1e-12)


def test_euler_rates_and_gyroscopic_term() -> None:
    x = _state(5)
    u = torch.tensor([1.0, 2.0, 3.0, 4.0], dtype=F64)
    xdot = Quadrotor(NOMINAL).f(x, u)
    W = euler_rate_matrix(x[6:9])
    assert torch.allclose(xdot[6:9], W @ x[9:12], atol=1e-13)
    J = torch.diag(torch.tensor(NOMINAL.inertia, dtype=F64))
    tau = (allocation_matrix(NOMINAL) @ u)[1:]
    w = x[9:12]
    assert torch.allclose(J @ xdot[9:12], -torch.linalg.cross(w, J @ w) + tau, atol=1e-12)


def test_residual_acceleration_enters_the_velocity_equation_only() -> None:
    x, u = _state(6), torch.tensor([1.0, 2.0, 3.0, 4.0], dtype=F64)
    a_res = torch.tensor([0.5, -1.0, 2.0], dtype=F64)
    quad = Quadrotor(NOMINAL)
    diff = quad.f(x, u, a_res) - quad.f(x, u)
    assert torch.allclose(diff, torch.cat([torch.zeros(3), a_res, torch.zeros(6)]).to(F64), atol=1e-13)


# --------------------------------------------------------------------------- allocation


# --------------------------------------------------------------------------- integration


def test_rk4_converges_at_fourth_order() -> None:
    quad = Quadrotor(TRAINING_TRUTH)
    x = torch.tensor([0.1, -0.2, 0.3, 1.0, -2.0, 0.5, 0.3, -0.2, 0.4, 1.5, -1.0, 0.8], dtype=F64)
    u = torch.tensor([1.5, 2.5, 2.0, 3.0], dtype=F64)
    ref = quad.step(x, u, Ts=0.1, substeps=256)
    errs = [float((quad.step(x, u, Ts=0.1, substeps=s) - ref).abs().max()) for s in (2, 4, 8)]
    # 4th order: halving the sub-step divides the error by ~2^4 = 16 (measured 14.5 and 15.3)
    for coarse, fine in zip(errs, errs[1:], strict=False):
        assert 8.0 < coarse / fine < 32.0


def test_step_uses_the_residual_at_every_stage() -> None:
    x, u = _state(8), torch.tensor([1.5, 2.5, 2.0, 3.0], dtype=F64)
    F = torch.tensor([0.3, -0.2, 0.1], dtype=F64)
    with_F = Quadrotor(NOMINAL.replace(force_disturbance=tuple(F.tolist())))
    calls: list[int] = []

    def a_res_fn(y: torch.Tensor) -> torch.Tensor:
        calls.append(1)
        return (F / NOMINAL.mass).expand(*y.shape[:-1], 3)

    stepped = Quadrotor(NOMINAL).step(x, u, Ts=0.05, substeps=3, a_res_fn=a_res_fn)
    assert len(calls) == 4 * 3
    assert torch.allclose(stepped, with_F.step(x, u, Ts=0.05, substeps=3), atol=1e-14)


def test_rollout_repeats_steps_and_hover_stays_put() -> None:
    quad = Quadrotor(NOMINAL)
    x0 = _state(9, 2)
    u_seq = torch.rand(2, 5, 4, dtype=F64, generator=torch.Generator().manual_seed(0)) + 1.5
    X = quad.rollout(x0, u_seq, Ts=0.02, substeps=2)
    assert X.shape == (2, 6, 12)
    x = x0
    for k in range(5):
        x = quad.step(x, u_seq[:, k], Ts=0.02, substeps=2)
        assert torch.allclose(X[:, k + 1], x, atol=1e-14)
    hover = quad.rollout(torch.zeros(12, dtype=F64), quad.hover_input().expand(50, 4), Ts=0.02)
    assert torch.allclose(hover, torch.zeros(51, 12, dtype=F64), atol=1e-12)


# --------------------------------------------------------------------------- checks, batching, dtypes


def test_bad_inputs_are_refused_before_any_work() -> None:
    quad = Quadrotor(NOMINAL)
    x, u = _state(10), quad.hover_input()
    bad = x.clone()
    bad[7] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        quad.f(bad, u)
    with pytest.raises(ValueError, match=r"\(\.\.\., 12\)"):
        quad.f(x[:11], u)
    with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
        quad.step(x, u[:3], Ts=0.02)
    with pytest.raises(ValueError, match="broadcast"):
        quad.f(_state(10, 3), u.expand(2, 4))
    with pytest.raises(ValueError, match="Ts"):
        quad.step(x, u, Ts=0.0)
    with pytest.raises(ValueError, match="substeps"):
        quad.step(x, u, Ts=0.02, substeps=0)
    with pytest.raises(TypeError, match="substeps"):
        quad.step(x, u, Ts=0.02, substeps=1.5)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="floating-point"):
        quad.f(torch.zeros(12, dtype=torch.int64), u)
    with pytest.raises(TypeError, match="QuadrotorParams"):
        Quadrotor(params={"mass": 1.0})  # type: ignore[arg-type]


def test_a_batch_equals_separate_calls() -> None:
    quad = Quadrotor(TEST_TRUTH)
    x = _state(11, 5)
    u = torch.rand(5, 4, dtype=F64, generator=torch.Generator().manual_seed(1)) * 3.0
    batched_f, batched_step = quad.f(x, u), quad.step(x, u, Ts=0.02, substeps=2)
    for i in range(5):
        assert torch.allclose(batched_f[i], quad.f(x[i], u[i]), atol=1e-13)
        assert torch.allclose(batched_step[i], quad.step(x[i], u[i], Ts=0.02, substeps=2), atol=1e-13)
    # leading dims broadcast: one input for a (2, 5) batch of states
    assert quad.f(x.expand(2, 5, 12), u[0]).shape == (2, 5, 12)


def test_float32_and_gradients() -> None:
    quad = Quadrotor(TRAINING_TRUTH)
    x, u = _state(12, 4), torch.full((4, 4), 2.0, dtype=F64)
    f32 = quad.f(x.float(), u.float())
    assert f32.dtype == torch.float32
    assert torch.allclose(f32.double(), quad.f(x, u), rtol=1e-5, atol=1e-4)
    xg, ug = x[:2].clone().requires_grad_(True), u[:2].clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda a, b: quad.step(a, b, Ts=0.02), (xg, ug))


# --------------------------------------------------------------------------- the few-op right-hand side


def test_rhs_attitude_rates_and_drag_equal_the_matrix_forms():
    """Theta' = W(Theta) omega, v' = -(T/m) R e3 + g e3 - R D R^T v + F/m, omega' = J^-1(tau - omega x J omega)."""
    torch.manual_seed(4)
    q = Quadrotor(TEST_TRUTH)
    prm = TEST_TRUTH
    x = torch.randn(40, 12, dtype=torch.float64)
    x[:, 6:9] = (torch.rand(40, 3, dtype=torch.float64) - 0.5) * 2.5  # |theta| < 1.25
    u = torch.rand(40, 4, dtype=torch.float64) * 5
    xd = q.f(x, u)
    v, Theta, omega = x[:, 3:6], x[:, 6:9], x[:, 9:12]
    R = rotation_matrix(Theta)
    wrench = u @ allocation_matrix(prm).T
    J = torch.tensor(prm.inertia, dtype=torch.float64)
    D = torch.diag(torch.tensor(prm.drag, dtype=torch.float64))
    e3 = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    F = torch.tensor(prm.force_disturbance, dtype=torch.float64)
    v_dot = (-(wrench[:, :1] / prm.mass) * (R @ e3) + prm.g * e3 - (R @ D @ R.transpose(1, 2) @ v[..., None])[..., 0]
             + F / prm.mass)
    torch.testing.assert_close(xd[:, :3], v, rtol=0, atol=0)
    torch.testing.assert_close(xd[:, 3:6], v_dot, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(xd[:, 6:9], (euler_rate_matrix(Theta) @ omega[..., None])[..., 0], rtol=1e-12,
                               atol=1e-12)
    torch.testing.assert_close(xd[:, 9:12], (wrench[:, 1:] - torch.linalg.cross(omega, J * omega)) / J, rtol=1e-12,
                               atol=1e-9)


def test_rk4_with_a_given_first_stage_is_the_same_step():
    q = Quadrotor(TEST_TRUTH)
    x = torch.randn(5, 12, dtype=torch.float64) * 0.3
    u = torch.full((5, 4), 3.0, dtype=torch.float64)
    for substeps in (1, 3):
        plain = q.step(x, u, Ts=0.02, substeps=substeps)
        given = q.step(x, u, Ts=0.02, substeps=substeps, k1=q.f(x, u))
        torch.testing.assert_close(given, plain, rtol=0, atol=0)
    # a wrong first stage changes the step (it is used), a wrong shape is refused
    assert not torch.equal(q.step(x, u, Ts=0.02, k1=torch.zeros(5, 12, dtype=torch.float64)), q.step(x, u, Ts=0.02))
    with pytest.raises(ValueError, match="k1 must have shape"):
        q.step(x, u, Ts=0.02, k1=torch.zeros(12, dtype=torch.float64))
