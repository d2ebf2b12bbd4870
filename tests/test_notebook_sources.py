"""Source notebooks are clean and built by jupytext from their percent-format scripts in notebooks/src/."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from notebook_source import REBUILD, ROOT, SOURCES, cells, read_source


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_notebook_matches_its_source(src: Path) -> None:
    nb_path = ROOT / "notebooks" / f"{src.stem}.ipynb"
    assert nb_path.is_file(), f"run: {REBUILD}"
    committed = json.loads(nb_path.read_text(encoding="utf-8"))
    assert cells(committed) == cells(read_source(src)), (
        f"{nb_path.name} is out of date with {src.name}: rebuild it with {REBUILD}")


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_source_notebook_has_no_outputs(src: Path) -> None:
    nb = json.loads((ROOT / "notebooks" / f"{src.stem}.ipynb").read_text(encoding="utf-8"))
    for cell in nb["cells"]:
        assert not cell.get("outputs") and not cell.get("execution_count"), "source notebooks carry no outputs"


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_settings_are_checked_right_after_the_parameters_cell(src: Path) -> None:
    """The notebook makes its settings dataclass (fnnbook.tasks), which runs the checks `fnn-pipeline check` runs."""
    from fnnbook.tasks import settings_class

    nb_cells = read_source(src).cells
    first = next(i for i, c in enumerate(nb_cells) if "parameters" in c.metadata.get("tags", []))
    task = re.sub(r"^\d+_", "", src.stem)  # files are numbered in paper order: 01_spiral.py runs task spiral
    cls = settings_class(task).__name__
    assert f"\nsettings = {cls}.from_namespace(globals())" in nb_cells[first + 1].source
    assert f"from fnnbook.tasks.{task} import {cls}" in nb_cells[first + 1].source


#: the most lines a code cell may have: its non-blank lines, comments included (what a reader sees)
MAX_CELL_LINES = 15


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_no_code_cell_is_over_15_lines(src: Path) -> None:
    """Short cells: a longer one is split, or its helper moves into fnnlib. The ``parameters`` cell is exempt
    (papermill overwrites it as one cell, one line a parameter)."""
    long = [(i, n) for i, c in enumerate(read_source(src).cells)
            if c.cell_type == "code" and "parameters" not in c.metadata.get("tags", [])
            and (n := sum(1 for line in c.source.splitlines() if line.strip())) > MAX_CELL_LINES]
    assert not long, f"{src.name}: code cells over {MAX_CELL_LINES} non-blank lines (cell index, lines): {long}"


def test_the_quick_start_is_a_short_program_of_public_calls():
    """The quick start's program (its code cells from the imports to the printed result): at most 25 lines
    besides its two imports, visible (not folded), and every ``F.`` name it calls is in fnnlib's public API."""
    import re

    import fnnlib

    src = (Path(__file__).parent.parent / "notebooks" / "src" / "11_quick_start.py").read_text()
    cells = src.split("# %%")
    first = next(i for i, c in enumerate(cells) if c.lstrip("\n").startswith("import torch"))
    last = next(i for i, c in enumerate(cells) if "nbval-check-output" in (c.splitlines() or [""])[0])
    code_cells = [c for c in cells[first:last] if not c.startswith(" [markdown]")]
    assert all("hide-input" not in c.splitlines()[0] and "remove-input" not in c.splitlines()[0] for c in code_cells)
    program = "\n".join(c.split("\n", 1)[1] for c in code_cells)
    lines = [ln for ln in program.splitlines() if ln.strip() and not ln.strip().startswith("#")]
    code = [ln for ln in lines if not ln.startswith(("import ", "from "))]
    assert len(code) <= 25, len(code)
    for name in set(re.findall(r"\bF\.([A-Za-z_]\w*)", program)):
        assert name in fnnlib.__all__, name
    assert "train_from_outputs" in program and "cascade_predict" in program
