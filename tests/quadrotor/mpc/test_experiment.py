"""The flight-test helpers of fnnlib.quadrotor.mpc.experiment: QP boxes, the table row, speed, Theorem 2, seed spread, claims."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fnnlib.quadrotor.residual import AeroResidual
from fnnlib.quadrotor.mpc.backends import Backend
from fnnlib.quadrotor.mpc.experiment import (CARRYING, SIX, SPEED_TARGETS, FlightRow, TableKey, acc_pred_rmse, adapnn_flights,
                                   adapnn_gain_on_validation, adapnn_model, disturbance_realisations, fallback_note,
                                   flight_row, flight_table_json, FlightSettings, MPCSettings, flight_tests, fnn_model, make_mpc,
                                   paired_units, pooled_speed, speed_summary, theorem2_check,
                                   thrust_needed)
from fnnlib.quadrotor.mpc.flight import FlightResult, FlightTest, fly, lissajous_reference
from fnnlib.quadrotor.mpc.models import paper_models
from fnnlib.quadrotor.mpc.linearized import LinearizedMPC, OSQPMPC
from fnnlib.quadrotor.mpc.tuning import randomized_vehicles
from fnnlib.quadrotor.presets import PAPER_LISSAJOUS, PAPER_MPC_WEIGHTS, PAPER_THETA_MAX, VALIDATION_RANDOMIZATION
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, TRAINING_TRUTH, Quadrotor


def _result(T: int = 50, seed: int = 0) -> FlightResult:
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(T + 1, 12))
    return FlightResult(name="m", x=x, u=rng.uniform(size=(T, 4)), x_ref=x + 0.1, xdot_true=rng.normal(size=(T, 12)),
                        xdot_pred=rng.normal(size=(T, 12)), x_tilde=rng.normal(size=(T, 12)),
                        delta=rng.normal(size=(T, 12)), t_linearize=np.full(T, 1e-3), t_solve=np.full(T, 2e-3),
                        n_fallbacks=1, Ts=0.02, elapsed_s=0.5)


def test_make_mpc_builds_eq28_with_the_boxes():
    for qp, cls in (("osqp", OSQPMPC), ("cvxpy", LinearizedMPC)):
        mpc = make_mpc(qp, 5, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], cost="as_flown", u_max=6.0,
                       theta_max=PAPER_THETA_MAX, solver="OSQP")
        assert type(mpc) is cls and mpc.N == 5 and mpc.cost == "as_flown"
        np.testing.assert_array_equal(mpc.u_lb, np.zeros(4))
        np.testing.assert_array_equal(mpc.u_ub, np.full(4, 6.0))
    with pytest.raises(ValueError, match="qp must be one of"):
        make_mpc("qpoases", 5, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], cost="as_written", u_max=6.0,
                 theta_max=1.0, solver="OSQP")
    with pytest.raises(ValueError, match="cost must be one of"):
        make_mpc("osqp", 5, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], cost="paper", u_max=6.0, theta_max=1.0,
                 solver="OSQP")


def test_flight_row_holds_tracking_prediction_and_timing():
    r = _result()
    row = flight_row(r)
    # x_ref = x + 0.1 on every axis: every RMSE is 0.1, the norm's sqrt(3) 0.1
    assert row.mean_axis == pytest.approx(0.1) and row.norm == pytest.approx(0.1 * math.sqrt(3))
    e = r.xdot_pred[:, 3:6] - r.xdot_true[:, 3:6]
    assert row.acc_pred_rmse == acc_pred_rmse(r) == pytest.approx(math.sqrt((e**2).sum(1).mean()), rel=1e-15)
    assert row.step_ms_median == pytest.approx(3.0) and row.fallbacks == 1
    assert row.real_time_factor == pytest.approx(50 * 0.02 / 0.5)
    assert not row.diverged and fallback_note(r) == ""
    r.n_fallbacks, r.fallback_reasons = 10, {"not_optimal": 10}  # 10 of 50 steps: past the diverged share
    assert flight_row(r).diverged and fallback_note(r) == "DIVERGED [not_optimal 10]"


def test_flight_table_is_keyed_by_cost_and_bound_and_serialises_as_before():
    row = flight_row(_result())
    d = row.to_dict()
    assert list(d)[:6] == ["x", "y", "z", "mean_axis", "norm", "acc_pred_rmse"] and list(d)[-1] == "real_time_factor"
    assert d["mean_axis"] == row.mean_axis and isinstance(row, FlightRow)
    table = {TableKey("as_flown", 6.0): {"Nomi": row}, TableKey("as_flown", 4.0): {"Nomi": row}}
    assert list(flight_table_json(table, 6.0)) == ["as_flown, 6 N", "as_flown, 4 N (context)"]
    assert flight_table_json(table, 6.0)["as_flown, 6 N"]["Nomi"] == d
    assert TableKey("as_written", 4.0) == ("as_written", 4.0)


def test_pooled_speed_pools_every_flight_of_a_model():
    a, b = _result(), _result(seed=1)
    b.t_solve[:] = 4e-3
    t = pooled_speed({"m": [a, b]})["m"]
    assert t["flights"] == 2 and t["step_ms_median"] == pytest.approx(4.0)  # medians of 3 ms and 5 ms steps: 4
    assert t["real_time_factor_median"] == pytest.approx(50 * 0.02 / 0.5)
    with pytest.raises(ValueError, match="no flights"):
        pooled_speed({"m": []})


def test_disturbances_start_with_the_papers_and_vary_size_and_direction():
    d = disturbance_realisations((0.3, 0.3, 0.3), 3, seed=5, spread=0.5)
    assert len(d) == 4 and d[0] == (0.3, 0.3, 0.3)
    drawn = np.array(d[1:])
    assert ((drawn >= 0.15) & (drawn <= 0.45)).all() and len({tuple(r) for r in drawn}) == 3
    assert np.ptp(drawn / np.linalg.norm(drawn, axis=1, keepdims=True), axis=0).max() > 0.01  # directions differ
    assert d == disturbance_realisations((0.3, 0.3, 0.3), 3, seed=5, spread=0.5)
    with pytest.raises(ValueError):
        disturbance_realisations((0.3, 0.3), 3, seed=5, spread=0.5)


def test_speed_summary_is_met_only_when_the_worst_model_meets_both_targets():
    fast = {"step_ms_median": 1.0, "real_time_factor_median": 9.0}
    slow = {"step_ms_median": SPEED_TARGETS["step_ms_median"] + 1, "real_time_factor_median": 9.0}
    kw = dict(repeats=3, thrust_bound=6.0, qp="osqp", backend=Backend("numba", "forward"), compile_s=0.1)
    good, bad = speed_summary({"A": fast, "B": fast}, **kw), speed_summary({"A": fast, "B": slow}, **kw)
    assert good["met"] and not bad["met"]
    assert bad["step_ms_median_worst_model"] == slow["step_ms_median"] and bad["step_ms_median_best_model"] == 1.0
    assert bad["linearize_method"] == "exact (forward mode, compiled)"
    assert bad["backend"] == "numba"
    assert speed_summary({"A": fast}, **{**kw, "backend": Backend("torch", "forward")})["linearize_method"] == "forward"


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


def _tiny(steps: int, N: int = 3, truth=TEST_TRUTH) -> tuple:
    """A small network, a short Lissajous test on ``truth`` (torch backend) and an as-flown QP with N = 3."""
    torch.manual_seed(0)
    net = AeroResidual((4,), "tanh").double()
    x_r, u_r = lissajous_reference(steps, N, Ts=0.02, params=NOMINAL, curve=PAPER_LISSAJOUS)
    test = FlightTest(Quadrotor(truth), x_r, u_r, steps=steps, Ts=0.02, substeps=1, backend=Backend("torch", "forward"))
    mpc = make_mpc("osqp", N, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], cost="as_flown", u_max=6.0,
                   theta_max=1.5, solver="OSQP")
    return net, test, mpc


def test_adapnn_flights_fly_one_model_per_gain():
    steps = 3
    net, test, mpc = _tiny(steps)
    runs = adapnn_flights(net, [1.0, 8.0], mpc, test)
    assert list(runs) == [1.0, 8.0] and all(r.name == "AdapNN" and r.x.shape == (steps + 1, 12) for r in runs.values())
    assert not np.array_equal(runs[1.0].x, runs[8.0].x)  # the gain is used


def _tiny_units(n: int = 2, steps: int = 3, N: int = 3):
    """``n`` tiny networks, ``n`` tiny MLPs and ``n`` tests under different forces."""
    torch.manual_seed(0)
    nets = [(k, AeroResidual((4,), "tanh").double()) for k in range(n)]
    mlps = [(k, AeroResidual((4,), "tanh").double()) for k in range(n)]
    x_r, u_r = lissajous_reference(steps, N, Ts=0.02, params=NOMINAL, curve=PAPER_LISSAJOUS)
    forces = ((0.3, 0.3, 0.3), (0.1, 0.4, 0.2), (0.2, 0.1, 0.45))[:n]
    tests = [FlightTest(Quadrotor(TEST_TRUTH.replace(force_disturbance=F)), x_r, u_r, steps=steps, Ts=0.02, substeps=1,
                        backend=Backend("torch", "forward")) for F in forces]
    mpc = make_mpc("osqp", N, PAPER_MPC_WEIGHTS["Q"], PAPER_MPC_WEIGHTS["R"], cost="as_flown", u_max=6.0,
                   theta_max=1.5, solver="OSQP")
    kw = dict(plant=Quadrotor(NOMINAL), L=3.0, beta=0.1, N=N, Gamma=0.16, Ts=0.02)
    return nets, mlps, tests, mpc, kw


def test_paired_units_fly_every_model_once_per_independent_unit():
    nets, mlps, tests, mpc, kw = _tiny_units()
    grid = paired_units(nets, mlps, tests=tests, mpc=mpc, model_settings=kw, adapnn_gamma=0.16)
    assert list(grid) == [*SIX, "AdapFNN"] and all(len(v) == 2 for v in grid.values())
    assert grid.units == ("network 0, MLP 0, disturbance 1", "network 1, MLP 1, disturbance 2")
    # nothing is copied: every model's unit flights are distinct flights, Nomi's included
    assert all(v[0] is not v[1] and not np.array_equal(v[0].x, v[1].x) for v in grid.values())
    assert grid.unit(1)["FNN"] is grid["FNN"][1]
    with pytest.raises(IndexError):
        grid.unit(2)
    # unit 1 is network 1, MLP 1 and test 1: as paper_models builds it (AdapNN at adapnn_gamma)
    again = paper_models(nets[1][1], mlps[1][1], **kw, adapnn_gamma=0.16)
    for m in again:
        assert np.array_equal(fly(m, mpc, tests[1]).x, grid.unit(1)[m.name].x), m.name
    assert not np.array_equal(fly(again[2], mpc, tests[0]).x, grid.unit(1)["MLP"].x)  # the test matters too
    some = paired_units(nets, mlps, tests=tests, mpc=mpc, model_settings=kw, adapnn_gamma=0.16, only=["FB", "AdapFNN"])
    assert list(some) == ["FB", "AdapFNN"] and np.array_equal(some["AdapFNN"][1].x, grid["AdapFNN"][1].x)
    with pytest.raises(ValueError, match="only must name"):
        paired_units(nets, mlps, tests=tests, mpc=mpc, model_settings=kw, adapnn_gamma=0.16, only=["FNN", "LSTM"])
    for bad in ((nets, mlps[:1], tests), (nets, mlps, tests[:1]), ([], [], [])):
        with pytest.raises(ValueError, match="one test per unit"):
            paired_units(bad[0], bad[1], tests=bad[2], mpc=mpc, model_settings=kw, adapnn_gamma=0.16)


def test_thrust_needed_is_hover_plus_the_references_peak_acceleration():
    hover_only = thrust_needed(TEST_TRUTH, {**PAPER_LISSAJOUS, "r_x": 0.0, "r_y": 0.0, "r_z": 0.0}, steps=10, Ts=0.02)
    assert hover_only["hover"] == pytest.approx(TEST_TRUTH.mass * TEST_TRUTH.g / 4)
    assert hover_only["peak"] == pytest.approx(hover_only["hover"])
    # y = r sin(2 pi t / T) alone peaks at r (2 pi / T)^2 sideways: the thrust is m sqrt(g^2 + a^2) / 4
    r, T = 3.0, 3.0
    side = thrust_needed(TEST_TRUTH, {**PAPER_LISSAJOUS, "r_x": 0.0, "r_y": r, "r_z": 0.0, "T_y": T}, steps=150, Ts=0.005)
    a = r * (2 * math.pi / T) ** 2
    assert side["peak"] == pytest.approx(TEST_TRUTH.mass * math.hypot(TEST_TRUTH.g, a) / 4, rel=1e-6)
    assert side["t_peak"] == pytest.approx(T / 4)
    paper = thrust_needed(TEST_TRUTH, PAPER_LISSAJOUS, steps=300, Ts=0.02)  # the paper's flight: above 4 N, below 6 N
    assert 4.0 < paper["peak"] < 6.0 and paper["hover"] < 4.0


def test_unjudged_bound_note_states_the_outcome_and_the_reason_with_the_numbers():
    from fnnbook.rules.quadrotor import unjudged_bound_note  # noqa: PLC0415 (the book's prose on these flights)

    rows = {n: flight_row(_result(seed=k)) for k, n in enumerate(("Nomi", "FNN"))}
    need = {"hover": 3.26, "peak": 5.53, "t_peak": 0.7}
    note = unjudged_bound_note(rows, metric="mean_axis", unit="m", need=need, u_max=4.0, setting="as written",
                               flown="one flight", compare=("FNN", "Nomi"))
    v = {n: r.mean_axis for n, r in rows.items()}
    assert f"Nomi {v['Nomi']:.2f}, FNN {v['FNN']:.2f} m" in note and "needs 5.53 N per motor" in note
    assert ("FNN worse than Nomi" in note) == (v["FNN"] > v["Nomi"]) and "no model can track" in note
    assert "not flown in this run" in unjudged_bound_note(None, metric="mean_axis", unit="m", need=need, u_max=4.0,
                                                          setting="as written", flown="-", compare=("FNN", "Nomi"))
    easy = unjudged_bound_note(rows, metric="mean_axis", unit="m", need={**need, "peak": 3.5}, u_max=4.0,
                               setting="as written", flown="one flight", compare=("FNN", "Nomi"))
    assert "no model can track" not in easy


def test_adapnn_gain_on_validation_flies_every_vehicle_on_every_reference() -> None:
    N, steps = 3, 4
    net, _, mpc = _tiny(steps, N)
    refs = [lissajous_reference(steps + 2, N, Ts=0.02, params=NOMINAL, curve={**PAPER_LISSAJOUS, "r_x": r})
            for r in (1.0, 2.0)]
    vehicles = randomized_vehicles(TRAINING_TRUTH, 2, seed=3, **VALIDATION_RANDOMIZATION)
    loop = dict(Ts=0.02, substeps=1, backend=Backend("torch", "forward"))
    sel = adapnn_gain_on_validation(net, [0.04, 0.16], refs, vehicles, mpc, steps=steps + 2, rtol=0.0, **loop)
    assert sel.value in (0.04, 0.16) and set(sel.table) == {0.04, 0.16}
    per_flight = sel.table[0.16]["rmse_per_flight"]
    assert len(per_flight) == 4 and len(set(per_flight)) == 4  # 2 vehicles x 2 references, all different
    # the order is vehicle, then reference; each entry is that vehicle flying that reference
    v, (x_v, u_v) = vehicles[1], refs[0]
    flown = fly(adapnn_model(net, 0.16, Ts=0.02), mpc, FlightTest(Quadrotor(v), x_v, u_v, steps=steps + 2, **loop))
    assert per_flight[2] == pytest.approx(flight_row(flown).mean_axis, rel=1e-12)
    assert sel.table[0.16]["rmse"] == pytest.approx(float(np.median(per_flight)))


def _settings(**changes) -> dict:
    """quadrotor_mpc's flight settings with tiny sizes (the names of its parameters cell)."""
    from fnnlib.quadrotor.presets import PAPER_MPC_WEIGHTS

    s = {"steps": 3, "N": 3, "Ts": 0.02, "truth_mass": TEST_TRUTH.mass, "truth_inertia": list(TEST_TRUTH.inertia),
         "truth_drag": list(TEST_TRUTH.drag), "disturbance": list(TEST_TRUTH.force_disturbance), "disturbance_draws": 1,
         "disturbance_seed": 11, "disturbance_spread": 0.5, "truth_substeps": 1, "backend": "torch",
         "linearize_method": "forward", "qp": "osqp", "Q": PAPER_MPC_WEIGHTS["Q"], "R": PAPER_MPC_WEIGHTS["R"],
         "theta_max": PAPER_THETA_MAX, "solver": "OSQP"}
    return {**s, **changes}


