r"""The quadrotor of Sec. 5.3 (App. A.5): Eq. (27) `quadrotor_model`, batched and differentiable.

Frames and conventions (fixed; :mod:`fnnlib.control` relies on them):

* world frame E is NED-like, ``z`` points **down**; gravity is ``+g e3``;
* body frame B is front-right-down; ``R = Rz(psi) Ry(theta) Rx(phi)``
  (Euler ZYX) maps body to world, so the body ``z`` axis in the world is
  ``z_B = R e3`` and the rotor thrust pushes along ``-z_B``;
* state ``x = [p (3), v (3), Theta = (phi, theta, psi) (3), omega (3)]`` (12),
  ``p, v`` in E, ``omega`` (body rates) in B;
* input ``u = [u1, u2, u3, u4]`` motor thrusts in N (4), numbered as in the
  PX4 "quad X" layout: 1 front-right, 2 rear-left, 3 front-left, 4 rear-right,
  motors 1 and 2 spinning so that their drag torque is ``+c u`` about ``z_B``.

Eq. (27) with the drag model of App. A.5 and the test disturbance of Sec. 5.3:

.. math::

    \dot p = v, \quad
    \dot v = -\tfrac{T}{m} R e_3 + g e_3 - R D R^\top v + F/m + a_{res}, \quad
    \dot\Theta = W(\Theta)\,\omega, \quad
    J\dot\omega = -\omega\times(J\omega) + \tau, \quad
    [T, \tau] = C u .

``a_res`` is an optional extra acceleration; it is where a learned residual
(App. A.5, "Implementation of learning aerodynamics effects") enters.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import torch
from torch import Tensor

from fnnlib._validation import check_finite

__all__ = [
    "NOMINAL",
    "TEST_TRUTH",
    "TRAINING_TRUTH",
    "Quadrotor",
    "QuadrotorParams",
    "allocation_inverse",
    "allocation_matrix",
    "check_step",
    "constants",
    "euler_from_rotation",
    "euler_rate_matrix",
    "inverse_euler_rate_matrix",
    "matvec",
    "rk4",
    "rmatvec",
    "rotation_matrix",
]

Vec3 = tuple[float, float, float]
AccelerationFn = Callable[[Tensor], Tensor]


def _vec3(value: Sequence[float] | Tensor, name: str) -> Vec3:
    try:
        items = [float(v) for v in value]  # type: ignore[union-attr]
    except TypeError as err:
        raise TypeError(f"{name} must be a sequence of 3 floats, got {type(value).__name__}") from err
    if len(items) != 3:
        raise ValueError(f"{name} must have 3 entries, got {len(items)}")
    if not all(math.isfinite(v) for v in items):
        raise ValueError(f"{name} must be finite, got {tuple(items)}")
    return (items[0], items[1], items[2])


@dataclass(frozen=True)
class QuadrotorParams:
    """Physical parameters of Eq. (27) `quadrotor_model`.

    Parameters
    ----------
    mass : float
        ``m`` in kg, > 0.
    inertia : tuple of 3 floats
        Diagonal of ``J`` in kg m^2, each > 0.
    drag : tuple of 3 floats
        Diagonal of the rotor-drag matrix ``D`` in 1/s, each >= 0; the drag
        acceleration is ``-R D R^T v`` (App. A.5).
    arm : float
        Motor distance ``l`` from the centre in m, > 0 (X layout, moment arm
        ``d = l / sqrt(2)`` about both body axes).
    torque_coeff : float
        Ratio ``c`` of a rotor's drag torque to its thrust, in m, > 0.
    g : float
        Gravity in m/s^2, > 0.
    force_disturbance : tuple of 3 floats
        Constant external force ``F`` in N, world frame (Sec. 5.3 tests).

    Notes
    -----
    The paper text (App. A.5) states ``D = diag(0.6, 0.6, 0.1)`` for the
    training data; the authors' release generates it with
    ``diag(0.7, 0.7, 0.2)`` (:data:`TRAINING_TRUTH`). The Sec. 5.3 test
    vehicle (:data:`TEST_TRUTH`) has +0.5 kg (37.6 %), +2e-3 kg m^2 on the
    x/y inertia (40 %), drag ``diag(0.6, 0.6, 0.15)`` (14.3 %, 14.3 %, 25 %
    below the release training drag) and a 0.3 N force on each axis.
    """

    mass: float = 0.83
    inertia: Vec3 = (3e-3, 3e-3, 4e-3)
    drag: Vec3 = (0.0, 0.0, 0.0)
    arm: float = 0.15
    torque_coeff: float = 0.01
    g: float = 9.81
    force_disturbance: Vec3 = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("mass", "arm", "torque_coeff", "g"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise TypeError(f"{name} must be a float, got {type(value).__name__}")
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite positive number, got {value!r}")
            object.__setattr__(self, name, float(value))
        inertia = _vec3(self.inertia, "inertia")
        if min(inertia) <= 0:
            raise ValueError(f"inertia must be positive on every axis, got {inertia}")
        drag = _vec3(self.drag, "drag")
        if min(drag) < 0:
            raise ValueError(f"drag must be non-negative on every axis, got {drag}")
        object.__setattr__(self, "inertia", inertia)
        object.__setattr__(self, "drag", drag)
        object.__setattr__(self, "force_disturbance", _vec3(self.force_disturbance, "force_disturbance"))

    def replace(self, **changes: Any) -> QuadrotorParams:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @property
    def moment_arm(self) -> float:
        """``d = l / sqrt(2)``, the moment arm of each motor about the body x and y axes."""
        return self.arm / math.sqrt(2.0)

    def tensor(self, name: str, like: Tensor) -> Tensor:
        """Field ``name`` (a 3-tuple) as a tensor, shape (3,), with ``like``'s dtype and device."""
        return torch.tensor(getattr(self, name), dtype=like.dtype, device=like.device)


