"""The QP of Eq. (28): LQR agreement, constraints, fresh parameters, fallback and input checks."""

from __future__ import annotations

import control
import numpy as np
import pytest

from fnnlib.quadrotor.mpc import LinearizedMPC, MPCSolution, OSQPMPC, RebuildMPC, shift_plan

DT = 0.1
A_DI = np.array([[1.0, DT], [0.0, 1.0]])  # discretised double integrator
B_DI = np.array([[DT * DT / 2], [DT]])
Q_DI = np.array([1.0, 0.1])
R_DI = np.array([0.01])
TIGHT = {"eps_abs": 1e-10, "eps_rel": 1e-10, "solver_options": {"polishing": True}}
TIGHT_CLARABEL = {"solver": "CLARABEL", "eps_abs": 1e-10, "eps_rel": 1e-10}


def lti(N: int, A: np.ndarray = A_DI, B: np.ndarray = B_DI) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.repeat(A[None], N, 0), np.repeat(B[None], N, 0), np.zeros((N, A.shape[0]))


# --- agreement with the infinite-horizon LQR -------------------------------------------------------------------

@pytest.mark.parametrize("N", [1, 4, 10])
@pytest.mark.parametrize("options", [TIGHT, TIGHT_CLARABEL], ids=["osqp", "clarabel"])
def test_terminal_dare_weight_gives_the_lqr_input(N: int, options: dict) -> None:
    K, P, _ = control.dlqr(A_DI, B_DI, np.diag(Q_DI), np.diag(R_DI))
    huge = 1e6 * np.ones(1)
    mpc = LinearizedMPC(N, Q_DI, R_DI, cost="as_written", Q_N=P, u_lb=-huge, u_ub=huge, **options)
    A, B, c = lti(N)
    for x0 in ([1.0, 0.0], [-0.3, 2.0], [2.5, -1.5]):
        sol = mpc.solve(np.array(x0), A, B, c, np.zeros(2), np.zeros(1))
        assert sol.ok and not sol.fallback
        np.testing.assert_allclose(sol.u[0], -K @ np.array(x0), rtol=1e-5)


def test_rebuild_agrees_with_the_lqr_input_too() -> None:
    K, P, _ = control.dlqr(A_DI, B_DI, np.diag(Q_DI), np.diag(R_DI))
    x0 = np.array([0.7, -0.4])
    sol = RebuildMPC(6, Q_DI, R_DI, cost="as_written", Q_N=P, **TIGHT).solve(x0, *lti(6), [0.0, 0.0], [0.0])
    np.testing.assert_allclose(sol.u[0], -K @ x0, rtol=1e-5)


def test_solution_is_consistent_with_the_dynamics_and_a_moving_reference() -> None:
    rng = np.random.default_rng(0)
    N, n, m = 5, 3, 2
    A = np.eye(n) + 0.1 * rng.normal(size=(N, n, n))
    B, c = rng.normal(size=(N, n, m)), rng.normal(size=(N, n))
    x0, x_r, u_r = rng.normal(size=n), rng.normal(size=(N, n)), rng.normal(size=(N, m))
    sol = LinearizedMPC(N, np.ones(n), np.ones(m), cost="as_written", **TIGHT).solve(x0, A, B, c, x_r, u_r)
    assert sol.x.shape == (N + 1, n) and sol.u.shape == (N, m)
    np.testing.assert_array_equal(sol.x[0], x0)
    for k in range(N):
        np.testing.assert_allclose(sol.x[k + 1], A[k] @ sol.x[k] + B[k] @ sol.u[k] + c[k], atol=1e-8)
    # and the same optimum as an independent solver on a freshly built problem
    ref = RebuildMPC(N, np.ones(n), np.ones(m), cost="as_written", **TIGHT_CLARABEL).solve(x0, A, B, c, x_r, u_r)
    np.testing.assert_allclose(sol.u, ref.u, atol=1e-6)


