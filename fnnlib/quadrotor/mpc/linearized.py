r"""Linear time-varying MPC, the QP form of Eq. (28) (App. A.5.3, ``Standard_MPC``), written once in cvxpy.

Along a linearisation :math:`x_{k+1} = A_k x_k + B_k u_k + c_k` (see
:func:`fnnlib.quadrotor.mpc.linearize`) Eq. (28) becomes the QP

.. math::
    \min_{x_{1:N},\, u_{0:N-1}} \;
        \sum_{k=1}^{N} \|x_k - x^r_k\|_{Q_k}^2 + \sum_{k=0}^{N-1} \|u_k - u^r_k\|_{R_k}^2

    \text{s.t.}\quad x_{k+1} = A_k x_k + B_k u_k + c_k,\; x_0 = x(0),\quad
    u_{lb} \le u_k \le u_{ub},\quad x_{lb} \le x_k \le x_{ub}\; (k \ge 1),

with the per-step weights :math:`Q_k, R_k` of one of two cost variants (``cost=``, required):

``"as_written"``
    Eq. (28) as the paper writes it: :math:`Q_k = Q` for :math:`k = 1..N-1`,
    :math:`Q_N` (default :math:`Q`; the paper's :math:`l_N = l_x`) on :math:`x_N`, and
    :math:`R_k = R` (the paper's :math:`R = I`) on every input :math:`u_0..u_{N-1}`.
``"as_flown"``
    The weighting of the authors' release, as its cost loop reads:
    :math:`Q_k = Q` for :math:`k = 1..N-1`, **no weight on** :math:`x_N`, and only the
    last input penalised, :math:`R_{N-1} = R`, :math:`R_k = 0` for :math:`k < N-1`. As
    :math:`u_{N-1}` moves only the unweighted :math:`x_N`, the inputs are in effect free
    (within their box). This is how the paper's numbers were flown.

Three classes solve it, all through the one cvxpy formulation :meth:`_MPCBase._formulate`:

* :class:`LinearizedMPC`: the problem built once with ``cp.Parameter`` data (DPP) and
  re-solved warm through ``problem.solve`` (any of :data:`SOLVERS`);
* :class:`OSQPMPC` (the fast path): the same parametrised problem, canonicalised once by
  cvxpy (``problem.get_problem_data(cp.OSQP)``); each step applies cvxpy's DPP parameter
  tensor to the new parameter vector and ``update``\ s one OSQP object in place;
* :class:`RebuildMPC`: a new problem from constants at every call (the benchmark's baseline).

Every solve is guarded (:meth:`_MPCBase.solve`): data that is not finite or reaches
OSQP's infinity (:data:`OSQP_INFTY`), a solver status other than optimal, or a plan
outside the boxes or off the dynamics (beyond :data:`PLAN_TOL`) is a *fallback*, with its
reason recorded (:attr:`MPCSolution.reason`, :attr:`_MPCBase.fallback_reasons`). The
fallback flies the last usable plan for at most N steps, then the reference input.

DPP note: :math:`A_0 x_0` would be a parameter times a parameter, which is not
DPP. The first row is therefore written :math:`x_1 = d_0 + B_0 u_0` with the
parameter :math:`d_0 = A_0 x_0 + c_0` computed in numpy; the decision variables
stay :math:`x_{1:N}, u_{0:N-1}` exactly as in Eq. (28). A diagonal weight is
written as :math:`\sum_i w_i e_i^2` expanded (:math:`w_i x_i^2 - 2 w_i x^r_i x_i`, the
constant :math:`w_i (x^r_i)^2` dropped: same minimiser), which cvxpy canonicalises
without auxiliary variables; a full weight is a ``quad_form``.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np
import osqp
import scipy.sparse as sp
from numpy.typing import ArrayLike

SOLVERS = ("OSQP", "CLARABEL")
COSTS = ("as_written", "as_flown")
USABLE_STATUSES = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)

OSQP_INFTY = 1e30
"""OSQP's infinity. osqp clips ``l``/``u`` to +-1e30 in ``update``; a finite equality right-hand side above it
leaves ``l > u``, the C library then rejects the whole vector update (``q`` included) and the next solve runs on
the previous step's data. Data at or above it is therefore refused before any solve (a fallback)."""

