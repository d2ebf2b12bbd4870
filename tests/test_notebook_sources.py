"""Source notebooks are clean and built from their cell scripts in notebooks/src/."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from conftest import load_nbbuild

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted((ROOT / "notebooks" / "src").glob("*.py"))


_nbbuild = load_nbbuild


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_notebook_matches_its_source(src: Path) -> None:
    nb_path = ROOT / "notebooks" / f"{src.stem}.ipynb"
    assert nb_path.is_file(), f"run: .venv/bin/python tools/nbbuild.py {src} {nb_path}"
    built = _nbbuild().build(src)
    committed = json.loads(nb_path.read_text(encoding="utf-8"))

    def text(source: str | list[str]) -> str:
        return "".join(source) if isinstance(source, list) else source

    assert [text(c["source"]) for c in committed["cells"]] == [text(c.source) for c in built.cells], (
        f"{nb_path.name} is out of date with {src.name}: rebuild it with tools/nbbuild.py")


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_source_notebook_has_no_outputs(src: Path) -> None:
    nb = json.loads((ROOT / "notebooks" / f"{src.stem}.ipynb").read_text(encoding="utf-8"))
    for cell in nb["cells"]:
        assert not cell.get("outputs") and not cell.get("execution_count"), "source notebooks carry no outputs"


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_settings_are_checked_right_after_the_parameters_cell(src: Path) -> None:
    """The notebook runs the same value checks as `fnn-pipeline check` (fnnbook.settings.check_notebook_settings)."""
    cells = _nbbuild().build(src).cells
    first = next(i for i, c in enumerate(cells) if "parameters" in c.metadata.get("tags", []))
    task = re.sub(r"^\d+_", "", src.stem)  # files are numbered in paper order: 01_spiral.py runs task spiral
    assert f'\ncheck_notebook_settings("{task}", globals())' in cells[first + 1].source
    assert "from fnnbook.settings import check_notebook_settings" in cells[first + 1].source
