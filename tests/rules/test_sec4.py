"""Rules of D1-D4: for every claim, numbers that must pass and numbers that must fail."""

from __future__ import annotations

import numpy as np
import pytest

from fnnbook.rules import sec4
from fnnbook.results import ClaimResult, GuaranteeFailed


def verdict(claim_id: str, rule: ClaimResult) -> str:
    assert rule.id == claim_id
    return rule.verdict


def test_d1() -> None:
    assert verdict("D1", sec4.d1(rel_dr=0.2, rel_nominal=0.01)) == "reproduced"
    assert verdict("D1", sec4.d1(rel_dr=[0.2, 0.3, 0.25, 0.2, 0.22], rel_nominal=[0.01] * 5)) == "reproduced"
    # worse by only 1.2x in most seeds
    assert verdict("D1", sec4.d1(rel_dr=[0.012, 0.3, 0.012, 0.012, 0.2], rel_nominal=[0.01] * 5)) == "not reproduced"
    # paired per seed: 4 of 5 seeds past 1.5x passes, 3 of 5 fails even though the mean gap is large
    nominal = [0.01, 0.02, 0.01, 0.03, 0.01]
    assert verdict("D1", sec4.d1(rel_dr=[0.2, 0.25, 0.2, 0.04, 0.3], rel_nominal=nominal)) == "reproduced"
    assert verdict("D1", sec4.d1(rel_dr=[0.2, 0.025, 0.9, 0.04, 0.3], rel_nominal=nominal)) == "not reproduced"


def test_d2() -> None:
    r = sec4.d2(rel_feedback=0.012, rel_nominal=0.01, frozen_unchanged=True)
    assert verdict("D2", r) == "reproduced" and r.guarantees == {"frozen_neural_ode_unchanged": True}
    # 9.5x off the nominal accuracy: not reproduced (the frozen weights no longer count)
    assert verdict("D2", sec4.d2(rel_feedback=0.095, rel_nominal=0.01, frozen_unchanged=True)) == "not reproduced"
    with pytest.raises(GuaranteeFailed, match="frozen_neural_ode_unchanged"):
        sec4.d2(rel_feedback=0.012, rel_nominal=0.01, frozen_unchanged=False)
    # per seed (a threshold: >= S-1 of S seeds): one seed off passes, two seeds off fail
    nominal = [0.01] * 5
    r = sec4.d2(rel_feedback=[0.012, 0.014, 0.03, 0.01, 0.011], rel_nominal=nominal, frozen_unchanged=[True] * 5)
    assert verdict("D2", r) == "reproduced" and "4 of 5 seeds" in r.rule
    r = sec4.d2(rel_feedback=[0.012, 0.02, 0.03, 0.01, 0.011], rel_nominal=nominal, frozen_unchanged=[True] * 5)
    assert verdict("D2", r) == "not reproduced"
    # one seed's frozen model changed: the guarantee stops the notebook
    with pytest.raises(GuaranteeFailed, match="frozen_neural_ode_unchanged"):
        sec4.d2(rel_feedback=[0.012] * 5, rel_nominal=nominal, frozen_unchanged=[True, True, False, True, True])
    with pytest.raises(ValueError, match="one bool per seed"):
        sec4.d2(rel_feedback=[0.012] * 5, rel_nominal=nominal, frozen_unchanged=[])


def test_d3() -> None:
    assert verdict("D3", sec4.d3(ratio=[0.1] * 5, trend=[0.01, -0.02, 0.0, 0.05, 0.03])) == "reproduced"
    assert verdict("D3", sec4.d3(ratio=0.1, trend=0.3)) == "partly"  # still falling at the end
    assert verdict("D3", sec4.d3(ratio=0.9, trend=0.3)) == "not reproduced"
    # per seed (thresholds: >= S-1 of S seeds): one seed not converged passes, two fail
    assert verdict("D3", sec4.d3(ratio=[0.1, 0.1, 0.7, 0.1, 0.1], trend=[0.01, 0.3, 0.0, 0.0, 0.0])) == "reproduced"
    r = sec4.d3(ratio=[0.1, 0.6, 0.7, 0.1, 0.1], trend=[0.01, 0.3, 0.2, 0.0, 0.0])
    assert r.checks == {"last_below_ratio_of_first": False, "last_window_flat": False}
    assert verdict("D3", r) == "not reproduced" and ">= 4 of 5 seeds" in r.rule


