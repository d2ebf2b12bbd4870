"""Cell tags written on the separators of notebooks/src/*.py (jupytext's percent format) reach the notebooks."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from notebook_source import REBUILD, ROOT, SOURCES, read_source


def _header(header: str) -> tuple[str, list[str]]:
    (cell,) = read_source("x.py", f"# %%{header}\nx = 1\n").cells
    return cell.cell_type, list(cell.metadata.get("tags", []))


@pytest.mark.parametrize(("header", "kind", "tags"), [
    ("", "code", []),
    (" [markdown]", "markdown", []),
    (' tags=["parameters"]', "code", ["parameters"]),
    (' tags=["hide-input", "nbval-check-output"]', "code", ["hide-input", "nbval-check-output"]),
    (' [markdown] tags=["remove-cell"]', "markdown", ["remove-cell"]),
])
def test_separator_tags(header: str, kind: str, tags: list[str]) -> None:
    assert _header(header) == (kind, tags)


@pytest.mark.parametrize(("header", "match"), [
    (" [tag: hide-input]", "cannot read its separator"),
    (" [tags: hide-input]", "cannot read its separator"),  # the former spelling
    (" tags=[hide-input]", "cannot read its separator"),  # not a JSON list
    (' tags=["hide input"]', "invalid tag"),
])
def test_a_bad_separator_is_an_error(header: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        _header(header)


def test_build_puts_tags_in_cell_metadata() -> None:
    text = ('# %% [markdown]\n# # Title\n\n# %% tags=["parameters"]\nx = 1\n\n'
            '# %% tags=["hide-input"]\nimport math\n\n# %%\nprint(x)\n')
    nb = read_source("n.py", text)
    assert [c.metadata.get("tags") for c in nb.cells] == [None, ["parameters"], ["hide-input"], None]
    with pytest.raises(ValueError, match=r"n\.py: cell 1"):  # names the cell
        read_source("n.py", "# %%\nx = 1\n# %% [tgs: a]\ny = 2\n")


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_committed_notebook_has_its_source_tags(src: Path) -> None:
    built = read_source(src)
    committed = json.loads((ROOT / "notebooks" / f"{src.stem}.ipynb").read_text(encoding="utf-8"))
    assert [c["metadata"].get("tags", []) for c in committed["cells"]] == \
        [c.metadata.get("tags", []) for c in built.cells], f"rebuild {src.stem}.ipynb: {REBUILD}"
    assert any("nbval-check-output" in c["metadata"].get("tags", []) for c in committed["cells"]), (
        f"{src.stem}: tag the cell that prints the verdicts '# %% tags=[\"nbval-check-output\"]'")
