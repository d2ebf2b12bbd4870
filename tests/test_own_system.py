"""B1 on the pendulum and the noisy spiral (fnnlib.own_system), on tiny settings: the records and runs one seed gives."""

from __future__ import annotations

from types import SimpleNamespace

import torch

import fnnlib as F
from fnnlib.metrics import n_step_errors
from fnnlib.seeding import make_generator, seed_everything
from fnnlib.systems import Pendulum, Spiral
from fnnlib import own_system as OS

P = SimpleNamespace(Ts=0.02, n_train=40, n_test=30, u_amp=1.5, nominal=[9.81, 0.1, 1.0, 0.0], test=[7.0, 0.4, 1.0, 1.5],
                    hidden=[8], activation="tanh", iterations=3, noise_std=0.01, N=5, L_hand=20.0, beta_hand=0.02,
                    L0=5.0, beta0=0.05, tune_iterations=2, tune_lr=0.1, kf_q_x=1e-8, kf_q_d=0.01, kf_p0_d=100.0,
                    spiral_Ts=0.01, spiral_N=5, spiral_noise_std=0.01, spiral_L=20.0, spiral_beta=0.02,
                    spiral_tune_iterations=2, hand_L_grid=[1.0, 4.0], hand_beta_grid=[0.0])


def test_the_records_of_a_seed_are_its_own_and_the_nominal_pendulums() -> None:
    gen, t, (u_train, u_tune, u_eval), x0, x_train = OS.pendulum_records(3, P)
    assert u_train.shape == (40, 1) and u_tune.shape == u_eval.shape == (30, 1) and x0.shape == (3, 2)
    assert u_train.abs().max() <= 1.5 * 1.5 + 1e-9 and not torch.equal(u_tune, u_eval)  # two sines, own phases
    torch.testing.assert_close(x_train, Pendulum(*P.nominal).simulate(x0[0], t[:40], u_train).float())
    again = OS.pendulum_records(3, P)
    assert torch.equal(again[4], x_train) and not torch.equal(OS.pendulum_records(4, P)[4], x_train)


def test_a_pendulum_run_scores_every_predictor_and_repeats_exactly() -> None:
    run = OS.pendulum_run(0, P)
    assert set(run["errors"]) == {"open_loop", "hand", "paper", "tuned", "kalman"}
    assert all(v >= 0 for v in run["errors"].values()) and len(run["loss"]) == 2
    assert run["hand_sweep"]["L"] in (1.0, 4.0)
    assert OS.pendulum_run(0, P)["errors"] == run["errors"]  # fixed seeds: the same draws in the same order


def test_the_spiral_run_tunes_on_its_own_noise_and_the_open_loop_is_the_rollout() -> None:
    seed_everything(0)
    net = F.NeuralODE(2, [8], "tanh")
    t = torch.arange(60, dtype=torch.float64) * 0.01
    x = Spiral(3.0, 0.05, 10.0).simulate(torch.tensor([9.0, 0.0], dtype=torch.float64), t).float()
    run = OS.spiral_run(1, net, x[:40], x, P)
    gen = make_generator(1001)
    F.add_measurement_noise(x[:40], 0.01, gen)
    y = F.add_measurement_noise(x, 0.01, gen)  # the judged measurements: the second draw of the seed's noise
    with torch.no_grad():
        open_loop = n_step_errors(F.rollout_predict(net, y, 0.01, 5), x, 5).mean()
    assert abs(run["errors"]["open_loop"] - float(open_loop)) < 1e-6
    assert run["seed"] == 1 and set(run["errors"]) == {"open_loop", "hand", "paper", "tuned", "kalman"}
