"""Batched sweeps equal the one-gain-at-a-time library calls; grids read like the paper's; bad inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fnnlib import GainError, LinearFeedback, cascade_predict
from fnnlib.systems import Spiral
from fnnlib._scan import linear_recurrence
from fnnlib.feedback import cascade_sweep, observe_gains, Gains
from fnnlib.paper.sweeps import (
    colon_range,
    n_step_errors,
    n_step_rmse,
    offset_spirals,
    outward_increase_fraction,
    paired_levels,
    residual_level_runs,
    simulate_levels,
    cascade_position_errors,
    level_errors,
    position_gain_sweep,
    position_gain_tuning,
    sweep_errors,
    switched_spiral_run,
)

F64 = torch.float64
TS = 0.05


@pytest.fixture(scope="module")
def x():
    """Two trajectories (levels) of 40 samples: shape (2, 40, 2)."""
    t = torch.arange(40, dtype=F64) * TS
    return simulate_levels([Spiral(3.0, 0.05, 1.0), Spiral(1.5, 0.2, -1.0)], torch.tensor([2.0, 0.0]), t)


# --- grids ------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("grid, count, last", [
    ((0, 5, 45), 10, 45.0),
    ((0.8, 0.4, 4.4), 10, 4.4),
    ((0.04, 0.02, 0.22), 10, 0.22),       # 0.18 / 0.02 is 8.999... in floating point
    ((-0.03, 0.005, 0.025), 12, 0.025),
    ((-14.4, 2.4, 12), 12, 12.0),
    ((-24, 8, 96), 16, 96.0),              # the paper's eps grid of Fig. 3 has 16 values, not 10
    ((0, 0.01, 0.06), 7, 0.06),
    ((1, 0.3, 2), 4, 1.9),                 # stop not on the grid: MATLAB stops before it
    ((5, -2, 0), 3, 1.0),
])
def test_colon_range_is_matlab_colon(grid, count, last):
    r = colon_range(*grid)
    assert r.dtype == F64 and r.numel() == count
    assert float(r[0]) == float(grid[0]) and float(r[-1]) == pytest.approx(last, abs=1e-12)


@pytest.mark.parametrize("grid", [(0, 0, 1), (0, -1, 1), (0, 1, float("nan"))])
def test_colon_range_refuses_empty_or_bad_grids(grid):
    with pytest.raises(ValueError, match="empty|non-finite"):
        colon_range(*grid)


def test_paired_levels_pairs_columns():
    levels = paired_levels(colon_range(0.8, 0.4, 4.4), colon_range(0.04, 0.02, 0.22), colon_range(-24, 8, 48))
    assert levels.shape == (10, 3)
    assert levels[3].tolist() == pytest.approx([2.0, 0.1, 0.0])  # level 3 is the nominal spiral
    with pytest.raises(ValueError, match=r"same length, got lengths \[10, 16\]"):
        paired_levels(colon_range(0.8, 0.4, 4.4), colon_range(-24, 8, 96))
    with pytest.raises(ValueError, match="at least one grid"):
        paired_levels()


def test_simulate_levels_stacks(x):
    assert x.shape == (2, 40, 2) and x.dtype == F64
    exact = Spiral(1.5, 0.2, -1.0).exact_solution(torch.tensor([2.0, 0.0]), torch.arange(40, dtype=F64) * TS)
    torch.testing.assert_close(x[1], exact, rtol=0, atol=1e-8)
    with pytest.raises(ValueError, match="at least one system"):
        simulate_levels([], torch.zeros(2), torch.arange(3.0))


# --- the batched scan and observer -------------------------------------------------------------------------------

def test_batched_diagonal_recurrence_matches_the_scan_per_batch():
    g = torch.Generator().manual_seed(1)
    a = torch.tensor([[0.9, -0.5], [1.05, 0.2], [-1.1, 0.0]], dtype=F64)  # stable, unstable, alternating
    b = torch.randn(3, 4, 33, 2, generator=g, dtype=F64)
    h0 = torch.randn(3, 4, 2, generator=g, dtype=F64)
    out = linear_recurrence(a[:, None, :], b, h0, diagonal=True)
    for i in range(3):
        torch.testing.assert_close(out[i], linear_recurrence(a[i], b[i], h0[i]), rtol=1e-13, atol=1e-13)
    h, ref = h0[1, 2], [h0[1, 2]]
    for k in range(33):  # and one by hand: h_{k+1} = a h_k + b_k
        h = a[1] * h + b[1, 2, k]
        ref.append(h)
    torch.testing.assert_close(out[1, 2], torch.stack(ref), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("L", [torch.tensor([0.0, 2.0, 7.5]), torch.tensor([[1.0, 3.0], [4.0, 0.5]])],
                         ids=["scalar_gains", "diagonal_gains"])
def test_observe_gains_equals_linear_feedback_per_gain(f, x, L):
    est = observe_gains(f, x, TS, L)
    assert est.x_hat.shape == est.f_hat.shape == (L.shape[0], 2, 40, 2)
    for g in range(L.shape[0]):
        one = LinearFeedback(f, TS, gains=Gains(L[g]), n=2).observe(x)
        torch.testing.assert_close(est.x_hat[g], one.x_hat, rtol=0, atol=1e-12)
        torch.testing.assert_close(est.f_hat[g], one.f_hat, rtol=0, atol=1e-12)


def test_observe_gains_refuses_unstable_unless_allowed(f, x):
    with pytest.raises(GainError, match=r"rho\(I - Ts L\)"):
        observe_gains(f, x, TS, torch.tensor([1.0, 50.0]))  # Ts L = 2.5
    est = observe_gains(f, x, TS, torch.tensor([1.0, 50.0]), allow_unstable=True)
    err = (x - est.x_hat).norm(dim=-1)
    assert float(err[1, :, -1].min()) > 1e3 * float(err[0, :, -1].max())  # |1 - Ts L| = 1.5: 1.5^39 ~ 7e6


# --- the batched cascade -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("L, beta", [
    (torch.tensor([0.0, 3.0, 10.0]), 0.0),
    (torch.tensor([0.0, 3.0, 10.0]), 0.1),
    (torch.tensor([[2.0, 6.0], [9.0, 1.0]]), torch.tensor([0.0, 0.2])),
    (5.0, torch.tensor([0.0, 0.05, 0.3])),
])
def test_cascade_sweep_equals_cascade_predict_per_pair(f, x, L, beta):
    z = cascade_sweep(f, x, TS, 7, Gains.sweep(L, beta))
    Lb = torch.as_tensor(L, dtype=F64).reshape(-1, *torch.as_tensor(L).shape[1:])
    bb = torch.as_tensor(beta, dtype=F64).reshape(-1)
    G = max(Lb.shape[0], bb.numel())
    assert z.shape == (G, 2, 40, 2)
    for g in range(G):
        Lg, bg = Lb[g % Lb.shape[0]], float(bb[g % bb.numel()])
        torch.testing.assert_close(z[g], cascade_predict(f, x, TS, 7, Gains(Lg, bg)), rtol=0, atol=1e-12)


def test_cascade_sweep_zero_gain_is_an_euler_rollout(f, x):
    z = cascade_sweep(f, x[0], TS, 5, Gains.sweep(0.0))[0]
    ref = x[0]
    for _ in range(5):
        ref = ref + TS * f(0.0, ref)  # Euler: z <- z + Ts f(z)
    torch.testing.assert_close(z, ref, rtol=0, atol=1e-13)


@pytest.mark.parametrize("kwargs, err, match", [
    (dict(N=0), ValueError, "N must be an integer >= 1"),
    (dict(N=2.5), ValueError, "N must be an integer >= 1"),
    (dict(beta=-0.1), ValueError, "decay rate beta must be finite and >= 0"),
    (dict(beta=torch.tensor([0.0, 0.1])), ValueError, "3 gains and 2 decay rates do not pair up"),
    (dict(L=torch.ones(3, 3)), ValueError, "a swept diagonal gain has 3 entries but the state has n = 2"),
    (dict(L=torch.tensor([])), ValueError, r"a gain sweep L must be a scalar, shape \(G,\)"),
    (dict(L=torch.tensor([1.0, -1.0, 2.0])), GainError, "not positive definite"),
    (dict(Ts=0.0), ValueError, "Ts must be a finite positive"),
])
def test_cascade_sweep_bad_inputs(f, x, kwargs, err, match):
    args = dict(Ts=TS, N=3, L=torch.tensor([1.0, 2.0, 3.0]), beta=0.0) | kwargs
    with pytest.raises(err, match=match):
        cascade_sweep(f, x, args["Ts"], args["N"], Gains.sweep(args["L"], args["beta"]))


# --- metrics of a sweep ------------------------------------------------------------------------------------------

def test_n_step_errors_pairs_row_k_with_truth_k_plus_N():
    truth = torch.arange(10, dtype=F64)[:, None].expand(10, 2)
    pred = truth + 3.0  # row k holds truth[k] + 3 = truth[k + 3] + 0: exact for N = 3
    assert torch.equal(n_step_errors(pred, truth, 3), torch.zeros(7, dtype=F64))
    assert n_step_errors(pred, truth, 1).tolist() == pytest.approx([2 * math.sqrt(2)] * 9)
    with pytest.raises(ValueError, match="need 1 <= N < T"):
        n_step_errors(pred, truth, 10)


def test_outward_increase_fraction():
    v = torch.tensor([[5.0, 3.0, 1.0, 2.0, 4.0],   # V around index 2: every outward step grows
                      [1.0, 3.0, 5.0, 4.0, 2.0],   # peak: every outward step shrinks
                      [5.0, 3.0, 1.0, 0.5, 4.0]])  # 3 of 4 grow
    assert outward_increase_fraction(v, 2).tolist() == [1.0, 0.0, 0.75]
    assert outward_increase_fraction(v[0], 0).tolist() == 0.5  # from the left end: 5->3, 3->1 shrink; 1->2, 2->4 grow
    with pytest.raises(ValueError, match="centre level 5"):
        outward_increase_fraction(v, 5)


def test_offset_spirals_add_the_offsets_to_the_base():
    offsets = paired_levels([-0.1, 0.0, 0.2], [0.01, 0.0, -0.02], [-1.0, 0.0, 3.0])
    systems = offset_spirals([2.0, 0.1, 0.0], offsets)
    assert [(s.omega, s.eta, s.eps) for s in systems] == [(2.0 - 0.1, 0.1 + 0.01, -1.0), (2.0, 0.1, 0.0),
                                                          (2.0 + 0.2, 0.1 - 0.02, 3.0)]
    with pytest.raises(ValueError, match="offsets of shape"):
        offset_spirals([2.0, 0.1, 0.0], torch.zeros(3, 2))


def test_n_step_rmse_is_the_root_mean_square_over_the_pooled_axes():
    truth = torch.zeros(10, 2, dtype=F64)
    pred = torch.zeros(3, 10, 2, dtype=F64)
    pred[0, :, 0], pred[1, :, 1], pred[2, :5, 0] = 3.0, 4.0, 2.0  # errors 3, 4, and 2 at 5 of the 8 starts
    torch.testing.assert_close(n_step_rmse(pred, truth, 2), torch.tensor([3.0, 4.0, (5 * 4 / 8) ** 0.5], dtype=F64))
    torch.testing.assert_close(n_step_rmse(pred, truth, 2, dim=(0, 1)), torch.tensor((8 * 9 + 8 * 16 + 5 * 4) / 24,
                                                                                    dtype=F64).sqrt())


def test_sweep_errors_are_each_members_mean_error_at_each_gain():
    """Cell (e, g): member e's cascade at gain L_g (decay beta), its mean N-step error; the gain 0 cell is the
    member's open-loop Euler rollout."""
    from fnnlib import NeuralODEEnsemble, rollout_predict
    from fnnlib.models import stack_members

    ens = NeuralODEEnsemble(2, [8], "tanh", [0, 1])
    x = Spiral(2.0, 0.1, 0.0).simulate(torch.tensor([9.0, 0.0], dtype=F64), torch.arange(60, dtype=F64) * 0.01).float()
    gains = torch.tensor([0.0, 5.0, 20.0], dtype=F64)
    got = sweep_errors(ens, stack_members(x, 2), x, 0.01, 5, gains, 0.02)
    assert got.shape == (2, 3)
    for e in range(2):
        m = ens.member(e)
        for g, L in enumerate(gains.tolist()):
            want = n_step_errors(cascade_predict(m, x, 0.01, 5, Gains(L, 0.02)), x, 5).mean()
            torch.testing.assert_close(got[e, g], want, rtol=1e-4, atol=1e-5)
        open_loop = n_step_errors(rollout_predict(m, x, 0.01, 5), x, 5).mean()
        torch.testing.assert_close(got[e, 0], open_loop, rtol=1e-4, atol=1e-5)


