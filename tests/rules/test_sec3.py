"""Rules of S1-S11: for every claim, numbers that must pass and numbers that must fail."""

from __future__ import annotations

import numpy as np
import pytest

from fnnbook.rules import sec3
from fnnbook.results import BY_CONSTRUCTION, ClaimResult, GuaranteeFailed

SEEDS_WIN = [0.10, 0.11, 0.09, 0.10, 0.12]  # paired with SEEDS_LOSE: lower in every seed
SEEDS_LOSE = [0.20, 0.21, 0.19, 0.22, 0.20]


def verdict(claim_id: str, rule: ClaimResult) -> str:
    assert rule.id == claim_id
    return rule.verdict


def test_s1() -> None:
    assert verdict("S1", sec3.s1(0.01)) == "reproduced"
    assert verdict("S1", sec3.s1([0.01, 0.02, 0.03, 0.04, 0.049])) == "reproduced"
    assert verdict("S1", sec3.s1([0.01, 0.02, 0.03, 0.04, 0.06])) == "not reproduced"  # one seed off
    assert verdict("S1", sec3.s1(0.2)) == "not reproduced"


def s2_numbers(**over):
    base = dict(nominal_rel=[0.01] * 5, test_rel_neural_ode=[0.3, 0.4, 0.35, 0.3, 0.5], rate_neural_ode=SEEDS_LOSE,
                rate_feedback=SEEDS_WIN, err_N_neural_ode=SEEDS_LOSE, err_N_feedback=SEEDS_WIN, N=50)
    return base | over


def test_s2() -> None:
    assert verdict("S2", sec3.s2(**s2_numbers())) == "reproduced"
    # the feedback is better in only 3 of 5 seeds: no win
    mixed = [0.10, 0.30, 0.09, 0.30, 0.12]
    r = sec3.s2(**s2_numbers(err_N_feedback=mixed))
    assert r.checks["feedback_N50_better"] is False and verdict("S2", r) == "partly"
    none = sec3.s2(**s2_numbers(rate_feedback=SEEDS_LOSE, rate_neural_ode=SEEDS_WIN,
                                err_N_feedback=SEEDS_LOSE, err_N_neural_ode=SEEDS_WIN))
    assert verdict("S2", none) == "not reproduced"
    assert "5 seeds" in none.rule
    # the degradation is the test spiral's premise (fixed by its choice): shown as a number, never a check
    assert set(none.checks) == {"feedback_rate_better", "feedback_N50_better"} and none.numbers["premise_holds_every_seed"]
    flat = sec3.s2(**s2_numbers(test_rel_neural_ode=[0.015] * 5))
    assert flat.verdict == "reproduced" and flat.numbers["premise_holds_every_seed"] is False


def s3_numbers(**over):
    # rows: noise std 0, 0.01, 0.1; columns: seeds
    base = dict(noise_std=[0.0, 0.01, 0.1], judged_std=0.01,
                decay=[[1.0] * 5, [1.2, 1.1, 1.3, 1.2, 1.2], [3.0] * 5],
                no_decay=[[1.05] * 5, [2.0, 2.1, 2.2, 2.0, 1.9], [9.0] * 5],
                neural_ode=[[4.0] * 5, [4.0, 4.1, 3.9, 4.0, 4.2], [4.5] * 5])
    return base | over


