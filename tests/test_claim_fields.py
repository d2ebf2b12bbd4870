"""The optional fields of a claim's result: guarantees apart from checks, headline number, paper's number."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import numpy as np
import pytest

from fnnbook.results import ClaimResult, GuaranteeFailed, Headline, headline_number, read_results, write_results


def test_a_result_without_the_new_fields_is_unchanged() -> None:
    entry = ClaimResult("S2", checks={"a": True}, numbers={"err": 0.5}, rule="r", figure="figures/f.png")
    assert list(entry.to_json()) == ["id", "verdict", "rule", "checks", "numbers", "figure"]  # as written before


def test_headline_over_seeds_is_mean_and_sample_spread() -> None:
    per_seed = np.array([4.56, 4.61, 4.49, 4.70, 4.52])
    head = headline_number("0.5 s position error, feedback", per_seed, unit="cm")
    assert head.value == pytest.approx(statistics.fmean(per_seed.tolist()))
    assert head.spread == pytest.approx(statistics.stdev(per_seed.tolist()))  # ddof = 1
    assert head.n == 5 and list(head.per_seed) == per_seed.tolist() and head.unit == "cm"
    assert list(head.to_json()) == ["name", "value", "spread", "n", "per_seed", "unit"]
    single = headline_number("rho", np.float64(0.99))
    assert single.to_json() == {"name": "rho", "value": 0.99, "unit": ""}  # one run: no spread claimed
    assert single == Headline("rho", 0.99) and Headline.from_json(head.to_json()) == head
    assert headline_number("one seed", [3.0]).spread == 0.0


@pytest.mark.parametrize(("name", "value", "match"), [("", 1.0, "needs a name"), ("x", [], "no per-seed values")])
def test_headline_refuses_bad_input(name: str, value: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        headline_number(name, value)  # type: ignore[arg-type]


def test_guarantees_are_apart_and_never_decide_the_verdict() -> None:
    entry = ClaimResult("D2", checks={"within 1.5x of nominal": False}, guarantees={"frozen weights": True},
                        numbers={}, rule="r")
    assert entry.verdict == "not reproduced"  # the holding guarantee does not lift it to "partly"
    assert entry.guarantees == {"frozen weights": True} and "frozen weights" not in entry.checks


def test_a_failed_guarantee_stops_the_run() -> None:
    with pytest.raises(GuaranteeFailed, match="claim D2: guarantee.*frozen weights"):
        ClaimResult("D2", checks={"a": True}, guarantees={"frozen weights": np.bool_(False)}, numbers={}, rule="r")


def test_headline_needs_name_and_value() -> None:
    entry = ClaimResult("S1", checks={"a": True}, numbers={}, rule="r").to_json()
    with pytest.raises(ValueError, match="headline lacks value"):
        ClaimResult.from_json(entry | {"headline": {"name": "x"}})
    with pytest.raises(TypeError, match="headline must be a Headline"):
        ClaimResult("S1", checks={"a": True}, numbers={}, rule="r", headline={"name": "x"})  # type: ignore[arg-type]


def test_new_fields_round_trip_and_a_forged_guarantee_is_refused(tmp_path: Path) -> None:
    entry = ClaimResult("O1", checks={"a": True}, numbers={}, rule="r", guarantees={"g": True},
                        headline=headline_number("err", [1.0, 2.0]), paper="4.56 vs 4.74 cm", title="feedback wins")
    path = write_results(tmp_path, task="bottle", profile="paper", claims=[entry])
    back = read_results(path).claim("O1")
    assert back.headline.spread == pytest.approx(0.7071067811865476)
    assert (back.paper, back.title, back.guarantees) == ("4.56 vs 4.74 cm", "feedback wins", {"g": True})
    data = json.loads(path.read_text())
    data["claims"][0]["guarantees"] = {"g": False}
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="claim 'O1' has a failed guarantee"):
        read_results(path)
