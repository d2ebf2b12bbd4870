"""The settings of ``notebooks/08_quadrotor_mpc``: MPC of a quadrotor under uncertainty (Sec. 5.2, App. A.5.3-A.9)."""

from __future__ import annotations

from dataclasses import dataclass

from fnnbook.tasks._base import TaskSettings, setting
from fnnbook.tasks._checks import (GAIN, N0, N1, N2, NONNEG, POS, SEED, cvxpy_solvers, from_mpc, lazy_choice, need,
                                   some, vec)
from fnnlib import checks as C
from fnnlib.quadrotor import presets as QP
from fnnlib.quadrotor.system import TEST_TRUTH

__all__ = ["QuadrotorMPCSettings"]


@dataclass(frozen=True, kw_only=True)
class QuadrotorMPCSettings(TaskSettings, notebook="quadrotor_mpc"):
    """The flight test: the MPC (horizon ``N``, weights ``Q``, ``R``, thrust bounds ``u_max`` of which
    ``u_max_judged`` is judged, tilt bound), the feedback (Eqs. (7)-(8), decay Eq. (11)) and AdapNN's gain
    (Eq. (30)) with its validation grid, the test vehicle and its drawn disturbances, and the QP backend."""

    steps: int = setting(300, N1)
    N: int = setting(QP.PAPER_HORIZON, N1)
    Ts: float = setting(QP.PAPER_TS, POS)
    Q: list[float] = setting(QP.PAPER_MPC_WEIGHTS["Q"], vec(12, 0.0))
    R: list[float] = setting(QP.PAPER_MPC_WEIGHTS["R"], vec(4, 0.0))
    costs: list[str] = setting(["as_written", "as_flown"], some("as_written", "as_flown"))
    u_max: list[float] = setting([4.0, 6.0], vec())
    u_max_judged: float = setting(6.0, POS)
    theta_max: float = setting(QP.PAPER_THETA_MAX, POS)
    L: float = setting(QP.PAPER_L, GAIN)
    beta: float = setting(QP.PAPER_BETA, NONNEG)
    Gamma: float = setting(QP.PAPER_GAMMA, POS)
    Gamma_adapnn_grid: list[float] = setting([0.04, 0.16, 0.64, 2.56], vec())
    Gamma_rtol: float = setting(0.05, NONNEG)
    validation_flights: int = setting(2, N1)
    validation_steps: int = setting(300, N1)
    validation_waypoints: int = setting(4, N2)
    validation_seed: int = setting(1000, SEED)
    truth_mass: float = setting(TEST_TRUTH.mass, POS)
    truth_inertia: list[float] = setting(TEST_TRUTH.inertia, vec(3, 0.0))
    truth_drag: list[float] = setting(TEST_TRUTH.drag, vec(3, 0.0))
    disturbance: list[float] = setting(TEST_TRUTH.force_disturbance, vec(3))
    disturbance_draws: int = setting(5, N0)
    disturbance_spread: float = setting(0.5, NONNEG)
    disturbance_seed: int = setting(11, SEED)
    truth_substeps: int = setting(1, N1)
    solver: str = setting("OSQP", lazy_choice(cvxpy_solvers))
    qp: str = setting("osqp", from_mpc("QP_CLASSES", "experiment"))
    linearize_method: str = setting("forward", from_mpc("METHODS", "linearize"))
    backend: str = setting("numba", from_mpc("BACKENDS", "backends"))
    transient_s: float = setting(1.0, NONNEG)
    validation_vehicles: int = setting(4, N1)
    validation_vehicle_seed: int = setting(1001, SEED)

    def check_relations(self) -> None:
        """A gain stable at ``Ts`` (Theorem 1, Eq. (25)); positive thrust bounds including the judged one; a
        distinct positive AdapNN grid; ``R`` positive definite; a positive inertia; the OSQP QP with its own
        solver; a transient shorter than the flight."""
        C.stable_gain("L", self.L, n=12, Ts=self.Ts)
        C.numbers("u_max", self.u_max, minimum=0.0)
        need(min(self.u_max) > 0, f"u_max must list positive thrust bounds, got {self.u_max}")
        need(self.u_max_judged in self.u_max,
             f"u_max_judged = {self.u_max_judged} must be one of u_max = {self.u_max}")
        grid = self.Gamma_adapnn_grid  # AdapNN's validation grid (fnnlib.quadrotor.mpc.tuning)
        need(len(set(grid)) == len(grid) and min(grid) > 0,
             f"Gamma_adapnn_grid must list distinct finite gains > 0, got {grid}")
        need(min(self.R) > 0, f"R must be positive definite (every weight > 0), got {self.R}")
        need(min(self.truth_inertia) > 0, f"truth_inertia must be > 0 about every axis, got {self.truth_inertia}")
        need(self.qp != "osqp" or self.solver == "OSQP", f"qp 'osqp' solves with solver 'OSQP' only, got solver "
                                                         f"{self.solver!r} (use qp 'cvxpy' for another solver)")
        length = self.steps * self.Ts
        need(self.transient_s < length, f"transient_s must be shorter than the flight, steps * Ts = {length:g} s, "
                                        f"got {self.transient_s}")