def test_s3() -> None:
    assert verdict("S3", sec3.s3(**s3_numbers())) == "reproduced"
    # the decayed cascade loses to the open-loop neural ODE at the judged level (the case)
    r = sec3.s3(**s3_numbers(neural_ode=[[4.0] * 5, [1.0] * 5, [4.5] * 5]))
    assert r.checks["decay_better_than_neural_ode_at_std_0.01"] is False and verdict("S3", r) == "partly"
    assert r.reading_verdicts() == {"strict": "partly", "as worded": "reproduced"}
    # decay helps as much without noise: not the noise mechanism
    r = sec3.s3(**s3_numbers(no_decay=[[2.0] * 5, [2.0, 2.1, 2.2, 2.0, 1.9], [9.0] * 5]))
    assert r.checks["decay_helps_more_at_std_0.01_than_noise_free"] is False
    assert r.reading_verdicts()["as worded"] == "partly"
    worse = sec3.s3(**s3_numbers(decay=[[2.0] * 5, [5.0] * 5, [9.5] * 5]))
    assert worse.readings["as worded"].verdict == "not reproduced"
    assert verdict("S3", worse) == "not reproduced"
    with pytest.raises(ValueError, match="judged level"):
        sec3.s3(**s3_numbers(judged_std=0.03))


def test_s4() -> None:
    n = np.arange(1, 101, dtype=float)
    nn = np.stack([n * 0.1 * (1 + 0.01 * s) for s in range(5)], axis=1)
    assert verdict("S4", sec3.s4(err_neural_ode=nn, err_feedback=nn * 0.5, N=50)) == "reproduced"
    late = nn * 0.5
    late[80:] = nn[80:] * 2  # feedback worse beyond N = 80
    r = sec3.s4(err_neural_ode=nn, err_feedback=late, N=50)
    assert r.checks == {"feedback_better_all_N<=50": True, "feedback_better_all_N<=100": False}
    assert verdict("S4", sec3.s4(err_neural_ode=nn[:, 0], err_feedback=nn[:, 0] * 2, N=50)) == "not reproduced"


def s5_numbers(**over):
    base = dict(ball_x=1.0, ball_f=21.0, feedback_x=0.3, feedback_f=6.0, continuous_x=0.3, continuous_f=6.0,
                ratio_x=3.0, ratio_f=3.5, L_sweep=[5.0, 10.0, 20.0], limit_x=[1.0, 0.5, 0.25],
                ball_x_sweep=[4.0, 2.0, 1.0])
    return base | over


def test_s5() -> None:
    r = sec3.s5(**s5_numbers())
    assert verdict("S5", r) == "reproduced" and len(r.guarantees) == 6 and len(r.checks) == 1
    assert verdict("S5", sec3.s5(**s5_numbers(ratio_x=1.5))) == "not reproduced"  # not conservative (the paper run)
    # the limit falling as L grows is the linear recursion's (Eq. (25)): a guarantee; a run against it stops
    with pytest.raises(GuaranteeFailed, match="limit_decreases_with_L"):
        sec3.s5(**s5_numbers(limit_x=[1.0, 0.5, 0.6]))
    assert "limit_decreases_with_L" not in r.checks and "project's choice" in r.reading
    bad = sec3.s5(**s5_numbers(ratio_x=0.5, ratio_f=0.7))
    assert verdict("S5", bad) == "not reproduced"
    # the feedback network outside its ball (Eq. (25) with the run's gamma) is a broken guarantee, not a verdict
    with pytest.raises(AssertionError, match="feedback_x_in_ball"):
        sec3.s5(**s5_numbers(feedback_x=2.0))
    with pytest.raises(AssertionError, match="inside_gamma_over_L"):
        sec3.s5(**s5_numbers(limit_x=[5.0, 6.0, 7.0]))
    # the continuous observer outside Theorem 1's ball is a broken guarantee: the run is wrong
    with pytest.raises(AssertionError, match="Theorem 1"):
        sec3.s5(**s5_numbers(continuous_x=2.0))


def s6_numbers(**over):
    rho = [1.0, 0.5, 0.01, 0.99, 1.01, 1.5]
    base = dict(rho=rho, diverges=[False, False, False, False, True, True], max_err=[1.0, 0.1, 0.1, 0.5, 1e3, 1e9],
                iss_bound=[np.inf, 0.2, 0.2, 0.6, np.inf, np.inf], switches=1, rho_lo=0.99 + 0.01, rho_hi=1.01,
                rate=[1.001, 1.0, 1.0, 1.0, 1.0101, 1.499])
    return base | over


