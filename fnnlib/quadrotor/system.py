r"""The quadrotor of Sec. 5.3 (App. A.5): Eq. (27) `quadrotor_model`, batched and differentiable.

Frames and conventions (fixed; :mod:`fnnlib.quadrotor.control` relies on them):

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

The rotations ``R``, ``W`` live in :mod:`fnnlib.quadrotor.rotations`, the allocation ``C`` in
:mod:`fnnlib.quadrotor.allocation`, the RK4 integrator in :mod:`fnnlib.systems.integrator`; this module
holds Eq. (27) itself, its parameters and the vehicles of the paper (:data:`NOMINAL`,
:data:`TRAINING_TRUTH`, :data:`TEST_TRUTH`).
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

from fnnlib.quadrotor.allocation import allocation_inverse, allocation_matrix
from fnnlib.systems.integrator import check_step, rk4
from fnnlib.quadrotor.rotations import (
    T_R,
    T_W,
    check_last,
    matvec,
    outer3,
    rmatvec,
    rotation_from_basis,
    rotation_matrix,
    trig_basis,
)

__all__ = ["NOMINAL", "STATE_GROUPS", "TEST_TRUTH", "TRAINING_TRUTH", "Quadrotor", "QuadrotorConstants", "QuadrotorParams",
           "constants", "vec3"]

Vec3 = tuple[float, float, float]
AccelerationFn = Callable[[Tensor], Tensor]

STATE_GROUPS = {"p": slice(0, 3), "v": slice(3, 6), "Theta": slice(6, 9), "omega": slice(9, 12)}
"""Where each part of the state ``x = [p, v, Theta, omega]`` sits."""


def vec3(value: Sequence[float] | Tensor, name: str) -> Vec3:
    """``value`` as a tuple of 3 finite floats, refused with a message naming ``name`` otherwise."""
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
        inertia = vec3(self.inertia, "inertia")
        if min(inertia) <= 0:
            raise ValueError(f"inertia must be positive on every axis, got {inertia}")
        drag = vec3(self.drag, "drag")
        if min(drag) < 0:
            raise ValueError(f"drag must be non-negative on every axis, got {drag}")
        object.__setattr__(self, "inertia", inertia)
        object.__setattr__(self, "drag", drag)
        object.__setattr__(self, "force_disturbance", vec3(self.force_disturbance, "force_disturbance"))

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



class QuadrotorConstants(NamedTuple):
    """Constant tensors of one :class:`QuadrotorParams` for one dtype/device (see :func:`constants`)."""

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
def constants(params: QuadrotorParams, dtype: torch.dtype, device: torch.device) -> QuadrotorConstants:
    """Constant tensors of ``params`` for a dtype/device, built once (read-only by convention).

    Built outside inference mode so that the cached tensors can be saved for
    backward in later autograd use.
    """
    with torch.inference_mode(False):
        return _make_constants(params, dtype, device)


def _make_constants(params: QuadrotorParams, dtype: torch.dtype, device: torch.device) -> QuadrotorConstants:
    e3 = torch.tensor([0.0, 0.0, 1.0], dtype=dtype, device=device)
    J = torch.tensor(params.inertia, dtype=dtype, device=device)
    F = torch.tensor(params.force_disturbance, dtype=dtype, device=device)
    C_T = allocation_matrix(params, dtype=dtype, device=device).T.contiguous()
    scale = torch.cat([torch.tensor([params.mass], dtype=dtype, device=device), J])
    return QuadrotorConstants(
        e3=e3,
        J=J,
        D=torch.tensor(params.drag, dtype=dtype, device=device),
        F=F,
        C_T=C_T,
        C_inv_T=allocation_inverse(params, dtype=dtype, device=device).T.contiguous(),
        S_T=(C_T / scale).contiguous(),
        a0=params.g * e3 + F / params.mass,
        T_R=T_R.to(dtype=dtype, device=device),
        T_W=T_W.to(dtype=dtype, device=device),
    )



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
        Physical parameters (the paper's vehicles: :data:`NOMINAL`, :data:`TRAINING_TRUTH`, :data:`TEST_TRUTH`).

    Notes
    -----
    All methods are batched over arbitrary leading dimensions, pure torch
    (differentiable), and follow the dtype/device of the state. Public methods
    validate their input (shapes, finiteness); the integrators validate once
    and then use the unchecked right-hand side.
    """

    n: ClassVar[int] = 12
    m: ClassVar[int] = 4

    def __init__(self, params: QuadrotorParams) -> None:
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
        check_last(x, self.n, "x")
        if u is None:
            return x.shape[:-1]
        check_last(u, self.m, "u")
        if u.dtype != x.dtype:
            raise TypeError(f"x and u must share a dtype, got {x.dtype} and {u.dtype}")
        return _broadcast_lead(x.shape[:-1], u.shape[:-1], names=("x", "u"))

    # ----------------------------------------------------------------- dynamics
    def _drag(self, v: Tensor, R: Tensor) -> Tensor:
        D = self._constants(v).D
        return -matvec(R, D * rmatvec(R, v))

    def _constants(self, like: Tensor) -> QuadrotorConstants:
        key = (like.dtype, like.device)
        cache = self.__dict__.setdefault("_constants_cache", {})
        if key not in cache:
            cache[key] = constants(self.params, like.dtype, like.device)
        return cache[key]

    def rhs(self, x: Tensor, u: Tensor, a_res: Tensor | None = None) -> Tensor:
        """Eq. (27) without checks, for callers that checked once (the integrators, the DFBC loop, the flat map).

        Few batched ops (see :func:`fnnlib.quadrotor.rotations._trilinear_maps`); arguments as in :meth:`f`.
        """
        prm = self.params
        k = self._constants(x)
        v, omega = x[..., 3:6], x[..., 9:12]
        basis = trig_basis(x[..., 6:9])  # rows (1, cos, sin) of phi, theta, psi
        b_phi, b_theta = basis[..., 0, :], basis[..., 1, :]
        R = rotation_from_basis(basis[..., 2, :], b_theta, b_phi, k.T_R)
        s = u @ k.S_T  # [T / m, tau / J]
        # v' = -(T / m) R e3 + g e3 + F / m - R D R^T v + a_res
        v_dot = k.a0 - s[..., :1] * R[..., :, 2]
        if any(prm.drag):
            v_dot = v_dot - matvec(R, k.D * rmatvec(R, v))
        if a_res is not None:
            v_dot = v_dot + a_res
        # Theta' = W(Theta) omega ;  omega' = J^{-1} (tau - omega x J omega)
        Theta_dot = (outer3(b_phi, b_theta, omega) @ k.T_W) / b_theta[..., 1:2]
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
            check_last(a_res, 3, "a_res")
            _broadcast_lead(lead, a_res.shape[:-1], names=("x/u", "a_res"))
        return self.rhs(x, u, a_res)

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
        return self._drag(x[..., 3:6], rotation_matrix(x[..., 6:9], check=False))

    def _step(self, x: Tensor, u: Tensor, Ts: float, substeps: int, a_res_fn: AccelerationFn | None,
              k1: Tensor | None = None) -> Tensor:
        if a_res_fn is None:
            return rk4(lambda y: self.rhs(y, u), x, Ts, substeps, k1)
        return rk4(lambda y: self.rhs(y, u, a_res_fn(y)), x, Ts, substeps, k1)

    def step(self, x: Tensor, u: Tensor, *, Ts: float, substeps: int = 1, a_res_fn: AccelerationFn | None = None,
             k1: Tensor | None = None) -> Tensor:
        """One classical RK4 step of Eq. (27) with the input held (zero-order hold).

        Parameters
        ----------
        x : Tensor, shape (..., 12)
        u : Tensor, shape (..., 4)
            Held constant over ``Ts``.
        Ts : float
            Step length in s.
        substeps : int
            Equal RK4 sub-steps within ``Ts``.
        a_res_fn : callable, Tensor (..., 12) -> Tensor (..., 3), optional
            Residual acceleration, evaluated at every RK4 stage.
        k1 : Tensor, shape (broadcast(...), 12), optional
            ``f(x, u, a_res_fn(x))`` if the caller computed it already (saves one evaluation).

        Returns
        -------
        Tensor, shape (broadcast(...), 12)
        """
        Ts, substeps = check_step(Ts, substeps)
        lead = self.check_inputs(x, u)
        if k1 is not None and tuple(k1.shape) != (*lead, self.n):
            raise ValueError(f"k1 must have shape {(*lead, self.n)}, got {tuple(k1.shape)}")
        return self._step(x.expand(*lead, self.n), u, Ts, substeps, a_res_fn, k1)

    def rollout(self, x0: Tensor, u_seq: Tensor, *, Ts: float, substeps: int = 1,
                a_res_fn: AccelerationFn | None = None) -> Tensor:
        """Open-loop simulation under a zero-order-hold input sequence.

        Parameters
        ----------
        x0 : Tensor, shape (..., 12)
        u_seq : Tensor, shape (..., T, 4)
            ``u_seq[..., k, :]`` is held over ``[k Ts, (k+1) Ts)``.
        Ts, substeps, a_res_fn
            As in :meth:`step`.

        Returns
        -------
        Tensor, shape (broadcast(...), T + 1, 12)
            ``x0`` followed by the ``T`` states after each step.
        """
        Ts, substeps = check_step(Ts, substeps)
        check_last(u_seq, self.m, "u_seq")
        if u_seq.ndim < 2:
            raise ValueError(f"u_seq must have shape (..., T, 4), got shape {tuple(u_seq.shape)}")
        lead = self.check_inputs(x0)
        if u_seq.dtype != x0.dtype:
            raise TypeError(f"x0 and u_seq must share a dtype, got {x0.dtype} and {u_seq.dtype}")
        lead = _broadcast_lead(lead, u_seq.shape[:-2], names=("x0", "u_seq (without T)"))
        x = x0.expand(*lead, self.n)
        out = [x]
        for k in range(u_seq.shape[-2]):
            x = self._step(x, u_seq[..., k, :], Ts, substeps, a_res_fn)
            out.append(x)
        return torch.stack(out, dim=-2)

    def hover_input(self, *, dtype: torch.dtype = torch.float64, device: torch.device | str | None = None) -> Tensor:
        """Motor thrusts that hold the vehicle still without drag or disturbance: ``m g / 4`` each.

        Returns
        -------
        Tensor, shape (4,)
        """
        return torch.full((self.m,), self.params.mass * self.params.g / 4.0, dtype=dtype, device=device)
