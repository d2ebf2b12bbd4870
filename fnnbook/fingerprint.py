"""Fingerprints: what a task's outputs depend on, and whether its last good outputs are current.

A task's fingerprint is a SHA-256 over everything that can change its result, each part kept apart in the
run record (``.fingerprint.json``) so that a rerun can say which one changed, as snakemake's rerun triggers:

- ``notebook``: the notebook's bytes;
- ``parameters``: its parameters (no paths);
- ``code``: each module of the packages searched (``fnnlib`` and ``fnnbook``) that the notebook imports,
  transitively, found from the source (:func:`imported_modules`), each hashed without its docstrings and
  comments (:func:`code_digest`: a docstring edit reruns nothing);
- ``environment``: the installed distributions and their versions, and the Python version
  (:func:`environment`);
- ``data``: the data files the task declares (``data:`` in ``pipeline.yaml``; the whole data directory for
  a task that reads ``data_dir`` and declares none), walked through symlinks, empty folders counted
  (:func:`data_inputs`);
- ``upstream``: its upstream tasks' fingerprints.

No absolute path enters it. The run record also holds the SHA-256 of every product.
"""

from __future__ import annotations

import ast
import glob
import hashlib
import json
import os
import sys
import warnings
from collections.abc import Iterable, Mapping, Sequence
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

import nbformat

from fnnbook.params import FINGERPRINT_FILE
from fnnbook.spec import PipelineSpec, Task
from fnnlib.io import file_sha256

if TYPE_CHECKING:
    from fnnbook.plan import Plan

__all__ = ["code_digest", "data_inputs", "environment", "fingerprint", "imported_modules", "inputs_of",
           "is_up_to_date", "product_files", "stale_reason", "stored"]

#: the trigger of a task that never ran here
NO_EARLIER_RUN = "no earlier run"
#: the parts of a fingerprint, in the order a rerun names them
PARTS = ("notebook", "parameters", "code", "environment", "data", "upstream")


# ---------------------------------------------------------------- code
def _strip_docstrings(tree: ast.AST) -> ast.AST:
    """The tree without module, class and function docstrings (comments never reach the AST)."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if (body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                    and isinstance(body[0].value.value, str)):
                node.body = body[1:] or [ast.Pass()]
    return tree


def code_digest(source: str) -> str:
    """SHA-256 of a module's code without docstrings and comments (its AST dump); of the text if it does not parse."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tree = _strip_docstrings(ast.parse(source))
    except SyntaxError:
        return hashlib.sha256(source.encode()).hexdigest()
    return hashlib.sha256(ast.dump(tree, include_attributes=False).encode()).hexdigest()


def _module_file(name: str, roots: Mapping[str, Path]) -> Path | None:
    """The file of module ``name`` (``pkg/__init__.py`` for a package) below ``roots`` (top package -> folder)."""
    parts = name.split(".")
    root = roots.get(parts[0])
    if root is None:
        return None
    base = root.joinpath(*parts[1:])
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    if base.with_suffix(".py").is_file():
        return base.with_suffix(".py")
    return None


def _imports(tree: ast.AST, module: str, is_package: bool) -> set[str]:
    """Every module name ``tree`` may import: ``import a.b``, ``from a import b`` (``a`` and ``a.b``), relative
    imports resolved against ``module``, and ``importlib.import_module("a.b")`` with a constant name."""
    names: set[str] = set()
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".") if package else []
                base_parts = base_parts[:len(base_parts) - (node.level - 1)] if node.level > 1 else base_parts
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            if base:
                names.add(base)
                names.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)
              and ((isinstance(node.func, ast.Attribute) and node.func.attr == "import_module")
                   or (isinstance(node.func, ast.Name) and node.func.id == "import_module"))):
            names.add(node.args[0].value)
    return names


@lru_cache(maxsize=4096)
def _parsed(path: Path, module: str, stamp: tuple[int, int]) -> tuple[str, frozenset[str] | None]:
    """(code digest, imported module names) of one module file; cached by its size and modification time."""
    source = path.read_text(encoding="utf-8")
    try:
        with warnings.catch_warnings():  # a module's own warnings (an invalid escape) are its tests' business
            warnings.simplefilter("ignore")
            tree = ast.parse(source)
    except SyntaxError:
        return code_digest(source), None
    names = frozenset(_imports(tree, module, path.name == "__init__.py"))
    digest = hashlib.sha256(ast.dump(_strip_docstrings(tree), include_attributes=False).encode()).hexdigest()
    return digest, names


def _parse_imports(path: Path, module: str) -> tuple[str, frozenset[str] | None]:
    stat = path.stat()
    return _parsed(path, module, (stat.st_size, stat.st_mtime_ns))


def notebook_code(notebook: Path) -> str:
    """The code cells of an ``.ipynb`` as one Python text (IPython magics and shell lines left out)."""
    nb = nbformat.read(notebook, as_version=4)
    lines: list[str] = []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for line in cell.source.splitlines():
            lines.append("" if line.lstrip().startswith(("%", "!")) else line)
        lines.append("")
    return "\n".join(lines)


