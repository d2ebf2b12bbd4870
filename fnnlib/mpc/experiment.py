r"""The flight test of Sec. 5.2.2 (App. A.5.3-A.5.4, A.9): seven prediction models in the MPC of Eq. (28).

What the ``quadrotor_mpc`` notebook computes, as functions: the QP with the paper's boxes, the flight
settings shared by every flight (:class:`FlightTest`), the per-model table, the AdapNN gain sweep, the
speed summary, the Theorem 2 check on the AdapFNN flight (Eq. (25) and Theorems 1-2), the spread over
the trained networks and the claim checks Q3-Q5.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from torch import Tensor, nn

from fnnlib.stability import theorem1_balls
from fnnlib.models.residual import AdaptiveResidual
from fnnlib.mpc.flight import FlightResult, fly, tracking_rmse
from fnnlib.mpc.linearized import LinearizedMPC, OSQPMPC
from fnnlib.mpc.models import AdaptiveNNModel, PredictionModel, paper_models
from fnnlib.systems.quadrotor import NOMINAL, Quadrotor

__all__ = [
    "CARRYING",
    "QP_CLASSES",
    "SIX",
    "SPEED_TARGETS",
    "FlightTest",
    "acc_pred_rmse",
    "adapnn_flights",
    "adapnn_model",
    "claim_checks",
    "flight_row",
    "make_mpc",
    "seed_spread",
    "speed_runs",
    "speed_summary",
    "spread_orderings",
    "theorem2_check",
]

QP_CLASSES: dict[str, type[OSQPMPC] | type[LinearizedMPC]] = {"osqp": OSQPMPC, "cvxpy": LinearizedMPC}
"""The QP of Eq. (28) by name: solved by OSQP directly, or through a cvxpy problem built once."""

SIX = ("Nomi", "Neural", "MLP", "FB", "AdapNN", "FNN")
"""The six models the tracking and prediction claims rank (AdapFNN is compared with FNN apart)."""

CARRYING = ("Neural", "AdapNN", "FNN", "AdapFNN")
"""The models that carry the trained residual network (flown again per trained network)."""

SPEED_TARGETS = {"step_ms_median": 4.0, "real_time_factor": 5.0}
"""Targets of this reproduction (not a paper claim): median linearize + solve per step, flown time over wall time."""

MPC = OSQPMPC | LinearizedMPC


def make_mpc(qp: str, N: int, Q: Sequence[float], R: Sequence[float], *, u_max: float, theta_max: float,
             solver: str) -> MPC:
    """Eq. (28) with diagonal weights ``Q`` (12), ``R`` (4), thrust box ``[0, u_max]`` and ``|Theta| <= theta_max``.

    ``qp`` is a key of :data:`QP_CLASSES`; ``solver`` is passed on (``"OSQP"`` in the paper run).
    """
    if qp not in QP_CLASSES:
        raise ValueError(f"qp must be one of {sorted(QP_CLASSES)}, got {qp!r}")
    x_lb = np.r_[np.full(6, -np.inf), np.full(3, -theta_max), np.full(3, -np.inf)]
    return QP_CLASSES[qp](N, np.asarray(Q), np.asarray(R), u_lb=np.zeros(4), u_ub=np.full(4, u_max), x_lb=x_lb,
                          x_ub=-x_lb, solver=solver)


@dataclass(frozen=True)
class FlightTest:
    """What every flight of the test shares: the vehicle, the reference and the loop settings of :func:`fly`."""

    truth: Quadrotor
    x_r: Tensor
    u_r: Tensor
    steps: int
    Ts: float
    substeps: int
    backend: str
    linearize_method: str | None

    def fly(self, model: PredictionModel, mpc: MPC, *, progress: bool = False) -> FlightResult:
        """One flight of ``model`` in ``mpc`` on the test vehicle."""
        return fly(model, mpc, self.truth, self.x_r, self.u_r, steps=self.steps, Ts=self.Ts, substeps=self.substeps,
                   linearize_method=self.linearize_method, backend=self.backend, progress=progress)


def acc_pred_rmse(r: FlightResult) -> float:
    """RMSE of the norm of the first-step acceleration prediction error (Fig. S8)."""
    return float(np.sqrt(np.mean(np.sum((r.xdot_pred[:, 3:6] - r.xdot_true[:, 3:6]) ** 2, axis=1))))


def flight_row(r: FlightResult) -> dict[str, Any]:
    """One model's row of the flight table: tracking RMSE, prediction RMSE, fallbacks, timings."""
    return {**tracking_rmse(r.x, r.x_ref), "acc_pred_rmse": acc_pred_rmse(r), "fallbacks": r.n_fallbacks,
            "reference_linearizations": r.n_reference_linearizations,
            "step_ms_median": 1e3 * float(np.median(r.t_linearize + r.t_solve)),
            "step_ms_p95": 1e3 * float(np.percentile(r.t_linearize + r.t_solve, 95)),
            "linearize_ms_median": 1e3 * float(np.median(r.t_linearize)),
            "solve_ms_median": 1e3 * float(np.median(r.t_solve)),
            "flight_s": r.elapsed_s, "real_time_factor": r.real_time_factor}


