"""The differentiable cascade and tune_gains: gradients against finite differences, admissible gains, B1 on a toy."""

from __future__ import annotations

import warnings

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fnnlib import NeuralODE, add_measurement_noise, cascade_predict, check_gain, tune_gains
from fnnlib.feedback import CascadeGains, GainWarning, cascade_forward, spectral_radius, Gains, TuneRecipe
from fnnlib.metrics import n_step_errors
from fnnlib.seeding import make_generator
from fnnlib.systems import LinearSystem
from fnnlib.feedback.tuning import prediction_loss

F64 = torch.float64


def _model(seed=0):
    torch.manual_seed(seed)
    return NeuralODE(2, [6], "tanh").double()


@pytest.mark.parametrize("full", [False, True], ids=["diagonal", "full"])
def test_gradient_matches_finite_differences(full):
    model, Ts, N = _model(), 0.05, 4
    x = torch.randn(25, 2, dtype=F64, generator=torch.Generator().manual_seed(1))
    gains = CascadeGains(2, Ts, L0=torch.tensor([3.0, 6.0]), beta0=0.1, full=full)

    def loss():
        return cascade_forward(model, x, Ts, N, gains).pow(2).sum()

    loss().backward()
    h = 1e-6
    for p in (gains.raw_L, gains.raw_beta, model.net[0].weight, model.net[-1].bias):
        assert p.grad is not None and bool(p.grad.abs().sum() > 0)
        for j in range(min(p.numel(), 4)):
            with torch.no_grad():
                p.view(-1)[j] += h
                plus = loss()
                p.view(-1)[j] -= 2 * h
                minus = loss()
                p.view(-1)[j] += h
            fd = float((plus - minus) / (2 * h))  # central difference, error ~ h^2
            assert float(p.grad.reshape(-1)[j]) == pytest.approx(fd, rel=1e-5, abs=1e-7)


@pytest.mark.parametrize("full", [False, True], ids=["diagonal", "full"])
def test_forward_equals_cascade_predict(full):
    model, Ts, N = _model(), 0.05, 6
    x = torch.randn(3, 40, 2, dtype=F64, generator=torch.Generator().manual_seed(2))
    gains = CascadeGains(2, Ts, L0=torch.tensor([3.0, 6.0]), beta0=0.07, full=full)
    vals = gains.values()
    L = torch.tensor(vals["L"], dtype=F64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GainWarning)
        ref = cascade_predict(model, x, Ts, N, Gains(L, vals["beta"]))
    torch.testing.assert_close(cascade_forward(model, x, Ts, N, gains).detach(), ref, rtol=0, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-30, 30), min_size=4, max_size=4), st.floats(-20, 20), st.booleans())
def test_any_raw_parameters_give_an_admissible_gain(raw, raw_beta, full):
    Ts = 0.02
    gains = CascadeGains(2, Ts, L0=10.0, beta0=0.1, full=full)
    with torch.no_grad():
        gains.raw_L.copy_(torch.tensor(raw, dtype=F64).reshape(2, 2) if full else torch.tensor(raw[:2], dtype=F64))
        gains.raw_beta.fill_(raw_beta)
        L = gains.L()
    M = torch.diag(L) if L.ndim == 1 else L
    if float(M.abs().max()) > 0:  # a sigmoid saturating to exactly 0 is L = 0: feedback off, accepted too
        assert float(torch.linalg.eigvalsh(0.5 * (M + M.T)).min()) >= 0
        assert spectral_radius(torch.eye(2, dtype=F64) - Ts * M) <= 1.0
    assert float(gains.beta().detach()) >= 0


def test_tuned_gains_beat_hand_picked_ones_and_the_open_loop_on_noisy_data():
    A_true = torch.tensor([[-0.1, 2.0], [-2.0, -0.1]], dtype=F64)
    model = LinearSystem(A_true * torch.tensor([[1.0, 0.8], [0.8, 1.0]], dtype=F64), torch.zeros(2, 1, dtype=F64))
    plant = LinearSystem(A_true, torch.zeros(2, 1, dtype=F64))
    Ts, T, N = 0.02, 300, 30
    t = torch.arange(T, dtype=F64) * Ts
    u = torch.zeros(T, 1, dtype=F64)
    gen = make_generator(0)
    x_tune, x_eval = plant.simulate(torch.tensor([5.0, 0.0]), t, u), plant.simulate(torch.tensor([0.0, 4.0]), t, u)
    y_tune, y_eval = add_measurement_noise(x_tune, 0.02, gen), add_measurement_noise(x_eval, 0.02, gen)
    tuned = tune_gains(model, y_tune, Ts, N, recipe=TuneRecipe(L0=5.0, beta0=0.05, iterations=60, lr=0.1), u=u)
    assert tuned.loss[-1] < tuned.loss[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GainWarning)
        err = {name: float(n_step_errors(cascade_predict(model, y_eval, Ts, N, Gains(L, b), u=u), x_eval, N).mean())
               for name, L, b in [("open", 0.0, 0.0), ("hand", 40.0, 0.0), ("tuned", tuned.L, tuned.beta)]}
    assert err["tuned"] < 0.9 * err["open"] and err["tuned"] < 0.9 * err["hand"], err


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match=r"initial gain L0 must lie in \(0, L_max"):
        CascadeGains(2, 0.1, L0=10.0, beta0=0.1)  # L_max = 1/Ts = 10
    with pytest.raises(ValueError, match="beta0 must be finite and > 0"):
        CascadeGains(2, 0.1, L0=1.0, beta0=0.0)
    with pytest.raises(ValueError, match="L_max = 30.0 allows rho"):
        CascadeGains(2, 0.1, L0=1.0, beta0=0.1, L_max=30.0)
    model = _model()
    with pytest.raises(ValueError, match="need more than N \\+ settle = 10 samples"):
        tune_gains(model, torch.randn(10, 2, dtype=F64), 0.1, 10,
                   recipe=TuneRecipe(L0=1.0, beta0=0.1, iterations=1, lr=0.1))
    with pytest.raises(ValueError, match="empty trajectory"):
        tune_gains(model, torch.randn(0, 2, dtype=F64), 0.1, 1,
                   recipe=TuneRecipe(L0=1.0, beta0=0.1, iterations=1, lr=0.1))


