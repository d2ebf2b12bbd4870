"""Verdicts derive from the checks alone."""

from __future__ import annotations

import pytest

from fnnlib.results import VERDICTS, ClaimResult, verdict_from_checks


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
