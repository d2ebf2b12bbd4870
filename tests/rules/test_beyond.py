"""The B1 rule (fnnbook.rules.beyond): numbers that must pass, numbers that must fail, bad input refused."""

from __future__ import annotations

import pytest

from fnnbook.rules.beyond import KALMAN_FACTOR, b1, b1_budget, b1_coverage, b1_paired, b1_summary, b2
from fnnbook.results import ClaimResult, Headline, headline_number

GOOD = {"tuned": [1.0, 1.1, 0.9, 1.0, 1.05], "hand": [2.0, 2.1, 1.9, 2.2, 2.0],
        "open_loop": [3.0, 3.2, 2.9, 3.1, 3.0], "kalman": [0.8, 0.9, 0.7, 0.8, 0.9]}
SWAPPED = {"tuned": GOOD["hand"], "hand": GOOD["tuned"]}


def verdict(errors) -> str:
    r = b1(errors)
    assert r.id == "B1"
    return r.verdict


def test_clear_wins_pass_every_check():
    r = b1({"spiral": GOOD})
    assert r.checks == {"spiral: tuned beats hand": True, "spiral: tuned beats open loop": True,
                           f"spiral: tuned within {KALMAN_FACTOR:g}x Kalman": True}
    assert r.guarantees == {} and verdict({"spiral": GOOD}) == "reproduced"
    stats = b1_paired({"spiral": GOOD})
    assert set(stats) == {"spiral: tuned vs hand", "spiral: tuned vs open_loop", "spiral: tuned vs kalman"}
    assert stats["spiral: tuned vs hand"]["wins"] == 5
    assert stats["spiral: tuned vs kalman"]["win"] is False  # worse than Kalman here, within the factor


def test_losing_to_the_hand_gains_fails():
    assert b1({"bottle": SWAPPED}).checks == {"bottle: tuned beats hand": False}
    assert verdict({"bottle": SWAPPED}) == "not reproduced"


def test_one_loss_is_allowed_two_are_not():
    hand = [2.0] * 5
    one_loss, two_losses = [1.0, 1.0, 1.0, 1.0, 2.1], [1.0, 1.0, 1.0, 2.1, 2.1]
    assert b1({"q": {"tuned": one_loss, "hand": hand}}).checks["q: tuned beats hand"] is True
    assert b1({"q": {"tuned": two_losses, "hand": hand}}).checks["q: tuned beats hand"] is False


def test_wins_inside_the_noise_fail():
    """Lower in every unit, but the 90 % interval of the mean difference reaches 0: no win."""
    errors = {"s": {"tuned": [1.0, 1.0, 1.0], "hand": [1.0001, 1.2, 1.0001]}}
    stats = b1_paired(errors)["s: tuned vs hand"]
    assert stats["wins"] == 3 and stats["ci_high"] > 0
    assert b1(errors).checks["s: tuned beats hand"] is False


def test_kalman_factor_all_units_but_one():
    kalman, hand = [1.0] * 5, [20.0] * 5
    ok = [KALMAN_FACTOR] * 4 + [10.0]
    bad = [KALMAN_FACTOR * 1.01] * 2 + [1.0] * 3
    key = f"s: tuned within {KALMAN_FACTOR:g}x Kalman"
    assert b1({"s": {"tuned": ok, "hand": hand, "kalman": kalman}}).checks[key] is True
    assert b1({"s": {"tuned": bad, "hand": hand, "kalman": kalman}}).checks[key] is False


def test_settings_are_judged_apart_and_some_checks_give_partly():
    errors = {"a": GOOD, "b": SWAPPED | {"open_loop": GOOD["open_loop"]}}
    checks = b1(errors).checks
    assert checks["a: tuned beats hand"] and not checks["b: tuned beats hand"]
    assert checks["b: tuned beats open loop"] is True  # worse than the hand gains, still better than no feedback
    assert "b: tuned within 2x Kalman" not in checks
    assert verdict(errors) == "partly"


@pytest.mark.parametrize("errors, match", [
    ({}, "at least one setting"),
    ({"s": {"tuned": [1.0, 2.0]}}, "no 'hand'"),
    ({"s": {"tuned": [1.0, 2.0], "hand": [1.0, 2.0], "ekf": [1.0, 1.0]}}, "unknown predictors"),
    ({"s": {"tuned": [1.0, 2.0], "hand": [1.0, 2.0, 3.0]}}, "one error per unit"),
    ({"s": {"tuned": [1.0], "hand": [1.0]}}, "at least 2"),
    ({"s": {"tuned": [1.0, float("nan")], "hand": [1.0, 2.0]}}, "non-finite"),
    ({"ok": GOOD, "s": {"tuned": [[1.0, 2.0]], "hand": [[1.0, 2.0]]}}, "one error per unit"),
])
def test_bad_input_is_refused(errors, match):
    with pytest.raises(ValueError, match=match):
        b1(errors)
    with pytest.raises(ValueError, match=match):
        b1_paired(errors)


def _headline(n: int | None) -> Headline:
    return Headline("x", 1.0) if n is None else Headline("x", 1.0, spread=0.1, n=n, per_seed=(1.0,) * n)


def test_b2_passes_when_every_claim_is_over_five_seeds_with_spread() -> None:
    rule = b2({"S1": _headline(5), "O1": _headline(5), "Q3": _headline(15)})
    assert all(rule.checks.values()) and all(rule.guarantees.values())


