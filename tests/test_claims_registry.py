"""The claims registry (claims.yaml): every claim of the paper once, each with its statement, place in the
paper, settings and the task that judges it; every task's declared claims in it."""

from __future__ import annotations

from pathlib import Path

from fnnbook import load_spec
from fnnbook.scoreboard import CLAIM_FIELDS, SEEDS_CHECK_ID, SELF_CHECK_ID, read_claims

ROOT = Path(__file__).resolve().parents[1]
#: the claim IDs of the reproduction: Sec. 3-4 spiral, Sec. 4 domain randomization, Sec. 5.1 object,
#: Sec. 5.2 quadrotor, beyond the paper
IDS = ([f"S{i}" for i in range(1, 12)] + [f"D{i}" for i in range(1, 5)] + ["O1", "O2"]
       + [f"Q{i}" for i in range(1, 7)] + ["B1", "B2", "B3", "B4", "B5", "B6"])


def _registry():
    spec = load_spec(ROOT / "pipeline.yaml")
    assert spec.claims_file.resolve().is_relative_to(ROOT), f"{spec.claims_file} is outside the repository"
    return spec, read_claims(spec.claims_file)


def test_every_claim_is_in_the_registry_once() -> None:
    _, claims = _registry()
    ids = [c.id for c in claims]
    assert sorted(ids) == sorted(IDS) and len(ids) == len(set(ids)) == 29


def test_every_claim_says_what_where_and_how() -> None:
    _, claims = _registry()  # read_claims refuses an empty required field (figure "none ..." reads as "")
    for c in claims:
        for field in (c.id, c.group, c.text, c.section, c.settings, c.task):
            assert field.strip(), f"{c.id}: an empty field (required: {CLAIM_FIELDS}, settings)"
        assert c.notebook == "" or (ROOT / c.notebook).is_file(), f"{c.id}: no notebook {c.notebook}"


def test_tasks_and_registry_agree_on_who_judges_what() -> None:
    spec, claims = _registry()
    judged = {c.id: c.task for c in claims}
    for name, task in spec.tasks.items():
        for cid in task.claims:
            assert judged.get(cid) == name, f"task {name!r} declares {cid}, the registry says {judged.get(cid)!r}"
    declared = {cid for task in spec.tasks.values() for cid in task.claims}
    by_book = {cid for cid, task in judged.items() if task == "scoreboard"}
    assert by_book == {SEEDS_CHECK_ID, SELF_CHECK_ID}  # computed by the scoreboard itself
    assert declared | by_book == set(judged), f"judged by no task: {sorted(set(judged) - declared - by_book)}"
    for c in claims:
        if c.notebook:
            assert spec.tasks[c.task].notebook.stem == Path(c.notebook).stem, f"{c.id}: {c.notebook}"
