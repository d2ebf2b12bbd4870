"""Cell tags written on the separators of notebooks/src/*.py reach the notebooks (tools/nbbuild.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import load_nbbuild

ROOT = Path(__file__).resolve().parents[2]
SOURCES = sorted((ROOT / "notebooks" / "src").glob("*.py"))


_nbbuild = load_nbbuild


@pytest.mark.parametrize(("header", "kind", "tags"), [
    ("", "code", []),
    (" [markdown]", "markdown", []),
    (' tags=["parameters"]', "code", ["parameters"]),
    (" [tags: hide-input, nbval-check-output]", "code", ["hide-input", "nbval-check-output"]),
    (" [markdown] [tags: remove-cell]", "markdown", ["remove-cell"]),
    (' tags=["hide-input"] [tags: hide-input]', "code", ["hide-input"]),  # once
])
def test_separator_tags(header: str, kind: str, tags: list[str]) -> None:
    assert _nbbuild().parse_header(header, "x.py:1") == (kind, tags)


@pytest.mark.parametrize(("header", "match"), [
    (" [tag: hide-input]", "unknown text"),
    (" tags=[hide-input]", "not a JSON list"),
    (" [tags: hide input]", "invalid tag"),
])
def test_a_bad_separator_is_an_error(header: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        _nbbuild().parse_header(header, "x.py:1")


def test_build_puts_tags_in_cell_metadata(tmp_path: Path) -> None:
    src = tmp_path / "n.py"
    src.write_text('# %% [markdown]\n# # Title\n\n# %% tags=["parameters"]\nx = 1\n\n'
                   "# %% [tags: hide-input]\nimport math\n\n# %%\nprint(x)\n")
    nb = _nbbuild().build(src)
    assert [c.metadata.get("tags") for c in nb.cells] == [None, ["parameters"], ["hide-input"], None]
    src.write_text("# %%\nx = 1\n# %% [tgs: a]\ny = 2\n")
    with pytest.raises(ValueError, match=r"n\.py:3"):  # names the line
        _nbbuild().build(src)


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_committed_notebook_has_its_source_tags(src: Path) -> None:
    built = _nbbuild().build(src)
    committed = json.loads((ROOT / "notebooks" / f"{src.stem}.ipynb").read_text(encoding="utf-8"))
    assert [c["metadata"].get("tags", []) for c in committed["cells"]] == \
        [c.metadata.get("tags", []) for c in built.cells], f"rebuild {src.stem}.ipynb with tools/nbbuild.py"
    assert any("nbval-check-output" in c["metadata"].get("tags", []) for c in committed["cells"]), (
        f"{src.stem}: tag the cell that prints the verdicts '# %% [tags: nbval-check-output]'")
