r"""The closed-loop flight test of Sec. 5.2: linearized MPC (Eq. (28)) with a prediction model, on a truth vehicle."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor
from tqdm import tqdm

from fnnlib._validation import check_finite, check_positive
from fnnlib.quadrotor.control.flatness import flat_reference
from fnnlib.quadrotor.control.lissajous import lissajous
from fnnlib.quadrotor.mpc.backends import Backend, FlightBackend
from fnnlib.quadrotor.mpc.linearize import Linearization
from fnnlib.quadrotor.mpc.linearized import LinearizedMPC, MPCSolution, OSQPMPC, is_diverged
from fnnlib.quadrotor.mpc.models import PredictionModel
from fnnlib.quadrotor.system import Quadrotor, QuadrotorParams

__all__ = ["FlightResult", "FlightTest", "fly", "lissajous_reference", "tracking_rmse"]


def lissajous_reference(steps: int, N: int, *, Ts: float, params: QuadrotorParams,
                        curve: Mapping[str, float]) -> tuple[Tensor, Tensor]:
    """The flight-test reference (App. A.5.5) on the control grid, by differential flatness (zero yaw).

    ``params`` is the vehicle the reference is computed for (the paper's: the nominal model), ``curve``
    the parameters of :func:`~fnnlib.quadrotor.control.lissajous.lissajous` (the paper's:
    :data:`~fnnlib.quadrotor.presets.PAPER_LISSAJOUS`). Returns ``x_r`` (steps + N + 1, 12) and
    ``u_r`` (steps + N, 4), float64, for ``t = 0, Ts, ...``; the extra ``N`` rows feed the last horizons.
    """
    t = np.arange(int(steps) + int(N) + 1) * check_positive(Ts, name="Ts")
    ref = lissajous(t, **curve)
    as_t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float64)  # noqa: E731
    Psi = torch.cat([as_t(ref.p), as_t(ref.v), as_t(ref.a), as_t(ref.j)], dim=-1)
    x_r, u_r = flat_reference(Psi, as_t(ref.s), params=params)
    return x_r, u_r[:-1]


@dataclass
class FlightResult:
    """One MPC flight: what happened and what the model predicted.

    Shapes: ``x`` (T+1, 12) flown states, ``u`` (T, 4) applied thrusts,
    ``x_ref`` (T+1, 12), ``xdot_true`` / ``xdot_pred`` (T, 12) the truth's and
    the model's change rate at each measured state and applied input (Fig.
    S8), ``x_tilde`` (T, 12) the layer-0 observation error (NaN where the model
    has none), ``delta`` (T, 12) the model's one-step residual
    :math:`(x_{t+1} - \\Phi(x_t, u_t)) / T_s` without feedback (for Theorems 1-2).
    ``t_linearize`` / ``t_solve`` (T,) are the seconds each step spent linearizing
    and solving; ``elapsed_s`` the wall time of the whole :func:`fly` call.
    ``n_reference_linearizations`` counts the steps after the first where the
    previous plan had left the model's domain (its linearization was not
    finite, as in a diverging flight) and the model was linearized along the
    reference instead. ``fallback_reasons`` counts the MPC's fallbacks per
    reason and ``n_reference_fallbacks`` those that flew the reference input
    (see :meth:`~fnnlib.quadrotor.mpc.linearized.LinearizedMPC.solve`), counted from this
    flight's solutions (:func:`fallback_counts`); :attr:`diverged`
    marks a flight with too many fallbacks.
    """

    name: str
    x: np.ndarray
    u: np.ndarray
    x_ref: np.ndarray
    xdot_true: np.ndarray
    xdot_pred: np.ndarray
    x_tilde: np.ndarray
    delta: np.ndarray
    t_linearize: np.ndarray
    t_solve: np.ndarray
    n_fallbacks: int
    Ts: float
    statuses: list[str] = field(default_factory=list)
    n_reference_linearizations: int = 0
    elapsed_s: float = float("nan")
    fallback_reasons: dict[str, int] = field(default_factory=dict)
    n_reference_fallbacks: int = 0

    @property
    def fallback_share(self) -> float:
        """Share of the steps that flew the MPC's fallback (reasons in :attr:`fallback_reasons`)."""
        return self.n_fallbacks / len(self.u)

    @property
    def diverged(self) -> bool:
        """True when :attr:`fallback_share` exceeds :data:`~fnnlib.quadrotor.mpc.linearized.DIVERGED_FALLBACK_SHARE`."""
        return is_diverged(self.n_fallbacks, len(self.u))

    @property
    def wall_time(self) -> float:
        """Seconds spent linearizing and solving (the controller's share of :attr:`elapsed_s`)."""
        return float(self.t_linearize.sum() + self.t_solve.sum())

    @property
    def real_time_factor(self) -> float:
        """Flown time over the wall time of the whole loop (simulation and bookkeeping included)."""
        return float(len(self.u) * self.Ts / self.elapsed_s)


