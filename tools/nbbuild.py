"""Build a clean source notebook from a plain-text cell script.

Cells in the script are separated by lines ``# %%`` (code) or ``# %% [markdown]``.
Markdown cells have their lines prefixed by ``# ``.  A separator line may
carry cell tags, in either spelling::

    # %% tags=["parameters"]
    # %% [tags: hide-input, nbval-check-output]
    # %% [markdown] [tags: remove-cell]

Tags the book and the tests read: ``parameters`` (papermill), ``hide-input``
/ ``remove-input`` / ``remove-cell`` / ``show-input`` (the book: fold, drop,
or keep open a cell's code), ``nbval-check-output`` (nbval compares this
cell's printed output; every other cell only has to run without error).
Anything else on a separator line is an error.

    .venv/bin/python tools/nbbuild.py                       # every notebooks/src/*.py -> notebooks/*.ipynb
    .venv/bin/python tools/nbbuild.py notebooks/src/01_spiral.py notebooks/01_spiral.ipynb
    .venv/bin/python tools/nbbuild.py          # every notebooks/src/<name>.py -> notebooks/<name>.ipynb
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[1]
_JUPYTEXT_TAGS = re.compile(r"\btags=(\[[^\]]*\])")
_TAGS = re.compile(r"\[tags:([^\]]*)\]")
_TAG = re.compile(r"^[A-Za-z0-9_-]+$")


def parse_header(header: str, where: str) -> tuple[str, list[str]]:
    """Return the cell type and tags a separator line (after ``# %%``) declares.

    Raises
    ------
    ValueError
        On text that is neither ``[markdown]`` nor a tags marker, or a malformed tag.
    """
    tags: list[str] = []
    rest = header
    for match in _JUPYTEXT_TAGS.finditer(header):
        try:
            found = json.loads(match.group(1))
        except ValueError as exc:
            raise ValueError(f"{where}: tags={match.group(1)} is not a JSON list of strings") from exc
        tags += found
        rest = rest.replace(match.group(0), "")
    for match in _TAGS.finditer(header):
        tags += [t.strip() for t in match.group(1).split(",") if t.strip()]
        rest = rest.replace(match.group(0), "")
    kind = "markdown" if "[markdown]" in rest else "code"
    rest = rest.replace("[markdown]", "")
    if rest.strip():
        raise ValueError(f"{where}: cannot read the cell separator '# %%{header}' (unknown text {rest.strip()!r}); "
                         "expected '# %%', '# %% [markdown]' and optional '[tags: a, b]' or 'tags=[\"a\"]'")
    bad = [t for t in tags if not isinstance(t, str) or not _TAG.match(t)]
    if bad:
        raise ValueError(f"{where}: invalid tag(s) {bad} in '# %%{header}'")
    return kind, list(dict.fromkeys(tags))


def build(src: Path) -> nbformat.NotebookNode:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.metadata["language_info"] = {"name": "python"}
    text = src.read_text(encoding="utf-8")
    blocks = re.split(r"^# %%(.*)$", text, flags=re.M)
    lines = [i + 1 for i, line in enumerate(text.splitlines()) if line.startswith("# %%")]
    for line, header, body in zip(lines, blocks[1::2], blocks[2::2]):
        kind, tags = parse_header(header, f"{src}:{line}")
        body = body.strip("\n")
        if kind == "markdown":
            text = "\n".join(line[2:] if line.startswith("# ") else line.lstrip("#") for line in body.splitlines())
            cell = nbformat.v4.new_markdown_cell(text)
        else:
            cell = nbformat.v4.new_code_cell(body)
        if tags:
            cell.metadata["tags"] = tags
        nb.cells.append(cell)
    for i, cell in enumerate(nb.cells):
        cell["id"] = f"cell-{i:02d}"
    return nb


def main(argv: list[str]) -> None:
    if len(argv) == 2:
        pairs = [(Path(argv[0]), Path(argv[1]))]
    elif not argv:
        pairs = [(s, ROOT / "notebooks" / f"{s.stem}.ipynb") for s in sorted((ROOT / "notebooks" / "src").glob("*.py"))]
    else:
        raise SystemExit("usage: nbbuild.py [SRC.py DST.ipynb]")
    for src, dst in pairs:
        nbformat.write(build(src), dst)
        print(f"wrote {dst}")


if __name__ == "__main__":
    main(sys.argv[1:])
