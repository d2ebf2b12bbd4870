"""The compiled (numba) twins of Eq. (27), its RK4 step and the step Jacobians, against the torch reference."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torch import nn

from fnnlib.quadrotor.residual import AdaptiveResidual, AeroResidual
from fnnlib.quadrotor.mpc import OSQPMPC
from fnnlib.quadrotor.mpc.compiled import CompiledModel, CompiledQuadrotor, residual_layers, warm_up
from fnnlib.quadrotor.mpc.backends import Backend
from fnnlib.quadrotor.mpc.flight import FlightTest, fly, lissajous_reference
from fnnlib.quadrotor.mpc.linearize import linearize
from fnnlib.quadrotor.mpc.models import paper_models
from fnnlib.quadrotor.presets import PAPER_LISSAJOUS, PAPER_MPC_WEIGHTS
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, Quadrotor

# one worker runs every test that compiles the numba kernels: they compile once (~8 s per network depth),
# not once per worker at the same moment
pytestmark = pytest.mark.xdist_group("numba")

F64 = torch.float64
N, TS = 10, 0.02


def _net(seed: int, hidden: tuple[int, ...] = (36, 36)) -> AeroResidual:
    torch.manual_seed(seed)
    net = AeroResidual(hidden, "tanh").double()
    with torch.no_grad():  # larger weights than the default init, so the network matters
        for p in net.parameters():
            p.mul_(3.0)
    return net


def _points(seed: int, B: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(B, 12)) * np.r_[np.ones(3), 2 * np.ones(3), 0.5 * np.ones(3), 2 * np.ones(3)]
    return X, rng.uniform(0.5, 4.0, size=(B, 4))


CASES = {
    "nominal": (NOMINAL, None),
    "test vehicle (drag, disturbance, mass, inertia)": (TEST_TRUTH, None),
    "nominal + residual": (NOMINAL, "aero"),
    "test vehicle + adaptive residual": (TEST_TRUTH, "adaptive"),
    "one hidden layer": (TEST_TRUTH, "shallow"),
}


def _case(name: str) -> tuple[Quadrotor, nn.Module | None]:
    params, kind = CASES[name]
    residual: nn.Module | None = None
    if kind == "aero":
        residual = _net(0)
    elif kind == "adaptive":
        residual = AdaptiveResidual(_net(1), 4.0)
        with torch.no_grad():
            residual.chi_hat.add_(0.3)  # as if adapted
    elif kind == "shallow":
        residual = _net(2, (20,))

    return Quadrotor(params), residual


@pytest.fixture(scope="module", autouse=True)
def _compiled():
    warm_up(_net(0), _net(2, (20,)))


@pytest.mark.parametrize("name", list(CASES))
def test_rate_and_step_equal_the_torch_reference(name):
    plant, residual = _case(name)
    cq = CompiledQuadrotor(plant, residual)
    X, U = _points(3, 25)
    Xt, Ut = torch.from_numpy(X), torch.from_numpy(U)
    with torch.no_grad():
        f_ref = plant.f(Xt, Ut, a_res=None if residual is None else residual(Xt)).numpy()
        for substeps in (1, 3):
            step_ref = plant.step(Xt, Ut, Ts=0.02, substeps=substeps, a_res_fn=residual).numpy()
            rate, step = cq.rate_and_step(X, U, 0.02, substeps)
            np.testing.assert_allclose(step, step_ref, rtol=0, atol=1e-13)
            np.testing.assert_allclose(rate, f_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cq.f(X, U), f_ref, rtol=0, atol=1e-12)
    # one row in, one row out; the input may be shared by all rows
    np.testing.assert_array_equal(cq.step(X[4], U[4], TS), cq.step(X, U, TS)[4])
    np.testing.assert_array_equal(cq.step(X[:3], U[1], TS), cq.step(X[:3], np.tile(U[1], (3, 1)), TS))


@pytest.mark.parametrize("name", list(CASES))
def test_step_jacobians_equal_torch_autograd(name):
    plant, residual = _case(name)
    cq = CompiledQuadrotor(plant, residual)
    X, U = _points(4, 6)
    for substeps in (1, 2):
        x_next, A, B = cq.step_jacobian(X, U, 0.02, substeps)
        np.testing.assert_allclose(x_next, cq.step(X, U, 0.02, substeps), rtol=0, atol=1e-14)
        for i in range(len(X)):
            JA, JB = torch.autograd.functional.jacobian(
                lambda x, u: plant.step(x, u, Ts=0.02, substeps=substeps, a_res_fn=residual), (torch.from_numpy(X[i]),
                                                                                   torch.from_numpy(U[i])))
            np.testing.assert_allclose(A[i], JA.numpy(), rtol=0, atol=1e-11)
            np.testing.assert_allclose(B[i], JB.numpy(), rtol=0, atol=1e-11)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3), st.lists(st.floats(-8, 8), min_size=6, max_size=6),
       st.lists(st.floats(0, 6), min_size=4, max_size=4))
def test_step_jacobians_anywhere_in_the_flight_envelope(angles, rates, u):
    """Angles up to 1.5 rad (cos(theta) down to 0.07, where W(Theta) grows), fast rotation, any thrust."""
    plant, residual = _case("test vehicle + adaptive residual")
    cq = CompiledQuadrotor(plant, residual)
    x = np.r_[0.1, -0.2, 0.3, rates[:3], angles, rates[3:]]
    _, A, B = cq.step_jacobian(x[None], np.asarray(u)[None], TS)
    JA, JB = torch.autograd.functional.jacobian(
        lambda x_, u_: plant.step(x_, u_, Ts=0.02, a_res_fn=residual), (torch.from_numpy(x), torch.as_tensor(u, dtype=F64)))
    scale = max(1.0, float(JA.abs().max()))
    np.testing.assert_allclose(A[0], JA.numpy(), rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(B[0], JB.numpy(), rtol=0, atol=1e-12 * scale)


def test_adaptation_is_seen_without_rebuilding():
    plant, residual = _case("test vehicle + adaptive residual")
    cq = CompiledQuadrotor(plant, residual)
    X, U = _points(5, 4)
    before = cq.step(X, U, TS)
    residual.adapt(torch.from_numpy(X[0]), torch.tensor([0.5, -0.2, 0.1], dtype=F64), 0.02)
    after = cq.step(X, U, TS)
    assert np.abs(after - before).max() > 1e-6
    with torch.no_grad():
        ref = plant.step(torch.from_numpy(X), torch.from_numpy(U), Ts=0.02, a_res_fn=residual).numpy()
    np.testing.assert_allclose(after, ref, rtol=0, atol=1e-13)
    residual.reset()
    np.testing.assert_allclose(cq.step(X, U, TS), CompiledQuadrotor(plant, AdaptiveResidual(_net(1), 4.0)).step(X, U, TS),
                               rtol=0, atol=0)


def test_refuses_what_it_cannot_compute():
    plant = Quadrotor(NOMINAL)
    with pytest.raises(TypeError, match="tanh"):
        CompiledQuadrotor(plant, AeroResidual((36, 36), "relu").double())
    with pytest.raises(TypeError, match="float64"):
        CompiledQuadrotor(plant, AeroResidual((36, 36), "tanh"))  # float32
    with pytest.raises(TypeError, match="AeroResidual or AdaptiveResidual"):
        residual_layers(nn.Linear(6, 3))
    with pytest.raises(TypeError, match="Quadrotor"):
        CompiledQuadrotor("plant")  # type: ignore[arg-type]
    cq = CompiledQuadrotor(plant)
    X, U = _points(6, 3)
    with pytest.raises(ValueError, match="shape"):
        cq.step(X[:, :11], U, TS)
    with pytest.raises(ValueError, match="same number of rows"):
        cq.step(X, U[:2], TS)
    X[1, 4] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        cq.step_jacobian(X, U, TS)
    with pytest.raises(ValueError, match="Ts"):
        cq.step(X[:1], U[:1], Ts=-0.02)


def _mid_flight_models(reference) -> list:
    """The seven models after a few steps of flight: cascades committed, adaptive layers moved."""
    x_r, u_r = reference
    models = paper_models(_net(0), _net(5), plant=Quadrotor(NOMINAL), L=3.0, beta=0.1, N=N, Ts=TS,
                          Gamma=4.0)
    mpc = OSQPMPC(N, np.array(PAPER_MPC_WEIGHTS["Q"]), np.array(PAPER_MPC_WEIGHTS["R"]), cost="as_written", u_lb=np.zeros(4),
                  u_ub=np.full(4, 6.0))
    for m in models:
        fly(m, mpc, FlightTest(Quadrotor(TEST_TRUTH), x_r[:N + 7], u_r[:N + 6], steps=6, Ts=TS, substeps=1,
                               backend=Backend("numba")))
    return models


@pytest.fixture(scope="module")
def reference():
    return lissajous_reference(40, N, Ts=TS, params=NOMINAL, curve=PAPER_LISSAJOUS)


def test_model_linearization_equals_autograd_of_model_step(reference):
    """CompiledModel.linearize == linearize(model.step, method="reverse") for all seven, feedback included."""
    x_r, u_r = reference
    x_bar, u_bar = x_r[3:3 + N].clone(), u_r[3:3 + N].clone()
    x_bar[0, :3] += 0.05
    for m in _mid_flight_models(reference):
        if m.name in ("FB", "FNN", "AdapFNN"):
            assert m.feedback_terms() is not None
        ref = linearize(m.step, x_bar, u_bar, torch.arange(N), method="reverse")
        got = CompiledModel(m).linearize(x_bar, u_bar)
        for field in ("A", "B", "c", "x_next"):
            np.testing.assert_allclose(getattr(got, field), getattr(ref, field), rtol=0, atol=1e-10,
                                       err_msg=f"{m.name}: {field}")
        cm = CompiledModel(m)
        rate, phi = cm.f_and_phi(x_bar, u_bar)
        with torch.no_grad():
            np.testing.assert_allclose(phi, m.phi(x_bar, u_bar).numpy(), rtol=0, atol=1e-13)
            np.testing.assert_allclose(rate, m.f(x_bar, u_bar).numpy(), rtol=0, atol=1e-12)


def test_numba_flight_equals_the_torch_flight(reference):
    """The same 30-step flight on both backends (torch with exact autograd Jacobians) for the models with
    feedback and adaptation; the loop's wall time is recorded on both."""
    x_r, u_r = reference
    Q = np.array(PAPER_MPC_WEIGHTS["Q"])
    steps = 30
    for name in ("Nomi", "FNN", "AdapFNN", "AdapNN"):
        runs = {}
        for backend in ("torch", "numba"):
            m = {mm.name: mm for mm in paper_models(_net(0), _net(5), plant=Quadrotor(NOMINAL), L=3.0, beta=0.1, N=N, Ts=TS,
                          Gamma=4.0)}[name]
            mpc = OSQPMPC(N, Q, np.ones(4), cost="as_written", u_lb=np.zeros(4), u_ub=np.full(4, 6.0))
            test = FlightTest(Quadrotor(TEST_TRUTH), x_r[:steps + N + 1], u_r[:steps + N], steps=steps, Ts=TS,
                              substeps=1, backend=Backend(backend, "reverse"))
            runs[backend] = fly(m, mpc, test)
        a, b = runs["torch"], runs["numba"]
        np.testing.assert_allclose(b.x, a.x, rtol=0, atol=1e-8, err_msg=name)
        np.testing.assert_allclose(b.u, a.u, rtol=0, atol=1e-6, err_msg=name)
        np.testing.assert_allclose(b.xdot_pred, a.xdot_pred, rtol=0, atol=1e-6, err_msg=name)
        np.testing.assert_allclose(b.xdot_true, a.xdot_true, rtol=0, atol=1e-6, err_msg=name)
        np.testing.assert_allclose(b.delta, a.delta, rtol=0, atol=1e-6, err_msg=name)
        if name in ("FNN", "AdapFNN"):
            np.testing.assert_allclose(b.x_tilde, a.x_tilde, rtol=0, atol=1e-8, err_msg=name)
        assert np.isfinite(b.elapsed_s) and b.real_time_factor > 0


