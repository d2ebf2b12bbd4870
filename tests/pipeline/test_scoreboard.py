"""The scoreboard: claim IDs from the claims file, verdicts from results.json."""

from __future__ import annotations

from pathlib import Path

import pytest

from fnnbook.scoreboard import NOT_RUN, read_claims, render_scoreboard, score_rows

CLAIMS = """# What the book must reproduce

Intro text with a | pipe that is not a table.

## Spiral (Sec. 3-4)
Some settings.

| ID | claim | paper figure |
|---|---|---|
| S1 | the neural ODE fits | Fig. 4c |
| S2 | feedback beats \\| the ODE | Fig. 4d-f |

## Beyond the paper
| ID | what | why |
|---|---|---|
| B1 | tune L | the paper's limitation |
"""


@pytest.fixture
def claims_file(tmp_path: Path) -> Path:
    path = tmp_path / "CLAIMS.md"
    path.write_text(CLAIMS)
    return path


def test_read_claims(claims_file: Path) -> None:
    claims = read_claims(claims_file)
    assert [c.id for c in claims] == ["S1", "S2", "B1"]
    assert claims[0].group == "Spiral (Sec. 3-4)"
    assert claims[0].text == "the neural ODE fits" and claims[0].figure == "Fig. 4c"
    assert claims[1].text == "feedback beats | the ODE"  # unescaped
    assert claims[2].group == "Beyond the paper" and claims[2].figure == ""  # "why" is no figure


def test_duplicate_id_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "CLAIMS.md"
    path.write_text("## A\n| ID | claim | paper figure |\n|---|---|---|\n| S1 | x | y |\n| S1 | z | w |\n")
    with pytest.raises(ValueError, match="claim ID 'S1' appears twice"):
        read_claims(path)


def test_repository_claims_file_parses() -> None:
    path = Path(__file__).resolve().parents[2] / ".." / "shared" / "CLAIMS.md"
    if not path.is_file():
        pytest.skip("no shared CLAIMS.md beside the repository")
    ids = [c.id for c in read_claims(path)]
    assert ids[:2] == ["S1", "S2"] and "D1" in ids and "Q6" in ids and "B3" in ids


def test_scoreboard_lists_verdicts_and_not_run(claims_file: Path) -> None:
    results = {"spiral": {"task": "spiral", "profile": "smoke", "claims": [
        {"id": "S1", "verdict": "partly", "rule": "err < 0.1 and fit", "figure": "figures/fig4c.png",
         "checks": {"small error": True, "fits": False},
         "numbers": {"err": 0.012345, "steps": 50, "curve": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]}}]}}
    rows = score_rows(read_claims(claims_file), results, {"spiral": ["S1", "S2"]})
    assert [(r.claim.id, r.verdict, r.task) for r in rows] == [
        ("S1", "partly", "spiral"), ("S2", NOT_RUN, "spiral"), ("B1", NOT_RUN, None)]

    page = render_scoreboard(rows, profile="smoke", pages={"spiral": "spiral/spiral.ipynb"},
                             figures={"spiral": "spiral"})
    assert page.startswith("# Scoreboard\n")
    assert "3 claims, 0 reproduced, 1 partly, 0 not reproduced, 2 not run." in page
    assert ":::{warning}" in page  # not the paper profile
    lines = page.splitlines()
    s1 = next(line for line in lines if line.startswith("| **S1** |"))
    assert "{bdg-warning}`partly`" in s1
    assert "`err = 0.0123; steps = 50; curve = [1, 2, 3, 4, ...] (n=6)`" in s1
    assert "`✓ small error; ✗ fits`" in s1
    assert "err < 0.1 and fit" in s1
    assert "[spiral](spiral/spiral.ipynb) [figure](spiral/figures/fig4c.png)" in s1
    s2 = next(line for line in lines if line.startswith("| **S2** |"))
    assert "{bdg-secondary}`not run`" in s2 and "[spiral](spiral/spiral.ipynb)" in s2  # declared there
    assert "| feedback beats \\| the ODE |" in s2  # escaped again inside the table
    b1 = next(line for line in lines if line.startswith("| **B1** |"))
    assert "{bdg-secondary}`not run`" in b1
    assert "## Spiral (Sec. 3-4)" in lines and "## Beyond the paper" in lines
    assert render_scoreboard(rows, profile="paper", pages={}).count(":::{warning}") == 0


def test_self_check_flags_a_verdict_not_from_its_checks() -> None:
    from fnnlib.results import claim_result
    from fnnbook.scoreboard import Claim, self_check

    claims = [Claim(id="S1", group="g", text="t", figure=""), Claim(id="B3", group="g", text="t", figure="")]
    good = claim_result("S1", checks={"a": True}, numbers={}, rule="r")
    assert self_check(claims, {"task": {"claims": [good]}})["verdict"] == "reproduced"
    forged = {**good, "checks": {"a": False}}  # verdict says reproduced, checks say otherwise
    result = self_check(claims, {"task": {"claims": [forged]}})
    assert result["verdict"] == "partly"
    assert result["numbers"]["verdicts_not_from_checks"] == ["S1"]
    assert self_check(claims, {})["checks"]["results_found"] is False