# --- constraints ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("solver", ["OSQP", "CLARABEL"])
def test_input_box_is_respected_when_the_unconstrained_optimum_violates_it(solver: str) -> None:
    N, x0 = 10, np.array([5.0, 0.0])
    free = LinearizedMPC(N, Q_DI, R_DI, cost="as_written", solver=solver).solve(x0, *lti(N), [0.0, 0.0], [0.0])
    assert np.abs(free.u).max() > 5.0  # the box below is active
    sol = LinearizedMPC(N, Q_DI, R_DI, cost="as_written", u_lb=[-1.0], u_ub=[1.0], solver=solver).solve(
        x0, *lti(N), [0.0, 0.0], [0.0])
    assert sol.ok
    assert sol.u.min() >= -1.0 - 1e-4 and sol.u.max() <= 1.0 + 1e-4
    assert np.isclose(sol.u[0, 0], -1.0, atol=1e-4)


def test_state_box_only_on_finite_indices() -> None:
    N, x0, R = 8, np.array([0.0, 1.5]), [1.0]
    kw = {"u_lb": [-4.0], "u_ub": [4.0], **TIGHT}
    free = LinearizedMPC(N, Q_DI, R, cost="as_written", **kw).solve(x0, *lti(N), [0.0, 0.0], [0.0])
    assert free.x[1:, 0].max() > 1.0
    box = LinearizedMPC(N, Q_DI, R, cost="as_written", x_lb=[-np.inf, -np.inf], x_ub=[0.5, np.inf], **kw)
    sol = box.solve(x0, *lti(N), [0.0, 0.0], [0.0])
    assert sol.ok and sol.x[1:, 0].max() <= 0.5 + 1e-6
    assert np.isclose(sol.x[1:, 0].max(), 0.5, atol=1e-6)  # active
    assert sol.x[1:, 1].max() > 1.0  # the infinite bound on the velocity made no constraint


# --- parameters are refreshed ----------------------------------------------------------------------------------------

def test_problem_is_dpp_and_resolves_with_fresh_parameters() -> None:
    rng = np.random.default_rng(4)
    N, n, m = 4, 3, 2
    kw = {"u_lb": -np.ones(m), "u_ub": np.ones(m), "x_lb": [-2.0, -np.inf, -np.inf], "x_ub": [2.0, np.inf, np.inf]}
    mpc = LinearizedMPC(N, [1.0, 2.0, 3.0], [1.0, 0.5], cost="as_written", **kw, **TIGHT)
    ref = RebuildMPC(N, [1.0, 2.0, 3.0], [1.0, 0.5], cost="as_written", **kw, **TIGHT_CLARABEL)
    assert mpc.problem.is_dpp()
    sparse_A = np.zeros((N, n, n)) + np.eye(n)  # a sparsity pattern that later fills in
    cases = [(sparse_A, np.zeros((N, n, m)) + 0.1)]
    cases += [(np.eye(n) + 0.2 * rng.normal(size=(N, n, n)), rng.normal(size=(N, n, m))) for _ in range(3)]
    previous = None
    for A, B in cases:
        x0, c = rng.normal(size=n), 0.1 * rng.normal(size=(N, n))
        x_r, u_r = rng.normal(size=(N, n)), rng.normal(size=(N, m))
        got, want = mpc.solve(x0, A, B, c, x_r, u_r), ref.solve(x0, A, B, c, x_r, u_r)
        assert got.ok and want.ok
        np.testing.assert_allclose(got.u, want.u, atol=1e-6)
        np.testing.assert_allclose(got.x, want.x, atol=1e-6)
        if previous is not None:
            assert np.abs(got.u - previous).max() > 1e-3
        previous = got.u
    assert mpc.n_solves == 4 and mpc.n_fallbacks == 0


# --- the same QP handed to OSQP directly ----------------------------------------------------------------------------

