r"""The flight test of Sec. 5.2.2 (App. A.5.3-A.5.4, A.9): seven prediction models in the MPC of Eq. (28).

What the ``quadrotor_mpc`` notebook computes, as functions: the QP with the paper's boxes, the flight
tests of Sec. 5.2.2 built from their settings (:func:`flight_tests` of :class:`FlightSettings`), the per-model table
(:class:`FlightRow`, keyed by :class:`TableKey`), the AdapNN gain sweep, the speed summary, the Theorem 2 check on the AdapFNN flight (Eq. (25) and Theorems 1-2), AdapNN's gain chosen
on validation flights, the disturbance realisations, the flights paired over independent units (a trained network,
its MLP and one drawn disturbance each, :func:`paired_units`), the thrust the test vehicle needs against a bound
(:func:`thrust_needed`) that the rules of Q3-Q5 (:mod:`fnnbook.rules.quadrotor`) judge.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any, NamedTuple

import numpy as np
from torch import Tensor, nn

from fnnlib.stability import theorem1_balls
from fnnlib.feedback import Gains
from fnnlib.quadrotor.residual import AdaptiveResidual
from fnnlib.quadrotor.mpc.backends import Backend
from fnnlib.quadrotor.control.lissajous import lissajous
from fnnlib.quadrotor.mpc.flight import FlightResult, FlightTest, fly, lissajous_reference, tracking_rmse
from fnnlib.quadrotor.mpc.linearized import COSTS, LinearizedMPC, OSQPMPC
from fnnlib.quadrotor.mpc.models import AdaptiveNNModel, FeedbackCascadeModel, PredictionModel, paper_models
from fnnlib.quadrotor.mpc.tuning import GainSelection, select_gain_on_validation
from fnnlib.quadrotor.presets import PAPER_LISSAJOUS
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, Quadrotor, QuadrotorParams

__all__ = [
    "CARRYING",
    "QP_CLASSES",
    "SIX",
    "SPEED_TARGETS",
    "FlightRow",
    "FlightSetup",
    "FlightTest",
    "PairedFlights",
    "TableKey",
    "acc_pred_rmse",
    "adapnn_flights",
    "adapnn_gain_on_validation",
    "adapnn_model",
    "disturbance_realisations",
    "fallback_note",
    "flight_row",
    "flight_table_json",
    "FlightSettings",
    "flight_tests",
    "flown_gain_sweep",
    "fnn_model",
    "hand_gains_on_flights",
    "make_mpc",
    "MPCSettings",
    "paired_units",
    "pooled_speed",
    "speed_summary",
    "theorem2_check",
    "thrust_needed",
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

    ``qp`` is a key of :data:`QP_CLASSES`; ``cost`` one of :data:`~fnnlib.quadrotor.mpc.linearized.COSTS` (Eq. (28)
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
    """The paper's constant force and ``n_drawn`` drawn around it (Q3-Q5 are judged over disturbances).

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
class MPCSettings:
    """The settings of Eq. (28) that a run fixes once: the QP's implementation ``qp`` (a key of
    :data:`QP_CLASSES`), the horizon ``N``, the diagonal weights ``Q`` (12) and ``R`` (4), the attitude bound
    ``theta_max`` and the QP ``solver``. A cost variant and a thrust bound then make one MPC (:meth:`build`)."""

    qp: str
    N: int
    Q: tuple[float, ...]
    R: tuple[float, ...]
    theta_max: float
    solver: str

    @classmethod
    def of(cls, parameters: Mapping[str, Any]) -> MPCSettings:
        """These settings from a run's parameters (a record holding at least these names; the rest ignored)."""
        return cls(**{f.name: parameters[f.name] for f in fields(cls)})

    def build(self, *, cost: str, u_max: float) -> MPC:
        """:func:`make_mpc` with these settings, cost variant ``cost`` and thrust box ``[0, u_max]``."""
        return make_mpc(self.qp, self.N, self.Q, self.R, cost=cost, u_max=u_max, theta_max=self.theta_max,
                        solver=self.solver)