def _throws(K: int = 2, T: int = 40) -> torch.Tensor:
    """K short projectile-like runs (K, T, 6): position and velocity under gravity, Ts = 0.01."""
    t = torch.arange(T, dtype=torch.float64)[:, None] * 0.01
    v0 = torch.tensor([[1.0, 0.5, 3.0], [0.5, -1.0, 2.0]], dtype=torch.float64)[:K, None]
    g = torch.tensor([0.0, 0.0, -9.81], dtype=torch.float64)
    return torch.cat([v0 * t + 0.5 * g * t**2, v0 + g * t], -1).float()


def test_cascade_position_errors_of_an_ensemble_are_each_members_own():
    """An ensemble's row e is member e's O1 error alone; L = 0 is the open-loop Euler rollout's."""
    from fnnlib import NeuralODEEnsemble, rollout_predict
    from fnnlib.metrics import ahead_position_errors

    x = _throws()
    ens = NeuralODEEnsemble(6, [8], "tanh", [0, 1])
    got = cascade_position_errors(ens, x, 0.01, 5, 2.0, 0.1)
    assert got.shape == (2, 2)
    for e in range(2):
        torch.testing.assert_close(got[e], cascade_position_errors(ens.member(e), x, 0.01, 5, 2.0, 0.1),
                                   rtol=1e-5, atol=1e-6)
    net = ens.member(0)
    open_loop = ahead_position_errors(rollout_predict(net, x[:, :-5], 0.01, 5), x, 5)
    torch.testing.assert_close(cascade_position_errors(net, x, 0.01, 5, 0.0, 0.0), open_loop, rtol=1e-5, atol=1e-6)


