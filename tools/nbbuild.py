"""Build a clean source notebook from a plain-text cell script.

Cells in the script are separated by lines ``# %%`` (code) or ``# %% [markdown]``;
a code cell whose marker line ends in ``tags=["parameters"]`` gets that tag.
Markdown cells have their lines prefixed by ``# ``.

    .venv/bin/python tools/nbbuild.py notebooks/src/spiral.py notebooks/spiral.ipynb
    .venv/bin/python tools/nbbuild.py          # every notebooks/src/<name>.py -> notebooks/<name>.ipynb
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import nbformat


def build(src: Path) -> nbformat.NotebookNode:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.metadata["language_info"] = {"name": "python"}
    blocks = re.split(r"^# %%(.*)$", src.read_text(encoding="utf-8"), flags=re.M)
    for header, body in zip(blocks[1::2], blocks[2::2]):
        body = body.strip("\n")
        if "[markdown]" in header:
            text = "\n".join(line[2:] if line.startswith("# ") else line.lstrip("#") for line in body.splitlines())
            nb.cells.append(nbformat.v4.new_markdown_cell(text))
        else:
            cell = nbformat.v4.new_code_cell(body)
            if 'tags=["parameters"]' in header:
                cell.metadata["tags"] = ["parameters"]
            nb.cells.append(cell)
    for i, cell in enumerate(nb.cells):
        cell["id"] = f"cell-{i:02d}"
    return nb


if __name__ == "__main__":
    if len(sys.argv) == 3:
        pairs = [(Path(sys.argv[1]), Path(sys.argv[2]))]
    elif len(sys.argv) == 1:
        notebooks = Path(__file__).resolve().parents[1] / "notebooks"
        pairs = [(src, notebooks / f"{src.stem}.ipynb") for src in sorted((notebooks / "src").glob("*.py"))]
    else:
        sys.exit("usage: nbbuild.py [SRC.py DST.ipynb]")
    for src, dst in pairs:
        nbformat.write(build(src), dst)
        print(f"wrote {dst}")
