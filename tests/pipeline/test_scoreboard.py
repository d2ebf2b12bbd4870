"""The scoreboard: claim IDs from the claims file, verdicts from results.json."""

from __future__ import annotations

from pathlib import Path

import pytest

from fnnbook.scoreboard import (NOT_RUN, SCOREBOARD_TASK, Claim, headline_of, plot_verdicts, read_claims,
                               render_scoreboard, score_rows, self_check, short_title, verdict_counts,
                               with_scoreboard_claims)
from fnnbook.results import BETTER, BY_CONSTRUCTION, ClaimResult, GuaranteeFailed, Reading, Results, headline_number


def _results(task: str, *claims: ClaimResult) -> dict[str, Results]:
    return {task: Results(task=task, profile="smoke", claims=claims)}

CLAIMS = """# a comment | with a pipe
groups:
  - name: Spiral (Sec. 3-4)
    settings: Some settings.
    claims:
      - id: S1
        statement: the neural ODE fits
        section: Sec. 3.1
        figure: Fig. 4c
        task: spiral
        notebook: notebooks/src/01_spiral.py
      - id: S2
        statement: >-
          feedback beats | the ODE
        section: Sec. 3.3
        figure: Fig. 4d-f
        settings: N = 50.
        task: spiral
  - name: Beyond the paper
    settings: Ours.
    claims:
      - {id: B1, statement: tune L, section: Sec. 7, figure: none, task: tuned}
"""


@pytest.fixture
def claims_file(tmp_path: Path) -> Path:
    path = tmp_path / "claims.yaml"
    path.write_text(CLAIMS)
    return path


def test_read_claims(claims_file: Path) -> None:
    claims = read_claims(claims_file)
    assert [c.id for c in claims] == ["S1", "S2", "B1"]
    assert claims[0].group == "Spiral (Sec. 3-4)"
    assert claims[0].text == "the neural ODE fits" and claims[0].figure == "Fig. 4c"
    assert claims[0].section == "Sec. 3.1" and claims[0].notebook == "notebooks/src/01_spiral.py"
    assert claims[0].settings == "Some settings." and claims[1].settings == "Some settings. N = 50."
    assert claims[1].text == "feedback beats | the ODE" and claims[1].notebook == ""
    assert claims[2].group == "Beyond the paper" and claims[2].task == "tuned"
    assert claims[2].figure == ""  # "none": the paper has no figure for it


@pytest.mark.parametrize(("registry", "message"), [
    ("groups:\n  - {name: A, settings: s, claims: [{id: S1, statement: x, section: y, figure: z, task: t},"
     " {id: S1, statement: x, section: y, figure: z, task: t}]}\n", "claim ID 'S1' appears twice"),
    ("groups:\n  - {name: A, settings: s, claims: [{id: S1, statement: '  ', section: y, figure: z, task: t}]}\n",
     "'statement' must be a non-empty string"),
    ("groups:\n  - {name: A, settings: s, claims: [{id: S1, statement: x, figure: z, task: t}]}\n",
     "'section' must be a non-empty string"),
    ("groups:\n  - {name: A, settings: s, claims: [{id: s-1, statement: x, section: y, figure: z, task: t}]}\n",
     "is not letters followed by a number"),
    ("groups:\n  - {name: A, settings: s, claims: [{id: S1, statement: x, section: y, figure: z, task: t,"
     " paper: p}]}\n", r"unknown field\(s\) \['paper'\]"),
    ("groups:\n  - {name: A, claims: []}\n", "'settings' must be a non-empty string"),
    ("| S1 | a markdown table | Fig. 1 |\n", "not a YAML claims registry"),
    ("# Claims\n\n## Spiral\n", "expected a list under 'groups'"),
])
def test_a_registry_off_the_schema_is_refused(registry: str, message: str, tmp_path: Path) -> None:
    path = tmp_path / "claims.yaml"
    path.write_text(registry)
    with pytest.raises(ValueError, match=message):
        read_claims(path)


def _row_lines(page: str, cid: str) -> tuple[str, str]:
    """The summary line of a claim's row and the body folded under it."""
    head = f"::::{{dropdown}} [{cid}]{{.sb-id}} "
    start = page.index(head)
    body_end = page.index("\n::::\n", start)
    line_end = page.index("\n", start)
    return page[start:line_end], page[line_end:body_end]


