r"""Baseline settings chosen away from the test flight: validation flights from the training distribution.

The paper tunes AdapNN "for optimal performance"; choosing its gain :math:`\Gamma` of Eq. (30) on the
test Lissajous flight itself would hand the baseline knowledge of the test, and so would a validation vehicle
placed with the test vehicle in mind. Here a gain is chosen on *validation* flights that never read the test:

* references drawn like the training data of App. A.5.4 (random rest-to-rest minimum-snap flights through
  waypoints in the training box, :func:`~fnnlib.quadrotor.control.min_snap.random_min_snap_flights`) with a seed of their
  own (:func:`validation_references`);
* vehicles drawn by domain randomisation around the *training* vehicle, in the spirit of Alg. 1 / Eq. (12),
  with ranges fixed a priori (:func:`randomized_vehicles`,
  :data:`~fnnlib.quadrotor.presets.VALIDATION_RANDOMIZATION`);
* every vehicle flies every reference at every gain, and a stated rule picks the gain
  (:func:`select_gain_on_validation`: lowest median validation RMSE, a diverged flight counting as worst, ties
  within a tolerance broken toward the smaller gain).

The test flight is then flown once with the chosen value. The oracle-tuned value (best on the test flight) can be
reported beside it, as context, and :func:`randomization_coordinates` says where the test vehicle lies in the
randomisation's ranges, also as context.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from fnnlib._validation import check_positive
from fnnlib.quadrotor.control.flatness import flat_reference
from fnnlib.quadrotor.control.min_snap import random_min_snap_flights
from fnnlib.quadrotor.mpc.flight import FlightResult, tracking_rmse
from fnnlib.quadrotor.system import QuadrotorParams

__all__ = ["GainSelection", "randomization_coordinates", "randomized_vehicles", "select_gain_on_validation",
           "validation_references"]

Reference = tuple[Tensor, Tensor]

_RELATIVE = ("mass", "inertia", "drag")  # randomised relative to the training value


def _check_widths(mass: float, inertia: float, drag: float, force_per_weight: float) -> dict[str, float]:
    widths = {"mass": mass, "inertia": inertia, "drag": drag}
    for name, w in widths.items():
        if isinstance(w, bool) or not (isinstance(w, (int, float)) and 0 <= w < 1):
            raise ValueError(f"the relative half-width of {name} must lie in [0, 1) (positive parameters), got {w!r}")
    if isinstance(force_per_weight, bool) or not (isinstance(force_per_weight, (int, float))
                                                  and math.isfinite(force_per_weight) and force_per_weight >= 0):
        raise ValueError(f"force_per_weight must be finite and >= 0, got {force_per_weight!r}")
    return {**{k: float(v) for k, v in widths.items()}, "force_per_weight": float(force_per_weight)}


def randomized_vehicles(train: QuadrotorParams, n: int, *, seed: int, mass: float, inertia: float, drag: float,
                        force_per_weight: float) -> list[QuadrotorParams]:
    r"""``n`` validation vehicles drawn by domain randomisation around the training vehicle (Alg. 1 / Eq. (12)).

    Mass, each inertia and each drag coefficient are independently uniform in ``train``'s value x (1 +- the
    relative half-width ``mass``, ``inertia``, ``drag``); the constant force has each axis uniform in
    +- ``force_per_weight`` x ``train.mass * train.g``, added to ``train``'s force. Draws come from
    ``numpy.random.default_rng(seed)``, per vehicle in the order mass, inertia (3), drag (3), force (3). The
    paper-run ranges are :data:`~fnnlib.quadrotor.presets.VALIDATION_RANDOMIZATION`, justified there.

    Only the training vehicle and the ranges enter: a test vehicle cannot.
    """
    w = _check_widths(mass, inertia, drag, force_per_weight)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be an int >= 1, got {n!r}")
    rng = np.random.default_rng(seed)
    weight = train.mass * train.g
    vehicles = []
    for _ in range(int(n)):
        m = train.mass * (1.0 + w["mass"] * rng.uniform(-1.0, 1.0))
        J = np.asarray(train.inertia) * (1.0 + w["inertia"] * rng.uniform(-1.0, 1.0, 3))
        D = np.asarray(train.drag) * (1.0 + w["drag"] * rng.uniform(-1.0, 1.0, 3))
        F = np.asarray(train.force_disturbance) + w["force_per_weight"] * weight * rng.uniform(-1.0, 1.0, 3)
        vehicles.append(train.replace(mass=float(m), inertia=tuple(map(float, J)), drag=tuple(map(float, D)),
                                      force_disturbance=tuple(map(float, F))))
    return vehicles


def randomization_coordinates(vehicle: QuadrotorParams, train: QuadrotorParams, *, mass: float, inertia: float,
                              drag: float, force_per_weight: float) -> dict[str, list[float]]:
    """Where ``vehicle`` lies in the ranges of :func:`randomized_vehicles`, in units of each half-width.

    Per parameter (``mass`` one value, the others three): ``(vehicle - train) / (train x half-width)`` for
    mass, inertia and drag, ``(force - train's force) / (force_per_weight x train's weight)`` for the force.
    Inside the range every entry lies in [-1, 1]; a parameter with zero width (or a zero training value) gives
    0 where it equals the training value and +-inf elsewhere. For context only (e.g. a test vehicle).
    """
    w = _check_widths(mass, inertia, drag, force_per_weight)

    def coord(delta: np.ndarray, scale: np.ndarray) -> list[float]:
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.where(delta == 0, 0.0, delta / scale)
        return [float(v) for v in np.atleast_1d(c)]

    out = {k: coord(np.asarray(getattr(vehicle, k), float) - np.asarray(getattr(train, k), float),
                    np.asarray(getattr(train, k), float) * w[k]) for k in _RELATIVE}
    out["force"] = coord(np.asarray(vehicle.force_disturbance) - np.asarray(train.force_disturbance),
                         np.full(3, w["force_per_weight"] * train.mass * train.g))
    return out


def validation_references(n_flights: int, steps: int, N: int, *, seed: int, Ts: float, n_waypoints: int,
                          box: Sequence[Sequence[float]], max_speed: float,
                          params: QuadrotorParams) -> list[Reference]:
    """Validation references from the training distribution: random min-snap flights on the control grid.

    Each is ``(x_r (steps + N + 1, 12), u_r (steps + N, 4))``, float64, by differential flatness
    (zero yaw) like :func:`~fnnlib.quadrotor.mpc.flight.lissajous_reference`, from
    ``random_min_snap_flights(n_flights, steps + N + 1, Ts=Ts, seed=seed, n_waypoints=..., box=...,
    max_speed=...)``: the training box and speed limit of App. A.5.4
    (:data:`~fnnlib.quadrotor.presets.PAPER_FLIGHT_DATA`). Pass a ``seed`` that neither the training nor
    the validation set of the learning task used. The training flights have about 100 nodes (2 s) per
    segment; ``n_waypoints`` = 1 + (steps + N) / 100 keeps that pace (4 for the paper's 300 steps).
    ``params`` is the vehicle the references are computed for by flatness (the paper's: the nominal
    model, like the test reference). Fly them on a vehicle other than the test vehicle.
    """
    if int(steps) < 1 or int(N) < 1:
        raise ValueError(f"steps and N must be >= 1, got steps={steps}, N={N}")
    flights = random_min_snap_flights(n_flights, int(steps) + int(N) + 1, Ts=check_positive(Ts, name="Ts"),
                                      seed=seed, n_waypoints=n_waypoints, box=box, max_speed=max_speed)
    refs = []
    for psi, snap in zip(flights.psi, flights.snap):
        x_r, u_r = flat_reference(torch.as_tensor(psi, dtype=torch.float64), torch.as_tensor(snap, dtype=torch.float64),
                                  params=params)
        refs.append((x_r, u_r[:-1]))
    return refs


@dataclass(frozen=True)
class GainSelection:
    """The gain chosen on validation flights, with the whole table.

    What :func:`select_gain_on_validation` returns: the table keeps every gain's flights, so a reader sees
    how close the runner-up came and which gains diverged.

    Attributes
    ----------
    value : float
        The chosen gain: the smallest gain whose median validation RMSE is within ``(1 + rtol)`` of the lowest
        one (see :func:`select_gain_on_validation`).
    table : dict
        Per gain: ``rmse`` (the median over the validation flights of the per-axis-mean position RMSE, the
        paper's number, with a diverged flight counted as worst, i.e. inf; so inf when at least half diverged),
        ``rmse_per_flight`` (inf where the flight diverged), ``diverged_flights`` (how many were marked diverged,
        :attr:`FlightResult.diverged`, or refused by ``fly`` with a ValueError as they left the model's domain;
        ``error`` then holds the first message), ``diverged`` (any of them), ``fallback_share`` (largest over the
        flights that ran) and ``fallback_reasons`` (summed over them).
    """

    value: float
    table: dict[float, dict[str, object]]


def select_gain_on_validation(fly_fn: Callable[..., FlightResult], grid: Sequence[float],
                              validation_cases: Sequence[tuple], *, rtol: float = 0.0) -> GainSelection:
    r"""Choose a baseline gain (e.g. AdapNN's :math:`\Gamma`) on validation flights, never on the test flight.

    The rule, stated before any flight: every gain flies every case; a gain scores the **median** of its
    flights' per-axis-mean position RMSE, a diverged flight counting as worst (inf); the lowest score wins, and
    ties within ``rtol`` go to the **smaller gain** (adaptive gains are riskier the larger they are). The median
    keeps one unlucky vehicle from deciding, and a gain that diverges on half the cases or more never wins.

    Parameters
    ----------
    fly_fn : callable
        ``fly_fn(gain, *case) -> FlightResult``: one closed-loop flight with a fresh model at that gain
        (e.g. a closure over :func:`~fnnlib.quadrotor.mpc.flight.fly` and the MPC). It may raise ValueError for a flight
        that leaves the model's domain: that flight counts as diverged.
    grid : sequence of float
        Candidate gains, each finite and > 0, no repeats. For AdapNN, bracket the release's effective value
        :math:`T_s \Gamma_{release} = 0.16` (see :class:`~fnnlib.quadrotor.mpc.models.AdaptiveNNModel`).
    validation_cases : sequence of tuples
        What each validation flight needs besides the gain, e.g. ``(x_r, u_r)`` from :func:`validation_references`
        or ``(truth, x_r, u_r)`` with the truth from :func:`randomized_vehicles`.
    rtol : float, keyword-only
        The tie tolerance: the chosen gain is the *smallest* whose median is at most ``(1 + rtol)`` times the
        lowest (default 0: the lowest).

    Returns
    -------
    GainSelection
        The chosen value and the table.

    Raises
    ------
    ValueError
        An empty or bad grid, no cases, a bad ``rtol`` (before any flight); every gain diverged on at least half
        of the cases (after the sweep, with the table in the message).
    """
    gains = [float(g) for g in grid]
    if not gains:
        raise ValueError("grid is empty")
    if any(not (math.isfinite(g) and g > 0) for g in gains):
        raise ValueError(f"every gain must be finite and > 0, got {gains}")
    if len(set(gains)) != len(gains):
        raise ValueError(f"grid repeats a gain: {gains}")
    if not (math.isfinite(rtol) and rtol >= 0):
        raise ValueError(f"rtol must be finite and >= 0, got {rtol}")
    cases = [tuple(c) for c in validation_cases]
    if not cases:
        raise ValueError("validation_cases is empty: the gain must be chosen on validation flights")
    table: dict[float, dict[str, object]] = {}
    for g in gains:
        per_flight, flown, errors = [], [], []
        for case in cases:
            try:
                r = fly_fn(g, *case)
            except ValueError as exc:  # fly's refusal of a flight that left the model's domain: diverged
                errors.append(str(exc))
                per_flight.append(math.inf)
                continue
            flown.append(r)
            per_flight.append(math.inf if r.diverged else tracking_rmse(r.x, r.x_ref)["mean_axis"])
        n_diverged = len(errors) + sum(r.diverged for r in flown)
        reasons = Counter(k for r in flown for k, n in r.fallback_reasons.items() for _ in range(n))
        table[g] = {"rmse": float(np.median(per_flight)), "rmse_per_flight": per_flight,
                    "diverged_flights": n_diverged, "diverged": n_diverged > 0,
                    "fallback_share": max((r.fallback_share for r in flown), default=math.nan),
                    "fallback_reasons": dict(reasons)}
        if errors:
            table[g]["error"] = errors[0]
    usable = {g: row["rmse"] for g, row in table.items() if math.isfinite(row["rmse"])}
    if not usable:
        raise ValueError(f"every gain diverged on at least half of the validation flights: {table}")
    best = min(usable.values())
    return GainSelection(value=min(g for g, r in usable.items() if r <= (1.0 + rtol) * best), table=table)