def test_s6() -> None:
    r = sec3.s6(**s6_numbers())
    assert verdict("S6", r) == BY_CONSTRUCTION and r.checks == {} and len(r.guarantees) == 2
    assert r.numbers["detector_agrees_with_Eq_25"] == {"diverges_above_rho_1": [True], "transition_at_rho_1": [True],
                                                       "growth_rate_is_rho": [True]}
    # a record too short to see rho = 1.01 diverge: reported, not a verdict and not a broken run
    short = sec3.s6(**s6_numbers(diverges=[False, False, False, False, False, True], switches=2, rho_hi=1.5))
    assert short.verdict == BY_CONSTRUCTION
    assert short.numbers["detector_agrees_with_Eq_25"]["diverges_above_rho_1"] == [False]
    with pytest.raises(AssertionError, match="bounded_below_rho_1"):
        sec3.s6(**s6_numbers(diverges=[False, True, False, False, True, True]))
    with pytest.raises(AssertionError, match="under_iss_bound"):
        sec3.s6(**s6_numbers(max_err=[1.0, 0.3, 0.1, 0.5, 1e3, 1e9]))


def s7_numbers(**over):
    base = dict(outward_noisy=0.9, outward_noise_free=0.85, levels_interior_min_noisy=8, n_levels=10,
                best_gain_noisy=[10.0] * 10, best_gain_noise_free=[45.0] * 10)
    return base | over


def test_s7() -> None:
    assert verdict("S7", sec3.s7(**s7_numbers())) == "reproduced"
    # the noise-free control has the same best gains: the shape is not the noise's doing
    r = sec3.s7(**s7_numbers(best_gain_noise_free=[10.0] * 10))
    assert r.checks["noise_lowers_the_best_gain(most_levels)"] is False and verdict("S7", r) == "partly"
    none = sec3.s7(**s7_numbers(outward_noisy=0.5, outward_noise_free=0.4, levels_interior_min_noisy=2,
                                best_gain_noise_free=[5.0] * 10))
    assert verdict("S7", none) == "not reproduced"


#: the paper's 12 residual levels (App. A.4): offsets {-0.72: 0.12: 0.6} etc.; level 6 is the zero residual
OFFSETS = [[-0.72 + 0.12 * j, -0.03 + 0.005 * j, -14.4 + 2.4 * j] for j in range(12)]


def test_s8() -> None:
    lo, hi = [0.1] * 12, [0.2] * 12
    r = sec3.s8(rate_neural_ode=hi, rate_feedback=lo, err_N_neural_ode=hi, err_N_feedback=lo, offsets=OFFSETS)
    assert r.reading_verdicts() == {"strict": "reproduced", "as worded": "reproduced"}
    zero_off = lo[:6] + [0.3] + lo[7:]  # lost at the zero-residual level only: strict partly, as worded holds
    r = sec3.s8(rate_neural_ode=hi, rate_feedback=lo, err_N_neural_ode=hi, err_N_feedback=zero_off, offsets=OFFSETS)
    assert r.reading_verdicts() == {"strict": "partly", "as worded": "reproduced"}
    other_off = lo[:3] + [0.3] + lo[4:]  # lost at a level with a residual: both readings fail it
    r = sec3.s8(rate_neural_ode=hi, rate_feedback=lo, err_N_neural_ode=hi, err_N_feedback=other_off, offsets=OFFSETS)
    assert r.reading_verdicts() == {"strict": "partly", "as worded": "partly"}
    r = sec3.s8(rate_neural_ode=lo, rate_feedback=hi, err_N_neural_ode=lo, err_N_feedback=hi, offsets=OFFSETS)
    assert r.reading_verdicts() == {"strict": "not reproduced", "as worded": "not reproduced"}
    with pytest.raises(ValueError, match="one finite row per level"):
        sec3.s8(rate_neural_ode=hi, rate_feedback=lo, err_N_neural_ode=hi, err_N_feedback=lo, offsets=OFFSETS[:11])