def test_scoreboard_lists_verdicts_and_not_run(claims_file: Path) -> None:
    results = {"spiral": Results.from_json({"task": "spiral", "profile": "smoke", "claims": [
        {"id": "S1", "verdict": "partly", "rule": "err < 0.1 and fit", "figure": "figures/fig4c.png",
         "checks": {"small error": True, "fits": False},
         "numbers": {"err": 0.012345, "steps": 50, "curve": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]}}]})}
    rows = score_rows(read_claims(claims_file), results, {"spiral": ["S1", "S2"]})
    assert [(r.claim.id, r.verdict, r.task) for r in rows] == [
        ("S1", "partly", "spiral"), ("S2", NOT_RUN, "spiral"), ("B1", NOT_RUN, None)]

    page = render_scoreboard(rows, profile="smoke", pages={"spiral": "spiral/spiral.ipynb"},
                             figures={"spiral": "spiral"}, summary_figure="verdicts.png")
    assert page.startswith("# Scoreboard\n")
    assert ("3 claims, 0 reproduced, 1 partly, 0 not reproduced, "
            "0 better than claimed, 0 verified by construction, 2 not run.") in page
    assert "```{image} verdicts.png" in page  # the verdicts per section, under the counts
    assert ":::{warning}" in page  # not the paper profile
    lines = page.splitlines()

    s1, s1_body = _row_lines(page, "S1")
    assert "{bdg-warning}`partly`" in s1
    assert "[the neural ODE fits]{.sb-claim}" in s1  # the claim in a few words
    assert "[*paper, Fig. 4c:* the neural ODE fits]{.sb-paper}" in s1  # the paper's statement and figure
    assert "[checks holding: **1 of 2**]{.sb-ours}" in s1  # no headline in the result: checks, not a guess
    assert "[section](spiral/spiral.ipynb) {ref}`figure <claim-s1-figure>`" in s1
    assert "| `err` | 0.0123 |" in s1_body and "| `steps` | 50 |" in s1_body
    assert "| `curve` | \\[1, 2, 3, 4, ...\\] (n=6) |" in s1_body
    assert "- ✓ `small error`" in s1_body and "- ✗ `fits`" in s1_body
    assert "**Rule.** err \\< 0.1 and fit" in s1_body  # escaped: no inline HTML taken from a rule
    assert "(claim-s1-figure)=\n```{image} spiral/figures/fig4c.png" in s1_body
    assert "Guarantees" not in s1_body  # none reported

    s2, s2_body = _row_lines(page, "S2")
    assert "{bdg-secondary}`not run`" in s2 and "[section](spiral/spiral.ipynb)" in s2  # declared there
    assert "feedback beats \\| the ODE" in s2  # escaped again inside the row
    assert "No task has produced a result" in s2_body
    b1, _ = _row_lines(page, "B1")
    assert "{bdg-secondary}`not run`" in b1 and "[—]{.sb-where}" in b1
    assert "## Spiral (Sec. 3-4)" in lines and "## Beyond the paper" in lines
    assert render_scoreboard(rows, profile="paper", pages={}).count(":::{warning}") == 0


def test_scoreboard_row_shows_headline_paper_and_guarantees_apart(claims_file: Path) -> None:
    entry = ClaimResult("S1", checks={"fb below node in 4 of 5 seeds": True},
                        guarantees={"frozen weights unchanged": True},
                        numbers={"err_fb": [0.1, 0.12, 0.11]}, rule="r",
                        headline=headline_number("N=50 error, feedback", [0.10, 0.12, 0.11], unit="m"),
                        paper="4.56 cm vs 4.74 cm", title="feedback fits better")
    rows = score_rows(read_claims(claims_file), _results("spiral", entry))
    s1, body = _row_lines(render_scoreboard(rows, profile="paper", pages={}), "S1")
    assert "[feedback fits better]{.sb-claim}" in s1
    assert "[N=50 error, feedback: **0.11 ± 0.01 m (n = 3 seeds)**]{.sb-ours}" in s1
    assert "[*paper, Fig. 4c:* 4.56 cm vs 4.74 cm]{.sb-paper}" in s1
    assert "{bdg-success}`reproduced`" in s1
    checks_at, guarantees_at = body.index("**Checks**"), body.index("**Guarantees**")
    assert body.index("`fb below node in 4 of 5 seeds`") < guarantees_at  # checks, then guarantees apart
    assert body.index("`frozen weights unchanged`") > guarantees_at > checks_at


