r"""Differential flatness of Eq. (27) `quadrotor_model` with zero yaw (App. A.5).

The flat outputs are the position and yaw; with ``psi = 0`` the command
signal of the paper is :math:`\bar\Psi = [p, v, a, j]` (12), optionally with
the snap ``s`` (3) for the feed-forward torque. Conventions follow
:mod:`fnnlib.quadrotor.system` (NED world, FRD body, ZYX Euler angles).

Attitude and thrust. Eq. (27) gives :math:`T z_B = m\,h` with the thrust
vector

.. math:: h = g e_3 - a \quad(\text{nominal}), \qquad z_B = h / \lVert h\rVert, \quad T = m \lVert h\rVert .

With ``psi = 0``, :math:`z_B = R e_3 = [\sin\theta\cos\phi, -\sin\phi, \cos\theta\cos\phi]`,
so :math:`\phi = \operatorname{asin}(-z_{B,y})`, :math:`\theta = \operatorname{atan2}(z_{B,x}, z_{B,z})`.

Body rates. :math:`\dot z_B = R(\omega\times e_3) = R[\omega_y, -\omega_x, 0]` and
:math:`\dot z_B = (I - z_B z_B^\top)\dot h / \lVert h\rVert` with :math:`\dot h = -j`,
so :math:`\omega_x = -(R^\top\dot z_B)_y`, :math:`\omega_y = (R^\top\dot z_B)_x`, and
:math:`\dot\psi = 0` in :math:`W(\Theta)` gives :math:`\omega_z = -\tan\phi\,\omega_y`.

Inputs. :math:`\dot\omega` is the exact derivative (:func:`jvp`, by automatic
differentiation) of the body-rate map along :math:`(\dot v, \dot a, \dot j) = (a, j, s)`,
:math:`\tau = J\dot\omega + \omega\times J\omega`, :math:`u = C^{-1}[T, \tau]`.

Drag and disturbance. The paper's map (and the DFBC) is the nominal one, no
drag. With ``params`` carrying rotor drag ``D = diag(d, d, d_z)`` (equal x/y
entries, true for every vehicle in :mod:`fnnlib.quadrotor.system`) and a
constant force ``F``, the map stays explicit: :math:`R D R^\top = d I + (d_z - d) z_B z_B^\top`,
so Eq. (27) reads :math:`(T/m + (d_z - d)\, z_B\cdot v)\, z_B = h` with

.. math:: h = g e_3 + F/m - d\,v - a, \qquad T = m\lVert h\rVert - m (d_z - d)\, z_B\cdot v,

and :math:`\dot h = -j - d\,a` (the rotor-drag flatness of Faessler et al., 2018,
restricted to ``psi = 0``). Unequal x/y drag makes the map implicit and is refused.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from torch import Tensor

from fnnlib.quadrotor.system import Quadrotor, QuadrotorParams, constants
from fnnlib.quadrotor.rotations import check_last, rmatvec, rotation_matrix

__all__ = [
    "attitude_from_thrust",
    "body_rates",
    "check_params",
    "flat_reference",
    "flat_state_parts",
    "flat_to_input",
    "flat_to_state",
    "jvp",
    "split_flat",
    "state_to_flat",
    "thrust_vector",
]


def jvp(fn: Callable[..., Any], primals: tuple[Tensor, ...], tangents: tuple[Tensor, ...]) -> tuple[Any, Any]:
    """``(fn(*primals), J tangents)``: the Jacobian-vector product of ``fn`` at ``primals``, as ``torch.func.jvp``
    returns it (``fn`` returns a tensor or a tuple of tensors).

    By reverse mode twice: ``g(w) = J^T w`` is linear in ``w``, so ``J t`` is the gradient of ``g(w) . t`` in
    ``w``. Forward mode gives the same derivative (to round-off) but loads ``torch._dynamo`` on its first product
    (~1 s of CPU in every process that computes a flight reference). The results carry a graph, and can be
    differentiated, where a primal or a tangent requires grad.
    """
    if len(primals) != len(tangents):
        raise ValueError(f"jvp: {len(primals)} primals but {len(tangents)} tangents")
    for i, (p, t) in enumerate(zip(primals, tangents)):
        if p.shape != t.shape or p.dtype != t.dtype:
            raise ValueError(f"jvp: tangent {i} is {tuple(t.shape)} {t.dtype}, its primal {tuple(p.shape)} {p.dtype}")
    graph = torch.is_grad_enabled() and any(t.requires_grad for t in (*primals, *tangents))
    with torch.enable_grad():
        xs = tuple(p if p.requires_grad else p.detach().requires_grad_() for p in primals)
        result = fn(*xs)
        flat = [result] if isinstance(result, Tensor) else list(result)
        live = [i for i, o in enumerate(flat) if o.requires_grad]
        ws = [torch.zeros_like(flat[i], requires_grad=True) for i in live]
        g = torch.autograd.grad([flat[i] for i in live], xs, ws, create_graph=True, allow_unused=True) if live else ()
        used = [(gi, t) for gi, t in zip(g, tangents) if gi is not None and gi.requires_grad]
        Jt = torch.autograd.grad([gi for gi, _ in used], ws, [t for _, t in used], create_graph=graph,
                                 allow_unused=True) if used else (None,) * len(ws)
    out = [torch.zeros_like(o) for o in flat]
    for i, d in zip(live, Jt):
        if d is not None:
            out[i] = d
    if not graph:
        flat, out = [o.detach() for o in flat], [d.detach() for d in out]
    if isinstance(result, Tensor):
        return flat[0], out[0]
    return tuple(flat), tuple(out)


# --------------------------------------------------------------------------- checks


def _vectors(names: tuple[str, ...], values: tuple[Tensor, ...], n: int = 3) -> tuple[Tensor, ...]:
    """Check each tensor is float, finite, shape (..., n); broadcast all to a common shape."""
    dtype = None
    for name, value in zip(names, values, strict=True):
        if not isinstance(value, Tensor):
            raise TypeError(f"{name} must be a torch.Tensor of shape (..., {n}), got {type(value).__name__}")
        check_last(value, n, name)
        if dtype is not None and value.dtype != dtype:
            raise TypeError(f"{names[0]} and {name} must share a dtype, got {dtype} and {value.dtype}")
        dtype = value.dtype
    try:
        lead = torch.broadcast_shapes(*(v.shape[:-1] for v in values))
    except RuntimeError as err:
        shapes = ", ".join(f"{k} {tuple(v.shape)}" for k, v in zip(names, values, strict=True))
        raise ValueError(f"leading dimensions do not broadcast: {shapes}") from err
    return tuple(v.expand(*lead, v.shape[-1]) for v in values)


def check_params(params: QuadrotorParams) -> QuadrotorParams:
    """Refuse anything but a :class:`QuadrotorParams` with equal x/y drag (the explicit flat map needs it)."""
    if not isinstance(params, QuadrotorParams):
        raise TypeError(f"params must be a QuadrotorParams, got {type(params).__name__}")
    if params.drag[0] != params.drag[1]:
        raise ValueError(
            f"the explicit flat map needs equal x/y drag (D = diag(d, d, d_z)), got drag = {params.drag}"
        )
    return params


def _check_thrust(h: Tensor) -> None:
    if bool((torch.linalg.vector_norm(h, dim=-1) <= 1e-9).any()):
        raise ValueError("the thrust vector g e3 - a vanishes (free fall): the attitude is undefined")


# --------------------------------------------------------------------------- shared maps (also used by DFBC)


def thrust_vector(v: Tensor, a: Tensor, params: QuadrotorParams) -> Tensor:
    """``h = g e3 + F/m - d v - a`` (``h = g e3 - a`` for :data:`NOMINAL`), shape (..., 3); unchecked."""
    k = constants(params, a.dtype, a.device)
    h = params.g * k.e3 - a
    if any(params.force_disturbance):
        h = h + k.F / params.mass
    if params.drag[0] != 0.0:
        h = h - params.drag[0] * v
    return h


def attitude_from_thrust(h: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Zero-yaw attitude whose body z axis is along ``h``; unchecked.

    Parameters
    ----------
    h : Tensor, shape (..., 3)
        Thrust vector (world frame, NED), nonzero.

    Returns
    -------
    Theta : Tensor, shape (..., 3)
        ``(asin(-z_B[1]), atan2(z_B[0], z_B[2]), 0)``.
    R : Tensor, shape (..., 3, 3)
    z_B : Tensor, shape (..., 3)
        ``h / ||h||``.
    h_norm : Tensor, shape (..., 1)
    """
    h_norm = torch.linalg.vector_norm(h, dim=-1, keepdim=True)
    z_B = h / h_norm
    phi = torch.asin(torch.clamp(-z_B[..., 1], -1.0, 1.0))
    theta = torch.atan2(z_B[..., 0], z_B[..., 2])
    Theta = torch.stack([phi, theta, torch.zeros_like(phi)], dim=-1)
    return Theta, rotation_matrix(Theta, check=False), z_B, h_norm


