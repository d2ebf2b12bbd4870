"""The Sec. 4 evaluation shared by the neural-feedback notebooks (fnnlib.paper.feedback_eval) and its judgement
(fnnbook.feedback_eval), on tiny networks."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import fnnlib as F
from fnnlib.models import NeuralFeedbackEnsemble
from fnnbook.feedback_eval import judge
from fnnlib.paper.feedback_eval import EvaluationSettings, evaluation_setup, nominal_errors
from fnnbook.tasks import settings_class

SMALL = {"n_samples": 60, "N": 5, "domega_range": [-0.72, 0.66, 0.6], "deta_range": [-0.03, 0.0275, 0.025],
         "deps_range": [-14.4, 13.2, 12.0], "dr_omega_range": [0.8, 0.12, 3.08], "dr_eta_range": [0.04, 0.005, 0.135],
         "dr_eps_range": [-24.0, 2.4, 21.6], "heldout_flip": [1.0, -1.0, 1.0], "heldout_min_distance": 1.0}


def networks(E: int):
    seeds = list(range(E))
    f = F.NeuralODEEnsemble.from_members([F.NeuralODE(2, [8], "relu") for _ in seeds], seeds)
    h = NeuralFeedbackEnsemble(2, [8], "relu", seeds)
    return f, h


def test_a_zero_feedback_keeps_the_neural_ode_and_the_rules_see_it() -> None:
    s = evaluation_setup(EvaluationSettings.of(settings_class("neural_feedback").defaults() | SMALL))
    assert s.x_s8.shape == (3, 60, 2) and s.x_held.shape[1:] == (60, 2) and s.offsets.shape == (3, 3)
    f, h = networks(2)
    with torch.no_grad():
        for p in h.parameters():
            p.zero_()  # h = 0: f_hat is f's rate
    alone, with_h = nominal_errors(f, None, s, 2), nominal_errors(f, h, s, 2)
    assert alone.shape == (2,) and np.allclose(alone, with_h)
    res, numbers = judge(f, h, s, 2, loss=np.linspace(1, 0.1, 50)[:, None].repeat(2, 1), factor=1.5,
                         ratio_max=0.5, flat=0.1)
    assert list(res) == ["D2", "D3", "D4"]
    assert res["D2"].verdict == "reproduced"  # equal errors: within 1.5x
    assert res["D3"].checks == {"last_below_ratio_of_first": True, "last_window_flat": False}  # still falling
    assert res["D4"].checks["all_3_S8_levels"] is False  # equal errors never beat
    assert numbers["s8"]["rate_neural_ode"].shape == (2, 3)


def test_the_release_frame_turns_the_spiral_the_other_way() -> None:
    p = settings_class("neural_feedback").defaults() | SMALL
    s = EvaluationSettings.of(p)
    ours, theirs = evaluation_setup(s), evaluation_setup(s, F.release.release_spiral)
    assert torch.allclose(ours.x_nom[:, 0], theirs.x_nom[:, 0]) and torch.allclose(ours.x_nom[:, 1], -theirs.x_nom[:, 1])
    with pytest.raises(ValueError, match="held-out"):
        evaluation_setup(EvaluationSettings.of(p | {"heldout_min_distance": 100.0}))
    with pytest.raises(KeyError, match="heldout_flip"):  # a record without a setting is refused, not defaulted
        EvaluationSettings.of({k: v for k, v in p.items() if k != "heldout_flip"})


def test_an_ensemble_of_trained_feedbacks_holds_each_and_refuses_other_kinds() -> None:
    import pytest  # noqa: PLC0415
    import torch  # noqa: PLC0415

    import fnnlib as F  # noqa: PLC0415
    from fnnlib.models import NeuralFeedbackEnsemble  # noqa: PLC0415

    members = []
    for s in (4, 9):
        torch.manual_seed(s)
        members.append(F.NeuralFeedback(2, (8,), "relu"))
    ens = NeuralFeedbackEnsemble.from_members(members, [4, 9])
    assert ens.seeds == [4, 9]
    for m, alone in enumerate(members):
        assert all(torch.equal(a, b) for a, b in zip(ens.member(m).parameters(), alone.parameters()))
    with pytest.raises(TypeError, match="NeuralFeedback"):
        NeuralFeedbackEnsemble.from_members([F.NeuralODE(2, (8,), "relu")], [0])


def test_the_settled_window_the_centred_feedback_and_the_release_form_loss() -> None:
    from fnnbook.feedback_eval import settled_errors
    from fnnlib.paper.feedback_eval import CentredFeedback, rate_error_curves, release_form_loss

    s = evaluation_setup(EvaluationSettings.of(settings_class("neural_feedback").defaults() | SMALL))
    f, h = networks(2)
    curves = rate_error_curves(f, h, s, 2)
    assert curves["neural_feedback"].shape == (2, 60)
    # the whole window's RMS of a curve is the relative RMSE of nominal_errors
    assert np.allclose(np.sqrt((curves["neural_feedback"] ** 2).mean(1)), nominal_errors(f, h, s, 2), rtol=1e-4)
    settled = settled_errors(curves)
    assert settled["settle_index"].shape == (2,) and settled["rel_rmse_settled_neural_ode"].shape == (2,)
    e = torch.randn(4, 4)
    assert torch.allclose(CentredFeedback(h)(torch.zeros(1, 4)), torch.zeros(1, 4))  # h(0) removed
    assert torch.allclose(CentredFeedback(h)(e) - h(e), -h(torch.zeros(1, 4)).expand(4, 4))
    loss = release_form_loss(f, h, s.x_s8, 0.01, 2, skip_seconds=0.1)
    assert loss.shape == (2,) and (loss > 0).all()
