"""The cascaded tanks chapter's measures: the N-step output RMSE, the free run through an observer, and the
overflow episodes with the error during and after each."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import fnnlib as F
from fnnlib.data.tanks import tanks_records
from fnnbook.tasks import settings_class
from fnnlib.tanks.evaluation import TanksSettings, episode_errors, free_run, n_step_output_rmse, overflow_episodes

C = torch.tensor([[0.0, 1.0]], dtype=torch.float64)


def _tanks(**changes) -> TanksSettings:
    """The chapter's settings (its paper values), with ``changes``."""
    return TanksSettings.of(settings_class("cascaded_tanks").defaults() | changes)


def test_n_step_rmse_pairs_row_k_with_sample_k_plus_n() -> None:
    y = torch.arange(10, dtype=torch.float64)[:, None]
    x_pred = torch.zeros(10, 2, dtype=torch.float64)
    x_pred[:, 1] = torch.arange(10, dtype=torch.float64) + 3  # row k predicts y[k + 3] exactly
    assert n_step_output_rmse(x_pred, y, 3, C) == 0.0
    assert n_step_output_rmse(x_pred, y, 2, C, skip=4) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="N must be"):
        n_step_output_rmse(x_pred, y, 10, C)
    x_pred[5, 1] = float("nan")
    with pytest.raises(ValueError, match="diverged"):
        n_step_output_rmse(x_pred, y, 3, C)


def test_free_run_sees_only_the_first_samples() -> None:
    """A linear plant and its exact model: the free run equals the simulation from the estimate, whatever the
    record holds after the first samples."""
    A = torch.tensor([[-0.1, 0.0], [0.1, -0.1]], dtype=torch.float64)
    model = lambda t, x, u: x @ A.T + torch.cat([u, torch.zeros_like(u)], -1)  # noqa: E731
    Ts, T = 1.0, 60
    u = torch.ones(T, 1, dtype=torch.float64)
    x = torch.zeros(T, 2, dtype=torch.float64)
    x[0] = torch.tensor([1.0, 2.0])
    for k in range(T - 1):  # Euler, as the observer steps the model
        x[k + 1] = x[k] + Ts * model(0.0, x[k:k + 1], u[k:k + 1])[0]
    y = x[:, 1:].clone()
    L = F.place_observer_gain(torch.eye(2, dtype=torch.float64) + Ts * A, Ts * C, [0.3, 0.4])
    obs = F.MeasuredFeedback(model, Ts, L=L, measurement=F.Measurement(C=C, x0=x[0]), A=A)
    y_bad = y.clone()
    y_bad[10:] += 50.0
    np.testing.assert_allclose(free_run(obs, y_bad, u, 10, C), y[:, 0].numpy(), atol=1e-8)
    with pytest.raises(ValueError, match="n_init"):
        free_run(obs, y, u, 0, C)


def test_overflow_episodes_and_their_errors() -> None:
    s = [False, True, True, False, False, True, False, False, False, True]
    eps = overflow_episodes(s)
    assert eps == [(1, 3), (5, 6), (9, 10)]
    y = np.zeros(10)
    y_hat = np.array([0, 1, 1, 2, 2, 3, 0, 0, np.nan, 4], dtype=float)
    out = episode_errors(y_hat, y, eps, after=2)
    assert out[0] == {"start": 1, "samples": 2, "during": 1.0, "after": 2.0}
    assert out[1]["after"] == 0.0 and out[2]["after"] is None  # the record ends with the last episode
    assert overflow_episodes([False, False]) == []
    assert overflow_episodes(s, gap=2) == [(1, 6), (9, 10)]
    with pytest.raises(ValueError, match="after"):
        episode_errors(y_hat, y, eps, after=0)


def _ensemble_setup(E: int):
    from fnnlib.models.scaled import ScaledField
    rec = tanks_records("synthetic", n_samples=80, seed=0, noise_std=0.02)
    kw = dict(x_center=5.0, x_scale=3.0, u_center=3.0, u_scale=2.0, rate=0.05)
    return rec, (lambda seeds: ScaledField(2, 1, [8], "tanh", seeds, **kw))


