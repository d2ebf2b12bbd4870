r"""Linear time-varying MPC, the QP form of Eq. (28) (App. A.5.3, ``Standard_MPC``).

Along a linearisation :math:`x_{k+1} = A_k x_k + B_k u_k + c_k` (see
:func:`fnnlib.mpc.linearize`) Eq. (28) becomes the QP

.. math::
    \min_{x_{1:N},\, u_{0:N-1}} \;
        \sum_{k=1}^{N-1} \|x_k - x^r_k\|_Q^2 + \|x_N - x^r_N\|_{Q_N}^2
        + \sum_{k=0}^{N-1} \|u_k - u^r_k\|_R^2

    \text{s.t.}\quad x_{k+1} = A_k x_k + B_k u_k + c_k,\; x_0 = x(0),\quad
    u_{lb} \le u_k \le u_{ub},\quad x_{lb} \le x_k \le x_{ub}\; (k \ge 1).

The paper writes :math:`l_N(x_N) + \sum_{i=1}^{N} l_x(x_i)` with
:math:`l_N = l_x`; here the weight of :math:`x_N` is :math:`Q_N` (default
:math:`Q`), i.e. the stage sum of the brief, :math:`\sum_{k=1}^{N}\|x_k - x^r_k\|_Q^2`.
Pass ``Q_N = 2 Q`` for the paper's literal double count of the last state.

:class:`LinearizedMPC` builds the cvxpy problem once with ``cp.Parameter`` data
(DPP, so cvxpy caches the canonicalisation) and each call only assigns values
and re-solves warm. :class:`RebuildMPC` builds a new problem from constants at
every call; it exists for the benchmark ratio. :class:`OSQPMPC` is the same QP
written once in OSQP's own sparse form: each call writes the new :math:`A_k,
B_k, c_k` and references into the fixed sparsity pattern (``update``) and
re-solves warm, skipping cvxpy's per-solve work (parameter checks, applying the
parameter tensor, unpacking: about 3.5 of the 4.5 ms a cvxpy solve takes here).
The tests hold the two to the same plan.

DPP note: :math:`A_0 x_0` would be a parameter times a parameter, which is not
DPP. The first row is therefore written :math:`x_1 = d_0 + B_0 u_0` with the
parameter :math:`d_0 = A_0 x_0 + c_0` computed in numpy; the decision variables
stay :math:`x_{1:N}, u_{0:N-1}` exactly as in Eq. (28).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np
import osqp
import scipy.sparse as sp
from numpy.typing import ArrayLike

SOLVERS = ("OSQP", "CLARABEL")
USABLE_STATUSES = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


@dataclass(frozen=True)
class MPCSolution:
    """Result of one MPC solve.

    Attributes
    ----------
    u : ndarray, shape (N, m)
        Planned inputs :math:`u_0..u_{N-1}`; apply ``u[0]``.
    x : ndarray, shape (N+1, n)
        Predicted states :math:`x_0..x_N` under the linear model (``x[0]`` is the given ``x0``).
    status : str
        The solver's status as cvxpy reports it (``"optimal"``, ``"infeasible"``, ...), or
        ``"solver_error: <exception>"`` when the solver raised.
    ok : bool
        True when the solver reported ``"optimal"`` and the solution is finite.
    solve_time_s : float
        Wall time of the whole call (checks, parameter assignment, solve, unpacking).
    fallback : bool
        True when ``u``/``x`` are not this solve's solution but the previous plan shifted
        by one step (or the clipped reference on a first call); see :meth:`LinearizedMPC.solve`.
    solver_time_s : float
        Time the solver itself reports (``solver_stats.solve_time``); NaN if unavailable.
    """

    u: np.ndarray
    x: np.ndarray
    status: str
    ok: bool
    solve_time_s: float
    fallback: bool
    solver_time_s: float = math.nan


# --- input checks --------------------------------------------------------------------------------------------------

def _check_weight(W: ArrayLike, name: str, *, definite: bool, size: int | None = None) -> np.ndarray:
    """Validate a weight given as (d,) diagonal or (d, d) symmetric matrix; return it as float64."""
    a = np.asarray(W, dtype=np.float64)
    if a.ndim not in (1, 2) or a.shape[0] == 0 or (a.ndim == 2 and a.shape[0] != a.shape[1]):
        raise ValueError(f"{name} must be a (d,) diagonal or a square (d, d) matrix, got shape {a.shape}")
    if size is not None and a.shape[0] != size:
        raise ValueError(f"{name} has size {a.shape[0]}, expected {size} (shape {a.shape})")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} holds a NaN or infinite value")
    what = "positive definite" if definite else "positive semidefinite"
    if a.ndim == 1:
        bad = a <= 0 if definite else a < 0
        if bad.any():
            raise ValueError(f"{name} must be {what}: diagonal entry {int(np.flatnonzero(bad)[0])} is {a[bad][0]:g}")
        return a
    scale = max(1.0, float(np.abs(a).max()))
    if not np.allclose(a, a.T, rtol=0.0, atol=1e-10 * scale):
        raise ValueError(f"{name} must be symmetric (max |{name} - {name}^T| = {np.abs(a - a.T).max():.3g})")
    lam = float(np.linalg.eigvalsh(0.5 * (a + a.T)).min())
    if (definite and lam <= 1e-12 * scale) or (not definite and lam < -1e-10 * scale):
        raise ValueError(f"{name} must be {what}; its smallest eigenvalue is {lam:.3g}")
    return 0.5 * (a + a.T)


def _weight_factor(W: np.ndarray) -> np.ndarray:
    """F with ||F e||^2 = e^T W e: (d,) sqrt of a diagonal, else (r, d) from the eigendecomposition."""
    if W.ndim == 2 and np.count_nonzero(W - np.diag(np.diag(W))) == 0:
        W = np.diag(W).copy()
    if W.ndim == 1:
        return np.sqrt(W)
    lam, V = np.linalg.eigh(W)
    keep = lam > 1e-14 * max(1.0, float(lam.max()))
    return np.sqrt(lam[keep])[:, None] * V[:, keep].T


def _check_box(lb: ArrayLike | None, ub: ArrayLike | None, d: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Bounds (d,) each, +-inf allowed (no constraint), lb <= ub, no NaN."""
    lo = np.full(d, -np.inf) if lb is None else np.asarray(lb, dtype=np.float64)
    hi = np.full(d, np.inf) if ub is None else np.asarray(ub, dtype=np.float64)
    for arr, side in ((lo, "lb"), (hi, "ub")):
        if arr.shape != (d,):
            raise ValueError(f"{name}_{side} must have shape ({d},), got {arr.shape}")
        if np.isnan(arr).any():
            raise ValueError(f"{name}_{side} holds NaN (use +-inf for no bound)")
    if (lo == np.inf).any() or (hi == -np.inf).any():
        raise ValueError(f"{name}_lb must be < +inf and {name}_ub > -inf")
    if (lo > hi).any():
        i = int(np.flatnonzero(lo > hi)[0])
        raise ValueError(f"{name}_lb > {name}_ub at index {i} ({lo[i]:g} > {hi[i]:g})")
    return lo, hi