def tracking_rmse(x: np.ndarray, x_ref: np.ndarray) -> dict[str, float]:
    """Position tracking RMSE: per axis, their mean (the paper's number) and the RMSE of the error norm."""
    e = np.asarray(x)[:, :3] - np.asarray(x_ref)[:, :3]
    per_axis = np.sqrt(np.mean(e**2, axis=0))
    return {"x": float(per_axis[0]), "y": float(per_axis[1]), "z": float(per_axis[2]),
            "mean_axis": float(per_axis.mean()), "norm": float(np.sqrt(np.mean(np.sum(e**2, axis=1))))}


@dataclass(frozen=True)
class FlightTest:
    r"""What every flight of a test shares: the truth vehicle, the reference and the loop settings of :func:`fly`.

    ``x_r`` (steps + N + 1, 12) and ``u_r`` (steps + N, 4) are the reference states and inputs on the control
    grid (from flatness, :func:`lissajous_reference`); ``Ts`` the control step in s, the model's (the paper's:
    0.02); ``substeps`` the truth's RK4 sub-steps per ``Ts`` (the paper run: 1); ``backend`` who does the
    numerics of each step (:class:`~fnnlib.quadrotor.mpc.backends.Backend`: the torch reference with its linearization
    method, or the compiled twins with exact Jacobians, the paper run). The models' online hooks are torch
    either way.
    """

    truth: Quadrotor
    x_r: Tensor
    u_r: Tensor
    steps: int
    Ts: float
    substeps: int
    backend: Backend

    def __post_init__(self) -> None:
        check_positive(self.Ts, name="Ts")
        if not isinstance(self.backend, Backend):
            raise TypeError(f"backend must be a fnnlib.quadrotor.mpc.Backend, got {self.backend!r}")
        if int(self.steps) < 1:
            raise ValueError(f"steps must be >= 1, got {self.steps}")


def fallback_counts(solutions: list[MPCSolution]) -> tuple[int, dict[str, int], int]:
    """The fallbacks among a flight's solutions: how many, how many per reason (first seen first), how many
    flew the reference input."""
    reasons = Counter(s.reason for s in solutions if s.fallback)
    return sum(s.fallback for s in solutions), dict(reasons), sum(s.reference_input for s in solutions)


