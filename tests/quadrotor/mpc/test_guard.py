"""The two cost variants of Eq. (28), the guard before every solve, and the safe fallback.

Every test runs through both QPs: the cvxpy problem (:class:`LinearizedMPC`) and the fast path that
updates OSQP from cvxpy's canonicalisation (:class:`OSQPMPC`).
"""

from __future__ import annotations

import numpy as np
import pytest

from fnnlib.quadrotor.mpc import LinearizedMPC, OSQPMPC
from fnnlib.quadrotor.mpc.linearized import COSTS, DIVERGED_FALLBACK_SHARE, FALLBACK_REASONS, OSQP_INFTY, is_diverged

DT = 0.1
A_DI = np.array([[1.0, DT], [0.0, 1.0]])  # discretised double integrator
B_DI = np.array([[DT * DT / 2], [DT]])
QPS = [LinearizedMPC, OSQPMPC]
TIGHT = {"eps_abs": 1e-10, "eps_rel": 1e-10, "solver_options": {"polishing": True}}


def lti(N: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.repeat(A_DI[None], N, 0), np.repeat(B_DI[None], N, 0), np.zeros((N, 2))


def boxed(cls: type, N: int = 5, cost: str = "as_written", **kw: object) -> LinearizedMPC:
    return cls(N, [1.0, 0.1], [0.01], cost=cost, u_lb=[-1.0], u_ub=[1.0], **kw)


# --- the guard: 1e31, 1e29, NaN ----------------------------------------------------------------------------------

@pytest.mark.parametrize("cost", COSTS)
@pytest.mark.parametrize("cls", QPS)
def test_data_at_osqp_infinity_is_a_fallback_not_a_stale_optimum(cls: type, cost: str, capfd) -> None:
    """A c entry of 1e31 made osqp reject the update and re-solve the previous step's data."""
    N, x0 = 5, np.array([0.5, 0.0])
    mpc = boxed(cls, N, cost, **TIGHT)
    good = mpc.solve(x0, *lti(N), np.zeros(2), np.zeros(1))
    assert good.ok
    A, B, c = lti(N)
    c[2, 0] = 1e31
    sol = mpc.solve(x0, A, B, c, np.zeros(2), np.zeros(1))
    assert sol.fallback and not sol.ok and sol.reason == "data_too_large" and sol.status == "not_solved"
    np.testing.assert_array_equal(sol.u[:-1], good.u[1:])  # the last plan, shifted
    assert mpc.fallback_reasons == {"data_too_large": 1}
    out, err = capfd.readouterr()
    assert "ERROR" not in out + err  # the solver never saw it
    # the next step solves the new data, not a stale copy: the same plan as a fresh solver's
    x1 = np.array([0.2, -0.3])
    again = mpc.solve(x1, *lti(N), np.zeros(2), np.zeros(1))
    fresh = boxed(cls, N, cost, **TIGHT).solve(x1, *lti(N), np.zeros(2), np.zeros(1))
    assert again.ok
    np.testing.assert_allclose(again.u, fresh.u, atol=1e-6)


@pytest.mark.parametrize("cls", QPS)
def test_derived_data_at_osqp_infinity_is_refused_too(cls: type) -> None:
    """d_0 = A_0 x_0 + c_0 reaches 1e31 although every input is below 1e30."""
    N = 3
    mpc = boxed(cls, N)
    A, B, c = lti(N)
    A[0] = 1e20
    sol = mpc.solve(np.array([1e11, 0.0]), A, B, c, np.zeros(2), np.zeros(1))
    assert sol.fallback and sol.reason == "data_too_large"
    assert np.isfinite(sol.u).all() and np.isfinite(sol.x).all()


@pytest.mark.parametrize("value", [1e29, -1e29])
@pytest.mark.parametrize("cost", COSTS)
@pytest.mark.parametrize("cls", QPS)
def test_data_near_1e29_never_gives_a_usable_plan_outside_the_box(cls: type, cost: str, value: float) -> None:
    """With data near 1e29 OSQP said "optimal" with u[0] = 4.4e19 against a box of [-1, 1]."""
    N = 5
    mpc = boxed(cls, N, cost)
    A, B, c = lti(N)
    c[2, 0] = value
    sol = mpc.solve(np.array([0.5, 0.0]), A, B, c, np.zeros(2), np.zeros(1))
    assert sol.fallback and not sol.ok
    assert sol.reason in ("not_optimal", "solution_not_finite", "outside_box", "dynamics_mismatch")
    assert -1.0 <= sol.u.min() and sol.u.max() <= 1.0  # the fallback respects the box


@pytest.mark.parametrize("where", ["A", "B", "c", "x_r", "u_r"])
@pytest.mark.parametrize("cls", QPS)
def test_nan_data_is_a_fallback(cls: type, where: str) -> None:
    N = 4
    mpc = boxed(cls, N)
    data = dict(zip(("A", "B", "c"), lti(N)), x_r=np.zeros((N, 2)), u_r=np.zeros((N, 1)))
    data[where] = data[where].copy()
    data[where].flat[1] = np.nan
    sol = mpc.solve(np.array([0.5, 0.0]), data["A"], data["B"], data["c"], data["x_r"], data["u_r"])
    assert sol.fallback and sol.reason == "data_not_finite" and sol.status == "not_solved"
    assert np.isfinite(sol.u).all() and np.isfinite(sol.x).all()
    assert mpc.n_fallbacks == 1 and mpc.fallback_reasons["data_not_finite"] == 1


# --- plans that are not usable ------------------------------------------------------------------------------------

@pytest.mark.parametrize("cls", QPS)
def test_an_optimal_plan_outside_the_box_is_not_used(cls: type, monkeypatch: pytest.MonkeyPatch) -> None:
    N = 3
    mpc = cls(N, [1.0, 0.1], [0.01], cost="as_written", u_lb=[-1.0], u_ub=[1.0], x_lb=[-2.0, -np.inf],
              x_ub=[2.0, np.inf])
    A, B, c = lti(N)
    x0 = np.array([0.5, 0.0])
    real = mpc._solve_qp

    def shifted(by_u: float, by_x: float):
        def solve_qp(*args):
            status, u, x, t = real(*args)
            return status, u + by_u, x + np.array([by_x, 0.0]), t
        return solve_qp

    monkeypatch.setattr(mpc, "_solve_qp", shifted(0.0, 0.0))
    assert mpc.solve(x0, A, B, c, np.zeros(2), np.zeros(1)).ok
    for by_u, by_x in ((1.5, 0.0), (0.0, 3.0)):
        monkeypatch.setattr(mpc, "_solve_qp", shifted(by_u, by_x))
        sol = mpc.solve(x0, A, B, c, np.zeros(2), np.zeros(1))
        assert sol.fallback and sol.reason in ("outside_box", "dynamics_mismatch")
        if by_u:  # the box is checked first
            assert sol.reason == "outside_box"


@pytest.mark.parametrize("cls", QPS)
def test_a_stale_solve_is_caught_by_the_dynamics_check(cls: type, monkeypatch: pytest.MonkeyPatch) -> None:
    """The solver re-solves the previous step's data (a rejected update): reported "optimal", but not this QP's."""
    N = 4
    mpc = boxed(cls, N)
    A, B, c = lti(N)
    first = mpc.solve(np.array([0.5, 0.0]), A, B, c, np.zeros(2), np.zeros(1))
    assert first.ok
    if cls is OSQPMPC:  # osqp ignores the update, exactly as after a rejected one
        monkeypatch.setattr(mpc._solver, "update", lambda **kw: None)
    else:  # cvxpy: the parameters are not refreshed
        monkeypatch.setattr(mpc, "_parameter_values", lambda *a: tuple(p.value for p in mpc.parameters))
    c2 = c.copy()
    c2[:, 1] = 0.05  # a constant push: the old plan violates the new dynamics
    sol = mpc.solve(np.array([0.5, 0.0]), A, B, c2, np.zeros(2), np.zeros(1))
    assert sol.fallback and not sol.ok and sol.reason == "dynamics_mismatch"
    assert sol.status == "optimal"  # what the solver claimed


# --- the fallback schedule -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("cls", QPS)
def test_fallback_flies_the_plan_for_at_most_N_steps_then_the_reference(cls: type) -> None:
    N = 4
    mpc = boxed(cls, N)
    A, B, c = lti(N)
    u_r = np.array([[0.1], [0.2], [0.3], [2.0]])  # the last one is clipped to the box
    good = mpc.solve(np.array([0.5, 0.0]), A, B, c, np.zeros(2), u_r)
    assert good.ok
    bad_c = c.copy()
    bad_c[0, 0] = np.nan
    for k in range(1, N + 3):
        sol = mpc.solve(np.array([0.5, 0.0]), A, B, bad_c, np.zeros(2), u_r)
        assert sol.fallback and mpc.n_consecutive_fallbacks == k
        if k < N:  # the plan's inputs u_k..u_{N-1}, then the (clipped) reference past it
            np.testing.assert_array_equal(sol.u, np.vstack([good.u[k:], np.clip(u_r[N - k:], -1.0, 1.0)]))
        else:
            np.testing.assert_array_equal(sol.u, np.clip(u_r, -1.0, 1.0))
    assert mpc.n_reference_fallbacks == 3 and mpc.n_fallbacks == N + 2
    assert mpc.fallback_reasons == {"data_not_finite": N + 2}
    assert mpc.solve(np.array([0.5, 0.0]), A, B, c, np.zeros(2), u_r).ok
    assert mpc.n_consecutive_fallbacks == 0
    mpc.reset()
    assert mpc.n_fallbacks == mpc.n_reference_fallbacks == 0 and not mpc.fallback_reasons


def test_reasons_and_the_diverged_share() -> None:
    assert set(FALLBACK_REASONS) >= {"data_not_finite", "data_too_large", "outside_box", "dynamics_mismatch"}
    assert OSQP_INFTY == 1e30 and 0 < DIVERGED_FALLBACK_SHARE < 1
    assert not is_diverged(0, 300) and not is_diverged(30, 300) and is_diverged(31, 300)
    assert is_diverged(278, 300)  # an AdapNN flight seen at Gamma = 8
    with pytest.raises(ValueError, match="n_steps"):
        is_diverged(1, 0)
    with pytest.raises(ValueError, match="share"):
        is_diverged(1, 10, share=1.5)


# --- the two cost variants ---------------------------------------------------------------------------------------

def kkt_plan(N: int, A: np.ndarray, B: np.ndarray, c: np.ndarray, x0: np.ndarray, x_r: np.ndarray, u_r: np.ndarray,
             Wx: list, Wu: list) -> np.ndarray:
    """Equality-constrained QP of Eq. (28) solved by its KKT system in numpy (no boxes): the inputs u (N, m)."""
    n, m = B.shape[1], B.shape[2]
    nz = N * (n + m)
    H, g = np.zeros((nz, nz)), np.zeros(nz)
    for k in range(N):  # z = [x_1..x_N, u_0..u_{N-1}]
        ix, iu = slice(k * n, (k + 1) * n), slice(N * n + k * m, N * n + (k + 1) * m)
        H[ix, ix], g[ix] = np.diag(Wx[k]), -np.diag(Wx[k]) @ x_r[k]
        H[iu, iu], g[iu] = np.diag(Wu[k]), -np.diag(Wu[k]) @ u_r[k]
    E, e = np.zeros((N * n, nz)), np.zeros(N * n)
    for k in range(N):
        rows = slice(k * n, (k + 1) * n)
        E[rows, k * n:(k + 1) * n] = np.eye(n)
        E[rows, N * n + k * m:N * n + (k + 1) * m] = -B[k]
        if k:
            E[rows, (k - 1) * n:k * n] = -A[k]
        e[rows] = c[k] + (A[0] @ x0 if k == 0 else 0.0)
    K = np.block([[H, E.T], [E, np.zeros((N * n, N * n))]])
    z = np.linalg.solve(K, np.concatenate([-g, e]))[:nz]
    return z[N * n:].reshape(N, m)


@pytest.mark.parametrize("cost", COSTS)
@pytest.mark.parametrize("cls", QPS)
def test_cost_variants_match_their_stated_weights(cls: type, cost: str) -> None:
    """as_written: Q on x_1..x_{N-1}, Q_N on x_N, R on every input; as_flown: Q on x_1..x_{N-1}, R on u_{N-1} only."""
    rng = np.random.default_rng(3)
    N, Q, Q_N, R = 5, np.array([1.0, 0.2]), np.array([3.0, 0.5]), np.array([0.4])
    A = np.eye(2) + 0.1 * rng.normal(size=(N, 2, 2))
    B = np.repeat(B_DI[None], N, 0) + 0.01 * rng.normal(size=(N, 2, 1))
    c, x0 = 0.01 * rng.normal(size=(N, 2)), rng.normal(size=2)
    x_r, u_r = rng.normal(size=(N, 2)), rng.normal(size=(N, 1))
    kw = {"Q_N": Q_N} if cost == "as_written" else {}
    mpc = cls(N, Q, R, cost=cost, **kw, **TIGHT)
    sol = mpc.solve(x0, A, B, c, x_r, u_r)
    assert sol.ok
    zero_x, zero_u = np.zeros(2), np.zeros(1)
    if cost == "as_written":
        Wx, Wu = [Q] * (N - 1) + [Q_N], [R] * N
    else:
        Wx, Wu = [Q] * (N - 1) + [zero_x], [zero_u] * (N - 1) + [R]
    np.testing.assert_allclose(sol.u, kkt_plan(N, A, B, c, x0, x_r, u_r, Wx, Wu), atol=1e-6)
    wx, wu = mpc.weights()
    assert len(wx) == len(wu) == N
    assert (wx[-1] is None) == (cost == "as_flown") and (wu[0] is None) == (cost == "as_flown")


@pytest.mark.parametrize("cls", QPS)
def test_as_flown_leaves_the_inputs_free(cls: type) -> None:
    """Under the release's weighting the nominal model pays nothing for thrust above u_ref: it tracks x_r closer."""
    N, x0 = 6, np.array([1.0, 0.0])
    A, B, c = lti(N)
    plans = {cost: cls(N, [1.0, 0.1], [10.0], cost=cost, **TIGHT).solve(x0, A, B, c, np.zeros(2), np.zeros(1))
             for cost in COSTS}
    err = {cost: np.abs(p.x[1:N, 0]).sum() for cost, p in plans.items()}
    assert err["as_flown"] < 0.7 * err["as_written"]  # 2.9 against 5.0 (the double integrator's reach in 0.5 s)
    assert np.abs(plans["as_flown"].u[:-1]).max() > 2 * np.abs(plans["as_written"].u[:-1]).max()


def test_cost_is_required() -> None:
    with pytest.raises(TypeError, match="cost"):
        LinearizedMPC(3, [1.0, 0.1], [0.01])  # type: ignore[call-arg]


# --- one formulation: the fast path equals the cvxpy problem on random problems ------------------------------------

@pytest.mark.parametrize("cost", COSTS)
def test_canonicalised_fast_path_equals_the_cvxpy_problem_on_random_problems(cost: str) -> None:
    rng = np.random.default_rng(11)
    active = 0
    for trial in range(12):
        N, n, m = int(rng.integers(1, 7)), int(rng.integers(2, 5)), int(rng.integers(1, 3))
        Q, R = rng.uniform(0.0, 3.0, n), rng.uniform(0.1, 2.0, m)
        x_lb, x_ub = np.full(n, -np.inf), np.full(n, np.inf)
        x_lb[0], x_ub[0] = -0.4, 0.4
        kw = {"u_lb": -np.full(m, 0.5), "u_ub": np.full(m, 0.5), "x_lb": x_lb, "x_ub": x_ub,
              "eps_abs": 1e-10, "eps_rel": 1e-10, "cost": cost}
        cvx, fast = LinearizedMPC(N, Q, R, **kw), OSQPMPC(N, Q, R, **kw)
        assert fast.n_var == N * (n + m)  # diagonal weights: no auxiliary variables in cvxpy's canonical form
        for _ in range(3):
            A = np.eye(n) + 0.2 * rng.normal(size=(N, n, n))
            B, c = rng.normal(size=(N, n, m)), 0.1 * rng.normal(size=(N, n))
            x0, x_r, u_r = 0.3 * rng.normal(size=n), rng.normal(size=(N, n)), rng.normal(size=(N, m))
            a, b = cvx.solve(x0, A, B, c, x_r, u_r), fast.solve(x0, A, B, c, x_r, u_r)
            if not a.ok:  # an infeasible draw (the state box): both must fall back
                assert a.fallback and b.fallback
                continue
            assert b.ok, (trial, b.status, b.reason)
            np.testing.assert_allclose(b.u, a.u, atol=1e-6)
            np.testing.assert_allclose(b.x, a.x, atol=1e-6)
            active += int(np.isclose(np.abs(b.u), 0.5, atol=1e-6).any() or np.isclose(np.abs(b.x[1:, 0]), 0.4).any())
    assert active > 3  # the boxes mattered


@pytest.mark.parametrize("cls", QPS)
def test_reset_forgets_the_warm_start(cls: type) -> None:
    """After reset() the same sequence of steps gives the same plans, bit for bit (the fast path keeps its
    canonicalisation and rebuilds only the OSQP object)."""
    rng = np.random.default_rng(5)
    N = 4
    steps = [(0.5 * rng.normal(size=2), np.eye(2) + 0.3 * rng.normal(size=(N, 2, 2)), rng.normal(size=(N, 2, 1)),
              rng.normal(size=(N, 2))) for _ in range(4)]
    mpc = boxed(cls, N, "as_flown")

    def fly_steps() -> list:
        return [mpc.solve(x0, A, B, np.zeros((N, 2)), x_r, np.zeros(1)).u for x0, A, B, x_r in steps]

    first = fly_steps()
    mpc.reset()
    again = fly_steps()
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    warm = fly_steps()  # no reset: warm-started
    assert any(not np.array_equal(a, b) for a, b in zip(first, warm))