def test_s9() -> None:
    beta = [0.0, 0.01, 0.02, 0.03]
    assert verdict("S9", sec3.s9(beta=beta, rmse_noisy=[3.0, 2.0, 1.5, 1.8],
                                 rmse_noise_free=[1.0, 1.1, 1.2, 1.3])) == "reproduced"
    # the noise-free control has its minimum at the same beta: the mechanism check fails
    r = sec3.s9(beta=beta, rmse_noisy=[3.0, 2.0, 1.5, 1.8], rmse_noise_free=[1.0, 0.9, 0.8, 0.85])
    assert r.checks["noise_raises_the_best_beta"] is False and verdict("S9", r) == "partly"
    assert verdict("S9", sec3.s9(beta=beta, rmse_noisy=[1.0, 2.0, 3.0, 4.0],
                                 rmse_noise_free=[1.0, 2.0, 3.0, 4.0])) == "not reproduced"


def test_s10() -> None:
    left = {"band": 1.0, "peak": 5.0, "time": 0.2}
    kw = dict(rate_err_after_feedback=0.1, rate_err_after_neural_ode=1.0)
    assert verdict("S10", sec3.s10(state=left, rate=left, multistep=left, **kw)) == "reproduced"
    # the state error never leaves its band: nothing was attenuated, the check fails (no longer vacuous)
    r = sec3.s10(state={"band": 1.0, "peak": 0.9, "time": 0.0}, rate=left, multistep=left, **kw)
    assert r.checks["observer_error_leaves_band_and_returns_within_0.5s"] is False
    assert r.reading_verdicts() == {"strict": "partly", "as worded": "reproduced"}
    # the N-step recovery counts: 0.7 s against the 0.5 s rule
    r = sec3.s10(state=left, rate=left, multistep={"band": 1.0, "peak": 5.0, "time": 0.7}, **kw)
    assert r.checks["multistep_error_leaves_band_and_returns_within_0.5s"] is False and verdict("S10", r) == "partly"
    assert r.reading_verdicts()["as worded"] == "partly"  # slow is slow in both readings
    slow = {"band": 1.0, "peak": 5.0, "time": 2.0}
    r = sec3.s10(state=slow, rate=slow, multistep=slow, rate_err_after_feedback=2.0, rate_err_after_neural_ode=1.0)
    assert r.reading_verdicts() == {"strict": "not reproduced", "as worded": "not reproduced"}


def s11_numbers(**over):
    design = {"luenberger_pole_err": 1e-12, "kf_L_rel_err_vs_dlqe": 1e-12, "kf_P_rel_err_vs_dlqe": 1e-12,
              "filterpy_K_rel_err": 1e-9, "rho_linear_feedback": 0.8, "rho_luenberger": 0.5, "rho_kalman_steady": 0.9}
    base = dict(design=design, equiv={"max_rel_diff_lowpass": 1e-7, "max_rel_diff_luenberger": 1e-7}, same_data=True,
                rate_settled={"neural ODE": 5.0, "linear feedback": 0.4, "Luenberger": 0.5, "Kalman": 0.3})
    return base | over


def test_s11() -> None:
    r = sec3.s11(**s11_numbers())
    assert verdict("S11", r) == "reproduced" and len(r.guarantees) == 5
    r = sec3.s11(**s11_numbers(rate_settled={"neural ODE": 5.0, "linear feedback": 1.0, "Kalman": 0.3}))
    assert verdict("S11", r) == "partly"
    r = sec3.s11(**s11_numbers(rate_settled={"neural ODE": 0.5, "linear feedback": 1.0, "Kalman": 0.3}))
    assert verdict("S11", r) == "not reproduced"
    with pytest.raises(AssertionError, match="luenberger_poles_as_placed"):
        design = s11_numbers()["design"] | {"luenberger_pole_err": 1e-3}
        sec3.s11(**s11_numbers(design=design))


