"""The paper-vs-release page says what the code runs now.

Each table row of ``book/paper_vs_release.md`` is read: every claim ID it names must be judged by a task of
its section (``pipeline.yaml``), and every setting it gives in the "this book" cell as ``name = value`` (or
``name: value``) must be, where ``name`` is a parameter of one of the section's notebooks, that notebook's
value (the first such mention in a row; later ones name the alternatives a parameter switches to).  A name
that is no parameter must still occur in the section's notebooks or the library (no stale names).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
import yaml

from fnnbook.params import read_parameters, task_defaults
from fnnbook.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "book" / "paper_vs_release.md"
#: the page's sections (headings) and the tasks whose settings they describe
SECTIONS = {"Spiral": ("spiral", "theory", "ablations", "observers", "neural_feedback"),
            "Neural feedback": ("neural_feedback",), "Irregular object": ("bottle",),
            "Quadrotor": ("quadrotor_learning", "quadrotor_mpc"),
            "Release-only details of the MPC flights": ("quadrotor_learning", "quadrotor_mpc")}
_ID = re.compile(r"(?<!Fig\. )(?<!Figs\. )\b([SDOQB]\d{1,2})\b")  # a claim ID, not a figure (Fig. S12)
#: words right after a setting that make it an alternative the parameter switches to, not the value that runs
_ALTERNATIVE = re.compile(r"^\W{0,3}\s*(switches|gives)")
_SETTING = re.compile(r"`([A-Za-z_][A-Za-z0-9_]*)\s*(?:=|:)\s*([^`]+)`")


def _plain(value: object) -> object:
    return [_plain(v) for v in value] if isinstance(value, (list, tuple)) else value


def rows() -> list[tuple[str, list[str]]]:
    """(section, cells) for every table row of the page (header and rule lines left out)."""
    out, section = [], None
    for line in PAGE.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            title = line.lstrip("#").strip()
            section = next((s for s in SECTIONS if title.startswith(s)), section)
        elif line.startswith("|") and not line.startswith("|---") and not line.startswith("| setting |"):
            assert section is not None, f"a table row before any known section: {line[:60]}"
            out.append((section, [c.strip() for c in line.strip().strip("|").split(" | ")]))
    return out


def _value(text: str) -> object:
    try:
        return ast.literal_eval(text.strip())
    except (ValueError, SyntaxError):
        return yaml.safe_load(text)


@pytest.fixture(scope="module")
def spec():
    return load_spec(ROOT / "pipeline.yaml")


@pytest.fixture(scope="module")
def defaults(spec) -> dict[str, dict[str, object]]:
    """Task -> its notebook's parameters as the paper profile runs them (its settings' paper values)."""
    out = {}
    for name, task in spec.tasks.items():
        values = task_defaults(task, read_parameters(task.notebook)) | dict(task.parameters.get("paper", {}))
        out[name] = {k: _plain(v) for k, v in values.items()}
    return out


def test_the_page_has_its_rows() -> None:
    found = rows()
    assert len(found) >= 50 and {s for s, _ in found} == set(SECTIONS)
    assert all(len(cells) == 4 for _, cells in found), [c[0] for _, c in found if len(c) != 4]


@pytest.mark.parametrize(("section", "cells"), rows(), ids=lambda v: v[0][:40] if isinstance(v, list) else v)
def test_each_row_names_claims_of_its_section_and_the_values_that_run(section, cells, spec, defaults) -> None:
    tasks = SECTIONS[section]
    judged = {cid: name for name, task in spec.tasks.items() for cid in task.claims}
    registry = yaml.safe_load((ROOT / "claims.yaml").read_text(encoding="utf-8"))
    by_book = {c["id"] for g in registry["groups"] for c in g["claims"] if c["task"] == "scoreboard"}
    for cid in _ID.findall(" ".join(cells[:1] + cells[3:])):
        if cid in by_book:
            continue  # computed by the scoreboard over every task (B2, B3)
        assert cid in judged, f"{cid} is judged by no task"
        assert judged[cid] in tasks, f"{cid} is judged by {judged[cid]}, not by a task of the {section} section"
    first: set[str] = set()
    for match in _SETTING.finditer(cells[3]):
        name, text = match.groups()
        if _ALTERNATIVE.match(cells[3][match.end():]):
            continue
        owners = [t for t in tasks if name in defaults[t]]
        if not owners:
            assert _occurs(name, tasks, spec), f"{name!r} is no parameter and occurs nowhere in the code"
            continue
        if name in first:
            continue  # an alternative the parameter switches to
        first.add(name)
        expect = _plain(_value(text))
        assert any(defaults[t][name] == expect for t in owners), (
            f"{section} / {cells[0]}: the page says {name} = {expect!r}, the notebooks run "
            f"{ {t: defaults[t][name] for t in owners} }")


def _occurs(name: str, tasks: tuple[str, ...], spec) -> bool:
    """``name`` is a word of one of the tasks' notebook sources or of the library."""
    word = re.compile(rf"\b{re.escape(name)}\b")
    files = [ROOT / "notebooks" / "src" / (Path(spec.tasks[t].notebook).stem + ".py") for t in tasks]
    files += sorted((ROOT / "fnnlib").rglob("*.py"))
    return any(word.search(f.read_text(encoding="utf-8")) for f in files if f.is_file())


def test_a_stale_value_fails(spec, defaults) -> None:
    """The row check can fail: the S11 row with a made-up value of a real parameter."""
    cells = ["Kalman comparison (S11)", "-", "-", "from `kf_tuning_cases = 12` training cases"]
    with pytest.raises(AssertionError, match="kf_tuning_cases"):
        test_each_row_names_claims_of_its_section_and_the_values_that_run("Spiral", cells, spec, defaults)
    with pytest.raises(AssertionError, match="Q3 is judged by quadrotor_mpc"):
        test_each_row_names_claims_of_its_section_and_the_values_that_run("Spiral", ["x (Q3)", "", "", ""],
                                                                          spec, defaults)