def _as_data(value: ArrayLike, shape: tuple[int, ...], name: str, *, broadcast_rows: bool = False) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if broadcast_rows and a.shape == shape[1:]:
        a = np.broadcast_to(a, shape)
    if a.shape != shape:
        extra = f" or {shape[1:]}" if broadcast_rows else ""
        raise ValueError(f"{name} must have shape {shape}{extra}, got {a.shape}")
    if not np.isfinite(a).all():
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        raise ValueError(f"{name} holds a NaN or infinite value (first at index {idx})")
    return a


def shift_plan(x: ArrayLike, u: ArrayLike, x0: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    r"""Next linearisation point from a plan: shift by one step, repeat the last entry.

    Parameters
    ----------
    x : array_like, shape (N+1, n)
        Plan :math:`x_0..x_N` (as in :attr:`MPCSolution.x`).
    u : array_like, shape (N, m)
        Plan :math:`u_0..u_{N-1}`.
    x0 : array_like, shape (n,), optional
        Measured state that replaces the first nominal state.

    Returns
    -------
    x_bar : ndarray, shape (N, n)
        :math:`x_1..x_N` (the predicted :math:`x_0..x_{N-1}` of the next step), row 0 replaced by ``x0`` if given.
    u_bar : ndarray, shape (N, m)
        :math:`u_1..u_{N-1}, u_{N-1}`.
    """
    xs = np.asarray(x, dtype=np.float64)
    us = np.asarray(u, dtype=np.float64)
    if us.ndim != 2 or us.shape[0] < 1 or xs.ndim != 2 or xs.shape[0] != us.shape[0] + 1:
        raise ValueError(f"expected x (N+1, n) and u (N, m), got x {xs.shape} and u {us.shape}")
    x_bar = xs[1:].copy()
    u_bar = np.concatenate([us[1:], us[-1:]], axis=0)
    if x0 is not None:
        x_bar[0] = _as_data(x0, (xs.shape[1],), "x0")
    return x_bar, u_bar


# --- common machinery ----------------------------------------------------------------------------------------------

class _MPCBase:
    """Checks, formulation, fallback and bookkeeping shared by both implementations.

    The constructor arguments are documented on :class:`LinearizedMPC`.
    """

    def __init__(
        self,
        N: int,
        Q: ArrayLike,
        R: ArrayLike,
        *,
        Q_N: ArrayLike | None = None,
        u_lb: ArrayLike | None = None,
        u_ub: ArrayLike | None = None,
        x_lb: ArrayLike | None = None,
        x_ub: ArrayLike | None = None,
        solver: str = "OSQP",
        eps_abs: float = 1e-5,
        eps_rel: float = 1e-5,
        max_iter: int = 10_000,
        solver_options: Mapping[str, Any] | None = None,
    ) -> None:
        if isinstance(N, bool) or not isinstance(N, (int, np.integer)) or N < 1:
            raise ValueError(f"horizon N must be an integer >= 1, got {N!r}")
        self.N = int(N)
        self.Q = _check_weight(Q, "Q", definite=False)
        self.n = self.Q.shape[0]
        self.R = _check_weight(R, "R", definite=True)
        self.m = self.R.shape[0]
        self.Q_N = self.Q if Q_N is None else _check_weight(Q_N, "Q_N", definite=False, size=self.n)
        self.u_lb, self.u_ub = _check_box(u_lb, u_ub, self.m, "u")
        self.x_lb, self.x_ub = _check_box(x_lb, x_ub, self.n, "x")
        name = str(solver).upper()
        if name not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
        for v, label in ((eps_abs, "eps_abs"), (eps_rel, "eps_rel")):
            if not (float(v) >= 0 and math.isfinite(float(v))):
                raise ValueError(f"{label} must be a finite number >= 0, got {v!r}")
        if isinstance(max_iter, bool) or int(max_iter) != max_iter or max_iter < 1:
            raise ValueError(f"max_iter must be an integer >= 1, got {max_iter!r}")
        self.solver = name
        self.solver_options = self._default_options(name, float(eps_abs), float(eps_rel), int(max_iter))
        self.solver_options.update(dict(solver_options or {}))
        self.n_solves = 0
        self.n_fallbacks = 0
        self.last_exception: BaseException | None = None
        self._plan: tuple[np.ndarray, np.ndarray] | None = None
        self._setup()

    def _setup(self) -> None:
        """Build what the implementation keeps between calls (after the checks)."""

    @staticmethod
    def _default_options(solver: str, eps_abs: float, eps_rel: float, max_iter: int) -> dict[str, Any]:
        if solver == "OSQP":
            # polishing off: with A_k changing every step cvxpy would otherwise polish after each refactorisation
            return {"eps_abs": eps_abs, "eps_rel": eps_rel, "max_iter": max_iter, "polishing": False}
        return {"tol_gap_abs": max(eps_abs, 1e-12), "tol_gap_rel": max(eps_rel, 1e-12),
                "tol_feas": max(eps_abs, 1e-12), "max_iter": max_iter}

    # formulation of Eq. (28), shared by the parametrised and the rebuilt problem
    def _formulate(self, A_rows: list, B_rows: list, d: Any, x_r: Any, u_r: Any) -> tuple[cp.Problem, cp.Variable, cp.Variable]:
        """Problem with ``A_rows[k-1]`` = A_k (k >= 1), ``B_rows[k]`` = B_k, ``d`` (N, n) = [A_0 x_0 + c_0; c_1..c_{N-1}]."""
        N, n, m = self.N, self.n, self.m
        x = cp.Variable((N, n), name="x")  # x_1..x_N
        u = cp.Variable((N, m), name="u")  # u_0..u_{N-1}
        rows = [d[0] + B_rows[0] @ u[0]]
        rows += [A_rows[k - 1] @ x[k - 1] + B_rows[k] @ u[k] + d[k] for k in range(1, N)]
        constraints = [x == (cp.vstack(rows) if N > 1 else cp.reshape(rows[0], (1, n), order="C"))]
        for var, lo, hi in ((u, self.u_lb, self.u_ub), (x, self.x_lb, self.x_ub)):
            i_lo, i_hi = np.flatnonzero(np.isfinite(lo)), np.flatnonzero(np.isfinite(hi))
            if i_lo.size:
                constraints.append(var[:, i_lo] >= np.broadcast_to(lo[i_lo], (N, i_lo.size)))
            if i_hi.size:
                constraints.append(var[:, i_hi] <= np.broadcast_to(hi[i_hi], (N, i_hi.size)))
        cost = _weighted_sq(u - u_r, _weight_factor(self.R))
        cost += _weighted_sq(x[N - 1:] - x_r[N - 1:], _weight_factor(self.Q_N))
        if N > 1:
            cost += _weighted_sq(x[: N - 1] - x_r[: N - 1], _weight_factor(self.Q))
        return cp.Problem(cp.Minimize(cost), constraints), x, u

    def _check_step(self, x0: ArrayLike, A: ArrayLike, B: ArrayLike, c: ArrayLike, x_r: ArrayLike,
                    u_r: ArrayLike) -> tuple[np.ndarray, ...]:
        N, n, m = self.N, self.n, self.m
        return (_as_data(x0, (n,), "x0"), _as_data(A, (N, n, n), "A"), _as_data(B, (N, n, m), "B"),
                _as_data(c, (N, n), "c"), _as_data(x_r, (N, n), "x_r", broadcast_rows=True),
                _as_data(u_r, (N, m), "u_r", broadcast_rows=True))

    def _solve_qp(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, x_r: np.ndarray,
                  u_r: np.ndarray) -> tuple[str, np.ndarray | None, np.ndarray | None, float]:
        raise NotImplementedError

    def solve(self, x0: ArrayLike, A: ArrayLike, B: ArrayLike, c: ArrayLike, x_r: ArrayLike,
              u_r: ArrayLike) -> MPCSolution:
        r"""Solve Eq. (28) for one control step; never raises on a solver failure.

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Current state :math:`x_0 = x(0)`.
        A : array_like, shape (N, n, n)
            :math:`A_0..A_{N-1}`.
        B : array_like, shape (N, n, m)
            :math:`B_0..B_{N-1}`.
        c : array_like, shape (N, n)
            :math:`c_0..c_{N-1}`, so that :math:`x_{k+1} = A_k x_k + B_k u_k + c_k`.
        x_r : array_like, shape (N, n) or (n,)
            Reference :math:`x^r_1..x^r_N` (one row is repeated).
        u_r : array_like, shape (N, m) or (m,)
            Reference :math:`u^r_0..u^r_{N-1}`.

        Returns
        -------
        MPCSolution
            If the solve fails (status other than optimal / optimal_inaccurate, a NaN in
            the solution, or an exception in the solver) the result has ``fallback=True``:
            ``u`` is the previous plan shifted by one step with its last input repeated
            (the clipped reference ``u_r`` if there is no previous plan), ``x`` is that
            ``u`` rolled out through this call's linear model from ``x0``, and
            :attr:`n_fallbacks` is incremented.

        Raises
        ------
        ValueError
            Wrong shapes or NaN/inf in the data (checked before any work).
        """
        t0 = time.perf_counter()
        x0, A, B, c, x_r, u_r = self._check_step(x0, A, B, c, x_r, u_r)
        self.n_solves += 1
        self.last_exception = None
        try:
            status, u, x, solver_time = self._solve_qp(x0, A, B, c, x_r, u_r)
        except Exception as exc:  # a solver failure must never stop the control loop
            self.last_exception = exc
            status, u, x, solver_time = f"solver_error: {type(exc).__name__}: {exc}", None, None, math.nan
        usable = (status in USABLE_STATUSES and u is not None and x is not None
                  and bool(np.isfinite(u).all()) and bool(np.isfinite(x).all()))
        if usable:
            assert u is not None and x is not None
            u_plan, x_plan = np.array(u, dtype=np.float64), np.vstack([x0, x])
        else:
            self.n_fallbacks += 1
            if self._plan is None:
                u_plan = np.clip(u_r, self.u_lb, self.u_ub)
            else:
                prev_u = self._plan[1]
                u_plan = np.clip(np.concatenate([prev_u[1:], prev_u[-1:]], axis=0), self.u_lb, self.u_ub)
            x_plan = self._rollout(x0, A, B, c, u_plan)
        self._plan = (x_plan, u_plan)
        return MPCSolution(u=u_plan.copy(), x=x_plan.copy(), status=status,
                           ok=usable and status == cp.OPTIMAL, solve_time_s=time.perf_counter() - t0,
                           fallback=not usable, solver_time_s=solver_time)

    def _rollout(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, u: np.ndarray) -> np.ndarray:
        """x_{k+1} = A_k x_k + B_k u_k + c_k from x0; x0 repeated if that overflows."""
        xs = np.empty((self.N + 1, self.n))
        xs[0] = x0
        with np.errstate(all="ignore"):
            for k in range(self.N):
                xs[k + 1] = A[k] @ xs[k] + B[k] @ u[k] + c[k]
        return xs if np.isfinite(xs).all() else np.tile(x0, (self.N + 1, 1))

    @property
    def plan(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The last returned plan ``(x (N+1, n), u (N, m))``, or None before the first solve."""
        return None if self._plan is None else (self._plan[0].copy(), self._plan[1].copy())

    def shift_plan(self, x0: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Next linearisation point ``(x_bar (N, n), u_bar (N, m))`` from the last plan; see :func:`shift_plan`.

        Raises
        ------
        RuntimeError
            Before the first :meth:`solve`.
        """
        if self._plan is None:
            raise RuntimeError("no plan yet: call solve() first")
        return shift_plan(self._plan[0], self._plan[1], x0)

    def reset(self) -> None:
        """Start afresh: forget the last plan and the solver's warm start, zero the counters.

        The solver state is rebuilt (:meth:`_setup`), so a flight after ``reset()`` gives the
        same numbers whatever was solved before it (the warm start moves iterates within
        the tolerance otherwise).
        """
        self._plan = None
        self.n_solves = 0
        self.n_fallbacks = 0
        self.last_exception = None
        self._setup()


def _weighted_sq(E: Any, F: np.ndarray) -> cp.Expression:
    """sum_k ||F e_k||^2 over the rows e_k of E (K, d); F is (d,) diagonal or (r, d)."""
    if F.ndim == 1:
        return cp.sum_squares(cp.multiply(np.broadcast_to(F, E.shape), E))
    return cp.sum_squares(E @ F.T)


# --- the two implementations ------------------------------------------------------------------------------------

class LinearizedMPC(_MPCBase):
    r"""Linear time-varying MPC of Eq. (28), built once with cvxpy Parameters (DPP) and re-solved warm.

    Parameters
    ----------
    N : int
        Horizon, >= 1.
    Q : array_like, shape (n,) or (n, n)
        State weight (diagonal or symmetric PSD) of :math:`x_1..x_{N-1}`.
    R : array_like, shape (m,) or (m, m)
        Input weight (diagonal or symmetric PD) of :math:`u_0..u_{N-1}`.
    Q_N : array_like, shape (n,) or (n, n), optional
        Terminal weight of :math:`x_N` (PSD); default ``Q``.
    u_lb, u_ub : array_like, shape (m,), optional
        Input box; entries may be +-inf (no constraint). Default: unbounded.
    x_lb, x_ub : array_like, shape (n,), optional
        State box on :math:`x_1..x_N`; only finite entries become constraints
        (e.g. :math:`|\Theta| \le \pi/2` on indices 6..8). Default: unbounded.
    solver : {"OSQP", "CLARABEL"}
        QP solver (case-insensitive).
    eps_abs, eps_rel, max_iter :
        Tolerances and iteration limit; for Clarabel they map to ``tol_gap_abs``/``tol_feas``,
        ``tol_gap_rel`` and ``max_iter``.
    solver_options : mapping, optional
        Extra keyword arguments for the solver, passed verbatim (override the above),
        e.g. ``{"polishing": True, "adaptive_rho": True}`` for OSQP.

    Attributes
    ----------
    problem : cvxpy.Problem
        The parametrised problem (``problem.is_dpp()`` is True), built once.
    A_param, B_param, d_param, x_r_param, u_r_param : cvxpy.Parameter
        :math:`A_1..A_{N-1}` stacked ((N-1) n, n) (a dummy (n, n) if N = 1),
        :math:`B_0..B_{N-1}` stacked (N n, m), :math:`[A_0 x_0 + c_0; c_1; ..; c_{N-1}]` (N, n),
        :math:`x^r_{1..N}` (N, n), :math:`u^r_{0..N-1}` (N, m). :meth:`solve` assigns them;
        five stacked parameters instead of 3N + 3 small ones, as each assignment costs
        cvxpy a value check.
    n_solves, n_fallbacks : int
        Calls to :meth:`solve` and how many of them returned a fallback plan.
    last_exception : BaseException or None
        The exception the solver raised in the last call, if any.
    """

    def _setup(self) -> None:
        N, n, m = self.N, self.n, self.m
        self.A_param = cp.Parameter((max(N - 1, 1) * n, n), name="A")  # A_1..A_{N-1} stacked (unused if N = 1)
        self.B_param = cp.Parameter((N * n, m), name="B")  # B_0..B_{N-1} stacked
        self.d_param = cp.Parameter((N, n), name="d")  # [A_0 x_0 + c_0; c_1; ..; c_{N-1}]
        self.x_r_param = cp.Parameter((N, n), name="x_r")
        self.u_r_param = cp.Parameter((N, m), name="u_r")
        A_rows = [self.A_param[(k - 1) * n: k * n] for k in range(1, N)]
        B_rows = [self.B_param[k * n: (k + 1) * n] for k in range(N)]
        self.problem, self._x, self._u = self._formulate(A_rows, B_rows, self.d_param, self.x_r_param, self.u_r_param)
        if not self.problem.is_dpp():  # pragma: no cover - guarded by the tests
            raise RuntimeError("internal error: the MPC problem is not DPP")

    def _solve_qp(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, x_r: np.ndarray,
                  u_r: np.ndarray) -> tuple[str, np.ndarray | None, np.ndarray | None, float]:
        N, n, m = self.N, self.n, self.m
        d = c.copy()
        d[0] += A[0] @ x0
        if N > 1:
            self.A_param.value = A[1:].reshape((N - 1) * n, n)
        else:
            self.A_param.value = np.zeros((n, n))
        self.B_param.value = B.reshape(N * n, m)
        self.d_param.value = d
        self.x_r_param.value = x_r
        self.u_r_param.value = u_r
        self.problem.solve(solver=self.solver, warm_start=True, enforce_dpp=True, **self.solver_options)
        return self.problem.status, self._u.value, self._x.value, _solver_time(self.problem)


class RebuildMPC(_MPCBase):
    """Same API and QP as :class:`LinearizedMPC`, but a new cvxpy Problem from constants at every call.

    The straightforward way; kept for the benchmark ratio (``benchmarks/bench_mpc.py``).
    """

    def _solve_qp(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, x_r: np.ndarray,
                  u_r: np.ndarray) -> tuple[str, np.ndarray | None, np.ndarray | None, float]:
        d = c.copy()
        d[0] += A[0] @ x0
        problem, x, u = self._formulate(list(A[1:]), list(B), d, x_r, u_r)
        problem.solve(solver=self.solver, **self.solver_options)
        return problem.status, u.value, x.value, _solver_time(problem)


def _solver_time(problem: cp.Problem) -> float:
    try:
        t = problem.solver_stats.solve_time
    except Exception:  # pragma: no cover - stats missing after some failures
        return math.nan
    return math.nan if t is None else float(t)


_OSQP_STATUS = {"solved": cp.OPTIMAL, "solved inaccurate": cp.OPTIMAL_INACCURATE}


class OSQPMPC(_MPCBase):
    r"""The QP of :class:`LinearizedMPC` handed to OSQP directly: set up once, then only ``update`` + ``solve``.

    Same constructor (``solver`` must be ``"OSQP"``), same :meth:`solve`, same
    fallback. With :math:`z = [x_1; ..; x_N; u_0; ..; u_{N-1}]` the problem is
    OSQP's :math:`\min \tfrac12 z^\top P z + q^\top z` s.t. :math:`l \le A_c z \le u` with

    * :math:`P = \mathrm{blkdiag}(Q, .., Q, Q_N, R, .., R)` (upper triangle),
      :math:`q = -[Q x^r_1; ..; Q_N x^r_N; R u^r_0; ..]` (half the cost of Eq. (28), same minimiser);
    * the dynamics as equality rows (:math:`l = u`):
      :math:`x_1 - B_0 u_0 = A_0 x_0 + c_0`,
      :math:`x_{k+1} - A_k x_k - B_k u_k = c_k`;
    * the boxes as identity rows on :math:`u_k` and on the bounded entries of :math:`x_k`.

    Every entry of every :math:`A_k, B_k` block is in the sparsity pattern
    (zeros included), so a new linearisation is one ``update(Ax=...)``; OSQP
    warm-starts from the last solution by itself.
    """

    def _setup(self) -> None:
        if self.solver != "OSQP":
            raise ValueError(f"OSQPMPC solves with OSQP only, got solver={self.solver!r}")
        N, n, m = self.N, self.n, self.m
        nx, nz = N * n, N * (n + m)
        rows, cols = [], []

        def block(r0: int, c0: int, h: int, w: int) -> None:
            r, c = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
            rows.append((r0 + r).ravel())
            cols.append((c0 + c).ravel())

        # pattern, in the order of the values written by _values(): identity, -A_1..-A_{N-1}, -B_0..-B_{N-1}
        rows.append(np.arange(nx))
        cols.append(np.arange(nx))
        for k in range(1, N):  # row block k holds x_{k+1} - A_k x_k - B_k u_k
            block(k * n, (k - 1) * n, n, n)
        for k in range(N):
            block(k * n, nx + k * m, n, m)
        # box rows: all u entries, the bounded x entries
        x_idx = np.flatnonzero(np.isfinite(self.x_lb) | np.isfinite(self.x_ub))
        box_cols = np.concatenate([np.arange(nx, nz)] + [k * n + x_idx for k in range(N)])
        rows.append(nx + np.arange(box_cols.size))
        cols.append(box_cols)
        r, c = np.concatenate(rows), np.concatenate(cols)
        labels = np.arange(1, r.size + 1, dtype=np.float64)
        A = sp.csc_matrix((labels, (r, c)), shape=(nx + box_cols.size, nz))
        A.sort_indices()
        self._perm = A.data.astype(np.int64) - 1  # CSC position -> index into the value vector
        self._n_eq = nx
        self._values = np.empty(r.size)
        self._values[:nx] = 1.0
        self._values[r.size - box_cols.size:] = 1.0
        self._sl_A = slice(nx, nx + (N - 1) * n * n)
        self._sl_B = slice(self._sl_A.stop, self._sl_A.stop + N * n * m)
        # bounds: equality rows are rewritten every step, box rows are fixed
        self._l = np.concatenate([np.zeros(nx), np.tile(self.u_lb, N), np.tile(self.x_lb[x_idx], N)])
        self._u = np.concatenate([np.zeros(nx), np.tile(self.u_ub, N), np.tile(self.x_ub[x_idx], N)])
        Qs = [_as_matrix(self.Q)] * (N - 1) + [_as_matrix(self.Q_N)] + [_as_matrix(self.R)] * N
        self._P = sp.triu(sp.block_diag(Qs, format="csc"), format="csc")
        self._q = np.zeros(nz)
        self._solver = osqp.OSQP()
        pattern = sp.csc_matrix((np.ones_like(A.data), A.indices, A.indptr), shape=A.shape)  # values come per solve
        self._solver.setup(self._P, self._q, pattern, self._l, self._u, verbose=False, **self.solver_options)

    def _solve_qp(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, x_r: np.ndarray,
                  u_r: np.ndarray) -> tuple[str, np.ndarray | None, np.ndarray | None, float]:
        N, n, m = self.N, self.n, self.m
        d = c.copy()
        d[0] += A[0] @ x0  # x_1 - B_0 u_0 = A_0 x_0 + c_0
        vals = self._values
        vals[self._sl_A] = -A[1:].ravel()
        vals[self._sl_B] = -B.ravel()
        eq = d.ravel()
        self._l[: self._n_eq] = eq
        self._u[: self._n_eq] = eq
        q = self._q
        q[: (N - 1) * n] = -_weigh(self.Q, x_r[:-1]).ravel()
        q[(N - 1) * n: N * n] = -_weigh(self.Q_N, x_r[-1:]).ravel()
        q[N * n:] = -_weigh(self.R, u_r).ravel()
        self._solver.update(q=q, l=self._l, u=self._u, Ax=vals[self._perm])
        res = self._solver.solve(raise_error=False)
        status = _OSQP_STATUS.get(str(res.info.status), str(res.info.status))
        z = res.x
        if z is None or z.shape != (N * (n + m),):
            return status, None, None, float(res.info.solve_time)
        return status, z[N * n:].reshape(N, m), z[: N * n].reshape(N, n), float(res.info.solve_time)


def _as_matrix(W: np.ndarray) -> sp.spmatrix:
    return sp.diags(W) if W.ndim == 1 else sp.csc_matrix(W)


def _weigh(W: np.ndarray, E: np.ndarray) -> np.ndarray:
    """Rows ``W e`` for the rows ``e`` of ``E``; ``W`` diagonal (d,) or symmetric (d, d)."""
    return E * W if W.ndim == 1 else E @ W