def d4_numbers(**over):
    lo, hi = np.full(12, 0.1), np.full(12, 0.2)
    base = dict(rate_neural_feedback=lo, rate_neural_ode=hi, err_N_neural_feedback=lo, err_N_neural_ode=hi,
                heldout_rate_neural_feedback=lo[:6], heldout_rate_neural_ode=hi[:6],
                heldout_err_N_neural_feedback=lo[:6], heldout_err_N_neural_ode=hi[:6], N=50,
                offsets=[[-0.72 + 0.12 * j, -0.03 + 0.005 * j, -14.4 + 2.4 * j] for j in range(12)])
    return base | over


def test_d4() -> None:
    assert verdict("D4", sec4.d4(**d4_numbers())) == "reproduced"
    # one held-out level lost in the N-step error: the held-out check fails
    held = np.full(6, 0.1)
    held[3] = 0.3
    r = sec4.d4(**d4_numbers(heldout_err_N_neural_feedback=held))
    assert r.checks == {"all_12_S8_levels": True, "all_6_heldout_levels": False} and verdict("D4", r) == "partly"
    # one S8 level lost (11 of 12, the single-seed paper run): no longer "partly" by a count of levels
    s8 = np.full(12, 0.1)
    s8[6] = 0.3
    r = sec4.d4(**d4_numbers(err_N_neural_feedback=s8, heldout_err_N_neural_feedback=held))
    assert verdict("D4", r) == "not reproduced" and "11 of 12" in r.rule
    assert r.reading_verdicts() == {"strict": "not reproduced", "as worded": "partly"}  # level 6: zero residual
    r = sec4.d4(**d4_numbers(err_N_neural_feedback=s8))
    assert r.reading_verdicts() == {"strict": "partly", "as worded": "reproduced"}
    s8[6], s8[2] = 0.1, 0.3  # lost at a level with a residual: both readings
    r = sec4.d4(**d4_numbers(err_N_neural_feedback=s8))
    assert r.reading_verdicts() == {"strict": "partly", "as worded": "partly"}
    # per seed: a level is won only by the paired rule
    seeds = np.tile([0.1, 0.3, 0.1, 0.3, 0.1], (12, 1))
    r = sec4.d4(**d4_numbers(rate_neural_feedback=seeds, rate_neural_ode=np.full((12, 5), 0.2),
                             err_N_neural_feedback=np.full((12, 5), 0.1), err_N_neural_ode=np.full((12, 5), 0.2)))
    assert r.checks["all_12_S8_levels"] is False and "5 seeds" in r.rule
    # per seed: every level won in 4 of 5 seeds with a clear mean gap passes; a level won in 3 of 5 fails
    lo = np.tile([0.1, 0.1, 0.1, 0.1, 0.25], (12, 1))
    r = sec4.d4(**d4_numbers(rate_neural_feedback=lo, rate_neural_ode=np.full((12, 5), 0.2),
                             err_N_neural_feedback=lo, err_N_neural_ode=np.full((12, 5), 0.2),
                             heldout_rate_neural_feedback=lo[:6], heldout_rate_neural_ode=np.full((6, 5), 0.2),
                             heldout_err_N_neural_feedback=lo[:6], heldout_err_N_neural_ode=np.full((6, 5), 0.2)))
    assert verdict("D4", r) == "reproduced"
    three = lo.copy()
    three[2] = [0.1, 0.1, 0.1, 0.25, 0.25]
    r = sec4.d4(**d4_numbers(rate_neural_feedback=lo, rate_neural_ode=np.full((12, 5), 0.2),
                             err_N_neural_feedback=three, err_N_neural_ode=np.full((12, 5), 0.2),
                             heldout_rate_neural_feedback=lo[:6], heldout_rate_neural_ode=np.full((6, 5), 0.2),
                             heldout_err_N_neural_feedback=lo[:6], heldout_err_N_neural_ode=np.full((6, 5), 0.2)))
    assert r.checks == {"all_12_S8_levels": False, "all_6_heldout_levels": True} and "11 of 12" in r.rule


