"""Source notebooks are clean and built by jupytext from their percent-format scripts in notebooks/src/."""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import jupytext
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
#: the most lines of a cell that is one figure or one plotting helper: a figure cut in two is two half-subjects
MAX_FIGURE_CELL_LINES = 30


def is_one_figure(source: str) -> bool:
    """A cell that draws one figure (one ``new_figure(`` and one ``save_figure(``, from fnnlib.plotting) or defines one plotting
    helper (its only ``def`` is named ``plot_*``/``draw_*``, nothing else at its top level but that)."""
    figure = source.count("new_figure(") == 1 and source.count("save_figure(") == 1
    try:
        body = ast.parse(source).body
    except SyntaxError:  # a cell with IPython syntax is no helper
        return figure
    helper = len(body) == 1 and isinstance(body[0], ast.FunctionDef) and re.match(r"(plot|draw)_", body[0].name)
    return figure or bool(helper)


def is_imports(source: str) -> bool:
    """A cell of imports alone (one subject: what the notebook uses)."""
    try:
        body = ast.parse(source).body
    except SyntaxError:
        return False
    return bool(body) and all(isinstance(s, (ast.Import, ast.ImportFrom)) for s in body)


def long_cells(nb) -> list[tuple[int, int]]:
    """The code cells over their limit, as (cell index, non-blank lines): :data:`MAX_CELL_LINES`, or
    :data:`MAX_FIGURE_CELL_LINES` for :func:`is_one_figure`. The ``parameters`` cell (papermill overwrites it as one
    cell, one line a parameter) and a cell of imports alone are exempt."""
    return [(i, n) for i, c in enumerate(nb.cells)
            if c.cell_type == "code" and "parameters" not in c.metadata.get("tags", []) and not is_imports(c.source)
            and (n := sum(1 for line in c.source.splitlines() if line.strip()))
            > (MAX_FIGURE_CELL_LINES if is_one_figure(c.source) else MAX_CELL_LINES)]


def test_the_cell_length_rule_gives_a_figure_room_and_nothing_else() -> None:
    code = "\n".join(f"v{i} = {i}" for i in range(16))
    figure = "fig, ax = new_figure()\n" + "\n".join(f"ax.plot({i})" for i in range(20)) + "\nsave_figure(fig, out, 'a')"
    helper = "def plot_a(ax):\n" + "\n".join(f"    ax.plot({i})" for i in range(20))
    two = helper + "\n\n\ndef plot_b(ax):\n    pass"
    logic = helper + "\nv = 1"
    imports = "\n".join(f"import m{i}" for i in range(20))
    nb = jupytext.reads("\n".join(f"# %%\n{s}\n" for s in (code, figure, helper, two, logic, figure + "\n" + code,
                                                             imports, imports + "\nv = 1")), fmt="py:percent")
    assert long_cells(nb) == [(0, 16), (3, 23), (4, 22), (5, 38), (7, 21)]


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_no_code_cell_is_over_15_lines(src: Path) -> None:
    """Short cells, cut where the subject changes: a longer one is split there, or its logic moves into fnnlib or
    fnnbook. A figure or a plotting helper is one subject and may run to 30 lines."""
    long = long_cells(read_source(src))
    assert not long, (f"{src.name}: code cells over {MAX_CELL_LINES} non-blank lines ({MAX_FIGURE_CELL_LINES} for "
                      f"one figure or plotting helper) (cell index, lines): {long}")


def test_the_quick_start_is_a_short_program_of_public_calls():
    """The quick start's program (its code cells from the imports to the printed result): at most 25 lines
    besides its imports, visible (not folded), and every ``F.`` name it calls is on fnnlib's face."""
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
        assert name in fnnlib.__all__, name  # the face
    assert "train_from_outputs" in program and "cascade_predict" in program
