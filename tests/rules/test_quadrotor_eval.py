"""The flight records of the why grid of Q3-Q5 (fnnlib.quadrotor.evaluation), on hand-made flights."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from fnnlib.quadrotor.evaluation import at_gains, flight_numbers


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


def test_a_record_flies_each_model_once_per_unit_and_the_adaptive_ones_per_gain() -> None:
    """Two tiny units: the named models once per unit, AdapNN per gain of its grid, AdapFNN per Gamma with Theorem
    2's share; each entry the numbers of the flights paired_units flies at that gain."""
    import torch

    import fnnlib.quadrotor.mpc as M
    from fnnlib.quadrotor.evaluation import fly_record
    from fnnlib.quadrotor.residual import AeroResidual
    from fnnlib.quadrotor.mpc.backends import Backend
    from fnnlib.quadrotor.presets import PAPER_LISSAJOUS, PAPER_MPC_WEIGHTS
    from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, Quadrotor

    torch.manual_seed(0)
    nets = [(k, AeroResidual((4,), "tanh").double()) for k in range(2)]
    mlps = [(k, AeroResidual((4,), "tanh").double()) for k in range(2)]
    x_r, u_r = M.lissajous_reference(3, 3, Ts=0.02, params=NOMINAL, curve=PAPER_LISSAJOUS)
    tests = [M.FlightTest(Quadrotor(TEST_TRUTH.replace(force_disturbance=f)), x_r, u_r, steps=3, Ts=0.02, substeps=1,
                          backend=Backend("torch", "forward")) for f in ((0.3, 0.3, 0.3), (0.1, 0.4, 0.2))]
    mpc = M.make_mpc("osqp", 3, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], cost="as_flown", u_max=6.0,
                     theta_max=1.5, solver="OSQP")
    kw = dict(plant=Quadrotor(NOMINAL), L=3.0, beta=0.1, N=3, Gamma=0.16, Ts=0.02)
    rec = fly_record(nets, mlps, tests=tests, mpc=mpc, model_settings=kw, adapnn_gamma=0.16, names=["FNN", "Nomi"],
                     adapnn_grid=[0.16, 0.64], Gamma_grid=[2.0, 8.0], transient=1)
    assert set(rec) == {"Nomi", "FNN", "AdapNN", "AdapFNN"}
    assert list(rec["AdapNN"]) == ["0.16", "0.64"] and list(rec["AdapFNN"]) == ["2.0", "8.0"]
    assert all(len(v["rmse"]) == 2 for v in (rec["FNN"], rec["AdapNN"]["0.64"], rec["AdapFNN"]["8.0"]))
    assert all(0.0 <= s <= 1.0 for s in rec["AdapFNN"]["2.0"]["theorem2_inside"])
    again = M.paired_units(nets, mlps, tests=tests, mpc=mpc, model_settings={**kw, "Gamma": 8.0}, adapnn_gamma=0.64,
                           only=["AdapNN", "AdapFNN"])
    assert rec["AdapNN"]["0.64"] == flight_numbers(again["AdapNN"])
    assert {k: v for k, v in rec["AdapFNN"]["8.0"].items() if k != "theorem2_inside"} == flight_numbers(again["AdapFNN"])
    assert rec["AdapFNN"]["2.0"]["rmse"] != rec["AdapFNN"]["8.0"]["rmse"]  # Gamma is used