def test_loss_convergence_reads_the_first_and_last_tenth() -> None:
    falling_then_flat = np.r_[np.linspace(1.0, 0.2, 80), np.full(20, 0.2)]
    ratio, trend = sec4.loss_convergence(falling_then_flat)
    assert ratio.shape == trend.shape == (1,)
    assert ratio[0] == pytest.approx(0.2 / np.linspace(1.0, 0.2, 80)[:10].mean()) and abs(trend[0]) < 1e-12
    still_falling = np.linspace(1.0, 0.1, 100)
    two = np.stack([falling_then_flat, still_falling], 1)  # (iterations, E): one value per seed
    ratio, trend = sec4.loss_convergence(two)
    assert trend[1] == pytest.approx(-(0.9 / 99) * 10 / still_falling[-10:].mean()) and trend[1] < -0.1
    assert sec4.d3(ratio=ratio[1:], trend=trend[1:]).checks == {"last_below_ratio_of_first": True,
                                                                 "last_window_flat": False}  # still falling
    with pytest.raises(ValueError, match="loss curve"):
        sec4.loss_convergence([1.0, np.nan, 0.5, 0.4])


def test_d4_in_each_metric_reads_only_that_metric() -> None:
    lose_multi = d4_numbers(err_N_neural_feedback=np.full(12, 0.3))  # rate won everywhere, N-step lost
    assert sec4.d4(**lose_multi).verdict == "partly"  # held-out levels still won in both
    assert sec4.d4(**lose_multi, metric="rate").checks["all_12_S8_levels"] is True
    assert sec4.d4(**lose_multi, metric="err_N").checks["all_12_S8_levels"] is False
    assert "change-rate RMSE at every" in sec4.d4(**lose_multi, metric="rate").rule
    with pytest.raises(ValueError, match="metric"):
        sec4.d4(**d4_numbers(), metric="loss")


def test_the_settling_time_is_read_from_the_curve() -> None:
    t = np.arange(200)
    curve = 0.01 + np.exp(-t / 10.0)  # a transient that decays onto a floor of 0.01
    k = int(sec4.settling_index(curve)[0])
    assert curve[k:].max() <= 2 * np.median(curve[100:]) < curve[k - 1]  # settled from k on, not before
    assert sec4.settling_index(np.full((3, 50), 0.5)).tolist() == [0, 0, 0]  # never out of its band
    spike = np.full(100, 0.1)
    spike[40] = 5.0  # a late excursion: it settles only after it
    assert sec4.settling_index(spike)[0] == 41
    spike[99] = 5.0  # out of its band at the very end: settled at the latest where the steady level is measured
    assert sec4.settling_index(spike)[0] == 50
    with pytest.raises(ValueError):
        sec4.settling_index(np.ones(3))


def test_the_readings_of_d3_each_fail_on_their_own_numbers() -> None:
    ratio, falling = [0.1] * 5, [-0.3] * 5  # fell by 10x, still falling at the end (cut at a stopping level)
    kw = dict(ratio=ratio, trend=falling, release_final=[0.45] * 5)
    assert not sec4.reading_holds_d3("falls and ends flat", **kw)
    assert sec4.reading_holds_d3("falls", **kw)
    assert sec4.reading_holds_d3("reaches the release's stop", **kw)
    assert not sec4.reading_holds_d3("reaches the release's stop", **kw | {"release_final": [0.6] * 5})
    assert not sec4.reading_holds_d3("falls", **kw | {"ratio": [0.9] * 5})
    with pytest.raises(ValueError, match="release's form"):
        sec4.reading_holds_d3("reaches the release's stop", ratio=ratio, trend=falling, release_final=None)
    assert set(sec4.D3_READINGS) == {"falls and ends flat", "falls", "reaches the release's stop"}
