"""The notebooks' sources: ``notebooks/src/NN_<name>.py`` in jupytext's percent format, read by jupytext.

A separator line is ``# %%`` (code) or ``# %% [markdown]``, with optional cell tags in jupytext's spelling,
``# %% tags=["hide-input", "nbval-check-output"]``. Tags the book and the tests read: ``parameters``
(papermill), ``hide-input`` / ``remove-input`` / ``remove-cell`` / ``show-input`` (the book: fold, drop, or keep
open a cell's code), ``nbval-check-output`` (nbval compares this cell's printed output). The committed
``notebooks/NN_<name>.ipynb`` are built from them by :data:`REBUILD`.
"""

from __future__ import annotations

import re
from pathlib import Path

import jupytext
import nbformat

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted((ROOT / "notebooks" / "src").glob("*.py"))
REBUILD = "make notebooks"
"""The command (from the repository root) that rebuilds every committed notebook from its source (jupytext)."""

_TAG = re.compile(r"^[A-Za-z0-9_-]+$")
#: cell metadata jupytext keeps from a separator line: the tags, and its own record of blank lines
_CELL_KEYS = {"tags", "lines_to_next_cell"}


def read_source(src: Path | str, text: str | None = None) -> nbformat.NotebookNode:
    """The notebook jupytext reads from the source ``src`` (or from ``text``, named ``src``).

    Raises
    ------
    ValueError
        On a separator jupytext does not read as cell type plus tags (another spelling, a tag list that is
        not JSON, anything else on the line), naming the cell, or on a malformed tag.
    """
    nb = jupytext.read(src) if text is None else jupytext.reads(text, fmt="py:percent")
    for i, cell in enumerate(nb.cells):
        extra = {k: v for k, v in cell.metadata.items() if k not in _CELL_KEYS}
        if extra:
            raise ValueError(f"{src}: cell {i}: cannot read its separator (jupytext read {extra}); expected "
                             "'# %%', '# %% [markdown]' and optional tags=[\"a\", \"b\"]")
        bad = [t for t in cell.metadata.get("tags", []) if not isinstance(t, str) or not _TAG.match(t)]
        if bad:
            raise ValueError(f"{src}: cell {i}: invalid tag(s) {bad}")
    return nb


def cells(nb: dict | nbformat.NotebookNode) -> list[tuple[str, str, list[str]]]:
    """Each cell's type, source text and tags: what a source fixes of its notebook."""
    def text(source: str | list[str]) -> str:
        return "".join(source) if isinstance(source, list) else source

    return [(c["cell_type"], text(c["source"]), list(c["metadata"].get("tags", []))) for c in nb["cells"]]