@dataclass(frozen=True)
class FlightSetup:
    """The flight tests of Sec. 5.2.2: the test vehicle (with the paper's force), the forces flown, the
    Lissajous reference ``x_r`` (steps + N + 1, 12), ``u_r`` (steps + N, 4), and one test per force.

    ``tests[0]`` flies the paper's force (:attr:`paper_test`), the others the independently drawn forces, one
    per unit of the paired comparisons (:attr:`unit_tests`, :func:`paired_units`)."""

    vehicle: QuadrotorParams
    forces: list[tuple[float, ...]]
    x_r: Tensor
    u_r: Tensor
    tests: list[FlightTest]

    @property
    def paper_test(self) -> FlightTest:
        """The test under the paper's force (the table, the figures and the context bounds fly it)."""
        return self.tests[0]

    @property
    def unit_tests(self) -> list[FlightTest]:
        """The tests under the drawn forces, one per independent unit."""
        return self.tests[1:]


@dataclass(frozen=True)
class FlightSettings:
    """The settings of the Sec. 5.2.2 flight tests (App. A.5.4), read by :func:`flight_tests`.

    The test vehicle is :data:`~fnnlib.quadrotor.system.TEST_TRUTH` with ``truth_mass``, ``truth_inertia``,
    ``truth_drag``; the forces are :func:`disturbance_realisations` of ``disturbance`` (``disturbance_draws``,
    ``disturbance_seed``, ``disturbance_spread``); the reference is the paper's Lissajous curve over ``steps``
    steps of ``Ts`` (horizon ``N``); the loop runs ``truth_substeps`` RK4 sub-steps on ``backend`` (with
    ``linearize_method`` for the torch reference).
    """

    steps: int
    N: int
    Ts: float
    truth_mass: float
    truth_inertia: tuple[float, ...]
    truth_drag: tuple[float, ...]
    truth_substeps: int
    disturbance: tuple[float, ...]
    disturbance_draws: int
    disturbance_seed: int
    disturbance_spread: float
    backend: str
    linearize_method: str

    @classmethod
    def of(cls, parameters: Mapping[str, Any]) -> FlightSettings:
        """These settings from a run's parameters (a record holding at least these names; the rest ignored)."""
        return cls(**{f.name: parameters[f.name] for f in fields(cls)})


def flight_tests(s: FlightSettings) -> FlightSetup:
    """The Sec. 5.2.2 flight tests (App. A.5.4) of :class:`FlightSettings` ``s``: the reference by flatness on
    the nominal vehicle, one test per force (the paper's first)."""
    vehicle = TEST_TRUTH.replace(mass=s.truth_mass, inertia=tuple(s.truth_inertia), drag=tuple(s.truth_drag),
                                 force_disturbance=tuple(s.disturbance))
    forces = disturbance_realisations(s.disturbance, s.disturbance_draws, seed=s.disturbance_seed,
                                      spread=s.disturbance_spread)
    x_r, u_r = lissajous_reference(s.steps, s.N, Ts=s.Ts, params=NOMINAL, curve=PAPER_LISSAJOUS)
    backend = Backend(s.backend, s.linearize_method)
    tests = [FlightTest(Quadrotor(vehicle.replace(force_disturbance=f)), x_r, u_r, steps=s.steps, Ts=s.Ts,
                        substeps=s.truth_substeps, backend=backend) for f in forces]
    return FlightSetup(vehicle, forces, x_r, u_r, tests)


def acc_pred_rmse(r: FlightResult) -> float:
    """RMSE of the norm of the first-step acceleration prediction error (Fig. S8)."""
    return float(np.sqrt(np.mean(np.sum((r.xdot_pred[:, 3:6] - r.xdot_true[:, 3:6]) ** 2, axis=1))))


def fallback_note(r: FlightResult) -> str:
    """``"DIVERGED"`` past the fallback share, then the fallbacks by reason (empty when there were none)."""
    reasons = ", ".join(f"{k} {v}" for k, v in sorted(r.fallback_reasons.items()))
    return ("DIVERGED " if r.diverged else "") + (f"[{reasons}]" if reasons else "")


@dataclass(frozen=True)
class FlightRow:
    """One model's row of the flight table: tracking RMSE (m; per axis, their mean, the error norm's),
    first-step acceleration prediction RMSE, fallbacks, timings (ms per step, s per flight)."""

    x: float
    y: float
    z: float
    mean_axis: float
    norm: float
    acc_pred_rmse: float
    fallbacks: int
    fallback_reasons: dict[str, int]
    reference_fallbacks: int
    diverged: bool
    reference_linearizations: int
    step_ms_median: float
    step_ms_p95: float
    linearize_ms_median: float
    solve_ms_median: float
    flight_s: float
    real_time_factor: float

    def to_dict(self) -> dict[str, Any]:
        """The row as results.json stores it (the fields in order)."""
        return asdict(self)