def test_depths_are_the_cascade_and_the_open_loop_at_every_horizon() -> None:
    """One cascade of depth N gives every shorter horizon: entry N'-1 equals cascade_predict at N' (a gain) and
    the observer's open-loop predict (L = 0)."""
    from fnnlib.tanks.evaluation import depths
    rec, field = _ensemble_setup(1)
    model = field([0])
    obs = F.MeasuredFeedback(model, rec.Ts, L=torch.tensor([[0.02], [0.15]], dtype=torch.float64),
                             measurement=F.Measurement(C=C, x0=rec.y_val[0, 0].repeat(2)), allow_unstable=True)
    L = torch.tensor([[0.0, 0.0], [0.03, 0.03]], dtype=torch.float64)
    beta = torch.tensor([[0.0, 0.0], [0.2, 0.2]], dtype=torch.float64)
    d = depths(model, obs, rec.y_val, rec.u_val, rec.Ts, L, beta, 6)
    assert d.shape == (6, 2, rec.y_val.shape[0], 2)
    for N in (1, 3, 6):
        torch.testing.assert_close(d[N - 1, 0], obs.predict(rec.y_val, N, rec.u_val))
        ref = F.cascade_predict(model, rec.y_val, rec.Ts, N, F.Gains(0.03, 0.2), u=rec.u_val, observer=obs)
        torch.testing.assert_close(d[N - 1, 1], ref)


def test_the_stacked_ensemble_tunes_each_member_as_alone() -> None:
    """tune_gains(members=E) on a stacked field with a block-diagonal observer gives each member the model,
    gains and decay rate it gets alone (losses add, gradients never mix)."""
    from fnnlib.tanks.evaluation import _blocks
    rec, field = _ensemble_setup(2)
    Lo = torch.tensor([[0.02], [0.15]], dtype=torch.float64)

    def tune(seeds):
        E = len(seeds)
        m = field(seeds)
        y = rec.y_est.expand(-1, E).contiguous()
        obs = F.MeasuredFeedback(m, rec.Ts, L=_blocks(Lo, E),
                                 measurement=F.Measurement(C=_blocks(C, E), x0=y[0, 0].repeat(2 * E)),
                                 allow_unstable=True)
        return m, F.tune_gains(m, y, rec.Ts, 4,
                               recipe=F.TuneRecipe(L0=0.01, beta0=0.1, iterations=3, lr=0.01, train_model=True,
                                                   members=E),
                               u=rec.u_est, observer=obs)
    both, tb = tune([0, 1])
    for e, seed in enumerate((0, 1)):
        one, t1 = tune([seed])
        np.testing.assert_allclose(tb.L[2 * e:2 * e + 2], t1.L, rtol=1e-7)
        assert tb.beta[e] == pytest.approx(t1.beta, rel=1e-7)
        for a, b in zip(both.member(e).parameters(), one.parameters()):
            torch.testing.assert_close(a, b, rtol=1e-6, atol=1e-9)
    with pytest.raises(ValueError, match="members"):
        F.tune_gains(both, rec.y_est.expand(-1, 2), rec.Ts, 4,
                     recipe=F.TuneRecipe(L0=0.01, beta0=0.1, iterations=1, lr=0.01, members=3), u=rec.u_est)


def test_keep_scores_only_the_kept_targets_and_the_window_leaves_out_overflow() -> None:
    from fnnlib.tanks.evaluation import outside_overflow
    y = torch.zeros(10, 1, dtype=torch.float64)
    x_pred = torch.zeros(10, 2, dtype=torch.float64)
    x_pred[4, 1] = 3.0  # row 4 predicts target 5 (N = 1) wrongly
    keep = np.ones(10, dtype=bool)
    assert n_step_output_rmse(x_pred, y, 1, C) > 0
    keep[5] = False
    assert n_step_output_rmse(x_pred, y, 1, C, keep=keep) == 0.0
    rec = tanks_records("synthetic", n_samples=400, seed=0, noise_std=0.02)
    s = _tanks(overflow_gap=3, overflow_after=7)
    eps = overflow_episodes(rec.saturated("val").numpy(), gap=3)
    out = outside_overflow(rec, s)
    for a, b in eps:
        assert not out[a:b + 7].any()
    assert out.sum() == 400 - len(set().union(*[range(a, min(b + 7, 400)) for a, b in eps]))