def adapnn_model(residual: nn.Module, Gamma: float, *, Ts: float) -> AdaptiveNNModel:
    """AdapNN (Cheng et al.) on the nominal plant with a copy of ``residual`` adapting at gain ``Gamma``."""
    return AdaptiveNNModel("AdapNN", Quadrotor(NOMINAL), AdaptiveResidual(residual, Gamma), Ts=Ts)


def adapnn_flights(residual: nn.Module, gammas: Iterable[float], mpc: MPC, test: FlightTest) -> dict[float, FlightResult]:
    """AdapNN flown once per adaptation gain (the paper tunes it "for optimal performance")."""
    return {g: test.fly(adapnn_model(residual, g, Ts=test.Ts), mpc) for g in gammas}


def speed_runs(models: Iterable[PredictionModel], mpc: MPC, test: FlightTest, repeats: int) -> dict[str, dict[str, Any]]:
    """Each model flown ``repeats`` times: median and 95th percentile of its steps, median real-time factor."""
    if int(repeats) < 1:
        raise ValueError(f"speed_repeats must be >= 1, got {repeats}")
    timing = {}
    for m in models:
        runs = [test.fly(m, mpc) for _ in range(int(repeats))]
        steps_ms = 1e3 * np.concatenate([r.t_linearize + r.t_solve for r in runs])
        timing[m.name] = {"step_ms_median": float(np.median(steps_ms)), "step_ms_p95": float(np.percentile(steps_ms, 95)),
                          "real_time_factor_median": float(np.median([r.real_time_factor for r in runs])),
                          "real_time_factor_each": [r.real_time_factor for r in runs]}
    return timing


def speed_summary(timing: Mapping[str, Mapping[str, Any]], *, repeats: int, thrust_bound: float, qp: str,
                  backend: str, linearize_method: str, compile_s: float) -> dict[str, Any]:
    """Worst and best model against :data:`SPEED_TARGETS`; ``met`` when the worst model meets both."""
    speed = {"per_model": timing, "repeats": int(repeats), "thrust_bound": thrust_bound,
             "step_ms_median_worst_model": max(v["step_ms_median"] for v in timing.values()),
             "step_ms_median_best_model": min(v["step_ms_median"] for v in timing.values()),
             "real_time_factor_worst_model": min(v["real_time_factor_median"] for v in timing.values()),
             "real_time_factor_best_model": max(v["real_time_factor_median"] for v in timing.values()),
             "targets": dict(SPEED_TARGETS), "qp": qp, "backend": backend,
             "linearize_method": linearize_method if backend == "torch" else "exact (forward mode, compiled)",
             "compile_s": compile_s}
    speed["met"] = (speed["step_ms_median_worst_model"] <= SPEED_TARGETS["step_ms_median"]) and (
        speed["real_time_factor_worst_model"] >= SPEED_TARGETS["real_time_factor"])
    return speed


def theorem2_check(r: FlightResult, L: float, transient_steps: int) -> dict[str, float]:
    r"""Theorem 2 on a flight with feedback: how often the layer-0 error stays in the ball after the transient.

    Layer 0 obeys Eq. (25), :math:`\tilde x_{t+1} = (I - T_s L)\tilde x_t + T_s\Delta_t`; ``gamma`` is the
    largest :math:`\lVert\Delta_t\rVert` after ``transient_steps`` steps and the ball is :math:`\gamma/\lambda_m(L)`.
    """
    e = np.linalg.norm(r.x_tilde[transient_steps:], axis=1)
    gamma = float(np.linalg.norm(r.delta[transient_steps:], axis=1).max())
    ball_x, _ = theorem1_balls(L, gamma, 12)
    return {"gamma": gamma, "ball_x": ball_x, "inside_fraction": float(np.mean(e <= ball_x)),
            "max_error": float(e.max())}