def test_row_shows_both_readings_n_and_the_paper_setting_the_count_uses_the_first(claims_file: Path) -> None:
    s1 = ClaimResult("S1", checks={"strict a": True, "strict b": False}, rule="r", reading="both a and b",
                     reading_name="strict", readings={"as worded": Reading("a only", {"a": True})}, n=3,
                     at_paper_setting="at 4 N: cannot be judged (needs 5.2 N of thrust)")
    s2 = ClaimResult("S2", checks={}, guarantees={"algebra of Eq. (25)": True}, rule="r")
    rows = score_rows(read_claims(claims_file), _results("spiral", s1, s2))
    page = render_scoreboard(rows, profile="paper", pages={})
    assert ("3 claims, 0 reproduced, 1 partly, 0 not reproduced, 0 better than claimed, 1 verified by construction, "
            "1 not run.") in page
    row, body = _row_lines(page, "S1")
    assert "{bdg-warning}`partly` strict (counted): partly; as worded: reproduced]{.sb-verdict}" in row
    assert "**1 of 2 (n = 3)**" in row and "at 4 N: cannot be judged (needs 5.2 N of thrust)" in row
    assert "**Reading (strict, counted).** both a and b" in body and 'Reading "as worded"** (reproduced' in body
    row2, body2 = _row_lines(page, "S2")
    assert "{bdg-info}`verified by construction`" in row2 and "No check" in body2
    assert verdict_counts(rows)["Spiral (Sec. 3-4)"][BY_CONSTRUCTION] == 1


def test_headline_of_a_single_value_has_no_spread() -> None:
    name, text = headline_of(ClaimResult("S1", checks={"a": True}, rule="r",
                                         headline=headline_number("RMSE", 0.0421, unit="cm")))
    assert (name, text) == ("RMSE", "0.0421 cm")
    assert headline_of(None) == ("", "")


def test_short_title_keeps_the_first_clause() -> None:
    assert short_title("Theorem 1: the error enters the ball") == "Theorem 1"
    assert short_title("a b c d e f g h i j k", words=3) == "a b c …"
    assert short_title("") == ""


