r"""The flight test of Sec. 5.2.2 (App. A.5.3-A.5.4, A.9): seven prediction models in the MPC of Eq. (28).

What the ``quadrotor_mpc`` notebook computes, as functions: the QP with the paper's boxes, the flight
settings shared by every flight (:class:`FlightTest`), the per-model table, the AdapNN gain sweep, the
speed summary, the Theorem 2 check on the AdapFNN flight (Eq. (25) and Theorems 1-2), AdapNN's gain chosen
on validation flights, the disturbance realisations, and the flights paired over trained networks x disturbances that
the rules of Q3-Q5 (:mod:`fnnbook.rules.quadrotor`) judge.
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
from fnnlib.mpc.linearized import COSTS, LinearizedMPC, OSQPMPC
from fnnlib.mpc.models import AdaptiveNNModel, PredictionModel, paper_models
from fnnlib.mpc.tuning import GainSelection, select_gain_on_validation
from fnnlib.systems.quadrotor import NOMINAL, Quadrotor, QuadrotorParams

__all__ = [
    "CARRYING",
    "QP_CLASSES",
    "SIX",
    "SPEED_TARGETS",
    "FlightTest",
    "acc_pred_rmse",
    "adapnn_flights",
    "adapnn_gain_on_validation",
    "adapnn_model",
    "disturbance_realisations",
    "fallback_note",
    "flight_row",
    "make_mpc",
    "paired_grid",
    "pooled_speed",
    "speed_runs",
    "speed_summary",
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


def make_mpc(qp: str, N: int, Q: Sequence[float], R: Sequence[float], *, cost: str, u_max: float,
             theta_max: float, solver: str) -> MPC:
    """Eq. (28) with diagonal weights ``Q`` (12), ``R`` (4), thrust box ``[0, u_max]`` and ``|Theta| <= theta_max``.

    ``qp`` is a key of :data:`QP_CLASSES`; ``cost`` one of :data:`~fnnlib.mpc.linearized.COSTS` (Eq. (28)
    as written, or the release's weighting); ``solver`` is passed on (``"OSQP"`` in the paper run).
    """
    if qp not in QP_CLASSES:
        raise ValueError(f"qp must be one of {sorted(QP_CLASSES)}, got {qp!r}")
    if cost not in COSTS:
        raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")
    x_lb = np.r_[np.full(6, -np.inf), np.full(3, -theta_max), np.full(3, -np.inf)]
    return QP_CLASSES[qp](N, np.asarray(Q), np.asarray(R), cost=cost, u_lb=np.zeros(4), u_ub=np.full(4, u_max),
                          x_lb=x_lb, x_ub=-x_lb, solver=solver)


def disturbance_realisations(paper: Sequence[float], n_drawn: int, *, seed: int, spread: float) -> list[tuple[float, ...]]:
    """The paper's constant force and ``n_drawn`` drawn around it (Q3-Q5 judged over disturbances).

    Each drawn force has every axis uniform in ``paper * (1 +- spread)`` (``numpy.random.default_rng(seed)``),
    so both its size and its direction vary around the paper's 0.3 N per axis. The paper's force comes first.
    """
    F0 = np.asarray(paper, dtype=float)
    if F0.shape != (3,) or not np.isfinite(F0).all():
        raise ValueError(f"paper must be 3 finite forces, got {paper}")
    if int(n_drawn) < 0 or not (0 <= spread < 1):
        raise ValueError(f"need n_drawn >= 0 and 0 <= spread < 1, got {n_drawn}, {spread}")
    rng = np.random.default_rng(seed)
    drawn = F0 * (1.0 + spread * rng.uniform(-1.0, 1.0, size=(int(n_drawn), 3)))
    return [tuple(float(f) for f in F0)] + [tuple(float(f) for f in row) for row in drawn]


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


def fallback_note(r: FlightResult) -> str:
    """``"DIVERGED"`` past the fallback share, then the fallbacks by reason (empty when there were none)."""
    reasons = ", ".join(f"{k} {v}" for k, v in sorted(r.fallback_reasons.items()))
    return ("DIVERGED " if r.diverged else "") + (f"[{reasons}]" if reasons else "")


def flight_row(r: FlightResult) -> dict[str, Any]:
    """One model's row of the flight table: tracking RMSE, prediction RMSE, fallbacks, timings."""
    return {**tracking_rmse(r.x, r.x_ref), "acc_pred_rmse": acc_pred_rmse(r), "fallbacks": r.n_fallbacks,
            "fallback_reasons": dict(r.fallback_reasons), "reference_fallbacks": r.n_reference_fallbacks,
            "diverged": r.diverged,
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


def adapnn_gain_on_validation(residual: nn.Module, grid: Sequence[float], refs: Sequence[tuple[Tensor, Tensor]],
                              vehicles: Sequence[QuadrotorParams], mpc: MPC, *, steps: int, Ts: float, substeps: int,
                              backend: str, linearize_method: str | None, rtol: float) -> GainSelection:
    """AdapNN's gain chosen on validation flights (:func:`~fnnlib.mpc.tuning.select_gain_on_validation`).

    Every vehicle of ``vehicles`` (e.g. :func:`~fnnlib.mpc.tuning.randomized_vehicles` around the training
    vehicle) flies every reference of ``refs`` (e.g. :func:`~fnnlib.mpc.tuning.validation_references`) for
    ``steps`` steps at every gain of ``grid``, with the loop settings of :func:`~fnnlib.mpc.flight.fly`. The
    flights are in the order vehicle, then reference. Nothing of the test flight is an argument: the choice
    cannot depend on it.
    """
    cases = [(Quadrotor(v), x_r, u_r) for v in vehicles for x_r, u_r in refs]

    def fly_fn(gain: float, truth: Quadrotor, x_r: Tensor, u_r: Tensor) -> FlightResult:
        return fly(adapnn_model(residual, gain, Ts=Ts), mpc, truth, x_r, u_r, steps=int(steps), Ts=Ts,
                   substeps=substeps, linearize_method=linearize_method, backend=backend)

    return select_gain_on_validation(fly_fn, grid, cases, rtol=rtol)


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


def pooled_speed(flights: Mapping[str, Sequence[FlightResult]]) -> dict[str, dict[str, Any]]:
    """Per model, the timing of all its flights pooled, as :func:`speed_runs` reports a model's repeats."""
    timing = {}
    for name, runs in flights.items():
        steps_ms = 1e3 * np.concatenate([r.t_linearize + r.t_solve for r in runs])
        timing[name] = {"step_ms_median": float(np.median(steps_ms)), "step_ms_p95": float(np.percentile(steps_ms, 95)),
                        "real_time_factor_median": float(np.median([r.real_time_factor for r in runs])),
                        "flights": len(runs)}
    return timing


def paired_grid(members: Sequence[tuple[str, nn.Module]], mlp: nn.Module, *, tests: Sequence[FlightTest], mpc: MPC,
                model_settings: Mapping[str, Any], adapnn_gamma: float) -> dict[str, list[FlightResult]]:
    """All seven models flown for every trained network x every test (one per disturbance): paired flights.

    Returns, per model, the flights in the order ``(seed, test)`` with the test varying fastest; models that
    do not carry the network (Nomi, MLP, FB) are flown once per test and repeated for each seed, so every
    model's list pairs entry by entry. AdapNN flies at ``adapnn_gamma``.
    """
    if not members or not tests:
        raise ValueError("need at least one trained network and one test")
    models = paper_models(members[0][1], mlp, **model_settings)
    fixed = {m.name: m for m in models if m.name not in CARRYING}
    fixed_flights = {n: [t.fly(m, mpc) for t in tests] for n, m in fixed.items()}
    out: dict[str, list[FlightResult]] = {m.name: [] for m in models}  # the paper's order
    for _, net in members:
        ms = {m.name: m for m in paper_models(net, mlp, **model_settings)}
        ms["AdapNN"] = adapnn_model(net, adapnn_gamma, Ts=model_settings["Ts"])
        for i, t in enumerate(tests):
            for n in fixed:
                out[n].append(fixed_flights[n][i])
            for n in CARRYING:
                out[n].append(t.fly(ms[n], mpc))
    return out


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
