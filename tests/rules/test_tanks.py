"""The rules of B4-B6 (the cascaded tanks benchmark), on made-up numbers that pass and that fail."""

from __future__ import annotations

import pytest

from fnnbook.rules.tanks import b4, b5, b6

WIN = [0.10, 0.11, 0.09, 0.12, 0.10]     # clearly lower in every seed
LOSE = [0.20, 0.22, 0.19, 0.21, 0.20]
NOISY = [0.15, 0.10, 0.25, 0.08, 0.30]   # lower in 2 of 5 seeds against LOSE: no win


def test_b4_reproduced_when_feedback_wins_at_every_horizon() -> None:
    errors = {N: {"feedback": WIN, "open_loop": LOSE} for N in (5, 10, 25, 50)} | {1: {"feedback": WIN, "open_loop": WIN}}
    r = b4(errors)
    assert r.verdict == "reproduced" and len(r.checks) == 4 and r.n == 5
    assert list(r.checks) == [f"N={N}: feedback beats open loop" for N in (5, 10, 25, 50)]
    assert r.guarantees == {"N=1: feedback equals open_loop (the observer alone, no layer after it)": True}
    assert r.headline.n == 5 and r.headline.value == pytest.approx(sum(w / l for w, l in zip(WIN, LOSE)) / 5)


def test_b4_partly_when_feedback_loses_at_long_horizons() -> None:
    errors = {2: {"feedback": WIN, "open_loop": LOSE}, 5: {"feedback": WIN, "open_loop": LOSE},
              25: {"feedback": LOSE, "open_loop": WIN}, 50: {"feedback": NOISY, "open_loop": LOSE}}
    r = b4(errors)
    assert r.verdict == "partly"
    assert r.checks == {"N=2: feedback beats open loop": True, "N=5: feedback beats open loop": True,
                        "N=25: feedback beats open loop": False, "N=50: feedback beats open loop": False}


def test_b4_not_reproduced_when_feedback_never_wins() -> None:
    assert b4({N: {"feedback": LOSE, "open_loop": WIN} for N in (2, 10)}).verdict == "not reproduced"


def test_n1_is_a_guarantee_not_a_check() -> None:
    """At N = 1 both predictions are the observer's: a difference there means the run itself is wrong."""
    from fnnbook.results import GuaranteeFailed  # noqa: PLC0415

    same = {1: {"tuned": WIN, "hand": WIN}}
    assert b6(same).verdict == "verified by construction" and not b6(same).checks
    with pytest.raises(GuaranteeFailed, match="N=1"):
        b6({1: {"tuned": WIN, "hand": LOSE}, 5: {"tuned": WIN, "hand": LOSE}})


def test_b5_wins_and_loses() -> None:
    assert b5(observer_trained=WIN, no_feedback=LOSE).verdict == "reproduced"
    assert b5(observer_trained=LOSE, no_feedback=WIN).verdict == "not reproduced"
    assert b5(observer_trained=NOISY, no_feedback=LOSE).verdict == "not reproduced"  # 2 of 5 seeds only
    r = b5(observer_trained=WIN, no_feedback=LOSE)
    assert r.headline.unit == "V" and r.numbers["mean"]["no_feedback"] == pytest.approx(0.204)


def test_b6_per_horizon() -> None:
    r = b6({5: {"tuned": WIN, "hand": LOSE}, 50: {"tuned": LOSE, "hand": WIN}})
    assert r.verdict == "partly"
    assert r.checks == {"N=5: tuned gains beat hand gains": True, "N=50: tuned gains beat hand gains": False}


@pytest.mark.parametrize(("call", "match"), [
    (lambda: b4({}), "at least one horizon"),
    (lambda: b4({0: {"feedback": WIN, "open_loop": LOSE}}), "integers >= 1"),
    (lambda: b4({5: {"feedback": WIN}}), "no 'open_loop'"),
    (lambda: b4({5: {"feedback": WIN, "open_loop": LOSE[:4]}}), "pair seed by seed"),
    (lambda: b4({5: {"feedback": [0.1], "open_loop": [0.2]}}), "at least 2 seeds"),
    (lambda: b6({5: {"tuned": [0.1, float("nan")], "hand": [0.2, 0.2]}}), "non-finite"),
    (lambda: b5(observer_trained=WIN, no_feedback=LOSE[:3]), "pair seed by seed"),
])
def test_bad_numbers_are_refused(call, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()


def test_the_rules_at_a_grid_point_read_the_named_columns() -> None:
    """b4_at pits the named cascade column against the open loop, b6_at the tuned gains against the hand gains."""
    from fnnbook.rules.tanks import b4_at, b6_at

    point = {"tuned": {2: WIN, 5: WIN}, "hand": {2: LOSE, 5: LOSE}, "L=0.01, beta=0": {2: NOISY, 5: NOISY},
             "open_loop": {2: LOSE, 5: LOSE}}
    assert b4_at(point, [2, 5]).verdict == "reproduced"
    assert b4_at(point, [2, 5], "L=0.01, beta=0").verdict == "not reproduced"
    assert b6_at(point, [2, 5]).verdict == "reproduced"
    assert b6_at(point | {"tuned": point["hand"], "hand": point["tuned"]}, [2]).verdict == "not reproduced"


def test_reproduced_marks_the_points_whose_rule_reads_reproduced() -> None:
    from fnnbook.why import reproduced

    assert reproduced([[b4({2: {"feedback": WIN, "open_loop": LOSE}}), b4({2: {"feedback": LOSE, "open_loop": WIN}})]]
                      ).tolist() == [[True, False]]