# ---- S5-S11 over seeds: threshold checks hold in >= S-1 of S seeds, wins are paired (fnnlib.stats.paired_win)

def test_most_seeds_and_every_seed() -> None:
    assert sec3.most_seeds([True, True, True, True, False]) and not sec3.most_seeds([True, True, True, False, False])
    assert sec3.most_seeds([True]) and not sec3.most_seeds([False])  # one run: that run, never vacuous
    assert sec3.most_seeds([True, False]) and not sec3.most_seeds([False, False])
    assert sec3.every_seed([True] * 5) and not sec3.every_seed([True] * 4 + [False])


def s5_seeds(**over):
    base = dict(ball_x=[1.0] * 5, ball_f=[21.0] * 5, feedback_x=[0.3] * 5, feedback_f=[6.0] * 5,
                continuous_x=[0.3] * 5, continuous_f=[6.0] * 5, ratio_x=[3.0, 2.5, 3.1, 2.2, 2.9],
                ratio_f=[3.5] * 5, L_sweep=[5.0, 10.0, 20.0], limit_x=[[1.0] * 5, [0.5] * 5, [0.25] * 5],
                ball_x_sweep=[[4.0] * 5, [2.0] * 5, [1.0] * 5])
    return base | over


def test_s5_over_seeds() -> None:
    r = sec3.s5(**s5_seeds())
    assert verdict("S5", r) == "reproduced" and "5 seeds" in r.rule
    # one seed not conservative: still holds (4 of 5); two seeds: fails
    assert sec3.s5(**s5_seeds(ratio_x=[3.0, 1.5, 3.1, 2.2, 2.9])).checks["conservative_ratio>=2"] is True
    r = sec3.s5(**s5_seeds(ratio_x=[3.0, 1.5, 1.1, 2.2, 2.9]))
    assert r.checks["conservative_ratio>=2"] is False and verdict("S5", r) == "not reproduced"
    lim = [[1.0] * 5, [0.5, 0.5, 1.2, 1.1, 0.5], [0.25] * 5]  # not decreasing in two seeds: against Eq. (25)
    with pytest.raises(GuaranteeFailed, match="limit_decreases_with_L"):
        sec3.s5(**s5_seeds(limit_x=lim, ball_x_sweep=[[4.0] * 5, [2.0] * 5, [2.0] * 5]))
    bad = sec3.s5(**s5_seeds(ratio_x=[0.5] * 5))
    assert verdict("S5", bad) == "not reproduced"
    with pytest.raises(AssertionError, match="feedback_f_in_ball"):
        sec3.s5(**s5_seeds(feedback_f=[6.0] * 4 + [30.0]))
    # Theorem 1 must hold in every seed: one seed outside the ball stops the run
    with pytest.raises(AssertionError, match="Theorem 1"):
        sec3.s5(**s5_seeds(continuous_x=[0.3] * 4 + [2.0]))
    with pytest.raises(ValueError, match="same seeds"):
        sec3.s5(**s5_seeds(ratio_f=[3.5] * 4))


def s6_seeds(**over):
    one = s6_numbers()
    col = lambda v: [[x] * 5 for x in v]  # noqa: E731 -- the same run in every seed
    base = dict(rho=one["rho"], diverges=col(one["diverges"]), max_err=col(one["max_err"]),
                iss_bound=col(one["iss_bound"]), switches=[1] * 5, rho_lo=[1.0] * 5, rho_hi=[1.01] * 5,
                rate=col(one["rate"]))
    return base | over


def test_s6_over_seeds() -> None:
    assert verdict("S6", sec3.s6(**s6_seeds())) == BY_CONSTRUCTION
    r = sec3.s6(**s6_seeds(switches=[1, 2, 1, 1, 1]))  # what the detector sees is reported per seed
    assert r.numbers["detector_agrees_with_Eq_25"]["transition_at_rho_1"] == [True, False, True, True, True]
    err = s6_seeds()["max_err"]
    err[1] = [0.1, 0.1, 0.1, 0.1, 0.3]  # one seed over its ISS bound: the guarantee fails
    with pytest.raises(AssertionError, match="under_iss_bound"):
        sec3.s6(**s6_seeds(max_err=err))