def imported_modules(code: str, roots: Mapping[str, Path]) -> dict[str, str]:
    """The modules below ``roots`` that ``code`` imports, transitively, with their :func:`code_digest`.

    A module brings its parent packages (their ``__init__`` runs first). ``from a import b`` brings ``a.b``
    when that is a module. Code that does not parse depends on every module below ``roots``.
    """
    try:
        start = _imports(ast.parse(code), "", False)
    except SyntaxError:
        start = {f"{top}.{p.relative_to(root).with_suffix('').as_posix().replace('/', '.')}".removesuffix(".__init__")
                 for top, root in roots.items() for p in root.rglob("*.py") if "__pycache__" not in p.parts}
    found: dict[str, str] = {}
    stack = sorted(start)
    seen: set[str] = set()
    while stack:
        name = stack.pop()
        if name in seen:
            continue
        seen.add(name)
        parts = name.split(".")
        for i in range(1, len(parts) + 1):
            mod = ".".join(parts[:i])
            if mod in found:
                continue
            path = _module_file(mod, roots)
            if path is None:
                continue
            digest, names = _parse_imports(path, mod)
            found[mod] = digest
            stack.extend(sorted(names or ()))
    return dict(sorted(found.items()))


def package_roots(packages: Sequence[Path] | None = None) -> dict[str, Path]:
    """Top package name -> folder: the given package folders, or the installed ``fnnlib`` and ``fnnbook``."""
    if packages is None:
        import fnnbook  # noqa: PLC0415
        import fnnlib  # noqa: PLC0415

        packages = [Path(fnnlib.__file__).resolve().parent, Path(fnnbook.__file__).resolve().parent]
    return {Path(p).name: Path(p).resolve() for p in packages}


# ---------------------------------------------------------------- environment
def environment() -> dict[str, str]:
    """The installed distributions (normalised name -> version) and the Python version: what the kernels run.

    Reading every distribution's metadata takes ~0.2 s, and a run reads it once per call of
    :func:`~fnnbook.runner.run` (the test suite: once per task, hundreds of times). It is read again only when
    a folder of ``sys.path`` changed: installing, upgrading or removing a distribution adds or removes its
    ``.dist-info`` folder there, which changes that folder's modification time.
    """
    return dict(_distributions(_path_stamps()))


def _path_stamps() -> tuple[tuple[str, int], ...]:
    """Each folder of ``sys.path`` with its modification time (ns)."""
    stamps = []
    for entry in sys.path:
        try:
            stamps.append((entry, os.stat(entry or ".").st_mtime_ns))
        except OSError:
            continue
    return tuple(stamps)


@lru_cache(maxsize=4)
def _distributions(stamps: tuple[tuple[str, int], ...]) -> tuple[tuple[str, str], ...]:
    """:func:`environment` for one state of ``sys.path`` (``stamps``, the cache key)."""
    dists: dict[str, str] = {"python": ".".join(map(str, sys.version_info[:3]))}
    for dist in metadata.distributions():
        name = (dist.metadata["Name"] or "").lower().replace("_", "-")
        if name:
            dists[name] = dist.version
    return tuple(sorted(dists.items()))


# ---------------------------------------------------------------- data
def _walk(top: Path, base: Path, out: dict[str, str]) -> None:
    """Every file (its SHA-256) and folder (``"folder"``) below ``top``, symlinks followed, keyed relative to
    ``base``; README and hidden files left out."""
    seen: set[tuple[int, int]] = set()
    for folder, dirs, files in os.walk(top, followlinks=True):
        here = Path(folder)
        st = here.stat()
        if (st.st_dev, st.st_ino) in seen:  # a symlink loop
            dirs[:] = []
            continue
        seen.add((st.st_dev, st.st_ino))
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        out[here.relative_to(base).as_posix() + "/"] = "folder"
        for name in sorted(files):
            if name.startswith(".") or name.lower().startswith("readme"):
                continue
            path = here / name
            if path.is_file():
                out[path.relative_to(base).as_posix()] = file_sha256(path)


def data_inputs(data_dir: Path, declared: Sequence[str]) -> dict[str, str]:
    """The data a task reads: for each declared entry (a file, or a folder as ``name/``; ``.`` for the whole
    directory), relative name -> SHA-256 (``"folder"`` for a folder, ``"missing"`` for an entry not there).

    Folders are walked through symlinks; an empty folder counts (it can change what a notebook does).
    """
    out: dict[str, str] = {}
    for entry in declared or (".",):
        path = data_dir / entry
        if path.is_dir():
            _walk(path, data_dir, out)
        elif path.is_file():
            out[Path(entry).as_posix()] = file_sha256(path)
        else:
            out[entry] = "missing"
    return dict(sorted(out.items()))