def test_fly_refuses_an_unknown_backend_a_mismatched_Ts_and_a_torch_backend_without_method(reference):
    x_r, u_r = reference
    m = paper_models(_net(0), _net(5), plant=Quadrotor(NOMINAL), L=3.0, beta=0.1, N=N, Ts=TS, Gamma=4.0)[0]
    mpc = OSQPMPC(N, np.ones(12), np.ones(4), cost="as_written", u_lb=np.zeros(4), u_ub=np.full(4, 6.0))
    def test(Ts: float, backend: Backend) -> FlightTest:
        return FlightTest(Quadrotor(TEST_TRUTH), x_r[:N + 3], u_r[:N + 2], steps=2, Ts=Ts, substeps=1, backend=backend)

    with pytest.raises(ValueError, match="backend"):
        Backend("jax")
    with pytest.raises(ValueError, match="Ts"):
        fly(m, mpc, test(0.01, Backend("numba")))
    with pytest.raises(ValueError, match="linearize_method"):
        Backend("torch")
    with pytest.raises(TypeError, match="Backend"):
        test(TS, "torch")  # type: ignore[arg-type]


def test_the_plant_alone_shares_the_compilation_of_the_papers_networks():
    """numba compiles per argument types, and a tuple's length is one: the stand-in for no residual is as deep as
    the paper's networks (2 x 36 tanh), so a flight of the nominal model and one of a learned residual compile
    the kernels once, not twice (~8 s on a fresh cache)."""
    import numba  # noqa: PLC0415

    from fnnlib.quadrotor.presets import PAPER_RESIDUAL_RECIPE  # noqa: PLC0415

    plant = Quadrotor(NOMINAL)
    alone = CompiledQuadrotor(plant)
    learned = CompiledQuadrotor(plant, _net(0, PAPER_RESIDUAL_RECIPE["hidden"]))
    assert [numba.typeof(part) for part in alone._net] == [numba.typeof(part) for part in learned._net[:2]] + [
        numba.typeof(False)]