def s7_seeds(**over):
    base = dict(outward_noisy=[0.9, 0.85, 0.95, 0.9, 0.7], outward_noise_free=[0.85] * 5,
                levels_interior_min_noisy=[8, 9, 7, 8, 8], n_levels=10,
                best_gain_noisy=[[10.0] * 5] * 10, best_gain_noise_free=[[45.0] * 5] * 10)
    return base | over


def test_s7_over_seeds() -> None:
    r = sec3.s7(**s7_seeds())
    assert verdict("S7", r) == "reproduced" and "5 seeds" in r.rule and "one trained network" not in r.rule
    r = sec3.s7(**s7_seeds(outward_noisy=[0.9, 0.7, 0.95, 0.9, 0.7]))  # two seeds below the trend fraction
    assert r.checks["error_grows_with_uncertainty_noisy(frac>=0.8)"] is False and verdict("S7", r) == "partly"
    r = sec3.s7(**s7_seeds(best_gain_noise_free=[[10.0] * 5] * 10))
    assert r.checks["noise_lowers_the_best_gain(most_levels)"] is False
    none = sec3.s7(**s7_seeds(outward_noisy=[0.5] * 5, outward_noise_free=[0.4] * 5,
                              levels_interior_min_noisy=[2] * 5, best_gain_noise_free=[[5.0] * 5] * 10))
    assert verdict("S7", none) == "not reproduced"


def test_s8_over_seeds() -> None:
    lo, hi = [SEEDS_WIN] * 12, [SEEDS_LOSE] * 12
    r = sec3.s8(rate_neural_ode=hi, rate_feedback=lo, err_N_neural_ode=hi, err_N_feedback=lo, offsets=OFFSETS)
    assert verdict("S8", r) == "reproduced" and "5 seeds" in r.rule
    # at one level the feedback wins in only 3 of 5 seeds: no paired win there
    mixed = lo[:6] + [[0.10, 0.30, 0.09, 0.30, 0.12]] + lo[7:]
    r = sec3.s8(rate_neural_ode=hi, rate_feedback=lo, err_N_neural_ode=hi, err_N_feedback=mixed, offsets=OFFSETS)
    assert r.checks["multistep_better_at_all_12_levels"] is False and verdict("S8", r) == "partly"
    assert r.reading_verdicts()["as worded"] == "reproduced"  # level 6 is the zero-residual one
    assert verdict("S8", sec3.s8(rate_neural_ode=lo, rate_feedback=hi, err_N_neural_ode=lo,
                                 err_N_feedback=hi, offsets=OFFSETS)) == "not reproduced"


def test_s9_over_seeds() -> None:
    beta = [0.0, 0.01, 0.02, 0.03]
    noisy = [[3.0, 3.1, 2.9, 3.0, 3.2], [2.0, 2.1, 2.0, 1.9, 2.2], [1.5] * 5, [1.8] * 5]
    clean = [[1.0] * 5, [1.1] * 5, [1.2] * 5, [1.3] * 5]
    assert verdict("S9", sec3.s9(beta=beta, rmse_noisy=noisy, rmse_noise_free=clean)) == "reproduced"
    # the fall at the second beta in only 3 of 5 seeds: no paired win
    r = sec3.s9(beta=beta, rmse_noisy=[noisy[0], [2.0, 3.5, 2.0, 3.5, 2.2], *noisy[2:]], rmse_noise_free=clean)
    assert r.checks["falls_at_first"] is False and verdict("S9", r) == "partly"
    # the noise-free best beta equals the noisy one in two seeds: the mechanism fails
    clean2 = [[1.0] * 5, [1.1] * 5, [1.2, 1.2, 1.2, 0.5, 0.5], [1.3] * 5]
    assert sec3.s9(beta=beta, rmse_noisy=noisy, rmse_noise_free=clean2).checks["noise_raises_the_best_beta"] is False
    rising = [[1.0] * 5, [2.0] * 5, [3.0] * 5, [4.0] * 5]
    assert verdict("S9", sec3.s9(beta=beta, rmse_noisy=rising, rmse_noise_free=rising)) == "not reproduced"


