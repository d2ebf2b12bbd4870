"""Differential flatness (zero yaw): flat -> (x, u) -> Eq. (27) reproduces the flat trajectory."""

from __future__ import annotations

import subprocess
import sys
import warnings

import pytest
import torch

from fnnlib.quadrotor.control.flatness import flat_reference, flat_to_input, flat_to_state, jvp, split_flat, state_to_flat
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, TRAINING_TRUTH, Quadrotor, QuadrotorParams

F64 = torch.float64
VEHICLES = [NOMINAL, TRAINING_TRUTH, TEST_TRUTH]


def flat(t: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """p(t) = [sin t, sin 2t, cos t] and its derivatives v, a, j, s, c (crackle), each (..., 3)."""
    S, C = torch.sin, torch.cos
    p = torch.stack([S(t), S(2 * t), C(t)], -1)
    v = torch.stack([C(t), 2 * C(2 * t), -S(t)], -1)
    a = torch.stack([-S(t), -4 * S(2 * t), -C(t)], -1)
    j = torch.stack([-C(t), -8 * C(2 * t), S(t)], -1)
    s = torch.stack([S(t), 16 * S(2 * t), C(t)], -1)
    c = torch.stack([C(t), 32 * C(2 * t), -S(t)], -1)
    return p, v, a, j, s, c


T_GRID = torch.linspace(0.0, 6.0, 25, dtype=F64)


@pytest.mark.parametrize("params", VEHICLES, ids=["nominal", "training_truth", "test_truth"])
def test_round_trip_through_the_model(params: QuadrotorParams) -> None:
    p, v, a, j, s, _ = flat(T_GRID)
    x = flat_to_state(p, v, a, j, params=params)
    u = flat_to_input(p, v, a, j, s, params=params)
    xdot = Quadrotor(params).f(x, u)
    assert torch.allclose(xdot[:, 0:3], v, atol=1e-12)  # p' = v
    assert torch.allclose(xdot[:, 3:6], a, atol=1e-12)  # v' = a (drag and disturbance included)
    h = 1e-4
    fd = (flat_to_state(*flat(T_GRID + h)[:4], params=params) - flat_to_state(*flat(T_GRID - h)[:4], params=params))
    fd = fd / (2 * h)
    # central difference in t: truncation ~ h^2 |x'''| / 6 ~ 1e-8 here, round-off ~ 1e-12
    assert torch.allclose(xdot[:, 6:9], fd[:, 6:9], atol=1e-6)  # Theta' = W(Theta) omega
    assert torch.allclose(xdot[:, 9:12], fd[:, 9:12], atol=1e-6)  # omega' from the torque
    assert torch.allclose(x[:, 8], torch.zeros_like(x[:, 8])) and torch.allclose(xdot[:, 8], torch.zeros_like(x[:, 8]))


def test_snap_is_the_angular_acceleration_feed_forward() -> None:
    p, v, a, j, s, _ = flat(T_GRID)
    x = flat_to_state(p, v, a, j, params=NOMINAL)
    without = Quadrotor(NOMINAL).f(x, flat_to_input(p, v, a, j, params=NOMINAL))  # s = 0
    with_s = Quadrotor(NOMINAL).f(x, flat_to_input(p, v, a, j, s, params=NOMINAL))
    assert torch.allclose(without[:, :9], with_s[:, :9], atol=1e-12)  # thrust is the same
    assert float((without[:, 9:] - with_s[:, 9:]).abs().max()) > 1.0  # torque is not


@pytest.mark.parametrize("params", VEHICLES, ids=["nominal", "training_truth", "test_truth"])
def test_state_to_flat_inverts_the_flat_maps(params: QuadrotorParams) -> None:
    p, v, a, j, s, c = flat(T_GRID)
    x = flat_to_state(p, v, a, j, params=params)
    # exact thrust rate along the trajectory: forward-mode derivative of the input map along (a, j, s, c)
    u, u_dot = jvp(lambda *fl: flat_to_input(p, *fl, params=params), (v, a, j, s), (a, j, s, c))
    Psi = state_to_flat(x, u, u_dot, params=params)
    assert torch.allclose(Psi, torch.cat([p, v, a, j], -1), atol=1e-10)
    # the zero-order-hold jerk (u' = 0) misses the thrust rate: the round trip is not vacuous
    assert float((state_to_flat(x, u, params=params)[:, 9:] - j).abs().max()) > 0.1


def test_hover_maps_to_rest_and_hover_thrust() -> None:
    zero = torch.zeros(3, dtype=F64)
    p = torch.tensor([1.0, 2.0, -3.0], dtype=F64)
    x, u = flat_reference(torch.cat([p, zero, zero, zero]), params=NOMINAL)
    assert torch.allclose(x, torch.cat([p, torch.zeros(9, dtype=F64)]), atol=1e-15)
    assert torch.allclose(u, Quadrotor(NOMINAL).hover_input(), atol=1e-14)


def test_known_tilt() -> None:
    # accelerating north at g: z_B along (-g, 0, g), i.e. pitch 45 deg nose down, thrust sqrt(2) m g
    zero = torch.zeros(3, dtype=F64)
    a = torch.tensor([9.81, 0.0, 0.0], dtype=F64)
    x = flat_to_state(zero, zero, a, zero, params=NOMINAL)
    assert torch.allclose(x[6:9], torch.tensor([0.0, -torch.pi / 4, 0.0], dtype=F64), atol=1e-15)
    u = flat_to_input(zero, zero, a, zero, params=NOMINAL)
    assert torch.allclose(u.sum(), torch.tensor(2.0**0.5 * 0.83 * 9.81, dtype=F64), atol=1e-12)


def test_batched_and_broadcast_and_float32() -> None:
    p, v, a, j, s, _ = flat(T_GRID[:5])
    x = flat_to_state(p, v, a, j, params=NOMINAL)
    u = flat_to_input(p, v, a, j, s, params=NOMINAL)
    for i in range(5):
        assert torch.allclose(x[i], flat_to_state(p[i], v[i], a[i], j[i], params=NOMINAL), atol=1e-14)
        assert torch.allclose(u[i], flat_to_input(p[i], v[i], a[i], j[i], s[i], params=NOMINAL), atol=1e-12)
    assert flat_to_state(p[0], v, a[0], j[0], params=NOMINAL).shape == (5, 12)  # leading dims broadcast
    x32 = flat_to_state(p.float(), v.float(), a.float(), j.float(), params=NOMINAL)
    u32 = flat_to_input(p.float(), v.float(), a.float(), j.float(), s.float(), params=NOMINAL)
    assert x32.dtype == u32.dtype == torch.float32
    assert torch.allclose(x32.double(), x, atol=1e-5) and torch.allclose(u32.double(), u, atol=1e-4)


def test_gradients_flow_through_the_input_map() -> None:
    p, v, a, j, s, _ = flat(T_GRID[:3])
    a = a.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda a_: flat_to_input(p, v, a_, j, s, params=NOMINAL), (a,))


