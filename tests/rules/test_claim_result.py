"""Every rule returns a ClaimResult for its own claim, and each survives results.json unchanged."""

from __future__ import annotations

import inspect
import json
import re
from pathlib import Path

import numpy as np
import pytest

from fnnbook.rules import beyond, bottle, quadrotor, sec3, sec4
from fnnbook.results import BY_CONSTRUCTION, ClaimResult, Results, headline_number, read_results, write_results

from .test_beyond import GOOD
from .test_quadrotor import paper_like
from .test_sec3 import s2_numbers, s3_numbers, s5_numbers, s6_numbers, s7_numbers, s11_numbers
from .test_sec4 import d4_numbers

HI, LO = np.full(12, 0.2), np.full(12, 0.1)
S = 15
#: one good call of every rule, by its function name
CALLS = {
    "s1": lambda: sec3.s1(0.01),
    "s2": lambda: sec3.s2(**s2_numbers()),
    "s3": lambda: sec3.s3(**s3_numbers()),
    "s4": lambda: sec3.s4(err_neural_ode=np.ones(100), err_feedback=np.full(100, 0.5), N=50),
    "s5": lambda: sec3.s5(**s5_numbers()),
    "s6": lambda: sec3.s6(**s6_numbers()),
    "s7": lambda: sec3.s7(**s7_numbers()),
    "s8": lambda: sec3.s8(rate_neural_ode=HI, rate_feedback=LO, err_N_neural_ode=HI, err_N_feedback=LO,
                          offsets=d4_numbers()["offsets"]),
    "s9": lambda: sec3.s9(beta=[0.0, 0.01, 0.02, 0.03], rmse_noisy=[3.0, 2.0, 1.5, 1.8],
                          rmse_noise_free=[1.0, 1.1, 1.2, 1.3]),
    "s10": lambda: sec3.s10(**{k: {"band": 1.0, "peak": 5.0, "time": 0.2} for k in ("state", "rate", "multistep")},
                            rate_err_after_feedback=0.1, rate_err_after_neural_ode=1.0),
    "s11": lambda: sec3.s11(**s11_numbers()),
    "d1": lambda: sec4.d1(rel_dr=0.2, rel_nominal=0.01),
    "d2": lambda: sec4.d2(rel_feedback=0.012, rel_nominal=0.01, frozen_unchanged=True),
    "d3": lambda: sec4.d3(ratio=[0.1] * 5, trend=[0.01, -0.02, 0.0, 0.05, 0.03]),
    "d4": lambda: sec4.d4(**d4_numbers()),
    "o1": lambda: bottle.o1(feedback=np.full(9, 0.03) + 0.001 * np.arange(9), neural_ode=np.full(9, 0.05),
                            drag=np.full(9, 0.10)),
    "o1_means": lambda: bottle.o1_means(per_throw={"feedback": np.full(9, 0.03) + 0.001 * np.arange(9),
                                                   "neural_ode": np.full(9, 0.05), "drag": np.full(9, 0.10)},
                                        per_seed={"feedback": np.full(5, 0.03) + 0.001 * np.arange(5),
                                                  "neural_ode": np.full(5, 0.05)}),
    "o1_per_seed": lambda: bottle.o1_per_seed(feedback=np.full((5, 9), 0.03) + 0.001 * np.arange(45).reshape(5, 9) / 45,
                                              neural_ode=np.full((5, 9), 0.05) + 0.001 * np.arange(45).reshape(5, 9) / 45,
                                              drag=np.full(9, 0.10)),
    "o2": lambda: bottle.o2(acc_rmse_feedback=0.5, acc_rmse_neural_ode=1.0, error_feedback=0.03, travel=1.0,
                            error_per_throw=[0.03] * 9),
    "q1_convergence": lambda: quadrotor.q1_convergence(np.outer(np.exp(-np.linspace(0, 10, 51)), np.ones(5)) + 0.01),
    "q2_prediction": lambda: quadrotor.q2_prediction([{"p": 0.02, "v": 0.03, "Theta": 0.05, "omega": 0.08 + k / 1e3}
                                                      for k in range(5)],
                                                     {"p": 0.5, "v": 0.4, "Theta": 0.1, "omega": 0.2}, units=range(5)),
    "q3_tracking": lambda: quadrotor.q3_tracking(paper_like(), units=range(len(paper_like()["FNN"])), label="6 N"),
    "q4_prediction": lambda: quadrotor.q4_prediction({k: v for k, v in paper_like().items() if k in quadrotor.SIX},
                                                     units=range(len(paper_like()["FNN"])), label="6 N"),
    "q5_adaptive": lambda: quadrotor.q5_adaptive(paper_like(), [1.0] * S, label="6 N"),
    "q6_training_cost": lambda: quadrotor.q6_training_cost(0, 1500.0),
    "b1": lambda: beyond.b1({"spiral": GOOD}),
    "b2": lambda: beyond.b2({"S1": headline_number("e", [1.0] * 5), "O1": headline_number("e", [2.0] * 5)}),
    "b3": lambda: beyond.b3({"S1", "B3"}, [ClaimResult("S1", checks={"a": True}, rule="r")], tasks_with_results=1,
                            expected={"S1"}),
}


