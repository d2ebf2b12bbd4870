"""Minimum-snap reference flights for the quadrotor (App. A.5.4, Fig. S6 left): the training commands.

Random position waypoints in a box are joined by a minimum-snap piecewise polynomial (Mellinger & Kumar,
ICRA 2011) that starts and ends at rest. :func:`min_snap` solves the equality-constrained quadratic
programme in closed form; a :class:`MinSnapTrajectory` samples it. :func:`random_min_snap_flights` draws
a seeded data set of such flights, as flat outputs ``Psi = [p, v, a, j]`` (shape ``(T, 12)``) for the
differential-flatness controller of App. A.5.

Everything here is NumPy, float64; callers convert to torch with ``torch.as_tensor(psi)``. Frames: the
quadrotor model of this library is z-down, like the authors' release; the waypoint box has no effect on
the dynamics because gravity is uniform.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Iterable, Literal, NamedTuple, Sequence

import numpy as np
from numpy.typing import ArrayLike

from fnnlib.quadrotor.control.checks import FloatArray, as_float_array, check_finite_real, check_int, check_positive

__all__ = [
    "MinSnapFlights",
    "MinSnapTrajectory",
    "allocate_times",
    "min_snap",
    "random_min_snap_flights",
    "random_waypoints",
]

Box = Sequence[Sequence[float]]
Allocation = Literal["equal", "distance"]

_DEGREE = 7  # minimum snap: Euler-Lagrange of int |p''''|^2 dt gives p^(8) = 0
_N_COEF = _DEGREE + 1
_MAX_ORDER = _DEGREE  # derivatives above 7 vanish identically
_REST_ORDERS = (1, 2, 3)  # v = a = j = 0 at both ends


# --------------------------------------------------------------------------- validation

def _check_times(times: ArrayLike, *, name: str = "times") -> FloatArray:
    t = as_float_array(times, name=name, ndim=1)
    if t.size < 2:
        raise ValueError(f"{name} needs at least 2 entries, got {t.size}")
    if np.any(np.diff(t) <= 0.0):
        raise ValueError(f"{name} must be strictly increasing, got {t}")
    return t


def _check_waypoints(waypoints: ArrayLike, *, name: str = "waypoints") -> FloatArray:
    w = as_float_array(waypoints, name=name, ndim=2)
    if w.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n_waypoints, 3), got {w.shape}")
    if w.shape[0] < 2:
        raise ValueError(f"{name} needs at least 2 waypoints, got {w.shape[0]}")
    return w


def _check_box(box: Box) -> FloatArray:
    b = as_float_array(box, name="box", ndim=2)
    if b.shape != (3, 2):
        raise ValueError(f"box must have shape (3, 2) as ((x_lo, x_hi), (y_lo, y_hi), (z_lo, z_hi)), got {b.shape}")
    if np.any(b[:, 0] >= b[:, 1]):
        raise ValueError(f"box needs lo < hi on every axis, got {b.tolist()}")
    return b


def _check_order(order: object) -> int:
    if isinstance(order, bool) or not isinstance(order, numbers.Integral):
        raise TypeError(f"order must be an int, got {type(order).__name__}")
    if not 0 <= int(order) <= _MAX_ORDER:
        raise ValueError(f"order must be in 0..{_MAX_ORDER} (0 = p, 1 = v, 2 = a, 3 = j, 4 = snap), got {order}")
    return int(order)


# --------------------------------------------------------------------------- polynomial algebra


def _falling(order: int) -> FloatArray:
    """Falling factorials ``i! / (i - order)!`` for ``i = 0..7`` (zero where ``i < order``), shape ``(8,)``."""
    out = np.zeros(_N_COEF)
    for i in range(order, _N_COEF):
        out[i] = math.perm(i, order)
    return out


def _basis(tau: FloatArray, order: int) -> FloatArray:
    """Rows ``d^r/dtau^r [1, tau, ..., tau^7]`` at each ``tau``, shape ``(len(tau), 8)``."""
    fall = _falling(order)
    powers = np.clip(np.arange(_N_COEF) - order, 0, None)
    return fall[None, :] * tau[:, None] ** powers[None, :]


def _snap_gram() -> FloatArray:
    """``Q[i, j] = int_0^1 (d^4 tau^i / dtau^4)(d^4 tau^j / dtau^4) dtau``, shape ``(8, 8)``."""
    fall = _falling(4)
    Q = np.zeros((_N_COEF, _N_COEF))
    for i in range(4, _N_COEF):
        for j in range(4, _N_COEF):
            Q[i, j] = fall[i] * fall[j] / (i + j - 7)
    return Q


# --------------------------------------------------------------------------- minimum snap


@dataclass(frozen=True, eq=False)
class MinSnapTrajectory:
    r"""Piecewise degree-7 polynomial in 3-D, one piece per segment ``[t_k, t_{k+1}]``.

    On segment ``k`` with duration ``h_k = t_{k+1} - t_k`` the position is
    written in the *normalised time* ``tau = (t - t_k) / h_k`` in ``[0, 1]``:

    .. math:: p(t) = \sum_{i=0}^{7} c_{k,i} \tau^i, \qquad
              \frac{d^r p}{dt^r} = h_k^{-r} \frac{d^r p}{d\tau^r}.

    Working in ``tau`` keeps the coefficients of comparable size whatever the
    segment durations, which conditions the KKT system of :func:`min_snap`.

    Parameters
    ----------
    times : array_like, shape (K + 1,)
        Strictly increasing knot times ``t_0 < ... < t_K`` [s].
    coefficients : array_like, shape (K, 8, 3)
        ``coefficients[k, i, d]`` multiplies ``tau^i`` on segment ``k``, axis ``d``.

    Notes
    -----
    Usually built by :func:`min_snap`; constructing one by hand is allowed
    (the tests perturb the coefficients). Arrays are stored read-only.
    """

    times: FloatArray
    coefficients: FloatArray

    def __post_init__(self) -> None:
        t = _check_times(self.times)
        c = as_float_array(self.coefficients, name="coefficients", ndim=3)
        if c.shape != (t.size - 1, _N_COEF, 3):
            raise ValueError(f"coefficients must have shape (K, 8, 3) = ({t.size - 1}, 8, 3) for {t.size} times, got {c.shape}")
        t.setflags(write=False)
        c.setflags(write=False)
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "coefficients", c)

    # ---------------------------------------------------------------- geometry

    @property
    def n_segments(self) -> int:
        """Number of polynomial pieces ``K``."""
        return int(self.coefficients.shape[0])

    @property
    def durations(self) -> FloatArray:
        """Segment durations ``h_k``, shape ``(K,)``."""
        return np.diff(self.times)

    @property
    def t_start(self) -> float:
        """First knot time ``t_0``."""
        return float(self.times[0])

    @property
    def t_end(self) -> float:
        """Last knot time ``t_K``."""
        return float(self.times[-1])

    @property
    def waypoints(self) -> FloatArray:
        """Positions at the knots, shape ``(K + 1, 3)``."""
        start = self.coefficients[:, 0, :]  # tau = 0
        end = self.coefficients[-1].sum(axis=0)  # tau = 1 on the last piece
        return np.vstack([start, end[None, :]])

    # ---------------------------------------------------------------- evaluation

    def evaluate_segment(self, k: int, tau: ArrayLike, order: int = 0) -> FloatArray:
        """Derivative of order ``order`` (w.r.t. ``t``) of piece ``k`` at normalised times ``tau``.

        Gives one-sided limits at the knots: ``evaluate_segment(k, [1.0])`` is
        the left limit at ``t_{k+1}``, ``evaluate_segment(k + 1, [0.0])`` the
        right limit.

        Parameters
        ----------
        k : int
            Segment index in ``0..K-1``.
        tau : array_like, shape (N,)
            Normalised times, usually in ``[0, 1]`` (not checked: a polynomial
            can be extrapolated).
        order : int
            0 position, 1 velocity, 2 acceleration, 3 jerk, 4 snap, up to 7.

        Returns
        -------
        ndarray, shape (N, 3)
        """
        k = check_int(k, name="k", minimum=0)
        if k >= self.n_segments:
            raise ValueError(f"k must be < n_segments = {self.n_segments}, got {k}")
        r = _check_order(order)
        s = as_float_array(tau, name="tau", ndim=1)
        h = float(self.durations[k])
        return _basis(s, r) @ self.coefficients[k] / h**r

    def evaluate(self, t: ArrayLike, order: int = 0) -> FloatArray:
        """Derivative of order ``order`` at times ``t``.

        At an interior knot the right piece is used (the trajectory is C^6
        there, so both sides agree for ``order <= 6``).

        Parameters
        ----------
        t : array_like, shape (N,)
            Times in ``[t_0, t_K]`` (a round-off overshoot of ``1e-9`` times the
            span is clipped).
        order : int
            0 position, 1 velocity, 2 acceleration, 3 jerk, 4 snap (up to 7).

        Returns
        -------
        ndarray, shape (N, 3)

        Raises
        ------
        ValueError
            If a time lies outside ``[t_0, t_K]``.
        """
        r = _check_order(order)
        tt = as_float_array(t, name="t", ndim=1)
        tol = 1e-9 * max(1.0, self.t_end - self.t_start)
        if tt.size and (tt.min() < self.t_start - tol or tt.max() > self.t_end + tol):
            raise ValueError(
                f"t must lie in [t_0, t_K] = [{self.t_start:g}, {self.t_end:g}], got range [{tt.min():g}, {tt.max():g}]"
            )
        tt = np.clip(tt, self.t_start, self.t_end)
        idx = np.clip(np.searchsorted(self.times, tt, side="right") - 1, 0, self.n_segments - 1)
        h = self.durations[idx]
        tau = (tt - self.times[idx]) / h
        B = _basis(tau, r)  # (N, 8)
        return np.einsum("ni,nid->nd", B, self.coefficients[idx]) / h[:, None] ** r

    def node_times(self, Ts: float, n_nodes: int) -> FloatArray:
        """Sample times ``t_0 + i Ts``, ``i = 0..n_nodes-1``, shape ``(n_nodes,)``.

        Raises
        ------
        ValueError
            If ``Ts <= 0``, ``n_nodes < 1`` or the last node is past ``t_K``.
        """
        Ts = check_positive(Ts, name="Ts")
        n = check_int(n_nodes, name="n_nodes", minimum=1)
        t = self.t_start + Ts * np.arange(n)
        tol = 1e-9 * max(1.0, self.t_end - self.t_start)
        if t[-1] > self.t_end + tol:
            raise ValueError(
                f"(n_nodes - 1) * Ts = {(n - 1) * Ts:g} s exceeds the trajectory duration {self.t_end - self.t_start:g} s"
            )
        return t

    def flat_outputs(self, Ts: float, n_nodes: int) -> FloatArray:
        """Flat-output reference ``Psi = [p, v, a, j]`` on the node grid (App. A.5.2).

        Parameters
        ----------
        Ts : float
            Node spacing [s], > 0.
        n_nodes : int
            Number of nodes; ``(n_nodes - 1) * Ts`` must not exceed the duration.

        Returns
        -------
        ndarray, shape (n_nodes, 12)
            Columns ``[p_xyz, v_xyz, a_xyz, j_xyz]`` at ``t_0 + i Ts``.
        """
        t = self.node_times(Ts, n_nodes)
        return np.concatenate([self.evaluate(t, r) for r in range(4)], axis=1)

    def snap(self, Ts: float, n_nodes: int) -> FloatArray:
        """Snap ``d^4 p / dt^4`` on the node grid, shape ``(n_nodes, 3)``."""
        return self.evaluate(self.node_times(Ts, n_nodes), 4)

    def snap_cost(self) -> FloatArray:
        r"""Exact cost ``int_{t_0}^{t_K} (d^4 p_d / dt^4)^2 dt`` per axis ``d``, shape ``(3,)``.

        On piece ``k`` the integral is ``h_k^{-7} c_k^T Q c_k`` with
        ``Q_ij = int_0^1 (tau^i)''''(tau^j)'''' dtau``.
        """
        Q = _snap_gram()
        per_seg = np.einsum("kid,ij,kjd->kd", self.coefficients, Q, self.coefficients)
        return (per_seg / self.durations[:, None] ** 7).sum(axis=0)


def min_snap(waypoints: ArrayLike, times: ArrayLike, *, continuity: int = 4) -> MinSnapTrajectory:
    r"""Minimum-snap trajectory through ``waypoints`` at ``times`` (Mellinger & Kumar 2011).

    Per axis, ``K`` pieces of degree 7 minimise the snap cost

    .. math:: J = \int_{t_0}^{t_K} \| p^{(4)}(t) \|^2 \, Ts
              = \sum_k h_k^{-7} c_k^\top Q c_k

    subject to linear equalities ``A c = b``:

    * both ends of every piece on its waypoints (``2K`` rows);
    * rest at both ends, ``v = a = j = 0`` at ``t_0`` and ``t_K`` (6 rows);
    * continuity of derivatives ``1..continuity`` at the ``K - 1`` interior
      waypoints.

    The programme is solved in closed form as one KKT system

    .. math:: \begin{bmatrix} H & A^\top \\ A & 0 \end{bmatrix}
              \begin{bmatrix} c \\ \lambda \end{bmatrix}
              = \begin{bmatrix} 0 \\ b \end{bmatrix},

    with the same matrix for x, y and z (three right-hand sides). Each piece
    uses the normalised time ``tau = (t - t_k) / h_k`` in ``[0, 1]`` (see
    :class:`MinSnapTrajectory`); a continuity row for derivative ``r`` is
    multiplied by ``h_k^r / r!`` so its entries are binomial coefficients, and
    ``Q`` is divided by ``(4!)^2`` -- scalings that leave the minimiser
    unchanged but keep the system well conditioned.

    The optimum is C^6 at the interior waypoints whatever ``continuity`` in
    3..6 is imposed: the natural (Euler-Lagrange) conditions of the snap
    cost make derivatives 4, 5, 6 continuous when they are left free. With
    ``continuity=6`` the constraints alone fix the solution (``8K`` rows for
    ``8K`` unknowns); with the default 4 (Mellinger's "up to snap") the cost
    does real work and the tests can check optimality against feasible
    perturbations. All choices give the same trajectory to round-off.

    Parameters
    ----------
    waypoints : array_like, shape (K + 1, 3)
        Positions ``W``, ``K + 1 >= 2``.
    times : array_like, shape (K + 1,)
        Strictly increasing arrival times ``t_wp`` [s].
    continuity : int, keyword-only
        Highest derivative made continuous by constraint at interior
        waypoints, in 3..6 (default 4).

    Returns
    -------
    MinSnapTrajectory
        With ``coefficients`` of shape ``(K, 8, 3)``.

    Raises
    ------
    ValueError
        Fewer than 2 waypoints, shapes that disagree, NaN/inf entries,
        non-increasing times, or ``continuity`` outside 3..6.
    """
    W = _check_waypoints(waypoints)
    t = _check_times(times)
    if t.size != W.shape[0]:
        raise ValueError(f"times has {t.size} entries but there are {W.shape[0]} waypoints; they must match")
    m = check_int(continuity, name="continuity", minimum=3)
    if m > 6:
        raise ValueError(f"continuity must be in 3..6 (degree-7 pieces), got {m}")

    K = W.shape[0] - 1
    h = np.diff(t)
    n = _N_COEF * K
    zero, one = np.zeros(1), np.ones(1)

    rows: list[FloatArray] = []
    rhs: list[FloatArray] = []

    def row() -> FloatArray:
        return np.zeros(n)

    # waypoint positions: p_k(0) = W_k, p_k(1) = W_{k+1}
    for k in range(K):
        for tau, w in ((zero, W[k]), (one, W[k + 1])):
            a = row()
            a[_N_COEF * k : _N_COEF * (k + 1)] = _basis(tau, 0)[0]
            rows.append(a)
            rhs.append(w)
    # rest at both ends: d^r p / dtau^r = 0, r = 1, 2, 3 (the factor h^-r is irrelevant for 0)
    for r in _REST_ORDERS:
        scale = 1.0 / math.factorial(r)
        a = row()
        a[:_N_COEF] = scale * _basis(zero, r)[0]
        rows.append(a)
        rhs.append(np.zeros(3))
        a = row()
        a[_N_COEF * (K - 1) :] = scale * _basis(one, r)[0]
        rows.append(a)
        rhs.append(np.zeros(3))
    # continuity at interior knots: h_k^-r p_k^(r)(1) = h_{k+1}^-r p_{k+1}^(r)(0), times h_k^r / r!
    for k in range(K - 1):
        for r in range(1, m + 1):
            scale = 1.0 / math.factorial(r)
            a = row()
            a[_N_COEF * k : _N_COEF * (k + 1)] = scale * _basis(one, r)[0]
            a[_N_COEF * (k + 1) : _N_COEF * (k + 2)] = -scale * (h[k] / h[k + 1]) ** r * _basis(zero, r)[0]
            rows.append(a)
            rhs.append(np.zeros(3))

    A = np.vstack(rows)  # (n_con, 8K)
    b = np.vstack(rhs)  # (n_con, 3)

    # cost: sum_k h_k^-7 c_k^T Q c_k, scaled by h_mean^7 / (4!)^2 (same minimiser)
    Q = _snap_gram() / math.factorial(4) ** 2
    h_ref = float(h.mean())
    H = np.zeros((n, n))
    for k in range(K):
        sl = slice(_N_COEF * k, _N_COEF * (k + 1))
        H[sl, sl] = (h_ref / h[k]) ** 7 * Q

    n_con = A.shape[0]
    kkt = np.block([[H, A.T], [A, np.zeros((n_con, n_con))]])
    sol = np.linalg.solve(kkt, np.vstack([np.zeros((n, 3)), b]))
    coef = sol[:n].reshape(K, _N_COEF, 3)
    return MinSnapTrajectory(times=t, coefficients=coef)


def allocate_times(
    waypoints: ArrayLike,
    duration: float,
    *,
    allocation: Allocation = "equal",
    t0: float = 0.0,
) -> FloatArray:
    """Arrival times at the waypoints for a flight of total ``duration``.

    Parameters
    ----------
    waypoints : array_like, shape (K + 1, 3)
        The waypoints, ``K + 1 >= 2``.
    duration : float
        ``t_K - t_0`` [s], > 0.
    allocation : {"equal", "distance"}, keyword-only
        ``"equal"``: every segment lasts ``duration / K``. ``"distance"``:
        durations proportional to the straight-line segment lengths, each
        length floored at 10 % of the mean length so that (near-)coincident
        waypoints still get time.
    t0 : float, keyword-only
        Start time.

    Returns
    -------
    ndarray, shape (K + 1,)
        Strictly increasing times from ``t0`` to ``t0 + duration``.
    """
    W = _check_waypoints(waypoints)
    T = check_positive(duration, name="duration")
    start = check_finite_real(t0, name="t0")
    K = W.shape[0] - 1
    if allocation == "equal":
        weights = np.ones(K)
    elif allocation == "distance":
        dist = np.linalg.norm(np.diff(W, axis=0), axis=1)
        mean = float(dist.mean())
        weights = np.ones(K) if mean == 0.0 else np.maximum(dist, 0.1 * mean)
    else:
        raise ValueError(f"allocation must be 'equal' or 'distance', got {allocation!r}")
    times = start + T * np.concatenate([[0.0], np.cumsum(weights) / weights.sum()])
    times[-1] = start + T  # exact end despite round-off
    return times


def random_waypoints(
    n_waypoints: int,
    rng: np.random.Generator,
    *,
    box: Box,
) -> FloatArray:
    """Waypoints drawn uniformly in an axis-aligned box.

    Parameters
    ----------
    n_waypoints : int
        Number of waypoints, >= 2 (the authors' release uses 3 per
        200-node training flight).
    rng : numpy.random.Generator
        Source of randomness, e.g. ``numpy.random.default_rng(seed)``.
    box : sequence, shape (3, 2), keyword-only
        ``((x_lo, x_hi), (y_lo, y_hi), (z_lo, z_hi))`` [m]; the release's is
        :data:`~fnnlib.quadrotor.presets.PAPER_WAYPOINT_BOX`.

    Returns
    -------
    ndarray, shape (n_waypoints, 3)
    """
    n = check_int(n_waypoints, name="n_waypoints", minimum=2)
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator (numpy.random.default_rng(seed)), got {type(rng).__name__}")
    b = _check_box(box)
    return rng.uniform(b[:, 0], b[:, 1], size=(n, 3))


class MinSnapFlights(NamedTuple):
    """A seeded set of minimum-snap flights; unpacks as ``psi, snap, waypoints``.

    Attributes
    ----------
    psi : ndarray, shape (n_flights, n_nodes, 12)
        Flat outputs ``[p, v, a, j]`` on the nodes ``i Ts``.
    snap : ndarray, shape (n_flights, n_nodes, 3)
        Snap on the same nodes.
    waypoints : list of ndarray, each shape (n_waypoints, 3)
        The accepted waypoints of each flight.
    """

    psi: FloatArray
    snap: FloatArray
    waypoints: list[FloatArray]


def random_min_snap_flights(
    n_flights: int,
    n_nodes: int,
    *,
    Ts: float,
    seed: int,
    n_waypoints: int,
    box: Box,
    max_speed: float,
    allocation: Allocation = "equal",
    max_tries: int = 1000,
    progress: bool = False,
) -> MinSnapFlights:
    """Random rest-to-rest minimum-snap flights: the training references of App. A.5.4.

    For each flight, ``n_waypoints`` waypoints are drawn uniformly in ``box``
    (:func:`random_waypoints`), given arrival times over ``[0, (n_nodes - 1) Ts]``
    by :func:`allocate_times` (default: equal segment durations), and joined by
    :func:`min_snap`. A flight whose speed ``|v|`` exceeds ``max_speed`` on any
    node is rejected and redrawn (the release's acceptance rule, speed
    <= 10 m/s). All draws come from ``numpy.random.default_rng(seed)`` in
    order, so a seed fixes the whole set.

    Parameters
    ----------
    n_flights : int
        Number of flights, >= 1 (the paper uses 40).
    n_nodes : int
        Nodes per flight, >= 2 (the paper uses 200).
    Ts : float
        Node spacing [s], > 0 (the release uses 0.02).
    seed : int
        Seed for ``numpy.random.default_rng``.
    n_waypoints : int
        Waypoints per flight, >= 2 (the release uses 3).
    box : sequence, shape (3, 2)
        Waypoint box (the release's: :data:`~fnnlib.quadrotor.presets.PAPER_WAYPOINT_BOX`).
    max_speed : float
        Largest accepted speed [m/s], > 0 (the release's: 10).

    ``Ts`` and everything after it are keyword-only (:data:`~fnnlib.quadrotor.presets.PAPER_FLIGHT_DATA`
    holds the release's ``n_waypoints``, ``box`` and ``max_speed``).
    allocation : {"equal", "distance"}, keyword-only
        Time allocation, see :func:`allocate_times`.
    max_tries : int, keyword-only
        Draws allowed per flight before giving up.
    progress : bool, keyword-only
        Show a ``tqdm`` bar over flights.

    Returns
    -------
    MinSnapFlights
        ``(psi (n_flights, n_nodes, 12), snap (n_flights, n_nodes, 3), waypoints)``.

    Raises
    ------
    RuntimeError
        If ``max_tries`` draws in a row exceed ``max_speed``.
    """
    n_f = check_int(n_flights, name="n_flights", minimum=1)
    n = check_int(n_nodes, name="n_nodes", minimum=2)
    step = check_positive(Ts, name="Ts")
    seed = check_int(seed, name="seed", minimum=0)
    n_wp = check_int(n_waypoints, name="n_waypoints", minimum=2)
    b = _check_box(box)
    v_max = check_positive(max_speed, name="max_speed")
    tries = check_int(max_tries, name="max_tries", minimum=1)
    if allocation not in ("equal", "distance"):
        raise ValueError(f"allocation must be 'equal' or 'distance', got {allocation!r}")

    rng = np.random.default_rng(seed)
    duration = (n - 1) * step
    psi = np.empty((n_f, n, 12))
    snap = np.empty((n_f, n, 3))
    accepted: list[FloatArray] = []

    flights: Iterable[int] = range(n_f)
    if progress:
        from tqdm import tqdm

        flights = tqdm(flights, desc="min-snap flights")
    for i in flights:
        for _ in range(tries):
            W = random_waypoints(n_wp, rng, box=b)
            traj = min_snap(W, allocate_times(W, duration, allocation=allocation))
            flat = traj.flat_outputs(step, n)
            if float(np.linalg.norm(flat[:, 3:6], axis=1).max()) <= v_max:
                break
        else:
            raise RuntimeError(
                f"flight {i}: no draw in {tries} tries kept the speed <= max_speed = {v_max:g} m/s; "
                "raise max_speed, the duration (n_nodes * Ts) or shrink the box"
            )
        psi[i] = flat
        snap[i] = traj.snap(step, n)
        accepted.append(W)
    return MinSnapFlights(psi=psi, snap=snap, waypoints=accepted)
