"""The MPC flight test of Sec. 5.2: the Lissajous reference, the closed loop `fly`, and the tracking RMSE."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fnnlib.quadrotor.control.flatness import flat_reference
from fnnlib.quadrotor.control.lissajous import lissajous
from fnnlib.quadrotor.mpc import LinearizedMPC, OSQPMPC
from fnnlib.quadrotor.mpc.backends import Backend
from fnnlib.quadrotor.mpc.flight import FlightResult, FlightTest, fly, lissajous_reference, tracking_rmse
from fnnlib.quadrotor.mpc.models import FeedbackCascadeModel, PredictionModel
from fnnlib.quadrotor.presets import PAPER_LISSAJOUS, PAPER_MPC_WEIGHTS, PAPER_THETA_MAX
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, Quadrotor

F64 = torch.float64
N, TS, STEPS = 10, 0.02, 15
#: the loop settings these tests fly with unless they say otherwise: the torch reference, central
#: differences, 4 RK4 sub-steps of the truth
LOOP = {"Ts": TS, "substeps": 4, "backend": Backend("torch", "central")}
HOVER_EACH = NOMINAL.mass * NOMINAL.g / 4


def _mpc(cls: type = LinearizedMPC, cost: str = "as_written", **options: float) -> LinearizedMPC | OSQPMPC:
    """Eq. (28) with App. A.5.3's weights and boxes (as written unless ``cost`` says otherwise).

    Q = diag(100 x3, 50 x6, 1 x3), R = I, 0 <= u <= 4, |Theta| <= pi/2.
    """
    Q, R = np.array(PAPER_MPC_WEIGHTS["Q"]), np.array(PAPER_MPC_WEIGHTS["R"])
    x_lb, x_ub = np.full(12, -np.inf), np.full(12, np.inf)
    x_lb[6:9], x_ub[6:9] = -PAPER_THETA_MAX, PAPER_THETA_MAX
    return cls(N, Q, R, cost=cost, u_lb=np.zeros(4), u_ub=np.full(4, 4.0), x_lb=x_lb, x_ub=x_ub,
               **options)


def _fly(model, mpc, truth, x_r, u_r, *, x0=None, linearize_method=None, **options):
    """:func:`fly` on a :class:`FlightTest` with :data:`LOOP`, some settings changed."""
    loop = {**LOOP, **options}
    if linearize_method is not None:
        loop["backend"] = Backend("torch", linearize_method)
    return fly(model, mpc, FlightTest(truth, x_r, u_r, **loop), x0=x0)


def _nominal_model() -> PredictionModel:
    return PredictionModel("Nomi", Quadrotor(NOMINAL), Ts=TS)


@pytest.fixture(scope="module")
def reference() -> tuple[torch.Tensor, torch.Tensor]:
    return lissajous_reference(STEPS, N, Ts=TS, params=NOMINAL, curve=PAPER_LISSAJOUS)


# --------------------------------------------------------------------------- the reference


def test_reference_shapes_and_start(reference):
    x_r, u_r = reference
    assert x_r.shape == (STEPS + N + 1, 12) and u_r.shape == (STEPS + N, 4)
    assert x_r.dtype == u_r.dtype == F64
    # p(0) = [0, 0, h + r_z] = [0, 0, 1] for the paper's curve, v(0) = [r_x w_x, r_y w_y, 0]
    torch.testing.assert_close(x_r[0, :3], torch.tensor([0.0, 0.0, 1.0], dtype=F64), rtol=0, atol=1e-14)
    torch.testing.assert_close(x_r[0, 3:6], torch.tensor([math.pi, 2 * math.pi, 0.0], dtype=F64), rtol=0, atol=1e-12)
    # every row on the control grid t = k Ts
    ref = lissajous(np.arange(STEPS + N + 1) * TS, **PAPER_LISSAJOUS)
    torch.testing.assert_close(x_r[:, :3], torch.as_tensor(ref.p), rtol=0, atol=1e-14)
    torch.testing.assert_close(x_r[:, 3:6], torch.as_tensor(ref.v), rtol=0, atol=1e-12)
    # other parameters reach the curve
    x_r2, _ = lissajous_reference(2, 3, Ts=TS, params=NOMINAL,
                                   curve={**PAPER_LISSAJOUS, "h": -0.5, "r_z": 0.3, "r_x": 1.0, "T_x": 4.0})
    torch.testing.assert_close(x_r2[0, :3], torch.tensor([0.0, 0.0, -0.2], dtype=F64), rtol=0, atol=1e-14)
    assert x_r2.shape == (6, 12)


def test_reference_thrust(reference):
    _, u_r = reference
    # the collective thrust of flatness: sum_i u_i = m |g e3 - a|
    a = torch.as_tensor(lissajous(np.arange(STEPS + N) * TS, **PAPER_LISSAJOUS).a)
    T = NOMINAL.mass * torch.linalg.norm(torch.tensor([0.0, 0.0, NOMINAL.g], dtype=F64) - a, dim=-1)
    torch.testing.assert_close(u_r.sum(-1), T, rtol=1e-10, atol=1e-10)
    # hover-like on average: m g / 4 per motor, more where the curve accelerates (Jensen), under the 4 N box
    assert HOVER_EACH <= float(u_r.mean()) < 1.5 * HOVER_EACH
    assert float(u_r.min()) > 0 and float(u_r.max()) < 4.0
    # a slow Lissajous is a hover: m g / 4 within 1 %
    slow = {**PAPER_LISSAJOUS, "T_x": 60.0, "T_y": 60.0, "T_z": 60.0}
    _, u_slow = lissajous_reference(50, N, Ts=TS, params=NOMINAL, curve=slow)
    assert float(u_slow.mean()) == pytest.approx(HOVER_EACH, rel=1e-2)
    # the model's mass enters
    heavy = NOMINAL.replace(mass=1.33)
    _, u_heavy = lissajous_reference(50, N, Ts=TS, params=heavy, curve=slow)
    assert float(u_heavy.mean()) == pytest.approx(heavy.mass * heavy.g / 4, rel=1e-2)


# --------------------------------------------------------------------------- fly


def _check_shapes(res: FlightResult, steps: int) -> None:
    assert res.x.shape == (steps + 1, 12) and res.u.shape == (steps, 4) and res.x_ref.shape == (steps + 1, 12)
    for arr in (res.xdot_true, res.xdot_pred, res.x_tilde, res.delta):
        assert arr.shape == (steps, 12)
    assert res.t_linearize.shape == res.t_solve.shape == (steps,) and len(res.statuses) == steps
    for arr in (res.x, res.u, res.x_ref, res.xdot_true, res.xdot_pred, res.delta, res.t_linearize, res.t_solve):
        assert np.isfinite(arr).all()


def test_nominal_model_on_the_nominal_vehicle(reference):
    x_r, u_r = reference
    res = _fly(_nominal_model(), _mpc(), Quadrotor(NOMINAL), x_r, u_r, steps=STEPS)
    _check_shapes(res, STEPS)
    assert res.name == "Nomi" and res.n_fallbacks == 0 and set(res.statuses) == {"optimal"}
    np.testing.assert_array_equal(res.x[0], x_r[0].numpy())
    np.testing.assert_array_equal(res.x_ref, x_r[:STEPS + 1].numpy())
    assert (res.u >= 0).all() and (res.u <= 4).all()
    rmse = tracking_rmse(res.x, res.x_ref)
    assert rmse["norm"] < 1e-3 and rmse["mean_axis"] < 1e-3  # starts on a feasible reference of its own model
    # the model is the vehicle: same change rates, one-step residual only from 1 vs 4 RK4 sub-steps
    np.testing.assert_array_equal(res.xdot_pred, res.xdot_true)
    assert np.abs(res.delta).max() < 1e-5
    assert np.isnan(res.x_tilde).all()  # no observer in the nominal model
    assert res.wall_time > 0


def test_feedback_model_on_the_test_vehicle_obeys_eq_25(reference):
    """In the loop, the recorded layer-0 error follows Eq. (25) with the recorded residual delta, exactly."""
    x_r, u_r = reference
    steps, L = 12, 3.0  # the thrust saturates at 4 N from step 7 on
    model = FeedbackCascadeModel(_nominal_model(), L, beta=0.1, N=N)
    res = _fly(model, _mpc(), Quadrotor(TEST_TRUTH), x_r[:steps + N + 1], u_r[:steps + N], steps=steps)
    _check_shapes(res, steps)
    assert res.name == "FB-Nomi" and res.n_fallbacks == 0
    assert res.u.max() == 4.0  # the input box is active: the applied, clipped input is what the model is told
    assert np.isnan(res.x_tilde[0]).all() and np.isfinite(res.x_tilde[1:]).all()
    np.testing.assert_allclose(res.x_tilde[1], TS * res.delta[0], rtol=0, atol=1e-12)
    for t in range(1, steps - 1):
        np.testing.assert_allclose(res.x_tilde[t + 1], (1 - TS * L) * res.x_tilde[t] + TS * res.delta[t],
                                   rtol=0, atol=1e-12)
    # the vehicle differs from the model, and the model's change rate includes the correction L x_tilde
    assert np.abs(res.delta).max() > 1.0
    assert np.abs(res.xdot_pred - res.xdot_true).max() > 0


def test_linearizes_along_the_shifted_plan_from_the_measured_state(reference, monkeypatch):
    import fnnlib.quadrotor.mpc.backends as backends

    x_r, u_r = reference
    calls, plans = [], []
    real_linearize = backends.linearize

    def spy(step, x_bar, u_bar, k, **kw):
        calls.append((x_bar.clone(), u_bar.clone(), k.clone()))
        return real_linearize(step, x_bar, u_bar, k, **kw)

    monkeypatch.setattr(backends, "linearize", spy)
    mpc = _mpc()
    real_solve = mpc.solve

    def solve(*args):
        sol = real_solve(*args)
        plans.append((sol.x.copy(), sol.u.copy()))
        return sol

    mpc.solve = solve
    steps = 4
    res = _fly(_nominal_model(), mpc, Quadrotor(TEST_TRUTH), x_r[:steps + N + 1],
              u_r[:steps + N], steps=steps)
    assert len(calls) == steps
    for t, (x_bar, u_bar, k) in enumerate(calls):
        assert x_bar.shape == (N, 12) and u_bar.shape == (N, 4) and torch.equal(k, torch.arange(N))
        np.testing.assert_array_equal(x_bar[0].numpy(), res.x[t])  # the measured state first
        if t == 0:  # the reference at the first step
            torch.testing.assert_close(x_bar[1:], x_r[1:N], rtol=0, atol=0)
            torch.testing.assert_close(u_bar, u_r[:N], rtol=0, atol=0)
        else:  # then the previous plan shifted by one step, last input repeated
            px, pu = plans[t - 1]
            np.testing.assert_array_equal(x_bar[1:].numpy(), px[2:N + 1])
            np.testing.assert_array_equal(u_bar.numpy(), np.concatenate([pu[1:], pu[-1:]]))


def test_fly_refuses_a_reference_of_the_wrong_length(reference):
    x_r, u_r = reference
    model = _nominal_model()
    mpc = _mpc()
    with pytest.raises(ValueError, match="reference must be"):
        _fly(model, mpc, Quadrotor(NOMINAL), x_r[:-1], u_r, steps=STEPS)
    with pytest.raises(ValueError, match="reference must be"):
        _fly(model, mpc, Quadrotor(NOMINAL), x_r, u_r[:-1], steps=STEPS)
    with pytest.raises(ValueError, match="reference must be"):
        _fly(model, mpc, Quadrotor(NOMINAL), x_r, u_r, steps=STEPS + 1)
    with pytest.raises(ValueError, match="reference must be"):
        _fly(model, mpc, Quadrotor(NOMINAL), x_r[:, :9], u_r, steps=STEPS)
    with pytest.raises(ValueError, match="steps"):
        _fly(model, mpc, Quadrotor(NOMINAL), x_r, u_r, steps=0)
    bad = x_r.clone()
    bad[3, 4] = float("nan")
    with pytest.raises(ValueError, match="x_r"):
        _fly(model, mpc, Quadrotor(NOMINAL), bad, u_r, steps=STEPS)


# --------------------------------------------------------------------------- tracking_rmse


def test_tracking_rmse_by_hand():
    x_ref = np.zeros((4, 12))
    x = np.zeros((4, 12))
    x[:, :3] = [[1.0, 0.0, 0.0], [-1.0, 2.0, 0.0], [1.0, 0.0, 3.0], [-1.0, -2.0, 0.0]]
    x[:, 3:] = 7.0  # only positions count
    r = tracking_rmse(x, x_ref)
    assert r["x"] == pytest.approx(1.0)
    assert r["y"] == pytest.approx(math.sqrt(2.0))
    assert r["z"] == pytest.approx(1.5)
    assert r["mean_axis"] == pytest.approx((1.0 + math.sqrt(2.0) + 1.5) / 3)
    assert r["norm"] == pytest.approx(math.sqrt((1 + 5 + 10 + 5) / 4))
    assert tracking_rmse(x_ref + 1.0, x_ref + 1.0) == {"x": 0.0, "y": 0.0, "z": 0.0, "mean_axis": 0.0, "norm": 0.0}


# --------------------------------------------------------------------------- hover and a slow circle


def _circle_reference(steps: int, radius: float = 1.0, period: float = 8.0) -> tuple[torch.Tensor, torch.Tensor]:
    """p(t) = [r sin(w t), r cos(w t) - r, -1] with analytic derivatives, through flatness (zero yaw)."""
    t = torch.arange(steps + N + 1, dtype=F64) * TS
    w = 2 * math.pi / period
    derivs = []
    for order in range(5):  # d^n/dt^n sin(w t) = w^n sin(w t + n pi/2)
        ph = w * t + order * math.pi / 2
        p = torch.stack([radius * w**order * torch.sin(ph), radius * w**order * torch.cos(ph),
                         torch.zeros_like(t)], dim=-1)
        derivs.append(p)
    derivs[0] = derivs[0] + torch.tensor([0.0, -radius, -1.0], dtype=F64)
    x_r, u_r = flat_reference(torch.cat(derivs[:4], dim=-1), derivs[4], params=NOMINAL)
    return x_r, u_r[:-1]


@pytest.mark.parametrize("mpc_cls", [LinearizedMPC, OSQPMPC])
def test_nominal_mpc_holds_hover_and_returns_to_it(mpc_cls):
    """Hover: held to 1e-6 m at m g / 4 per motor; from 0.5 m (x) and 0.3 m (z) off, back monotonically.

    With the paper's weights and a 0.2 s horizon (terminal weight = Q) the MPC is slow to
    regulate a large offset: in 2 s the distance falls by about 27 % (time constant ~7 s in x,
    ~3 s in z), with no overshoot and the attitude within 0.1 rad. Tolerances: > 20 % in 2 s,
    distance never growing, |Theta| < 0.1, |v| < 0.2 m/s.
    """
    steps = 100
    x_r = torch.zeros(steps + N + 1, 12, dtype=F64)
    u_r = torch.full((steps + N, 4), HOVER_EACH, dtype=F64)
    still = _fly(_nominal_model(), _mpc(mpc_cls), Quadrotor(NOMINAL), x_r, u_r,
                steps=steps)
    assert np.abs(still.x).max() < 1e-6
    np.testing.assert_allclose(still.u, HOVER_EACH, atol=1e-5)
    x0 = x_r[0].clone()
    x0[0], x0[2] = 0.5, 0.3
    res = _fly(_nominal_model(), _mpc(mpc_cls), Quadrotor(NOMINAL), x_r, u_r,
              steps=steps, x0=x0)
    assert res.n_fallbacks == 0
    dist = np.linalg.norm(res.x[:, :3], axis=1)
    assert np.diff(dist).max() <= 0.0
    assert dist[-1] < 0.8 * dist[0]
    assert np.abs(res.x[:, 6:9]).max() < 0.1 and np.abs(res.x[:, 3:6]).max() < 0.2
    assert abs(res.x[:, 1]).max() < 1e-9  # nothing pushes it sideways


@pytest.mark.parametrize("mpc_cls", [LinearizedMPC, OSQPMPC])
def test_nominal_mpc_tracks_a_slow_circle(mpc_cls):
    """A 1 m circle at 0.79 m/s (period 8 s) for 2 s, model = vehicle: position RMSE < 1 mm, max error < 2 mm."""
    steps = 100
    x_r, u_r = _circle_reference(steps)
    res = _fly(_nominal_model(), _mpc(mpc_cls), Quadrotor(NOMINAL), x_r, u_r,
              steps=steps)
    assert res.n_fallbacks == 0
    rmse = tracking_rmse(res.x, res.x_ref)
    assert rmse["norm"] < 1e-3
    assert np.linalg.norm(res.x[:, :3] - res.x_ref[:, :3], axis=1).max() < 2e-3
    # and it went round: a quarter of the circle in 2 s
    assert res.x[-1, 0] == pytest.approx(1.0, abs=0.01) and res.x[-1, 1] == pytest.approx(-1.0, abs=0.01)


def test_both_qp_implementations_fly_the_same_flight(reference):
    """The cvxpy problem and the direct OSQP one give the same applied inputs on the test vehicle."""
    x_r, u_r = reference
    tight = {"eps_abs": 1e-9, "eps_rel": 1e-9}
    runs = [_fly(FeedbackCascadeModel(_nominal_model(), 3.0, beta=0.1, N=N),
                _mpc(cls, **tight), Quadrotor(TEST_TRUTH), x_r, u_r, steps=STEPS) for cls in (LinearizedMPC, OSQPMPC)]
    np.testing.assert_allclose(runs[0].u, runs[1].u, rtol=0, atol=1e-6)
    np.testing.assert_allclose(runs[0].x, runs[1].x, rtol=0, atol=1e-7)


@pytest.mark.parametrize("mpc_cls", [LinearizedMPC, OSQPMPC])
def test_a_flight_does_not_depend_on_what_the_controller_flew_before(reference, mpc_cls):
    """fly() resets the controller, warm start included: the same flight twice gives the same bits."""
    x_r, u_r = reference
    mpc = _mpc(mpc_cls)
    model = lambda: FeedbackCascadeModel(_nominal_model(), 3.0, beta=0.1, N=N)  # noqa: E731
    first = _fly(model(), mpc, Quadrotor(TEST_TRUTH), x_r, u_r, steps=STEPS)
    _fly(_nominal_model(), mpc, Quadrotor(NOMINAL), x_r, u_r, steps=STEPS)
    again = _fly(model(), mpc, Quadrotor(TEST_TRUTH), x_r, u_r, steps=STEPS)
    np.testing.assert_array_equal(again.x, first.x)
    np.testing.assert_array_equal(again.u, first.u)


class _LeavesItsDomain(PredictionModel):
    """The nominal model, whose step is NaN on the calls listed in ``bad`` (1-based), as a model is outside the
    domain where it is finite (a diverging flight's plan, a state at gimbal lock)."""

    def __init__(self, bad: set[int] | None = None, bad_from: int | None = None) -> None:
        super().__init__("Nomi", Quadrotor(NOMINAL), Ts=TS)
        self.bad, self.bad_from, self.calls = bad or set(), bad_from, 0

    def step(self, x, u, k):
        self.calls += 1
        out = super().step(x, u, k)
        if self.calls in self.bad or (self.bad_from is not None and self.calls >= self.bad_from):
            out = torch.full_like(out, float("nan"))
        return out


def test_a_plan_outside_the_models_domain_is_replaced_by_the_reference(reference):
    """Step 1's plan linearizes to NaN: that step is linearized along the reference instead, counted, and the
    flight goes on; where even the reference gives NaN, fly stops with a clear error."""
    x_r, u_r = reference
    # "forward" linearizes with one call of step: call 1 is step 0 (reference), call 2 step 1's plan (NaN),
    # call 3 step 1 again along the reference
    run = _fly(_LeavesItsDomain(bad={2}), _mpc(OSQPMPC), Quadrotor(TEST_TRUTH), x_r, u_r, steps=STEPS,
              linearize_method="forward")
    assert run.n_reference_linearizations == 1 and run.n_fallbacks == 0
    assert np.isfinite(run.x).all() and np.isfinite(run.u).all()
    clean = _fly(_LeavesItsDomain(), _mpc(OSQPMPC), Quadrotor(TEST_TRUTH), x_r, u_r, steps=STEPS,
                linearize_method="forward")
    assert clean.n_reference_linearizations == 0
    assert 0 < np.abs(run.u[1] - clean.u[1]).max()  # step 1 did use another linearization point
    # nowhere to linearize: a clear error, not NaN in the QP
    with pytest.raises(ValueError, match="left the model's domain"):
        _fly(_LeavesItsDomain(bad_from=2), _mpc(OSQPMPC), Quadrotor(TEST_TRUTH), x_r, u_r, steps=STEPS,
            linearize_method="forward")
