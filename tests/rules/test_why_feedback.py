"""D2-D4 at the points of their why grids (fnnbook.rules.why_feedback): the claims' own rules, point by point."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fnnlib.paper.feedback_eval import EvaluationSettings, evaluation_setup
from fnnbook.rules import why_feedback as WF
from fnnbook.tasks import settings_class

TH = WF.Thresholds(d2_factor=1.5, d3_ratio=0.5, d3_flat=0.1)
S = 5


def numbers(d2_ratio: float, d2_settled: float, ratio: float, trend: float, won: int) -> dict:
    """One point's numbers for S seeds: D2's ratios feedback / alone over the whole record and after settling, D3's
    loss ratio and end trend, and S8 errors where the feedback wins ``won`` of 3 levels in both metrics."""
    one = np.ones(S)
    s8 = {"rate_neural_ode": np.ones((S, 3)), "err_N_neural_ode": np.ones((S, 3)),
          "rate_neural_feedback": np.where(np.arange(3) < won, 0.5, 2.0) * np.ones((S, 3)),
          "err_N_neural_feedback": 0.5 * np.ones((S, 3))}
    return {"rel_rmse_nominal_neural_ode": 0.1 * one, "rel_rmse_neural_feedback": 0.1 * d2_ratio * one,
            "rel_rmse_settled_nominal_neural_ode": 0.1 * one, "rel_rmse_settled_neural_feedback": 0.1 * d2_settled * one,
            "settle_seconds": 0.3 * one, "ratio": ratio * one, "last_window_trend_relative": trend * one, "s8": s8}


def results(d2: str, d4_worded: str) -> dict:
    return {"D2": {"verdict": d2}, "D3": {"verdict": "not reproduced"},
            "D4": {"verdict": "partly reproduced", "readings": {"as worded": {"verdict": d4_worded}}}}


def test_counted_reads_the_worded_reading_of_d4_and_the_verdict_of_the_others() -> None:
    r = results("reproduced", "not reproduced")
    assert WF.counted(r["D4"], "D4") == "not reproduced" and WF.counted(r["D2"], "D2") == "reproduced"


def test_levels_won_counts_the_levels_lower_in_both_metrics_per_seed() -> None:
    assert WF.levels_won(numbers(1, 1, 0.1, 0.0, won=2)["s8"]).tolist() == [2] * S


def test_measured_reads_d2_in_both_windows_and_d3_in_every_reading() -> None:
    n = numbers(3.0, 1.2, 0.2, 0.5, won=3) | {"release_form_final": 0.6 * np.ones(S)}
    m = WF.measured(results("not reproduced", "reproduced"), n, TH)
    assert m["D2_window"] == {"whole record": False, "after settling": True}  # 3x alone, 1.2x once settled
    # the loss falls to 0.2 of its start but still moves 50 % at its end; the release's form ends above 0.5
    assert m["D3_reading"] == {"falls and ends flat": False, "falls": True, "reaches the release's stop": False}
    assert m["verdict"] == {"D2": "not reproduced", "D3": "not reproduced", "D4": "reproduced"}
    np.testing.assert_allclose(m["D2"], 3.0)
    assert m["D4"].tolist() == [3] * S


def test_measured_without_the_release_form_cannot_judge_the_release_reading() -> None:
    n = numbers(1.0, 1.0, 0.2, 0.0, won=3)
    with pytest.raises(ValueError, match="release's form"):
        WF.measured(results("reproduced", "reproduced"), n, TH)
    m = WF.measured(results("reproduced", "reproduced"), n | {"release_form_final": 0.4 * np.ones(S)}, TH)
    assert all(m["D3_reading"].values()) and not np.isnan(m["D3_release"]).any()


def test_a_setting_grid_runs_through_the_profile_point_sorted_by_the_setting() -> None:
    recipe = {"optimizer": "rmsprop", "lr": 0.01, "iterations": 2000, "refresh_every": 10}
    rel = {"release_form_final": 0.4 * np.ones(S)}
    profile = WF.measured(results("reproduced", "reproduced"), numbers(1.0, 1.0, 0.2, 0.0, 3) | rel, TH)
    points = [{"change": {"lr_times": 0.1}, "recipe": recipe | {"lr": 0.001}},
              {"change": {"optimizer": "adam"}, "recipe": recipe | {"optimizer": "adam"}},
              {"change": {"lr_times": 10}, "recipe": recipe | {"lr": 0.1}}]
    point_m = [WF.measured(results("not reproduced", "not reproduced"), numbers(3.0, 3.0, 0.9, 0.0, 0) | rel, TH)] * 3
    g = WF.setting_grid("lr_times", "D2", profile_recipe=recipe, profile=profile, points=points,
                        point_measured=point_m, th=TH)
    assert [a.name for a in g.axes] == ["fb_lr", "window"]
    assert g.axes[0].values == (0.001, 0.01, 0.1) and g.axes[0].ours == 0.01 and g.axes[0].paper == 0.01
    assert g.holds.tolist() == [[False, False], [True, True], [False, False]] and g.n == S
    d4 = WF.setting_grid("optimizer", "D4", profile_recipe=recipe, profile=profile, points=points,
                         point_measured=point_m, th=TH)
    assert d4.axes[0].values == ("adam", "rmsprop") and d4.holds.tolist() == [False, True]
    assert d4.holds_at_profile() is True


def test_the_window_grid_and_the_release_curves_grid() -> None:
    g = WF.window_grid(numbers(3.0, 1.2, 0.2, 0.0, 3), TH, units=S, unit="seed", networks="ours", title="window")
    assert g.holds.tolist() == [False, True]
    falling = np.linspace(2.0, 0.45, 200)  # cut where it fell below 0.5: falls, not flat, reaches the stop
    c = WF.curves_grid({"a": falling, "b": falling * 1.01}, TH)
    assert dict(zip(c.axes[0].values, c.holds.tolist())) == {"falls and ends flat": False, "falls": True,
                                                             "reaches the release's stop": True}
    assert c.n == 2 and c.networks == "authors"


SMALL = {"n_samples": 60, "N": 5, "domega_range": [-0.72, 0.66, 0.6], "deta_range": [-0.03, 0.0275, 0.025],
         "deps_range": [-14.4, 13.2, 12.0], "dr_omega_range": [0.8, 0.12, 3.08], "dr_eta_range": [0.04, 0.005, 0.135],
         "dr_eps_range": [-24.0, 2.4, 21.6], "heldout_flip": [1.0, -1.0, 1.0], "heldout_min_distance": 1.0}


def test_the_usage_grid_judges_d4_at_every_metric_decay_and_first_estimate() -> None:
    """With h = 0 the feedback adds nothing: the cascade equals the Euler rollout, D4 fails in every metric."""
    import fnnlib as F
    from fnnlib.models import NeuralFeedbackEnsemble

    setup = evaluation_setup(EvaluationSettings.of(settings_class("neural_feedback").defaults() | SMALL))
    f = F.NeuralODEEnsemble.from_members([F.NeuralODE(2, [8], "relu") for _ in range(2)], [0, 1])
    h = NeuralFeedbackEnsemble(2, [8], "relu", [0, 1])
    with torch.no_grad():
        for p in h.parameters():
            p.zero_()
    g = WF.usage_grid(f, h, 2, setup, TH, betas=[0.0, 0.1], unit="seed", networks="ours", title="usage")
    assert g.holds.shape == (3, 2, 2) and not g.holds.any()
    assert np.asarray(g.numbers["S8_levels_won_both"]).shape == (2, 2, 2)