def flight_row(r: FlightResult) -> FlightRow:
    """The flight's row of the flight table."""
    return FlightRow(**tracking_rmse(r.x, r.x_ref), acc_pred_rmse=acc_pred_rmse(r), fallbacks=r.n_fallbacks,
                     fallback_reasons=dict(r.fallback_reasons), reference_fallbacks=r.n_reference_fallbacks,
                     diverged=r.diverged, reference_linearizations=r.n_reference_linearizations,
                     step_ms_median=1e3 * float(np.median(r.t_linearize + r.t_solve)),
                     step_ms_p95=1e3 * float(np.percentile(r.t_linearize + r.t_solve, 95)),
                     linearize_ms_median=1e3 * float(np.median(r.t_linearize)),
                     solve_ms_median=1e3 * float(np.median(r.t_solve)),
                     flight_s=r.elapsed_s, real_time_factor=r.real_time_factor)


class TableKey(NamedTuple):
    """A flight table's key: the cost variant of Eq. (28) and the thrust bound in N."""

    cost: str
    u_max: float

    def label(self, judged_u_max: float) -> str:
        """The key as results.json writes it: ``"as_flown, 6 N"``, ``" (context)"`` added off the judged bound."""
        return f"{self.cost}, {self.u_max:g} N" + ("" if self.u_max == judged_u_max else " (context)")


def flight_table_json(table: Mapping[TableKey, Mapping[str, FlightRow]], judged_u_max: float) -> dict[str, Any]:
    """The flight table as results.json stores it: labelled keys (:meth:`TableKey.label`), rows as dicts."""
    return {k.label(judged_u_max): {n: row.to_dict() for n, row in rows.items()} for k, rows in table.items()}


def fnn_model(residual: nn.Module, L: float | Tensor, beta: float, *, plant: Quadrotor, N: int,
              Ts: float) -> FeedbackCascadeModel:
    """FNN: the cascade of Eq. (11) with gain ``L`` (scalar or (12,)) and decay ``beta`` on the neural model
    (``plant`` plus ``residual``), as :func:`~fnnlib.quadrotor.mpc.models.paper_models` builds it, with other gains."""
    return FeedbackCascadeModel(PredictionModel("Neural", plant, residual, Ts=Ts), L, beta, N, name="FNN")


def adapnn_model(residual: nn.Module, Gamma: float, *, Ts: float) -> AdaptiveNNModel:
    """AdapNN (Cheng et al.) on the nominal plant with a copy of ``residual`` adapting at gain ``Gamma``."""
    return AdaptiveNNModel("AdapNN", Quadrotor(NOMINAL), AdaptiveResidual(residual, Gamma), Ts=Ts)


def adapnn_flights(residual: nn.Module, gammas: Iterable[float], mpc: MPC, test: FlightTest) -> dict[float, FlightResult]:
    """AdapNN flown once per adaptation gain (the paper tunes it "for optimal performance")."""
    return {g: fly(adapnn_model(residual, g, Ts=test.Ts), mpc, test) for g in gammas}


def adapnn_gain_on_validation(residual: nn.Module, grid: Sequence[float], refs: Sequence[tuple[Tensor, Tensor]],
                              vehicles: Sequence[QuadrotorParams], mpc: MPC, *, steps: int, Ts: float, substeps: int,
                              backend: Backend, rtol: float) -> GainSelection:
    """AdapNN's gain chosen on validation flights (:func:`~fnnlib.quadrotor.mpc.tuning.select_gain_on_validation`).

    Every vehicle of ``vehicles`` (e.g. :func:`~fnnlib.quadrotor.mpc.tuning.randomized_vehicles` around the training
    vehicle) flies every reference of ``refs`` (e.g. :func:`~fnnlib.quadrotor.mpc.tuning.validation_references`) for
    ``steps`` steps at every gain of ``grid``, with the loop settings of :func:`~fnnlib.quadrotor.mpc.flight.fly`. The
    flights are in the order vehicle, then reference. Nothing of the test flight is an argument: the choice
    cannot depend on it.
    """
    cases = [(FlightTest(Quadrotor(v), x_r, u_r, steps=int(steps), Ts=Ts, substeps=substeps, backend=backend),)
             for v in vehicles for x_r, u_r in refs]

    def fly_fn(gain: float, test: FlightTest) -> FlightResult:
        return fly(adapnn_model(residual, gain, Ts=Ts), mpc, test)

    return select_gain_on_validation(fly_fn, grid, cases, rtol=rtol)