def fly(model: PredictionModel, mpc: LinearizedMPC | OSQPMPC, test: FlightTest, *, x0: Tensor | None = None,
        progress: bool = False) -> FlightResult:
    r"""Fly ``test.steps`` control steps of the MPC with ``model`` on the test's truth vehicle.

    At step ``t``: the model observes the measured state; the model is
    linearized along the previous plan shifted by one step (the reference at
    the first step), with the measured state as the first point; the QP of
    Eq. (28) is solved against the reference ``x_r[t+1 .. t+N]``,
    ``u_r[t .. t+N-1]``; ``u_0`` is applied to the truth for ``Ts`` (RK4 with
    ``substeps``); the model commits the plan.

    Parameters
    ----------
    test : FlightTest
        The vehicle, the reference (shapes (steps + N + 1, 12) and (steps + N, 4) for the MPC's ``N``) and
        the loop settings.
    x0 : Tensor, shape (12,), optional
        Initial state; default ``x_r[0]``.
    """
    t_start = time.perf_counter()
    steps, N, Ts = int(test.steps), int(mpc.N), test.Ts
    x_r = torch.as_tensor(test.x_r, dtype=torch.float64)
    u_r = torch.as_tensor(test.u_r, dtype=torch.float64)
    if x_r.shape != (steps + N + 1, 12) or u_r.shape != (steps + N, 4):
        raise ValueError(f"reference must be x_r ({steps + N + 1}, 12) and u_r ({steps + N}, 4) for steps={steps}, "
                         f"N={N}; got {tuple(x_r.shape)} and {tuple(u_r.shape)}")
    check_finite(x_r, name="x_r")
    check_finite(u_r, name="u_r")
    x = (x_r[0] if x0 is None else torch.as_tensor(x0, dtype=torch.float64)).clone()
    check_finite(x, name="x0")
    numerics: FlightBackend = test.backend.build(model, test.truth, Ts=Ts, substeps=test.substeps, N=N)
    model.reset()
    mpc.reset()
    u_lb, u_ub = np.asarray(mpc.u_lb, dtype=np.float64), np.asarray(mpc.u_ub, dtype=np.float64)
    X_r, U_r = x_r.numpy(), u_r.numpy()
    as_t = torch.from_numpy  # the loop works in numpy; the models' hooks see torch views

    def linearize_at(x_bar: np.ndarray, u_bar: np.ndarray) -> Linearization | None:
        """The model's affine form along (x_bar, u_bar), or None where it is not finite there."""
        try:
            return numerics.linearize(x_bar, u_bar)
        except ValueError:  # a NaN/inf point or output, refused by either linearization
            return None

    x = x.numpy().copy()
    n_reference = 0
    xs, us = [x], []
    xdot_true, xdot_pred, x_tilde, delta = [], [], [], []
    t_lin, t_sol, solutions = np.zeros(steps), np.zeros(steps), []
    plan_x: np.ndarray | None = None
    plan_u: np.ndarray | None = None
    bar = tqdm(range(steps), desc=model.name, disable=not progress, leave=False)
    for t in bar:
        x_t = as_t(x)
        model.observe(x_t)
        e = model.observer_error
        x_tilde.append(np.full(12, np.nan) if e is None else e.numpy().copy())
        # linearisation point: the previous plan shifted by one step, starting at the measured state
        tic = time.perf_counter()
        lin = None
        if plan_x is not None and plan_u is not None:
            lin = linearize_at(np.vstack([x, plan_x[2:N + 1]]), np.vstack([plan_u[1:], plan_u[-1:]]))
            n_reference += lin is None
        if lin is None:  # the first step, or a plan outside the model's domain: along the reference
            lin = linearize_at(np.vstack([x, X_r[t + 1:t + N]]), U_r[t:t + N].copy())
            if lin is None:
                raise ValueError(f"step {t}: the model's linearization at the measured state and the reference is "
                                 f"not finite (state {x.round(3).tolist()}); the flight has left the model's domain")
        t_lin[t] = time.perf_counter() - tic
        tic = time.perf_counter()
        sol = mpc.solve(x, lin.A, lin.B, lin.c, X_r[t + 1:t + N + 1], U_r[t:t + N])
        t_sol[t] = time.perf_counter() - tic
        solutions.append(sol)
        plan_u = np.array(sol.u, dtype=np.float64)
        plan_x = np.array(sol.x, dtype=np.float64)
        plan_x[0] = x
        u = np.minimum(np.maximum(plan_u[0], u_lb), u_ub)  # solver tolerance
        plan_u[0] = u  # the models are told the input actually applied (commit's contract)
        with torch.no_grad():
            # the truth's step, then the model along the new plan, once: row 0 is (x, u), the rest feeds the
            # cascade's commit
            rate_true, x_next = numerics.truth_rate_and_step(x, u)
            rates, phi_plan = numerics.model_rate_and_phi(plan_x[:-1], plan_u)
            xdot_true.append(rate_true)
            xdot_pred.append(model.xdot(x_t, as_t(u), f=as_t(rates[0])).numpy())
            delta.append((x_next - phi_plan[0]) / Ts)
        model.commit(as_t(plan_x), as_t(plan_u), as_t(phi_plan))
        if not np.isfinite(x_next).all():
            check_finite(as_t(x_next), name=f"truth state at step {t + 1}")
        us.append(u)
        x = x_next
        xs.append(x)
    n_fallbacks, reasons, n_reference_fallbacks = fallback_counts(solutions)
    return FlightResult(
        name=model.name, x=np.stack(xs), u=np.stack(us), x_ref=X_r[:steps + 1].copy(),
        xdot_true=np.stack(xdot_true), xdot_pred=np.stack(xdot_pred), x_tilde=np.stack(x_tilde),
        delta=np.stack(delta), t_linearize=t_lin, t_solve=t_sol, n_fallbacks=n_fallbacks,
        statuses=[str(s.status) for s in solutions], Ts=float(Ts), elapsed_s=time.perf_counter() - t_start,
        n_reference_linearizations=n_reference, fallback_reasons=reasons, n_reference_fallbacks=n_reference_fallbacks)