def body_rates(Theta: Tensor, R: Tensor, z_B: Tensor, h_norm: Tensor, h_dot: Tensor) -> Tensor:
    """Zero-yaw-rate body rates that turn ``z_B = h/||h||`` at the rate set by ``h'``; unchecked.

    ``z_B' = (I - z_B z_B^T) h' / ||h||``, ``omega_x = -(R^T z_B')_y``,
    ``omega_y = (R^T z_B')_x``, ``omega_z = -tan(phi) omega_y``.

    Returns
    -------
    Tensor, shape (..., 3)
    """
    z_dot = (h_dot - z_B * (z_B * h_dot).sum(-1, keepdim=True)) / h_norm
    zb = rmatvec(R, z_dot)  # R^T z_B' = [omega_y, -omega_x, 0]
    w_x, w_y = -zb[..., 1], zb[..., 0]
    w_z = -torch.tan(Theta[..., 0]) * w_y
    return torch.stack([w_x, w_y, w_z], dim=-1)


def flat_state_parts(v: Tensor, a: Tensor, j: Tensor, params: QuadrotorParams) -> tuple[Tensor, Tensor, Tensor]:
    """(Theta, omega, T) from (v, a, j); unchecked."""
    h = thrust_vector(v, a, params)
    h_dot = -j - params.drag[0] * a if params.drag[0] != 0.0 else -j
    Theta, R, z_B, h_norm = attitude_from_thrust(h)
    omega = body_rates(Theta, R, z_B, h_norm, h_dot)
    T = params.mass * h_norm
    if params.drag[2] != params.drag[0]:
        T = T - params.mass * (params.drag[2] - params.drag[0]) * (z_B * v).sum(-1, keepdim=True)
    return Theta, omega, T