def test_verdict_figure_counts_per_section(claims_file: Path, tmp_path: Path) -> None:
    results = _results("t", ClaimResult("S1", checks={"a": True}, numbers={}, rule="r"))
    rows = score_rows(read_claims(claims_file), results)
    assert verdict_counts(rows) == {
        "Spiral (Sec. 3-4)": {"reproduced": 1, "partly": 0, "not reproduced": 0, BETTER: 0, BY_CONSTRUCTION: 0,
                              NOT_RUN: 1},
        "Beyond the paper": {"reproduced": 0, "partly": 0, "not reproduced": 0, BETTER: 0, BY_CONSTRUCTION: 0,
                             NOT_RUN: 1}}
    png = plot_verdicts(rows, tmp_path / "verdicts.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_self_check_flags_a_verdict_not_from_its_checks() -> None:
    claims = [Claim(id="S1", group="g", text="t", figure=""), Claim(id="B3", group="g", text="t", figure="")]
    good = ClaimResult("S1", checks={"a": True}, numbers={}, rule="r")
    assert self_check(claims, _results("task", good)).verdict == BY_CONSTRUCTION
    assert self_check(claims, _results("task", good)).guarantees["verdicts_follow_checks"] is True
    forged = good.to_json() | {"checks": {"a": False}}  # verdict says reproduced, checks say otherwise
    with pytest.raises(ValueError, match=r"claim 'S1': verdict 'reproduced' is not the one its checks imply"):
        Results.from_json({"task": "task", "profile": "smoke", "claims": [forged]})  # refused as it is read
    with pytest.raises(GuaranteeFailed, match=r"not in the claims file \['X9'\]"):
        self_check(claims, _results("task", good.replace(id="X9")))
    assert self_check(claims, {}).checks == {} and self_check(claims, {}).numbers["tasks_with_results"] == 0


def test_self_check_b3_is_bookkeeping_verified_by_construction() -> None:
    """B3 is bookkeeping: no check decides it; a task that did not run is shown (claims_not_reported), not judged."""
    claims = [Claim(id=i, group="g", text="t", figure="") for i in ("S1", "O1", "B3")]
    good = ClaimResult("S1", checks={"a": True}, numbers={}, rule="r")
    result = self_check(claims, _results("spiral", good), {"spiral": ["S1"], "bottle": ["O1"]})
    assert result.verdict == BY_CONSTRUCTION and result.checks == {}
    assert result.numbers["claims_not_reported"] == ["O1"]
    assert set(result.guarantees) == {"ids_known", "verdicts_follow_checks"}


def test_the_scoreboard_adds_b2_then_b3_over_everything() -> None:
    claims = [Claim(id=i, group="g", text="t", figure="") for i in ("S1", "B2", "B3")]
    s1 = ClaimResult("S1", checks={"a": True}, rule="r", headline=headline_number("e", [1.0] * 5))
    results = with_scoreboard_claims(claims, _results("spiral", s1), "smoke", {"spiral": ["S1"]})
    own = results[SCOREBOARD_TASK]
    assert [c.id for c in own] == ["B2", "B3"] and own.claim("B2").verdict == "reproduced"
    assert own.claim("B3").numbers == {"tasks_with_results": 2, "claims_reported": 2, "claims_listed": 3,
                                       "claims_not_reported": []}
    assert SCOREBOARD_TASK not in with_scoreboard_claims(claims[:1], _results("spiral", s1), "smoke")


def test_the_tally_counts_the_reading_of_the_paper_words_and_shows_the_strict_one_beside(tmp_path: Path) -> None:
    path = tmp_path / "claims.yaml"
    path.write_text(CLAIMS.replace("task: spiral", "task: spiral\n        words: {reading: as worded, sentence: "
                                   "'the words'}\n        strict: strict", 1))
    claims = read_claims(path)
    assert claims[0].words == "as worded" and claims[0].words_sentence == "the words" and claims[0].strict == "strict"
    s1 = ClaimResult("S1", checks={"strict a": True, "strict b": False}, rule="r", reading="both a and b",
                     reading_name="strict", readings={"as worded": Reading("a only", {"a": True})})
    rows = score_rows(claims, _results("spiral", s1))
    assert rows[0].verdict == "reproduced" and rows[0].strict == "partly"  # counted: the words; strict beside
    assert verdict_counts(rows)["Spiral (Sec. 3-4)"]["reproduced"] == 1
    page = render_scoreboard(rows, profile="paper", pages={})
    assert "1 reproduced, 0 partly" in page and "by the strict readings of S1: 1 partly" in page
    row, body = _row_lines(page, "S1")
    assert "{bdg-success}`reproduced` as worded (counted): reproduced; strict: partly" in row
    assert "The paper's words" in body and '"the words"' in body
    # the claims file and the rule must agree on the readings' names
    with pytest.raises(ValueError, match="names the reading"):
        score_rows(claims, _results("spiral", s1.replace(readings={"other": Reading("x", {"a": True})})))
    bad = tmp_path / "bad.yaml"
    bad.write_text(CLAIMS.replace("task: spiral", "task: spiral\n        strict: strict", 1))
    with pytest.raises(ValueError, match="go together"):
        read_claims(bad)


def test_better_than_claimed_is_a_verdict_of_its_own(claims_file: Path) -> None:
    s1 = ClaimResult("S1", checks={"cost within the band (upper)": True, "cost within the band (lower)": False},
                     rule="r", better={"cost within the band (lower)": True})
    rows = score_rows(read_claims(claims_file), _results("spiral", s1))
    assert rows[0].verdict == BETTER
    page = render_scoreboard(rows, profile="paper", pages={})
    assert "1 better than claimed" in page and "`better than claimed`" in page


def test_a_row_says_what_its_units_share(tmp_path: Path) -> None:
    path = tmp_path / "claims.yaml"
    path.write_text(CLAIMS.replace("task: spiral", "task: spiral\n        units: one ensemble, shared batches", 1))
    claims = read_claims(path)
    assert claims[0].units == "one ensemble, shared batches"
    s1 = ClaimResult("S1", checks={"a": True}, rule="r", n=5)
    page = render_scoreboard(score_rows(claims, _results("spiral", s1)), profile="paper", pages={})
    assert "**Units:** n = 5. one ensemble, shared batches" in _row_lines(page, "S1")[1]


def test_a_spread_over_shared_units_is_not_shown_as_independent(tmp_path: Path) -> None:
    path = tmp_path / "claims.yaml"
    path.write_text(CLAIMS.replace("task: spiral", "task: spiral\n        units: one ensemble, shared batches"
                                                   "\n        shared: one ensemble", 1))
    claims = read_claims(path)
    assert claims[0].shared == "one ensemble"
    s1 = ClaimResult("S1", checks={"a": True}, rule="r",
                     headline=headline_number("RMSE", [0.04, 0.05, 0.06, 0.05, 0.05], unit="cm"))
    name, text = headline_of(s1, shared=claims[0].shared)
    assert text.endswith("(n = 5 seeds, one ensemble: not independent)")
    assert headline_of(s1)[1].endswith("(n = 5 seeds)")  # independent units: as before
    page = render_scoreboard(score_rows(claims, _results("spiral", s1)), profile="paper", pages={})
    row, body = _row_lines(page, "S1")
    assert "one ensemble: not independent" in row
    # a claim that names what its units share explains it in its units
    path.write_text(CLAIMS.replace("task: spiral", "task: spiral\n        shared: one ensemble", 1))
    with pytest.raises(ValueError, match="units"):
        read_claims(path)