def test_frozen_model_is_left_without_gradients():
    model = _model()
    y = torch.randn(40, 2, dtype=F64, generator=torch.Generator().manual_seed(3))
    before = [p.detach().clone() for p in model.parameters()]
    tune_gains(model, y, 0.05, 3, recipe=TuneRecipe(L0=2.0, beta0=0.1, iterations=2, lr=0.1))
    assert all(torch.equal(a, b) for a, b in zip(before, model.parameters()))
    assert all(p.grad is None and p.requires_grad for p in model.parameters())
    check_gain(torch.tensor([1.0, 2.0]), None, 0.05)  # n implied by L


@pytest.mark.parametrize("with_inputs", [False, True], ids=["autonomous", "inputs"])
def test_rows_are_the_first_rows_of_the_whole_cascade(with_inputs):
    """``rows`` runs only the first start times; by causality they equal the whole run's, inputs included."""
    gen = torch.Generator().manual_seed(4)
    Ts, N, T, rows = 0.05, 5, 30, 12
    x = torch.randn(2, T, 2, dtype=F64, generator=gen)
    if with_inputs:
        torch.manual_seed(0)
        model, u = NeuralODE(2, [6], "tanh", n_input=1).double(), torch.randn(2, T, 1, dtype=F64, generator=gen)
    else:
        model, u = _model(), None
    gains = CascadeGains(2, Ts, L0=torch.tensor([3.0, 6.0]), beta0=0.1)
    whole = cascade_forward(model, x, Ts, N, gains, u=u)
    first = cascade_forward(model, x, Ts, N, gains, u=u, rows=rows)
    assert first.shape == (2, rows, 2)
    torch.testing.assert_close(first, whole[:, :rows], rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="rows must lie in 1..30"):
        cascade_forward(model, x, Ts, N, gains, rows=T + 1)


def test_tune_gains_equals_descent_on_the_whole_cascade():
    """tune_gains runs the T - N rows with a target only; the same Adam steps on the whole cascade agree."""
    model, Ts, N = _model(), 0.05, 4
    y = torch.randn(3, 25, 2, dtype=F64, generator=torch.Generator().manual_seed(5))
    tuned = tune_gains(model, y, Ts, N, recipe=TuneRecipe(L0=2.0, beta0=0.1, iterations=3, lr=0.2))
    gains = CascadeGains(2, Ts, L0=2.0, beta0=0.1)
    opt = torch.optim.Adam(gains.parameters(), lr=0.2)
    ref = []
    for _ in range(3):
        opt.zero_grad()
        loss = prediction_loss(cascade_forward(model, y, Ts, N, gains), y, N)
        loss.backward()
        opt.step()
        ref.append(loss.item())
    assert tuned.loss == pytest.approx(ref, rel=1e-12)
    assert tuned.L == pytest.approx(gains.values()["L"], rel=1e-12)
    assert tuned.beta == pytest.approx(gains.values()["beta"], rel=1e-12)


def test_sweep_gains_keeps_the_cheapest_pair_and_skips_diverged_ones():
    from fnnlib.feedback import sweep_gains

    calls = []

    def cost(L, beta):  # a bowl at L = 5, beta = 0.1; L = 20 "diverges"
        calls.append((L, beta))
        return float("nan") if L == 20 else (L - 5) ** 2 + (beta - 0.1) ** 2

    s = sweep_gains(cost, [2.0, 5.0, 20.0], [0.02, 0.1, 0.5])
    assert (s.L, s.beta) == (5.0, 0.1) and s.cost == 0.0 and len(calls) == 9
    assert s.table[2] == [float("inf")] * 3 and s.as_dict()["L_grid"] == [2.0, 5.0, 20.0]
    with pytest.raises(ValueError, match="no pair"):
        sweep_gains(lambda L, b: float("inf"), [1.0], [0.1])
    for bad in ([], [0.0], [float("nan")]):
        with pytest.raises(ValueError, match="L_grid"):
            sweep_gains(cost, bad, [0.1])
    with pytest.raises(ValueError, match="beta_grid"):
        sweep_gains(cost, [1.0], [-0.1])
