"""The flight-test helpers of fnnlib.mpc.experiment: QP boxes, the table row, speed, Theorem 2, seed spread, claims."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fnnlib.models.residual import AeroResidual
from fnnlib.mpc.experiment import (CARRYING, SIX, SPEED_TARGETS, FlightTest, acc_pred_rmse, adapnn_flights, claim_checks,
                                   flight_row, make_mpc, speed_runs, speed_summary, spread_orderings, theorem2_check)
from fnnlib.mpc.flight import FlightResult, lissajous_reference
from fnnlib.mpc.linearized import LinearizedMPC, OSQPMPC
from fnnlib.quadrotor_presets import PAPER_LISSAJOUS, PAPER_MPC_WEIGHTS, PAPER_THETA_MAX
from fnnlib.systems.quadrotor import NOMINAL, TEST_TRUTH, Quadrotor


def _result(T: int = 50, seed: int = 0) -> FlightResult:
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(T + 1, 12))
    return FlightResult(name="m", x=x, u=rng.uniform(size=(T, 4)), x_ref=x + 0.1, xdot_true=rng.normal(size=(T, 12)),
                        xdot_pred=rng.normal(size=(T, 12)), x_tilde=rng.normal(size=(T, 12)),
                        delta=rng.normal(size=(T, 12)), t_linearize=np.full(T, 1e-3), t_solve=np.full(T, 2e-3),
                        n_fallbacks=1, Ts=0.02, elapsed_s=0.5)


def test_make_mpc_builds_eq28_with_the_boxes():
    for qp, cls in (("osqp", OSQPMPC), ("cvxpy", LinearizedMPC)):
        mpc = make_mpc(qp, 5, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], u_max=6.0, theta_max=PAPER_THETA_MAX,
                       solver="OSQP")
        assert type(mpc) is cls and mpc.N == 5
        np.testing.assert_array_equal(mpc.u_lb, np.zeros(4))
        np.testing.assert_array_equal(mpc.u_ub, np.full(4, 6.0))
    with pytest.raises(ValueError, match="qp must be one of"):
        make_mpc("qpoases", 5, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], u_max=6.0, theta_max=1.0, solver="OSQP")


def test_flight_row_holds_tracking_prediction_and_timing():
    r = _result()
    row = flight_row(r)
    # x_ref = x + 0.1 on every axis: every RMSE is 0.1, the norm's sqrt(3) 0.1
    assert row["mean_axis"] == pytest.approx(0.1) and row["norm"] == pytest.approx(0.1 * math.sqrt(3))
    e = r.xdot_pred[:, 3:6] - r.xdot_true[:, 3:6]
    assert row["acc_pred_rmse"] == acc_pred_rmse(r) == pytest.approx(math.sqrt((e**2).sum(1).mean()), rel=1e-15)
    assert row["step_ms_median"] == pytest.approx(3.0) and row["fallbacks"] == 1
    assert row["real_time_factor"] == pytest.approx(50 * 0.02 / 0.5)


def test_speed_summary_is_met_only_when_the_worst_model_meets_both_targets():
    fast = {"step_ms_median": 1.0, "real_time_factor_median": 9.0}
    slow = {"step_ms_median": SPEED_TARGETS["step_ms_median"] + 1, "real_time_factor_median": 9.0}
    kw = dict(repeats=3, thrust_bound=6.0, qp="osqp", backend="numba", linearize_method="forward", compile_s=0.1)
    good, bad = speed_summary({"A": fast, "B": fast}, **kw), speed_summary({"A": fast, "B": slow}, **kw)
    assert good["met"] and not bad["met"]
    assert bad["step_ms_median_worst_model"] == slow["step_ms_median"] and bad["step_ms_median_best_model"] == 1.0
    assert bad["linearize_method"] == "exact (forward mode, compiled)"
    assert speed_summary({"A": fast}, **{**kw, "backend": "torch"})["linearize_method"] == "forward"
    with pytest.raises(ValueError, match="speed_repeats"):
        speed_runs([], None, None, 0)  # type: ignore[arg-type]


def test_theorem2_check_counts_the_ball_after_the_transient():
    r = _result(T=40)
    r.x_tilde[:] = 0.0
    r.x_tilde[20:, 0] = np.linspace(0.0, 2.0, 20)  # grows past the ball late in the flight
    r.delta[:] = 0.0
    r.delta[5:, 1] = 3.0  # gamma = 3 after the transient
    out = theorem2_check(r, 3.0, 5)
    assert out["gamma"] == 3.0 and out["ball_x"] == pytest.approx(1.0)  # gamma / lambda_m(L) = 3 / 3
    e = np.linalg.norm(r.x_tilde[5:], axis=1)
    assert out["inside_fraction"] == pytest.approx(np.mean(e <= 1.0)) and 0 < out["inside_fraction"] < 1
    assert out["max_error"] == 2.0


def _table(rmse: dict[str, float], acc: dict[str, float]) -> dict:
    return {"6.0": {n: {"mean_axis": rmse[n], "acc_pred_rmse": acc[n]} for n in rmse}}


def test_claim_checks_follow_the_rules():
    rmse = {"Nomi": 0.5, "Neural": 0.3, "MLP": 0.4, "FB": 0.2, "AdapNN": 0.25, "FNN": 0.1, "AdapFNN": 0.11}
    acc = {"Nomi": 3.0, "Neural": 2.0, "MLP": 2.5, "FB": 1.0, "AdapNN": 1.8, "FNN": 0.9, "AdapFNN": 0.95}
    q3, q4, q5 = claim_checks(_table(rmse, acc), {"6.0": {"inside_fraction": 0.97}})
    assert all(q3.values()) and all(q4.values()) and all(q5.values()) and len(q3) == 3 and len(q5) == 3
    worse = {**rmse, "AdapFNN": 0.2, "FNN": 0.21}  # FNN no longer the best of the six, AdapFNN < FNN
    q3, _, q5 = claim_checks(_table(worse, acc), {"6.0": {"inside_fraction": 0.5}})
    assert not q3["6.0 N: FNN best of the six"] and not q5["6.0 N: AdapFNN >= FNN"]
    assert not q5["6.0 N: Theorem 2 ball holds >= 95 % after the transient"]


def test_spread_orderings_are_fractions_over_seeds():
    table = {"6.0": {"Nomi": {"mean_axis": 0.5}, "MLP": {"mean_axis": 0.4}, "FB": {"mean_axis": 0.2}}}
    spread = {"6.0": {"Neural": {"0": 0.3, "1": 0.3}, "AdapNN": {"0": 0.25, "1": 0.05},
                      "FNN": {"0": 0.1, "1": 0.1}, "AdapFNN": {"0": 0.11, "1": 0.09}}}
    o = spread_orderings(spread, table)["6.0"]
    assert o["FNN best of the six"] == 0.5 and o["FNN < AdapNN"] == 0.5 and o["Neural < Nomi"] == 1.0
    assert o["AdapFNN >= FNN"] == 0.5 and o["AdapFNN within 25 % of FNN"] == 1.0
    assert set(CARRYING) < set(SIX) | {"AdapFNN"}


def test_adapnn_flights_fly_one_model_per_gain():
    torch.manual_seed(0)
    net = AeroResidual((4,), "tanh").double()
    N, steps = 3, 3
    x_r, u_r = lissajous_reference(steps, N, Ts=0.02, params=NOMINAL, curve=PAPER_LISSAJOUS)
    test = FlightTest(Quadrotor(TEST_TRUTH), x_r, u_r, steps=steps, Ts=0.02, substeps=1, backend="torch",
                      linearize_method="forward")
    mpc = make_mpc("osqp", N, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], u_max=6.0, theta_max=1.5, solver="OSQP")
    runs = adapnn_flights(net, [1.0, 8.0], mpc, test)
    assert list(runs) == [1.0, 8.0] and all(r.name == "AdapNN" and r.x.shape == (steps + 1, 12) for r in runs.values())
    assert not np.array_equal(runs[1.0].x, runs[8.0].x)  # the gain is used
