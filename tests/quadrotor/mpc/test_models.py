"""MPC prediction models (App. A.5.3-A.5.4): nominal/residual, the feedback cascade (Eqs. (7), (8), (11), (25))
and the adaptive last layer (Eqs. (29)-(30))."""

from __future__ import annotations

import math

import pytest
import torch

from fnnlib.quadrotor.residual import AdaptiveResidual, AeroResidual
from fnnlib.quadrotor.mpc.models import AdaptiveNNModel, FeedbackCascadeModel, PredictionModel, paper_models
from fnnlib.feedback import GainError
from fnnlib.quadrotor.presets import PAPER_BETA, PAPER_GAMMA, PAPER_L
from fnnlib.quadrotor.system import NOMINAL, TEST_TRUTH, Quadrotor

F64 = torch.float64
TS = 0.02
PLANT, TRUTH = Quadrotor(NOMINAL), Quadrotor(TEST_TRUTH)
HOVER = PLANT.hover_input()


def _x0() -> torch.Tensor:
    x = torch.zeros(12, dtype=F64)
    x[3:6] = torch.tensor([1.0, -0.5, 0.2])
    x[6:9] = torch.tensor([0.05, -0.03, 0.1])
    x[9:12] = torch.tensor([0.1, 0.0, -0.05])
    return x


def _inputs(t: int, N: int) -> torch.Tensor:
    """A plan's inputs at control step t: hover plus small, step-dependent changes."""
    g = torch.Generator().manual_seed(100 + t)
    return HOVER + 0.05 * (torch.rand(N, 4, generator=g, dtype=F64) - 0.5)


