"""Tiny generated notebooks for the pipeline and book tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import nbformat

MakePipeline = Callable[..., Path]  # the make_pipeline fixture (conftest.py)

CLAIMS_YAML = """groups:
  - name: Group one
    settings: the group's settings
    claims:
      - {id: S1, statement: the first claim, section: Sec. 1, figure: Fig. 1, task: leaf}
      - {id: S2, statement: the second claim, section: Sec. 2, figure: Fig. 2, task: child}
"""

# A task that writes results.json (claim S1) and value.txt; `fail` makes it raise.
# (Plain json, no fnnlib import: the kernel starts in about a second.)
LEAF_PARAMS = 'profile = "smoke"\nout_dir = "."\nvalue = 1\nscale = 1.0\nfail = False\n'
LEAF_BODY = """\
import json, pathlib
if fail:
    raise RuntimeError("boom: asked to fail")
out = pathlib.Path(out_dir)
(out / "value.txt").write_text(str(value * scale))
claim = {"id": "S1", "verdict": "reproduced" if value > 0 else "not reproduced", "rule": "value > 0",
         "checks": {"positive": value > 0}, "numbers": {"value": value}, "figure": None}
(out / "results.json").write_text(json.dumps({"task": "leaf", "profile": profile, "created": "",
                                              "claims": [claim], "metrics": {}}))
"""

# A task that reads its upstream's value.txt and doubles it.
CHILD_PARAMS = 'profile = "smoke"\nout_dir = "."\nupstream_dirs = {}\n'
CHILD_BODY = """\
import pathlib
src = pathlib.Path(upstream_dirs["leaf"]) / "value.txt"
(pathlib.Path(out_dir) / "double.txt").write_text(str(2 * float(src.read_text())))
"""


def write_notebook(path: Path, params: str | None, body: str = "", *, tag: str = "parameters") -> Path:
    """Write an nbformat-4 notebook: a title, a tagged parameters cell, a body cell."""
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells.append(nbformat.v4.new_markdown_cell(f"# {path.stem}"))
    if params is not None:
        nb.cells.append(nbformat.v4.new_code_cell(params, metadata={"tags": [tag]}))
    if body:
        nb.cells.append(nbformat.v4.new_code_cell(body))
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, path)
    return path


def book_parameters_cell(notebook: str) -> str:
    """The ``parameters`` cell of one of the book's notebooks (``"06_bottle"``), as source."""
    path = Path(__file__).resolve().parents[2] / "notebooks" / f"{notebook}.ipynb"
    cell = next(c for c in nbformat.read(path, as_version=4).cells if "parameters" in c.metadata.get("tags", []))
    return cell.source


def leaf_task(**params: Any) -> dict[str, Any]:
    return {"title": "Leaf", "notebook": "notebooks/leaf.ipynb", "claims": ["S1"], "upstream": [],
            "products": ["results.json", "value.txt"],
            "parameters": {"smoke": {"value": 2, **params}, "paper": {"value": 3}}}


def child_task() -> dict[str, Any]:
    return {"title": "Child", "notebook": "notebooks/child.ipynb", "claims": [], "upstream": ["leaf"],
            "products": ["double.txt"], "parameters": {"smoke": {}, "paper": {}}}