def test_the_hand_sweep_keeps_the_grid_pair_of_lowest_o1_loss_and_the_tuner_lowers_it():
    from fnnlib import NeuralODE
    from fnnlib.metrics import ahead_position_loss
    from fnnlib.seeding import seed_everything

    x = _throws()
    seed_everything(0)
    net = NeuralODE(6, [8], "tanh")
    sweep = position_gain_sweep(net, x, 0.01, 5, [0.5, 5.0, 50.0], [0.0, 0.1])
    with torch.no_grad():
        table = [[float(ahead_position_loss(x, cascade_predict(net, x[..., :-5, :], 0.01, 5, Gains(L, b)), 5))
                  for b in (0.0, 0.1)] for L in (0.5, 5.0, 50.0)]
    np.testing.assert_allclose(sweep.table, table, rtol=1e-6)
    assert sweep.cost == pytest.approx(min(min(r) for r in table))
    tuned = position_gain_tuning(net, x, 0.01, 5, L0=5.0, beta0=0.1, iterations=4, lr=0.1)
    assert len(tuned.loss) == 4 and tuned.loss[-1] < tuned.loss[0]
    assert tuned.loss[0] == pytest.approx(table[1][1], rel=1e-4)  # the objective is O1's loss at the start


def test_level_errors_of_a_zero_neural_feedback_are_the_neural_odes():
    """h = 0 adds nothing: the neural feedback's rates and N-step errors are the neural ODE's; the linear
    feedback's are each member's own LinearFeedback and cascade."""
    from fnnlib import LinearFeedback, NeuralFeedbackObserver, NeuralODEEnsemble
    from fnnlib.models import NeuralFeedbackEnsemble

    ens = NeuralODEEnsemble(2, [8], "tanh", [0, 1])
    h = NeuralFeedbackEnsemble(2, [8], "tanh", [0, 1])
    with torch.no_grad():
        for p in h.parameters():
            p.zero_()
    t = torch.arange(40, dtype=F64) * 0.01
    x, f = residual_level_runs([2.0, 0.1, 0.0], paired_levels([-0.5, 0.5], [0.0, 0.0], [0.0, 1.0]),
                               torch.tensor([9.0, 0.0], dtype=F64), t)
    rate, ms, seconds = level_errors(ens, NeuralFeedbackObserver(ens, 0.01, h=h, n=4), x, f, 0.01, 5, 20.0, 0.02)
    assert rate["neural_ode"].shape == ms["neural_ode"].shape == (2, 2) and seconds >= 0
    torch.testing.assert_close(rate["neural_feedback"], rate["neural_ode"])
    torch.testing.assert_close(ms["neural_feedback"], ms["neural_ode"], rtol=1e-5, atol=1e-6)
    m = ens.member(1)
    lf = LinearFeedback(m, 0.01, gains=Gains(20.0), n=2).observe(x[0]).f_hat
    torch.testing.assert_close(rate["linear_feedback"][1, 0], ((lf - f[0]) ** 2).sum(-1).mean().sqrt(),
                               rtol=1e-4, atol=1e-5)
    z = cascade_predict(m, x[1], 0.01, 5, Gains(20.0, 0.02))
    torch.testing.assert_close(ms["linear_feedback"][1, 1], n_step_errors(z, x[1], 5).mean(), rtol=1e-4, atol=1e-5)