def test_bad_inputs_are_refused() -> None:
    p, v, a, j, _, _ = flat(T_GRID[:4])
    with pytest.raises(ValueError, match=r"a must have shape \(\.\.\., 3\)"):
        flat_to_state(p, v, a[:, :2], j, params=NOMINAL)
    nan = a.clone()
    nan[2, 1] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        flat_to_input(p, v, nan, j, params=NOMINAL)
    with pytest.raises(ValueError, match="broadcast"):
        flat_to_state(p, v[:3], a, j, params=NOMINAL)
    free_fall = torch.tensor([0.0, 0.0, 9.81], dtype=F64).expand(4, 3)
    with pytest.raises(ValueError, match="free fall"):
        flat_to_state(p, v, free_fall, j, params=NOMINAL)
    with pytest.raises(ValueError, match="equal x/y drag"):
        flat_to_input(p, v, a, j, params=NOMINAL.replace(drag=(0.5, 0.6, 0.1)))
    with pytest.raises(ValueError, match=r"\(\.\.\., 12\)"):
        split_flat(torch.zeros(4, 9, dtype=F64))
    with pytest.raises(TypeError, match="dtype"):
        flat_to_state(p, v.float(), a, j, params=NOMINAL)


def _field(x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Three outputs: one of both inputs, one of ``x`` alone, one of neither."""
    return torch.sin(x) * y.pow(2), torch.exp(x).sum(-1, keepdim=True), torch.ones(2, dtype=F64)


def _func_jvp(*args):
    """``torch.func.jvp``, quiet about torch's own one-time ``torch.jit.script`` deprecation warning."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*torch\.jit\.script.*deprecated", category=DeprecationWarning)
        return torch.func.jvp(*args)


def test_jvp_is_torch_funcs_product_without_forward_mode() -> None:
    g = torch.Generator().manual_seed(0)
    x, y, tx, ty = (torch.randn(4, 3, generator=g, dtype=F64) for _ in range(4))
    ours = jvp(_field, (x, y), (tx, ty))
    theirs = _func_jvp(_field, (x, y), (tx, ty))
    for a, b in zip((*ours[0], *ours[1]), (*theirs[0], *theirs[1])):
        assert a.shape == b.shape and torch.allclose(a, b, rtol=1e-13, atol=1e-14)
    assert torch.equal(ours[1][2], torch.zeros(2, dtype=F64))  # an output of neither input: no change
    assert not any(t.requires_grad for t in (*ours[0], *ours[1]))  # no input needs grad: plain tensors
    one = jvp(lambda x_: x_.pow(3), (x,), (tx,))  # a function of one tensor returns tensors, not tuples
    assert torch.allclose(one[1], 3 * x.pow(2) * tx, rtol=1e-13)
    with pytest.raises(ValueError, match="tangent 0 is"):
        jvp(lambda x_: x_, (x,), (tx[:2],))


def test_jvp_is_differentiable_where_an_input_needs_grad() -> None:
    g = torch.Generator().manual_seed(1)
    x, y, tx, ty = (torch.randn(4, 3, generator=g, dtype=F64) for _ in range(4))
    x.requires_grad_(True)
    ours = torch.autograd.grad(jvp(_field, (x, y), (tx, ty))[1][0].sum(), x)[0]
    theirs = torch.autograd.grad(_func_jvp(_field, (x, y), (tx, ty))[1][0].sum(), x)[0]
    assert torch.allclose(ours, theirs, rtol=1e-13, atol=1e-14)


def test_a_flight_reference_leaves_torch_dynamo_unloaded() -> None:
    """Forward mode loads ``torch._dynamo`` on its first product (~1 s in every process that flies)."""
    code = ("import sys, torch\nfrom fnnlib.quadrotor.control.flatness import flat_reference\n"
            "from fnnlib.quadrotor.system import NOMINAL\n"
            "x, u = flat_reference(torch.full((5, 12), 0.1, dtype=torch.float64), params=NOMINAL)\n"
            "print('torch._dynamo' in sys.modules, bool(torch.isfinite(u).all()))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False", "True"], done.stdout + done.stderr