@pytest.mark.parametrize(("headlines", "failing"), [
    ({"S1": _headline(5), "O1": _headline(2)}, "per_seed_headlines_over_>=5_seeds"),  # a smoke-sized run
    ({"S1": _headline(5), "Q6": _headline(None)}, "every_claim_shows_a_spread"),  # one claim on one run
    ({"S1": _headline(5), "Q6": None}, "every_claim_shows_a_spread"),  # no headline at all
])
def test_b2_fails_on_too_few_seeds_or_a_single_run(headlines: dict, failing: str) -> None:
    rule = b2(headlines)
    assert rule.checks[failing] is False
    assert sum(rule.checks.values()) == 1


def test_b2_fails_entirely_when_nothing_is_over_seeds() -> None:
    rule = b2({"S1": _headline(None), "O1": _headline(None)})
    assert not any(rule.checks.values())
    with pytest.raises(ValueError, match="headlines"):
        b2({})


def test_b2_is_computed_by_the_scoreboard_from_the_tasks_claims() -> None:
    from fnnbook.scoreboard import seeds_check  # noqa: PLC0415
    from fnnbook.results import Results  # noqa: PLC0415

    s1 = ClaimResult("S1", checks={"a": True}, rule="r", headline=headline_number("e", [1.0] * 5))
    q6 = ClaimResult("Q6", checks={"a": True}, rule="r", headline=headline_number("t", 2.0))
    spiral, learning = Results("spiral", "paper", (s1,)), Results("quadrotor_learning", "paper", (q6,))
    assert seeds_check({"spiral": spiral}).verdict == "reproduced"
    partly = seeds_check({"spiral": spiral, "quadrotor_learning": learning})
    assert partly.verdict == "partly" and partly.numbers["claims_without_spread"] == ["Q6"]
    assert seeds_check({}) is None


def test_summary_reports_the_true_n_and_where_kalman_wins():
    kalman_better = {"tuned": [1.0, 1.1, 0.9, 1.0, 1.05, 1.0, 1.1], "hand": [2.0] * 7,
                     "kalman": [0.6, 0.6, 0.5, 0.55, 0.6, 0.6, 0.6]}
    tuned_better = {"tuned": [1.0, 1.1, 0.9], "hand": [2.0, 2.1, 2.2], "kalman": [1.5, 1.6, 1.7]}
    s = b1_summary({"a": kalman_better, "b": tuned_better, "c": SWAPPED})
    assert s["a"]["n"] == 7 and s["b"]["n"] == 3 and s["c"]["n"] == 5
    assert s["a"]["kalman_beats_tuned"] is True  # the chapter must say the filter wins here
    assert s["b"]["kalman_beats_tuned"] is False
    assert s["c"]["kalman_beats_tuned"] is None  # no filter given
    assert s["b"]["mean"]["hand"] == pytest.approx(2.1)
    # within 2x of the filter, so the check holds although the filter wins: the summary says so
    assert b1({"a": kalman_better}).checks["a: tuned within 2x Kalman"] is True


def test_summary_refuses_what_b1_refuses():
    with pytest.raises(ValueError, match="no 'hand'"):
        b1_summary({"a": {"tuned": [1.0, 2.0]}})


def test_the_budget_is_the_same_for_tuned_and_hand_gains_or_refused():
    assert b1_budget({"pendulum": {"tuned": 24, "hand": 24}, "bottle": {"tuned": 6, "hand": 6}}) == \
        {"pendulum": 24, "bottle": 6}
    with pytest.raises(ValueError, match="pendulum.*60.*9"):  # the old pendulum: 60 Adam steps against 9 grid points
        b1_budget({"pendulum": {"tuned": 60, "hand": 9}})
    with pytest.raises(ValueError, match="at least 1"):
        b1_budget({"bottle": {"tuned": 0, "hand": 0}})
    with pytest.raises(ValueError, match="tuned"):
        b1_budget({"bottle": {"hand": 6}})


def test_coverage_says_which_tuned_gains_lie_outside_the_hand_grid():
    grid = {"L_grid": [1.0, 4.0, 16.0], "beta_grid": [0.0, 0.1, 0.5]}
    inside = [{"L": [2.0, 15.9], "beta": 0.05}, {"L": 16.0, "beta": 0.0}]
    outside = [{"L": [2.0, 40.0], "beta": 0.05}, {"L": 3.0, "beta": 0.9}, {"L": 0.5, "beta": 0.1}]
    c = b1_coverage({"a": inside, "b": inside + outside}, {"a": [grid, grid], "b": [grid] * 5})
    assert c["a"] == {"units": 2, "covered": 2, "outside": [], "L_span": [1.0, 16.0], "beta_span": [0.0, 0.5]}
    assert c["b"]["covered"] == 2 and c["b"]["outside"] == [2, 3, 4]
    # the old spiral grid (L in 2..20) misses a tuned gain of 35
    old = {"L_grid": [2.0, 5.0, 20.0], "beta_grid": [0.02, 0.1, 0.5]}
    assert b1_coverage({"s": [{"L": [35.0, 30.0], "beta": 0.01}]}, {"s": [old]})["s"]["outside"] == [0]
    with pytest.raises(ValueError, match="one hand grid per unit"):
        b1_coverage({"a": inside}, {"a": [grid]})
