"""Verdicts derive from the checks alone."""

from __future__ import annotations

import json

import pytest

from fnnbook.results import BY_CONSTRUCTION, STATUSES, VERDICTS, ClaimResult, Reading, verdict_from_checks


@pytest.mark.parametrize(("checks", "verdict"), [
    ({"a": True}, "reproduced"),
    ({"a": True, "b": True}, "reproduced"),
    ({"a": True, "b": False}, "partly"),
    ({"a": False, "b": False}, "not reproduced"),
    ({"a": 0, "b": 1.0}, "partly"),  # truthiness, as numpy bools give
])
def test_verdict_from_checks(checks: dict[str, bool], verdict: str) -> None:
    assert verdict_from_checks(checks) == verdict
    assert verdict in VERDICTS


def test_a_claim_without_checks_has_no_verdict() -> None:
    with pytest.raises(ValueError, match="at least one check"):
        verdict_from_checks({})


def test_a_claim_result_carries_the_derived_verdict() -> None:
    entry = ClaimResult("S2", checks={"smaller": True, "better": False}, numbers={"err": 0.5},
                        rule="err_fb < err_node", figure="figures/fig4f.png")
    assert entry.verdict == "partly" and entry.to_json()["verdict"] == "partly"
    assert entry.figure == "figures/fig4f.png"


def _two_readings() -> ClaimResult:
    return ClaimResult("S3", checks={"decay beats no decay": True, "decay beats neural ODE": False},
                       rule="r", reading="strict: both", reading_name="strict",
                       readings={"as worded": Reading("decay beats no decay only", {"decay beats no decay": True})},
                       n=5, at_paper_setting="at 4 N: not judged (thrust 5.1 N needed, bound 4 N)")


def test_readings_each_derive_their_verdict_and_round_trip() -> None:
    claim = _two_readings()
    assert claim.verdict == "partly"
    assert claim.reading_verdicts() == {"strict": "partly", "as worded": "reproduced"}
    back = ClaimResult.from_json(json.loads(json.dumps(claim.to_json())))
    assert back == claim and back.n == 5 and back.at_paper_setting.startswith("at 4 N")


def test_a_stored_reading_verdict_other_than_its_checks_is_refused() -> None:
    data = _two_readings().to_json()
    data["readings"]["as worded"]["verdict"] = "not reproduced"
    with pytest.raises(ValueError, match="not the one its checks imply"):
        ClaimResult.from_json(data)


def test_readings_need_a_name_for_the_counted_one_and_reading_objects() -> None:
    with pytest.raises(ValueError, match="reading_name"):
        ClaimResult("S3", checks={"a": True}, rule="r", readings={"x": Reading("s", {"a": True})})
    with pytest.raises(TypeError):
        ClaimResult("S3", checks={"a": True}, rule="r", reading_name="strict", readings={"x": ("s", {"a": True})})


@pytest.mark.parametrize("n", [0, -1, 2.5, True])
def test_n_is_a_positive_count(n: object) -> None:
    with pytest.raises(ValueError, match="positive count"):
        ClaimResult("Q3", checks={"a": True}, rule="r", n=n)


def test_guarantees_alone_verify_by_construction_never_reproduce() -> None:
    claim = ClaimResult("S6", checks={}, guarantees={"Eq. (25) recursion exact": True}, rule="r")
    assert claim.verdict == BY_CONSTRUCTION != "reproduced" and claim.verdict in STATUSES
    assert ClaimResult.from_json(claim.to_json()).verdict == BY_CONSTRUCTION
    with pytest.raises(ValueError, match="at least one check"):
        ClaimResult("S6", checks={}, guarantees={}, rule="r")
    data = claim.to_json() | {"verdict": "reproduced"}
    with pytest.raises(ValueError, match="not the one its checks imply"):
        ClaimResult.from_json(data)


def test_a_claim_without_the_new_fields_writes_the_old_json() -> None:
    claim = ClaimResult("S2", checks={"a": True}, rule="r", numbers={"e": 1.0}, guarantees={"g": True})
    assert list(claim.to_json()) == ["id", "verdict", "rule", "checks", "numbers", "figure", "guarantees"]
    old = {"id": "S2", "verdict": "reproduced", "rule": "r", "checks": {"a": True}, "numbers": {}, "figure": None}
    assert ClaimResult.from_json(old).reading is None and ClaimResult.from_json(old).to_json() == old