PLAN_TOL = 1e-3
"""Relative tolerance for a usable plan: an entry may exceed its box by ``PLAN_TOL * max(1, |bound|)`` and the
dynamics residual may reach ``PLAN_TOL * (1 + |largest term|)``. Two orders above the solvers' default accuracy
(eps 1e-5) and far below any physical margin of the quadrotor's boxes (thrust 0..4 or 6 N, angles pi/2); a stale or
diverged solve (one seen: u = 4.4e19 against a box of [-1, 1]) misses it by many orders."""

FALLBACK_REASONS = ("data_not_finite", "data_too_large", "solver_error", "not_optimal", "solution_not_finite",
                    "outside_box", "dynamics_mismatch")
"""Why a solve fell back, in the order they are checked (see :meth:`_MPCBase.solve`)."""

DIVERGED_FALLBACK_SHARE = 0.1
"""A flight whose share of fallback steps exceeds this is marked diverged (:func:`is_diverged`).

A flight under a working controller has no fallbacks at all (the one paper-profile flight with
fallbacks is the runaway AdapNN at Gamma = 8, 278 of 300 steps, 93 %). Ten per cent is 30 of the paper's 300
steps: three full horizons (N = 10) flown on the fallback instead of an optimal plan, more than one lost plan
explains; beyond it the numbers describe the fallback, not the MPC with that model."""


def is_diverged(n_fallbacks: int, n_steps: int, share: float = DIVERGED_FALLBACK_SHARE) -> bool:
    """True when more than ``share`` of ``n_steps`` control steps were fallbacks (see :data:`DIVERGED_FALLBACK_SHARE`)."""
    if n_steps < 1:
        raise ValueError(f"n_steps must be >= 1, got {n_steps}")
    if not 0.0 <= share < 1.0:
        raise ValueError(f"share must be in [0, 1), got {share}")
    return n_fallbacks > share * n_steps


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
        The solver's status as cvxpy reports it (``"optimal"``, ``"infeasible"``, ...),
        ``"solver_error: <exception>"`` when the solver raised, ``"not_solved"`` when the guard
        refused the data before any solve.
    ok : bool
        True when the plan is this solve's and the solver reported ``"optimal"``.
    solve_time_s : float
        Wall time of the whole call (checks, parameter assignment, solve, unpacking).
    fallback : bool
        True when ``u``/``x`` are not this solve's solution but the fallback plan; see :meth:`LinearizedMPC.solve`.
    solver_time_s : float
        Time the solver itself reports; NaN if unavailable.
    reason : str
        Why the solve fell back, one of :data:`FALLBACK_REASONS`; ``""`` for a usable plan.
    reference_input : bool
        True when the fallback flew the clipped reference input (no usable plan left).
    """

    u: np.ndarray
    x: np.ndarray
    status: str
    ok: bool
    solve_time_s: float
    fallback: bool
    solver_time_s: float = math.nan
    reason: str = ""
    reference_input: bool = False


class _UnsafeData(Exception):
    """Raised by an implementation whose derived solver data fails the guard; carries the reason."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def _data_reason(*arrays: np.ndarray) -> str:
    """``"data_not_finite"``, ``"data_too_large"`` (some ``|entry| >= OSQP_INFTY``) or ``""``."""
    for a in arrays:
        if not np.isfinite(a).all():
            return "data_not_finite"
    for a in arrays:
        if a.size and np.abs(a).max() >= OSQP_INFTY:
            return "data_too_large"
    return ""


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


