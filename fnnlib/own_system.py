r"""Claim B1 on systems the paper does not treat in Sec. 5: gains of Eq. (11) picked by hand or tuned from data.

Two settings, each run once per seed: a damped pendulum driven by a known torque,
:math:`\dot\theta = \omega`, :math:`\dot\omega = -a\sin\theta - c\,\omega + b\,u + d`
(:class:`fnnlib.systems.Pendulum`), learned by a neural ODE :math:`f_{neural}(x, u)` on the nominal pendulum and
tested on another one under noisy measurements; and the paper's noisy spiral (the S3 setting) with the spiral
task's networks. In each, the cascade of Sec. 3.3 predicts N steps ahead with the hand-picked gains
(:func:`fnnlib.paper.sweeps.n_step_gain_sweep`), the paper's gains and gains tuned by descending the N-step error
(:func:`fnnlib.feedback.tune_gains`); the open loop and a steady-state Kalman filter on the same model are the
baselines.

``p``: the run's settings, read by attribute (the ``own_system`` notebook's settings: ``Ts``, ``n_train``,
``n_test``, ``u_amp``, ``nominal``, ``test``, ``hidden``, ``activation``, ``iterations``, ``noise_std``, ``N``,
``L_hand``, ``beta_hand``, ``L0``, ``beta0``, ``tune_iterations``, ``tune_lr``, ``kf_q_x``, ``kf_q_d``, ``kf_p0_d``,
the ``spiral_`` ones and the hand grids).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import Tensor

from fnnlib.feedback import Gains, TuneRecipe, cascade_predict, tune_gains
from fnnlib.feedback.tuning import GainSweep, TunedGains
from fnnlib.models import NeuralODE
from fnnlib.observers import Covariances, KalmanObserver
from fnnlib.seeding import make_generator, seed_everything
from fnnlib.metrics import n_step_errors
from fnnlib.paper.sweeps import n_step_gain_sweep
from fnnlib.systems import Pendulum, add_measurement_noise
from fnnlib.training import QUICK_RECIPE, train_neural_ode

__all__ = ["pendulum_model", "pendulum_records", "pendulum_run", "predictions", "spiral_run"]


def pendulum_records(seed: int, p: Any) -> tuple:
    """One seed's pendulum records: its generator (drawn from again later), the time grid ``t``, the known torques
    ``u`` (train (n_train, 1), tune and eval (n_test, 1): two sines with phases drawn from the seed), three start
    states ``x0`` (3, 2) and the nominal training trajectory (n_train, 2)."""
    gen = make_generator(seed)
    t = torch.arange(max(p.n_train, p.n_test), dtype=torch.float64) * p.Ts

    def inputs(T: int) -> Tensor:
        phase = 2 * torch.pi * torch.rand(2, generator=gen, dtype=torch.float64)
        return p.u_amp * (torch.sin(0.9 * t[:T] + phase[0]) + 0.5 * torch.sin(2.3 * t[:T] + phase[1]))[:, None]
    u = inputs(p.n_train), inputs(p.n_test), inputs(p.n_test)
    x0 = 0.5 * torch.randn(3, 2, generator=gen, dtype=torch.float64)
    return gen, t, u, x0, Pendulum(*p.nominal).simulate(x0[0], t[:p.n_train], u[0]).float()


def pendulum_model(seed: int, t: Tensor, x_train: Tensor, u_train: Tensor, p: Any) -> NeuralODE:
    """The neural ODE :math:`f_{neural}(x, u)` of one seed, trained on the nominal pendulum's record (the quick
    recipe, ``p.iterations`` iterations)."""
    seed_everything(seed)
    model = NeuralODE(2, p.hidden, p.activation, n_input=1)
    train_neural_ode(model, t[:p.n_train].float(), x_train, QUICK_RECIPE.replace(iterations=p.iterations),
                     seed=seed, u=u_train.float(), progress=False)
    return model


def predictions(model: Any, y: Tensor, Ts: float, N: int, *, hand: GainSweep, tuned: TunedGains,
                paper: tuple[float, float], noise_std: float, p: Any, u: Tensor | None = None) -> dict[str, Tensor]:
    """Each predictor's N-step predictions from the measurements ``y`` (T, 2): the open loop, the cascade with the
    hand-picked, the paper's (``paper``: L, beta) and the tuned gains, and a steady-state Kalman filter with a
    constant-disturbance state (measurement variance ``noise_std``^2) followed by a rollout."""
    kalman = KalmanObserver(model, Ts, n=2, cov=Covariances([p.kf_q_x] * 2 + [p.kf_q_d] * 2, noise_std ** 2,
                                                         P0=[noise_std ** 2] * 2 + [p.kf_p0_d] * 2),
                            steady_state=True)
    kw = {} if u is None else {"u": u}
    with torch.no_grad():
        return {"open_loop": cascade_predict(model, y, Ts, N, Gains(0.0), **kw),
                "hand": cascade_predict(model, y, Ts, N, Gains(hand.L, hand.beta), **kw),
                "paper": cascade_predict(model, y, Ts, N, Gains(*paper), **kw),
                "tuned": cascade_predict(model, y, Ts, N, tuned.schedule(), **kw),
                "kalman": kalman.predict(y, N, **kw).float()}


def pendulum_run(seed: int, p: Any) -> dict[str, Any]:
    """One seed of the pendulum, start to finish: records, training, the test pendulum measured with noise, gains
    tuned on one test trajectory and picked by hand on it, each predictor's mean N-step error on another."""
    gen, t, (u_train, u_tune, u_eval), x0, x_train = pendulum_records(seed, p)
    model = pendulum_model(seed, t, x_train, u_train, p)
    plant = Pendulum(*p.test)
    x_tune, x_eval = (plant.simulate(x, t[:p.n_test], u).float() for x, u in [(x0[1], u_tune), (x0[2], u_eval)])
    y_tune, y_eval = (add_measurement_noise(x, p.noise_std, gen) for x in (x_tune, x_eval))
    u_tune, u_eval = u_tune.float(), u_eval.float()
    tuned = tune_gains(model, y_tune, p.Ts, p.N,
                       recipe=TuneRecipe(L0=p.L0, beta0=p.beta0, iterations=p.tune_iterations, lr=p.tune_lr),
                       u=u_tune)
    hand = n_step_gain_sweep(model, y_tune, p.Ts, p.N, p.hand_L_grid, p.hand_beta_grid, u=u_tune)
    preds = predictions(model, y_eval, p.Ts, p.N, hand=hand, tuned=tuned, paper=(p.L_hand, p.beta_hand),
                        noise_std=p.noise_std, p=p, u=u_eval)
    return {"errors": {k: float(n_step_errors(z, x_eval, p.N).mean()) for k, z in preds.items()},
            "L": tuned.L.tolist(), "beta": tuned.beta, "tune_seconds": tuned.seconds, "loss": tuned.loss,
            "hand_sweep": hand.as_dict(),
            "trace": {k: z[: p.n_test - p.N, 0].numpy() for k, z in preds.items()} | {"truth": x_eval[p.N:, 0].numpy()}}