def test_flight_tests_build_the_test_vehicle_per_disturbance():
    s = _settings()
    setup = flight_tests(FlightSettings.of(s))
    assert setup.forces == disturbance_realisations(s["disturbance"], 1, seed=11, spread=0.5)
    assert len(setup.tests) == 2 and setup.vehicle == TEST_TRUTH
    assert [t.truth.params.force_disturbance for t in setup.tests] == setup.forces
    assert setup.paper_test is setup.tests[0] and setup.unit_tests == setup.tests[1:]
    assert setup.x_r.shape == (3 + 3 + 1, 12) and setup.tests[0].backend == Backend("torch", "forward")
    x_r, _ = lissajous_reference(3, 3, Ts=0.02, params=NOMINAL, curve=PAPER_LISSAJOUS)
    assert torch.equal(setup.x_r, x_r)
    assert flight_tests(FlightSettings.of(_settings(truth_mass=0.9))).tests[0].truth.params.mass == 0.9
    with pytest.raises(KeyError, match="truth_mass"):  # a record without a setting is refused, not defaulted
        FlightSettings.of({k: v for k, v in s.items() if k != "truth_mass"})
    assert MPCSettings.of(s) == MPCSettings("osqp", 3, s["Q"], s["R"], PAPER_THETA_MAX, "OSQP")