# --------------------------------------------------------------------------- public maps


def split_flat(Psi_bar: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Split a command ``Psi_bar = [p, v, a, j]``.

    Parameters
    ----------
    Psi_bar : Tensor, shape (..., 12)

    Returns
    -------
    p, v, a, j : Tensor, shape (..., 3) each
    """
    if not isinstance(Psi_bar, Tensor) or Psi_bar.ndim < 1 or Psi_bar.shape[-1] != 12:
        raise ValueError(f"Psi_bar must have shape (..., 12), got {getattr(Psi_bar, 'shape', type(Psi_bar).__name__)}")
    p, v, a, j = Psi_bar.split(3, dim=-1)
    return p, v, a, j


def flat_to_state(p: Tensor, v: Tensor, a: Tensor, j: Tensor, *, params: QuadrotorParams) -> Tensor:
    """State of Eq. (27) `quadrotor_model` along a zero-yaw flat trajectory.

    Parameters
    ----------
    p, v, a, j : Tensor, shape (..., 3)
        Position, velocity, acceleration and jerk (world frame, NED); leading
        dims broadcast.
    params : QuadrotorParams
        Vehicle; only ``g`` matters for :data:`NOMINAL`; drag and force
        disturbance enter as described in the module notes.

    Returns
    -------
    Tensor, shape (..., 12)
        ``x = [p, v, Theta, omega]``.
    """
    params = check_params(params)
    p, v, a, j = _vectors(("p", "v", "a", "j"), (p, v, a, j))
    _check_thrust(thrust_vector(v, a, params))
    Theta, omega, _ = flat_state_parts(v, a, j, params)
    return torch.cat([p, v, Theta, omega], dim=-1)


def _flat_input(v: Tensor, a: Tensor, j: Tensor, s: Tensor, params: QuadrotorParams) -> Tensor:
    def omega_map(v_: Tensor, a_: Tensor, j_: Tensor) -> tuple[Tensor, Tensor]:
        _, omega_, T_ = flat_state_parts(v_, a_, j_, params)
        return omega_, T_

    (omega, T), (omega_dot, _) = jvp(omega_map, (v, a, j), (a, j, s))
    k = constants(params, v.dtype, v.device)
    tau = k.J * omega_dot + torch.linalg.cross(omega, k.J * omega)
    return torch.cat([T, tau], dim=-1) @ k.C_inv_T


def flat_to_input(
    p: Tensor,
    v: Tensor,
    a: Tensor,
    j: Tensor,
    s: Tensor | None = None,
    *,
    params: QuadrotorParams,
) -> Tensor:
    """Motor thrusts that make Eq. (27) `quadrotor_model` follow a zero-yaw flat trajectory.

    Parameters
    ----------
    p, v, a, j : Tensor, shape (..., 3)
        Flat outputs (``p`` is only checked; the input does not depend on it).
    s : Tensor, shape (..., 3), optional
        Snap; zero if omitted (then the torque lacks the angular-acceleration feed-forward).
    params : QuadrotorParams
        Vehicle (mass, inertia, allocation; drag/disturbance as in the module notes).

    Returns
    -------
    Tensor, shape (..., 4)
        ``u = C^{-1} [T, J omega' + omega x J omega]``.
    """
    params = check_params(params)
    if s is None:
        s = torch.zeros_like(torch.as_tensor(a))
    p, v, a, j, s = _vectors(("p", "v", "a", "j", "s"), (p, v, a, j, s))
    _check_thrust(thrust_vector(v, a, params))
    return _flat_input(v, a, j, s, params)


def flat_reference(
    Psi_bar: Tensor, s: Tensor | None = None, *, params: QuadrotorParams
) -> tuple[Tensor, Tensor]:
    """Reference state and input from a command ``Psi_bar = [p, v, a, j]`` (e.g. for MPC, App. A.5).

    Parameters
    ----------
    Psi_bar : Tensor, shape (..., 12)
    s : Tensor, shape (..., 3), optional
        Snap (zero if omitted).
    params : QuadrotorParams

    Returns
    -------
    x : Tensor, shape (..., 12)
    u : Tensor, shape (..., 4)
    """
    p, v, a, j = split_flat(Psi_bar)
    return flat_to_state(p, v, a, j, params=params), flat_to_input(p, v, a, j, s, params=params)


def state_to_flat(
    x: Tensor, u: Tensor, u_dot: Tensor | None = None, *, params: QuadrotorParams
) -> Tensor:
    """Flat outputs seen by the model: the inverse of :func:`flat_to_state` / :func:`flat_to_input`.

    ``a = v'`` from Eq. (27), and ``j = a'`` by an exact derivative (:func:`jvp`)
    of the acceleration along ``(x', u') = (f(x, u), u_dot)``.

    Parameters
    ----------
    x : Tensor, shape (..., 12)
    u : Tensor, shape (..., 4)
    u_dot : Tensor, shape (..., 4), optional
        Rate of the motor thrusts; zero (zero-order hold) if omitted.
    params : QuadrotorParams
        The model whose acceleration is differentiated.

    Returns
    -------
    Tensor, shape (..., 12)
        ``Psi_bar = [p, v, a, j]``.
    """
    quad = Quadrotor(params)
    lead = quad.check_inputs(x, u)
    if u_dot is None:
        u_dot = torch.zeros_like(u)
    else:
        quad.check_inputs(x, u_dot)
    x, u, u_dot = (t.expand(*lead, t.shape[-1]) for t in (x, u, u_dot))

    def acceleration(x_: Tensor, u_: Tensor) -> Tensor:
        return quad.rhs(x_, u_)[..., 3:6]

    a, j = jvp(acceleration, (x, u), (quad.rhs(x, u), u_dot))
    return torch.cat([x[..., 0:6], a, j], dim=-1)