@pytest.mark.parametrize("N", [1, 4, 10])
def test_direct_osqp_gives_the_lqr_input(N: int) -> None:
    K, P, _ = control.dlqr(A_DI, B_DI, np.diag(Q_DI), np.diag(R_DI))
    mpc = OSQPMPC(N, Q_DI, R_DI, cost="as_written", Q_N=P, **TIGHT)
    for x0 in ([1.0, 0.0], [-0.3, 2.0]):
        sol = mpc.solve(np.array(x0), *lti(N), np.zeros(2), np.zeros(1))
        assert sol.ok and not sol.fallback
        np.testing.assert_allclose(sol.u[0], -K @ np.array(x0), rtol=1e-5)


@pytest.mark.parametrize("full_weights", [False, True], ids=["diagonal", "full"])
def test_direct_osqp_equals_the_cvxpy_problem_step_after_step(full_weights: bool) -> None:
    """Random time-varying data, boxes on u and on some x, moving references: the same plans."""
    rng = np.random.default_rng(7)
    N, n, m = 6, 4, 2
    if full_weights:
        G = rng.normal(size=(n, n))
        Q, R, Q_N = G @ G.T + np.eye(n), np.array([[2.0, 0.3], [0.3, 1.0]]), 3 * np.eye(n)
    else:
        Q, R, Q_N = np.array([1.0, 2.0, 0.5, 0.0]), np.array([1.0, 0.1]), None
    kw = {"Q_N": Q_N, "u_lb": [-1.0, -2.0], "u_ub": [1.0, 0.5], "x_lb": [-np.inf, -0.3, -np.inf, -np.inf],
          "x_ub": [np.inf, 0.3, np.inf, 2.0], "eps_abs": 1e-10, "eps_rel": 1e-10}
    cvx, direct = LinearizedMPC(N, Q, R, cost="as_written", **kw), OSQPMPC(N, Q, R, cost="as_written", **kw)
    active = 0
    for _ in range(5):
        A = np.eye(n) + 0.3 * rng.normal(size=(N, n, n))
        B, c = rng.normal(size=(N, n, m)), 0.1 * rng.normal(size=(N, n))
        x0, x_r, u_r = 0.2 * rng.normal(size=n), rng.normal(size=(N, n)), rng.normal(size=(N, m))
        a, b = cvx.solve(x0, A, B, c, x_r, u_r), direct.solve(x0, A, B, c, x_r, u_r)
        assert a.ok and b.ok and not b.fallback
        np.testing.assert_allclose(b.u, a.u, atol=1e-6)
        np.testing.assert_allclose(b.x, a.x, atol=1e-6)
        for k in range(N):
            np.testing.assert_allclose(b.x[k + 1], A[k] @ b.x[k] + B[k] @ b.u[k] + c[k], atol=1e-7)
        active += int(np.isclose(np.abs(b.x[1:, 1]), 0.3, atol=1e-6).any() or np.isclose(b.u[:, 0], 1.0).any())
    assert active > 0  # the boxes mattered somewhere


def test_direct_osqp_refuses_another_solver() -> None:
    with pytest.raises(ValueError, match="OSQP only"):
        OSQPMPC(3, Q_DI, R_DI, cost="as_written", solver="CLARABEL")


# --- fallback ------------------------------------------------------------------------------------------------------

def infeasible_mpc(N: int = 5, cls: type = LinearizedMPC) -> LinearizedMPC:
    """|position| <= 0.1 cannot hold at x_1 from velocity 10 with |u| <= 1."""
    return cls(N, Q_DI, R_DI, cost="as_written", u_lb=[-1.0], u_ub=[1.0], x_lb=[-0.1, -np.inf], x_ub=[0.1, np.inf])


