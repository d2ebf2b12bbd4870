r"""Differential-flatness-based controller (DFBC) of App. A.5, Mellinger style, with internal states.

The paper writes the controller as :math:`[\dot z, u] = \pi(z, x, \bar\Psi)`, with
``z`` the auxiliary states "for the integrators and approximated derivatives in
the rotational controller", and the closed loop as
:math:`[\dot x, \dot z] = \Phi([x, z], \bar\Psi)` (18 states), the stable system
through which the aerodynamic residual is learned end to end. Here:

Translational loop
    :math:`a_{des} = a_r + K_p (p_r - p) + K_v (v_r - v)`; thrust vector
    :math:`h = g e_3 - a_{des}`, desired zero-yaw attitude :math:`\Theta_{des}` with
    :math:`z_{B,des} = h / \lVert h\rVert` and collective thrust
    :math:`T = m\, z_{B,des}\cdot h = m\lVert h\rVert` (the flat map of
    :mod:`fnnlib.quadrotor.control.flatness` applied to :math:`a_{des}`); feed-forward body
    rates :math:`\omega_{des}` from the reference jerk :math:`j_r` by the same flat map.

Attitude loop
    :math:`\dot\Theta_{des} = K_\Theta\,\mathrm{wrap}(\Theta_{des} - \Theta)`,
    rate error :math:`e_\omega = \omega_{des} + W(\Theta)^{-1}\dot\Theta_{des} - \omega`,
    PID :math:`\alpha = K_{p,\omega} e_\omega + K_{i,\omega} z_I + K_{d,\omega}\dot e_\omega`
    with a first-order ("dirty") derivative of time constant :math:`\tau_f`:
    :math:`\dot z_F = (e_\omega - z_F)/\tau_f`, :math:`\dot e_\omega \approx (e_\omega - z_F)/\tau_f`,
    and :math:`\dot z_I = e_\omega`. Torque :math:`\tau = J\alpha + \omega\times J\omega`,
    thrusts :math:`u = C^{-1}[T, \tau]`.

``z = [z_I (3), z_F (3)]``. The controller uses its own model parameters
(the paper's: :data:`~fnnlib.quadrotor.system.NOMINAL`), never the plant's.
The gains of the authors' release are :data:`~fnnlib.quadrotor.presets.PAPER_DFBC_GAINS`.

Notes
-----
* No thrust clipping: the learning closed loop must stay smooth and
  differentiable; :meth:`DFBC.rollout` returns the applied thrusts so callers can
  report their range (e.g. against the MPC box ``0 <= u <= 4`` N).
* Derivative kick: with ``z_F(0) = 0`` the filtered derivative starts at
  ``e_omega(0) / tau_f``. Starting on the reference (the state from
  :func:`~fnnlib.quadrotor.control.flatness.flat_to_state`, including hover at rest)
  gives ``e_omega(0) = 0`` exactly, so there is no kick. Starting off the
  reference gives a kick of ``K_d e_omega(0) / tau_f`` (10 ``e_omega(0)`` on
  x/y with the default gains, a quarter of the proportional term) that decays
  with ``tau_f``; :meth:`DFBC.initial_closed_loop_state` with ``Psi_bar`` sets
  ``z_F(0) = e_omega(0)`` to remove it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import torch
from torch import Tensor

from fnnlib.quadrotor.control.flatness import check_params, flat_state_parts
from fnnlib.systems.integrator import check_step, rk4
from fnnlib.quadrotor.system import Quadrotor, QuadrotorParams, constants, vec3
from fnnlib.quadrotor.rotations import check_last, inverse_euler_rate_matrix, matvec

__all__ = ["DFBC"]

AccelerationFn = Callable[[Tensor], Tensor]
Gain = Sequence[float]


def _gain(value: Gain | float, name: str) -> tuple[float, float, float]:
    """A diagonal gain: one float for all three axes, or three floats; finite and non-negative."""
    scalar = isinstance(value, (int, float)) and not isinstance(value, bool)
    items = (float(value),) * 3 if scalar else vec3(value, name)  # type: ignore[arg-type]
    if not all(math.isfinite(v) and v >= 0 for v in items):
        raise ValueError(f"{name} must be finite and non-negative, got {tuple(items)}")
    return items


def _lead(*pairs: tuple[str, torch.Size]) -> torch.Size:
    try:
        return torch.broadcast_shapes(*(s for _, s in pairs))
    except RuntimeError as err:
        listed = ", ".join(f"{n} {tuple(s)}" for n, s in pairs)
        raise ValueError(f"leading dimensions do not broadcast: {listed}") from err


class DFBC:
    """Differential-flatness-based controller with PID rate loop (App. A.5).

    Parameters
    ----------
    params : QuadrotorParams
        The controller's model (mass, inertia, allocation, ``g``);
        the paper's is :data:`NOMINAL`. Must have equal x/y drag; a controller
        model with drag or a force disturbance compensates them through the
        flat map of :mod:`fnnlib.quadrotor.control.flatness` (the paper's DFBC has none).
    Kp, Kv : float or 3 floats
        Diagonal position and velocity gains; ``Kv`` defaults to ``4 Kp``.
    K_Theta : float or 3 floats
        Diagonal attitude gain (1/s).
    Kp_w, Ki_w, Kd_w : float or 3 floats
        Diagonal PID gains of the body-rate loop.
    tau_f : float
        Time constant of the dirty derivative, s (> 0).
    """

    nz: int = 6

    def __init__(
        self,
        params: QuadrotorParams,
        *,
        Kp: Gain | float,
        K_Theta: Gain | float,
        Kp_w: Gain | float,
        Ki_w: Gain | float,
        Kd_w: Gain | float,
        tau_f: float,
        Kv: Gain | float | None = None,
    ) -> None:
        self.params = check_params(params)
        self.Kp = _gain(Kp, "Kp")
        self.Kv = _gain(Kv, "Kv") if Kv is not None else (4.0 * self.Kp[0], 4.0 * self.Kp[1], 4.0 * self.Kp[2])
        self.K_Theta = _gain(K_Theta, "K_Theta")
        self.Kp_w = _gain(Kp_w, "Kp_w")
        self.Ki_w = _gain(Ki_w, "Ki_w")
        self.Kd_w = _gain(Kd_w, "Kd_w")
        if isinstance(tau_f, bool) or not isinstance(tau_f, (int, float)):
            raise TypeError(f"tau_f must be a float, got {type(tau_f).__name__}")
        if not (math.isfinite(tau_f) and tau_f > 0):
            raise ValueError(f"tau_f must be a finite positive number, got {tau_f!r}")
        self.tau_f = float(tau_f)
        self._gain_cache: dict[tuple[torch.dtype, torch.device], Tensor] = {}

    def __repr__(self) -> str:
        return (
            f"DFBC(Kp={self.Kp}, Kv={self.Kv}, K_Theta={self.K_Theta}, Kp_w={self.Kp_w}, "
            f"Ki_w={self.Ki_w}, Kd_w={self.Kd_w}, tau_f={self.tau_f})"
        )

    def _gains(self, like: Tensor) -> Tensor:
        """All diagonal gains as one tensor, shape (6, 3): Kp, Kv, K_Theta, Kp_w, Ki_w, Kd_w (cached)."""
        key = (like.dtype, like.device)
        G = self._gain_cache.get(key)
        if G is None:
            with torch.inference_mode(False):
                rows = [self.Kp, self.Kv, self.K_Theta, self.Kp_w, self.Ki_w, self.Kd_w]
                G = torch.tensor(rows, dtype=like.dtype, device=like.device)
            self._gain_cache[key] = G
        return G

    # ----------------------------------------------------------------- the law
    def _rate_error(self, x: Tensor, Psi_bar: Tensor) -> tuple[Tensor, Tensor]:
        """(e_omega, T) for state ``x`` and command ``Psi_bar``; unchecked."""
        p, v, Theta, omega = x[..., 0:3], x[..., 3:6], x[..., 6:9], x[..., 9:12]
        p_r, v_r, a_r, j_r = Psi_bar[..., 0:3], Psi_bar[..., 3:6], Psi_bar[..., 6:9], Psi_bar[..., 9:12]
        Kp, Kv, K_Theta = self._gains(x)[:3]
        a_des = a_r + Kp * (p_r - p) + Kv * (v_r - v)
        Theta_des, omega_des, T = flat_state_parts(v, a_des, j_r, self.params)
        e_Theta = Theta_des - Theta
        e_Theta = torch.atan2(torch.sin(e_Theta), torch.cos(e_Theta))  # wrap to (-pi, pi]
        omega_cmd = matvec(inverse_euler_rate_matrix(Theta, check=False), K_Theta * e_Theta)  # W^{-1} Theta'_des
        return omega_des + omega_cmd - omega, T

    def _control(self, x: Tensor, z: Tensor, Psi_bar: Tensor) -> tuple[Tensor, Tensor]:
        e_w, T = self._rate_error(x, Psi_bar)
        z_I, z_F = z[..., 0:3], z[..., 3:6]
        e_w_dot = (e_w - z_F) / self.tau_f
        Kp_w, Ki_w, Kd_w = self._gains(x)[3:]
        alpha = Kp_w * e_w + Ki_w * z_I + Kd_w * e_w_dot
        omega = x[..., 9:12]
        k = constants(self.params, x.dtype, x.device)
        tau = k.J * alpha + torch.linalg.cross(omega, k.J * omega)
        u = torch.cat([T, tau], dim=-1) @ k.C_inv_T
        return u, torch.cat([e_w, e_w_dot], dim=-1)

    def control(self, x: Tensor, z: Tensor, Psi_bar: Tensor) -> tuple[Tensor, Tensor]:
        """The controller :math:`[\\dot z, u] = \\pi(z, x, \\bar\\Psi)` of App. A.5.

        Parameters
        ----------
        x : Tensor, shape (..., 12)
            Measured state ``[p, v, Theta, omega]``.
        z : Tensor, shape (..., 6)
            Controller state ``[z_I, z_F]``.
        Psi_bar : Tensor, shape (..., 12)
            Command ``[p_r, v_r, a_r, j_r]``. Leading dims of all three broadcast.

        Returns
        -------
        u : Tensor, shape (..., 4)
            Motor thrusts in N (not clipped).
        z_dot : Tensor, shape (..., 6)
            ``[e_omega, (e_omega - z_F) / tau_f]``.
        """
        check_last(x, 12, "x")
        check_last(z, self.nz, "z")
        check_last(Psi_bar, 12, "Psi_bar")
        lead = _lead(("x", x.shape[:-1]), ("z", z.shape[:-1]), ("Psi_bar", Psi_bar.shape[:-1]))
        u, z_dot = self._control(x, z, Psi_bar)
        return u.expand(*lead, 4), z_dot.expand(*lead, self.nz)

    # ----------------------------------------------------------------- closed loop
    def initial_closed_loop_state(self, x: Tensor, Psi_bar: Tensor | None = None) -> Tensor:
        """Closed-loop state ``[x, z]`` with ``z_I = 0``.

        Parameters
        ----------
        x : Tensor, shape (..., 12)
        Psi_bar : Tensor, shape (..., 12), optional
            If given, ``z_F(0) = e_omega(0)`` (no derivative kick); otherwise ``z_F(0) = 0``.

        Returns
        -------
        Tensor, shape (..., 18)
        """
        check_last(x, 12, "x")
        if Psi_bar is None:
            return torch.cat([x, x.new_zeros(*x.shape[:-1], self.nz)], dim=-1)
        check_last(Psi_bar, 12, "Psi_bar")
        lead = _lead(("x", x.shape[:-1]), ("Psi_bar", Psi_bar.shape[:-1]))
        e_w, _ = self._rate_error(x, Psi_bar)
        x = x.expand(*lead, 12)
        return torch.cat([x, torch.zeros_like(e_w), e_w.expand(*lead, 3)], dim=-1)

    def _closed_loop(
        self, x18: Tensor, Psi_bar: Tensor, plant: Quadrotor, a_res_fn: AccelerationFn | None
    ) -> tuple[Tensor, Tensor]:
        x, z = x18[..., :12], x18[..., 12:]
        u, z_dot = self._control(x, z, Psi_bar)
        a_res = a_res_fn(x) if a_res_fn is not None else None
        x_dot = plant.rhs(x, u, a_res)
        lead = x_dot.shape[:-1]
        return torch.cat([x_dot, z_dot.expand(*lead, self.nz)], dim=-1), u

    def _check_loop(self, x18: Tensor, Psi_bar: Tensor, plant: Quadrotor, psi_name: str) -> torch.Size:
        if not isinstance(plant, Quadrotor):
            raise TypeError(f"plant must be a Quadrotor, got {type(plant).__name__}")
        check_last(x18, 12 + self.nz, "x18")
        check_last(Psi_bar, 12, psi_name)
        if Psi_bar.dtype != x18.dtype:
            raise TypeError(f"x18 and {psi_name} must share a dtype, got {x18.dtype} and {Psi_bar.dtype}")
        lead_psi = Psi_bar.shape[:-2] if psi_name == "Psi_seq" else Psi_bar.shape[:-1]
        return _lead(("x18", x18.shape[:-1]), (psi_name, lead_psi))

    def closed_loop(
        self, x18: Tensor, Psi_bar: Tensor, plant: Quadrotor, a_res_fn: AccelerationFn | None = None
    ) -> Tensor:
        """The closed loop :math:`[\\dot x, \\dot z] = \\Phi([x, z], \\bar\\Psi)` of App. A.5.

        Parameters
        ----------
        x18 : Tensor, shape (..., 18)
            ``[x (12), z (6)]``.
        Psi_bar : Tensor, shape (..., 12)
        plant : Quadrotor
            The vehicle flown (its own parameters; the controller keeps its model).
        a_res_fn : callable, Tensor (..., 12) -> Tensor (..., 3), optional
            Residual acceleration added to the plant (e.g. a neural ODE).

        Returns
        -------
        Tensor, shape (..., 18)
        """
        self._check_loop(x18, Psi_bar, plant, "Psi_bar")
        return self._closed_loop(x18, Psi_bar, plant, a_res_fn)[0]

    def _loop_step(
        self,
        x18: Tensor,
        Psi_bar: Tensor,
        plant: Quadrotor,
        Ts: float,
        substeps: int,
        a_res_fn: AccelerationFn | None,
    ) -> Tensor:
        return rk4(lambda y: self._closed_loop(y, Psi_bar, plant, a_res_fn)[0], x18, Ts, substeps)

    def closed_loop_step(self, x18: Tensor, Psi_bar: Tensor, plant: Quadrotor, *, Ts: float, substeps: int = 1,
                         a_res_fn: AccelerationFn | None = None) -> Tensor:
        """One RK4 step of the closed loop with ``Psi_bar`` held over the step.

        Parameters
        ----------
        x18 : Tensor, shape (..., 18)
        Psi_bar : Tensor, shape (..., 12)
        plant : Quadrotor
        Ts : float
            Step length, s.
        substeps : int
            Equal RK4 sub-steps.
        a_res_fn : callable, optional
            As in :meth:`closed_loop`, evaluated at every RK4 stage.

        Returns
        -------
        Tensor, shape (broadcast(...), 18)
        """
        Ts, substeps = check_step(Ts, substeps)
        lead = self._check_loop(x18, Psi_bar, plant, "Psi_bar")
        return self._loop_step(x18.expand(*lead, 18), Psi_bar, plant, Ts, substeps, a_res_fn)

    def rollout(self, x18_0: Tensor, Psi_seq: Tensor, plant: Quadrotor, *, Ts: float, substeps: int = 1,
                a_res_fn: AccelerationFn | None = None) -> tuple[Tensor, Tensor]:
        """Fly a command sequence in closed loop (RK4, command held over each step).

        Parameters
        ----------
        x18_0 : Tensor, shape (..., 18)
            Initial closed-loop state (see :meth:`initial_closed_loop_state`).
        Psi_seq : Tensor, shape (..., T, 12)
            ``Psi_seq[..., k, :]`` is held over ``[k Ts, (k+1) Ts)``; leading
            dims broadcast against ``x18_0``'s.
        plant : Quadrotor
        Ts, substeps, a_res_fn
            As in :meth:`closed_loop_step`.

        Returns
        -------
        X : Tensor, shape (..., T + 1, 18)
            Closed-loop states, ``X[..., 0, :] = x18_0``.
        U : Tensor, shape (..., T, 4)
            Thrusts applied at the start of each step (unclipped).
        """
        Ts, substeps = check_step(Ts, substeps)
        if isinstance(Psi_seq, Tensor) and Psi_seq.ndim < 2:
            raise ValueError(f"Psi_seq must have shape (..., T, 12), got shape {tuple(Psi_seq.shape)}")
        lead = self._check_loop(x18_0, Psi_seq, plant, "Psi_seq")
        y = x18_0.expand(*lead, 18)
        Psi_seq = Psi_seq.expand(*lead, *Psi_seq.shape[-2:])
        states, inputs = [y], []
        for k in range(Psi_seq.shape[-2]):
            Psi = Psi_seq[..., k, :]
            first: list[Tensor] = []

            def rhs(y_: Tensor, Psi: Tensor = Psi, first: list[Tensor] = first) -> Tensor:
                y_dot, u = self._closed_loop(y_, Psi, plant, a_res_fn)
                if not first:  # the first RK4 stage is the start of the step
                    first.append(u)
                return y_dot

            y = rk4(rhs, y, Ts, substeps)
            states.append(y)
            inputs.append(first[0])
        X = torch.stack(states, dim=-2)
        U = torch.stack(inputs, dim=-2) if inputs else y.new_zeros(*lead, 0, 4)
        return X, U
