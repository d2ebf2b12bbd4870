"""The flight records of the why grid of Q3-Q5 (fnnbook.quadrotor_eval), on hand-made flights."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from fnnbook.quadrotor_eval import at_gains, flight_numbers


def flight(offset: float, acc_error: float, diverged: bool = False) -> SimpleNamespace:
    """A flight of 4 steps off the reference by ``offset`` in x only, its acceleration prediction off by
    ``acc_error`` in one axis."""
    x_ref = np.zeros((5, 12))
    x = x_ref.copy()
    x[:, 0] = offset
    xdot_true = np.zeros((4, 12))
    xdot_pred = xdot_true.copy()
    xdot_pred[:, 4] = acc_error
    return SimpleNamespace(x=x, x_ref=x_ref, xdot_true=xdot_true, xdot_pred=xdot_pred, diverged=diverged)


def test_the_numbers_of_a_flight_are_its_mean_axis_rmse_and_first_step_acceleration_error() -> None:
    got = flight_numbers([flight(0.3, 2.0), flight(0.0, 0.0, diverged=True)])
    assert got["rmse"] == pytest.approx([0.1, 0.0])  # 0.3 m in x only: (0.3 + 0 + 0) / 3
    assert got["acc"] == pytest.approx([2.0, 0.0])
    assert got["diverged"] == [False, True]


def test_the_adaptive_models_are_read_at_their_own_gain_the_others_as_flown() -> None:
    record = {"FNN": {"rmse": [1.0]}, "AdapNN": {"0.16": {"rmse": [2.0]}, "0.64": {"rmse": [3.0]}},
              "AdapFNN": {"2.0": {"rmse": [4.0]}, "8.0": {"rmse": [5.0]}}}
    assert at_gains(record, "FNN", 0.64, 8.0) == {"rmse": [1.0]}
    assert at_gains(record, "AdapNN", 0.64, 2.0) == {"rmse": [3.0]}
    assert at_gains(record, "AdapFNN", 0.16, 2.0) == {"rmse": [4.0]}
    with pytest.raises(KeyError, match="AdapFNN was not flown at the gain 32"):
        at_gains(record, "AdapFNN", 0.16, 32.0)