# ---------------------------------------------------------------- the fingerprint
def _sha(value: Any) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()


def inputs_of(task: Task, params: Mapping[str, Any], upstream: Mapping[str, str], code: Mapping[str, str],
              env: Mapping[str, str], data: Mapping[str, str] | None) -> dict[str, Any]:
    """Each part of a task's fingerprint (:data:`PARTS`): what the run record keeps to name a rerun's trigger."""
    stable = {k: v for k, v in params.items() if k not in ("out_dir", "upstream_dirs", "data_dir")}
    return {"notebook": file_sha256(task.notebook), "parameters": json.loads(json.dumps(stable, default=str)),
            "code": dict(code), "environment": dict(env), "data": None if data is None else dict(data),
            "upstream": dict(sorted(upstream.items()))}


def fingerprint(inputs: Mapping[str, Any]) -> str:
    """SHA-256 over a task's :func:`inputs_of`; paths (out_dir, upstream_dirs, data_dir) stay out."""
    return _sha({part: inputs.get(part) for part in PARTS})


def _changed(old: Any, new: Any) -> list[str]:
    """The keys of two mappings whose values differ (added and removed ones too)."""
    if not isinstance(old, Mapping) or not isinstance(new, Mapping):
        return []
    return sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))


def _listed(names: Iterable[str], limit: int = 3) -> str:
    names = list(names)
    return ", ".join(names[:limit]) + (f" and {len(names) - limit} more" if len(names) > limit else "")


def trigger(old: Mapping[str, Any], new: Mapping[str, Any]) -> str:
    """Which input changed between a run record's ``inputs`` and the plan's: ``code: fnnbook.rules.sec3``,
    ``data: bottle/Testing_dataset.mat``, ``environment: numpy``, ``parameters: N``, ``upstream: spiral``,
    ``notebook`` (the first that differs of each kind, joined by ``; ``)."""
    said = []
    for part in PARTS:
        if old.get(part) == new.get(part):
            continue
        keys = _changed(old.get(part), new.get(part))
        said.append(f"{part}: {_listed(keys)}" if keys else part)
    return "; ".join(said) or "inputs changed"


def stored(spec: PipelineSpec, profile: str, task: str) -> dict[str, Any]:
    """The ``.fingerprint.json`` of a task's last good output ({} if none)."""
    try:
        stored = json.loads((spec.output_dir(profile, task) / FINGERPRINT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return stored if isinstance(stored, dict) else {}


def product_files(products: Sequence[str], directory: Path) -> tuple[list[str], list[str]]:
    """The product files in ``directory`` and the products missing there: ``(files, missing)``.

    A product with a glob wildcard (``neural_ode_seed*.pt``: one file per seed, as many as the profile's seeds)
    stands for every file it matches, and is missing when it matches none.
    """
    files: list[str] = []
    missing: list[str] = []
    for product in products:
        if glob.has_magic(product):
            matches = sorted(p.relative_to(directory).as_posix() for p in directory.glob(product) if p.is_file())
            files += matches
            if not matches:
                missing.append(product)
        elif (directory / product).exists():
            files.append(product)
        else:
            missing.append(product)
    return files, missing


def stale_reason(spec: PipelineSpec, plan: Plan, task: str) -> str | None:
    """Why ``task``'s last good output is not current (None when it is): the rerun's trigger.

    Current when its output folder holds every product with the SHA-256 recorded when it was made (a
    truncated or edited product is stale), was made with the plan's fingerprint, and from the upstream
    outputs that are there now (an upstream task rerun since, even with the same inputs, makes it stale).
    """
    spec = spec.for_profile(plan.profile)
    out = spec.output_dir(plan.profile, task)
    record = stored(spec, plan.profile, task)
    if not record:
        return NO_EARLIER_RUN
    if record.get("fingerprint") != plan.fingerprints[task]:
        old = record.get("inputs")
        return trigger(old, plan.inputs[task]) if isinstance(old, Mapping) and plan.inputs else \
            "inputs changed (the earlier run's record names no inputs)"
    runs = {u: stored(spec, plan.profile, u).get("run_id") for u in spec.tasks[task].upstream}
    if record.get("upstream_runs") != runs:
        return f"upstream: {_listed(u for u in runs if record.get('upstream_runs', {}).get(u) != runs[u])} ran since"
    products = record.get("products")
    files, missing = product_files(spec.tasks[task].products, out) if out.is_dir() else ([], ["*"])
    if not isinstance(products, dict) or missing or set(products) != set(files):
        return "products missing"
    changed = [p for p, digest in products.items() if not (out / p).is_file() or file_sha256(out / p) != digest]
    return f"products changed: {_listed(changed)}" if changed else None


def is_up_to_date(spec: PipelineSpec, plan: Plan, task: str) -> bool:
    """Whether ``task``'s last good output is current (:func:`stale_reason` finds nothing)."""
    return stale_reason(spec, plan, task) is None
