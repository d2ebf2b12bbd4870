"""The book's API reference page: every public name of fnnlib, grouped as ARCHITECTURE.md groups the library.

The names are fnnlib's flat public face (``fnnlib._api.__all__``); each name's group is the subpackage
``fnnlib/_api.py`` imports it from. The page is one MyST file of Sphinx directives: per group a summary
table (each name with its docstring's first paragraph, math included) and an ``autofunction`` /
``autoclass`` entry per callable (numpydoc docstrings read by napoleon, their math rendered by MathJax); a
constant is documented by its ``#:`` comment, read from the module that defines it. (Sphinx's autosummary
would cut each summary at the first ". ", which here is mostly "Eq. (7)".)
"""

from __future__ import annotations

import ast
import importlib
import inspect
import os
import pkgutil
from dataclasses import dataclass
from pathlib import Path

__all__ = ["API_PAGE", "GROUPS", "PublicName", "public_names", "render_api_page", "write_api_page"]

#: the page's name inside the book folder (without suffix)
API_PAGE = "api"

#: subpackage or module fnnlib._api imports from -> group title, in ARCHITECTURE.md's order
GROUPS: dict[str, str] = {
    "fnnlib.feedback": "The feedback core (Sec. 3: Eqs. (7)-(11), the cascade, the gain checks)",
    "fnnlib.observers": "Observers",
    "fnnlib.systems": "Systems",
    "fnnlib.models": "Models",
    "fnnlib.training": "Training and checkpoints",
    "fnnlib.data": "Data",
    "fnnlib.stability": "Stability (Theorem 1, Eq. (25))",
    "fnnlib.sweeps": "Sweeps, metrics and statistics",
    "fnnlib.metrics": "Sweeps, metrics and statistics",
    "fnnlib.stats": "Sweeps, metrics and statistics",
    "fnnlib.results": "Results, settings and utilities",
    "fnnlib.settings": "Results, settings and utilities",
    "fnnlib.plotting": "Results, settings and utilities",
    "fnnlib.seeding": "Results, settings and utilities",
    "fnnlib._threads": "Results, settings and utilities",
}


@dataclass(frozen=True)
class PublicName:
    """One public name of fnnlib.

    Attributes
    ----------
    name : str
        As ``fnnlib.<name>``.
    source : str
        The module fnnlib._api imports it from (a key of :data:`GROUPS`).
    kind : str
        ``"class"``, ``"function"`` or ``"data"``.
    doc : str
        Its docstring (a constant: its ``#:`` comment); "" when it has none.
    """

    name: str
    source: str
    kind: str
    doc: str


def _imported_from() -> dict[str, str]:
    """Name -> the module ``fnnlib/_api.py`` imports it from (read from its source)."""
    api = importlib.import_module("fnnlib._api")
    tree = ast.parse(Path(api.__file__).read_text(encoding="utf-8"))
    return {alias.asname or alias.name: node.module for node in tree.body if isinstance(node, ast.ImportFrom)
            and node.module and node.module.startswith("fnnlib") for alias in node.names}


def _data_doc(name: str, package: str) -> str:
    """The ``#:`` comment over ``name = ...`` in ``package`` or one of its modules ("" when none)."""
    from sphinx.pycode import ModuleAnalyzer  # noqa: PLC0415 (the book's dependency)

    pkg = importlib.import_module(package)
    modules = [package]
    if hasattr(pkg, "__path__"):
        modules += [m.name for m in pkgutil.walk_packages(pkg.__path__, prefix=f"{package}.")]
    for module in modules:
        docs = ModuleAnalyzer.for_module(module).find_attr_docs()
        if ("", name) in docs:
            return "\n".join(docs[("", name)]).strip()
    return ""


def _own_doc(obj: object) -> str:
    """A class's or function's own docstring; a dataclass's generated ``Name(field, ...)`` does not count."""
    doc = obj.__doc__ or ""
    if inspect.isclass(obj) and doc.startswith(f"{obj.__name__}("):
        return ""
    return inspect.cleandoc(doc)


def public_names() -> list[PublicName]:
    """Every name of ``fnnlib._api.__all__`` (once, in that order) with its group source, kind and doc.

    Raises
    ------
    ValueError
        If a public name is not imported by ``fnnlib/_api.py`` from a module of :data:`GROUPS`.
    """
    import fnnlib  # noqa: PLC0415

    api = importlib.import_module("fnnlib._api")
    sources = _imported_from()
    out = []
    for name in dict.fromkeys(api.__all__):
        source = sources.get(name)
        if source is not None and source not in GROUPS:  # e.g. fnnlib.systems.projectile: its subpackage
            source = next((g for g in GROUPS if source.startswith(g + ".")), source)
        if source not in GROUPS:
            raise ValueError(f"fnnlib.{name}: imported from {source!r}, which has no group in "
                             "fnnbook.apiref.GROUPS")
        obj = getattr(fnnlib, name)
        if inspect.isclass(obj):
            kind, doc = "class", _own_doc(obj)
        elif inspect.isroutine(obj):
            kind, doc = "function", _own_doc(obj)
        else:
            kind, doc = "data", _data_doc(name, source)
        out.append(PublicName(name, source, kind, doc))
    return out


def _indent(text: str, by: str = "   ") -> list[str]:
    return [by + line if line.strip() else "" for line in text.splitlines()]


def _entry(item: PublicName) -> list[str]:
    if item.kind == "class":
        return [f".. autoclass:: fnnlib.{item.name}", "   :members:", "   :show-inheritance:", ""]
    if item.kind == "function":
        return [f".. autofunction:: fnnlib.{item.name}", ""]
    import fnnlib  # noqa: PLC0415

    value = getattr(fnnlib, item.name)
    head = [f".. py:data:: {item.name}", "   :module: fnnlib"]
    if isinstance(value, (int, float, str)):
        head.append(f"   :value: {value!r}")
    elif type(value).__module__.startswith("fnnlib"):  # a recipe: its class, documented on this page
        head.append(f"   :type: {type(value).__name__}")
    return [*head, "", *_indent(item.doc), ""]


def render_api_page(names: list[PublicName] | None = None) -> str:
    """The API reference page (MyST markdown): an intro, then per group a summary table and each entry."""
    names = public_names() if names is None else names
    out = ["# API reference", "",
           "Every public name of `fnnlib`, importable from the package itself (`import fnnlib as F; "
           "F.cascade_predict(...)`), grouped by the part of the library that holds it. Each entry's "
           "docstring gives the paper's equation or algorithm and the shapes; the modules are listed one "
           "line each in the repository's `ARCHITECTURE.md`.", ""]
    for title in dict.fromkeys(GROUPS.values()):
        group = [n for n in names if GROUPS[n.source] == title]
        if not group:
            continue
        out += [f"## {title}", "", "```{eval-rst}", ".. list-table::", "   :widths: 30 70",
                "   :class: api-summary", ""]
        for item in group:
            first = " ".join(item.doc.split("\n\n", 1)[0].split())
            out += [f"   * - :py:obj:`~fnnlib.{item.name}`", f"     - {first}"]
        out.append("")
        for item in group:
            out += _entry(item)
        out += ["```", ""]
    return "\n".join(out)


def write_api_page(folder: str | os.PathLike[str]) -> Path:
    """Write :func:`render_api_page` to ``<folder>/api.md``; returns its path."""
    path = Path(folder) / f"{API_PAGE}.md"
    path.write_text(render_api_page(), encoding="utf-8")
    return path
