"""No check's outcome is fixed before the run.

A check decides a verdict only if a plausible run could fail it.  This scans the source of every rule in
``fnnbook/rules/*.py`` (an AST scan, no run) and flags a check whose expression

* is a literal (``True``, ``False``, a number),
* depends only on settings -- parameters with a default (``min_members=5``), module constants, the *count*
  of the measured values (``x.shape``, ``x.size``, ``len(x)``) -- and not on a measured number, or
* is the same expression as a guarantee of the same rule (a property asserted by construction).

A check's expression is a value of the ``checks=`` mapping of a ``ClaimResult(...)`` or of a ``Reading(...)``,
followed through the local names that build it (``checks = {...}``, ``checks[k] = ...``, ``dict(a)``, ``a | b``).
"""

from __future__ import annotations

import ast
import builtins
from pathlib import Path

import pytest

RULES = sorted((Path(__file__).resolve().parents[2] / "fnnbook" / "rules").glob("*.py"))
_COUNTS = {"shape", "size", "ndim"}


def _names(node: ast.AST) -> set[str]:
    """Names an expression reads, where ``x.shape``/``x.size``/``len(x)`` read no data (a count, a setting)."""
    out: set[str] = set()

    def walk(n: ast.AST) -> None:
        if isinstance(n, ast.Attribute) and n.attr in _COUNTS:
            return
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "len":
            return
        if isinstance(n, ast.Name):
            out.add(n.id)
        for child in ast.iter_child_nodes(n):
            walk(child)

    walk(node)
    return out


def _check_dicts(fn: ast.FunctionDef) -> tuple[list[ast.expr], list[ast.expr]]:
    """The check expressions and the guarantee expressions of one rule function."""
    calls = [n for n in ast.walk(fn) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
             and n.func.id in ("ClaimResult", "Reading")]
    roots: list[ast.expr] = []
    guarantees: list[ast.expr] = []
    for call in calls:
        kw = {k.arg: k.value for k in call.keywords}
        if "checks" in kw:
            roots.append(kw["checks"])
        elif len(call.args) >= 2:
            roots.append(call.args[1])
        if isinstance(kw.get("guarantees"), ast.Dict):
            guarantees += kw["guarantees"].values
    # the local names that flow into a checks mapping, and what they are built from
    assigned: dict[str, list[ast.expr]] = {}
    subscripted: dict[str, list[ast.expr]] = {}
    for node in ast.walk(fn):
        if isinstance(node, ast.Assign):
            for target in node.targets:
                pairs = [(target, node.value)]
                if isinstance(target, ast.Tuple):  # ``a, b = {}, {}`` pairs up; ``a, b = f()`` binds both to f()
                    values = node.value.elts if isinstance(node.value, ast.Tuple) and \
                        len(node.value.elts) == len(target.elts) else [node.value] * len(target.elts)
                    pairs = list(zip(target.elts, values))
                for t, value in pairs:
                    if isinstance(t, ast.Name):
                        assigned.setdefault(t.id, []).append(value)
                    elif isinstance(t, ast.Subscript) and isinstance(t.value, ast.Name):
                        subscripted.setdefault(t.value.id, []).append(value)
    exprs: list[ast.expr] = []
    seen: set[str] = set()

    def collect(node: ast.expr) -> None:
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                (collect(value) if key is None else exprs.append(value))  # ``**other`` merges another mapping
        elif isinstance(node, ast.DictComp):
            exprs.append(node.value)
        elif isinstance(node, ast.BinOp):
            collect(node.left)
            collect(node.right)
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict":
            for arg in node.args:
                collect(arg)
        elif isinstance(node, ast.Name) and node.id not in seen:
            seen.add(node.id)
            for value in assigned.get(node.id, []):
                collect(value)
            exprs.extend(subscripted.get(node.id, []))
        elif not isinstance(node, ast.Name):
            exprs.append(node)  # a mapping built some other way: judge the expression as a whole

    for root in roots:
        collect(root)
    return exprs, guarantees


def fixed_checks(source: str, where: str = "<rules>") -> list[str]:
    """Every check of every rule function in ``source`` whose outcome is fixed before the run, as text."""
    tree = ast.parse(source)
    constants = {t.id for node in tree.body if isinstance(node, (ast.Assign, ast.AnnAssign))
                 for t in (node.targets if isinstance(node, ast.Assign) else [node.target]) if isinstance(t, ast.Name)}
    found = []
    for fn in (n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)):
        args = fn.args
        positional = args.posonlyargs + args.args
        with_default = {a.arg for a in positional[len(positional) - len(args.defaults):]}
        with_default |= {a.arg for a, d in zip(args.kwonlyargs, args.kw_defaults) if d is not None}
        settings = with_default | constants | set(dir(builtins)) | {"np", "math"}
        # local names computed only from settings are settings too (in order of assignment)
        for node in ast.walk(fn):
            if isinstance(node, ast.Assign) and all(isinstance(t, ast.Name) for t in node.targets) \
                    and _names(node.value) <= settings:
                settings |= {t.id for t in node.targets}
        exprs, guarantees = _check_dicts(fn)
        dumped = {ast.dump(g) for g in guarantees}
        for expr in exprs:
            text = f"{where}:{fn.name}: {ast.unparse(expr)}"
            if isinstance(expr, ast.Constant):
                found.append(f"{text} (a literal)")
            elif _names(expr) <= settings:
                found.append(f"{text} (settings and counts only, no measured number)")
            elif ast.dump(expr) in dumped:
                found.append(f"{text} (also a guarantee)")
    return found


@pytest.mark.parametrize("path", RULES, ids=lambda p: p.name)
def test_no_rule_has_a_check_fixed_before_the_run(path: Path) -> None:
    assert fixed_checks(path.read_text(encoding="utf-8"), path.name) == []


def test_the_scan_finds_the_rules_checks() -> None:
    """The scan is not vacuous: it reaches the checks of the rules (here S3's, built in steps)."""
    source = (RULES[0].parent / "sec3.py").read_text(encoding="utf-8")
    fn = next(n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.FunctionDef) and n.name == "s3")
    exprs, _ = _check_dicts(fn)
    assert len(exprs) >= 3


PLANTED = '''
def q0(rmse, *, min_members=5, tol=0.1):
    n = len(rmse)
    ok = bool(rmse[0] < tol)
    checks = {"measured": ok}
    checks["planted literal"] = True
    return ClaimResult("Q0", checks=checks | {"enough members": n >= min_members},
                       guarantees={"frozen": bool(rmse[0] < tol)},
                       readings={"other": Reading("s", {"same as a guarantee": bool(rmse[0] < tol),
                                                        "a setting": tol < 1})})
'''


def test_a_planted_fixed_check_is_caught() -> None:
    found = fixed_checks(PLANTED, "planted")
    assert any("True (a literal)" in f for f in found)
    assert any("n >= min_members (settings" in f for f in found)
    assert any("tol < 1 (settings" in f for f in found)
    assert any("(also a guarantee)" in f for f in found)
    assert not any(f.startswith("planted:q0: ok") for f in found)  # a measured check is not flagged
    assert len(found) == 4
