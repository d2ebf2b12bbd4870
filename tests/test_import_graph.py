"""No import cycle between the modules of fnnlib and fnnbook, type-only and function-level imports included."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fnnlib", "fnnbook")


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def _target(name: str, modules: dict[str, Path]) -> str | None:
    """The module of ours that ``name`` (a dotted import) lands on: itself, or its longest known prefix."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def imports(path: Path, module: str, modules: dict[str, Path]) -> set[str]:
    """The modules of ours that ``path`` imports anywhere (under ``if TYPE_CHECKING``, in functions too)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
            names = [f"{base}.{a.name}" for a in node.names] + [base]
        else:
            continue
        for n in names:
            t = _target(n, modules)
            if t is not None and t != module and t.split(".")[0] in PACKAGES:
                found.add(t)
    return found


def graph() -> dict[str, set[str]]:
    modules = _modules()
    return {m: imports(p, m, modules) for m, p in modules.items()}


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_planted_cycle() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_a_type_only_import_is_an_edge(tmp_path: Path) -> None:
    p = tmp_path / "m.py"
    p.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from fnnbook.plan import Plan\n")
    assert imports(p, "fnnbook.m", {"fnnbook.plan": p, "fnnbook.m": p}) == {"fnnbook.plan"}


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle(package: str) -> None:
    found = [c for c in cycles(graph()) if any(m.split(".")[0] == package for m in c)]
    assert not found, f"import cycles: {found}"


def test_the_method_does_not_import_the_quadrotor_stack() -> None:
    """The Sec. 5 quadrotor and MPC stack lives in fnnlib.quadrotor; the method's subpackages never import it."""
    method = ("fnnlib.systems", "fnnlib.models", "fnnlib.training", "fnnlib.feedback", "fnnlib.observers")
    found = {m: sorted(t for t in ts if t.startswith("fnnlib.quadrotor"))
             for m, ts in graph().items() if m.startswith(method)}
    assert not {m: ts for m, ts in found.items() if ts}