def test_fnn_flown_again_from_the_settings_is_the_paired_units_flight():
    """What the tuned-gains chapter relies on: its FNN flight, built from quadrotor_mpc's settings with the
    paper's gains, is bit for bit the FNN flight quadrotor_mpc flies (network k on unit test k)."""
    nets, mlps, _, _, _ = _tiny_units()
    s = _settings(disturbance_draws=2)
    setup = flight_tests(FlightSettings.of(s))
    kw = dict(plant=Quadrotor(NOMINAL), L=3.0, beta=0.1, N=s["N"], Gamma=0.16, Ts=s["Ts"])
    grid = paired_units(nets, mlps, tests=setup.unit_tests, mpc=MPCSettings.of(s).build(cost="as_flown", u_max=6.0),
                        model_settings=kw, adapnn_gamma=0.16)
    # as the tuned-gains chapter builds it: again from the settings, its own MPC, fnn_model
    again_tests = flight_tests(FlightSettings.of(dict(s))).unit_tests
    mpc = MPCSettings.of(s).build(cost="as_flown", u_max=6.0)
    for k, ((_, net), test) in enumerate(zip(nets, again_tests)):
        again = fly(fnn_model(net, 3.0, 0.1, plant=Quadrotor(NOMINAL), N=s["N"], Ts=s["Ts"]), mpc, test)
        flown = grid.unit(k)["FNN"]
        assert np.array_equal(again.x, flown.x) and flight_row(again).mean_axis == flight_row(flown).mean_axis
    # and the check can fail: other settings fly another flight
    other = flight_tests(FlightSettings.of(_settings(truth_mass=0.9, disturbance_draws=2))).unit_tests[0]
    moved = fly(fnn_model(nets[0][1], 3.0, 0.1, plant=Quadrotor(NOMINAL), N=s["N"], Ts=s["Ts"]), mpc, other)
    assert not np.array_equal(moved.x, grid.unit(0)["FNN"].x)


