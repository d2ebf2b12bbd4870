"""Minimum-snap reference flights (App. A.5.4): waypoints, rest, smoothness, optimality, seeded draws, checks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import null_space

from fnnlib.quadrotor.control.min_snap import (
    MinSnapFlights,
    MinSnapTrajectory,
    allocate_times,
    min_snap,
    random_min_snap_flights,
    random_waypoints,
)
from fnnlib.quadrotor.presets import PAPER_FLIGHT_DATA, PAPER_WAYPOINT_BOX

DRAW = {k: PAPER_FLIGHT_DATA[k] for k in ("n_waypoints", "box", "max_speed")}


def flights(n_flights: int, n_nodes: int, Ts: float, **changes: object) -> MinSnapFlights:
    """The release's random flights (3 waypoints, its box, <= 10 m/s), some settings changed."""
    return random_min_snap_flights(n_flights, n_nodes, Ts=Ts, **{**DRAW, **changes})  # type: ignore[arg-type]



def _random_problem(seed: int, n_segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Waypoints in the default box and uneven durations in [0.3, 2.5] s."""
    rng = np.random.default_rng(seed)
    W = random_waypoints(n_segments + 1, rng, box=PAPER_WAYPOINT_BOX)
    t = np.concatenate([[rng.uniform(-1.0, 1.0)], rng.uniform(0.3, 2.5, n_segments)]).cumsum()
    return W, t


# --------------------------------------------------------------------------- independent checks


def _snap_cost_by_quadrature(traj: MinSnapTrajectory) -> float:
    """int |p''''|^2 dt summed over axes, by 8-point Gauss-Legendre per piece (exact for degree 6)."""
    x, w = np.polynomial.legendre.leggauss(8)
    total = 0.0
    for k in range(traj.n_segments):
        a, b = traj.times[k], traj.times[k + 1]
        tau = 0.5 * (x + 1.0)
        s = traj.evaluate_segment(k, tau, 4)
        total += 0.5 * (b - a) * float(np.sum(w[:, None] * s**2))
    return total


def _constraint_matrix(times: np.ndarray) -> np.ndarray:
    """Linear functionals of one axis' coefficients that a feasible perturbation must zero.

    Built by evaluating unit-coefficient trajectories, not from the library's
    own constraint rows: positions at both ends of every piece; v, a, j at the
    first and last knot; jumps of derivatives 1..4 at interior knots.
    """
    K = times.size - 1
    cols = []
    for k in range(K):
        for i in range(8):
            c = np.zeros((K, 8, 3))
            c[k, i, :] = 1.0
            tr = MinSnapTrajectory(times, c)
            f = []
            for kk in range(K):
                f += [tr.evaluate_segment(kk, [0.0])[0, 0], tr.evaluate_segment(kk, [1.0])[0, 0]]
            for r in (1, 2, 3):
                f += [tr.evaluate_segment(0, [0.0], r)[0, 0], tr.evaluate_segment(K - 1, [1.0], r)[0, 0]]
            for kk in range(K - 1):
                for r in (1, 2, 3, 4):
                    jump = tr.evaluate_segment(kk, [1.0], r) - tr.evaluate_segment(kk + 1, [0.0], r)
                    f.append(jump[0, 0])
            cols.append(f)
    return np.array(cols).T  # (n_constraints, 8K)


def _first_order_gain(traj: MinSnapTrajectory, n_trials: int, seed: int) -> list[tuple[float, float]]:
    """For random feasible perturbations d: (J(c + d) - J(c), J(c + d) - 2 J(c) + J(c - d)) / 2, relative to J(c)."""
    K = traj.n_segments
    N = null_space(_constraint_matrix(traj.times))  # (8K, dim)
    assert N.shape[1] == 2 * K - 2  # 8K unknowns, 2K + 6 + 4(K - 1) independent constraints
    rng = np.random.default_rng(seed)
    J0 = _snap_cost_by_quadrature(traj)
    out = []
    for _ in range(n_trials):
        d = (N @ rng.standard_normal((N.shape[1], 3))).reshape(K, 8, 3)
        dJ = _snap_cost_by_quadrature(MinSnapTrajectory(traj.times, d))
        eps = 10.0 ** rng.uniform(-4, 0) * np.sqrt(J0 / dJ)  # perturbation cost eps^2 dJ in [1e-8, 1] J0
        Jp = _snap_cost_by_quadrature(MinSnapTrajectory(traj.times, traj.coefficients + eps * d))
        Jm = _snap_cost_by_quadrature(MinSnapTrajectory(traj.times, traj.coefficients - eps * d))
        out.append(((Jp - J0) / J0, (Jm - J0) / J0))
    return out


# --------------------------------------------------------------------------- minimum snap


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_segments=st.integers(1, 5))
def test_passes_through_waypoints_at_rest_and_is_smooth(seed: int, n_segments: int) -> None:
    W, t = _random_problem(seed, n_segments)
    tr = min_snap(W, t)
    np.testing.assert_allclose(tr.evaluate(t), W, rtol=0, atol=1e-9)
    np.testing.assert_allclose(tr.waypoints, W, rtol=0, atol=1e-9)
    # rest at both ends: v = a = j = 0 (scale: the largest value over the flight)
    dense = np.linspace(t[0], t[-1], 401)
    for r in (1, 2, 3):
        scale = np.abs(tr.evaluate(dense, r)).max()
        ends = tr.evaluate(t[[0, -1]], r)
        assert np.abs(ends).max() <= 1e-9 * scale, (r, ends)
    # p, v, a, j, snap continuous at every interior waypoint: left limit == right limit
    for r in range(5):
        scale = np.abs(tr.evaluate(dense, r)).max()
        for k in range(n_segments - 1):
            left = tr.evaluate_segment(k, [1.0], r)
            right = tr.evaluate_segment(k + 1, [0.0], r)
            assert np.abs(left - right).max() <= 1e-6 * scale, (k, r, left, right)


def test_min_snap_optimum_is_c6_though_only_c4_is_imposed() -> None:
    # Euler-Lagrange natural conditions: free derivatives 5 and 6 come out continuous,
    # so imposing continuity up to 3, 4, 5 or 6 gives the same trajectory.
    W, t = _random_problem(3, 4)
    ref = min_snap(W, t, continuity=4)
    dense = np.linspace(t[0], t[-1], 401)
    for r in (5, 6):
        scale = np.abs(ref.evaluate(dense, r)).max()
        for k in range(3):
            jump = ref.evaluate_segment(k, [1.0], r) - ref.evaluate_segment(k + 1, [0.0], r)
            assert np.abs(jump).max() <= 1e-6 * scale
    for m in (3, 5, 6):
        other = min_snap(W, t, continuity=m)
        for r in range(5):
            a, b = ref.evaluate(dense, r), other.evaluate(dense, r)
            assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max(), (m, r)


@pytest.mark.parametrize("seed, n_segments", [(0, 2), (1, 3), (2, 5)])
def test_no_feasible_perturbation_lowers_the_snap_cost(seed: int, n_segments: int) -> None:
    W, t = _random_problem(seed, n_segments)
    tr = min_snap(W, t)
    for up, down in _first_order_gain(tr, n_trials=20, seed=seed + 100):
        assert up >= -1e-12 and down >= -1e-12, (up, down)
        # at the optimum the gradient along feasible directions vanishes: J(c + d) == J(c - d)
        assert abs(up - down) <= 1e-7 * max(up, 1e-6), (up, down)


def test_the_optimality_check_catches_a_suboptimal_trajectory() -> None:
    # Shift the optimum along one feasible direction: still feasible, no longer optimal.
    W, t = _random_problem(0, 3)
    tr = min_snap(W, t)
    N = null_space(_constraint_matrix(t))
    d = (N[:, [0, 0, 0]]).reshape(3, 8, 3)
    scale = np.sqrt(_snap_cost_by_quadrature(tr) / _snap_cost_by_quadrature(MinSnapTrajectory(t, d)))
    bad = MinSnapTrajectory(t, tr.coefficients + 0.3 * scale * d)
    gains = _first_order_gain(bad, n_trials=20, seed=7)
    assert min(min(g) for g in gains) < -1e-6


def test_snap_cost_closed_form_matches_quadrature() -> None:
    W, t = _random_problem(5, 3)
    tr = min_snap(W, t)
    assert tr.snap_cost().shape == (3,)
    np.testing.assert_allclose(tr.snap_cost().sum(), _snap_cost_by_quadrature(tr), rtol=1e-10)


def test_two_waypoints_give_the_rest_to_rest_septic() -> None:
    W = np.array([[0.5, -1.0, 2.0], [-2.5, 1.0, -0.5]])
    t0, T = 1.5, 2.5
    tr = min_snap(W, [t0, t0 + T])
    t = np.linspace(t0, t0 + T, 57)
    s = ((t - t0) / T)[:, None]
    dW = W[1] - W[0]
    shape = [
        35 * s**4 - 84 * s**5 + 70 * s**6 - 20 * s**7,
        (140 * s**3 - 420 * s**4 + 420 * s**5 - 140 * s**6) / T,
        (420 * s**2 - 1680 * s**3 + 2100 * s**4 - 840 * s**5) / T**2,
        (840 * s - 5040 * s**2 + 8400 * s**3 - 4200 * s**4) / T**3,
        (840 - 10080 * s + 25200 * s**2 - 16800 * s**3) / T**4,
    ]
    np.testing.assert_allclose(tr.evaluate(t, 0), W[0] + dW * shape[0], rtol=0, atol=1e-12)
    for r in range(1, 5):
        np.testing.assert_allclose(tr.evaluate(t, r), dW * shape[r], rtol=0, atol=1e-9 * np.abs(dW * shape[r]).max())
    # peak speed of the septic: 35/16 |dW| / T at the midpoint
    v = np.linalg.norm(tr.evaluate(np.linspace(t0, t0 + T, 1001), 1), axis=1)
    assert v.max() == pytest.approx(35 / 16 * np.linalg.norm(dW) / T, rel=1e-9)


def test_flat_outputs_and_snap_sample_the_polynomial_on_the_node_grid() -> None:
    W, t = _random_problem(4, 2)
    tr = min_snap(W, t)
    Ts = 0.02
    n = int(np.floor((t[-1] - t[0]) / Ts)) + 1
    psi = tr.flat_outputs(Ts, n)
    nodes = t[0] + Ts * np.arange(n)
    assert psi.shape == (n, 12) and psi.dtype == np.float64
    for r in range(4):
        np.testing.assert_array_equal(psi[:, 3 * r : 3 * r + 3], tr.evaluate(nodes, r))
    np.testing.assert_array_equal(tr.snap(Ts, n), tr.evaluate(nodes, 4))
    # velocity is the derivative of position (central differences on a fine grid)
    tt = np.linspace(t[0] + 0.01, t[-1] - 0.01, 50)
    eps = 1e-5
    fd = (tr.evaluate(tt + eps) - tr.evaluate(tt - eps)) / (2 * eps)
    np.testing.assert_allclose(fd, tr.evaluate(tt, 1), atol=1e-6 * np.abs(fd).max())


def test_distance_allocation_is_proportional_to_segment_length() -> None:
    W = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 3.0, 0.0]])
    np.testing.assert_allclose(allocate_times(W, 4.0, allocation="distance", t0=1.0), [1.0, 2.0, 5.0])
    np.testing.assert_allclose(allocate_times(W, 4.0), [0.0, 2.0, 4.0])


# --------------------------------------------------------------------------- random flights


def test_random_flights_are_seeded_feasible_and_in_the_box() -> None:
    n_f, n, Ts = 6, 200, 0.02
    a = flights(n_f, n, Ts, seed=11)
    b = flights(n_f, n, Ts, seed=11)
    c = flights(n_f, n, Ts, seed=12)
    assert a.psi.shape == (n_f, n, 12) and a.snap.shape == (n_f, n, 3)
    assert len(a.waypoints) == n_f and all(w.shape == (3, 3) for w in a.waypoints)
    np.testing.assert_array_equal(a.psi, b.psi)
    np.testing.assert_array_equal(a.snap, b.snap)
    assert not np.allclose(a.psi, c.psi)
    box = np.array(PAPER_WAYPOINT_BOX)
    for psi, W in zip(a.psi, a.waypoints):
        assert np.all(W >= box[:, 0]) and np.all(W <= box[:, 1])
        np.testing.assert_allclose(psi[0, :3], W[0], atol=1e-9)
        np.testing.assert_allclose(psi[-1, :3], W[-1], atol=1e-9)  # last node at (n - 1) Ts = t_K
        np.testing.assert_allclose(psi[[0, -1], 3:], 0.0, atol=1e-9)  # rest at both ends
    assert np.linalg.norm(a.psi[..., 3:6], axis=-1).max() <= 10.0


def test_fast_flights_are_redrawn() -> None:
    loose = flights(8, 200, 0.02, seed=0)
    tight = flights(8, 200, 0.02, seed=0, max_speed=4.0)
    speed = np.linalg.norm(loose.psi[..., 3:6], axis=-1).max(axis=1)
    assert speed.max() > 4.0  # some draw needs rejecting, else the test proves nothing
    assert np.linalg.norm(tight.psi[..., 3:6], axis=-1).max() <= 4.0
    with pytest.raises(RuntimeError, match="max_speed"):
        flights(1, 200, 0.02, seed=0, max_speed=0.01, max_tries=5)


def test_random_waypoints_respect_a_custom_box() -> None:
    box = ((1.0, 2.0), (-5.0, -4.0), (0.0, 0.1))
    W = random_waypoints(500, np.random.default_rng(0), box=box)
    assert W.shape == (500, 3)
    lo, hi = np.array(box).T
    assert np.all(W >= lo) and np.all(W <= hi)
    assert np.all(W.max(0) - W.min(0) > 0.9 * (hi - lo))  # fills the box


def test_progress_bar_is_optional(capsys: pytest.CaptureFixture[str]) -> None:
    flights(2, 50, 0.02, seed=0)
    assert capsys.readouterr().err == ""
    flights(2, 50, 0.02, seed=0, progress=True)
    assert "min-snap flights" in capsys.readouterr().err


# --------------------------------------------------------------------------- bad input


def test_min_snap_refuses_bad_input() -> None:
    W = np.zeros((3, 3))
    with pytest.raises(ValueError, match="strictly increasing"):
        min_snap(W, [0.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="at least 2 waypoints"):
        min_snap(np.zeros((1, 3)), [0.0])
    with pytest.raises(ValueError, match="NaN"):
        min_snap(np.array([[0.0, 0.0, 0.0], [1.0, np.nan, 0.0]]), [0.0, 1.0])
    with pytest.raises(ValueError, match=r"shape \(n_waypoints, 3\)"):
        min_snap(np.zeros((3, 2)), [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="must match"):
        min_snap(W, [0.0, 1.0])
    with pytest.raises(ValueError, match="continuity"):
        min_snap(W, [0.0, 1.0, 2.0], continuity=7)
    with pytest.raises(TypeError, match="real numbers"):
        min_snap([["a", "b", "c"], ["d", "e", "f"]], [0.0, 1.0])
    with pytest.raises(ValueError, match="shape"):
        MinSnapTrajectory(np.array([0.0, 1.0]), np.zeros((2, 8, 3)))


def test_sampling_refuses_bad_input() -> None:
    tr = min_snap(np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]), [0.0, 1.0])
    with pytest.raises(ValueError, match="Ts must be a finite positive"):
        tr.flat_outputs(0.0, 10)
    with pytest.raises(ValueError, match="Ts must be a finite positive"):
        tr.snap(-0.1, 10)
    with pytest.raises(ValueError, match="exceeds the trajectory duration"):
        tr.flat_outputs(0.02, 52)
    assert tr.flat_outputs(0.02, 51).shape == (51, 12)  # 50 * 0.02 == 1.0 up to round-off
    with pytest.raises(ValueError, match=r"t must lie in \[t_0, t_K\]"):
        tr.evaluate([0.5, 1.5])
    with pytest.raises(ValueError, match="order must be in 0..7"):
        tr.evaluate([0.5], 8)
    with pytest.raises(TypeError, match="n_nodes must be an int"):
        tr.flat_outputs(0.02, 10.0)  # type: ignore[arg-type]


def test_generators_refuse_bad_input() -> None:
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="n_waypoints must be >= 2"):
        random_waypoints(1, rng, box=PAPER_WAYPOINT_BOX)
    with pytest.raises(TypeError, match="numpy.random.Generator"):
        random_waypoints(3, 0, box=PAPER_WAYPOINT_BOX)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="lo < hi"):
        random_waypoints(3, rng, box=((1.0, -1.0), (0.0, 1.0), (0.0, 1.0)))
    with pytest.raises(ValueError, match="box must have shape"):
        random_waypoints(3, rng, box=((0.0, 1.0), (0.0, 1.0)))
    with pytest.raises(ValueError, match="Ts must be a finite positive"):
        flights(2, 200, 0.0, seed=0)
    with pytest.raises(ValueError, match="n_nodes must be >= 2"):
        flights(2, 1, 0.02, seed=0)
    with pytest.raises(ValueError, match="allocation"):
        flights(2, 200, 0.02, seed=0, allocation="uniform")  # type: ignore[arg-type]