def spiral_run(seed: int, model: Any, x_tune: Tensor, x_eval: Tensor, p: Any) -> dict[str, Any]:
    """One network of the spiral task on the noisy spiral (the S3 setting): gains tuned and picked by hand on the
    tuning run ``x_tune`` measured with noise drawn from the network's seed, each predictor's mean N-step error on
    the judged run ``x_eval``."""
    gen = make_generator(1000 + seed)
    y_tune, y = (add_measurement_noise(x, p.spiral_noise_std, gen) for x in (x_tune, x_eval))
    tuned = tune_gains(model, y_tune, p.spiral_Ts, p.spiral_N,
                       recipe=TuneRecipe(L0=p.L0, beta0=p.beta0, iterations=p.spiral_tune_iterations, lr=p.tune_lr))
    hand = n_step_gain_sweep(model, y_tune, p.spiral_Ts, p.spiral_N, p.hand_L_grid, p.hand_beta_grid)
    preds = predictions(model, y, p.spiral_Ts, p.spiral_N, hand=hand, tuned=tuned, paper=(p.spiral_L, p.spiral_beta),
                        noise_std=p.spiral_noise_std, p=p)
    return {"errors": {k: float(n_step_errors(z, x_eval, p.spiral_N).mean()) for k, z in preds.items()},
            "L": tuned.L.tolist(), "beta": tuned.beta, "tune_seconds": tuned.seconds, "loss": tuned.loss,
            "hand_sweep": hand.as_dict(), "seed": seed}