def test_residual_level_runs_pair_each_levels_run_with_its_own_rate():
    """Level j: the run of spiral base + offsets[j], and Eq. (26)'s rate of that spiral along it (the zero
    offset is the base spiral; a rate from another level would not match its run's finite differences)."""
    offsets = paired_levels([-0.5, 0.0, 0.5], [0.0, 0.0, 0.05], [0.0, 0.0, 2.0])
    Ts = 0.01
    t = torch.arange(200, dtype=F64) * Ts
    x, f = residual_level_runs([2.0, 0.1, 0.0], offsets, torch.tensor([9.0, 0.0], dtype=F64), t)
    assert x.shape == f.shape == (3, 200, 2) and x.dtype == f.dtype == torch.float32
    torch.testing.assert_close(x[1], Spiral(2.0, 0.1, 0.0).simulate(torch.tensor([9.0, 0.0], dtype=F64), t).float())
    rate_fd = (x[:, 2:] - x[:, :-2]) / (2 * Ts)  # central differences: the rate of each level's own run
    for j in range(3):
        torch.testing.assert_close(f[j, 1:-1], rate_fd[j], rtol=0.01, atol=0.01)
    assert (f[0] - f[2]).abs().max() > 1.0


def test_the_switched_run_follows_each_spiral_on_its_side_of_the_switch():
    """Before the switch the run is the first spiral's, after it the second's (restarted from the state at the
    switch), and the rate is the one of the spiral in force."""
    before, after, x0 = (3.0, 0.05, 10.0), (1.0, 0.12, 5.0), torch.tensor([9.0, 0.0], dtype=F64)
    t = torch.arange(301, dtype=F64) * 0.01  # switch at t = 1.5 s, sample 150
    x, f = switched_spiral_run(before, after, 1.5, x0, t)
    assert x.shape == f.shape == (301, 2) and x.dtype == f.dtype == torch.float32
    torch.testing.assert_close(x[:151], Spiral(*before).simulate(x0, t[:151]).float(), rtol=1e-5, atol=1e-5)
    x_sw = Spiral(*before).simulate(x0, t[:151])[-1]
    torch.testing.assert_close(x[150:], Spiral(*after).simulate(x_sw, t[150:] - 1.5).float(), rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(f[200:], Spiral(*after).rate(x[200:].double()).float(), rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(f[:150], Spiral(*before).rate(x[:150].double()).float(), rtol=1e-5, atol=1e-5)


def test_simulate_levels_exact_uses_the_closed_form():
    systems = [Spiral(2.0, 0.1, 0.0), Spiral(3.0, 0.05, 1.0)]
    t = torch.arange(30, dtype=F64) * TS
    x0 = torch.tensor([9.0, 0.0], dtype=F64)
    exact = simulate_levels(systems, x0, t, exact=True)
    for s, xs in zip(systems, exact):
        assert torch.equal(xs, s.exact_solution(x0, t))
    torch.testing.assert_close(exact, simulate_levels(systems, x0, t), rtol=1e-7, atol=1e-7)  # dopri5 at 1e-10