def pooled_speed(flights: Mapping[str, Sequence[FlightResult]]) -> dict[str, dict[str, Any]]:
    """Per model, the timing of all its flights pooled: median and 95th percentile of the steps (linearize +
    solve, ms), median real-time factor, number of flights."""
    timing = {}
    for name, runs in flights.items():
        if not runs:
            raise ValueError(f"model {name!r} has no flights to time")
        steps_ms = 1e3 * np.concatenate([r.t_linearize + r.t_solve for r in runs])
        timing[name] = {"step_ms_median": float(np.median(steps_ms)), "step_ms_p95": float(np.percentile(steps_ms, 95)),
                        "real_time_factor_median": float(np.median([r.real_time_factor for r in runs])),
                        "flights": len(runs)}
    return timing


@dataclass(frozen=True)
class PairedFlights(Mapping[str, list[FlightResult]]):
    """Per model, its flights over the independent units, entry ``k`` being unit ``k`` (:func:`paired_units`).

    A mapping model name -> flights; entry ``k`` of every model's list is unit ``units[k]`` (a trained network,
    its MLP and one disturbance), so the lists pair entry by entry and every entry is its own unit: nothing is
    copied. :meth:`unit` gives one unit's flights.
    """

    by_model: dict[str, list[FlightResult]]
    units: tuple[str, ...]

    def __getitem__(self, name: str) -> list[FlightResult]:
        return self.by_model[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.by_model)

    def __len__(self) -> int:
        return len(self.by_model)

    def unit(self, k: int) -> dict[str, FlightResult]:
        """Every model's flight of unit ``k``."""
        if not 0 <= k < len(self.units):
            raise IndexError(f"unit {k} outside the {len(self.units)} units")
        return {n: runs[k] for n, runs in self.by_model.items()}


def paired_units(members: Sequence[tuple[Any, nn.Module]], mlps: Sequence[tuple[Any, nn.Module]], *,
                 tests: Sequence[FlightTest], mpc: MPC, model_settings: Mapping[str, Any],
                 adapnn_gamma: float, only: Iterable[str] | None = None) -> PairedFlights:
    """All seven models flown once on each independent unit: trained network k, MLP k and disturbance k.

    Unit ``k`` pairs ``members[k]`` (seed, residual network), ``mlps[k]`` (seed, MLP) and ``tests[k]`` (one
    disturbance drawn independently of the others): the units share nothing random, so they are independent
    and each model's flight of a unit is its own (Nomi and FB fly unit k's disturbance once, as every other
    model). Every comparison of Q3-Q5 is then paired over the S units, with S their true number. AdapNN
    flies at ``adapnn_gamma``. ``only`` flies just the named models (all seven when ``None``; e.g. AdapFNN alone
    at another ``Gamma``). Raises ValueError unless the three lists have the same length >= 1, or for a name
    ``only`` lists that is not one of the seven.
    """
    if not members or not (len(members) == len(mlps) == len(tests)):
        raise ValueError(f"need one trained network, one MLP and one test per unit (at least one unit), got "
                         f"{len(members)} networks, {len(mlps)} MLPs, {len(tests)} tests")
    names = None if only is None else set(only)
    if names is not None and (not names or names - {*SIX, "AdapFNN"}):
        raise ValueError(f"only must name some of {[*SIX, 'AdapFNN']}, got {sorted(names)}")
    out: dict[str, list[FlightResult]] = {}
    for (_, net), (_, mlp), test in zip(members, mlps, tests):
        for m in paper_models(net, mlp, **model_settings, adapnn_gamma=adapnn_gamma):  # the paper's order
            if names is None or m.name in names:
                out.setdefault(m.name, []).append(fly(m, mpc, test))
    units = tuple(f"network {s}, MLP {s_m}, disturbance {k + 1}" for k, ((s, _), (s_m, _)) in
                  enumerate(zip(members, mlps)))
    return PairedFlights(out, units)