NOMINAL = QuadrotorParams()
"""The nominal model of Eq. (27): no drag, no disturbance (the DFBC and Nomi-MPC model)."""

TRAINING_TRUTH = QuadrotorParams(drag=(0.7, 0.7, 0.2))
"""The vehicle that makes the training data (release drag; the paper text says diag(0.6, 0.6, 0.1))."""

TEST_TRUTH = QuadrotorParams(
    mass=1.33,
    inertia=(5e-3, 5e-3, 4e-3),
    drag=(0.6, 0.6, 0.15),
    force_disturbance=(0.3, 0.3, 0.3),
)
"""The Sec. 5.3 flight-test vehicle: mass, inertia and drag uncertainties plus a 0.3 N force per axis."""


# --------------------------------------------------------------------------- rotations


def _check_last(x: Tensor, n: int, name: str) -> Tensor:
    if not isinstance(x, Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if not x.is_floating_point():
        raise TypeError(f"{name} must be a floating-point tensor, got dtype {x.dtype}")
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got shape {tuple(x.shape)}")
    check_finite(x, name=name)
    return x


def _mat3(entries: list[Tensor]) -> Tensor:
    """Stack 9 tensors of shape (...,) row-major into shape (..., 3, 3)."""
    M = torch.stack(entries, dim=-1)
    return M.reshape(*M.shape[:-1], 3, 3)


def _elementary_rotations() -> tuple[Tensor, Tensor, Tensor]:
    """``Rx``, ``Ry``, ``Rz`` as (3, 3, 3) tensors ``T[i, j, c]``, linear in ``b = (1, cos, sin)`` of their angle.

    ``Rx(phi)[i, j] = sum_c T_x[i, j, c] b_phi[c]`` and likewise for ``Ry(theta)``, ``Rz(psi)``.
    """
    T_x, T_y, T_z = (torch.zeros(3, 3, 3, dtype=torch.float64) for _ in range(3))
    one, cos, sin = 0, 1, 2
    # Rx = [[1, 0, 0], [0, c, -s], [0, s, c]]
    T_x[0, 0, one], T_x[1, 1, cos], T_x[1, 2, sin], T_x[2, 1, sin], T_x[2, 2, cos] = 1, 1, -1, 1, 1
    # Ry = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    T_y[0, 0, cos], T_y[0, 2, sin], T_y[1, 1, one], T_y[2, 0, sin], T_y[2, 2, cos] = 1, 1, 1, -1, 1
    # Rz = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T_z[0, 0, cos], T_z[0, 1, sin], T_z[1, 0, sin], T_z[1, 1, cos], T_z[2, 2, one] = 1, -1, 1, 1, 1
    return T_x, T_y, T_z


def _trilinear_maps() -> tuple[Tensor, Tensor]:
    r"""Constant maps that turn Eq. (27)'s trigonometry into one matmul each (float64).

    With ``b_a = (1, cos a, sin a)`` for each Euler angle:

    * ``R = Rz(psi) Ry(theta) Rx(phi)`` is trilinear in ``(b_psi, b_theta, b_phi)``, so
      ``vec(R) = (b_psi (x) b_theta (x) b_phi) @ T_R`` with ``T_R`` (27, 9);
    * ``cos(theta) W(Theta) omega`` is trilinear in ``(b_phi, b_theta, omega)``:
      ``[[ct, sf st, cf st], [0, cf ct, -sf ct], [0, sf, cf]] omega``, so
      ``Theta' = ((b_phi (x) b_theta (x) omega) @ T_W) / cos(theta)`` with ``T_W`` (27, 3).

    A handful of batched ops instead of dozens of scalar products: the
    quadrotor right-hand side is bound by per-op overhead at MPC batch sizes.
    """
    T_x, T_y, T_z = _elementary_rotations()
    T_R = torch.einsum("ija,jkb,klc->abcil", T_z, T_y, T_x).reshape(27, 9)
    T_W = torch.zeros(3, 3, 3, 3, dtype=torch.float64)  # [b_phi, b_theta, omega, row]
    one, cos, sin = 0, 1, 2
    T_W[one, cos, 0, 0] = 1.0  # ct w1
    T_W[sin, sin, 1, 0] = 1.0  # sf st w2
    T_W[cos, sin, 2, 0] = 1.0  # cf st w3
    T_W[cos, cos, 1, 1] = 1.0  # cf ct w2
    T_W[sin, cos, 2, 1] = -1.0  # -sf ct w3
    T_W[sin, one, 1, 2] = 1.0  # sf w2
    T_W[cos, one, 2, 2] = 1.0  # cf w3
    return T_R, T_W.reshape(27, 3)


_T_R, _T_W = _trilinear_maps()


def _trig_basis(Theta: Tensor) -> Tensor:
    """``(..., 3 angles, 3)``: row ``a`` is ``(1, cos a, sin a)`` for ``a = phi, theta, psi``."""
    c = torch.cos(Theta)
    return torch.stack([torch.ones_like(c), c, torch.sin(Theta)], dim=-1)


def _outer3(a: Tensor, b: Tensor, c: Tensor) -> Tensor:
    """``a (x) b (x) c`` flattened: (..., 3) x3 -> (..., 27), index ``9 i + 3 j + k``."""
    return ((a.unsqueeze(-1) * b.unsqueeze(-2)).unsqueeze(-1) * c.unsqueeze(-2).unsqueeze(-2)).flatten(-3)


def _rotation_from_basis(b_psi: Tensor, b_theta: Tensor, b_phi: Tensor, T_R: Tensor) -> Tensor:
    """``R`` (..., 3, 3) from the (1, cos, sin) bases of psi, theta, phi (see :func:`_trilinear_maps`)."""
    return (_outer3(b_psi, b_theta, b_phi) @ T_R).unflatten(-1, (3, 3))


def _rotation_matrix(Theta: Tensor) -> Tensor:
    """``R = Rz(psi) Ry(theta) Rx(phi)``, i.e. ::

        [[cp ct, cp st sf - sp cf, cp st cf + sp sf],
         [sp ct, sp st sf + cp cf, sp st cf - cp sf],
         [-st,   ct sf,            ct cf           ]]

    (``c``/``s`` cos/sin, ``f`` phi, ``t`` theta, ``p`` psi), by the trilinear map of :func:`_trilinear_maps`.
    """
    basis = _trig_basis(Theta)
    return _rotation_from_basis(basis[..., 2, :], basis[..., 1, :], basis[..., 0, :],
                                _T_R.to(dtype=Theta.dtype, device=Theta.device))


def rotation_matrix(Theta: Tensor) -> Tensor:
    """Body-to-world rotation ``R = Rz(psi) Ry(theta) Rx(phi)`` (Euler ZYX).

    Parameters
    ----------
    Theta : Tensor, shape (..., 3)
        Euler angles ``(phi roll, theta pitch, psi yaw)`` in rad.

    Returns
    -------
    Tensor, shape (..., 3, 3)
    """
    return _rotation_matrix(_check_last(Theta, 3, "Theta"))


def _euler_rate_matrix(Theta: Tensor) -> Tensor:
    phi, theta = Theta[..., 0], Theta[..., 1]
    cf, sf = torch.cos(phi), torch.sin(phi)
    ct, tt = torch.cos(theta), torch.tan(theta)
    zero, one = torch.zeros_like(phi), torch.ones_like(phi)
    return _mat3([one, sf * tt, cf * tt, zero, cf, -sf, zero, sf / ct, cf / ct])


def euler_rate_matrix(Theta: Tensor) -> Tensor:
    """``W(Theta)`` of Eq. (27): ``Theta' = W(Theta) omega`` for ZYX Euler angles and body rates.

    Parameters
    ----------
    Theta : Tensor, shape (..., 3)

    Returns
    -------
    Tensor, shape (..., 3, 3)
        ``[[1, sin(phi) tan(theta), cos(phi) tan(theta)], [0, cos(phi), -sin(phi)],
        [0, sin(phi)/cos(theta), cos(phi)/cos(theta)]]``; singular at
        ``|theta| = pi/2`` (gimbal lock).
    """
    return _euler_rate_matrix(_check_last(Theta, 3, "Theta"))


def _inverse_euler_rate_matrix(Theta: Tensor) -> Tensor:
    phi, theta = Theta[..., 0], Theta[..., 1]
    cf, sf = torch.cos(phi), torch.sin(phi)
    ct, st = torch.cos(theta), torch.sin(theta)
    zero, one = torch.zeros_like(phi), torch.ones_like(phi)
    return _mat3([one, zero, -st, zero, cf, sf * ct, zero, -sf, cf * ct])


def matvec(M: Tensor, v: Tensor) -> Tensor:
    """Batched ``M v`` for ``M`` (..., k, n) and ``v`` (..., n), leading dims broadcast; returns (..., k)."""
    return (M @ v.unsqueeze(-1)).squeeze(-1)


def rmatvec(M: Tensor, v: Tensor) -> Tensor:
    """Batched ``M^T v`` for ``M`` (..., n, k) and ``v`` (..., n); returns (..., k)."""
    return (v.unsqueeze(-2) @ M).squeeze(-2)


def inverse_euler_rate_matrix(Theta: Tensor) -> Tensor:
    """``W(Theta)^{-1}``: body rates from Euler-angle rates, ``omega = W^{-1} Theta'``.

    Parameters
    ----------
    Theta : Tensor, shape (..., 3)

    Returns
    -------
    Tensor, shape (..., 3, 3)
        ``[[1, 0, -sin(theta)], [0, cos(phi), sin(phi) cos(theta)], [0, -sin(phi), cos(phi) cos(theta)]]``
        (defined everywhere, unlike ``W``).
    """
    return _inverse_euler_rate_matrix(_check_last(Theta, 3, "Theta"))


def euler_from_rotation(R: Tensor) -> Tensor:
    """ZYX Euler angles of a rotation matrix, the inverse of :func:`rotation_matrix` for ``|theta| < pi/2``.

    Parameters
    ----------
    R : Tensor, shape (..., 3, 3)

    Returns
    -------
    Tensor, shape (..., 3)
        ``(phi, theta, psi)`` with ``phi, psi`` in ``(-pi, pi]``, ``theta`` in ``[-pi/2, pi/2]``.
    """
    if not isinstance(R, Tensor) or R.ndim < 2 or R.shape[-2:] != (3, 3):
        raise ValueError(f"R must be a tensor of shape (..., 3, 3), got {getattr(R, 'shape', type(R).__name__)}")
    check_finite(R, name="R")
    phi = torch.atan2(R[..., 2, 1], R[..., 2, 2])
    theta = torch.asin(torch.clamp(-R[..., 2, 0], -1.0, 1.0))
    psi = torch.atan2(R[..., 1, 0], R[..., 0, 0])
    return torch.stack([phi, theta, psi], dim=-1)


# --------------------------------------------------------------------------- allocation


def allocation_matrix(
    params: QuadrotorParams = NOMINAL, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None
) -> Tensor:
    """Control allocation ``C`` of Eq. (27): ``[T, tau_x, tau_y, tau_z] = C u``.

    With ``d = l / sqrt(2)`` and ``c`` the torque coefficient::

        T     =    u1 + u2 + u3 + u4
        tau_x = d(-u1 + u2 + u3 - u4)
        tau_y = d( u1 - u2 + u3 - u4)
        tau_z = c( u1 + u2 - u3 - u4)

    (each motor at ``r_i`` in B pushing ``-u_i e3`` gives ``r_i x (-u_i e3)``).

    Returns
    -------
    Tensor, shape (4, 4)
    """
    d, c = params.moment_arm, params.torque_coeff
    rows = [[1.0, 1.0, 1.0, 1.0], [-d, d, d, -d], [d, -d, d, -d], [c, c, -c, -c]]
    return torch.tensor(rows, dtype=dtype, device=device)


def allocation_inverse(
    params: QuadrotorParams = NOMINAL, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None
) -> Tensor:
    """``C^{-1}``: motor thrusts from ``[T, tau]``, ``u = C^{-1} [T, tau]``.

    The rows of ``C`` are orthogonal, so ``C^{-1} = C^T diag(1/4, 1/(4d^2), 1/(4d^2), 1/(4c^2))``
    (exact, no numerical inversion).

    Returns
    -------
    Tensor, shape (4, 4)
    """
    d, c = params.moment_arm, params.torque_coeff
    C = allocation_matrix(params, dtype=dtype, device=device)
    scale = torch.tensor([0.25, 0.25 / d**2, 0.25 / d**2, 0.25 / c**2], dtype=dtype, device=device)
    return C.T * scale


class _Constants(NamedTuple):
    e3: Tensor  # (3,)
    J: Tensor  # (3,) inertia diagonal
    D: Tensor  # (3,) drag diagonal
    F: Tensor  # (3,) force disturbance
    C_T: Tensor  # (4, 4) allocation, transposed (u @ C_T = [T, tau])
    C_inv_T: Tensor  # (4, 4) inverse allocation, transposed ([T, tau] @ C_inv_T = u)
    S_T: Tensor  # (4, 4) scaled allocation: u @ S_T = [T / m, tau / J]
    a0: Tensor  # (3,) input-free acceleration g e3 + F / m
    T_R: Tensor  # (27, 9) trilinear map of the rotation matrix
    T_W: Tensor  # (27, 3) trilinear map of cos(theta) W(Theta) omega


@functools.lru_cache(maxsize=64)
def constants(params: QuadrotorParams, dtype: torch.dtype, device: torch.device) -> _Constants:
    """Constant tensors of ``params`` for a dtype/device, built once (read-only by convention).

    Built outside inference mode so that the cached tensors can be saved for
    backward in later autograd use.
    """
    with torch.inference_mode(False):
        return _make_constants(params, dtype, device)


def _make_constants(params: QuadrotorParams, dtype: torch.dtype, device: torch.device) -> _Constants:
    e3 = torch.tensor([0.0, 0.0, 1.0], dtype=dtype, device=device)
    J = torch.tensor(params.inertia, dtype=dtype, device=device)
    F = torch.tensor(params.force_disturbance, dtype=dtype, device=device)
    C_T = allocation_matrix(params, dtype=dtype, device=device).T.contiguous()
    scale = torch.cat([torch.tensor([params.mass], dtype=dtype, device=device), J])
    return _Constants(
        e3=e3,
        J=J,
        D=torch.tensor(params.drag, dtype=dtype, device=device),
        F=F,
        C_T=C_T,
        C_inv_T=allocation_inverse(params, dtype=dtype, device=device).T.contiguous(),
        S_T=(C_T / scale).contiguous(),
        a0=params.g * e3 + F / params.mass,
        T_R=_T_R.to(dtype=dtype, device=device),
        T_W=_T_W.to(dtype=dtype, device=device),
    )


# --------------------------------------------------------------------------- integration


def rk4(fun: Callable[[Tensor], Tensor], y: Tensor, dt: float, substeps: int = 1, k1: Tensor | None = None) -> Tensor:
    """Classical fourth-order Runge-Kutta over ``dt`` in ``substeps`` equal sub-steps of ``y' = fun(y)``.

    Parameters
    ----------
    fun : callable, Tensor (..., n) -> Tensor (..., n)
        Right-hand side, evaluated four times per sub-step.
    y : Tensor, shape (..., n)
    dt : float
        Step length (> 0; not checked here, see :func:`check_step`).
    substeps : int
        Number of equal RK4 sub-steps (>= 1).
    k1 : Tensor, shape (..., n), optional
        ``fun(y)`` if the caller has it already (it is the change rate at the start);
        used for the first sub-step only.

    Returns
    -------
    Tensor, shape (..., n)
    """
    h = dt / substeps
    for i in range(substeps):
        if i > 0 or k1 is None:
            k1 = fun(y)
        k2 = fun(torch.add(y, k1, alpha=0.5 * h))
        k3 = fun(torch.add(y, k2, alpha=0.5 * h))
        k4 = fun(torch.add(y, k3, alpha=h))
        # y + h/6 (k1 + 2 k2 + 2 k3 + k4), in fused adds (the step is bound by per-op overhead)
        y = torch.add(y, torch.add(torch.add(k1, k4), torch.add(k2, k3), alpha=2.0), alpha=h / 6.0)
    return y


def check_step(dt: float, substeps: int) -> tuple[float, int]:
    """Validate an integration step: ``dt`` finite and > 0, ``substeps`` an int >= 1."""
    if isinstance(dt, bool) or not isinstance(dt, (int, float)):
        raise TypeError(f"dt must be a float, got {type(dt).__name__}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite positive number, got {dt!r}")
    if isinstance(substeps, bool) or not isinstance(substeps, int):
        raise TypeError(f"substeps must be an int, got {type(substeps).__name__}")
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    return float(dt), substeps


def _broadcast_lead(*shapes: torch.Size, names: Sequence[str]) -> torch.Size:
    try:
        return torch.broadcast_shapes(*shapes)
    except RuntimeError as err:
        listed = ", ".join(f"{n} {tuple(s)}" for n, s in zip(names, shapes, strict=True))
        raise ValueError(f"leading dimensions do not broadcast: {listed}") from err


# --------------------------------------------------------------------------- the model


class Quadrotor:
    """Eq. (27) `quadrotor_model` with rotor drag, a constant force disturbance and an optional residual.

    Parameters
    ----------
    params : QuadrotorParams
        Physical parameters; :data:`NOMINAL` by default.

    Notes
    -----
    All methods are batched over arbitrary leading dimensions, pure torch
    (differentiable), and follow the dtype/device of the state. Public methods
    validate their input (shapes, finiteness); the integrators validate once
    and then use the unchecked right-hand side.
    """

    n: ClassVar[int] = 12
    m: ClassVar[int] = 4

    def __init__(self, params: QuadrotorParams = NOMINAL) -> None:
        if not isinstance(params, QuadrotorParams):
            raise TypeError(f"params must be a QuadrotorParams, got {type(params).__name__}")
        self.params = params

    def __repr__(self) -> str:
        return f"Quadrotor({self.params!r})"

    # ----------------------------------------------------------------- checks
    def check_inputs(self, x: Tensor, u: Tensor | None = None) -> torch.Size:
        """Check ``x`` (..., 12) and ``u`` (..., 4): float tensors, finite, broadcastable leading dims.

        Returns
        -------
        torch.Size
            The broadcast leading shape.
        """
        _check_last(x, self.n, "x")
        if u is None:
            return x.shape[:-1]
        _check_last(u, self.m, "u")
        if u.dtype != x.dtype:
            raise TypeError(f"x and u must share a dtype, got {x.dtype} and {u.dtype}")
        return _broadcast_lead(x.shape[:-1], u.shape[:-1], names=("x", "u"))

    # ----------------------------------------------------------------- dynamics
    def _drag(self, v: Tensor, R: Tensor) -> Tensor:
        D = self._constants(v).D
        return -matvec(R, D * rmatvec(R, v))

    def _constants(self, like: Tensor) -> _Constants:
        key = (like.dtype, like.device)
        cache = self.__dict__.setdefault("_constants_cache", {})
        if key not in cache:
            cache[key] = constants(self.params, like.dtype, like.device)
        return cache[key]

    def _f(self, x: Tensor, u: Tensor, a_res: Tensor | None = None) -> Tensor:
        """Eq. (27) without checks, in few batched ops (see :func:`_trilinear_maps`)."""
        prm = self.params
        k = self._constants(x)
        v, omega = x[..., 3:6], x[..., 9:12]
        basis = _trig_basis(x[..., 6:9])  # rows (1, cos, sin) of phi, theta, psi
        b_phi, b_theta = basis[..., 0, :], basis[..., 1, :]
        R = _rotation_from_basis(basis[..., 2, :], b_theta, b_phi, k.T_R)
        s = u @ k.S_T  # [T / m, tau / J]
        # v' = -(T / m) R e3 + g e3 + F / m - R D R^T v + a_res
        v_dot = k.a0 - s[..., :1] * R[..., :, 2]
        if any(prm.drag):
            v_dot = v_dot - matvec(R, k.D * rmatvec(R, v))
        if a_res is not None:
            v_dot = v_dot + a_res
        # Theta' = W(Theta) omega ;  omega' = J^{-1} (tau - omega x J omega)
        Theta_dot = (_outer3(b_phi, b_theta, omega) @ k.T_W) / b_theta[..., 1:2]
        omega_dot = s[..., 1:] - torch.linalg.cross(omega, k.J * omega) / k.J
        parts = (v, v_dot, Theta_dot, omega_dot)
        if not all(p.shape == v_dot.shape for p in parts):  # leading dims of x, u, a_res broadcast
            lead = v_dot.shape[:-1] if v_dot.ndim >= v.ndim else v.shape[:-1]
            lead = torch.broadcast_shapes(lead, *(p.shape[:-1] for p in parts))
            parts = tuple(p.expand(*lead, 3) for p in parts)
        return torch.cat(parts, dim=-1)

    def f(self, x: Tensor, u: Tensor, a_res: Tensor | None = None) -> Tensor:
        """Right-hand side of Eq. (27) `quadrotor_model`.

        Parameters
        ----------
        x : Tensor, shape (..., 12)
            State ``[p, v, Theta, omega]``.
        u : Tensor, shape (..., 4)
            Motor thrusts in N; leading dims broadcast against ``x``.
        a_res : Tensor, shape (..., 3), optional
            Extra world-frame acceleration added to ``v'`` (a learned residual).

        Returns
        -------
        Tensor, shape (broadcast(...), 12)
            ``x' = [v, v', Theta', omega']``.
        """
        lead = self.check_inputs(x, u)
        if a_res is not None:
            _check_last(a_res, 3, "a_res")
            _broadcast_lead(lead, a_res.shape[:-1], names=("x/u", "a_res"))
        return self._f(x, u, a_res)

    def drag_acceleration(self, x: Tensor) -> Tensor:
        """Rotor-drag acceleration ``-R D R^T v`` (App. A.5).

        Parameters
        ----------
        x : Tensor, shape (..., 12)

        Returns
        -------
        Tensor, shape (..., 3)
        """
        self.check_inputs(x)
        return self._drag(x[..., 3:6], _rotation_matrix(x[..., 6:9]))

    def _step(self, x: Tensor, u: Tensor, dt: float, substeps: int, a_res_fn: AccelerationFn | None,
              k1: Tensor | None = None) -> Tensor:
        if a_res_fn is None:
            return rk4(lambda y: self._f(y, u), x, dt, substeps, k1)
        return rk4(lambda y: self._f(y, u, a_res_fn(y)), x, dt, substeps, k1)

    def step(
        self,
        x: Tensor,
        u: Tensor,
        dt: float = 0.02,
        substeps: int = 1,
        a_res_fn: AccelerationFn | None = None,
        k1: Tensor | None = None,
    ) -> Tensor:
        """One classical RK4 step of Eq. (27) with the input held (zero-order hold).

        Parameters
        ----------
        x : Tensor, shape (..., 12)
        u : Tensor, shape (..., 4)
            Held constant over ``dt``.
        dt : float
            Step length in s.
        substeps : int
            Equal RK4 sub-steps within ``dt``.
        a_res_fn : callable, Tensor (..., 12) -> Tensor (..., 3), optional
            Residual acceleration, evaluated at every RK4 stage.
        k1 : Tensor, shape (broadcast(...), 12), optional
            ``f(x, u, a_res_fn(x))`` if the caller computed it already (saves one evaluation).

        Returns
        -------
        Tensor, shape (broadcast(...), 12)
        """
        dt, substeps = check_step(dt, substeps)
        lead = self.check_inputs(x, u)
        if k1 is not None and tuple(k1.shape) != (*lead, self.n):
            raise ValueError(f"k1 must have shape {(*lead, self.n)}, got {tuple(k1.shape)}")
        return self._step(x.expand(*lead, self.n), u, dt, substeps, a_res_fn, k1)

    def rollout(
        self,
        x0: Tensor,
        u_seq: Tensor,
        dt: float = 0.02,
        substeps: int = 1,
        a_res_fn: AccelerationFn | None = None,
    ) -> Tensor:
        """Open-loop simulation under a zero-order-hold input sequence.

        Parameters
        ----------
        x0 : Tensor, shape (..., 12)
        u_seq : Tensor, shape (..., T, 4)
            ``u_seq[..., k, :]`` is held over ``[k dt, (k+1) dt)``.
        dt, substeps, a_res_fn
            As in :meth:`step`.

        Returns
        -------
        Tensor, shape (broadcast(...), T + 1, 12)
            ``x0`` followed by the ``T`` states after each step.
        """
        dt, substeps = check_step(dt, substeps)
        _check_last(u_seq, self.m, "u_seq")
        if u_seq.ndim < 2:
            raise ValueError(f"u_seq must have shape (..., T, 4), got shape {tuple(u_seq.shape)}")
        lead = self.check_inputs(x0)
        if u_seq.dtype != x0.dtype:
            raise TypeError(f"x0 and u_seq must share a dtype, got {x0.dtype} and {u_seq.dtype}")
        lead = _broadcast_lead(lead, u_seq.shape[:-2], names=("x0", "u_seq (without T)"))
        x = x0.expand(*lead, self.n)
        out = [x]
        for k in range(u_seq.shape[-2]):
            x = self._step(x, u_seq[..., k, :], dt, substeps, a_res_fn)
            out.append(x)
        return torch.stack(out, dim=-2)

    def hover_input(self, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None) -> Tensor:
        """Motor thrusts that hold the vehicle still without drag or disturbance: ``m g / 4`` each.

        Returns
        -------
        Tensor, shape (4,)
        """
        return torch.full((self.m,), self.params.mass * self.params.g / 4.0, dtype=dtype, device=device)