@pytest.mark.parametrize("cls", [LinearizedMPC, OSQPMPC])
def test_first_call_fallback_returns_the_clipped_reference(cls: type) -> None:
    N = 5
    mpc = infeasible_mpc(N, cls)
    u_r = np.array([[3.0], [-3.0], [0.5], [0.2], [1.5]])
    sol = mpc.solve([0.0, 10.0], *lti(N), [0.0, 0.0], u_r)
    assert sol.fallback and not sol.ok and "infeasible" in sol.status
    np.testing.assert_array_equal(sol.u, np.clip(u_r, -1.0, 1.0))
    assert np.isfinite(sol.x).all() and sol.x.shape == (N + 1, 2)
    np.testing.assert_allclose(sol.x[1], A_DI @ [0.0, 10.0] + B_DI @ sol.u[0])
    assert mpc.n_fallbacks == 1


@pytest.mark.parametrize("cls", [LinearizedMPC, OSQPMPC])
def test_infeasible_step_returns_the_shifted_previous_plan(cls: type) -> None:
    N = 5
    mpc = infeasible_mpc(N, cls)
    good = mpc.solve([0.05, 0.0], *lti(N), [0.0, 0.0], [0.3])
    assert good.ok and not good.fallback
    bad = mpc.solve([0.0, 10.0], *lti(N), [0.0, 0.0], [0.3])
    assert bad.fallback and not bad.ok and mpc.n_fallbacks == 1 and bad.reason == "not_optimal"
    np.testing.assert_array_equal(bad.u, np.vstack([good.u[1:], [[0.3]]]))  # past the plan: the reference
    assert np.isfinite(bad.x).all()
    again = mpc.solve([0.0, 10.0], *lti(N), [0.0, 0.0], [0.3])  # keeps shifting
    np.testing.assert_array_equal(again.u, np.vstack([good.u[2:], [[0.3]], [[0.3]]]))
    assert mpc.n_fallbacks == 2 and mpc.n_solves == 3 and mpc.fallback_reasons == {"not_optimal": 2}
    recovered = mpc.solve([0.05, 0.0], *lti(N), [0.0, 0.0], [0.3])
    assert recovered.ok and not recovered.fallback
    np.testing.assert_allclose(recovered.u, good.u, atol=1e-4)


@pytest.mark.filterwarnings("ignore:Solution may be inaccurate")
def test_solver_exception_and_iteration_limit_fall_back(monkeypatch: pytest.MonkeyPatch) -> None:
    mpc = LinearizedMPC(3, Q_DI, R_DI, cost="as_written", u_lb=[-1.0], u_ub=[1.0])

    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError("solver crashed")

    monkeypatch.setattr(mpc.problem, "solve", boom)
    sol = mpc.solve([1.0, 0.0], *lti(3), [0.0, 0.0], [2.0])
    assert sol.fallback and sol.status.startswith("solver_error") and "solver crashed" in sol.status
    assert isinstance(mpc.last_exception, RuntimeError)
    np.testing.assert_array_equal(sol.u, np.ones((3, 1)))
    monkeypatch.undo()
    starved = LinearizedMPC(10, [100.0, 1.0], R_DI, cost="as_written", max_iter=1, eps_abs=1e-12, eps_rel=1e-12)
    out = starved.solve([3.0, -2.0], *lti(10), [0.0, 0.0], [0.0])
    assert out.status == "user_limit"
    assert out.fallback and not out.ok and np.isfinite(out.u).all() and np.isfinite(out.x).all()


def test_shift_plan() -> None:
    x = np.arange(12.0).reshape(4, 3)  # x_0..x_3
    u = np.arange(6.0).reshape(3, 2)  # u_0..u_2
    x_bar, u_bar = shift_plan(x, u)
    np.testing.assert_array_equal(x_bar, x[1:])
    np.testing.assert_array_equal(u_bar, [[2.0, 3.0], [4.0, 5.0], [4.0, 5.0]])
    x_bar, _ = shift_plan(x, u, x0=[-1.0, -2.0, -3.0])
    np.testing.assert_array_equal(x_bar[0], [-1.0, -2.0, -3.0])
    np.testing.assert_array_equal(x_bar[1:], x[2:])
    mpc = LinearizedMPC(3, Q_DI, R_DI, cost="as_written")
    with pytest.raises(RuntimeError, match="no plan"):
        mpc.shift_plan()
    sol = mpc.solve([1.0, 0.0], *lti(3), [0.0, 0.0], [0.0])
    np.testing.assert_array_equal(mpc.shift_plan()[1], shift_plan(sol.x, sol.u)[1])
    with pytest.raises(ValueError, match="expected x"):
        shift_plan(x[:3], u)