def _plan(model: PredictionModel, x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """The model's own rollout from the measured state: (N+1, 12), first row x."""
    xs = [x]
    for k in range(u.shape[0]):
        xs.append(model.phi(xs[-1], u[k]))
    return torch.stack(xs)


def _net(seed: int = 0) -> AeroResidual:
    torch.manual_seed(seed)
    return AeroResidual(hidden=(8, 8), activation="tanh").double()


# --------------------------------------------------------------------------- PredictionModel


def test_nominal_model_is_the_rk4_step_of_eq_27():
    m = PredictionModel("Nomi", PLANT, Ts=TS, substeps=2)
    x, u = _x0().expand(3, 12), _inputs(0, 3)
    torch.testing.assert_close(m.phi(x, u), PLANT.step(x, u, Ts=TS, substeps=2), rtol=0, atol=0)
    for k in (torch.zeros(3, dtype=torch.long), torch.tensor([0, 4, 9])):
        torch.testing.assert_close(m.step(x, u, k), m.phi(x, u), rtol=0, atol=0)
    torch.testing.assert_close(m.f(x, u), PLANT.f(x, u), rtol=0, atol=0)
    torch.testing.assert_close(m.xdot(x, u), PLANT.f(x, u), rtol=0, atol=0)
    m.observe(x[0])
    m.commit(torch.zeros(4, 12, dtype=F64), torch.zeros(3, 4, dtype=F64))
    m.reset()
    assert m.observer_error is None
    with pytest.raises(ValueError, match="Ts"):
        PredictionModel("bad", PLANT, Ts=0.0)


def test_residual_enters_the_velocity_equation_and_is_frozen():
    net = _net()
    m = PredictionModel("Neural", PLANT, net, Ts=TS)
    assert not any(p.requires_grad for p in net.parameters())
    x, u = torch.stack([_x0(), 2 * _x0()]), _inputs(0, 2)
    r = net(x)
    expected = PLANT.f(x, u).clone()
    expected[:, 3:6] += r
    torch.testing.assert_close(m.f(x, u), expected, rtol=1e-13, atol=1e-13)
    torch.testing.assert_close(m.phi(x, u), PLANT.step(x, u, Ts=TS, a_res_fn=net), rtol=0, atol=0)
    assert (m.phi(x, u) - PredictionModel("Nomi", PLANT, Ts=TS).phi(x, u))[:, 3:6].abs().min() > 0


# --------------------------------------------------------------------------- FeedbackCascadeModel


def test_gain_decay_eq_11():
    L = torch.diag(torch.linspace(1.0, 6.0, 12, dtype=F64))
    fb = FeedbackCascadeModel(PredictionModel("Nomi", PLANT, Ts=TS), L, beta=0.3, N=4)
    assert fb.L_stack.shape == (4, 12, 12) and fb.N == 4 and fb.name == "FB-Nomi"
    for k in range(4):
        torch.testing.assert_close(fb.L_stack[k], L * math.exp(-0.3 * k), rtol=1e-15, atol=0)
    scalar = FeedbackCascadeModel(PredictionModel("Nomi", PLANT, Ts=TS), 3.0, beta=0.1, N=2, name="FB")
    torch.testing.assert_close(scalar.L_stack[1], 3.0 * math.exp(-0.1) * torch.eye(12, dtype=F64), rtol=1e-15, atol=0)
    assert scalar.name == "FB"


def test_no_correction_before_the_first_commit_and_the_first_commit():
    N = 4
    fb = FeedbackCascadeModel(PredictionModel("Nomi", PLANT, Ts=TS), 3.0, beta=0.1, N=N)
    x, u, k = _x0().expand(N, 12), _inputs(0, N), torch.arange(N)
    fb.observe(_x0())  # before any commit: nothing to compare with
    assert fb.observer_error is None and fb.x_hat is None
    torch.testing.assert_close(fb.step(x, u, k), fb.phi(x, u), rtol=0, atol=0)
    torch.testing.assert_close(fb.xdot(x[0], u[0]), fb.f(x[0], u[0]), rtol=0, atol=0)
    plan_x = _plan(fb, _x0(), u) + 0.01  # any plan of the right shape
    fb.commit(plan_x, u)
    # every layer starts on the plan, so after the first commit x_hat = Phi(X, u)
    torch.testing.assert_close(fb.x_hat, fb.phi(plan_x[:-1], u), rtol=0, atol=1e-15)


def test_commit_is_eq_8_on_every_layer_and_step_is_eq_7():
    N, beta = 4, 0.2
    L = torch.diag(torch.linspace(1.0, 6.0, 12, dtype=F64))
    fb = FeedbackCascadeModel(PredictionModel("Nomi", PLANT, Ts=TS), L, beta=beta, N=N)
    u0, u1 = _inputs(0, N), _inputs(1, N)
    fb.commit(_plan(fb, _x0(), u0), u0)
    X = _plan(fb, _x0() + 0.02, u1)[:-1]  # a second plan that differs from the estimates
    old = fb.x_hat.clone()
    fb.commit(torch.cat([X, X[-1:]]), u1)
    for k in range(N):
        L_k = L * math.exp(-beta * k)
        expected = old[k] + (fb.phi(X[k], u1[k]) - X[k]) + TS * L_k @ (X[k] - old[k])
        torch.testing.assert_close(fb.x_hat[k], expected, rtol=1e-13, atol=1e-13)
    # the corrected step: Phi(x, u) + Ts L_k (x - x_hat^(k)), batched over k
    x, k = X + 0.1, torch.tensor([0, 1, 2, 3])
    corr = torch.stack([L * math.exp(-beta * i) @ (x[i] - fb.x_hat[i]) for i in range(N)])
    torch.testing.assert_close(fb.step(x, u1, k), fb.phi(x, u1) + TS * corr, rtol=1e-13, atol=1e-13)
    torch.testing.assert_close(fb.xdot(x[0], u1[0]), fb.f(x[0], u1[0]) + corr[0], rtol=1e-13, atol=1e-13)
    # reset forgets it
    fb.reset()
    assert fb.x_hat is None and fb.observer_error is None
    torch.testing.assert_close(fb.step(x, u1, k), fb.phi(x, u1), rtol=0, atol=0)


def test_layer_0_error_obeys_eq_25():
    """Measured states from a different vehicle; the plan's first row is the measured state:
    x_tilde_{t+1} = (I - Ts L) x_tilde_t + Ts Delta_t with Delta_t = (x_{t+1} - Phi(x_t, u_t)) / Ts."""
    N = 5
    L = torch.diag(torch.linspace(1.0, 6.0, 12, dtype=F64))
    fb = FeedbackCascadeModel(PredictionModel("Nomi", PLANT, Ts=TS), L, beta=0.1, N=N)
    A = torch.eye(12, dtype=F64) - TS * L
    x, x_tilde, Delta = _x0(), torch.zeros(12, dtype=F64), None
    for t in range(15):
        fb.observe(x)
        if t == 0:
            assert fb.observer_error is None
        else:
            # at the first commit every layer starts on the plan: the error before it counts as zero
            expected = A @ x_tilde + TS * Delta
            torch.testing.assert_close(fb.observer_error, expected, rtol=1e-12, atol=1e-13)
            x_tilde = fb.observer_error.clone()
        u = _inputs(t, N)
        plan = _plan(fb, x, u)
        plan[1:] += 0.05  # only the first row (the measured state) matters for layer 0
        fb.commit(plan, u)
        x_next = TRUTH.step(x, u[0], Ts=TS, substeps=4)
        Delta = (x_next - fb.phi(x, u[0])) / TS
        x = x_next
    assert float(x_tilde.abs().max()) > 1e-3  # the truth does differ from the model


def test_correction_converges_to_a_constant_residual():
    """With a constant extra acceleration a on the truth, Delta = [a Ts/2, a, 0, 0] exactly, and L x_tilde -> Delta:
    the corrected one-step prediction becomes exact while the uncorrected one keeps missing by Ts Delta."""
    N, Lg = 3, 20.0
    fb = FeedbackCascadeModel(PredictionModel("Nomi", PLANT, Ts=TS), Lg, beta=0.1, N=N)
    a = torch.tensor([0.4, -0.3, 0.8], dtype=F64)

    def truth_step(x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        return PLANT.step(x, u, Ts=TS, a_res_fn=lambda y: a.expand(*y.shape[:-1], 3))

    Delta = torch.cat([a * TS / 2, a, torch.zeros(6, dtype=F64)])
    x = _x0()
    for t in range(40):
        fb.observe(x)
        u = _inputs(t, N)
        fb.commit(_plan(fb, x, u), u)
        x_next = truth_step(x, u[0])
        torch.testing.assert_close((x_next - fb.phi(x, u[0])) / TS, Delta, rtol=1e-8, atol=1e-9)
        x = x_next
    fb.observe(x)
    torch.testing.assert_close(Lg * fb.observer_error, Delta, rtol=1e-6, atol=1e-7)
    torch.testing.assert_close(fb.xdot(x, HOVER) - fb.f(x, HOVER), Delta, rtol=1e-6, atol=1e-7)
    u = _inputs(99, N)
    true_next = truth_step(x, u[0])
    corrected = fb.step(x[None], u[:1], torch.zeros(1, dtype=torch.long))[0]
    assert float((corrected - true_next).abs().max()) < 1e-8
    assert float((fb.phi(x, u[0]) - true_next).abs().max()) > 1e-3


def test_cascade_refuses_unstable_gains_and_wrong_plans():
    base = PredictionModel("Nomi", PLANT, Ts=TS)
    with pytest.raises(GainError, match="unstable"):  # rho(I - 0.02 * 200 I) = 3
        FeedbackCascadeModel(base, 200.0, beta=0.1, N=10)
    with pytest.raises(GainError, match="positive definite"):
        FeedbackCascadeModel(base, -1.0, beta=0.1, N=10)
    with pytest.raises(ValueError, match="beta"):
        FeedbackCascadeModel(base, 3.0, beta=-0.1, N=10)
    fb = FeedbackCascadeModel(base, 3.0, beta=0.1, N=4)
    good_x, good_u = torch.zeros(5, 12, dtype=F64), torch.zeros(4, 4, dtype=F64)
    for px, pu in ((good_x[:4], good_u), (good_x, good_u[:3]), (good_x[:, :11], good_u), (good_x, good_u[:, :3])):
        with pytest.raises(ValueError, match="plan must be"):
            fb.commit(px, pu)
    assert fb.x_hat is None
    with pytest.raises(TypeError, match="AdaptiveResidual"):
        FeedbackCascadeModel(base, 3.0, beta=0.1, N=4, adaptive=True)


# --------------------------------------------------------------------------- adaptation


def test_adaptive_nn_adapts_only_after_an_observe_following_a_commit():
    net = _net()
    ad = AdaptiveResidual(net, Gamma=8.0)
    m = AdaptiveNNModel("AdapNN", PLANT, ad, Ts=TS)
    chi0 = ad.chi_hat.clone()
    x0, u = _x0(), _inputs(0, 3)
    m.observe(x0)
    assert torch.equal(ad.chi_hat, chi0)
    m.commit(_plan(m, x0, u), u)
    assert torch.equal(ad.chi_hat, chi0)
    pred = m.phi(x0, u[0])  # the model's prediction with the weights at commit time
    x1 = TRUTH.step(x0, u[0], Ts=TS, substeps=4)
    m.observe(x1)
    # chi_hat += Ts Gamma a_tilde phi(x_0)^T with a_tilde = (v_1 - v_hat_1) / Ts
    a_tilde = (x1[3:6] - pred[3:6]) / TS
    expected = chi0 + TS * 8.0 * torch.outer(a_tilde, ad.features(x0))
    torch.testing.assert_close(ad.chi_hat, expected, rtol=1e-12, atol=1e-14)
    assert not torch.equal(ad.chi_hat, chi0)
    m.reset()
    assert torch.equal(ad.chi_hat, chi0)
    m.observe(x1)  # nothing committed since the reset
    assert torch.equal(ad.chi_hat, chi0)
    with pytest.raises(TypeError, match="AdaptiveResidual"):
        AdaptiveNNModel("bad", PLANT, net, Ts=TS)


def test_adaptive_nn_with_a_perfect_prediction_does_not_move():
    ad = AdaptiveResidual(_net(), Gamma=8.0)
    m = AdaptiveNNModel("AdapNN", PLANT, ad, Ts=TS)
    x0, u = _x0(), _inputs(0, 2)
    m.commit(_plan(m, x0, u), u)
    m.observe(m.phi(x0, u[0]))
    torch.testing.assert_close(ad.chi_hat, ad.chi_0, rtol=0, atol=1e-15)


def test_adaptive_feedback_cascade_eq_30_with_the_observer_error():
    N = 3
    ad = AdaptiveResidual(_net(1), Gamma=5.0)
    fb = FeedbackCascadeModel(PredictionModel("AdapNN", PLANT, ad, Ts=TS), 3.0, beta=0.1, N=N, adaptive=True)
    assert fb.adaptive and fb.residual is ad
    chi0 = ad.chi_hat.clone()
    x0, u = _x0(), _inputs(0, N)
    fb.observe(x0)
    assert torch.equal(ad.chi_hat, chi0)
    fb.commit(_plan(fb, x0, u), u)
    assert torch.equal(ad.chi_hat, chi0)
    x1 = TRUTH.step(x0, u[0], Ts=TS, substeps=4)
    x_hat0 = fb.x_hat[0].clone()
    fb.observe(x1)
    x_tilde = x1 - x_hat0
    torch.testing.assert_close(fb.observer_error, x_tilde, rtol=0, atol=0)
    expected = chi0 + TS * 5.0 * torch.outer(x_tilde[3:6], ad.features(x1))
    torch.testing.assert_close(ad.chi_hat, expected, rtol=1e-12, atol=1e-14)
    fb.reset()
    assert torch.equal(ad.chi_hat, chi0) and fb.x_hat is None
    # the same cascade without adaptive=True leaves the weights alone
    plain = FeedbackCascadeModel(PredictionModel("NN", PLANT, ad, Ts=TS), 3.0, beta=0.1, N=N)
    plain.commit(_plan(plain, x0, u), u)
    plain.observe(x1)
    assert torch.equal(ad.chi_hat, chi0)
    plain.reset()


def test_paper_models_keep_their_adaptations_apart():
    residual, mlp = _net(0), _net(1)
    models = paper_models(residual, mlp, plant=PLANT, L=PAPER_L, beta=PAPER_BETA, N=4, Gamma=PAPER_GAMMA, Ts=TS)
    assert [m.name for m in models] == ["Nomi", "Neural", "MLP", "FB", "AdapNN", "FNN", "AdapFNN"]
    adap_nn, adap_fnn = models[4], models[6]
    assert adap_fnn.adaptive and adap_nn.residual is not adap_fnn.residual
    x0, u = _x0(), _inputs(0, 4)
    for m in models:
        m.reset()
        m.observe(x0)
        m.commit(_plan(m, x0, u), u)
        m.observe(TRUTH.step(x0, u[0], Ts=TS, substeps=4))
    # each adaptive model moved its own last layer; the shared offline network is untouched
    assert not torch.equal(adap_nn.residual.chi_hat, residual.last.weight)
    assert not torch.equal(adap_fnn.residual.chi_hat, residual.last.weight)
    assert not torch.equal(adap_nn.residual.chi_hat, adap_fnn.residual.chi_hat)
    x = torch.stack([x0, 2 * x0])
    torch.testing.assert_close(models[1].f(x, u[:2])[:, 3:6] - PLANT.f(x, u[:2])[:, 3:6], residual(x),
                               rtol=1e-12, atol=1e-12)