def _as_data(value: ArrayLike, shape: tuple[int, ...], name: str, *, broadcast_rows: bool = False,
             finite: bool = True) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if broadcast_rows and a.shape == shape[1:]:
        a = np.broadcast_to(a, shape)
    if a.shape != shape:
        extra = f" or {shape[1:]}" if broadcast_rows else ""
        raise ValueError(f"{name} must have shape {shape}{extra}, got {a.shape}")
    if finite and not np.isfinite(a).all():
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
    """Checks, the one formulation of Eq. (28), the guard, the fallback and bookkeeping.

    The constructor arguments are documented on :class:`LinearizedMPC`.
    """

    def __init__(
        self,
        N: int,
        Q: ArrayLike,
        R: ArrayLike,
        *,
        cost: str,
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
        if cost not in COSTS:
            raise ValueError(f"cost must be one of {COSTS} (Eq. (28) as written, or the release's weighting), "
                             f"got {cost!r}")
        if cost == "as_flown" and Q_N is not None:
            raise ValueError("cost='as_flown' puts no weight on x_N; Q_N is for cost='as_written' only")
        self.N = int(N)
        self.cost = cost
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
        self._zero_counters()
        self._setup()

    def _zero_counters(self) -> None:
        self.n_solves = 0
        self.n_fallbacks = 0
        self.n_reference_fallbacks = 0
        self.n_consecutive_fallbacks = 0
        self.fallback_reasons: Counter[str] = Counter()
        self.last_exception: BaseException | None = None
        self._plan: tuple[np.ndarray, np.ndarray] | None = None
        self._good_u: np.ndarray | None = None

    def _setup(self) -> None:
        """Build what the implementation keeps between calls (after the checks)."""

    @staticmethod
    def _default_options(solver: str, eps_abs: float, eps_rel: float, max_iter: int) -> dict[str, Any]:
        if solver == "OSQP":
            # polishing off: with A_k changing every step cvxpy would otherwise polish after each refactorisation
            return {"eps_abs": eps_abs, "eps_rel": eps_rel, "max_iter": max_iter, "polishing": False}
        return {"tol_gap_abs": max(eps_abs, 1e-12), "tol_gap_rel": max(eps_rel, 1e-12),
                "tol_feas": max(eps_abs, 1e-12), "max_iter": max_iter}

    def weights(self) -> tuple[list[np.ndarray | None], list[np.ndarray | None]]:
        """The cost variant's weights: of :math:`x_1..x_N` and of :math:`u_0..u_{N-1}`, one entry per step (None: no weight)."""
        N = self.N
        if self.cost == "as_written":  # Eq. (28): Q on x_1..x_{N-1}, Q_N on x_N, R on u_0..u_{N-1}
            return [self.Q] * (N - 1) + [self.Q_N], [self.R] * N
        # the release: Q on x_1..x_{N-1}, nothing on x_N, R on u_{N-1} only
        return [self.Q] * (N - 1) + [None], [None] * (N - 1) + [self.R]

    # the one formulation of Eq. (28), shared by the parametrised and the rebuilt problem
    def _formulate(self, A_rows: list, B_rows: list, d: Any, x_r: Any, u_r: Any) -> tuple[cp.Problem, cp.Variable, cp.Variable]:
        """Problem with ``A_rows[k-1]`` = A_k (k >= 1), ``B_rows[k]`` = B_k, ``d`` (N, n) = [A_0 x_0 + c_0; c_1..c_{N-1}]."""
        N, n, m = self.N, self.n, self.m
        x = cp.Variable((N, n), name="x")  # x_1..x_N
        u = cp.Variable((N, m), name="u")  # u_0..u_{N-1}
        rows = [d[0] + B_rows[0] @ u[0]]  # x_1 = A_0 x_0 + c_0 + B_0 u_0
        rows += [A_rows[k - 1] @ x[k - 1] + B_rows[k] @ u[k] + d[k] for k in range(1, N)]  # x_{k+1} = A_k x_k + B_k u_k + c_k
        constraints = [x == (cp.vstack(rows) if N > 1 else cp.reshape(rows[0], (1, n), order="C"))]
        for var, lo, hi in ((u, self.u_lb, self.u_ub), (x, self.x_lb, self.x_ub)):
            i_lo, i_hi = np.flatnonzero(np.isfinite(lo)), np.flatnonzero(np.isfinite(hi))
            if i_lo.size:
                constraints.append(var[:, i_lo] >= np.broadcast_to(lo[i_lo], (N, i_lo.size)))
            if i_hi.size:
                constraints.append(var[:, i_hi] <= np.broadcast_to(hi[i_hi], (N, i_hi.size)))
        W_x, W_u = self.weights()
        cost = _tracking_cost(x, x_r, W_x) + _tracking_cost(u, u_r, W_u)
        return cp.Problem(cp.Minimize(cost), constraints), x, u

    def _check_step(self, x0: ArrayLike, A: ArrayLike, B: ArrayLike, c: ArrayLike, x_r: ArrayLike,
                    u_r: ArrayLike) -> tuple[np.ndarray, ...]:
        """Shapes (ValueError); a non-finite ``x0`` too. The data's values are the guard's job."""
        N, n, m = self.N, self.n, self.m
        return (_as_data(x0, (n,), "x0"), _as_data(A, (N, n, n), "A", finite=False),
                _as_data(B, (N, n, m), "B", finite=False), _as_data(c, (N, n), "c", finite=False),
                _as_data(x_r, (N, n), "x_r", broadcast_rows=True, finite=False),
                _as_data(u_r, (N, m), "u_r", broadcast_rows=True, finite=False))

    def _solve_qp(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, x_r: np.ndarray,
                  u_r: np.ndarray) -> tuple[str, np.ndarray | None, np.ndarray | None, float]:
        raise NotImplementedError

    def solve(self, x0: ArrayLike, A: ArrayLike, B: ArrayLike, c: ArrayLike, x_r: ArrayLike,
              u_r: ArrayLike) -> MPCSolution:
        r"""Solve Eq. (28) for one control step; never raises on bad data or a solver failure.

        Parameters
        ----------
        x0 : array_like, shape (n,)
            Current state :math:`x_0 = x(0)` (must be finite).
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
            A usable plan, or a fallback (``fallback=True``) with its ``reason``. Checked in order:

            1. the guard, before any solve: ``A, B, c, x_r, u_r`` (and the solver data the
               implementation derives from them) must be finite (``"data_not_finite"``) and
               below :data:`OSQP_INFTY` (``"data_too_large"``);
            2. the solver must not raise (``"solver_error"``) and must report optimal or
               optimal_inaccurate (``"not_optimal"``, the status is in ``status``);
            3. the plan must be finite (``"solution_not_finite"``), inside the input and state
               boxes (``"outside_box"``) and satisfy this call's dynamics
               (``"dynamics_mismatch"``, which a stale solve on the previous step's data fails),
               each to :data:`PLAN_TOL`.

            The fallback, for consecutive calls (= control steps): at the k-th fallback in a row,
            the last usable plan's inputs :math:`u_k..u_{N-1}` followed by this call's clipped
            reference for the steps past that plan, so the plan is flown for at most N steps
            (its N inputs each once, counting the step that solved it); from the N-th fallback
            in a row on (or with no usable plan yet), the clipped reference ``u_r``
            (counted in :attr:`n_reference_fallbacks`); a non-finite reference entry is replaced
            by the last returned input (the box's middle, or 0, before the first solve). ``x`` is that ``u`` rolled out through
            this call's linear model from ``x0`` (``x0`` repeated where that is not finite).

        Raises
        ------
        ValueError
            Wrong shapes, or a NaN/inf measured state ``x0`` (checked before any work).
        """
        t0 = time.perf_counter()
        x0, A, B, c, x_r, u_r = self._check_step(x0, A, B, c, x_r, u_r)
        self.n_solves += 1
        self.last_exception = None
        status, u, x, solver_time = "not_solved", None, None, math.nan
        reason = _data_reason(A, B, c, x_r, u_r)
        if not reason:
            try:
                status, u, x, solver_time = self._solve_qp(x0, A, B, c, x_r, u_r)
            except _UnsafeData as exc:
                reason = exc.reason
            except Exception as exc:  # a solver failure must never stop the control loop
                self.last_exception = exc
                status, reason = f"solver_error: {type(exc).__name__}: {exc}", "solver_error"
        if not reason:
            reason = self._plan_reason(status, x0, A, B, c, u, x)
        reference_input = False
        if not reason:
            assert u is not None and x is not None
            u_plan, x_plan = np.array(u, dtype=np.float64), np.vstack([x0, x])
            self._good_u, self.n_consecutive_fallbacks = u_plan.copy(), 0
        else:
            u_plan, reference_input = self._fallback_inputs(u_r)
            self.n_fallbacks += 1
            self.fallback_reasons[reason] += 1
            x_plan = self._rollout(x0, A, B, c, u_plan)
        self._plan = (x_plan, u_plan)
        return MPCSolution(u=u_plan.copy(), x=x_plan.copy(), status=status,
                           ok=not reason and status == cp.OPTIMAL, solve_time_s=time.perf_counter() - t0,
                           fallback=bool(reason), solver_time_s=solver_time, reason=reason,
                           reference_input=reference_input)

    def _plan_reason(self, status: str, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray,
                     u: np.ndarray | None, x: np.ndarray | None) -> str:
        """Step 2-3 of :meth:`solve`'s checks: ``""`` for a usable plan, else the reason."""
        if status not in USABLE_STATUSES:
            return "not_optimal"
        if u is None or x is None or not (np.isfinite(u).all() and np.isfinite(x).all()):
            return "solution_not_finite"
        for v, lo, hi in ((u, self.u_lb, self.u_ub), (x, self.x_lb, self.x_ub)):
            with np.errstate(invalid="ignore"):  # inf - inf where a bound is absent
                over = np.maximum(lo - v, v - hi) / np.maximum(1.0, np.abs(np.where(v < lo, lo, hi)))
            if (over > PLAN_TOL).any():
                return "outside_box"
        xs = np.vstack([x0, x])
        with np.errstate(all="ignore"):
            Ax, Bu = np.einsum("kij,kj->ki", A, xs[:-1]), np.einsum("kij,kj->ki", B, u)
            scale = 1.0 + np.max(np.abs(np.stack([xs[1:], Ax, Bu, c])), axis=0)
            err = np.abs(xs[1:] - Ax - Bu - c) / scale
        if not (err <= PLAN_TOL).all():
            return "dynamics_mismatch"
        return ""

    def _fallback_inputs(self, u_r: np.ndarray) -> tuple[np.ndarray, bool]:
        """The fallback inputs of :meth:`solve` (the last usable plan for at most N steps, then the reference).

        Returns the inputs (N, m) and whether they are the reference's."""
        self.n_consecutive_fallbacks += 1
        k, N = self.n_consecutive_fallbacks, self.N
        u_ref = np.clip(u_r, self.u_lb, self.u_ub)
        if not np.isfinite(u_ref).all():  # a broken reference: hold the last input (else the box's middle, or 0)
            mid = np.where(np.isfinite(self.u_lb + self.u_ub), 0.5 * (self.u_lb + self.u_ub), 0.0)
            hold = self._plan[1][0] if self._plan is not None else mid
            u_ref = np.where(np.isfinite(u_ref), u_ref, hold)
        if self._good_u is not None and k < N:
            return np.concatenate([self._good_u[k:], u_ref[N - k:]], axis=0), False
        self.n_reference_fallbacks += 1
        return u_ref, True

    def _rollout(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, u: np.ndarray) -> np.ndarray:
        """x_{k+1} = A_k x_k + B_k u_k + c_k from x0; x0 repeated if that is not finite."""
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
        """Start afresh: forget the plans and the solver's warm start, zero the counters.

        The solver state is rebuilt (:meth:`_setup`), so a flight after ``reset()`` gives the
        same numbers whatever was solved before it (the warm start moves iterates within
        the tolerance otherwise).
        """
        self._zero_counters()
        self._setup()


def _tracking_cost(E: cp.Variable, E_r: Any, Ws: list[np.ndarray | None]) -> cp.Expression:
    r""":math:`\sum_k \|e_k - e^r_k\|_{W_k}^2` over the rows of ``E`` (K, d), up to the constant :math:`\sum_k \|e^r_k\|_{W_k}^2`.

    ``Ws[k]`` is row k's weight: None (no term), diagonal (d,) or full (d, d). All diagonal: one expression
    :math:`\sum_{k,i} w_{ki} e_{ki}^2 - 2 \sum_{k,i} w_{ki} e^r_{ki} e_{ki}` on the whole variable, which cvxpy
    canonicalises without auxiliary variables (a slice ``E[k]`` would cost it one per entry). Otherwise row by
    row, :math:`\|F_k (e_k - e^r_k)\|^2` with :math:`F_k^\top F_k = W_k` (exact, constant included).
    """
    K, d = E.shape
    if all(W is None or W.ndim == 1 for W in Ws):
        Wb = np.stack([np.zeros(d) if W is None else W for W in Ws])
        return cp.sum(cp.multiply(Wb, cp.square(E))) - 2 * cp.sum(cp.multiply(cp.multiply(Wb, E_r), E))
    terms = [cp.sum_squares((E[k] - E_r[k]) @ _weight_factor(W).T) for k, W in enumerate(Ws) if W is not None]
    return cp.sum(cp.hstack(terms)) if terms else cp.Constant(0.0)


def _weight_factor(W: np.ndarray) -> np.ndarray:
    """F (r, d) with ||F e||^2 = e^T W e, from the eigendecomposition (W diagonal (d,) or symmetric (d, d))."""
    if W.ndim == 1:
        return np.diag(np.sqrt(W))
    lam, V = np.linalg.eigh(W)
    keep = lam > 1e-14 * max(1.0, float(lam.max()))
    return np.sqrt(lam[keep])[:, None] * V[:, keep].T


# --- the implementations ---------------------------------------------------------------------------------------

class LinearizedMPC(_MPCBase):
    r"""Linear time-varying MPC of Eq. (28), built once with cvxpy Parameters (DPP) and re-solved warm.

    Parameters
    ----------
    N : int
        Horizon, >= 1.
    Q : array_like, shape (n,) or (n, n)
        State weight (diagonal or symmetric PSD) of :math:`x_1..x_{N-1}`.
    R : array_like, shape (m,) or (m, m)
        Input weight (diagonal or symmetric PD); on :math:`u_0..u_{N-1}` (``"as_written"``) or
        on :math:`u_{N-1}` only (``"as_flown"``).
    cost : {"as_written", "as_flown"}
        The cost variant (required, keyword): Eq. (28) as written, or the release's weighting; see
        the module docstring.
    Q_N : array_like, shape (n,) or (n, n), optional
        Terminal weight of :math:`x_N` (PSD) for ``cost="as_written"``; default ``Q``.
        Not allowed with ``"as_flown"`` (no weight on :math:`x_N`).
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
    fallback_reasons : collections.Counter
        Fallbacks per reason (keys from :data:`FALLBACK_REASONS`).
    n_reference_fallbacks : int
        Fallbacks that flew the reference input (no usable plan left).
    n_consecutive_fallbacks : int
        Fallbacks since the last usable plan.
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

    def _parameter_values(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, x_r: np.ndarray,
                          u_r: np.ndarray) -> tuple[np.ndarray, ...]:
        """Values of (A_param, B_param, d_param, x_r_param, u_r_param) for one step; refuses an unsafe ``d``."""
        N, n, m = self.N, self.n, self.m
        with np.errstate(all="ignore"):
            d = c.copy()
            d[0] += A[0] @ x0  # x_1 - B_0 u_0 = A_0 x_0 + c_0
        reason = _data_reason(d)
        if reason:
            raise _UnsafeData(reason)
        A_stack = A[1:].reshape((N - 1) * n, n) if N > 1 else np.zeros((n, n))
        return A_stack, B.reshape(N * n, m), d, x_r, u_r

    @property
    def parameters(self) -> tuple[cp.Parameter, ...]:
        """(A_param, B_param, d_param, x_r_param, u_r_param), in the order of :meth:`_parameter_values`."""
        return self.A_param, self.B_param, self.d_param, self.x_r_param, self.u_r_param

    def _solve_qp(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, x_r: np.ndarray,
                  u_r: np.ndarray) -> tuple[str, np.ndarray | None, np.ndarray | None, float]:
        for param, value in zip(self.parameters, self._parameter_values(x0, A, B, c, x_r, u_r)):
            param.value = value
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


class OSQPMPC(LinearizedMPC):
    r"""The fast path: :class:`LinearizedMPC`'s problem, canonicalised once by cvxpy, updated in one OSQP object.

    Same constructor (``solver`` must be ``"OSQP"``), same :meth:`solve`, guard and fallback.
    At construction, ``problem.get_problem_data(cp.OSQP, enforce_dpp=True)`` gives cvxpy's
    parametrised QP (a ``ParamConeProg``): :math:`\min \tfrac12 z^\top P z + q(p)^\top z`
    s.t. :math:`A_{eq}(p) z + b_{eq}(p) = 0`, :math:`A_{in}(p) z + b_{in}(p) \ge 0`, with
    :math:`p` the flattened parameter vector (plus a constant 1) and every coefficient an
    entry of cvxpy's DPP parameter tensor (``reduced_A.reduced_mat``, ``q``) times
    :math:`p`. :math:`P` holds no parameter and is fixed. The tensor's sparsity pattern is
    fixed too, so OSQP is set up once on it (rows :math:`[A_{eq}; -A_{in}]`, bounds
    :math:`l = [-b_{eq}; -\infty]`, :math:`u = [-b_{eq}; b_{in}]`), and each step is

    1. :math:`p` from this step's :math:`A_{1..N-1}, B, d, x^r, u^r` (column-major, as cvxpy flattens);
    2. one sparse product of each tensor with :math:`p` (the values of ``Ax``, the bounds and ``q``);
    3. the guard on those values, ``update(q, l, u, Ax)`` and a warm ``solve``.

    osqp's Python ``update`` returns nothing (osqp 1.1.3 drops the C call's exit code, and
    a rejected vector update leaves the previous ``q, l, u`` in place); the guard refuses
    every input the C validation would reject (non-finite data, bounds at or above
    :data:`OSQP_INFTY`, where ``l > u`` would follow), and :meth:`solve`'s dynamics check
    would catch a stale solve anyway.

    Attributes
    ----------
    n_var, n_eq, n_ineq : int
        Size of cvxpy's canonical QP (variables, equality rows, inequality rows).
    """

    def _setup(self) -> None:
        if self.solver != "OSQP":
            raise ValueError(f"OSQPMPC solves with OSQP only, got solver={self.solver!r}")
        if not hasattr(self, "_T_A"):  # canonicalise once; reset() only rebuilds the OSQP object
            self._canonicalise()
        self._solver = osqp.OSQP()
        # copies: osqp keeps the matrices it is given and writes each update's Ax into their data
        self._solver.setup(self._P.copy(), np.zeros(self.n_var), self._A_pattern.copy(), self._lo0.copy(),
                           self._hi0.copy(), verbose=False, **self.solver_options)

    def _canonicalise(self) -> None:
        """The cvxpy problem, its canonical QP and the maps from the parameter vector to OSQP's data."""
        super()._setup()
        data, _, _ = self.problem.get_problem_data(cp.OSQP, enforce_dpp=True)
        prob = data[cp.settings.PARAM_PROB]
        self.n_var, self.n_eq, self.n_ineq = int(data["n_var"]), int(data["n_eq"]), int(data["n_ineq"])
        # the parameter vector p: our five parameters at their columns, the constant 1 at the remaining one
        cols = dict(prob.param_id_to_col)
        self._p = np.zeros(prob.total_param_size + 1)
        self._p_slots = []
        for p in self.parameters:  # A_param is absent for N = 1 (no A_1..A_{N-1}): its slot stays empty
            col = cols.pop(p.id, None)
            self._p_slots.append(slice(0, 0) if col is None else slice(col, col + p.size))
        if len(cols) != 1:  # pragma: no cover
            raise RuntimeError(f"internal error: unexpected parameter columns {cols}")
        self._p[next(iter(cols.values()))] = 1.0
        # constraint tensor: row j of reduced_mat gives entry j (CSC order) of [A_eq A_in | b] (rows, n_var + 1)
        prob.reduced_A.cache(keep_zeros=True)
        self._T_A = sp.csr_matrix(prob.reduced_A.reduced_mat)
        indices, indptr, shape = prob.reduced_A.problem_data_index
        row = np.asarray(indices, dtype=np.int64)
        col = np.repeat(np.arange(shape[1]), np.diff(indptr))
        in_matrix = col < self.n_var
        sign = np.where(row < self.n_eq, 1.0, -1.0)  # A_in z + b_in >= 0  <=>  -A_in z <= b_in
        pos = np.flatnonzero(in_matrix)
        labels = np.arange(1, pos.size + 1, dtype=np.float64)
        pattern = sp.csc_matrix((labels, (row[pos], col[pos])), shape=(shape[0], self.n_var))
        pattern.sort_indices()
        order = pattern.data.astype(np.int64) - 1  # CSC position -> index into pos
        self._A_pos, self._A_sign = pos[order], sign[pos[order]]
        off = np.flatnonzero(~in_matrix)
        self._eq_off, self._in_off = off[row[off] < self.n_eq], off[row[off] >= self.n_eq]
        self._eq_rows, self._in_rows = row[self._eq_off], row[self._in_off]
        self._lo = np.concatenate([np.zeros(self.n_eq), np.full(self.n_ineq, -np.inf)])
        self._hi = np.zeros(self.n_eq + self.n_ineq)
        # objective: q(p) from cvxpy's tensor; P constant (checked)
        self._T_q = sp.csr_matrix(prob.q)
        prob.reduced_P.cache(keep_zeros=False)
        T_P = sp.csc_matrix(prob.reduced_P.reduced_mat)
        if T_P[:, :-1].count_nonzero():  # pragma: no cover - the weights are constants
            raise RuntimeError("internal error: P depends on a parameter")
        P, _ = prob.reduced_P.get_matrix_from_tensor(self._p, with_offset=False)
        # variables in cvxpy's z, flattened column-major
        self._z_x = slice(prob.var_id_to_col[self._x.id], prob.var_id_to_col[self._x.id] + self._x.size)
        self._z_u = slice(prob.var_id_to_col[self._u.id], prob.var_id_to_col[self._u.id] + self._u.size)
        self._P = sp.triu(sp.csc_matrix(P), format="csc")
        self._A_pattern = sp.csc_matrix((np.ones(pattern.nnz), pattern.indices, pattern.indptr), shape=pattern.shape)
        self._lo0, self._hi0 = self._lo.copy(), np.where(np.arange(self._hi.size) < self.n_eq, 0.0, np.inf)

    def _solve_qp(self, x0: np.ndarray, A: np.ndarray, B: np.ndarray, c: np.ndarray, x_r: np.ndarray,
                  u_r: np.ndarray) -> tuple[str, np.ndarray | None, np.ndarray | None, float]:
        p = self._p
        for slot, value in zip(self._p_slots, self._parameter_values(x0, A, B, c, x_r, u_r)):
            if slot.stop > slot.start:
                p[slot] = value.ravel(order="F")  # cvxpy flattens parameters column-major
        with np.errstate(all="ignore"):
            flat = self._T_A @ p
            q = (self._T_q @ p)[: self.n_var]
        Ax = self._A_sign * flat[self._A_pos]
        l, u = self._lo, self._hi
        u[:] = 0.0
        l[: self.n_eq] = 0.0
        u[self._eq_rows] = -flat[self._eq_off]  # A_eq z = -b_eq
        l[self._eq_rows] = -flat[self._eq_off]
        u[self._in_rows] = flat[self._in_off]  # -A_in z <= b_in
        reason = _data_reason(Ax, q, u)
        if reason:
            raise _UnsafeData(reason)
        self._solver.update(q=q, l=l, u=u, Ax=Ax)
        res = self._solver.solve(raise_error=False)
        status = _OSQP_STATUS.get(str(res.info.status), str(res.info.status))
        z = res.x
        if z is None or z.shape != (self.n_var,):
            return status, None, None, float(res.info.solve_time)
        x = z[self._z_x].reshape((self.N, self.n), order="F")
        u_plan = z[self._z_u].reshape((self.N, self.m), order="F")
        return status, u_plan, x, float(res.info.solve_time)