# --- input checks ----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"N": 0}, "horizon N"),
        ({"N": True}, "horizon N"),
        ({"N": 2.5}, "horizon N"),
        ({"Q": [1.0, -1.0]}, "Q must be positive semidefinite"),
        ({"Q": [[1.0, 2.0], [2.0, 1.0]]}, "Q must be positive semidefinite"),
        ({"Q": [[1.0, 0.5], [0.0, 1.0]]}, "Q must be symmetric"),
        ({"Q": np.ones((2, 3))}, "square"),
        ({"Q": [1.0, np.nan]}, "Q holds a NaN"),
        ({"R": [0.0]}, "R must be positive definite"),
        ({"R": [[0.0]]}, "R must be positive definite"),
        ({"Q_N": [1.0, 1.0, 1.0]}, "Q_N has size 3, expected 2"),
        ({"u_lb": [1.0], "u_ub": [0.0]}, "u_lb > u_ub at index 0"),
        ({"u_lb": [0.0, 0.0]}, r"u_lb must have shape \(1,\)"),
        ({"x_lb": [np.nan, 0.0]}, "x_lb holds NaN"),
        ({"x_ub": [np.inf, -np.inf]}, "x_ub > -inf"),
        ({"solver": "gurobi"}, "solver must be one of"),
        ({"max_iter": 0}, "max_iter"),
        ({"eps_abs": -1.0}, "eps_abs"),
        ({"cost": "paper"}, "cost must be one of"),
        ({"cost": "as_flown", "Q_N": [1.0, 1.0]}, "no weight on x_N"),
    ],
)
def test_bad_construction_raises(kwargs: dict, match: str) -> None:
    args = {"N": 3, "Q": Q_DI, "R": R_DI, "cost": "as_written", **kwargs}
    with pytest.raises(ValueError, match=match):
        LinearizedMPC(args.pop("N"), args.pop("Q"), args.pop("R"), **args)


def test_bad_step_data_raises_before_solving() -> None:
    mpc = LinearizedMPC(3, Q_DI, R_DI, cost="as_written")
    A, B, c = lti(3)
    with pytest.raises(ValueError, match=r"x0 holds a NaN or infinite value \(first at index \(1,\)\)"):
        mpc.solve([0.0, np.nan], A, B, c, [0.0, 0.0], [0.0])
    with pytest.raises(ValueError, match=r"A must have shape \(3, 2, 2\)"):
        mpc.solve([0.0, 0.0], A[:2], B, c, [0.0, 0.0], [0.0])
    with pytest.raises(ValueError, match=r"B must have shape \(3, 2, 1\)"):
        mpc.solve([0.0, 0.0], A, B[..., 0], c, [0.0, 0.0], [0.0])
    with pytest.raises(ValueError, match=r"x_r must have shape \(3, 2\) or \(2,\)"):
        mpc.solve([0.0, 0.0], A, B, c, np.zeros((4, 2)), [0.0])
    assert mpc.n_solves == 0 and mpc.plan is None
    # non-finite data is not an input error but a failed solve (the guard; see test_guard.py)
    sol = mpc.solve([0.0, 0.0], A, B, np.full((3, 2), np.inf), [0.0, 0.0], [0.0])
    assert sol.fallback and sol.reason == "data_not_finite" and mpc.n_solves == 1


def test_solution_type() -> None:
    sol = LinearizedMPC(2, Q_DI, R_DI, cost="as_written").solve([1.0, 0.0], *lti(2), [0.0, 0.0], [0.0])
    assert isinstance(sol, MPCSolution)
    assert sol.solve_time_s > 0 and sol.solver_time_s >= 0
