"""The observers side by side (fnnlib.observers.comparison): the linear feedback's low-pass and Luenberger twins, and
each design against its closed form, on a tiny network."""

from __future__ import annotations

import pytest
import torch

import fnnlib as F
from fnnlib.feedback import eval_field
from fnnlib.observers import evaluate_observer
from fnnlib.seeding import make_generator, seed_everything
from fnnlib.systems import Spiral
from fnnlib.observers import comparison as OC

TS, L = 0.01, 20.0


def _setup():
    seed_everything(0)
    model = F.NeuralODE(2, [8], "tanh")
    t = torch.arange(200, dtype=torch.float64) * TS
    x = Spiral(3.0, 0.05, 10.0).simulate(torch.tensor([9.0, 0.0], dtype=torch.float64), t).float()
    y = F.add_measurement_noise(x, 0.01, make_generator(1))
    obs = OC.observer_set(model, TS, L=L, beta=0.02, poles=[0.8, 0.8, 0.5, 0.5], noise_std=0.01, q_x=1e-8, q_d=0.01,
                          p0_d=100.0)
    return model, x, y, obs


def test_the_set_holds_the_seven_observers() -> None:
    _, _, _, obs = _setup()
    assert list(obs) == ["neural ODE", "linear feedback", "Luenberger (as LF)", "Luenberger", "Kalman",
                         "Kalman, steady state", "EKF"]


def test_the_linear_feedback_is_a_lowpass_of_the_residual_and_its_luenberger_twin() -> None:
    """Both identities hold to float precision: the recursion and the twin are the feedback itself."""
    model, x, y, obs = _setup()
    f_true = Spiral(3.0, 0.05, 10.0).rate(x)
    est = {k: evaluate_observer(obs[k], y, (x, f_true), 5, repeats=1).estimate
           for k in ("linear feedback", "Luenberger (as LF)")}
    with torch.no_grad():
        d_true = f_true - eval_field(model, x)
    d_lf, eq = OC.lowpass_twin(est, model, y, x, d_true, TS, L)
    assert d_lf.shape == (200, 2)
    assert eq["max_rel_diff_lowpass"] < 1e-4 and eq["max_rel_diff_luenberger"] < 1e-4
    assert eq["mean_abs_delta_f_over_L"] == pytest.approx(float(d_true.norm(dim=-1).mean()) / L)
    _, wrong = OC.lowpass_twin(est, model, y, x, d_true, TS, 2 * L)  # another gain's low-pass is not the feedback
    assert wrong["max_rel_diff_lowpass"] > 1e-2


def test_the_designs_match_their_closed_forms() -> None:
    _, _, _, obs = _setup()
    d = OC.design_checks(obs, [0.8, 0.8, 0.5, 0.5], 2000, TS)
    assert d["luenberger_pole_err"] < 1e-6 and d["kf_L_rel_err_vs_dlqe"] < 1e-6 and d["kf_P_rel_err_vs_dlqe"] < 1e-6
    assert d["rho_linear_feedback"] == pytest.approx(1 - TS * L)  # the error pole of Eq. (25)
    assert d["rho_luenberger"] == pytest.approx(0.8) and d["rho_kalman_steady"] < 1
