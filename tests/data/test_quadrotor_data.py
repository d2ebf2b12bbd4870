"""Quadrotor flight data (Sec. 5.2, App. A.5.2): generation, single-step labels, saving and refusing bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from fnnlib.quadrotor.control.dfbc import DFBC
from fnnlib.quadrotor.control.min_snap import random_min_snap_flights
from fnnlib.data.bottle import DataError
from fnnlib.data.quadrotor import Flights, load_flights, make_flights, save_flights, single_step_labels
from fnnlib.quadrotor.presets import PAPER_DFBC_GAINS, PAPER_FLIGHT_DATA, PAPER_TS
from fnnlib.quadrotor.system import NOMINAL, TRAINING_TRUTH, Quadrotor

F64 = torch.float64
#: the release's flights (0.02 s, DFBC on the nominal model); tests change some settings
PAPER = {"Ts": PAPER_TS, "controller": DFBC(NOMINAL, **PAPER_DFBC_GAINS), **PAPER_FLIGHT_DATA}


@pytest.fixture(scope="module")
def flights() -> Flights:
    return make_flights(3, 30, **{**PAPER, "seed": 0, "truth": TRAINING_TRUTH})


# --------------------------------------------------------------------------- make_flights


def test_shapes_and_dtype(flights):
    assert flights.x.shape == (3, 31, 18) and flights.Psi.shape == (3, 30, 12) and flights.u.shape == (3, 30, 4)
    assert flights.x.dtype == flights.Psi.dtype == flights.u.dtype == F64
    assert flights.Ts == 0.02 and flights.n_flights == 3 and flights.n_steps == 30
    assert all(bool(torch.isfinite(getattr(flights, k)).all()) for k in ("x", "Psi", "u"))


def test_commands_are_the_seeded_min_snap_flights_and_start_at_rest(flights):
    ref = random_min_snap_flights(3, 30, Ts=0.02, seed=0, n_waypoints=3, box=PAPER["box"], max_speed=PAPER["max_speed"])
    assert torch.equal(flights.Psi, torch.as_tensor(ref.psi))
    # starts at rest on its first waypoint, controller states zero
    first_waypoints = torch.as_tensor(np.stack([w[0] for w in ref.waypoints]), dtype=F64)
    torch.testing.assert_close(flights.x[:, 0, :3], first_waypoints, rtol=0, atol=1e-12)
    assert torch.equal(flights.x[:, 0, :3], flights.Psi[:, 0, :3])
    assert torch.equal(flights.x[:, 0, 3:], torch.zeros(3, 15, dtype=F64))
    assert float(flights.Psi[:, 0, 3:].abs().max()) < 1e-9  # the command starts at rest too (min-snap solve)


def test_records_the_dfbc_flying_the_truth(flights):
    # one step re-flown by hand: the DFBC (nominal model) on the drag truth, RK4 with 4 sub-steps
    ctrl = DFBC(NOMINAL, **PAPER_DFBC_GAINS)
    for i in (0, 10, 20):
        x1 = ctrl.closed_loop_step(flights.x[:, i], flights.Psi[:, i], Quadrotor(TRAINING_TRUTH), Ts=0.02, substeps=4)
        torch.testing.assert_close(flights.x[:, i + 1], x1, rtol=1e-12, atol=1e-12)
    x1_nominal = ctrl.closed_loop_step(flights.x[:, 5], flights.Psi[:, 5], Quadrotor(NOMINAL), Ts=0.02, substeps=4)
    assert (flights.x[:, 6] - x1_nominal).abs().max() > 1e-6  # the drag is there
    u0, _ = ctrl.control(flights.x[:, 7, :12], flights.x[:, 7, 12:], flights.Psi[:, 7])
    torch.testing.assert_close(flights.u[:, 7], u0, rtol=0, atol=1e-12)


def test_deterministic_per_seed():
    kw = {**PAPER, "Ts": 0.05, "n_waypoints": 2, "truth": TRAINING_TRUTH}
    a, b, c = make_flights(2, 12, seed=3, **kw), make_flights(2, 12, seed=3, **kw), make_flights(2, 12, seed=4, **kw)
    for k in ("x", "Psi", "u"):
        assert torch.equal(getattr(a, k), getattr(b, k))
        assert not torch.equal(getattr(a, k), getattr(c, k))
    assert a.Ts == 0.05


def test_make_flights_checks():
    with pytest.raises(ValueError, match="n_flights"):
        make_flights(0, 30, **{**PAPER, "seed": 0, "truth": NOMINAL})
    with pytest.raises(ValueError, match="n_nodes"):
        make_flights(2, 1, **{**PAPER, "seed": 0, "truth": NOMINAL})
    with pytest.raises(TypeError, match="truth must be a QuadrotorParams"):
        make_flights(2, 30, **{**PAPER, "seed": 0, "truth": Quadrotor(NOMINAL)})
    with pytest.raises(TypeError, match="controller must be a DFBC"):
        make_flights(2, 30, **{**PAPER, "seed": 0, "truth": NOMINAL, "controller": None})


def test_flights_refuse_inconsistent_or_nonfinite_arrays():
    x, Psi, u = torch.zeros(2, 6, 18, dtype=F64), torch.zeros(2, 5, 12, dtype=F64), torch.zeros(2, 5, 4, dtype=F64)
    Flights(x=x, Psi=Psi, u=u, Ts=0.02)
    with pytest.raises(DataError, match="inconsistent"):
        Flights(x=x, Psi=Psi[:, :4], u=u, Ts=0.02)
    with pytest.raises(DataError, match="inconsistent"):
        Flights(x=x[..., :12], Psi=Psi, u=u, Ts=0.02)
    bad = u.clone()
    bad[1, 2, 3] = float("nan")
    with pytest.raises(DataError, match="u holds NaN"):
        Flights(x=x, Psi=Psi, u=bad, Ts=0.02)


# --------------------------------------------------------------------------- single_step_labels


def test_labels_are_the_drag_up_to_the_finite_difference_error():
    """Truth with drag, nominal model without: label_i = (v_{i+1} - v_i)/dt - a_nom(x_i, u_i) ~ -R D R^T v_i.

    The forward difference is the mean of v' over the step, so label_i - drag(x_i) = (Ts/2) a'(t_i) + O(dt^2)
    with a' the time derivative of the true acceleration along the truth's vector field. The tolerance is that
    first-order term plus a second-order remainder of 2 Ts^2 (measured: 1.2 Ts^2); a misaligned input (u_{i+1})
    or a missing model term is off by > 1 m/s^2. Inputs are held per step and differ between steps, so an index
    slip shows. (Hand-made open-loop data: make_flights' short flights are too violent for a tight bound.)
    """
    truth, Ts, K, T = Quadrotor(TRAINING_TRUTH), 0.02, 2, 40
    g = torch.Generator().manual_seed(0)
    x0 = torch.zeros(K, 12, dtype=F64)
    x0[:, 3:6] = torch.tensor([[3.0, -2.0, 1.0], [-1.0, 4.0, -0.5]])
    x0[:, 6:9] = torch.tensor([[0.1, -0.05, 0.2], [-0.15, 0.1, -0.3]])
    x0[:, 9:12] = torch.tensor([[0.3, -0.2, 0.1], [0.0, 0.2, -0.1]])
    common = 1 + 0.2 * (torch.rand(K, T, 1, generator=g, dtype=F64) - 0.5)
    u = truth.hover_input() * common + 0.01 * (torch.rand(K, T, 4, generator=g, dtype=F64) - 0.5)
    X = truth.rollout(x0, u, Ts=Ts, substeps=4)
    data = Flights(x=torch.cat([X, torch.zeros(K, T + 1, 6, dtype=F64)], -1), Psi=torch.zeros(K, T, 12, dtype=F64),
                   u=u, Ts=Ts)

    xs, labels = single_step_labels(data, Quadrotor(NOMINAL))
    assert xs.shape == (K * T, 12) and labels.shape == (K * T, 3)
    torch.testing.assert_close(xs, X[:, :-1].reshape(-1, 12), rtol=0, atol=0)
    us = u.reshape(-1, 4)
    drag = truth.drag_acceleration(xs)
    # a' = (d a / d x) x' along the truth (u held), by a central difference: error ~1e-10, far below 2 dt^2
    h, x_dot = 1e-5, truth.f(xs, us)
    a_dot = (truth.f(xs + h * x_dot, us)[:, 3:6] - truth.f(xs - h * x_dot, us)[:, 3:6]) / (2 * h)
    err = labels - drag
    first_order = 0.5 * Ts * a_dot
    assert float((err - first_order).norm(dim=-1).max()) <= 2 * Ts**2
    assert bool((err.norm(dim=-1) <= first_order.norm(dim=-1) + 2 * Ts**2).all())
    # not vacuous: the drag is large against that error (rms drag ~2 m/s^2, error < 0.04 m/s^2)
    assert float(drag.norm(dim=-1).min()) > 20 * float(err.norm(dim=-1).max())


# --------------------------------------------------------------------------- save / load


def test_round_trip(flights, tmp_path):
    path = save_flights(tmp_path / "sub" / "f.npz", flights, {"seed": 0, "drag": [0.7, 0.7, 0.2]})
    assert path.is_file() and sorted(p.name for p in path.parent.iterdir()) == ["f.npz"]  # no temp file left
    back, meta = load_flights(path)
    assert meta == {"seed": 0, "drag": [0.7, 0.7, 0.2]}
    for k in ("x", "Psi", "u"):
        assert torch.equal(getattr(back, k), getattr(flights, k))
        assert getattr(back, k).dtype == F64
    assert back.Ts == flights.Ts
    _, meta = load_flights(save_flights(tmp_path / "g.npz", flights))
    assert meta == {}


def test_flipped_bytes_are_refused(flights, tmp_path):
    path = save_flights(tmp_path / "f.npz", flights)
    raw = bytearray(path.read_bytes())
    start = raw.find(flights.x.numpy().tobytes()[:64])  # inside the stored array x
    assert start > 0
    for i in range(start + 800, start + 808):
        raw[i] ^= 0xFF
    path.write_bytes(bytes(raw))
    with pytest.raises(DataError, match="corrupt"):
        load_flights(path)


def test_modified_array_with_the_old_header_is_refused(flights, tmp_path):
    path = save_flights(tmp_path / "f.npz", flights)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["u"] = arrays["u"].copy()
    arrays["u"][0, 0, 0] += 1e-9  # a tiny change, same shapes
    np.savez(path, **arrays)
    with pytest.raises(DataError, match="checksum"):
        load_flights(path)


def test_missing_and_foreign_files_are_refused(flights, tmp_path):
    with pytest.raises(DataError, match="does not exist"):
        load_flights(tmp_path / "nope.npz")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(DataError, match="not an fnnlib flight file"):
        load_flights(tmp_path / "other.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(DataError, match="corrupt"):
        load_flights(tmp_path / "text.npz")
    # a checksum that matches but arrays that do not fit together are refused too
    x = flights.x.numpy()[:, :-2]
    arrays = {"x": x, "Psi": flights.Psi.numpy(), "u": flights.u.numpy(), "dt": np.asarray(0.02)}
    from fnnlib.data.quadrotor import _digest

    np.savez(tmp_path / "bad.npz", header=np.asarray(json.dumps({"sha256": _digest(arrays), "meta": {}})), **arrays)
    with pytest.raises(DataError, match="inconsistent"):
        load_flights(tmp_path / "bad.npz")