def _rules() -> list[str]:
    """Every rule function of fnnbook.rules: the public functions named after a claim (``s1``, ``q3_tracking``)."""
    return sorted(name for module in (sec3, sec4, bottle, quadrotor, beyond)
                  for name, f in inspect.getmembers(module, inspect.isfunction)
                  if f.__module__ == module.__name__ and re.fullmatch(r"[a-z]\d+(_[a-z_]+)?", name)
                  and name not in ("b1_paired", "b1_summary", "b1_budget", "b1_coverage"))  # b1's numbers, not rules


def test_every_rule_has_a_call_here() -> None:
    assert set(_rules()) == set(CALLS)  # a new rule gets its call (and so its checks below)


@pytest.mark.parametrize("name", sorted(CALLS))
def test_every_rule_returns_its_claim_result_and_it_round_trips(name: str) -> None:
    result = CALLS[name]()
    assert isinstance(result, ClaimResult)
    assert result.id == name.split("_")[0].upper()
    assert result.rule
    # passing numbers reproduce; a claim with only guarantees is verified by construction, never reproduced
    assert (result.checks and result.verdict == "reproduced") or (
        not result.checks and result.guarantees and result.verdict == BY_CONSTRUCTION)
    again = ClaimResult.from_json(json.loads(json.dumps(result.to_json())))
    assert again == result and again.to_json() == result.to_json()


#: the rules that state their reading of the paper's words (Sec. 3-4 and Q1, Q5, Q6)
READ = [n for n in CALLS if n[0] in "sd" or n.split("_")[0] in ("q1", "q5", "q6")]


@pytest.mark.parametrize("name", READ)
def test_each_rule_states_its_reading_in_one_sentence(name: str) -> None:
    result = CALLS[name]()
    assert result.reading and not re.search(r"[a-z]{3,}\. [A-Z]", result.reading)  # one sentence (Fig. 4 aside)
    for other in (result.readings or {}).values():  # every other reading has its sentence and own checks
        assert other.sentence and other.checks and result.reading_name


def test_to_json_writes_the_keys_in_the_order_results_json_has_them() -> None:
    bare = ClaimResult("S2", checks={"a": True, "b": np.bool_(False)}, numbers={"err": np.float64(0.5)}, rule="r",
                       figure="figures/f.png")
    assert list(bare.to_json()) == ["id", "verdict", "rule", "checks", "numbers", "figure"]
    assert bare.to_json()["checks"] == {"a": True, "b": False} and type(bare.to_json()["numbers"]["err"]) is float
    full = bare.replace(guarantees={"g": True}, headline=headline_number("h", [1.0, 2.0]), paper="p", title="t")
    assert list(full.to_json()) == ["id", "verdict", "rule", "checks", "numbers", "figure", "guarantees",
                                    "headline", "paper", "title"]
    assert full.replace(guarantees={}).to_json()["guarantees"] == {}  # an empty dict is written, None is not
    nan = ClaimResult("S1", checks={"a": True}, rule="r", numbers={"x": float("nan")})
    assert nan.numbers == {"x": "nan"} and ClaimResult.from_json(nan.to_json()) == nan


def test_a_result_cannot_be_changed_behind_its_verdict() -> None:
    r = ClaimResult("S1", checks={"a": True}, rule="r")
    with pytest.raises(AttributeError):
        r.checks = {"a": False}  # type: ignore[misc]
    r.to_json()["checks"]["a"] = False  # a copy
    assert r.verdict == "reproduced"


@pytest.mark.parametrize(("change", "match"), [
    ({"verdict": "partly"}, "not the one its checks imply"),
    ({"verdict": "fine"}, "has verdict 'fine'"),
    ({"guarantees": {"g": False}}, "has a failed guarantee"),
    ({"extra": 1}, "unknown \\['extra'\\]"),
])
def test_from_json_refuses_a_forged_or_broken_claim(change: dict, match: str) -> None:
    good = ClaimResult("S1", checks={"a": True}, rule="r", guarantees={"g": True}).to_json()
    with pytest.raises(ValueError, match=match):
        ClaimResult.from_json(good | change)
    broken = {k: v for k, v in good.items() if k != "rule"}
    with pytest.raises(ValueError, match="missing \\['rule'\\]"):
        ClaimResult.from_json(broken)


def test_results_round_trip_through_the_file_and_find_a_claim(tmp_path: Path) -> None:
    claims = [CALLS["s5"]().replace(numbers={"ball": [0.1, 0.2]}, figure="figures/s1.png"), CALLS["q6_training_cost"]()]
    path = write_results(tmp_path, task="theory", profile="smoke", claims=claims, metrics={"seeds": np.arange(3)})
    back = read_results(path)
    assert isinstance(back, Results) and (back.task, back.profile) == ("theory", "smoke")
    assert list(back) == claims and back.claim("S5") == claims[0] and back.metrics == {"seeds": [0, 1, 2]}
    assert json.loads(path.read_text()) == back.to_json()
    with pytest.raises(KeyError, match="task 'theory' reports no claim 'S9' \\(it has \\['S5', 'Q6'\\]\\)"):
        back.claim("S9")
    with pytest.raises(ValueError, match="duplicate claim IDs"):
        write_results(tmp_path, task="theory", profile="smoke", claims=claims + claims[:1])
    with pytest.raises(TypeError, match="ClaimResult"):
        write_results(tmp_path, task="theory", profile="smoke", claims=[claims[0].to_json()])  # type: ignore[list-item]