def seed_spread(members: Sequence[tuple[str, nn.Module]], mlp: nn.Module, *, u_max: Sequence[float],
                make_qp: Callable[[float], MPC], test: FlightTest, model_settings: Mapping[str, Any],
                adapnn_gamma: Mapping[str, float]) -> dict[str, dict[str, dict[str, float]]]:
    """Mean per-axis RMSE of the :data:`CARRYING` models flown with every trained network.

    ``members`` are ``(seed, network)`` pairs; ``model_settings`` the keywords of :func:`paper_models`
    after the networks; AdapNN flies at ``adapnn_gamma[str(u_max)]``. Returns ``[str(u_max)][model][seed]``.
    """
    spread: dict[str, dict[str, dict[str, float]]] = {str(umax): {n: {} for n in CARRYING} for umax in u_max}
    for seed, net in members:
        for umax in u_max:
            mpc = make_qp(umax)
            ms = {m.name: m for m in paper_models(net, mlp, **model_settings)}
            ms["AdapNN"] = adapnn_model(net, adapnn_gamma[str(umax)], Ts=model_settings["Ts"])
            for name in CARRYING:
                r = test.fly(ms[name], mpc)
                spread[str(umax)][name][seed] = tracking_rmse(r.x, r.x_ref)["mean_axis"]
    return spread


def spread_orderings(spread: Mapping[str, Mapping[str, Mapping[str, float]]],
                     table: Mapping[str, Mapping[str, Mapping[str, Any]]]) -> dict[str, dict[str, float]]:
    """Per thrust bound, the fraction of trained networks for which each ordering of the claims holds.

    Nomi, MLP and FB do not carry the network: their flights of ``table`` stand for every seed.
    """
    orderings = {}
    for u, per_model in spread.items():
        fixed = {n: table[u][n]["mean_axis"] for n in ("Nomi", "MLP", "FB")}
        per_seed = [{**fixed, **{n: per_model[n][sd] for n in CARRYING}} for sd in per_model["FNN"]]
        orderings[u] = {
            "FNN best of the six": float(np.mean([min(SIX, key=r.get) == "FNN" for r in per_seed])),
            "FNN < Neural": float(np.mean([r["FNN"] < r["Neural"] for r in per_seed])),
            "FNN < AdapNN": float(np.mean([r["FNN"] < r["AdapNN"] for r in per_seed])),
            "Neural < Nomi": float(np.mean([r["Neural"] < r["Nomi"] for r in per_seed])),
            "AdapFNN >= FNN": float(np.mean([r["AdapFNN"] >= r["FNN"] for r in per_seed])),
            "AdapFNN within 25 % of FNN": float(np.mean([abs(r["AdapFNN"] - r["FNN"]) <= 0.25 * r["FNN"]
                                                          for r in per_seed])),
        }
    return orderings


def claim_checks(table: Mapping[str, Mapping[str, Mapping[str, Any]]],
                 thm2: Mapping[str, Mapping[str, float]]) -> tuple[dict[str, bool], dict[str, bool], dict[str, bool]]:
    """The checks of Q3 (tracking), Q4 (first-step prediction) and Q5 (AdapFNN), at every thrust bound."""
    q3, q4, q5 = {}, {}, {}
    for umax, rows in table.items():
        rm = {n: rows[n]["mean_axis"] for n in rows}
        ac = {n: rows[n]["acc_pred_rmse"] for n in rows}
        q3[f"{umax} N: FNN best of the six"] = min(SIX, key=rm.get) == "FNN"
        q3[f"{umax} N: Neural < Nomi"] = rm["Neural"] < rm["Nomi"]
        q3[f"{umax} N: MLP > Neural"] = rm["MLP"] > rm["Neural"]
        q4[f"{umax} N: best first-step prediction is a feedback model"] = min(SIX, key=ac.get) in ("FB", "FNN")
        q4[f"{umax} N: FNN < Neural"] = ac["FNN"] < ac["Neural"]
        q5[f"{umax} N: AdapFNN within 25 % of FNN"] = abs(rm["AdapFNN"] - rm["FNN"]) <= 0.25 * rm["FNN"]
        q5[f"{umax} N: AdapFNN >= FNN"] = rm["AdapFNN"] >= rm["FNN"]
        q5[f"{umax} N: Theorem 2 ball holds >= 95 % after the transient"] = thm2[umax]["inside_fraction"] >= 0.95
    return q3, q4, q5
