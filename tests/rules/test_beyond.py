"""The B1 rule (fnnbook.rules.beyond): numbers that must pass, numbers that must fail, bad input refused."""

from __future__ import annotations

import pytest

from fnnbook.rules.beyond import KALMAN_FACTOR, b1, b1_paired
from fnnlib.results import claim_result

GOOD = {"tuned": [1.0, 1.1, 0.9, 1.0, 1.05], "hand": [2.0, 2.1, 1.9, 2.2, 2.0],
        "open_loop": [3.0, 3.2, 2.9, 3.1, 3.0], "kalman": [0.8, 0.9, 0.7, 0.8, 0.9]}
SWAPPED = {"tuned": GOOD["hand"], "hand": GOOD["tuned"]}


def verdict(errors) -> str:
    return claim_result("B1", **b1(errors), numbers={})["verdict"]


def test_clear_wins_pass_every_check():
    r = b1({"spiral": GOOD})
    assert r["checks"] == {"spiral: tuned beats hand": True, "spiral: tuned beats open loop": True,
                           f"spiral: tuned within {KALMAN_FACTOR:g}x Kalman": True}
    assert r["guarantees"] == {} and verdict({"spiral": GOOD}) == "reproduced"
    stats = b1_paired({"spiral": GOOD})
    assert set(stats) == {"spiral: tuned vs hand", "spiral: tuned vs open_loop", "spiral: tuned vs kalman"}
    assert stats["spiral: tuned vs hand"]["wins"] == 5
    assert stats["spiral: tuned vs kalman"]["win"] is False  # worse than Kalman here, within the factor


def test_losing_to_the_hand_gains_fails():
    assert b1({"bottle": SWAPPED})["checks"] == {"bottle: tuned beats hand": False}
    assert verdict({"bottle": SWAPPED}) == "not reproduced"


def test_one_loss_is_allowed_two_are_not():
    hand = [2.0] * 5
    one_loss, two_losses = [1.0, 1.0, 1.0, 1.0, 2.1], [1.0, 1.0, 1.0, 2.1, 2.1]
    assert b1({"q": {"tuned": one_loss, "hand": hand}})["checks"]["q: tuned beats hand"] is True
    assert b1({"q": {"tuned": two_losses, "hand": hand}})["checks"]["q: tuned beats hand"] is False


def test_wins_inside_the_noise_fail():
    """Lower in every unit, but the 90 % interval of the mean difference reaches 0: no win."""
    errors = {"s": {"tuned": [1.0, 1.0, 1.0], "hand": [1.0001, 1.2, 1.0001]}}
    stats = b1_paired(errors)["s: tuned vs hand"]
    assert stats["wins"] == 3 and stats["ci_high"] > 0
    assert b1(errors)["checks"]["s: tuned beats hand"] is False


def test_kalman_factor_all_units_but_one():
    kalman, hand = [1.0] * 5, [20.0] * 5
    ok = [KALMAN_FACTOR] * 4 + [10.0]
    bad = [KALMAN_FACTOR * 1.01] * 2 + [1.0] * 3
    key = f"s: tuned within {KALMAN_FACTOR:g}x Kalman"
    assert b1({"s": {"tuned": ok, "hand": hand, "kalman": kalman}})["checks"][key] is True
    assert b1({"s": {"tuned": bad, "hand": hand, "kalman": kalman}})["checks"][key] is False


def test_settings_are_judged_apart_and_some_checks_give_partly():
    errors = {"a": GOOD, "b": SWAPPED | {"open_loop": GOOD["open_loop"]}}
    checks = b1(errors)["checks"]
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