def thrust_needed(vehicle: QuadrotorParams, curve: Mapping[str, float], *, steps: int, Ts: float) -> dict[str, float]:
    r"""Thrust per motor the vehicle needs on the Lissajous reference: to hover, and at its peak acceleration.

    The total thrust vector that makes the vehicle follow ``p(t)`` is :math:`m\,(g e_3 - a(t))` (z down, Eq.
    (27) without drag or force), :math:`a(t)` the reference's analytic acceleration
    (:func:`~fnnlib.quadrotor.control.lissajous.lissajous`, ``curve`` its parameters) on ``t = 0, Ts, ..., steps Ts``.
    Returns ``hover`` (:math:`m g / 4`) and ``peak`` (:math:`m \max_t \lVert g e_3 - a(t)\rVert / 4`), in N per
    motor, and ``t_peak`` in s. Drag and an external force come on top.
    """
    t = np.arange(int(steps) + 1) * float(Ts)
    a = lissajous(t, **curve).a  # (T + 1, 3)
    h = np.linalg.norm(np.array([0.0, 0.0, vehicle.g]) - a, axis=1)
    return {"hover": vehicle.mass * vehicle.g / 4, "peak": float(vehicle.mass * h.max() / 4),
            "t_peak": float(t[int(np.argmax(h))])}


def speed_summary(timing: Mapping[str, Mapping[str, Any]], *, repeats: int, thrust_bound: float, qp: str,
                  backend: Backend, compile_s: float) -> dict[str, Any]:
    """Worst and best model against :data:`SPEED_TARGETS`; ``met`` when the worst model meets both."""
    speed = {"per_model": timing, "repeats": int(repeats), "thrust_bound": thrust_bound,
             "step_ms_median_worst_model": max(v["step_ms_median"] for v in timing.values()),
             "step_ms_median_best_model": min(v["step_ms_median"] for v in timing.values()),
             "real_time_factor_worst_model": min(v["real_time_factor_median"] for v in timing.values()),
             "real_time_factor_best_model": max(v["real_time_factor_median"] for v in timing.values()),
             "targets": dict(SPEED_TARGETS), "qp": qp, "backend": backend.name,
             "linearize_method": backend.linearization,
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


def hand_gains_on_flights(model: PredictionModel, x: Tensor, u: Tensor, Ts: float, N: int, L_grid: Sequence[float],
                          beta_grid: Sequence[float]):
    """Gains tuned by hand on recorded flights, never a flown loop (B1, Sec. 5.2.2): the (L, beta) of the grid
    (a scalar L times I) whose N-step cascade of Sec. 3.3 on ``model`` (Euler steps of ``Ts``, the recorded thrusts
    ``u`` (K, T, 4) as inputs) has the lowest mean N-step position error (m) along the flights ``x`` (K, T, 12)."""
    import torch  # noqa: PLC0415

    from fnnlib.feedback import cascade_predict, sweep_gains  # noqa: PLC0415
    from fnnlib.metrics import n_step_errors  # noqa: PLC0415

    def cost(L: float, beta: float) -> float:
        with torch.no_grad():
            z = cascade_predict(lambda t, x_, u_: model.f(x_, u_), x, Ts, N, Gains(L, beta), u=u)
        return float(n_step_errors(z[..., :3], x[..., :3], N).mean())
    return sweep_gains(cost, L_grid, beta_grid)


def flown_gain_sweep(residual: nn.Module, tests: Sequence[FlightTest], mpc: LinearizedMPC | OSQPMPC, *,
                     L_grid: Sequence[float], beta_grid: Sequence[float], plant: Quadrotor, N: int, Ts: float):
    """Gains tuned through the closed loop they serve (B1, Sec. 5.2.2): FNN (:func:`fnn_model`: the nominal
    ``plant`` plus ``residual``, the cascade at (L, beta)) flies every flight of ``tests`` under ``mpc`` (Eq. (28))
    at each grid pair; the pair with the lowest mean tracking RMSE is kept (:func:`fnnlib.feedback.sweep_gains`),
    a flight that diverges or leaves the model's domain scoring inf."""
    from fnnlib.feedback import sweep_gains  # noqa: PLC0415

    def rmse(L: float, beta: float) -> float:
        out = []
        for test in tests:
            try:
                r = fly(fnn_model(residual, L, beta, plant=plant, N=N, Ts=Ts), mpc, test)
            except ValueError:
                return float("inf")
            out.append(float("inf") if r.diverged else tracking_rmse(r.x, r.x_ref)["mean_axis"])
        return float(np.mean(out))
    return sweep_gains(rmse, L_grid, beta_grid)
