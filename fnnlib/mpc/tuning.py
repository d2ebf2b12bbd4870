r"""Baseline settings chosen away from the test flight (issue 16): validation flights from the training distribution.

The paper tunes AdapNN "for optimal performance"; choosing its gain :math:`\Gamma` of Eq. (30) on the
test Lissajous flight itself would hand the baseline knowledge of the test. Here a gain is chosen on
*validation* flights drawn like the training data of App. A.5.4 (random rest-to-rest minimum-snap flights
through waypoints in the training box, :func:`~fnnlib.control.min_snap.random_min_snap_flights`)
with a seed of their own, and the test flight is flown once with the chosen value. The oracle-tuned value
(best on the test flight) can still be reported beside it, as context.
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
from fnnlib.control.flatness import flat_reference
from fnnlib.control.min_snap import random_min_snap_flights
from fnnlib.mpc.flight import FlightResult, tracking_rmse
from fnnlib.systems.quadrotor import QuadrotorParams

__all__ = ["GainSelection", "select_gain_on_validation", "validation_references"]

Reference = tuple[Tensor, Tensor]


def validation_references(n_flights: int, steps: int, N: int, *, seed: int, Ts: float, n_waypoints: int,
                          box: Sequence[Sequence[float]], max_speed: float,
                          params: QuadrotorParams) -> list[Reference]:
    """Validation references from the training distribution: random min-snap flights on the control grid.

    Each is ``(x_r (steps + N + 1, 12), u_r (steps + N, 4))``, float64, by differential flatness
    (zero yaw) like :func:`~fnnlib.mpc.flight.lissajous_reference`, from
    ``random_min_snap_flights(n_flights, steps + N + 1, Ts=Ts, seed=seed, n_waypoints=..., box=...,
    max_speed=...)``: the training box and speed limit of App. A.5.4
    (:data:`~fnnlib.quadrotor_presets.PAPER_FLIGHT_DATA`). Pass a ``seed`` that neither the training nor
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

    Attributes
    ----------
    value : float
        The chosen gain: the lowest mean validation RMSE among the gains with no diverged flight (or the
        smallest gain within ``rtol`` of it, see :func:`select_gain_on_validation`).
    table : dict
        Per gain: ``rmse`` (mean over the validation flights of the per-axis-mean position RMSE, the
        paper's number; inf when a flight diverged), ``rmse_per_flight``, ``fallback_share`` (largest
        over the flights), ``fallback_reasons`` (summed over the flights) and ``diverged`` (any flight marked diverged, :attr:`FlightResult.diverged`, or
        refused by ``fly`` with a ValueError as it left the model's domain; then ``error`` holds the message).
    """

    value: float
    table: dict[float, dict[str, object]]


def select_gain_on_validation(fly_fn: Callable[[float, Tensor, Tensor], FlightResult], grid: Sequence[float],
                              validation_refs: Sequence[Reference], *, rtol: float = 0.0) -> GainSelection:
    r"""Choose a baseline gain (e.g. AdapNN's :math:`\Gamma`) on validation flights, never on the test flight.

    Parameters
    ----------
    fly_fn : callable
        ``fly_fn(gain, x_r, u_r) -> FlightResult``: one closed-loop flight with a fresh model at that gain
        (e.g. a closure over :func:`~fnnlib.mpc.flight.fly` and the MPC).
    grid : sequence of float
        Candidate gains, each finite and > 0, no repeats. For AdapNN, bracket the release's effective value
        :math:`T_s \Gamma_{release} = 0.16` (see :class:`~fnnlib.mpc.models.AdaptiveNNModel`).
    validation_refs : sequence of (x_r, u_r)
        Validation references, e.g. from :func:`validation_references`.
    rtol : float, keyword-only
        Parsimony: the *smallest* gain whose validation RMSE is within ``(1 + rtol)`` times the best one
        (default 0: the best). Adaptive gains are riskier the larger they are, and gentle validation
        flights may keep improving up to the grid's end while the test flight runs away.

    Returns
    -------
    GainSelection
        The chosen value and the table. A gain with a diverged validation flight is never chosen.

    Raises
    ------
    ValueError
        An empty or bad grid, no references (before any flight); every gain diverged (after the sweep,
        with the table in the message).
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
    refs = list(validation_refs)
    if not refs:
        raise ValueError("validation_refs is empty: the gain must be chosen on validation flights")
    table: dict[float, dict[str, object]] = {}
    for g in gains:
        try:
            flights = [fly_fn(g, x_r, u_r) for x_r, u_r in refs]
        except ValueError as exc:  # fly's refusal of a flight that left the model's domain: diverged
            table[g] = {"rmse": math.inf, "rmse_per_flight": [], "fallback_share": math.nan, "diverged": True,
                        "error": str(exc)}
            continue
        per_flight = [tracking_rmse(r.x, r.x_ref)["mean_axis"] for r in flights]
        diverged = any(r.diverged for r in flights)
        reasons = Counter(k for r in flights for k, n in r.fallback_reasons.items() for _ in range(n))
        table[g] = {"rmse": math.inf if diverged else float(np.mean(per_flight)), "rmse_per_flight": per_flight,
                    "fallback_share": max(r.fallback_share for r in flights), "fallback_reasons": dict(reasons),
                    "diverged": diverged}
    usable = {g: row["rmse"] for g, row in table.items() if not row["diverged"]}
    if not usable:
        raise ValueError(f"every gain diverged on a validation flight: {table}")
    best = min(usable.values())
    return GainSelection(value=min(g for g, r in usable.items() if r <= (1.0 + rtol) * best), table=table)
