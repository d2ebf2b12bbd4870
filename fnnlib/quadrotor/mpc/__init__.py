"""MPC of Eq. (28) (App. A.5.3) and the flight test of Sec. 5.2.2.

The public face, what a notebook needs: the prediction models (:func:`paper_models`), a flight test
(:class:`FlightTest` on a :class:`Backend`, or :func:`flight_tests`), one closed-loop flight
(:func:`fly`), the QP (:func:`make_mpc`), the flight table (:func:`flight_row`, :class:`TableKey`), the paired
flights over independent units (:func:`paired_units`), the thrust a vehicle needs (:func:`thrust_needed`), AdapNN's gain chosen on validation flights, the speed summary and Theorem 2.
Below them: the affine models of a torch step along a plan and the linear time-varying QP.
"""

from __future__ import annotations

from torch import nn

from fnnlib.quadrotor.mpc.backends import Backend
from fnnlib.quadrotor.mpc.experiment import (CARRYING, SIX, SPEED_TARGETS, FlightRow, FlightSetup, PairedFlights, TableKey,
                                   acc_pred_rmse, adapnn_flights, adapnn_gain_on_validation, adapnn_model,
                                   disturbance_realisations, fallback_note, flight_row, flight_table_json,
                                   FlightSettings, MPCSettings, flight_tests, flown_gain_sweep, fnn_model, hand_gains_on_flights,
                                   make_mpc, paired_units,
                                   pooled_speed, speed_summary, theorem2_check, thrust_needed)
from fnnlib.quadrotor.mpc.flight import FlightResult, FlightTest, fly, lissajous_reference, tracking_rmse
from fnnlib.quadrotor.mpc.linearize import Linearization, StepFn, linearize
from fnnlib.quadrotor.mpc.linearized import LinearizedMPC, MPCSolution, OSQPMPC, RebuildMPC, shift_plan
from fnnlib.quadrotor.mpc.models import AdaptiveNNModel, FeedbackCascadeModel, PredictionModel, paper_models
from fnnlib.quadrotor.mpc.tuning import (GainSelection, randomization_coordinates, randomized_vehicles,
                               select_gain_on_validation, validation_references)


def warm_up(*residuals: nn.Module | None) -> float:
    """Compile the numba kernels of the compiled backend (:func:`fnnlib.quadrotor.mpc.compiled.warm_up`); seconds taken.

    numba is imported only here, when the compiled backend is asked for."""
    from fnnlib.quadrotor.mpc.compiled import warm_up as compile_kernels

    return compile_kernels(*residuals)


__all__ = [
    "CARRYING", "SIX", "SPEED_TARGETS", "AdaptiveNNModel", "Backend", "FeedbackCascadeModel", "FlightResult",
    "FlightRow", "FlightSetup", "FlightTest", "GainSelection", "Linearization", "LinearizedMPC", "MPCSolution",
    "OSQPMPC", "PairedFlights", "PredictionModel", "RebuildMPC", "StepFn", "TableKey", "acc_pred_rmse",
    "adapnn_flights", "adapnn_gain_on_validation", "adapnn_model", "disturbance_realisations", "fallback_note",
    "flight_row", "flight_table_json", "FlightSettings", "MPCSettings", "flight_tests", "flown_gain_sweep", "fly", "fnn_model",
    "hand_gains_on_flights", "lissajous_reference", "linearize",
    "make_mpc", "paired_units", "paper_models", "pooled_speed", "randomization_coordinates",
    "randomized_vehicles", "select_gain_on_validation", "shift_plan", "speed_summary", "theorem2_check",
    "thrust_needed", "tracking_rmse", "validation_references", "warm_up",
]