def test_trained_ensembles_load_as_saved(tmp_path) -> None:
    from fnnlib.tanks.evaluation import load_trained, one_member, save_trained
    s = _tanks(hidden=[8], activation="tanh", x_center=5.0, x_scale=3.0, u_center=3.0, u_scale=2.0, rate=0.05)
    from fnnlib.tanks.evaluation import _field
    m = _field(s, [3, 4])
    save_trained(tmp_path / "m.pt", {"seeds": [3, 4], "observer_trained": m, "no_feedback": _field(s, [3, 4]),
                                     "tuned_L": [0.1] * 4, "tuned_beta": [0.2, 0.3], "hand": []})
    back = load_trained(tmp_path / "m.pt", s)
    x, u = torch.rand(3, 4, dtype=torch.float64), torch.rand(3, 1, dtype=torch.float64)
    torch.testing.assert_close(back["observer_trained"](0.0, x, u), m(0.0, x, u))
    torch.testing.assert_close(back["observer_trained"].member(1)(0.0, x[:, 2:], u), one_member(s, 4)(0.0, x[:, 2:], u))
    assert back["tuned_beta"] == [0.2, 0.3]


def test_the_baseline_start_is_chosen_on_the_estimation_record_only() -> None:
    """The no-feedback baseline keeps the start whose free run of the estimation record is best: the validation
    record changes its score, never the choice."""
    import dataclasses

    from fnnlib.tanks.evaluation import LEVEL, no_feedback, one_member
    rec = tanks_records("synthetic", n_samples=60, seed=0, noise_std=0.02)
    s = _tanks(hidden=[8], activation="tanh", x_center=5.0, x_scale=3.0, u_center=3.0, u_scale=2.0, rate=0.05,
             n_init=5, baseline_horizon=10, baseline_starts=["free", "encoder"], train_iterations=3, train_lr=0.01,
             observer_gain=[0.02, 0.15])
    a = no_feedback(rec, 0, s, one_member(s, 0), LEVEL)
    bad = dataclasses.replace(rec, y_val=rec.y_val.flip(0) + 3.0)
    b = no_feedback(bad, 0, s, one_member(s, 0), LEVEL)
    assert a["start"] == b["start"] and a["estimation_free_run"] == b["estimation_free_run"]
    assert a["start"] == min(a["estimation_free_run"], key=a["estimation_free_run"].get)
    assert a["free_run"] != b["free_run"]  # the validation record is what it is scored on


def test_the_free_start_baselines_train_as_one_ensemble_as_alone() -> None:
    """The free-start baseline of two seeds trained as one stacked ensemble gives each seed the model it gets
    alone (Adam is elementwise; the ensemble's mean loss scales each member's by 1/2, which Adam's steps ignore
    up to its epsilon)."""
    from fnnlib.tanks.evaluation import LEVEL, _field, _free_starts
    from fnnlib.training.outputs import OutputRecipe, train_from_outputs
    rec = tanks_records("synthetic", n_samples=60, seed=0, noise_std=0.02)
    s = _tanks(hidden=[8], activation="tanh", x_center=5.0, x_scale=3.0, u_center=3.0, u_scale=2.0, rate=0.05,
             baseline_horizon=10, train_iterations=4, train_lr=0.01)
    both = _free_starts(rec, [0, 1], s, _field(s, [0, 1]), LEVEL)
    for e, seed in enumerate((0, 1)):
        one = _field(s, [seed])
        train_from_outputs(one, rec.y_est, LEVEL, OutputRecipe(start="free", iterations=4, lr=0.01, burn=1, horizon=10,
                                                               seed=seed), Ts=rec.Ts, u=rec.u_est, progress=False)
        for a, b in zip(both.member(e).parameters(), one.parameters()):
            torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-7)


def test_the_overflow_table_averages_each_models_episode_errors_over_the_seeds() -> None:
    from fnnlib.tanks.evaluation import overflow_table

    seeds = [{"tuned": [{"during": 0.2, "after": 0.1}], "open_loop": [{"during": 0.4, "after": None}]},
             {"tuned": [{"during": 0.4, "after": 0.3}], "open_loop": [{"during": 0.6, "after": 0.5}]}]
    rows = overflow_table(seeds, [(10, 20)]).splitlines()
    assert rows[0] == "| episode (samples) | tuned: during / after | open_loop: during / after |"
    assert rows[2] == "| 10-19 | 0.300 / 0.200 | 0.500 / - |"  # a seed without an error after it: no mean