def test_s10_over_seeds() -> None:
    left = {"band": [1.0] * 5, "peak": [5.0] * 5, "time": [0.2, 0.3, 0.1, 0.2, 0.6]}  # one seed slow: still holds
    kw = dict(rate_err_after_feedback=SEEDS_WIN, rate_err_after_neural_ode=SEEDS_LOSE)
    r = sec3.s10(state=left, rate=left, multistep=left, **kw)
    assert verdict("S10", r) == "reproduced" and "5 seeds" in r.rule
    slow2 = left | {"time": [0.2, 0.7, 0.1, 0.2, 0.6]}  # two seeds over 0.5 s
    r = sec3.s10(state=left, rate=left, multistep=slow2, **kw)
    assert r.checks["multistep_error_leaves_band_and_returns_within_0.5s"] is False and verdict("S10", r) == "partly"
    inside = left | {"peak": [0.9, 0.9, 5.0, 5.0, 5.0]}  # never leaves its band in two seeds
    assert sec3.s10(state=inside, rate=left, multistep=left, **kw).checks[
        "observer_error_leaves_band_and_returns_within_0.5s"] is False
    slow = {"band": [1.0] * 5, "peak": [5.0] * 5, "time": [2.0] * 5}
    assert verdict("S10", sec3.s10(state=slow, rate=slow, multistep=slow, rate_err_after_feedback=SEEDS_LOSE,
                                   rate_err_after_neural_ode=SEEDS_WIN)) == "not reproduced"


def s11_seeds(**over):
    one = s11_numbers()
    base = dict(design={k: [v] * 5 for k, v in one["design"].items()},
                equiv={k: [v] * 5 for k, v in one["equiv"].items()}, same_data=True,
                rate_settled={"neural ODE": [5.0, 5.1, 4.9, 5.0, 5.2], "linear feedback": [0.4, 0.41, 0.39, 0.4, 0.42],
                              "Luenberger": [0.5] * 5, "Kalman": [0.3] * 5})
    return base | over


def test_s11_over_seeds() -> None:
    r = sec3.s11(**s11_seeds())
    assert verdict("S11", r) == "reproduced" and "5 seeds" in r.rule and "one trained network" not in r.rule
    rs = s11_seeds()["rate_settled"] | {"linear feedback": [0.4, 0.7, 0.8, 0.4, 0.4]}  # > 2x Kalman in two seeds
    assert verdict("S11", sec3.s11(**s11_seeds(rate_settled=rs))) == "partly"
    # below the neural ODE in only 3 of 5 seeds: no paired win
    rs = s11_seeds()["rate_settled"] | {"neural ODE": [0.3, 5.0, 0.3, 5.0, 5.0], "linear feedback": [0.4] * 5}
    assert sec3.s11(**s11_seeds(rate_settled=rs)).checks["feedback_rate_beats_neural_ode"] is False
    rs = {"neural ODE": [0.5] * 5, "linear feedback": [1.0] * 5, "Kalman": [0.3] * 5}
    assert verdict("S11", sec3.s11(**s11_seeds(rate_settled=rs))) == "not reproduced"
    design = s11_seeds()["design"] | {"luenberger_pole_err": [1e-12] * 4 + [1e-3]}  # one seed's design off
    with pytest.raises(AssertionError, match="luenberger_poles_as_placed"):
        sec3.s11(**s11_seeds(design=design))