def test_flown_and_hand_gain_sweeps_keep_the_grid_pair_of_least_error():
    """The flown sweep scores each (L, beta) by the mean tracking RMSE of FNN's flights; the hand sweep by the
    N-step position error of the cascade along recorded flights, which the flights of a unit provide."""
    from fnnlib.quadrotor.mpc.experiment import flown_gain_sweep, hand_gains_on_flights
    from fnnlib.quadrotor.mpc.flight import tracking_rmse
    from fnnlib.quadrotor.mpc.models import PredictionModel

    nets, _, tests, mpc, kw = _tiny_units()
    net = nets[0][1]
    sweep = flown_gain_sweep(net, tests, mpc, L_grid=[1.0, 3.0], beta_grid=[0.1], plant=kw["plant"], N=3, Ts=0.02)
    want = [[float(np.mean([tracking_rmse(r.x, r.x_ref)["mean_axis"] for r in
                            (fly(fnn_model(net, L, 0.1, plant=kw["plant"], N=3, Ts=0.02), mpc, t) for t in tests)]))]
             for L in (1.0, 3.0)]
    assert sweep.table == want and sweep.cost == min(w[0] for w in want)
    flown = fly(fnn_model(net, 3.0, 0.1, plant=kw["plant"], N=3, Ts=0.02), mpc, tests[0])
    x = torch.as_tensor(flown.x[None, :-1], dtype=torch.float64)  # (1, T, 12), the thrusts (1, T, 4)
    u = torch.as_tensor(flown.u[None], dtype=torch.float64)
    neural = PredictionModel("Neural", kw["plant"], net, Ts=0.02)
    hand = hand_gains_on_flights(neural, x, u, 0.02, 1, [1.0, 3.0], [0.0, 0.1])
    assert np.isfinite(hand.table).all() and hand.cost == min(min(r) for r in hand.table)
