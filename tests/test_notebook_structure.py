"""The notebooks read like the paper: their logic lives in tested modules, and no block of code repeats.

Two rules over ``notebooks/src/*.py`` (jupytext's percent format, so markdown cells are comment lines):

* **No logic defined in a notebook.** A ``def`` or ``class`` anywhere in a notebook is allowed only when it is a
  plotting helper: a function whose name starts ``plot_`` or ``draw_`` and which calls nothing of torch, of
  fnnbook, or of fnnlib beyond its figure functions (``new_figure``, ``save_figure``, ``F.plotting.*``). Science
  goes to fnnlib, verdict and why machinery to fnnbook, each with its tests. A ``class`` is never allowed.
* **No block repeats across notebooks.** No run of :data:`MIN_BLOCK` or more consecutive code lines (white space
  folded; blank lines, comment-only lines, import lines and the ``parameters`` cells left out: papermill needs
  each notebook's own) stands in two notebooks.

:data:`EXEMPT` names what a notebook keeps on purpose (a listed name that is gone fails too, so the list stays true).
"""

from __future__ import annotations

import ast
import re
from itertools import combinations
from pathlib import Path

import pytest
from notebook_source import SOURCES, read_source

#: the fewest consecutive code lines that count as a repeated block
MIN_BLOCK = 6

#: definitions a notebook keeps on purpose, with why
EXEMPT = {
    # the quick start teaches how a user writes their own plant: the class is the lesson
    "11_quick_start": {"Cart"},
}

_PLOT_NAME = re.compile(r"^(plot|draw)_")
_FIGURE_CALLS = {("F", "new_figure"), ("F", "save_figure"), ("F", "plotting")}
_LIBRARIES = ("torch", "fnnlib", "fnnbook")


def _library_aliases(tree: ast.Module) -> set[str]:
    """The names a notebook binds to torch, fnnlib or fnnbook (modules or their members)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names if a.name.split(".")[0] in _LIBRARIES}
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in _LIBRARIES:
            if node.module.startswith("fnnlib.plotting"):
                continue
            names |= {a.asname or a.name for a in node.names}
    return names


def _call_root(func: ast.expr) -> tuple[str, ...]:
    """``F.plotting.COLORS`` -> ("F", "plotting", "COLORS"); () where the callee is not a dotted name."""
    parts = []
    while isinstance(func, ast.Attribute):
        parts.append(func.attr)
        func = func.value
    return (func.id, *reversed(parts)) if isinstance(func, ast.Name) else ()


def is_plotting_helper(node: ast.AST, libraries: set[str]) -> bool:
    """A ``def`` named ``plot_*``/``draw_*`` whose calls reach torch, fnnlib and fnnbook only for figures."""
    if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) or not _PLOT_NAME.match(node.name):
        return False
    for call in (n for n in ast.walk(node) if isinstance(n, ast.Call)):
        root = _call_root(call.func)
        if root and root[0] in libraries and root[:2] not in _FIGURE_CALLS:
            return False
    return True


_DEFS = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)


def _outermost_definitions(node: ast.AST):
    """The definitions in ``node`` that no other definition encloses (a nested one moves with its outer one)."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, _DEFS):
            yield child
        else:
            yield from _outermost_definitions(child)


def defined_logic(src: Path, text: str | None = None) -> set[str]:
    """The names of the outermost definitions in notebook source ``src`` that are not plotting helpers (a ``def``
    inside a loop or an ``if`` counts; one inside another ``def`` or a ``class`` belongs to it)."""
    tree = ast.parse(src.read_text(encoding="utf-8") if text is None else text)
    libraries = _library_aliases(tree)
    return {n.name for n in _outermost_definitions(tree) if not is_plotting_helper(n, libraries)}


def code_lines(src: Path, text: str | None = None) -> list[str]:
    """A notebook's code lines as the duplicate rule reads them: white space folded; blank, comment-only and
    import lines and the ``parameters`` cells left out."""
    lines = []
    for cell in read_source(src, text).cells:
        if cell.cell_type != "code" or "parameters" in cell.metadata.get("tags", []):
            continue
        for line in cell.source.splitlines():
            folded = " ".join(line.split())
            if folded and not folded.startswith(("#", "import ", "from ")):
                lines.append(folded)
    return lines


def shared_blocks(a: list[str], b: list[str], k: int = MIN_BLOCK) -> list[tuple[str, ...]]:
    """The runs of ``k`` consecutive lines that stand in both ``a`` and ``b``."""
    runs_a = {tuple(a[i:i + k]) for i in range(len(a) - k + 1)}
    return sorted({run for i in range(len(b) - k + 1) if (run := tuple(b[i:i + k])) in runs_a})


# the rules themselves must be able to fail


def test_the_logic_rule_tells_plotting_helpers_from_logic(tmp_path: Path) -> None:
    text = ("import torch\nimport fnnlib as F\nfrom fnnbook import why as W\n\n"
            "def plot_curve(ax, v):\n    fig, ax = F.new_figure()\n    ax.plot(v, color=F.plotting.COLORS['x'])\n"
            "    return F.save_figure(fig, '.', 'x')\n\n"
            "def plot_and_compute(ax, v):\n    ax.plot(torch.cumsum(v, 0))\n\n"
            "def draw_grid(ax, g):\n    return W.summary([g])\n\n"
            "def split(z):\n    return F.split_members(z, 2)\n\n"
            "class Plant:\n    def rate(self):\n        pass\n\n"
            "for k in range(2):\n    def plot_k(ax):\n        return torch.zeros(k)\n")
    assert defined_logic(tmp_path / "nb.py", text) == {"plot_and_compute", "draw_grid", "split", "Plant", "plot_k"}


def test_the_duplicate_rule_finds_a_repeated_block_in_other_white_space(tmp_path: Path) -> None:
    block = "".join(f"v{i} = f({i})\n" for i in range(MIN_BLOCK))
    a = code_lines(tmp_path / "a.py", "# %%\n" + block + "# %%\nx = 1\n")
    b = code_lines(tmp_path / "b.py", "# %%\ny = 2\n" + block.replace(" = ", "  =  ").replace("v3", "\n# a comment\nv3"))
    assert shared_blocks(a, b) == [tuple(" ".join(line.split()) for line in block.splitlines())]
    assert shared_blocks(a[:-2], b[:MIN_BLOCK]) == []  # five shared lines are not a block


# the notebooks


@pytest.mark.parametrize("src", SOURCES, ids=[p.stem for p in SOURCES])
def test_a_notebook_defines_no_logic(src: Path) -> None:
    found, exempt = defined_logic(src), EXEMPT.get(src.stem, set())
    assert found <= exempt, (f"{src.name} defines {sorted(found - exempt)}: move them into fnnlib (science) or "
                             "fnnbook (verdicts, whys) with tests; a notebook keeps only plot_*/draw_* helpers")
    assert found == exempt, f"{src.name} no longer defines {sorted(exempt - found)}: strike them from EXEMPT"


def test_no_block_repeats_across_notebooks() -> None:
    lines = {src.stem: code_lines(src) for src in SOURCES}
    repeated = {(a, b): blocks[0] for a, b in combinations(sorted(lines), 2)
                if (blocks := shared_blocks(lines[a], lines[b]))}
    assert not repeated, "blocks repeated across notebooks (move them into a module): " + "; ".join(
        f"{a} and {b}: {list(block)}" for (a, b), block in repeated.items())
